/* glb_meshopt_codec.h: meshoptimizer's index and vertex codecs (version 0 of each, the
 * bitstreams of EXT_meshopt_compression's TRIANGLES and ATTRIBUTES modes), written byte
 * for byte as meshopt_encodeIndexBuffer and meshopt_encodeVertexBuffer write them, with
 * the work done 16 entries at a time (glb_meshopt_index.c, glb_meshopt_vertex.c);
 * internal to proto/. */
#ifndef PROTO_GLB_MESHOPT_CODEC_H
#define PROTO_GLB_MESHOPT_CODEC_H

#include <stddef.h>
#include <stdint.h>

/* Encodes `count` indices (3 per triangle) into buf, which holds at least
 * meshopt_encodeIndexBufferBound(count, vertices) bytes; returns the bytes written, the
 * same bytes as meshopt_encodeIndexBuffer at version 0 (0 if buf is too small). */
size_t proto_meshopt_encode_indices(unsigned char *buf, size_t size, const uint32_t *indices, size_t count);

/* Encodes `count` vertices of `stride` bytes (a multiple of 4, at most 256) into buf, which
 * holds at least meshopt_encodeVertexBufferBound(count, stride) bytes; returns the bytes
 * written, the same bytes as meshopt_encodeVertexBuffer at version 0 (0 if buf is too
 * small or the stride is not one the codec takes). */
size_t proto_meshopt_encode_vertices(unsigned char *buf, size_t size, const void *vertices, size_t count,
                                     size_t stride);

#endif
