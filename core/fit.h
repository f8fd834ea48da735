/* fit.h: a box's fit error (Lemma 1) over a block of samples already read as doubles, with
 * an early exit: the test extraction makes below each brick on the fly, and the one the
 * hierarchy makes a-priori for each brick's fan floor (tree.h).
 *
 * The block is a brick's samples, x fastest: n[a] samples per axis from lo[a]. A box inside
 * it spans at most ISO_BRICK_CELLS cells per axis. */
#ifndef ISO_FIT_H
#define ISO_FIT_H

#include <stddef.h>
#include <stdint.h>

#include "bricks.h"
#include "tree.h"

typedef struct iso_fit_block {
    const double *samples; /* n[0] * n[1] * n[2], x fastest */
    uint32_t lo[3];        /* the block's first sample per axis */
    uint32_t n[3];         /* its samples per axis, at most ISO_BRICK_SAMPLES */
    int integer_samples;   /* no NaN or infinity can occur: a branch-free maximum */
} iso_fit_block;

/* The block's sample at (x, y, z), a point inside it. */
static inline const double *iso_fit_sample(const iso_fit_block *b, uint32_t x, uint32_t y, uint32_t z)
{
    return b->samples + ((size_t)(z - b->lo[2]) * b->n[1] + (y - b->lo[1])) * b->n[0] + (x - b->lo[0]);
}

/* max |p(s) - T(s)| over the samples s of box, T the trilinear through its 8 corners; or
 * any value above limit as soon as one row shows the error passes it (INFINITY if a sample
 * is NaN). The middle sample is tried first: where the data strays from its corners'
 * trilinear most often, so most boxes that will not fit are refused after one sample. */
double iso_fit_error_past(const iso_fit_block *block, const iso_box *box, double limit);

#endif
