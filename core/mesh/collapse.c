/* collapse.c: simplification that makes no pinch (iso_simplify_manifold, see mesh.h):
 * half-edge collapses, cheapest first by quadric error, each refused where it would break
 * the link condition (and so pinch two sheets together or lay one triangle onto another)
 * or turn a triangle over. Every vertex left is an input vertex where it was.
 *
 * Passes of iso_simplify_manifold:
 *   1. adjacency: each vertex's corners, a linked list through the triangles' corners;
 *   2. lock: a vertex on an edge not used exactly once each way (an open edge: the border)
 *      or whose triangles make more than one fan stays where it is (collapses onto it are
 *      allowed);
 *   3. quadrics: each vertex gets the area-weighted plane quadrics of its triangles;
 *   4. order: each free vertex's cheapest collapse onto a neighbour goes into a heap, its
 *      cost the vertex's quadric at the neighbour per unit of area (meshoptimizer's
 *      measure, so the errors compare with iso_simplify's);
 *      (ranked by cost, ties by vertex number; with iso_collapser_coarse, the cheap ones
 *      by classes of a factor of 2 and vertex number: rank_of);
 *   5. collapse: the cheapest is checked (its edge has two triangles, its ends share no
 *      neighbour but their two opposite corners, no triangle turns over) and made: the
 *      removed vertex's quadric joins the kept one's and the kept vertex and its neighbours
 *      are costed again. A refused one goes back with its cheapest allowed collapse, or
 *      waits until its neighbourhood changes. Until the target count, or the next
 *      collapse would exceed the target error;
 *   6. write: the triangles left, in their input order. */
#include "collapse.h"

#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "base/base.h"

#define NONE UINT32_MAX
#define LOCKED 1u
#define REMOVED 2u
#define CHECKED 4u /* the vertex's key is its cheapest allowed collapse's, not a bound */
#define ON_BORDER 8u /* on an open edge (and LOCKED) */

typedef struct quadric {
    double a00, a01, a02, a11, a12, a22, b0, b1, b2, c, w;
} quadric;

struct iso_collapser {
    const float *pos;
    uint32_t *tri;           /* the triangles' corners, relabelled as vertices collapse */
    unsigned char *dead;     /* per triangle */
    uint32_t *head, *next;   /* per vertex its first corner, per corner the next (NONE ends) */
    unsigned char *flags;    /* per vertex: LOCKED, REMOVED */
    quadric *q;
    uint64_t *heap;          /* a binary min-heap of the vertices' ranks (rank_of) */
    uint32_t *slot;          /* each vertex's place in it */
    double *key;             /* per vertex: its cheapest collapse's cost */
    uint32_t *to;            /* per vertex: that collapse's target */
    size_t heap_count;
    unsigned char *refused;  /* per vertex: a collapse of it was refused for its topology */
    size_t alive;
    size_t triangle_count, vertex_count;
    double worst;            /* the largest cost collapsed */
    double fine_from;        /* keys below rank in coarse classes (rank_of) */
    double coarse;           /* iso_collapser_coarse's share and target */
    size_t coarse_target;
    double *sample;          /* RANK_SAMPLE keys: where a run will stop (ranks_for) */
};
typedef struct iso_collapser collapser;

void iso_collapser_destroy(collapser *c)
{
    if (!c)
        return;
    free(c->tri);
    free(c->dead);
    free(c->head);
    free(c->next);
    free(c->flags);
    free(c->q);
    free(c->heap);
    free(c->sample);
    free(c->slot);
    free(c->key);
    free(c->to);
    free(c->refused);
    free(c);
}

/* ---- the heap ---- */

