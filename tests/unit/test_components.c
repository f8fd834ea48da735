/* test_components.c: no connected component of a surface disappears from its
 * simplification chain, and min_component removes exactly the small closed ones.
 *
 * The surface, built by hand: a sphere of radius 14 and four closed specks of radius 1.2
 * to 2.6 (the 0-level of the largest of r_i - |p - c_i|, 1 mm voxels), each speck far
 * from the others. By default every level of the chain has the five components of the
 * exact surface, the specks at their smallest closed forms; with min_component between
 * the specks' enclosed volumes and the sphere's the specks go, counted exactly, and the
 * largest one's bounding-box diagonal is reported. A chain built only down to one
 * distance serves a finer one as the whole chain would. */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "check.h"
#include "pipeline.h"
#include "surface.h"

#define N 48
#define BLOBS 5
static const double blobs[BLOBS][4] = {/* centre, radius */
    {24, 24, 24, 14}, {5, 5, 5, 1.6}, {42, 6, 40, 2.2}, {6, 42, 8, 1.2}, {41, 41, 41, 2.6}};

static iso_volume *specks_volume(void)
{
    iso_volume *vol = surface_make_volume(N, N, N, ISO_F32);
    if (!vol)
        return NULL;
    float *f = vol->data;
    for (size_t k = 0; k < N; k++)
        for (size_t j = 0; j < N; j++)
            for (size_t i = 0; i < N; i++) {
                double best = -INFINITY;
                for (int b = 0; b < BLOBS; b++) {
                    double dx = (double)i - blobs[b][0], dy = (double)j - blobs[b][1], dz = (double)k - blobs[b][2];
                    best = fmax(best, blobs[b][3] - sqrt(dx * dx + dy * dy + dz * dz));
                }
                f[(k * N + j) * N + i] = (float)best;
            }
    iso_vol_update_stats(vol);
    return vol;
}

/* The blob nearest p (each component lies around its own). */
static int blob_of(const float *p)
{
    int best = 0;
    double bd = INFINITY;
    for (int b = 0; b < BLOBS; b++) {
        double d = fabs(hypot(hypot(p[0] - blobs[b][0], p[1] - blobs[b][1]), p[2] - blobs[b][2]) - blobs[b][3]);
        if (d < bd)
            bd = d, best = b;
    }
    return best;
}

static size_t components_of(const iso_mesh *m)
{
    size_t n = 0;
    CHECK_EQ(iso_mesh_count_components(m, &n), 0);
    return n;
}

static void test_every_level_keeps_every_component(void)
{
    iso_volume *vol = specks_volume();
    if (!vol)
        return;
    iso_tree *tree = surface_build(vol);
    iso_mesh exact, m;
    iso_mesh_init(&exact);
    iso_mesh_init(&m);
    iso_extract_stats st;
    iso_error err = {0};
    iso_extract_params xp = {.level = 0, .space = ISO_SPACE_WORLD};
    CHECK_OK(iso_extract(tree, &xp, &exact, &st, &err), &err);
    CHECK_EQ(components_of(&exact), BLOBS);
    iso_mesh_chain *chain = NULL;
    CHECK_OK(iso_mesh_chain_build(&exact, 1, 2, &chain, &err), &err);
    if (chain) {
        CHECKF(chain->levels >= 10, "%d levels", chain->levels);
        for (int k = 1; k < chain->levels; k++) {
            CHECK_OK(iso_mesh_chain_mesh(chain, k, &m, &err), &err);
            CHECKF(components_of(&m) == BLOBS, "level %d (%zu triangles): %zu components", k, m.triangle_count,
                   components_of(&m));
            iso_census c;
            CHECK_OK(iso_census_compute(vol, &m, ISO_SPACE_WORLD, &c, &err), &err);
            CHECK(c.closed);
        }
        /* The coarsest: each speck at a handful of triangles, the sphere has the rest. */
        size_t on_specks = 0;
        for (size_t t = 0; t < m.triangle_count; t++)
            on_specks += blob_of(m.positions + 3 * (size_t)m.indices[3 * t]) != 0;
        printf("  %d levels; the coarsest: %zu triangles, %zu on the specks (exact %zu)\n", chain->levels,
               m.triangle_count, on_specks, exact.triangle_count);
        CHECKF(on_specks >= 16 && on_specks <= 40, "%zu of %zu triangles on the specks", on_specks,
               m.triangle_count);
    }
    iso_mesh_chain_destroy(chain);
    iso_mesh_free(&m);
    iso_mesh_free(&exact);
    iso_tree_destroy(tree);
    iso_vol_destroy(vol);
}

