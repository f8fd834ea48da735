/* test_simplify.c: meshoptimizer's simplifier on iso_meshes, and the budget policy.
 *
 * Hand-built meshes with exact answers (a flat square of 128 triangles becomes 2 with
 * error 0; a mesh within its target is not touched, byte for byte); analytic fields whose
 * simplified surfaces keep their topology and stay within the reported error of the exact
 * surface (distances measured here, point to triangle); the budget policy's two paths;
 * and CThead's skin, where the open edges on the volume's border come out exactly as they
 * went in and every edge stays paired. */
#include <float.h>
#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "mesh/mesh.h"
#include "mesh/collapse.h"
#include "check.h"
#include "extract/extract.h"
#include "io/io.h"
#include "surface.h"
#include "hierarchy/tree.h"

/* ---- helpers ---- */

/* An n x n grid of vertices on z = 0, spacing 1, two triangles per square, wound so that
 * normals point to +z. */
static void flat_square(iso_mesh *m, int n)
{
    iso_mesh_init(m);
    CHECK(iso_mesh_reserve(m, (size_t)(n * n), (size_t)(2 * (n - 1) * (n - 1))) == 0);
    for (int j = 0; j < n; j++)
        for (int i = 0; i < n; i++) {
            float *p = m->positions + 3 * (size_t)(j * n + i);
            p[0] = (float)i, p[1] = (float)j, p[2] = 0;
        }
    m->vertex_count = (size_t)(n * n);
    uint32_t *t = m->indices;
    for (int j = 0; j + 1 < n; j++)
        for (int i = 0; i + 1 < n; i++) {
            uint32_t a = (uint32_t)(j * n + i), b = a + 1, c = a + (uint32_t)n, d = c + 1;
            *t++ = a, *t++ = b, *t++ = d;
            *t++ = a, *t++ = d, *t++ = c;
        }
    m->triangle_count = (size_t)(2 * (n - 1) * (n - 1));
}

static double dot3(const double a[3], const double b[3])
{
    return a[0] * b[0] + a[1] * b[1] + a[2] * b[2];
}

/* Distance from p to triangle abc (Ericson, Real-Time Collision Detection, 5.1.5). */
static double point_triangle(const double p[3], const double a[3], const double b[3], const double c[3])
{
    double ab[3], ac[3], ap[3], q[3];
    for (int k = 0; k < 3; k++)
        ab[k] = b[k] - a[k], ac[k] = c[k] - a[k], ap[k] = p[k] - a[k];
    double d1 = dot3(ab, ap), d2 = dot3(ac, ap);
    if (d1 <= 0 && d2 <= 0) {
        memcpy(q, a, sizeof q);
        goto done;
    }
    double bp[3], cp[3];
    for (int k = 0; k < 3; k++)
        bp[k] = p[k] - b[k], cp[k] = p[k] - c[k];
    double d3 = dot3(ab, bp), d4 = dot3(ac, bp), d5 = dot3(ab, cp), d6 = dot3(ac, cp);
    double vc = d1 * d4 - d3 * d2, vb = d5 * d2 - d1 * d6, va = d3 * d6 - d5 * d4;
    if (d3 >= 0 && d4 <= d3)
        memcpy(q, b, sizeof q);
    else if (d6 >= 0 && d5 <= d6)
        memcpy(q, c, sizeof q);
    else if (vc <= 0 && d1 >= 0 && d3 <= 0)
        for (int k = 0; k < 3; k++) q[k] = a[k] + d1 / (d1 - d3) * ab[k];
    else if (vb <= 0 && d2 >= 0 && d6 <= 0)
        for (int k = 0; k < 3; k++) q[k] = a[k] + d2 / (d2 - d6) * ac[k];
    else if (va <= 0 && d4 - d3 >= 0 && d5 - d6 >= 0) {
        double w = (d4 - d3) / ((d4 - d3) + (d5 - d6));
        for (int k = 0; k < 3; k++) q[k] = b[k] + w * (c[k] - b[k]);
    } else {
        double den = 1 / (va + vb + vc), v = vb * den, w = vc * den;
        for (int k = 0; k < 3; k++) q[k] = a[k] + ab[k] * v + ac[k] * w;
    }
done:;
    double d[3] = {p[0] - q[0], p[1] - q[1], p[2] - q[2]};
    return sqrt(dot3(d, d));
}

