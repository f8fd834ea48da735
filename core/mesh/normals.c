/* normals.c: B-spline gradient normals (Elber and Malzbender, section 4; see mesh.h).
 *
 * Uniform B-spline bases, per axis, at x = i + t (closed forms of the standard tables):
 *   order 2 (linear, support 2):    i = floor(x):   {1-t, t}
 *   order 3 (quadratic, support 3): i = round(x):   {(1/2-t)^2/2, 3/4-t^2, (1/2+t)^2/2}
 *                                   on samples i-1, i, i+1, t in [-1/2, 1/2]
 *   order 4 (cubic, support 4):     i = floor(x):   {(1-t)^3, 3t^3-6t^2+4, -3t^3+3t^2+3t+1, t^3}/6
 *                                   on samples i-1 .. i+2
 * with their derivatives in t. The gradient's component along an axis takes that axis's
 * derivative weights and the other two axes' weights. */
#include "mesh.h"

#include <assert.h>
#include <math.h>
#include <stdint.h>
#include <stdlib.h>
#include <string.h>

#include "base/base.h"

#if defined(__SSE2__)
#include <immintrin.h>
#endif

static const char *const order_names[5] = {"none", NULL, "trilinear", "triquadratic", "tricubic"};

int iso_normals_order_from_name(const char *name)
{
    for (int o = 0; name && o < 5; o++)
        if (order_names[o] && !strcmp(name, order_names[o]))
            return o;
    return -1;
}

const char *iso_normals_name(int order)
{
    assert(order == 0 || (order >= 2 && order <= 4));
    return order_names[order];
}

/* floor(x) without libm's rounding sequence (the baseline x86-64 has no round
 * instruction): a zero may come out +0 where floor gives -0, which no weight or sum here
 * can tell apart (every sum starts at +0, and a signed zero added to it changes nothing). */
static inline double floor_fast(double x)
{
    if (!(fabs(x) < 0x1p52))
        return floor(x);
    double i = (double)(int64_t)x;
    return i > x ? i - 1 : i;
}

/* *qa = a / by_a and *qb = b / by_b, both in one instruction where there is one (the
 * quotients are the same: each is correctly rounded). */
static inline void div2(double a, double by_a, double b, double by_b, double *qa, double *qb)
{
#if defined(__SSE2__)
    __m128d q = _mm_div_pd(_mm_set_pd(b, a), _mm_set_pd(by_b, by_a));
    *qa = _mm_cvtsd_f64(q);
    *qb = _mm_cvtsd_f64(_mm_unpackhi_pd(q, q));
#else
    *qa = a / by_a;
    *qb = b / by_b;
#endif
}

/* Weights w and derivative weights d of one axis at coordinate x; *first is the sample of
 * weight 0 (may lie outside 0..n-1: callers clamp). */
static inline __attribute__((always_inline)) void basis(const int order, double x, size_t n, long *first, double w[4], double d[4])
{
    if (order == 2) {
        double i = floor_fast(x);
        if (i > (double)n - 2)
            i = (double)n - 2; /* the last sample plane belongs to the last cell */
        if (i < 0)
            i = 0;
        double t = x - i;
        *first = (long)i;
        w[0] = 1 - t, w[1] = t;
        d[0] = -1, d[1] = 1;
    } else if (order == 3) {
        double i = floor_fast(x + 0.5), t = x - i;
        *first = (long)i - 1;
        w[0] = 0.5 * (0.5 - t) * (0.5 - t), w[1] = 0.75 - t * t, w[2] = 0.5 * (0.5 + t) * (0.5 + t);
        d[0] = t - 0.5, d[1] = -2 * t, d[2] = 0.5 + t;
    } else {
        double i = floor_fast(x), t = x - i, s = 1 - t;
        *first = (long)i - 1;
        div2(s * s * s, 6, 3 * t * t * t - 6 * t * t + 4, 6, &w[0], &w[1]);
        div2(-3 * t * t * t + 3 * t * t + 3 * t + 1, 6, t * t * t, 6, &w[2], &w[3]);
        d[0] = -s * s / 2;
        d[1] = (3 * t * t - 4 * t) / 2;
        d[2] = (-3 * t * t + 2 * t + 1) / 2;
        d[3] = t * t / 2;
    }
}

static size_t clamp_index(long i, size_t n)
{
    return i < 0 ? 0 : (size_t)i >= n ? n - 1 : (size_t)i;
}

/* The n[0] x n[1] x n[2] samples of the spline's support from first[] on, x fastest, into
 * block: border samples repeated, NaN read as the volume's minimum. Row offsets are
 * computed once per axis, and the voxel type is switched on once per vertex, not per
 * sample. */
#define GATHER(T)                                                                   \
    do {                                                                            \
        const T *data = (const T *)vol->data;                                       \
        _Pragma("GCC unroll 4") for (int k = 0; k < n2; k++)                        \
            _Pragma("GCC unroll 4") for (int j = 0; j < n1; j++) {                  \
                const T *row = data + z[k] * plane + y[j] * vol->dims[0];           \
                _Pragma("GCC unroll 4") for (int i = 0; i < n0; i++)                \
                    *out++ = (double)row[x[i]];                                     \
            }                                                                       \
    } while (0)

