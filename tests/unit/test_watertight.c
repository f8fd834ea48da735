/* test_watertight.c: adaptive meshes are watertight at every level and tolerance.
 *
 * After welding: no open edge off the volume's border, no edge with three or more
 * triangles, every interior edge used once in each direction, no zero-area triangle; with
 * cap, no open edge at all. The vertex guarantee still holds. Checked on hand-built fields
 * with exact answers, a seeded property test over hundreds of random and analytic fields,
 * Debian's MNI brain, and the shared CT and MR scans, where the enclosed
 * volumes of the cranium's capped skin and bone surfaces are checked against InVesalius'. */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

#include "mesh/mesh.h"
#include "check.h"
#include "extract/extract.h"
#include "extract/lod.h"
#include "io/io.h"
#include "surface.h"
#include "hierarchy/tree.h"

#define MRICRON_CH2BET "/usr/share/mricron/templates/ch2bet.nii.gz"

typedef struct totals {
    size_t cases, coarse_cases, coarse_bricks, capped_closed;
} totals;

static int extract(const iso_tree *tree, double level, double tolerance, int cap, iso_space space,
                   iso_mesh *m, iso_extract_stats *st)
{
    iso_extract_params p = {.level = level, .tolerance = tolerance, .cap = cap, .space = space,
                            .coarsen = ISO_COARSEN_ALL};
    iso_error err;
    int rc = iso_extract(tree, &p, m, st, &err);
    CHECKF(rc == 0, "iso_extract(%g, %g): %s", level, tolerance, err.message);
    return rc;
}

/* Everything watertightness and the guarantee promise, for a mesh in index space. */
static void check_sound(const iso_volume *vol, const iso_mesh *m, const iso_extract_stats *st,
                        double level, double tolerance, int cap, const char *what)
{
    iso_census c;
    iso_error err;
    CHECK_OK(iso_census_compute(vol, m, ISO_SPACE_INDEX, &c, &err), &err);
    CHECKF(c.open_edges == 0 && c.nonmanifold_edges == 0 && c.misoriented_edges == 0 &&
               c.degenerate_triangles == 0,
           "%s level %g tol %g cap %d: open %zu, non-manifold %zu, misoriented %zu, degenerate %zu",
           what, level, tolerance, cap, c.open_edges, c.nonmanifold_edges, c.misoriented_edges,
           c.degenerate_triangles);
    if (cap)
        CHECKF(c.boundary_edges == 0 && (m->triangle_count == 0 || c.closed),
               "%s level %g tol %g: capped mesh has %zu border edges", what, level, tolerance,
               c.boundary_edges);
    double worst = surface_worst_vertex_error(vol, m, level);
    CHECKF(worst <= st->error_bound + surface_rounding_slack(vol),
           "%s level %g tol %g: vertex off by %g, bound %g", what, level, tolerance, worst, st->error_bound);
    CHECKF(st->error_bound <= fmax(tolerance, surface_tie_allowance(vol)),
           "%s level %g tol %g: bound %g", what, level, tolerance, st->error_bound);
}

/* ---- hand-built: exact answers ---- */

/* f = x on 9^3 at level 4.25: the brick's coarsest level fits exactly (fit error 0), so
 * the surface is marching cubes on its one 8-cell cell: 2 triangles on 4 crossings, where
 * marching cubes on the data makes 128. */
static void test_plane_is_one_coarse_cell(void)
{
    iso_volume *vol = surface_make_volume(9, 9, 9, ISO_F32);
    for (size_t k = 0; k < 9; k++)
        for (size_t j = 0; j < 9; j++)
            for (size_t i = 0; i < 9; i++)
                iso_vol_set(vol, i, j, k, (double)i);
    iso_vol_update_stats(vol);
    iso_tree *tree = surface_build(vol);
    iso_mesh m;
    iso_mesh_init(&m);
    iso_extract_stats st;
    extract(tree, 4.25, 1, 0, ISO_SPACE_INDEX, &m, &st);
    CHECK_EQ(st.nodes_polygonized, 1);
    CHECK_EQ(st.cells_visited, 1);
    CHECK_EQ(st.triangles, 2);
    CHECK_EQ(st.vertices, 4);
    for (size_t v = 0; v < m.vertex_count; v++) {
        const float *p = m.positions + 3 * v;
        CHECK(fabs(p[0] - 4.25) < 1e-6);
        CHECK((p[1] == 0.0f || p[1] == 8.0f) && (p[2] == 0.0f || p[2] == 8.0f));
    }
    iso_census c;
    iso_error err;
    CHECK_OK(iso_census_compute(vol, &m, ISO_SPACE_INDEX, &c, &err), &err);
    CHECK_EQ(c.boundary_edges, 4);
    CHECK_EQ(c.edges, 5);
    check_sound(vol, &m, &st, 4.25, 1, 0, "plane");
    /* Marching cubes: 8 x 8 crossed cells, two triangles each. */
    extract(tree, 4.25, 0, 0, ISO_SPACE_INDEX, &m, &st);
    CHECK_EQ(st.triangles, 128);
    /* Capped, the part above the level is a closed box 3.75 x 8 x 8 (the cap sits 1/1024
     * outside the border, adding ~0.18). */
    extract(tree, 4.25, 1, 1, ISO_SPACE_INDEX, &m, &st);
    check_sound(vol, &m, &st, 4.25, 1, 1, "capped plane");
    CHECKF(fabs(iso_mesh_enclosed_volume(&m) - 240.0) < 0.3, "enclosed %g", iso_mesh_enclosed_volume(&m));
    iso_mesh_free(&m);
    iso_tree_destroy(tree);
    iso_vol_destroy(vol);
}

