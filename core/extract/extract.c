/* extract.c: iso-surface extraction over the hierarchy (Elber and Malzbender, with
 * Wilhelms and Van Gelder's min/max pruning), and the full-scan marching cubes baseline.
 *
 * Everything that is not fanned is marching cubes by the brick kernel (march.c), which
 * computes each crossing once and gives it one id; fans name their loop vertices by grid
 * edge and take those ids, so no weld is needed. Tolerance 0 is the kernel alone.
 *
 * PASS 1 (descend, tolerance > 0): from the root, skip every stored node whose [min, max]
 *   cannot hold the level; stop at the first node of at least MIN_FAN_CELLS cells whose
 *   fit error is within the fit share of the tolerance and whose face loops fan within
 *   the tolerance (fan.c). The bricks inside a fanned node are marked: the kernel numbers
 *   their crossings but marches none of their cells. Stored leaves are the kernel's
 *   bricks (tree.h), so an unfanned leaf goes to PASS 2 whole. The top of the tree is
 *   walked on one thread down to a depth with several subtrees per thread; the subtrees
 *   are walked on the threads, and their fans kept in the serial walk's order.
 * PASS 2 (march): the kernel classifies the active bricks; for each unmarked one, the
 *   same rule runs on the fly below it (cover), on its samples read once: a sub-box is
 *   active when it holds a mixed cell (the kernel's bits), its fit error is scanned with
 *   an early exit past the limit, its fan classifies its faces by the kernel's inside bits
 *   (transposed once per brick for faces across the rows), and a fanned sub-box's cells
 *   are covered. The kernel then marches the cells left.
 * PASS 3 (number the fans): fan centres become new vertices, loop vertices the kernel's
 *   ids; the vertices only fanned-over cells used are dropped.
 * PASS 4 (cap, if asked): the cells between the volume's border samples and a virtual
 *   layer below every level around it, welded on in index space.
 * PASS 5 (place): index space to world millimetres, if asked (the kernel places its own
 *   vertices directly when there is no cap). */
#include "extract.h"

#include <assert.h>
#include <limits.h>
#include <math.h>
#include <stdatomic.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

#include "base/base.h"
#include "fan.h"
#include "hierarchy/tree.h"
#include "march.h"
#include "mc.h"

#define BRICK_SAMPLES (ISO_BRICK_SAMPLES * ISO_BRICK_SAMPLES * ISO_BRICK_SAMPLES)

/* The smallest box a fan may replace (tree.h says why). */
#define MIN_FAN_CELLS ISO_TREE_FAN_MIN_CELLS
/* Subtrees per thread PASS 1 splits the tree into: enough that a thread which finishes
 * early takes another. */
#define TOP_UNITS_PER_THREAD 8
/* Share of the tolerance a fan's centre may be off the level (Newton lands far closer). */
#define CENTRE_SHARE (1.0 / 64)

/* What the fans of one walk did, summed into the stats at the end. */
typedef struct fan_tally {
    size_t nodes_visited, nodes_polygonized;
    double vertex_error, fit_error;
} fan_tally;

/* The first centre and triangle of one brick's fans in its thread's output. */
typedef struct fan_mark {
    size_t brick;  /* its index in the grid, z, y, then x */
    size_t centre, triangle;
} fan_mark;

/* The fans one thread made below the bricks (PASS 2), and its scratch. */
typedef struct sub_walk {
    iso_fan_scratch scratch;
    iso_fan_output fans;
    fan_tally tally;
    iso_march_brick *brick;         /* the brick at hand */
    double samples[BRICK_SAMPLES];  /* its samples, x fastest, brick->n per axis */
    iso_fit_block block;            /* the same, for fit errors */
    /* Its inside bits along y and z (iso_fan_inside), transposed from the kernel's. */
    uint16_t along_y[ISO_BRICK_SAMPLES * ISO_BRICK_SAMPLES], along_z[ISO_BRICK_SAMPLES * ISO_BRICK_SAMPLES];
    int transposed;                 /* along_y and along_z are the brick's (made on first use) */
    /* Where each brick's fans begin in fans, for the bricks that made some, in the order
     * this thread covered them: PASS 3 numbers them in grid order whichever thread took
     * which brick, so the mesh does not depend on the scheduling. */
    fan_mark *marks;
    size_t mark_count, mark_capacity;
} sub_walk;

