/* march.c: exact marching cubes over active bricks, count-then-fill like VTK's
 * vtkFlyingEdges3D but brick by brick, so that min/max pruning skips the rest unread.
 *
 * Every crossing edge has one owner: the brick that holds its lower corner (the last
 * brick along an axis also holds the volume's last sample plane). A brick numbers the
 * crossings of the edges it owns row by row, in the order z, y, axis, then x; any brick
 * finds a neighbour's vertex id from that neighbour's crossing rows by a popcount.
 *
 * PASS 1 (select): bricks with min <= level < max, in grid order (for iso_march_selected,
 *   the bricks with marked blocks and their ghosts: bricks the level crosses that own
 *   edges a marked block holds; a brick not wholly marked keeps only the crossings of
 *   edges its own or its lower neighbours' marked blocks hold, and marches the cells of
 *   its own marked blocks only).
 * PASS 2 (classify, threads): per active brick, one 9-bit word per x-row of samples
 *   saying which are above the level; from those by shifts and xors, the owned crossing
 *   edges of every row and axis and the row's cells that are neither all inside nor all
 *   outside (8 rows at a time with SSE2 in a full interior brick); then the crossings'
 *   running count and the mixed cells' triangles, in the rows that have some.
 * PASS 3 (offsets): prefix sums give each brick its first vertex and first triangle; the
 *   mesh is allocated once at its final size (the caller's arrays reused if they fit).
 * PASS 4 (generate, threads): per active brick, the positions of its owned crossings in
 *   numbering order, then the triangles of its mixed cells into its own range.
 *
 * Layout: a brick has at most 9x9x9 samples; row r = z * 9 + y of the brick holds bit x
 * for sample (x, y, z), brick-local; a row of cells is named by the sample row of its
 * low corners. Only bricks with triangles are touched in PASS 4. */
#include "march.h"

#include <assert.h>
#include <math.h>
#include <pthread.h>
#include <stdatomic.h>
#include <stdint.h>
#include <stdlib.h>
#include <string.h>
#ifdef __SSE2__
#include <emmintrin.h>
#endif

#include "mc.h"
#include "base/base.h"

#define S ISO_BRICK_SAMPLES
#define ROWS (S * S)
#define ROW_VECTORS 11                   /* the 81 rows, 8 at a time */
#define PADDED_ROWS (8 * ROW_VECTORS)
#define INSIDE_ROWS (PADDED_ROWS + S + 7) /* a vector reads rows r + 1, r + 9 and r + 10 too */

typedef struct active_brick {
    uint32_t brick[3];
    uint8_t partial;                     /* not wholly marked (iso_march_selected): masked */
    uint8_t blocks;                      /* its marked blocks, bit x | y << 1 | z << 2 */
    uint8_t lower[8];                    /* [k]: the marked blocks of the neighbour at -k */
    uint8_t n[3];                        /* samples per axis, 2..9 */
    uint8_t owned[3];                    /* corners 0..owned-1 per axis are this brick's */
    uint32_t vertices, triangles;        /* counted in PASS 2 */
    size_t first_vertex, first_triangle; /* PASS 3 */
    /* Per row r = z * 9 + y; rows past the 81 are padding that SSE2 reads 8 at a time. */
    uint16_t inside[INSIDE_ROWS];        /* bit x: sample (x, y, z) above the level */
    uint16_t cross[3][PADDED_ROWS];      /* bit x: owned edge from (x, y, z) along axis crosses */
    uint16_t before[3][PADDED_ROWS];     /* owned crossings numbered before; rows with some only */
    uint8_t marching[PADDED_ROWS];       /* bit x: cell (x, y, z) to march: mixed */
    /* Which rows PASS 4 has work in, so that it visits only those (a brick the surface
     * crosses as a sheet has work in a third of its rows or so), bit r: the sample rows
     * with an owned crossing, the rows of cells to march. */
    uint64_t crossing_rows[2];
    uint64_t marching_rows[2];
} active_brick;

#define MAX_THREADS ISO_PARALLEL_MAX_THREADS

/* The level as each type compares against it: march.h's iso_march_threshold. An integer
 * sample is above the level exactly when it is above the level's floor, so integer data
 * is compared as integers, and 8- and 16-bit rows 8 samples at a time where SSE2 is there
 * (x86-64 always has it): the inside bits were 12% of the exact path's instructions one
 * double compare at a time. Below the type's smallest value every sample is above; at or
 * past its largest none is. */
typedef iso_march_threshold threshold;
enum { SOME_ABOVE = ISO_MARCH_SOME_ABOVE, ALL_ABOVE = ISO_MARCH_ALL_ABOVE, NONE_ABOVE = ISO_MARCH_NONE_ABOVE };

typedef struct march_job {
    const iso_volume *vol;
    const iso_bricks *bricks;
    double level;
    threshold threshold;     /* the level as the voxel type compares it, made once */
    active_brick *active;
    size_t active_count;
    int32_t *slot;     /* per brick of the grid: its index in active, or -1 */
    const uint8_t *marked; /* iso_march_selected's bricks to march, or NULL: min/max */
    /* iso_march_label: inside is "sample == label" (the indicator of one label), every
     * crossing at its edge's midpoint; the bricks are listed (grid indices, ascending)
     * and looked up there, so no per-grid slot array is made. */
    int indicator;
    const uint32_t *listed;
    size_t listed_count;
    iso_mesh *mesh;
    int world;         /* positions in world mm rather than index space */
    int axis_aligned;  /* the volume's direction is the identity */
    /* Where a coordinate depends on its own axis only (index space, or an identity
     * direction), per axis the position of every sample plane as store_position writes
     * it, and the map of that axis (offset + index * scale): a vertex then computes only
     * its edge's coordinate. NULL otherwise. */
    float *plane[3];
    double offset[3], scale[3];
    double error[MAX_THREADS];
    size_t cells[MAX_THREADS]; /* cells marched, per thread: counted where classified */
    atomic_size_t next_brick;  /* the next active brick a thread may take (PASS 2, 4) */
} march_job;

static uint8_t bit_count[1 << S]; /* popcount of 9-bit words, without needing popcnt */
static uint64_t pair_spread[1 << S]; /* bits x, x + 1 of a 9-bit row at bits 8x, 8x + 1 */

static void learn_edges(void);

#ifdef __SSE2__
static void make_full_rows(void);
#endif

static void make_tables(void)
{
    learn_edges();
#ifdef __SSE2__
    make_full_rows();
#endif
    for (unsigned w = 0; w < (1u << S); w++) {
        bit_count[w] = (uint8_t)((w & 1) + bit_count[w >> 1]);
        pair_spread[w] = 0;
        for (int x = 0; x < ISO_BRICK_CELLS; x++)
            pair_spread[w] |= (uint64_t)(w >> x & 3) << (8 * x);
    }
}

/* ---- one brick's inside bits, per voxel type ---- */


static void type_range(iso_voxel_type type, int64_t *lowest, int64_t *highest)
{
    switch (type) {
    case ISO_U8: *lowest = 0, *highest = UINT8_MAX; break;
    case ISO_I8: *lowest = INT8_MIN, *highest = INT8_MAX; break;
    case ISO_U16: *lowest = 0, *highest = UINT16_MAX; break;
    case ISO_I16: *lowest = INT16_MIN, *highest = INT16_MAX; break;
    case ISO_U32: *lowest = 0, *highest = UINT32_MAX; break;
    default: *lowest = INT32_MIN, *highest = INT32_MAX; break;
    }
}

/* The indicator's threshold: th->floor is the label, and for 8- and 16-bit types every
 * lane of th->lanes (compared for equality, so no bias). A label the type cannot hold is
 * in no sample. */
static void make_label(iso_voxel_type type, int64_t label, threshold *th)
{
    memset(th, 0, sizeof *th);
    int64_t lowest, highest;
    type_range(type, &lowest, &highest);
    th->reach = SOME_ABOVE;
    if (iso_vol_type_is_float(type) || label < lowest || label > highest) {
        th->reach = NONE_ABOVE;
        return;
    }
    th->floor = label;
#ifdef __SSE2__
    __m128i lanes = _mm_setzero_si128();
    if (type == ISO_U8 || type == ISO_I8)
        lanes = _mm_set1_epi8((char)label);
    else if (type == ISO_U16 || type == ISO_I16)
        lanes = _mm_set1_epi16((short)label);
    _mm_storeu_si128((__m128i *)(void *)th->lanes, lanes);
#endif
}

