/* draco_shim.h: the C side of the Draco shim (draco_shim.cc) for encoders that need to
 * describe the Draco bytes they embed (glb.c), and for callers that report them (the
 * server's headers): what a decoder will get out of them, and the speed used.
 * proto_encode_draco and proto_draco_decode (encode.h) are implemented in the shim too. */
#ifndef PROTO_DRACO_SHIM_H
#define PROTO_DRACO_SHIM_H

#include <stddef.h>

#include "encode.h"

#ifdef __cplusplus
extern "C" {
#endif

/* What decoding the stream gives, known at encoding time. */
typedef struct proto_draco_info {
    /* Points and triangles after decoding: edgebreaker drops vertices no triangle uses and
     * splits non-manifold ones, so these can differ from the mesh's counts. */
    size_t points, faces;
    /* Draco attribute unique ids (KHR_draco_mesh_compression's "attributes" map); normal_id
     * is -1 when the mesh has no normals. */
    int position_id, normal_id;
    /* Bounds of the decoded (dequantized) positions, bit-exact: glTF wants an accessor's
     * min/max to be those of the data a loader will see. Both 0 when points is 0. */
    float min[3], max[3];
    /* The Draco speed used: the options' own, or what auto chose. */
    int speed;
} proto_draco_info;

/* proto_encode_draco (encode.h) that also fills `info` (which may be NULL). */
int proto_draco_encode_info(const iso_mesh *mesh, const proto_encode_options *opt,
                            unsigned char **out, size_t *out_size, proto_draco_info *info,
                            iso_error *err);

/* proto_encode_glb (encode.h) that also fills `embedded` (which may be NULL) with what
 * the embedded Draco stream holds (implemented in glb.c). */
int proto_glb_encode_info(const iso_mesh *mesh, const proto_encode_options *opt,
                          unsigned char **out, size_t *out_size, proto_draco_info *embedded,
                          iso_error *err);

#ifdef __cplusplus
}
#endif

#endif