static inline __attribute__((always_inline)) void gather(const iso_volume *vol, const int n0, const int n1,
                                                         const int n2, const long first[3], double *block)
{
    size_t x[4], y[4], z[4], plane = vol->dims[0] * vol->dims[1];
    if (first[0] >= 0 && first[1] >= 0 && first[2] >= 0 && (size_t)first[0] + (size_t)n0 <= vol->dims[0] &&
        (size_t)first[1] + (size_t)n1 <= vol->dims[1] && (size_t)first[2] + (size_t)n2 <= vol->dims[2]) {
        /* Inside the volume, as nearly every vertex is: no clamping. */
        for (int a = 0; a < 4; a++) {
            x[a] = (size_t)first[0] + (size_t)a;
            y[a] = (size_t)first[1] + (size_t)a;
            z[a] = (size_t)first[2] + (size_t)a;
        }
    } else {
        for (int a = 0; a < n0; a++)
            x[a] = clamp_index(first[0] + a, vol->dims[0]);
        for (int a = 0; a < n1; a++)
            y[a] = clamp_index(first[1] + a, vol->dims[1]);
        for (int a = 0; a < n2; a++)
            z[a] = clamp_index(first[2] + a, vol->dims[2]);
    }
    double *out = block;
    switch (vol->type) {
    case ISO_U8: GATHER(uint8_t); break;
    case ISO_I8: GATHER(int8_t); break;
    case ISO_U16: GATHER(uint16_t); break;
    case ISO_I16: GATHER(int16_t); break;
    case ISO_U32: GATHER(uint32_t); break;
    case ISO_I32: GATHER(int32_t); break;
    case ISO_F32: GATHER(float); break;
    case ISO_F64: GATHER(double); break;
    default: /* a loaded volume has one of the types above */
        assert(0);
        memset(block, 0, sizeof(double) * (size_t)(n0 * n1 * n2));
    }
    if (vol->has_nan)
        for (int n = 0; n < n0 * n1 * n2; n++)
            if (block[n] != block[n])
                block[n] = vol->value_min;
}

/* The spline's gradient in index space from its weights, separably: each x row of the
 * block reduces to its value and x derivative, each y column of those to three partial
 * sums, then z. About 2 n^3 + 3 n^2 + 6 multiply-adds instead of 3 n^3 products of four.
 * Inlined with constant tap counts (gradient_2/3/4) so that its loops unroll. */
static inline __attribute__((always_inline)) void spline_gradient(const iso_volume *vol, const int n0,
                                                                  const int n1, const int n2,
                                                                  const long first[3], const double (*w)[4],
                                                                  const double (*d)[4], double g[3])
{
    double block[64];
    gather(vol, n0, n1, n2, first, block);
    g[0] = g[1] = g[2] = 0;
#pragma GCC unroll 4
    for (int k = 0; k < n2; k++) {
        double value_xy = 0, dx_y = 0, x_dy = 0; /* f, df/dx, df/dy on this z plane */
#pragma GCC unroll 4
        for (int j = 0; j < n1; j++) {
            const double *row = block + (k * n1 + j) * n0;
            double value_x = 0, dx = 0;
#pragma GCC unroll 4
            for (int i = 0; i < n0; i++) {
                value_x += w[0][i] * row[i];
                dx += d[0][i] * row[i];
            }
            value_xy += w[1][j] * value_x;
            x_dy += d[1][j] * value_x;
            dx_y += w[1][j] * dx;
        }
        g[0] += w[2][k] * dx_y;
        g[1] += w[2][k] * x_dy;
        g[2] += d[2][k] * value_xy;
    }
}

static inline __attribute__((always_inline)) void gradient_of(const iso_volume *vol, const int order,
                                                              const double p[3], double g[3])
{
    double w[3][4], d[3][4];
    long first[3];
    for (int a = 0; a < 3; a++)
        basis(order, p[a], vol->dims[a], &first[a], w[a], d[a]);
    spline_gradient(vol, order, order, order, first, w, d, g);
}

static void gradient_2(const iso_volume *vol, const double p[3], double g[3]) { gradient_of(vol, 2, p, g); }
static void gradient_3(const iso_volume *vol, const double p[3], double g[3]) { gradient_of(vol, 3, p, g); }

/* ---- the tricubic gradient at a grid edge's crossing ----
 *
 * Every vertex marching cubes places lies on a grid edge: two of its three coordinates
 * are sample planes. There the cubic's weights are {1, 4, 1, 0} / 6 and its derivative's
 * {-1, 0, 1, 0} / 2: one tap of four vanishes on each of those axes, and the support is
 * 4 x 3 x 3 samples, not 64. World positions come back to index space through floats, so
 * a plane is recognised within EDGE_SLACK of a sample and its vanishing tap dropped
 * there: that tap's weights are then below EDGE_SLACK^2 / 2 (5e-9), far under a float
 * normal's rounding. */
#define EDGE_SLACK 1e-4

/* Which of coordinate p's four taps vanishes: 1 the last (t^3 / 6, p just above a sample
 * plane), 2 the first ((1 - t)^3 / 6, just below one), 0 none. */
static inline __attribute__((always_inline)) int vanishing_tap(double p)
{
    double t = p - floor_fast(p);
    return t < EDGE_SLACK ? 1 : t > 1 - EDGE_SLACK ? 2 : 0;
}

