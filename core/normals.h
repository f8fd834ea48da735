/* normals.h: per-vertex normals from the gradient of a B-spline of the samples
 * (Elber and Malzbender, section 4: the samples as coefficients of a tensor-product uniform
 * B-spline of order 2, 3 or 4, whose gradient is evaluated at each vertex).
 *
 * Order 2 is the trilinear interpolant itself; orders 3 (triquadratic) and 4 (tricubic)
 * are smoother approximating splines: their normals vary continuously across cell faces,
 * which shading shows. Normals point toward lower values (out of the region f > level),
 * matching the mesh's winding (mesh.h). */
#ifndef ISO_NORMALS_H
#define ISO_NORMALS_H

#include "error.h"
#include "extract.h"
#include "mesh.h"
#include "volume.h"

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

#endif