/* Half smooth, half rough: bricks at their coarsest level on the left meet marching cubes
 * on the data's cells on the right, through transition cells, along one plane. A crack
 * would be an open edge there. */
static void test_coarse_bricks_meet_cells(void)
{
    iso_volume *vol = surface_make_volume(33, 17, 17, ISO_F32);
    for (size_t k = 0; k < 17; k++)
        for (size_t j = 0; j < 17; j++)
            for (size_t i = 0; i < 33; i++) {
                double rough = i >= 16 ? 0.8 * (surface_uniform() - 0.5) : 0;
                iso_vol_set(vol, i, j, k, 0.7 * (double)i + 0.4 * (double)j - 0.2 * (double)k + rough);
            }
    iso_vol_update_stats(vol);
    iso_tree *tree = surface_build(vol);
    iso_mesh m;
    iso_mesh_init(&m);
    iso_extract_stats st;
    size_t coarse = 0;
    for (double level = 3.3; level < 24; level += 1.7) {
        extract(tree, level, 0.5, 0, ISO_SPACE_INDEX, &m, &st);
        coarse += st.nodes_polygonized;
        check_sound(vol, &m, &st, level, 0.5, 0, "half rough");
        extract(tree, level, 0.5, 1, ISO_SPACE_INDEX, &m, &st);
        check_sound(vol, &m, &st, level, 0.5, 1, "half rough capped");
    }
    CHECKF(coarse >= 4, "%zu bricks coarsened", coarse);
    iso_mesh_free(&m);
    iso_tree_destroy(tree);
    iso_vol_destroy(vol);
}

/* f = x - 1.5 on 17^3 (2 x 2 x 2 bricks, 4 x 4 x 4 blocks), one block coarse: block
 * (0, 0, 0) asked at stride 4 among blocks at stride 1. The plane crosses its faces y = 4
 * and z = 4, which it shares with stride-1 blocks, so the balance takes it to stride 2
 * (a stride-4 block never meets a stride-1 one across a crossed set); asked at 2, the same.
 * Its 2 x 2 x 2 cells at stride 2: the plane crosses the four with x in [0, 2]. The one at
 * y, z in [0, 2] is marching cubes' (2 triangles); the two touching one refined face have a
 * loop of 5 crossings (3 triangles each), the one touching both faces of 6 (4): 12. The
 * 15 stride-1 blocks with x in [0, 4] have 4 x 4 crossed cells, 2 triangles each: 480.
 * Vertices: the 17 x 17 crossings of the plane's data x-edges, less the 25 of the coarse
 * block's box but the 9 on its refined faces, plus its 4 stride-2 x-edges off those
 * faces: 277. Every vertex is on the plane: no vertex inside a cell. */
static void test_one_coarse_block_among_fine_ones(void)
{
    iso_volume *vol = surface_make_volume(17, 17, 17, ISO_F32);
    for (size_t k = 0; k < 17; k++)
        for (size_t j = 0; j < 17; j++)
            for (size_t i = 0; i < 17; i++)
                iso_vol_set(vol, i, j, k, (double)i - 1.5);
    iso_vol_update_stats(vol);
    iso_error err;
    iso_tree *tree = surface_build(vol);
    iso_extract_params p = {.level = 0, .tolerance = 1, .space = ISO_SPACE_INDEX, .threads = 1,
                            .coarsen = ISO_COARSEN_ALL};
    iso_mesh m;
    iso_mesh_init(&m);
    iso_extract_stats st = {0};
    for (int stride = 2; stride >= 1 && !check_failed(); stride--) {
        uint8_t plan[4 * 4 * 4] = {0};
        plan[0] = (uint8_t)stride;
        memset(&st, 0, sizeof st);
        CHECK_OK(iso_lod_extract_planned(tree, &p, plan, NULL, &m, &st, &err), &err);
        CHECK_EQ(m.triangle_count, 492);
        CHECK_EQ(m.vertex_count, 277);
        CHECK_EQ(st.nodes_polygonized, 1);
    }
    for (size_t v = 0; v < m.vertex_count; v++)
        CHECKF(m.positions[3 * v] == 1.5f, "vertex %zu at x = %g", v, (double)m.positions[3 * v]);
    iso_census c;
    CHECK_OK(iso_census_compute(vol, &m, ISO_SPACE_INDEX, &c, &err), &err);
    CHECK(c.open_edges == 0 && c.nonmanifold_edges == 0 && c.misoriented_edges == 0 && c.degenerate_triangles == 0);
    /* The area is the plane's, 16 x 16, whatever the triangulation. */
    CHECK_NEAR(iso_mesh_area(&m), 256.0, 1e-3);
    /* The fit is exact everywhere, so the tolerance's own plan takes every brick at stride
     * 8 whole: one cell for each of the 4 bricks with x < 8 that the level crosses, two
     * triangles each, transition cells nowhere. */
    p.tolerance = 0.25;
    iso_mesh_clear(&m);
    CHECK_OK(iso_extract(tree, &p, &m, &st, &err), &err);
    CHECK_EQ(st.cells_visited, 4);
    CHECK_EQ(st.triangles, 4 * 2);
    iso_mesh_free(&m);
    iso_tree_destroy(tree);
    iso_vol_destroy(vol);
}

