/* mesh.h: indexed triangle meshes and what is done to them after extraction: the
 * watertightness census with area and enclosed volume, vertex normals from the samples,
 * and simplification.
 *
 * Ownership: a mesh owns its arrays (iso_mesh_destroy frees them); functions that change
 * a mesh grow or replace its arrays, never the caller's other buffers. Errors: ISO_E_NOMEM,
 * ISO_E_ARGUMENT for a parameter out of range, each through iso_error. Thread-safety: a
 * mesh is not shared while it is changed; reading one from several threads is safe.
 * Cost: the census and simplification are O(n log n) in the triangles, normals O(n) with
 * up to 64 sample reads per vertex. */
#ifndef ISO_MESH_H
#define ISO_MESH_H

#include <stddef.h>
#include <stdint.h>

#include "base/base.h"
#include "volume/volume.h"

/* Indexed triangle meshes, the output of extraction and the input of encoders.
 *
 * Positions are float x,y,z triples; triangles are uint32 index triples whose winding
 * (counter-clockwise seen from the side the normal points to) makes normals point from
 * higher values toward lower values. Normals, when present, are unit float triples per
 * vertex. A mesh owns its arrays; iso_mesh_destroy frees them. */

/* Where a mesh's positions live: world millimetres (the volume's geometry applied) or
 * index space (sample i at coordinate i). */
typedef enum iso_space { ISO_SPACE_WORLD = 0, ISO_SPACE_INDEX = 1 } iso_space;

typedef struct iso_mesh {
    float *positions;      /* 3 * vertex_count */
    float *normals;        /* 3 * vertex_count, or NULL */
    uint32_t *indices;     /* 3 * triangle_count */
    size_t vertex_count, triangle_count;
    size_t vertex_capacity, triangle_capacity;
} iso_mesh;

/* Initialises an empty mesh (no allocation). */
void iso_mesh_init(iso_mesh *mesh);
/* Frees the arrays and leaves an empty mesh; NULL is allowed. */
void iso_mesh_free(iso_mesh *mesh);
/* Empties the mesh but keeps its position and index arrays for reuse (normals are
 * freed): extracting again into the same mesh then faults no fresh pages in. */
void iso_mesh_clear(iso_mesh *mesh);
/* Makes room for at least the given totals. Returns 0 or ISO_E_NOMEM (mesh unchanged). */
int iso_mesh_reserve(iso_mesh *mesh, size_t vertices, size_t triangles);
/* Merges vertices with bit-identical positions and drops triangles that become degenerate
 * (two equal indices). Vertex order: first occurrence. O(V) expected, allocates a
 * temporary hash table of ~2V entries. Returns 0 or ISO_E_NOMEM (mesh unchanged). */
int iso_mesh_weld(iso_mesh *mesh);

/* Removes the vertices no triangle uses, keeping the others in order, and renumbers the
 * triangles. O(V + T), allocates a temporary V-entry table. Returns 0 or ISO_E_NOMEM
 * (mesh unchanged). */
int iso_mesh_drop_unused(iso_mesh *mesh);
/* The same with the caller's scratch: remap has vertex_count entries (it ends up holding
 * each old vertex's new index, UINT32_MAX for those dropped). Cannot fail. */
void iso_mesh_drop_unused_into(iso_mesh *mesh, uint32_t *remap);

/* Sum of triangle areas, in the square of the position unit. O(T). */
double iso_mesh_area(const iso_mesh *mesh);
/* Signed enclosed volume (divergence theorem), positive when normals point outward of
 * the enclosed region; meaningful for closed meshes. O(T). */
double iso_mesh_enclosed_volume(const iso_mesh *mesh);

/* Edge census after welding: edges used by one triangle, by three or more, and by exactly
 * two triangles in opposite directions. O(T) plus a sort of each vertex's few edges;
 * allocates 24 bytes per triangle and 8 per vertex for the call. Returns 0, ISO_E_NOMEM,
 * or ISO_E_ARGUMENT when an index is not below vertex_count (out is then undefined). */
