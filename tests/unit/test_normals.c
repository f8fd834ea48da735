/* test_normals.c: B-spline gradient normals. Every order reproduces linear functions, so a
 * ramp gives its exact normal (index and world space, anisotropic spacing and a rotated
 * frame); on a sphere every normal is unit and points outward (toward lower values), and
 * the smoother orders are no worse than trilinear; the thread count changes no bit. */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "check.h"
#include "extract/extract.h"
#include "io/io.h"
#include "mesh/mesh.h"
#include "hierarchy/tree.h"

static void test_names(void)
{
    CHECK_EQ(iso_normals_order_from_name("none"), 0);
    CHECK_EQ(iso_normals_order_from_name("trilinear"), 2);
    CHECK_EQ(iso_normals_order_from_name("triquadratic"), 3);
    CHECK_EQ(iso_normals_order_from_name("tricubic"), 4);
    CHECK_EQ(iso_normals_order_from_name("cubic"), -1);
    CHECK_EQ(iso_normals_order_from_name(NULL), -1);
    for (int o = 0; o <= 4; o++)
        if (o != 1)
            CHECK_EQ(iso_normals_order_from_name(iso_normals_name(o)), o);
}

/* f = 2i - 3j + 5k on 12^3; spacing (0.5, 2, 1); the frame rotated 90 degrees about z;
 * stored as floats and as 16-bit integers. Points off and on grid edges (enough of them
 * for the four-vertex path of normals.c, in both spaces). */
static void test_ramp_exact_every_order(void)
{
    iso_error err;
    size_t dims[3] = {12, 12, 12};
    for (int type = 0; type < 2; type++) {
        iso_volume *vol = iso_vol_create(dims, type ? ISO_I16 : ISO_F32, 0, &err);
        CHECK(vol != NULL);
        if (!vol)
            return;
        for (size_t k = 0; k < 12; k++)
            for (size_t j = 0; j < 12; j++)
                for (size_t i = 0; i < 12; i++)
                    iso_vol_set(vol, i, j, k, 2.0 * i - 3.0 * j + 5.0 * k);
        vol->spacing[0] = 0.5, vol->spacing[1] = 2, vol->spacing[2] = 1;
        double rot[3][3] = {{0, -1, 0}, {1, 0, 0}, {0, 0, 1}};
        memcpy(vol->direction, rot, sizeof rot);
        iso_vol_update_stats(vol);
        /* Index gradient (2,-3,5); world gradient = A^-T g with A = R diag(s):
         * A^-T = R diag(1/s), so world g = R (4, -1.5, 5) = (1.5, 4, 5). */
        const double index_n[3] = {-2, 3, -5}, world_n[3] = {-1.5, -4, -5};
        enum { POINTS = 9 };
        const double pts[POINTS][3] = {{4.3, 5.6, 6.1}, {3, 4, 5},    {7.5, 2.25, 8.9}, {4.3, 5, 6}, {3, 4.6, 5},
                                       {7, 2, 8.9},     {5, 6, 7.25}, {2.5, 3, 4},      {6, 7.75, 8}};
        for (int space = 0; space < 2; space++)
            for (int order = 2; order <= 4; order++) {
                iso_mesh mesh;
                iso_mesh_init(&mesh);
                CHECK_OK(iso_mesh_reserve(&mesh, POINTS, 1), &err);
                for (int v = 0; v < POINTS; v++) {
                    double w[3];
                    if (space == ISO_SPACE_WORLD)
                        iso_vol_index_to_world(vol, pts[v], w);
                    else
                        memcpy(w, pts[v], sizeof w);
                    for (int c = 0; c < 3; c++)
                        mesh.positions[3 * v + c] = (float)w[c];
                }
                mesh.vertex_count = POINTS;
                CHECK_OK(iso_normals_compute(vol, &mesh, order, (iso_space)(space ? ISO_SPACE_INDEX : ISO_SPACE_WORLD), 0, &err), &err);
                const double *want = space ? index_n : world_n;
                double len = sqrt(want[0] * want[0] + want[1] * want[1] + want[2] * want[2]);
                for (int v = 0; v < POINTS && mesh.normals; v++)
                    for (int c = 0; c < 3; c++)
                        CHECKF(fabs(mesh.normals[3 * v + c] - want[c] / len) <= 2e-6, "type %d space %d order %d point %d: %g, want %g",
                               type, space, order, v, mesh.normals[3 * v + c], want[c] / len);
                CHECK_OK(iso_normals_compute(vol, &mesh, 0, ISO_SPACE_WORLD, 0, &err), &err);
                CHECK(mesh.normals == NULL);
                iso_mesh_free(&mesh);
            }
        iso_vol_destroy(vol);
    }
}

