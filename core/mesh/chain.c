/* chain.c: a surface's simplification chain, and the meshes it answers (see mesh.h).
 *
 * Passes of iso_mesh_chain_build:
 *   1. keep: the exact surface's positions and triangles become level 0;
 *   2. simplify: level k (k = 1..ISO_CHAIN_LEVELS) is level k - 1 simplified to half its
 *      triangles (iso_simplify_manifold, borders locked), in parts, each gathered over
 *      compact vertices and mapped back to the chain's (so that every level indexes the
 *      one position array): on a large level and several threads, first (2a) slabs across
 *      one axis, one per thread, each with its cut locked (the cut's edges are open in the
 *      slab), making half of the level's collapses, then (2b) the joined level with the
 *      cuts free makes the rest, by error over the whole surface; a small level, or one
 *      thread, is one part;
 *   3. measure: each level's distance from level 0 (iso_mesh_distance_between, samples three
 *      voxels apart, against level 0's grid built once for all levels), so the answers
 *      below rest on measurements, not on estimates. */
#include "distance.h"

#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "base/base.h"

void iso_mesh_chain_destroy(iso_mesh_chain *chain)
{
    if (!chain)
        return;
    for (int k = 0; k < chain->levels; k++)
        free(chain->level[k].indices);
    free(chain->positions);
    free(chain);
}

/* A mesh over the chain's positions with level k's triangles (nothing owned). */
static iso_mesh view_of(const iso_mesh_chain *chain, int k)
{
    iso_mesh m;
    iso_mesh_init(&m);
    m.positions = chain->positions;
    m.vertex_count = m.vertex_capacity = chain->vertex_count;
    m.indices = chain->level[k].indices;
    m.triangle_count = m.triangle_capacity = chain->level[k].triangle_count;
    return m;
}

static size_t used_vertices(const iso_mesh *m, unsigned char *seen)
{
    memset(seen, 0, m->vertex_count);
    size_t n = 0;
    for (size_t i = 0; i < 3 * m->triangle_count; i++)
        if (!seen[m->indices[i]])
            seen[m->indices[i]] = 1, n++;
    return n;
}

/* One part of a level, simplified on its own thread (PASS 2a, 2b). */
typedef struct part {
    iso_mesh mesh;          /* its triangles over its own vertices */
    uint32_t *global;       /* its vertex i is the chain's vertex global[i] */
    size_t triangles;       /* the source's triangles in it */
    size_t target;
    iso_simplify_result result;
    int rc;
    iso_error err;
} part;

typedef struct part_job {
    const iso_mesh_chain *chain;
    const iso_mesh *source;
    const int *part_of;     /* per source triangle: its part, or -1 (kept as it is) */
    part *parts;
    int count;
} part_job;

/* One part on one thread: its triangles gathered over compact vertices (so that its cost
 * follows its own size, not the chain's vertex count), then simplified with every vertex
 * on an open edge, which is where the part was cut out, locked. */
static void simplify_part(void *context, int thread, int threads)
{
    part_job *job = context;
    const iso_mesh *m = job->source;
    for (int s = thread; s < job->count; s += threads) {
        part *pt = &job->parts[s];
        size_t n = pt->triangles;
        uint32_t *local = malloc((m->vertex_count ? m->vertex_count : 1) * sizeof *local);
        iso_mesh_init(&pt->mesh);
        if (!local || iso_mesh_reserve(&pt->mesh, 3 * n, n) ||
            !(pt->global = malloc((3 * n + 1) * sizeof *pt->global))) {
            free(local);
            pt->rc = iso_error_set(&pt->err, ISO_E_NOMEM, "chain: no memory for a part of %zu triangles", n);
            continue;
        }
        memset(local, 0xff, m->vertex_count * sizeof *local);
        size_t v = 0, i = 0;
        for (size_t t = 0; t < m->triangle_count; t++) {
            if (job->part_of[t] != s)
                continue;
            for (int k = 0; k < 3; k++) {
                uint32_t g = m->indices[3 * t + k];
                if (local[g] == UINT32_MAX) {
                    local[g] = (uint32_t)v;
                    pt->global[v] = g;
                    memcpy(pt->mesh.positions + 3 * v++, m->positions + 3 * (size_t)g, 3 * sizeof(float));
                }
                pt->mesh.indices[i++] = local[g];
            }
        }
        free(local);
        pt->mesh.vertex_count = v;
        pt->mesh.triangle_count = n;
        iso_simplify_params sp = {.target_triangles = pt->target ? pt->target : 1,
                                  .target_error = INFINITY, .voxel_size = job->chain->voxel_size,
                                  .lock_border = 1, .keep_vertices = 1};
        pt->rc = iso_simplify_manifold(&pt->mesh, &sp, &pt->result, &pt->err);
    }
}

