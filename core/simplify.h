/* simplify.h: fewer triangles for an extracted mesh, by edge collapse (meshoptimizer).
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
 * in result->nonmanifold_edges (on CThead skin at 100k triangles, 70-90 of ~150k edges).
 * Freezing the triangles around such an edge and simplifying again was tried: it
 * converges slowly and drives the error up, so it is not done. */
#ifndef ISO_SIMPLIFY_H
#define ISO_SIMPLIFY_H

#include <stddef.h>

#include "error.h"
#include "mesh.h"

typedef struct iso_simplify_params {
    size_t target_triangles; /* at most this many triangles (>= 1) */
    double target_error;     /* position units: no collapse beyond this error; INFINITY (or
                              * anything >= the mesh's extent) for no limit, 0 for lossless
                              * collapses only (meshoptimizer's own float rounding aside) */
    double voxel_size;       /* position units per voxel, for error_voxels; 0 means 1 */
    int lock_border;         /* 1: vertices on open edges stay where they are */
} iso_simplify_params;

typedef struct iso_simplify_result {
    size_t triangles_in, vertices_in;
    size_t triangles, vertices;  /* what the mesh has now */
    double error;                /* meshoptimizer's error, position units (0 if untouched) */
    double error_voxels;         /* error / voxel_size */
    double scale;                /* position units per unit of meshoptimizer's relative error */
    size_t folds_dropped;        /* triangles dropped as folds (pairs) */
    size_t nonmanifold_edges;    /* edges of the result used by 3 or more triangles */
    size_t unpaired_edges;       /* edges used twice or more, not as often in each direction
                                  * (0 whenever the input had none: the tests check it) */
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

#endif
