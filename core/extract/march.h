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

/* ---- marching with coarser pieces: the tolerance path (extract.c) ----
 *
 * A caller that emits some of the surface itself, as fans over coarse boxes, keeps those
 * cells out of marching cubes and names the fans' loop vertices by their grid edges:
 * every crossing still has its one id, so fans and cells meet with no weld. */

/* One active brick after classification, as a cover function sees it. Cells and samples
 * are brick-local: sample (x, y, z) is volume sample lo + (x, y, z). */
typedef struct iso_march_brick {
    uint32_t lo[3];          /* its first sample, a multiple of ISO_BRICK_CELLS */
    uint8_t n[3];            /* samples per axis, 2..9 */
    const uint16_t *inside;  /* row z * 9 + y, bit x: sample (x, y, z) above the level */
    uint8_t mixed[8][8];     /* [z][y], bit x: cell (x, y, z) neither all inside nor outside */
    uint8_t covered[8][8];   /* [z][y], bit x: cell the cover function emits itself; zeroed */
    size_t extra_vertices, extra_triangles; /* what it emits, so the mesh is sized once */
} iso_march_brick;

/* Called once per active, unskipped brick, on thread `thread` (0..threads-1). Which
 * thread gets which brick depends on timing; each sees its own in increasing grid order.
 * Returns 0 or ISO_E_NOMEM. */
typedef int (*iso_march_cover_fn)(void *context, int thread, iso_march_brick *brick);

/* What to do with a brick a caller's fan covers whole. */
enum iso_march_skip {
    ISO_MARCH_SKIP_NONE = 0,
    ISO_MARCH_SKIP_NUMBERED = 1, /* number its crossings (neighbours and fans use them),
                                  * march none of its cells */
    ISO_MARCH_SKIP_UNREAD = 2    /* leave it out: nothing refers to its crossings */
};

typedef struct iso_march_options {
    int prune, world, threads;  /* as for iso_march_bricks */
    const uint8_t *skip;        /* per brick of the grid (iso_march_skip), or NULL */
    iso_march_cover_fn cover;   /* or NULL */
    void *cover_context;
    size_t extra_vertices, extra_triangles; /* room kept for the caller beyond the covers' */
} iso_march_options;

typedef struct iso_march iso_march;

/* Marches every active brick's uncovered cells into mesh, leaving room for the extra
 * vertices and triangles (the caller appends them, then calls iso_march_end). Returns as
 * iso_march_bricks does; on failure *out is NULL and the mesh empty. */
int iso_march_begin(const iso_volume *vol, const iso_bricks *bricks, double level,
                    const iso_march_options *options, iso_mesh *mesh, iso_march **out,
                    iso_march_stats *stats, iso_error *err);
/* The vertex id of the crossing on the grid edge from corner along axis; the edge must
 * cross the level. UINT32_MAX if it does not (a caller's bug, asserted in debug builds). */
uint32_t iso_march_vertex(const iso_march *march, const uint32_t corner[3], int axis);
/* Triangles marching cubes gives the brick's cells in the brick-local cell box
 * [lo, hi) (all three axes). */
size_t iso_march_box_triangles(const iso_march_brick *brick, const uint32_t lo[3], const uint32_t hi[3]);
/* Frees what iso_march_begin kept. NULL is allowed. */
void iso_march_end(iso_march *march);

#endif
