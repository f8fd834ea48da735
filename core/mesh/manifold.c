/* manifold.c: pinches (non-manifold edges and vertices), counted, and simplification that
 * makes none (see mesh.h).
 *
 * meshoptimizer's collapses do not check the link condition: where a short loop of edges
 * runs around a handle or a thin neck of the surface (CT skin and thin bone have many), a
 * collapse can shrink the loop to a triangle that is not a face, and the two sheets then
 * share an edge of four triangles or a vertex whose triangles make two fans. Passes of
 * iso_simplify_manifold:
 *   1. simplify: the input simplified (iso_simplify) with the locked vertices kept where
 *      they are (none in the first round): every vertex is an input vertex, and the
 *      result is watertight wherever the input was;
 *   2. find: the result's pinches that the input did not have;
 *   3. lock: around each, the input's vertices within the reach of the collapses that made
 *      it (those joined to the pinch by input edges inside a ball of its longest result
 *      edge) are locked, and pass 1 runs again from the input, no longer allowed a larger
 *      error than ISO_MANIFOLD_ERROR_GROWTH times the first round's, at most
 *      ISO_MANIFOLD_ROUNDS times; what is left is counted, never hidden. */
#include "mesh.h"

#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "base/base.h"

#define ISO_MANIFOLD_ERROR_GROWTH 1.25

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

static double distance2(const float *positions, uint32_t a, uint32_t b)
{
    double s = 0;
    for (int d = 0; d < 3; d++) {
        double x = (double)positions[3 * (size_t)a + d] - positions[3 * (size_t)b + d];
        s += x * x;
    }
    return s;
}

/* The longest edge at v among the result's triangles, squared. */
static double reach2(const iso_mesh *result, const vertex_triangles *rt, uint32_t v)
{
    double most = 0;
    for (size_t i = rt->first[v]; i < rt->first[v + 1]; i++)
        for (int k = 0; k < 3; k++) {
            double d = distance2(result->positions, v, result->indices[3 * (size_t)rt->list[i] + k]);
            most = d > most ? d : most;
        }
    return most;
}

/* PASS 3 for pinch p: a walk over the input's edges from p inside the ball, locking every
 * vertex reached (appended to locked). stack and seen (per vertex, cleared by the caller's
 * stamp) are scratch. */
static void lock_around(const iso_mesh *in, const vertex_triangles *vt, uint32_t p, double radius2,
                        unsigned char *is_locked, uint32_t *locked, size_t *locked_count,
                        uint32_t *stack, uint32_t *seen, uint32_t stamp)
{
    size_t top = 0;
    stack[top++] = p;
    seen[p] = stamp;
    while (top) {
        uint32_t v = stack[--top];
        if (!is_locked[v])
            is_locked[v] = 1, locked[(*locked_count)++] = v;
        for (size_t i = vt->first[v]; i < vt->first[v + 1]; i++)
            for (int k = 0; k < 3; k++) {
                uint32_t w = in->indices[3 * (size_t)vt->list[i] + k];
                if (seen[w] != stamp && distance2(in->positions, p, w) <= radius2) {
                    seen[w] = stamp;
                    stack[top++] = w;
                }
            }
    }
}

/* PASS 1: in simplified into out (whose index array holds all of in's) with the locked
 * vertices kept where they are. meshoptimizer 0.18 has no per-vertex lock, but it never
 * moves a vertex that shares its position with another vertex and is not on a seam of
 * open edges: each locked vertex gets a twin no triangle uses, appended to a copy of
 * the positions (ext, vertex_count + locked_count triples). */
static int simplify_locked(const iso_mesh *in, const uint32_t *locked, size_t locked_count,
                           float *ext, const iso_simplify_params *params, iso_mesh *out,
                           iso_simplify_result *r, iso_error *err)
{
    for (size_t i = 0; i < locked_count; i++)
        memcpy(ext + 3 * (in->vertex_count + i), in->positions + 3 * (size_t)locked[i], 3 * sizeof *ext);
    iso_mesh work = *out;
    work.positions = ext;
    work.normals = NULL;
    work.vertex_count = work.vertex_capacity = in->vertex_count + locked_count;
    memcpy(work.indices, in->indices, 3 * in->triangle_count * sizeof *work.indices);
    work.triangle_count = in->triangle_count;
    iso_simplify_params sp = *params;
    sp.keep_vertices = 1;
    sp.measure = 0;
    int rc = iso_simplify(&work, &sp, r, err);
    out->triangle_count = work.triangle_count;
    return rc;
}

typedef struct manifold_work {
    iso_mesh in;              /* the input's triangles (a copy) over the mesh's positions */
    vertex_triangles vt;      /* the input's */
    unsigned char *had, *now; /* pinch marks per vertex: the input's, the result's */
    unsigned char *folds;     /* the corners of folds the last round dropped */
    unsigned char *is_locked; /* per vertex */
    uint32_t *locked;         /* the locked vertices, in the order locked */
    size_t locked_count;
    float *ext;               /* the positions and the locked vertices' twins */
    uint32_t *stack, *seen, stamp;
    uint32_t *remap;          /* for dropping unused vertices */
} manifold_work;

static void work_free(manifold_work *w)
{
    free(w->in.indices);
    vertex_triangles_free(&w->vt);
    free(w->had);
    free(w->now);
    free(w->folds);
    free(w->is_locked);
    free(w->locked);
    free(w->ext);
    free(w->stack);
    free(w->seen);
    free(w->remap);
}

