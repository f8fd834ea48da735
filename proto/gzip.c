/* gzip.c: a gzip member (RFC 1952) of a whole buffer, for HTTP's Content-Encoding: gzip
 * (see encode.h).
 *
 * The buffer may be cut into pieces, each with its own strategy, and a Huffman-only piece
 * into parts of whole blocks; each part is deflated on its own (proto_deflate_run: raw
 * deflate, the parts but the last ending in a sync flush, so that they join byte-aligned
 * into one stream, as pigz does), the threads taking the costliest left first; then the
 * header, the joined stream, and the trailer (the CRC-32 and length of the whole input,
 * combined).
 *
 * Both strategies are coded here as RFC 1951 dynamic blocks, one per BLOCK_BYTES of input
 * (a table per 64 KB follows the vertex streams' changes, positions then normals, for
 * about 100 bytes of header each):
 * - Huffman only: literals, for bytes with few repeats (zlib's Huffman-only mode still
 *   runs its match loop's bookkeeping per byte, about 4 times this coder's time);
 * - matches: greedy LZ77 in the manner of the fastest levels of libdeflate and zlib-ng,
 *   which suits the index codec's repeats: one hash probe of the next 4 bytes, a 32 KB
 *   window, the match taken whole (up to 258 bytes) and each of its bytes hashed too, so
 *   that later matches may start inside it (10% fewer bytes on the index codes for 12%
 *   more time).
 * A block is written in passes:
 *   1. parse: the block's symbols (literals, or for matches also lengths and distances,
 *      one 32-bit item each) and their counts;
 *   2. code lengths: Huffman's two-queue construction over the counts sorted, then
 *      lengths past 15 bits folded back (JPEG's Annex K.3 adjustment of the counts per
 *      length), handed out to the symbols in order of count; canonical codes, bit
 *      reversed (deflate writes codes from their first bit);
 *   3. the block header: the literal/length and distance code lengths, themselves coded
 *      with a code-length code (lengths up to 7 bits, no run-length symbols);
 *   4. the symbols' codes and extra bits, and the end-of-block code;
 * and a piece that is not the last ends with an empty stored block (the sync flush). */
#include "encode.h"

#include <assert.h>
#include <stdatomic.h>
#include <stdint.h>
#include <stdlib.h>
#include <string.h>
#include <zlib.h>
#if defined(__x86_64__) && defined(__GNUC__)
#include <immintrin.h>
#endif

#include "base/base.h"
#include "gzip_parts.h"

/* Below this many bytes one thread deflates every piece: another thread's share would
 * cost more to hand over than to do. */
#define GZIP_BYTES_PER_THREAD (1u << 20)

/* Input bytes per block (see the top). */
#define BLOCK_BYTES (64u << 10)

/* The matcher: positions hashed by their next 4 bytes into 2^LZ_HASH_BITS slots (one
 * probe each); deflate's window and longest match. */
#define LZ_HASH_BITS 15
#define LZ_MIN 4
#define LZ_WINDOW 32768u
#define LZ_MAX 258u
/* Past 2^LZ_SKIP_AFTER misses in a row the probes thin out (as LZ4's do): on bytes with
 * long stretches without repeats (the meshopt index codec's data bytes, measured) a probe
 * per byte cost 19% more time for 2.3% fewer bytes; on the index codes it changes
 * neither. */
#define LZ_SKIP_AFTER 3

enum { LITERALS = 257, END = 256, LENGTH_CODES = 29, LITLEN = LITERALS + LENGTH_CODES, DISTANCES = 30,
       CODE_LENGTHS = 19 };

/* Bits out, first bit first (deflate's order). After bits_flush at most 7 bits wait, so
 * 56 more may be put before the next flush; a flush stores 8 bytes, so the output needs
 * 8 bytes of slack past its bound. */
typedef struct bit_writer {
    unsigned char *out;
    uint64_t bits;
    unsigned count;
} bit_writer;

static inline void bits_put(bit_writer *w, uint32_t value, unsigned n)
{
    w->bits |= (uint64_t)value << w->count;
    w->count += n;
}

static inline void bits_flush(bit_writer *w)
{
    memcpy(w->out, &w->bits, 8); /* little-endian, as every target of this server */
    w->out += w->count >> 3;
    w->bits >>= w->count & ~7u;
    w->count &= 7;
}