/* The cubic B-spline's weight, or its derivative's, of the sample at offset m in -1..2
 * from floor(x), t = x - floor(x): the textbook table, term by term. */
static double cubic_weight(int m, double t, int derivative)
{
    double s = 1 - t;
    switch (m) {
    case -1: return derivative ? -s * s / 2 : s * s * s / 6;
    case 0: return derivative ? (3 * t * t - 4 * t) / 2 : (3 * t * t * t - 6 * t * t + 4) / 6;
    case 1: return derivative ? (-3 * t * t + 2 * t + 1) / 2 : (-3 * t * t * t + 3 * t * t + 3 * t + 1) / 6;
    default: return derivative ? t * t / 2 : t * t * t / 6;
    }
}

/* The tricubic gradient at p from all 64 taps, border samples repeated. */
static void tricubic_reference(const iso_volume *vol, const double p[3], double g[3])
{
    long floor_of[3];
    double t[3];
    for (int a = 0; a < 3; a++) {
        floor_of[a] = (long)floor(p[a]);
        t[a] = p[a] - (double)floor_of[a];
    }
    g[0] = g[1] = g[2] = 0;
    for (int k = -1; k <= 2; k++)
        for (int j = -1; j <= 2; j++)
            for (int i = -1; i <= 2; i++) {
                long at[3] = {floor_of[0] + i, floor_of[1] + j, floor_of[2] + k};
                for (int a = 0; a < 3; a++)
                    at[a] = at[a] < 0 ? 0 : at[a] >= (long)vol->dims[a] ? (long)vol->dims[a] - 1 : at[a];
                double f = iso_vol_get(vol, (size_t)at[0], (size_t)at[1], (size_t)at[2]);
                int m[3] = {i, j, k};
                for (int c = 0; c < 3; c++)
                    g[c] += f * cubic_weight(m[0], t[0], c == 0) * cubic_weight(m[1], t[1], c == 1) *
                            cubic_weight(m[2], t[2], c == 2);
            }
}

/* Marching cubes' vertices lie on grid edges, where the tricubic has 36 taps, not 64
 * (normals.c): on x, y and z edges, exactly on the sample planes, a hair off them either
 * way (as world positions come back), off them, and at samples and near the border, the
 * normals agree with all 64 taps summed here. A tap dropped on the wrong side, or the
 * weights of a kept tap shifted wrongly, is off by a whole weight (1/6). A hair off an
 * edge whose support lies inside, the normal is the edge point's (the plane coordinates
 * snapped to their samples), within 1e-3 of the gradient at the hair-off point (3.5e-4
 * at most here, on a steep field 3e-5 off). */
