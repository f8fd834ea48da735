/* test_manifold.c: pinches counted exactly on hand-built meshes, and simplification that
 * makes none where plain meshoptimizer does (a thin tube whose cross-section is a triangle:
 * every collapse along it breaks the link condition). */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <unistd.h>
#include <string.h>

#include "mesh/mesh.h"
#include "check.h"
#include "extract/extract.h"
#include "hierarchy/tree.h"
#include "io/io.h"
#include "surface.h"

static void add_vertex(iso_mesh *m, double x, double y, double z)
{
    float *p = m->positions + 3 * m->vertex_count++;
    p[0] = (float)x, p[1] = (float)y, p[2] = (float)z;
}

static void add_triangle(iso_mesh *m, uint32_t a, uint32_t b, uint32_t c)
{
    uint32_t *t = m->indices + 3 * m->triangle_count++;
    t[0] = a, t[1] = b, t[2] = c;
}

/* A tetrahedron on corners a, b, c, d, its four faces wound consistently. */
static void add_tetrahedron(iso_mesh *m, uint32_t a, uint32_t b, uint32_t c, uint32_t d)
{
    add_triangle(m, a, c, b);
    add_triangle(m, a, b, d);
    add_triangle(m, b, c, d);
    add_triangle(m, c, a, d);
}

static void test_counts_on_hand_built_meshes(void)
{
    iso_mesh m;
    iso_mesh_init(&m);
    CHECK(iso_mesh_reserve(&m, 16, 16) == 0);
    unsigned char mark[16];
    iso_mesh_pinches p;
    /* One tetrahedron: 6 edges, no pinch. */
    add_vertex(&m, 0, 0, 0), add_vertex(&m, 1, 0, 0), add_vertex(&m, 0, 1, 0), add_vertex(&m, 0, 0, 1);
    add_tetrahedron(&m, 0, 1, 2, 3);
    CHECK_EQ(iso_mesh_find_pinches(&m, mark, &p), 0);
    CHECK_EQ(p.edges, 6);
    CHECK_EQ(p.pinch_edges, 0);
    CHECK_EQ(p.pinch_vertices, 0);
    CHECK_EQ(p.unpaired_edges, 0);
    for (int v = 0; v < 4; v++)
        CHECK_EQ(mark[v], 0);
    /* A second one sharing vertex 0 only: a bowtie, vertex 0 has two fans. */
    add_vertex(&m, -1, 0, 0), add_vertex(&m, 0, -1, 0), add_vertex(&m, 0, 0, -1);
    add_tetrahedron(&m, 0, 4, 5, 6);
    CHECK_EQ(iso_mesh_find_pinches(&m, mark, &p), 0);
    CHECK_EQ(p.edges, 12);
    CHECK_EQ(p.pinch_edges, 0);
    CHECK_EQ(p.pinch_vertices, 1);
    CHECK_EQ(mark[0], 1);
    for (int v = 1; v < 7; v++)
        CHECK_EQ(mark[v], 0);
    /* A third one sharing edge 1-2 with the first: that edge has four triangles; its ends
     * keep one fan each (the triangles join through the other end). */
    add_vertex(&m, 1, 1, 1), add_vertex(&m, 1, 1, -1);
    add_tetrahedron(&m, 1, 2, 7, 8);
    CHECK_EQ(iso_mesh_find_pinches(&m, mark, &p), 0);
    CHECK_EQ(p.edges, 12 + 5);
    CHECK_EQ(p.pinch_edges, 1);
    CHECK_EQ(p.pinch_vertices, 1);
    CHECK_EQ(mark[1], 1);
    CHECK_EQ(mark[2], 1);
    CHECK_EQ(mark[0], 1);
    CHECK_EQ(mark[3] + mark[4] + mark[5] + mark[6] + mark[7] + mark[8], 0);
    /* An index out of range is refused. */
    m.indices[0] = (uint32_t)m.vertex_count;
    CHECK_EQ(iso_mesh_find_pinches(&m, NULL, &p), ISO_E_ARGUMENT);
    iso_mesh_free(&m);
}

