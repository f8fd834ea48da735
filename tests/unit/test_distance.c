/* test_distance.c: the measured distance between two surfaces (iso_mesh_distance_compute).
 *
 * Hand-built meshes with exact answers (two parallel squares a quarter apart; a square
 * against its left half; a point against each feature of one triangle), and a simplified
 * sphere against its exact surface, where every sample's distance is found again here by
 * brute force with a point-to-triangle distance of another construction (projection onto
 * the plane, else the nearest of the three sides) and the weighted percentile by a full
 * sort: the maxima and the 99th percentiles must agree to float rounding. Then the
 * simplification chain of a torus, level by level, against the same brute force. */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "check.h"
#include "io/io.h"
#include "mesh/mesh.h"
#include "mesh/distance.h"
#include "extract/extract.h"
#include "surface.h"

/* A w x h rectangle at height z as two triangles, corners (x0, 0), (x0 + w, h). */
static void rectangle(iso_mesh *m, double x0, double w, double h, double z)
{
    iso_mesh_init(m);
    CHECK(iso_mesh_reserve(m, 4, 2) == 0);
    float p[12] = {(float)x0, 0, (float)z, (float)(x0 + w), 0, (float)z,
                   (float)(x0 + w), (float)h, (float)z, (float)x0, (float)h, (float)z};
    uint32_t t[6] = {0, 1, 2, 0, 2, 3};
    memcpy(m->positions, p, sizeof p);
    memcpy(m->indices, t, sizeof t);
    m->vertex_count = 4;
    m->triangle_count = 2;
}

static void test_parallel_squares_are_a_quarter_apart(void)
{
    iso_mesh a, b;
    rectangle(&a, 0, 1, 1, 0);
    rectangle(&b, 0, 1, 1, 0.25);
    iso_mesh_distance d;
    iso_error err;
    CHECK_OK(iso_mesh_distance_compute(&a, &b, 0.1, 0, &d, &err), &err);
    CHECK_NEAR(d.p99_ab, 0.25, 1e-7);
    CHECK_NEAR(d.p99_ba, 0.25, 1e-7);
    CHECK_NEAR(d.max_ab, 0.25, 1e-7);
    CHECK_NEAR(d.max, 0.25, 1e-7);
    CHECK_NEAR(d.mean_ab, 0.25, 1e-7);
    CHECK_NEAR(d.mean, 0.25, 1e-7);
    /* The diagonal, sqrt 2, makes 15 x 15 sub-triangles per triangle; and 4 vertices. */
    CHECK_EQ(d.samples_a, 2 * 15 * 15 + 4);
    CHECK_EQ(d.samples_b, 2 * 15 * 15 + 4);
    CHECK_EQ(iso_mesh_distance_compute(&a, &b, 0, 0, &d, &err), ISO_E_ARGUMENT);
    iso_mesh_free(&a);
    iso_mesh_free(&b);
}

/* The unit square against its left half: from the half, 0 everywhere; from the square,
 * max(0, x - 1/2), whose 99th percentile by area is 0.49 (to the sampling's spacing),
 * whose maximum is 1/2, at the right-hand corners, and whose mean is the integral of
 * x - 1/2 over [1/2, 1], 1/8. Pooled by area (1 and 1/2): (1/8 * 1 + 0) / 1.5 = 1/12. */
static void test_square_against_its_half(void)
{
    iso_mesh a, b;
    rectangle(&a, 0, 1, 1, 0);
    rectangle(&b, 0, 0.5, 1, 0);
    iso_mesh_distance d;
    iso_error err;
    double spacing = 1.0 / 64;
    CHECK_OK(iso_mesh_distance_compute(&a, &b, spacing, 0, &d, &err), &err);
    CHECK_NEAR(d.max_ab, 0.5, 1e-7);
    CHECK_NEAR(d.p99_ab, 0.49, spacing);
    CHECK_EQ(d.max_ba, 0);
    CHECK_EQ(d.p99_ba, 0);
    CHECK_NEAR(d.p99, d.p99_ab, 0);
    CHECK_NEAR(d.mean_ab, 1.0 / 8, spacing / 4);
    CHECK_EQ(d.mean_ba, 0);
    CHECK_NEAR(d.mean, 1.0 / 12, spacing / 4);
    iso_mesh empty;
    iso_mesh_init(&empty);
    CHECK_OK(iso_mesh_distance_compute(&empty, &a, spacing, 0, &d, &err), &err);
    CHECK(d.max_ab == 0 && isinf(d.max_ba));
    CHECK(isinf(d.mean));
    iso_mesh_free(&a);
    iso_mesh_free(&b);
}

static void test_point_against_each_feature(void)
{
    iso_mesh m;
    iso_mesh_init(&m);
    CHECK(iso_mesh_reserve(&m, 3, 1) == 0);
    float p[9] = {0, 0, 0, 1, 0, 0, 0, 1, 0};
    uint32_t t[3] = {0, 1, 2};
    memcpy(m.positions, p, sizeof p);
    memcpy(m.indices, t, sizeof t);
    m.vertex_count = 3, m.triangle_count = 1;
    struct { double p[3], d; } cases[] = {
        {{0.25, 0.25, 2}, 2},           /* the face */
        {{-1, -1, 0}, sqrt(2)},         /* corner a */
        {{2, 0, 0}, 1},                 /* corner b */
        {{0, 3, 0}, 2},                 /* corner c */
        {{0.5, -1, 0}, 1},              /* side ab */
        {{-3, 0.5, 4}, 5},              /* side ac */
        {{1, 1, 0}, sqrt(0.5)},         /* side bc */
    };
    for (size_t i = 0; i < sizeof cases / sizeof cases[0]; i++)
        CHECK_NEAR(iso_mesh_point_distance(&m, cases[i].p), cases[i].d, 1e-12);
    iso_mesh_free(&m);
}

/* ---- brute force, built otherwise ---- */

static void sub(const double a[3], const double b[3], double out[3])
{
    for (int k = 0; k < 3; k++)
        out[k] = a[k] - b[k];
}

static double dot3(const double a[3], const double b[3])
{
    return a[0] * b[0] + a[1] * b[1] + a[2] * b[2];
}

static void cross(const double a[3], const double b[3], double out[3])
{
    out[0] = a[1] * b[2] - a[2] * b[1];
    out[1] = a[2] * b[0] - a[0] * b[2];
    out[2] = a[0] * b[1] - a[1] * b[0];
}

