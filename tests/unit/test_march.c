/* test_march.c: the exact, directly indexed marching cubes over bricks (march.h): the
 * same triangles as the full scan, whatever the brick boundaries, the thread count or the
 * NaN samples; vertices shared across bricks exactly once. */
#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "check.h"
#include "extract/march.h"
#include "extract/mc.h"
#include "surface.h"

static void march(const iso_volume *vol, double level, int threads, iso_mesh *m, iso_march_stats *st)
{
    iso_bricks bricks;
    iso_error err;
    CHECK_OK(iso_bricks_build(vol, threads, &bricks, &err), &err);
    CHECK_OK(iso_march_bricks(vol, &bricks, level, 1, 0, threads, m, st, &err), &err);
    iso_bricks_free(&bricks);
}

static void check_same_as_full_scan(const iso_volume *vol, double level)
{
    iso_mesh full, m;
    iso_mesh_init(&full);
    iso_mesh_init(&m);
    iso_error err;
    iso_extract_stats fs;
    iso_march_stats st;
    CHECK_OK(iso_extract_full_scan(vol, level, ISO_SPACE_INDEX, &full, &fs, &err), &err);
    march(vol, level, 2, &m, &st);
    CHECKF(m.triangle_count == full.triangle_count && m.vertex_count == full.vertex_count,
           "%zux%zux%zu level %g: %zu triangles %zu vertices, full scan %zu, %zu", vol->dims[0],
           vol->dims[1], vol->dims[2], level, m.triangle_count, m.vertex_count, full.triangle_count,
           full.vertex_count);
    CHECK(st.error_bound == fs.error_bound);
    if (m.triangle_count == full.triangle_count) {
        surface_triangle *a = surface_canonical_triangles(&m), *b = surface_canonical_triangles(&full);
        CHECK(memcmp(a, b, m.triangle_count * sizeof *a) == 0);
        free(a);
        free(b);
    }
    iso_mesh_free(&full);
    iso_mesh_free(&m);
}

/* Random fields across brick boundaries (sizes 2..27, so 1 to 4 bricks per axis with
 * partial last bricks), integer-valued with ties at the level, real-valued, and float
 * volumes with NaN samples. A third of the trials have full interior bricks, which the
 * kernel classifies 8 rows at a time with SSE2, beside the last ones it does row by row. */
static void test_random_fields_match_full_scan(void)
{
    for (int trial = 0; trial < 60 && !check_failed(); trial++) {
        size_t n[3];
        for (int d = 0; d < 3; d++)
            n[d] = 2 + (size_t)(surface_uniform() * 26);
        int kind = trial % 3;
        iso_volume *vol = surface_make_volume(n[0], n[1], n[2], kind == 0 ? ISO_U8 : ISO_F32);
        for (size_t k = 0; k < n[2]; k++)
            for (size_t j = 0; j < n[1]; j++)
                for (size_t i = 0; i < n[0]; i++) {
                    double v = kind == 0 ? floor(surface_uniform() * 4) : surface_uniform();
                    if (kind == 2 && surface_uniform() < 0.05)
                        v = NAN;
                    iso_vol_set(vol, i, j, k, v);
                }
        iso_vol_update_stats(vol);
        check_same_as_full_scan(vol, kind == 0 ? 1 : 0.5);
        iso_vol_destroy(vol);
    }
}

/* Every voxel type, with samples at the ends of its range and levels on, between and
 * next to them: the kernel compares integers with the level's floor, 8 at a time, and
 * must agree with the full scan's double compare everywhere. 21 x 11 x 10 samples: full
 * 9-sample rows and a partial last brick along x. */
