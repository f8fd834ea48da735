/* manifold.c: pinches (non-manifold edges and vertices), counted (see mesh.h).
 *
 * meshoptimizer's collapses do not check the link condition: where a short loop of edges
 * runs around a handle or a thin neck of the surface (CT skin and thin bone have many), a
 * collapse can shrink the loop to a triangle that is not a face, and the two sheets then
 * share an edge of four triangles or a vertex whose triangles make two fans. This file
 * finds them; collapse.c simplifies without making them. */
#include "mesh.h"

#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "base/base.h"

/* Each vertex's triangles (compressed rows: first[v] .. first[v + 1] in list). */
typedef struct vertex_triangles {
    size_t *first;
    uint32_t *list;
} vertex_triangles;

static void vertex_triangles_free(vertex_triangles *vt)
{
    free(vt->first);
    free(vt->list);
}

static int vertex_triangles_build(const iso_mesh *m, vertex_triangles *vt)
{
    vt->first = calloc(m->vertex_count + 2, sizeof *vt->first);
    vt->list = malloc((3 * m->triangle_count + 1) * sizeof *vt->list);
    if (!vt->first || !vt->list) {
        vertex_triangles_free(vt);
        return ISO_E_NOMEM;
    }
    for (size_t i = 0; i < 3 * m->triangle_count; i++)
        vt->first[m->indices[i] + 2]++;
    for (size_t v = 0; v < m->vertex_count; v++)
        vt->first[v + 2] += vt->first[v + 1];
    for (size_t t = 0; t < m->triangle_count; t++)
        for (int k = 0; k < 3; k++)
            vt->list[vt->first[m->indices[3 * t + k] + 1]++] = (uint32_t)t;
    return 0; /* first[v] .. first[v + 1] now holds v's triangles */
}

/* The union-find root of link corner i. */
static size_t root_of(size_t *parent, size_t i)
{
    while (parent[i] != i)
        i = parent[i] = parent[parent[i]];
    return i;
}

/* How many fans v's triangles make: the triangles (v, a, b) joined where they share a
 * corner other than v. scratch holds 6 entries per triangle of v. */
static size_t fans_of(const iso_mesh *m, const vertex_triangles *vt, uint32_t v, size_t *scratch)
{
    size_t begin = vt->first[v], n = vt->first[v + 1] - begin;
    uint32_t *corner = (uint32_t *)scratch; /* 2 n corners, then 2 n parents */
    size_t *parent = scratch + n;
    for (size_t i = 0; i < n; i++) {
        const uint32_t *t = m->indices + 3 * (size_t)vt->list[begin + i];
        int at = t[0] == v ? 0 : t[1] == v ? 1 : 2;
        corner[2 * i] = t[(at + 1) % 3];
        corner[2 * i + 1] = t[(at + 2) % 3];
    }
    for (size_t i = 0; i < n; i++)
        parent[i] = i;
    for (size_t i = 0; i < 2 * n; i++)
        for (size_t j = i + 1; j < 2 * n; j++)
            if (corner[i] == corner[j] && corner[i] != v) {
                size_t a = root_of(parent, i / 2), b = root_of(parent, j / 2);
                if (a != b)
                    parent[a] = b;
            }
    size_t fans = 0;
    for (size_t i = 0; i < n; i++)
        fans += root_of(parent, i) == i;
    return fans;
}

typedef struct pinch_marks {
    unsigned char *mark;
    iso_mesh_pinches *out;
} pinch_marks;

static void count_pinch_edge(void *context, uint32_t lo, uint32_t hi, uint32_t forward, uint32_t backward)
{
    pinch_marks *p = context;
    p->out->edges++;
    if (forward + backward == 1)
        p->out->open_edges++;
    if (forward + backward > 1 && forward != backward)
        p->out->unpaired_edges++;
    if (forward + backward > 2) {
        p->out->pinch_edges++;
        if (p->mark)
            p->mark[lo] = p->mark[hi] = 1;
    }
}

int iso_mesh_find_pinches(const iso_mesh *mesh, unsigned char *mark, iso_mesh_pinches *out)
{
    memset(out, 0, sizeof *out);
    if (mark)
        memset(mark, 0, mesh->vertex_count);
    pinch_marks p = {mark, out};
    int rc = iso_mesh_visit_edges(mesh, count_pinch_edge, &p);
    if (rc)
        return rc;
    vertex_triangles vt;
    if (vertex_triangles_build(mesh, &vt))
        return ISO_E_NOMEM;
    size_t most = 0;
    for (size_t v = 0; v < mesh->vertex_count; v++)
        if (vt.first[v + 1] - vt.first[v] > most)
            most = vt.first[v + 1] - vt.first[v];
    size_t *scratch = malloc((3 * most + 1) * sizeof *scratch);
    if (!scratch) {
        vertex_triangles_free(&vt);
        return ISO_E_NOMEM;
    }
    for (size_t v = 0; v < mesh->vertex_count; v++)
        if (vt.first[v + 1] > vt.first[v] && fans_of(mesh, &vt, (uint32_t)v, scratch) > 1) {
            out->pinch_vertices++;
            if (mark)
                mark[v] = 1;
        }
    free(scratch);
    vertex_triangles_free(&vt);
    return 0;
}