/* Simplifies the parts of m (part_of, parts[s].target set) on `threads` and joins them
 * into m: first the triangles of no part, as they were, then each part's. */
static int run_parts(part_job *job, iso_mesh *m, int threads, iso_simplify_result *r, iso_error *err)
{
    iso_parallel_run(threads < job->count ? threads : job->count, simplify_part, job);
    int rc = 0;
    size_t joined = 0;
    for (int s = 0; s < job->count; s++)
        if (job->parts[s].rc && !rc) {
            rc = job->parts[s].rc;
            if (err)
                *err = job->parts[s].err;
        }
    for (size_t t = 0; !rc && t < m->triangle_count; t++)
        if (job->part_of[t] < 0)
            memmove(m->indices + 3 * joined, m->indices + 3 * t, 3 * sizeof *m->indices), joined++;
    for (int s = 0; s < job->count; s++) {
        part *pt = &job->parts[s];
        for (size_t i = 0; !rc && i < 3 * pt->mesh.triangle_count; i++)
            m->indices[3 * joined + i] = pt->global[pt->mesh.indices[i]];
        joined += rc ? 0 : pt->mesh.triangle_count;
        r->error = fmax(r->error, pt->result.error);
        r->folds_dropped += pt->result.folds_dropped;
        iso_mesh_free(&pt->mesh);
        free(pt->global);
        pt->global = NULL;
    }
    if (!rc)
        m->triangle_count = joined;
    return rc;
}

/* A triangle's centroid along an axis. */
static float centre_of(const iso_mesh *m, size_t t, int axis)
{
    float c = 0;
    for (int k = 0; k < 3; k++)
        c += m->positions[3 * (size_t)m->indices[3 * t + k] + (size_t)axis];
    return c / 3;
}

/* PASS 2 for level k: m (level k - 1's triangles) simplified to `target`. On several
 * threads, in slabs (2a) across an axis (the longest side on even levels, the next on odd
 * ones), one per thread, each with its cut locked, making half of the level's collapses
 * (each slab its share); then (2b) the joined level with the cuts free makes the other half,
 * chosen by error over the whole surface: slabs sent all the way to their shares of the
 * target spend collapses where a slab's own share forces them, not where they cost least
 * (docs/performance.md). A small level, or one thread, is one part. */