/* A piece of PASS 1 in the serial walk's order: a node the top walk fanned, or a subtree
 * it left to the threads. Its fans are [centre, centre_end) and [triangle,
 * triangle_end) of *fans once walked. */
typedef struct top_unit {
    uint32_t node;
    iso_box box;
    const iso_fan_output *fans;
    size_t centre, centre_end, triangle, triangle_end;
} top_unit;

typedef struct coarse {
    const iso_tree *tree;
    const iso_volume *vol;
    double level, fit_limit, centre_limit;
    int prune;
    uint8_t *skip;            /* per brick of the grid: inside a node fanned whole */
    iso_fan_scratch scratch;  /* the top walk's (PASS 1) */
    iso_fan_output fans;
    fan_tally tally;
    unsigned split_depth;     /* the top walk's last depth; deeper subtrees go to threads */
    top_unit *units;
    size_t unit_count, unit_capacity;
    atomic_size_t next_unit;  /* the next unit a thread may take */
    int status[ISO_PARALLEL_MAX_THREADS];
    sub_walk *threads;
    int thread_count;
} coarse;

/* Doubles a list's room (at least 64 items). */
static int grow_list(void **list, size_t *capacity, size_t item)
{
    size_t more = *capacity ? 2 * *capacity : 64;
    void *grown = realloc(*list, more * item);
    if (!grown)
        return ISO_E_NOMEM;
    *list = grown;
    *capacity = more;
    return 0;
}

/* Fans box if its fit error and face loops allow: 1 done, 0 not, <0 error. Below a brick,
 * where counting is cheap, a small node with a tangled surface can fan into more
 * triangles than its cells would give (max_triangles): it is refused then, so no
 * tolerance ever costs triangles. */
static int try_fan(const coarse *c, const iso_box *box, double fit_error, size_t max_triangles,
                   const iso_fan_inside *inside, iso_fan_scratch *scratch, iso_fan_output *fans,
                   fan_tally *tally)
{
    if (iso_box_cells(box) < MIN_FAN_CELLS || !(fit_error <= c->fit_limit))
        return 0;
    iso_fan_result result;
    /* Centres must land on the surface, not merely within the tolerance of its level: a
     * centre left in a flat background would meet that loosely and still be far off. */
    int rc = iso_fan_polygonize(c->vol, box, c->level, c->centre_limit, max_triangles, inside, scratch,
                                fans, &result);
    if (rc == 1) {
        tally->nodes_polygonized++;
        if (result.vertex_error > tally->vertex_error)
            tally->vertex_error = result.vertex_error;
        if (fit_error > tally->fit_error)
            tally->fit_error = fit_error;
    }
    return rc;
}

/* ---- PASS 1: stored nodes ---- */

/* Marks the bricks of a fanned box: those on its boundary still number their crossings
 * (the fan's loop vertices and the marched cells next to it use them), those inside it
 * are not even read. */
static void skip_bricks_of(const coarse *c, const iso_box *box)
{
    const iso_bricks *g = &c->tree->bricks;
    uint32_t lo[3], hi[3];
    for (int d = 0; d < 3; d++) {
        lo[d] = box->lo[d] / ISO_BRICK_CELLS;
        hi[d] = (box->hi[d] - 1) / ISO_BRICK_CELLS;
    }
    for (uint32_t k = lo[2]; k <= hi[2]; k++)
        for (uint32_t j = lo[1]; j <= hi[1]; j++)
            for (uint32_t i = lo[0]; i <= hi[0]; i++) {
                int inner = i > lo[0] && i < hi[0] && j > lo[1] && j < hi[1] && k > lo[2] && k < hi[2];
                c->skip[((size_t)k * g->count[1] + j) * g->count[0] + i] =
                    inner ? ISO_MARCH_SKIP_UNREAD : ISO_MARCH_SKIP_NUMBERED;
            }
}

/* The subtree of node index: its fans go to fans, its counts to tally. */
static int descend(const coarse *c, iso_fan_scratch *scratch, iso_fan_output *fans, fan_tally *tally,
                   uint32_t index, const iso_box *box)
{
    const iso_tree_node *node = &c->tree->nodes[index];
    tally->nodes_visited++;
    if (c->prune && !(node->min <= c->level && c->level < node->max))
        return 0;
    int rc = try_fan(c, box, node->err, SIZE_MAX, NULL, scratch, fans, tally);
    if (rc == 1)
        skip_bricks_of(c, box);
    if (rc || !node->first_child)
        return rc < 0 ? rc : 0; /* fanned, or a brick left to PASS 2 */
    iso_box left, right;
    iso_box_split(box, &left, &right);
    rc = descend(c, scratch, fans, tally, node->first_child, &left);
    return rc ? rc : descend(c, scratch, fans, tally, node->first_child + 1, &right);
}

