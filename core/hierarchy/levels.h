/* levels.h: each brick's and block's fit error at its coarse levels (tree.h), computed in
 * the build. */
#ifndef ISO_LEVELS_H
#define ISO_LEVELS_H

#include "tree.h"
#include "base/base.h"
#include "volume/volume.h"

/* Per brick of bricks (x fastest), ISO_TREE_CODES codes of scale (iso_tree_level_error,
 * iso_tree_block_error), each rounded up. O(N) per level on `threads` threads (0 = all
 * cores); *out is malloc'd. Returns 0 or ISO_E_NOMEM. */
int iso_levels_build(const iso_volume *vol, const iso_bricks *bricks, const iso_tree_scale *scale, int threads,
                     uint8_t **out, iso_error *err);

#endif
