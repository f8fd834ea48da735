/* chain.c: a surface's simplification chain, and the meshes it answers (see mesh.h).
 *
 * Passes of iso_mesh_chain_build:
 *   1. keep: the exact surface's positions and triangles become level 0;
 *   2. simplify: level k (k = 1..ISO_CHAIN_LEVELS) is level k - 1 simplified to half its
 *      triangles (iso_simplify, borders locked, unused vertices kept so that every level
 *      indexes the one position array): on a large level, first (2a) in slabs across one
 *      axis, one per thread, each with its cut locked (the cut's edges are open in the
 *      slab), then (2b) the joined mesh with the cuts free, which has little left to do;
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

/* One slab of a level being simplified on several threads (PASS 2a). */
typedef struct slab {
    iso_mesh mesh;          /* its triangles over its own vertices */
    uint32_t *global;       /* its vertex i is the chain's vertex global[i] */
    size_t target;
    iso_simplify_result result;
    int rc;
    iso_error err;
} slab;

typedef struct slab_job {
    const iso_mesh_chain *chain;
    const iso_mesh *source;
    int axis;
    float cut[ISO_CHAIN_SLABS_MAX + 1]; /* slab s: cut[s] <= centre < cut[s + 1] */
    slab *slabs;
    int count;
    size_t target;
} slab_job;

static int slab_of(const slab_job *job, const iso_mesh *m, size_t t)
{
    float c = 0;
    for (int k = 0; k < 3; k++)
        c += m->positions[3 * (size_t)m->indices[3 * t + k] + (size_t)job->axis];
    c /= 3;
    int s = 0;
    while (s + 1 < job->count && c >= job->cut[s + 1])
        s++;
    return s;
}

/* PASS 2a on one thread: gathers slab `part`'s triangles over compact vertices, then
 * simplifies them with every vertex on the slab's cut (an open edge there) locked. */
static void simplify_slab(void *context, int part, int parts)
{
    slab_job *job = context;
    const iso_mesh *m = job->source;
    for (int s = part; s < job->count; s += parts) {
        slab *sl = &job->slabs[s];
        size_t n = 0;
        for (size_t t = 0; t < m->triangle_count; t++)
            n += slab_of(job, m, t) == s;
        uint32_t *local = malloc((m->vertex_count ? m->vertex_count : 1) * sizeof *local);
        iso_mesh_init(&sl->mesh);
        if (!local || iso_mesh_reserve(&sl->mesh, 3 * n, n) ||
            !(sl->global = malloc((3 * n + 1) * sizeof *sl->global))) {
            free(local);
            sl->rc = iso_error_set(&sl->err, ISO_E_NOMEM, "chain: no memory for a slab of %zu triangles", n);
            continue;
        }
        memset(local, 0xff, m->vertex_count * sizeof *local);
        size_t v = 0, i = 0;
        for (size_t t = 0; t < m->triangle_count; t++) {
            if (slab_of(job, m, t) != s)
                continue;
            for (int k = 0; k < 3; k++) {
                uint32_t g = m->indices[3 * t + k];
                if (local[g] == UINT32_MAX) {
                    local[g] = (uint32_t)v;
                    sl->global[v] = g;
                    memcpy(sl->mesh.positions + 3 * v++, m->positions + 3 * (size_t)g, 3 * sizeof(float));
                }
                sl->mesh.indices[i++] = local[g];
            }
        }
        free(local);
        sl->mesh.vertex_count = v;
        sl->mesh.triangle_count = n;
        sl->target = (size_t)((double)job->target * (double)n / (double)m->triangle_count) + 1;
        iso_simplify_params sp = {.target_triangles = sl->target, .target_error = INFINITY,
                                  .voxel_size = job->chain->voxel_size, .lock_border = 1,
                                  .keep_vertices = 1};
        sl->rc = iso_simplify_manifold(&sl->mesh, &sp, &sl->result, &sl->err);
    }
}

