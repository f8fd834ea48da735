/* extract.h: iso-surface extraction from the hierarchy, with a proven error bound.
 *
 * The guarantee: every output vertex v on the level satisfies |f(v) - level| <= error_bound
 * (plus float rounding), f the trilinear interpolant of the full-resolution samples, and
 * error_bound <= tolerance unless a sample sits exactly on the level, where crossings are
 * moved ISO_MC_END_GAP of an edge off it (mc.h). Tolerance 0 gives marching cubes'
 * surface of the full-resolution data. At every tolerance the mesh is indexed (no
 * position twice) and watertight: open edges only on the volume's border (none with cap),
 * two triangles per other edge in opposite directions, no zero-area triangle (mesh/mesh.h).
 *
 * Samples equal to the level count as below it (inside = value > level); NaN samples
 * count as below every level. */
#ifndef ISO_EXTRACT_H
#define ISO_EXTRACT_H

#include <stddef.h>

#include "base/base.h"
#include "mesh/mesh.h"
#include "hierarchy/tree.h"

typedef struct iso_extract_params {
    double level;
    double tolerance;  /* >= 0, in the volume's value units */
    int no_minmax;     /* 1: do not prune by min/max (the paper's middle time column) */
    int cap;           /* 1: close the surface at the volume's border, as if the volume were
                        * surrounded by values below the level (a closed, printable mesh) */
    iso_space space;   /* output positions in world mm (default) or index space */
    int threads;       /* threads for the brick kernel and the walk below bricks
                        * (march.h); 0 = all cores. The mesh does not depend on it. */
} iso_extract_params;

typedef struct iso_extract_stats {
    size_t triangles, vertices;
    size_t nodes_visited;   /* hierarchy nodes examined, stored and on the fly, plus the
                             * bricks the kernel classified */
    size_t cells_visited;   /* cells of the bricks the kernel classified, less those fans
                             * cover, plus the nodes fanned (the paper's column, counted as
                             * the kernel reads: 8 cells at a time, whole bricks) */
    size_t nodes_polygonized;/* nodes larger than a cell emitted whole, as fans */
    double extract_ms;
    double error_bound;     /* max |f(v) - level| over the vertices on the level (all but
                             * a cap's): fan centres as measured, crossings moved off a
                             * tie by ISO_MC_END_GAP; 0 otherwise */
    double fit_error;       /* max fit error of the nodes fanned: how far the data strays
                             * from the trilinear of a node emitted whole */
} iso_extract_stats;

/* Extracts the iso-surface at params->level within params->tolerance into mesh (which is
 * emptied first), welded. stats may be NULL. Returns 0, ISO_E_ARGUMENT for a bad
 * parameter (NaN, negative tolerance), or ISO_E_NOMEM. */
int iso_extract(const iso_tree *tree, const iso_extract_params *params, iso_mesh *mesh,
                iso_extract_stats *stats, iso_error *err);

/* The baseline: marching cubes over every cell, no hierarchy. Same table, welding and
 * output space as iso_extract at tolerance 0. */
int iso_extract_full_scan(const iso_volume *vol, double level, iso_space space,
                          iso_mesh *mesh, iso_extract_stats *stats, iso_error *err);

#endif
