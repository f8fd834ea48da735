/* lod_balance.c: PASS 2 of the coarse kernel (lod_march.c): the plan balanced so that no
 * two blocks more than one stride apart share a face or edge the level crosses. Then every
 * transition cell's boundary holds samples of its own stride and half of it only, which is
 * what transition.h's cases are keyed by. A block is refined through the caller's
 * callback (the coarsest stride its error allows below the limit); a stride-8 brick
 * refined gives up stride 8 whole. Whether a shared set is crossed is read from the
 * volume, its samples only: the bricks are classified after the plan. */
#include <stddef.h>
#include <stdlib.h>

#include "lod_job.h"

/* 1 if the samples of the set block q shares with its neighbour at q + delta lie on both
 * sides of the level (read from the volume: bricks are classified after the plan). */
#define DEFINE_SET_CROSSES(NAME, T, ABOVE)                                                     \
    static int NAME(const lod_job *job, const size_t lo[3], const size_t hi[3])                \
    {                                                                                          \
        const iso_volume *vol = job->vol;                                                      \
        const iso_march_threshold *th = &job->threshold;                                       \
        const T *data = (const T *)vol->data;                                                  \
        int above = 0, below = 0;                                                              \
        for (size_t z = lo[2]; z <= hi[2]; z++)                                                \
            for (size_t y = lo[1]; y <= hi[1]; y++) {                                          \
                const T *p = data + (z * vol->dims[1] + y) * vol->dims[0];                     \
                for (size_t x = lo[0]; x <= hi[0]; x++) {                                      \
                    int in = ABOVE;                                                            \
                    above |= in;                                                               \
                    below |= !in;                                                              \
                }                                                                              \
                if (above && below)                                                            \
                    return 1;                                                                  \
            }                                                                                  \
        return 0;                                                                              \
    }
DEFINE_SET_CROSSES(set_crosses_u8, uint8_t, p[x] > th->floor)
DEFINE_SET_CROSSES(set_crosses_i8, int8_t, p[x] > th->floor)
DEFINE_SET_CROSSES(set_crosses_u16, uint16_t, p[x] > th->floor)
DEFINE_SET_CROSSES(set_crosses_i16, int16_t, p[x] > th->floor)
DEFINE_SET_CROSSES(set_crosses_u32, uint32_t, p[x] > th->floor)
DEFINE_SET_CROSSES(set_crosses_i32, int32_t, p[x] > th->floor)
DEFINE_SET_CROSSES(set_crosses_f32, float, (double)p[x] > th->level)
DEFINE_SET_CROSSES(set_crosses_f64, double, p[x] > th->level)

static int shared_set_crosses(const lod_job *job, const uint32_t q[3], const int8_t delta[3])
{
    const iso_volume *vol = job->vol;
    if (job->threshold.reach != ISO_MARCH_SOME_ABOVE)
        return 0; /* every sample on one side */
    size_t lo[3], hi[3];
    for (int d = 0; d < 3; d++) {
        size_t first = (size_t)q[d] * HALF, last = first + HALF < vol->dims[d] - 1 ? first + HALF : vol->dims[d] - 1;
        lo[d] = delta[d] > 0 ? last : first;
        hi[d] = delta[d] < 0 ? first : last;
    }
    switch (vol->type) {
    case ISO_U8: return set_crosses_u8(job, lo, hi);
    case ISO_I8: return set_crosses_i8(job, lo, hi);
    case ISO_U16: return set_crosses_u16(job, lo, hi);
    case ISO_I16: return set_crosses_i16(job, lo, hi);
    case ISO_U32: return set_crosses_u32(job, lo, hi);
    case ISO_I32: return set_crosses_i32(job, lo, hi);
    case ISO_F32: return set_crosses_f32(job, lo, hi);
    case ISO_F64: return set_crosses_f64(job, lo, hi);
    }
    return 0;
}

/* The finest and coarsest stride of every selected brick's blocks (the others keep 3:
 * PASS 2 never refines a brick the level does not cross). */
