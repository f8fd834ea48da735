/* lod_march.h: the tolerance path's brick kernel (lod.h): marching cubes over blocks on
 * their own strides, joined by transition cells (transition.h), every crossing computed
 * once and numbered by the brick that owns it, on several threads. Internal to the
 * extract stage.
 *
 * Input is a plan, a log2 stride per block (lod.h), that lod.c made valid for the
 * volume's shape; the kernel balances it (PASS 3 in lod_march.c) so that every lattice set
 * the level crosses is held by blocks at most one stride apart, asking the caller for the
 * new stride of every block it refines. */
#ifndef ISO_LOD_MARCH_H
#define ISO_LOD_MARCH_H

#include <stddef.h>
#include <stdint.h>

#include "base/base.h"
#include "hierarchy/tree.h"
#include "mesh/mesh.h"

/* The stride (log2) block `block` (index in the block grid) takes when it must be at most
 * `most`: a valid stride <= most (0 always is). */
typedef int (*iso_lod_refine_fn)(void *context, size_t block, int most);

typedef struct iso_lod_march_params {
    const iso_tree *tree;
    double level;
    int visit_all;       /* classify every brick, not only those whose [min, max] hold the level */
    int threads;         /* 0: all cores; the mesh does not depend on it */
    uint8_t *shift;      /* per block, ceil((dims - 1) / 4) per axis, x fastest; refined in place */
    iso_lod_refine_fn refine;
    void *refine_context;
} iso_lod_march_params;

typedef struct iso_lod_march_stats {
    size_t bricks;            /* bricks classified (their [min, max] holds the level) */
    size_t cells;             /* cells classified, each unit's at its own stride */
    size_t coarse_bricks;     /* bricks with a unit marched coarse */
    size_t coarse_blocks;     /* blocks (a stride-8 brick counts its 8) marched coarse */
    size_t blocks;            /* blocks of the classified bricks */
    size_t refined;           /* blocks the balance (and infeasible transition cells) refined */
    size_t transition_cells;  /* cells marched by transition.h's cases */
    double error_bound;       /* max |f(v) - level| over the vertices */
} iso_lod_march_stats;

/* Replaces mesh with the surface of the plan in index space. Returns 0, ISO_E_NOMEM or
 * ISO_E_LIMIT (more than 2^32 - 1 vertices); the mesh is then empty. */
int iso_lod_march(const iso_lod_march_params *params, iso_mesh *mesh, iso_lod_march_stats *stats, iso_error *err);

#endif
