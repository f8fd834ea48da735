/* lod.c: extraction within a tolerance, blocks and bricks on their own coarse grids joined
 * by transition cells (lod.h says how and why): PASS 1 (plan) and PASS 2 (fine) here,
 * PASS 3 (the coarse units) in coarse.c, run in that order by extract(). */
#include "lod.h"

#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "lod_context.h"

/* ---- PASS 1: plan ---- */

static int brick_active(const lod *c, size_t at)
{
    const iso_bricks *g = &c->tree->bricks;
    return g->min[at] <= c->level && c->level < g->max[at];
}

/* Brick `at`'s coordinates in the brick grid. */
static void brick_at(const lod *c, size_t at, uint32_t b[3])
{
    b[0] = (uint32_t)(at % c->count[0]);
    b[1] = (uint32_t)(at / c->count[0] % c->count[1]);
    b[2] = (uint32_t)(at / c->count[0] / c->count[1]);
}

/* Lists the bricks the level crosses, once: the passes below walk those only, a surface
 * crossing a small share of a scan's bricks. */
static void list_active(lod *c)
{
    size_t total = iso_bricks_total(&c->tree->bricks), n = 0;
    for (size_t at = 0; at < total; at++) {
        c->active[n] = (uint32_t)at;
        n += (size_t)brick_active(c, at);
    }
    c->active_count = n;
}

/* Every brick whose [min, max] holds the level: stride 8 whole if its level 3 error is
 * within the tolerance, else per block the coarsest of strides 4, 2 whose error is, or 1.
 * The other bricks' blocks get stride 8, which touches nothing (all their samples lie on
 * one side of the level). No sample is read. */
static void plan(lod *c, double tolerance)
{
    const iso_tree *tree = c->tree;
    memset(c->shift, ISO_TREE_LEVELS, (size_t)c->blocks[0] * c->blocks[1] * c->blocks[2]);
    for (size_t n = 0; n < c->active_count; n++) {
        size_t at = c->active[n];
        if (iso_tree_level_error(tree, at) <= tolerance)
            continue;
        uint32_t b[3], first[3], m[3];
        brick_at(c, at, b);
        brick_blocks(c, b, first, m);
        size_t base = block_index(c, first), row = c->blocks[0], plane = row * c->blocks[1];
        for (uint32_t z = 0; z < m[2]; z++)
            for (uint32_t y = 0; y < m[1]; y++)
                for (uint32_t x = 0; x < m[0]; x++) {
                    int l;
                    for (l = ISO_TREE_BLOCK_LEVELS; l > 0; l--)
                        if (iso_tree_block_error(tree, at, (int)(x | y << 1 | z << 2), l) <= tolerance)
                            break;
                    c->shift[base + x + y * row + z * plane] = (uint8_t)l;
                }
    }
}

/* A given plan, made valid: stride 8 only where every block of the brick has it (else 4). */
static void plan_given(lod *c, const uint8_t *given)
{
    for (uint32_t k = 0; k < c->count[2]; k++)
        for (uint32_t j = 0; j < c->count[1]; j++)
            for (uint32_t i = 0; i < c->count[0]; i++) {
                uint32_t b[3] = {i, j, k}, first[3], m[3];
                brick_blocks(c, b, first, m);
                int whole = 1;
                for (uint32_t z = 0; z < m[2]; z++)
                    for (uint32_t y = 0; y < m[1]; y++)
                        for (uint32_t x = 0; x < m[0]; x++) {
                            uint32_t q[3] = {first[0] + x, first[1] + y, first[2] + z};
                            whole &= given[block_index(c, q)] >= ISO_TREE_LEVELS;
                        }
                for (uint32_t z = 0; z < m[2]; z++)
                    for (uint32_t y = 0; y < m[1]; y++)
                        for (uint32_t x = 0; x < m[0]; x++) {
                            uint32_t q[3] = {first[0] + x, first[1] + y, first[2] + z};
                            uint8_t l = given[block_index(c, q)];
                            c->shift[block_index(c, q)] = whole ? ISO_TREE_LEVELS : l < ISO_TREE_LEVELS ? l : ISO_TREE_BLOCK_LEVELS;
                        }
            }
}

/* PASS 3, the coarse units, is coarse.c's (iso_coarse_brick). */