/* A torus of `ring` cross-sections around the z axis, each a triangle of radius r. */
static void thin_tube(iso_mesh *m, int ring, double r)
{
    iso_mesh_init(m);
    CHECK(iso_mesh_reserve(m, (size_t)(3 * ring), (size_t)(6 * ring)) == 0);
    for (int i = 0; i < ring; i++) {
        double a = 2 * M_PI * i / ring;
        for (int j = 0; j < 3; j++) {
            double b = 2 * M_PI * j / 3, rho = 10 + r * cos(b);
            add_vertex(m, rho * cos(a), rho * sin(a), r * sin(b));
        }
    }
    for (int i = 0; i < ring; i++)
        for (int j = 0; j < 3; j++) {
            uint32_t a = (uint32_t)(3 * i + j), b = (uint32_t)(3 * i + (j + 1) % 3);
            uint32_t c = (uint32_t)(3 * ((i + 1) % ring) + j), d = (uint32_t)(3 * ((i + 1) % ring) + (j + 1) % 3);
            add_triangle(m, a, c, b);
            add_triangle(m, b, c, d);
        }
}

/* Every edge used exactly twice, once each way, and no pinch vertex. */
static void check_closed_manifold(const iso_mesh *m)
{
    iso_mesh_edges e;
    CHECK_EQ(iso_mesh_count_edges(m, &e), 0);
    CHECK_EQ(e.open, 0);
    CHECK_EQ(e.nonmanifold, 0);
    CHECK_EQ(e.misoriented, 0);
    iso_mesh_pinches p;
    CHECK_EQ(iso_mesh_find_pinches(m, NULL, &p), 0);
    CHECK_EQ(p.pinch_edges, 0);
    CHECK_EQ(p.pinch_vertices, 0);
    CHECK_EQ(p.unpaired_edges, 0);
}

static void test_thin_tube_is_not_pinched(void)
{
    iso_mesh plain, kept;
    thin_tube(&plain, 40, 0.5);
    thin_tube(&kept, 40, 0.5);
    check_closed_manifold(&plain);
    iso_simplify_params sp = {.target_triangles = 60, .target_error = INFINITY, .lock_border = 1,
                              .keep_vertices = 1};
    iso_simplify_result r;
    iso_error err = {0};
    /* Plain meshoptimizer pinches this tube: the case is a real one. */
    CHECK_OK(iso_simplify(&plain, &sp, &r, &err), &err);
    iso_mesh_pinches p;
    CHECK_EQ(iso_mesh_find_pinches(&plain, NULL, &p), 0);
    CHECKF(p.pinch_edges + p.pinch_vertices > 0, "plain simplification made no pinch (%zu triangles)",
           plain.triangle_count);
    CHECK_OK(iso_simplify_manifold(&kept, &sp, &r, &err), &err);
    check_closed_manifold(&kept);
    CHECK_EQ(r.nonmanifold_edges, 0);
    CHECK_EQ(r.pinch_vertices, 0);
    CHECK_EQ(r.triangles, kept.triangle_count);
    CHECK(kept.triangle_count < 240);
    CHECK(r.locked_vertices > 0);
    /* Every vertex used is an input vertex (indices into the unchanged positions). */
    for (size_t i = 0; i < 3 * kept.triangle_count; i++)
        CHECK(kept.indices[i] < 120);
    iso_mesh_free(&plain);
    iso_mesh_free(&kept);
}

/* The thin tube with a lone tetrahedron (a speck) beside it, simplified as far as it
 * goes: the speck stays, its four triangles as they were (its collapses would lay two of
 * its faces onto each other: no component of a surface goes), the tube is simplified, and
 * what is left is closed, with no pinch. */
static void test_speck_stays(void)
{
    iso_mesh m;
    thin_tube(&m, 40, 0.5);
    iso_mesh grown;
    iso_mesh_init(&grown);
    CHECK(iso_mesh_reserve(&grown, m.vertex_count + 4, m.triangle_count + 4) == 0);
    memcpy(grown.positions, m.positions, 3 * m.vertex_count * sizeof(float));
    memcpy(grown.indices, m.indices, 3 * m.triangle_count * sizeof(uint32_t));
    grown.vertex_count = m.vertex_count, grown.triangle_count = m.triangle_count;
    uint32_t s = (uint32_t)grown.vertex_count;
    add_vertex(&grown, 30, 0, 0), add_vertex(&grown, 30.1, 0, 0), add_vertex(&grown, 30, 0.1, 0);
    add_vertex(&grown, 30, 0, 0.1);
    add_tetrahedron(&grown, s, s + 1, s + 2, s + 3);
    check_closed_manifold(&grown);
    iso_simplify_params sp = {.target_triangles = 1, .target_error = INFINITY, .lock_border = 1,
                              .keep_vertices = 1};
    iso_simplify_result r;
    iso_error err = {0};
    CHECK_OK(iso_simplify_manifold(&grown, &sp, &r, &err), &err);
    check_closed_manifold(&grown);
    size_t on_speck = 0;
    for (size_t i = 0; i < 3 * grown.triangle_count; i++)
        on_speck += grown.indices[i] >= s;
    CHECKF(on_speck == 12, "%zu corners on the speck", on_speck);
    CHECK(grown.triangle_count - 4 < m.triangle_count);
    size_t components = 0;
    CHECK_EQ(iso_mesh_count_components(&grown, &components), 0);
    CHECK_EQ(components, 2);
    iso_mesh_free(&m);
    iso_mesh_free(&grown);
}

