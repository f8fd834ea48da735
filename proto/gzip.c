/* gzip.c: a gzip member (RFC 1952) of a whole buffer, for HTTP's Content-Encoding: gzip
 * (see encode.h).
 *
 * The buffer may be cut into pieces, each deflated on its own (raw deflate, the pieces
 * but the last ending in a sync flush, so that they join byte-aligned into one stream, as
 * pigz does) with its own strategy and on up to two threads; then the header, the joined
 * stream, and the trailer (the CRC-32 and length of the whole input).
 *
 * Level 1 is zlib's. Huffman-only pieces are written here (zlib's Huffman-only mode still
 * runs its match loop's bookkeeping per byte: about 8 ns a byte, against about 2 here),
 * as RFC 1951 dynamic blocks of literals, one per HUFFMAN_BLOCK bytes, each in turn:
 *   1. count the block's bytes;
 *   2. code lengths: Huffman's two-queue construction over the counts sorted, then
 *      lengths past 15 bits folded back (JPEG's Annex K.3 adjustment of the counts per
 *      length), handed out to the symbols in order of count; canonical codes, bit
 *      reversed (deflate writes codes from their first bit);
 *   3. the block header: the literal and distance code lengths, themselves coded with a
 *      code-length code (lengths up to 7 bits, no run-length symbols);
 *   4. the bytes' codes and the end-of-block code;
 * and a piece that is not the last ends with an empty stored block (the sync flush). */
#include "encode.h"

#include <assert.h>
#include <stdint.h>
#include <stdlib.h>
#include <string.h>
#include <zlib.h>

#include "base/base.h"

/* Below this many bytes one thread deflates every piece: another thread's share would
 * cost more to hand over than to do. */
#define GZIP_BYTES_PER_THREAD (1u << 20)

/* Bytes per Huffman-only block: a table per 64 KB follows the vertex streams' changes
 * (positions, then normals) for about 100 bytes of header each. */
#define HUFFMAN_BLOCK (64u << 10)

/* Bits out, first bit first (deflate's order). */
typedef struct bit_writer {
    unsigned char *out;
    uint64_t bits;
    int count;
} bit_writer;

static inline void bits_put(bit_writer *w, uint32_t value, int n)
{
    w->bits |= (uint64_t)value << w->count;
    w->count += n;
    if (w->count >= 32) {
        for (int b = 0; b < 4; b++)
            *w->out++ = (unsigned char)(w->bits >> (8 * b));
        w->bits >>= 32;
        w->count -= 32;
    }
}

/* Pads to a byte boundary and writes what is left. */
static void bits_flush(bit_writer *w)
{
    while (w->count > 0) {
        *w->out++ = (unsigned char)w->bits;
        w->bits >>= 8;
        w->count -= 8;
    }
    w->bits = 0;
    w->count = 0;
}

/* Step 2: code lengths (at most `limit` bits) for n symbols of counts `freq` (0: unused,
 * length 0), at least two of them used. */
static void code_lengths(const uint32_t *freq, int n, int limit, uint8_t *length)
{
    int order[320], used = 0;
    for (int s = 0; s < n; s++) {
        length[s] = 0;
        if (freq[s]) { /* insertion by count, ascending: n is at most 286 */
            int i = used++;
            for (; i > 0 && freq[order[i - 1]] > freq[s]; i--)
                order[i] = order[i - 1];
            order[i] = s;
        }
    }
    /* Two queues: the leaves by count, the joined nodes in the order made (their counts
     * never decrease). Node k < used is leaf order[k]; node used + j is join j. */
    uint64_t weight[640];
    int parent[640], leaf = 0, join = 0, joins = used - 1;
    for (int k = 0; k < used; k++)
        weight[k] = freq[order[k]];
    for (int j = 0; j < joins; j++) {
        int pick[2];
        for (int p = 0; p < 2; p++) {
            int take_leaf = leaf < used && (join >= j || weight[leaf] <= weight[used + join]);
            pick[p] = take_leaf ? leaf++ : used + join++;
        }
        weight[used + j] = weight[pick[0]] + weight[pick[1]];
        parent[pick[0]] = parent[pick[1]] = used + j;
    }
    int depth[640], count[64] = {0};
    depth[used + joins - 1] = 0;
    for (int k = used + joins - 2; k >= 0; k--)
        depth[k] = depth[parent[k]] + 1;
    for (int k = 0; k < used; k++)
        count[depth[k] < 63 ? depth[k] : 63]++;
    /* Fold codes longer than the limit back (JPEG Annex K.3): two leaves at the deepest
     * length become one a length up and, with a shorter leaf moved down one, a pair. */
    for (int l = 63; l > limit; l--)
        while (count[l] > 0) {
            int j = l - 2;
            while (count[j] == 0)
                j--;
            count[l] -= 2;
            count[l - 1] += 1;
            count[j + 1] += 2;
            count[j] -= 1;
        }
    /* The shortest lengths to the most frequent symbols. */
    int k = used - 1;
    for (int l = 1; l <= limit; l++)
        for (int c = 0; c < count[l]; c++)
            length[order[k--]] = (uint8_t)l;
}

