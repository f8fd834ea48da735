/* glb.c: the glTF 2.0 binary container (glb_container.h) and the encoder of one triangle
 * primitive whose data is a Draco stream (KHR_draco_mesh_compression), as three.js's
 * GLTFLoader + DRACOLoader read it. */
#include "encode.h"
#include "bytes.h"
#include "draco_shim.h"
#include "glb_container.h"

#include <assert.h>
#include <stdarg.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

enum {
    GLB_MAGIC = 0x46546C67,      /* "glTF" */
    GLB_VERSION = 2,
    GLB_CHUNK_JSON = 0x4E4F534A, /* "JSON" */
    GLB_CHUNK_BIN = 0x004E4942   /* "BIN\0" */
};

void proto_glb_json_add(proto_glb_json *j, const char *fmt, ...)
{
    va_list ap;
    va_start(ap, fmt);
    int n = vsnprintf(j->text + j->len, sizeof j->text - j->len, fmt, ap);
    va_end(ap);
    /* The text is bounded by the skeleton, so running out of room is a bug here. */
    assert(n >= 0 && (size_t)n < sizeof j->text - j->len);
    j->len += (size_t)n;
}

/* "%.9g" round-trips a float and never prints nan/inf here (positions are checked finite),
 * so every number is valid JSON. Assumes the C locale's decimal point. */
void proto_glb_json_vec3(proto_glb_json *j, const char *key, const float v[3])
{
    proto_glb_json_add(j, ",\"%s\":[%.9g,%.9g,%.9g]", key, v[0], v[1], v[2]);
}

void proto_glb_json_empty(proto_glb_json *j)
{
    proto_glb_json_add(j, "{\"asset\":{\"version\":\"2.0\",\"generator\":\"isoserve\"},"
                          "\"scene\":0,\"scenes\":[{}]}");
}

static void json_mesh(proto_glb_json *j, const proto_draco_info *info, size_t draco_size)
{
    const int normals = info->normal_id >= 0;
    const int indices_accessor = normals ? 2 : 1;
    proto_glb_json_add(j, "{\"asset\":{\"version\":\"2.0\",\"generator\":\"isoserve\"},"
                "\"extensionsUsed\":[\"KHR_draco_mesh_compression\"],"
                "\"extensionsRequired\":[\"KHR_draco_mesh_compression\"],"
                "\"scene\":0,\"scenes\":[{\"nodes\":[0]}],\"nodes\":[{\"mesh\":0}],");
    /* The primitive's accessors have no bufferView: the extension supplies their data. */
    proto_glb_json_add(j, "\"meshes\":[{\"primitives\":[{\"attributes\":{\"POSITION\":0%s},"
                "\"indices\":%d,\"mode\":%d,",
             normals ? ",\"NORMAL\":1" : "", indices_accessor, PROTO_GLTF_TRIANGLES);
    proto_glb_json_add(j, "\"extensions\":{\"KHR_draco_mesh_compression\":{\"bufferView\":0,"
                "\"attributes\":{\"POSITION\":%d", info->position_id);
    if (normals)
        proto_glb_json_add(j, ",\"NORMAL\":%d", info->normal_id);
    proto_glb_json_add(j, "}}}}]}],");
    proto_glb_json_add(j, "\"accessors\":[{\"componentType\":%d,\"count\":%zu,\"type\":\"VEC3\"",
             PROTO_GLTF_FLOAT, info->points);
    proto_glb_json_vec3(j, "min", info->min);
    proto_glb_json_vec3(j, "max", info->max);
    proto_glb_json_add(j, "}");
    if (normals)
        proto_glb_json_add(j, ",{\"componentType\":%d,\"count\":%zu,\"type\":\"VEC3\"}", PROTO_GLTF_FLOAT,
                 info->points);
    proto_glb_json_add(j, ",{\"componentType\":%d,\"count\":%zu,\"type\":\"SCALAR\"}],",
             PROTO_GLTF_UNSIGNED_INT, 3 * info->faces);
    proto_glb_json_add(j, "\"bufferViews\":[{\"buffer\":0,\"byteOffset\":0,\"byteLength\":%zu}],"
                "\"buffers\":[{\"byteLength\":%zu}]}",
             draco_size, draco_size);
}

