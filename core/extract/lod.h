/* lod.h: extraction within a tolerance: each brick marched on its own coarse grid, chosen
 * a-priori from the hierarchy's level errors, and joined crack-free to finer neighbours by
 * transition cells (docs/watertight.md, docs/algorithm.md).
 *
 * PASS 1 (plan): every brick whose [min, max] holds the level gets the coarsest level l
 *   (stride 2^l, tree.h) whose stored fit error is within the tolerance, or stride 1; the
 *   others get the coarsest stride, which touches nothing (their samples all lie on one
 *   side of the level). No sample is read.
 * PASS 2 (fine): the stride-1 bricks, marched by the exact kernel (march.h,
 *   iso_march_selected) on the request's threads; its ghosts give the crossings of the
 *   edges a stride-1 brick shares with a coarse brick that owns them.
 * PASS 3 (coarse): brick after brick in grid order, cell after cell of its stride grid.
 *   Every lattice face and edge has a stride of its own, the finest of the bricks that
 *   hold it (with a cap, the volume's border counts as stride 1). A cell whose faces and
 *   edges all have its stride is a regular cell: marching cubes (mc.h) on its 8 corners.
 *   Any other cell is a transition cell: each face is cut into squares of the face's
 *   stride, each square's sides split at their own strides, and each such polygon gets
 *   mc.h's face rule (a run of inside corners is cut off by a segment from the side
 *   where it is left to the side where it was entered); the segments chain into closed
 *   loops on the cell's boundary, each fanned around a centre placed on f = level
 *   (a loop of three is one triangle). A crossing is named by its lattice segment (low
 *   end, axis, length), so a vertex shared by cells is made once; on a data edge the
 *   kernel's vertex is used where PASS 2 made one.
 *
 * The value bound: a crossing on a lattice segment of stride 2^l lies on a grid edge of a
 * brick at level l, where |f - T_l| <= err_l <= tolerance (Lemma 1), T_l linear along the
 * edge; centres are placed by false position on f itself. The error reported is the largest
 * |f(v) - level| measured over the vertices. */
#ifndef ISO_LOD_H
#define ISO_LOD_H

#include <stdint.h>

#include "extract.h"

/* Replaces mesh with the surface at params->level within params->tolerance (> 0), in index
 * space, fills stats' counts and error_bound (not triangles, vertices or time). With
 * params->cap the border is joined at stride 1, so the cap (extract.c) seals it. If PASS 1
 * leaves no brick the level crosses coarse, sets *exact and touches nothing else: the
 * exact path is then the same surface without this path's index-space detour. Returns 0,
 * ISO_E_NOMEM, ISO_E_LIMIT (more than 2^32 - 1 vertices) or ISO_E_INTERNAL (a loop that
 * does not close: a bug); the mesh is then empty. */
int iso_lod_extract(const iso_tree *tree, const iso_extract_params *params, int *exact, iso_mesh *mesh,
                    iso_extract_stats *stats, iso_error *err);

/* The same with the plan given: shift[b] = log2 of brick b's stride (0..ISO_TREE_LEVELS),
 * whatever the tolerance and the fit errors say. For tests of the construction: any plan
 * must give a watertight mesh; only PASS 1's choice makes the value bound hold. */
int iso_lod_extract_planned(const iso_tree *tree, const iso_extract_params *params, const uint8_t *shift,
                            iso_mesh *mesh, iso_extract_stats *stats, iso_error *err);

#endif