static void gradient_4(const iso_volume *vol, const double p[3], double g[3])
{
    double w[3][4], d[3][4];
    long first[3];
    int tap[3];
    unsigned planes = 0;
    for (int a = 0; a < 3; a++) {
        basis(4, p[a], vol->dims[a], &first[a], w[a], d[a]);
        tap[a] = vanishing_tap(p[a]);
        planes |= (unsigned)(tap[a] != 0) << a;
    }
    if (planes != 3 && planes != 5 && planes != 6) {
        spline_gradient(vol, 4, 4, 4, first, w, d, g); /* a fan centre, a sample */
        return;
    }
    /* On a grid edge: the two plane axes keep their three taps that do not vanish. */
    for (int a = 0; a < 3; a++)
        if (tap[a] == 2) {
            for (int i = 0; i < 3; i++)
                w[a][i] = w[a][i + 1], d[a][i] = d[a][i + 1];
            first[a]++;
        }
    if (planes == 6)
        spline_gradient(vol, 4, 3, 3, first, w, d, g); /* an x edge */
    else if (planes == 5)
        spline_gradient(vol, 3, 4, 3, first, w, d, g); /* a y edge */
    else
        spline_gradient(vol, 3, 3, 4, first, w, d, g); /* a z edge */
}

/* ---- the tricubic gradient on a grid edge, in integers ----
 *
 * The vertex lies on the edge: its two plane coordinates are samples, and only the float
 * round trip puts them a hair (under EDGE_SLACK) off. Taken at the edge point itself, the
 * plane axes' weights are the constants {1, 4, 1} / 6 and {-1, 0, 1} / 2, so each of the
 * four 3 x 3 cross-sections along the edge reduces to three sums with small integer
 * weights: exact in 32-bit integers for voxels of up to 16 bits (in doubles for wider
 * ones), one row of three samples at a time. Only the edge axis keeps weights that vary.
 * The hair's own effect on the weights is left out: it is rounding noise, not geometry
 * (under 1e-3 of a unit normal on test_normals' steep field). */

/* s[a], dp[a], dq[a]: the cross-section at edge sample a weighted {1,4,1} x {1,4,1},
 * {-1,0,1} x {1,4,1} (derivative along the first plane axis) and {1,4,1} x {-1,0,1}. */
#define EDGE_SUMS(T, ACC)                                                                  \
    do {                                                                                   \
        const T *v0 = (const T *)vol->data + base;                                         \
        for (int a = 0; a < 4; a++) {                                                      \
            ACC u[3], dv[3];                                                               \
            for (int c = 0; c < 3; c++) {                                                  \
                const T *r = v0 + (size_t)a * se + (size_t)c * sq;                         \
                ACC f0 = (ACC)r[0], f1 = (ACC)r[sp], f2 = (ACC)r[2 * sp];                  \
                u[c] = f0 + 4 * f1 + f2;                                                   \
                dv[c] = f2 - f0;                                                           \
            }                                                                              \
            s[a] = (double)(u[0] + 4 * u[1] + u[2]);                                       \
            dp[a] = (double)(dv[0] + 4 * dv[1] + dv[2]);                                   \
            dq[a] = (double)(u[2] - u[0]);                                                 \
        }                                                                                  \
    } while (0)

#if defined(__SSE2__)
/* The same sums for 8- and 16-bit voxels, four lanes of 32-bit integers at a time (SSE2,
 * every x86-64): integer sums are exact in any order, so s, dp and dq are the scalar
 * sums' values. Four samples along x are loaded as one lane vector. */
static inline __attribute__((always_inline)) __m128i load4(const void *p, const iso_voxel_type type)
{
    __m128i z = _mm_setzero_si128(), v;
    if (type == ISO_U8 || type == ISO_I8) {
        int32_t word;
        memcpy(&word, p, sizeof word);
        v = _mm_cvtsi32_si128(word);
        v = type == ISO_U8 ? _mm_unpacklo_epi8(v, z) : _mm_srai_epi16(_mm_unpacklo_epi8(v, v), 8);
    } else {
        v = _mm_loadl_epi64((const __m128i *)p);
    }
    return type == ISO_I8 || type == ISO_I16 ? _mm_srai_epi32(_mm_unpacklo_epi16(v, v), 16)
                                             : _mm_unpacklo_epi16(v, z);
}

static inline __m128i x4(__m128i v) { return _mm_slli_epi32(v, 2); }

/* a + 4b + c, lane by lane. */
static inline __m128i smooth3(__m128i a, __m128i b, __m128i c)
{
    return _mm_add_epi32(_mm_add_epi32(a, c), x4(b));
}

/* An x edge: the four edge samples are adjacent, one lane each; the nine loads are the
 * 3 x 3 cross-section's rows along x. */
static inline __attribute__((always_inline)) void edge_sums_x(const char *v0, const iso_voxel_type type,
                                                              size_t bytes, size_t sp, size_t sq, __m128i out[3])
{
    __m128i u[3], dv[3];
    for (int c = 0; c < 3; c++) {
        const char *r = v0 + c * sq * bytes;
        __m128i f0 = load4(r, type), f1 = load4(r + sp * bytes, type), f2 = load4(r + 2 * sp * bytes, type);
        u[c] = smooth3(f0, f1, f2);
        dv[c] = _mm_sub_epi32(f2, f0);
    }
    out[0] = smooth3(u[0], u[1], u[2]);
    out[1] = smooth3(dv[0], dv[1], dv[2]);
    out[2] = _mm_sub_epi32(u[2], u[0]);
}