/* A vertex's rank in the heap: its key's class, then its number. A key at or above
 * fine_from has a fine class (the double's exponent and top 20 bits of mantissa: cost
 * order), one below it a coarse class (its exponent: a factor of 2). Within a class,
 * collapses go in vertex order, which is memory order (neighbours in space are near in
 * number), so that consecutive collapses reuse each other's cache lines instead of each
 * starting cold. The coarse classes cover only the costs well below where the run will
 * stop (iso_collapser_run), whose collapses are all made whatever their order; the last
 * ones, which decide the level's error, go in cost order. A key >= 0 has monotone bits;
 * the rank carries the vertex (its low 32 bits). */
#define RANK_SAMPLE 1024   /* keys sampled to find where a run will stop */
#define FINE_BITS 0xffffffff00000000u
#define COARSE_BITS 0xfff0000000000000u

static uint64_t rank_of(const collapser *c, double key, uint32_t v)
{
    uint64_t bits;
    memcpy(&bits, &key, sizeof bits);
    return (bits & (key < c->fine_from ? COARSE_BITS : FINE_BITS)) | v;
}

static void heap_place(collapser *c, size_t i, uint64_t rank)
{
    c->heap[i] = rank;
    c->slot[(uint32_t)rank] = (uint32_t)i;
}

/* The heap is 4-ary: half the depth of a binary one, and a node's four children share a
 * cache line. Ranks are distinct (they carry the vertex), so the collapses come out in
 * the same order from any heap. */
static void heap_up(collapser *c, size_t i)
{
    uint64_t rank = c->heap[i];
    while (i > 0) {
        size_t parent = (i - 1) / 4;
        if (c->heap[parent] < rank)
            break;
        heap_place(c, i, c->heap[parent]);
        i = parent;
    }
    heap_place(c, i, rank);
}

static void heap_down(collapser *c, size_t i)
{
    uint64_t rank = c->heap[i];
    for (;;) {
        size_t first = 4 * i + 1, child = first;
        if (first >= c->heap_count)
            break;
        for (size_t j = first + 1; j < first + 4 && j < c->heap_count; j++)
            child = c->heap[j] < c->heap[child] ? j : child;
        if (rank < c->heap[child])
            break;
        heap_place(c, i, c->heap[child]);
        i = child;
    }
    heap_place(c, i, rank);
}

/* The heap's entries made a heap, bottom up (Floyd). An empty heap (every vertex locked:
 * a surface all of whose vertices lie on its borders) has no root to sift. */
static void heapify(collapser *c)
{
    if (!c->heap_count)
        return;
    for (size_t i = c->heap_count / 4 + 1; i-- > 0;)
        heap_down(c, i);
}

/* v enters the heap, or moves in it, with cost key. */
static void heap_set(collapser *c, uint32_t v, double key)
{
    c->key[v] = key;
    uint64_t rank = rank_of(c, key, v);
    if (c->slot[v] == NONE) {
        heap_place(c, c->heap_count++, rank);
        heap_up(c, c->heap_count - 1);
        return;
    }
    size_t i = c->slot[v];
    uint64_t old = c->heap[i];
    c->heap[i] = rank;
    if (rank < old)
        heap_up(c, i);
    else
        heap_down(c, i);
}

static void heap_remove(collapser *c, uint32_t v)
{
    size_t i = c->slot[v];
    if (i == NONE)
        return;
    c->slot[v] = NONE;
    uint64_t last = c->heap[--c->heap_count];
    if (i == c->heap_count)
        return;
    heap_place(c, i, last);
    heap_up(c, i);
    heap_down(c, c->slot[(uint32_t)last]);
}

/* ---- quadrics ---- */