static int add_unit(coarse *c, top_unit unit)
{
    top_unit *last = c->unit_count ? &c->units[c->unit_count - 1] : NULL;
    if (unit.fans && last && last->fans == unit.fans && last->centre_end == unit.centre &&
        last->triangle_end == unit.triangle) {
        last->centre_end = unit.centre_end; /* one slice for consecutive fans of the top walk */
        last->triangle_end = unit.triangle_end;
        return 0;
    }
    if (c->unit_count == c->unit_capacity && grow_list((void **)&c->units, &c->unit_capacity, sizeof unit))
        return ISO_E_NOMEM;
    c->units[c->unit_count++] = unit;
    return 0;
}

/* The top of the tree, as descend, down to split_depth: a node there is left to the
 * threads whole (its own fan attempt included), as a unit. */
static int descend_top(coarse *c, uint32_t index, const iso_box *box, unsigned depth)
{
    const iso_tree_node *node = &c->tree->nodes[index];
    if (depth == c->split_depth && node->first_child)
        return add_unit(c, (top_unit){.node = index, .box = *box});
    c->tally.nodes_visited++;
    if (c->prune && !(node->min <= c->level && c->level < node->max))
        return 0;
    size_t centre = c->fans.centre_count, triangle = c->fans.triangle_count;
    int rc = try_fan(c, box, node->err, SIZE_MAX, NULL, &c->scratch, &c->fans, &c->tally);
    if (rc == 1) {
        skip_bricks_of(c, box);
        return add_unit(c, (top_unit){index, *box, &c->fans, centre, c->fans.centre_count, triangle,
                                      c->fans.triangle_count});
    }
    if (rc || !node->first_child)
        return rc < 0 ? rc : 0;
    iso_box left, right;
    iso_box_split(box, &left, &right);
    rc = descend_top(c, node->first_child, &left, depth + 1);
    return rc ? rc : descend_top(c, node->first_child + 1, &right, depth + 1);
}

/* The units left to the threads, taken one at a time from a shared counter; a thread's
 * fans go one unit after another into its sub_walk's output (before PASS 2's). */
static void descend_share(void *context, int t, int threads)
{
    (void)threads;
    coarse *c = context;
    sub_walk *w = &c->threads[t];
    c->status[t] = 0;
    for (;;) {
        size_t i = atomic_fetch_add_explicit(&c->next_unit, 1, memory_order_relaxed);
        if (i >= c->unit_count)
            return;
        top_unit *u = &c->units[i];
        if (u->fans)
            continue; /* fanned by the top walk */
        u->fans = &w->fans;
        u->centre = w->fans.centre_count;
        u->triangle = w->fans.triangle_count;
        c->status[t] = descend(c, &w->scratch, &w->fans, &w->tally, u->node, &u->box);
        u->centre_end = w->fans.centre_count;
        u->triangle_end = w->fans.triangle_count;
        if (c->status[t])
            return;
    }
}

/* PASS 1. With one thread the top walk is the whole walk. */
static int descend_all(coarse *c)
{
    iso_box root = iso_box_root(c->vol);
    unsigned depth = 0;
    while (c->thread_count > 1 && (1u << depth) < TOP_UNITS_PER_THREAD * (unsigned)c->thread_count)
        depth++;
    c->split_depth = c->thread_count > 1 ? depth : UINT_MAX;
    int rc = descend_top(c, 0, &root, 0);
    if (rc || c->thread_count == 1)
        return rc;
    atomic_store_explicit(&c->next_unit, 0, memory_order_relaxed);
    iso_parallel_run(c->thread_count, descend_share, c);
    for (int t = 0; t < c->thread_count; t++)
        if (c->status[t])
            return c->status[t];
    return 0;
}

/* ---- PASS 2: below the bricks ---- */

