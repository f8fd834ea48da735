/* surface.h: helpers for tests that check extracted surfaces against their volume. */
#ifndef TEST_SURFACE_H
#define TEST_SURFACE_H

#include <stddef.h>

#include "extract/extract.h"
#include "mesh/mesh.h"
#include "hierarchy/tree.h"
#include "volume/volume.h"

/* Uniform in [0, 1) from xorshift64* with a fixed seed: failures reproduce. */
double surface_uniform(void);
/* A zeroed volume (the check fails if it cannot be made). */
iso_volume *surface_make_volume(size_t nx, size_t ny, size_t nz, iso_voxel_type type);
/* How many of m's vertices no triangle uses (the check fails if it cannot count). */
size_t surface_unused_vertices(const iso_mesh *m);
/* A volume of random samples, x fastest: surface_uniform() values, or with steps their
 * floor(4 u), 0..3, so that a level of 1 meets ties; its stats updated. */
iso_volume *surface_random_volume(const size_t n[3], iso_voxel_type type, int steps);
/* The shared scan `file` (a name in ../shared/volumes), loaded; NULL after a skip line
 * when ../shared/volumes is absent, or after a failed check when it does not load. */
iso_volume *surface_load_shared(const char *file);
/* The volume's hierarchy (the check fails if it cannot be built). */
iso_tree *surface_build(const iso_volume *vol);
/* f(p): the data's own trilinear interpolant at index-space point p. */
double surface_interpolate(const iso_volume *vol, const float p[3]);
/* Largest |f(v) - level| over the vertices inside the volume (index space); a cap's
 * vertices, just outside the border, are not on the level and are skipped. */
double surface_worst_vertex_error(const iso_volume *vol, const iso_mesh *m, double level);
/* Float positions carry ~2^-17 relative rounding; through the steepest sample difference
 * that is the slack a vertex may show beyond the bound. */
double surface_rounding_slack(const iso_volume *vol);
/* Integer levels on integer data put samples exactly on the level; their crossings are
 * moved ISO_MC_END_GAP of an edge off (mc.h), which costs at most this much. */
double surface_tie_allowance(const iso_volume *vol);

/* A triangle by its corners' positions. */
typedef struct surface_triangle {
    float p[9];
} surface_triangle;
/* The mesh's triangles by position, each rotated to start at its smallest corner (the
 * winding kept), sorted (malloc'd, triangle_count of them): two meshes are the same
 * surface iff these lists are equal. */
surface_triangle *surface_canonical_triangles(const iso_mesh *m);

#endif
