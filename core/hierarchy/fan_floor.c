/* fan_floor.c: each brick's least fit error below it (fan_floor.h). */
#include "fan_floor.h"

#include <math.h>
#include <stdlib.h>

#include "tree.h"
#include "base/base.h"

/* 1 if every sample of box equals its first: no level crosses it, so extraction never
 * tries it (a box is tried only when it holds a mixed cell). */
static int constant_box(const iso_fit_block *block, const iso_box *box)
{
    double first = *iso_fit_sample(block, box->lo[0], box->lo[1], box->lo[2]);
    for (uint32_t z = box->lo[2]; z <= box->hi[2]; z++)
        for (uint32_t y = box->lo[1]; y <= box->hi[1]; y++) {
            const double *row = iso_fit_sample(block, box->lo[0], y, z);
            for (uint32_t x = 0; x <= box->hi[0] - box->lo[0]; x++)
                if (row[x] != first)
                    return 0;
        }
    return 1;
}

/* The least fit error among box and the boxes its splits give down to
 * ISO_TREE_FAN_MIN_CELLS cells, constant ones left out, or best if none is below it.
 * Children come first: a small error found low lets the larger boxes stop at their first
 * row past it. */
static double least_fit(const iso_fit_block *block, const iso_box *box, double best)
{
    if (iso_box_cells(box) < ISO_TREE_FAN_MIN_CELLS || best == 0)
        return best;
    iso_box left, right;
    if (iso_box_split(box, &left, &right) >= 0) {
        best = least_fit(block, &left, best);
        best = least_fit(block, &right, best);
    }
    double err = iso_fit_error_past(block, box, best);
    return err < best && !constant_box(block, box) ? err : best;
}

typedef struct floor_job {
    const iso_volume *vol;
    const iso_bricks *bricks;
    float *floor;
} floor_job;

/* Brick (i, j, k)'s floor: its halves and below (the brick itself is a stored node). */
static float brick_floor(const floor_job *job, const uint32_t brick[3], double *samples)
{
    size_t lo[3], hi[3];
    iso_bricks_box(job->vol, brick, lo, hi);
    iso_box box, left, right;
    iso_fit_block block = {.samples = samples, .integer_samples = !iso_vol_type_is_float(job->vol->type)};
    for (int d = 0; d < 3; d++) {
        box.lo[d] = block.lo[d] = (uint32_t)lo[d];
        box.hi[d] = (uint32_t)hi[d];
        block.n[d] = (uint32_t)(hi[d] - lo[d] + 1);
    }
    if (iso_box_split(&box, &left, &right) < 0)
        return INFINITY;
    iso_vol_read_box(job->vol, lo, hi, samples);
    double best = least_fit(&block, &left, INFINITY);
    return iso_float_down(least_fit(&block, &right, best));
}

/* Thread t takes the brick slabs z = t, t + threads, ...: slabs are equal in size. */
static void floor_slabs(void *context, int t, int threads)
{
    const floor_job *job = context;
    const iso_bricks *b = job->bricks;
    double samples[ISO_BRICK_SAMPLES * ISO_BRICK_SAMPLES * ISO_BRICK_SAMPLES];
    for (uint32_t k = (uint32_t)t; k < b->count[2]; k += (uint32_t)threads)
        for (uint32_t j = 0; j < b->count[1]; j++)
            for (uint32_t i = 0; i < b->count[0]; i++) {
                size_t at = ((size_t)k * b->count[1] + j) * b->count[0] + i;
                uint32_t brick[3] = {i, j, k};
                /* A constant brick holds no level: extraction never walks it. */
                job->floor[at] = b->min[at] == b->max[at] ? INFINITY : brick_floor(job, brick, samples);
            }
}

int iso_fan_floor_build(const iso_volume *vol, const iso_bricks *bricks, int threads, float **out,
                        iso_error *err)
{
    size_t total = iso_bricks_total(bricks);
    floor_job job = {vol, bricks, malloc((total ? total : 1) * sizeof(float))};
    *out = NULL;
    if (!job.floor)
        return iso_error_set(err, ISO_E_NOMEM, "out of memory for %zu brick fan floors", total);
    iso_parallel_run(iso_parallel_threads(threads), floor_slabs, &job);
    *out = job.floor;
    return 0;
}