/* Pads to a byte boundary and writes what is left. */
static void bits_align(bit_writer *w)
{
    bits_flush(w);
    if (w->count) {
        *w->out++ = (unsigned char)w->bits;
        w->bits = 0;
        w->count = 0;
    }
}

/* Step 2: code lengths (at most `limit` bits) for n symbols of counts `freq` (0: unused,
 * length 0), at least two of them used. */
static void code_lengths(const uint32_t *freq, int n, int limit, uint8_t *length)
{
    /* The used symbols by count, ascending, ties by symbol: a radix sort, a stable pass
     * per byte of the counts (two bytes but in a block of one value repeated). */
    int order[320], spare[320], used = 0, high = 0;
    for (int s = 0; s < n; s++) {
        length[s] = 0;
        if (freq[s]) {
            order[used++] = s;
            high |= freq[s] >= 1u << 16;
        }
    }
    for (int pass = 0; pass < (high ? 4 : 2); pass++) {
        int start[257] = {0};
        int shift = 8 * pass;
        for (int k = 0; k < used; k++)
            start[(freq[order[k]] >> shift & 255) + 1]++;
        for (int b = 0; b < 256; b++)
            start[b + 1] += start[b];
        for (int k = 0; k < used; k++)
            spare[start[freq[order[k]] >> shift & 255]++] = order[k];
        memcpy(order, spare, (size_t)used * sizeof *order);
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

/* A block's codes: literal/length symbols and distances. */
typedef struct block_codes {
    uint8_t lit_length[LITLEN], dist_length[DISTANCES];
    uint32_t lit_code[LITLEN], dist_code[DISTANCES];
} block_codes;

/* At least two symbols of a code used (zlib's decoders want a complete code), so that
 * code_lengths has a tree to build. */
static void two_used(uint32_t *freq, int n)
{
    int used = 0;
    for (int s = 0; s < n && used < 2; s++)
        used += freq[s] > 0;
    for (int s = 0; s < n && used < 2; s++)
        if (!freq[s])
            freq[s] = 1, used++;
}

/* Steps 2 and 3: the codes of the counts (lit_freq's END set), nlit literal/length and
 * ndist distance symbols, and the block header (not final, dynamic). */
static void block_header(bit_writer *w, uint32_t *lit_freq, int nlit, uint32_t *dist_freq, int ndist,
                         block_codes *c)
{
    two_used(lit_freq, nlit);
    two_used(dist_freq, ndist);
    code_lengths(lit_freq, nlit, 15, c->lit_length);
    canonical_codes(c->lit_length, nlit, c->lit_code);
    code_lengths(dist_freq, ndist, 15, c->dist_length);
    canonical_codes(c->dist_length, ndist, c->dist_code);
    uint32_t cl_freq[CODE_LENGTHS] = {0}, cl_code[CODE_LENGTHS];
    uint8_t cl_length[CODE_LENGTHS];
    for (int s = 0; s < nlit; s++)
        cl_freq[c->lit_length[s]]++;
    for (int s = 0; s < ndist; s++)
        cl_freq[c->dist_length[s]]++;
    two_used(cl_freq, CODE_LENGTHS);
    code_lengths(cl_freq, CODE_LENGTHS, 7, cl_length);
    canonical_codes(cl_length, CODE_LENGTHS, cl_code);
    static const uint8_t cl_order[CODE_LENGTHS] = {16, 17, 18, 0, 8, 7, 9, 6, 10, 5, 11, 4, 12, 3, 13, 2, 14, 1, 15};
    int hclen = CODE_LENGTHS;
    while (hclen > 4 && cl_length[cl_order[hclen - 1]] == 0)
        hclen--;
    bits_put(w, 0 | 2 << 1, 3);                 /* not final, dynamic codes */
    bits_put(w, (uint32_t)(nlit - 257), 5);     /* HLIT */
    bits_put(w, (uint32_t)(ndist - 1), 5);      /* HDIST */
    bits_put(w, (uint32_t)(hclen - 4), 4);      /* HCLEN */
    bits_flush(w);
    for (int k = 0; k < hclen; k++) {
        bits_put(w, cl_length[cl_order[k]], 3);
        if (k == 9) /* 19 lengths of 3 bits and 7 waiting would fill all 64 */
            bits_flush(w);
    }
    bits_flush(w);
    for (int s = 0; s < nlit + ndist; s++) {
        uint8_t l = s < nlit ? c->lit_length[s] : c->dist_length[s - nlit];
        bits_put(w, cl_code[l], cl_length[l]);
        bits_flush(w);
    }
}

/* Counts of n bytes into freq (added). */
static void count_bytes(const unsigned char *in, size_t n, uint32_t *freq)
{
    uint32_t part[3][256] = {{0}};
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
}

/* A Huffman-only block of n > 0 bytes: steps 1-4. */
static void huffman_block(bit_writer *w, const unsigned char *in, size_t n)
{
    uint32_t freq[LITERALS] = {0}, dist_freq[2] = {1, 1};
    count_bytes(in, n, freq);
    freq[END] = 1;
    block_codes c;
    block_header(w, freq, LITERALS, dist_freq, 2, &c);
    /* Four codes per flush when none is longer than 14 bits, else three (56 bits free).
     * Code and length merged, so that one load gives both. */
    uint32_t code[LITERALS];
    int longest = 0;
    for (int s = 0; s < LITERALS; s++) {
        code[s] = c.lit_code[s] | (uint32_t)c.lit_length[s] << 16;
        longest = c.lit_length[s] > longest ? c.lit_length[s] : longest;
    }
    size_t i = 0;
    for (; longest <= 14 && i + 4 <= n; i += 4) {
        uint32_t a = code[in[i]], b = code[in[i + 1]], d = code[in[i + 2]], e = code[in[i + 3]];
        bits_put(w, a & 0xffff, a >> 16);
        bits_put(w, b & 0xffff, b >> 16);
        bits_put(w, d & 0xffff, d >> 16);
        bits_put(w, e & 0xffff, e >> 16);
        bits_flush(w);
    }
    for (; i + 3 <= n; i += 3) {
        uint32_t a = code[in[i]], b = code[in[i + 1]], d = code[in[i + 2]];
        bits_put(w, a & 0xffff, a >> 16);
        bits_put(w, b & 0xffff, b >> 16);
        bits_put(w, d & 0xffff, d >> 16);
        bits_flush(w);
    }
    for (; i < n; i++) {
        bits_put(w, code[in[i]] & 0xffff, code[in[i]] >> 16);
        bits_flush(w);
    }
    bits_put(w, c.lit_code[END], c.lit_length[END]);
    bits_flush(w);
}

/* Extra bits of each length symbol (from 257) and distance symbol (RFC 1951 3.2.5). */
static const uint8_t length_extra[LENGTH_CODES] = {0, 0, 0, 0, 0, 0, 0, 0, 1, 1, 1, 1, 2, 2, 2,
                                                   2, 3, 3, 3, 3, 4, 4, 4, 4, 5, 5, 5, 5, 0};
static const uint8_t dist_extra[DISTANCES] = {0, 0, 0, 0, 1, 1, 2, 2, 3, 3, 4, 4, 5, 5, 6,
                                              6, 7, 7, 8, 8, 9, 9, 10, 10, 11, 11, 12, 12, 13, 13};

/* A match as one item: its length symbol (bits 0-8), length extra (9-13), distance
 * symbol (14-18), distance extra (19-31); a literal is its byte. Symbols by the bit
 * patterns of RFC 1951's tables: from 8 up (lengths) and 4 up (distances), each power of
 * two takes 4 (2) symbols, picked by the bits below the highest. */
static inline uint32_t match_item(unsigned length, unsigned distance)
{
    unsigned l = length - 3, sym = 257 + l, lext = 0;
    if (length == LZ_MAX) {
        sym = 285;
    } else if (l >= 8) {
        unsigned b = 31 - (unsigned)__builtin_clz(l), bits = b - 2;
        sym = 257 + 4 * (b - 1) + (l >> bits & 3);
        lext = l & ((1u << bits) - 1);
    }
    unsigned d = distance - 1, dsym = d, dext = 0;
    if (d >= 4) {
        unsigned b = 31 - (unsigned)__builtin_clz(d), bits = b - 1;
        dsym = 2 * b + (d >> bits & 1);
        dext = d & ((1u << bits) - 1);
    }
    return sym | lext << 9 | dsym << 14 | dext << 19;
}

static inline uint32_t load32(const unsigned char *p)
{
    uint32_t v;
    memcpy(&v, p, 4);
    return v;
}

static inline uint64_t load64(const unsigned char *p)
{
    uint64_t v;
    memcpy(&v, p, 8);
    return v;
}

/* The length of the match of in[at..] with in[from..] (from < at), 4 bytes known equal,
 * at most max. */
static inline size_t match_length(const unsigned char *in, size_t from, size_t at, size_t max)
{
    size_t n = LZ_MIN;
    for (; n + 8 <= max; n += 8) {
        uint64_t x = load64(in + at + n) ^ load64(in + from + n);
        if (x)
            return n + ((unsigned)__builtin_ctzll(x) >> 3);
    }
    while (n < max && in[at + n] == in[from + n])
        n++;
    return n;
}

/* The matcher's state across a piece's blocks. */
typedef struct matcher {
    uint32_t head[1u << LZ_HASH_BITS]; /* the last position with each hash (0 at first: a
                                          real position, checked like any other) */
    uint32_t items[BLOCK_BYTES + LZ_MAX];
} matcher;

/* Step 1 for a block of matches: the items from `at` until the block's end (a match may
 * run past it) and their counts; returns the position after the last item. */
static size_t lz_parse(matcher *m, const unsigned char *in, size_t size, size_t at, size_t end, size_t *count,
                       uint32_t *lit_freq, uint32_t *dist_freq)
{
    size_t k = 0, misses = 0;
    while (at < end) {
        if (at + LZ_MIN > size) { /* the last bytes: no match fits */
            lit_freq[in[at]]++;
            m->items[k++] = in[at++];
            continue;
        }
        uint32_t v = load32(in + at), h = (v * 2654435761u) >> (32 - LZ_HASH_BITS);
        size_t from = m->head[h];
        m->head[h] = (uint32_t)at;
        if (at - from - 1 < LZ_WINDOW && load32(in + from) == v) {
            size_t left = size - at, n = match_length(in, from, at, left < LZ_MAX ? left : LZ_MAX);
            uint32_t item = match_item((unsigned)n, (unsigned)(at - from));
            lit_freq[item & 511]++;
            dist_freq[item >> 14 & 31]++;
            m->items[k++] = item;
            for (size_t j = 1; j < n && at + j + LZ_MIN <= size; j++) {
                uint32_t w = load32(in + at + j);
                m->head[(w * 2654435761u) >> (32 - LZ_HASH_BITS)] = (uint32_t)(at + j);
            }
            at += n;
            misses = 0;
        } else { /* after 8 misses in a row, probe every other byte; after 16, every third... */
            size_t step = 1 + (misses++ >> LZ_SKIP_AFTER);
            for (size_t j = 0; j < step && at < end; j++) {
                lit_freq[in[at]]++;
                m->items[k++] = in[at++];
            }
        }
    }
    *count = k;
    return at;
}

/* Step 4 for a block of matches. */
static void lz_write(bit_writer *w, const uint32_t *items, size_t count, const block_codes *c)
{
    for (size_t k = 0; k < count; k++) {
        uint32_t item = items[k], sym = item & 511;
        bits_put(w, c->lit_code[sym], c->lit_length[sym]);
        if (sym > END) {
            uint32_t dsym = item >> 14 & 31;
            bits_put(w, item >> 9 & 31, length_extra[sym - 257]);
            bits_put(w, c->dist_code[dsym], c->dist_length[dsym]);
            bits_put(w, item >> 19, dist_extra[dsym]);
        }
        bits_flush(w);
    }
    bits_put(w, c->lit_code[END], c->lit_length[END]);
    bits_flush(w);
}

/* The bytes a piece of n bytes may take, either strategy: at most 15 bits a literal and
 * 48 bits a match of 4 bytes or more, a header per block, the ending, the flush's slack. */
size_t proto_deflate_bound(size_t n)
{
    return n / BLOCK_BYTES * 700 + 700 + n * 15 / 8 + 32;
}

/* A piece's blocks, then the sync flush's empty stored block, or for the last piece an
 * empty final fixed-code block. m NULL: Huffman only. Returns the bytes written to out,
 * which holds proto_deflate_bound(n). */
static size_t deflate_blocks(const unsigned char *in, size_t n, int last, matcher *m, unsigned char *out)
{
    bit_writer w = {.out = out};
    if (m)
        memset(m->head, 0, sizeof m->head);
    for (size_t at = 0; at < n;) {
        size_t end = n - at < BLOCK_BYTES ? n : at + BLOCK_BYTES;
        if (!m) {
            huffman_block(&w, in + at, end - at);
            at = end;
            continue;
        }
        uint32_t lit_freq[LITLEN] = {0}, dist_freq[DISTANCES] = {0};
        size_t count;
        at = lz_parse(m, in, n, at, end, &count, lit_freq, dist_freq);
        lit_freq[END] = 1;
        block_codes c;
        block_header(&w, lit_freq, LITLEN, dist_freq, DISTANCES, &c);
        lz_write(&w, m->items, count, &c);
    }
    if (last) {
        bits_put(&w, 1 | 1 << 1, 3); /* final, fixed codes: the end-of-block code alone */
        bits_put(&w, 0, 7);
    } else {
        bits_put(&w, 0, 3); /* a stored block of no bytes */
        bits_align(&w);
        bits_put(&w, 0xffff0000u, 32);
    }
    bits_align(&w);
    return (size_t)(w.out - out);
}

/* The CRC-32 of n bytes (gzip's, zlib's crc32_z). With PCLMULQDQ the bulk is folded 64
 * bytes at a time by carry-less products (Intel's "Fast CRC Computation for Generic
 * Polynomials Using PCLMULQDQ"; the constants are x^(k*32) mod P for the fold distances,
 * then a Barrett reduction), about 5 times as fast as zlib's tables; zlib does the rest. */
#if defined(__x86_64__) && defined(__GNUC__)
__attribute__((target("pclmul,sse4.1"))) static uint32_t crc_fold(const unsigned char *p, size_t n, uint32_t crc)
{
    const __m128i k1k2 = _mm_set_epi64x(0x01c6e41596, 0x0154442bd4), k3k4 = _mm_set_epi64x(0x00ccaa009e, 0x01751997d0),
                  k5 = _mm_set_epi64x(0, 0x0163cd6124), poly = _mm_set_epi64x(0x01f7011641, 0x01db710641),
                  low32 = _mm_setr_epi32(~0, 0, ~0, 0);
    /* n >= 64, a multiple of 16; crc is the inverted running value. */
    __m128i x1 = _mm_loadu_si128((const __m128i *)p), x2 = _mm_loadu_si128((const __m128i *)(p + 16)),
            x3 = _mm_loadu_si128((const __m128i *)(p + 32)), x4 = _mm_loadu_si128((const __m128i *)(p + 48));
    x1 = _mm_xor_si128(x1, _mm_cvtsi32_si128((int)crc));
    for (p += 64, n -= 64; n >= 64; p += 64, n -= 64) {
        __m128i a = _mm_clmulepi64_si128(x1, k1k2, 0x00), b = _mm_clmulepi64_si128(x2, k1k2, 0x00),
                c = _mm_clmulepi64_si128(x3, k1k2, 0x00), d = _mm_clmulepi64_si128(x4, k1k2, 0x00);
        x1 = _mm_xor_si128(_mm_xor_si128(_mm_clmulepi64_si128(x1, k1k2, 0x11), a), _mm_loadu_si128((const __m128i *)p));
        x2 = _mm_xor_si128(_mm_xor_si128(_mm_clmulepi64_si128(x2, k1k2, 0x11), b),
                           _mm_loadu_si128((const __m128i *)(p + 16)));
        x3 = _mm_xor_si128(_mm_xor_si128(_mm_clmulepi64_si128(x3, k1k2, 0x11), c),
                           _mm_loadu_si128((const __m128i *)(p + 32)));
        x4 = _mm_xor_si128(_mm_xor_si128(_mm_clmulepi64_si128(x4, k1k2, 0x11), d),
                           _mm_loadu_si128((const __m128i *)(p + 48)));
    }
    /* Four lanes folded into one, then the 16-byte blocks left. */
    __m128i next[3] = {x2, x3, x4};
    for (int k = 0; k < 3; k++)
        x1 = _mm_xor_si128(_mm_xor_si128(_mm_clmulepi64_si128(x1, k3k4, 0x11), _mm_clmulepi64_si128(x1, k3k4, 0x00)),
                           next[k]);
    for (; n >= 16; p += 16, n -= 16)
        x1 = _mm_xor_si128(_mm_xor_si128(_mm_clmulepi64_si128(x1, k3k4, 0x11), _mm_clmulepi64_si128(x1, k3k4, 0x00)),
                           _mm_loadu_si128((const __m128i *)p));
    /* 128 bits to 64, then 64 to 32 (Barrett). */
    x2 = _mm_clmulepi64_si128(x1, k3k4, 0x10);
    x1 = _mm_xor_si128(_mm_srli_si128(x1, 8), x2);
    x2 = _mm_srli_si128(x1, 4);
    x1 = _mm_xor_si128(_mm_clmulepi64_si128(_mm_and_si128(x1, low32), k5, 0x00), x2);
    x2 = _mm_clmulepi64_si128(_mm_and_si128(x1, low32), poly, 0x10);
    x2 = _mm_clmulepi64_si128(_mm_and_si128(x2, low32), poly, 0x00);
    return (uint32_t)_mm_extract_epi32(_mm_xor_si128(x1, x2), 1);
}

static uLong crc_of(const unsigned char *p, size_t n)
{
    uLong crc = 0;
    if (n >= 64 && __builtin_cpu_supports("pclmul") && __builtin_cpu_supports("sse4.1")) {
        size_t bulk = n & ~(size_t)15;
        crc = ~crc_fold(p, bulk, ~0u) & 0xffffffffu;
        p += bulk, n -= bulk;
    }
    return crc32_z(crc, p, n);
}
#else
static uLong crc_of(const unsigned char *p, size_t n)
{
    return crc32_z(0, p, n);
}
#endif

/* At most this many parts (the Huffman-only ones of at least PART_BYTES, more for a
 * large buffer, see proto_gzip_pieces). */
#define PARTS_MAX (32 + 2 * PROTO_GZIP_PIECES_MAX)
#define PART_BYTES (256u << 10)

void proto_deflate_run(proto_deflate *d)
{
    matcher *m = d->huffman ? NULL : malloc(sizeof *m);
    if (!d->huffman && !m) {
        d->rc = ISO_E_NOMEM;
        return;
    }
    d->out_size = deflate_blocks(d->in, d->size, d->last, m, d->out);
    free(m);
    d->crc = crc_of(d->in, d->size);
}

/* The parts, taken by the threads in order of cost, each the next one left: a thread
 * that starts late (a busy machine) takes what remains, and none waits on a share that
 * another has not begun. */
typedef struct gzip_job {
    proto_deflate *parts;
    int order[PARTS_MAX];
    int count;
    atomic_int next;
} gzip_job;

static void gzip_share(void *context, int t, int threads)
{
    (void)t, (void)threads;
    gzip_job *job = context;
    for (int k; (k = atomic_fetch_add(&job->next, 1)) < job->count;)
        proto_deflate_run(&job->parts[job->order[k]]);
}

/* A part's cost, in Huffman-coded bytes: matching costs about 3 times as much a byte. */
static size_t part_cost(const proto_deflate *d)
{
    return d->huffman ? d->size : 3 * d->size;
}

enum { GZIP_HEADER = 10, GZIP_TRAILER = 8 };

/* The member at buf: the header, the parts' deflate streams in order (each moved down from
 * where it was deflated, which may be in buf, at or after its place), the trailer (the
 * CRC-32 of the whole input combined from the parts', and its length). Returns its size. */
static size_t member(const proto_deflate *d, int count, unsigned char *buf)
{
    /* The header: magic, deflate, no flags, no time, fastest (XFL 4), Unix. */
    static const unsigned char header[GZIP_HEADER] = {0x1f, 0x8b, 8, 0, 0, 0, 0, 0, 4, 3};
    memcpy(buf, header, sizeof header);
    size_t at = sizeof header, size = 0;
    uLong crc = 0;
    for (int i = 0; i < count; i++) {
        memmove(buf + at, d[i].out, d[i].out_size);
        at += d[i].out_size;
        crc = crc32_combine(crc, d[i].crc, (z_off_t)d[i].size);
        size += d[i].size;
    }
    for (int b = 0; b < 4; b++)
        buf[at++] = (unsigned char)(crc >> (8 * b));
    for (int b = 0; b < 4; b++)
        buf[at++] = (unsigned char)((uint32_t)size >> (8 * b));
    return at;
}

int proto_gzip_pieces(const unsigned char *in, size_t size, const proto_gzip_piece *pieces, int count,
                      int threads, unsigned char **out, size_t *out_size, iso_error *err)
{
    assert(in && out && out_size && count >= 1 && count <= PROTO_GZIP_PIECES_MAX);
    *out = NULL;
    *out_size = 0;
    if (size > UINT32_MAX)
        return iso_error_set(err, ISO_E_LIMIT, "gzip: cannot compress %zu bytes", size);
    /* One buffer: the header, each part's room (its bound), the trailer; the parts are
     * moved down against each other when done. */
    size_t part_bytes = (size / 32 + BLOCK_BYTES - 1) / BLOCK_BYTES * BLOCK_BYTES;
    part_bytes = part_bytes > PART_BYTES ? part_bytes : PART_BYTES;
    proto_deflate d[PARTS_MAX];
    gzip_job job = {.parts = d};
    size_t from = 0, room = GZIP_HEADER;
    for (int i = 0; i < count; i++) {
        size_t end = i == count - 1 ? size : pieces[i].end;
        assert(end >= from && end <= size);
        do { /* at least one part, if empty */
            size_t n = pieces[i].huffman && end - from > part_bytes ? part_bytes : end - from;
            assert(job.count < PARTS_MAX);
            d[job.count++] = (proto_deflate){.in = in + from, .size = n, .huffman = pieces[i].huffman,
                                        .last = i == count - 1 && from + n == end};
            room += proto_deflate_bound(n);
            from += n;
        } while (from < end);
    }
    unsigned char *buf = malloc(room + GZIP_TRAILER);
    if (!buf)
        return iso_error_set(err, ISO_E_NOMEM, "gzip: no memory to compress %zu bytes", size);
    d[0].out = buf + GZIP_HEADER;
    for (int i = 1; i < job.count; i++)
        d[i].out = d[i - 1].out + proto_deflate_bound(d[i - 1].size);
    for (int i = 0; i < job.count; i++) { /* costliest first: insertion, a few dozen */
        int k = i;
        for (; k > 0 && part_cost(&d[job.order[k - 1]]) < part_cost(&d[i]); k--)
            job.order[k] = job.order[k - 1];
        job.order[k] = i;
    }
    atomic_init(&job.next, 0);
    threads = size < GZIP_BYTES_PER_THREAD ? 1 : iso_parallel_threads(threads);
    iso_parallel_run(threads < job.count ? threads : job.count, gzip_share, &job);
    int rc = 0;
    for (int i = 0; i < job.count; i++)
        rc = rc ? rc : d[i].rc;
    if (rc) {
        free(buf);
        return iso_error_set(err, rc, "gzip: no memory to compress %zu bytes", size);
    }
    size_t at = member(d, job.count, buf);
    unsigned char *fit = realloc(buf, at); /* gives back the rooms' unused ends */
    *out = fit ? fit : buf;
    *out_size = at;
    return 0;
}

int proto_gzip_join(const proto_deflate *parts, int count, unsigned char **out, size_t *out_size,
                    iso_error *err)
{
    assert(parts && count >= 1 && out && out_size && parts[count - 1].last);
    *out = NULL;
    *out_size = 0;
    size_t room = GZIP_HEADER + GZIP_TRAILER, size = 0;
    for (int i = 0; i < count; i++) {
        if (parts[i].rc)
            return iso_error_set(err, parts[i].rc, "gzip: no memory to compress a part of %zu bytes", parts[i].size);
        room += parts[i].out_size;
        size += parts[i].size;
    }
    if (size > UINT32_MAX)
        return iso_error_set(err, ISO_E_LIMIT, "gzip: cannot compress %zu bytes", size);
    unsigned char *buf = malloc(room);
    if (!buf)
        return iso_error_set(err, ISO_E_NOMEM, "gzip: no memory for a member of %zu bytes", room);
    *out_size = member(parts, count, buf);
    *out = buf;
    return 0;
}

int proto_gzip(const unsigned char *in, size_t size, unsigned char **out, size_t *out_size,
               iso_error *err)
{
    proto_gzip_piece whole = {.end = size};
    return proto_gzip_pieces(in, size, &whole, 1, 1, out, out_size, err);
}
