/* simplify_meshopt.h: the C face of the meshoptimizer shim (simplify_meshopt.cc).
 *
 * meshoptimizer is C-callable, but its scratch comes from operator new, which throws on
 * exhaustion; the shim turns that into a status, so no exception crosses into C. */
#ifndef ISO_SIMPLIFY_MESHOPT_H
#define ISO_SIMPLIFY_MESHOPT_H

#include <stddef.h>

#ifdef __cplusplus
extern "C" {
#endif

/* meshopt_simplify (see meshoptimizer.h; destination may be indices, in place) with
 * *out_index_count receiving its result. Returns 0, or ISO_E_NOMEM when meshoptimizer's
 * scratch could not be allocated (destination then holds no meaning). */
int iso_meshopt_simplify(unsigned int *destination, const unsigned int *indices,
                         size_t index_count, const float *positions, size_t vertex_count,
                         size_t target_index_count, float target_error, unsigned int options,
                         float *result_error, size_t *out_index_count);

/* meshopt_simplifyScale over xyz float triples: the mesh's extent. */
float iso_meshopt_scale(const float *positions, size_t vertex_count);

#ifdef __cplusplus
}
#endif

#endif
