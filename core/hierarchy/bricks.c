/* bricks.c: the regular min/max grid of bricks (see tree.h). */
#include "tree.h"

#include <math.h>
#include <stdlib.h>

#include "base/base.h"

void iso_bricks_box(const iso_volume *vol, const uint32_t brick[3], size_t lo[3], size_t hi[3])
{
    for (int d = 0; d < 3; d++) {
        lo[d] = (size_t)brick[d] * ISO_BRICK_CELLS;
        hi[d] = lo[d] + ISO_BRICK_CELLS;
        if (hi[d] > vol->dims[d] - 1)
            hi[d] = vol->dims[d] - 1;
    }
}

int iso_bricks_on_border(const iso_bricks *g, size_t at)
{
    size_t b[3] = {at % g->count[0], at / g->count[0] % g->count[1], at / g->count[0] / g->count[1]};
    for (int d = 0; d < 3; d++)
        if (b[d] == 0 || b[d] + 1 == g->count[d])
            return 1;
    return 0;
}

void iso_bricks_count(const iso_volume *vol, uint32_t count[3])
{
    for (int d = 0; d < 3; d++)
        count[d] = vol->dims[d] < 2 || vol->dims[d] > UINT32_MAX ? 0
                                                                 : (uint32_t)((vol->dims[d] - 2) / ISO_BRICK_CELLS + 1);
}

typedef struct scan_job {
    const iso_volume *vol;
    iso_bricks *bricks;
} scan_job;

/* Thread t scans the brick slabs z = t, t + threads, ...: slabs are equal in size. */
static void scan_slabs(void *context, int t, int threads)
{
    scan_job *job = context;
    const iso_bricks *b = job->bricks;
    double samples[ISO_BRICK_SAMPLES * ISO_BRICK_SAMPLES * ISO_BRICK_SAMPLES];
    for (uint32_t k = (uint32_t)t; k < b->count[2]; k += (uint32_t)threads)
        for (uint32_t j = 0; j < b->count[1]; j++)
            for (uint32_t i = 0; i < b->count[0]; i++) {
                uint32_t brick[3] = {i, j, k};
                size_t lo[3], hi[3];
                iso_bricks_box(job->vol, brick, lo, hi);
                iso_vol_read_box(job->vol, lo, hi, samples);
                size_t n = (hi[0] - lo[0] + 1) * (hi[1] - lo[1] + 1) * (hi[2] - lo[2] + 1);
                double mn = INFINITY, mx = -INFINITY;
                int nan = 0;
                for (size_t s = 0; s < n; s++) {
                    double v = samples[s];
                    if (v < mn) mn = v;
                    if (v > mx) mx = v;
                    nan |= v != v;
                }
                size_t at = ((size_t)k * b->count[1] + j) * b->count[0] + i;
                b->min[at] = nan ? -INFINITY : iso_float_down(mn);
                b->max[at] = iso_float_up(mx);
            }
}

int iso_bricks_build(const iso_volume *vol, int threads, iso_bricks *bricks, iso_error *err)
{
    iso_bricks b;
    int rc = iso_bricks_alloc(vol, &b, err);
    if (rc)
        return rc;
    scan_job job = {vol, &b};
    iso_parallel_run(threads, scan_slabs, &job);
    *bricks = b;
    return 0;
}

int iso_bricks_alloc(const iso_volume *vol, iso_bricks *bricks, iso_error *err)
{
    *bricks = (iso_bricks){0};
    iso_bricks b = {0};
    for (int d = 0; d < 3; d++)
        if (vol->dims[d] < 2 || vol->dims[d] > UINT32_MAX)
            return iso_error_set(err, ISO_E_ARGUMENT, "volume dimension %zu out of range", vol->dims[d]);
    iso_bricks_count(vol, b.count);
    size_t total = iso_bricks_total(&b);
    b.min = malloc(total * sizeof *b.min);
    b.max = malloc(total * sizeof *b.max);
    if (!b.min || !b.max) {
        iso_bricks_free(&b);
        return iso_error_set(err, ISO_E_NOMEM, "out of memory for %zu brick bounds", total);
    }
    *bricks = b;
    return 0;
}

void iso_bricks_free(iso_bricks *bricks)
{
    if (!bricks)
        return;
    free(bricks->min);
    free(bricks->max);
    bricks->min = bricks->max = NULL;
}
