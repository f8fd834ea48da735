/* budget.c: the finest tolerance that fits a triangle budget (see budget.h). */
#include "budget.h"

#include <assert.h>
#include <math.h>

#define LADDER_STEPS 20

static int run(const iso_tree *tree, const iso_extract_params *base, double tolerance,
               iso_mesh *mesh, iso_extract_stats *stats, iso_budget_result *result,
               iso_error *err)
{
    iso_extract_params p = *base;
    p.tolerance = tolerance;
    result->extractions++;
    return iso_extract(tree, &p, mesh, stats, err);
}

int iso_extract_budget(const iso_tree *tree, const iso_extract_params *params, size_t budget,
                       iso_mesh *mesh, iso_extract_stats *stats, iso_budget_result *result,
                       iso_error *err)
{
    assert(tree && params && mesh && stats && result && budget >= 1);
    *result = (iso_budget_result){.tolerance = params->tolerance};
    int rc = run(tree, params, params->tolerance, mesh, stats, result, err);
    if (rc || stats->triangles <= budget) {
        result->fits = !rc;
        return rc;
    }
    /* Ladder above the requested tolerance, ascending. */
    double range = tree->vol->value_max - tree->vol->value_min;
    double ladder[LADDER_STEPS + 1];
    int steps = 0;
    for (int k = LADDER_STEPS; k >= 0 && range > 0; k--) {
        double t = ldexp(range, -k);
        if (t > params->tolerance)
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
    if (answer < 0) /* constant volume: nothing above the requested tolerance */
        return 0;
    result->tolerance = ladder[answer];
    if (answer != last_run)
        rc = run(tree, params, ladder[answer], mesh, stats, result, err);
    return rc;
}