static void test_every_type_at_its_range_ends(void)
{
    static const struct {
        iso_voxel_type type;
        double lowest, highest;
    } types[] = {
        {ISO_U8, 0, 255}, {ISO_I8, -128, 127}, {ISO_U16, 0, 65535}, {ISO_I16, -32768, 32767},
        {ISO_U32, 0, 4294967295.0}, {ISO_I32, -2147483648.0, 2147483647.0},
        {ISO_F32, -1e30, 1e30}, {ISO_F64, -1e300, 1e300},
    };
    for (size_t t = 0; t < sizeof types / sizeof *types && !check_failed(); t++) {
        double lo = types[t].lowest, hi = types[t].highest, mid = floor((lo + hi) / 2);
        /* Values: both ends, the middle and its neighbours: unsigned types cross their
         * signed half there, which the vector compare handles by a bias. */
        const double values[] = {lo, lo + 1, mid - 1, mid, mid + 1, hi - 1, hi};
        const size_t count = sizeof values / sizeof *values;
        iso_volume *vol = surface_make_volume(21, 11, 10, types[t].type);
        for (size_t k = 0; k < 10; k++)
            for (size_t j = 0; j < 11; j++)
                for (size_t i = 0; i < 21; i++)
                    iso_vol_set(vol, i, j, k, values[(size_t)(surface_uniform() * (double)count)]);
        iso_vol_update_stats(vol);
        const double levels[] = {lo, lo + 0.5, mid - 1, mid - 0.5, mid, mid + 0.25, hi - 1, hi - 0.5};
        for (size_t l = 0; l < sizeof levels / sizeof *levels && !check_failed(); l++)
            check_same_as_full_scan(vol, levels[l]);
        iso_vol_destroy(vol);
    }
}

/* Levels a hair either side of samples that no float holds: the kernel selects bricks by
 * comparing their float bounds with the largest float not above the level, which must
 * keep every brick the double compare of the full scan would. 26 x 10 x 10 doubles, four
 * bricks along x. */
static void test_levels_between_floats(void)
{
    const double values[] = {0.1, 1.0 / 3, 0.7, 1e-9};
    iso_volume *vol = surface_make_volume(26, 10, 10, ISO_F64);
    for (size_t k = 0; k < 10; k++)
        for (size_t j = 0; j < 10; j++)
            for (size_t i = 0; i < 26; i++)
                iso_vol_set(vol, i, j, k, values[(i / 8 + (surface_uniform() < 0.3)) % 4]);
    iso_vol_update_stats(vol);
    for (size_t v = 0; v < sizeof values / sizeof *values && !check_failed(); v++) {
        check_same_as_full_scan(vol, values[v]);
        check_same_as_full_scan(vol, nextafter(values[v], INFINITY));
        check_same_as_full_scan(vol, nextafter(values[v], -INFINITY));
        check_same_as_full_scan(vol, (double)(float)values[v]);
    }
    iso_vol_destroy(vol);
}

/* World positions are the index positions, as floats, through iso_vol_index_to_world to
 * the bit, with an identity direction (the kernel's shortcut) and with a rotated one. */
static void test_world_positions_are_the_index_map(void)
{
    const double spacing[3] = {0.9570312, 0.6, 1.5}, origin[3] = {-12.25, 3.5, 100.125};
    const double rotated[3][3] = {{0.6, -0.8, 0}, {0.8, 0.6, 0}, {0, 0, 1}};
    for (int rotate = 0; rotate < 2 && !check_failed(); rotate++) {
        iso_volume *vol = surface_make_volume(23, 19, 17, ISO_I16);
        for (size_t k = 0; k < 17; k++)
            for (size_t j = 0; j < 19; j++)
                for (size_t i = 0; i < 23; i++)
                    iso_vol_set(vol, i, j, k, floor(surface_uniform() * 2000) - 1000);
        iso_vol_update_stats(vol);
        memcpy(vol->spacing, spacing, sizeof spacing);
        memcpy(vol->origin, origin, sizeof origin);
        if (rotate)
            memcpy(vol->direction, rotated, sizeof rotated);
        iso_bricks bricks;
        iso_error err;
        iso_mesh index, world;
        iso_mesh_init(&index);
        iso_mesh_init(&world);
        iso_march_stats st;
        CHECK_OK(iso_bricks_build(vol, 1, &bricks, &err), &err);
        CHECK_OK(iso_march_bricks(vol, &bricks, -142, 1, 0, 1, &index, &st, &err), &err);
        CHECK_OK(iso_march_bricks(vol, &bricks, -142, 1, 1, 1, &world, &st, &err), &err);
        CHECK(index.vertex_count > 1000 && index.vertex_count == world.vertex_count);
        size_t differ = 0;
        for (size_t v = 0; v < index.vertex_count; v++) {
            double p[3] = {index.positions[3 * v], index.positions[3 * v + 1], index.positions[3 * v + 2]}, w[3];
            iso_vol_index_to_world(vol, p, w);
            for (int d = 0; d < 3; d++)
                differ += (float)w[d] != world.positions[3 * v + d];
        }
        CHECKF(differ == 0, "rotated %d: %zu coordinates differ from iso_vol_index_to_world", rotate, differ);
        iso_mesh_free(&index);
        iso_mesh_free(&world);
        iso_bricks_free(&bricks);
        iso_vol_destroy(vol);
    }
}

