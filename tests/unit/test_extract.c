/* test_extract.c: the hierarchy and bounded extraction, on hand-built volumes with exact
 * answers (the paper's D1, D2, D3, a sphere, a torus), a brute-force check of Lemma 1 (the
 * fit error peaks at samples), and the guarantee on the paper's own CT head. */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

#include "mesh/mesh.h"
#include "check.h"
#include "surface.h"
#include "extract/extract.h"
#include "extract/lod.h"
#include "io/io.h"
#include "extract/mc.h"
#include "base/base.h"
#include "hierarchy/tree.h"
#include "volume/volume.h"

/* ---- helpers ---- */

static int extract(const iso_tree *tree, double level, double tolerance, iso_mesh *m,
                   iso_extract_stats *st)
{
    iso_extract_params p = {.level = level, .tolerance = tolerance, .space = ISO_SPACE_INDEX,
                            .coarsen = ISO_COARSEN_ALL};
    iso_error err;
    int rc = iso_extract(tree, &p, m, st, &err);
    CHECKF(rc == 0, "iso_extract(%g, %g): %s", level, tolerance, err.message);
    return rc;
}



/* ---- the marching cubes table ---- */

static void test_mc_table_shapes(void)
{
    const iso_mc_case *cs = iso_mc_cases();
    CHECK_EQ(cs[0].triangle_count, 0);
    CHECK_EQ(cs[255].triangle_count, 0);
    /* One corner cut off: one triangle; a whole face: a quad; every case: at most 12 edges. */
    for (int k = 0; k < 8; k++) {
        CHECK_EQ(cs[1u << k].triangle_count, 1);
        CHECK_EQ(cs[255u ^ (1u << k)].triangle_count, 1);
    }
    CHECK_EQ(cs[0x0F].triangle_count, 2); /* the z = 0 face inside */
    CHECK_EQ(cs[0x55].triangle_count, 2); /* the x = 0 face inside */
    for (int i = 0; i < 256; i++) {
        CHECK(cs[i].triangle_count <= 12);
        for (int t = 0; t < 3 * cs[i].triangle_count; t++)
            CHECK(cs[i].edges[t] < 12);
        /* Without an ambiguous face (two diagonal corners inside, two outside) a case and
         * its complement are the same surface, so they have as many triangles. */
        int ambiguous = 0;
        static const int faces[6][4] = {{0, 2, 6, 4}, {1, 3, 7, 5}, {0, 1, 5, 4},
                                        {2, 3, 7, 6}, {0, 1, 3, 2}, {4, 5, 7, 6}};
        for (int f = 0; f < 6; f++) {
            int a = (i >> faces[f][0]) & 1, b = (i >> faces[f][1]) & 1;
            int c = (i >> faces[f][2]) & 1, d = (i >> faces[f][3]) & 1;
            ambiguous |= a == c && b == d && a != b;
        }
        if (!ambiguous)
            CHECKF(cs[i].triangle_count == cs[255 - i].triangle_count, "case %d", i);
    }
}

static void test_mc_single_corner_winding(void)
{
    /* Corner 0 high: the triangle's normal must point away from it, toward (1,1,1). */
    double v[8] = {1, 0, 0, 0, 0, 0, 0, 0}, origin[3] = {0, 0, 0}, size[3] = {1, 1, 1};
    iso_mesh m;
    iso_mesh_init(&m);
    CHECK_EQ(iso_mc_cell(v, 0.5, origin, size, &m, NULL), 1);
    float *a = m.positions, *b = m.positions + 3, *c = m.positions + 6;
    double u[3] = {b[0] - a[0], b[1] - a[1], b[2] - a[2]}, w[3] = {c[0] - a[0], c[1] - a[1], c[2] - a[2]};
    double n[3] = {u[1] * w[2] - u[2] * w[1], u[2] * w[0] - u[0] * w[2], u[0] * w[1] - u[1] * w[0]};
    CHECK(n[0] > 0 && n[1] > 0 && n[2] > 0);
    for (int k = 0; k < 9; k++)
        CHECK(m.positions[k] == 0.0f || m.positions[k] == 0.5f);
    iso_mesh_free(&m);
}

/* Random fields: the welded full-scan surface is closed inside the volume, 2-manifold and
 * consistently oriented, which a table with inconsistent face rules would break. */
static void test_mc_random_fields_watertight(void)
{
    for (int trial = 0; trial < 40 && !check_failed(); trial++) {
        size_t n[3] = {3 + (size_t)(surface_uniform() * 9), 3 + (size_t)(surface_uniform() * 9), 3 + (size_t)(surface_uniform() * 9)};
        iso_volume *vol = surface_random_volume(n, ISO_F32, trial % 2);
        double level = trial % 2 ? 1.5 : 0.5;
        iso_mesh m;
        iso_mesh_init(&m);
        iso_error err;
        iso_extract_stats fs;
        CHECK_OK(iso_extract_full_scan(vol, level, ISO_SPACE_INDEX, &m, &fs, &err), &err);
        iso_mesh_edges e;
        CHECK_OK(iso_mesh_count_edges(&m, &e), &err);
        CHECK_EQ(e.nonmanifold, 0);
        CHECK_EQ(e.misoriented, 0);
        iso_census c;
        CHECK_OK(iso_census_compute(vol, &m, ISO_SPACE_INDEX, &c, &err), &err);
        CHECK_EQ(c.open_edges, 0);
        CHECK(surface_worst_vertex_error(vol, &m, level) <= fs.error_bound + surface_rounding_slack(vol));
        CHECK(fs.error_bound <= surface_tie_allowance(vol));
        iso_mesh_free(&m);
        iso_vol_destroy(vol);
    }
}

/* ---- Lemma 1, brute force ---- */

static void test_lemma1_fit_error_brute_force(void)
{
    for (int trial = 0; trial < 50 && !check_failed(); trial++) {
        iso_volume *vol = surface_make_volume(2 + (size_t)(surface_uniform() * 6), 2 + (size_t)(surface_uniform() * 6),
                                      2 + (size_t)(surface_uniform() * 6), ISO_F64);
        for (size_t k = 0; k < vol->dims[2]; k++)
            for (size_t j = 0; j < vol->dims[1]; j++)
                for (size_t i = 0; i < vol->dims[0]; i++)
                    iso_vol_set(vol, i, j, k, surface_uniform() * 10);
        iso_box box = iso_box_root(vol);
        double mn, mx, er, c[8];
        iso_tree_scan_box(vol, &box, &mn, &mx, &er);
        for (int k = 0; k < 8; k++)
            c[k] = iso_vol_get(vol, k & 1 ? box.hi[0] : 0, k & 2 ? box.hi[1] : 0, k & 4 ? box.hi[2] : 0);
        double seen = 0;
        for (int s = 0; s < 3000; s++) {
            float p[3];
            for (int d = 0; d < 3; d++)
                p[d] = (float)(surface_uniform() * (double)box.hi[d]);
            double t = iso_tri_eval(c, p[0] / box.hi[0], p[1] / box.hi[1], p[2] / box.hi[2]);
            double dev = fabs(surface_interpolate(vol, p) - t);
            CHECKF(dev <= er + 1e-9, "|f - T| = %g above the fit error %g", dev, er);
            if (dev > seen)
                seen = dev;
        }
        /* The maximum is attained at a sample, so the bound is exact there. */
        double at_samples = 0;
        for (size_t k = 0; k < vol->dims[2]; k++)
            for (size_t j = 0; j < vol->dims[1]; j++)
                for (size_t i = 0; i < vol->dims[0]; i++) {
                    double t = iso_tri_eval(c, (double)i / box.hi[0], (double)j / box.hi[1], (double)k / box.hi[2]);
                    double d = fabs(iso_vol_get(vol, i, j, k) - t);
                    if (d > at_samples) at_samples = d;
                }
        CHECK_NEAR(at_samples, er, 1e-12);
        iso_vol_destroy(vol);
    }
}