static void quadric_add_triangle(quadric *q, const float *p0, const float *p1, const float *p2)
{
    double e1[3], e2[3], n[3];
    for (int d = 0; d < 3; d++)
        e1[d] = (double)p1[d] - p0[d], e2[d] = (double)p2[d] - p0[d];
    n[0] = e1[1] * e2[2] - e1[2] * e2[1];
    n[1] = e1[2] * e2[0] - e1[0] * e2[2];
    n[2] = e1[0] * e2[1] - e1[1] * e2[0];
    double length = sqrt(n[0] * n[0] + n[1] * n[1] + n[2] * n[2]);
    if (!(length > 0))
        return;
    for (int d = 0; d < 3; d++)
        n[d] /= length;
    double dist = -(n[0] * p0[0] + n[1] * p0[1] + n[2] * p0[2]), w = 0.5 * length;
    q->a00 += w * n[0] * n[0], q->a01 += w * n[0] * n[1], q->a02 += w * n[0] * n[2];
    q->a11 += w * n[1] * n[1], q->a12 += w * n[1] * n[2], q->a22 += w * n[2] * n[2];
    q->b0 += w * dist * n[0], q->b1 += w * dist * n[1], q->b2 += w * dist * n[2];
    q->c += w * dist * dist, q->w += w;
}

static void quadric_join(quadric *into, const quadric *q)
{
    into->a00 += q->a00, into->a01 += q->a01, into->a02 += q->a02;
    into->a11 += q->a11, into->a12 += q->a12, into->a22 += q->a22;
    into->b0 += q->b0, into->b1 += q->b1, into->b2 += q->b2;
    into->c += q->c, into->w += q->w;
}

/* The mean squared distance of q's planes from p, weighted by area. */
static inline double quadric_error(const quadric *q, const float *p)
{
    double x = p[0], y = p[1], z = p[2];
    double e = q->a00 * x * x + q->a11 * y * y + q->a22 * z * z +
               2 * (q->a01 * x * y + q->a02 * x * z + q->a12 * y * z) +
               2 * (q->b0 * x + q->b1 * y + q->b2 * z) + q->c;
    return q->w > 0 ? fabs(e) / q->w : 0;
}

static inline double cost_of(const collapser *c, uint32_t u, uint32_t v)
{
    return quadric_error(&c->q[u], c->pos + 3 * (size_t)v);
}

/* The corner after and before corner k of its triangle. */
static uint32_t after(const collapser *c, uint32_t k)
{
    uint32_t r = k % 3;
    return c->tri[r == 2 ? k - 2 : k + 1];
}

static uint32_t before(const collapser *c, uint32_t k)
{
    uint32_t r = k % 3;
    return c->tri[r == 0 ? k + 2 : k - 1];
}

/* PASS 4: u's cheapest collapse, its topology not checked (a lower bound of the allowed
 * ones'), into the heap; a locked or isolated vertex stays out. */
static void order(collapser *c, uint32_t u)
{
    c->flags[u] &= (unsigned char)~CHECKED;
    if (c->flags[u] & (LOCKED | REMOVED)) {
        heap_remove(c, u);
        return;
    }
    double best = INFINITY;
    uint32_t to = NONE;
    const quadric q = c->q[u]; /* in registers across the walk */
    for (uint32_t k = c->head[u]; k != NONE; k = c->next[k]) {
        uint32_t x = after(c, k);
        double e = quadric_error(&q, c->pos + 3 * (size_t)x);
        if (e < best)
            best = e, to = x;
    }
    if (to == NONE) {
        heap_remove(c, u);
        return;
    }
    c->to[u] = to;
    heap_set(c, u, best);
}

/* Whether triangle (u, x, y) moved to (v, x, y) turns over (or collapses to a line). */
static int turns_over(const float *pu, const float *pv, const float *px, const float *py)
{
    double ex[3], ey[3], fx[3], fy[3];
    for (int d = 0; d < 3; d++) {
        ex[d] = (double)px[d] - pu[d], ey[d] = (double)py[d] - pu[d];
        fx[d] = (double)px[d] - pv[d], fy[d] = (double)py[d] - pv[d];
    }
    double n0[3] = {ex[1] * ey[2] - ex[2] * ey[1], ex[2] * ey[0] - ex[0] * ey[2], ex[0] * ey[1] - ex[1] * ey[0]};
    double n1[3] = {fx[1] * fy[2] - fx[2] * fy[1], fx[2] * fy[0] - fx[0] * fy[2], fx[0] * fy[1] - fx[1] * fy[0]};
    return n0[0] * n1[0] + n0[1] * n1[1] + n0[2] * n1[2] <= 0;
}