/* 1 if the samples block a shares with its face or edge neighbour a + delta lie on both
 * sides of level (blocks of ISO_TREE_BLOCK cells, clipped by the border). */
static int shared_set_crosses(const iso_volume *vol, const size_t a[3], const int delta[3], double level)
{
    size_t lo[3], hi[3];
    for (int d = 0; d < 3; d++) {
        size_t first = a[d] * ISO_TREE_BLOCK, last = first + ISO_TREE_BLOCK < vol->dims[d] - 1 ? first + ISO_TREE_BLOCK : vol->dims[d] - 1;
        lo[d] = delta[d] > 0 ? last : first;
        hi[d] = delta[d] < 0 ? first : last;
    }
    int above = 0, below = 0;
    for (size_t k = lo[2]; k <= hi[2]; k++)
        for (size_t j = lo[1]; j <= hi[1]; j++)
            for (size_t i = lo[0]; i <= hi[0]; i++) {
                int in = iso_vol_get(vol, i, j, k) > level;
                above |= in;
                below |= !in;
            }
    return above && below;
}

/* The pairs of face or edge neighbours in a plan (log2 strides per block) more than one
 * stride apart across a set the level crosses: 0 once the kernel has balanced it. */
static size_t unbalanced_pairs(const iso_volume *vol, const uint8_t *plan, double level)
{
    size_t n[3], pairs = 0;
    for (int d = 0; d < 3; d++)
        n[d] = (vol->dims[d] - 1 + ISO_TREE_BLOCK - 1) / ISO_TREE_BLOCK;
    for (size_t z = 0; z < n[2]; z++)
        for (size_t y = 0; y < n[1]; y++)
            for (size_t x = 0; x < n[0]; x++)
                for (int dz = -1; dz <= 1; dz++)
                    for (int dy = -1; dy <= 1; dy++)
                        for (int dx = -1; dx <= 1; dx++) {
                            int off = (dx != 0) + (dy != 0) + (dz != 0);
                            size_t q[3] = {x + (size_t)dx, y + (size_t)dy, z + (size_t)dz};
                            if (off == 0 || off == 3 || q[0] >= n[0] || q[1] >= n[1] || q[2] >= n[2])
                                continue;
                            size_t a[3] = {x, y, z};
                            const int delta[3] = {dx, dy, dz};
                            int sa = plan[(z * n[1] + y) * n[0] + x], sb = plan[(q[2] * n[1] + q[1]) * n[0] + q[0]];
                            if (sa > sb + 1 && shared_set_crosses(vol, a, delta, level))
                                pairs++;
                        }
    return pairs;
}

/* Each brick's blocks from the tolerance's own plan: one rough block of a brick at stride
 * 1 keeps it from stride 8, and its seven smooth blocks take stride 4. Field: the plane
 * f = 0.5x + 0.3y + 0.2z, with noise only on the samples strictly inside block (1, 1, 1)
 * (5..7 per axis), at level 6.1, which crosses 6 of the 8 bricks. The kernel's balance then
 * refines what shares a crossed face or edge with the rough block to stride 2 (a stride-8
 * brick there gives up stride 8), and so on until no crossed set joins strides more than
 * one apart; the rough block stays the only one at stride 1. The vertex bound holds and
 * the mesh is sound, capped and not. */
