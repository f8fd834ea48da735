/* levels.c: each brick's and block's fit error at its coarse levels, and the one-byte
 * codes that keep them (levels.h, tree.h). */
#include "levels.h"

#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "tree.h"
#include "base/base.h"

typedef struct levels_job {
    const iso_volume *vol;
    const iso_bricks *bricks;
    const iso_tree_scale *scale;
    uint8_t *code;
} levels_job;

/* Lemma 1 over every cell of a stride grid on the sub-box of the brick's block that starts
 * at sample `from` (brick-local) and has n[] samples: the largest |p(s) - T(s)| of its
 * samples against the trilinear pieces through the grid's samples. The last cell per axis
 * ends at the sub-box's last sample, narrower where the border clips it. */
static double stride_error(const iso_fit_block *block, const uint32_t from[3], const uint32_t n[3], unsigned stride)
{
    double worst = 0;
    iso_box cell;
    for (uint32_t z = 0; z + 1 < n[2]; z += stride)
        for (uint32_t y = 0; y + 1 < n[1]; y += stride)
            for (uint32_t x = 0; x + 1 < n[0]; x += stride) {
                uint32_t at[3] = {x, y, z};
                for (int d = 0; d < 3; d++) {
                    cell.lo[d] = block->lo[d] + from[d] + at[d];
                    cell.hi[d] = at[d] + stride < n[d] ? cell.lo[d] + stride : block->lo[d] + from[d] + n[d] - 1;
                }
                double e = iso_fit_error_past(block, &cell, INFINITY);
                if (!(e <= worst))
                    worst = e == e ? e : INFINITY;
            }
    return worst;
}

/* The brick's level 3 code, then per block (x | y << 1 | z << 2) its level 1 and 2 codes;
 * a block the brick lacks (clipped to one block along an axis) gets 0. */
static void brick_levels(const levels_job *job, const uint32_t brick[3], double *samples, uint8_t *out)
{
    size_t lo[3], hi[3];
    iso_bricks_box(job->vol, brick, lo, hi);
    iso_fit_block block = {.samples = samples, .integer_samples = !iso_vol_type_is_float(job->vol->type)};
    for (int d = 0; d < 3; d++) {
        block.lo[d] = (uint32_t)lo[d];
        block.n[d] = (uint32_t)(hi[d] - lo[d] + 1);
    }
    iso_vol_read_box(job->vol, lo, hi, samples);
    const uint32_t whole[3] = {0, 0, 0};
    out[0] = iso_tree_code(job->scale, iso_float_up(stride_error(&block, whole, block.n, 1u << ISO_TREE_LEVELS)));
    for (int k = 0; k < 8; k++) {
        uint32_t from[3], n[3];
        int present = 1;
        for (int d = 0; d < 3; d++) {
            from[d] = (uint32_t)(k >> d & 1) * ISO_TREE_BLOCK;
            present &= from[d] + 1 < block.n[d];
            n[d] = block.n[d] - from[d] < ISO_TREE_BLOCK + 1 ? block.n[d] - from[d] : ISO_TREE_BLOCK + 1;
        }
        for (int l = 1; l <= ISO_TREE_BLOCK_LEVELS; l++)
            out[1 + k * ISO_TREE_BLOCK_LEVELS + l - 1] =
                present ? iso_tree_code(job->scale, iso_float_up(stride_error(&block, from, n, 1u << l))) : 0;
    }
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
                uint8_t *out = job->code + at * ISO_TREE_CODES;
                if (b->min[at] == b->max[at]) {
                    /* A constant brick holds no level; its trilinears are exact anyway. */
                    memset(out, 0, ISO_TREE_CODES);
                    continue;
                }
                brick_levels(job, brick, samples, out);
            }
}

void iso_tree_scale_make(double range, iso_tree_scale *scale)
{
    scale->value[0] = 0;
    for (int k = 1; k < 255; k++)
        scale->value[k] = range < INFINITY ? range * exp2((k - 238) / 16.0) : INFINITY;
    scale->value[255] = INFINITY;
}

uint8_t iso_tree_code(const iso_tree_scale *scale, double e)
{
    if (e <= 0)
        return 0;
    if (!(e <= scale->value[254]))
        return 255;
    int lo = 1, hi = 254; /* the values rise: the first at or above e */
    while (lo < hi) {
        int mid = (lo + hi) / 2;
        if (scale->value[mid] >= e)
            hi = mid;
        else
            lo = mid + 1;
    }
    return (uint8_t)lo;
}

int iso_levels_build(const iso_volume *vol, const iso_bricks *bricks, const iso_tree_scale *scale, int threads,
                     uint8_t **out, iso_error *err)
{
    size_t total = iso_bricks_total(bricks);
    levels_job job = {vol, bricks, scale, malloc((total ? total : 1) * ISO_TREE_CODES)};
    *out = NULL;
    if (!job.code)
        return iso_error_set(err, ISO_E_NOMEM, "out of memory for %zu bricks' level errors", total);
    iso_parallel_run(iso_parallel_threads(threads), level_slabs, &job);
    *out = job.code;
    return 0;
}
