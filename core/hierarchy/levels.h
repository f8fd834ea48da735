/* levels.h: each brick's fit error at its coarse levels (tree.h), computed in the build. */
#ifndef ISO_LEVELS_H
#define ISO_LEVELS_H

#include "tree.h"
#include "base/base.h"
#include "volume/volume.h"

/* Per brick of bricks (x fastest), ISO_TREE_LEVELS fit errors (iso_tree_level_error),
 * rounded up as stored (iso_tree_level_encode). O(N) per level on `threads` threads
 * (0 = all cores); *out is malloc'd. Returns 0 or ISO_E_NOMEM. */
int iso_levels_build(const iso_volume *vol, const iso_bricks *bricks, int threads, uint16_t **out,
                     iso_error *err);

#endif