#define MAX_VALENCE 64 /* a free vertex with more triangles stays (its checks' scratch) */

/* Whether the edge u->v's collapse keeps the surface a manifold without turning a
 * triangle over, and leaves no component without a closed form: 1 yes, 0 no. a and b
 * receive the edge's opposite corners.
 * One walk over u's triangles gathers its neighbours (on the stack: no per-vertex marks
 * to write), finds the edge's two triangles and checks the others' turning; one over
 * v's checks the link condition. */
static int allowed(const collapser *c, uint32_t u, uint32_t v, uint32_t *a, uint32_t *b)
{
    if (c->flags[v] & REMOVED)
        return 0;
    uint32_t near[MAX_VALENCE], apex[2] = {NONE, NONE};
    int shared = 0;
    size_t valence_u = 0, valence_v = 0;
    const float *pu = c->pos + 3 * (size_t)u, *pv = c->pos + 3 * (size_t)v;
    uint32_t first_x = NONE, first_y = NONE; /* a triangle of u without v: (u, a, b)? */
    for (uint32_t k = c->head[u]; k != NONE; k = c->next[k]) {
        uint32_t x = after(c, k), y = before(c, k);
        if (valence_u == MAX_VALENCE)
            return 0;
        near[valence_u++] = x; /* u's fan is closed: each neighbour comes once as x */
        if (x == v || y == v) {
            if (shared < 2)
                apex[shared] = x == v ? y : x;
            shared++;
        } else {
            if (turns_over(pu, pv, c->pos + 3 * (size_t)x, c->pos + 3 * (size_t)y))
                return 0;
            first_x = x, first_y = y;
        }
    }
    if (shared != 2 || apex[0] == apex[1])
        return 0;
    *a = apex[0], *b = apex[1];
    /* No new edge between two border vertices: where the border is a cut between parts
     * simplified apart (the chain's slabs), the other part may make the same edge, and
     * joined, it would have four triangles. */
    if (c->flags[v] & ON_BORDER)
        for (size_t i = 0; i < valence_u; i++)
            if (near[i] != v && near[i] != *a && near[i] != *b && (c->flags[near[i]] & ON_BORDER))
                return 0;
    /* u of valence 3 has one triangle without v, on (u, a, b) */
    int facing_ab = valence_u == 3 && ((first_x == *a && first_y == *b) || (first_x == *b && first_y == *a));
    /* The link condition: the ends' only common neighbours are the opposite corners. */
    int tetrahedron = 0;
    for (uint32_t k = c->head[v]; k != NONE; k = c->next[k]) {
        uint32_t x = after(c, k), y = before(c, k);
        valence_v++;
        for (size_t i = 0; i < valence_u; i++)
            if ((near[i] == x || near[i] == y) && near[i] != u && near[i] != *a && near[i] != *b)
                return 0;
        tetrahedron |= (x == *a && y == *b) || (x == *b && y == *a);
    }
    /* A lone tetrahedron's collapse would fold it; it stays, as its component's smallest
     * closed form (no component of the surface goes). */
    if (facing_ab && tetrahedron && valence_v == 3)
        return 0;
    return 1;
}

/* x's corner list without the dead triangles' corners. */
static void compact(collapser *c, uint32_t x)
{
    uint32_t *link = &c->head[x];
    while (*link != NONE) {
        if (c->dead[*link / 3])
            *link = c->next[*link];
        else
            link = &c->next[*link];
    }
}

static void remove_vertex(collapser *c, uint32_t v)
{
    c->flags[v] |= REMOVED;
    c->head[v] = NONE;
    heap_remove(c, v);
}

