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
#include <stdint.h>

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

/* The surface of one label's indicator (1 where the sample equals label, else 0) at 0.5,
 * marching cubes' surface of that 0/1 volume: every crossing at its edge's midpoint
 * (error_bound 0), the same case table, winding (normals out of the label) and
 * numbering as above. Only the listed bricks (grid indices, ascending, count > 0 or not)
 * are visited: they must include every brick whose samples hold label and another value
 * (hierarchy/labels.h lists them); others listed add nothing. An integer volume's label;
 * float volumes give an empty mesh. */
int iso_march_label(const iso_volume *vol, const iso_bricks *bricks, int64_t label, const uint32_t *listed,
                    size_t count, int world, int threads, iso_mesh *mesh, iso_march_stats *stats, iso_error *err);

/* The surface of the blocks marked in index space, for the tolerance path (lod.h):
 * marked[b] per brick of the grid (x fastest), bit x | y << 1 | z << 2 for its block of
 * ISO_TREE_BLOCK cells per axis at (x, y, z) (0xFF: the whole brick); marching cubes as
 * above on those blocks' cells, none other. A brick that owns an edge a marked block
 * holds (it holds the edge's low corner) gives that edge's vertex even where it marches
 * no cell there, so that every crossing on a marked block's closed box is in the mesh, and
 * no other. *part keeps the numbering for iso_march_part_vertex until iso_march_part_free
 * (NULL after an error). */
typedef struct march_job iso_march_part;
int iso_march_selected(const iso_volume *vol, const iso_bricks *bricks, double level, const uint8_t *marked,
                       int threads, iso_mesh *mesh, iso_march_stats *stats, iso_march_part **part,
                       iso_error *err);

/* 1 and *id the vertex of the crossing on the data edge from sample p along axis, if the
 * mesh of iso_march_selected has one; else 0. */
int iso_march_part_vertex(const iso_march_part *part, const uint32_t p[3], int axis, uint32_t *id);
void iso_march_part_free(iso_march_part *part);

/* A level as the kernel compares a volume's samples against it (integers against the
 * level's floor, 8 and 16 bits a row at a time): made once, read by any thread. */
enum { ISO_MARCH_SOME_ABOVE, ISO_MARCH_ALL_ABOVE, ISO_MARCH_NONE_ABOVE };
typedef struct iso_march_threshold {
    double level;               /* floating types: above when sample > level; NaN never is */
    int64_t floor;              /* integer types: above when sample > floor */
    int reach;                  /* ISO_MARCH_*: a level outside the type's values */
    uint64_t bias[2], lanes[2]; /* SSE2 lanes for 8- and 16-bit types (added to samples to
                                 * compare as signed; floor + bias), laid out the same in any build */
} iso_march_threshold;
void iso_march_threshold_make(const iso_volume *vol, double level, iso_march_threshold *th);

/* Bit x of rows[z * 9 + y]: sample lo + (x, y, z) is above level, for the n[] samples of
 * a brick's box (rows past n[1], n[2] untouched), as the kernel classifies them. The
 * _every form fills only the rows whose y and z are multiples of step (all 9 bits). */
void iso_march_inside_rows_every(const iso_volume *vol, const iso_march_threshold *th, const size_t lo[3],
                                 const uint8_t n[3], int step, uint16_t rows[ISO_BRICK_SAMPLES * ISO_BRICK_SAMPLES]);
/* The same for the rows r (= z * 9 + y) whose bit is set in wanted[r / 64]. */
void iso_march_inside_rows_listed(const iso_volume *vol, const iso_march_threshold *th, const size_t lo[3],
                                  const uint8_t n[3], const uint64_t wanted[2],
                                  uint16_t rows[ISO_BRICK_SAMPLES * ISO_BRICK_SAMPLES]);
void iso_march_inside_rows(const iso_volume *vol, double level, const size_t lo[3], const uint8_t n[3],
                           uint16_t rows[ISO_BRICK_SAMPLES * ISO_BRICK_SAMPLES]);

#endif