/* A single sample above the level at (8, 8, 8), the corner of 8 bricks: an octahedron of
 * 6 vertices and 8 triangles whose edges are owned by 7 different bricks. Only the 8
 * bricks holding that sample are active. */
static void test_octahedron_across_eight_bricks(void)
{
    iso_volume *vol = surface_make_volume(33, 33, 33, ISO_U8);
    iso_vol_set(vol, 8, 8, 8, 10);
    iso_vol_update_stats(vol);
    iso_mesh m;
    iso_mesh_init(&m);
    iso_march_stats st;
    march(vol, 5, 3, &m, &st);
    CHECK_EQ(m.vertex_count, 6);
    CHECK_EQ(m.triangle_count, 8);
    CHECK_EQ(st.bricks_active, 8);
    CHECK_EQ(st.cells_visited, 8 * 512);
    iso_mesh_edges e;
    CHECK(iso_mesh_count_edges(&m, &e) == 0);
    CHECK_EQ(e.edges, 12);
    CHECK_EQ(e.open, 0);
    CHECK_EQ(e.nonmanifold, 0);
    CHECK_EQ(e.misoriented, 0);
    for (size_t v = 0; v < m.vertex_count; v++) {
        const float *p = m.positions + 3 * v;
        double off = fabs(p[0] - 8) + fabs(p[1] - 8) + fabs(p[2] - 8);
        CHECK_NEAR(off, 0.5, 1e-6); /* level 5 halfway between 10 and 0 */
    }
    iso_mesh_free(&m);
    iso_vol_destroy(vol);
}

/* The mesh is fixed by the brick grid: 1, 2 and 5 threads give the same bytes. */
static void test_threads_give_identical_meshes(void)
{
    iso_volume *vol = surface_make_volume(40, 29, 35, ISO_F32);
    for (size_t k = 0; k < 35; k++)
        for (size_t j = 0; j < 29; j++)
            for (size_t i = 0; i < 40; i++)
                iso_vol_set(vol, i, j, k, sin(0.3 * (double)i) + cos(0.25 * (double)j) * sin(0.2 * (double)k));
    iso_vol_update_stats(vol);
    iso_mesh one, other;
    iso_mesh_init(&one);
    iso_mesh_init(&other);
    iso_march_stats st;
    march(vol, 0.2, 1, &one, &st);
    CHECK(one.triangle_count > 1000);
    const int threads[] = {2, 5};
    for (int t = 0; t < 2; t++) {
        march(vol, 0.2, threads[t], &other, &st);
        CHECK_EQ(other.triangle_count, one.triangle_count);
        CHECK_EQ(other.vertex_count, one.vertex_count);
        if (other.vertex_count == one.vertex_count && other.triangle_count == one.triangle_count) {
            CHECK(memcmp(other.positions, one.positions, 3 * one.vertex_count * sizeof(float)) == 0);
            CHECK(memcmp(other.indices, one.indices, 3 * one.triangle_count * sizeof(uint32_t)) == 0);
        }
    }
    iso_mesh_free(&one);
    iso_mesh_free(&other);
    iso_vol_destroy(vol);
}

/* The real scan: the exact path over the hierarchy equals the full scan. */
static void test_cthead_matches_full_scan(void)
{
    iso_volume *vol = surface_load_shared("CThead_256x256x113_u16be.nhdr");
    if (!vol)
        return;
    check_same_as_full_scan(vol, 700);
    check_same_as_full_scan(vol, 1500.5);
    iso_vol_destroy(vol);
}

/* iso_march_selected on random fields and random marks (whole bricks, and blocks of 4^3
 * cells in any pattern): the triangles are exactly those marching cubes gives the marked
 * blocks' cells, every vertex is some triangle's, and iso_march_part_vertex finds each
 * crossing of a marked block's cells at its position (the ghosts' vertices included: a
 * cell's crossing on an edge another brick owns). */