static void test_rough_block_keeps_only_itself_fine(void)
{
    iso_volume *vol = surface_make_volume(17, 17, 17, ISO_F32);
    for (size_t k = 0; k < 17; k++)
        for (size_t j = 0; j < 17; j++)
            for (size_t i = 0; i < 17; i++) {
                int rough = i >= 5 && i <= 7 && j >= 5 && j <= 7 && k >= 5 && k <= 7;
                iso_vol_set(vol, i, j, k, 0.5 * (double)i + 0.3 * (double)j + 0.2 * (double)k + (rough ? 2 * (surface_uniform() - 0.5) : 0));
            }
    iso_vol_update_stats(vol);
    iso_tree *tree = surface_build(vol);
    /* Block (1, 1, 1) is brick 0's block 7; its 7 other blocks are exact at stride 4 up to
     * the float rounding of the samples. */
    double rough = iso_tree_block_error(tree, 0, 7, 1);
    CHECKF(rough > 0.1, "the rough block's stride-2 error %g", rough);
    CHECK(iso_tree_level_error(tree, 0) > 0.05);
    for (int b = 0; b < 7; b++)
        CHECK(iso_tree_block_error(tree, 0, b, 2) < 1e-3);
    iso_mesh m;
    iso_mesh_init(&m);
    iso_extract_stats st;
    for (int cap = 0; cap < 2; cap++) {
        extract(tree, 6.1, 0.05, cap, ISO_SPACE_INDEX, &m, &st);
        check_sound(vol, &m, &st, 6.1, 0.05, cap, "rough block");
        CHECKF(st.error_bound <= 0.05, "bound %g", st.error_bound);
    }
    /* The plan before and after the balance (64 blocks, 4 per axis). */
    uint8_t planned[64], balanced[64];
    CHECK(iso_lod_plan(tree, 6.1, 0.05, planned) == 0);
    for (int k = 0; k < 8; k++) {
        size_t b = (size_t)(k >> 2) * 16 + (size_t)(k >> 1 & 1) * 4 + (size_t)(k & 1);
        CHECK_EQ(planned[b], k == 7 ? 0 : 2);
    }
    iso_extract_params p = {.level = 6.1, .tolerance = 0.05, .space = ISO_SPACE_INDEX, .threads = 1,
                            .coarsen = ISO_COARSEN_ALL};
    iso_error err;
    CHECK_OK(iso_lod_extract_planned(tree, &p, planned, balanced, &m, &st, &err), &err);
    size_t fine = 0, refined = 0;
    for (size_t b = 0; b < 64; b++) {
        fine += balanced[b] == 0;
        refined += balanced[b] < planned[b];
    }
    CHECK_EQ(fine, 1);
    CHECK_EQ(balanced[16 + 4 + 1], 0);
    CHECKF(refined > 0, "the rough block refined nothing around it");
    CHECK_EQ(unbalanced_pairs(vol, planned, 6.1) > 0, 1);
    CHECK_EQ(unbalanced_pairs(vol, balanced, 6.1), 0);
    iso_mesh_free(&m);
    iso_tree_destroy(tree);
    iso_vol_destroy(vol);
}

/* ---- transition cells, every configuration ---- */

/* Blocks per axis of vol (tree.h: ISO_TREE_BLOCK cells each, the last clipped). */
static size_t blocks_along(const iso_volume *vol, int d)
{
    return (vol->dims[d] - 1 + ISO_TREE_BLOCK - 1) / ISO_TREE_BLOCK;
}

/* A plan per block from one per brick: every block of a brick takes the brick's stride. */
static void blocks_from_bricks(const iso_volume *vol, const uint8_t *brick_plan, uint8_t *plan)
{
    size_t n[3], bricks[3];
    for (int d = 0; d < 3; d++) {
        n[d] = blocks_along(vol, d);
        bricks[d] = (vol->dims[d] - 2) / ISO_BRICK_CELLS + 1;
    }
    for (size_t z = 0; z < n[2]; z++)
        for (size_t y = 0; y < n[1]; y++)
            for (size_t x = 0; x < n[0]; x++)
                plan[(z * n[1] + y) * n[0] + x] = brick_plan[((z / 2) * bricks[1] + y / 2) * bricks[0] + x / 2];
}

/* A random plan per block: a brick at stride 8 whole one time in four, else each of its
 * blocks at stride 1, 2 or 4. */
static void random_block_plan(const iso_volume *vol, uint8_t *plan)
{
    size_t n[3], bricks[3];
    for (int d = 0; d < 3; d++) {
        n[d] = blocks_along(vol, d);
        bricks[d] = (vol->dims[d] - 2) / ISO_BRICK_CELLS + 1;
    }
    uint8_t whole[64];
    for (size_t b = 0; b < bricks[0] * bricks[1] * bricks[2] && b < sizeof whole; b++)
        whole[b] = surface_uniform() < 0.25;
    for (size_t z = 0; z < n[2]; z++)
        for (size_t y = 0; y < n[1]; y++)
            for (size_t x = 0; x < n[0]; x++) {
                size_t b = ((z / 2) * bricks[1] + y / 2) * bricks[0] + x / 2;
                plan[(z * n[1] + y) * n[0] + x] = whole[b] ? 3 : (uint8_t)(surface_uniform() * 3);
            }
}

/* The mesh of a forced plan (one log2 stride per block, tree.h), checked for cracks, folds
 * and zero-area triangles: any plan must be watertight. */