typedef struct iso_mesh_edges {
    size_t edges, open, nonmanifold, misoriented;
    size_t open_excused; /* open edges the classifier accepted (counted apart from open) */
} iso_mesh_edges;
int iso_mesh_count_edges(const iso_mesh *mesh, iso_mesh_edges *out);
/* The same census, asking excuse(context, a, b) about every open edge (a, b): those it
 * answers 1 for count in open_excused instead of open (a volume border, for example). */
typedef int (*iso_mesh_edge_excuse_fn)(void *context, uint32_t a, uint32_t b);
int iso_mesh_count_edges_excusing(const iso_mesh *mesh, iso_mesh_edge_excuse_fn excuse,
                                  void *context, iso_mesh_edges *out);

/* Calls visit(context, lo, hi, forward, backward) once for every edge (lo < hi) with its
 * uses as lo->hi and as hi->lo, in order of lo, then hi. Allocates 24 bytes per triangle
 * and 8 per vertex for the call; returns 0, ISO_E_NOMEM or ISO_E_ARGUMENT (an index not
 * below vertex_count), nothing visited then. */
typedef void (*iso_mesh_edge_visit_fn)(void *context, uint32_t lo, uint32_t hi,
                                       uint32_t forward, uint32_t backward);
int iso_mesh_visit_edges(const iso_mesh *mesh, iso_mesh_edge_visit_fn visit, void *context);

/* 1 when triangle t has zero area: its edge vectors' cross product, in double from the
 * float positions, is exactly zero. */
int iso_mesh_zero_area(const iso_mesh *mesh, size_t t);

/* Axis-aligned bounds of the positions; min > max for an empty mesh. */
void iso_mesh_bounds(const iso_mesh *mesh, float min[3], float max[3]);

/* The measured distance between two surfaces, both ways, independent of any estimate.
 *
 * From a to b: samples cover a's surface evenly (every triangle cut into similar
 * sub-triangles whose sides are at most `spacing`, one sample at each one's centroid
 * weighing its area, and every vertex a uses, weighing nothing). max_ab is the largest
 * distance from any of them to the nearest point of b's triangles, exactly (a uniform grid
 * of b's triangles, searched ring by ring, each sample only as far as it could raise the
 * maximum). p99_ab is the smallest distance within which 99% of a's area lies, and
 * mean_ab the mean distance by area, measured exactly at those centroids when there are
 * at most ISO_DISTANCE_SAMPLES of them (drawn_a 0); else at ISO_DISTANCE_SAMPLES points
 * drawn by area (drawn_a of them), stratified: the area cut into that many strata of
 * equal area, one uniformly random point in each, with a fixed seed. The share of a's
 * area within a drawn p99 is then 99% with a standard deviation of at most
 * sqrt(0.99 x 0.01 / drawn) (0.078 percentage points), and those points count for the
 * maximum too. The same from b to a; p99 and max are the larger of the two, mean the two
 * means pooled by the surfaces' areas. Units: the positions'. A mesh without triangles is
 * at distance 0 from anything and anything else is at INFINITY from it. Cost: O(samples)
 * grid lookups, most ending at the first triangle, plus ISO_DISTANCE_SAMPLES full
 * searches per direction; `threads` share the samples (0 = all cores; the result does not
 * depend on it). Allocates about 8 bytes per triangle and 16 per drawn point for the
 * call. Returns 0, ISO_E_ARGUMENT (spacing not > 0) or ISO_E_NOMEM. */
#define ISO_DISTANCE_SAMPLES 16384
typedef struct iso_mesh_distance {
    double p99_ab, max_ab, p99_ba, max_ba;
    double p99, max;
    double mean_ab, mean_ba, mean;
    size_t samples_a, samples_b; /* centroids and vertices */
    size_t drawn_a, drawn_b;     /* points drawn for the percentile, 0 = the centroids */
    double ms;
} iso_mesh_distance;
int iso_mesh_distance_compute(const iso_mesh *a, const iso_mesh *b, double spacing, int threads,
                              iso_mesh_distance *out, iso_error *err);
/* The exact distance from p to mesh's nearest triangle, by brute force over all of them
 * (INFINITY without triangles); for checks. O(T). */
double iso_mesh_point_distance(const iso_mesh *mesh, const double p[3]);