/* PASS 5: u onto v, the edge's opposite corners a and b. */
static void collapse(collapser *c, uint32_t u, uint32_t v, uint32_t a, uint32_t b)
{
    uint32_t last = NONE;
    for (uint32_t k = c->head[u]; k != NONE; k = c->next[k]) {
        uint32_t t = k / 3;
        if (c->tri[3 * t] == v || c->tri[3 * t + 1] == v || c->tri[3 * t + 2] == v) {
            c->dead[t] = 1;
            c->alive--;
        } else {
            c->tri[k] = v;
        }
        last = k;
    }
    if (last != NONE) { /* u's corners join v's */
        c->next[last] = c->head[v];
        c->head[v] = c->head[u];
    }
    quadric_join(&c->q[v], &c->q[u]);
    remove_vertex(c, u);
    compact(c, v);
    compact(c, a);
    compact(c, b);
    /* A neighbour's quadric is as it was and its neighbours are too, but for u gone and
     * v come: only a collapse onto v is new, unless its cheapest went to u. */
    order(c, v);
    for (uint32_t k = c->head[v]; k != NONE; k = c->next[k]) {
        uint32_t x = after(c, k);
        if (c->flags[x] || c->slot[x] == NONE || c->to[x] == u) {
            order(c, x);
            continue;
        }
        double e = cost_of(c, x, v);
        if (e < c->key[x]) {
            c->to[x] = v;
            heap_set(c, x, e);
        }
    }
}

/* A refused u gets its cheapest allowed collapse back in the heap, or leaves it. */
static void reorder(collapser *c, uint32_t u)
{
    c->refused[u] = 1;
    double best = INFINITY;
    uint32_t to = NONE, a, b;
    for (uint32_t k = c->head[u]; k != NONE; k = c->next[k]) {
        uint32_t x = after(c, k);
        double e = cost_of(c, u, x);
        if (e < best && allowed(c, u, x, &a, &b))
            best = e, to = x;
    }
    if (to == NONE) {
        heap_remove(c, u);
        return;
    }
    c->to[u] = to;
    c->flags[u] |= CHECKED;
    heap_set(c, u, best);
}

/* PASS 2 for vertex u: 0 when its edges are each used once each way and its triangles
 * make one fan, BORDER when two of its edges are open and its triangles one fan from one
 * to the other, PINCHED otherwise. xs and ys (room for u's valence) receive each of u's
 * triangles' corner after and before u, so that the pairwise checks run on the stack's
 * cache lines instead of walking the corner list again for each triangle. */
#define BORDER 1
#define PINCHED 2

/* kind_of's common case, in about n * n / 2 comparisons instead of 3 * n * n: the walk
 * from triangle 0 to the first triangle whose corner before u is this one's corner after
 * u comes back to triangle 0 first after exactly n steps. Then it met every triangle once,
 * so each corner after u is the corner before u of exactly one triangle: every edge is
 * used once each way and the triangles make one closed fan. 0 leaves the full check. */
static int one_closed_fan(const uint32_t *xs, const uint32_t *ys, size_t n)
{
    size_t i = 0;
    for (size_t steps = 1; steps <= n; steps++) {
        size_t j = 0;
        while (j < n && ys[j] != xs[i])
            j++;
        if (j == n || (j == 0) != (steps == n))
            return 0;
        i = j;
    }
    return 1;
}
static int kind_of(const collapser *c, uint32_t u, uint32_t *xs, uint32_t *ys)
{
    size_t n = 0, open = 0, start = 0;
    for (uint32_t k = c->head[u]; k != NONE; k = c->next[k])
        xs[n] = after(c, k), ys[n++] = before(c, k);
    if (n >= 3 && one_closed_fan(xs, ys, n))
        return 0;
    for (size_t i = 0; i < n; i++) {
        size_t forward = 0, backward = 0, into = 0;
        for (size_t j = 0; j < n; j++)
            forward += xs[j] == xs[i], backward += ys[j] == xs[i], into += xs[j] == ys[i];
        if (forward != 1 || backward > 1)
            return PINCHED;
        open += !backward;
        if (!into) /* no triangle leads into this one: an open fan starts here */
            start = i;
    }
    if (n < 3 || (open != 0 && open != 1))
        return PINCHED;
    /* One fan: walking from triangle to triangle across u's edges meets all n. */
    size_t i = start, steps = 0;
    do {
        size_t j = 0;
        while (j < n && ys[j] != xs[i])
            j++;
        i = j;
        steps++;
    } while (i < n && i != start && steps <= n);
    if (steps != n || (open ? i < n : i != start))
        return PINCHED;
    return open ? BORDER : 0;
}

