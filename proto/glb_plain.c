/* glb_plain.c: a glTF 2.0 binary that needs no extension: float positions and normals and
 * uint32 indices as they are, for tools without a Draco or meshopt decoder (older CAD and
 * 3D printing software, some PACS viewers). Lossless, the mesh's own order, about 3x the
 * bytes of the meshopt glb. */
#include "encode.h"
#include "bytes.h"
#include "glb_container.h"

#include <assert.h>
#include <float.h>
#include <stdlib.h>
#include <string.h>

enum { GLTF_ARRAY_BUFFER = 34962, GLTF_ELEMENT_ARRAY_BUFFER = 34963 };

/* The JSON: accessors 0 POSITION, 1 NORMAL (when present), then the indices; one buffer
 * view per accessor, in the BIN chunk in that order (each a multiple of 4 bytes). */
static void json_plain(proto_glb_json *j, const iso_mesh *mesh, const float min[3], const float max[3])
{
    const int normals = mesh->normals != NULL;
    const size_t v = mesh->vertex_count, t = mesh->triangle_count;
    const size_t vertex_bytes = 12 * v, index_bytes = 12 * t;
    proto_glb_json_add(j, "{\"asset\":{\"version\":\"2.0\",\"generator\":\"isoserve\"},"
                          "\"scene\":0,\"scenes\":[{\"nodes\":[0]}],\"nodes\":[{\"mesh\":0}],"
                          "\"meshes\":[{\"primitives\":[{\"attributes\":{\"POSITION\":0%s},"
                          "\"indices\":%d,\"mode\":%d}]}],",
                       normals ? ",\"NORMAL\":1" : "", normals ? 2 : 1, PROTO_GLTF_TRIANGLES);
    proto_glb_json_add(j, "\"accessors\":[{\"bufferView\":0,\"componentType\":%d,\"count\":%zu,\"type\":\"VEC3\"",
                       PROTO_GLTF_FLOAT, v);
    proto_glb_json_vec3(j, "min", min);
    proto_glb_json_vec3(j, "max", max);
    proto_glb_json_add(j, "}");
    if (normals)
        proto_glb_json_add(j, ",{\"bufferView\":1,\"componentType\":%d,\"count\":%zu,\"type\":\"VEC3\"}",
                           PROTO_GLTF_FLOAT, v);
    proto_glb_json_add(j, ",{\"bufferView\":%d,\"componentType\":%d,\"count\":%zu,\"type\":\"SCALAR\"}],",
                       normals ? 2 : 1, PROTO_GLTF_UNSIGNED_INT, 3 * t);
    proto_glb_json_add(j, "\"bufferViews\":[{\"buffer\":0,\"byteOffset\":0,\"byteLength\":%zu,\"target\":%d}",
                       vertex_bytes, GLTF_ARRAY_BUFFER);
    if (normals)
        proto_glb_json_add(j, ",{\"buffer\":0,\"byteOffset\":%zu,\"byteLength\":%zu,\"target\":%d}",
                           vertex_bytes, vertex_bytes, GLTF_ARRAY_BUFFER);
    proto_glb_json_add(j, ",{\"buffer\":0,\"byteOffset\":%zu,\"byteLength\":%zu,\"target\":%d}],"
                          "\"buffers\":[{\"byteLength\":%zu}]}",
                       (normals ? 2 : 1) * vertex_bytes, index_bytes, GLTF_ELEMENT_ARRAY_BUFFER,
                       (normals ? 2 : 1) * vertex_bytes + index_bytes);
}

/* Little-endian floats, whatever the host. */
static unsigned char *put_floats(unsigned char *p, const float *f, size_t n)
{
    for (size_t i = 0; i < n; i++)
        p = proto_put_f32(p, f[i]);
    return p;
}

int proto_encode_glb_plain(const iso_mesh *mesh, unsigned char **out, size_t *out_size, iso_error *err)
{
    assert(mesh && out && out_size);
    *out = NULL;
    *out_size = 0;
    int rc = proto_mesh_check(mesh, 1, err);
    if (rc)
        return rc;
    proto_glb_json json = {.len = 0};
    if (mesh->triangle_count == 0 || mesh->vertex_count == 0) {
        proto_glb_json_empty(&json);
        return proto_glb_write(&json, NULL, 0, out, out_size, err);
    }
    /* glTF requires POSITION's bounds; they are the float positions' own. */
    float min[3] = {FLT_MAX, FLT_MAX, FLT_MAX}, max[3] = {-FLT_MAX, -FLT_MAX, -FLT_MAX};
    for (size_t v = 0; v < mesh->vertex_count; v++)
        for (int d = 0; d < 3; d++) {
            float x = mesh->positions[3 * v + d];
            min[d] = x < min[d] ? x : min[d];
            max[d] = x > max[d] ? x : max[d];
        }
    json_plain(&json, mesh, min, max);
    const size_t vertex_bytes = 12 * mesh->vertex_count, index_bytes = 12 * mesh->triangle_count;
    const size_t bin_size = (mesh->normals ? 2 : 1) * vertex_bytes + index_bytes;
    size_t size;
    if ((rc = proto_glb_size(&json, bin_size, &size, err)))
        return rc;
    unsigned char *buf = malloc(size);
    if (!buf)
        return iso_error_set(err, ISO_E_NOMEM, "no memory for a glb of %zu bytes", size);
    unsigned char *p = buf + proto_glb_head(&json, bin_size, buf);
    p = put_floats(p, mesh->positions, 3 * mesh->vertex_count);
    if (mesh->normals)
        p = put_floats(p, mesh->normals, 3 * mesh->vertex_count);
    for (size_t i = 0; i < 3 * mesh->triangle_count; i++)
        p = proto_put_u32(p, mesh->indices[i]);
    assert((size_t)(p - buf) == size); /* bin_size is a multiple of 4: no padding */
    *out = buf;
    *out_size = size;
    return 0;
}