static double point_segment(const double p[3], const double a[3], const double b[3])
{
    double ab[3], ap[3];
    sub(b, a, ab), sub(p, a, ap);
    double len = dot3(ab, ab), t = len > 0 ? dot3(ap, ab) / len : 0;
    t = t < 0 ? 0 : t > 1 ? 1 : t;
    double q[3];
    for (int k = 0; k < 3; k++)
        q[k] = p[k] - (a[k] + t * ab[k]);
    return sqrt(dot3(q, q));
}

/* The plane's foot if it falls inside (same side of all three sides), else the nearest
 * side. */
static double brute_point_triangle(const double p[3], const double c[3][3])
{
    double u[3], v[3], n[3];
    sub(c[1], c[0], u), sub(c[2], c[0], v), cross(u, v, n);
    double nn = dot3(n, n);
    if (nn > 0) {
        double w[3], foot[3];
        sub(p, c[0], w);
        double h = dot3(w, n) / nn;
        for (int k = 0; k < 3; k++)
            foot[k] = p[k] - h * n[k];
        int inside = 1;
        for (int e = 0; e < 3; e++) {
            double side[3], to[3], x[3];
            sub(c[(e + 1) % 3], c[e], side), sub(foot, c[e], to), cross(side, to, x);
            inside &= dot3(x, n) >= 0;
        }
        if (inside)
            return fabs(h) * sqrt(nn);
    }
    double best = INFINITY;
    for (int e = 0; e < 3; e++)
        best = fmin(best, point_segment(p, c[e], c[(e + 1) % 3]));
    return best;
}

static void corners(const iso_mesh *m, size_t t, double c[3][3])
{
    for (int k = 0; k < 3; k++)
        for (int a = 0; a < 3; a++)
            c[k][a] = m->positions[3 * (size_t)m->indices[3 * t + k] + a];
}

static double brute_point_mesh(const iso_mesh *m, const double p[3])
{
    double best = INFINITY;
    for (size_t t = 0; t < m->triangle_count; t++) {
        double c[3][3];
        corners(m, t, c);
        best = fmin(best, brute_point_triangle(p, c));
    }
    return best;
}

typedef struct sample { double d, w; } sample;

static int by_distance(const void *pa, const void *pb)
{
    double a = ((const sample *)pa)->d, b = ((const sample *)pb)->d;
    return (a > b) - (a < b);
}

/* Triangle t of src cut into k x k similar sub-triangles, k the fewest that make their
 * sides at most `spacing`: their centroids' distances to dst by brute force, appended to
 * *s (n of *cap), each weighing its area. */
static void brute_triangle(const iso_mesh *src, size_t t, const iso_mesh *dst, double spacing,
                           sample **s, size_t *n, size_t *cap)
{
    double c[3][3], u[3], v[3], x[3], longest = 0;
    corners(src, t, c);
    for (int e = 0; e < 3; e++) {
        double side[3];
        sub(c[(e + 1) % 3], c[e], side);
        longest = fmax(longest, sqrt(dot3(side, side)));
    }
    int k = (int)ceil(longest / spacing);
    k = k < 1 ? 1 : k;
    sub(c[1], c[0], u), sub(c[2], c[0], v), cross(u, v, x);
    double w = 0.5 * sqrt(dot3(x, x)) / (k * k);
    for (int i = 0; i < k; i++)
        for (int j = 0; j < k; j++) {
            /* Sub-triangle (i, j) of the parallelogram grid: two centroids when inside. */
            for (int down = 0; down < 2; down++) {
                if (i + j + down >= k)
                    continue;
                double a = (i + (down ? 2.0 : 1.0) / 3) / k, b = (j + (down ? 2.0 : 1.0) / 3) / k;
                double p[3];
                for (int q = 0; q < 3; q++)
                    p[q] = c[0][q] + a * u[q] + b * v[q];
                if (*n == *cap)
                    *s = realloc(*s, (*cap *= 2) * sizeof **s);
                (*s)[(*n)++] = (sample){brute_point_mesh(dst, p), w};
            }
        }
}

/* Every sample mesh.h promises (sub-triangle centroids weighing their area, used vertices
 * weighing 0), measured by brute force; the weighted 99th percentile by a full sort, and
 * the share of the weight within distance `within` (returned). */
static double brute_share(const iso_mesh *src, const iso_mesh *dst, double spacing, double within,
                          double *p99, double *max, size_t *count)
{
    size_t cap = 1024, n = 0;
    sample *s = malloc(cap * sizeof *s);
    char *used = calloc(src->vertex_count, 1);
    for (size_t t = 0; t < src->triangle_count; t++) {
        brute_triangle(src, t, dst, spacing, &s, &n, &cap);
        for (int q = 0; q < 3; q++)
            used[src->indices[3 * t + q]] = 1;
    }
    for (size_t v = 0; v < src->vertex_count; v++)
        if (used[v]) {
            double p[3] = {src->positions[3 * v], src->positions[3 * v + 1], src->positions[3 * v + 2]};
            if (n == cap)
                s = realloc(s, (cap *= 2) * sizeof *s);
            s[n++] = (sample){brute_point_mesh(dst, p), 0};
        }
    qsort(s, n, sizeof *s, by_distance);
    double total = 0, below = 0;
    for (size_t i = 0; i < n; i++)
        total += s[i].w;
    *max = n ? s[n - 1].d : 0;
    *p99 = 0;
    for (size_t i = 0; i < n; i++) {
        below += s[i].w;
        if (below >= 0.99 * total) {
            *p99 = s[i].d;
            break;
        }
    }
    double share = 0;
    for (size_t i = 0; i < n && s[i].d <= within; i++)
        share += s[i].w;
    *count = n;
    free(s);
    free(used);
    return total > 0 ? share / total : 0;
}

static void brute_one_way(const iso_mesh *src, const iso_mesh *dst, double spacing,
                          double *p99, double *max, size_t *count)
{
    brute_share(src, dst, spacing, 0, p99, max, count);
}

/* Field `name` (loaded, its hierarchy built) and its exact surface at `level` in index
 * space, into exact (initialised here). Returns the volume (the caller destroys it), or
 * NULL when a CHECK failed. */