static void check_tricubic_on_grid_edges(const iso_volume *vol)
{
    iso_error err;
    const double hair[] = {0, 3e-5, -3e-5, 0.25, 0.5};
    const double along[] = {0.1, 0.5, 0.93};
    const double anchors[][3] = {{7, 9, 11}, {1, 1, 18}, {0, 12, 5}, {18, 0, 0}, {19, 19, 19}};
    enum { POINTS = 3 * 5 * 5 * 5 * 3 };
    iso_mesh mesh;
    iso_mesh_init(&mesh);
    CHECK_OK(iso_mesh_reserve(&mesh, POINTS, 1), &err);
    double want[POINTS][3], hair_off[POINTS][3];
    size_t n = 0;
    for (int axis = 0; axis < 3; axis++)
        for (int h1 = 0; h1 < 5; h1++)
            for (int h2 = 0; h2 < 5; h2++)
                for (int an = 0; an < 5; an++)
                    for (int f = 0; f < 3; f++, n++) {
                        double p[3];
                        for (int a = 0; a < 3; a++)
                            p[a] = anchors[an][a];
                        p[axis] = fmin(anchors[an][axis] + along[f], (double)vol->dims[axis] - 1);
                        p[(axis + 1) % 3] = fmax(0, p[(axis + 1) % 3] + hair[h1]);
                        p[(axis + 2) % 3] = fmax(0, p[(axis + 2) % 3] + hair[h2]);
                        for (int a = 0; a < 3; a++) {
                            mesh.positions[3 * n + a] = (float)p[a];
                            p[a] = mesh.positions[3 * n + a]; /* the point the normal is asked at */
                        }
                        double g[3], snapped[3];
                        tricubic_reference(vol, p, g);
                        double len = sqrt(g[0] * g[0] + g[1] * g[1] + g[2] * g[2]);
                        for (int c = 0; c < 3; c++)
                            want[n][c] = hair_off[n][c] = -g[c] / len;
                        /* On the edge (both hairs under 1e-4) with its 4 x 3 x 3 support inside. */
                        int inside = h1 < 3 && h2 < 3 && floor(p[axis]) >= 1 && floor(p[axis]) + 2 < vol->dims[axis];
                        for (int a = 0; a < 3; a++) {
                            snapped[a] = a == axis ? p[a] : round(p[a]);
                            if (a != axis)
                                inside = inside && snapped[a] >= 1 && snapped[a] + 1 < vol->dims[a];
                        }
                        if (inside) {
                            tricubic_reference(vol, snapped, g);
                            len = sqrt(g[0] * g[0] + g[1] * g[1] + g[2] * g[2]);
                            for (int c = 0; c < 3; c++)
                                want[n][c] = -g[c] / len;
                        }
                    }
    mesh.vertex_count = n;
    CHECK_OK(iso_normals_compute(vol, &mesh, 4, ISO_SPACE_INDEX, 1, &err), &err);
    for (size_t v = 0; v < n && mesh.normals; v++)
        for (int c = 0; c < 3; c++) {
            CHECKF(fabs(mesh.normals[3 * v + c] - want[v][c]) <= 1e-6, "point %zu (%g, %g, %g): %g, want %g", v,
                   mesh.positions[3 * v], mesh.positions[3 * v + 1], mesh.positions[3 * v + 2],
                   mesh.normals[3 * v + c], want[v][c]);
            CHECKF(fabs(mesh.normals[3 * v + c] - hair_off[v][c]) <= 1e-3, "point %zu: %g, %g at the hair", v,
                   mesh.normals[3 * v + c], hair_off[v][c]);
        }
    iso_mesh_free(&mesh);
}

/* The normals at points on grid edges along every axis up to the volume's last samples,
 * into out (3 per point): all in one call, or (one_by_one) each point alone in a mesh of
 * its own, where it takes the one-vertex path (normals.c computes four at a time where
 * the CPU can). */
static void grid_edge_normals(const iso_volume *vol, float *out, size_t n, int one_by_one)
{
    iso_error err;
    iso_mesh mesh;
    iso_mesh_init(&mesh);
    CHECK_OK(iso_mesh_reserve(&mesh, n, 1), &err);
    size_t v = 0;
    for (size_t k = 1; k + 2 < vol->dims[2] && v < n; k += 3)
        for (size_t j = 0; j < vol->dims[1] && v < n; j++)
            for (int axis = 0; axis < 3 && v < n; axis++, v++)
                for (int a = 0; a < 3; a++) /* along each axis from (j, j, k), to the last samples */
                    mesh.positions[3 * v + a] = (float)(a == axis ? fmin((a == 2 ? k : j) + 0.37, vol->dims[a] - 1.0)
                                                                  : a == 2 ? (double)k : (double)j);
    mesh.vertex_count = v;
    if (!one_by_one) {
        CHECK_OK(iso_normals_compute(vol, &mesh, 4, ISO_SPACE_INDEX, 1, &err), &err);
        if (mesh.normals)
            memcpy(out, mesh.normals, v * 3 * sizeof *out);
    }
    for (size_t u = 0; one_by_one && u < v; u++) {
        iso_mesh alone;
        iso_mesh_init(&alone);
        alone.positions = mesh.positions + 3 * u;
        alone.vertex_count = 1;
        CHECK_OK(iso_normals_compute(vol, &alone, 4, ISO_SPACE_INDEX, 1, &err), &err);
        if (alone.normals)
            memcpy(out + 3 * u, alone.normals, 3 * sizeof *out);
        free(alone.normals);
    }
    iso_mesh_free(&mesh);
}

