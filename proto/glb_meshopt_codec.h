/* glb_meshopt_codec.h: meshoptimizer's index and vertex codecs as EXT_meshopt_compression
 * names them (its TRIANGLES mode: the index codec at version 1, header 0xe1; its ATTRIBUTES
 * mode: the vertex codec at version 0, header 0xa0), written byte for byte as
 * meshopt_encodeIndexBuffer and meshopt_encodeVertexBuffer write them at those versions,
 * with the work done 16 entries at a time (glb_meshopt_index.c, glb_meshopt_vertex.c);
 * internal to proto/. */
#ifndef PROTO_GLB_MESHOPT_CODEC_H
#define PROTO_GLB_MESHOPT_CODEC_H

#include <stddef.h>
#include <stdint.h>

/* Encodes `count` indices (3 per triangle) into buf, which holds at least
 * meshopt_encodeIndexBufferBound(count, vertices) bytes; returns the bytes written, the
 * same bytes as meshopt_encodeIndexBuffer after meshopt_encodeIndexVersion(1) (0 if buf is
 * too small). */
size_t proto_meshopt_encode_indices(unsigned char *buf, size_t size, const uint32_t *indices, size_t count);

/* Encodes `count` vertices of `stride` bytes (a multiple of 4, at most 256) into buf, which
 * holds at least meshopt_encodeVertexBufferBound(count, stride) bytes; returns the bytes
 * written, the same bytes as meshopt_encodeVertexBuffer at version 0 (0 if buf is too
 * small or the stride is not one the codec takes). */
size_t proto_meshopt_encode_vertices(unsigned char *buf, size_t size, const void *vertices, size_t count,
                                     size_t stride);

#endif
