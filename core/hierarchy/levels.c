/* levels.c: each brick's fit error at its coarse levels (levels.h, tree.h). */
#include "levels.h"

#include <math.h>
#include <stdlib.h>

#include "tree.h"
#include "base/base.h"

typedef struct levels_job {
    const iso_volume *vol;
    const iso_bricks *bricks;
    uint16_t *error;
} levels_job;

/* Lemma 1 over every cell of the brick's stride grid: the largest |p(s) - T(s)| of the
 * brick's samples against the trilinear pieces through the grid's samples. In a brick
 * clipped by the border the last cell per axis ends at the last sample, narrower. */
static double stride_error(const iso_fit_block *block, unsigned stride)
{
    double worst = 0;
    iso_box cell;
    for (uint32_t z = 0; z + 1 < block->n[2]; z += stride)
        for (uint32_t y = 0; y + 1 < block->n[1]; y += stride)
            for (uint32_t x = 0; x + 1 < block->n[0]; x += stride) {
                uint32_t at[3] = {x, y, z};
                for (int d = 0; d < 3; d++) {
                    cell.lo[d] = block->lo[d] + at[d];
                    cell.hi[d] = at[d] + stride < block->n[d] ? cell.lo[d] + stride : block->lo[d] + block->n[d] - 1;
                }
                double e = iso_fit_error_past(block, &cell, INFINITY);
                if (!(e <= worst))
                    worst = e == e ? e : INFINITY;
            }
    return worst;
}

static void brick_levels(const levels_job *job, const uint32_t brick[3], double *samples, uint16_t *out)
{
    size_t lo[3], hi[3];
    iso_bricks_box(job->vol, brick, lo, hi);
    iso_fit_block block = {.samples = samples, .integer_samples = !iso_vol_type_is_float(job->vol->type)};
    for (int d = 0; d < 3; d++) {
        block.lo[d] = (uint32_t)lo[d];
        block.n[d] = (uint32_t)(hi[d] - lo[d] + 1);
    }
    iso_vol_read_box(job->vol, lo, hi, samples);
    for (int l = 1; l <= ISO_TREE_LEVELS; l++)
        out[l - 1] = iso_tree_level_encode(iso_float_up(stride_error(&block, 1u << l)));
}

/* Thread t takes the brick slabs z = t, t + threads, ...: slabs are equal in size. */
static void level_slabs(void *context, int t, int threads)
{
    const levels_job *job = context;
    const iso_bricks *b = job->bricks;
    double samples[ISO_BRICK_SAMPLES * ISO_BRICK_SAMPLES * ISO_BRICK_SAMPLES];
    for (uint32_t k = (uint32_t)t; k < b->count[2]; k += (uint32_t)threads)
        for (uint32_t j = 0; j < b->count[1]; j++)
            for (uint32_t i = 0; i < b->count[0]; i++) {
                size_t at = ((size_t)k * b->count[1] + j) * b->count[0] + i;
                uint32_t brick[3] = {i, j, k};
                uint16_t *out = job->error + at * ISO_TREE_LEVELS;
                if (b->min[at] == b->max[at]) {
                    /* A constant brick holds no level; its trilinears are exact anyway. */
                    for (int l = 0; l < ISO_TREE_LEVELS; l++)
                        out[l] = 0;
                    continue;
                }
                brick_levels(job, brick, samples, out);
            }
}

int iso_levels_build(const iso_volume *vol, const iso_bricks *bricks, int threads, uint16_t **out,
                     iso_error *err)
{
    size_t total = iso_bricks_total(bricks);
    levels_job job = {vol, bricks, malloc((total ? total : 1) * ISO_TREE_LEVELS * sizeof(uint16_t))};
    *out = NULL;
    if (!job.error)
        return iso_error_set(err, ISO_E_NOMEM, "out of memory for %zu bricks' level errors", total);
    iso_parallel_run(iso_parallel_threads(threads), level_slabs, &job);
    *out = job.error;
    return 0;
}