static void corner(const iso_mesh *m, size_t t, int k, double out[3])
{
    const float *p = m->positions + 3 * (size_t)m->indices[3 * t + k];
    out[0] = p[0], out[1] = p[1], out[2] = p[2];
}

static double point_mesh(const double p[3], const iso_mesh *m)
{
    double best = INFINITY;
    for (size_t t = 0; t < m->triangle_count; t++) {
        double a[3], b[3], c[3];
        corner(m, t, 0, a), corner(m, t, 1, b), corner(m, t, 2, c);
        double d = point_triangle(p, a, b, c);
        if (d < best)
            best = d;
    }
    return best;
}

/* The one-sided distances that matter, by brute force: from every vertex of `exact` to
 * the surface of `simple`, and from the centroid and edge midpoints of every triangle of
 * `simple` to the surface of `exact`. The larger of the two maxima. */
static double measured_distance(const iso_mesh *exact, const iso_mesh *simple)
{
    double worst = 0;
    for (size_t v = 0; v < exact->vertex_count; v++) {
        const float *f = exact->positions + 3 * v;
        double p[3] = {f[0], f[1], f[2]};
        worst = fmax(worst, point_mesh(p, simple));
    }
    for (size_t t = 0; t < simple->triangle_count; t++) {
        double c[3][3], p[3];
        for (int k = 0; k < 3; k++)
            corner(simple, t, k, c[k]);
        for (int s = 0; s < 4; s++) {
            for (int d = 0; d < 3; d++)
                p[d] = s == 3 ? (c[0][d] + c[1][d] + c[2][d]) / 3 : (c[s][d] + c[(s + 1) % 3][d]) / 2;
            worst = fmax(worst, point_mesh(p, exact));
        }
    }
    return worst;
}

static long euler_characteristic(const iso_mesh *m)
{
    iso_mesh_edges e;
    CHECK(iso_mesh_count_edges(m, &e) == 0);
    return (long)m->vertex_count - (long)e.edges + (long)m->triangle_count;
}

static iso_mesh copy_mesh(const iso_mesh *m)
{
    iso_mesh c;
    iso_mesh_init(&c);
    CHECK(iso_mesh_reserve(&c, m->vertex_count, m->triangle_count) == 0);
    memcpy(c.positions, m->positions, 3 * m->vertex_count * sizeof(float));
    memcpy(c.indices, m->indices, 3 * m->triangle_count * sizeof(uint32_t));
    c.vertex_count = m->vertex_count;
    c.triangle_count = m->triangle_count;
    return c;
}

/* ---- hand-built meshes ---- */

/* 9 x 9 vertices, 128 triangles, all in one plane: every interior and edge vertex can go
 * at no error, leaving the 4 corners and 2 triangles of the same area and winding. */
