/* budget.c: the finest tolerance that fits a triangle budget, and past a faithful
 * tolerance, simplification (see extract.h). */
#include "extract.h"

#include <assert.h>
#include <math.h>

#define LADDER_STEPS 20

/* One rung. stats describe the mesh the rung leaves, but its nodes and cells visited add
 * up over every rung the search ran: they are the request's work, not only the answer's. */
static int run(const iso_tree *tree, const iso_extract_params *base, double tolerance,
               iso_mesh *mesh, iso_extract_stats *stats, iso_budget_result *result,
               iso_error *err)
{
    iso_extract_params p = *base;
    p.tolerance = tolerance;
    p.coarsen = ISO_COARSEN_ALL; /* a budget wants the fewest triangles, not the fastest rung */
    size_t nodes = result->extractions ? stats->nodes_visited : 0;
    size_t cells = result->extractions ? stats->cells_visited : 0;
    result->extractions++;
    int rc = iso_extract(tree, &p, mesh, stats, err);
    stats->nodes_visited += nodes;
    stats->cells_visited += cells;
    return rc;
}

/* The ladder from params->tolerance up to `top`: bisection for the finest rung that fits
 * (mesh.h). */
static int climb(const iso_tree *tree, const iso_extract_params *params, size_t budget,
                 double top, iso_mesh *mesh, iso_extract_stats *stats,
                 iso_budget_result *result, iso_error *err)
{
    assert(tree && params && mesh && stats && result && budget >= 1);
    *result = (iso_budget_result){.tolerance = params->tolerance};
    int rc = run(tree, params, params->tolerance, mesh, stats, result, err);
    if (rc || stats->triangles <= budget) {
        result->fits = !rc;
        return rc;
    }
    /* Ladder above the requested tolerance, ascending, up to top. */
    double range = tree->vol->value_max - tree->vol->value_min;
    double ladder[LADDER_STEPS + 1];
    int steps = 0;
    for (int k = LADDER_STEPS; k >= 0 && range > 0; k--) {
        double t = ldexp(range, -k);
        if (t > params->tolerance && t <= top)
            ladder[steps++] = t;
    }
    /* PASS 1: bisect for the first rung that fits; the mesh of the last rung tried may not
     * be the answer, so the answer is extracted again unless it was the last one run. */
    int lo = 0, hi = steps, last_run = -1;
    while (lo < hi) {
        int mid = lo + (hi - lo) / 2;
        if ((rc = run(tree, params, ladder[mid], mesh, stats, result, err)))
            return rc;
        last_run = mid;
        if (stats->triangles <= budget)
            hi = mid;
        else
            lo = mid + 1;
    }
    /* PASS 2: lo is the first rung that fits, or steps when none does (the coarsest rung
     * then stands as the best effort). */
    result->fits = lo < steps;
    int answer = result->fits ? lo : steps - 1;
    if (answer < 0) /* no rung between the requested tolerance and top: its mesh stands */
        return 0;
    result->tolerance = ladder[answer];
    if (answer != last_run)
        rc = run(tree, params, ladder[answer], mesh, stats, result, err);
    return rc;
}

int iso_extract_budget(const iso_tree *tree, const iso_extract_params *params, size_t budget,
                       iso_mesh *mesh, iso_extract_stats *stats, iso_budget_result *result,
                       iso_error *err)
{
    return climb(tree, params, budget, INFINITY, mesh, stats, result, err);
}

double iso_preview_tolerance(const iso_volume *vol)
{
    return ldexp(vol->value_max - vol->value_min, -ISO_PREVIEW_SHIFT);
}

double iso_budget_faithful_tolerance(const iso_volume *vol, double requested)
{
    double faithful = ldexp(vol->value_max - vol->value_min, -ISO_BUDGET_FAITHFUL_SHIFT);
    return faithful > requested ? faithful : requested;
}

int iso_extract_budget_faithful(const iso_tree *tree, const iso_extract_params *params,
                                size_t budget, iso_mesh *mesh, iso_extract_stats *stats,
                                iso_budget_result *result, iso_error *err)
{
    double top = iso_budget_faithful_tolerance(tree->vol, params->tolerance);
    int rc = climb(tree, params, budget, top, mesh, stats, result, err);
    if (rc || result->fits)
        return rc;
    /* The requested tolerance's mesh is the best input: the finest the user accepts, and
     * at tolerance 0 the fastest path too. The ladder left a coarser one in mesh. */
    if (result->tolerance != params->tolerance) {
        result->tolerance = params->tolerance;
        if ((rc = run(tree, params, params->tolerance, mesh, stats, result, err)))
            return rc;
    }
    iso_simplify_params sp = {.target_triangles = budget, .target_error = INFINITY,
                              .voxel_size = params->space == ISO_SPACE_INDEX ? 1 : iso_vol_min_spacing(tree->vol),
                              .lock_border = 1};
    if ((rc = iso_simplify(mesh, &sp, &result->simplify, err)))
        return rc;
    result->simplified = 1;
    result->fits = mesh->triangle_count <= budget;
    stats->triangles = mesh->triangle_count;
    stats->vertices = mesh->vertex_count;
    return 0;
}