static int simplify_level(const iso_mesh_chain *chain, iso_mesh *m, int k, size_t target,
                          int threads, iso_simplify_result *r, iso_error *err)
{
    size_t T = m->triangle_count;
    int slabs = threads > 1 && T >= (size_t)threads * ISO_CHAIN_SLAB_MIN ? threads : 1;
    slabs = slabs < ISO_CHAIN_SLABS_MAX ? slabs : ISO_CHAIN_SLABS_MAX;
    *r = (iso_simplify_result){.triangles_in = T, .vertices_in = m->vertex_count};
    int *part_of = malloc((T ? T : 1) * sizeof *part_of);
    part *parts = calloc((size_t)slabs, sizeof *parts);
    if (!part_of || !parts) {
        free(part_of);
        free(parts);
        return iso_error_set(err, ISO_E_NOMEM, "chain: no memory for the parts of level %d", k);
    }
    float lo[3], hi[3];
    iso_mesh_bounds(m, lo, hi);
    int order[3] = {0, 1, 2};
    for (int a = 0; a < 3; a++)
        for (int b = a + 1; b < 3; b++)
            if (hi[order[b]] - lo[order[b]] > hi[order[a]] - lo[order[a]]) {
                int swap = order[a];
                order[a] = order[b], order[b] = swap;
            }
    int axis = order[k % 2];
    double side = (double)hi[axis] - lo[axis];
    for (size_t t = 0; t < T; t++) {
        int s = (int)(((double)centre_of(m, t, axis) - lo[axis]) / side * slabs);
        part_of[t] = s < 0 ? 0 : s >= slabs ? slabs - 1 : s;
        parts[part_of[t]].triangles++;
    }
    size_t goal = slabs > 1 && T > target ? target + (T - target) / 2 : target;
    for (int s = 0; s < slabs; s++)
        parts[s].target = (size_t)((double)goal * (double)parts[s].triangles / (double)(T ? T : 1));
    part_job job = {.chain = chain, .source = m, .part_of = part_of, .parts = parts, .count = slabs};
    int rc = run_parts(&job, m, threads, r, err); /* PASS 2a */
    if (!rc && slabs > 1 && m->triangle_count > target) {
        /* PASS 2b: the joined level as one part, the cuts free. */
        memset(parts, 0, sizeof *parts);
        memset(part_of, 0, m->triangle_count * sizeof *part_of);
        parts[0].triangles = m->triangle_count, parts[0].target = target;
        job.count = 1;
        rc = run_parts(&job, m, threads, r, err);
    }
    r->triangles = m->triangle_count;
    free(part_of);
    free(parts);
    return rc;
}

/* PASS 2c: a closed surface's level whose enclosed volume strays more than
 * ISO_CHAIN_VOLUME_SLACK from level 0's gets the offset along its normals that restores
 * it; *level then becomes that moved level (owned, for the measure), else stays the view. */
static int keep_volume(iso_mesh_chain *chain, int k, iso_mesh *level, iso_error *err)
{
    iso_mesh_chain_level *lv = &chain->level[k];
    if (!chain->closed || chain->volume == 0)
        return 0;
    double v = iso_mesh_enclosed_volume(level);
    lv->volume_change = (v - chain->volume) / chain->volume;
    if (!(fabs(lv->volume_change) > ISO_CHAIN_VOLUME_SLACK))
        return 0;
    if (iso_mesh_volume_offset(level, chain->volume, &lv->offset))
        return iso_error_set(err, ISO_E_NOMEM, "chain: no memory to keep level %d's volume", k);
    iso_mesh moved;
    iso_mesh_init(&moved);
    int rc = iso_mesh_chain_mesh(chain, k, &moved, err);
    if (rc) {
        iso_mesh_free(&moved);
        lv->offset = 0;
        return rc;
    }
    lv->volume_change = (iso_mesh_enclosed_volume(&moved) - chain->volume) / chain->volume;
    *level = moved;
    return 0;
}

