/* gzip.c: a gzip member (RFC 1952) of a whole buffer with zlib, for HTTP's
 * Content-Encoding: gzip (see encode.h).
 *
 * The buffer may be cut into pieces, each deflated on its own (raw deflate, the pieces
 * but the last ending in a sync flush, so that they join byte-aligned into one stream, as
 * pigz does) with its own strategy and on up to two threads; then the header, the joined
 * stream, and the trailer (the CRC-32 and length of the whole input). */
#include "encode.h"

#include <assert.h>
#include <stdlib.h>
#include <string.h>
#include <zlib.h>

#include "base/base.h"

/* Below this many bytes one thread deflates every piece: another thread's share would
 * cost more to hand over than to do. */
#define GZIP_BYTES_PER_THREAD (1u << 20)

/* One piece's deflate stream (malloc'd) or its zlib error. */
typedef struct deflated {
    const unsigned char *in;
    size_t size;
    int huffman, last;
    unsigned char *out;
    size_t out_size;
    uLong crc;
    int rc; /* 0, ISO_E_NOMEM or ISO_E_INTERNAL */
} deflated;

static void deflate_piece(deflated *d)
{
    z_stream z = {0};
    /* Level 1, the fastest; raw deflate (-15): the gzip wrapper is written around the
     * joined pieces. */
    if (deflateInit2(&z, 1, Z_DEFLATED, -15, 8, d->huffman ? Z_HUFFMAN_ONLY : Z_DEFAULT_STRATEGY) != Z_OK) {
        d->rc = ISO_E_NOMEM;
        return;
    }
    size_t bound = deflateBound(&z, (uLong)d->size) + 16; /* + the sync flush's marker */
    d->out = malloc(bound);
    if (!d->out) {
        deflateEnd(&z);
        d->rc = ISO_E_NOMEM;
        return;
    }
    z.next_in = (Bytef *)(uintptr_t)d->in;
    z.avail_in = (uInt)d->size;
    z.next_out = d->out;
    z.avail_out = (uInt)bound;
    int rc = deflate(&z, d->last ? Z_FINISH : Z_SYNC_FLUSH);
    d->out_size = bound - z.avail_out;
    deflateEnd(&z);
    if (rc != (d->last ? Z_STREAM_END : Z_OK) || z.avail_in) {
        d->rc = ISO_E_INTERNAL;
        return;
    }
    d->crc = crc32_z(0, d->in, d->size);
}

typedef struct gzip_job {
    deflated *pieces;
    int count;
} gzip_job;

static void gzip_share(void *context, int t, int threads)
{
    gzip_job *job = context;
    for (int i = t; i < job->count; i += threads)
        deflate_piece(&job->pieces[i]);
}

int proto_gzip_pieces(const unsigned char *in, size_t size, const proto_gzip_piece *pieces, int count,
                      int threads, unsigned char **out, size_t *out_size, iso_error *err)
{
    assert(in && out && out_size && count >= 1 && count <= PROTO_GZIP_PIECES_MAX);
    *out = NULL;
    *out_size = 0;
    if (size > UINT32_MAX)
        return iso_error_set(err, ISO_E_LIMIT, "gzip: cannot compress %zu bytes", size);
    deflated d[PROTO_GZIP_PIECES_MAX];
    size_t from = 0;
    for (int i = 0; i < count; i++) {
        size_t end = i == count - 1 ? size : pieces[i].end;
        assert(end >= from && end <= size);
        d[i] = (deflated){.in = in + from, .size = end - from, .huffman = pieces[i].huffman, .last = i == count - 1};
        from = end;
    }
    gzip_job job = {.pieces = d, .count = count};
    threads = size < GZIP_BYTES_PER_THREAD ? 1 : iso_parallel_threads(threads);
    iso_parallel_run(threads < count ? threads : count, gzip_share, &job);
    int rc = 0;
    size_t total = 10 + 8;
    for (int i = 0; i < count; i++) {
        rc = rc ? rc : d[i].rc;
        total += d[i].out_size;
    }
    unsigned char *buf = rc ? NULL : malloc(total);
    if (!rc && !buf)
        rc = ISO_E_NOMEM;
    if (!rc) {
        /* The header: magic, deflate, no flags, no time, fastest (XFL 4), Unix. */
        static const unsigned char header[10] = {0x1f, 0x8b, 8, 0, 0, 0, 0, 0, 4, 3};
        memcpy(buf, header, sizeof header);
        size_t at = sizeof header;
        uLong crc = 0;
        for (int i = 0; i < count; i++) {
            memcpy(buf + at, d[i].out, d[i].out_size);
            at += d[i].out_size;
            crc = crc32_combine(crc, d[i].crc, (z_off_t)d[i].size);
        }
        for (int b = 0; b < 4; b++)
            buf[at++] = (unsigned char)(crc >> (8 * b));
        for (int b = 0; b < 4; b++)
            buf[at++] = (unsigned char)((uint32_t)size >> (8 * b));
        *out = buf;
        *out_size = at;
    }
    for (int i = 0; i < count; i++)
        free(d[i].out);
    if (rc == ISO_E_NOMEM)
        return iso_error_set(err, rc, "gzip: no memory to compress %zu bytes", size);
    if (rc)
        return iso_error_set(err, rc, "gzip: deflate failed within its own bound");
    return 0;
}

int proto_gzip(const unsigned char *in, size_t size, unsigned char **out, size_t *out_size,
               iso_error *err)
{
    proto_gzip_piece whole = {.end = size};
    return proto_gzip_pieces(in, size, &whole, 1, 1, out, out_size, err);
}