static void test_flat_square_becomes_two_triangles(void)
{
    iso_mesh m;
    flat_square(&m, 9);
    iso_simplify_params p = {.target_triangles = 2, .target_error = INFINITY};
    iso_simplify_result r;
    iso_error err;
    CHECK_OK(iso_simplify(&m, &p, &r, &err), &err);
    CHECK_EQ(r.triangles_in, 128);
    CHECK_EQ(r.vertices_in, 81);
    CHECK_EQ(m.triangle_count, 2);
    CHECK_EQ(m.vertex_count, 4);
    CHECK_EQ(r.triangles, 2);
    CHECK_EQ(r.vertices, 4);
    CHECK(r.error < 1e-5);
    CHECK_NEAR(iso_mesh_area(&m), 64, 1e-9);
    for (size_t v = 0; v < 4; v++) {
        const float *q = m.positions + 3 * v;
        CHECKF((q[0] == 0 || q[0] == 8) && (q[1] == 0 || q[1] == 8) && q[2] == 0,
               "vertex %zu at (%g, %g, %g) is not a corner", v, q[0], q[1], q[2]);
    }
    /* The winding survives: both triangles' normals still point to +z. */
    for (size_t t = 0; t < 2; t++) {
        double a[3], b[3], c[3];
        corner(&m, t, 0, a), corner(&m, t, 1, b), corner(&m, t, 2, c);
        CHECK((b[0] - a[0]) * (c[1] - a[1]) - (b[1] - a[1]) * (c[0] - a[0]) > 0);
    }
    CHECK_EQ(r.folds_dropped, 0);
    CHECK_EQ(r.nonmanifold_edges, 0);
    CHECK_EQ(r.unpaired_edges, 0);
    iso_mesh_free(&m);
}

/* With the border locked the 32 border vertices stay where they are, and only the 49
 * interior ones go: a fan over a 32-gon, 30 triangles, the same area. */
static void test_locked_border_keeps_the_rim(void)
{
    iso_mesh m;
    flat_square(&m, 9);
    iso_simplify_params p = {.target_triangles = 2, .target_error = INFINITY, .lock_border = 1};
    iso_simplify_result r;
    iso_error err;
    CHECK_OK(iso_simplify(&m, &p, &r, &err), &err);
    CHECK_EQ(m.vertex_count, 32);
    CHECK_EQ(m.triangle_count, 30);
    CHECK(r.error < 1e-5);
    CHECK_NEAR(iso_mesh_area(&m), 64, 1e-9);
    for (size_t v = 0; v < m.vertex_count; v++) {
        const float *q = m.positions + 3 * v;
        CHECKF(q[0] == 0 || q[0] == 8 || q[1] == 0 || q[1] == 8, "vertex (%g, %g) is inside", q[0], q[1]);
    }
    iso_mesh_edges e;
    CHECK(iso_mesh_count_edges(&m, &e) == 0);
    CHECK_EQ(e.open, 32);
    CHECK_EQ(e.nonmanifold + e.misoriented, 0);
    iso_mesh_free(&m);
}

/* A target at or above the count, or an error limit of 0 on a curved surface, changes
 * nothing: the same bytes come back. */
static void test_within_target_is_untouched(void)
{
    iso_mesh m;
    flat_square(&m, 5);
    iso_mesh before = copy_mesh(&m);
    iso_error err;
    iso_simplify_result r;
    size_t targets[] = {32, 33, 1000000};
    for (size_t i = 0; i < 3; i++) {
        iso_simplify_params p = {.target_triangles = targets[i], .target_error = INFINITY};
        CHECK_OK(iso_simplify(&m, &p, &r, &err), &err);
        CHECK_EQ(m.triangle_count, 32);
        CHECK_EQ(m.vertex_count, 25);
        CHECK(!memcmp(m.positions, before.positions, 25 * 3 * sizeof(float)));
        CHECK(!memcmp(m.indices, before.indices, 32 * 3 * sizeof(uint32_t)));
        CHECK(r.error == 0 && r.triangles == 32 && r.triangles_in == 32);
    }
    /* Bend the square into a roof along x = 2: with error 0 only lossless collapses go
     * (meshoptimizer's float quadrics leave a few more than the 4 triangles of two
     * rectangles), so the roof is still exactly the roof. */
    for (size_t v = 0; v < m.vertex_count; v++)
        m.positions[3 * v + 2] = fabsf(m.positions[3 * v] - 2.0f);
    iso_mesh roof = copy_mesh(&m);
    iso_simplify_params p = {.target_triangles = 1, .target_error = 0};
    CHECK_OK(iso_simplify(&m, &p, &r, &err), &err);
    CHECKF(m.triangle_count >= 4 && m.triangle_count < 32, "%zu triangles", m.triangle_count);
    CHECK_NEAR(iso_mesh_area(&m), 16 * sqrt(2), 1e-5);
    CHECK(measured_distance(&roof, &m) < 1e-6);
    iso_mesh_free(&roof);
    iso_mesh_free(&m);
    iso_mesh_free(&before);
}

