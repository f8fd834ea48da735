/* lod.c: extraction within a tolerance (lod.h says how and why): the plan, made valid for
 * the volume's shape, then lod_march.c's kernel on it. */
#include "lod.h"

#include <math.h>
#include <stdint.h>
#include <stdlib.h>
#include <string.h>

#include "lod_march.h"

typedef struct plan {
    const iso_tree *tree;
    double level;
    double tolerance;   /* < 0: a given plan, every valid stride allowed */
    uint32_t dims[3], bricks[3], blocks[3];
    uint8_t *shift;
} plan;

static void plan_grid(plan *p, const iso_tree *tree, double level, double tolerance, uint8_t *shift)
{
    p->tree = tree;
    p->level = level;
    p->tolerance = tolerance;
    p->shift = shift;
    for (int d = 0; d < 3; d++) {
        p->dims[d] = (uint32_t)tree->vol->dims[d];
        p->bricks[d] = tree->bricks.count[d];
        p->blocks[d] = (p->dims[d] - 1 + ISO_TREE_BLOCK - 1) / ISO_TREE_BLOCK;
    }
}

static size_t blocks_total(const plan *p)
{
    return (size_t)p->blocks[0] * p->blocks[1] * p->blocks[2];
}

static void block_at(const plan *p, size_t b, uint32_t q[3])
{
    q[0] = (uint32_t)(b % p->blocks[0]);
    q[1] = (uint32_t)(b / p->blocks[0] % p->blocks[1]);
    q[2] = (uint32_t)(b / p->blocks[0] / p->blocks[1]);
}

static size_t brick_of(const plan *p, const uint32_t q[3])
{
    return ((size_t)(q[2] / 2) * p->bricks[1] + q[1] / 2) * p->bricks[0] + q[0] / 2;
}

/* 1 if block q may take stride 2^l: its cells along every axis are a multiple of it (the
 * volume's border clips the last blocks), and for l = 3 its brick is whole. */
static int stride_valid(const plan *p, const uint32_t q[3], int l)
{
    for (int d = 0; d < 3; d++) {
        uint32_t first = q[d] * ISO_TREE_BLOCK, cells = p->dims[d] - 1 - first;
        if (l == ISO_TREE_LEVELS) {
            if (p->dims[d] - 1 < (q[d] / 2 + 1) * ISO_BRICK_CELLS)
                return 0;
        } else if (cells < ISO_TREE_BLOCK && cells % (1u << l)) {
            return 0;
        }
    }
    return 1;
}

static double block_error(const plan *p, const uint32_t q[3], int l)
{
    size_t brick = brick_of(p, q);
    if (l == ISO_TREE_LEVELS)
        return iso_tree_level_error(p->tree, brick);
    return iso_tree_block_error(p->tree, brick, (int)((q[0] & 1) | (q[1] & 1) << 1 | (q[2] & 1) << 2), l);
}

/* The coarsest stride <= most that block b may take: valid for its shape and, unless the
 * plan was given, with its level error within the tolerance. */
static int coarsest(void *context, size_t b, int most)
{
    const plan *p = context;
    uint32_t q[3];
    block_at(p, b, q);
    for (int l = most; l > 0; l--)
        if (stride_valid(p, q, l) && (p->tolerance < 0 || block_error(p, q, l) <= p->tolerance))
            return l;
    return 0;
}

static int brick_active(const plan *p, size_t brick)
{
    const iso_bricks *g = &p->tree->bricks;
    return g->min[brick] <= p->level && p->level < g->max[brick];
}

/* Calls visit(p, brick, first block, blocks per axis) for every brick the level crosses,
 * in grid order. */
#define FOR_ACTIVE_BRICKS(p, brick, first, m)                                                  \
    for (uint32_t bz_ = 0; bz_ < (p)->bricks[2]; bz_++)                                        \
        for (uint32_t by_ = 0; by_ < (p)->bricks[1]; by_++)                                    \
            for (uint32_t bx_ = 0; bx_ < (p)->bricks[0]; bx_++)                                \
                for (size_t brick = ((size_t)bz_ * (p)->bricks[1] + by_) * (p)->bricks[0] + bx_; \
                     brick != SIZE_MAX && brick_active((p), brick); brick = SIZE_MAX)          \
                    for (uint32_t first[3] = {2 * bx_, 2 * by_, 2 * bz_},                      \
                                  m[3] = {(p)->blocks[0] - first[0] < 2 ? 1u : 2u,             \
                                          (p)->blocks[1] - first[1] < 2 ? 1u : 2u,             \
                                          (p)->blocks[2] - first[2] < 2 ? 1u : 2u},            \
                                  once_ = 1;                                                    \
                         once_; once_ = 0)

static size_t block_of(const plan *p, const uint32_t first[3], unsigned k)
{
    return ((size_t)(first[2] + (k >> 2)) * p->blocks[1] + first[1] + (k >> 1 & 1)) * p->blocks[0] + first[0] + (k & 1);
}

