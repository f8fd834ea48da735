/* lod_context.h: the tolerance path's working state (lod), shared by its passes: lod.c's
 * PASS 1 (plan) and PASS 2 (fine), and coarse.c's PASS 3 (the coarse units). Internal to
 * the extract stage (lod.h says how and why). */
#ifndef ISO_LOD_CONTEXT_H
#define ISO_LOD_CONTEXT_H

#include <stddef.h>
#include <stdint.h>

#include "base/base.h"
#include "extract.h"
#include "hierarchy/tree.h"
#include "march.h"

#define BRICK_SAMPLES (ISO_BRICK_SAMPLES * ISO_BRICK_SAMPLES * ISO_BRICK_SAMPLES)
/* Where a lattice set lies along one axis of a unit of at most two blocks: on a block
 * plane (even classes 0, 2, 4) or strictly inside a block (odd classes 1, 3). */
#define UNIT_CLASSES (2 * (ISO_BRICK_CELLS / ISO_TREE_BLOCK) + 1)
#define BLOCKS_PER_BRICK (ISO_BRICK_CELLS / ISO_TREE_BLOCK)

/* Vertex ids by lattice segment, open addressing; key 0 marks a free slot. */
typedef struct vertex_map {
    uint64_t *keys;
    uint32_t *ids;
    size_t mask, count;
} vertex_map;

/* One iso-segment on a transition cell's boundary, between two crossings' vertices, and
 * the sample points on either side of its end's crossing (for the centre's root finder). */
typedef struct loop_segment {
    uint32_t from, to;
    uint32_t above[3], below[3];
    int used;
} loop_segment;

typedef struct lod {
    const iso_tree *tree;
    const iso_volume *vol;
    double level;
    int cap;
    uint32_t dims[3], count[3], blocks[3];
    uint8_t *shift;               /* per block: log2 of its stride (PASS 1) */
    uint32_t *active;             /* the bricks whose [min, max] hold the level, grid order */
    size_t active_count;
    const iso_march_part *fine;   /* PASS 2's stride-1 blocks, marched by march.c */
    iso_mesh *mesh;
    /* From here on PASS 3's (coarse.c) but error and cells, which PASS 2 starts; PASS 3
     * grows map, segments and loop, and iso_coarse_free frees them. */
    vertex_map map;
    double error;                 /* largest |f(v) - level| measured */
    size_t cells;
    /* The brick at hand: its box, the samples of its box read so far, and the vertices of
     * the segments strictly inside one of its units; the last two valid where their stamp
     * is the brick's. */
    uint32_t lo[3], hi[3], n[3];
    uint32_t stamp;
    uint32_t brick_first[3], brick_m[3]; /* its blocks (brick_blocks) */
    /* The strides of the lattice sets in the brick's closed box by class (brick_around),
     * valid where around_stamp is the brick's. */
    uint8_t around[UNIT_CLASSES][UNIT_CLASSES][UNIT_CLASSES]; /* [z][y][x] */
    uint32_t around_stamp;
    /* The unit at hand (a block, or a brick marched at stride 8 whole): its box. */
    uint32_t ulo[3], uhi[3];
    uint8_t point_class[3][ISO_BRICK_SAMPLES], span_class[3][ISO_BRICK_CELLS];
    double value[BRICK_SAMPLES];
    uint32_t value_stamp[BRICK_SAMPLES];
    /* Row z * 9 + y has bit x set where sample (x, y, z) (brick-local) is above. */
    uint16_t rows[ISO_BRICK_SAMPLES * ISO_BRICK_SAMPLES];
    uint32_t corner_cell[3], corner_stamp; /* value_at's last data cell, and its corners */
    double corner[8];
    /* The crossings' vertices by segment (low end, axis), with the length they were made
     * for; valid where the stamp is the brick's (crossing). */
    uint32_t seen_id[BRICK_SAMPLES * 3], seen_stamp[BRICK_SAMPLES * 3];
    uint8_t seen_length[BRICK_SAMPLES * 3];
    loop_segment *segments;
    size_t segment_count, segment_capacity;
    uint32_t *loop;
    size_t loop_capacity;
} lod;

/* Block q's index in the block grid (x fastest). */
static inline size_t block_index(const lod *c, const uint32_t q[3])
{
    return ((size_t)q[2] * c->blocks[1] + q[1]) * c->blocks[0] + q[0];
}

/* The blocks of brick b per axis (2, or 1 where the border clips the brick to one block),
 * and its first block. */
static inline void brick_blocks(const lod *c, const uint32_t b[3], uint32_t first[3], uint32_t m[3])
{
    for (int d = 0; d < 3; d++) {
        first[d] = BLOCKS_PER_BRICK * b[d];
        m[d] = c->blocks[d] - first[d] < BLOCKS_PER_BRICK ? c->blocks[d] - first[d] : BLOCKS_PER_BRICK;
    }
}

/* PASS 3 on brick b, not wholly stride 1 (coarse.c): its coarse units' cells into c->mesh,
 * the crossings PASS 2 made (c->fine) used where it made them. Returns 0, ISO_E_NOMEM,
 * ISO_E_LIMIT or ISO_E_INTERNAL, with err set. */
int iso_coarse_brick(lod *c, const uint32_t b[3], iso_error *err);
/* Frees what PASS 3 grew in c over its bricks (the vertex map, the segments, the loop). */
void iso_coarse_free(lod *c);

#endif