static void test_bad_parameters(void)
{
    iso_mesh m;
    flat_square(&m, 3);
    iso_error err;
    iso_simplify_params zero = {.target_triangles = 0, .target_error = 1};
    CHECK_EQ(iso_simplify(&m, &zero, NULL, &err), ISO_E_ARGUMENT);
    CHECK(strstr(err.message, "at least 1") != NULL);
    iso_simplify_params nan = {.target_triangles = 1, .target_error = NAN};
    CHECK_EQ(iso_simplify(&m, &nan, NULL, &err), ISO_E_ARGUMENT);
    iso_simplify_params negative = {.target_triangles = 1, .target_error = -1};
    CHECK_EQ(iso_simplify(&m, &negative, NULL, &err), ISO_E_ARGUMENT);
    iso_simplify_params voxel = {.target_triangles = 1, .target_error = 1, .voxel_size = -2};
    CHECK_EQ(iso_simplify(&m, &voxel, NULL, &err), ISO_E_ARGUMENT);
    CHECK_EQ(m.triangle_count, 8); /* untouched by every refusal */
    iso_mesh_free(&m);
}

/* Normals travel with their vertices through the compaction. */
static void test_normals_follow_vertices(void)
{
    iso_mesh m;
    flat_square(&m, 6);
    m.normals = malloc(m.vertex_capacity * 3 * sizeof(float));
    CHECK(m.normals != NULL);
    for (size_t v = 0; v < m.vertex_count; v++) /* a normal that names its position */
        for (int k = 0; k < 3; k++)
            m.normals[3 * v + k] = m.positions[3 * v + k] * 10 + (float)k;
    iso_simplify_params p = {.target_triangles = 2, .target_error = INFINITY};
    iso_error err;
    CHECK_OK(iso_simplify(&m, &p, NULL, &err), &err);
    CHECK_EQ(m.vertex_count, 4);
    for (size_t v = 0; v < m.vertex_count; v++)
        for (int k = 0; k < 3; k++)
            CHECK(m.normals[3 * v + k] == m.positions[3 * v + k] * 10 + (float)k);
    iso_mesh_free(&m);
}

/* ---- the collapser's order ---- */

/* A regular octahedron of radius r at x = cx, vertices base.. (+x, -x, +y, -y, +z, -z),
 * wound outward. Each vertex's cheapest collapse costs 2 r^2 / 3: its quadric's four
 * planes, two of which pass through any neighbour and two lie 2 r / sqrt(3) from it. */
static void add_octahedron(iso_mesh *m, double cx, double r)
{
    uint32_t base = (uint32_t)m->vertex_count;
    for (int axis = 0; axis < 3; axis++)
        for (int sign = 1; sign >= -1; sign -= 2) {
            float *p = m->positions + 3 * m->vertex_count++;
            p[0] = (float)cx, p[1] = 0, p[2] = 0;
            p[axis] += (float)(sign * r);
        }
    for (int sx = 0; sx < 2; sx++)
        for (int sy = 0; sy < 2; sy++)
            for (int sz = 0; sz < 2; sz++) {
                uint32_t *t = m->indices + 3 * m->triangle_count++;
                uint32_t x = base + (uint32_t)sx, y = base + 2 + (uint32_t)sy, z = base + 4 + (uint32_t)sz;
                int outward = (sx + sy + sz) % 2 == 0; /* an even count of minus signs */
                t[0] = x, t[1] = outward ? y : z, t[2] = outward ? z : y;
            }
}