static void make_threshold(iso_voxel_type type, double level, threshold *th)
{
    memset(th, 0, sizeof *th);
    th->level = level;
    th->reach = SOME_ABOVE;
    if (type == ISO_F32 || type == ISO_F64)
        return;
    int64_t lowest, highest;
    type_range(type, &lowest, &highest);
    double f = floor(level);
    if (f < (double)lowest) {
        th->reach = ALL_ABOVE;
        return;
    }
    if (f >= (double)highest) {
        th->reach = NONE_ABOVE;
        return;
    }
    th->floor = (int64_t)f;
#ifdef __SSE2__
    __m128i bias = _mm_setzero_si128(), lanes = _mm_setzero_si128();
    if (type == ISO_U8 || type == ISO_I8) {
        int b = type == ISO_U8 ? -128 : 0;
        bias = _mm_set1_epi8((char)b);
        lanes = _mm_set1_epi8((char)(th->floor + b));
    } else if (type == ISO_U16 || type == ISO_I16) {
        int b = type == ISO_U16 ? -32768 : 0;
        bias = _mm_set1_epi16((short)b);
        lanes = _mm_set1_epi16((short)(th->floor + b));
    }
    _mm_storeu_si128((__m128i *)(void *)th->bias, bias);
    _mm_storeu_si128((__m128i *)(void *)th->lanes, lanes);
#endif
}

/* The threshold as the row tests read it, in registers: built once per brick. */
typedef struct row_test {
    double level;
    int64_t floor;
#ifdef __SSE2__
    __m128i bias, lanes;
#endif
} row_test;

static inline row_test row_test_of(const threshold *th)
{
    row_test t = {.level = th->level, .floor = th->floor};
#ifdef __SSE2__
    t.bias = _mm_loadu_si128((const __m128i *)(const void *)th->bias);
    t.lanes = _mm_loadu_si128((const __m128i *)(const void *)th->lanes);
#endif
    return t;
}

#define DEFINE_SCALAR_ROW(NAME, T, TEST)                              \
    static inline unsigned NAME(const T *p, int n, const row_test *th) \
    {                                                                 \
        unsigned bits = 0;                                            \
        for (int x = 0; x < n; x++)                                   \
            bits |= (unsigned)(TEST) << x;                            \
        return bits;                                                  \
    }

DEFINE_SCALAR_ROW(scalar_u8, uint8_t, p[x] > th->floor)
DEFINE_SCALAR_ROW(scalar_i8, int8_t, p[x] > th->floor)
DEFINE_SCALAR_ROW(scalar_u16, uint16_t, p[x] > th->floor)
DEFINE_SCALAR_ROW(scalar_i16, int16_t, p[x] > th->floor)
DEFINE_SCALAR_ROW(row_u32, uint32_t, p[x] > th->floor)
DEFINE_SCALAR_ROW(row_i32, int32_t, p[x] > th->floor)
DEFINE_SCALAR_ROW(row_f32, float, (double)p[x] > th->level) /* NaN: outside */
DEFINE_SCALAR_ROW(row_f64, double, p[x] > th->level)

