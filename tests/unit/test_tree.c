/* test_tree.c: the hierarchy's nodes as the build computes them (deepest first, the
 * errors above bricks by a branch and bound over the bricks below) against a scan of each
 * node's whole box (iso_tree_scan_box), rounded as the build rounds: min, max and error
 * must agree bit for bit, and the brick grid with iso_bricks_build's, on random data of every voxel type in boxes clipped by odd
 * dimensions, on smooth and on constant data (where every bound ties), on floats with NaN,
 * infinities and huge magnitudes, on one and on two threads, and on the shared CThead. */
#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "check.h"
#include "surface.h"

/* Every node against a scan of its box. The boxes in breadth-first order (tree.h): a
 * node that is not a brick appends its two children. */
static void check_nodes_match_scans(const iso_volume *vol, const iso_tree *tree)
{
    iso_box *boxes = malloc(tree->node_count * sizeof *boxes);
    CHECK(boxes != NULL);
    if (!boxes)
        return;
    boxes[0] = iso_box_root(vol);
    size_t wrong = 0, laid = 1;
    for (size_t n = 0; n < tree->node_count; n++) {
        const iso_tree_node *node = &tree->nodes[n];
        if (!iso_box_is_brick(&boxes[n])) {
            CHECK(laid + 2 <= tree->node_count);
            if (laid + 2 > tree->node_count)
                break;
            iso_box_split(&boxes[n], &boxes[laid], &boxes[laid + 1]);
            laid += 2;
        }
        double mn, mx, er;
        iso_tree_scan_box(vol, &boxes[n], &mn, &mx, &er);
        float want_min = mn <= mx ? iso_float_down(mn) : INFINITY, want_max = mn <= mx ? iso_float_up(mx) : -INFINITY;
        float want_err = iso_float_up(er);
        if (memcmp(&want_min, &node->min, sizeof want_min) || memcmp(&want_max, &node->max, sizeof want_max) ||
            memcmp(&want_err, &node->err, sizeof want_err)) {
            if (!wrong++)
                CHECKF(0, "node %zu: min %g max %g err %g, its scan %g %g %g", n, (double)node->min,
                       (double)node->max, (double)node->err, (double)want_min, (double)want_max, (double)want_err);
        }
    }
    CHECKF(wrong == 0, "%zu of %zu nodes differ from their scans", wrong, tree->node_count);
    CHECK_EQ(laid, tree->node_count);
    free(boxes);
}

/* Built on one and on two threads: the same nodes, and each what its scan gives. */
static void check_volume(const iso_volume *vol)
{
    iso_tree *one, *two;
    iso_error err;
    CHECK_OK(iso_tree_build(vol, 1, NULL, NULL, &one, &err), &err);
    CHECK_OK(iso_tree_build(vol, 2, NULL, NULL, &two, &err), &err);
    if (check_failed())
        return;
    CHECK_EQ(one->node_count, two->node_count);
    CHECK(memcmp(one->nodes, two->nodes, iso_tree_bytes(one)) == 0);
    check_nodes_match_scans(vol, one);
    /* The brick grid, copied from the leaves for integer samples, is what its scan gives. */
    iso_bricks scanned;
    CHECK_OK(iso_bricks_build(vol, 1, &scanned, &err), &err);
    size_t n = iso_bricks_total(&scanned);
    CHECK_EQ(iso_bricks_total(&one->bricks), n);
    if (iso_bricks_total(&one->bricks) == n) {
        CHECK(memcmp(scanned.min, one->bricks.min, n * sizeof *scanned.min) == 0);
        CHECK(memcmp(scanned.max, one->bricks.max, n * sizeof *scanned.max) == 0);
    }
    iso_bricks_free(&scanned);
    iso_tree_destroy(one);
    iso_tree_destroy(two);
}

static size_t random_size(size_t lo, size_t span)
{
    return lo + (size_t)(surface_uniform() * (double)span);
}