/* Triangles of the output (iso_collapser_triangles) all of whose corners are below n. */
static size_t triangles_below(const uint32_t *t, size_t count, uint32_t n)
{
    size_t k = 0;
    for (size_t i = 0; i < count; i++)
        k += t[3 * i] < n && t[3 * i + 1] < n && t[3 * i + 2] < n;
    return k;
}

/* Two octahedra whose collapses cost 1.5 (A, vertices 0..5) and 1.2 (B, 6..11): one
 * factor-of-2 class. One collapse is asked for. In cost order (the default, and with a
 * coarse share of 0.5: the run's expected last cost is B's, so both keys rank fine) B's
 * goes; with share 2 both rank in the coarse class, where vertex order puts A first.
 * Each way the collapse leaves its octahedron 6 triangles, the other 8, and the
 * collapser's error is that collapse's cost, to float rounding. */
static void test_coarse_classes_go_in_vertex_order(void)
{
    const double share[3] = {0, 0.5, 2};
    const size_t a_left[3] = {8, 8, 6};
    for (int i = 0; i < 3; i++) {
        iso_mesh m;
        iso_mesh_init(&m);
        CHECK(iso_mesh_reserve(&m, 12, 16) == 0);
        add_octahedron(&m, 0, sqrt(2.25));
        add_octahedron(&m, 10, sqrt(1.8));
        iso_collapser *c;
        int pinch_free;
        CHECK(iso_collapser_create(&m, &c, &pinch_free) == 0);
        CHECK_EQ(pinch_free, 1);
        CHECK(fabs(iso_collapser_next(c) - sqrt(1.2)) < 1e-6);
        iso_collapser_coarse(c, share[i], 14);
        CHECK_EQ(iso_collapser_run(c, 14, INFINITY), 14);
        uint32_t out[3 * 14];
        iso_collapser_triangles(c, out);
        CHECKF(triangles_below(out, 14, 6) == a_left[i], "share %g: A has %zu triangles", share[i],
               triangles_below(out, 14, 6));
        double cost = a_left[i] == 6 ? 1.5 : 1.2;
        CHECKF(fabs(iso_collapser_error(c) - sqrt(cost)) < 1e-6, "share %g: error %g", share[i],
               iso_collapser_error(c));
        iso_collapser_destroy(c);
        iso_mesh_free(&m);
    }
}

/* ---- analytic fields ---- */

static iso_tree *field_tree(const char *path, iso_volume **vol)
{
    iso_error err;
    *vol = NULL;
    CHECK_OK(iso_field_load(path, NULL, vol, &err), &err);
    if (!*vol)
        return NULL;
    iso_vol_update_stats(*vol);
    return surface_build(*vol);
}

/* Sphere and torus: the simplified surface has at most N triangles, the same topology
 * (Euler characteristic 2 and 0, closed, every edge paired), every vertex still within the
 * extraction's error bound of the level, and every measured distance to the exact surface
 * within the error meshoptimizer reports. */