static void check_plan(iso_volume *vol, const uint8_t *shift, int cap, const char *what, size_t *triangles)
{
    iso_error err;
    iso_tree *tree;
    CHECK_OK(iso_tree_build(vol, 1, NULL, NULL, &tree, &err), &err);
    if (!tree)
        return;
    iso_extract_params p = {.level = 0, .tolerance = 1, .cap = cap, .space = ISO_SPACE_INDEX,
                            .coarsen = ISO_COARSEN_ALL};
    iso_mesh m;
    iso_mesh_init(&m);
    iso_extract_stats st = {0};
    CHECK_OK(iso_lod_extract_planned(tree, &p, shift, NULL, &m, &st, &err), &err);
    iso_census c;
    CHECK_OK(iso_census_compute(vol, &m, ISO_SPACE_INDEX, &c, &err), &err);
    CHECKF(c.open_edges == 0 && c.nonmanifold_edges == 0 && c.misoriented_edges == 0 &&
               c.degenerate_triangles == 0,
           "%s: open %zu, non-manifold %zu, misoriented %zu, degenerate %zu", what, c.open_edges,
           c.nonmanifold_edges, c.misoriented_edges, c.degenerate_triangles);
    *triangles += m.triangle_count;
    iso_mesh_free(&m);
    iso_tree_destroy(tree);
}

/* A value on the given side of level 0, never on it. */
static double side_value(int inside)
{
    double u = 0.3 + 0.7 * surface_uniform();
    return inside ? u : -u;
}

/* A stride-2 cell against a stride-1 brick: its 13 samples (the 3 x 3 fine face and the 4
 * far corners), in all 2^13 patterns, uncapped and capped; everything else below the
 * level. The face sits in the plane x = 8 between brick 0 (stride 2) and brick 1
 * (stride 1), the cell in the corner where two faces are the volume's border. */
static void test_transition_cell_every_pattern(void)
{
    iso_volume *vol = surface_make_volume(17, 9, 9, ISO_F32);
    static const uint8_t bricks[2] = {1, 0};
    uint8_t plan[4 * 2 * 2];
    blocks_from_bricks(vol, bricks, plan);
    size_t triangles = 0;
    for (unsigned pattern = 0; pattern < (1u << 13) && !check_failed(); pattern++) {
        for (size_t k = 0; k < 9; k++)
            for (size_t j = 0; j < 9; j++)
                for (size_t i = 0; i < 17; i++)
                    iso_vol_set(vol, i, j, k, -1);
        for (int b = 0; b < 9; b++)
            iso_vol_set(vol, 8, (size_t)(b % 3), (size_t)(b / 3), side_value((pattern >> b) & 1));
        for (int b = 0; b < 4; b++)
            iso_vol_set(vol, 6, (size_t)(2 * (b & 1)), (size_t)(b & 2), side_value((pattern >> (9 + b)) & 1));
        iso_vol_update_stats(vol);
        char what[64];
        snprintf(what, sizeof what, "pattern %u", pattern);
        check_plan(vol, plan, (int)(pattern & 1), what, &triangles);
    }
    printf("  info: 8192 patterns of a 2:1 transition cell, %zu triangles\n", triangles);
    CHECK(triangles > 8192);
    iso_vol_destroy(vol);
}

/* Random plans (strides 1, 2, 4 per block, 8 per brick, so faces, edges and corners
 * between any two, inside a brick and across bricks) on random fields, uncapped and
 * capped: 4 x 2 x 2 bricks, 8 x 4 x 3 blocks, the far ones clipped. */
static void test_random_plans(void)
{
    iso_volume *vol = surface_make_volume(31, 17, 12, ISO_F32);
    uint8_t plan[8 * 4 * 3];
    size_t triangles = 0;
    for (int trial = 0; trial < 300 && !check_failed(); trial++) {
        double w[3] = {0.2 + surface_uniform(), 0.2 + surface_uniform(), 0.2 + surface_uniform()};
        for (size_t k = 0; k < 12; k++)
            for (size_t j = 0; j < 17; j++)
                for (size_t i = 0; i < 31; i++) {
                    double v = sin(w[0] * (double)i) + cos(w[1] * (double)j) + sin(w[2] * (double)k + 1);
                    iso_vol_set(vol, i, j, k, v + (trial % 3 == 0 ? surface_uniform() - 0.5 : 0) + 0.01234);
                }
        iso_vol_update_stats(vol);
        random_block_plan(vol, plan);
        char what[64];
        snprintf(what, sizeof what, "random plan %d", trial);
        check_plan(vol, plan, trial & 1, what, &triangles);
    }
    printf("  info: 300 random plans, %zu triangles\n", triangles);
    CHECK(triangles > 300);
    iso_vol_destroy(vol);
}

/* Random plans on random shapes: dims 2 to 27 per axis, so bricks clipped to one block,
 * blocks of one to three cells and one-cell bricks at the far ends, random fields (noisy
 * on every other trial), uncapped and capped. */