/* Rows r0..r3 as columns: out[b] holds element b of each row. */
static inline void transpose4(const __m128i r[4], __m128i out[4])
{
    __m128i t0 = _mm_unpacklo_epi32(r[0], r[1]), t1 = _mm_unpacklo_epi32(r[2], r[3]);
    __m128i t2 = _mm_unpackhi_epi32(r[0], r[1]), t3 = _mm_unpackhi_epi32(r[2], r[3]);
    out[0] = _mm_unpacklo_epi64(t0, t1);
    out[1] = _mm_unpackhi_epi64(t0, t1);
    out[2] = _mm_unpacklo_epi64(t2, t3);
    out[3] = _mm_unpackhi_epi64(t2, t3);
}

/* A y or z edge: the plane axis along x is the lanes (the fourth is unused: the caller
 * checks that it lies inside the volume); per edge sample, the three rows are combined
 * across the other plane axis, then the 4 x 4 block is turned so that lanes are the edge
 * samples again. */
static inline __attribute__((always_inline)) void edge_sums_yz(const char *v0, const iso_voxel_type type,
                                                               size_t bytes, size_t se, size_t sq, __m128i out[3])
{
    __m128i across[4], diff[4], c_across[4], c_diff[4];
    for (int a = 0; a < 4; a++) {
        const char *r = v0 + a * se * bytes;
        __m128i f0 = load4(r, type), f1 = load4(r + sq * bytes, type), f2 = load4(r + 2 * sq * bytes, type);
        across[a] = smooth3(f0, f1, f2);
        diff[a] = _mm_sub_epi32(f2, f0);
    }
    transpose4(across, c_across);
    transpose4(diff, c_diff);
    out[0] = smooth3(c_across[0], c_across[1], c_across[2]);
    out[1] = _mm_sub_epi32(c_across[2], c_across[0]);
    out[2] = smooth3(c_diff[0], c_diff[1], c_diff[2]);
}

/* s, dp and dq (EDGE_SUMS) as lanes: out[0], out[1], out[2]. */
static inline __attribute__((always_inline)) void edge_sums_lanes(const iso_volume *vol, const iso_voxel_type type,
                                                                  size_t base, int e, size_t se, size_t sp,
                                                                  size_t sq, __m128i out[3])
{
    size_t bytes = type == ISO_U8 || type == ISO_I8 ? 1 : 2;
    const char *v0 = (const char *)vol->data + base * bytes;
    if (e == 0)
        edge_sums_x(v0, type, bytes, sp, sq, out);
    else
        edge_sums_yz(v0, type, bytes, se, sq, out);
}

static inline __attribute__((always_inline)) void edge_sums_vector(const iso_volume *vol, const iso_voxel_type type,
                                                                   size_t base, int e, size_t se, size_t sp,
                                                                   size_t sq, double s[4], double dp[4],
                                                                   double dq[4])
{
    __m128i out[3];
    int32_t si[4], dpi[4], dqi[4];
    edge_sums_lanes(vol, type, base, e, se, sp, sq, out);
    _mm_storeu_si128((__m128i *)si, out[0]);
    _mm_storeu_si128((__m128i *)dpi, out[1]);
    _mm_storeu_si128((__m128i *)dqi, out[2]);
    for (int a = 0; a < 4; a++)
        s[a] = si[a], dp[a] = dpi[a], dq[a] = dqi[a];
}
#endif

/* The gradient at p when p is on a grid edge whose 4 x 3 x 3 support lies inside the
 * volume (and the volume has no NaN): 0; else -1 and g untouched. type is vol->type
 * (a constant where the caller is specialised for it). */