static void test_analytic_fields_stay_within_reported_error(void)
{
    struct { const char *field; double level; long euler; size_t budget; } cases[] = {
        {"field:sphere:40", 3.0, 2, 600},
        {"field:torus:48", 1.0, 0, 900},
    };
    for (size_t i = 0; i < 2 && !check_failed(); i++) {
        iso_volume *vol;
        iso_tree *tree = field_tree(cases[i].field, &vol);
        if (!tree)
            return;
        iso_mesh exact, m;
        iso_mesh_init(&exact);
        iso_extract_stats st;
        iso_error err;
        iso_extract_params xp = {.level = cases[i].level, .space = ISO_SPACE_INDEX};
        CHECK_OK(iso_extract(tree, &xp, &exact, &st, &err), &err);
        CHECK_EQ(euler_characteristic(&exact), cases[i].euler);
        CHECKF(exact.triangle_count > 4 * cases[i].budget, "%s: only %zu triangles", cases[i].field,
               exact.triangle_count);
        m = copy_mesh(&exact);
        iso_simplify_params p = {.target_triangles = cases[i].budget, .target_error = INFINITY,
                                 .lock_border = 1};
        iso_simplify_result r;
        CHECK_OK(iso_simplify(&m, &p, &r, &err), &err);
        CHECKF(m.triangle_count <= cases[i].budget && m.triangle_count > cases[i].budget * 9 / 10,
               "%s: %zu triangles for a budget of %zu", cases[i].field, m.triangle_count, cases[i].budget);
        CHECK_EQ(euler_characteristic(&m), cases[i].euler);
        iso_census c;
        CHECK_OK(iso_census_compute(vol, &m, ISO_SPACE_INDEX, &c, &err), &err);
        CHECKF(c.closed, "%s: open %zu, non-manifold %zu, misoriented %zu, degenerate %zu", cases[i].field,
               c.open_edges, c.nonmanifold_edges, c.misoriented_edges, c.degenerate_triangles);
        CHECK_EQ(r.unpaired_edges, 0);
        CHECK(surface_worst_vertex_error(vol, &m, cases[i].level) <= st.error_bound + surface_rounding_slack(vol));
        /* meshoptimizer's error is an estimate, not a bound (mesh/mesh.h): on these smooth
         * surfaces the largest measured distance is 1-2 times it. A unit slip (the
         * relative error left unscaled, the extent is ~40 voxels) would be far outside. */
        double measured = measured_distance(&exact, &m);
        CHECKF(r.error > 0 && measured <= 2 * r.error && measured >= r.error / 2,
               "%s: measured %g voxels, reported %g", cases[i].field, measured, r.error);
        CHECK(r.error_voxels == r.error); /* index space: voxel size 1 */
        iso_mesh_free(&m);
        iso_mesh_free(&exact);
        iso_tree_destroy(tree);
        iso_vol_destroy(vol);
    }
}

/* The policy: a budget the faithful ladder meets is met by it (no simplification, a
 * tolerance no larger than the faithful one); a smaller one is met by simplifying the
 * requested tolerance's mesh, with the error in mm and in voxels of the smallest spacing. */
static void test_budget_policy(void)
{
    iso_volume *vol;
    iso_tree *tree = field_tree("field:ml:41", &vol); /* 40 cells: whole bricks, some coarse at range / 32 */
    if (!tree)
        return;
    /* Anisotropic world geometry: voxels of 0.5 x 1 x 2 mm. */
    vol->spacing[0] = 0.5, vol->spacing[2] = 2;
    iso_extract_params xp = {.level = 0.5};
    iso_mesh m;
    iso_mesh_init(&m);
    iso_extract_stats exact, st;
    iso_error err;
    CHECK_OK(iso_extract(tree, &xp, &m, &exact, &err), &err);
    double faithful = iso_budget_faithful_tolerance(vol, 0);
    CHECK_NEAR(faithful, (vol->value_max - vol->value_min) / 32, 1e-12);
    CHECK(iso_budget_faithful_tolerance(vol, 2 * faithful) == 2 * faithful);
    iso_extract_params fp = xp;
    fp.tolerance = faithful;
    fp.coarsen = ISO_COARSEN_ALL; /* as the budget ladder asks */
    iso_extract_stats at_faithful;
    CHECK_OK(iso_extract(tree, &fp, &m, &at_faithful, &err), &err);
    CHECKF(at_faithful.triangles < exact.triangles, "%zu vs %zu", at_faithful.triangles, exact.triangles);

    iso_budget_result res;
    CHECK_OK(iso_extract_budget_faithful(tree, &xp, at_faithful.triangles, &m, &st, &res, &err), &err);
    CHECK(!res.simplified && res.fits && res.tolerance > 0 && res.tolerance <= faithful);
    CHECK(st.triangles <= at_faithful.triangles && st.triangles == m.triangle_count);

    size_t budget = at_faithful.triangles / 3;
    CHECK_OK(iso_extract_budget_faithful(tree, &xp, budget, &m, &st, &res, &err), &err);
    CHECK(res.simplified && res.fits && res.tolerance == 0);
    CHECK(m.triangle_count <= budget && st.triangles == m.triangle_count && st.vertices == m.vertex_count);
    CHECK_EQ(res.simplify.triangles_in, exact.triangles);
    CHECK(res.simplify.error > 0 && res.simplify.error_voxels == res.simplify.error / 0.5);
    CHECK(st.error_bound == exact.error_bound);

    /* The old ladder, for comparison, never simplifies. */
    CHECK_OK(iso_extract_budget(tree, &xp, budget, &m, &st, &res, &err), &err);
    CHECK(!res.simplified);
    iso_mesh_free(&m);
    iso_tree_destroy(tree);
    iso_vol_destroy(vol);
}