/* The Marschner-Lobb field as floats, and as 8- and 16-bit integers (unsigned and signed:
 * the vector integer sums of normals.c). The integer volumes' normals are also the same,
 * bit for bit, as those of the same values stored as floats (summed one by one in doubles,
 * exactly for such values), and as those of each point computed alone (one vertex at a
 * time, not four), on edges along every axis up to the volume's last samples. */
static void test_tricubic_on_grid_edges(void)
{
    iso_error err;
    iso_volume *vol = NULL;
    CHECK_OK(iso_field_load("field:ml:20", NULL, &vol, &err), &err);
    if (!vol)
        return;
    iso_vol_update_stats(vol);
    check_tricubic_on_grid_edges(vol);
    const iso_voxel_type types[] = {ISO_U16, ISO_I16, ISO_U8, ISO_I8};
    const double range[] = {60000, 60000, 250, 250}, low[] = {0, -30000, 0, -125};
    enum { EDGE_POINTS = 3 * 20 * 6 };
    for (int t = 0; t < 4; t++) {
        iso_volume *ints = iso_vol_create(vol->dims, types[t], 0, &err);
        iso_volume *floats = iso_vol_create(vol->dims, ISO_F32, 0, &err);
        CHECK(ints != NULL && floats != NULL);
        if (!ints || !floats) {
            iso_vol_destroy(ints);
            iso_vol_destroy(floats);
            break;
        }
        double scale = range[t] / (vol->value_max - vol->value_min);
        for (size_t k = 0; k < vol->dims[2]; k++)
            for (size_t j = 0; j < vol->dims[1]; j++)
                for (size_t i = 0; i < vol->dims[0]; i++) {
                    double f = round((iso_vol_get(vol, i, j, k) - vol->value_min) * scale + low[t]);
                    iso_vol_set(ints, i, j, k, f);
                    iso_vol_set(floats, i, j, k, f);
                }
        iso_vol_update_stats(ints);
        iso_vol_update_stats(floats);
        check_tricubic_on_grid_edges(ints);
        static float from_ints[EDGE_POINTS * 3], from_floats[EDGE_POINTS * 3], alone[EDGE_POINTS * 3];
        memset(from_ints, 0, sizeof from_ints);
        memset(from_floats, 0xff, sizeof from_floats);
        memset(alone, 0x7f, sizeof alone);
        grid_edge_normals(ints, from_ints, EDGE_POINTS, 0);
        grid_edge_normals(floats, from_floats, EDGE_POINTS, 0);
        grid_edge_normals(ints, alone, EDGE_POINTS, 1);
        CHECKF(!memcmp(from_ints, from_floats, sizeof from_ints), "voxel type %d: normals differ from the float copy's",
               (int)types[t]);
        CHECKF(!memcmp(from_ints, alone, sizeof from_ints), "voxel type %d: normals differ one vertex at a time",
               (int)types[t]);
        iso_vol_destroy(ints);
        iso_vol_destroy(floats);
    }
    iso_vol_destroy(vol);
}

/* Extracts field `name` at `level` into mesh; returns its volume (NULL on failure, a
 * CHECK failure already recorded). The caller destroys the volume and frees the mesh. */
