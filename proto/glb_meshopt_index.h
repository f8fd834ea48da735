/* glb_meshopt_index.h: meshoptimizer's index codec (version 0, EXT_meshopt_compression's
 * TRIANGLES mode), encoded byte for byte as meshopt_encodeIndexBuffer writes it, with
 * its two 16-entry FIFOs searched 16 entries at a time; internal to proto/. */
#ifndef PROTO_GLB_MESHOPT_INDEX_H
#define PROTO_GLB_MESHOPT_INDEX_H

#include <stddef.h>
#include <stdint.h>

/* Encodes `count` indices (3 per triangle) into buf, which holds at least
 * meshopt_encodeIndexBufferBound(count, vertices) bytes; returns the bytes written, the
 * same bytes as meshopt_encodeIndexBuffer at version 0 (0 if buf is too small). */
size_t proto_meshopt_encode_indices(unsigned char *buf, size_t size, const uint32_t *indices, size_t count);

#endif