/* Through the pipeline, as the CLI and the server ask: distance=0.5 mm with
 * min_component=200 mm3 (the largest speck encloses about 74, the sphere 11,500). */
static void test_min_component_removes_the_specks(void)
{
    iso_volume *vol = specks_volume();
    if (!vol)
        return;
    iso_tree *tree = surface_build(vol);
    iso_mesh exact;
    iso_mesh_init(&exact);
    iso_extract_stats st;
    iso_error err = {0};
    iso_extract_params xp = {.level = 0, .space = ISO_SPACE_WORLD};
    CHECK_OK(iso_extract(tree, &xp, &exact, &st, &err), &err);
    /* What should go: the specks' triangles and their largest bounding-box diagonal. */
    size_t speck_triangles = 0;
    float lo[BLOBS][3], hi[BLOBS][3];
    for (int b = 0; b < BLOBS; b++)
        for (int d = 0; d < 3; d++)
            lo[b][d] = INFINITY, hi[b][d] = -INFINITY;
    for (size_t t = 0; t < exact.triangle_count; t++) {
        int b = blob_of(exact.positions + 3 * (size_t)exact.indices[3 * t]);
        speck_triangles += b != 0;
        for (int c = 0; c < 3; c++)
            for (int d = 0; d < 3; d++) {
                float x = exact.positions[3 * (size_t)exact.indices[3 * t + c] + d];
                lo[b][d] = fminf(lo[b][d], x), hi[b][d] = fmaxf(hi[b][d], x);
            }
    }
    double largest = 0;
    for (int b = 1; b < BLOBS; b++) {
        double e[3] = {hi[b][0] - lo[b][0], hi[b][1] - lo[b][1], hi[b][2] - lo[b][2]};
        largest = fmax(largest, sqrt(e[0] * e[0] + e[1] * e[1] + e[2] * e[2]));
    }
    proto_pipeline_request req;
    proto_pipeline_request_init(&req);
    req.extract = xp;
    req.distance = 0.5;
    req.normals = 0;
    req.format = PROTO_FORMAT_NONE;
    proto_pipeline_result res;
    /* By default: nothing removed, every component served. */
    CHECK_OK(proto_pipeline_run(tree, vol, &req, &res, &err), &err);
    CHECK(res.chain_level > 0 && res.components.removed == 0);
    CHECK_EQ(components_of(&res.mesh), BLOBS);
    proto_pipeline_result_free(&res);
    req.min_component = 200;
    CHECK_OK(proto_pipeline_run(tree, vol, &req, &res, &err), &err);
    printf("  min_component 200: %zu of %zu components removed, %zu triangles, largest %.3f mm\n",
           res.components.removed, res.components.components, res.components.removed_triangles,
           res.components.removed_largest);
    CHECK_EQ(res.components.components, BLOBS);
    CHECK_EQ(res.components.removed, BLOBS - 1);
    CHECK_EQ(res.components.removed_triangles, speck_triangles);
    CHECKF(res.components.removed_largest == largest, "largest %.9g, expected %.9g", res.components.removed_largest,
           largest);
    CHECK_EQ(components_of(&res.mesh), 1);
    CHECK(res.chain_built && res.chain_built->min_component == 200 &&
          res.chain_built->level[0].triangle_count == exact.triangle_count - speck_triangles);
    /* The chain it built answers the same request again; one of another min_component does
     * not (it is built anew). */
    iso_mesh_chain *chain = res.chain_built;
    res.chain_built = NULL;
    proto_pipeline_result_free(&res);
    req.chain = chain;
    CHECK_OK(proto_pipeline_run(tree, vol, &req, &res, &err), &err);
    CHECK(res.chain_built == NULL && res.components.removed == BLOBS - 1 && components_of(&res.mesh) == 1);
    proto_pipeline_result_free(&res);
    req.min_component = 1; /* under every speck's volume */
    CHECK_OK(proto_pipeline_run(tree, vol, &req, &res, &err), &err);
    CHECK(res.chain_built != NULL && res.components.removed == 0 && components_of(&res.mesh) == BLOBS);
    proto_pipeline_result_free(&res);
    /* The exact mesh, no chain: the same removal. */
    req.chain = NULL;
    req.distance = -1;
    req.min_component = 200;
    CHECK_OK(proto_pipeline_run(tree, vol, &req, &res, &err), &err);
    CHECK(res.chain_level == -1 && res.components.removed == BLOBS - 1);
    CHECK_EQ(res.mesh.triangle_count, exact.triangle_count - speck_triangles);
    CHECK_EQ(res.stats.triangles, res.mesh.triangle_count);
    proto_pipeline_result_free(&res);
    iso_mesh_chain_destroy(chain);
    iso_mesh_free(&exact);
    iso_tree_destroy(tree);
    iso_vol_destroy(vol);
}

