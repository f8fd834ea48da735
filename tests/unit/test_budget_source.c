/* test_budget_source.c: budget= answered by the value-tolerance ladder, not the chain.
 *
 * A budget the faithful tolerance's mesh fits is answered by whichever of that mesh and
 * the chain's finest level within the budget is closer to the exact surface, measured
 * (proto/pipeline.c). On CT the chain wins; here the ladder must. The field is a fold:
 * f = z - h(x, y), with h a bumpy sheet (20 + 6 sin 0.9x sin 0.8y) over x < n/2 and flat
 * (20) beyond. f is linear over the flat half, so every coarse grid of its bricks is exact
 * and the ladder marches them coarsely onto the very same plane: fewer triangles, no
 * distance. The bumps keep their bricks fine. A budget just above the ladder's mesh then
 * leaves the chain its 50% level, which must move bumps to get there. Checked: the
 * ladder answers (source "tolerance", no chain level, the tolerance above 0, fewer
 * triangles than exact, within the budget); its reported distances against brute force
 * (every exact vertex, and every answer triangle's centroid, within the reported maximum
 * of the other surface); the other distance reported is the chain level's own; and, by
 * brute force, more than 0.1% of that chain level's centroids lie farther from the exact
 * surface than the whole ladder mesh does, so the chain level is truly the farther one. */
#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "check.h"
#include "pipeline.h"
#include "surface.h"

#define N 32

static iso_volume *fold_volume(void)
{
    iso_volume *vol = surface_make_volume(N, N, N, ISO_F32);
    if (!vol)
        return NULL;
    for (size_t k = 0; k < N; k++)
        for (size_t j = 0; j < N; j++)
            for (size_t i = 0; i < N; i++) {
                double h = i < N / 2 ? 14 + 6 * sin(0.9 * (double)i) * sin(0.8 * (double)j) : 14;
                iso_vol_set(vol, i, j, k, (double)k - h);
            }
    iso_vol_update_stats(vol);
    return vol;
}

/* The largest distance from m's vertices (or, centroids, its triangles' centroids) to
 * `to`, by brute force; *far counts those farther than `beyond`. */
static double brute_max(const iso_mesh *m, int centroids, const iso_mesh *to, double beyond, size_t *far)
{
    double top = 0;
    size_t n = centroids ? m->triangle_count : m->vertex_count;
    *far = 0;
    for (size_t i = 0; i < n; i++) {
        double p[3] = {0, 0, 0};
        for (int c = 0; c < (centroids ? 3 : 1); c++) {
            const float *v = m->positions + 3 * (size_t)(centroids ? m->indices[3 * i + (size_t)c] : i);
            for (int a = 0; a < 3; a++)
                p[a] += v[a] / (centroids ? 3.0 : 1.0);
        }
        double d = iso_mesh_point_distance(to, p);
        top = fmax(top, d);
        *far += d > beyond;
    }
    return top;
}

static void test_ladder_answers_when_closer(void)
{
    iso_error err = {0};
    iso_volume *vol = fold_volume();
    if (!vol)
        return;
    iso_tree *tree = surface_build(vol);
    iso_mesh exact;
    iso_extract_stats st;
    iso_extract_params xp = {.level = 0.5, .space = ISO_SPACE_WORLD};
    iso_mesh_init(&exact);
    CHECK_OK(iso_extract(tree, &xp, &exact, &st, &err), &err);
    /* The ladder's mesh: the faithful tolerance's, with fewer triangles than exact. */
    iso_mesh faithful;
    iso_mesh_init(&faithful);
    iso_extract_params fp = xp;
    fp.tolerance = iso_budget_faithful_tolerance(vol, 0);
    fp.coarsen = ISO_COARSEN_ALL; /* as the budget ladder asks */
    CHECK_OK(iso_extract(tree, &fp, &faithful, &st, &err), &err);
    CHECKF(faithful.triangle_count < exact.triangle_count * 95 / 100, "faithful %zu of %zu triangles",
           faithful.triangle_count, exact.triangle_count);
    CHECKF(faithful.triangle_count > exact.triangle_count / 2, "faithful %zu of %zu: the 50%% level fits it",
           faithful.triangle_count, exact.triangle_count);

    proto_pipeline_request req;
    proto_pipeline_request_init(&req);
    req.extract = xp;
    req.budget = faithful.triangle_count + 10;
    req.budget_chain = 1;
    req.normals = 0;
    req.format = PROTO_FORMAT_NONE;
    proto_pipeline_result res;
    CHECK_OK(proto_pipeline_run(tree, vol, &req, &res, &err), &err);
    if (check_failed())
        return;
    CHECKF(res.budget_source && !strcmp(res.budget_source, "tolerance"), "source %s",
           res.budget_source ? res.budget_source : "(none)");
    CHECK_EQ(res.chain_level, -1);
    CHECK(res.chosen.tolerance > 0 && res.chosen.fits == 1 && !res.chosen.simplified);
    CHECK(res.mesh.triangle_count <= req.budget && res.mesh.triangle_count < exact.triangle_count);
    CHECK(res.distance_measured);
    /* The reported distances against brute force, both ways. */
    size_t far;
    double from_exact = brute_max(&exact, 0, &res.mesh, INFINITY, &far);
    double to_exact = brute_max(&res.mesh, 1, &exact, INFINITY, &far);
    CHECKF(from_exact <= res.distance.max + 1e-5 && to_exact <= res.distance.max + 1e-5,
           "brute force %g and %g, reported max %g", from_exact, to_exact, res.distance.max);
    CHECKF(res.distance.p99 <= res.distance.max && res.distance.max < 1e-3, "p99 %g, max %g",
           res.distance.p99, res.distance.max);
    /* The other: the chain's finest level within the budget, farther by its own measure
     * and by brute force. */
    const iso_mesh_chain *chain = res.chain_built;
    CHECK(chain != NULL);
    if (chain) {
        int k = iso_mesh_chain_pick_budget(chain, req.budget);
        CHECK_EQ(k, 1);
        CHECK(res.budget_other_p99 == chain->level[k].distance.p99);
        CHECKF(res.budget_other_p99 > res.distance.p99, "other %g, answer %g", res.budget_other_p99,
               res.distance.p99);
        iso_mesh level;
        iso_mesh_init(&level);
        CHECK_OK(iso_mesh_chain_mesh(chain, k, &level, &err), &err);
        double beyond = fmax(from_exact, to_exact) + 1e-5;
        brute_max(&level, 1, &exact, beyond, &far);
        CHECKF(far * 1000 > level.triangle_count, "%zu of %zu chain centroids beyond %g", far,
               level.triangle_count, beyond);
        iso_mesh_free(&level);
    }
    proto_pipeline_result_free(&res);
    iso_mesh_free(&faithful);
    iso_mesh_free(&exact);
    iso_tree_destroy(tree);
    iso_vol_destroy(vol);
}

int main(void)
{
    CHECK_RUN(test_ladder_answers_when_closer);
    return check_finish();
}