static void test_selected_bricks(void)
{
    for (int trial = 0; trial < 120 && !check_failed(); trial++) {
        size_t n[3];
        for (int d = 0; d < 3; d++)
            n[d] = 2 + (size_t)(surface_uniform() * 30);
        iso_volume *vol = surface_random_volume(n, trial % 2 ? ISO_U8 : ISO_F32, trial % 2);
        double level = trial % 2 ? 1 : 0.5;
        iso_bricks bricks;
        iso_error err;
        CHECK_OK(iso_bricks_build(vol, 1, &bricks, &err), &err);
        size_t total = iso_bricks_total(&bricks);
        uint8_t *marked = malloc(total);
        for (size_t b = 0; b < total; b++) {
            double u = surface_uniform();
            marked[b] = trial % 5 == 0 || u < 0.3 ? 0xFF : u < 0.6 ? (uint8_t)(surface_uniform() * 256) : 0;
        }
        iso_mesh m, soup;
        iso_mesh_init(&m);
        iso_mesh_init(&soup);
        iso_march_stats st;
        iso_march_part *part = NULL;
        CHECK_OK(iso_march_selected(vol, &bricks, level, marked, 1 + trial % 3, &m, &st, &part, &err), &err);
        static const double unit[3] = {1, 1, 1};
        size_t found = 0, crossings = 0;
        for (size_t z = 0; z + 1 < n[2]; z++)
            for (size_t y = 0; y + 1 < n[1]; y++)
                for (size_t x = 0; x + 1 < n[0]; x++) {
                    size_t b = ((z / 8) * bricks.count[1] + y / 8) * bricks.count[0] + x / 8;
                    if (!(marked[b] >> (x / 4 % 2 | (y / 4 % 2) << 1 | (z / 4 % 2) << 2) & 1))
                        continue;
                    double v[8], origin[3] = {(double)x, (double)y, (double)z};
                    for (int c = 0; c < 8; c++)
                        v[c] = iso_vol_get(vol, x + (c & 1), y + (c >> 1 & 1), z + (c >> 2 & 1));
                    CHECK(iso_mc_cell(v, level, origin, unit, &soup, NULL) >= 0);
                    for (int e = 0; e < 12; e++) {
                        int lo = iso_mc_edge_corner[e][0], hi = iso_mc_edge_corner[e][1], axis = e / 4;
                        if ((v[lo] > level) == (v[hi] > level))
                            continue;
                        uint32_t p[3] = {(uint32_t)x + (lo & 1), (uint32_t)y + (lo >> 1 & 1), (uint32_t)z + (lo >> 2 & 1)}, id;
                        crossings++;
                        if (!iso_march_part_vertex(part, p, axis, &id) || id >= m.vertex_count)
                            continue;
                        float want = (float)((double)p[axis] + iso_mc_edge_t(v[lo], v[hi], level));
                        found += m.positions[3 * id + axis] == want;
                    }
                }
        CHECK_EQ(found, crossings);
        CHECK_EQ(m.triangle_count, soup.triangle_count);
        if (m.triangle_count == soup.triangle_count) {
            surface_triangle *a = surface_canonical_triangles(&m), *b = surface_canonical_triangles(&soup);
            CHECK(memcmp(a, b, m.triangle_count * sizeof *a) == 0);
            free(a);
            free(b);
        }
        CHECK_EQ(surface_unused_vertices(&m), 0);
        iso_march_part_free(part);
        iso_mesh_free(&m);
        iso_mesh_free(&soup);
        free(marked);
        iso_bricks_free(&bricks);
        iso_vol_destroy(vol);
    }
}

int main(void)
{
    CHECK_RUN(test_random_fields_match_full_scan);
    CHECK_RUN(test_every_type_at_its_range_ends);
    CHECK_RUN(test_levels_between_floats);
    CHECK_RUN(test_world_positions_are_the_index_map);
    CHECK_RUN(test_octahedron_across_eight_bricks);
    CHECK_RUN(test_threads_give_identical_meshes);
    CHECK_RUN(test_cthead_matches_full_scan);
    CHECK_RUN(test_selected_bricks);
    return check_finish();
}