/* Brick b's blocks' strides (log2) into s by march.h's bit k = x | y << 1 | z << 2 (its
 * block at x, y, z); returns the bits of the blocks it has. */
static unsigned brick_shifts(const lod *c, const uint32_t b[3], uint8_t s[8])
{
    uint32_t first[3], m[3];
    brick_blocks(c, b, first, m);
    static const unsigned low_half[3] = {0x55, 0x33, 0x0F}; /* the blocks at x, y, z = 0 */
    const uint8_t *at = c->shift + block_index(c, first);
    size_t row = c->blocks[0], plane = row * c->blocks[1], off[8] = {0, 1, row, row + 1};
    unsigned have = 0xFF;
    for (int d = 0; d < 3; d++)
        have &= m[d] < BLOCKS_PER_BRICK ? low_half[d] : 0xFF;
    for (unsigned k = 4; k < 8; k++)
        off[k] = off[k - 4] + plane;
    for (unsigned k = 0; k < 8; k++)
        if (have >> k & 1)
            s[k] = at[off[k]];
    return have;
}

/* A box's stride grid (its samples lo, lo + stride, ... below hi, then hi, per axis, as
 * the levels are built), as sample offsets: lo and hi per axis times the axis's step. */
typedef struct stride_grid {
    size_t lo[3], hi[3], stride[3];
} stride_grid;

/* The lowest and highest sample of grid g, 0 if one is NaN. With a constant type the
 * sample's switch folds away, and integer samples skip the NaN test. */
static inline __attribute__((always_inline)) int grid_range_as(const void *data, iso_voxel_type type,
                                                               const stride_grid *g, double *lo, double *hi)
{
    double low = INFINITY, high = -INFINITY;
    for (size_t z = g->lo[2];; z = z + g->stride[2] < g->hi[2] ? z + g->stride[2] : g->hi[2]) {
        for (size_t y = g->lo[1];; y = y + g->stride[1] < g->hi[1] ? y + g->stride[1] : g->hi[1]) {
            size_t row = z + y;
            for (size_t x = g->lo[0];; x += g->stride[0]) {
                x = x < g->hi[0] ? x : g->hi[0];
                double v = iso_vol_sample_as(data, type, row + x);
                if ((type == ISO_F32 || type == ISO_F64) && v != v)
                    return 0;
                low = v < low ? v : low;
                high = v > high ? v : high;
                if (x == g->hi[0])
                    break;
            }
            if (y == g->hi[1])
                break;
        }
        if (z == g->hi[2])
            break;
    }
    *lo = low;
    *hi = high;
    return 1;
}

static int grid_range(const iso_volume *vol, const stride_grid *g, double *lo, double *hi)
{
    switch (vol->type) {
    case ISO_U8: return grid_range_as(vol->data, ISO_U8, g, lo, hi);
    case ISO_I8: return grid_range_as(vol->data, ISO_I8, g, lo, hi);
    case ISO_U16: return grid_range_as(vol->data, ISO_U16, g, lo, hi);
    case ISO_I16: return grid_range_as(vol->data, ISO_I16, g, lo, hi);
    case ISO_U32: return grid_range_as(vol->data, ISO_U32, g, lo, hi);
    case ISO_I32: return grid_range_as(vol->data, ISO_I32, g, lo, hi);
    case ISO_F32: return grid_range_as(vol->data, ISO_F32, g, lo, hi);
    case ISO_F64: return grid_range_as(vol->data, ISO_F64, g, lo, hi);
    }
    return 0;
}

/* 1 if the level crosses no cell of the box lo..hi (inclusive samples) at `stride`, whose
 * fit error there is `error`: the stride grid's samples all lie farther than the error
 * from the level, on one side. The fit through them stays within their range and f within
 * the error of the fit over the whole box (Lemma 1, tree.h), so every fine sample of it is
 * on that side too, none of them read. */
static int box_clear_of_level(const lod *c, const uint32_t lo[3], const uint32_t hi[3], uint32_t stride, double error)
{
    stride_grid g;
    size_t step[3] = {1, c->dims[0], (size_t)c->dims[0] * c->dims[1]};
    for (int d = 0; d < 3; d++) {
        g.lo[d] = lo[d] * step[d];
        g.hi[d] = hi[d] * step[d];
        g.stride[d] = stride * step[d];
    }
    double low, high;
    if (!grid_range(c->vol, &g, &low, &high))
        return 0;
    return low - error > c->level || high + error < c->level;
}