static iso_volume *field_surface(const char *name, double level, iso_mesh *exact)
{
    iso_volume *vol = NULL;
    iso_error err;
    iso_mesh_init(exact);
    CHECK_OK(iso_field_load(name, NULL, &vol, &err), &err);
    if (!vol)
        return NULL;
    iso_vol_update_stats(vol);
    iso_tree *tree = surface_build(vol);
    iso_extract_stats st;
    iso_extract_params xp = {.level = level, .space = ISO_SPACE_INDEX};
    CHECK_OK(iso_extract(tree, &xp, exact, &st, &err), &err);
    iso_tree_destroy(tree);
    return vol;
}

static void test_simplified_sphere_matches_brute_force(void)
{
    iso_error err;
    iso_mesh exact, simple;
    iso_volume *vol = field_surface("field:sphere:24", 3.0, &exact);
    if (!vol)
        return;
    iso_mesh_init(&simple);
    CHECK(iso_mesh_reserve(&simple, exact.vertex_count, exact.triangle_count) == 0);
    memcpy(simple.positions, exact.positions, 3 * exact.vertex_count * sizeof(float));
    memcpy(simple.indices, exact.indices, 3 * exact.triangle_count * sizeof(uint32_t));
    simple.vertex_count = exact.vertex_count, simple.triangle_count = exact.triangle_count;
    iso_simplify_params sp = {.target_triangles = exact.triangle_count / 10, .target_error = INFINITY,
                              .voxel_size = 1, .measure = 1};
    iso_simplify_result r;
    CHECK_OK(iso_simplify(&simple, &sp, &r, &err), &err);
    CHECK(r.measured && r.distance.max > 0);
    iso_mesh_distance one, all;
    CHECK_OK(iso_mesh_distance_compute(&exact, &simple, 1, 1, &one, &err), &err);
    CHECK_OK(iso_mesh_distance_compute(&exact, &simple, 1, 0, &all, &err), &err);
    /* Threads change nothing, and simplify's own measure is the same one. */
    CHECK(one.p99 == all.p99 && one.max == all.max && one.max_ba == all.max_ba);
    CHECK(r.distance.p99 == all.p99 && r.distance.max == all.max);
    double p99, max;
    size_t n;
    brute_one_way(&exact, &simple, 1, &p99, &max, &n);
    CHECK_EQ(n, all.samples_a);
    CHECK_NEAR(all.max_ab, max, 1e-5);
    CHECK_NEAR(all.p99_ab, p99, 1e-5);
    brute_one_way(&simple, &exact, 1, &p99, &max, &n);
    CHECK_EQ(n, all.samples_b);
    CHECK_NEAR(all.max_ba, max, 1e-5);
    CHECK_NEAR(all.p99_ba, p99, 1e-5);
    /* Not the trivial answer: the surfaces differ, by less than a voxel. */
    CHECKF(all.p99 > 0.01 && all.max < 1, "p99 %g, max %g", all.p99, all.max);
    iso_mesh_free(&exact);
    iso_mesh_free(&simple);
    iso_vol_destroy(vol);
}

/* The unit square at z = 0, its left half cut into 20 x 40 small squares and its right
 * half into 2 large ones (two triangles each): triangles of very unequal sizes. */
static void uneven_square(iso_mesh *m)
{
    iso_mesh_init(m);
    CHECK(iso_mesh_reserve(m, 4 * 802, 2 * 802) == 0);
    size_t v = 0, t = 0;
    for (int i = 0; i < 22; i++) {
        int right = i >= 20;
        double x0 = right ? 0.5 : i * 0.025, w = right ? 0.5 : 0.025, h = right ? 0.5 : 0.025;
        for (int j = 0; j < (right ? 1 : 40); j++) {
            double y0 = right ? (i - 20) * 0.5 : j * 0.025;
            float p[12] = {(float)x0, (float)y0, 0, (float)(x0 + w), (float)y0, 0,
                           (float)(x0 + w), (float)(y0 + h), 0, (float)x0, (float)(y0 + h), 0};
            memcpy(m->positions + 3 * v, p, sizeof p);
            uint32_t q[6] = {(uint32_t)v, (uint32_t)v + 1, (uint32_t)v + 2, (uint32_t)v, (uint32_t)v + 2, (uint32_t)v + 3};
            memcpy(m->indices + 3 * t, q, sizeof q);
            v += 4, t += 2;
        }
    }
    m->vertex_count = v, m->triangle_count = t;
}

/* Past the cap, the percentile comes from points drawn by area. From that uneven square
 * to its left half the distance is max(0, x - 1/2): half the area is at 0, but 800 of the
 * 804 triangles are, so points drawn by triangle instead of by area would give 0. The
 * share of the area (brute force over all centroids) within the drawn p99 must be 99% to
 * within four of the stated standard deviations; the maximum is still every centroid's
 * and vertex's (1/2, at the right-hand corners); threads change nothing. */
static void test_drawn_percentile_is_within_its_stated_error(void)
{
    iso_error err;
    iso_mesh a, b;
    uneven_square(&a);
    rectangle(&b, 0, 0.5, 1, 0);
    const size_t cap = 1024;
    const double spacing = 1.0 / 64, sd = sqrt(0.99 * 0.01 / (double)cap);
    iso_mesh_distance d, one;
    CHECK_OK(iso_mesh_distance_between(&a, NULL, &b, NULL, spacing, cap, 0, NULL, &d, &err), &err);
    CHECK_OK(iso_mesh_distance_between(&a, NULL, &b, NULL, spacing, cap, 1, NULL, &one, &err), &err);
    CHECK(one.p99_ab == d.p99_ab && one.max_ab == d.max_ab);
    CHECK_EQ(d.drawn_a, cap);
    double p99, max;
    size_t n;
    double share = brute_share(&a, &b, spacing, d.p99_ab, &p99, &max, &n);
    CHECKF(n > 4 * cap, "%zu samples", n);
    CHECK_EQ(d.samples_a, n);
    CHECKF(fabs(share - 0.99) <= 4 * sd, "%.4f of the area within the drawn p99 %g (all: %g)", share,
           d.p99_ab, p99);
    CHECK_NEAR(d.max_ab, 0.5, 1e-7);
    CHECK_NEAR(max, 0.5, 1e-7);
    CHECKF(d.max_ba < 1e-9, "back: max %g", d.max_ba);
    iso_mesh_free(&a);
    iso_mesh_free(&b);
}

