/* budget.h: extraction under a triangle budget.
 *
 * A thin client asks for "the best mesh of at most N triangles" rather than a tolerance.
 * Triangle counts fall as the tolerance grows, so the finest tolerance whose mesh fits is
 * found by bisection over a ladder: the requested tolerance, then the value range halved
 * again and again (range / 2^20 .. range). The guarantee of extract.h holds for the
 * tolerance chosen.
 *
 * The ladder has a limit on CT: a node's fit error stays above any useful tolerance until
 * the node is one cell wide, so even at tolerance = the whole value range CThead's skin
 * keeps 38% of its triangles, and a faithful tolerance keeps 91-100%
 * (docs/performance.md). So iso_extract_budget_faithful, the policy the server uses,
 * climbs the ladder only as far as a faithful tolerance and, when that does not fit,
 * simplifies the mesh of the requested tolerance with meshoptimizer instead (simplify.h).
 * The comparison that chose it is tests/bench/bench_simplify.py: at the same triangle
 * count the simplified mesh is closer to the exact surface than the ladder's coarse one. */
#ifndef ISO_BUDGET_H
#define ISO_BUDGET_H

#include <stddef.h>

#include "extract.h"
#include "simplify.h"

/* The faithful top of the ladder: value range / 2^5 (3.1% of the range). bench_peer.py
 * measured every tolerance up to 5% of the range within 0.5 voxel of the exact surface at
 * the 99th percentile on all 8 of its cases. */
#define ISO_BUDGET_FAITHFUL_SHIFT 5

typedef struct iso_budget_result {
    double tolerance;   /* the tolerance of the mesh extracted */
    int fits;           /* 1 if the mesh has at most `budget` triangles; 0 when even the
                         * coarsest tolerance of the ladder (or the simplifier) does not
                         * get there */
    int extractions;    /* extractions run to find it */
    int simplified;     /* 1: the mesh was simplified, `simplify` says how */
    iso_simplify_result simplify;
} iso_budget_result;

/* Extracts at params->level with the smallest ladder tolerance >= params->tolerance whose
 * mesh has at most `budget` triangles (budget >= 1). Costs about log2(21) + 1 extractions
 * at worst, the coarse ones being the cheap ones. Returns what iso_extract returns. */
int iso_extract_budget(const iso_tree *tree, const iso_extract_params *params, size_t budget,
                       iso_mesh *mesh, iso_extract_stats *stats, iso_budget_result *result,
                       iso_error *err);

/* The faithful tolerance of a volume: max(requested, value range / 2^ISO_BUDGET_FAITHFUL_SHIFT). */
double iso_budget_faithful_tolerance(const iso_volume *vol, double requested);

/* The server's policy. Like iso_extract_budget, but the ladder stops at
 * iso_budget_faithful_tolerance; when no rung up to it fits, the mesh of the requested
 * tolerance is simplified to `budget` triangles (no error limit, open edges locked) and
 * result->simplified is set. stats then describe the extraction at the requested
 * tolerance except triangles and vertices, which are the simplified mesh's; every vertex
 * kept is one of the extraction's, so stats->error_bound still holds for each. The
 * simplifier's error is reported in result->simplify in the mesh's units (world mm or
 * index space, params->space) and in voxels (mm over the volume's smallest spacing).
 * Returns what iso_extract or iso_simplify return. */
int iso_extract_budget_faithful(const iso_tree *tree, const iso_extract_params *params,
                                size_t budget, iso_mesh *mesh, iso_extract_stats *stats,
                                iso_budget_result *result, iso_error *err);

#endif
