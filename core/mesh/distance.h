/* distance.h: the distance measure's grid of a mesh's triangles, kept by callers that
 * measure many meshes against one (the chain keeps its exact surface's), and the measure
 * with its sample cap exposed (tests choose a small one). Internal to core/mesh. */
#ifndef ISO_MESH_DISTANCE_H
#define ISO_MESH_DISTANCE_H

#include "mesh.h"

/* A mesh's triangles in two uniform grids (about four cells per triangle, and one 8
 * times coarser for points far from the surface) over the box lo..hi, which should hold
 * every point that will be looked up (points outside are answered, more slowly). The
 * mesh is not copied: it must outlive the grid unchanged. */
typedef struct iso_mesh_grid iso_mesh_grid;
int iso_mesh_grid_build(const iso_mesh *mesh, const float lo[3], const float hi[3],
                        iso_mesh_grid **out);
void iso_mesh_grid_destroy(iso_mesh_grid *g);
size_t iso_mesh_grid_bytes(const iso_mesh_grid *g); /* what it holds in memory */

/* A mesh's samples at one spacing (how many each triangle holds, the area before it) and
 * its bounds, for callers that measure that mesh as a against many (the chain's level 0
 * against each level). The mesh is not copied: it must outlive them unchanged. */
typedef struct iso_mesh_samples iso_mesh_samples;
int iso_mesh_samples_build(const iso_mesh *mesh, double spacing, iso_mesh_samples **out);
void iso_mesh_samples_destroy(iso_mesh_samples *s);

/* What a measure of b against a can take from an earlier measure against the same a, at
 * the same spacing, of a mesh `prior` over the same positions as b (a chain's previous
 * level), and leave for the next one. A triangle of b with the same three indices in the
 * same order as one of prior's has the same samples, so their distances to a are within
 * that triangle's bound: when the bound is within the largest distance found so far, the
 * triangle cannot raise the maximum from b to a and is not searched (pass 5). The maximum
 * stays exact over all samples. */
typedef struct iso_mesh_distance_reuse {
    const uint32_t *prior_indices; /* 3 per prior triangle, over b's positions; NULL: none */
    size_t prior_triangles;
    const double *prior_bound;     /* per prior triangle, the square of a distance no sample
                                    * of it exceeds; NULL: prior's triangles are a's own (its
                                    * samples lie on a: each is tried against its triangle) */
    double *bound;                 /* out, per triangle of b (NULL: not wanted): the same for
                                    * this measure, for the next one's prior_bound */
    int exhaustive;                /* nonzero: every sample searched on its own, no block of
                                    * them skipped by a bound (for checks: same results) */
    const iso_mesh_samples *a_samples; /* a's at this spacing (NULL: counted for the call) */
    int without_max;               /* nonzero: the maximum is not wanted: PASS 5 is skipped
                                    * (max comes out NAN; the p99 is the same bit for bit) */
    int without_mean;              /* nonzero: the mean is not wanted (it comes out NAN), so
                                    * that of the points drawn for the percentile only those
                                    * that may lie in its top 1% are measured exactly (the
                                    * p99 and max are the same bit for bit) */
} iso_mesh_distance_reuse;

/* iso_mesh_distance_compute with a's grid ga and b's grid gb given (either may be NULL:
 * built over both meshes' bounds for the call), the percentile's sample cap, and reuse
 * (NULL: none). */
int iso_mesh_distance_between(const iso_mesh *a, const iso_mesh_grid *ga, const iso_mesh *b,
                              const iso_mesh_grid *gb, double spacing, size_t cap, int threads,
                              const iso_mesh_distance_reuse *reuse, iso_mesh_distance *out,
                              iso_error *err);

/* Level 0's grid into chain->grid (none below 2 triangles), counted in chain->bytes:
 * built with the chain, or after reading it from a file (chain.c). 0 or ISO_E_NOMEM. */
int iso_mesh_chain_grid_build(iso_mesh_chain *chain);

#endif