static inline __attribute__((always_inline)) int edge_gradient_of(const iso_volume *vol, const iso_voxel_type type,
                                                                  const double p[3], double g[3])
{
    long at[3];
    unsigned planes = 0;
    for (int a = 0; a < 3; a++) {
        double r = floor_fast(p[a] + 0.5);
        at[a] = (long)r;
        planes |= (unsigned)(fabs(p[a] - r) < EDGE_SLACK) << a;
    }
    int e = planes == 6 ? 0 : planes == 5 ? 1 : planes == 3 ? 2 : -1;
    if (e < 0 || vol->has_nan)
        return -1;
    int pa = e == 0 ? 1 : 0, qa = e == 2 ? 1 : 2;
    double w[4], d[4];
    long first;
    basis(4, p[e], vol->dims[e], &first, w, d);
    const size_t *dims = vol->dims;
    if (first < 0 || (size_t)first + 3 >= dims[e] || at[pa] < 1 || (size_t)at[pa] + 1 >= dims[pa] ||
        at[qa] < 1 || (size_t)at[qa] + 1 >= dims[qa])
        return -1;
    const size_t stride[3] = {1, dims[0], dims[0] * dims[1]};
    const size_t se = stride[e], sp = stride[pa], sq = stride[qa];
    const size_t base = (size_t)first * se + (size_t)(at[pa] - 1) * sp + (size_t)(at[qa] - 1) * sq;
    double s[4], dp[4], dq[4];
#if defined(__SSE2__)
    /* Along x four samples are loaded where a y or z edge uses three: the fourth must be
     * inside the volume. */
    int vector = e == 0 || (size_t)at[0] + 2 < dims[0];
#else
    int vector = 0;
#endif
    switch (type) {
#if defined(__SSE2__)
    case ISO_U8: if (vector) edge_sums_vector(vol, ISO_U8, base, e, se, sp, sq, s, dp, dq); else EDGE_SUMS(uint8_t, int32_t); break;
    case ISO_I8: if (vector) edge_sums_vector(vol, ISO_I8, base, e, se, sp, sq, s, dp, dq); else EDGE_SUMS(int8_t, int32_t); break;
    case ISO_U16: if (vector) edge_sums_vector(vol, ISO_U16, base, e, se, sp, sq, s, dp, dq); else EDGE_SUMS(uint16_t, int32_t); break;
    case ISO_I16: if (vector) edge_sums_vector(vol, ISO_I16, base, e, se, sp, sq, s, dp, dq); else EDGE_SUMS(int16_t, int32_t); break;
#else
    case ISO_U8: (void)vector; EDGE_SUMS(uint8_t, int32_t); break;
    case ISO_I8: EDGE_SUMS(int8_t, int32_t); break;
    case ISO_U16: EDGE_SUMS(uint16_t, int32_t); break;
    case ISO_I16: EDGE_SUMS(int16_t, int32_t); break;
#endif
    case ISO_U32: EDGE_SUMS(uint32_t, double); break;
    case ISO_I32: EDGE_SUMS(int32_t, double); break;
    case ISO_F32: EDGE_SUMS(float, double); break;
    case ISO_F64: EDGE_SUMS(double, double); break;
    default: return -1; /* a loaded volume has one of the types above */
    }
    double ge = 0, gp = 0, gq = 0;
    for (int a = 0; a < 4; a++) {
        ge += d[a] * s[a];
        gp += w[a] * dp[a];
        gq += w[a] * dq[a];
    }
    div2(ge, 36, gp, 12, &g[e], &g[pa]);
    g[qa] = gq / 12;
    return 0;
}

static int edge_gradient(const iso_volume *vol, const double p[3], double g[3])
{
    return edge_gradient_of(vol, vol->type, p, g);
}

static void gradient(const iso_volume *vol, int order, const double p[3], double g[3])
{
    if (order == 2)
        gradient_2(vol, p, g);
    else if (order == 3)
        gradient_3(vol, p, g);
    else if (edge_gradient(vol, p, g))
        gradient_4(vol, p, g);
}

/* The linear part A of index-to-world (columns: world steps of i, j, k), its inverse and
 * the origin. */
static int world_frame(const iso_volume *vol, double a[3][3], double inv[3][3], double origin[3])
{
    double affine[3][4];
    iso_vol_affine(vol, affine);
    for (int r = 0; r < 3; r++)
        origin[r] = affine[r][3];
    return iso_vol_frame(vol, a, inv, NULL);
}

/* What every thread of one iso_normals_compute call shares. */
typedef struct normals_job {
    const iso_volume *vol;
    iso_mesh *mesh;
    int order;
    iso_space space;
    double inv[3][3], origin[3];
    int avx2; /* the CPU has AVX2 (the four-vertex edge path) */
} normals_job;

/* Vertex v's position in index space. */
static inline __attribute__((always_inline)) void index_point(const normals_job *job, size_t v, double p[3])
{
    const float *q = job->mesh->positions + 3 * v;
    if (job->space == ISO_SPACE_WORLD)
        for (int r = 0; r < 3; r++)
            p[r] = job->inv[r][0] * (q[0] - job->origin[0]) + job->inv[r][1] * (q[1] - job->origin[1]) +
                   job->inv[r][2] * (q[2] - job->origin[2]);
    else
        for (int c = 0; c < 3; c++)
            p[c] = q[c];
}

/* Vertex v's unit normal from the index-space gradient g: world gradient = A^-T g. */
static inline __attribute__((always_inline)) void unit_normal(const normals_job *job, size_t v, const double g[3])
{
    double n[3];
    for (int c = 0; c < 3; c++)
        n[c] = job->space == ISO_SPACE_WORLD
                   ? -(job->inv[0][c] * g[0] + job->inv[1][c] * g[1] + job->inv[2][c] * g[2])
                   : -g[c];
    double len = sqrt(n[0] * n[0] + n[1] * n[1] + n[2] * n[2]);
    if (!(len > 0) || !isfinite(len)) {
        n[0] = n[1] = 0, n[2] = 1, len = 1;
    }
    float *out = job->mesh->normals + 3 * v;
    double n0, n1;
    div2(n[0], len, n[1], len, &n0, &n1);
    out[0] = (float)n0;
    out[1] = (float)n1;
    out[2] = (float)(n[2] / len);
}

static void normal_at(const normals_job *job, size_t v)
{
    double p[3], g[3];
    index_point(job, v, p);
    gradient(job->vol, job->order, p, g);
    if (g[0] == 0 && g[1] == 0 && g[2] == 0 && job->order != 2)
        gradient(job->vol, 2, p, g);
    unit_normal(job, v, g);
}

