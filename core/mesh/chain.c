/* chain.c: a surface's simplification chain, and the meshes it answers (see mesh.h).
 *
 * Passes of iso_mesh_chain_build:
 *   1. keep: the exact surface's positions and triangles become level 0, and its census
 *      (pinches, closed or not, enclosed volume) is taken beside level 1's simplification,
 *      with PASS 3's grid and samples of it (prepare: level 1 reads none of them);
 *   2. simplify: level k (k = 1..ISO_CHAIN_LEVELS) is level k - 1 simplified to
 *      1/sqrt(2) of its triangles (iso_mesh_chain_target) by collapses that keep the link
 *      condition and every component (collapse.c), borders locked, in up to two slabs on
 *      their own threads (simplify_level: 2a gather, 2b collapse in steps of error, 2c
 *      join), mapped back to the chain's vertices (so that every level indexes the one
 *      position array); a level that cannot shed 1/CHAIN_STALL of the triangles ends the
 *      chain;
 *   3. measure: each level's distance from level 0 (iso_mesh_distance_between, samples three
 *      voxels apart, against level 0's grid built once and kept with the chain), so the
 *      answers below rest on measurements, not on estimates; a level's triangles left as
 *      they were in the level before keep that level's bounds on their distance, so that
 *      the search for the largest distance skips those that cannot raise it (distance.h).
 *      Levels are measured in order beside the simplification of the next ones (the
 *      pipeline below), each on the threads the simplification leaves.
 * Level k depends only on level k - 1 (and, for level 1, the thread count): a build
 * stopped at a request's level (iso_mesh_chain_build_until) and extended later makes the
 * same levels as a full one (grow). */
#include "collapse.h"
#include "distance.h"

#include <math.h>
#include <pthread.h>
#include <stdlib.h>
#include <string.h>

#include "base/base.h"

void iso_mesh_chain_destroy(iso_mesh_chain *chain)
{
    if (!chain)
        return;
    for (int k = 0; k < chain->levels; k++)
        free(chain->level[k].indices);
    iso_mesh_grid_destroy(chain->grid);
    free(chain->positions);
    free(chain);
}

static int level_mesh(const iso_mesh_chain *chain, int k, iso_mesh *mesh, iso_error *err);