/* ---- the paper's D1, D2 and D3: nodes kept whole ---- */

static void test_d1_constant_is_one_node(void)
{
    iso_volume *vol = surface_make_volume(33, 40, 27, ISO_U8);
    for (size_t i = 0; i < iso_vol_count(vol); i++)
        ((uint8_t *)vol->data)[i] = 1;
    iso_vol_update_stats(vol);
    iso_tree *tree = surface_build(vol);
    iso_mesh m;
    iso_mesh_init(&m);
    iso_extract_stats st;
    for (int t = 0; t < 2; t++) {
        extract(tree, 0.5, t ? 10 : 0, &m, &st);
        CHECK_EQ(st.triangles, 0);
        CHECK_EQ(st.nodes_visited, 1);
        CHECK_EQ(st.cells_visited, 0);
    }
    iso_mesh_free(&m);
    iso_tree_destroy(tree);
    iso_vol_destroy(vol);
}

static void test_d2_spike_takes_log_steps(void)
{
    for (size_t w = 16; w <= 128 && !check_failed(); w *= 2) {
        iso_volume *vol = surface_make_volume(w, w, w, ISO_F32);
        for (size_t i = 0; i < iso_vol_count(vol); i++)
            ((float *)vol->data)[i] = 1;
        iso_vol_set(vol, 0, 0, 0, 0);
        iso_vol_update_stats(vol);
        iso_tree *tree = surface_build(vol);
        iso_mesh m;
        iso_mesh_init(&m);
        iso_extract_stats st;
        extract(tree, 0.5, 0.01, &m, &st);
        CHECK_EQ(st.triangles, 1);
        /* The one active brick: its spike's block at stride 1 (64 cells); the other seven
         * are constant (error 0, so the plan coarsens them), and the level crosses none
         * of them nor any set they share with the spike's block, so they are read at their
         * stride and pass by. Nothing else. */
        CHECK_EQ(st.cells_visited, 64);
        CHECK_EQ(st.nodes_polygonized, 0);
        /* Each stored level visits the active child and its inactive sibling: 2 per
         * halving; then the brick itself and the 6 sub-boxes of >= 8 cells around the
         * spike that the walk below it tries. */
        double halvings = 3 * log2((double)(w - 1));
        CHECKF(st.nodes_visited <= 2 * (size_t)ceil(halvings) + 1 + 1 + 6, "%zu nodes visited for W=%zu",
               st.nodes_visited, w);
        CHECK(surface_worst_vertex_error(vol, &m, 0.5) <= 1e-6);
        iso_mesh_free(&m);
        iso_tree_destroy(tree);
        iso_vol_destroy(vol);
    }
}

static void test_d3_ijk_is_one_trilinear(void)
{
    iso_volume *vol = surface_make_volume(33, 33, 33, ISO_F32);
    for (size_t k = 0; k < 33; k++)
        for (size_t j = 0; j < 33; j++)
            for (size_t i = 0; i < 33; i++)
                iso_vol_set(vol, i, j, k, (double)(i * j * k));
    iso_vol_update_stats(vol);
    iso_tree *tree = surface_build(vol);
    CHECKF(tree->nodes[0].err <= 1e-9 * vol->value_max, "root err %g", tree->nodes[0].err);
    iso_mesh m;
    iso_mesh_init(&m);
    iso_extract_stats st;
    /* ijk is trilinear, so every brick's coarsest level fits it exactly: each active brick
     * (4 x 4 x 4 whole bricks) is one cell, 8 wide. */
    extract(tree, 3000, 1000, &m, &st);
    const iso_bricks *g = &tree->bricks;
    size_t active = 0;
    for (size_t at = 0; at < iso_bricks_total(g); at++)
        active += g->min[at] <= 3000 && 3000 < g->max[at];
    CHECK(active > 0);
    CHECK_EQ(st.nodes_polygonized, active);
    CHECK_EQ(st.cells_visited, active);
    CHECK_EQ(st.fit_error, 0);
    CHECK(st.triangles > 0);
    CHECK(st.error_bound <= 1000);
    CHECKF(surface_worst_vertex_error(vol, &m, 3000) <= st.error_bound + surface_rounding_slack(vol),
           "vertex error %g, bound %g", surface_worst_vertex_error(vol, &m, 3000), st.error_bound);
    /* Tolerance 0 is marching cubes: the same surface as the full scan. */
    iso_mesh full;
    iso_mesh_init(&full);
    iso_extract_stats fs;
    iso_error err;
    extract(tree, 3000, 0, &m, &st);
    CHECK_OK(iso_extract_full_scan(vol, 3000, ISO_SPACE_INDEX, &full, &fs, &err), &err);
    CHECK_EQ(st.triangles, fs.triangles);
    CHECK_EQ(st.vertices, fs.vertices);
    iso_mesh_free(&full);
    iso_mesh_free(&m);
    iso_tree_destroy(tree);
    iso_vol_destroy(vol);
}

/* ---- analytic shapes ---- */

static iso_volume *sphere_volume(size_t n, double *radius_at_zero)
{
    iso_volume *vol = surface_make_volume(n, n + 3, n - 2, ISO_F32);
    double c[3] = {(n - 1) / 2.0, (n + 2) / 2.0, (n - 3) / 2.0}, r0 = (n - 3) / 2.0;
    for (size_t k = 0; k < vol->dims[2]; k++)
        for (size_t j = 0; j < vol->dims[1]; j++)
            for (size_t i = 0; i < vol->dims[0]; i++)
                iso_vol_set(vol, i, j, k, r0 - sqrt((i - c[0]) * (i - c[0]) + (j - c[1]) * (j - c[1]) + (k - c[2]) * (k - c[2])));
    iso_vol_update_stats(vol);
    *radius_at_zero = r0;
    return vol;
}