/* 1 if the level crosses none of brick b's coarse blocks (strides s and blocks `have` from
 * brick_shifts; box_clear_of_level): marched at
 * stride 1 they would hold no crossing either. A brick at stride 8 whole is never clear:
 * it is only planned so when its min and max hold the level. */
static int coarse_blocks_clear(const lod *c, size_t at, const uint32_t b[3], const uint8_t s[8], unsigned have)
{
    if (s[0] == ISO_TREE_LEVELS)
        return 0;
    uint32_t low[2][3], high[2][3]; /* per axis, the lower and the upper block's samples */
    for (int h = 0; h < 2; h++)
        for (int d = 0; d < 3; d++) {
            low[h][d] = (BLOCKS_PER_BRICK * b[d] + (uint32_t)h) * ISO_TREE_BLOCK;
            high[h][d] = low[h][d] + ISO_TREE_BLOCK < c->dims[d] - 1 ? low[h][d] + ISO_TREE_BLOCK : c->dims[d] - 1;
        }
    for (unsigned k = 0; k < 8; k++) {
        if (!(have >> k & 1) || !s[k])
            continue;
        uint32_t lo[3] = {low[k & 1][0], low[k >> 1 & 1][1], low[k >> 2][2]};
        uint32_t hi[3] = {high[k & 1][0], high[k >> 1 & 1][1], high[k >> 2][2]};
        if (!box_clear_of_level(c, lo, hi, 1u << s[k], iso_tree_block_error(c->tree, at, (int)k, s[k])))
            return 0;
    }
    return 1;
}

/* PASS 1's last step: per brick, the blocks PASS 2 marches (march.h's marks) into marked,
 * and 1 returned if every brick the level crosses is marched whole, i.e. no block the
 * level crosses is coarse. An active brick's marks are its stride-1 blocks; with `prove`,
 * all of its blocks where its coarse blocks are provably clear of the level (smooth
 * regions beside the surface, which a plan coarsens however small the tolerance): at
 * stride 1 they hold no crossing either, so the kernel's surface is the same, its
 * unmasked rows make it, and PASS 3 passes the brick by. (A clear block beside a coarse
 * one the level crosses keeps its stride in the plan: the lattice sets they share keep
 * theirs.) Without min/max pruning the other bricks are marked whole too: they are read
 * and give nothing. */
static int mark_fine(const lod *c, int prove, int no_minmax, uint8_t *marked)
{
    int whole = 1;
    memset(marked, no_minmax ? 0xFF : 0, iso_bricks_total(&c->tree->bricks));
    for (size_t n = 0; n < c->active_count; n++) {
        size_t at = c->active[n];
        uint32_t b[3];
        brick_at(c, at, b);
        uint8_t s[8];
        unsigned have = brick_shifts(c, b, s), fine = 0;
        for (unsigned k = 0; k < 8; k++)
            fine |= (unsigned)((have >> k & 1) && !s[k]) << k;
        if (fine != have && prove && coarse_blocks_clear(c, at, b, s, have))
            fine = have;
        marked[at] = (uint8_t)(fine == have ? 0xFF : fine);
        whole &= fine == have;
    }
    return whole;
}

/* 1 if active brick `at` is marked whole (PASS 2 makes all of its surface). */
static int brick_fine(const uint8_t *marked, size_t at)
{
    return marked[at] == 0xFF;
}

/* PASS 2: the marked blocks (mark_fine), march.c's kernel on those, on the request's
 * threads. */
static int march_fine(lod *c, const iso_extract_params *params, const uint8_t *marked, iso_march_part **fine,
                      iso_error *err)
{
    iso_march_stats ms;
    int rc = iso_march_selected(c->vol, &c->tree->bricks, c->level, marked, params->threads, c->mesh, &ms, fine, err);
    if (rc)
        return rc;
    c->fine = *fine;
    c->cells += ms.cells_visited;
    c->error = ms.error_bound;
    return 0;
}