static void test_random_data_of_every_type(void)
{
    static const iso_voxel_type types[] = {ISO_U8, ISO_I8, ISO_U16, ISO_I16, ISO_U32, ISO_I32, ISO_F32, ISO_F64};
    static const double spans[] = {255, 255, 65535, 65535, 4e9, 4e9, 1e6, 1e6};
    static const double lows[] = {0, -128, 0, -32768, 0, -2e9, -5e5, -5e5};
    for (size_t t = 0; t < sizeof types / sizeof types[0] && !check_failed(); t++)
        for (int trial = 0; trial < 3 && !check_failed(); trial++) {
            iso_volume *vol = surface_make_volume(random_size(2, 60), random_size(2, 50), random_size(2, 40), types[t]);
            /* Half the trials smooth with noise (bounds prune), half pure noise (they do not). */
            double noise = trial % 2 ? 1.0 : 0.02;
            for (size_t k = 0; k < vol->dims[2]; k++)
                for (size_t j = 0; j < vol->dims[1]; j++)
                    for (size_t i = 0; i < vol->dims[0]; i++) {
                        double smooth = 0.5 + 0.4 * sin(0.11 * (double)i) * cos(0.07 * (double)j + 0.05 * (double)k);
                        double u = (1 - noise) * smooth + noise * surface_uniform();
                        iso_vol_set(vol, i, j, k, floor(lows[t] + u * spans[t]));
                    }
            iso_vol_update_stats(vol);
            check_volume(vol);
            iso_vol_destroy(vol);
        }
}

static void test_constant_and_linear_data(void)
{
    iso_volume *vol = surface_make_volume(41, 33, 19, ISO_U16);
    for (size_t k = 0; k < 19; k++)
        for (size_t j = 0; j < 33; j++)
            for (size_t i = 0; i < 41; i++)
                iso_vol_set(vol, i, j, k, 700);
    iso_vol_update_stats(vol);
    check_volume(vol);
    for (size_t k = 0; k < 19; k++)
        for (size_t j = 0; j < 33; j++)
            for (size_t i = 0; i < 41; i++)
                iso_vol_set(vol, i, j, k, (double)(3 * i + 5 * j + 7 * k));
    iso_vol_update_stats(vol);
    check_volume(vol);
    iso_vol_destroy(vol);
}

/* NaN, infinities and magnitudes near FLT_MAX: the build scans where bounds cannot be
 * trusted, and must still give each node its scan's figures. */
static void test_floats_with_nan_infinity_and_huge_values(void)
{
    for (int trial = 0; trial < 4 && !check_failed(); trial++) {
        iso_volume *vol = surface_make_volume(random_size(9, 40), random_size(9, 40), random_size(9, 30), ISO_F32);
        for (size_t k = 0; k < vol->dims[2]; k++)
            for (size_t j = 0; j < vol->dims[1]; j++)
                for (size_t i = 0; i < vol->dims[0]; i++) {
                    double u = surface_uniform(), v = 100 * sin(0.2 * (double)(i + j + k));
                    if (u < 0.002)
                        v = NAN;
                    else if (u < 0.004 && trial >= 2)
                        v = u < 0.003 ? INFINITY : -INFINITY;
                    else if (trial == 3)
                        v *= 3e35;
                    iso_vol_set(vol, i, j, k, v);
                }
        iso_vol_update_stats(vol);
        check_volume(vol);
        iso_vol_destroy(vol);
    }
}

static void test_cthead_nodes_match_scans(void)
{
    iso_volume *vol = surface_load_shared("CThead_256x256x113_u16be.nhdr");
    if (!vol)
        return;
    check_volume(vol);
    iso_vol_destroy(vol);
}

int main(void)
{
    CHECK_RUN(test_random_data_of_every_type);
    CHECK_RUN(test_constant_and_linear_data);
    CHECK_RUN(test_floats_with_nan_infinity_and_huge_values);
    CHECK_RUN(test_cthead_nodes_match_scans);
    return check_finish();
}