/* The brick-local cell range of box, and whether any of its cells is mixed. */
static int box_cells(const sub_walk *w, const iso_box *box, uint32_t lo[3], uint32_t hi[3])
{
    for (int d = 0; d < 3; d++) {
        lo[d] = box->lo[d] - w->brick->lo[d];
        hi[d] = box->hi[d] - w->brick->lo[d];
    }
    unsigned span = ((1u << hi[0]) - 1) & ~((1u << lo[0]) - 1);
    for (uint32_t z = lo[2]; z < hi[2]; z++)
        for (uint32_t y = lo[1]; y < hi[1]; y++)
            if (w->brick->mixed[z][y] & span)
                return 1;
    return 0;
}

static void cover_cells(iso_march_brick *brick, const uint32_t lo[3], const uint32_t hi[3])
{
    unsigned span = ((1u << hi[0]) - 1) & ~((1u << lo[0]) - 1);
    for (uint32_t z = lo[2]; z < hi[2]; z++)
        for (uint32_t y = lo[1]; y < hi[1]; y++)
            brick->covered[z][y] |= (uint8_t)span;
}

/* The kernel's inside bits (rows along x at [z][y]) as rows along y at [x][z] and along
 * z at [y][x], for iso_fan_inside. */
static void transpose_inside(sub_walk *w)
{
    const iso_march_brick *b = w->brick;
    if (w->transposed)
        return;
    w->transposed = 1;
    memset(w->along_y, 0, sizeof w->along_y);
    memset(w->along_z, 0, sizeof w->along_z);
    for (unsigned z = 0; z < b->n[2]; z++)
        for (unsigned y = 0; y < b->n[1]; y++)
            for (unsigned r = b->inside[z * ISO_BRICK_SAMPLES + y]; r; r &= r - 1) {
                unsigned x = (unsigned)__builtin_ctz(r);
                w->along_y[x * ISO_BRICK_SAMPLES + z] |= (uint16_t)(1u << y);
                w->along_z[y * ISO_BRICK_SAMPLES + x] |= (uint16_t)(1u << z);
            }
}

static int visit_sub(const coarse *c, sub_walk *w, const iso_box *box)
{
    uint32_t lo[3], hi[3];
    if (iso_box_cells(box) < MIN_FAN_CELLS || !box_cells(w, box, lo, hi))
        return 0; /* marching cubes' cells, or nothing to draw */
    w->tally.nodes_visited++;
    double err = iso_fit_error_past(&w->block, box, c->fit_limit);
    if (err <= c->fit_limit) {
        size_t triangles = w->fans.triangle_count, centres = w->fans.centre_count;
        size_t most = iso_march_box_triangles(w->brick, lo, hi);
        /* The kernel classified the brick's samples: the fan's faces take its bits. */
        transpose_inside(w);
        iso_fan_inside inside = {.rows = {w->brick->inside, w->along_y, w->along_z}, .stride = ISO_BRICK_SAMPLES};
        memcpy(inside.origin, w->brick->lo, sizeof inside.origin);
        int rc = try_fan(c, box, err, most, &inside, &w->scratch, &w->fans, &w->tally);
        if (rc < 0)
            return rc;
        if (rc == 1) {
            cover_cells(w->brick, lo, hi);
            w->brick->extra_triangles += w->fans.triangle_count - triangles;
            w->brick->extra_vertices += w->fans.centre_count - centres;
            return 0;
        }
    }
    iso_box left, right;
    iso_box_split(box, &left, &right);
    int rc = visit_sub(c, w, &left);
    return rc ? rc : visit_sub(c, w, &right);
}

static size_t brick_index(const iso_bricks *g, const iso_march_brick *brick)
{
    size_t b[3];
    for (int d = 0; d < 3; d++)
        b[d] = brick->lo[d] / ISO_BRICK_CELLS;
    return (b[2] * g->count[1] + b[1]) * g->count[0] + b[0];
}

static int add_mark(sub_walk *w, fan_mark mark)
{
    if (w->mark_count == w->mark_capacity && grow_list((void **)&w->marks, &w->mark_capacity, sizeof mark))
        return ISO_E_NOMEM;
    w->marks[w->mark_count++] = mark;
    return 0;
}