/* PASS 2a: level k - 1 (in m) cut into slabs across an axis (the longest side on even
 * levels, the next on odd ones, so that one level's cuts are simplified by the next),
 * simplified on all threads, and joined back into m. */
static int simplify_slabs(const iso_mesh_chain *chain, iso_mesh *m, int k, size_t target,
                          int threads, iso_simplify_result *r, iso_error *err)
{
    slab_job job = {.chain = chain, .source = m, .target = target};
    job.count = threads < ISO_CHAIN_SLABS_MAX ? threads : ISO_CHAIN_SLABS_MAX;
    float lo[3], hi[3];
    iso_mesh_bounds(m, lo, hi);
    int order[3] = {0, 1, 2};
    for (int a = 0; a < 3; a++)
        for (int b = a + 1; b < 3; b++)
            if (hi[order[b]] - lo[order[b]] > hi[order[a]] - lo[order[a]]) {
                int swap = order[a];
                order[a] = order[b], order[b] = swap;
            }
    job.axis = order[k % 2];
    for (int s = 0; s <= job.count; s++)
        job.cut[s] = lo[job.axis] + (hi[job.axis] - lo[job.axis]) * (float)s / (float)job.count;
    if (!(job.slabs = calloc((size_t)job.count, sizeof *job.slabs)))
        return iso_error_set(err, ISO_E_NOMEM, "chain: no memory for slabs");
    iso_parallel_run(threads, simplify_slab, &job);
    int rc = 0;
    size_t joined = 0;
    *r = (iso_simplify_result){.triangles_in = m->triangle_count, .vertices_in = m->vertex_count};
    for (int s = 0; s < job.count; s++) {
        slab *sl = &job.slabs[s];
        if (sl->rc && !rc) {
            rc = sl->rc;
            if (err)
                *err = sl->err;
        }
        for (size_t i = 0; !rc && i < 3 * sl->mesh.triangle_count; i++)
            m->indices[joined++] = sl->global[sl->mesh.indices[i]];
        r->error = fmax(r->error, sl->result.error);
        r->nonmanifold_edges += sl->result.nonmanifold_edges;
        r->folds_dropped += sl->result.folds_dropped;
        iso_mesh_free(&sl->mesh);
        free(sl->global);
    }
    free(job.slabs);
    if (!rc)
        m->triangle_count = joined / 3;
    return rc;
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
    iso_simplify_params sp = {.target_triangles = target, .target_error = INFINITY,
                              .voxel_size = chain->voxel_size, .lock_border = 1,
                              .keep_vertices = 1};
    iso_simplify_result r, slabs = {0};
    double start = iso_clock_ms();
    int workers = iso_parallel_threads(threads), rc = 0;
    /* PASS 2a, on large levels: slabs on all threads, to a little under the target so that
     * the cuts' unsimplified strips still fit; PASS 2b, the joined mesh with the cuts free,
     * which has little left to do. */
    if (workers > 1 && prev->triangle_count >= (size_t)workers * ISO_CHAIN_SLAB_MIN)
        rc = simplify_slabs(chain, &m, k, target - target / 64, workers, &slabs, err);
    if (!rc)
        rc = iso_simplify_manifold(&m, &sp, &r, err);
    if (rc) {
        free(m.indices);
        return rc;
    }
    if (slabs.triangles_in) {
        r.error = fmax(r.error, slabs.error);
        r.folds_dropped += slabs.folds_dropped;
        if (r.triangles == r.triangles_in) /* PASS 2b had nothing to do: the slabs' count */
            r.nonmanifold_edges = slabs.nonmanifold_edges;
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
    rc = iso_mesh_distance_between(&exact, exact_grid, &level, NULL,
                                   ISO_CHAIN_SPACING_VOXELS * chain->voxel_size,
                                   ISO_DISTANCE_SAMPLES, threads, &lv->distance, err);
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
    return 0;
}
