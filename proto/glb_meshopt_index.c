/* glb_meshopt_index.c: meshoptimizer's index codec, version 1 (Giesen's and Stokes's FIFO
 * coding as meshopt_encodeIndexBuffer writes it after meshopt_encodeIndexVersion(1); the
 * format EXT_meshopt_compression's TRIANGLES mode names, header 0xe1, which three.js's
 * MeshoptDecoder and meshopt_decodeIndexBuffer read). Each triangle is looked up among the
 * last 16 edges, else its corners among the last 16 vertices. The library scans those
 * FIFOs one entry at a time; here each FIFO lives in four SSE2 registers, newest first,
 * shifted as entries are pushed (a plain array elsewhere), so one lookup compares all 16
 * entries at once and the age of the newest match is the lowest set bit of a mask. The
 * bytes are the library's, checked against it in test_proto_encode.
 *
 * Per triangle, in order:
 *   1. edge lookup: the newest FIFO edge equal to (a,b), (b,c) or (c,a), at ages 0..14;
 *   2. a hit codes the edge's age and the third corner: a vertex FIFO age 1..12, the next
 *      new vertex, the last free index minus or plus one (version 1's codes 13 and 14: a
 *      strip's free corners often step by one), or a free index delta-coded as a zigzag
 *      varint; it pushes two edges;
 *   3. a miss rotates the triangle to start at the next new vertex; a triangle (0,1,2)
 *      after vertex 0 restarts the numbering (version 1's reset: the vertex FIFO empties);
 *      it codes the corners (the pair of the second and third through the fixed 16-entry
 *      table when it can) and pushes all three edges;
 * then the fixed table closes the stream (the decoder reads it, and it pads the data). */
#include "glb_meshopt_codec.h"

#include <string.h>

#if defined(__SSE2__) && !defined(PROTO_MESHOPT_SCALAR)
#define MESHOPT_SSE2 1
#include <emmintrin.h>
#endif

enum {
    INDEX_HEADER = 0xe1, /* version 1 */
    FIFO_SIZE = 16,
    /* Version 1: a hit's third corner codes as a vertex FIFO age below 13 (13 and 14
     * code the last free index -1 and +1). */
    FIFO_AGE_END = 13,
    CODE_LAST_MINUS_ONE = 13,
    CODE_LAST_PLUS_ONE = 14,
    CODE_FREE = 15
};

/* The table the library codes a miss's second and third corners with (its last two
 * entries unused for coding); written at the end of every stream. */
static const unsigned char code_aux_table[16] = {0x00, 0x76, 0x87, 0x56, 0x67, 0x78, 0xa9, 0x86,
                                                 0x65, 0x89, 0x68, 0x98, 0x01, 0x69, 0,    0};

/* 16 FIFO entries, entry k of age k; a push of n entries ages the others by n and drops
 * the n oldest. The library starts every entry at ~0. */
#if MESHOPT_SSE2
typedef struct lanes {
    __m128i v[4]; /* entries 4k..4k+3 in v[k], the youngest in the lowest lane */
} lanes;

static inline void lanes_fill(lanes *l)
{
    for (int k = 0; k < 4; k++)
        l->v[k] = _mm_set1_epi32(-1);
}

/* Shifts the entries n places older (byte shifts take constants: n is 1, 2 or 3 at
 * every call site, after inlining), then puts `young` (entries 0..n-1) in front. */
#define LANES_SHIFT(l, n, k) \
    ((l)->v[k] = _mm_or_si128(_mm_slli_si128((l)->v[k], 4 * (n)), _mm_srli_si128((l)->v[(k) - 1], 16 - 4 * (n))))
#define LANES_SHIFT_IN(l, n, young)                                           \
    do {                                                                      \
        LANES_SHIFT(l, n, 3);                                                 \
        LANES_SHIFT(l, n, 2);                                                 \
        LANES_SHIFT(l, n, 1);                                                 \
        (l)->v[0] = _mm_or_si128(_mm_slli_si128((l)->v[0], 4 * (n)), (young)); \
    } while (0)

static inline void lanes_push1(lanes *l, uint32_t e0)
{
    LANES_SHIFT_IN(l, 1, _mm_cvtsi32_si128((int)e0));
}

static inline void lanes_push2(lanes *l, uint32_t e0, uint32_t e1)
{
    LANES_SHIFT_IN(l, 2, _mm_set_epi32(0, 0, (int)e1, (int)e0));
}

static inline void lanes_push3(lanes *l, uint32_t e0, uint32_t e1, uint32_t e2)
{
    LANES_SHIFT_IN(l, 3, _mm_set_epi32(0, (int)e2, (int)e1, (int)e0));
}

/* The 16 lanes of four compares' results (all ones or zero, entries 0..15 in order) as
 * a 16-bit mask: packed down to bytes (saturation keeps -1 and 0) and one movemask, not
 * four movemasks shifted into place. */