static int work_init(const iso_mesh *mesh, manifold_work *w)
{
    memset(w, 0, sizeof *w);
    size_t nv = mesh->vertex_count + 1, nt = mesh->triangle_count + 1;
    w->in = *mesh;
    w->in.normals = NULL;
    w->in.indices = malloc(3 * nt * sizeof *w->in.indices);
    w->had = malloc(nv);
    w->now = malloc(nv);
    w->folds = calloc(nv, 1);
    w->is_locked = calloc(nv, 1);
    w->locked = malloc(nv * sizeof *w->locked);
    w->ext = malloc(2 * 3 * nv * sizeof *w->ext);
    w->stack = malloc(nv * sizeof *w->stack);
    w->seen = calloc(nv, sizeof *w->seen);
    w->remap = malloc(nv * sizeof *w->remap);
    if (!w->in.indices || !w->had || !w->now || !w->folds || !w->is_locked || !w->locked || !w->ext || !w->stack || !w->seen || !w->remap)
        return ISO_E_NOMEM;
    memcpy(w->in.indices, mesh->indices, 3 * mesh->triangle_count * sizeof *w->in.indices);
    memcpy(w->ext, mesh->positions, 3 * mesh->vertex_count * sizeof *w->ext);
    return vertex_triangles_build(&w->in, &w->vt);
}

/* PASS 2 and 3: locks around the result's new pinches; returns how many there were. */
static int lock_new_pinches(manifold_work *w, const iso_mesh *result, size_t *pinches)
{
    iso_mesh_pinches found;
    int rc = iso_mesh_find_pinches(result, w->now, &found);
    if (rc)
        return rc;
    vertex_triangles rt;
    if (vertex_triangles_build(result, &rt))
        return ISO_E_NOMEM;
    *pinches = 0;
    for (size_t v = 0; v < result->vertex_count; v++) {
        double radius2 = 0;
        if (w->now[v] && !w->had[v])
            radius2 = reach2(result, &rt, (uint32_t)v);
        /* a fold's corner may be used no more: the reach of the input's edges there */
        if (w->folds[v])
            radius2 = fmax(radius2, 4 * reach2(&w->in, &w->vt, (uint32_t)v));
        if (!(radius2 > 0))
            continue;
        ++*pinches;
        lock_around(&w->in, &w->vt, (uint32_t)v, radius2, w->is_locked, w->locked,
                    &w->locked_count, w->stack, w->seen, ++w->stamp);
    }
    vertex_triangles_free(&rt);
    return 0;
}

int iso_simplify_manifold(iso_mesh *mesh, const iso_simplify_params *params,
                          iso_simplify_result *result, iso_error *err)
{
    iso_simplify_result local;
    iso_simplify_result *r = result ? result : &local;
    if (mesh->triangle_count <= params->target_triangles || !params->lock_border)
        return iso_simplify(mesh, params, r, err);
    manifold_work w;
    iso_mesh_pinches had;
    int rc = work_init(mesh, &w);
    if (!rc)
        rc = iso_mesh_find_pinches(&w.in, w.had, &had);
    if (rc) {
        work_free(&w);
        return iso_error_set(err, ISO_E_NOMEM, "simplify: no memory to look for pinches in %zu triangles",
                             mesh->triangle_count);
    }
    double start = iso_clock_ms();
    size_t pinches = 0;
    iso_simplify_params sp = *params;
    sp.fold_marks = w.folds;
    for (int round = 0; !rc; round++) {
        memset(w.folds, 0, w.in.vertex_count);
        if ((rc = simplify_locked(&w.in, w.locked, w.locked_count, w.ext, &sp, mesh, r, err)))
            break;
        /* Locked vertices leave fewer collapses: the count is then not worth any error,
         * only a little more than the first round's (the level keeps more triangles). */
        if (round == 0)
            sp.target_error = fmin(params->target_error, ISO_MANIFOLD_ERROR_GROWTH * r->error);
        if (round == ISO_MANIFOLD_ROUNDS)
            break;
        if ((rc = lock_new_pinches(&w, mesh, &pinches)))
            rc = iso_error_set(err, rc, "simplify: no memory to look for pinches");
        else if (!pinches)
            break;
    }
    iso_mesh_pinches left = {0};
    if (!rc && (rc = iso_mesh_find_pinches(mesh, NULL, &left)))
        rc = iso_error_set(err, rc, "simplify: no memory to count pinches");
    if (!rc && params->measure) {
        double spacing = params->voxel_size > 0 ? params->voxel_size : 1;
        rc = iso_mesh_distance_compute(&w.in, mesh, spacing, params->threads, &r->distance, err);
        r->measured = !rc;
    }
    if (rc) { /* the mesh as it came in */
        memcpy(mesh->indices, w.in.indices, 3 * w.in.triangle_count * sizeof *mesh->indices);
        mesh->triangle_count = w.in.triangle_count;
        work_free(&w);
        return rc;
    }
    r->triangles_in = w.in.triangle_count;
    r->triangles = mesh->triangle_count;
    r->nonmanifold_edges = left.pinch_edges;
    r->pinch_vertices = left.pinch_vertices;
    r->unpaired_edges = left.unpaired_edges;
    r->locked_vertices = w.locked_count;
    r->ms = iso_clock_ms() - start;
    if (!params->keep_vertices)
        iso_mesh_drop_unused_into(mesh, w.remap);
    work_free(&w);
    r->vertices = mesh->vertex_count;
    return 0;
}
