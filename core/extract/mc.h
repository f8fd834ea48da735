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

#include "mesh/mesh.h"

typedef struct iso_mc_case {
    uint8_t triangle_count;
    uint8_t edges[36]; /* 3 edge ids per triangle, wound so normals point toward low values */
} iso_mc_case;

extern const uint8_t iso_mc_edge_corner[12][2];

/* The face rule, shared by every module that cuts faces so that all agree. inside[i]
 * says whether corner i of a face is above the level, corners listed counter-clockwise
 * as seen from outside the cell. A run of inside corners is entered through one side
 * (side i joins corner i to corner i + 1 mod 4) and left through another; its
 * iso-segment runs from the side where it is left to the side where it was entered, so
 * with two diagonal inside corners the two runs stay apart. Writes the sides of each
 * segment to from[] and to[]; returns the number of segments, 0 to 2. */
int iso_mc_face_segments(const int inside[4], int from[2], int to[2]);

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

/* Crossings are kept this fraction of an edge away from its ends. A sample exactly at the
 * level (common: integer levels on integer data) would otherwise put the crossings of all
 * its edges on one point, and welding them pinches the surface into non-manifold edges
 * and zero-area triangles. The vertex is then off the level by at most this share of the
 * edge's value step, which extraction reports in its error bound. */
#define ISO_MC_END_GAP (1.0 / 1024)

/* The crossing iso_mc_edge_t gives for ends known not to be infinite (integer samples),
 * without testing for them. */
static inline double iso_mc_edge_t_finite(double a, double b, double level)
{
    double t = (level - a) / (b - a);
    if (!(t >= 0.0 && t <= 1.0))
        return 0.5;
    if (t < ISO_MC_END_GAP)
        return ISO_MC_END_GAP;
    if (t > 1.0 - ISO_MC_END_GAP)
        return 1.0 - ISO_MC_END_GAP;
    return t;
}

/* The crossing on an edge whose low end has value a and high end b, as a fraction of the
 * edge from the low end; exactly one end must be above the level. A NaN end puts it
 * midway, an infinite end against the other. Every module that places vertices on grid
 * edges uses this, so that a vertex is bit-identical whichever piece of the surface
 * computes it. */
static inline double iso_mc_edge_t(double a, double b, double level)
{
    /* An infinite end (a float volume's, or the virtual layer of a cap) is infinitely far
     * in value: the crossing sits against the finite end. */
    if (a - a != 0 && a == a)
        return 1.0 - ISO_MC_END_GAP;
    if (b - b != 0 && b == b)
        return ISO_MC_END_GAP;
    return iso_mc_edge_t_finite(a, b, level);
}

/* |value at the crossing - level| for the crossing t = iso_mc_edge_t(a, b, level): nonzero
 * only where the gap moved it (NaN where an end is NaN or infinite). */
static inline double iso_mc_edge_error(double a, double b, double t, double level)
{
    double e = a + t * (b - a) - level;
    return e < 0 ? -e : e;
}

/* Appends the triangles of one cell as a soup (3 fresh vertices each) in index space.
 * origin: index coordinates of corner 0; size: the cell's extent per axis (1 for a data
 * cell). Vertices on an edge are interpolated linearly from its low to its high end, so
 * the two cells sharing an edge produce bit-identical positions. vertex_error, unless NULL,
 * is raised to the largest |f(v) - level| of the cell's vertices (iso_mc_edge_error).
 * Returns triangles added, or ISO_E_NOMEM. */
int iso_mc_cell(const double v[8], double level, const double origin[3], const double size[3],
                iso_mesh *soup, double *vertex_error);

#endif