/* The largest level error (tree.h) of brick b's coarse blocks, as planned. */
static double brick_fit(const lod *c, size_t at, const uint32_t b[3])
{
    uint32_t first[3], m[3];
    brick_blocks(c, b, first, m);
    if (c->shift[block_index(c, first)] == ISO_TREE_LEVELS)
        return iso_tree_level_error(c->tree, at);
    double worst = 0;
    for (uint32_t z = 0; z < m[2]; z++)
        for (uint32_t y = 0; y < m[1]; y++)
            for (uint32_t x = 0; x < m[0]; x++) {
                uint32_t q[3] = {first[0] + x, first[1] + y, first[2] + z};
                unsigned l = c->shift[block_index(c, q)];
                double e = l ? iso_tree_block_error(c->tree, at, (int)(x | y << 1 | z << 2), (int)l) : 0;
                worst = e > worst ? e : worst;
            }
    return worst;
}

/* The volume's and the grids' sizes, for the level. */
static void lod_grid(lod *c, const iso_tree *tree, double level)
{
    c->tree = tree;
    c->vol = tree->vol;
    c->level = level;
    for (int d = 0; d < 3; d++) {
        c->dims[d] = (uint32_t)tree->vol->dims[d];
        c->count[d] = tree->bricks.count[d];
        c->blocks[d] = (c->dims[d] - 1 + ISO_TREE_BLOCK - 1) / ISO_TREE_BLOCK;
    }
}

/* iso_lod_extract's work, with the plan given or (shift NULL) made; with exact not NULL,
 * a plan with no coarse brick sets *exact and extracts nothing. */
static int extract(const iso_tree *tree, const iso_extract_params *params, const uint8_t *shift, int *exact,
                   iso_mesh *mesh, iso_extract_stats *stats, iso_error *err)
{
    lod c = {.cap = params->cap, .mesh = mesh};
    const iso_bricks *g = &tree->bricks;
    lod_grid(&c, tree, params->level);
    iso_mesh_clear(mesh);
    size_t total = iso_bricks_total(g), blocks = (size_t)c.blocks[0] * c.blocks[1] * c.blocks[2];
    c.shift = malloc(blocks + total + 1);
    c.active = malloc((total + 1) * sizeof *c.active);
    if (!c.shift || !c.active) {
        free(c.shift);
        free(c.active);
        return iso_error_set(err, ISO_E_NOMEM, "out of memory extracting the surface");
    }
    list_active(&c);
    if (shift)
        plan_given(&c, shift);
    else
        plan(&c, params->tolerance);
    uint8_t *marked = c.shift + blocks;
    int whole = mark_fine(&c, !shift, params->no_minmax, marked);
    if (!shift && exact && (*exact = whole)) {
        free(c.shift);
        free(c.active);
        return 0;
    }
    iso_march_part *fine = NULL;
    int rc = march_fine(&c, params, marked, &fine, err);
    stats->nodes_visited += params->no_minmax ? total : c.active_count;
    for (size_t n = 0; n < c.active_count && !rc; n++) {
        size_t at = c.active[n];
        if (brick_fine(marked, at))
            continue; /* marched by march_fine */
        uint32_t b[3];
        brick_at(&c, at, b);
        stats->nodes_polygonized++;
        double fit = brick_fit(&c, at, b);
        stats->fit_error = fit > stats->fit_error ? fit : stats->fit_error;
        rc = iso_coarse_brick(&c, b, err);
    }
    stats->cells_visited = c.cells;
    stats->error_bound = c.error;
    iso_march_part_free(fine);
    free(c.shift);
    free(c.active);
    iso_coarse_free(&c);
    if (rc)
        iso_mesh_free(mesh);
    return rc;
}

int iso_lod_extract(const iso_tree *tree, const iso_extract_params *params, int *exact, iso_mesh *mesh,
                    iso_extract_stats *stats, iso_error *err)
{
    *exact = 0;
    return extract(tree, params, NULL, exact, mesh, stats, err);
}

int iso_lod_extract_planned(const iso_tree *tree, const iso_extract_params *params, const uint8_t *shift,
                            iso_mesh *mesh, iso_extract_stats *stats, iso_error *err)
{
    return extract(tree, params, shift, NULL, mesh, stats, err);
}

int iso_lod_plan(const iso_tree *tree, double level, double tolerance, uint8_t *shift)
{
    lod c = {.shift = shift};
    lod_grid(&c, tree, level);
    c.active = malloc((iso_bricks_total(&tree->bricks) + 1) * sizeof *c.active);
    if (!c.active)
        return ISO_E_NOMEM;
    list_active(&c);
    plan(&c, tolerance);
    free(c.active);
    return 0;
}