/* PASS 2 and 3 for level k. */
static int add_level(iso_mesh_chain *chain, const iso_mesh_grid *exact_grid, int k, int threads,
                     unsigned char *seen, iso_error *err)
{
    const iso_mesh_chain_level *prev = &chain->level[k - 1];
    iso_mesh_chain_level *lv = &chain->level[k];
    iso_mesh m = view_of(chain, k - 1);
    if (!(m.indices = malloc(3 * prev->triangle_count * sizeof *m.indices)))
        return iso_error_set(err, ISO_E_NOMEM, "chain: no memory for level %d", k);
    memcpy(m.indices, prev->indices, 3 * prev->triangle_count * sizeof *m.indices);
    size_t target = chain->level[0].triangle_count >> k;
    target = target ? target : 1;
    iso_simplify_result r;
    double start = iso_clock_ms();
    int rc = simplify_level(chain, &m, k, target, iso_parallel_threads(threads), &r, err);
    if (rc) {
        free(m.indices);
        return rc;
    }
    r.ms = iso_clock_ms() - start;
    uint32_t *shrunk = realloc(m.indices, (3 * m.triangle_count + 1) * sizeof *m.indices);
    lv->indices = m.indices = shrunk ? shrunk : m.indices;
    lv->triangle_count = m.triangle_count;
    lv->vertex_count = used_vertices(&m, seen);
    chain->levels = k + 1; /* the level is the chain's from here: destroy frees it */
    lv->estimate = r.error;
    lv->folds_dropped = r.folds_dropped;
    iso_mesh_pinches pinches;
    if ((rc = iso_mesh_find_pinches(&m, NULL, &pinches)))
        return iso_error_set(err, rc, "chain: no memory to count level %d's pinches", k);
    lv->nonmanifold_edges = pinches.pinch_edges;
    lv->pinch_vertices = pinches.pinch_vertices;
    lv->edges = pinches.edges;
    iso_mesh exact = view_of(chain, 0), level = view_of(chain, k);
    double measure_start = iso_clock_ms();
    if ((rc = keep_volume(chain, k, &level, err)))
        return rc;
    rc = iso_mesh_distance_between(&exact, exact_grid, &level, NULL,
                                   ISO_CHAIN_SPACING_VOXELS * chain->voxel_size,
                                   ISO_DISTANCE_SAMPLES, threads, &lv->distance, err);
    if (lv->offset != 0)
        iso_mesh_free(&level);
    lv->simplify_ms = r.ms;
    lv->measure_ms = iso_clock_ms() - measure_start;
    chain->bytes += 3 * lv->triangle_count * sizeof *lv->indices;
    return rc;
}

int iso_mesh_chain_build(const iso_mesh *exact, double voxel_size, int threads,
                         iso_mesh_chain **out, iso_error *err)
{
    *out = NULL;
    if (!(voxel_size > 0) || !isfinite(voxel_size))
        return iso_error_set(err, ISO_E_ARGUMENT, "chain: voxel size %g must be > 0", voxel_size);
    double start = iso_clock_ms();
    iso_mesh_chain *c = calloc(1, sizeof *c);
    unsigned char *seen = malloc(exact->vertex_count ? exact->vertex_count : 1);
    if (!c || !seen) {
        free(c);
        free(seen);
        return iso_error_set(err, ISO_E_NOMEM, "chain: no memory");
    }
    c->voxel_size = voxel_size;
    c->vertex_count = exact->vertex_count;
    c->positions = malloc((3 * exact->vertex_count + 1) * sizeof *c->positions);
    c->level[0].indices = malloc((3 * exact->triangle_count + 1) * sizeof *c->level[0].indices);
    if (!c->positions || !c->level[0].indices) {
        free(c->level[0].indices);
        c->levels = 0;
        iso_mesh_chain_destroy(c);
        free(seen);
        return iso_error_set(err, ISO_E_NOMEM, "chain: no memory for %zu triangles", exact->triangle_count);
    }
    /* PASS 1 */
    if (exact->vertex_count) /* an empty mesh may have no arrays at all */
        memcpy(c->positions, exact->positions, 3 * exact->vertex_count * sizeof *c->positions);
    if (exact->triangle_count)
        memcpy(c->level[0].indices, exact->indices, 3 * exact->triangle_count * sizeof *exact->indices);
    c->level[0].triangle_count = exact->triangle_count;
    c->levels = 1;
    iso_mesh level0 = view_of(c, 0);
    c->level[0].vertex_count = used_vertices(&level0, seen);
    iso_mesh_pinches pinches;
    if (iso_mesh_find_pinches(&level0, NULL, &pinches)) {
        iso_mesh_chain_destroy(c);
        free(seen);
        return iso_error_set(err, ISO_E_NOMEM, "chain: no memory to count pinches");
    }
    c->level[0].edges = pinches.edges;
    c->level[0].nonmanifold_edges = pinches.pinch_edges;
    c->level[0].pinch_vertices = pinches.pinch_vertices;
    c->closed = exact->triangle_count > 0 && pinches.open_edges == 0;
    c->volume = c->closed ? iso_mesh_enclosed_volume(&level0) : 0;
    c->bytes = sizeof *c + 3 * exact->vertex_count * sizeof *c->positions +
               3 * exact->triangle_count * sizeof *exact->indices;
    /* PASS 3's grid of level 0, once for all levels: every level lies within its bounds. */
    float lo[3], hi[3];
    iso_mesh_bounds(&level0, lo, hi);
    iso_mesh_grid *grid = NULL;
    int rc = exact->triangle_count > 1 && iso_mesh_grid_build(&level0, lo, hi, &grid)
                 ? iso_error_set(err, ISO_E_NOMEM, "chain: no memory for the grid of %zu triangles",
                                 exact->triangle_count)
                 : 0;
    for (int k = 1; k <= ISO_CHAIN_LEVELS && !rc; k++) {
        if ((exact->triangle_count >> k) < 1)
            break;
        rc = add_level(c, grid, k, threads, seen, err);
    }
    iso_mesh_grid_destroy(grid);
    free(seen);
    if (rc) {
        iso_mesh_chain_destroy(c);
        return rc;
    }
    c->build_ms = iso_clock_ms() - start;
    *out = c;
    return 0;
}