static void test_sphere_surface_is_bounded_and_closed(void)
{
    double r0;
    iso_volume *vol = sphere_volume(48, &r0);
    iso_tree *tree = surface_build(vol);
    double c[3] = {23.5, 25, 22.5}, level = 4; /* radius r0 - 4 = 18.5 */
    const double tolerances[] = {0, 0.05, 0.2, 1};
    size_t last_triangles = SIZE_MAX;
    for (int t = 0; t < 4; t++) {
        iso_mesh m;
        iso_mesh_init(&m);
        iso_extract_stats st;
        extract(tree, level, tolerances[t], &m, &st);
        double worst = 0;
        for (size_t v = 0; v < m.vertex_count; v++) {
            float *p = m.positions + 3 * v;
            double r = sqrt((p[0] - c[0]) * (p[0] - c[0]) + (p[1] - c[1]) * (p[1] - c[1]) + (p[2] - c[2]) * (p[2] - c[2]));
            if (fabs(r - (r0 - level)) > worst)
                worst = fabs(r - (r0 - level));
        }
        /* Linear interpolation of a distance field along a unit edge is off by at most
         * 1/(8r); a vertex within tolerance t of the level is within t of the sphere. */
        CHECKF(worst <= tolerances[t] + 1.0 / (8 * (r0 - level - 1)) + 1e-4, "t=%g: vertex %g off the sphere",
               tolerances[t], worst);
        CHECK(surface_worst_vertex_error(vol, &m, level) <= st.error_bound + surface_rounding_slack(vol));
        CHECK(st.error_bound <= tolerances[t]);
        CHECKF(st.triangles <= last_triangles, "t=%g: %zu triangles after %zu", tolerances[t],
               st.triangles, last_triangles);
        last_triangles = st.triangles;
        if (tolerances[t] == 0) {
            /* Exact surface: closed, oriented outward (higher values inside), volume right. */
            iso_mesh_edges e;
            CHECK(iso_mesh_count_edges(&m, &e) == 0);
            CHECK_EQ(e.open, 0);
            CHECK_EQ(e.nonmanifold, 0);
            CHECK_EQ(e.misoriented, 0);
            double r = r0 - level, exact = 4.0 / 3.0 * M_PI * r * r * r;
            CHECKF(fabs(iso_mesh_enclosed_volume(&m) - exact) < 0.01 * exact, "volume %g vs %g",
                   iso_mesh_enclosed_volume(&m), exact);
            CHECK_NEAR(iso_mesh_area(&m), 4 * M_PI * r * r, 0.01 * 4 * M_PI * r * r);
        }
        iso_mesh_free(&m);
    }
    iso_tree_destroy(tree);
    iso_vol_destroy(vol);
}

static void test_torus_surface_is_bounded(void)
{
    size_t n = 40;
    iso_volume *vol = surface_make_volume(n, n, n / 2, ISO_F64);
    double cx = (n - 1) / 2.0, cy = (n - 1) / 2.0, cz = (n / 2 - 1) / 2.0, ring = 12, tube = 5;
    for (size_t k = 0; k < vol->dims[2]; k++)
        for (size_t j = 0; j < n; j++)
            for (size_t i = 0; i < n; i++) {
                double q = sqrt((i - cx) * (i - cx) + (j - cy) * (j - cy)) - ring;
                iso_vol_set(vol, i, j, k, tube - sqrt(q * q + (k - cz) * (k - cz)));
            }
    iso_vol_update_stats(vol);
    iso_tree *tree = surface_build(vol);
    for (double t = 0; t <= 0.5; t += 0.25) {
        iso_mesh m;
        iso_mesh_init(&m);
        iso_extract_stats st;
        extract(tree, 0, t, &m, &st);
        CHECK(st.triangles > 100);
        double worst = 0;
        for (size_t v = 0; v < m.vertex_count; v++) {
            float *p = m.positions + 3 * v;
            double q = sqrt((p[0] - cx) * (p[0] - cx) + (p[1] - cy) * (p[1] - cy)) - ring;
            double d = fabs(sqrt(q * q + (p[2] - cz) * (p[2] - cz)) - tube);
            if (d > worst) worst = d;
        }
        CHECKF(worst <= t + 1.0 / (8 * (tube - 1)) + 1e-4, "t=%g: vertex %g off the torus", t, worst);
        if (t == 0) {
            iso_mesh_edges e;
            CHECK(iso_mesh_count_edges(&m, &e) == 0);
            CHECK_EQ(e.open + e.nonmanifold + e.misoriented, 0);
        }
        iso_mesh_free(&m);
    }
    iso_tree_destroy(tree);
    iso_vol_destroy(vol);
}

/* ---- the hierarchy file ---- */

static void test_tree_file_round_trip_and_refusals(void)
{
    double r0;
    iso_volume *vol = sphere_volume(30, &r0);
    iso_tree *tree = surface_build(vol), *back = NULL;
    char path[512];
    snprintf(path, sizeof path, "%s/sphere.isotree", check_temp_dir());
    iso_error err;
    CHECK_OK(iso_tree_save(tree, path, &err), &err);
    CHECK_OK(iso_tree_load(vol, path, &back, &err), &err);
    if (back) {
        CHECK_EQ(back->node_count, tree->node_count);
        CHECK(memcmp(back->nodes, tree->nodes, iso_tree_bytes(tree)) == 0);
        /* The level codes are saved after the nodes and read back to the same bytes, on the
         * same scale. */
        CHECK(memcmp(back->level_code, tree->level_code, iso_bricks_total(&tree->bricks) * ISO_TREE_CODES) == 0);
        CHECK(memcmp(&back->scale, &tree->scale, sizeof tree->scale) == 0);
        iso_tree_destroy(back);
    }
    FILE *f = fopen(path, "rb");
    long size = 0;
    char *bytes = NULL;
    if (f && fseek(f, 0, SEEK_END) == 0 && (size = ftell(f)) > 0 && fseek(f, 0, SEEK_SET) == 0) {
        bytes = malloc((size_t)size);
        CHECK(fread(bytes, 1, (size_t)size, f) == (size_t)size);
    }
    if (f)
        fclose(f);
    CHECK(bytes != NULL && size > 64);
    struct { const char *what; long offset; int flip; long keep; int code; } cases[] = {
        {"flipped node byte", 64 + 5, 1, 0, ISO_E_CORRUPT},
        {"flipped header byte", 20, 1, 0, ISO_E_CORRUPT},
        {"bad magic", 0, 1, 0, ISO_E_FORMAT},
        {"truncated nodes", 0, 0, 64 + (long)sizeof(iso_tree_node) * 3, ISO_E_CORRUPT},
        {"truncated header", 0, 0, 40, ISO_E_FORMAT},
    };
    char bad[560];
    snprintf(bad, sizeof bad, "%s/bad.isotree", check_temp_dir());
    for (size_t i = 0; bytes && i < sizeof cases / sizeof cases[0]; i++) {
        f = fopen(bad, "wb");
        long n = cases[i].keep ? cases[i].keep : size;
        bytes[cases[i].offset] ^= (char)(cases[i].flip ? 0x40 : 0);
        CHECK(f && fwrite(bytes, 1, (size_t)n, f) == (size_t)n);
        bytes[cases[i].offset] ^= (char)(cases[i].flip ? 0x40 : 0);
        if (f)
            fclose(f);
        back = NULL;
        int rc = iso_tree_load(vol, bad, &back, &err);
        CHECKF(rc == cases[i].code, "%s: got %d (%s)", cases[i].what, rc, rc ? err.message : "ok");
        CHECKF(rc == 0 || strstr(err.message, "bad.isotree"), "%s: message names the file: %s", cases[i].what, err.message);
        CHECK(back == NULL);
        iso_tree_destroy(back);
    }
    /* The same file against a volume whose samples changed is stale. */
    iso_vol_set(vol, 3, 4, 5, 99);
    CHECK(iso_tree_load(vol, path, &back, &err) == ISO_E_STALE);
    double r1;
    iso_volume *other = sphere_volume(31, &r1);
    CHECK(iso_tree_load(other, path, &back, &err) == ISO_E_STALE);
    CHECK(iso_tree_load(vol, "/nonexistent/x.isotree", &back, &err) == ISO_E_IO);
    free(bytes);
    iso_vol_destroy(other);
    iso_tree_destroy(tree);
    iso_vol_destroy(vol);
}