/* A real CT head's chain (skin and bone of the VTK quarter head): every level watertight
 * (no crack, nothing misoriented, the border's open edges as in the exact surface), no fold
 * dropped, and pinches under 1 in 10,000 edges, where one plain simplification of the
 * same surface to a quarter makes more. */
static void check_real_chain(const iso_volume *vol, const iso_tree *tree, double level)
{
    iso_mesh m, plain;
    iso_mesh_init(&m);
    iso_mesh_init(&plain);
    iso_extract_stats st;
    iso_error err = {0};
    iso_extract_params xp = {.level = level, .space = ISO_SPACE_INDEX};
    CHECK_OK(iso_extract(tree, &xp, &m, &st, &err), &err);
    iso_census exact, c;
    CHECK_OK(iso_census_compute(vol, &m, ISO_SPACE_INDEX, &exact, &err), &err);
    iso_mesh_chain *chain = NULL;
    CHECK_OK(iso_mesh_chain_build(&m, 1, 0, &chain, &err), &err);
    if (!chain)
        return;
    /* thin bone allows few collapses past 2.4% (level 11): the chain ends there */
    CHECKF(chain->levels >= ISO_CHAIN_LEVELS && !chain->partial, "%d levels", chain->levels);
    size_t pinched_levels = 0;
    for (int k = 1; k < chain->levels; k++) {
        const iso_mesh_chain_level *lv = &chain->level[k];
        CHECK_OK(iso_mesh_chain_mesh(chain, k, &m, &err), &err);
        CHECK_OK(iso_census_compute(vol, &m, ISO_SPACE_INDEX, &c, &err), &err);
        iso_mesh_pinches p;
        CHECK_EQ(iso_mesh_find_pinches(&m, NULL, &p), 0);
        CHECK_EQ(p.pinch_edges, lv->nonmanifold_edges);
        CHECK_EQ(p.pinch_vertices, lv->pinch_vertices);
        CHECK_EQ(p.edges, lv->edges);
        CHECK_EQ(c.nonmanifold_edges, p.pinch_edges);
        /* Collapses that keep the link condition make none: only level 0's can be left. */
        CHECKF(p.pinch_edges + p.pinch_vertices <= chain->level[0].nonmanifold_edges + chain->level[0].pinch_vertices,
               "level %d: %zu + %zu pinches in %zu edges", k, p.pinch_edges, p.pinch_vertices, p.edges);
        pinched_levels += p.pinch_edges + p.pinch_vertices > 0;
        CHECK_EQ(c.open_edges, 0);
        CHECK_EQ(c.misoriented_edges, 0);
        CHECK_EQ(c.boundary_edges, exact.boundary_edges);
        CHECK_EQ(lv->folds_dropped, 0);
    }
    CHECK_OK(iso_mesh_chain_mesh(chain, 0, &plain, &err), &err);
    iso_simplify_params sp = {.target_triangles = plain.triangle_count / 4, .target_error = INFINITY,
                              .lock_border = 1};
    iso_simplify_result r;
    CHECK_OK(iso_simplify(&plain, &sp, &r, &err), &err);
    iso_mesh_pinches q;
    CHECK_EQ(iso_mesh_find_pinches(&plain, NULL, &q), 0);
    CHECKF(q.pinch_edges + q.pinch_vertices > chain->level[2].nonmanifold_edges + chain->level[2].pinch_vertices,
           "plain: %zu + %zu pinches", q.pinch_edges, q.pinch_vertices);
    iso_mesh_chain_destroy(chain);
    iso_mesh_free(&m);
    iso_mesh_free(&plain);
}