/* Is an extracted surface watertight? Edge and triangle counts anyone can check.
 *
 * After welding, an edge is interior when exactly two triangles use it, once in each
 * direction. Anything else is counted: open edges (one triangle) split into those on the
 * volume's outer boundary, where a surface that leaves the data must end, and the rest,
 * which are cracks; non-manifold edges (three or more triangles); misoriented edges (two
 * triangles, same direction); degenerate triangles (zero area). A mesh is closed when it
 * has no open edge of either kind and nothing else counted. */

typedef struct iso_census {
    size_t edges;
    size_t open_edges;        /* one triangle, not on the volume border: cracks */
    size_t boundary_edges;    /* one triangle, both ends on one border plane of the volume */
    size_t nonmanifold_edges; /* three or more triangles */
    size_t misoriented_edges; /* two triangles using it in the same direction */
    size_t degenerate_triangles; /* zero area */
    int closed;               /* every count above but edges is zero, and there are triangles */
} iso_census;

/* Counts mesh's edges; space says whether positions are world mm or index coordinates of
 * vol (world positions are mapped back to find the border). O(T) with a temporary table;
 * returns 0 or ISO_E_NOMEM. */
int iso_census_compute(const iso_volume *vol, const iso_mesh *mesh, iso_space space,
                       iso_census *out, iso_error *err);

/* Per-vertex normals from the gradient of a B-spline of the samples
 * (Elber and Malzbender, section 4: the samples as coefficients of a tensor-product uniform
 * B-spline of order 2, 3 or 4, whose gradient is evaluated at each vertex).
 *
 * Order 2 is the trilinear interpolant itself; orders 3 (triquadratic) and 4 (tricubic)
 * are smoother approximating splines: their normals vary continuously across cell faces,
 * which shading shows. Normals point toward lower values (out of the region f > level),
 * matching the mesh's winding (mesh.h). */

/* "none" -> 0, "trilinear" -> 2, "triquadratic" -> 3, "tricubic" -> 4; -1 for anything
 * else (NULL included). */
int iso_normals_order_from_name(const char *name);
/* The reverse; "none" for 0. order must be 0, 2, 3 or 4 (asserted). */
const char *iso_normals_name(int order);

/* Sets mesh->normals (allocated to the mesh's vertex capacity) to the unit negative
 * gradient of the order-`order` B-spline of vol at each vertex; order 0 removes them.
 * Positions are read, and normals written, in `space` (world normals use the inverse
 * transpose of the index-to-world map, so anisotropic spacing is honoured). Samples
 * outside the volume repeat the border; NaN samples count as the volume's minimum (below
 * every level, as in extraction). Where the gradient vanishes the trilinear one is used,
 * else (0, 0, 1): never NaN, always unit length. O(V * order^3) sample reads (36, not 64,
 * for a tricubic normal on a grid edge, as marching cubes' vertices are), no allocation
 * but the normals array; `threads` share the vertices (0 = all cores; the
 * result does not depend on it). Returns 0, ISO_E_ARGUMENT (bad order, a singular
 * geometry) or ISO_E_NOMEM (mesh unchanged). */
int iso_normals_compute(const iso_volume *vol, iso_mesh *mesh, int order, iso_space space,
                        int threads, iso_error *err);

/* Fewer triangles for an extracted mesh, by edge collapse (meshoptimizer).
 *
 * The hierarchy's tolerance removes few triangles across sharp CT edges: a node's fit
 * error stays above any faithful tolerance until the node is one cell wide. When a
 * triangle budget must still be met, the extracted mesh is simplified with
 * meshopt_simplify (Garland and Heckbert's quadric error metric, 1997), which collapses
 * edges onto existing vertices: every vertex left is one of the input's, so the
 * extraction's vertex guarantee (|f(v) - level| <= error bound, extract.h) still holds for
 * every vertex, and the geometric error between the two surfaces is what is reported.
 *
 * Error units: meshoptimizer measures error relative to the mesh's extent (its largest
 * bounding-box side, meshopt_simplifyScale); here it is converted to position units (world
 * mm or index space, whatever the mesh holds) and to voxels. The figure is
 * meshoptimizer's own: the square root of the largest quadric error of a collapse, the
 * area-weighted distance of a kept vertex from the planes of the triangles it absorbed.
 * It is an estimate, not a proof; tests/unit/test_simplify.c and tests/bench/bench_simplify.py
 * measure the real distance against it.
 *
 * Topology. meshoptimizer 0.18 collapses a border vertex only along its border loop, so a
 * closed mesh gets no open edge; with lock_border, vertices on open edges do not move at
 * all and the open edges come out exactly as they went in (an extracted mesh's open edges
 * lie on the volume's border planes, and collapsing along them could cut the volume's
 * corners). Collapses keep every edge's balance: as many uses in one direction as in the
 * other, so the result still bounds the same kind of solid and its enclosed volume means
 * what it meant. But meshoptimizer does not check the link condition: where two sheets of
 * surface come close (thin bone, skin folds) a collapse can lay a pair of triangles onto
 * each other (a fold: same corners, opposite windings; dropped here, which keeps every
 * balance) or pinch the sheets onto one edge of four triangles, which stays and is counted
 * in result->nonmanifold_edges (a few in 10,000 edges on CT skin; docs/performance.md).
 * iso_simplify_manifold (below) makes neither. */