int iso_mesh_chain_pick_distance(const iso_mesh_chain *chain, double distance)
{
    int best = 0;
    for (int k = 1; k < chain->levels; k++)
        if (chain->level[k].distance.p99 <= distance &&
            chain->level[k].triangle_count < chain->level[best].triangle_count)
            best = k;
    return best;
}

int iso_mesh_chain_pick_budget(const iso_mesh_chain *chain, size_t triangles)
{
    int k = 0;
    while (k + 1 < chain->levels && chain->level[k].triangle_count > triangles)
        k++;
    return k;
}

int iso_mesh_chain_mesh(const iso_mesh_chain *chain, int k, iso_mesh *mesh, iso_error *err)
{
    if (k < 0 || k >= chain->levels)
        return iso_error_set(err, ISO_E_ARGUMENT, "chain: no level %d (it has %d)", k, chain->levels);
    const iso_mesh_chain_level *lv = &chain->level[k];
    iso_mesh_clear(mesh);
    uint32_t *remap = malloc((chain->vertex_count ? chain->vertex_count : 1) * sizeof *remap);
    if (!remap || iso_mesh_reserve(mesh, lv->vertex_count, lv->triangle_count)) {
        free(remap);
        return iso_error_set(err, ISO_E_NOMEM, "chain: no memory for %zu triangles", lv->triangle_count);
    }
    memset(remap, 0xff, chain->vertex_count * sizeof *remap);
    /* Vertices keep the exact surface's order: level 0 comes out as it went in. */
    for (size_t i = 0; i < 3 * lv->triangle_count; i++)
        remap[lv->indices[i]] = 0;
    size_t n = 0;
    for (size_t v = 0; v < chain->vertex_count; v++)
        if (remap[v] == 0) {
            remap[v] = (uint32_t)n;
            memcpy(mesh->positions + 3 * n++, chain->positions + 3 * v, 3 * sizeof(float));
        }
    for (size_t i = 0; i < 3 * lv->triangle_count; i++)
        mesh->indices[i] = remap[lv->indices[i]];
    mesh->vertex_count = n;
    mesh->triangle_count = lv->triangle_count;
    free(remap);
    if (iso_mesh_offset_along_normals(mesh, lv->offset)) {
        iso_mesh_clear(mesh);
        return iso_error_set(err, ISO_E_NOMEM, "chain: no memory to move level %d's vertices", k);
    }
    return 0;
}