static void test_random_plans_on_random_shapes(void)
{
    size_t triangles = 0;
    uint8_t plan[7 * 7 * 7];
    for (int trial = 0; trial < 200 && !check_failed(); trial++) {
        size_t n[3];
        for (int d = 0; d < 3; d++)
            n[d] = 2 + (size_t)(surface_uniform() * 26);
        iso_volume *vol = surface_make_volume(n[0], n[1], n[2], ISO_F32);
        double w[3] = {0.2 + surface_uniform(), 0.2 + surface_uniform(), 0.2 + surface_uniform()};
        for (size_t k = 0; k < n[2]; k++)
            for (size_t j = 0; j < n[1]; j++)
                for (size_t i = 0; i < n[0]; i++) {
                    double v = sin(w[0] * (double)i) + cos(w[1] * (double)j) + sin(w[2] * (double)k + 1);
                    iso_vol_set(vol, i, j, k, v + (trial % 2 ? surface_uniform() - 0.5 : 0) + 0.01234);
                }
        iso_vol_update_stats(vol);
        random_block_plan(vol, plan);
        char what[64];
        snprintf(what, sizeof what, "random shape %zux%zux%zu, plan %d", n[0], n[1], n[2], trial);
        check_plan(vol, plan, trial % 3 == 0, what, &triangles);
        iso_vol_destroy(vol);
    }
    printf("  info: 200 random plans on random shapes, %zu triangles\n", triangles);
    CHECK(triangles > 200);
}

/* A trilinear field, f = (x - 7.3)(y - 5.6)(z - 4.1) + 0.37 x, under random plans: every
 * coarse grid reproduces it exactly (level errors 0), so the data's interpolant is f
 * itself, linear along every lattice edge. Every vertex lies on a lattice edge (at most one
 * coordinate off the integers: transition cells add no vertex inside a cell), and so on the
 * level to within the reported bound and the float rounding of its position, on a
 * watertight mesh. */
static double trilinear_field(double x, double y, double z)
{
    return (x - 7.3) * (y - 5.6) * (z - 4.1) + 0.37 * x;
}

static void test_vertices_on_lattice_edges(void)
{
    iso_volume *vol = surface_make_volume(31, 17, 12, ISO_F64);
    for (size_t k = 0; k < 12; k++)
        for (size_t j = 0; j < 17; j++)
            for (size_t i = 0; i < 31; i++)
                iso_vol_set(vol, i, j, k, trilinear_field((double)i, (double)j, (double)k));
    iso_vol_update_stats(vol);
    iso_error err;
    iso_tree *tree;
    CHECK_OK(iso_tree_build(vol, 1, NULL, NULL, &tree, &err), &err);
    uint8_t plan[8 * 4 * 3];
    size_t on_edges = 0, inside = 0;
    double worst = 0, slack = surface_rounding_slack(vol);
    for (int trial = 0; trial < 400 && tree && !check_failed(); trial++) {
        random_block_plan(vol, plan);
        double level = vol->value_min + (vol->value_max - vol->value_min) * (0.3 + 0.4 * surface_uniform());
        iso_extract_params p = {.level = level, .tolerance = 1, .cap = trial & 1, .space = ISO_SPACE_INDEX,
                                .coarsen = ISO_COARSEN_ALL};
        iso_mesh m;
        iso_mesh_init(&m);
        iso_extract_stats st = {0};
        CHECK_OK(iso_lod_extract_planned(tree, &p, plan, NULL, &m, &st, &err), &err);
        char what[64];
        snprintf(what, sizeof what, "trilinear plan %d", trial);
        check_sound(vol, &m, &st, level, st.error_bound, 0, what);
        for (size_t v = 0; v < m.vertex_count; v++) {
            const float *x = m.positions + 3 * v;
            int outside = 0; /* a cap's vertex, toward the virtual layer */
            for (int d = 0; d < 3; d++)
                outside |= x[d] < 0 || x[d] > (float)(vol->dims[d] - 1);
            if (outside)
                continue;
            int off = (x[0] != floorf(x[0])) + (x[1] != floorf(x[1])) + (x[2] != floorf(x[2]));
            inside += off > 1;
            on_edges += off == 1;
            /* Beyond the bound the extraction reports: its measured worst, which holds the
             * gap a crossing keeps from a sample on the level (mc.h). */
            worst = fmax(worst, fabs(trilinear_field(x[0], x[1], x[2]) - level) - st.error_bound);
        }
        iso_mesh_free(&m);
    }
    printf("  info: 400 plans on a trilinear field, %zu vertices on lattice edges, largest |f - level| past the bound %.3g "
           "(slack %.3g)\n",
           on_edges, worst, slack);
    CHECK_EQ(inside, 0);
    CHECK(on_edges > 1000);
    CHECKF(worst <= slack, "a vertex off the level by %g", worst);
    iso_tree_destroy(tree);
    iso_vol_destroy(vol);
}

/* ---- property test ---- */