typedef struct iso_simplify_params {
    size_t target_triangles; /* at most this many triangles (>= 1) */
    double target_error;     /* position units: no collapse beyond this error; INFINITY (or
                              * anything >= the mesh's extent) for no limit, 0 for lossless
                              * collapses only (meshoptimizer's own float rounding aside) */
    double voxel_size;       /* position units per voxel, for error_voxels; 0 means 1 */
    int lock_border;         /* 1: vertices on open edges stay where they are */
    int measure;             /* 1: measure the distance between input and result (result->
                              * distance, iso_mesh_distance_compute, samples voxel_size apart) */
    int threads;             /* for the measure: 0 = all cores */
    int keep_vertices;       /* 1: keep unused vertices (indices stay valid for the input's
                              * positions); 0: drop them */
    unsigned char *fold_marks; /* NULL, or vertex_count bytes: the corners of every fold
                              * dropped are set to 1 (the others left as they were) */
} iso_simplify_params;

typedef struct iso_simplify_result {
    size_t triangles_in, vertices_in;
    size_t triangles, vertices;  /* what the mesh has now */
    double error;                /* meshoptimizer's error, position units (0 if untouched) */
    double error_voxels;         /* error / voxel_size */
    double scale;                /* position units per unit of meshoptimizer's relative error */
    size_t folds_dropped;        /* triangles dropped as folds (pairs) */
    size_t nonmanifold_edges;    /* edges of the result used by 3 or more triangles */
    size_t pinch_vertices;       /* vertices whose triangles make two fans or more
                                  * (iso_simplify_manifold only; 0 from iso_simplify) */
    size_t locked_vertices;      /* vertices left that iso_simplify_manifold refused a
                                  * collapse for its topology */
    size_t unpaired_edges;       /* edges used twice or more, not as often in each direction
                                  * (0 whenever the input had none: the tests check it) */
    int measured;                /* distance below was measured (params->measure) */
    iso_mesh_distance distance;  /* a = the input, b = the result, position units */
    double ms;
} iso_simplify_result;

/* Simplifies mesh in place to at most params->target_triangles triangles, stopping
 * earlier where the next collapse would exceed params->target_error, or where topology
 * allows no more (then more triangles than the target remain: compare result->triangles).
 * Unused vertices are dropped, the others keep their relative order, normals (if any)
 * follow their vertices. A mesh already within the target is not touched (not a byte).
 * Allocates an index buffer of the input's size, a remap table (4 bytes per vertex) and
 * meshoptimizer's own scratch, all freed before return. O(T log T). result may be NULL. Returns 0, ISO_E_ARGUMENT (target 0, a NaN or
 * negative target error, a voxel size <= 0) or ISO_E_NOMEM (mesh unchanged, meshoptimizer's
 * own allocations included). Safe on any mesh whose indices are below vertex_count. */
int iso_simplify(iso_mesh *mesh, const iso_simplify_params *params,
                 iso_simplify_result *result, iso_error *err);

