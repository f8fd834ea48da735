/* extract.h: iso-surface extraction from the hierarchy, with a proven error bound.
 *
 * The guarantee: every output vertex v on the level satisfies |f(v) - level| <= error_bound
 * (plus float rounding), f the trilinear interpolant of the full-resolution samples, and
 * error_bound <= tolerance unless a sample sits exactly on the level, where crossings are
 * moved ISO_MC_END_GAP of an edge off it (mc.h). Tolerance 0 gives marching cubes'
 * surface of the full-resolution data. At every tolerance the mesh is indexed (no
 * position twice) and watertight: open edges only on the volume's border (none with cap),
 * two triangles per other edge in opposite directions, no zero-area triangle (mesh/mesh.h).
 *
 * Samples equal to the level count as below it (inside = value > level); NaN samples
 * count as below every level.
 *
 * Ownership: the caller owns the mesh it passes (emptied, then filled); the tree and its
 * volume are only read. Errors: ISO_E_ARGUMENT (a NaN level, a negative tolerance),
 * ISO_E_LIMIT (more than 2^32 - 1 vertices), ISO_E_NOMEM (the mesh is then empty).
 * Thread-safety: any number of extractions may share one tree, each with its own mesh.
 * Cost: at tolerance 0, the bricks whose [min, max] holds the level plus the output; above
 * it, the same bricks' cells at each block's own coarse level (lod.h) plus the output;
 * under a budget, a few extractions. */
#ifndef ISO_EXTRACT_H
#define ISO_EXTRACT_H

#include <stddef.h>
#include <stdint.h>

#include "base/base.h"
#include "mesh/mesh.h"
#include "hierarchy/tree.h"

/* What a tolerance buys. The exact surface satisfies every tolerance, so extraction may
 * answer with it wherever coarse units would cost more time than they save. */
typedef enum iso_coarsen {
    ISO_COARSEN_WHERE_FASTER = 0, /* coarse units only where the plan says they beat the
                                   * exact kernel (lod.h); else the exact surface */
    ISO_COARSEN_ALL = 1           /* every coarse unit the tolerance allows: the fewest
                                   * triangles, whatever the time (budgets, Table 1) */
} iso_coarsen;

typedef struct iso_extract_params {
    double level;
    double tolerance;  /* >= 0, in the volume's value units */
    int no_minmax;     /* 1: do not prune by min/max (the paper's middle time column) */
    int cap;           /* 1: close the surface at the volume's border, as if the volume were
                        * surrounded by values below the level (a closed, printable mesh) */
    iso_space space;   /* output positions in world mm (default) or index space */
    int threads;       /* threads for the brick kernel and the walk below bricks
                        * (march.h); 0 = all cores. The mesh does not depend on it. */
    iso_coarsen coarsen;/* above tolerance 0; the default answers fastest */
} iso_extract_params;

typedef struct iso_extract_stats {
    size_t triangles, vertices;
    size_t nodes_visited;   /* the root, plus the bricks classified */
    size_t cells_visited;   /* cells classified (the paper's column): at tolerance 0 the
                             * data cells of the bricks the kernel reads (8 at a time, whole
                             * bricks); above it, each block's cells at its own level
                             * (a stride-8 brick's one cell) */
    size_t nodes_polygonized;/* bricks with a block (or the whole) on a coarse level */
    double extract_ms;
    double error_bound;     /* max |f(v) - level| over the vertices on the level (all but
                             * a cap's): measured at every vertex above tolerance 0; at 0,
                             * crossings moved off a tie by ISO_MC_END_GAP, 0 otherwise */
    double fit_error;       /* max level error (tree.h) of the units marched coarse: how
                             * far the data strays from the grids the surface came from */
    double coarse_share;    /* of the blocks the level may cross, the share marched at a
                             * stride above 1 (0: the exact surface answered) */
} iso_extract_stats;

/* Extracts the iso-surface at params->level within params->tolerance into mesh (which is
 * emptied first), welded. stats may be NULL. Returns 0, ISO_E_ARGUMENT for a bad
 * parameter (NaN, negative tolerance), or ISO_E_NOMEM. */
int iso_extract(const iso_tree *tree, const iso_extract_params *params, iso_mesh *mesh,
                iso_extract_stats *stats, iso_error *err);

/* The surface of one label of a label volume (vol->labels; hierarchy/labels.h): marching
 * cubes' surface of its indicator (1 where a sample equals label) at 0.5, vertices at edge
 * midpoints, over the bricks the label sets say hold the label and another (label.c);
 * with cap closed half a voxel past the border (the indicator 0 beyond it); in `space`.
 * stats: cells and bricks visited, triangles, time (error_bound 0). Returns 0,
 * ISO_E_ARGUMENT (the tree has no label sets), ISO_E_LIMIT or ISO_E_NOMEM (mesh empty). */
int iso_extract_label(const iso_tree *tree, int64_t label, int cap, iso_space space, int threads, iso_mesh *mesh,
                      iso_extract_stats *stats, iso_error *err);

/* Marching cubes' surface of any volume at level, through its brick min/max grid (made
 * here: one pass over the samples) and the exact kernel, without a hierarchy: for volumes
 * made on the fly (a segment's smoothed field). The same surface as iso_extract at
 * tolerance 0. stats: bricks and cells visited, triangles, time, error bound. Returns 0,
 * ISO_E_LIMIT or ISO_E_NOMEM. */
