// simplify_meshopt.cc: meshoptimizer's simplifier behind a C entry point that catches
// every C++ exception (see simplify_meshopt.h).
#include "simplify_meshopt.h"

#include <meshoptimizer.h>

#include <new>

#include "base/base.h"

extern "C" int iso_meshopt_simplify(unsigned int *destination, const unsigned int *indices,
                                    size_t index_count, const float *positions,
                                    size_t vertex_count, size_t target_index_count,
                                    float target_error, unsigned int options,
                                    float *result_error, size_t *out_index_count)
{
    try {
        *out_index_count = meshopt_simplify(destination, indices, index_count, positions,
                                            vertex_count, 3 * sizeof(float), target_index_count,
                                            target_error, options, result_error);
        return 0;
    } catch (...) { // std::bad_alloc from operator new is the only one it throws
        return ISO_E_NOMEM;
    }
}

extern "C" float iso_meshopt_scale(const float *positions, size_t vertex_count)
{
    return meshopt_simplifyScale(positions, vertex_count, 3 * sizeof(float));
}