/* The chain of a torus (genus 1): level k has at most 1/2^k of the exact triangles, every
 * level is closed with the torus's Euler characteristic, every vertex of every level is
 * bit for bit one of the exact surface's, each level's stored distance is what brute force
 * measures, and the picks choose as documented. */
static long euler_of(const iso_mesh *m)
{
    iso_mesh_edges e;
    CHECK(iso_mesh_count_edges(m, &e) == 0);
    return (long)m->vertex_count - (long)e.edges + (long)m->triangle_count;
}

static int by_position(const void *pa, const void *pb)
{
    return memcmp(pa, pb, 3 * sizeof(float));
}

/* Every vertex of chain level k is an exact vertex, or, on a level moved to keep the
 * enclosed volume, one moved by exactly |offset| (float rounding aside) from its exact
 * vertex; the level's enclosed volume within 0.5% of the exact one's (and as recorded). */
static void check_level_vertices(const iso_mesh *exact, const float *sorted, const iso_mesh_chain *chain,
                                 int k, const iso_mesh *m)
{
    const iso_mesh_chain_level *lv = &chain->level[k];
    double v0 = iso_mesh_enclosed_volume(exact), v = iso_mesh_enclosed_volume(m);
    CHECKF(fabs(v - v0) <= 0.005 * fabs(v0), "level %d: volume %g, exact %g", k, v, v0);
    CHECKF(fabs((v - v0) / v0 - lv->volume_change) <= 1e-9 + 1e-6 * fabs(lv->volume_change),
           "level %d: volume change %g, recorded %g", k, (v - v0) / v0, lv->volume_change);
    /* the moved ones by brute force: a sample of them on large surfaces */
    size_t stride = lv->offset != 0 && m->vertex_count > 2000 ? m->vertex_count / 2000 : 1;
    for (size_t i = 0; i < m->vertex_count; i += stride) {
        const float *p = m->positions + 3 * i;
        if (lv->offset == 0) {
            CHECKF(bsearch(p, sorted, exact->vertex_count, 3 * sizeof(float), by_position),
                   "level %d: vertex %zu is not an exact vertex", k, i);
            continue;
        }
        double best = INFINITY;
        for (size_t j = 0; j < exact->vertex_count; j++) {
            const float *q = exact->positions + 3 * j;
            double d = sqrt((p[0] - q[0]) * (p[0] - q[0]) + (p[1] - q[1]) * (p[1] - q[1]) +
                            (p[2] - q[2]) * (p[2] - q[2]));
            best = d < best ? d : best;
        }
        CHECKF(best <= fabs(lv->offset) + 1e-4, "level %d: vertex %zu is %g from the exact ones, offset %g",
               k, i, best, lv->offset);
        if (check_failed())
            return;
    }
}

static void test_chain_levels_are_measured_and_closed(void)
{
    iso_error err;
    iso_mesh exact, m;
    iso_volume *vol = field_surface("field:torus:32", 1.0, &exact);
    if (!vol)
        return;
    iso_mesh_init(&m);
    CHECKF(exact.triangle_count >= 2048, "%zu triangles", exact.triangle_count);
    iso_mesh_chain *chain = NULL;
    CHECK_EQ(iso_mesh_chain_build(&exact, 0, 0, &chain, &err), ISO_E_ARGUMENT);
    CHECK_OK(iso_mesh_chain_build(&exact, 1, 0, &chain, &err), &err);
    if (!chain)
        return;
    CHECK_EQ(chain->levels, ISO_CHAIN_LEVELS + 1);
    float *sorted = malloc(3 * exact.vertex_count * sizeof *sorted);
    memcpy(sorted, exact.positions, 3 * exact.vertex_count * sizeof *sorted);
    qsort(sorted, exact.vertex_count, 3 * sizeof(float), by_position);
    for (int k = 0; k < chain->levels && !check_failed(); k++) {
        const iso_mesh_chain_level *lv = &chain->level[k];
        CHECK_OK(iso_mesh_chain_mesh(chain, k, &m, &err), &err);
        CHECK_EQ(m.triangle_count, lv->triangle_count);
        CHECK_EQ(m.vertex_count, lv->vertex_count);
        size_t target = iso_mesh_chain_target(exact.triangle_count, k);
        CHECKF(lv->triangle_count <= target && lv->triangle_count >= target * 8 / 10,
               "level %d: %zu triangles of %zu", k, lv->triangle_count, exact.triangle_count);
        iso_census c;
        CHECK_OK(iso_census_compute(vol, &m, ISO_SPACE_INDEX, &c, &err), &err);
        CHECKF(c.closed, "level %d: open %zu, non-manifold %zu, misoriented %zu", k, c.open_edges,
               c.nonmanifold_edges, c.misoriented_edges);
        CHECK_EQ(euler_of(&m), 0);
        check_level_vertices(&exact, sorted, chain, k, &m);
        if (k == 0) {
            CHECK(!memcmp(m.positions, exact.positions, 3 * exact.vertex_count * sizeof(float)));
            CHECK(!memcmp(m.indices, exact.indices, 3 * exact.triangle_count * sizeof(uint32_t)));
            CHECK(lv->distance.p99 == 0 && lv->distance.max == 0);
            continue;
        }
        double p99, max;
        size_t n;
        brute_one_way(&exact, &m, ISO_CHAIN_SPACING_VOXELS, &p99, &max, &n);
        CHECK_NEAR(lv->distance.p99_ab, p99, 1e-5);
        CHECK_NEAR(lv->distance.max_ab, max, 1e-5);
        brute_one_way(&m, &exact, ISO_CHAIN_SPACING_VOXELS, &p99, &max, &n);
        CHECK_NEAR(lv->distance.p99_ba, p99, 1e-5);
        CHECK_NEAR(lv->distance.max_ba, max, 1e-5);
        CHECKF(lv->distance.p99 > chain->level[k - 1].distance.p99 * 0.9,
               "level %d p99 %g after %g", k, lv->distance.p99, chain->level[k - 1].distance.p99);
    }
    /* Picks: the coarsest level within a distance; the finest within a budget. */
    for (int k = 1; k < chain->levels; k++) {
        int j = iso_mesh_chain_pick_distance(chain, chain->level[k].distance.p99);
        CHECK(chain->level[j].distance.p99 <= chain->level[k].distance.p99);
        CHECK(chain->level[j].triangle_count <= chain->level[k].triangle_count);
        CHECK_EQ(iso_mesh_chain_pick_budget(chain, chain->level[k].triangle_count), k);
        CHECK_EQ(iso_mesh_chain_pick_budget(chain, chain->level[k].triangle_count - 1),
                 k + 1 < chain->levels ? k + 1 : k);
    }
    CHECK_EQ(iso_mesh_chain_pick_distance(chain, 0), 0);
    CHECK_EQ(iso_mesh_chain_pick_distance(chain, 1e9), chain->levels - 1);
    CHECK_EQ(iso_mesh_chain_pick_budget(chain, exact.triangle_count), 0);
    CHECK_EQ(iso_mesh_chain_mesh(chain, chain->levels, &m, &err), ISO_E_ARGUMENT);
    /* An empty surface (a level outside the values) has a chain of its level 0 alone. */
    iso_mesh empty;
    iso_mesh_init(&empty);
    iso_mesh_chain *none = NULL;
    CHECK_OK(iso_mesh_chain_build(&empty, 1, 0, &none, &err), &err);
    CHECK(none && none->levels == 1 && iso_mesh_chain_pick_distance(none, 1) == 0 &&
          iso_mesh_chain_pick_budget(none, 1) == 0);
    CHECK_OK(iso_mesh_chain_mesh(none, 0, &m, &err), &err);
    CHECK(m.triangle_count == 0 && m.vertex_count == 0);
    iso_mesh_chain_destroy(none);
    free(sorted);
    iso_mesh_chain_destroy(chain);
    iso_mesh_free(&m);
    iso_mesh_free(&exact);
    iso_vol_destroy(vol);
}