static void test_tree_is_small(void)
{
    double r0;
    iso_volume *vol = sphere_volume(100, &r0);
    iso_tree *tree = surface_build(vol);
    size_t volume_bytes = iso_vol_count(vol) * iso_vol_type_size(vol->type);
    CHECKF(iso_tree_memory(tree) * 10 < volume_bytes, "tree %zu bytes, volume %zu", iso_tree_memory(tree), volume_bytes);
    iso_tree_destroy(tree);
    iso_vol_destroy(vol);
}

/* ---- coarse bricks and transition cells ---- */

static void extract_threads(const iso_tree *tree, double level, double tolerance, int threads, iso_mesh *m,
                            iso_extract_stats *st)
{
    iso_extract_params p = {.level = level, .tolerance = tolerance, .space = ISO_SPACE_INDEX, .threads = threads,
                            .coarsen = ISO_COARSEN_ALL};
    iso_error err;
    CHECK_OK(iso_extract(tree, &p, m, st, &err), &err);
}


/* Coarse bricks and transition cells name every crossing by its lattice segment, so the
 * mesh comes out welded: welding again merges nothing, every vertex is used, every
 * interior edge has two triangles, and the bytes do not depend on the thread count. */
static void test_coarse_bricks_join_without_weld(void)
{
    static const char *fields[] = {"field:sphere:61x47x53", "field:torus:64x64x40", "field:ml:65x65x65",
                                   "field:ml:113x113x113"};
    static const double levels[] = {0.5, 0.5, 0.5, 0.5};
    for (int f = 0; f < 4 && !check_failed(); f++) {
        iso_volume *vol;
        iso_error err;
        CHECK_OK(iso_load(fields[f], NULL, &vol, &err), &err);
        iso_tree *tree = surface_build(vol);
        double range = tree->nodes[0].max - tree->nodes[0].min;
        size_t fanned = 0;
        for (double share = 0.005; share < 0.1; share *= 4) {
            iso_mesh one, two, five;
            iso_mesh_init(&one);
            iso_mesh_init(&two);
            iso_mesh_init(&five);
            iso_extract_stats st, st2, st5;
            extract_threads(tree, levels[f], share * range, 1, &one, &st);
            extract_threads(tree, levels[f], share * range, 2, &two, &st2);
            extract_threads(tree, levels[f], share * range, 5, &five, &st5);
            fanned += st.nodes_polygonized;
            CHECK_EQ(two.vertex_count, one.vertex_count);
            CHECK_EQ(five.triangle_count, one.triangle_count);
            CHECK(two.vertex_count == one.vertex_count &&
                  memcmp(two.positions, one.positions, 12 * one.vertex_count) == 0 &&
                  memcmp(five.indices, one.indices, 12 * one.triangle_count) == 0);
            CHECK_EQ(st2.nodes_polygonized, st.nodes_polygonized);
            size_t unused = surface_unused_vertices(&one);
            CHECKF(unused == 0, "%s tol %g: %zu unused vertices", fields[f], share * range, unused);
            size_t vertices = two.vertex_count, triangles = two.triangle_count;
            CHECK(iso_mesh_weld(&two) == 0);
            CHECKF(two.vertex_count == vertices && two.triangle_count == triangles,
                   "%s tol %g: welding merged %zu vertices", fields[f], share * range, vertices - two.vertex_count);
            iso_census c;
            CHECK_OK(iso_census_compute(vol, &one, ISO_SPACE_INDEX, &c, &err), &err);
            CHECKF(c.nonmanifold_edges == 0 && c.misoriented_edges == 0 && c.open_edges == 0,
                   "%s tol %g: %zu nonmanifold, %zu misoriented, %zu open inside", fields[f], share * range,
                   c.nonmanifold_edges, c.misoriented_edges, c.open_edges);
            iso_mesh_free(&one);
            iso_mesh_free(&two);
            iso_mesh_free(&five);
        }
        CHECKF(fanned > 0, "%s: no tolerance coarsened a brick", fields[f]);
        iso_tree_destroy(tree);
        iso_vol_destroy(vol);
    }
}

/* ---- the level errors ---- */

/* Lemma 1 over the cells of the stride grid on the box [lo, hi], each scanned in full
 * (iso_tree_scan_box), the last cell per axis narrower. */
static double box_level_error(const iso_volume *vol, const size_t lo[3], const size_t hi[3], uint32_t s)
{
    double want = 0;
    for (size_t z = lo[2]; z < hi[2]; z += s)
        for (size_t y = lo[1]; y < hi[1]; y += s)
            for (size_t x = lo[0]; x < hi[0]; x += s) {
                iso_box cell = {{(uint32_t)x, (uint32_t)y, (uint32_t)z},
                                {(uint32_t)(x + s < hi[0] ? x + s : hi[0]), (uint32_t)(y + s < hi[1] ? y + s : hi[1]),
                                 (uint32_t)(z + s < hi[2] ? z + s : hi[2])}};
                double mn, mx, er;
                iso_tree_scan_box(vol, &cell, &mn, &mx, &er);
                want = er == er && er > want ? er : (er == er ? want : INFINITY);
            }
    return want;
}

/* The code kept for an error: never below it, at most one step (2^(1/16)) above it, on
 * the scale of the root's range. */
