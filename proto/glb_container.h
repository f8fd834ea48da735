/* glb_container.h: the glTF 2.0 binary container shared by proto's glb encoders (glb.c
 * with KHR_draco_mesh_compression, glb_meshopt.c with EXT_meshopt_compression); internal
 * to proto/, not part of its public header. */
#ifndef PROTO_GLB_CONTAINER_H
#define PROTO_GLB_CONTAINER_H

#include <stddef.h>

#include "base/base.h"

enum {
    PROTO_GLTF_BYTE = 5120,
    PROTO_GLTF_SHORT = 5122,
    PROTO_GLTF_UNSIGNED_SHORT = 5123,
    PROTO_GLTF_UNSIGNED_INT = 5125,
    PROTO_GLTF_FLOAT = 5126,
    PROTO_GLTF_TRIANGLES = 4
};

/* The JSON chunk: a fixed skeleton plus a few dozen numbers, so a fixed buffer is ample. */
typedef struct proto_glb_json {
    char text[4096];
    size_t len;
} proto_glb_json;

/* Appends printf-style text; the skeletons are bounded, so overflowing is a bug (asserted). */
void proto_glb_json_add(proto_glb_json *j, const char *fmt, ...)
#if defined(__GNUC__)
    __attribute__((format(printf, 2, 3)))
#endif
    ;

/* ",\"key\":[x,y,z]" with floats that round-trip. */
void proto_glb_json_vec3(proto_glb_json *j, const char *key, const float v[3]);

/* A scene with no nodes: glTF forbids accessors of count 0, so this is a mesh without
 * triangles. */
void proto_glb_json_empty(proto_glb_json *j);

/* The container: header, the JSON chunk padded with spaces, then a BIN chunk of `bin`
 * padded with zeros when bin_size > 0. *out is malloc'd. Returns 0, ISO_E_NOMEM or
 * ISO_E_LIMIT (over glTF's 4 GiB). */
int proto_glb_write(const proto_glb_json *json, const unsigned char *bin, size_t bin_size,
                    unsigned char **out, size_t *out_size, iso_error *err);

/* proto_glb_write with JSON text of any length (a scene of many meshes). */
int proto_glb_write_text(const char *text, size_t len, const unsigned char *bin, size_t bin_size,
                         unsigned char **out, size_t *out_size, iso_error *err);

/* The container's bytes before the BIN chunk's data (header, JSON chunk, and the BIN
 * chunk's header when bin_size > 0) written to out, which holds PROTO_GLB_HEAD_MAX bytes;
 * returns how many. For encoders that write their BIN data in place after it. */
#define PROTO_GLB_HEAD_MAX (12 + 8 + sizeof(((proto_glb_json *)0)->text) + 8)
size_t proto_glb_head(const proto_glb_json *json, size_t bin_size, unsigned char *out);

/* The whole container's size for a BIN chunk of bin_size bytes: 0, or ISO_E_LIMIT (over
 * glTF's 4 GiB). */
int proto_glb_size(const proto_glb_json *json, size_t bin_size, size_t *size, iso_error *err);

/* n rounded up to a multiple of 4: glTF aligns chunks and buffer views to 4 bytes. */
static inline size_t proto_glb_pad4(size_t n)
{
    return (n + 3) & ~(size_t)3;
}

#endif