/* A sphere of 40,000 triangles and more, its chain built on two threads: every level is
 * still closed and within its share of the triangles, every vertex is an exact vertex, and
 * each level's stored distance is what a fresh measure gives; the one-thread chain beside
 * it gives the same counts. */
static void test_chain_in_slabs_stays_closed(void)
{
    iso_error err;
    iso_mesh exact, m;
    iso_volume *vol = field_surface("field:sphere:96", 3.0, &exact);
    if (!vol)
        return;
    iso_mesh_init(&m);
    CHECKF(exact.triangle_count >= 40000, "%zu triangles", exact.triangle_count);
    iso_mesh_chain *two = NULL, *one = NULL;
    CHECK_OK(iso_mesh_chain_build(&exact, 1, 2, &two, &err), &err);
    CHECK_OK(iso_mesh_chain_build(&exact, 1, 1, &one, &err), &err);
    if (!two || !one)
        return;
    float *sorted = malloc(3 * exact.vertex_count * sizeof *sorted);
    memcpy(sorted, exact.positions, 3 * exact.vertex_count * sizeof *sorted);
    qsort(sorted, exact.vertex_count, 3 * sizeof(float), by_position);
    for (int k = 1; k < two->levels && !check_failed(); k++) {
        const iso_mesh_chain_level *lv = &two->level[k];
        CHECK_OK(iso_mesh_chain_mesh(two, k, &m, &err), &err);
        size_t target = iso_mesh_chain_target(exact.triangle_count, k);
        CHECKF(lv->triangle_count <= target && lv->triangle_count >= target * 9 / 10,
               "level %d: %zu triangles of %zu", k, lv->triangle_count, exact.triangle_count);
        CHECKF(lv->triangle_count * 10 >= one->level[k].triangle_count * 9, "level %d: %zu and %zu", k,
               lv->triangle_count, one->level[k].triangle_count);
        iso_census c;
        CHECK_OK(iso_census_compute(vol, &m, ISO_SPACE_INDEX, &c, &err), &err);
        CHECKF(c.closed, "level %d: open %zu, non-manifold %zu, misoriented %zu", k, c.open_edges,
               c.nonmanifold_edges, c.misoriented_edges);
        CHECK_EQ(euler_of(&m), 2);
        check_level_vertices(&exact, sorted, two, k, &m);
        iso_mesh_distance d;
        CHECK_OK(iso_mesh_distance_compute(&exact, &m, ISO_CHAIN_SPACING_VOXELS, 1, &d, &err), &err);
        CHECK(d.p99 == lv->distance.p99 && d.max == lv->distance.max);
        CHECKF(lv->distance.p99 <= 2 * one->level[k].distance.p99 + 0.01, "level %d: p99 %g against %g", k,
               lv->distance.p99, one->level[k].distance.p99);
    }
    free(sorted);
    iso_mesh_chain_destroy(two);
    iso_mesh_chain_destroy(one);
    iso_mesh_free(&m);
    iso_mesh_free(&exact);
    iso_vol_destroy(vol);
}

/* A view of chain level k over the chain's positions (nothing owned). */
static iso_mesh level_view(const iso_mesh_chain *chain, int k)
{
    iso_mesh m;
    iso_mesh_init(&m);
    m.positions = chain->positions;
    m.vertex_count = chain->vertex_count;
    m.indices = chain->level[k].indices;
    m.triangle_count = chain->level[k].triangle_count;
    return m;
}

/* Every bound (squared, per triangle of b) at least its triangle's largest sample distance
 * to a by brute force (s: scratch). */
static void check_bounds(const iso_mesh *b, const iso_mesh *a, double spacing, const double *bound, int k,
                         sample **s, size_t *scap)
{
    for (size_t t = 0; t < b->triangle_count && !check_failed(); t++) {
        size_t n = 0;
        brute_triangle(b, t, a, spacing, s, &n, scap);
        double most = 0;
        for (size_t i = 0; i < n; i++)
            most = fmax(most, (*s)[i].d);
        CHECKF(most <= sqrt(bound[t]) + 1e-6, "level %d triangle %zu: %g past its bound %g", k, t, most,
               sqrt(bound[t]));
    }
}

/* The small sphere's measures: a cap small enough that the maximum takes its own pass. */
static const size_t cap = 64;
static const double spacing = 1.5;

/* The sphere of radius 3 in field:sphere:24: its exact surface and its chain (one thread).
 * Returns the volume (the caller destroys it and the chain), or NULL when a CHECK failed. */
static iso_volume *small_sphere_chain(iso_mesh *exact, iso_mesh_chain **chain)
{
    iso_error err;
    iso_volume *vol = field_surface("field:sphere:24", 3.0, exact);
    if (!vol)
        return NULL;
    CHECK_OK(iso_mesh_chain_build(exact, 1, 1, chain, &err), &err);
    if (!*chain) {
        iso_mesh_free(exact);
        iso_vol_destroy(vol);
        return NULL;
    }
    return vol;
}