void iso_lod_brick_ranges(lod_job *job)
{
    for (size_t i = 0; i < job->work_count; i++) {
        const work_brick *wb = &job->work[i];
        unsigned lo = NO_BLOCK, hi = 0;
        for (int k = 0; k < 8; k++) {
            uint32_t at[3] = {2 * wb->brick[0] + (uint32_t)(k & 1), 2 * wb->brick[1] + (uint32_t)(k >> 1 & 1),
                              2 * wb->brick[2] + (uint32_t)(k >> 2)};
            if (at[0] >= job->blocks[0] || at[1] >= job->blocks[1] || at[2] >= job->blocks[2])
                continue;
            unsigned s = job->shift[block_index(job, at[0], at[1], at[2])];
            lo = s < lo ? s : lo;
            hi = s > hi ? s : hi;
        }
        const iso_bricks *g = job->bricks;
        size_t at = ((size_t)wb->brick[2] * g->count[1] + wb->brick[1]) * g->count[0] + wb->brick[0];
        job->brick_lo[at] = (uint8_t)lo;
        job->brick_hi[at] = (uint8_t)hi;
    }
}

/* The finest stride of the blocks of brick b and its 26 neighbours (from brick_lo). */
unsigned iso_lod_bricks_around(const lod_job *job, const uint32_t b[3], unsigned *hi_around)
{
    const iso_bricks *g = job->bricks;
    unsigned lo = NO_BLOCK, hi = 0;
    for (int dz = -1; dz <= 1; dz++)
        for (int dy = -1; dy <= 1; dy++)
            for (int dx = -1; dx <= 1; dx++) {
                uint32_t n[3] = {b[0] + (uint32_t)dx, b[1] + (uint32_t)dy, b[2] + (uint32_t)dz};
                if (n[0] >= g->count[0] || n[1] >= g->count[1] || n[2] >= g->count[2])
                    continue;
                size_t at = ((size_t)n[2] * g->count[1] + n[1]) * g->count[0] + n[0];
                lo = job->brick_lo[at] < lo ? job->brick_lo[at] : lo;
                hi = job->brick_hi[at] > hi ? job->brick_hi[at] : hi;
            }
    if (hi_around)
        *hi_around = hi;
    return lo;
}

/* Blocks to check, each listed once until it is taken. */
typedef struct balance_queue {
    size_t *items;
    size_t count;
    uint8_t *queued;
} balance_queue;

static void push(balance_queue *q, size_t block)
{
    if (q->queued[block])
        return;
    q->queued[block] = 1;
    q->items[q->count++] = block;
}

static void block_coords(const lod_job *job, size_t b, uint32_t p[3])
{
    p[0] = (uint32_t)(b % job->blocks[0]);
    p[1] = (uint32_t)(b / job->blocks[0] % job->blocks[1]);
    p[2] = (uint32_t)(b / job->blocks[0] / job->blocks[1]);
}

/* The 18 offsets of a block's face and edge neighbours. */
static const int8_t neighbour[18][3] = {
    {-1, 0, 0}, {1, 0, 0}, {0, -1, 0}, {0, 1, 0}, {0, 0, -1}, {0, 0, 1},
    {-1, -1, 0}, {1, -1, 0}, {-1, 1, 0}, {1, 1, 0}, {-1, 0, -1}, {1, 0, -1},
    {-1, 0, 1}, {1, 0, 1}, {0, -1, -1}, {0, 1, -1}, {0, -1, 1}, {0, 1, 1}};

/* Pushes block b's neighbours whose stride may now be too coarse for it. */
static void push_neighbours(const lod_job *job, balance_queue *q, size_t b)
{
    uint32_t p[3];
    block_coords(job, b, p);
    for (int k = 0; k < 18; k++) {
        uint32_t n[3] = {p[0] + (uint32_t)neighbour[k][0], p[1] + (uint32_t)neighbour[k][1],
                         p[2] + (uint32_t)neighbour[k][2]};
        if (n[0] < job->blocks[0] && n[1] < job->blocks[1] && n[2] < job->blocks[2]) {
            size_t nb = block_index(job, n[0], n[1], n[2]);
            if (job->shift[nb] > job->shift[b] + 1)
                push(q, nb);
        }
    }
}

/* Sets block b's stride to at most `most`; a stride-8 brick gives up stride 8 whole (its
 * other blocks at most 4). Pushes what that may have unbalanced; returns the blocks
 * changed. */
