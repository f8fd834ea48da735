/* chain.c: a surface's simplification chain, and the meshes it answers (see mesh.h).
 *
 * Passes of iso_mesh_chain_build:
 *   1. keep: the exact surface's positions and triangles become level 0;
 *   2. simplify: level k (k = 1..ISO_CHAIN_LEVELS) is level k - 1 simplified to half its
 *      triangles (iso_simplify, borders locked, unused vertices kept so that every level
 *      indexes the one position array);
 *   3. measure: each level's distance from level 0 (iso_mesh_distance_compute, samples three
 *      voxels apart), so the answers below rest on measurements, not on estimates. */
#include "mesh.h"

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

/* PASS 2 and 3 for level k. */
static int add_level(iso_mesh_chain *chain, int k, int threads, unsigned char *seen, iso_error *err)
{
    const iso_mesh_chain_level *prev = &chain->level[k - 1];
    iso_mesh_chain_level *lv = &chain->level[k];
    iso_mesh m = view_of(chain, k - 1);
    if (!(m.indices = malloc(3 * prev->triangle_count * sizeof *m.indices)))
        return iso_error_set(err, ISO_E_NOMEM, "chain: no memory for level %d", k);
    memcpy(m.indices, prev->indices, 3 * prev->triangle_count * sizeof *m.indices);
    size_t target = chain->level[0].triangle_count >> k;
    iso_simplify_params sp = {.target_triangles = target ? target : 1, .target_error = INFINITY,
                              .voxel_size = chain->voxel_size, .lock_border = 1,
                              .keep_vertices = 1};
    iso_simplify_result r;
    int rc = iso_simplify(&m, &sp, &r, err);
    if (rc) {
        free(m.indices);
        return rc;
    }
    uint32_t *shrunk = realloc(m.indices, (3 * m.triangle_count + 1) * sizeof *m.indices);
    lv->indices = m.indices = shrunk ? shrunk : m.indices;
    lv->triangle_count = m.triangle_count;
    lv->vertex_count = used_vertices(&m, seen);
    lv->estimate = r.error;
    lv->nonmanifold_edges = r.nonmanifold_edges;
    lv->folds_dropped = r.folds_dropped;
    chain->levels = k + 1;
    iso_mesh exact = view_of(chain, 0), level = view_of(chain, k);
    double start = iso_clock_ms();
    rc = iso_mesh_distance_compute(&exact, &level, ISO_CHAIN_SPACING_VOXELS * chain->voxel_size, threads, &lv->distance, err);
    lv->simplify_ms = r.ms;
    lv->measure_ms = iso_clock_ms() - start;
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
    memcpy(c->positions, exact->positions, 3 * exact->vertex_count * sizeof *c->positions);
    memcpy(c->level[0].indices, exact->indices, 3 * exact->triangle_count * sizeof *exact->indices);
    c->level[0].triangle_count = exact->triangle_count;
    c->levels = 1;
    iso_mesh level0 = view_of(c, 0);
    c->level[0].vertex_count = used_vertices(&level0, seen);
    c->bytes = sizeof *c + 3 * exact->vertex_count * sizeof *c->positions +
               3 * exact->triangle_count * sizeof *exact->indices;
    int rc = 0;
    for (int k = 1; k <= ISO_CHAIN_LEVELS && !rc; k++) {
        if ((exact->triangle_count >> k) < 1)
            break;
        rc = add_level(c, k, threads, seen, err);
    }
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