int iso_extract_exact(const iso_volume *vol, double level, iso_space space, int threads, iso_mesh *mesh,
                      iso_extract_stats *stats, iso_error *err);

/* Moves mesh's index-space positions to world millimetres, bit for bit as the exact
 * kernel places its own (an identity direction: origin + index * spacing), and keeps the
 * winding (iso_extract_world_winding). O(V + T). */
void iso_extract_to_world(const iso_volume *vol, iso_mesh *mesh);

/* For a mesh already in world space: where the index-to-world map is mirrored (a negative
 * determinant, as LPI), swaps two corners of every triangle, so that the winding keeps
 * mesh.h's meaning in world space. O(T); nothing where the map is not mirrored. */
void iso_extract_world_winding(const iso_volume *vol, iso_mesh *mesh);

/* The baseline: marching cubes over every cell, no hierarchy. Same table, welding and
 * output space as iso_extract at tolerance 0. */
int iso_extract_full_scan(const iso_volume *vol, double level, iso_space space,
                          iso_mesh *mesh, iso_extract_stats *stats, iso_error *err);

/* Extraction under a triangle budget.
 *
 * A thin client asks for "the best mesh of at most N triangles" rather than a tolerance.
 * Triangle counts fall as the tolerance grows, so the finest tolerance whose mesh fits is
 * found by bisection over a ladder: the requested tolerance, then the value range halved
 * again and again (range / 2^20 .. range). The guarantee of extract.h holds for the
 * tolerance chosen.
 *
 * The ladder has a limit on CT: a block's coarse levels fit only once the tolerance passes
 * its sharpest cell's error, so faithful tolerances keep most of the triangles (half the
 * range keeps under 12%, but not faithfully; docs/performance.md). So iso_extract_budget_faithful, the
 * policy the server uses, climbs the ladder only as far as a faithful tolerance and, when
 * that does not fit, simplifies the mesh of the requested tolerance with meshoptimizer
 * instead (iso_simplify): at the same triangle count the simplified mesh is the closer to
 * the exact surface (tests/bench/bench_simplify.py measures both). */

/* The faithful top of the ladder: value range / 2^5 (3.1% of the range): tolerances up to
 * this stay within half a voxel of the exact surface at the 99th percentile on the
 * benchmark's CT, MR and industrial cases (docs/performance.md). */
#define ISO_BUDGET_FAITHFUL_SHIFT 5

typedef struct iso_budget_result {
    double tolerance;   /* the tolerance of the mesh extracted */
    int fits;           /* 1 if the mesh has at most `budget` triangles; 0 when even the
                         * coarsest tolerance of the ladder (or the simplifier) does not
                         * get there */
    int extractions;    /* extractions run to find it */
    int simplified;     /* 1: the mesh was simplified, `simplify` says how */
    iso_simplify_result simplify;
} iso_budget_result;

/* Extracts at params->level with the smallest ladder tolerance >= params->tolerance whose
 * mesh has at most `budget` triangles (budget >= 1). Costs about log2(21) + 1 extractions
 * at worst, the coarse ones being the cheap ones. stats are the answer's mesh's, but for
 * nodes_visited and cells_visited, which count every extraction run (result->extractions).
 * Returns what iso_extract returns. */
int iso_extract_budget(const iso_tree *tree, const iso_extract_params *params,
                       size_t budget, iso_mesh *mesh, iso_extract_stats *stats, iso_budget_result *result,
                       iso_error *err);

/* The preview tolerance: value range / 2^ISO_PREVIEW_SHIFT, half the range. A client that
 * shows a coarse mesh while the full one comes (or while a level slider drags) asks for
 * this: most blocks then take their coarsest level, and the mesh keeps 6.5-7.3% of the
 * exact triangles on CThead's skin and bone (docs/performance.md), every vertex still within it
 * of the level. */
#define ISO_PREVIEW_SHIFT 1
double iso_preview_tolerance(const iso_volume *vol);

/* The faithful tolerance of a volume: max(requested, value range / 2^ISO_BUDGET_FAITHFUL_SHIFT). */
double iso_budget_faithful_tolerance(const iso_volume *vol, double requested);

/* The server's policy. Like iso_extract_budget, but the ladder stops at
 * iso_budget_faithful_tolerance; when no rung up to it fits, the mesh of the requested
 * tolerance is simplified to `budget` triangles (no error limit, open edges locked) and
 * result->simplified is set. stats then describe the extraction at the requested
 * tolerance except triangles and vertices, which are the simplified mesh's; every vertex
 * kept is one of the extraction's, so stats->error_bound still holds for each. The
 * simplifier's error is reported in result->simplify in the mesh's units (world mm or
 * index space, params->space) and in voxels (mm over the volume's smallest spacing).
 * Returns what iso_extract or iso_simplify return. */
int iso_extract_budget_faithful(const iso_tree *tree,
                                const iso_extract_params *params, size_t budget,
                                iso_mesh *mesh, iso_extract_stats *stats,
                                iso_budget_result *result, iso_error *err);

#endif
