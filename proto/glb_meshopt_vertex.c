/* glb_meshopt_vertex.c: meshoptimizer's vertex codec, version 0 (EXT_meshopt_compression's
 * ATTRIBUTES mode), encoded byte for byte as meshopt_encodeVertexBuffer writes it (checked
 * against it in test_proto_encode). The library gathers each byte of the vertex with a
 * strided load, then measures each group of 16 deltas once per bit width; here 16
 * vertices at a time are loaded whole (SSE2; a plain loop elsewhere), their byte deltas
 * zigzagged in registers and transposed to one register per byte, and a group's three
 * sizes come from two compares and a popcount.
 *
 * The stream: a header byte, then blocks of up to 256 vertices (8 KB / stride, a multiple
 * of 16); in each block, per byte of the vertex:
 *   1. deltas: each vertex's byte minus the previous vertex's (the last block's last
 *      vertex before the first; the first vertex before the stream), zigzagged (0, -1, 1,
 *      -2 .. as 0, 1, 2, 3 ..), padded with zeros to a multiple of 16;
 *   2. a header of 2 bits per group of 16, the group's width: 0 (all zero), 2 or 4 bits
 *      (values at or above the width's all-ones sentinel stored whole after the packed
 *      ones), or 8; the smallest, the narrower on a tie, as the library measures them;
 *   3. each group's packed bits (first value in the high bits) and whole bytes;
 * then the first vertex, after zeros up to 32 bytes. */
#include "glb_meshopt_codec.h"

#include <string.h>

#if defined(__SSE2__) && !defined(PROTO_MESHOPT_SCALAR)
#define MESHOPT_SSE2 1
#include <emmintrin.h>
#endif

enum {
    VERTEX_HEADER = 0xa0, /* version 0 */
    GROUP = 16,
    BLOCK_BYTES = 8192,
    BLOCK_MAX = 256,
    TAIL = 32
};

static size_t block_vertices(size_t stride)
{
    size_t n = (BLOCK_BYTES / stride) & ~(size_t)(GROUP - 1);
    return n < BLOCK_MAX ? n : BLOCK_MAX;
}

static inline unsigned char zigzag(unsigned char d)
{
    return (unsigned char)((unsigned char)(d << 1) ^ (unsigned char)-(d >> 7));
}

/* Step 1 for one byte k of the block's n vertices into deltas[0..n rounded up to 16). */
static void deltas_scalar(const unsigned char *v, size_t n, size_t stride, size_t k, unsigned char prev,
                          unsigned char *deltas)
{
    size_t i = 0;
    for (; i < n; i++) {
        unsigned char x = v[i * stride + k];
        deltas[i] = zigzag((unsigned char)(x - prev));
        prev = x;
    }
    for (; i % GROUP; i++)
        deltas[i] = 0;
}

#if MESHOPT_SSE2
/* Step 1 for all 8 bytes of 16 vertices of stride 8 (v), the vertex before them at
 * v - 8 (or `before` for the stream's first): out[k * BLOCK_MAX] gets byte k's deltas. */
