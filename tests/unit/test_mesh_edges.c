/* test_mesh_edges.c: the edge census (iso_mesh_count_edges) on hand-built meshes with
 * exactly known counts: a closed tetrahedron, the same with a face missing or flipped, a
 * three-page book, a fan whose centre has more edges than the short-list sort handles, an
 * excuse callback, and the refusals. */
#include <stdio.h>
#include <string.h>

#include "check.h"
#include "mesh/mesh.h"

/* A mesh over `vertices` points (positions unused by the census) and the given triangles. */
static void build(iso_mesh *m, size_t vertices, const uint32_t *tri, size_t triangles)
{
    iso_mesh_init(m);
    CHECK_EQ(iso_mesh_reserve(m, vertices, triangles), 0);
    if (vertices) /* the census reads no position; zeroed for the sanitizers' sake */
        memset(m->positions, 0, vertices * 3 * sizeof *m->positions);
    if (triangles)
        memcpy(m->indices, tri, triangles * 3 * sizeof *tri);
    m->vertex_count = vertices;
    m->triangle_count = triangles;
}

static iso_mesh_edges census(const uint32_t *tri, size_t triangles, size_t vertices)
{
    iso_mesh m;
    build(&m, vertices, tri, triangles);
    iso_mesh_edges e;
    memset(&e, 0xff, sizeof e);
    CHECK_EQ(iso_mesh_count_edges(&m, &e), 0);
    iso_mesh_free(&m);
    return e;
}

/* Outward-wound tetrahedron on vertices 0..3. */
static const uint32_t tetra[12] = {0, 2, 1, 0, 1, 3, 0, 3, 2, 1, 2, 3};

static void test_closed_tetrahedron(void)
{
    iso_mesh_edges e = census(tetra, 4, 4);
    CHECK_EQ(e.edges, 6);
    CHECK_EQ(e.open, 0);
    CHECK_EQ(e.nonmanifold, 0);
    CHECK_EQ(e.misoriented, 0);
    CHECK_EQ(e.open_excused, 0);
}

static void test_missing_face_opens_three_edges(void)
{
    iso_mesh_edges e = census(tetra, 3, 4);
    CHECK_EQ(e.edges, 6);
    CHECK_EQ(e.open, 3);
    CHECK_EQ(e.nonmanifold, 0);
    CHECK_EQ(e.misoriented, 0);
}

static void test_flipped_face_misorients_three_edges(void)
{
    uint32_t flipped[12];
    memcpy(flipped, tetra, sizeof flipped);
    flipped[10] = 3, flipped[11] = 2; /* 1,2,3 -> 1,3,2 */
    iso_mesh_edges e = census(flipped, 4, 4);
    CHECK_EQ(e.edges, 6);
    CHECK_EQ(e.open, 0);
    CHECK_EQ(e.misoriented, 3);
    CHECK_EQ(e.nonmanifold, 0);
}

/* Three triangles on the spine 0-1: one non-manifold edge, six open ones. */
static void test_book_of_three_pages(void)
{
    const uint32_t book[9] = {0, 1, 2, 1, 0, 3, 0, 1, 4};
    iso_mesh_edges e = census(book, 3, 5);
    CHECK_EQ(e.edges, 7);
    CHECK_EQ(e.nonmanifold, 1);
    CHECK_EQ(e.open, 6);
    CHECK_EQ(e.misoriented, 0);
}

/* A disc of 40 triangles around vertex 0: its 80 edge uses as lower end go through the
 * long-list sort; 40 spokes inside, 40 rim edges open. */
static void test_fan_of_forty(void)
{
    enum { N = 40 };
    uint32_t fan[3 * N];
    for (uint32_t i = 0; i < N; i++) {
        fan[3 * i] = 0;
        fan[3 * i + 1] = 1 + i;
        fan[3 * i + 2] = 1 + (i + 1) % N;
    }
    iso_mesh_edges e = census(fan, N, N + 1);
    CHECK_EQ(e.edges, 2 * N);
    CHECK_EQ(e.open, N);
    CHECK_EQ(e.nonmanifold, 0);
    CHECK_EQ(e.misoriented, 0);
}

/* Excuses the open edges whose both ends are even. */
static int both_even(void *context, uint32_t a, uint32_t b)
{
    (*(int *)context)++;
    return a % 2 == 0 && b % 2 == 0;
}

static void test_excuse_is_asked_about_open_edges_only(void)
{
    /* The missing face of test_missing_face_opens_three_edges is 1,2,3: its open edges are
     * 1-2, 2-3 and 1-3, none with both ends even. Without face 0,2,1 instead: 0-2 is. */
    const uint32_t three[9] = {0, 1, 3, 0, 3, 2, 1, 2, 3};
    iso_mesh m;
    build(&m, 4, three, 3);
    iso_mesh_edges e;
    int asked = 0;
    CHECK_EQ(iso_mesh_count_edges_excusing(&m, both_even, &asked, &e), 0);
    CHECK_EQ(asked, 3);
    CHECK_EQ(e.open_excused, 1);
    CHECK_EQ(e.open, 2);
    CHECK_EQ(e.edges, 6);
    iso_mesh_free(&m);
}

static void test_empty_and_bad_indices(void)
{
    iso_mesh_edges e = census(NULL, 0, 0);
    CHECK_EQ(e.edges, 0);
    CHECK_EQ(e.open, 0);
    const uint32_t bad[3] = {0, 1, 7};
    iso_mesh m;
    build(&m, 3, bad, 1);
    CHECK_EQ(iso_mesh_count_edges(&m, &e), ISO_E_ARGUMENT);
    iso_mesh_free(&m);
}

int main(void)
{
    CHECK_RUN(test_closed_tetrahedron);
    CHECK_RUN(test_missing_face_opens_three_edges);
    CHECK_RUN(test_flipped_face_misorients_three_edges);
    CHECK_RUN(test_book_of_three_pages);
    CHECK_RUN(test_fan_of_forty);
    CHECK_RUN(test_excuse_is_asked_about_open_edges_only);
    CHECK_RUN(test_empty_and_bad_indices);
    return check_finish();
}
