/* simplify.c: meshoptimizer's edge-collapse simplifier on an iso_mesh (see mesh.h). */
#include "mesh.h"

#include <float.h>
#include <math.h>
#include <stdint.h>
#include <stdlib.h>
#include <string.h>

#include "base/base.h"
#include "simplify_meshopt.h"

/* meshoptimizer 0.18's one option: do not move vertices on open edges. */
#define MESHOPT_LOCK_BORDER 1u

/* A triangle under its sorted corners, with its winding's parity, for finding folds. */
typedef struct corner_key {
    uint32_t v[3];      /* corners ascending */
    uint32_t triangle;  /* index in the result; its top bit: winding odd */
} corner_key;

#define ODD_WINDING 0x80000000u

static int compare_keys(const void *pa, const void *pb)
{
    const corner_key *a = pa, *b = pb;
    for (int k = 0; k < 3; k++)
        if (a->v[k] != b->v[k])
            return a->v[k] < b->v[k] ? -1 : 1;
    return (a->triangle > b->triangle) - (a->triangle < b->triangle);
}

static corner_key key_of(const uint32_t *t, uint32_t index)
{
    uint32_t a = t[0], b = t[1], c = t[2];
    int odd = 0;
    uint32_t s;
    /* Three compare-swaps sort the corners; each swap flips the winding's parity. */
    if (a > b) s = a, a = b, b = s, odd ^= 1;
    if (b > c) s = b, b = c, c = s, odd ^= 1;
    if (a > b) s = a, a = b, b = s, odd ^= 1;
    return (corner_key){{a, b, c}, index | (odd ? ODD_WINDING : 0)};
}

/* PASS 2: drops folds, pairs of triangles on the same three corners with opposite
 * windings (a collapse laid one onto the other). Each adds one use in each direction to
 * its three edges, so dropping the pair leaves every edge's balance as it was. keys has
 * triangle_count entries. O(T log T). Returns the triangles dropped. */
static size_t drop_folds(uint32_t *indices, size_t triangle_count, corner_key *keys,
                         unsigned char *marks)
{
    for (size_t t = 0; t < triangle_count; t++)
        keys[t] = key_of(indices + 3 * t, (uint32_t)t);
    qsort(keys, triangle_count, sizeof *keys, compare_keys);
    size_t dropped = 0;
    for (size_t i = 0; i + 1 < triangle_count; i++) {
        corner_key *a = keys + i, *b = keys + i + 1;
        if (memcmp(a->v, b->v, sizeof a->v) || !((a->triangle ^ b->triangle) & ODD_WINDING))
            continue;
        for (int k = 0; marks && k < 3; k++)
            marks[a->v[k]] = 1;
        /* UINT32_MAX in a first corner marks a dropped triangle for the compaction below. */
        indices[3 * (size_t)(a->triangle & ~ODD_WINDING)] = UINT32_MAX;
        indices[3 * (size_t)(b->triangle & ~ODD_WINDING)] = UINT32_MAX;
        dropped += 2;
        i++;
    }
    size_t kept = 0;
    for (size_t t = 0; t < triangle_count; t++)
        if (indices[3 * t] != UINT32_MAX)
            memmove(indices + 3 * kept++, indices + 3 * t, 3 * sizeof *indices);
    return dropped;
}

/* PASS 4: what topology the result has (mesh.h). */
static void count_edge(void *context, uint32_t lo, uint32_t hi, uint32_t forward, uint32_t backward)
{
    (void)lo, (void)hi;
    iso_simplify_result *r = context;
    if (forward + backward > 2)
        r->nonmanifold_edges++;
    if (forward + backward > 1 && forward != backward)
        r->unpaired_edges++;
}

static int check_params(const iso_simplify_params *p, iso_error *err)
{
    if (p->target_triangles < 1)
        return iso_error_set(err, ISO_E_ARGUMENT, "simplify: the target must be at least 1 triangle");
    if (!(p->target_error >= 0))
        return iso_error_set(err, ISO_E_ARGUMENT, "simplify: target error %g must be >= 0",
                             p->target_error);
    if (!(p->voxel_size >= 0) || !isfinite(p->voxel_size))
        return iso_error_set(err, ISO_E_ARGUMENT, "simplify: voxel size %g must be >= 0 and finite",
                             p->voxel_size);
    return 0;
}