static void deltas_sse2_stride8(const unsigned char *v, const unsigned char *before, unsigned char *out)
{
    __m128i zero = _mm_setzero_si128(), r[8];
    for (int j = 0; j < 8; j++) {
        __m128i cur = _mm_loadu_si128((const __m128i *)(v + 16 * j));
        __m128i prev = j == 0 ? _mm_unpacklo_epi64(_mm_loadl_epi64((const __m128i *)before), cur)
                              : _mm_loadu_si128((const __m128i *)(v + 16 * j - 8));
        __m128i d = _mm_sub_epi8(cur, prev);
        r[j] = _mm_xor_si128(_mm_add_epi8(d, d), _mm_cmpgt_epi8(zero, d)); /* zigzag */
    }
    /* r[j] holds vertices 2j, 2j+1 (8 bytes each). Bytes of vertices 4q..4q+3 per byte k,
     * then 32-bit lanes across the four quads. */
    __m128i lo[4], hi[4];
    for (int q = 0; q < 4; q++) {
        __m128i a = _mm_unpacklo_epi8(r[2 * q], r[2 * q + 1]), b = _mm_unpackhi_epi8(r[2 * q], r[2 * q + 1]);
        lo[q] = _mm_unpacklo_epi8(a, b); /* bytes 0..3, four vertices each */
        hi[q] = _mm_unpackhi_epi8(a, b); /* bytes 4..7 */
    }
    for (int h = 0; h < 2; h++) {
        __m128i *x = h ? hi : lo;
        __m128i t0 = _mm_unpacklo_epi32(x[0], x[1]), t1 = _mm_unpacklo_epi32(x[2], x[3]);
        __m128i t2 = _mm_unpackhi_epi32(x[0], x[1]), t3 = _mm_unpackhi_epi32(x[2], x[3]);
        _mm_storeu_si128((__m128i *)(out + (4 * h + 0) * BLOCK_MAX), _mm_unpacklo_epi64(t0, t1));
        _mm_storeu_si128((__m128i *)(out + (4 * h + 1) * BLOCK_MAX), _mm_unpackhi_epi64(t0, t1));
        _mm_storeu_si128((__m128i *)(out + (4 * h + 2) * BLOCK_MAX), _mm_unpacklo_epi64(t2, t3));
        _mm_storeu_si128((__m128i *)(out + (4 * h + 3) * BLOCK_MAX), _mm_unpackhi_epi64(t2, t3));
    }
}

/* Bit i set where group value i is at least `floor` (unsigned). */
static inline unsigned at_least(__m128i g, unsigned char floor)
{
    __m128i f = _mm_set1_epi8((char)floor);
    return (unsigned)_mm_movemask_epi8(_mm_cmpeq_epi8(_mm_max_epu8(g, f), g));
}
#endif

/* The masks of a group's values at least 1, 3 and 15. */
static inline void group_masks(const unsigned char *g, unsigned *nonzero, unsigned *over2, unsigned *over4)
{
#if MESHOPT_SSE2
    __m128i x = _mm_loadu_si128((const __m128i *)g);
    *nonzero = at_least(x, 1), *over2 = at_least(x, 3), *over4 = at_least(x, 15);
#else
    unsigned a = 0, b = 0, c = 0;
    for (int i = 0; i < GROUP; i++) {
        a |= (unsigned)(g[i] >= 1) << i;
        b |= (unsigned)(g[i] >= 3) << i;
        c |= (unsigned)(g[i] >= 15) << i;
    }
    *nonzero = a, *over2 = b, *over4 = c;
#endif
}

/* The set bits of a group's 16-bit mask, in registers: without -mpopcnt the compiler's
 * __builtin_popcount is a call into libgcc, which cost more than the rest of the group's
 * sizing. */
static inline unsigned popcount16(unsigned x)
{
    x -= x >> 1 & 0x5555u;
    x = (x & 0x3333u) + (x >> 2 & 0x3333u);
    x = (x + (x >> 4)) & 0x0f0fu;
    return (x + (x >> 8)) & 0x1fu;
}

/* Step 3's packed bits of a group at 2 or 4 bits a value (each capped at the all-ones
 * sentinel, first value in the high bits); returns the end of the 4 or 8 bytes written. */
static inline unsigned char *pack_group(unsigned char *data, const unsigned char *g, int bits)
{
#if MESHOPT_SSE2
    /* Neighbours joined in 16-bit lanes (the first shifted up), then for 2 bits the pairs
     * so made in 32-bit lanes, then the lanes narrowed to bytes. */
    __m128i x = _mm_min_epu8(_mm_loadu_si128((const __m128i *)g), _mm_set1_epi8((char)((1 << bits) - 1)));
    __m128i low16 = _mm_set1_epi16(0xff);
    if (bits == 4) {
        __m128i t = _mm_and_si128(_mm_or_si128(_mm_slli_epi16(x, 4), _mm_srli_epi16(x, 8)), low16);
        _mm_storel_epi64((__m128i *)(void *)data, _mm_packus_epi16(t, t));
        return data + 8;
    }
    __m128i t = _mm_and_si128(_mm_or_si128(_mm_slli_epi16(x, 2), _mm_srli_epi16(x, 8)), low16);
    __m128i u = _mm_and_si128(_mm_or_si128(_mm_slli_epi32(t, 4), _mm_srli_epi32(t, 16)), _mm_set1_epi32(0xff));
    __m128i w = _mm_packs_epi32(u, u);
    uint32_t four = (uint32_t)_mm_cvtsi128_si32(_mm_packus_epi16(w, w));
    memcpy(data, &four, 4);
    return data + 4;
#else
    unsigned sentinel = (1u << bits) - 1;
    for (int j = 0; j < GROUP; j += 8 / bits) {
        unsigned byte = 0;
        for (int k = 0; k < 8 / bits; k++)
            byte = byte << bits | (g[j + k] < sentinel ? g[j + k] : sentinel);
        *data++ = (unsigned char)byte;
    }
    return data;
#endif
}