/* The reuse between a chain's levels (distance.h), with a cap small enough that the
 * maximum takes its own pass: level k measured with level k - 1's bounds gives bit for bit
 * what it gives alone; every bound it leaves is at least its triangle's largest centroid
 * distance by brute force; some triangles are matched; and a false bound (0 for every
 * prior triangle) is taken as given for every matched triangle, so the skip is what ran. */
static void test_reuse_between_levels_changes_nothing(void)
{
    iso_error err;
    iso_mesh exact;
    iso_mesh_chain *chain = NULL;
    iso_volume *vol = small_sphere_chain(&exact, &chain);
    if (!vol)
        return;
    iso_mesh a = level_view(chain, 0);
    double *prior = NULL, *zeros = calloc(exact.triangle_count, sizeof *zeros);
    size_t matched_total = 0, scap = 64;
    sample *s = malloc(scap * sizeof *s);
    for (int k = 1; k < chain->levels && !check_failed(); k++) {
        iso_mesh b = level_view(chain, k), p = level_view(chain, k - 1);
        double *bound = malloc(b.triangle_count * sizeof *bound);
        iso_mesh_distance_reuse reuse = {.prior_indices = p.indices, .prior_triangles = p.triangle_count,
                                         .prior_bound = prior, .bound = bound};
        iso_mesh_distance alone, with;
        CHECK_OK(iso_mesh_distance_between(&a, NULL, &b, NULL, spacing, cap, 1, NULL, &alone, &err), &err);
        CHECK_OK(iso_mesh_distance_between(&a, NULL, &b, NULL, spacing, cap, 1, &reuse, &with, &err), &err);
        CHECK_EQ(alone.drawn_b, cap);
        CHECK(alone.p99 == with.p99 && alone.max == with.max && alone.max_ba == with.max_ba &&
              alone.p99_ba == with.p99_ba && alone.mean == with.mean);
        check_bounds(&b, &a, spacing, bound, k, &s, &scap);
        /* The prior's triangles matched here: those the false bound must reach. */
        double *told = malloc(b.triangle_count * sizeof *told);
        reuse.prior_bound = zeros, reuse.bound = told;
        CHECK_OK(iso_mesh_distance_between(&a, NULL, &b, NULL, spacing, cap, 1, &reuse, &with, &err), &err);
        size_t matched = 0, zero = 0;
        for (size_t t = 0; t < b.triangle_count; t++) {
            int same = 0;
            for (size_t q = 0; q < p.triangle_count && !same; q++)
                same = !memcmp(b.indices + 3 * t, p.indices + 3 * q, 3 * sizeof *b.indices);
            matched += same;
            zero += same && told[t] == 0;
        }
        CHECKF(zero == matched, "level %d: %zu of %zu matched triangles took the given bound", k, zero, matched);
        matched_total += matched;
        free(told);
        free(prior);
        prior = bound;
    }
    CHECKF(matched_total > 0, "no triangle kept from one level to the next");
    free(prior);
    free(zeros);
    free(s);
    iso_mesh_chain_destroy(chain);
    iso_mesh_free(&exact);
    iso_vol_destroy(vol);
}

/* m's triangles and vertices into out (initialised here), with a tetrahedron of side 1
 * at (x, 0, 0) added before them: a speck far from the rest, as CT noise leaves, whose
 * samples come first. */
static void with_speck(const iso_mesh *m, double x, iso_mesh *out)
{
    iso_mesh_init(out);
    CHECK(iso_mesh_reserve(out, m->vertex_count + 4, m->triangle_count + 4) == 0);
    memcpy(out->positions, m->positions, 3 * m->vertex_count * sizeof(float));
    memcpy(out->indices + 12, m->indices, 3 * m->triangle_count * sizeof(uint32_t));
    float p[12] = {(float)x, 0, 0, (float)x + 1, 0, 0, (float)x, 1, 0, (float)x, 0, 1};
    uint32_t v = (uint32_t)m->vertex_count, t[12] = {v, v + 2, v + 1, v, v + 1, v + 3, v, v + 3, v + 2,
                                                     v + 1, v + 2, v + 3};
    memcpy(out->positions + 3 * m->vertex_count, p, sizeof p);
    memcpy(out->indices, t, sizeof t);
    out->vertex_count = m->vertex_count + 4;
    out->triangle_count = m->triangle_count + 4;
}

/* The block tests of the maximum's pass (distance.c, PASS 5) against every sample searched
 * alone: a sphere's chain levels against the exact sphere, a speck 30 voxels off added to
 * the level on odd levels and to the exact side on even ones (so that the maximum is large
 * one way and whole blocks of samples fall within it), at a cap small enough that the maximum takes its own
 * pass. Every distance is the same bit for bit, on one thread and two; every bound a
 * block leaves is at least its triangle's largest sample distance by brute force; and
 * some bounds differ from the exhaustive pass's (so the blocks are what ran). */
static void test_block_bounds_change_nothing(void)
{
    iso_error err;
    iso_mesh exact, specked;
    iso_mesh_chain *chain = NULL;
    iso_volume *vol = small_sphere_chain(&exact, &chain);
    if (!vol)
        return;
    size_t differ = 0, scap = 64;
    sample *s = malloc(scap * sizeof *s);
    with_speck(&exact, -30, &specked);
    for (int k = 1; k < chain->levels && !check_failed(); k++) {
        iso_mesh level = level_view(chain, k), b;
        if (k % 2) /* the speck on the level's side on odd levels, on the exact side on even */
            with_speck(&level, -30, &b);
        else
            b = level;
        const iso_mesh *a = k % 2 ? &exact : &specked;
        double *fast = malloc(b.triangle_count * sizeof *fast), *slow = malloc(b.triangle_count * sizeof *slow);
        iso_mesh_distance_reuse all = {.exhaustive = 1, .bound = slow}, blocks = {.bound = fast};
        iso_mesh_distance one, two, alone;
        CHECK_OK(iso_mesh_distance_between(a, NULL, &b, NULL, spacing, cap, 1, &all, &alone, &err), &err);
        CHECK_OK(iso_mesh_distance_between(a, NULL, &b, NULL, spacing, cap, 1, &blocks, &one, &err), &err);
        CHECK_OK(iso_mesh_distance_between(a, NULL, &b, NULL, spacing, cap, 2, NULL, &two, &err), &err);
        CHECK(alone.drawn_a == cap && alone.drawn_b == cap);
        CHECKF((k % 2 ? alone.max_ba : alone.max_ab) > 25, "level %d: max %g, %g", k, alone.max_ab,
               alone.max_ba);
        CHECK(alone.p99_ab == one.p99_ab && alone.p99_ba == one.p99_ba && alone.max_ab == one.max_ab &&
              alone.max_ba == one.max_ba && alone.mean == one.mean);
        CHECK(one.p99_ab == two.p99_ab && one.p99_ba == two.p99_ba && one.max_ab == two.max_ab &&
              one.max_ba == two.max_ba && one.mean == two.mean);
        for (size_t t = 0; t < b.triangle_count; t++)
            differ += fast[t] != slow[t];
        check_bounds(&b, a, spacing, fast, k, &s, &scap);
        free(fast);
        free(slow);
        if (k % 2)
            iso_mesh_free(&b);
    }
    CHECKF(differ > 0, "no block test skipped a triangle");
    free(s);
    iso_mesh_free(&specked);
    iso_mesh_chain_destroy(chain);
    iso_mesh_free(&exact);
    iso_vol_destroy(vol);
}