/* A full row of S samples: bits 0-7 from one vector compare, bit 8 alone. */
#ifdef __SSE2__
#define VECTOR_ROW(NAME, T, LOAD, COMPARE, PACK, SCALAR)                                   \
    static inline unsigned NAME(const T *p, int n, const row_test *th)                     \
    {                                                                                      \
        if (n != S)                                                                        \
            return SCALAR(p, n, th);                                                       \
        __m128i above = COMPARE(_mm_add_epi##PACK(LOAD, th->bias), th->lanes);            \
        unsigned low = (unsigned)_mm_movemask_epi8(PACK == 16 ? _mm_packs_epi16(above, above) : above) & 0xFFu; \
        return low | (unsigned)(p[S - 1] > th->floor) << (S - 1);                          \
    }
VECTOR_ROW(row_u8, uint8_t, _mm_loadl_epi64((const __m128i *)p), _mm_cmpgt_epi8, 8, scalar_u8)
VECTOR_ROW(row_i8, int8_t, _mm_loadl_epi64((const __m128i *)p), _mm_cmpgt_epi8, 8, scalar_i8)
VECTOR_ROW(row_u16, uint16_t, _mm_loadu_si128((const __m128i *)p), _mm_cmpgt_epi16, 16, scalar_u16)
VECTOR_ROW(row_i16, int16_t, _mm_loadu_si128((const __m128i *)p), _mm_cmpgt_epi16, 16, scalar_i16)
#else
#define row_u8 scalar_u8
#define row_i8 scalar_i8
#define row_u16 scalar_u16
#define row_i16 scalar_i16
#endif

/* The indicator's rows: bit x set where the sample equals the label (th->floor). */
DEFINE_SCALAR_ROW(equal_scalar_u8, uint8_t, p[x] == th->floor)
DEFINE_SCALAR_ROW(equal_scalar_i8, int8_t, p[x] == th->floor)
DEFINE_SCALAR_ROW(equal_scalar_u16, uint16_t, p[x] == th->floor)
DEFINE_SCALAR_ROW(equal_scalar_i16, int16_t, p[x] == th->floor)
DEFINE_SCALAR_ROW(equal_u32, uint32_t, p[x] == th->floor)
DEFINE_SCALAR_ROW(equal_i32, int32_t, p[x] == th->floor)

#ifdef __SSE2__
#define EQUAL_ROW(NAME, T, LOAD, COMPARE, PACK, SCALAR)                                    \
    static inline unsigned NAME(const T *p, int n, const row_test *th)                     \
    {                                                                                      \
        if (n != S)                                                                        \
            return SCALAR(p, n, th);                                                       \
        __m128i same = COMPARE(LOAD, th->lanes);                                           \
        unsigned low = (unsigned)_mm_movemask_epi8(PACK == 16 ? _mm_packs_epi16(same, same) : same) & 0xFFu; \
        return low | (unsigned)(p[S - 1] == th->floor) << (S - 1);                         \
    }
EQUAL_ROW(equal_u8, uint8_t, _mm_loadl_epi64((const __m128i *)p), _mm_cmpeq_epi8, 8, equal_scalar_u8)
EQUAL_ROW(equal_i8, int8_t, _mm_loadl_epi64((const __m128i *)p), _mm_cmpeq_epi8, 8, equal_scalar_i8)
EQUAL_ROW(equal_u16, uint16_t, _mm_loadu_si128((const __m128i *)p), _mm_cmpeq_epi16, 16, equal_scalar_u16)
EQUAL_ROW(equal_i16, int16_t, _mm_loadu_si128((const __m128i *)p), _mm_cmpeq_epi16, 16, equal_scalar_i16)
#else
#define equal_u8 equal_scalar_u8
#define equal_i8 equal_scalar_i8
#define equal_u16 equal_scalar_u16
#define equal_i16 equal_scalar_i16
#endif

#define DEFINE_INSIDE_ROWS(NAME, T, ROW)                                                       \
    static void NAME(const iso_volume *vol, const size_t lo[3], const uint8_t n[3], int step,  \
                     const threshold *th, uint16_t *rows)                                      \
    {                                                                                          \
        const row_test test = row_test_of(th);                                                 \
        const size_t row_step = vol->dims[0] * (size_t)step, plane_step = vol->dims[1] * row_step; \
        const T *plane = (const T *)vol->data + (lo[2] * vol->dims[1] + lo[1]) * vol->dims[0] + lo[0]; \
        for (int z = 0; z < n[2]; z += step, plane += plane_step) {                            \
            const T *p = plane;                                                                \
            for (int y = 0; y < n[1]; y += step, p += row_step)                                \
                rows[z * S + y] = (uint16_t)ROW(p, n[0], &test);                               \
        }                                                                                      \
    }

/* The rows whose bit r = z * 9 + y is set in wanted[r / 64]. */
#define DEFINE_LISTED_ROWS(NAME, T, ROW)                                                       \
    static void NAME(const iso_volume *vol, const size_t lo[3], const uint8_t n[3], const uint64_t wanted[2], \
                     const threshold *th, uint16_t *rows)                                      \
    {                                                                                          \
        const row_test test = row_test_of(th);                                                 \
        const T *first = (const T *)vol->data + (lo[2] * vol->dims[1] + lo[1]) * vol->dims[0] + lo[0]; \
        for (int word = 0; word < 2; word++)                                                   \
            for (uint64_t m = wanted[word]; m; m &= m - 1) {                                   \
                int r = 64 * word + __builtin_ctzll(m);                                        \
                const T *p = first + ((size_t)(r / S) * vol->dims[1] + (size_t)(r % S)) * vol->dims[0]; \
                rows[r] = (uint16_t)ROW(p, n[0], &test);                                       \
            }                                                                                  \
    }

DEFINE_LISTED_ROWS(listed_u8, uint8_t, row_u8)
DEFINE_LISTED_ROWS(listed_i8, int8_t, row_i8)
DEFINE_LISTED_ROWS(listed_u16, uint16_t, row_u16)
DEFINE_LISTED_ROWS(listed_i16, int16_t, row_i16)
DEFINE_LISTED_ROWS(listed_u32, uint32_t, row_u32)
DEFINE_LISTED_ROWS(listed_i32, int32_t, row_i32)
DEFINE_LISTED_ROWS(listed_f32, float, row_f32)
DEFINE_LISTED_ROWS(listed_f64, double, row_f64)

DEFINE_INSIDE_ROWS(inside_u8, uint8_t, row_u8)
DEFINE_INSIDE_ROWS(inside_i8, int8_t, row_i8)
DEFINE_INSIDE_ROWS(inside_u16, uint16_t, row_u16)
DEFINE_INSIDE_ROWS(inside_i16, int16_t, row_i16)
DEFINE_INSIDE_ROWS(inside_u32, uint32_t, row_u32)
DEFINE_INSIDE_ROWS(inside_i32, int32_t, row_i32)
DEFINE_INSIDE_ROWS(inside_f32, float, row_f32)
DEFINE_INSIDE_ROWS(inside_f64, double, row_f64)
DEFINE_INSIDE_ROWS(label_u8, uint8_t, equal_u8)
DEFINE_INSIDE_ROWS(label_i8, int8_t, equal_i8)
DEFINE_INSIDE_ROWS(label_u16, uint16_t, equal_u16)
DEFINE_INSIDE_ROWS(label_i16, int16_t, equal_i16)
DEFINE_INSIDE_ROWS(label_u32, uint32_t, equal_u32)
DEFINE_INSIDE_ROWS(label_i32, int32_t, equal_i32)

static void inside_rows_every(const iso_volume *vol, const threshold *th, const size_t lo[3], const uint8_t n[3],
                              int step, uint16_t *rows)
{
    if (th->reach != SOME_ABOVE) {
        uint16_t all = th->reach == ALL_ABOVE ? (uint16_t)((1u << n[0]) - 1) : 0;
        for (int z = 0; z < n[2]; z += step)
            for (int y = 0; y < n[1]; y += step)
                rows[z * S + y] = all;
        return;
    }
    switch (vol->type) {
    case ISO_U8: inside_u8(vol, lo, n, step, th, rows); break;
    case ISO_I8: inside_i8(vol, lo, n, step, th, rows); break;
    case ISO_U16: inside_u16(vol, lo, n, step, th, rows); break;
    case ISO_I16: inside_i16(vol, lo, n, step, th, rows); break;
    case ISO_U32: inside_u32(vol, lo, n, step, th, rows); break;
    case ISO_I32: inside_i32(vol, lo, n, step, th, rows); break;
    case ISO_F32: inside_f32(vol, lo, n, step, th, rows); break;
    case ISO_F64: inside_f64(vol, lo, n, step, th, rows); break;
    }
}

static void inside_rows(const march_job *job, const size_t lo[3], const uint8_t n[3], uint16_t *rows)
{
    const iso_volume *vol = job->vol;
    const threshold *th = &job->threshold;
    if (!job->indicator || th->reach != SOME_ABOVE) {
        inside_rows_every(vol, th, lo, n, 1, rows);
        return;
    }
    switch (vol->type) {
    case ISO_U8: label_u8(vol, lo, n, 1, th, rows); break;
    case ISO_I8: label_i8(vol, lo, n, 1, th, rows); break;
    case ISO_U16: label_u16(vol, lo, n, 1, th, rows); break;
    case ISO_I16: label_i16(vol, lo, n, 1, th, rows); break;
    case ISO_U32: label_u32(vol, lo, n, 1, th, rows); break;
    case ISO_I32: label_i32(vol, lo, n, 1, th, rows); break;
    case ISO_F32: case ISO_F64: break; /* make_label's NONE_ABOVE */
    }
}

void iso_march_threshold_make(const iso_volume *vol, double level, iso_march_threshold *th)
{
    make_threshold(vol->type, level, th);
}

void iso_march_inside_rows_every(const iso_volume *vol, const iso_march_threshold *th, const size_t lo[3],
                                 const uint8_t n[3], int step, uint16_t rows[ISO_BRICK_SAMPLES * ISO_BRICK_SAMPLES])
{
    inside_rows_every(vol, th, lo, n, step, rows);
}

void iso_march_inside_rows_listed(const iso_volume *vol, const iso_march_threshold *th, const size_t lo[3],
                                  const uint8_t n[3], const uint64_t wanted[2],
                                  uint16_t rows[ISO_BRICK_SAMPLES * ISO_BRICK_SAMPLES])
{
    if (th->reach != SOME_ABOVE) {
        uint16_t all = th->reach == ALL_ABOVE ? (uint16_t)((1u << n[0]) - 1) : 0;
        for (int word = 0; word < 2; word++)
            for (uint64_t m = wanted[word]; m; m &= m - 1)
                rows[64 * word + __builtin_ctzll(m)] = all;
        return;
    }
    switch (vol->type) {
    case ISO_U8: listed_u8(vol, lo, n, wanted, th, rows); break;
    case ISO_I8: listed_i8(vol, lo, n, wanted, th, rows); break;
    case ISO_U16: listed_u16(vol, lo, n, wanted, th, rows); break;
    case ISO_I16: listed_i16(vol, lo, n, wanted, th, rows); break;
    case ISO_U32: listed_u32(vol, lo, n, wanted, th, rows); break;
    case ISO_I32: listed_i32(vol, lo, n, wanted, th, rows); break;
    case ISO_F32: listed_f32(vol, lo, n, wanted, th, rows); break;
    case ISO_F64: listed_f64(vol, lo, n, wanted, th, rows); break;
    }
}

void iso_march_inside_rows(const iso_volume *vol, double level, const size_t lo[3], const uint8_t n[3],
                           uint16_t rows[ISO_BRICK_SAMPLES * ISO_BRICK_SAMPLES])
{
    threshold th;
    make_threshold(vol->type, level, &th);
    inside_rows_every(vol, &th, lo, n, 1, rows);
}

static void brick_origin(const active_brick *ab, size_t lo[3])
{
    for (int d = 0; d < 3; d++)
        lo[d] = (size_t)ab->brick[d] * ISO_BRICK_CELLS;
}

/* The four sample rows around the row of cells at (y, z): a, b at z (y and y + 1), c, d at
 * z + 1. A cell's case and the row's mixed cells are shifts of these, read once per row. */
typedef struct cell_row {
    unsigned a, b, c, d;
} cell_row;

static inline cell_row cell_row_at(const uint16_t *inside, int y, int z)
{
    cell_row q = {inside[z * S + y], inside[z * S + y + 1], inside[(z + 1) * S + y], inside[(z + 1) * S + y + 1]};
    return q;
}

/* Cells x of the row that are neither all inside nor all outside. */
static inline unsigned row_mixed(cell_row q, int samples_x)
{
    unsigned any = q.a | q.b | q.c | q.d, all = q.a & q.b & q.c & q.d;
    unsigned full = all & (all >> 1), empty = ~any & ~(any >> 1);
    return ~(full | empty) & ((1u << (samples_x - 1)) - 1);
}

/* The cases of the row's 8 cells, byte x for cell x: (a >> x & 3) | (b >> x & 3) << 2 |
 * (c >> x & 3) << 4 | (d >> x & 3) << 6, made with four table loads per row rather than
 * twelve operations per cell. */
static inline uint64_t row_cases(cell_row q)
{
    return pair_spread[q.a] | pair_spread[q.b] << 2 | pair_spread[q.c] << 4 | pair_spread[q.d] << 6;
}

static inline unsigned case_of(uint64_t cases, int x)
{
    return (unsigned)(cases >> (8 * x)) & 0xFF;
}

/* ---- PASS 2: classify ---- */

/* Any brick: per row its owned crossing edges and its mixed cells, one row at a time. */
static void scalar_rows(active_brick *ab)
{
    unsigned owned_x = (1u << ab->owned[0]) - 1, x_edges = (1u << (ab->n[0] - 1)) - 1;
    memset(ab->cross, 0, sizeof ab->cross);
    memset(ab->marching, 0, sizeof ab->marching);
    for (int z = 0; z < ab->owned[2]; z++)
        for (int y = 0; y < ab->owned[1]; y++) {
            int r = z * S + y;
            unsigned row = ab->inside[r];
            ab->cross[0][r] = (uint16_t)((row ^ (row >> 1)) & x_edges & owned_x);
            if (y + 1 < ab->n[1])
                ab->cross[1][r] = (uint16_t)((row ^ ab->inside[r + 1]) & owned_x);
            if (z + 1 < ab->n[2])
                ab->cross[2][r] = (uint16_t)((row ^ ab->inside[r + S]) & owned_x);
        }
    for (int z = 0; z + 1 < ab->n[2]; z++)
        for (int y = 0; y + 1 < ab->n[1]; y++)
            ab->marching[z * S + y] = (uint8_t)row_mixed(cell_row_at(ab->inside, y, z), ab->n[0]);
    for (int r = 0; r < ROWS; r++) {
        unsigned any = ab->cross[0][r] | ab->cross[1][r] | ab->cross[2][r];
        ab->crossing_rows[r / 64] |= (uint64_t)(any != 0) << (r % 64);
        ab->marching_rows[r / 64] |= (uint64_t)(ab->marching[r] != 0) << (r % 64);
    }
}

#ifdef __SSE2__
/* Per row of a full interior brick (9 samples per axis, 8 owned): 0xFF where y < 8 and
 * z < 8 (the rows whose edges it owns and whose cells it marches), 0 elsewhere. */
static uint16_t full_rows[PADDED_ROWS];

static void make_full_rows(void)
{
    for (int r = 0; r < PADDED_ROWS; r++)
        full_rows[r] = r < ROWS && r % S < ISO_BRICK_CELLS && r / S < ISO_BRICK_CELLS ? 0xFF : 0;
}

/* The 8 bits of rows 8k .. 8k + 7 that are not zero. */
static inline uint64_t nonzero_rows(__m128i v)
{
    __m128i zero = _mm_cmpeq_epi16(v, _mm_setzero_si128());
    return ~(uint64_t)_mm_movemask_epi8(_mm_packs_epi16(zero, zero)) & 0xFF;
}

/* 9 samples per axis, 8 of them owned: not the volume's last brick along any axis. */
static int full_brick(const active_brick *ab)
{
    return ab->n[0] == S && ab->n[1] == S && ab->n[2] == S && ab->owned[0] == ISO_BRICK_CELLS &&
           ab->owned[1] == ISO_BRICK_CELLS && ab->owned[2] == ISO_BRICK_CELLS;
}

/* scalar_rows for a full interior brick, 8 rows at a time: the same shifts and xors,
 * with rows y + 1, z + 1 and both read at offsets 1, 9 and 10. */
static void vector_rows(active_brick *ab)
{
    memset(ab->inside + ROWS, 0, (INSIDE_ROWS - ROWS) * sizeof *ab->inside);
    for (int k = 0; k < ROW_VECTORS; k++) {
        int r = 8 * k;
        const uint16_t *in = ab->inside + r;
        __m128i own = _mm_loadu_si128((const __m128i *)(full_rows + r));
        __m128i a = _mm_loadu_si128((const __m128i *)in), b = _mm_loadu_si128((const __m128i *)(in + 1));
        __m128i c = _mm_loadu_si128((const __m128i *)(in + S)), d = _mm_loadu_si128((const __m128i *)(in + S + 1));
        __m128i x = _mm_and_si128(_mm_xor_si128(a, _mm_srli_epi16(a, 1)), own);
        __m128i y = _mm_and_si128(_mm_xor_si128(a, b), own);
        __m128i z = _mm_and_si128(_mm_xor_si128(a, c), own);
        _mm_storeu_si128((__m128i *)(ab->cross[0] + r), x);
        _mm_storeu_si128((__m128i *)(ab->cross[1] + r), y);
        _mm_storeu_si128((__m128i *)(ab->cross[2] + r), z);
        __m128i any = _mm_or_si128(_mm_or_si128(a, b), _mm_or_si128(c, d));
        __m128i all = _mm_and_si128(_mm_and_si128(a, b), _mm_and_si128(c, d));
        __m128i full = _mm_and_si128(all, _mm_srli_epi16(all, 1));
        __m128i empty = _mm_andnot_si128(_mm_or_si128(any, _mm_srli_epi16(any, 1)), own);
        __m128i mixed = _mm_andnot_si128(_mm_or_si128(full, empty), own);
        _mm_storel_epi64((__m128i *)(ab->marching + r), _mm_packus_epi16(mixed, mixed));
        ab->crossing_rows[r / 64] |= nonzero_rows(_mm_or_si128(_mm_or_si128(x, y), z)) << (r % 64);
        ab->marching_rows[r / 64] |= nonzero_rows(mixed) << (r % 64);
    }
}
#endif

/* Numbers the owned crossings row by row (z, y, then axis, then x); returns how many. */
static uint32_t number_crossings(active_brick *ab)
{
    uint32_t count = 0;
    for (int word = 0; word < 2; word++)
        for (uint64_t rows = ab->crossing_rows[word]; rows; rows &= rows - 1) {
            int r = 64 * word + __builtin_ctzll(rows);
            for (int a = 0; a < 3; a++) {
                ab->before[a][r] = (uint16_t)count;
                count += bit_count[ab->cross[a][r]];
            }
        }
    return count;
}

static uint32_t count_triangles(const active_brick *ab)
{
    const iso_mc_case *cases = iso_mc_cases();
    uint32_t triangles = 0;
    for (int word = 0; word < 2; word++)
        for (uint64_t rows = ab->marching_rows[word]; rows; rows &= rows - 1) {
            int r = 64 * word + __builtin_ctzll(rows);
            uint64_t row = row_cases(cell_row_at(ab->inside, r % S, r / S));
            for (unsigned m = ab->marching[r]; m; m &= m - 1)
                triangles += cases[case_of(row, __builtin_ctz(m))].triangle_count;
        }
    return triangles;
}

/* Sets in keep[axis][row] the edges whose closed extent lies in the box [lo, hi] (brick-
 * local samples). */
static void keep_box(uint16_t keep[3][ROWS], const int lo[3], const int hi[3])
{
    for (int a = 0; a < 3; a++) {
        int end[3];
        for (int d = 0; d < 3; d++)
            end[d] = hi[d] - (d == a);
        if (end[a] < lo[a])
            continue;
        unsigned bits = ((1u << (end[0] - lo[0] + 1)) - 1) << lo[0];
        for (int z = lo[2]; z <= end[2]; z++)
            for (int y = lo[1]; y <= end[1]; y++)
                keep[a][z * S + y] |= (uint16_t)bits;
    }
}

/* A brick not wholly marked: keeps the crossings of the edges some marked block holds (its
 * own, or a lower neighbour's whose closed box reaches its low planes) and marches the
 * cells of its own marked blocks only. Returns the cells it marches. */
static size_t keep_marked(active_brick *ab)
{
    uint16_t keep[3][ROWS], cells[ROWS];
    memset(keep, 0, sizeof keep);
    memset(cells, 0, sizeof cells);
    size_t count = 0;
    for (int k = 0; k < 8; k++) {
        unsigned mask = k ? ab->lower[k] : ab->blocks;
        for (int blk = 0; mask && blk < 8; blk++) {
            if (!(mask >> blk & 1))
                continue;
            int lo[3], hi[3], there = 1;
            for (int d = 0; d < 3; d++) {
                int half = blk >> d & 1;
                if (k >> d & 1) { /* the neighbour below along d: its upper block's box ends at 0 */
                    there &= half;
                    lo[d] = hi[d] = 0;
                } else {
                    lo[d] = half * ISO_TREE_BLOCK;
                    hi[d] = lo[d] + ISO_TREE_BLOCK < ab->n[d] - 1 ? lo[d] + ISO_TREE_BLOCK : ab->n[d] - 1;
                    there &= lo[d] < ab->n[d] - 1;
                }
            }
            if (!there)
                continue;
            keep_box(keep, lo, hi);
            if (k)
                continue;
            count += (size_t)(hi[0] - lo[0]) * (size_t)(hi[1] - lo[1]) * (size_t)(hi[2] - lo[2]);
            for (int z = lo[2]; z < hi[2]; z++)
                for (int y = lo[1]; y < hi[1]; y++)
                    cells[z * S + y] |= (uint16_t)(((1u << (hi[0] - lo[0])) - 1) << lo[0]);
        }
    }
    /* Only the rows with work can lose it (cross and marching are 0 in the others). */
    for (int word = 0; word < 2; word++) {
        uint64_t rows = ab->crossing_rows[word] | ab->marching_rows[word];
        ab->crossing_rows[word] = ab->marching_rows[word] = 0;
        for (; rows; rows &= rows - 1) {
            int r = 64 * word + __builtin_ctzll(rows);
            unsigned any = 0;
            for (int a = 0; a < 3; a++)
                any |= ab->cross[a][r] &= keep[a][r];
            ab->marching[r] &= (uint8_t)cells[r];
            ab->crossing_rows[word] |= (uint64_t)(any != 0) << (r % 64);
            ab->marching_rows[word] |= (uint64_t)(ab->marching[r] != 0) << (r % 64);
        }
    }
    return count;
}

/* Returns the cells of the brick marching cubes visits. */
static size_t classify(march_job *job, active_brick *ab)
{
    size_t lo[3], hi[3];
    iso_bricks_box(job->vol, ab->brick, lo, hi);
    for (int d = 0; d < 3; d++) {
        ab->n[d] = (uint8_t)(hi[d] - lo[d] + 1);
        ab->owned[d] = (uint8_t)(ab->brick[d] + 1 == job->bricks->count[d] ? ab->n[d] : ab->n[d] - 1);
    }
    inside_rows(job, lo, ab->n, ab->inside);
    ab->crossing_rows[0] = ab->crossing_rows[1] = 0;
    ab->marching_rows[0] = ab->marching_rows[1] = 0;
#ifdef __SSE2__
    if (full_brick(ab))
        vector_rows(ab);
    else
#endif
        scalar_rows(ab);
    size_t cells = (size_t)(ab->n[0] - 1) * (size_t)(ab->n[1] - 1) * (size_t)(ab->n[2] - 1);
    if (ab->partial)
        cells = keep_marked(ab);
    ab->vertices = number_crossings(ab);
    ab->triangles = count_triangles(ab);
    return cells;
}

typedef struct range {
    size_t begin, end;
} range;

/* Active bricks are handed out CHUNK at a time from a shared counter: on a machine where
 * another process holds one core, a fixed split waits for the thread stuck there, while
 * chunks let the free core take more. Chunks of 8 were slower on CThead (neighbouring
 * bricks, which read each other's crossing rows, ended up on different cores); 64 were
 * as fast as the fixed split on an idle machine. */
#define CHUNK 64

static int next_chunk(march_job *job, range *r)
{
    return iso_parallel_next_chunk(&job->next_brick, job->active_count, CHUNK, &r->begin, &r->end);
}

/* Bricks in chunks from the shared counter; the mesh does not depend on which thread took
 * which brick (PASS 3 lays the bricks out in grid order). */
static void classify_share(void *context, int t, int threads)
{
    march_job *job = context;
    size_t cells = 0; /* summed here, stored once: the job's lines stay unshared */
    range r;
    (void)threads;
    while (next_chunk(job, &r))
        for (size_t i = r.begin; i < r.end; i++)
            cells += classify(job, &job->active[i]);
    job->cells[t] = cells;
}

/* ---- PASS 4: generate ---- */

/* World mm of a vertex of a volume with a rotated direction, from its float index
 * position, exactly as the other extraction paths place theirs (iso_vol_index_to_world).
 * Index space and identity directions go through job->plane instead (along_axis), to the
 * same bits: there the map is origin + index * spacing (the other terms add +0 to a sum
 * that cannot be -0, indices being >= 0). */
static void store_position(const march_job *job, const size_t c[3], int axis, double t, float *p)
{
    /* Rounded once, in one expression per coordinate: GCC 12.2's SLP vectorizer at -O2
     * dropped the float rounding of `index[axis] += t; index[d] = (float)index[d];` over
     * the array (test_march's world positions test catches that). */
    double index[3] = {(float)c[0], (float)c[1], (float)c[2]}, world[3];
    index[axis] = (float)((double)c[axis] + t);
    assert(job->world && !job->axis_aligned);
    iso_vol_index_to_world(job->vol, index, world);
    for (int d = 0; d < 3; d++)
        p[d] = (float)world[d];
}

/* The one coordinate of a vertex on an edge along axis from sample c: as store_position
 * writes it, where job->plane is there. */
static inline float along_axis(const march_job *job, int axis, size_t c, double t)
{
    double index = (float)((double)c + t);
    return (float)(job->offset[axis] + index * job->scale[axis]);
}

/* Fills job->plane, or leaves it NULL where positions need the direction. */
static int make_planes(march_job *job)
{
    const iso_volume *vol = job->vol;
    if (job->world && !job->axis_aligned)
        return 0;
    float *all = malloc((vol->dims[0] + vol->dims[1] + vol->dims[2]) * sizeof *all);
    if (!all)
        return ISO_E_NOMEM;
    for (int d = 0; d < 3; d++) {
        job->plane[d] = d ? job->plane[d - 1] + vol->dims[d - 1] : all;
        job->offset[d] = job->world ? vol->origin[d] : 0.0;
        job->scale[d] = job->world ? vol->spacing[d] : 1.0;
        for (size_t i = 0; i < vol->dims[d]; i++)
            job->plane[d][i] = along_axis(job, d, i, 0.0);
    }
    return 0;
}

/* The vertex id of every crossing edge of one brick's sample box, [axis][z * 9 + y][x],
 * brick-local: its own crossings' as PASS 4 places them, its upper faces' looked up in
 * the neighbours once per edge. A triangle corner is then one load. Entries of edges that
 * do not cross are never read. 8.7 KB, on the generating thread's stack. */
typedef struct id_table {
    uint32_t at[3][ROWS][S];
} id_table;

/* The crossings of row r along axis a of a brick: ids into table from *id, positions from
 * p on; returns p past them. Inlined with a constant a, so that the position's axis and
 * the sample step fold. c is the row's first sample, row_at its linear index. */
static inline __attribute__((always_inline)) float *place_row(const march_job *job, const active_brick *ab,
                                                              id_table *table, const iso_voxel_type type,
                                                              const int indicator, const int a, int r, const size_t c[3],
                                                              size_t row_at, uint32_t *id, double *worst, float *p)
{
    const iso_volume *vol = job->vol;
    const double level = job->level;
    const int integer = type != ISO_F32 && type != ISO_F64;
    const size_t step = a == 0 ? 1 : a == 1 ? vol->dims[0] : vol->dims[0] * vol->dims[1];
    const float *plane_x = job->plane[0];
    /* What is the same along the row is read once (the compiler cannot hoist it: p may
     * alias the planes). */
    const float row_y = plane_x ? job->plane[1][c[1]] : 0, row_z = plane_x ? job->plane[2][c[2]] : 0;
    uint32_t next = *id;
    double most = *worst;
    for (unsigned m = ab->cross[a][r]; m; m &= m - 1) {
        int x = __builtin_ctz(m);
        table->at[a][r][x] = next++;
        double t = 0.5; /* the indicator's 0 and 1 cross 0.5 midway, exactly */
        if (!indicator) {
            size_t at = row_at + (size_t)x;
            double from = iso_vol_sample_as(vol->data, type, at);
            double to = iso_vol_sample_as(vol->data, type, at + step);
            t = integer ? iso_mc_edge_t_finite(from, to, level) : iso_mc_edge_t(from, to, level);
            double e = iso_mc_edge_error(from, to, t, level);
            if (e > most)
                most = e;
        }
        size_t cx = c[0] + (size_t)x;
        if (plane_x) {
            p[0] = a == 0 ? along_axis(job, 0, cx, t) : plane_x[cx];
            p[1] = a == 1 ? along_axis(job, 1, c[1], t) : row_y;
            p[2] = a == 2 ? along_axis(job, 2, c[2], t) : row_z;
        } else {
            const size_t corner[3] = {cx, c[1], c[2]};
            store_position(job, corner, a, t, p);
        }
        p += 3;
    }
    *id = next;
    *worst = most;
    return p;
}

/* Positions of the brick's owned crossings, in numbering order (rows in ascending
 * r = z * 9 + y, then axis, then x), and their ids into table; returns the largest
 * vertex error. */
static inline __attribute__((always_inline)) double place_vertices_as(const march_job *job, const active_brick *ab,
                                                                      id_table *table, const iso_voxel_type type,
                                                                      const int indicator)
{
    const iso_volume *vol = job->vol;
    const size_t row_step = vol->dims[0], plane_step = vol->dims[0] * vol->dims[1];
    size_t lo[3];
    brick_origin(ab, lo);
    float *p = job->mesh->positions + 3 * ab->first_vertex;
    uint32_t id = (uint32_t)ab->first_vertex;
    double worst = 0;
    for (int word = 0; word < 2; word++)
        for (uint64_t rows = ab->crossing_rows[word]; rows; rows &= rows - 1) {
            int r = 64 * word + __builtin_ctzll(rows);
            const size_t c[3] = {lo[0], lo[1] + (size_t)(r % S), lo[2] + (size_t)(r / S)};
            size_t row_at = c[0] + c[1] * row_step + c[2] * plane_step;
            p = place_row(job, ab, table, type, indicator, 0, r, c, row_at, &id, &worst, p);
            p = place_row(job, ab, table, type, indicator, 1, r, c, row_at, &id, &worst, p);
            p = place_row(job, ab, table, type, indicator, 2, r, c, row_at, &id, &worst, p);
        }
    assert(p == job->mesh->positions + 3 * (ab->first_vertex + ab->vertices));
    return worst;
}

/* place_vertices_as, one copy per voxel type (the sample reads without a switch). */
static double place_vertices(const march_job *job, const active_brick *ab, id_table *table)
{
    if (job->indicator) /* reads no sample: one copy for every type */
        return place_vertices_as(job, ab, table, ISO_U8, 1);
    switch (job->vol->type) {
    case ISO_U8: return place_vertices_as(job, ab, table, ISO_U8, 0);
    case ISO_I8: return place_vertices_as(job, ab, table, ISO_I8, 0);
    case ISO_U16: return place_vertices_as(job, ab, table, ISO_U16, 0);
    case ISO_I16: return place_vertices_as(job, ab, table, ISO_I16, 0);
    case ISO_U32: return place_vertices_as(job, ab, table, ISO_U32, 0);
    case ISO_I32: return place_vertices_as(job, ab, table, ISO_I32, 0);
    case ISO_F32: return place_vertices_as(job, ab, table, ISO_F32, 0);
    case ISO_F64: return place_vertices_as(job, ab, table, ISO_F64, 0);
    }
    return 0;
}

/* The index in job->active of the brick at grid index at, or -1: from the slot array, or
 * for listed bricks by bisection of the list (iso_march_label: a few lookups per brick
 * with triangles, against a pass over the whole grid to fill an array). */
static int32_t slot_at(const march_job *job, size_t at)
{
    if (job->slot)
        return job->slot[at];
    size_t lo = 0, hi = job->listed_count;
    while (lo < hi) {
        size_t mid = lo + (hi - lo) / 2;
        if (job->listed[mid] < at)
            lo = mid + 1;
        else
            hi = mid;
    }
    return lo < job->listed_count && job->listed[lo] == at ? (int32_t)lo : -1;
}

/* The brick and its upper neighbours, by k = up_x | up_y << 1 | up_z << 2 (NULL where
 * there is none, or none active). */
static void neighbours_of(const march_job *job, const active_brick *ab, const active_brick *out[8])
{
    const iso_bricks *g = job->bricks;
    out[0] = ab;
    for (int k = 1; k < 8; k++) {
        uint32_t b[3] = {ab->brick[0] + (uint32_t)(k & 1), ab->brick[1] + (uint32_t)(k >> 1 & 1),
                         ab->brick[2] + (uint32_t)(k >> 2 & 1)};
        out[k] = NULL;
        if (b[0] < g->count[0] && b[1] < g->count[1] && b[2] < g->count[2]) {
            int32_t slot = slot_at(job, ((size_t)b[2] * g->count[1] + b[1]) * g->count[0] + b[0]);
            out[k] = slot >= 0 ? &job->active[slot] : NULL;
        }
    }
}

/* The crossing edges in m (bits x < owned x) of row r along axis, owned by the neighbour
 * whose own row is owner_row: numbered there in increasing x, from the row's first id. */
static inline void shared_run(uint32_t *ids, unsigned m, const active_brick *owner, int owner_row, int axis)
{
    if (!m)
        return; /* the neighbour may be inactive then */
    assert(owner);
    uint32_t id = (uint32_t)(owner->first_vertex + owner->before[axis][owner_row]);
    for (; m; m &= m - 1)
        ids[__builtin_ctz(m)] = id++;
}

/* The crossing on the edge at x = 8 of row r along axis, if any: the first of the
 * x neighbour's row. */
static inline void shared_corner(uint32_t *ids, unsigned m, const active_brick *owner, int owner_row, int axis)
{
    if (!(m >> ISO_BRICK_CELLS & 1))
        return;
    assert(owner);
    ids[ISO_BRICK_CELLS] = (uint32_t)(owner->first_vertex + owner->before[axis][owner_row]);
}

#ifdef __SSE2__
/* The x face's column of a full brick, 8 rows at a time: the rows whose edge at x = 8
 * along y or z crosses (bit 8 of the same xors as vector_rows), then only those. */
static void column_ids(const active_brick *ab, const active_brick *owner, id_table *table)
{
    uint64_t rows[2][2] = {{0, 0}, {0, 0}}; /* [y, z][word] */
    for (int k = 0; k < ROW_VECTORS; k++) {
        int r = 8 * k;
        const uint16_t *in = ab->inside + r;
        __m128i own = _mm_loadu_si128((const __m128i *)(full_rows + r)); /* 0xFF where owned */
        __m128i column = _mm_and_si128(_mm_slli_epi16(own, 1), _mm_set1_epi16(0x100));
        __m128i a = _mm_loadu_si128((const __m128i *)in);
        __m128i y = _mm_and_si128(_mm_xor_si128(a, _mm_loadu_si128((const __m128i *)(in + 1))), column);
        __m128i z = _mm_and_si128(_mm_xor_si128(a, _mm_loadu_si128((const __m128i *)(in + S))), column);
        rows[0][r / 64] |= nonzero_rows(y) << (r % 64);
        rows[1][r / 64] |= nonzero_rows(z) << (r % 64);
    }
    for (int axis = 1; axis < 3; axis++)
        for (int word = 0; word < 2; word++)
            for (uint64_t m = rows[axis - 1][word]; m; m &= m - 1) {
                int r = 64 * word + __builtin_ctzll(m);
                assert(owner);
                table->at[axis][r][ISO_BRICK_CELLS] = (uint32_t)(owner->first_vertex + owner->before[axis][r]);
            }
}
#endif

/* 1 and *id the vertex of the crossing on the data edge from sample p along axis, if some
 * selected brick numbered it (its owner); else 0. */
static int vertex_of(const march_job *job, const uint32_t p[3], int axis, uint32_t *id)
{
    const iso_bricks *g = job->bricks;
    uint32_t b[3], local[3];
    for (int d = 0; d < 3; d++) {
        b[d] = p[d] / ISO_BRICK_CELLS;
        if (b[d] >= g->count[d])
            b[d] = g->count[d] - 1; /* the last brick owns the volume's last sample plane */
        local[d] = p[d] - b[d] * ISO_BRICK_CELLS;
    }
    int32_t slot = slot_at(job, ((size_t)b[2] * g->count[1] + b[1]) * g->count[0] + b[0]);
    if (slot < 0)
        return 0;
    const active_brick *ab = &job->active[slot];
    unsigned r = local[2] * S + local[1], row = ab->cross[axis][r];
    if (!(ab->crossing_rows[r / 64] >> (r % 64) & 1) || !(row >> local[0] & 1))
        return 0;
    *id = (uint32_t)(ab->first_vertex + ab->before[axis][r] + bit_count[row & ((1u << local[0]) - 1)]);
    return 1;
}

/* The ids of the crossing edges m of row (y, z) along axis a of the brick at lo, each
 * from its owner (vertex_of). */
static inline void shared_ids_looked_up(const march_job *job, const size_t lo[3], id_table *table, unsigned m, int a,
                                        int y, int z)
{
    for (; m; m &= m - 1) {
        int x = __builtin_ctz(m);
        uint32_t p[3] = {(uint32_t)(lo[0] + (size_t)x), (uint32_t)(lo[1] + (size_t)y), (uint32_t)(lo[2] + (size_t)z)},
                 id;
        if (vertex_of(job, p, a, &id))
            table->at[a][z * S + y][x] = id;
    }
}

/* fill_shared_ids where the brick or a neighbour is not wholly marked: each crossing
 * edge of its box that a neighbour owns, from the owner (which kept it if a
 * marked block of this brick holds it, the only ones its cells use). */
static void fill_shared_ids_partial(const march_job *job, const active_brick *ab, id_table *table)
{
    const uint8_t *n = ab->n, *o = ab->owned;
    size_t lo[3];
    brick_origin(ab, lo);
    /* The rows of its upper y and z faces: any edge of theirs. */
    for (int z = 0; z < n[2]; z++)
        for (int y = z < o[2] ? o[1] : 0; y < n[1]; y++) {
            int r = z * S + y;
            unsigned row = ab->inside[r];
            shared_ids_looked_up(job, lo, table, (row ^ (row >> 1)) & ((1u << (n[0] - 1)) - 1), 0, y, z);
            if (y + 1 < n[1])
                shared_ids_looked_up(job, lo, table, row ^ ab->inside[r + 1], 1, y, z);
            if (z + 1 < n[2])
                shared_ids_looked_up(job, lo, table, row ^ ab->inside[r + S], 2, y, z);
        }
    /* The other rows: the edges along y and z at its upper x face, if it has one. */
    if (o[0] == n[0])
        return;
    unsigned column = 1u << o[0];
    for (int z = 0; z < o[2]; z++)
        for (int y = 0; y < o[1]; y++) {
            int r = z * S + y;
            unsigned row = ab->inside[r];
            if (y + 1 < n[1])
                shared_ids_looked_up(job, lo, table, (row ^ ab->inside[r + 1]) & column, 1, y, z);
            if (z + 1 < n[2])
                shared_ids_looked_up(job, lo, table, (row ^ ab->inside[r + S]) & column, 2, y, z);
        }
}

/* The ids of the crossings on the brick's upper faces, which its neighbours own (none
 * on a face that is the volume's last sample plane: the brick owns those). An edge's
 * samples belong to its owner too, so the owner's min/max hold the level: it is active.
 *
 * Face by face, since only the faces' rows have such edges: the z face (every edge of
 * its rows but those along z), the y face below it (edges along x and z), and the x
 * face's column (bit 8 of the edges along y and z of every other row). Where a row's
 * edges belong to the neighbour at the same x, they are that neighbour's crossings of
 * the same row in the same order, so their ids are consecutive from the row's first. */
static void fill_shared_ids(const march_job *job, const active_brick *ab, id_table *table)
{
    const active_brick *near[8];
    neighbours_of(job, ab, near);
    /* Where a neighbour kept only some crossings, a row's are not consecutive there. */
    int masked = ab->partial;
    for (int k = 1; k < 8 && job->marked; k++)
        masked |= near[k] && near[k]->partial;
    if (masked) {
        fill_shared_ids_partial(job, ab, table);
        return;
    }
    const uint16_t *inside = ab->inside;
    int upper[3];
    for (int d = 0; d < 3; d++)
        upper[d] = ab->owned[d] < ab->n[d]; /* the brick has an upper face along d */
    unsigned low = (1u << ab->owned[0]) - 1; /* edges along y, z the same-x owner holds */
    unsigned x_edges = (1u << (ab->n[0] - 1)) - 1;
    const int C = ISO_BRICK_CELLS;
    if (upper[2]) { /* z = 8: owners up in z (k = 4, 5, and 6, 7 past the y face) */
        int z = C;
        for (int y = 0; y < ab->n[1]; y++) {
            int r = z * S + y, up_y = y >= ab->owned[1], owner_row = r - (up_y + S) * C, k = 4 | up_y << 1;
            unsigned row = inside[r];
            shared_run(table->at[0][r], (row ^ (row >> 1)) & x_edges, near[k], owner_row, 0);
            if (y + 1 < ab->n[1]) {
                unsigned m = row ^ inside[r + 1];
                shared_run(table->at[1][r], m & low, near[k], owner_row, 1);
                if (upper[0])
                    shared_corner(table->at[1][r], m, near[k | 1], owner_row, 1);
            }
        }
    }
    if (upper[1]) { /* y = 8 below the z face: owners up in y (k = 2, 3) */
        int y = C;
        for (int z = 0; z < ab->owned[2]; z++) {
            int r = z * S + y, owner_row = r - C;
            unsigned row = inside[r];
            shared_run(table->at[0][r], (row ^ (row >> 1)) & x_edges, near[2], owner_row, 0);
            if (z + 1 < ab->n[2]) {
                unsigned m = row ^ inside[r + S];
                shared_run(table->at[2][r], m & low, near[2], owner_row, 2);
                if (upper[0])
                    shared_corner(table->at[2][r], m, near[3], owner_row, 2);
            }
        }
    }
    if (!upper[0])
        return;
#ifdef __SSE2__
    if (full_brick(ab)) {
        column_ids(ab, near[1], table);
        return;
    }
#endif
    /* x = 8 of the rows inside both other faces: the x neighbour (k = 1) */
    for (int z = 0; z < ab->owned[2]; z++)
        for (int y = 0; y < ab->owned[1]; y++) {
            int r = z * S + y;
            unsigned row = inside[r];
            if (y + 1 < ab->n[1])
                shared_corner(table->at[1][r], row ^ inside[r + 1], near[1], r, 1);
            if (z + 1 < ab->n[2])
                shared_corner(table->at[2][r], row ^ inside[r + S], near[1], r, 2);
        }
}

/* Per case, each triangle corner as an offset into an id_table from the entry of the
 * cell's own corner 0 (axis 0, its row, its x): a corner is then one load. */
#define MAX_CORNERS 15
static uint16_t case_corner[256][MAX_CORNERS];

static void learn_edges(void)
{
    const iso_mc_case *cases = iso_mc_cases();
    int offset[12];
    for (int e = 0; e < 12; e++) {
        int lo = iso_mc_edge_corner[e][0], axis = e / 4;
        offset[e] = (axis * ROWS + (lo >> 1 & 1) + (lo >> 2 & 1) * S) * S + (lo & 1);
    }
    for (int c = 0; c < 256; c++) {
        assert(3 * cases[c].triangle_count <= MAX_CORNERS);
        for (int k = 0; k < 3 * cases[c].triangle_count; k++)
            case_corner[c][k] = (uint16_t)offset[cases[c].edges[k]];
    }
}

static void emit_triangles(const march_job *job, const active_brick *ab, const id_table *table)
{
    const iso_mc_case *cases = iso_mc_cases();
    const uint32_t *ids = &table->at[0][0][0];
    uint32_t *out = job->mesh->indices + 3 * ab->first_triangle;
    for (int word = 0; word < 2; word++)
        for (uint64_t rows = ab->marching_rows[word]; rows; rows &= rows - 1) {
            int r = 64 * word + __builtin_ctzll(rows);
            uint64_t row = row_cases(cell_row_at(ab->inside, r % S, r / S));
            for (unsigned m = ab->marching[r]; m; m &= m - 1) {
                int x = __builtin_ctz(m);
                unsigned c = case_of(row, x);
                const uint32_t *cell = ids + r * S + x;
                const uint16_t *corner = case_corner[c];
                for (int k = cases[c].triangle_count; k > 0; k--, corner += 3, out += 3) {
                    out[0] = cell[corner[0]];
                    out[1] = cell[corner[1]];
                    out[2] = cell[corner[2]];
                }
            }
        }
    assert(out == job->mesh->indices + 3 * (ab->first_triangle + ab->triangles));
}

/* Asks for the sample rows of the brick's owned crossings ahead of time: PASS 2 read
 * them long before, and along y and z consecutive rows are far apart in memory. The rows
 * are those with crossings and those their edges along y and z end in. */
static void prefetch_samples(const march_job *job, const active_brick *ab)
{
    const iso_volume *vol = job->vol;
    size_t size = iso_vol_type_size(vol->type), lo[3];
    brick_origin(ab, lo);
    const char *base = (const char *)vol->data + ((lo[2] * vol->dims[1] + lo[1]) * vol->dims[0] + lo[0]) * size;
    size_t row_bytes = vol->dims[0] * size, plane_bytes = vol->dims[1] * row_bytes;
    for (int word = 0; word < 2; word++)
        for (uint64_t rows = ab->crossing_rows[word]; rows; rows &= rows - 1) {
            int r = 64 * word + __builtin_ctzll(rows);
            const char *row = base + (size_t)(r / S) * plane_bytes + (size_t)(r % S) * row_bytes;
            __builtin_prefetch(row);
            if (ab->cross[1][r])
                __builtin_prefetch(row + row_bytes);
            if (ab->cross[2][r])
                __builtin_prefetch(row + plane_bytes);
        }
}

static void generate_share(void *context, int t, int threads)
{
    march_job *job = context;
    double worst = 0;
    id_table table;
    range r;
    (void)threads;
    /* Every brick writes its own, already counted range of the mesh, so chunks may go to
     * any thread in any order and the mesh is the same. */
    while (next_chunk(job, &r))
        for (size_t i = r.begin; i < r.end; i++) {
            const active_brick *ab = &job->active[i];
            if (i + 1 < r.end && job->active[i + 1].vertices)
                prefetch_samples(job, &job->active[i + 1]);
            if (ab->vertices) {
                double e = place_vertices(job, ab, &table);
                if (e > worst)
                    worst = e;
            }
            if (ab->triangles) {
                fill_shared_ids(job, ab, &table);
                emit_triangles(job, ab, &table);
            }
        }
    job->error[t] = worst;
}

/* ---- the passes in order ---- */

/* The largest float not above level: a float x is <= level exactly when x <= it, and
 * > level exactly when x > it, so the bricks' float bounds are compared without widening
 * each one to double. */
static float float_at_or_below(double level)
{
    float f = (float)level;
    return (double)f > level ? nextafterf(f, -INFINITY) : f;
}

/* Numbers the selected bricks in grid order: slot[at] is the number or -1, order[n] the
 * grid index of number n. One branch-free pass over the grid, as many bricks are
 * inactive as there are in a sparse volume. */
static size_t number_selected(const march_job *job, int prune, int32_t *slot, uint32_t *order)
{
    const iso_bricks *g = job->bricks;
    size_t total = iso_bricks_total(g), n = 0;
    float level = float_at_or_below(job->level);
    for (size_t at = 0; at < total; at++) {
        int on = !prune || ((g->min[at] <= level) & (g->max[at] > level));
        slot[at] = on ? (int32_t)n : -1;
        order[n] = (uint32_t)at;
        n += (size_t)on;
    }
    return n;
}

/* The blocks brick b has, bit x | y << 1 | z << 2: two per axis, one where the border
 * clips it to at most ISO_TREE_BLOCK cells. */
static unsigned blocks_of(const march_job *job, const uint32_t b[3])
{
    static const unsigned low_half[3] = {0x55, 0x33, 0x0F};
    unsigned have = 0xFF;
    for (int d = 0; d < 3; d++)
        if (job->vol->dims[d] - 1 - (size_t)b[d] * ISO_BRICK_CELLS <= ISO_TREE_BLOCK)
            have &= low_half[d];
    return have;
}

/* How brick b takes part in iso_march_selected: 0 not at all, 1 wholly marked, 2 partly:
 * it has marked blocks, or it is a ghost (the level crosses it and it owns edges that a
 * lower neighbour's marked blocks hold). lower[0]: its own marked blocks; lower[k]: those
 * of the neighbour at -(k & 1), -(k >> 1 & 1), -(k >> 2 & 1) whose closed boxes reach its
 * low planes (the upper blocks along every axis where k steps down). */
static int marks_of(const march_job *job, const uint32_t b[3], float level, uint8_t lower[8])
{
    static const unsigned upper_half[3] = {0xAA, 0xCC, 0xF0};
    const iso_bricks *g = job->bricks;
    size_t at = ((size_t)b[2] * g->count[1] + b[1]) * g->count[0] + b[0];
    unsigned mark = job->marked[at];
    int active = g->min[at] <= level && g->max[at] > level;
    if (!mark && !active)
        return 0; /* most bricks: decided before their blocks are counted */
    unsigned have = blocks_of(job, b), own = mark & have, reach = 0;
    lower[0] = (uint8_t)own;
    if (own == have)
        return 1;
    for (int k = 1; k < 8; k++) {
        uint32_t o[3] = {k & 1, k >> 1 & 1, k >> 2 & 1};
        lower[k] = 0;
        if ((o[0] && !b[0]) || (o[1] && !b[1]) || (o[2] && !b[2]))
            continue;
        size_t n = ((size_t)(b[2] - o[2]) * g->count[1] + (b[1] - o[1])) * g->count[0] + (b[0] - o[0]);
        unsigned m = job->marked[n];
        for (int d = 0; d < 3; d++)
            if (o[d])
                m &= upper_half[d];
        lower[k] = (uint8_t)m;
        reach |= m;
    }
    return own || reach ? 2 : 0;
}

/* number_selected for iso_march_selected: the bricks with marked blocks and their ghosts. */
static size_t number_marked(const march_job *job, int32_t *slot, uint32_t *order)
{
    const iso_bricks *g = job->bricks;
    float level = float_at_or_below(job->level);
    size_t n = 0, at = 0;
    uint8_t lower[8];
    for (uint32_t k = 0; k < g->count[2]; k++)
        for (uint32_t j = 0; j < g->count[1]; j++)
            for (uint32_t i = 0; i < g->count[0]; i++, at++) {
                uint32_t b[3] = {i, j, k};
                /* marks_of's first test, inline: most bricks stop at it. */
                int near = job->marked[at] || (g->min[at] <= level && g->max[at] > level);
                int taken = near && marks_of(job, b, level, lower);
                slot[at] = taken ? (int32_t)n : -1;
                if (slot[at] >= 0)
                    order[n++] = (uint32_t)at;
            }
    return n;
}

/* iso_march_label's bricks: the list as given. */
static int select_listed(march_job *job)
{
    const iso_bricks *g = job->bricks;
    size_t n = job->listed_count;
    job->active = malloc((n ? n : 1) * sizeof *job->active);
    if (!job->active)
        return ISO_E_NOMEM;
    for (size_t i = 0; i < n; i++) {
        active_brick *ab = &job->active[i];
        uint32_t at = job->listed[i];
        assert(at < iso_bricks_total(g) && (i == 0 || job->listed[i - 1] < at));
        ab->brick[0] = at % g->count[0];
        ab->brick[1] = at / g->count[0] % g->count[1];
        ab->brick[2] = at / g->count[0] / g->count[1];
        ab->partial = 0;
    }
    job->active_count = n;
    return 0;
}

static int select_bricks(march_job *job, int prune)
{
    const iso_bricks *g = job->bricks;
    size_t total = iso_bricks_total(g);
    if (job->listed)
        return select_listed(job);
    job->slot = malloc(total * sizeof *job->slot);
    uint32_t *order = malloc(total * sizeof *order);
    if (!job->slot || !order) {
        free(order);
        return ISO_E_NOMEM;
    }
    size_t n = job->marked ? number_marked(job, job->slot, order) : number_selected(job, prune, job->slot, order);
    job->active = malloc((n ? n : 1) * sizeof *job->active);
    if (!job->active) {
        free(order);
        return ISO_E_NOMEM;
    }
    float level = float_at_or_below(job->level);
    for (size_t i = 0; i < n; i++) {
        active_brick *ab = &job->active[i];
        uint32_t at = order[i];
        ab->brick[0] = at % g->count[0];
        ab->brick[1] = at / g->count[0] % g->count[1];
        ab->brick[2] = at / g->count[0] / g->count[1];
        ab->partial = job->marked && marks_of(job, ab->brick, level, ab->lower) == 2;
        ab->blocks = ab->lower[0];
    }
    free(order);
    job->active_count = n;
    return 0;
}

static int lay_out_mesh(march_job *job, iso_mesh *mesh)
{
    size_t vertices = 0, triangles = 0;
    for (size_t i = 0; i < job->active_count; i++) {
        job->active[i].first_vertex = vertices;
        job->active[i].first_triangle = triangles;
        vertices += job->active[i].vertices;
        triangles += job->active[i].triangles;
    }
    if (vertices > UINT32_MAX)
        return ISO_E_LIMIT;
    iso_mesh_clear(mesh);
    if (iso_mesh_reserve(mesh, vertices, triangles))
        return ISO_E_NOMEM;
    mesh->vertex_count = vertices;
    mesh->triangle_count = triangles;
    return 0;
}

static int run_passes(march_job *job, int prune, int threads, iso_march_stats *stats)
{
    threads = iso_parallel_threads(threads);
    int rc = make_planes(job);
    if (rc)
        return rc;
    rc = select_bricks(job, prune);
    if (rc)
        return rc;
    int used = job->active_count < (size_t)threads ? (job->active_count ? (int)job->active_count : 1) : threads;
    atomic_store_explicit(&job->next_brick, 0, memory_order_relaxed);
    iso_parallel_run(used, classify_share, job);
    rc = lay_out_mesh(job, job->mesh);
    if (rc)
        return rc;
    atomic_store_explicit(&job->next_brick, 0, memory_order_relaxed);
    iso_parallel_run(used, generate_share, job);
    for (int t = 0; t < used; t++)
        if (job->error[t] > stats->error_bound)
            stats->error_bound = job->error[t];
    stats->bricks_active = job->active_count;
    for (int t = 0; t < used; t++)
        stats->cells_visited += job->cells[t];
    return 0;
}

static void march_free(march_job *job)
{
    if (!job)
        return;
    free(job->slot);
    free(job->active);
    free(job->plane[0]);
    free(job);
}

/* Which bricks a march visits and what it classifies, beyond the min/max default. */
typedef struct march_choice {
    const uint8_t *marked;   /* iso_march_selected */
    const uint32_t *listed;  /* iso_march_label: its bricks and label */
    size_t listed_count;
    int64_t label;
} march_choice;

/* Runs the passes on a new job; *out keeps it (for iso_march_part_vertex) if not NULL. */
static int march(const iso_volume *vol, const iso_bricks *bricks, double level, int prune, const march_choice *choice,
                 int world, int threads, iso_mesh *mesh, iso_march_stats *stats, march_job **out, iso_error *err)
{
    static pthread_once_t once = PTHREAD_ONCE_INIT;
    assert(vol && bricks && mesh && stats);
    pthread_once(&once, make_tables);
    memset(stats, 0, sizeof *stats);
    march_job *job = calloc(1, sizeof *job);
    if (!job) {
        iso_mesh_free(mesh);
        return iso_error_set(err, ISO_E_NOMEM, "out of memory extracting the surface");
    }
    job->vol = vol;
    job->bricks = bricks;
    job->level = level;
    job->marked = choice ? choice->marked : NULL;
    job->listed = choice ? choice->listed : NULL;
    job->listed_count = choice ? choice->listed_count : 0;
    job->indicator = job->listed != NULL;
    if (job->indicator)
        make_label(vol->type, choice->label, &job->threshold);
    else
        make_threshold(vol->type, level, &job->threshold);
    job->mesh = mesh;
    job->world = world;
    job->axis_aligned = 1;
    for (int r = 0; r < 3; r++)
        for (int c = 0; c < 3; c++)
            job->axis_aligned &= vol->direction[r][c] == (r == c);
    int rc = run_passes(job, prune, threads, stats);
    if (rc || !out) {
        march_free(job);
        job = NULL;
    }
    if (out)
        *out = job;
    if (rc) {
        iso_mesh_free(mesh);
        if (rc == ISO_E_LIMIT)
            return iso_error_set(err, rc, "the surface needs more than 2^32 - 1 vertices");
        return iso_error_set(err, ISO_E_NOMEM, "out of memory extracting the surface");
    }
    return 0;
}

int iso_march_bricks(const iso_volume *vol, const iso_bricks *bricks, double level, int prune,
                     int world, int threads, iso_mesh *mesh, iso_march_stats *stats, iso_error *err)
{
    return march(vol, bricks, level, prune, NULL, world, threads, mesh, stats, NULL, err);
}

int iso_march_label(const iso_volume *vol, const iso_bricks *bricks, int64_t label, const uint32_t *listed,
                    size_t count, int world, int threads, iso_mesh *mesh, iso_march_stats *stats, iso_error *err)
{
    static const uint32_t none[1] = {0};
    march_choice choice = {.listed = count ? listed : none, .listed_count = count, .label = label};
    return march(vol, bricks, 0.5, 1, &choice, world, threads, mesh, stats, NULL, err);
}

int iso_march_selected(const iso_volume *vol, const iso_bricks *bricks, double level, const uint8_t *marked,
                       int threads, iso_mesh *mesh, iso_march_stats *stats, iso_march_part **part,
                       iso_error *err)
{
    march_choice choice = {.marked = marked};
    return march(vol, bricks, level, 0, &choice, 0, threads, mesh, stats, part, err);
}

int iso_march_part_vertex(const iso_march_part *job, const uint32_t p[3], int axis, uint32_t *id)
{
    return vertex_of(job, p, axis, id);
}

void iso_march_part_free(iso_march_part *part)
{
    march_free(part);
}