/* Canonical codes (RFC 1951 3.2.2) of the lengths, bit reversed. */
static void canonical_codes(const uint8_t *length, int n, uint32_t *code)
{
    int count[16] = {0};
    uint32_t next[16];
    for (int s = 0; s < n; s++)
        count[length[s]]++;
    count[0] = 0;
    uint32_t c = 0;
    for (int l = 1; l < 16; l++) {
        c = (c + (uint32_t)count[l - 1]) << 1;
        next[l] = c;
    }
    for (int s = 0; s < n; s++) {
        if (!length[s])
            continue;
        uint32_t v = next[length[s]]++, r = 0;
        for (int b = 0; b < length[s]; b++)
            r |= (v >> b & 1) << (length[s] - 1 - b);
        code[s] = r;
    }
}

/* Steps 1-4 for one block of n > 0 bytes. */
static void huffman_block(bit_writer *w, const unsigned char *in, size_t n)
{
    enum { LITERALS = 257, END = 256, CODE_LENGTHS = 19 };
    uint32_t freq[LITERALS] = {0}, part[3][256] = {{0}};
    size_t i = 0;
    for (; i + 4 <= n; i += 4) { /* four tables: no chain of increments on one counter */
        freq[in[i]]++;
        part[0][in[i + 1]]++;
        part[1][in[i + 2]]++;
        part[2][in[i + 3]]++;
    }
    for (; i < n; i++)
        freq[in[i]]++;
    for (int s = 0; s < 256; s++)
        freq[s] += part[0][s] + part[1][s] + part[2][s];
    freq[END] = 1;
    uint8_t length[LITERALS];
    uint32_t code[LITERALS];
    code_lengths(freq, LITERALS, 15, length);
    canonical_codes(length, LITERALS, code);
    /* The code-length code over the 257 literal lengths and the two distance lengths
     * (one bit each: no distance is used, but zlib's decoders want a complete code). */
    uint32_t cl_freq[CODE_LENGTHS] = {0}, cl_code[CODE_LENGTHS];
    uint8_t cl_length[CODE_LENGTHS];
    for (int s = 0; s < LITERALS; s++)
        cl_freq[length[s]]++;
    cl_freq[1] += 2;
    int distinct = 0;
    for (int s = 0; s < CODE_LENGTHS; s++)
        distinct += cl_freq[s] > 0;
    if (distinct < 2) /* every literal the same length as the distances: add one unused */
        cl_freq[cl_freq[0] ? 2 : 0] = 1;
    code_lengths(cl_freq, CODE_LENGTHS, 7, cl_length);
    canonical_codes(cl_length, CODE_LENGTHS, cl_code);
    static const uint8_t cl_order[CODE_LENGTHS] = {16, 17, 18, 0, 8, 7, 9, 6, 10, 5, 11, 4, 12, 3, 13, 2, 14, 1, 15};
    int hclen = CODE_LENGTHS;
    while (hclen > 4 && cl_length[cl_order[hclen - 1]] == 0)
        hclen--;
    bits_put(w, 0 | 2 << 1, 3);                         /* not final, dynamic codes */
    bits_put(w, LITERALS - 257, 5);                     /* HLIT */
    bits_put(w, 2 - 1, 5);                              /* HDIST */
    bits_put(w, (uint32_t)(hclen - 4), 4);              /* HCLEN */
    for (int k = 0; k < hclen; k++)
        bits_put(w, cl_length[cl_order[k]], 3);
    for (int s = 0; s < LITERALS; s++)
        bits_put(w, cl_code[length[s]], cl_length[length[s]]);
    for (int d = 0; d < 2; d++)
        bits_put(w, cl_code[1], cl_length[1]);
    for (i = 0; i < n; i++)
        bits_put(w, code[in[i]], length[in[i]]);
    bits_put(w, code[END], length[END]);
}

/* A Huffman-only piece: its blocks, then the sync flush's empty stored block, or for the
 * last piece an empty final fixed-code block. Returns the bytes written to out, which
 * holds huffman_bound(n). */
static size_t huffman_bound(size_t n)
{
    return n / HUFFMAN_BLOCK * 700 + 700 + n * 15 / 8 + 16;
}

static size_t huffman_piece(const unsigned char *in, size_t n, int last, unsigned char *out)
{
    bit_writer w = {.out = out};
    for (size_t at = 0; at < n; at += HUFFMAN_BLOCK)
        huffman_block(&w, in + at, n - at < HUFFMAN_BLOCK ? n - at : HUFFMAN_BLOCK);
    if (last) {
        bits_put(&w, 1 | 1 << 1, 3); /* final, fixed codes: the end-of-block code alone */
        bits_put(&w, 0, 7);
    } else {
        bits_put(&w, 0, 3); /* a stored block of no bytes */
        bits_flush(&w);
        bits_put(&w, 0xffff0000u, 32);
    }
    bits_flush(&w);
    return (size_t)(w.out - out);
}

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
    if (d->huffman) {
        d->out = malloc(huffman_bound(d->size));
        if (!d->out) {
            d->rc = ISO_E_NOMEM;
            return;
        }
        d->out_size = huffman_piece(d->in, d->size, d->last, d->out);
        d->crc = crc32_z(0, d->in, d->size);
        return;
    }
    z_stream z = {0};
    /* Level 1, the fastest; raw deflate (-15): the gzip wrapper is written around the
     * joined pieces. */
    if (deflateInit2(&z, 1, Z_DEFLATED, -15, 8, Z_DEFAULT_STRATEGY) != Z_OK) {
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