/* A chain the pipeline built only down to distance=0.5 answers 0.1 too (it covers it),
 * from a level measured without its maximum: the pipeline measures it, as the full
 * chain's. */
static void test_partial_chain_serves_a_finer_distance(void)
{
    iso_volume *vol = specks_volume();
    if (!vol)
        return;
    iso_tree *tree = surface_build(vol);
    iso_error err = {0};
    proto_pipeline_request req;
    proto_pipeline_request_init(&req);
    req.extract = (iso_extract_params){.level = 0, .space = ISO_SPACE_WORLD};
    req.distance = 0.5;
    req.chain_partial = 1;
    req.normals = 0;
    req.format = PROTO_FORMAT_NONE;
    proto_pipeline_result res;
    CHECK_OK(proto_pipeline_run(tree, vol, &req, &res, &err), &err);
    iso_mesh_chain *part = res.chain_built, *full = NULL;
    res.chain_built = NULL;
    proto_pipeline_result_free(&res);
    iso_mesh exact;
    iso_mesh_init(&exact);
    iso_extract_stats st;
    CHECK_OK(iso_extract(tree, &req.extract, &exact, &st, &err), &err);
    CHECK_OK(iso_mesh_chain_build(&exact, 1, 0, &full, &err), &err);
    if (part && full) {
        CHECK(part->partial && part->levels < full->levels);
        req.chain = part;
        req.distance = 0.1;
        int k = iso_mesh_chain_pick_distance(part, 0.1);
        CHECK(k > 0 && k < iso_mesh_chain_pick_distance(part, 0.5) && isnan(part->level[k].distance.max));
        CHECK_OK(proto_pipeline_run(tree, vol, &req, &res, &err), &err);
        CHECK(res.chain_built == NULL && res.chain_level == k);
        CHECKF(res.distance.p99 == full->level[k].distance.p99 && res.distance.max == full->level[k].distance.max,
               "level %d: p99 %g max %g, the full chain's %g %g", k, res.distance.p99, res.distance.max,
               full->level[k].distance.p99, full->level[k].distance.max);
        proto_pipeline_result_free(&res);
    }
    iso_mesh_chain_destroy(part);
    iso_mesh_chain_destroy(full);
    iso_mesh_free(&exact);
    iso_tree_destroy(tree);
    iso_vol_destroy(vol);
}

int main(void)
{
    CHECK_RUN(test_every_level_keeps_every_component);
    CHECK_RUN(test_min_component_removes_the_specks);
    CHECK_RUN(test_partial_chain_serves_a_finer_distance);
    return check_finish();
}