static size_t refine(lod_job *job, balance_queue *q, size_t b, int most)
{
    const iso_lod_march_params *p = job->params;
    size_t changed = 0;
    if (job->shift[b] == ISO_TREE_LEVELS) {
        uint32_t at[3];
        block_coords(job, b, at);
        for (int k = 0; k < 8; k++) {
            uint32_t s[3] = {at[0] / 2 * 2 + (uint32_t)(k & 1), at[1] / 2 * 2 + (uint32_t)(k >> 1 & 1),
                             at[2] / 2 * 2 + (uint32_t)(k >> 2)};
            if (s[0] >= job->blocks[0] || s[1] >= job->blocks[1] || s[2] >= job->blocks[2])
                continue;
            size_t sb = block_index(job, s[0], s[1], s[2]);
            if (sb == b)
                continue;
            job->shift[sb] = (uint8_t)p->refine(p->refine_context, sb, ISO_TREE_BLOCK_LEVELS);
            push(q, sb);
            push_neighbours(job, q, sb);
            changed++;
        }
    }
    job->shift[b] = (uint8_t)p->refine(p->refine_context, b, most);
    push_neighbours(job, q, b);
    return changed + 1;
}

/* Checks block b against its face and edge neighbours; refines it where one is more than
 * one stride finer across a crossed set. */
static size_t balance_block(lod_job *job, balance_queue *q, size_t b)
{
    int s = job->shift[b];
    if (s < 2)
        return 0; /* no stride is more than one below it */
    uint32_t p[3];
    block_coords(job, b, p);
    int inner = p[0] > 0 && p[1] > 0 && p[2] > 0 && p[0] + 1 < job->blocks[0] && p[1] + 1 < job->blocks[1] &&
                p[2] + 1 < job->blocks[2];
    const ptrdiff_t row = (ptrdiff_t)job->blocks[0], plane = row * (ptrdiff_t)job->blocks[1];
    int most = NO_BLOCK;
    for (int k = 0; k < 18; k++) {
        const int8_t *o = neighbour[k];
        if (!inner) {
            uint32_t n[3] = {p[0] + (uint32_t)o[0], p[1] + (uint32_t)o[1], p[2] + (uint32_t)o[2]};
            if (n[0] >= job->blocks[0] || n[1] >= job->blocks[1] || n[2] >= job->blocks[2])
                continue;
        }
        int limit = job->shift[(ptrdiff_t)b + o[0] + o[1] * row + o[2] * plane] + 1;
        if (s <= limit || limit >= most)
            continue;
        if (shared_set_crosses(job, p, o))
            most = limit;
    }
    return most < s ? refine(job, q, b, most) : 0;
}

/* PASS 2: the blocks of the selected bricks at stride 4 or 8 (a block of stride 1 or 2
 * has no neighbour two strides finer), then what refining them touches; or, given
 * `start`, those blocks refined one stride (a cell without a triangulation) first. */
int iso_lod_balance(lod_job *job, const size_t *start, size_t start_count, size_t *refined)
{
    size_t total = (size_t)job->blocks[0] * job->blocks[1] * job->blocks[2];
    balance_queue q = {0};
    q.items = malloc((total ? total : 1) * sizeof *q.items);
    q.queued = calloc(total ? total : 1, 1);
    if (!q.items || !q.queued) {
        free(q.items);
        free(q.queued);
        return ISO_E_NOMEM;
    }
    if (start) {
        /* A block is listed once per cell without a triangulation, with its stride then:
         * refined once. */
        for (size_t i = 0; i < start_count; i++) {
            size_t b = start[i] / LEVELS;
            int was = (int)(start[i] % LEVELS);
            if (job->shift[b] == was && was)
                *refined += refine(job, &q, b, was - 1);
        }
    } else {
        for (size_t i = 0; i < job->work_count; i++) {
            const work_brick *wb = &job->work[i];
            const iso_bricks *g = job->bricks;
            size_t here = ((size_t)wb->brick[2] * g->count[1] + wb->brick[1]) * g->count[0] + wb->brick[0];
            unsigned lo = iso_lod_bricks_around(job, wb->brick, NULL);
            if (job->brick_hi[here] <= lo + 1)
                continue; /* no block of it has a neighbour two strides finer */
            for (int k = 0; k < 8; k++) {
                uint32_t at[3] = {2 * wb->brick[0] + (uint32_t)(k & 1), 2 * wb->brick[1] + (uint32_t)(k >> 1 & 1),
                                  2 * wb->brick[2] + (uint32_t)(k >> 2)};
                if (at[0] >= job->blocks[0] || at[1] >= job->blocks[1] || at[2] >= job->blocks[2])
                    continue;
                size_t b = block_index(job, at[0], at[1], at[2]);
                if (job->shift[b] >= lo + 2)
                    push(&q, b);
            }
        }
    }
    while (q.count) {
        size_t b = q.items[--q.count];
        q.queued[b] = 0;
        *refined += balance_block(job, &q, b);
    }
    free(q.items);
    free(q.queued);
    return 0;
}