/* Connected components: triangles joined through shared vertices (components.c).
 * iso_mesh_count_components counts them; iso_mesh_remove_components removes the closed
 * ones (every edge used once each way) whose enclosed volume, |signed|, is under
 * min_volume (position units cubed: mm3 in world space), with the vertices only they
 * used; components with an open edge (cut by the volume's border) always stay. Vertices
 * left keep their order, normals follow. Both O(V + T) and allocate 8 bytes per vertex
 * (remove: and 24 per triangle, 40 per component) for the call; 0 or ISO_E_NOMEM (mesh
 * unchanged). */
typedef struct iso_mesh_components {
    size_t components;        /* before the removal */
    size_t removed, removed_triangles;
    double removed_largest;   /* the largest bounding-box diagonal among those removed
                               * (position units), 0 when none was */
} iso_mesh_components;
int iso_mesh_count_components(const iso_mesh *mesh, size_t *count);
int iso_mesh_remove_components(iso_mesh *mesh, double min_volume, iso_mesh_components *out);

/* Pinches: where two sheets of a surface meet at an edge of three or more triangles or at
 * a vertex whose triangles make two fans or more (joined through corners other than the
 * vertex). A watertight extraction has none; edge collapses that ignore the link
 * condition make them (manifold.c). */
typedef struct iso_mesh_pinches {
    size_t edges;          /* all edges */
    size_t open_edges;     /* used by 1 triangle */
    size_t pinch_edges;    /* used by 3 or more triangles */
    size_t pinch_vertices; /* whose triangles make 2 fans or more */
    size_t unpaired_edges; /* used twice or more, not as often in each direction */
} iso_mesh_pinches;
/* Counts mesh's pinches; mark, when not NULL (vertex_count bytes), gets 1 at every pinch
 * vertex and both ends of every pinch edge, 0 elsewhere. O(T log T), allocates about 40
 * bytes per triangle for the call. Returns 0, ISO_E_NOMEM or ISO_E_ARGUMENT (an index not
 * below vertex_count). */
int iso_mesh_find_pinches(const iso_mesh *mesh, unsigned char *mark, iso_mesh_pinches *out);

/* iso_simplify that makes no pinch and no fold (collapse.c, not meshoptimizer): half-edge
 * collapses, cheapest first by the same quadric measure as meshoptimizer's (so
 * result->error compares with iso_simplify's), each refused where it would break the link
 * condition (the edge's two ends may share no neighbour but the edge's two opposite
 * corners), turn a triangle over, or join two border vertices by a new edge. Vertices on
 * open edges, on edges not used once each way, or whose triangles make more than one fan,
 * and free vertices of more than 64 triangles, do not move (collapses onto them stay
 * allowed), so the input's pinches stay as they were and are counted in
 * result->nonmanifold_edges and pinch_vertices. No connected component goes: a lone
 * tetrahedron (a speck's smallest closed form) is not collapsed. Every vertex is still an input vertex, the result watertight wherever the input
 * was; where topology allows no more collapses, more triangles than the target remain.
 * result->locked_vertices counts the vertices left that had a collapse refused. Needs
 * params->lock_border (without it, this is iso_simplify). O(T log T), allocates about 120
 * bytes per vertex and 25 per triangle for the call. Errors as iso_simplify's (the mesh
 * unchanged). */
int iso_simplify_manifold(iso_mesh *mesh, const iso_simplify_params *params,
                          iso_simplify_result *result, iso_error *err);

/* Enclosed volume kept (volume_keep.c): every used vertex moved by `offset` (position
 * units) along its unit normal, the area-weighted mean of its triangles' (winding side);
 * unused vertices stay. O(V + T), allocates 24 bytes per vertex for the call. Returns 0
 * or ISO_E_NOMEM (mesh unchanged). */
int iso_mesh_offset_along_normals(iso_mesh *mesh, double offset);
/* The offset for iso_mesh_offset_along_normals that makes mesh's signed enclosed volume
 * `target` (Newton's method, a few steps of O(V + T)); 0 for a mesh without area. mesh is
 * not changed. Returns 0 or ISO_E_NOMEM. */
int iso_mesh_volume_offset(const iso_mesh *mesh, double target, double *offset);
/* The largest |f(v) - level| over the vertices any triangle uses, f the trilinear
 * interpolant of vol's samples (samples outside repeat the border; NaN samples skipped),
 * positions in `space`. O(V) with 8 sample reads per vertex, allocates V bytes for the
 * call (0 on failing to). */