static iso_volume *field_mesh(const char *name, double level, iso_mesh *mesh)
{
    iso_error err;
    iso_volume *vol = NULL;
    iso_tree *tree = NULL;
    iso_mesh_init(mesh);
    CHECK_OK(iso_field_load(name, NULL, &vol, &err), &err);
    if (!vol)
        return NULL;
    iso_vol_update_stats(vol);
    CHECK_OK(iso_tree_build(vol, 0, NULL, NULL, &tree, &err), &err);
    iso_extract_params params = {.level = level};
    if (tree)
        CHECK_OK(iso_extract(tree, &params, mesh, NULL, &err), &err);
    iso_tree_destroy(tree);
    return vol;
}

/* The sphere field is R - |p - c|: the true outward normal is (p - c) / |p - c|. */
static void test_sphere_outward_unit_and_ordered(void)
{
    iso_error err;
    iso_mesh mesh;
    iso_volume *vol = field_mesh("field:sphere:48", 8.3, &mesh);
    if (!vol)
        return;
    CHECK(mesh.vertex_count > 1000);
    double mean[5] = {0}, worst[5] = {0};
    const double c = 23.5;
    for (int order = 2; order <= 4; order++) {
        CHECK_OK(iso_normals_compute(vol, &mesh, order, ISO_SPACE_WORLD, 0, &err), &err);
        for (size_t v = 0; v < mesh.vertex_count && mesh.normals; v++) {
            const float *p = mesh.positions + 3 * v, *n = mesh.normals + 3 * v;
            double r[3] = {p[0] - c, p[1] - c, p[2] - c};
            double rl = sqrt(r[0] * r[0] + r[1] * r[1] + r[2] * r[2]);
            double nl = sqrt((double)n[0] * n[0] + (double)n[1] * n[1] + (double)n[2] * n[2]);
            CHECKF(fabs(nl - 1) < 1e-5, "order %d vertex %zu: |n| = %.9f", order, v, nl);
            double dot = (n[0] * r[0] + n[1] * r[1] + n[2] * r[2]) / rl / nl;
            CHECKF(dot > 0, "order %d vertex %zu points inward", order, v);
            double angle = acos(dot > 1 ? 1 : dot) * 180 / M_PI;
            mean[order] += angle / (double)mesh.vertex_count;
            if (angle > worst[order])
                worst[order] = angle;
        }
    }
    printf("normals sphere 48^3 level 8.3: trilinear mean %.4f max %.4f deg, triquadratic mean %.4f max %.4f, "
           "tricubic mean %.4f max %.4f\n", mean[2], worst[2], mean[3], worst[3], mean[4], worst[4]);
    CHECK(mean[3] <= mean[2] && mean[4] <= mean[2]);
    CHECK(mean[2] < 3.0 && mean[3] < 0.5 && mean[4] < 0.5);
    iso_mesh_free(&mesh);
    iso_vol_destroy(vol);
}

/* Threads share the vertices; every normal is its own vertex's, so the bytes agree. */
static void test_threads_give_identical_normals(void)
{
    iso_error err;
    iso_mesh mesh;
    iso_volume *vol = field_mesh("field:ml:80", 0.5, &mesh);
    if (!vol)
        return;
    CHECK(mesh.vertex_count > 40000); /* 45,304: three threads' minimum shares */
    size_t bytes = mesh.vertex_count * 3 * sizeof(float);
    float *one = malloc(bytes);
    CHECK(one != NULL);
    for (int order = 2; order <= 4 && one; order++) {
        CHECK_OK(iso_normals_compute(vol, &mesh, order, ISO_SPACE_WORLD, 1, &err), &err);
        memcpy(one, mesh.normals, bytes);
        CHECK_OK(iso_normals_compute(vol, &mesh, order, ISO_SPACE_WORLD, 3, &err), &err);
        CHECKF(!memcmp(one, mesh.normals, bytes), "order %d: 1 and 3 threads differ", order);
    }
    free(one);
    iso_mesh_free(&mesh);
    iso_vol_destroy(vol);
}

int main(void)
{
    CHECK_RUN(test_names);
    CHECK_RUN(test_ramp_exact_every_order);
    CHECK_RUN(test_tricubic_on_grid_edges);
    CHECK_RUN(test_sphere_outward_unit_and_ordered);
    CHECK_RUN(test_threads_give_identical_normals);
    return check_finish();
}