/* Vertices begin..end of a tricubic job on a volume of `type` (a constant here, so that
 * the edge path is compiled for it): the edge path, and normal_at for the vertices it
 * does not take (off an edge, near the border, a zero gradient). */
static inline __attribute__((always_inline)) void tricubic_range(const normals_job *job, const iso_voxel_type type,
                                                                 size_t begin, size_t end)
{
    for (size_t v = begin; v < end; v++) {
        double p[3], g[3];
        index_point(job, v, p);
        if (edge_gradient_of(job->vol, type, p, g) || (g[0] == 0 && g[1] == 0 && g[2] == 0))
            normal_at(job, v);
        else
            unit_normal(job, v, g);
    }
}

#if defined(__SSE2__) && defined(__GNUC__) && (defined(__x86_64__) || defined(__i386__))
#define NORMALS_AVX2 1
/* ---- the tricubic edge path, four vertices at a time (AVX2) ----
 *
 * The same operations as edge_gradient_of, index_point and unit_normal, in the same order,
 * on four vertices' doubles at once: each lane's results are those of the scalar path, bit
 * for bit (IEEE operations are correctly rounded whatever the vector width; no fused
 * multiply-add, as in the scalar build). Only the integer sums stay per vertex. A lane
 * the edge path does not take goes through normal_at. */

/* Lanes of m (all ones or zero per lane) as bits. */
__attribute__((target("avx2"))) static inline int lanes_of(__m256d m) { return _mm256_movemask_pd(m); }

__attribute__((target("avx2"))) static inline __m256d add3(__m256d a, __m256d b, __m256d c)
{
    return _mm256_add_pd(_mm256_add_pd(a, b), c);
}