double iso_mesh_value_error(const iso_volume *vol, const iso_mesh *mesh, iso_space space, double level);

/* A simplification chain: one surface at a few levels of detail, each measured.
 *
 * Level 0 is the surface given (the exact one); level k has 1/sqrt(2) of level k - 1's
 * triangles (iso_mesh_chain_target: 70.7%, 50%, 35.4%, 25%, ... 1.56% of level 0 at level
 * 12) by iso_simplify_manifold's collapses with borders locked, each from the one before,
 * so that doubling a distance changes the level wherever the surface allows, and no
 * connected component of level 0 goes (a speck keeps its smallest closed form). Each
 * level is simplified over its own compact vertices, level 1 in two slabs on two threads
 * (each with its cut locked, collapsing in steps of error), the others on one thread while
 * another measures (chain.c). Every level indexes the one position array, a copy of
 * level 0's: every vertex of every level is a vertex of the exact surface, so its value
 * error is the exact surface's, with one exception: on a closed surface, collapses cut
 * chords and a coarse level encloses less (2-3% on a blob of a few hundred triangles),
 * so a level whose enclosed volume strays more than
 * ISO_CHAIN_VOLUME_SLACK from level 0's is moved, every vertex by the same `offset` along
 * its normal (iso_mesh_volume_offset), which gives the volume back; its vertices are then
 * |offset| from exact ones, its measured distance is the moved level's, and the caller
 * reports their value error (iso_mesh_value_error). Each level carries its
 * distance from level 0, measured (iso_mesh_distance_compute's measure, a = level 0,
 * samples three voxels apart), and meshoptimizer's estimate beside it. A built chain is read-only:
 * any number of threads may pick from it and copy meshes out of it at once. */
#define ISO_CHAIN_LEVELS 12
#define ISO_CHAIN_SPACING_VOXELS 3 /* the measures' sample spacing */
#define ISO_CHAIN_VOLUME_SLACK 1e-3 /* a closed level whose enclosed volume strays further
                                     * (relative) is moved along its normals */

typedef struct iso_mesh_chain_level {
    uint32_t *indices;            /* 3 * triangle_count, into the chain's positions */
    size_t triangle_count, vertex_count;
    iso_mesh_distance distance;   /* from level 0; all zero for level 0; means NAN (the
                                   * chain measures p99 and max only); max NAN where a
                                   * build for a distance left it out (build_until) */
    double estimate;              /* meshoptimizer's error for the step, position units */
    size_t nonmanifold_edges, folds_dropped;
    size_t pinch_vertices, edges; /* pinches left (iso_simplify_manifold), all edges */
    double offset;                /* along the normals, so that a closed level 0's enclosed
                                   * volume is kept (iso_mesh_volume_offset); 0: the level's
                                   * vertices are level 0's, unmoved */
    double volume_change;         /* (level's enclosed volume - level 0's) / level 0's, after
                                   * the offset; 0 when level 0 is not closed */
    double value_error;           /* a moved level's vertices' largest value error, which
                                   * the caller with the volume measures once
                                   * (iso_mesh_value_error) and the file keeps; 0 for an
                                   * unmoved level, -1 while not measured */
    double simplify_ms, measure_ms;
} iso_mesh_chain_level;

typedef struct iso_mesh_chain {
    float *positions;             /* level 0's, 3 * vertex_count */
    size_t vertex_count;
    iso_mesh_chain_level level[ISO_CHAIN_LEVELS + 1];
    int levels;                   /* 1 + the levels made (fewer for tiny surfaces) */
    double voxel_size;            /* position units per voxel */
    int closed;                   /* level 0 has no open edge */
    double volume;                /* level 0's signed enclosed volume, when closed */
    size_t faithful_triangles;    /* the caller's, kept in the file: the triangles of the
                                   * value-tolerance mesh budgets compare with (proto's
                                   * pipeline); 0 unknown */
    struct iso_mesh_grid *grid;   /* level 0's search grid, kept for later measures against
                                   * level 0 (iso_mesh_chain_distance); NULL below 2 triangles */
    size_t bytes;                 /* what it holds in memory, the grid included */
    double build_ms;              /* all of its building, extensions included */
    int partial;                  /* 1: built only down to a stop (iso_mesh_chain_build_until);
                                   * iso_mesh_chain_extend makes the rest. A file keeps no such
                                   * flag: save only complete chains */
    double min_component;         /* the caller's: the surface had its closed components
                                   * enclosing less than this removed before the chain was
                                   * built (iso_mesh_remove_components, what it removed in
                                   * `components`); 0: none. Not in the file */
    iso_mesh_components components;
} iso_mesh_chain;