int iso_collapser_create(const iso_mesh *mesh, collapser **out, int *pinch_free)
{
    collapser *c = calloc(1, sizeof *c);
    *out = c;
    if (!c)
        return ISO_E_NOMEM;
    size_t nv = mesh->vertex_count ? mesh->vertex_count : 1, nt = mesh->triangle_count ? mesh->triangle_count : 1;
    c->pos = mesh->positions;
    c->tri = malloc(3 * nt * sizeof *c->tri);
    c->dead = calloc(nt, 1);
    c->next = malloc(3 * nt * sizeof *c->next);
    c->head = malloc(nv * sizeof *c->head);
    c->flags = calloc(nv, 1);
    c->q = calloc(nv, sizeof *c->q);
    c->heap = malloc(nv * sizeof *c->heap);
    c->sample = malloc(RANK_SAMPLE * sizeof *c->sample);
    c->slot = malloc(nv * sizeof *c->slot);
    c->key = malloc(nv * sizeof *c->key);
    c->to = malloc(nv * sizeof *c->to);
    c->refused = calloc(nv, 1);
    if (!c->tri || !c->dead || !c->next || !c->head || !c->flags || !c->q || !c->heap || !c->sample || !c->slot ||
        !c->key || !c->to || !c->refused) {
        iso_collapser_destroy(c);
        *out = NULL;
        return ISO_E_NOMEM;
    }
    c->triangle_count = mesh->triangle_count, c->vertex_count = mesh->vertex_count;
    memcpy(c->tri, mesh->indices, 3 * mesh->triangle_count * sizeof *c->tri);
    memset(c->slot, 0xff, nv * sizeof *c->slot);
    /* PASS 1 */
    memset(c->head, 0xff, nv * sizeof *c->head);
    for (size_t k = 3 * mesh->triangle_count; k-- > 0;) {
        c->next[k] = c->head[c->tri[k]];
        c->head[c->tri[k]] = (uint32_t)k;
    }
    c->alive = mesh->triangle_count;
    /* PASS 3 */
    for (size_t t = 0; t < mesh->triangle_count; t++) {
        const uint32_t *x = c->tri + 3 * t;
        const float *p0 = c->pos + 3 * (size_t)x[0], *p1 = c->pos + 3 * (size_t)x[1], *p2 = c->pos + 3 * (size_t)x[2];
        quadric q = {0};
        quadric_add_triangle(&q, p0, p1, p2);
        for (int k = 0; k < 3; k++)
            quadric_join(&c->q[x[k]], &q);
    }
    /* PASS 2, then PASS 4 over the free vertices */
    size_t most = 0; /* the largest valence: kind_of's scratch */
    for (uint32_t v = 0; v < mesh->vertex_count; v++) {
        size_t n = 0;
        for (uint32_t k = c->head[v]; k != NONE; k = c->next[k])
            n++;
        most = n > most ? n : most;
    }
    uint32_t *scratch = malloc(2 * (most + 1) * sizeof *scratch);
    if (!scratch) {
        iso_collapser_destroy(c);
        *out = NULL;
        return ISO_E_NOMEM;
    }
    *pinch_free = 1;
    for (uint32_t v = 0; v < mesh->vertex_count; v++) {
        int kind = c->head[v] == NONE ? 0 : kind_of(c, v, scratch, scratch + most + 1);
        c->flags[v] |= kind ? LOCKED : 0;
        c->flags[v] |= kind == BORDER ? ON_BORDER : 0;
        *pinch_free &= kind != PINCHED;
    }
    free(scratch);
    /* PASS 4 as order() would make it, over the corners in turn rather than vertex by
     * vertex (the same first cheapest: a vertex's corner list runs in corner order), so
     * that the triangles are read once in memory order. */
    for (size_t v = 0; v < mesh->vertex_count; v++)
        c->key[v] = INFINITY, c->to[v] = NONE;
    for (uint32_t k = 0; k < 3 * mesh->triangle_count; k++) {
        uint32_t u = c->tri[k];
        if (c->flags[u] & LOCKED)
            continue;
        double e = cost_of(c, u, after(c, k));
        if (e < c->key[u])
            c->key[u] = e, c->to[u] = after(c, k);
    }
    for (uint32_t v = 0; v < mesh->vertex_count; v++)
        if (c->to[v] != NONE)
            heap_place(c, c->heap_count++, rank_of(c, c->key[v], v));
    heapify(c);
    return 0;
}