/* The four vertices from v on, vertex l in lane l; 1 if every lane took the edge path. */
__attribute__((target("avx2"))) static inline __attribute__((always_inline)) void
tricubic_four(const normals_job *job, const iso_voxel_type type, size_t v)
{
    const iso_volume *vol = job->vol;
    const float *q = job->mesh->positions + 3 * v;
    __m256d x = _mm256_setr_pd(q[0], q[3], q[6], q[9]), y = _mm256_setr_pd(q[1], q[4], q[7], q[10]);
    __m256d z = _mm256_setr_pd(q[2], q[5], q[8], q[11]), p[3];
    if (job->space == ISO_SPACE_WORLD) {
        __m256d dx = _mm256_sub_pd(x, _mm256_set1_pd(job->origin[0]));
        __m256d dy = _mm256_sub_pd(y, _mm256_set1_pd(job->origin[1]));
        __m256d dz = _mm256_sub_pd(z, _mm256_set1_pd(job->origin[2]));
        for (int r = 0; r < 3; r++)
            p[r] = add3(_mm256_mul_pd(_mm256_set1_pd(job->inv[r][0]), dx),
                        _mm256_mul_pd(_mm256_set1_pd(job->inv[r][1]), dy),
                        _mm256_mul_pd(_mm256_set1_pd(job->inv[r][2]), dz));
    } else {
        p[0] = x, p[1] = y, p[2] = z;
    }
    /* On which planes (edge_gradient_of), and the edge axis's coordinate. */
    const __m256d half = _mm256_set1_pd(0.5), slack = _mm256_set1_pd(EDGE_SLACK);
    const __m256d sign = _mm256_set1_pd(-0.0), big = _mm256_set1_pd(0x1p30);
    __m256d near[3], r[3], in_range = _mm256_castsi256_pd(_mm256_set1_epi64x(-1));
    for (int a = 0; a < 3; a++) {
        r[a] = _mm256_floor_pd(_mm256_add_pd(p[a], half));
        near[a] = _mm256_cmp_pd(_mm256_andnot_pd(sign, _mm256_sub_pd(p[a], r[a])), slack, _CMP_LT_OQ);
        in_range = _mm256_and_pd(in_range, _mm256_cmp_pd(_mm256_andnot_pd(sign, p[a]), big, _CMP_LT_OQ));
    }
    __m256d on_x = _mm256_andnot_pd(near[0], _mm256_and_pd(near[1], near[2])); /* planes == 6 */
    __m256d on_y = _mm256_andnot_pd(near[1], _mm256_and_pd(near[0], near[2])); /* planes == 5 */
    __m256d on_z = _mm256_andnot_pd(near[2], _mm256_and_pd(near[0], near[1])); /* planes == 3 */
    __m256d xe = _mm256_blendv_pd(_mm256_blendv_pd(p[2], p[1], on_y), p[0], on_x);
    int edge = lanes_of(_mm256_and_pd(in_range, _mm256_or_pd(on_x, _mm256_or_pd(on_y, on_z))));
    /* basis(4) along the edge. */
    __m256d i = _mm256_floor_pd(xe), t = _mm256_sub_pd(xe, i), s = _mm256_sub_pd(_mm256_set1_pd(1), t);
    __m256d c2 = _mm256_set1_pd(2), c3 = _mm256_set1_pd(3), c4 = _mm256_set1_pd(4), c6 = _mm256_set1_pd(6);
    __m256d m3 = _mm256_set1_pd(-3), one = _mm256_set1_pd(1);
    __m256d tt = _mm256_mul_pd(t, t), ttt = _mm256_mul_pd(tt, t);
    __m256d t3 = _mm256_mul_pd(_mm256_mul_pd(_mm256_mul_pd(c3, t), t), t);    /* 3 * t * t * t */
    __m256d m3t2 = _mm256_mul_pd(_mm256_mul_pd(m3, t), t);                     /* -3 * t * t */
    __m256d w[4], d[4];
    w[0] = _mm256_div_pd(_mm256_mul_pd(_mm256_mul_pd(s, s), s), c6);
    w[1] = _mm256_div_pd(_mm256_add_pd(_mm256_sub_pd(t3, _mm256_mul_pd(_mm256_mul_pd(c6, t), t)), c4), c6);
    w[2] = _mm256_div_pd(add3(_mm256_add_pd(_mm256_mul_pd(m3t2, t), _mm256_mul_pd(_mm256_mul_pd(c3, t), t)),
                              _mm256_mul_pd(c3, t), one), c6);
    w[3] = _mm256_div_pd(ttt, c6);
    /* Halving is exact: x * 0.5 is x / 2 (as the scalar build compiles it). */
    d[0] = _mm256_mul_pd(_mm256_mul_pd(_mm256_xor_pd(s, sign), s), half);
    d[1] = _mm256_mul_pd(_mm256_sub_pd(_mm256_mul_pd(_mm256_mul_pd(c3, t), t), _mm256_mul_pd(c4, t)), half);
    d[2] = _mm256_mul_pd(add3(m3t2, _mm256_mul_pd(c2, t), one), half);
    d[3] = _mm256_mul_pd(tt, half);
    /* The integer sums, vertex by vertex, then turned so that lanes are vertices. */
    int at[3][4], first[4];
    for (int a = 0; a < 3; a++)
        _mm_storeu_si128((__m128i *)at[a], _mm256_cvttpd_epi32(_mm256_and_pd(r[a], in_range)));
    _mm_storeu_si128((__m128i *)first, _mm256_cvttpd_epi32(_mm256_and_pd(i, in_range)));
    const size_t *dims = vol->dims;
    const size_t stride[3] = {1, dims[0], dims[0] * dims[1]};
    __m128i sums[3][4];
    const int x_edges = lanes_of(on_x), y_edges = lanes_of(on_y);
    for (int l = 0; l < 4; l++) {
        int e = (edge >> l & 1) ? (x_edges >> l & 1 ? 0 : y_edges >> l & 1 ? 1 : 2) : -1;
        int pa = e == 0 ? 1 : 0, qa = e == 2 ? 1 : 2;
        long f = (long)first[l] - 1, ap = at[pa][l], aq = at[qa][l];
        if (e < 0 || f < 0 || (size_t)f + 3 >= dims[e] || ap < 1 || (size_t)ap + 1 >= dims[pa] || aq < 1 ||
            (size_t)aq + 1 >= dims[qa] || (e != 0 && (size_t)at[0][l] + 2 >= dims[0])) {
            edge &= ~(1 << l);
            sums[0][l] = sums[1][l] = sums[2][l] = _mm_setzero_si128();
            continue;
        }
        size_t base = (size_t)f * stride[e] + (size_t)(ap - 1) * stride[pa] + (size_t)(aq - 1) * stride[qa];
        __m128i out[3];
        edge_sums_lanes(vol, type, base, e, stride[e], stride[pa], stride[qa], out);
        for (int k = 0; k < 3; k++)
            sums[k][l] = out[k];
    }
    __m256d ge = _mm256_setzero_pd(), gp = ge, gq = ge;
    __m128i by_sample[3][4];
    for (int k = 0; k < 3; k++)
        transpose4(sums[k], by_sample[k]);
    for (int a = 0; a < 4; a++) {
        ge = _mm256_add_pd(ge, _mm256_mul_pd(d[a], _mm256_cvtepi32_pd(by_sample[0][a])));
        gp = _mm256_add_pd(gp, _mm256_mul_pd(w[a], _mm256_cvtepi32_pd(by_sample[1][a])));
        gq = _mm256_add_pd(gq, _mm256_mul_pd(w[a], _mm256_cvtepi32_pd(by_sample[2][a])));
    }
    ge = _mm256_div_pd(ge, _mm256_set1_pd(36));
    gp = _mm256_div_pd(gp, _mm256_set1_pd(12));
    gq = _mm256_div_pd(gq, _mm256_set1_pd(12));
    /* g[e] = ge, g[pa] = gp, g[qa] = gq. */
    __m256d g[3];
    g[0] = _mm256_blendv_pd(gp, ge, on_x);
    g[1] = _mm256_blendv_pd(_mm256_blendv_pd(gq, ge, on_y), gp, on_x);
    g[2] = _mm256_blendv_pd(gq, ge, on_z);
    __m256d zero = _mm256_setzero_pd();
    __m256d nonzero = _mm256_or_pd(_mm256_or_pd(_mm256_cmp_pd(g[0], zero, _CMP_NEQ_UQ),
                                                _mm256_cmp_pd(g[1], zero, _CMP_NEQ_UQ)),
                                   _mm256_cmp_pd(g[2], zero, _CMP_NEQ_UQ));
    edge &= lanes_of(nonzero);
    /* unit_normal. */
    __m256d n[3];
    for (int c = 0; c < 3; c++)
        n[c] = job->space == ISO_SPACE_WORLD
                   ? _mm256_xor_pd(add3(_mm256_mul_pd(_mm256_set1_pd(job->inv[0][c]), g[0]),
                                        _mm256_mul_pd(_mm256_set1_pd(job->inv[1][c]), g[1]),
                                        _mm256_mul_pd(_mm256_set1_pd(job->inv[2][c]), g[2])),
                                   sign)
                   : _mm256_xor_pd(g[c], sign);
    __m256d len = _mm256_sqrt_pd(add3(_mm256_mul_pd(n[0], n[0]), _mm256_mul_pd(n[1], n[1]), _mm256_mul_pd(n[2], n[2])));
    __m256d finite = _mm256_and_pd(_mm256_cmp_pd(len, zero, _CMP_GT_OQ),
                                   _mm256_cmp_pd(len, _mm256_set1_pd(INFINITY), _CMP_LT_OQ));
    edge &= lanes_of(finite);
    float out[3][4];
    for (int c = 0; c < 3; c++)
        _mm_storeu_ps(out[c], _mm256_cvtpd_ps(_mm256_div_pd(n[c], len)));
    float *normals = job->mesh->normals + 3 * v;
    for (int l = 0; l < 4; l++)
        if (edge >> l & 1)
            for (int c = 0; c < 3; c++)
                normals[3 * l + c] = out[c][l];
        else
            normal_at(job, v + (size_t)l);
}

