/* fan.h: one hierarchy node's surface as fans over its face loops: coarse, yet crack-free.
 *
 * A node the tolerance lets extraction keep whole is polygonized from its six faces, not
 * from its interior (docs/watertight.md):
 *
 * PASS 1 (faces): marching squares over every data cell of the node's faces, with the
 *   face rule of mc.h and the same vertex placement (iso_mc_edge_t). A neighbouring node,
 *   fine or coarse, computes the very same segments on the shared face, with
 *   bit-identical vertices, whatever its own size: that is what closes every crack and
 *   leaves no T-junction, at any difference of depth (Cubical Marching Squares, Ho et al.
 *   2005, taken to the data's own resolution on every face). Each face is classified
 *   as bit lines (or taken from the caller's bits, iso_fan_inside) and only the squares
 *   the level crosses build segments.
 * PASS 2 (link): every crossing starts one segment and ends one, so the segments chain
 *   into closed loops, oriented like marching cubes' (normals toward lower values). All
 *   loops are linked before any is fanned, so the triangle count is known first.
 * PASS 3 (fan): a loop of three is one triangle; a longer loop is fanned around a centre
 *   vertex, the loop's centroid moved by Newton steps onto f = level inside the node (f
 *   the data's trilinear interpolant). The node is refused, and the caller descends, when
 *   no face crosses the level (the surface is a closed piece inside), a loop has fewer
 *   than three vertices, the loops would give more than max_triangles (decided from the
 *   crossing count alone when even loops of three would, else after PASS 2: no centre is
 *   placed for such a node), the centre cannot get within vertex_limit of the level, or a
 *   fan triangle would be degenerate or face up the gradient (a fold).
 *
 * The loop vertices are marching cubes' own, so the vertex guarantee of extract.h holds
 * with the centres' measured |f(c) - level|. A closed part of the surface that touches no
 * face of the node (a bubble smaller than the node) is dropped: the tolerance allowed it. */
#ifndef ISO_FAN_H
#define ISO_FAN_H

#include <stddef.h>
#include <stdint.h>

#include "hierarchy/tree.h"
#include "volume/volume.h"

/* Reusable working memory, owned by the caller; grows as needed, never shrinks. Start it
 * zeroed; iso_fan_scratch_free releases it. */
typedef struct iso_fan_segment iso_fan_segment;
typedef struct iso_fan_scratch {
    uint64_t *inside;             /* one face's samples above the level: a bit row per line */
    size_t inside_capacity;
    iso_fan_segment *segments;
    size_t segment_count, segment_capacity;
    uint32_t *slots;              /* open addressing: segment by its start vertex's edge */
    size_t slot_capacity, slot_mask; /* allocated; in use for the node at hand */
    uint32_t *loop;               /* the segments of every loop, in order, one loop after another */
    size_t loop_capacity;
    uint32_t *lengths;            /* the loops' lengths */
    size_t loop_count, length_capacity;
} iso_fan_scratch;

void iso_fan_scratch_free(iso_fan_scratch *scratch);

/* A fan's triangles, as references the caller turns into vertex ids: a loop vertex is
 * named by the grid edge it lies on, key ((z * ny + y) * nx + x) * 3 + axis with (x, y, z)
 * the edge's low end (marching cubes numbers the same crossing, so nothing needs welding);
 * a centre is ISO_FAN_CENTRE | i, its index-space position centres[3i..3i+2]. Owned by the
 * caller; grows as needed; iso_fan_output_free releases it. */
#define ISO_FAN_CENTRE (UINT64_C(1) << 63)
typedef struct iso_fan_output {
    uint64_t *corners;                 /* 3 per triangle */
    size_t triangle_count, triangle_capacity;
    float *centres;                    /* 3 per centre */
    size_t centre_count, centre_capacity;
} iso_fan_output;

void iso_fan_output_free(iso_fan_output *out);

/* The grid edge of a key: its low end and axis. */
void iso_fan_edge_of_key(const iso_volume *vol, uint64_t key, uint32_t corner[3], int *axis);

typedef struct iso_fan_result {
    size_t triangles, loops;
    double vertex_error; /* largest |f(v) - level| over the vertices emitted */
} iso_fan_result;

/* Inside bits a caller already holds for a block of samples around the box (the brick
 * kernel's, march.h, and their transposes), as value > level decides them (NaN is not),
 * in rows along each axis a: with (a, a1, a2) = (a, a + 1, a + 2) mod 3 and p local to
 * origin, bit p[a] of rows[a][p[a2] * stride + p[a1]] says whether sample origin + p is
 * above the level (rows[0] is the kernel's own layout). Each face line is then one shift.
 * Rows hold 16 samples at most. */
typedef struct iso_fan_inside {
    const uint16_t *rows[3];
    uint32_t origin[3];
    uint32_t stride;
} iso_fan_inside;

/* Appends box's surface to out. Returns 1 when emitted, 0 when refused (nothing
 * appended; also when it would take more than max_triangles), ISO_E_NOMEM. The box must
 * hold at least two cells. inside: the box's samples classified already, or NULL. */
int iso_fan_polygonize(const iso_volume *vol, const iso_box *box, double level,
                       double vertex_limit, size_t max_triangles, const iso_fan_inside *inside,
                       iso_fan_scratch *scratch, iso_fan_output *out, iso_fan_result *result);

#endif