static void check_code(const iso_tree *tree, double got, double want, int constant, const char *what)
{
    double range = (double)tree->nodes[0].max - (double)tree->nodes[0].min;
    if (constant) {
        CHECKF(got == 0, "%s: a constant brick keeps %g", what, got);
        return;
    }
    CHECKF(got >= want, "%s: %.9g kept for Lemma 1's %.9g", what, got, want);
    if (isfinite(want) && want > range * exp2(-237 / 16.0))
        CHECKF(got <= want * exp2(1 / 16.0) * (1 + 1e-12), "%s: %.9g kept for %.9g", what, got, want);
    else if (isfinite(want))
        CHECKF(got <= range * exp2(-237 / 16.0) * (1 + 1e-12), "%s: %.9g kept for %.9g", what, got, want);
}

/* Every brick's error at level 3 and every block's at levels 1 and 2 is the largest Lemma 1
 * error of the cells of its 2^l grid, each scanned in full, the last cell of a clipped box
 * narrower, kept rounded up by at most a step of the code: on fields with partial and
 * one-cell bricks and blocks, a volume with constant regions, and a float volume with a
 * NaN (its cells: infinite error). */
static void test_level_errors_are_lemma1_per_coarse_cell(void)
{
    static const char *fields[] = {"field:ml:41x37x29", "field:sphere:10x18x26", "field:torus:33x33x17"};
    iso_error err;
    for (int f = 0; f < 5 && !check_failed(); f++) {
        iso_volume *vol = NULL;
        if (f < 3) {
            CHECK_OK(iso_load(fields[f], NULL, &vol, &err), &err);
        } else {
            size_t dims[3] = {26, 19, 17};
            vol = iso_vol_create(dims, f == 3 ? ISO_U8 : ISO_F32, 0, &err);
            CHECK(vol != NULL);
            for (size_t k = 0; vol && k < dims[2]; k++)
                for (size_t j = 0; j < dims[1]; j++)
                    for (size_t i = 0; i < dims[0]; i++) /* a ball of noise in a constant block */
                        iso_vol_set(vol, i, j, k, (i - 13.0) * (i - 13.0) + (j - 9.0) * (j - 9.0) < 40 ? (double)((i * 7 + j * 13 + k * 5) % 11) : 3.0);
            if (vol && f == 4)
                iso_vol_set(vol, 12, 9, 8, NAN);
        }
        if (!vol)
            continue;
        iso_vol_update_stats(vol);
        iso_tree *tree = surface_build(vol);
        const iso_bricks *g = &tree->bricks;
        size_t finite = 0, infinite = 0, blocks = 0;
        char what[96];
        for (uint32_t k = 0; k < g->count[2]; k++)
            for (uint32_t j = 0; j < g->count[1]; j++)
                for (uint32_t i = 0; i < g->count[0]; i++) {
                    uint32_t brick[3] = {i, j, k};
                    size_t lo[3], hi[3], at = ((size_t)k * g->count[1] + j) * g->count[0] + i;
                    iso_bricks_box(vol, brick, lo, hi);
                    int constant = g->min[at] == g->max[at];
                    double got = iso_tree_level_error(tree, at);
                    snprintf(what, sizeof what, "%d: brick (%u, %u, %u) level 3", f, i, j, k);
                    check_code(tree, got, box_level_error(vol, lo, hi, 8), constant, what);
                    finite += isfinite(got);
                    infinite += !isfinite(got);
                    for (int b = 0; b < 8; b++) {
                        size_t blo[3], bhi[3];
                        int present = 1;
                        for (int d = 0; d < 3; d++) {
                            blo[d] = lo[d] + (size_t)(b >> d & 1) * ISO_TREE_BLOCK;
                            bhi[d] = blo[d] + ISO_TREE_BLOCK < hi[d] ? blo[d] + ISO_TREE_BLOCK : hi[d];
                            present &= blo[d] < hi[d];
                        }
                        for (int l = 1; l <= ISO_TREE_BLOCK_LEVELS; l++) {
                            got = iso_tree_block_error(tree, at, b, l);
                            snprintf(what, sizeof what, "%d: brick (%u, %u, %u) block %d level %d", f, i, j, k, b, l);
                            if (!present) {
                                CHECKF(got == 0, "%s: a missing block keeps %g", what, got);
                                continue;
                            }
                            blocks += l == 1;
                            check_code(tree, got, box_level_error(vol, blo, bhi, 1u << l), constant, what);
                            finite += isfinite(got);
                            infinite += !isfinite(got);
                        }
                    }
                }
        /* Only field 4's NaN makes a level error infinite. */
        CHECKF(finite > 0 && (f == 4) == (infinite > 0), "%d: %zu finite, %zu infinite level errors", f, finite,
               infinite);
        CHECKF(blocks > 8 * iso_bricks_total(g) / 2, "%d: %zu blocks in %zu bricks", f, blocks, iso_bricks_total(g));
        iso_tree_destroy(tree);
        iso_vol_destroy(vol);
    }
}

/* The code: 0 for 0, the first value at or above an error, INFINITY past twice the range
 * or for NaN, and a value for every code that rises with it. */
static void test_level_codes(void)
{
    iso_tree_scale scale;
    iso_tree_scale_make(1000, &scale);
    CHECK_EQ(iso_tree_code(&scale, 0), 0);
    CHECK_EQ(iso_tree_code(&scale, NAN), 255);
    CHECK_EQ(iso_tree_code(&scale, 2001), 255);
    CHECK_EQ(iso_tree_code(&scale, 2000), 254);
    CHECK_EQ(iso_tree_code(&scale, 1000), 238);
    CHECK_EQ(iso_tree_code(&scale, 1e-30), 1);
    CHECK(isinf(scale.value[255]));
    for (int k = 1; k < 255; k++)
        CHECK(scale.value[k] > scale.value[k - 1]);
    for (int i = 0; i < 10000; i++) {
        double e = 2000 * pow((double)i / 10000, 4);
        uint8_t c = iso_tree_code(&scale, e);
        CHECKF(scale.value[c] >= e && (c == 0 || c == 1 || scale.value[c - 1] < e), "error %g: code %d", e, c);
    }
    /* A volume whose root spans an infinite range keeps no finite error but 0. */
    iso_tree_scale_make(INFINITY, &scale);
    CHECK(isinf(scale.value[iso_tree_code(&scale, 1)]));
    CHECK_EQ(iso_tree_code(&scale, 0), 0);
}

/* Dimensions 10, 18, 26 leave bricks one cell thick at the far end of every axis (the
 * corner one is a single cell): the walk below bricks must take them as they are. */