static int cover(void *context, int thread, iso_march_brick *brick)
{
    const coarse *c = context;
    sub_walk *w = &c->threads[thread];
    iso_box box, left, right;
    size_t lo[3], hi[3];
    for (int d = 0; d < 3; d++) {
        box.lo[d] = brick->lo[d];
        box.hi[d] = brick->lo[d] + brick->n[d] - 1u;
        lo[d] = box.lo[d];
        hi[d] = box.hi[d];
    }
    /* The brick itself was tried whole in PASS 1; a brick of one cell has no sub-box, and
     * one whose floor (fan_floor.h) is past the fit limit has none that could fan. */
    size_t index = brick_index(&c->tree->bricks, brick);
    if (iso_box_split(&box, &left, &right) < 0 || !(c->tree->fan_floor[index] <= c->fit_limit))
        return 0;
    w->brick = brick;
    w->block = (iso_fit_block){.samples = w->samples, .integer_samples = !iso_vol_type_is_float(c->vol->type)};
    for (int d = 0; d < 3; d++) {
        w->block.lo[d] = brick->lo[d];
        w->block.n[d] = brick->n[d];
    }
    iso_vol_read_box(c->vol, lo, hi, w->samples);
    w->transposed = 0;
    fan_mark mark = {index, w->fans.centre_count, w->fans.triangle_count};
    int rc = visit_sub(c, w, &left);
    if (!rc)
        rc = visit_sub(c, w, &right);
    if (rc || w->fans.triangle_count == mark.triangle)
        return rc;
    return add_mark(w, mark);
}

/* ---- PASS 3: the fans' vertices ---- */

static void place_centre(const iso_volume *vol, const float *index, int world, float *out)
{
    double p[3] = {index[0], index[1], index[2]}, q[3];
    if (world)
        iso_vol_index_to_world(vol, p, q);
    for (int d = 0; d < 3; d++)
        out[d] = (float)(world ? q[d] : p[d]);
}

/* Centres [centre, centre_end) and triangles [triangle, triangle_end) of fans, to be
 * written from vertex first_vertex and triangle first_triangle of the mesh. A slice's
 * triangles name only its own centres (a fan's centre is made with it). */
typedef struct fan_slice {
    const iso_fan_output *fans;
    size_t centre, centre_end, triangle, triangle_end;
    size_t first_vertex, first_triangle;
} fan_slice;

/* Centres become new vertices, loop vertices the kernel's ids. */
static int number_slice(const iso_volume *vol, const fan_slice *s, const iso_march *march, int world,
                        iso_mesh *mesh)
{
    const iso_fan_output *fans = s->fans;
    float *position = mesh->positions + 3 * s->first_vertex;
    for (size_t i = s->centre; i < s->centre_end; i++, position += 3)
        place_centre(vol, fans->centres + 3 * i, world, position);
    uint32_t *out = mesh->indices + 3 * s->first_triangle;
    for (size_t i = 0; i < 3 * (s->triangle_end - s->triangle); i++) {
        uint64_t ref = fans->corners[3 * s->triangle + i];
        if (ref & ISO_FAN_CENTRE) {
            size_t index = (size_t)(ref & ~ISO_FAN_CENTRE);
            assert(index >= s->centre && index < s->centre_end);
            out[i] = (uint32_t)(s->first_vertex + index - s->centre);
            continue;
        }
        uint32_t corner[3];
        int axis;
        iso_fan_edge_of_key(vol, ref, corner, &axis);
        out[i] = iso_march_vertex(march, corner, axis);
        if (out[i] == UINT32_MAX)
            return ISO_E_INTERNAL; /* a loop vertex the kernel did not number: a bug */
    }
    return 0;
}

/* PASS 1's fans in its units' order, then the bricks' in grid order, merged from the
 * threads' marks (each thread's are in grid order already), placed one after another
 * from the mesh's end. Returns how many, or 0 if the array cannot be had (*slices NULL). */
static size_t order_slices(const coarse *c, const iso_mesh *mesh, fan_slice **slices)
{
    size_t count = c->unit_count, next[ISO_PARALLEL_MAX_THREADS] = {0};
    assert(c->thread_count <= ISO_PARALLEL_MAX_THREADS);
    for (int t = 0; t < c->thread_count; t++)
        count += c->threads[t].mark_count;
    fan_slice *s = *slices = malloc((count ? count : 1) * sizeof *s);
    if (!s)
        return 0;
    for (size_t i = 0; i < c->unit_count; i++) {
        const top_unit *u = &c->units[i];
        s[i] = (fan_slice){u->fans, u->centre, u->centre_end, u->triangle, u->triangle_end, 0, 0};
    }
    for (size_t i = c->unit_count; i < count; i++) {
        int t = -1;
        for (int u = 0; u < c->thread_count; u++)
            if (next[u] < c->threads[u].mark_count &&
                (t < 0 || c->threads[u].marks[next[u]].brick < c->threads[t].marks[next[t]].brick))
                t = u;
        const sub_walk *w = &c->threads[t];
        const fan_mark *m = &w->marks[next[t]++];
        int last = next[t] == w->mark_count;
        s[i] = (fan_slice){&w->fans, m->centre, last ? w->fans.centre_count : m[1].centre, m->triangle,
                           last ? w->fans.triangle_count : m[1].triangle, 0, 0};
    }
    size_t vertex = mesh->vertex_count, triangle = mesh->triangle_count;
    for (size_t i = 0; i < count; i++) {
        s[i].first_vertex = vertex;
        s[i].first_triangle = triangle;
        vertex += s[i].centre_end - s[i].centre;
        triangle += s[i].triangle_end - s[i].triangle;
    }
    return count;
}