/* A few Gaussian blobs over a tilted ramp, optionally rounded to integers (ties). */
static iso_volume *random_field(int integer, double *lo, double *hi)
{
    size_t n[3];
    for (int d = 0; d < 3; d++)
        n[d] = 4 + (size_t)(surface_uniform() * 21);
    iso_volume *vol = surface_make_volume(n[0], n[1], n[2], integer ? ISO_I16 : ISO_F32);
    double centre[4][3], width[4], weight[4], tilt[3];
    for (int b = 0; b < 4; b++) {
        for (int d = 0; d < 3; d++)
            centre[b][d] = surface_uniform() * (double)n[d];
        width[b] = 1.5 + surface_uniform() * 6;
        weight[b] = (surface_uniform() - 0.3) * 100;
    }
    for (int d = 0; d < 3; d++)
        tilt[d] = (surface_uniform() - 0.5) * 4;
    double noise = surface_uniform() < 0.3 ? 20 : 0;
    for (size_t k = 0; k < n[2]; k++)
        for (size_t j = 0; j < n[1]; j++)
            for (size_t i = 0; i < n[0]; i++) {
                double p[3] = {(double)i, (double)j, (double)k}, v = 0;
                for (int d = 0; d < 3; d++)
                    v += tilt[d] * p[d];
                for (int b = 0; b < 4; b++) {
                    double r2 = 0;
                    for (int d = 0; d < 3; d++)
                        r2 += (p[d] - centre[b][d]) * (p[d] - centre[b][d]);
                    v += weight[b] * exp(-r2 / (width[b] * width[b]));
                }
                v += noise * (surface_uniform() - 0.5);
                iso_vol_set(vol, i, j, k, integer ? round(v) : v);
            }
    iso_vol_update_stats(vol);
    *lo = vol->value_min;
    *hi = vol->value_max;
    return vol;
}

static void check_levels(const iso_volume *vol, const double *levels, int level_count, totals *t,
                         const char *what)
{
    static const double shares[] = {0, 0.005, 0.02, 0.1, 0.4, 1};
    iso_tree *tree = surface_build(vol);
    iso_mesh m;
    iso_mesh_init(&m);
    double range = vol->value_max - vol->value_min;
    for (int l = 0; l < level_count && !check_failed(); l++)
        for (int s = 0; s < 6 && !check_failed(); s++) {
            double tolerance = shares[s] * range;
            int cap = (t->cases & 1) != 0;
            iso_extract_stats st;
            extract(tree, levels[l], tolerance, cap, ISO_SPACE_INDEX, &m, &st);
            check_sound(vol, &m, &st, levels[l], tolerance, cap, what);
            t->cases++;
            t->coarse_bricks += st.nodes_polygonized;
            t->coarse_cases += st.nodes_polygonized > 0;
            if (cap && m.triangle_count)
                t->capped_closed++;
        }
    iso_mesh_free(&m);
    iso_tree_destroy(tree);
}

static void test_random_fields_property(void)
{
    totals t = {0};
    for (int trial = 0; trial < 80 && !check_failed(); trial++) {
        double lo, hi;
        int integer = trial % 3 == 2;
        iso_volume *vol = random_field(integer, &lo, &hi);
        double levels[2];
        for (int l = 0; l < 2; l++) {
            levels[l] = lo + (0.1 + 0.8 * surface_uniform()) * (hi - lo);
            if (integer)
                levels[l] = round(levels[l]); /* samples on the level: ties */
        }
        check_levels(vol, levels, 2, &t, integer ? "integer field" : "random field");
        iso_vol_destroy(vol);
    }
    printf("  info: %zu random cases, %zu with coarse bricks (%zu in all), %zu capped closed\n", t.cases,
           t.coarse_cases, t.coarse_bricks, t.capped_closed);
    CHECK(t.cases >= 900);
    CHECK(t.coarse_cases > t.cases / 4); /* a sixth are tolerance 0; clipped bricks stay fine */
}

static void test_analytic_fields_property(void)
{
    static const struct {
        const char *name;
        double levels[4];
    } fields[] = {{"field:sphere:40", {0.5, 5, 12.25, 18}},
                  {"field:torus:48", {-3, 0, 2.5, 5}},
                  {"field:ml:40", {0.2, 0.5, 0.7, 0.9}},
                  {"field:ijk:24", {10, 500.5, 3000, 9000}}};
    totals t = {0};
    for (size_t f = 0; f < sizeof fields / sizeof fields[0]; f++) {
        iso_volume *vol = NULL;
        iso_error err;
        CHECK_OK(iso_load(fields[f].name, NULL, &vol, &err), &err);
        if (!vol)
            continue;
        iso_vol_update_stats(vol);
        check_levels(vol, fields[f].levels, 4, &t, fields[f].name);
        iso_vol_destroy(vol);
    }
    printf("  info: %zu analytic cases, %zu with coarse bricks (%zu in all)\n", t.cases, t.coarse_cases, t.coarse_bricks);
    CHECK(t.coarse_cases > t.cases / 2);
}

/* ---- real scans ---- */

static iso_volume *load_or_skip(const char *path)
{
    if (!iso_load_recognises(path) || access(path, R_OK) != 0) {
        check_skip("%s is not here", path);
        return NULL;
    }
    iso_volume *vol = NULL;
    iso_error err;
    CHECK_OK(iso_load(path, NULL, &vol, &err), &err);
    return vol;
}