static void test_tolerance_on_one_cell_bricks(void)
{
    iso_volume *vol;
    iso_error err;
    CHECK_OK(iso_load("field:sphere:10x18x26", NULL, &vol, &err), &err);
    iso_tree *tree = surface_build(vol);
    CHECK_EQ(tree->bricks.count[0] * tree->bricks.count[1] * tree->bricks.count[2], 2 * 3 * 4);
    for (double t = 0; t <= 2; t += 0.5) {
        iso_mesh m;
        iso_mesh_init(&m);
        iso_extract_stats st;
        extract(tree, 0.5, t, &m, &st);
        CHECK(st.triangles > 0);
        CHECKF(surface_worst_vertex_error(vol, &m, 0.5) <= st.error_bound + surface_rounding_slack(vol),
               "t=%g: vertex off by %g, bound %g", t, surface_worst_vertex_error(vol, &m, 0.5), st.error_bound);
        CHECK(st.error_bound <= t);
        iso_census c;
        CHECK_OK(iso_census_compute(vol, &m, ISO_SPACE_INDEX, &c, &err), &err);
        CHECKF(c.open_edges + c.nonmanifold_edges + c.misoriented_edges == 0,
               "t=%g: %zu open inside, %zu nonmanifold, %zu misoriented", t, c.open_edges, c.nonmanifold_edges,
               c.misoriented_edges);
        iso_mesh_free(&m);
    }
    iso_tree_destroy(tree);
    iso_vol_destroy(vol);
}

/* ---- real data: the paper's 3dhead ---- */

static void test_cthead_guarantee_and_trend(void)
{
    iso_volume *vol = surface_load_shared("CThead_256x256x113_u16be.nhdr");
    if (!vol)
        return;
    iso_error err;
    iso_tree *tree = surface_build(vol);
    const double levels[] = {700, 1500}, tolerances[] = {0, 10, 50, 200};
    for (int l = 0; l < 2; l++) {
        iso_mesh full, m;
        iso_mesh_init(&full);
        iso_mesh_init(&m);
        iso_extract_stats fs, st;
        CHECK_OK(iso_extract_full_scan(vol, levels[l], ISO_SPACE_INDEX, &full, &fs, &err), &err);
        size_t last_tri = SIZE_MAX, last_cells = SIZE_MAX, first_cells = 0;
        for (int t = 0; t < 4; t++) {
            extract(tree, levels[l], tolerances[t], &m, &st);
            double worst = surface_worst_vertex_error(vol, &m, levels[l]);
            CHECKF(worst <= st.error_bound + surface_rounding_slack(vol), "level %g tol %g: vertex off by %g, bound %g",
                   levels[l], tolerances[t], worst, st.error_bound);
            CHECKF(st.error_bound <= fmax(tolerances[t], surface_tie_allowance(vol)), "level %g tol %g: bound %g",
                   levels[l], tolerances[t], st.error_bound);
            CHECKF(st.triangles <= last_tri && st.cells_visited <= last_cells,
                   "level %g tol %g: %zu triangles, %zu cells after %zu, %zu", levels[l], tolerances[t],
                   st.triangles, st.cells_visited, last_tri, last_cells);
            if (t == 0) {
                first_cells = st.cells_visited;
                CHECK_EQ(st.triangles, fs.triangles);
                CHECK_NEAR(iso_mesh_area(&m), iso_mesh_area(&full), 0.01 * iso_mesh_area(&full));
                CHECK(st.cells_visited < fs.cells_visited / 4);
            }
            last_tri = st.triangles;
            last_cells = st.cells_visited;
        }
        CHECKF(last_tri < fs.triangles, "tolerance 200 should shed triangles: %zu of %zu", last_tri, fs.triangles);
        /* Cells visited: at 0 the kernel's whole active bricks, above it each brick's cells
         * at its own stride; a coarse tolerance must cut them. */
        CHECKF(last_cells < first_cells, "tolerance 200 visits %zu cells, tolerance 0 %zu", last_cells, first_cells);
        /* The preview (half the range, extract.h) keeps at most 12% of the triangles, within
         * its tolerance of the level. */
        double preview = iso_preview_tolerance(vol);
        extract(tree, levels[l], preview, &m, &st);
        CHECKF(st.triangles * 100 <= fs.triangles * 12, "level %g preview %g: %zu of %zu triangles", levels[l],
               preview, st.triangles, fs.triangles);
        CHECK(st.error_bound <= preview);
        CHECKF(surface_worst_vertex_error(vol, &m, levels[l]) <= st.error_bound + surface_rounding_slack(vol),
               "level %g preview: vertex past the bound %g", levels[l], st.error_bound);
        iso_mesh_free(&full);
        iso_mesh_free(&m);
    }
    iso_tree_destroy(tree);
    iso_vol_destroy(vol);
}

/* A tolerance under every crossed brick's finest level error coarsens nothing: the answer
 * is the exact path's, byte for byte, in both spaces and capped. */
static void test_tolerance_that_coarsens_nothing_is_exact(void)
{
    double r0;
    iso_volume *vol = sphere_volume(40, &r0);
    iso_tree *tree = surface_build(vol);
    double level = 3, finest = INFINITY;
    const iso_bricks *g = &tree->bricks;
    for (size_t b = 0; b < iso_bricks_total(g); b++)
        if (g->min[b] <= level && level < g->max[b])
            for (int k = 0; k < 8; k++) {
                uint32_t brick[3] = {(uint32_t)(b % g->count[0]), (uint32_t)(b / g->count[0] % g->count[1]),
                                     (uint32_t)(b / g->count[0] / g->count[1])};
                size_t lo[3], hi[3];
                iso_bricks_box(vol, brick, lo, hi);
                int present = 1; /* a block the brick has: a clipped brick may lack some */
                for (int d = 0; d < 3; d++)
                    present &= lo[d] + (size_t)(k >> d & 1) * ISO_TREE_BLOCK < hi[d];
                if (present)
                    finest = fmin(finest, iso_tree_block_error(tree, b, k, 1));
            }
    CHECKF(finest > 0 && isfinite(finest), "finest level error %g", finest);
    for (int variant = 0; variant < 3; variant++) {
        iso_mesh exact, tol;
        iso_mesh_init(&exact);
        iso_mesh_init(&tol);
        iso_extract_stats se, st;
        iso_error err;
        iso_extract_params p = {.level = level, .space = variant == 1 ? ISO_SPACE_WORLD : ISO_SPACE_INDEX,
                                .cap = variant == 2, .threads = 1, .coarsen = ISO_COARSEN_ALL};
        CHECK(iso_extract(tree, &p, &exact, &se, &err) == 0);
        p.tolerance = finest / 2;
        CHECK(iso_extract(tree, &p, &tol, &st, &err) == 0);
        CHECK(exact.triangle_count > 0);
        CHECK_EQ(tol.vertex_count, exact.vertex_count);
        CHECK_EQ(tol.triangle_count, exact.triangle_count);
        CHECK(memcmp(tol.positions, exact.positions, 3 * sizeof(float) * exact.vertex_count) == 0);
        CHECK(memcmp(tol.indices, exact.indices, 3 * sizeof(uint32_t) * exact.triangle_count) == 0);
        CHECK(st.error_bound == se.error_bound);
        /* At the finest error one block coarsens; it holds no crossing and its stride-2
         * samples lie farther than its error from the level, so the plan still has no
         * coarse block the level crosses: the exact path again, byte for byte. */
        p.tolerance = finest;
        CHECK(iso_extract(tree, &p, &tol, &st, &err) == 0);
        CHECK_EQ(st.nodes_polygonized, 0);
        CHECK_EQ(tol.triangle_count, exact.triangle_count);
        CHECK(memcmp(tol.indices, exact.indices, 3 * sizeof(uint32_t) * exact.triangle_count) == 0);
        CHECK(memcmp(tol.positions, exact.positions, 3 * sizeof(float) * exact.vertex_count) == 0);
        iso_mesh_free(&exact);
        iso_mesh_free(&tol);
    }
    iso_tree_destroy(tree);
    iso_vol_destroy(vol);
}