static int has_block(const uint32_t m[3], unsigned k)
{
    return (k & 1) < m[0] && (k >> 1 & 1) < m[1] && (k >> 2) < m[2];
}

/* How much of the crossed bricks PASS 1 left coarse, a-priori (before the balance). */
typedef struct plan_share {
    size_t blocks;   /* blocks of the bricks the level may cross */
    size_t coarse;   /* of those, at a stride above 1 */
    size_t whole;    /* of those, in a brick at stride 8 */
} plan_share;

/* 1 if crossed brick `brick` (blocks first.., m per axis) takes stride 8 whole: it is whole,
 * its level 3 error is within the tolerance and, with a cap, no block of it is on the
 * volume's border. */
static int brick_whole(const plan *p, size_t brick, const uint32_t first[3], const uint32_t m[3], int cap)
{
    int whole = m[0] == 2 && m[1] == 2 && m[2] == 2 && stride_valid(p, first, ISO_TREE_LEVELS) &&
                iso_tree_level_error(p->tree, brick) <= p->tolerance;
    for (int d = 0; d < 3 && cap && whole; d++)
        whole = first[d] != 0 && first[d] + 2 != p->blocks[d];
    return whole;
}

/* PASS 1's share of blocks in stride-8 bricks alone, without choosing the other blocks'
 * strides: enough to tell whether coarse units pay (coarse_pays), at a fraction of the
 * plan's cost, which would otherwise fall on every exact answer. */
static plan_share whole_share(const plan *p, int cap)
{
    plan_share share = {0, 0, 0};
    FOR_ACTIVE_BRICKS(p, brick, first, m) {
        size_t n = (size_t)m[0] * m[1] * m[2];
        share.blocks += n;
        share.whole += brick_whole(p, brick, first, m, cap) ? n : 0;
    }
    share.coarse = share.whole;
    return share;
}

/* PASS 1: every brick whose [min, max] holds the level takes stride 8 whole if it may,
 * else each of its blocks the coarsest of strides 4 and 2 it may, or 1; the other bricks
 * stride 8, which touches nothing (their samples all lie on one side of the level). No
 * sample is read. With a cap, blocks on the volume's border take stride 1, the cap's (and
 * their brick leaves stride 8). */
static plan_share plan_tolerance(plan *p, int cap)
{
    plan_share share = {0, 0, 0};
    memset(p->shift, ISO_TREE_LEVELS, blocks_total(p));
    FOR_ACTIVE_BRICKS(p, brick, first, m) {
        int whole = brick_whole(p, brick, first, m, cap);
        for (unsigned k = 0; k < 8; k++) {
            if (!has_block(m, k))
                continue;
            size_t b = block_of(p, first, k);
            if (!whole) {
                p->shift[b] = (uint8_t)coarsest(p, b, ISO_TREE_BLOCK_LEVELS);
                uint32_t q[3] = {first[0] + (k & 1), first[1] + (k >> 1 & 1), first[2] + (k >> 2)};
                for (int d = 0; d < 3 && cap; d++)
                    if (q[d] == 0 || q[d] + 1 == p->blocks[d])
                        p->shift[b] = 0;
            }
            share.blocks++;
            share.coarse += p->shift[b] != 0;
            share.whole += p->shift[b] == ISO_TREE_LEVELS;
        }
    }
    return share;
}

/* Whether the coarse kernel beats the exact one on this plan. Per block it pays more than
 * the exact kernel at strides 1 to 4 (transition cells, the balance, units gathered apart)
 * and far less for a stride-8 brick (one cell for 512); measured on the bench cases
 * (docs/performance.md), it is faster exactly where most crossed blocks lie in stride-8
 * bricks. */
static int coarse_pays(const plan_share *share)
{
    return share->coarse && (double)share->whole >= ISO_LOD_PAYS * (double)share->blocks;
}

/* The largest level error of the blocks marched coarse. */
static double plan_fit(const plan *p)
{
    double worst = 0;
    FOR_ACTIVE_BRICKS(p, brick, first, m) {
        for (unsigned k = 0; k < 8; k++) {
            if (!has_block(m, k))
                continue;
            size_t b = block_of(p, first, k);
            if (!p->shift[b])
                continue;
            uint32_t q[3] = {first[0] + (k & 1), first[1] + (k >> 1 & 1), first[2] + (k >> 2)};
            double e = block_error(p, q, p->shift[b]);
            worst = e > worst ? e : worst;
        }
    }
    return worst;
}

/* A given plan made valid: stride 8 only where every block of a whole brick has it (else
 * at most 4), and every stride one its block's shape allows. With a cap, the border at 1. */
