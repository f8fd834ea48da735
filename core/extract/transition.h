/* transition.h: the triangles of a transition cell, a cell of stride S some of whose faces
 * and edges carry the samples of a neighbour at stride S / 2 (lod.h), without a vertex of
 * its own: every vertex lies on a lattice edge of the cell's boundary, so the value bound
 * of the grid that edge belongs to holds for it.
 *
 * The cell is seen as the 3 x 3 x 3 lattice of its half-stride points, of which the 26 on
 * its boundary may be present: the 8 corners always, an edge's midpoint when the edge is
 * split, a face's centre (with the midpoints of its 4 edges) when the face is refined. Point
 * (i, j, k), each 0..2 in half strides, has index i + 3 j + 9 k. A case is the set of
 * present points and which of them are above the level; its triangles join the crossings
 * on the cell's boundary edges (slots: the 48 half edges and the 12 whole edges), made by
 * marching cubes' face rule on each face polygon (mc.h), chained into loops, each loop
 * triangulated without a vertex inside the cell:
 *   - no diagonal lies in a face that is not refined (the neighbour across it may draw
 *     one there too) nor along one of the cell's edges, and none repeats a loop segment;
 *   - no triangle has its three corners in one face plane unless that face is refined and
 *     the three crossings can never be collinear, wherever they lie on their edges.
 * So a mesh of such cells and marching cubes' cells is watertight with no zero-area
 * triangle (docs/watertight.md). A few cases have no such triangulation (a loop lying in a
 * face that is not refined); iso_transition_get says so, and the plan refines the cell.
 *
 * Cases are built on first use and kept for the life of the process, shared by all
 * threads (lookups take no lock); past ISO_TRANSITION_MEMO cases, or if memory runs out,
 * a case is built into the caller's scratch instead. */
#ifndef ISO_TRANSITION_H
#define ISO_TRANSITION_H

#include <stdint.h>

#define ISO_TRANSITION_POINTS 27 /* the 3 x 3 x 3 lattice; index 13, the middle, is never used */
#define ISO_TRANSITION_SLOTS 60
#define ISO_TRANSITION_MAX_TRIANGLES 60
#define ISO_TRANSITION_MEMO (1u << 18)

/* Slot s is the boundary edge along `axis` from point `low` (i + 3 j + 9 k) over `length`
 * half strides (1: a half edge, 2: a whole edge of the cell). */
typedef struct iso_transition_slot {
    uint8_t axis, length, low[3];
} iso_transition_slot;
/* The 60 slots, in the order the cases name them. Thread-safe. */
const iso_transition_slot *iso_transition_slots(void);

typedef struct iso_transition_case {
    uint8_t triangle_count;
    uint8_t slot[3 * ISO_TRANSITION_MAX_TRIANGLES]; /* wound so normals point to lower values */
} iso_transition_case;

/* Room for a case built outside the memo. */
typedef struct iso_transition_scratch {
    iso_transition_case built;
} iso_transition_scratch;

/* The case of the points `present` (bit p for point p; corners are always taken as present)
 * with `inside` above the level (bits of absent points ignored); NULL when it has no
 * triangulation as above. The pointer is valid for the life of the process, or (when the
 * memo is full) until the next call with the same scratch. Thread-safe. */
const iso_transition_case *iso_transition_get(uint32_t present, uint32_t inside, iso_transition_scratch *scratch);

/* Point index of (i, j, k). */
static inline unsigned iso_transition_point(unsigned i, unsigned j, unsigned k)
{
    return i + 3 * j + 9 * k;
}

#endif
