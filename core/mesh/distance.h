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

/* iso_mesh_distance_compute with a's grid ga and b's grid gb given (either may be NULL:
 * built over both meshes' bounds for the call) and the percentile's sample cap. */
int iso_mesh_distance_between(const iso_mesh *a, const iso_mesh_grid *ga, const iso_mesh *b,
                              const iso_mesh_grid *gb, double spacing, size_t cap, int threads,
                              iso_mesh_distance *out, iso_error *err);

#endif