static void check_scan(const char *path, const double *levels, int level_count)
{
    static const double tolerances[] = {0, 5, 20, 100, 400};
    iso_volume *vol = load_or_skip(path);
    if (!vol)
        return;
    iso_tree *tree = surface_build(vol);
    iso_mesh m;
    iso_mesh_init(&m);
    for (int l = 0; l < level_count; l++) {
        size_t exact = 0;
        for (int t = 0; t < 5 && !check_failed(); t++) {
            iso_extract_stats st;
            extract(tree, levels[l], tolerances[t], 0, ISO_SPACE_INDEX, &m, &st);
            check_sound(vol, &m, &st, levels[l], tolerances[t], 0, path);
            if (t == 0)
                exact = st.triangles;
            /* A tolerance costs accuracy, not triangles: a brick whose coarse level barely
             * fits may give its transition cells a few more triangles than its data cells
             * would, never a thousandth of the mesh. */
            CHECKF(st.triangles <= exact + exact / 1000, "%s level %g tol %g: %zu triangles, exact %zu", path,
                   levels[l], tolerances[t], st.triangles, exact);
            printf("  info: %s level %g tol %g: %zu triangles, %zu coarse bricks, bound %.3g\n",
                   strrchr(path, '/') + 1, levels[l], tolerances[t], st.triangles,
                   st.nodes_polygonized, st.error_bound);
        }
    }
    iso_mesh_free(&m);
    iso_tree_destroy(tree);
    iso_vol_destroy(vol);
}

static void test_mricron_brain(void)
{
    static const double levels[] = {30, 60};
    check_scan(MRICRON_CH2BET, levels, 2);
}

static void test_shared_scans(void)
{
    const char *dir = check_shared_volumes();
    if (!dir) {
        check_skip("needs ../shared/volumes");
        return;
    }
    static const struct {
        const char *file;
        double levels[2];
        int count;
    } scans[] = {{"CThead_256x256x113_u16be.nhdr", {700, 1500}, 2},
                 {"cranium_256x256x108_i16le.nhdr", {-142, 300}, 2},
                 {"ch2bet_181x217x181_u8.nhdr", {30, 0}, 1},
                 {"engine_256x256x128_u8.nhdr", {80, 0}, 1}};
    for (size_t s = 0; s < sizeof scans / sizeof scans[0] && !check_failed(); s++) {
        char path[1024];
        snprintf(path, sizeof path, "%s/%s", dir, scans[s].file);
        check_scan(path, scans[s].levels, scans[s].count);
    }
}

/* InVesalius' own surfaces of this CT enclose 3,161,711 mm^3 (skin, -142 HU) and 657,706
 * mm^3 (bone, 226 HU); voxel counts agree within 1%. Capped, at tolerance 0, within 2%. */
static void test_cranium_enclosed_volumes(void)
{
    const char *dir = check_shared_volumes();
    if (!dir) {
        check_skip("needs ../shared/volumes");
        return;
    }
    char path[1024];
    snprintf(path, sizeof path, "%s/cranium_256x256x108_i16le.nhdr", dir);
    iso_volume *vol = load_or_skip(path);
    if (!vol)
        return;
    iso_tree *tree = surface_build(vol);
    static const double levels[] = {-142, 226}, expected[] = {3161711, 657706};
    iso_mesh m;
    iso_mesh_init(&m);
    for (int l = 0; l < 2; l++) {
        iso_extract_stats st;
        extract(tree, levels[l], 0, 1, ISO_SPACE_WORLD, &m, &st);
        iso_census c;
        iso_error err;
        CHECK_OK(iso_census_compute(vol, &m, ISO_SPACE_WORLD, &c, &err), &err);
        CHECKF(c.closed, "level %g: open %zu, border %zu, non-manifold %zu", levels[l], c.open_edges,
               c.boundary_edges, c.nonmanifold_edges);
        double enclosed = fabs(iso_mesh_enclosed_volume(&m));
        printf("  info: cranium level %g capped: %.0f mm^3 enclosed, InVesalius %.0f (%+.2f%%)\n",
               levels[l], enclosed, expected[l], 100 * (enclosed - expected[l]) / expected[l]);
        CHECKF(fabs(enclosed - expected[l]) <= 0.02 * expected[l], "level %g: %.0f mm^3", levels[l], enclosed);
    }
    iso_mesh_free(&m);
    iso_tree_destroy(tree);
    iso_vol_destroy(vol);
}

int main(void)
{
    CHECK_RUN(test_plane_is_one_coarse_cell);
    CHECK_RUN(test_coarse_bricks_meet_cells);
    CHECK_RUN(test_one_coarse_block_among_fine_ones);
    CHECK_RUN(test_rough_block_keeps_only_itself_fine);
    CHECK_RUN(test_transition_cell_every_pattern);
    CHECK_RUN(test_random_plans);
    CHECK_RUN(test_random_plans_on_random_shapes);
    CHECK_RUN(test_vertices_on_lattice_edges);
    CHECK_RUN(test_random_fields_property);
    CHECK_RUN(test_analytic_fields_property);
    CHECK_RUN(test_mricron_brain);
    CHECK_RUN(test_shared_scans);
    CHECK_RUN(test_cranium_enclosed_volumes);
    return check_finish();
}