typedef struct numbering {
    const iso_volume *vol;
    const iso_march *march;
    int world;
    iso_mesh *mesh;
    const fan_slice *slices;
    size_t count;
    int status[ISO_PARALLEL_MAX_THREADS];
} numbering;

/* Every slice writes its own, already placed range: any split gives the same mesh. */
static void number_share(void *context, int t, int threads)
{
    numbering *n = context;
    size_t begin = n->count * (size_t)t / (size_t)threads, end = n->count * (size_t)(t + 1) / (size_t)threads;
    n->status[t] = 0;
    for (size_t i = begin; i < end && !n->status[t]; i++)
        n->status[t] = number_slice(n->vol, &n->slices[i], n->march, n->world, n->mesh);
}

/* PASS 3, on the extraction's threads. */
static int number_fans(const coarse *c, const iso_march *march, int world, iso_mesh *mesh)
{
    fan_slice *slices;
    size_t count = order_slices(c, mesh, &slices);
    if (!slices)
        return ISO_E_NOMEM;
    if (!count) {
        free(slices);
        return 0;
    }
    const fan_slice *last = &slices[count - 1];
    size_t vertices = last->first_vertex + last->centre_end - last->centre;
    size_t triangles = last->first_triangle + last->triangle_end - last->triangle;
    assert(vertices <= mesh->vertex_capacity && triangles <= mesh->triangle_capacity);
    numbering n = {.vol = c->vol, .march = march, .world = world, .mesh = mesh,
                   .slices = slices, .count = count};
    int threads = count < (size_t)c->thread_count ? (int)count : c->thread_count;
    iso_parallel_run(threads, number_share, &n);
    free(slices);
    for (int t = 0; t < threads; t++)
        if (n.status[t])
            return n.status[t];
    mesh->vertex_count = vertices;
    mesh->triangle_count = triangles;
    return 0;
}

static void sum_tally(fan_tally *into, const fan_tally *from)
{
    into->nodes_visited += from->nodes_visited;
    into->nodes_polygonized += from->nodes_polygonized;
    if (from->vertex_error > into->vertex_error)
        into->vertex_error = from->vertex_error;
    if (from->fit_error > into->fit_error)
        into->fit_error = from->fit_error;
}

/* ---- the passes after descent ---- */

/* The value of padded sample (i, j, k): the volume's inside it, below every level on the
 * virtual layer one sample outside it. */
static double padded_value(const iso_volume *vol, long i, long j, long k)
{
    long p[3] = {i, j, k};
    for (int d = 0; d < 3; d++)
        if (p[d] < 0 || p[d] >= (long)vol->dims[d])
            return -INFINITY;
    return iso_vol_get(vol, (size_t)i, (size_t)j, (size_t)k);
}

/* PASS 2: marching cubes on the padded grid's cells that touch the virtual layer, i.e.
 * lower corners in -1..n-1 with some coordinate -1 or n-1: about two cells per border
 * sample. Their faces on the border carry the same crossings as the cells and fans
 * inside, their crossings toward the virtual layer sit 1/1024 voxel outside the border
 * (iso_mc_edge_t), so the cap is flat against the border and seals the surface. The cap's
 * own vertices are on the border, not on the level: they do not enter the error bound. */
