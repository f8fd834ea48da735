/* budget.h: extraction under a triangle budget.
 *
 * A thin client asks for "the best mesh of at most N triangles" rather than a tolerance.
 * Triangle counts fall as the tolerance grows, so the finest tolerance whose mesh fits is
 * found by bisection over a ladder: the requested tolerance, then the value range halved
 * again and again (range / 2^20 .. range). The guarantee of extract.h holds for the
 * tolerance chosen. */
#ifndef ISO_BUDGET_H
#define ISO_BUDGET_H

#include <stddef.h>

#include "extract.h"

typedef struct iso_budget_result {
    double tolerance;   /* the tolerance of the mesh returned */
    int fits;           /* 1 if the mesh has at most `budget` triangles; 0 when even the
                         * coarsest tolerance of the ladder does not get there */
    int extractions;    /* extractions run to find it */
} iso_budget_result;

/* Extracts at params->level with the smallest ladder tolerance >= params->tolerance whose
 * mesh has at most `budget` triangles (budget >= 1). Costs about log2(21) + 1 extractions
 * at worst, the coarse ones being the cheap ones. Returns what iso_extract returns. */
int iso_extract_budget(const iso_tree *tree, const iso_extract_params *params, size_t budget,
                       iso_mesh *mesh, iso_extract_stats *stats, iso_budget_result *result,
                       iso_error *err);

#endif