/* ---- a real scan ---- */

/* CThead's skin at 100k triangles: at most 100k; its 1,068 open edges on the volume's
 * border come out as they went in (the same count, still on the border); no crack, no
 * misoriented or unpaired edge; non-manifold edges few (meshoptimizer's pinches,
 * mesh/mesh.h: 70-90 measured); every vertex one of the exact mesh's. */
static void test_cthead_skin(void)
{
    iso_volume *vol = surface_load_shared("CThead_256x256x113_u16be.nhdr");
    if (!vol)
        return;
    iso_tree *tree = surface_build(vol);
    iso_mesh m;
    iso_mesh_init(&m);
    iso_extract_stats st;
    iso_error err;
    iso_extract_params xp = {.level = 700, .space = ISO_SPACE_INDEX};
    CHECK_OK(iso_extract(tree, &xp, &m, &st, &err), &err);
    iso_census before, after;
    CHECK_OK(iso_census_compute(vol, &m, ISO_SPACE_INDEX, &before, &err), &err);
    iso_simplify_params p = {.target_triangles = 100000, .target_error = INFINITY, .lock_border = 1};
    iso_simplify_result r;
    CHECK_OK(iso_simplify(&m, &p, &r, &err), &err);
    CHECK_OK(iso_census_compute(vol, &m, ISO_SPACE_INDEX, &after, &err), &err);
    CHECKF(m.triangle_count <= 100000 && m.triangle_count > 99000, "%zu triangles", m.triangle_count);
    CHECK_EQ(before.open_edges, 0);
    CHECK_EQ(after.open_edges, 0);
    CHECK_EQ(after.boundary_edges, before.boundary_edges);
    CHECK_EQ(after.misoriented_edges, 0);
    CHECK_EQ(r.unpaired_edges, 0);
    CHECK_EQ(after.nonmanifold_edges, r.nonmanifold_edges);
    CHECKF(r.nonmanifold_edges < after.edges / 1000, "%zu non-manifold edges of %zu", r.nonmanifold_edges,
           after.edges);
    CHECK(after.degenerate_triangles < 20);
    CHECK(r.error > 0 && r.error < 1);
    CHECK(surface_worst_vertex_error(vol, &m, 700) <= st.error_bound + surface_rounding_slack(vol));
    iso_mesh_free(&m);
    iso_tree_destroy(tree);
    iso_vol_destroy(vol);
}

int main(void)
{
    CHECK_RUN(test_flat_square_becomes_two_triangles);
    CHECK_RUN(test_locked_border_keeps_the_rim);
    CHECK_RUN(test_within_target_is_untouched);
    CHECK_RUN(test_bad_parameters);
    CHECK_RUN(test_normals_follow_vertices);
    CHECK_RUN(test_coarse_classes_go_in_vertex_order);
    CHECK_RUN(test_analytic_fields_stay_within_reported_error);
    CHECK_RUN(test_budget_policy);
    CHECK_RUN(test_cthead_skin);
    return check_finish();
}