static int by_value(const void *a, const void *b)
{
    double x = *(const double *)a, y = *(const double *)b;
    return (x > y) - (x < y);
}

/* PASS 5's ranks: fine_from becomes c->coarse times the cost where simplifying to
 * c->coarse_target triangles is expected to stop (the sampled key that many collapses in
 * would reach it: low, since costs grow as quadrics join, so the last collapses stay in
 * cost order; the target of the whole simplification, not of one step of it, so that
 * steps of error, as the chain's slabs run, get memory order too), and the heap is
 * ranked again when that moved by more than a factor of 2. */
static void ranks_for(collapser *c)
{
    size_t target = c->coarse_target;
    size_t n = c->heap_count, m = 0;
    if (!n || !(c->coarse > 0))
        return;
    for (size_t i = 0; i < RANK_SAMPLE; i++) { /* by vertex: the same from any heap */
        size_t v = i * c->vertex_count / RANK_SAMPLE;
        if (c->slot[v] != NONE)
            c->sample[m++] = c->key[v];
    }
    if (!m)
        c->sample[m++] = c->key[(uint32_t)c->heap[0]];
    qsort(c->sample, m, sizeof *c->sample, by_value);
    size_t collapses = c->alive > target ? (c->alive - target + 1) / 2 : 0;
    double stop = c->sample[collapses >= n ? m - 1 : collapses * m / n];
    double fine_from = c->coarse * stop;
    if (c->fine_from > 0 && fine_from <= 2 * c->fine_from && 2 * fine_from >= c->fine_from)
        return;
    c->fine_from = fine_from;
    for (size_t i = 0; i < n; i++) {
        uint32_t v = (uint32_t)c->heap[i];
        c->heap[i] = rank_of(c, c->key[v], v);
    }
    heapify(c);
}

size_t iso_collapser_run(collapser *c, size_t target_triangles, double target_error)
{
    /* PASS 5 */
    double limit = target_error * target_error;
    ranks_for(c);
    while (c->alive > target_triangles && c->heap_count) {
        uint32_t u = (uint32_t)c->heap[0], a, b;
        if (c->key[u] > limit)
            break;
        int ok = allowed(c, u, c->to[u], &a, &b);
        if (!ok) {
            reorder(c, u);
            continue;
        }
        c->worst = fmax(c->worst, c->key[u]);
        collapse(c, u, c->to[u], a, b);
    }
    return c->alive;
}

void iso_collapser_triangles(const collapser *c, uint32_t *out)
{
    /* PASS 6 */
    size_t kept = 0;
    for (size_t t = 0; t < c->triangle_count; t++)
        if (!c->dead[t])
            memcpy(out + 3 * kept++, c->tri + 3 * t, 3 * sizeof *out);
}

