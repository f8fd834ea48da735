/* lod.h: extraction within a tolerance: each block (a brick's 2 x 2 x 2 sub-boxes of 4^3
 * cells, tree.h) marched on its own coarse grid, or a whole brick on its stride-8 grid,
 * chosen a-priori from the hierarchy's level errors, and joined crack-free to finer
 * neighbours by transition cells (docs/watertight.md, docs/algorithm.md).
 *
 * PASS 1 (plan): a brick whose [min, max] holds the level takes stride 8 whole if its
 *   level 3 error is within the tolerance; else each of its blocks takes the coarsest of
 *   strides 4 and 2 whose stored error is within it, or stride 1. The other bricks take
 *   stride 8, which touches nothing (their samples all lie on one side of the level). No
 *   sample is read.
 * PASS 2 (fine): the stride-1 blocks, marched by the exact kernel (march.h,
 *   iso_march_selected, given per brick the mask of its stride-1 blocks; a brick whose
 *   coarse blocks are all provably clear of the level is given whole, as it then holds
 *   the same surface at stride 1) on the request's threads; it also numbers the crossings
 *   of the edges such a block shares with a brick that owns them (the brick's own coarse
 *   blocks, or a ghost).
 * PASS 3 (coarse; coarse.c, the others lod.c, whose extract() runs them in this order):
 *   the bricks with a coarse block in grid order, each classified once, then unit after
 *   unit (the brick at stride 8, or its coarse blocks at their strides; a unit whose
 *   samples all lie on one side is skipped), cell after cell of the unit's grid. Every
 *   lattice set (a face, edge or line of a block's closed box, or the open part of one
 *   inside a block) has a stride of its own, the finest of the blocks that hold it (with a
 *   cap, the volume's border counts as stride 1). A cell whose faces, and the edges and
 *   lines in them, all have its stride is a regular cell: marching cubes (mc.h) on its 8
 *   corners. Any other cell is a transition cell: each face is cut into regions, one per
 *   block face it spans, each region into squares of its own stride, each square's sides
 *   split at the strides of the sets they run along; each such polygon gets mc.h's face
 *   rule (a run of inside corners is cut off by a segment from the side where it is left to
 *   the side where it was entered); the segments chain into closed loops on the cell's
 *   boundary, each fanned around a centre placed on f = level (a loop of three is one
 *   triangle). A crossing is named by its lattice segment (low end, axis, length), so a
 *   vertex shared by cells is made once; on a data edge the kernel's vertex is used where
 *   PASS 2 made one.
 *
 * The value bound: a crossing on a lattice segment of stride 2^l lies on a grid edge of a
 * block (or, at stride 8, a brick) at level l, where |f - T_l| <= err_l <= tolerance
 * (Lemma 1), T_l linear along the edge; centres are placed by false position on f itself.
 * The error reported is the largest |f(v) - level| measured over the vertices. */
#ifndef ISO_LOD_H
#define ISO_LOD_H

#include <stdint.h>

#include "extract.h"

/* Replaces mesh with the surface at params->level within params->tolerance (> 0), in index
 * space, fills stats' counts and error_bound (not triangles, vertices or time). With
 * params->cap the border is joined at stride 1, so the cap (extract.c) seals it. If PASS 1
 * leaves no block the level crosses coarse (a coarse block counts as uncrossed when its
 * stride grid's samples lie farther than its fit error from the level, on one side), sets
 * *exact and touches nothing else: the exact path is then the same surface without this
 * path's index-space detour. Returns 0,
 * ISO_E_NOMEM, ISO_E_LIMIT (more than 2^32 - 1 vertices) or ISO_E_INTERNAL (a loop that
 * does not close: a bug); the mesh is then empty. */
int iso_lod_extract(const iso_tree *tree, const iso_extract_params *params, int *exact, iso_mesh *mesh,
                    iso_extract_stats *stats, iso_error *err);

/* The same with the plan given: shift[b] = log2 of block b's stride (0..ISO_TREE_LEVELS;
 * blocks of ISO_TREE_BLOCK cells, ceil((dims - 1) / 4) per axis, x fastest), whatever the
 * tolerance and the fit errors say; stride 8 counts only where every block of the brick
 * has it (stride 4 otherwise). For tests of the construction: any plan must give a
 * watertight mesh; only PASS 1's choice makes the value bound hold. */
int iso_lod_extract_planned(const iso_tree *tree, const iso_extract_params *params, const uint8_t *shift,
                            iso_mesh *mesh, iso_extract_stats *stats, iso_error *err);

/* PASS 1's plan for the level and tolerance (> 0), into shift as iso_lod_extract_planned
 * takes it: for tests, which give it back to compare the two answers. Returns 0 or
 * ISO_E_NOMEM. */
int iso_lod_plan(const iso_tree *tree, double level, double tolerance, uint8_t *shift);

#endif