static int emit_caps(const iso_volume *vol, double level, iso_mesh *soup)
{
    static const double unit[3] = {1, 1, 1};
    long n[3] = {(long)vol->dims[0], (long)vol->dims[1], (long)vol->dims[2]};
    for (long k = -1; k < n[2]; k++)
        for (long j = -1; j < n[1]; j++) {
            int inner = k >= 0 && k < n[2] - 1 && j >= 0 && j < n[1] - 1;
            for (long i = -1; i < n[0]; i += inner && i == -1 ? n[0] : 1) {
                double v[8], origin[3] = {(double)i, (double)j, (double)k};
                for (int c = 0; c < 8; c++)
                    v[c] = padded_value(vol, i + (c & 1), j + ((c >> 1) & 1), k + ((c >> 2) & 1));
                if (iso_mc_cell(v, level, origin, unit, soup, NULL) < 0)
                    return ISO_E_NOMEM;
            }
        }
    return 0;
}

static void to_world(const iso_volume *vol, iso_mesh *mesh)
{
    for (size_t v = 0; v < mesh->vertex_count; v++) {
        float *p = mesh->positions + 3 * v;
        double index[3] = {p[0], p[1], p[2]}, world[3];
        iso_vol_index_to_world(vol, index, world);
        for (int d = 0; d < 3; d++)
            p[d] = (float)world[d];
    }
}

static int finish(const iso_volume *vol, iso_space space, int weld, iso_mesh *mesh,
                  iso_extract_stats *stats, double start, iso_error *err)
{
    if (weld && iso_mesh_weld(mesh))
        return iso_error_set(err, ISO_E_NOMEM, "out of memory welding the mesh");
    if (space == ISO_SPACE_WORLD)
        to_world(vol, mesh);
    stats->triangles = mesh->triangle_count;
    stats->vertices = mesh->vertex_count;
    stats->extract_ms = iso_clock_ms() - start;
    return 0;
}

/* PASS 2 to 5, after PASS 1 when c is not NULL: the kernel, the fans, the cap. */
static int march_and_finish(const iso_tree *tree, const iso_extract_params *params, coarse *c,
                            iso_mesh *mesh, iso_extract_stats *stats, double start, iso_error *err)
{
    /* With a cap the march stays in index space, so that the cap's vertices weld to it. */
    int world = params->space == ISO_SPACE_WORLD && !params->cap;
    iso_march_options options = {.prune = !params->no_minmax, .world = world, .threads = params->threads};
    if (c) {
        options.skip = c->skip;
        options.cover = cover;
        options.cover_context = c;
        for (size_t i = 0; i < c->unit_count; i++) {
            options.extra_vertices += c->units[i].centre_end - c->units[i].centre;
            options.extra_triangles += c->units[i].triangle_end - c->units[i].triangle;
        }
    }
    iso_march *march;
    iso_march_stats ms;
    int rc = iso_march_begin(tree->vol, &tree->bricks, params->level, &options, mesh, &march, &ms, err);
    if (rc)
        return rc;
    fan_tally tally = {0};
    if (c) {
        sum_tally(&tally, &c->tally);
        for (int t = 0; t < c->thread_count; t++)
            sum_tally(&tally, &c->threads[t].tally);
        rc = number_fans(c, march, world, mesh);
        if (!rc && tally.nodes_polygonized && iso_mesh_drop_unused(mesh))
            rc = ISO_E_NOMEM;
    }
    iso_march_end(march);
    if (rc) {
        iso_mesh_free(mesh);
        return rc == ISO_E_NOMEM ? iso_error_set(err, rc, "out of memory extracting the surface")
                                 : iso_error_set(err, rc, "a fan vertex has no crossing in the brick kernel");
    }
    stats->nodes_visited += tally.nodes_visited + ms.bricks_active;
    stats->nodes_polygonized = tally.nodes_polygonized;
    stats->cells_visited = ms.cells_visited + tally.nodes_polygonized;
    stats->error_bound = ms.error_bound > tally.vertex_error ? ms.error_bound : tally.vertex_error;
    stats->fit_error = tally.fit_error;
    if (params->cap && emit_caps(tree->vol, params->level, mesh)) {
        iso_mesh_free(mesh);
        return iso_error_set(err, ISO_E_NOMEM, "out of memory capping the surface");
    }
    /* Positions the march placed in world mm already are left as they are. */
    return finish(tree->vol, world ? ISO_SPACE_INDEX : params->space, params->cap, mesh, stats, start, err);
}

static void coarse_free(coarse *c)
{
    iso_fan_scratch_free(&c->scratch);
    iso_fan_output_free(&c->fans);
    for (int t = 0; c->threads && t < c->thread_count; t++) {
        iso_fan_scratch_free(&c->threads[t].scratch);
        iso_fan_output_free(&c->threads[t].fans);
        free(c->threads[t].marks);
    }
    free(c->threads);
    free(c->skip);
    free(c->units);
}