__attribute__((target("avx2"))) static inline __attribute__((always_inline)) void
tricubic_range_four(const normals_job *job, const iso_voxel_type type, size_t begin, size_t end)
{
    size_t v = begin;
    for (; v + 4 <= end; v += 4)
        tricubic_four(job, type, v);
    tricubic_range(job, type, v, end);
}

__attribute__((target("avx2"))) static void tricubic_avx2(const normals_job *job, size_t begin, size_t end)
{
    switch (job->vol->type) {
    case ISO_U8: tricubic_range_four(job, ISO_U8, begin, end); break;
    case ISO_I8: tricubic_range_four(job, ISO_I8, begin, end); break;
    case ISO_U16: tricubic_range_four(job, ISO_U16, begin, end); break;
    case ISO_I16: tricubic_range_four(job, ISO_I16, begin, end); break;
    default: tricubic_range(job, job->vol->type, begin, end); break;
    }
}
#endif

/* Thread t of threads: a contiguous share of the vertices (each normal depends only on
 * its own position, so the result does not depend on the split). */
static void normals_share(void *context, int t, int threads)
{
    const normals_job *job = context;
    size_t n = job->mesh->vertex_count;
    size_t begin = n * (size_t)t / (size_t)threads, end = n * (size_t)(t + 1) / (size_t)threads;
#if defined(NORMALS_AVX2)
    if (job->order == 4 && !job->vol->has_nan && job->avx2) {
        tricubic_avx2(job, begin, end);
        return;
    }
#endif
    if (job->order == 4 && !job->vol->has_nan)
        switch (job->vol->type) {
        case ISO_U8: tricubic_range(job, ISO_U8, begin, end); return;
        case ISO_I8: tricubic_range(job, ISO_I8, begin, end); return;
        case ISO_U16: tricubic_range(job, ISO_U16, begin, end); return;
        case ISO_I16: tricubic_range(job, ISO_I16, begin, end); return;
        default: tricubic_range(job, job->vol->type, begin, end); return;
        }
    for (size_t v = begin; v < end; v++)
        normal_at(job, v);
}

/* Below this many vertices one thread does it all: starting threads would cost more. */
#define NORMALS_PER_THREAD 16384

int iso_normals_compute(const iso_volume *vol, iso_mesh *mesh, int order, iso_space space,
                        int threads, iso_error *err)
{
    assert(vol && mesh);
    if (order == 0) {
        free(mesh->normals);
        mesh->normals = NULL;
        return 0;
    }
    if (order < 2 || order > 4)
        return iso_error_set(err, ISO_E_ARGUMENT, "normals: order %d is not 2, 3 or 4", order);
    normals_job job = {.vol = vol, .mesh = mesh, .order = order, .space = space};
#if defined(NORMALS_AVX2)
    job.avx2 = __builtin_cpu_supports("avx2");
#endif
    double a[3][3];
    if (world_frame(vol, a, job.inv, job.origin))
        return iso_error_set(err, ISO_E_ARGUMENT, "normals: the volume's index-to-world map is singular");
    size_t capacity = mesh->vertex_capacity > mesh->vertex_count ? mesh->vertex_capacity : mesh->vertex_count;
    float *normals = realloc(mesh->normals, (capacity ? capacity : 1) * 3 * sizeof *normals);
    if (!normals)
        return iso_error_set(err, ISO_E_NOMEM, "normals: out of memory for %zu vertices", mesh->vertex_count);
    mesh->normals = normals;
    threads = iso_parallel_threads(threads);
    size_t most = mesh->vertex_count / NORMALS_PER_THREAD + 1;
    if ((size_t)threads > most)
        threads = (int)most;
    iso_parallel_run(threads, normals_share, &job);
    return 0;
}