static int same_mesh(const iso_mesh *a, const iso_mesh *b)
{
    return a->vertex_count == b->vertex_count && a->triangle_count == b->triangle_count &&
           memcmp(a->positions, b->positions, 3 * sizeof(float) * a->vertex_count) == 0 &&
           memcmp(a->indices, b->indices, 3 * sizeof(uint32_t) * a->triangle_count) == 0;
}

/* By default a tolerance buys time, never costs it: where most crossed blocks cannot lie in
 * stride-8 bricks the exact surface answers, byte for byte; where nearly all do, the
 * coarse units answer, as ISO_COARSEN_ALL would. ISO_COARSEN_ALL always coarsens. */
static void test_tolerance_coarsens_only_where_it_pays(void)
{
    double r0;
    iso_volume *vol = sphere_volume(66, &r0);
    iso_tree *tree = surface_build(vol);
    double level = 8; /* a sphere of radius 23.5, a brick or more from the border */
    iso_mesh exact, fast, all;
    iso_mesh_init(&exact);
    iso_mesh_init(&fast);
    iso_mesh_init(&all);
    iso_extract_stats se, sf, sa;
    iso_error err;
    iso_extract_params p = {.level = level, .space = ISO_SPACE_INDEX};
    CHECK_OK(iso_extract(tree, &p, &exact, &se, &err), &err);
    CHECK_EQ(se.coarse_share, 0);
    /* 0.05: strides 2 (error about 4 / (8 r)) but never 8; 2: stride 8 nearly everywhere. */
    static const double tolerances[2] = {0.05, 2};
    for (int t = 0; t < 2; t++) {
        p.tolerance = tolerances[t];
        p.coarsen = ISO_COARSEN_WHERE_FASTER;
        CHECK_OK(iso_extract(tree, &p, &fast, &sf, &err), &err);
        p.coarsen = ISO_COARSEN_ALL;
        CHECK_OK(iso_extract(tree, &p, &all, &sa, &err), &err);
        CHECKF(sa.coarse_share > 0 && all.triangle_count < exact.triangle_count,
               "tolerance %g: every coarse unit gives %zu of %zu triangles, share %g", tolerances[t],
               all.triangle_count, exact.triangle_count, sa.coarse_share);
        CHECK(sa.error_bound <= tolerances[t]);
        if (t == 0) {
            CHECKF(same_mesh(&fast, &exact) && sf.coarse_share == 0,
                   "tolerance %g: %zu triangles, share %g, not the exact surface", tolerances[t],
                   fast.triangle_count, sf.coarse_share);
        } else {
            CHECKF(same_mesh(&fast, &all) && sf.coarse_share == sa.coarse_share && sa.coarse_share > 0.8,
                   "tolerance %g: %zu triangles (all: %zu), share %g", tolerances[t], fast.triangle_count,
                   all.triangle_count, sf.coarse_share);
        }
    }
    iso_mesh_free(&exact);
    iso_mesh_free(&fast);
    iso_mesh_free(&all);
    iso_tree_destroy(tree);
    iso_vol_destroy(vol);
}

/* The tolerance path's mesh is the same bytes on 1, 2 and 3 threads: every brick numbers
 * its crossings and lays out its triangles in grid order, whoever counts it. */
static void check_threads_give_same_bytes(const iso_tree *tree, double level, double tolerance, int cap)
{
    iso_mesh one, other;
    iso_mesh_init(&one);
    iso_mesh_init(&other);
    iso_extract_stats s1, sn;
    iso_error err;
    iso_extract_params p = {.level = level, .tolerance = tolerance, .cap = cap, .space = ISO_SPACE_INDEX, .threads = 1,
                            .coarsen = ISO_COARSEN_ALL};
    CHECK_OK(iso_extract(tree, &p, &one, &s1, &err), &err);
    for (int threads = 2; threads <= 3; threads++) {
        p.threads = threads;
        CHECK_OK(iso_extract(tree, &p, &other, &sn, &err), &err);
        CHECKF(same_mesh(&one, &other), "level %g tolerance %g cap %d: %d threads differ from 1", level, tolerance,
               cap, threads);
        CHECK(s1.error_bound == sn.error_bound && s1.cells_visited == sn.cells_visited);
    }
    iso_mesh_free(&one);
    iso_mesh_free(&other);
}

static void test_tolerance_meshes_do_not_depend_on_threads(void)
{
    double r0;
    iso_volume *vol = sphere_volume(40, &r0);
    iso_tree *tree = surface_build(vol);
    const double rungs[4][2] = {{4, 11}, {4, 0.5}, {7.5, 3}, {0.07, 0.15}};
    for (int t = 0; t < 4; t++)
        for (int cap = 0; cap < 2; cap++)
            check_threads_give_same_bytes(tree, rungs[t][0], rungs[t][1], cap);
    iso_tree_destroy(tree);
    iso_vol_destroy(vol);
    vol = surface_load_shared("CThead_256x256x113_u16be.nhdr");
    if (!vol)
        return;
    tree = surface_build(vol);
    const double levels[] = {700, 1500}, shares[] = {65.44, 654.4, 1636};
    for (int l = 0; l < 2; l++)
        for (int t = 0; t < 3; t++)
            check_threads_give_same_bytes(tree, levels[l], shares[t], 0);
    iso_tree_destroy(tree);
    iso_vol_destroy(vol);
}

/* World positions off the tolerance path (and its cap, and the full scan) are the index
 * positions through iso_vol_index_to_world, bit for bit: extract.c's one multiply-add per
 * coordinate with an identity direction, the general map with a rotated one. */
/* The surface at `level` extracted twice, in index space and in world space, by the
 * hierarchy (with `tolerance`, every block coarsened that may be, closed at the border when
 * `cap`) or by the full scan. */