static void plan_given(plan *p, const uint8_t *given, int cap)
{
    size_t total = blocks_total(p);
    for (size_t b = 0; b < total; b++) {
        uint32_t q[3];
        block_at(p, b, q);
        int l = given[b] > ISO_TREE_LEVELS ? ISO_TREE_LEVELS : given[b];
        if (l == ISO_TREE_LEVELS) {
            int whole = stride_valid(p, q, ISO_TREE_LEVELS);
            for (int k = 0; k < 8 && whole; k++) {
                uint32_t s[3] = {(q[0] & ~1u) + (k & 1), (q[1] & ~1u) + (k >> 1 & 1), (q[2] & ~1u) + (k >> 2)};
                whole = s[0] < p->blocks[0] && s[1] < p->blocks[1] && s[2] < p->blocks[2] &&
                        given[((size_t)s[2] * p->blocks[1] + s[1]) * p->blocks[0] + s[0]] >= ISO_TREE_LEVELS;
            }
            if (!whole)
                l = ISO_TREE_BLOCK_LEVELS;
        }
        p->shift[b] = (uint8_t)(l == ISO_TREE_LEVELS ? l : coarsest(p, b, l));
        for (int d = 0; d < 3 && cap; d++)
            if (q[d] == 0 || q[d] + 1 == p->blocks[d])
                p->shift[b] = 0;
    }
    for (size_t b = 0; b < total && cap; b++) {
        uint32_t q[3];
        block_at(p, b, q);
        if (p->shift[b] != ISO_TREE_LEVELS)
            continue;
        for (int k = 0; k < 8; k++) {
            uint32_t s[3] = {(q[0] & ~1u) + (k & 1), (q[1] & ~1u) + (k >> 1 & 1), (q[2] & ~1u) + (k >> 2)};
            if (s[0] < p->blocks[0] && s[1] < p->blocks[1] && s[2] < p->blocks[2] &&
                !p->shift[((size_t)s[2] * p->blocks[1] + s[1]) * p->blocks[0] + s[0]])
                p->shift[b] = (uint8_t)coarsest(p, b, ISO_TREE_BLOCK_LEVELS);
        }
    }
}

static int march(plan *p, const iso_extract_params *params, iso_mesh *mesh, iso_extract_stats *stats,
                 iso_error *err)
{
    iso_lod_march_params mp = {.tree = p->tree, .level = params->level, .visit_all = params->no_minmax,
                               .threads = params->threads, .shift = p->shift, .refine = coarsest,
                               .refine_context = p};
    iso_lod_march_stats ms;
    int rc = iso_lod_march(&mp, mesh, &ms, err);
    if (rc)
        return rc;
    stats->nodes_visited += ms.bricks;
    stats->cells_visited = ms.cells;
    stats->nodes_polygonized = ms.coarse_bricks;
    stats->coarse_share = ms.blocks ? (double)ms.coarse_blocks / (double)ms.blocks : 0;
    stats->error_bound = ms.error_bound;
    stats->fit_error = plan_fit(p);
    return 0;
}

int iso_lod_extract(const iso_tree *tree, const iso_extract_params *params, int *exact, iso_mesh *mesh,
                    iso_extract_stats *stats, iso_error *err)
{
    plan p;
    plan_grid(&p, tree, params->level, params->tolerance, NULL);
    plan_share share = whole_share(&p, params->cap);
    if ((*exact = params->coarsen != ISO_COARSEN_ALL && !coarse_pays(&share)))
        return 0;
    size_t total = blocks_total(&p);
    uint8_t *shift = p.shift = malloc(total ? total : 1);
    if (!shift)
        return iso_error_set(err, ISO_E_NOMEM, "out of memory extracting the surface");
    share = plan_tolerance(&p, params->cap);
    if ((*exact = share.coarse == 0)) {
        free(shift);
        return 0;
    }
    iso_mesh_clear(mesh);
    int rc = march(&p, params, mesh, stats, err);
    free(shift);
    return rc;
}

int iso_lod_extract_planned(const iso_tree *tree, const iso_extract_params *params, const uint8_t *shift,
                            uint8_t *balanced, iso_mesh *mesh, iso_extract_stats *stats, iso_error *err)
{
    plan p;
    size_t total = (size_t)((tree->vol->dims[0] + 2) / 4) * ((tree->vol->dims[1] + 2) / 4) * ((tree->vol->dims[2] + 2) / 4);
    uint8_t *mine = malloc(total ? total : 1);
    if (!mine)
        return iso_error_set(err, ISO_E_NOMEM, "out of memory extracting the surface");
    plan_grid(&p, tree, params->level, -1, mine);
    plan_given(&p, shift, params->cap);
    iso_mesh_clear(mesh);
    int rc = march(&p, params, mesh, stats, err);
    if (!rc && balanced)
        memcpy(balanced, mine, total);
    free(mine);
    return rc;
}

int iso_lod_plan(const iso_tree *tree, double level, double tolerance, uint8_t *shift)
{
    plan p;
    plan_grid(&p, tree, level, tolerance, shift);
    (void)plan_tolerance(&p, 0);
    return 0;
}
