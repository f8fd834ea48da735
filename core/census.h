/* census.h: is an extracted surface watertight? Edge and triangle counts anyone can check.
 *
 * After welding, an edge is interior when exactly two triangles use it, once in each
 * direction. Anything else is counted: open edges (one triangle) split into those on the
 * volume's outer boundary, where a surface that leaves the data must end, and the rest,
 * which are cracks; non-manifold edges (three or more triangles); misoriented edges (two
 * triangles, same direction); degenerate triangles (zero area). A mesh is closed when it
 * has no open edge of either kind and nothing else counted. */
#ifndef ISO_CENSUS_H
#define ISO_CENSUS_H

#include <stddef.h>

#include "error.h"
#include "extract.h"
#include "mesh.h"
#include "volume.h"

typedef struct iso_census {
    size_t edges;
    size_t open_edges;        /* one triangle, not on the volume border: cracks */
    size_t boundary_edges;    /* one triangle, both ends on one border plane of the volume */
    size_t nonmanifold_edges; /* three or more triangles */
    size_t misoriented_edges; /* two triangles using it in the same direction */
    size_t degenerate_triangles; /* zero area */
    int closed;               /* every count above but edges is zero, and there are triangles */
} iso_census;

/* Counts mesh's edges; space says whether positions are world mm or index coordinates of
 * vol (world positions are mapped back to find the border). O(T) with a temporary table;
 * returns 0 or ISO_E_NOMEM. */
int iso_census_compute(const iso_volume *vol, const iso_mesh *mesh, iso_space space,
                       iso_census *out, iso_error *err);

#endif
