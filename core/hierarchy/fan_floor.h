/* fan_floor.h: below each brick, the smallest fit error of any box extraction could keep
 * whole there; an a-priori bound that lets a tolerance skip a brick's on-the-fly walk.
 *
 * Below a brick, extraction splits boxes by the tree's rule on the fly and tries to fan
 * those of at least ISO_TREE_FAN_MIN_CELLS cells whose fit error is within the tolerance's
 * (extract.c). The walk reads the brick's samples and scans box after box: at a small
 * tolerance nearly every box fails, and the walk costs as much as marching the brick
 * (docs/performance.md has the counts). Like the
 * fit errors of the stored nodes, the smallest fit error among those boxes depends only on
 * the data, so it is computed once per brick: a brick whose floor exceeds the fit limit has
 * nothing to fan and is marched without its walk. */
#ifndef ISO_FAN_FLOOR_H
#define ISO_FAN_FLOOR_H

#include "tree.h"
#include "base/base.h"
#include "volume/volume.h"

/* Per brick of bricks (x fastest), the least fit error of the boxes below it, the brick's
 * two halves and their splits down to ISO_TREE_FAN_MIN_CELLS cells, rounded down to a float
 * (INFINITY where there is none, or the brick is constant and so never crossed). O(N) on
 * `threads` threads (0 = all cores); *out is malloc'd. Returns 0 or ISO_E_NOMEM. */
int iso_fan_floor_build(const iso_volume *vol, const iso_bricks *bricks, int threads, float **out,
                        iso_error *err);

#endif