static void test_real_chain_is_not_pinched(void)
{
    iso_volume *vol = surface_load_shared("headsq_quarter_64x64x93_u16le.nhdr");
    if (!vol)
        return;
    iso_tree *tree = surface_build(vol);
    check_real_chain(vol, tree, 500);
    check_real_chain(vol, tree, 1150);
    iso_tree_destroy(tree);
    iso_vol_destroy(vol);
}

/* A chain written and read back is the same chain, byte for byte where it matters; a
 * foreign identity is stale, a flipped byte anywhere or a cut file corrupt, a file of
 * something else not a chain file, a missing one an I/O error. */
static void write_bytes(const char *path, const unsigned char *data, size_t n)
{
    FILE *f = fopen(path, "wb");
    CHECK(f != NULL);
    if (f) {
        CHECK_EQ(fwrite(data, 1, n, f), n);
        fclose(f);
    }
}

static void test_chain_file_round_trip(void)
{
    iso_volume *vol = NULL;
    iso_error err = {0};
    CHECK_OK(iso_field_load("field:torus:32", NULL, &vol, &err), &err);
    if (!vol)
        return;
    iso_vol_update_stats(vol);
    iso_tree *tree = surface_build(vol);
    iso_mesh m;
    iso_mesh_init(&m);
    iso_extract_stats st;
    iso_extract_params xp = {.level = 1.0, .space = ISO_SPACE_INDEX};
    CHECK_OK(iso_extract(tree, &xp, &m, &st, &err), &err);
    iso_mesh_chain *chain = NULL, *back = NULL;
    CHECK_OK(iso_mesh_chain_build(&m, 1, 0, &chain, &err), &err);
    char path[] = "/tmp/test_manifold_chain_XXXXXX";
    int fd = mkstemp(path);
    CHECK(fd >= 0);
    if (!chain || fd < 0)
        return;
    close(fd);
    /* What the caller keeps in the chain (proto's pipeline) goes to the file too. */
    chain->faithful_triangles = 1234;
    for (int k = 1; k < chain->levels; k++)
        chain->level[k].value_error = 0.125 * k; /* data here: any value makes the trip */
    CHECK(chain->grid != NULL);
    CHECK_OK(iso_mesh_chain_save(chain, path, 42, &err), &err);
    CHECK_OK(iso_mesh_chain_load(path, 42, &back, &err), &err);
    if (back) {
        CHECK_EQ(back->levels, chain->levels);
        CHECK_EQ(back->vertex_count, chain->vertex_count);
        CHECK_EQ(back->closed, chain->closed);
        CHECK(back->volume == chain->volume && back->voxel_size == chain->voxel_size);
        CHECK_EQ(back->faithful_triangles, 1234);
        /* Level 0's grid is built again on reading, and measures as the build's did. */
        CHECK(back->grid != NULL);
        CHECK_EQ(back->bytes, chain->bytes);
        CHECK(!memcmp(back->positions, chain->positions, 3 * chain->vertex_count * sizeof(float)));
        for (int k = 0; k < chain->levels; k++) {
            const iso_mesh_chain_level *a = &chain->level[k], *b = &back->level[k];
            CHECK_EQ(b->triangle_count, a->triangle_count);
            CHECK(b->distance.p99 == a->distance.p99 && b->offset == a->offset);
            CHECK(b->value_error == a->value_error);
            if (k > 0) {
                iso_mesh lm;
                iso_mesh_distance d;
                iso_mesh_init(&lm);
                CHECK_OK(iso_mesh_chain_mesh(back, k, &lm, &err), &err);
                CHECK_OK(iso_mesh_chain_distance(back, &lm, 1, &d, &err), &err);
                CHECKF(d.p99 == a->distance.p99 && d.max == a->distance.max, "level %d: %g %g, built %g %g",
                       k, d.p99, d.max, a->distance.p99, a->distance.max);
                iso_mesh_free(&lm);
            }
            CHECK_EQ(b->pinch_vertices, a->pinch_vertices);
            CHECK(!memcmp(b->indices, a->indices, 3 * a->triangle_count * sizeof(uint32_t)));
        }
        iso_mesh mine, theirs;
        iso_mesh_init(&mine);
        iso_mesh_init(&theirs);
        CHECK_OK(iso_mesh_chain_mesh(chain, 3, &mine, &err), &err);
        CHECK_OK(iso_mesh_chain_mesh(back, 3, &theirs, &err), &err);
        CHECK(mine.vertex_count == theirs.vertex_count &&
              !memcmp(mine.positions, theirs.positions, 3 * mine.vertex_count * sizeof(float)));
        iso_mesh_free(&mine);
        iso_mesh_free(&theirs);
        iso_mesh_chain_destroy(back);
    }
    back = NULL;
    CHECK_EQ(iso_mesh_chain_load(path, 43, &back, &err), ISO_E_STALE);
    CHECK(back == NULL);
    FILE *f = fopen(path, "rb");
    unsigned char *data = malloc(1 << 22);
    size_t n = f && data ? fread(data, 1, 1 << 22, f) : 0;
    if (f)
        fclose(f);
    CHECK(n > 64 && n < (1 << 22));
    for (size_t at = 0; n > 64 && at < n; at += n / 37 + 1) { /* a flipped byte anywhere */
        data[at] ^= 0x55;
        write_bytes(path, data, n);
        int rc = iso_mesh_chain_load(path, 42, &back, &err);
        CHECKF(rc == ISO_E_CORRUPT || (at < 8 && rc == ISO_E_FORMAT), "byte %zu flipped: %d", at, rc);
        CHECK(back == NULL);
        data[at] ^= 0x55;
    }
    /* Mapped: the header, table and records checked at once, each level before its first
     * cut. The last level's indices end the file: a byte flipped there is found by that
     * level's check only, and the mapping is refused from then on. */
    iso_mesh_chain_map *map = NULL;
    write_bytes(path, data, n);
    CHECK_OK(iso_mesh_chain_map_open(path, 42, &map, &err), &err);
    if (map) {
        const iso_mesh_chain *mc = iso_mesh_chain_map_chain(map);
        CHECK_EQ(mc->levels, chain->levels);
        CHECK_EQ(iso_mesh_chain_map_bytes(map), n);
        CHECK(mc->grid == NULL && !memcmp(mc->positions, chain->positions, 3 * chain->vertex_count * sizeof(float)));
        for (int k = 0; k < mc->levels; k++) {
            CHECK_OK(iso_mesh_chain_map_check(map, k, &err), &err);
            CHECK(!memcmp(mc->level[k].indices, chain->level[k].indices, 3 * chain->level[k].triangle_count * 4));
        }
        CHECK_EQ(iso_mesh_chain_map_check(map, mc->levels, &err), ISO_E_ARGUMENT);
        iso_mesh_chain_map_close(map);
    }
    data[n - 2] ^= 0x55;
    write_bytes(path, data, n);
    map = NULL;
    CHECK_OK(iso_mesh_chain_map_open(path, 42, &map, &err), &err);
    if (map) {
        CHECK_OK(iso_mesh_chain_map_check(map, 0, &err), &err);
        CHECK_EQ(iso_mesh_chain_map_check(map, chain->levels - 1, &err), ISO_E_CORRUPT);
        CHECK_EQ(iso_mesh_chain_map_check(map, 0, &err), ISO_E_CORRUPT);
        iso_mesh_chain_map_close(map);
    }
    data[n - 2] ^= 0x55;
    write_bytes(path, data, n - 5); /* cut short */
    CHECK_EQ(iso_mesh_chain_map_open(path, 42, &map, &err), ISO_E_CORRUPT);
    CHECK(map == NULL);
    CHECK_EQ(iso_mesh_chain_load(path, 42, &back, &err), ISO_E_CORRUPT);
    write_bytes(path, (const unsigned char *)"not a chain at all, but long enough to hold a header of 64 bytes", 64);
    CHECK_EQ(iso_mesh_chain_load(path, 42, &back, &err), ISO_E_FORMAT);
    remove(path);
    CHECK_EQ(iso_mesh_chain_load(path, 42, &back, &err), ISO_E_IO);
    free(data);
    iso_mesh_chain_destroy(chain);
    iso_mesh_free(&m);
    iso_tree_destroy(tree);
    iso_vol_destroy(vol);
}

int main(void)
{
    CHECK_RUN(test_counts_on_hand_built_meshes);
    CHECK_RUN(test_thin_tube_is_not_pinched);
    CHECK_RUN(test_speck_stays);
    CHECK_RUN(test_real_chain_is_not_pinched);
    CHECK_RUN(test_chain_file_round_trip);
    return check_finish();
}
