/* bricks.h: min and max of the samples over a regular grid of bricks, the flat bottom
 * level of the hierarchy that exact extraction prunes with (march.h).
 *
 * Brick (i, j, k) holds the cells whose lower corner is in [8i, 8i+8) x [8j, 8j+8) x
 * [8k, 8k+8), clipped to the volume, and so the samples [8i, min(8i+8, n-1)] per axis:
 * neighbouring bricks share their face samples. A level can cross a cell of a brick only if
 * min <= level < max (a sample is inside when above the level). Floats are rounded outward
 * and a NaN sample (below every level) makes min -inf, so pruning never drops a crossing.
 * Memory: 8 bytes per brick, 1/64 byte per voxel. */
#ifndef ISO_BRICKS_H
#define ISO_BRICKS_H

#include <stddef.h>
#include <stdint.h>

#include "error.h"
#include "volume.h"

#define ISO_BRICK_CELLS 8
#define ISO_BRICK_SAMPLES (ISO_BRICK_CELLS + 1)

typedef struct iso_bricks {
    uint32_t count[3];  /* bricks per axis: ceil((dims - 1) / 8) */
    float *min, *max;   /* count[0] * count[1] * count[2], x fastest */
} iso_bricks;

/* Scans vol on `threads` threads (0 = all cores). O(N). On failure *bricks is empty. */
int iso_bricks_build(const iso_volume *vol, int threads, iso_bricks *bricks, iso_error *err);
/* Frees the arrays; NULL and an empty grid are allowed. */
void iso_bricks_free(iso_bricks *bricks);

static inline size_t iso_bricks_total(const iso_bricks *b)
{
    return (size_t)b->count[0] * b->count[1] * b->count[2];
}

/* Bricks per axis of vol's grid, ceil((dims - 1) / 8); 0 on an axis of fewer than 2 samples. */
void iso_bricks_count(const iso_volume *vol, uint32_t count[3]);

/* The inclusive sample box of brick (i, j, k): lo = 8 * index, hi clipped to dims - 1. */
void iso_bricks_box(const iso_volume *vol, const uint32_t brick[3], size_t lo[3], size_t hi[3]);

#endif