int proto_encode_glb(const iso_mesh *mesh, const proto_encode_options *opt,
                     unsigned char **out, size_t *out_size, iso_error *err)
{
    return proto_glb_encode_info(mesh, opt, out, out_size, NULL, err);
}

int proto_glb_encode_info(const iso_mesh *mesh, const proto_encode_options *opt,
                          unsigned char **out, size_t *out_size, proto_draco_info *embedded,
                          iso_error *err)
{
    assert(mesh && out && out_size);
    *out = NULL;
    *out_size = 0;
    unsigned char *draco = NULL;
    size_t draco_size = 0;
    proto_draco_info info;
    int rc = proto_draco_encode_info(mesh, opt, &draco, &draco_size, &info, err);
    if (rc)
        return rc;
    if (embedded)
        *embedded = info;

    proto_glb_json json;
    json.len = 0;
    if (info.faces == 0) {
        proto_glb_json_empty(&json);
        draco_size = 0; /* no BIN chunk at all */
    } else {
        json_mesh(&json, &info, draco_size);
    }
    rc = proto_glb_write(&json, draco, draco_size, out, out_size, err);
    free(draco);
    return rc;
}

/* The head for JSON text of any length (proto_glb_head's, and proto_glb_write_text's). */
static size_t head_of_text(const char *text, size_t len, size_t bin_size, unsigned char *out)
{
    /* Layout: header (12), JSON chunk (8 + text padded with spaces), BIN chunk (8 + bytes
     * padded with zeros) when there is one. Lengths are uint32 in the container. */
    const size_t json_padded = proto_glb_pad4(len), bin_padded = proto_glb_pad4(bin_size);
    const size_t size = 12 + 8 + json_padded + (bin_size ? 8 + bin_padded : 0);
    unsigned char *p = out;
    p = proto_put_u32(p, GLB_MAGIC);
    p = proto_put_u32(p, GLB_VERSION);
    p = proto_put_u32(p, (uint32_t)size);
    p = proto_put_u32(p, (uint32_t)json_padded);
    p = proto_put_u32(p, GLB_CHUNK_JSON);
    memcpy(p, text, len);
    memset(p + len, ' ', json_padded - len);
    p += json_padded;
    if (bin_size) {
        p = proto_put_u32(p, (uint32_t)bin_padded);
        p = proto_put_u32(p, GLB_CHUNK_BIN);
    }
    return (size_t)(p - out);
}

size_t proto_glb_head(const proto_glb_json *json, size_t bin_size, unsigned char *out)
{
    return head_of_text(json->text, json->len, bin_size, out);
}

static int size_of_text(size_t len, size_t bin_size, size_t *size, iso_error *err)
{
    *size = 12 + 8 + proto_glb_pad4(len) + (bin_size ? 8 + proto_glb_pad4(bin_size) : 0);
    if (bin_size > UINT32_MAX - 64 || *size > UINT32_MAX)
        return iso_error_set(err, ISO_E_LIMIT, "glb of %zu bytes exceeds glTF's 4 GiB", *size);
    return 0;
}

int proto_glb_size(const proto_glb_json *json, size_t bin_size, size_t *size, iso_error *err)
{
    return size_of_text(json->len, bin_size, size, err);
}

int proto_glb_write(const proto_glb_json *json, const unsigned char *bin, size_t bin_size,
                    unsigned char **out, size_t *out_size, iso_error *err)
{
    return proto_glb_write_text(json->text, json->len, bin, bin_size, out, out_size, err);
}

int proto_glb_write_text(const char *text, size_t len, const unsigned char *bin, size_t bin_size,
                         unsigned char **out, size_t *out_size, iso_error *err)
{
    *out = NULL;
    *out_size = 0;
    size_t size;
    int rc = size_of_text(len, bin_size, &size, err);
    if (rc)
        return rc;
    unsigned char *buf = malloc(size);
    if (!buf)
        return iso_error_set(err, ISO_E_NOMEM, "no memory for a glb of %zu bytes", size);
    size_t head = head_of_text(text, len, bin_size, buf);
    if (bin_size) {
        memcpy(buf + head, bin, bin_size);
        memset(buf + head + bin_size, 0, size - head - bin_size);
    }
    *out = buf;
    *out_size = size;
    return 0;
}
