/* gzip_parts.h: gzip.c's deflate of one part of a buffer on its own, and the join of such
 * parts into one gzip member, for an encoder that deflates each piece of its output on
 * the thread that made it, as soon as it is made (glb_meshopt.c); internal to proto/. */
#ifndef PROTO_GZIP_PARTS_H
#define PROTO_GZIP_PARTS_H

#include <stddef.h>

#include "base/base.h"

/* A part: `size` bytes at `in`, deflated as raw deflate blocks (Huffman only, or gzip.c's
 * greedy matches) ending in a sync flush, or for the last part of a member in the final
 * block, so that parts join byte-aligned in their order (as pigz joins them). */
typedef struct proto_deflate {
    const unsigned char *in;
    size_t size;
    int huffman, last;
    unsigned char *out;  /* room for proto_deflate_bound(size) bytes */
    size_t out_size;     /* written by proto_deflate_run */
    unsigned long crc;   /* the part's CRC-32 */
    int rc;              /* 0, or ISO_E_NOMEM (a matcher's tables) */
} proto_deflate;

/* The most bytes a part of n bytes deflates to, either strategy. */
size_t proto_deflate_bound(size_t n);

/* Deflates d->in into d->out, fills out_size, crc and rc. */
void proto_deflate_run(proto_deflate *d);

/* One gzip member holding the parts' inputs in order (the last part's `last` set), in a
 * new buffer of its exact size (malloc'd, *out). Returns 0, a part's error, ISO_E_NOMEM or
 * ISO_E_LIMIT (over 4 GiB of input). */
int proto_gzip_join(const proto_deflate *parts, int count, unsigned char **out, size_t *out_size,
                    iso_error *err);

#endif