static inline unsigned mask16(__m128i c0, __m128i c1, __m128i c2, __m128i c3)
{
    return (unsigned)_mm_movemask_epi8(_mm_packs_epi16(_mm_packs_epi32(c0, c1), _mm_packs_epi32(c2, c3)));
}

/* Bit k set where entry k equals x. */
static inline unsigned lanes_match(const lanes *l, uint32_t x)
{
    __m128i k = _mm_set1_epi32((int)x);
    return mask16(_mm_cmpeq_epi32(l->v[0], k), _mm_cmpeq_epi32(l->v[1], k), _mm_cmpeq_epi32(l->v[2], k),
                  _mm_cmpeq_epi32(l->v[3], k));
}
#else
typedef struct lanes {
    uint32_t v[FIFO_SIZE];
} lanes;

static inline void lanes_fill(lanes *l)
{
    memset(l->v, 0xff, sizeof l->v);
}

static inline void lanes_push1(lanes *l, uint32_t e0)
{
    memmove(l->v + 1, l->v, (FIFO_SIZE - 1) * sizeof l->v[0]);
    l->v[0] = e0;
}

static inline void lanes_push2(lanes *l, uint32_t e0, uint32_t e1)
{
    memmove(l->v + 2, l->v, (FIFO_SIZE - 2) * sizeof l->v[0]);
    l->v[0] = e0, l->v[1] = e1;
}

static inline void lanes_push3(lanes *l, uint32_t e0, uint32_t e1, uint32_t e2)
{
    memmove(l->v + 3, l->v, (FIFO_SIZE - 3) * sizeof l->v[0]);
    l->v[0] = e0, l->v[1] = e1, l->v[2] = e2;
}

static inline unsigned lanes_match(const lanes *l, uint32_t x)
{
    unsigned m = 0;
    for (int k = 0; k < FIFO_SIZE; k++)
        m |= (unsigned)(l->v[k] == x) << k;
    return m;
}
#endif

/* The edge FIFO: directed edges (from, to). */
typedef struct edges {
    lanes from, to;
} edges;

/* The age of the newest vertex equal to v, or -1. */
static inline int vertex_age(const lanes *vertices, uint32_t v)
{
    unsigned m = lanes_match(vertices, v);
    return m ? __builtin_ctz(m) : -1;
}

/* Entry 0 (the newest) alone. */
static inline uint32_t lanes_first(const lanes *l)
{
#if MESHOPT_SSE2
    return (uint32_t)_mm_cvtsi128_si32(l->v[0]);
#else
    return l->v[0];
#endif
}

/* Step 1: the newest edge among ages 0..14 as age * 4 + which (0: (a,b), 1: (b,c),
 * 2: (c,a); at one age the library tries them in that order), or -1. The newest edge
 * first, on its own: a surface strip's next triangle shares it (a third of the
 * triangles of an extracted mesh), and then the 16-wide compare is not needed. */
static inline int edge_find(const edges *e, uint32_t a, uint32_t b, uint32_t c)
{
    uint32_t from = lanes_first(&e->from), to = lanes_first(&e->to);
    if (from == a && to == b)
        return 0;
    if (from == b && to == c)
        return 1;
    if (from == c && to == a)
        return 2;
    unsigned ab, bc, ca;
#if MESHOPT_SSE2
    __m128i va = _mm_set1_epi32((int)a), vb = _mm_set1_epi32((int)b), vc = _mm_set1_epi32((int)c);
#define EDGE_EQ(k, x, y) _mm_and_si128(_mm_cmpeq_epi32(e->from.v[k], x), _mm_cmpeq_epi32(e->to.v[k], y))
    ab = mask16(EDGE_EQ(0, va, vb), EDGE_EQ(1, va, vb), EDGE_EQ(2, va, vb), EDGE_EQ(3, va, vb));
    bc = mask16(EDGE_EQ(0, vb, vc), EDGE_EQ(1, vb, vc), EDGE_EQ(2, vb, vc), EDGE_EQ(3, vb, vc));
    ca = mask16(EDGE_EQ(0, vc, va), EDGE_EQ(1, vc, va), EDGE_EQ(2, vc, va), EDGE_EQ(3, vc, va));
#undef EDGE_EQ
#else
    ab = lanes_match(&e->from, a) & lanes_match(&e->to, b);
    bc = lanes_match(&e->from, b) & lanes_match(&e->to, c);
    ca = lanes_match(&e->from, c) & lanes_match(&e->to, a);
#endif
    const unsigned below15 = (1u << (FIFO_SIZE - 1)) - 1; /* an age-15 hit codes as a miss */
    unsigned any = (ab | bc | ca) & below15;
    if (!any)
        return -1;
    int age = __builtin_ctz(any);
    return age << 2 | ((ab >> age & 1) ? 0 : (bc >> age & 1) ? 1 : 2);
}

