/* lod.h: extraction within a tolerance: each block (a brick's 2 x 2 x 2 sub-boxes of 4^3
 * cells, tree.h) marched on its own coarse grid, or a whole brick on its stride-8 grid,
 * chosen a-priori from the hierarchy's level errors, and joined crack-free to finer
 * neighbours by transition cells (docs/watertight.md, docs/algorithm.md).
 *
 * PASS 1 (plan, lod.c): a brick whose [min, max] holds the level takes stride 8 whole if
 *   its level 3 error is within the tolerance; else each of its blocks takes the coarsest
 *   of strides 4 and 2 whose stored error is within it, or stride 1. The other bricks take
 *   stride 8, which touches nothing (their samples all lie on one side of the level). A
 *   stride must divide the block's cells where the volume's border clips it; with a cap
 *   the border's blocks take stride 1. No sample is read. Unless params->coarsen asks for
 *   every coarse unit, a plan with fewer than ISO_LOD_PAYS of its crossed blocks in
 *   stride-8 bricks is answered by the exact path (extract.c): the exact kernel is faster
 *   there (docs/performance.md), and its surface satisfies every tolerance.
 * Then lod_march.c's kernel (lod_march.h): the bricks classified, the plan balanced so
 *   that a crossed face or edge is shared by blocks at most one stride apart (a block it
 *   refines takes the coarsest stride its error allows below the limit, or 1), and every
 *   block marched at its stride: marching cubes where a cell's boundary has its stride,
 *   transition.h's cases where finer blocks put samples on it. Every vertex lies on a
 *   lattice edge: the crossing of a segment of stride 2^l, whose set has that stride, lies
 *   on a grid edge of a block (or, at stride 8, a brick) at level l, where
 *   |f - T_l| <= err_l <= tolerance (Lemma 1), T_l linear along the edge. The error
 *   reported is the largest |f(v) - level| measured over the vertices. */
#ifndef ISO_LOD_H
#define ISO_LOD_H

#include <stdint.h>

#include "extract.h"

/* The share of the crossed blocks that must lie in stride-8 bricks for the coarse kernel
 * to run (iso_coarsen). Measured with callgrind on the bench cases and the bunny
 * (docs/performance.md, "Tolerance ladder"): the coarse kernel takes 0.3-0.79x the exact
 * kernel's instructions where 74% or more do, and 1.4-3.9x where 53% or fewer do. */
#define ISO_LOD_PAYS 0.7

/* Replaces mesh with the surface at params->level within params->tolerance (> 0), in index
 * space, fills stats' counts and error_bound (not triangles, vertices or time). With
 * params->cap the border is joined at stride 1, so the cap (extract.c) seals it. If PASS 1
 * leaves no block of a brick the level crosses coarse, or (params->coarsen) coarse units
 * would not pay, sets *exact and touches nothing else: the exact path answers. Returns 0, ISO_E_NOMEM or ISO_E_LIMIT
 * (more than 2^32 - 1 vertices); the mesh is then empty. */
int iso_lod_extract(const iso_tree *tree, const iso_extract_params *params, int *exact, iso_mesh *mesh,
                    iso_extract_stats *stats, iso_error *err);

/* The same with the plan given: shift[b] = log2 of block b's stride (0..ISO_TREE_LEVELS;
 * blocks of ISO_TREE_BLOCK cells, ceil((dims - 1) / 4) per axis, x fastest), whatever the
 * tolerance and the fit errors say; stride 8 counts only where every block of the brick
 * has it (stride 4 otherwise), each stride made valid for its block's shape, then balanced
 * as above (a refined block takes the coarsest valid stride below the limit). For tests of
 * the construction: any plan must give a watertight mesh; only PASS 1's choice makes the
 * value bound hold. balanced, unless NULL, receives the plan as marched (as many bytes as
 * shift). */
int iso_lod_extract_planned(const iso_tree *tree, const iso_extract_params *params, const uint8_t *shift,
                            uint8_t *balanced, iso_mesh *mesh, iso_extract_stats *stats, iso_error *err);

/* PASS 1's plan for the level and tolerance (> 0), into shift as iso_lod_extract_planned
 * takes it: for tests, which give it back to compare the two answers. Returns 0 or
 * ISO_E_NOMEM. */
int iso_lod_plan(const iso_tree *tree, double level, double tolerance, uint8_t *shift);

#endif