/* Steps 2 and 3 for one byte's deltas (count a multiple of 16). */
static unsigned char *encode_bytes(unsigned char *data, const unsigned char *deltas, size_t count)
{
    size_t groups = count / GROUP, header_size = (groups + 3) / 4;
    unsigned char *header = data;
    memset(header, 0, header_size);
    data += header_size;
    for (size_t i = 0; i < groups; i++) {
        const unsigned char *g = deltas + i * GROUP;
        unsigned nonzero, over2, over4;
        group_masks(g, &nonzero, &over2, &over4);
        int width = 3; /* log2 of 8 bits: 16 bytes */
        size_t best = GROUP;
        if (!nonzero)
            width = 0, best = 0;
        size_t two = 4 + (size_t)popcount16(over2), four = 8 + (size_t)popcount16(over4);
        if (two < best)
            width = 1, best = two;
        if (four < best)
            width = 2, best = four;
        header[i / 4] |= (unsigned char)(width << (i % 4 * 2));
        if (width == 3) {
            memcpy(data, g, GROUP);
            data += GROUP;
        } else if (width) {
            unsigned whole = width == 1 ? over2 : over4;
            data = pack_group(data, g, width == 1 ? 2 : 4);
            for (; whole; whole &= whole - 1)
                *data++ = g[__builtin_ctz(whole)];
        }
    }
    return data;
}

size_t proto_meshopt_encode_vertices(unsigned char *buf, size_t size, const void *vertices, size_t count,
                                     size_t stride)
{
    const unsigned char *v = vertices;
    size_t tail = stride < TAIL ? TAIL : stride, per_block = block_vertices(stride);
    if (stride == 0 || stride % 4 || stride > 256 || size < 1 + tail)
        return 0;
    /* The library writes at most this much per block: a header and 16 bytes per group. */
    size_t block_most = stride * ((per_block / GROUP + 3) / 4 + per_block);
    unsigned char first[256] = {0}, deltas[8 * BLOCK_MAX];
    if (count)
        memcpy(first, v, stride);
    unsigned char *data = buf, *end = buf + size;
    *data++ = VERTEX_HEADER;
    for (size_t at = 0; at < count; at += per_block) {
        if ((size_t)(end - data) < block_most + tail)
            return 0;
        size_t n = count - at < per_block ? count - at : per_block;
        const unsigned char *block = v + at * stride, *before = at ? block - stride : first;
#if MESHOPT_SSE2
        if (stride == 8 && n % GROUP == 0) {
            for (size_t i = 0; i < n; i += GROUP)
                deltas_sse2_stride8(block + i * 8, i ? block + i * 8 - 8 : before, deltas + i);
            for (size_t k = 0; k < 8; k++)
                data = encode_bytes(data, deltas + k * BLOCK_MAX, n);
            continue;
        }
#endif
        for (size_t k = 0; k < stride; k++) {
            deltas_scalar(block, n, stride, k, before[k], deltas);
            data = encode_bytes(data, deltas, (n + GROUP - 1) & ~(size_t)(GROUP - 1));
        }
    }
    if ((size_t)(end - data) < tail)
        return 0;
    memset(data, 0, tail - stride);
    memcpy(data + tail - stride, first, stride);
    return (size_t)(data + tail - buf);
}