/* Level k's triangle target for a level 0 of `triangles`: floor(triangles / 2^(k/2)),
 * the odd levels' from the even level before times 1/sqrt(2). */
size_t iso_mesh_chain_target(size_t triangles, int k);

/* Builds the chain of `exact` (copied; the caller keeps its mesh). voxel_size: position
 * units per voxel (> 0). threads: for the measures, 0 = all cores. On success *out is a
 * chain for iso_mesh_chain_destroy. Cost: the simplifications and one measure per level;
 * memory about twice the exact mesh's, and level 0's search grid (about 95 bytes per
 * exact triangle). Returns 0, ISO_E_ARGUMENT or ISO_E_NOMEM. */
int iso_mesh_chain_build(const iso_mesh *exact, double voxel_size, int threads,
                         iso_mesh_chain **out, iso_error *err);
/* The same chain built only down to the first level whose measured p99 is over
 * `distance` (>= 0; < 0: no such stop) or that has at most `triangles` (> 0; 0: no such
 * stop), whichever comes first: what a request for that distance or budget needs, each
 * level made as in the full build (a level made beyond the stop is dropped unmeasured).
 * chain->partial says whether levels are left. For a distance, the levels' p99 are
 * measured as the full build's and only the level answering it
 * (iso_mesh_chain_pick_distance) gets its maximum: the others' distance.max is NAN (the
 * maximum's pass over every sample is about a third of a measure). Errors as the build's. */
int iso_mesh_chain_build_until(const iso_mesh *exact, double voxel_size, int threads, double distance,
                               size_t triangles, iso_mesh_chain **out, iso_error *err);
/* Makes a partial chain's remaining levels (all of them, or down to the same kind of
 * stop), each from the one before as the full build does, and the maxima left out
 * (extend: every level's; extend_until a distance: its answer's): build_until then extend
 * gives the full build's levels, index for index, and its measures. Levels already there
 * keep their triangles (their indices are not moved), a missing maximum is written in
 * place; new levels are appended and chain->levels, partial, bytes and build_ms updated
 * at the end: the caller keeps readers off the chain meanwhile (or reads levels below the
 * count it saw under its own lock, and no distance.max it saw NAN). On failure the chain
 * keeps the levels made and measured before the failing one. Returns 0 (also when there
 * was nothing to do), ISO_E_NOMEM. */
int iso_mesh_chain_extend(iso_mesh_chain *chain, int threads, iso_error *err);
int iso_mesh_chain_extend_until(iso_mesh_chain *chain, int threads, double distance, size_t triangles,
                                iso_error *err);
/* 1 when the chain answers a request for `distance` (>= 0) or `triangles` (> 0) as its
 * full build would: it is complete, or its last level is beyond the distance or within
 * the triangles. */
int iso_mesh_chain_covers(const iso_mesh_chain *chain, double distance, size_t triangles);
/* 1 when the chain is what a full build makes: every level made and measured, maxima
 * included (what a file should keep); iso_mesh_chain_extend makes any chain so. */
int iso_mesh_chain_complete(const iso_mesh_chain *chain);
void iso_mesh_chain_destroy(iso_mesh_chain *chain);
/* A copy of `chain` (an in-memory one, complete or partial) to extend while readers keep
 * the original: every level and measure alike, without level 0's search grid (a measure
 * builds it again, about a tenth of a level's measure). *out for iso_mesh_chain_destroy.
 * 0 or ISO_E_NOMEM (nothing left allocated). */
int iso_mesh_chain_copy(const iso_mesh_chain *chain, iso_mesh_chain **out, iso_error *err);
/* The level with the fewest triangles among levels 1..k whose measured p99 distances are
 * all at most `distance` (0, the exact surface, when level 1's is over it), so that a
 * partial chain (iso_mesh_chain_covers) answers as the full one. O(levels). */