static void describe(const iso_mesh *mesh, iso_simplify_result *r)
{
    r->triangles = mesh->triangle_count;
    r->vertices = mesh->vertex_count;
}

int iso_simplify(iso_mesh *mesh, const iso_simplify_params *params,
                 iso_simplify_result *result, iso_error *err)
{
    iso_simplify_result local;
    iso_simplify_result *r = result ? result : &local;
    double start = iso_clock_ms();
    int rc = check_params(params, err);
    if (rc)
        return rc;
    *r = (iso_simplify_result){.triangles_in = mesh->triangle_count,
                               .vertices_in = mesh->vertex_count};
    describe(mesh, r);
    if (mesh->triangle_count <= params->target_triangles) {
        r->measured = params->measure; /* untouched: at distance 0 */
        r->ms = iso_clock_ms() - start;
        return 0;
    }
    /* The result goes to buffers of its own and replaces the mesh's indices only when
     * nothing can fail any more: on ISO_E_NOMEM the mesh is the one that came in. */
    uint32_t *indices = malloc(3 * mesh->triangle_count * sizeof *indices);
    uint32_t *remap = malloc(mesh->vertex_count * sizeof *remap);
    corner_key *keys = NULL;
    if (!indices || !remap)
        goto nomem;
    /* PASS 1: meshoptimizer works in units of the extent; past FLT_MAX of them, no limit. */
    r->scale = iso_meshopt_scale(mesh->positions, mesh->vertex_count);
    double relative = r->scale > 0 ? params->target_error / r->scale : 0;
    float limit = relative < FLT_MAX ? (float)relative : FLT_MAX, achieved = 0;
    size_t index_count = 0;
    if (iso_meshopt_simplify(indices, mesh->indices, 3 * mesh->triangle_count, mesh->positions,
                             mesh->vertex_count, 3 * params->target_triangles, limit,
                             params->lock_border ? MESHOPT_LOCK_BORDER : 0, &achieved,
                             &index_count))
        goto nomem;
    size_t triangles = index_count / 3;
    if (!(keys = malloc((triangles ? triangles : 1) * sizeof *keys)))
        goto nomem;
    r->folds_dropped = drop_folds(indices, triangles, keys, params->fold_marks);
    triangles -= r->folds_dropped;
    free(keys);
    keys = NULL;
    /* PASS 4 before the mesh changes, so that its failure leaves the mesh as it was too. */
    iso_mesh view = *mesh;
    view.indices = indices;
    view.triangle_count = triangles;
    if (iso_mesh_visit_edges(&view, count_edge, r))
        goto nomem;
    /* PASS 4b: the result's distance from the input, both share the positions yet. */
    if (params->measure) {
        double spacing = params->voxel_size > 0 ? params->voxel_size : 1;
        if ((rc = iso_mesh_distance_compute(mesh, &view, spacing, params->threads, &r->distance, err))) {
            free(indices);
            free(remap);
            return rc;
        }
        r->measured = 1;
    }
    memcpy(mesh->indices, indices, 3 * triangles * sizeof *indices);
    free(indices);
    mesh->triangle_count = triangles;
    if (!params->keep_vertices)
        iso_mesh_drop_unused_into(mesh, remap); /* PASS 5 */
    free(remap);
    describe(mesh, r);
    r->error = (double)achieved * r->scale;
    r->error_voxels = r->error / (params->voxel_size > 0 ? params->voxel_size : 1);
    r->ms = iso_clock_ms() - start;
    return 0;
nomem:
    free(indices);
    free(remap);
    free(keys);
    return iso_error_set(err, ISO_E_NOMEM, "simplify: no memory for %zu triangles",
                         mesh->triangle_count);
}