void iso_collapser_coarse(collapser *c, double share, size_t target_triangles)
{
    c->coarse = share;
    c->coarse_target = target_triangles;
}

double iso_collapser_next(const collapser *c)
{
    return c->heap_count ? sqrt(c->key[(uint32_t)c->heap[0]]) : INFINITY;
}

double iso_collapser_error(const collapser *c)
{
    return sqrt(c->worst);
}

size_t iso_collapser_refused(const collapser *c)
{
    size_t n = 0;
    for (size_t v = 0; v < c->vertex_count; v++)
        n += c->refused[v] && !(c->flags[v] & REMOVED);
    return n;
}

int iso_simplify_manifold(iso_mesh *mesh, const iso_simplify_params *params,
                          iso_simplify_result *result, iso_error *err)
{
    iso_simplify_result local;
    iso_simplify_result *r = result ? result : &local;
    if (mesh->triangle_count <= params->target_triangles || !params->lock_border)
        return iso_simplify(mesh, params, r, err);
    if (params->target_triangles < 1 || !(params->target_error >= 0) || !(params->voxel_size >= 0) ||
        !isfinite(params->voxel_size))
        return iso_simplify(mesh, params, r, err); /* its argument errors */
    double start = iso_clock_ms();
    *r = (iso_simplify_result){.triangles_in = mesh->triangle_count, .vertices_in = mesh->vertex_count,
                               .scale = 1};
    collapser *c;
    int pinch_free;
    if (iso_collapser_create(mesh, &c, &pinch_free))
        return iso_error_set(err, ISO_E_NOMEM, "simplify: no memory for %zu triangles", mesh->triangle_count);
    size_t kept = iso_collapser_run(c, params->target_triangles, params->target_error);
    /* The result goes to a buffer of its own and replaces the mesh's indices only when
     * nothing can fail any more. */
    iso_mesh view = *mesh;
    view.indices = malloc((3 * kept + 1) * sizeof *view.indices);
    view.triangle_count = kept;
    uint32_t *remap = params->keep_vertices ? NULL : malloc((mesh->vertex_count ? mesh->vertex_count : 1) * sizeof *remap);
    iso_mesh_pinches left = {0};
    int rc = !view.indices || (!params->keep_vertices && !remap)
                 ? iso_error_set(err, ISO_E_NOMEM, "simplify: no memory for the result")
                 : 0;
    if (!rc) {
        iso_collapser_triangles(c, view.indices);
        r->error = iso_collapser_error(c);
        r->error_voxels = r->error / (params->voxel_size > 0 ? params->voxel_size : 1);
        r->locked_vertices = iso_collapser_refused(c);
    }
    iso_collapser_destroy(c);
    /* Collapses that keep the link condition make no pinch: only the input's can be left. */
    if (!rc && !pinch_free && (rc = iso_mesh_find_pinches(&view, NULL, &left)))
        rc = iso_error_set(err, rc, "simplify: no memory to count pinches");
    if (!rc && params->measure) {
        double spacing = params->voxel_size > 0 ? params->voxel_size : 1;
        rc = iso_mesh_distance_compute(mesh, &view, spacing, params->threads, &r->distance, err);
        r->measured = !rc;
    }
    if (!rc) {
        memcpy(mesh->indices, view.indices, 3 * kept * sizeof *view.indices);
        mesh->triangle_count = kept;
        r->triangles = kept;
        r->nonmanifold_edges = left.pinch_edges;
        r->pinch_vertices = left.pinch_vertices;
        r->unpaired_edges = left.unpaired_edges;
        if (remap)
            iso_mesh_drop_unused_into(mesh, remap);
        r->vertices = mesh->vertex_count;
    }
    free(view.indices);
    free(remap);
    r->ms = iso_clock_ms() - start;
    return rc;
}