static inline unsigned char *put_index(unsigned char *data, uint32_t index, uint32_t last)
{
    uint32_t d = index - last;
    uint32_t v = (d << 1) ^ (uint32_t)(-(int32_t)(d >> 31)); /* zigzag */
    do {
        *data++ = (unsigned char)((v & 127) | (v > 127 ? 128 : 0));
        v >>= 7;
    } while (v);
    return data;
}

size_t proto_meshopt_encode_indices(unsigned char *buf, size_t size, const uint32_t *indices, size_t count)
{
    const size_t triangles = count / 3;
    if (size < 1 + triangles + FIFO_SIZE)
        return 0;
    /* Where in code_aux_table each (second, third) pair codes, or 14 and above: none. */
    unsigned char aux_slot[256];
    memset(aux_slot, 14, sizeof aux_slot);
    for (int i = 13; i >= 0; i--)
        aux_slot[code_aux_table[i]] = (unsigned char)i;
    edges ef;
    lanes vf;
    lanes_fill(&ef.from);
    lanes_fill(&ef.to);
    lanes_fill(&vf);
    uint32_t next = 0, last = 0;
    buf[0] = INDEX_HEADER;
    unsigned char *code = buf + 1, *data = code + triangles;
    const unsigned char *data_safe_end = buf + size - FIFO_SIZE;
    for (size_t i = 0; i < 3 * triangles; i += 3) {
        if (data > data_safe_end) /* a triangle writes at most 16 bytes */
            return 0;
        uint32_t t[3] = {indices[i], indices[i + 1], indices[i + 2]};
        int fer = edge_find(&ef, t[0], t[1], t[2]);
        if (fer >= 0) { /* step 2 */
            int r = fer & 3;
            uint32_t a = t[r], b = t[(r + 1) % 3], c = t[(r + 2) % 3];
            int fc = vertex_age(&vf, c);
            int fec = fc >= 1 && fc < FIFO_AGE_END ? fc : c == next ? (next++, 0) : CODE_FREE;
            if (fec == CODE_FREE) {
                if (c + 1 == last)
                    fec = CODE_LAST_MINUS_ONE, last = c;
                else if (c == last + 1)
                    fec = CODE_LAST_PLUS_ONE, last = c;
                else
                    data = put_index(data, c, last), last = c;
            }
            *code++ = (unsigned char)((fer >> 2) << 4 | fec);
            if (fec == 0 || fec >= CODE_LAST_MINUS_ONE)
                lanes_push1(&vf, c);
            /* the library pushes (c,b), then (a,c) */
            lanes_push2(&ef.from, a, c);
            lanes_push2(&ef.to, c, b);
        } else { /* step 3 */
            int r = t[1] == next ? 1 : t[2] == next ? 2 : 0;
            uint32_t a = t[r], b = t[(r + 1) % 3], c = t[(r + 2) % 3];
            /* A reset (0,1,2 once vertex 0 is past) empties the vertex FIFO and codes as
             * the table's entry 0 written out: 0xfe, then aux 0x00. */
            int fea = CODE_FREE, reset = 0;
            if (a == next) {
                fea = 0, next++;
            } else if (a == 0 && b == 1 && c == 2) {
                fea = 0, next = 1, reset = 1;
                lanes_fill(&vf);
            }
            int fb = vertex_age(&vf, b), fc = vertex_age(&vf, c);
            int feb = fb >= 0 && fb < 14 ? fb + 1 : b == next ? (next++, 0) : CODE_FREE;
            int fec = fc >= 0 && fc < 14 ? fc + 1 : c == next ? (next++, 0) : CODE_FREE;
            unsigned char aux = (unsigned char)(feb << 4 | fec);
            if (fea == 0 && aux_slot[aux] < 14 && !reset) {
                *code++ = (unsigned char)(0xf0 | aux_slot[aux]);
            } else {
                *code++ = (unsigned char)(0xf0 | 14 | fea);
                *data++ = aux;
            }
            if (fea == CODE_FREE)
                data = put_index(data, a, last), last = a;
            if (feb == CODE_FREE)
                data = put_index(data, b, last), last = b;
            if (fec == CODE_FREE)
                data = put_index(data, c, last), last = c;
            if (fea == 0 || fea == CODE_FREE)
                lanes_push1(&vf, a);
            if (feb == 0 || feb == CODE_FREE)
                lanes_push1(&vf, b);
            if (fec == 0 || fec == CODE_FREE)
                lanes_push1(&vf, c);
            /* the library pushes (b,a), (c,b), then (a,c) */
            lanes_push3(&ef.from, a, c, b);
            lanes_push3(&ef.to, c, b, a);
        }
    }
    if (data > data_safe_end)
        return 0;
    memcpy(data, code_aux_table, sizeof code_aux_table);
    data += sizeof code_aux_table;
    return (size_t)(data - buf);
}
