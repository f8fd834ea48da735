/* mc.h: marching cubes on one cell (Lorensen and Cline 1987), with a case table generated
 * from face rules so that neighbouring cells always agree on their shared face.
 *
 * Corner k of a cell sits at offset (k & 1, (k >> 1) & 1, (k >> 2) & 1). Edge e runs along
 * axis e / 4 from corner iso_mc_edge_corner[e][0] (low end) to [1] (high end). A corner is
 * inside when its value is above the level. On a face with two diagonal inside corners the
 * inside corners are kept apart, a rule that depends only on the face, hence crack-free. */
#ifndef ISO_MC_H
#define ISO_MC_H

#include <stdint.h>

#include "mesh.h"

typedef struct iso_mc_case {
    uint8_t triangle_count;
    uint8_t edges[36]; /* 3 edge ids per triangle, wound so normals point toward low values */
} iso_mc_case;

extern const uint8_t iso_mc_edge_corner[12][2];

/* The 256 cases, indexed by sum over inside corners k of 1 << k. Built once, thread-safe. */
const iso_mc_case *iso_mc_cases(void);

/* Case index of 8 corner values against level (value > level is inside; NaN is not). */
static inline unsigned iso_mc_case_index(const double v[8], double level)
{
    unsigned c = 0;
    for (int k = 0; k < 8; k++)
        c |= (unsigned)(v[k] > level) << k;
    return c;
}

/* Appends the triangles of one cell as a soup (3 fresh vertices each) in index space.
 * origin: index coordinates of corner 0; size: the cell's extent per axis (1 for a data
 * cell). Vertices on an edge are interpolated linearly from its low to its high end, so
 * the two cells sharing an edge produce bit-identical positions. Returns triangles added,
 * or ISO_E_NOMEM. */
int iso_mc_cell(const double v[8], double level, const double origin[3], const double size[3],
                iso_mesh *soup);

#endif
