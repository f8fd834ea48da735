/* fuzz_draco.c: libFuzzer target for the Draco decoder shim (proto/draco_shim.cc's
 * proto_draco_decode), which the tests use to check what the server sends and which must
 * survive any bytes: a mesh whose indices are in range, or an error. */
#include <stdint.h>
#include <stdlib.h>

#include "encode.h"

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size);

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size)
{
    iso_mesh mesh;
    iso_mesh_init(&mesh);
    iso_error err;
    if (proto_draco_decode(data, size, &mesh, &err) == 0)
        for (size_t i = 0; i < 3 * mesh.triangle_count; i++)
            if (mesh.indices[i] >= mesh.vertex_count)
                abort();
    iso_mesh_free(&mesh);
    return 0;
}