/* Tolerance > 0: PASS 1, then the rest. */
static int extract_coarse(const iso_tree *tree, const iso_extract_params *params,
                          iso_mesh *mesh, iso_extract_stats *stats, double start, iso_error *err)
{
    coarse c = {.tree = tree, .vol = tree->vol, .level = params->level, .prune = !params->no_minmax};
    c.fit_limit = params->tolerance;
    c.centre_limit = params->tolerance * CENTRE_SHARE;
    c.thread_count = iso_parallel_threads(params->threads);
    c.threads = calloc((size_t)c.thread_count, sizeof *c.threads);
    c.skip = calloc(iso_bricks_total(&tree->bricks), 1);
    int rc = c.threads && c.skip ? descend_all(&c) : ISO_E_NOMEM;
    if (rc) {
        coarse_free(&c);
        iso_mesh_free(mesh);
        return iso_error_set(err, ISO_E_NOMEM, "out of memory extracting the surface");
    }
    rc = march_and_finish(tree, params, &c, mesh, stats, start, err);
    coarse_free(&c);
    return rc;
}

int iso_extract(const iso_tree *tree, const iso_extract_params *params, iso_mesh *mesh,
                iso_extract_stats *stats, iso_error *err)
{
    iso_extract_stats local;
    double start = iso_clock_ms();
    if (!stats)
        stats = &local;
    memset(stats, 0, sizeof *stats);
    if (!isfinite(params->level))
        return iso_error_set(err, ISO_E_ARGUMENT, "level must be a finite number");
    if (!(params->tolerance >= 0) || !isfinite(params->tolerance))
        return iso_error_set(err, ISO_E_ARGUMENT, "tolerance must be a finite number >= 0");
    /* The root's bounds answer a level outside the data with one node. */
    const iso_tree_node *root = &tree->nodes[0];
    if (!params->no_minmax && !params->cap && !(root->min <= params->level && params->level < root->max)) {
        stats->nodes_visited = 1;
        iso_mesh_clear(mesh);
        return finish(tree->vol, params->space, 0, mesh, stats, start, err);
    }
    if (params->tolerance > 0)
        return extract_coarse(tree, params, mesh, stats, start, err);
    stats->nodes_visited = 1;
    return march_and_finish(tree, params, NULL, mesh, stats, start, err);
}

int iso_extract_full_scan(const iso_volume *vol, double level, iso_space space,
                          iso_mesh *mesh, iso_extract_stats *stats, iso_error *err)
{
    iso_extract_stats local;
    double start = iso_clock_ms();
    if (!stats)
        stats = &local;
    memset(stats, 0, sizeof *stats);
    if (!isfinite(level))
        return iso_error_set(err, ISO_E_ARGUMENT, "level must be a finite number");
    size_t nx = vol->dims[0], ny = vol->dims[1], nz = vol->dims[2];
    double *slab = malloc(2 * nx * ny * sizeof *slab);
    if (!slab)
        return iso_error_set(err, ISO_E_NOMEM, "out of memory");
    iso_mesh_free(mesh);
    static const double unit[3] = {1, 1, 1};
    int rc = 0;
    /* Two slices at a time, converted once; each cell reads its 8 corners from them. */
    for (size_t z = 0; z + 1 < nz && rc >= 0; z++) {
        size_t lo[3] = {0, 0, z}, hi[3] = {nx - 1, ny - 1, z + 1};
        iso_vol_read_box(vol, lo, hi, slab);
        for (size_t y = 0; y + 1 < ny && rc >= 0; y++)
            for (size_t x = 0; x + 1 < nx && rc >= 0; x++) {
                double v[8], origin[3] = {(double)x, (double)y, (double)z};
                for (int k = 0; k < 8; k++)
                    v[k] = slab[((size_t)((k >> 2) & 1) * ny + y + ((k >> 1) & 1)) * nx + x + (k & 1)];
                rc = iso_mc_cell(v, level, origin, unit, mesh, &stats->error_bound);
            }
    }
    free(slab);
    stats->cells_visited = (nx - 1) * (ny - 1) * (nz - 1);
    if (rc < 0) {
        iso_mesh_free(mesh);
        return iso_error_set(err, ISO_E_NOMEM, "out of memory extracting the surface");
    }
    return finish(vol, space, 1, mesh, stats, start, err);
}