int iso_mesh_chain_pick_distance(const iso_mesh_chain *chain, double distance);
/* The finest level with at most `triangles` triangles, else the coarsest. O(levels). */
int iso_mesh_chain_pick_budget(const iso_mesh_chain *chain, size_t triangles);
/* Copies level k into mesh (its arrays reused or grown; normals dropped), its vertices
 * in the exact surface's order (level 0 comes out as the surface went in). O(level's triangles) plus a table of the chain's vertex count.
 * Returns 0, ISO_E_ARGUMENT (no such level) or ISO_E_NOMEM (mesh left empty). */
int iso_mesh_chain_mesh(const iso_mesh_chain *chain, int k, iso_mesh *mesh, iso_error *err);
/* mesh's distance from the chain's level 0, measured as the levels are (samples
 * ISO_CHAIN_SPACING_VOXELS apart, the chain's grid of level 0 reused): what a mesh made
 * from the chain, or beside it, reports (p99 and max; means NAN). Returns as
 * iso_mesh_distance_compute. */
int iso_mesh_chain_distance(const iso_mesh_chain *chain, const iso_mesh *mesh, int threads,
                            iso_mesh_distance *out, iso_error *err);

/* A chain on disk (chain_file.c): iso_mesh_chain_save writes it with the caller's
 * identity (a hash of what the chain was built from: volume version, level, tolerance;
 * never trusted from the file) through a temporary file renamed into place; returns 0,
 * ISO_E_NOMEM or ISO_E_IO. The file holds the positions and each level's indices as
 * aligned sections, each with its own checksum, so that a level can be cut from the
 * mapped file without reading the rest. iso_mesh_chain_load reads one back whole as a
 * chain for iso_mesh_chain_destroy (level 0's grid built again), after checking
 * everything: ISO_E_IO (cannot read), ISO_E_FORMAT (not a chain file), ISO_E_STALE
 * (another version, layout or identity), ISO_E_CORRUPT (sizes, indices or checksums
 * disagree), ISO_E_NOMEM; *out NULL then. Both O(file). */
int iso_mesh_chain_save(const iso_mesh_chain *chain, const char *path, uint64_t identity,
                        iso_error *err);
int iso_mesh_chain_load(const char *path, uint64_t identity, iso_mesh_chain **out, iso_error *err);

/* A chain file mapped read-only (mmap): iso_mesh_chain_map_open checks the header, the
 * table of sections against the file's size (a file cut short is ISO_E_CORRUPT) and the
 * level records' checksum, O(levels), and fails as iso_mesh_chain_load. Its chain (the
 * records in memory, positions and indices in the mapping, no grid: a measure against it
 * builds one for the call) may be picked from at once, but a level may be copied out
 * (iso_mesh_chain_mesh) or measured against only after iso_mesh_chain_map_check(k) said 0
 * for it (and level 0 for iso_mesh_chain_distance): that checks the positions' and level
 * k's checksums and k's indices, once per mapping, O(level k + positions); thread-safe;
 * ISO_E_CORRUPT, after which every check fails. The chain must never be given to
 * iso_mesh_chain_destroy; iso_mesh_chain_map_close unmaps it (NULL allowed).
 * iso_mesh_chain_map_grid builds level 0's grid once (level 0 checked first), for the
 * measures against it that follow (0, ISO_E_CORRUPT or ISO_E_NOMEM); call it before
 * sharing the chain with threads that measure. bytes: the file's size, plus the grid's
 * once built. */
typedef struct iso_mesh_chain_map iso_mesh_chain_map;
int iso_mesh_chain_map_open(const char *path, uint64_t identity, iso_mesh_chain_map **out, iso_error *err);
const iso_mesh_chain *iso_mesh_chain_map_chain(const iso_mesh_chain_map *map);
int iso_mesh_chain_map_check(iso_mesh_chain_map *map, int k, iso_error *err);
size_t iso_mesh_chain_map_bytes(const iso_mesh_chain_map *map);
int iso_mesh_chain_map_grid(iso_mesh_chain_map *map, iso_error *err);
void iso_mesh_chain_map_close(iso_mesh_chain_map *map);

#endif
