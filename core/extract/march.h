/* march.h: exact marching cubes over the bricks whose min/max hold the level, indexed
 * directly (every crossing computed once, no welding), on several threads.
 *
 * The output is the mesh iso_extract_full_scan gives at the same level, up to the order
 * of vertices and triangles: the same case table (mc.h), the same crossings
 * (iso_mc_edge_t), the same positions bit for bit. Order is fixed by the brick grid, so
 * it does not depend on the thread count. */
#ifndef ISO_MARCH_H
#define ISO_MARCH_H

#include <stddef.h>

#include "hierarchy/tree.h"
#include "base/base.h"
#include "mesh/mesh.h"
#include "volume/volume.h"

typedef struct iso_march_stats {
    size_t bricks_active;  /* bricks whose cells were classified (read) */
    size_t cells_visited;  /* cells of those bricks */
    double error_bound;    /* max |f(v) - level| over the vertices (ties, see mc.h) */
} iso_march_stats;

/* Replaces mesh with the surface at level, positions in world mm if world = 1 (as
 * iso_vol_index_to_world maps the float index positions), else index space. prune = 0
 * visits every brick (the "no min/max" baseline). threads: 0 = all cores. Returns 0, ISO_E_NOMEM, or ISO_E_ARGUMENT
 * when the mesh would need more than 2^32 - 1 vertices. */
int iso_march_bricks(const iso_volume *vol, const iso_bricks *bricks, double level, int prune,
                     int world, int threads, iso_mesh *mesh, iso_march_stats *stats, iso_error *err);

#endif