int iso_mesh_chain_copy(const iso_mesh_chain *chain, iso_mesh_chain **out, iso_error *err)
{
    *out = NULL;
    iso_mesh_chain *c = malloc(sizeof *c);
    if (!c)
        return iso_error_set(err, ISO_E_NOMEM, "chain: no memory to copy it");
    *c = *chain;
    c->grid = NULL; /* built again when a measure needs it: a grid has no copy */
    c->bytes = chain->bytes - iso_mesh_grid_bytes(chain->grid);
    c->positions = malloc((3 * chain->vertex_count + 1) * sizeof *c->positions);
    int ok = c->positions != NULL;
    for (int k = 0; k < c->levels; k++) {
        size_t n = 3 * chain->level[k].triangle_count;
        c->level[k].indices = ok ? malloc((n + 1) * sizeof *c->level[k].indices) : NULL;
        if (c->level[k].indices && n)
            memcpy(c->level[k].indices, chain->level[k].indices, n * sizeof *c->level[k].indices);
        ok = ok && c->level[k].indices;
    }
    if (!ok) {
        iso_mesh_chain_destroy(c);
        return iso_error_set(err, ISO_E_NOMEM, "chain: no memory to copy %zu triangles", chain->level[0].triangle_count);
    }
    if (chain->vertex_count)
        memcpy(c->positions, chain->positions, 3 * chain->vertex_count * sizeof *c->positions);
    *out = c;
    return 0;
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

/* Level 0's grid for the measures (NULL below 2 triangles): every level lies within its
 * bounds. 0 or ISO_E_NOMEM. */
static int level0_grid(const iso_mesh_chain *chain, iso_mesh_grid **out)
{
    iso_mesh level0 = view_of(chain, 0);
    *out = NULL;
    if (level0.triangle_count < 2)
        return 0;
    float lo[3], hi[3];
    iso_mesh_bounds(&level0, lo, hi);
    return iso_mesh_grid_build(&level0, lo, hi, out);
}

/* A level's pinches (manifold.c) counted over its own vertices, numbered in first use
 * (remap: scratch per chain vertex), so that the count's cost follows the level, not the
 * chain's vertex count; the topology, and so every count, is the same. Sets *used. */
static int level_pinches(const iso_mesh *m, uint32_t *remap, size_t *used, iso_mesh_pinches *out)
{
    iso_mesh compact;
    iso_mesh_init(&compact);
    memset(remap, 0xff, m->vertex_count * sizeof *remap);
    size_t n = 0;
    for (size_t i = 0; i < 3 * m->triangle_count; i++)
        if (remap[m->indices[i]] == UINT32_MAX)
            remap[m->indices[i]] = (uint32_t)n++;
    *used = n;
    if (iso_mesh_reserve(&compact, n, m->triangle_count))
        return ISO_E_NOMEM;
    for (size_t i = 0; i < 3 * m->triangle_count; i++) {
        uint32_t g = m->indices[i];
        compact.indices[i] = remap[g];
        memcpy(compact.positions + 3 * (size_t)remap[g], m->positions + 3 * (size_t)g, 3 * sizeof(float));
    }
    compact.vertex_count = n;
    compact.triangle_count = m->triangle_count;
    int rc = iso_mesh_find_pinches(&compact, NULL, out);
    iso_mesh_free(&compact);
    return rc;
}

#define CHAIN_SLAB_MIN 20000 /* triangles per slab, at least, else one part */
#define CHAIN_STEP 1.25      /* each step's error limit over the one before (PASS 2b) */
/* Levels 1 and 2, three quarters of the chain's collapses, make those costing less than
 * half the level's expected last one in memory order (iso_collapser_coarse), which is
 * cheaper; later levels, small and decided by fewer collapses, keep cost order, which
 * their p99 depends on more (docs/performance.md, "Faithful chains"). */
#define CHAIN_COARSE 0.5
#define CHAIN_COARSE_LEVELS 4

/* One slab of a level: its triangles over its own vertices, and their collapser. */
typedef struct slab {
    iso_mesh mesh;
    uint32_t *global;        /* its vertex i is the chain's vertex global[i] */
    iso_collapser *collapser;
    size_t alive, goal;      /* triangles left; this step's goal */
    int rc;
} slab;

typedef struct slab_job {
    const iso_mesh *source;
    const unsigned char *slab_of; /* per source triangle */
    slab *slabs;
    int count;
    double limit;            /* this step's error limit */
    int coarse;              /* the cheap collapses in memory order (CHAIN_COARSE) */
    double keep;             /* the level's target over its source's triangles */
} slab_job;

/* PASS 2a for the slabs of thread t: each gathered over compact vertices (so that its cost
 * follows its own size, not the chain's vertex count), and its collapser made; the cut's
 * edges are open in a slab, so the cut stays where it is. */
static void gather_slab(void *context, int t, int threads)
{
    slab_job *job = context;
    const iso_mesh *m = job->source;
    for (int s = t; s < job->count; s += threads) {
        slab *sl = &job->slabs[s];
        size_t n = sl->alive, v = 0, i = 0;
        uint32_t *local = malloc((m->vertex_count ? m->vertex_count : 1) * sizeof *local);
        iso_mesh_init(&sl->mesh);
        if (!local || iso_mesh_reserve(&sl->mesh, 3 * n, n) ||
            !(sl->global = malloc((3 * n + 1) * sizeof *sl->global))) {
            free(local);
            sl->rc = ISO_E_NOMEM;
            continue;
        }
        memset(local, 0xff, m->vertex_count * sizeof *local);
        for (size_t tri = 0; tri < m->triangle_count; tri++) {
            if (job->slab_of[tri] != s)
                continue;
            for (int k = 0; k < 3; k++) {
                uint32_t g = m->indices[3 * tri + k];
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
        int pinch_free;
        sl->rc = iso_collapser_create(&sl->mesh, &sl->collapser, &pinch_free);
        if (!sl->rc && job->coarse) /* the slab's share of the level's target */
            iso_collapser_coarse(sl->collapser, CHAIN_COARSE, (size_t)((double)n * job->keep));
    }
}

/* PASS 2b, one step for the slabs of thread t. */
static void step_slab(void *context, int t, int threads)
{
    slab_job *job = context;
    for (int s = t; s < job->count; s += threads)
        job->slabs[s].alive = iso_collapser_run(job->slabs[s].collapser, job->slabs[s].goal, job->limit);
}

/* PASS 2 for level k: m (level k - 1's triangles) simplified to `target` by collapses that
 * keep the link condition (collapse.c), borders locked. On several threads and a level of
 * 2 x CHAIN_SLAB_MIN triangles or more, in two slabs across an axis (the longest side on
 * even levels, the next on odd ones, so that no cut stays), each on its own thread with
 * its cut locked. (2a) each slab is gathered; (2b) the slabs collapse in steps, each up
 * to an error limit CHAIN_STEP times the one before and to its share of the triangles
 * still to go, so that the two spend their collapses where they cost least over the
 * whole level, not where a fixed share of the target would force them; (2c) the slabs'
 * triangles are mapped back to the chain's vertices. A smaller level, or one thread, is
 * one slab and one run. */
static int simplify_level(iso_mesh *m, int k, size_t target, int threads, iso_simplify_result *r,
                          iso_error *err)
{
    size_t T = m->triangle_count;
    int count = threads > 1 && T >= 2 * CHAIN_SLAB_MIN ? 2 : 1;
    *r = (iso_simplify_result){.triangles_in = T, .vertices_in = m->vertex_count};
    unsigned char *slab_of = malloc(T ? T : 1);
    slab slabs[2] = {{.alive = 0}, {.alive = 0}};
    if (!slab_of)
        return iso_error_set(err, ISO_E_NOMEM, "chain: no memory for the slabs of level %d", k);
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
    double middle = 0.5 * ((double)lo[axis] + hi[axis]);
    for (size_t t = 0; t < T; t++) {
        double centre = 0;
        for (int c = 0; c < 3; c++)
            centre += m->positions[3 * (size_t)m->indices[3 * t + c] + (size_t)axis];
        slab_of[t] = count > 1 && centre / 3 >= middle;
        slabs[slab_of[t]].alive++;
    }
    if (count > 1 && (!slabs[0].alive || !slabs[1].alive)) { /* all on one side */
        count = 1;
        memset(slab_of, 0, T);
        slabs[0].alive = T, slabs[1].alive = 0;
    }
    slab_job job = {.source = m, .slab_of = slab_of, .slabs = slabs, .count = count,
                    .coarse = k <= CHAIN_COARSE_LEVELS, .keep = T ? (double)target / (double)T : 0};
    iso_parallel_run(count, gather_slab, &job); /* PASS 2a */
    int rc = slabs[0].rc ? slabs[0].rc : slabs[1].rc;
    if (count == 1 && !rc) {
        slabs[0].goal = target, job.limit = INFINITY;
        step_slab(&job, 0, 1);
    }
    for (double limit = 0; count > 1 && !rc;) { /* PASS 2b */
        size_t total = slabs[0].alive + slabs[1].alive;
        double next = fmin(iso_collapser_next(slabs[0].collapser), iso_collapser_next(slabs[1].collapser));
        if (total <= target || next == INFINITY)
            break;
        job.limit = limit = fmax(limit * CHAIN_STEP, next);
        for (int s = 0; s < 2; s++) {
            size_t share = (size_t)ceil((double)(total - target) * (double)slabs[s].alive / (double)total);
            slabs[s].goal = slabs[s].alive > share ? slabs[s].alive - share : 0;
        }
        iso_parallel_run(2, step_slab, &job);
    }
    size_t joined = 0; /* PASS 2c */
    for (int s = 0; s < count; s++) {
        slab *sl = &slabs[s];
        if (!rc) {
            iso_collapser_triangles(sl->collapser, m->indices + 3 * joined);
            for (size_t i = 3 * joined; i < 3 * (joined + sl->alive); i++)
                m->indices[i] = sl->global[m->indices[i]];
            joined += sl->alive;
            r->error = fmax(r->error, iso_collapser_error(sl->collapser));
            r->locked_vertices += iso_collapser_refused(sl->collapser);
        }
        iso_collapser_destroy(sl->collapser);
        iso_mesh_free(&sl->mesh);
        free(sl->global);
    }
    free(slab_of);
    if (rc)
        return iso_error_set(err, rc, "chain: no memory for level %d (%zu triangles)", k, T);
    m->triangle_count = r->triangles = joined;
    return 0;
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
    int rc = level_mesh(chain, k, &moved, err);
    if (rc) {
        iso_mesh_free(&moved);
        lv->offset = 0;
        return rc;
    }
    lv->volume_change = (iso_mesh_enclosed_volume(&moved) - chain->volume) / chain->volume;
    lv->value_error = -1; /* the caller, who has the volume, measures it (mesh.h) */
    *level = moved;
    return 0;
}

/* PASS 3 for level k (level, moved or a view): its distance from level 0. *bound comes in
 * per triangle of level k - 1 (NULL: nothing known; level 1's prior is level 0 itself)
 * and leaves per triangle of level k (NULL when it was moved, so that its samples are not
 * level k + 1's): what the measure of the next level reuses (distance.h). */
static int measure_level(iso_mesh_chain *chain, const iso_mesh_grid *exact_grid,
                         const iso_mesh_samples *exact_samples, int k, const iso_mesh *level, int threads,
                         int without_max, double **bound, iso_error *err)
{
    const iso_mesh_chain_level *prev = &chain->level[k - 1];
    iso_mesh_chain_level *lv = &chain->level[k];
    iso_mesh_distance_reuse reuse = {.a_samples = exact_samples, .without_mean = 1};
    double *next = lv->offset == 0 ? malloc((lv->triangle_count + 1) * sizeof *next) : NULL;
    if (next && (k == 1 || *bound))
        reuse = (iso_mesh_distance_reuse){.prior_indices = prev->indices,
                                          .prior_triangles = prev->triangle_count,
                                          .prior_bound = k == 1 ? NULL : *bound,
                                          .a_samples = exact_samples, .without_mean = 1};
    reuse.bound = next;
    reuse.without_max = without_max;
    iso_mesh exact = view_of(chain, 0);
    int rc = iso_mesh_distance_between(&exact, exact_grid, level, NULL,
                                       ISO_CHAIN_SPACING_VOXELS * chain->voxel_size,
                                       ISO_DISTANCE_SAMPLES, threads, &reuse, &lv->distance, err);
    free(*bound);
    if (rc) {
        free(next);
        next = NULL;
    }
    *bound = next;
    return rc;
}

/* PASS 2 for level k on `threads`. The level is the chain's once this returns, even
 * failing (the builder counts it for destroy). A level that could not lose 1/CHAIN_STALL
 * of the triangles (the surface's topology allows few more collapses) is not made:
 * *stalled is set, the chain ends before it. */
#define CHAIN_STALL 20
static int add_level(iso_mesh_chain *chain, int k, int threads, uint32_t *remap, int *stalled,
                     iso_error *err)
{
    const iso_mesh_chain_level *prev = &chain->level[k - 1];
    iso_mesh_chain_level *lv = &chain->level[k];
    iso_mesh m = view_of(chain, k - 1);
    if (!(m.indices = malloc(3 * prev->triangle_count * sizeof *m.indices)))
        return iso_error_set(err, ISO_E_NOMEM, "chain: no memory for level %d", k);
    memcpy(m.indices, prev->indices, 3 * prev->triangle_count * sizeof *m.indices);
    size_t target = iso_mesh_chain_target(chain->level[0].triangle_count, k);
    target = target ? target : 1;
    iso_simplify_result r;
    double start = iso_clock_ms();
    int rc = simplify_level(&m, k, target, threads, &r, err);
    if (rc) {
        free(m.indices);
        return rc;
    }
    r.ms = iso_clock_ms() - start;
    if ((*stalled = m.triangle_count > prev->triangle_count - prev->triangle_count / CHAIN_STALL)) {
        free(m.indices);
        return 0;
    }
    uint32_t *shrunk = realloc(m.indices, (3 * m.triangle_count + 1) * sizeof *m.indices);
    lv->indices = m.indices = shrunk ? shrunk : m.indices;
    lv->triangle_count = m.triangle_count;
    lv->simplify_ms = r.ms;
    chain->bytes += 3 * lv->triangle_count * sizeof *lv->indices;
    lv->estimate = r.error;
    lv->folds_dropped = r.folds_dropped;
    if (k >= 2 && prev->nonmanifold_edges == 0 && prev->pinch_vertices == 0) {
        /* One collapser over a level without pinches makes none, and each collapse takes
         * one vertex, two triangles and three edges: nothing to count. */
        size_t collapses = (prev->triangle_count - lv->triangle_count) / 2;
        lv->vertex_count = prev->vertex_count - collapses;
        lv->edges = prev->edges - 3 * collapses;
        return 0;
    }
    iso_mesh_pinches pinches;
    if ((rc = level_pinches(&m, remap, &lv->vertex_count, &pinches)))
        return iso_error_set(err, rc, "chain: no memory to count level %d's pinches", k);
    lv->nonmanifold_edges = pinches.pinch_edges;
    lv->pinch_vertices = pinches.pinch_vertices;
    lv->edges = pinches.edges;
    return 0;
}

/* PASS 2c and 3 for level k (*bound: measure_level's). */
static int measure_step(iso_mesh_chain *chain, const iso_mesh_grid *exact_grid,
                        const iso_mesh_samples *exact_samples, int k, int threads, int without_max,
                        double **bound, iso_error *err)
{
    iso_mesh_chain_level *lv = &chain->level[k];
    iso_mesh level = view_of(chain, k);
    double start = iso_clock_ms();
    int rc = keep_volume(chain, k, &level, err);
    if (!rc)
        rc = measure_level(chain, exact_grid, exact_samples, k, &level, threads, without_max, bound, err);
    if (lv->offset != 0)
        iso_mesh_free(&level);
    lv->measure_ms = iso_clock_ms() - start;
    return rc;
}

/* PASS 3 again for a level a partial build measured without its maximum (distance.max
 * NAN): the whole measure, which gives the same p99 bit for bit and the exact maximum, as
 * the full build's. Its time joins the level's. */
static int measure_max_of(iso_mesh_chain *chain, const iso_mesh_grid *exact_grid,
                          const iso_mesh_samples *exact_samples, int k, int threads, iso_error *err)
{
    iso_mesh_chain_level *lv = &chain->level[k];
    if (!isnan(lv->distance.max))
        return 0;
    double start = iso_clock_ms(), before = lv->measure_ms;
    iso_mesh level = view_of(chain, k);
    int rc = lv->offset != 0 ? (iso_mesh_init(&level), level_mesh(chain, k, &level, err)) : 0;
    double *bound = NULL;
    if (!rc)
        rc = measure_level(chain, exact_grid, exact_samples, k, &level, threads, 0, &bound, err);
    free(bound);
    if (lv->offset != 0)
        iso_mesh_free(&level);
    lv->measure_ms = before + iso_clock_ms() - start;
    return rc;
}

/* PASS 2 and 3 side by side: the simplification is one thread's (but for level 1, made
 * before on all threads, beside level 0's preparation, since nothing waits to be measured
 * beside it), so the levels already made are measured meanwhile on the chain's other
 * threads, each after the one before (it reuses that one's bounds), and on all of them
 * once the last level is made. Level k's measure writes only level k's measured fields,
 * which nothing else touches; levels are handed over under the lock. A partial build
 * (stop_distance or stop_triangles) stops at the first level that meets either: then the
 * simplification runs at most one level ahead of the measure, and a level made but not
 * measured when the measure stops is dropped. */
typedef struct pipeline {
    iso_mesh_chain *chain;
    uint32_t *remap;           /* the simplification's scratch, per chain vertex */
    int levels, threads;       /* the last level to make; the chain's threads */
    int first;                 /* the first level to make and measure */
    double stop_distance;      /* >= 0: stop after the first level measured beyond it */
    size_t stop_triangles;     /* > 0: stop after the first level made within it */
    pthread_mutex_t lock;
    pthread_cond_t changed;    /* made, measured or stop changed */
    int made;                  /* levels simplified (under the lock) */
    int measured;              /* levels measured (under the lock) */
    int over;                  /* the simplification stopped: no more levels (under the lock) */
    int stalled;               /* a level lost no triangle: the chain ends (under the lock) */
    int stop;                  /* a measure failed or met stop_distance: simplify no further
                                * (under the lock) */
    int rc_simplify, rc_measure, rc_prepare;
    iso_error err_simplify, err_measure;
    iso_mesh_grid *grid;       /* level 0's (PASS 3), made by prepare or the chain's */
    iso_mesh_samples *samples; /* level 0's (NULL without memory: each measure counts) */
    double samples_ms;
} pipeline;

/* Level 0's samples for the measures. Out of memory here leaves them NULL: each measure
 * then counts level 0's samples itself, and reports its own lack of memory if that fails
 * too. */
static void prepare_samples(pipeline *p)
{
    iso_mesh level0 = view_of(p->chain, 0);
    double start = iso_clock_ms();
    if (p->levels >= p->first &&
        iso_mesh_samples_build(&level0, ISO_CHAIN_SPACING_VOXELS * p->chain->voxel_size, &p->samples))
        p->samples = NULL;
    p->samples_ms = iso_clock_ms() - start;
}

/* PASS 1's census of level 0 (its pinches, whether it is closed, its volume) and PASS 3's
 * grid and samples of it: all the measure needs before level 1's, and nothing level 1's
 * simplification reads, so made beside it. Writes only level 0's counts, the chain's
 * closed and volume, and p's grid and samples (the chain's bytes are counted after). */
static void prepare(pipeline *p)
{
    iso_mesh_chain *c = p->chain;
    iso_mesh level0 = view_of(c, 0);
    iso_mesh_pinches pinches;
    if (iso_mesh_find_pinches(&level0, NULL, &pinches)) {
        p->rc_prepare = ISO_E_NOMEM;
        return;
    }
    c->level[0].edges = pinches.edges;
    c->level[0].nonmanifold_edges = pinches.pinch_edges;
    c->level[0].pinch_vertices = pinches.pinch_vertices;
    c->closed = level0.triangle_count > 0 && pinches.open_edges == 0;
    c->volume = c->closed ? iso_mesh_enclosed_volume(&level0) : 0;
    if (level0_grid(c, &p->grid)) {
        p->rc_prepare = ISO_E_NOMEM;
        return;
    }
    prepare_samples(p);
}

/* Whether level k ends a partial build made for stop_triangles. */
static int enough_triangles(const pipeline *p, int k)
{
    return p->stop_triangles && p->chain->level[k].triangle_count <= p->stop_triangles;
}

/* Level 1 (share 0, on all threads: its slabs' shares go to any thread free, so also to
 * this one's once prepare is done) beside prepare (share 1). */
static void first_stage(void *context, int t, int threads)
{
    pipeline *p = context;
    (void)threads;
    if (t == 1) {
        prepare(p);
        return;
    }
    if (p->levels > 0) {
        p->rc_simplify = add_level(p->chain, 1, p->threads, p->remap, &p->stalled, &p->err_simplify);
        p->made = !p->stalled;
        p->over = p->rc_simplify || p->stalled || p->levels == 1 || enough_triangles(p, 1);
    } else {
        p->over = 1;
    }
}

static void simplify_all(pipeline *p)
{
    for (int k = p->made + 1; k <= p->levels && !p->rc_simplify && !p->over; k++) {
        pthread_mutex_lock(&p->lock);
        /* A partial build for a distance makes level k once level k - 2 is measured: one
         * level made ahead of the measure, not more that may be dropped. */
        while (p->stop_distance >= 0 && !p->stop && p->measured < k - 2)
            pthread_cond_wait(&p->changed, &p->lock);
        int stop = p->stop;
        pthread_mutex_unlock(&p->lock);
        int stalled = 0, rc = stop ? 0 : add_level(p->chain, k, 1, p->remap, &stalled, &p->err_simplify);
        pthread_mutex_lock(&p->lock);
        p->made = stop || stalled ? p->made : k; /* a failed level is still the chain's, to free */
        p->stalled = stalled;
        p->over = stop || rc || stalled || k == p->levels || enough_triangles(p, k);
        p->rc_simplify = rc;
        pthread_cond_broadcast(&p->changed);
        pthread_mutex_unlock(&p->lock);
    }
    pthread_mutex_lock(&p->lock);
    p->over = 1;
    pthread_cond_broadcast(&p->changed);
    pthread_mutex_unlock(&p->lock);
}

static void measure_all(pipeline *p)
{
    double *bound = NULL;
    for (int k = p->first; k <= p->levels; k++) {
        pthread_mutex_lock(&p->lock);
        while (p->made < k && !p->over)
            pthread_cond_wait(&p->changed, &p->lock);
        int ready = p->made >= k && !(p->made == k && p->rc_simplify), all = p->over;
        /* A partial build's simplifier waits for this measure once it is a level ahead:
         * then this one has its thread too. */
        all |= p->stop_distance >= 0 && p->made >= k + 1;
        pthread_mutex_unlock(&p->lock);
        if (!ready)
            break;
        int threads = all || p->threads < 2 ? p->threads : p->threads - 1;
        int rc = measure_step(p->chain, p->grid, p->samples, k, threads, p->stop_distance >= 0, &bound,
                              &p->err_measure);
        if (k == p->first) /* level 0's samples, counted once for all levels, in the first one's time */
            p->chain->level[k].measure_ms += p->samples_ms;
        pthread_mutex_lock(&p->lock);
        p->rc_measure = rc;
        p->measured = rc ? p->measured : k;
        p->stop = rc || (p->stop_distance >= 0 && p->chain->level[k].distance.p99 > p->stop_distance);
        pthread_cond_broadcast(&p->changed);
        int stop = p->stop;
        pthread_mutex_unlock(&p->lock);
        if (stop)
            break;
    }
    free(bound);
}

static void pipeline_stage(void *context, int t, int threads)
{
    (void)threads;
    if (t == 0)
        simplify_all(context);
    else
        measure_all(context);
}

size_t iso_mesh_chain_target(size_t triangles, int k)
{
    size_t half = k / 2 < 64 ? triangles >> (k / 2) : 0;
    return k % 2 ? (size_t)((double)half * M_SQRT1_2) : half;
}

/* The levels past 0 a full chain of a surface of `triangles` has: each with fewer
 * triangles than the one before, at least 1. */
static int levels_for(size_t triangles)
{
    int k = 0;
    while (k < ISO_CHAIN_LEVELS && iso_mesh_chain_target(triangles, k + 1) >= 1 &&
           iso_mesh_chain_target(triangles, k + 1) < iso_mesh_chain_target(triangles, k))
        k++;
    return k;
}

int iso_mesh_chain_complete(const iso_mesh_chain *chain)
{
    for (int k = 1; k < chain->levels; k++)
        if (isnan(chain->level[k].distance.max))
            return 0;
    return !chain->partial;
}

int iso_mesh_chain_covers(const iso_mesh_chain *chain, double distance, size_t triangles)
{
    const iso_mesh_chain_level *last = &chain->level[chain->levels - 1];
    return !chain->partial || (distance >= 0 && chain->levels > 1 && last->distance.p99 > distance) ||
           (triangles && last->triangle_count <= triangles);
}

/* Level 0's vertices, counted after level 1 (whose scratch remap is). */
static void count_level0_vertices(iso_mesh_chain *c, uint32_t *remap)
{
    const iso_mesh_chain_level *l0 = &c->level[0];
    memset(remap, 0, c->vertex_count * sizeof *remap);
    size_t used = 0;
    for (size_t i = 0; i < 3 * l0->triangle_count; i++)
        used += !remap[l0->indices[i]]++;
    c->level[0].vertex_count = used;
}

/* PASS 2 and 3 from the chain's last level on, until the stop (grow's callers). Level 0's
 * census and grid come first when the chain has only level 0. On return the chain holds
 * the levels measured (those made past them are dropped), counted in levels, bytes and
 * partial, even on failure (then the levels before the failing one). */
static int grow(iso_mesh_chain *c, int threads, double stop_distance, size_t stop_triangles, iso_error *err)
{
    double start = iso_clock_ms();
    uint32_t *remap = malloc((c->vertex_count ? c->vertex_count : 1) * sizeof *remap);
    if (!remap)
        return iso_error_set(err, ISO_E_NOMEM, "chain: no memory");
    int fresh = c->levels == 1;
    pipeline p = {.chain = c, .remap = remap, .threads = iso_parallel_threads(threads),
                  .levels = levels_for(c->level[0].triangle_count), .first = c->levels,
                  .made = c->levels - 1, .measured = c->levels - 1, .stop_distance = stop_distance,
                  .stop_triangles = stop_triangles, .lock = PTHREAD_MUTEX_INITIALIZER,
                  .changed = PTHREAD_COND_INITIALIZER};
    int rc = 0;
    if (fresh && p.threads > 1) {
        iso_parallel_run(2, first_stage, &p);
    } else if (fresh) {
        prepare(&p);
        first_stage(&p, 0, 1);
    } else {
        p.over = p.made >= p.levels;
        if (!(rc = iso_mesh_chain_grid_build(c) ? ISO_E_NOMEM : 0))
            prepare_samples(&p);
        p.grid = c->grid;
    }
    if (fresh) {
        count_level0_vertices(c, remap);
        c->grid = p.grid;
        c->bytes += iso_mesh_grid_bytes(c->grid);
        rc = p.rc_prepare;
    }
    if (rc)
        rc = iso_error_set(err, ISO_E_NOMEM, "chain: no memory for the grid of %zu triangles",
                           c->level[0].triangle_count);
    if (!rc && p.threads > 1 && !p.over) { /* share 0 makes the levels, share 1 measures them */
        iso_parallel_run(2, pipeline_stage, &p);
    } else if (!rc) {
        simplify_all(&p);
        measure_all(&p);
    }
    for (int k = p.measured + 1; k <= p.made; k++) { /* made, not measured: dropped */
        c->bytes -= 3 * c->level[k].triangle_count * sizeof *c->level[k].indices;
        free(c->level[k].indices);
        c->level[k] = (iso_mesh_chain_level){0};
    }
    c->levels = 1 + p.measured;
    c->partial = !(p.stalled && p.measured == p.made) && p.measured < p.levels;
    /* A build for a distance measured its levels without their maxima (PASS 3 without its
     * pass over every sample, a third of the measure): only the level that answers the
     * distance gets its maximum now; iso_mesh_chain_extend measures the others'. */
    int answer = stop_distance >= 0 ? iso_mesh_chain_pick_distance(c, stop_distance) : 0;
    if (!rc && !p.rc_simplify && !p.rc_measure && answer > 0)
        rc = measure_max_of(c, p.grid, p.samples, answer, p.threads, err);
    iso_mesh_samples_destroy(p.samples);
    if (!rc && (p.rc_simplify || p.rc_measure)) {
        rc = p.rc_simplify ? p.rc_simplify : p.rc_measure;
        if (err)
            *err = p.rc_simplify ? p.err_simplify : p.err_measure;
    }
    pthread_mutex_destroy(&p.lock);
    pthread_cond_destroy(&p.changed);
    free(remap);
    c->build_ms += iso_clock_ms() - start;
    return rc;
}

int iso_mesh_chain_build_until(const iso_mesh *exact, double voxel_size, int threads, double distance,
                               size_t triangles, iso_mesh_chain **out, iso_error *err)
{
    *out = NULL;
    if (!(voxel_size > 0) || !isfinite(voxel_size))
        return iso_error_set(err, ISO_E_ARGUMENT, "chain: voxel size %g must be > 0", voxel_size);
    double start = iso_clock_ms();
    iso_mesh_chain *c = calloc(1, sizeof *c);
    if (!c)
        return iso_error_set(err, ISO_E_NOMEM, "chain: no memory");
    c->voxel_size = voxel_size;
    c->vertex_count = exact->vertex_count;
    c->positions = malloc((3 * exact->vertex_count + 1) * sizeof *c->positions);
    c->level[0].indices = malloc((3 * exact->triangle_count + 1) * sizeof *c->level[0].indices);
    c->levels = 1;
    if (!c->positions || !c->level[0].indices) {
        iso_mesh_chain_destroy(c);
        return iso_error_set(err, ISO_E_NOMEM, "chain: no memory for %zu triangles", exact->triangle_count);
    }
    /* PASS 1 */
    if (exact->vertex_count) /* an empty mesh may have no arrays at all */
        memcpy(c->positions, exact->positions, 3 * exact->vertex_count * sizeof *c->positions);
    if (exact->triangle_count)
        memcpy(c->level[0].indices, exact->indices, 3 * exact->triangle_count * sizeof *exact->indices);
    c->level[0].triangle_count = exact->triangle_count;
    c->level[0].vertex_count = exact->vertex_count;
    c->bytes = sizeof *c + 3 * exact->vertex_count * sizeof *c->positions +
               3 * exact->triangle_count * sizeof *exact->indices;
    c->build_ms = iso_clock_ms() - start;
    int rc = grow(c, threads, distance, triangles, err);
    if (rc) {
        iso_mesh_chain_destroy(c);
        return rc;
    }
    *out = c;
    return 0;
}

int iso_mesh_chain_build(const iso_mesh *exact, double voxel_size, int threads,
                         iso_mesh_chain **out, iso_error *err)
{
    return iso_mesh_chain_build_until(exact, voxel_size, threads, -1, 0, out, err);
}

/* The maxima a build for a distance left out (distance.max NAN): every level's
 * (distance < 0), or only that of the level answering `distance`. */
static int measure_maxima(iso_mesh_chain *c, int threads, double distance, iso_error *err)
{
    int answer = distance >= 0 ? iso_mesh_chain_pick_distance(c, distance) : 0, wanted = 0;
    for (int k = 1; k < c->levels; k++)
        wanted += isnan(c->level[k].distance.max) && (distance < 0 || k == answer);
    if (!wanted)
        return 0;
    if (iso_mesh_chain_grid_build(c))
        return iso_error_set(err, ISO_E_NOMEM, "chain: no memory for the grid of %zu triangles",
                             c->level[0].triangle_count);
    iso_mesh level0 = view_of(c, 0);
    iso_mesh_samples *samples = NULL; /* without memory for them each measure counts its own */
    if (iso_mesh_samples_build(&level0, ISO_CHAIN_SPACING_VOXELS * c->voxel_size, &samples))
        samples = NULL;
    int rc = 0;
    for (int k = 1; !rc && k < c->levels; k++)
        if (distance < 0 || k == answer)
            rc = measure_max_of(c, c->grid, samples, k, iso_parallel_threads(threads), err);
    iso_mesh_samples_destroy(samples);
    return rc;
}

int iso_mesh_chain_extend_until(iso_mesh_chain *chain, int threads, double distance, size_t triangles,
                                iso_error *err)
{
    int rc = 0;
    if (chain->partial && !((distance >= 0 || triangles) && iso_mesh_chain_covers(chain, distance, triangles)))
        rc = grow(chain, threads, distance, triangles, err);
    double start = iso_clock_ms();
    if (!rc && (distance >= 0 || !triangles))
        rc = measure_maxima(chain, threads, distance, err);
    chain->build_ms += iso_clock_ms() - start;
    return rc;
}

int iso_mesh_chain_extend(iso_mesh_chain *chain, int threads, iso_error *err)
{
    return iso_mesh_chain_extend_until(chain, threads, -1, 0, err);
}

int iso_mesh_chain_grid_build(iso_mesh_chain *chain)
{
    if (chain->grid)
        return 0;
    int rc = level0_grid(chain, &chain->grid);
    chain->bytes += iso_mesh_grid_bytes(chain->grid);
    return rc;
}

int iso_mesh_chain_distance(const iso_mesh_chain *chain, const iso_mesh *mesh, int threads,
                            iso_mesh_distance *out, iso_error *err)
{
    iso_mesh exact = view_of(chain, 0);
    iso_mesh_distance_reuse quick = {.without_mean = 1}; /* as the levels: p99 and max */
    return iso_mesh_distance_between(&exact, chain->grid, mesh, NULL,
                                     ISO_CHAIN_SPACING_VOXELS * chain->voxel_size,
                                     ISO_DISTANCE_SAMPLES, threads, &quick, out, err);
}

int iso_mesh_chain_pick_distance(const iso_mesh_chain *chain, double distance)
{
    int best = 0;
    for (int k = 1; k < chain->levels && chain->level[k].distance.p99 <= distance; k++)
        if (chain->level[k].triangle_count < chain->level[best].triangle_count)
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
    return level_mesh(chain, k, mesh, err);
}

/* iso_mesh_chain_mesh without the range check: while the chain is built, its levels are
 * counted only at the end. */
static int level_mesh(const iso_mesh_chain *chain, int k, iso_mesh *mesh, iso_error *err)
{
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