/* The percentile by selection (distance.h, without_mean): on the small sphere's chain
 * levels against the exact sphere, at caps of 256 and 2,048 drawn points (so that the
 * top 1% is 3 and 21 points), every p99 and maximum is what measuring every point gives,
 * bit for bit, on one thread and two, and the mean is NAN. */
static void test_selected_percentile_is_exact(void)
{
    iso_mesh_distance_reuse select = {.without_mean = 1};
    iso_mesh_chain *chain = NULL;
    iso_mesh exact;
    iso_volume *vol = small_sphere_chain(&exact, &chain);
    if (!vol)
        return;
    iso_error err;
    for (int k = 1; k < chain->levels && !check_failed(); k++)
        for (size_t drawn = 256; drawn <= 2048; drawn *= 8) {
            iso_mesh b = level_view(chain, k);
            iso_mesh_distance all, one, two;
            CHECK_OK(iso_mesh_distance_between(&exact, NULL, &b, NULL, 0.5, drawn, 1, NULL, &all, &err), &err);
            CHECK_OK(iso_mesh_distance_between(&exact, NULL, &b, NULL, 0.5, drawn, 1, &select, &one, &err), &err);
            CHECK_OK(iso_mesh_distance_between(&exact, NULL, &b, NULL, 0.5, drawn, 2, &select, &two, &err), &err);
            CHECKF(all.drawn_a == drawn && all.drawn_b == drawn, "level %d: drawn %zu, %zu", k, all.drawn_a,
                   all.drawn_b);
            CHECKF(all.p99_ab > 0 && all.p99_ba > 0 && isfinite(all.mean), "level %d: p99 %g, %g", k,
                   all.p99_ab, all.p99_ba);
            CHECKF(all.p99_ab == one.p99_ab && all.p99_ba == one.p99_ba && all.max_ab == one.max_ab &&
                   all.max_ba == one.max_ba, "level %d, %zu drawn: p99 %.9g %.9g, selected %.9g %.9g", k,
                   drawn, all.p99_ab, all.p99_ba, one.p99_ab, one.p99_ba);
            CHECK(two.p99_ab == one.p99_ab && two.p99_ba == one.p99_ba && two.max == one.max);
            CHECK(isnan(one.mean) && isnan(one.mean_ab) && isnan(two.mean_ba));
        }
    iso_mesh_chain_destroy(chain);
    iso_mesh_free(&exact);
    iso_vol_destroy(vol);
}

/* The chain's steps on a torus of about 10,000 triangles: every level has 0.6 to 0.8 of
 * the triangles of the one before (1/sqrt(2) asked), measured p99 distances never fall
 * from one level to the next, and doubling the distance of a level past 1 picks another,
 * coarser level. */
static void test_chain_steps_are_fine(void)
{
    iso_error err;
    iso_mesh exact;
    iso_volume *vol = field_surface("field:torus:64", 1.0, &exact);
    if (!vol)
        return;
    iso_mesh_chain *chain = NULL;
    CHECK_OK(iso_mesh_chain_build(&exact, 1, 2, &chain, &err), &err);
    if (!chain)
        return;
    CHECKF(exact.triangle_count >= 8000, "%zu triangles", exact.triangle_count);
    CHECK_EQ(chain->levels, ISO_CHAIN_LEVELS + 1);
    CHECK_EQ(chain->partial, 0);
    for (int k = 1; k < chain->levels; k++) {
        const iso_mesh_chain_level *lv = &chain->level[k], *prev = &chain->level[k - 1];
        double ratio = (double)lv->triangle_count / (double)prev->triangle_count;
        printf("  level %d: %zu triangles (%.3f of the level before), p99 %.4f\n", k, lv->triangle_count, ratio,
               lv->distance.p99);
        CHECKF(ratio >= 0.6 && ratio <= 0.8, "level %d: %.3f of the level before", k, ratio);
        CHECKF(lv->distance.p99 >= prev->distance.p99, "level %d: p99 %g after %g", k, lv->distance.p99,
               prev->distance.p99);
        double d = lv->distance.p99;
        if (k >= 2 && k + 1 < chain->levels) /* level 1's p99 is near 0: level 2's is more than twice it */
            CHECKF(iso_mesh_chain_pick_distance(chain, 2 * d) > iso_mesh_chain_pick_distance(chain, d),
                   "level %d: %g and %g pick the same level", k, d, 2 * d);
    }
    iso_mesh_chain_destroy(chain);
    iso_mesh_free(&exact);
    iso_vol_destroy(vol);
}

/* Chains a and b have the same first `levels` levels: triangles, index arrays, measures
 * (a's maxima where it has them). */