static void index_and_world(const iso_tree *tree, double level, double tolerance, int cap, int full_scan,
                            iso_mesh *index, iso_mesh *world)
{
    iso_mesh_init(index);
    iso_mesh_init(world);
    iso_extract_params p = {.level = level, .tolerance = tolerance, .cap = cap, .space = ISO_SPACE_INDEX, .threads = 1,
                            .coarsen = ISO_COARSEN_ALL};
    iso_error err;
    if (full_scan) {
        CHECK_OK(iso_extract_full_scan(tree->vol, level, ISO_SPACE_INDEX, index, NULL, &err), &err);
        CHECK_OK(iso_extract_full_scan(tree->vol, level, ISO_SPACE_WORLD, world, NULL, &err), &err);
        return;
    }
    CHECK_OK(iso_extract(tree, &p, index, NULL, &err), &err);
    p.space = ISO_SPACE_WORLD;
    CHECK_OK(iso_extract(tree, &p, world, NULL, &err), &err);
}

static void test_world_positions_are_the_index_map(void)
{
    double r0;
    iso_volume *vol = sphere_volume(40, &r0);
    const double spacing[3] = {0.957, 1.5, 0.3}, origin[3] = {-120.4, -0.0, 33.3};
    for (int d = 0; d < 3; d++) {
        vol->spacing[d] = spacing[d];
        vol->origin[d] = origin[d];
    }
    iso_tree *tree = surface_build(vol);
    for (int rotated = 0; rotated < 2; rotated++) {
        if (rotated) { /* a quarter turn about z */
            double turn[3][3] = {{0, -1, 0}, {1, 0, 0}, {0, 0, 1}};
            memcpy(vol->direction, turn, sizeof turn);
        }
        for (int variant = 0; variant < 3; variant++) {
            iso_mesh index, world;
            index_and_world(tree, 4, variant == 2 ? 0 : 0.15, variant == 1, variant == 2, &index, &world);
            CHECK(index.vertex_count > 0);
            CHECK_EQ(world.vertex_count, index.vertex_count);
            size_t off = 0;
            for (size_t v = 0; v < index.vertex_count && v < world.vertex_count; v++) {
                const float *a = index.positions + 3 * v, *b = world.positions + 3 * v;
                double x[3] = {a[0], a[1], a[2]}, w[3];
                iso_vol_index_to_world(vol, x, w);
                for (int d = 0; d < 3; d++)
                    off += memcmp(&(float){(float)w[d]}, &b[d], sizeof(float)) != 0;
            }
            CHECKF(off == 0, "rotated %d variant %d: %zu coordinates not the map's", rotated, variant, off);
            iso_mesh_free(&index);
            iso_mesh_free(&world);
        }
    }
    iso_tree_destroy(tree);
    iso_vol_destroy(vol);
}

/* A mirrored index-to-world map (one axis flipped: LPI, a radiological NIfTI) would turn
 * the surface inside out in world space; the winding is kept instead: the world mesh's
 * signed enclosed volume is the index mesh's times the voxel volume, positive (normals
 * outward, toward the lower values), by every extraction path, with corners 1 and 2 of
 * each triangle swapped exactly when the map mirrors. */
static void test_mirrored_map_keeps_winding(void)
{
    double r0;
    iso_volume *vol = sphere_volume(32, &r0);
    const double spacing[3] = {0.8, 1.25, 2};
    memcpy(vol->spacing, spacing, sizeof spacing);
    iso_tree *tree = surface_build(vol);
    const double maps[3][3][3] = {{{1, 0, 0}, {0, 1, 0}, {0, 0, 1}},   /* LPS */
                                  {{1, 0, 0}, {0, 1, 0}, {0, 0, -1}},  /* LPI: mirrored */
                                  {{0, -1, 0}, {-1, 0, 0}, {0, 0, 1}}}; /* axes swapped: mirrored */
    for (int m = 0; m < 3; m++) {
        memcpy(vol->direction, maps[m], sizeof maps[m]);
        int mirrored = m > 0;
        for (int variant = 0; variant < 4; variant++) {
            iso_mesh index, world;
            index_and_world(tree, 4, variant == 1 ? 0.15 : 0, variant == 2, variant == 3, &index, &world);
            double in_index = iso_mesh_enclosed_volume(&index), in_world = iso_mesh_enclosed_volume(&world);
            double voxel = spacing[0] * spacing[1] * spacing[2];
            CHECKF(in_index > 0 && fabs(in_world - in_index * voxel) < 1e-4 * in_index * voxel,
                   "map %d variant %d: enclosed %g in index space, %g in world (want %g)", m, variant,
                   in_index, in_world, in_index * voxel);
            size_t same = 0, swapped = 0;
            for (size_t t = 0; t < index.triangle_count && index.triangle_count == world.triangle_count; t++) {
                const uint32_t *a = index.indices + 3 * t, *b = world.indices + 3 * t;
                same += a[0] == b[0] && a[1] == b[1] && a[2] == b[2];
                swapped += a[0] == b[0] && a[1] == b[2] && a[2] == b[1];
            }
            CHECKF((mirrored ? swapped : same) == index.triangle_count && index.triangle_count > 0,
                   "map %d variant %d: %zu same, %zu swapped of %zu", m, variant, same, swapped, index.triangle_count);
            iso_mesh_free(&index);
            iso_mesh_free(&world);
        }
    }
    iso_tree_destroy(tree);
    iso_vol_destroy(vol);
}

int main(void)
{
    CHECK_RUN(test_mc_table_shapes);
    CHECK_RUN(test_mc_single_corner_winding);
    CHECK_RUN(test_mc_random_fields_watertight);
    CHECK_RUN(test_lemma1_fit_error_brute_force);
    CHECK_RUN(test_d1_constant_is_one_node);
    CHECK_RUN(test_d2_spike_takes_log_steps);
    CHECK_RUN(test_d3_ijk_is_one_trilinear);
    CHECK_RUN(test_sphere_surface_is_bounded_and_closed);
    CHECK_RUN(test_torus_surface_is_bounded);
    CHECK_RUN(test_tree_file_round_trip_and_refusals);
    CHECK_RUN(test_tree_is_small);
    CHECK_RUN(test_coarse_bricks_join_without_weld);
    CHECK_RUN(test_tolerance_on_one_cell_bricks);
    CHECK_RUN(test_tolerance_that_coarsens_nothing_is_exact);
    CHECK_RUN(test_tolerance_coarsens_only_where_it_pays);
    CHECK_RUN(test_tolerance_meshes_do_not_depend_on_threads);
    CHECK_RUN(test_world_positions_are_the_index_map);
    CHECK_RUN(test_mirrored_map_keeps_winding);
    CHECK_RUN(test_level_errors_are_lemma1_per_coarse_cell);
    CHECK_RUN(test_level_codes);
    CHECK_RUN(test_cthead_guarantee_and_trend);
    return check_finish();
}