static void check_same_levels(const iso_mesh_chain *a, const iso_mesh_chain *b, int levels)
{
    for (int k = 0; k < levels; k++) {
        const iso_mesh_chain_level *x = &a->level[k], *y = &b->level[k];
        CHECK_EQ(x->triangle_count, y->triangle_count);
        CHECK_EQ(x->vertex_count, y->vertex_count);
        CHECK_EQ(x->edges, y->edges);
        CHECKF(x->triangle_count == y->triangle_count &&
                   !memcmp(x->indices, y->indices, 3 * x->triangle_count * sizeof *x->indices),
               "level %d: other triangles", k);
        CHECKF(x->distance.p99 == y->distance.p99 &&
                   (isnan(x->distance.max) || x->distance.max == y->distance.max) &&
                   x->offset == y->offset && x->volume_change == y->volume_change,
               "level %d: p99 %g and %g, max %g and %g", k, x->distance.p99, y->distance.p99, x->distance.max,
               y->distance.max);
    }
}

/* A chain built only down to a request's level, then extended, is the full build's, level
 * for level; built for a distance only the answer's maximum is measured (the others come
 * with the extension); built for a budget it stops at the first level within it. */
static void test_partial_chain_then_extended(void)
{
    iso_error err;
    iso_mesh exact;
    iso_volume *vol = field_surface("field:torus:64", 1.0, &exact);
    if (!vol)
        return;
    iso_mesh_chain *full = NULL, *part = NULL, *budget = NULL;
    CHECK_OK(iso_mesh_chain_build(&exact, 1, 2, &full, &err), &err);
    if (!full)
        return;
    double d = full->level[5].distance.p99; /* level 6's is larger (test_chain_steps_are_fine) */
    CHECK_OK(iso_mesh_chain_build_until(&exact, 1, 2, d, 0, &part, &err), &err);
    CHECK_OK(iso_mesh_chain_build_until(&exact, 1, 2, -1, full->level[3].triangle_count, &budget, &err), &err);
    if (!part || !budget)
        return;
    CHECK_EQ(part->levels, 7);
    CHECK_EQ(part->partial, 1);
    CHECK(iso_mesh_chain_complete(full) && !iso_mesh_chain_complete(part));
    CHECK(iso_mesh_chain_covers(part, d, 0) && !iso_mesh_chain_covers(part, 2 * full->level[6].distance.p99, 0));
    CHECK_EQ(iso_mesh_chain_pick_distance(part, d), iso_mesh_chain_pick_distance(full, d));
    CHECK(part->bytes < full->bytes);
    check_same_levels(part, full, part->levels);
    for (int k = 1; k < part->levels; k++)
        CHECKF(isnan(part->level[k].distance.max) == (k != 5), "level %d: max %g", k, part->level[k].distance.max);
    for (int k = 1; k < budget->levels; k++)
        CHECK(!isnan(budget->level[k].distance.max));
    CHECK_EQ(budget->levels, 4);
    CHECK(budget->partial && iso_mesh_chain_covers(budget, -1, full->level[3].triangle_count));
    CHECK_EQ(iso_mesh_chain_pick_budget(budget, full->level[3].triangle_count), 3);
    check_same_levels(budget, full, budget->levels);
    /* A copy is extended alone (the server extends copies while readers keep the original):
     * it becomes the full chain, the original keeps its levels and missing maxima. */
    iso_mesh_chain *copy = NULL;
    CHECK_OK(iso_mesh_chain_copy(part, &copy, &err), &err);
    if (copy) {
        CHECK(!copy->grid && copy->partial && copy->levels == part->levels && copy->positions != part->positions);
        CHECK_OK(iso_mesh_chain_extend(copy, 2, &err), &err);
        CHECK(copy->levels == full->levels && iso_mesh_chain_complete(copy) && copy->bytes == full->bytes);
        check_same_levels(copy, full, full->levels);
        CHECK(part->levels == 7 && part->partial && isnan(part->level[1].distance.max));
        check_same_levels(part, full, part->levels);
    }
    iso_mesh_chain_destroy(copy);
    /* Covered: nothing to do; then the rest, from a chain with no bounds of its last level. */
    CHECK_OK(iso_mesh_chain_extend_until(part, 2, d, 0, &err), &err);
    CHECK_EQ(part->levels, 7);
    CHECK_OK(iso_mesh_chain_extend(part, 2, &err), &err);
    CHECK_OK(iso_mesh_chain_extend(budget, 1, &err), &err);
    CHECK_EQ(part->levels, full->levels);
    CHECK_EQ(budget->levels, full->levels);
    CHECK(!part->partial && !budget->partial && part->bytes == full->bytes);
    check_same_levels(part, full, full->levels);
    check_same_levels(budget, full, full->levels);
    for (int k = 1; k < part->levels; k++)
        CHECK(!isnan(part->level[k].distance.max));
    CHECK(iso_mesh_chain_complete(part) && iso_mesh_chain_complete(budget));
    /* Built for a distance every level is within: all levels made, not all maxima. */
    iso_mesh_chain *all = NULL;
    CHECK_OK(iso_mesh_chain_build_until(&exact, 1, 2, 1e30, 0, &all, &err), &err);
    if (all) {
        CHECK(all->levels == full->levels && !all->partial && !iso_mesh_chain_complete(all));
        CHECK(isnan(all->level[1].distance.max) && !isnan(all->level[all->levels - 1].distance.max));
        CHECK_OK(iso_mesh_chain_extend(all, 2, &err), &err);
        CHECK(iso_mesh_chain_complete(all));
        check_same_levels(all, full, full->levels);
    }
    iso_mesh_chain_destroy(all);
    CHECK_OK(iso_mesh_chain_extend(part, 2, &err), &err); /* complete: nothing to do */
    CHECK_EQ(part->levels, full->levels);
    iso_mesh_chain_destroy(part);
    iso_mesh_chain_destroy(budget);
    iso_mesh_chain_destroy(full);
    iso_mesh_free(&exact);
    iso_vol_destroy(vol);
}

int main(void)
{
    CHECK_RUN(test_parallel_squares_are_a_quarter_apart);
    CHECK_RUN(test_square_against_its_half);
    CHECK_RUN(test_point_against_each_feature);
    CHECK_RUN(test_simplified_sphere_matches_brute_force);
    CHECK_RUN(test_drawn_percentile_is_within_its_stated_error);
    CHECK_RUN(test_chain_levels_are_measured_and_closed);
    CHECK_RUN(test_chain_in_slabs_stays_closed);
    CHECK_RUN(test_chain_steps_are_fine);
    CHECK_RUN(test_partial_chain_then_extended);
    CHECK_RUN(test_reuse_between_levels_changes_nothing);
    CHECK_RUN(test_block_bounds_change_nothing);
    CHECK_RUN(test_selected_percentile_is_exact);
    return check_finish();
}
