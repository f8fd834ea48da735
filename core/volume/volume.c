/* volume.c: scalar volumes: voxel types, size checks, sample access and statistics (see volume.h). */
#include "volume.h"

#include <assert.h>
#include <ctype.h>
#include <inttypes.h>
#include <math.h>
#include <stdlib.h>
#include <string.h>

/* ---- voxel types ---- */

static const struct {
    const char *name;
    size_t size;
    int is_float;
} type_info[] = {
    [ISO_U8] = {"u8", 1, 0},   [ISO_I8] = {"i8", 1, 0},   [ISO_U16] = {"u16", 2, 0},
    [ISO_I16] = {"i16", 2, 0}, [ISO_U32] = {"u32", 4, 0}, [ISO_I32] = {"i32", 4, 0},
    [ISO_F32] = {"f32", 4, 1}, [ISO_F64] = {"f64", 8, 1},
};

#define TYPE_COUNT (sizeof type_info / sizeof type_info[0])

static int type_valid(iso_voxel_type type)
{
    return (unsigned)type < TYPE_COUNT;
}

size_t iso_vol_type_size(iso_voxel_type type)
{
    assert(type_valid(type));
    return type_info[type].size;
}

const char *iso_vol_type_name(iso_voxel_type type)
{
    return type_valid(type) ? type_info[type].name : "invalid";
}

int iso_vol_type_parse(const char *name, iso_voxel_type *type)
{
    assert(name && type);
    for (size_t t = 0; t < TYPE_COUNT; t++)
        if (strcmp(name, type_info[t].name) == 0) {
            *type = (iso_voxel_type)t;
            return 0;
        }
    return -1;
}

int iso_vol_type_is_float(iso_voxel_type type)
{
    assert(type_valid(type));
    return type_info[type].is_float;
}

/* ---- sizes and lifetime ---- */

/* max_bytes 0 means ISO_VOL_DEFAULT_MAX_BYTES, as for iso_vol_create. The dims usually come
 * from a file header, so the product is checked step by step instead of trusted. */
int iso_vol_check_size(const size_t dims[3], iso_voxel_type type, uint64_t max_bytes,
                       uint64_t *bytes, iso_error *err)
{
    assert(dims && type_valid(type));
    if (max_bytes == 0)
        max_bytes = ISO_VOL_DEFAULT_MAX_BYTES;
    for (int d = 0; d < 3; d++)
        if (dims[d] < 2)
            return iso_error_set(err, ISO_E_ARGUMENT,
                                 "volume of %zux%zux%zu samples: every axis needs at least 2",
                                 dims[0], dims[1], dims[2]);
    uint64_t total = type_info[type].size;
    for (int d = 0; d < 3; d++) {
        if ((uint64_t)dims[d] > max_bytes / total)
            return iso_error_set(err, ISO_E_LIMIT,
                                 "volume of %zux%zux%zu %s samples exceeds the limit of %" PRIu64
                                 " bytes",
                                 dims[0], dims[1], dims[2], type_info[type].name, max_bytes);
        total *= dims[d];
    }
    /* On 32-bit hosts a limit above 4 GiB could still let the count overflow size_t. */
    if (total > SIZE_MAX)
        return iso_error_set(err, ISO_E_LIMIT,
                             "volume of %zux%zux%zu %s samples does not fit in this address space",
                             dims[0], dims[1], dims[2], type_info[type].name);
    if (bytes)
        *bytes = total;
    return ISO_OK;
}

iso_volume *iso_vol_create(const size_t dims[3], iso_voxel_type type, uint64_t max_bytes,
                           iso_error *err)
{
    uint64_t bytes;
    iso_volume *vol = NULL;
    if (iso_vol_check_size(dims, type, max_bytes, &bytes, err) != ISO_OK)
        return NULL;
    vol = calloc(1, sizeof *vol);
    if (!vol)
        goto nomem;
    vol->data = calloc(1, (size_t)bytes);
    if (!vol->data)
        goto nomem;
    vol->type = type;
    for (int d = 0; d < 3; d++) {
        vol->dims[d] = dims[d];
        vol->spacing[d] = 1.0;
        vol->direction[d][d] = 1.0;
    }
    return vol;

nomem:
    iso_vol_destroy(vol);
    iso_error_set(err, ISO_E_NOMEM, "out of memory for a volume of %zux%zux%zu %s samples (%" PRIu64
                  " bytes)", dims[0], dims[1], dims[2], type_info[type].name, bytes);
    return NULL;
}

void iso_vol_destroy(iso_volume *vol)
{
    if (!vol)
        return;
    free(vol->data);
    free(vol);
}

/* ---- single samples ---- */

static size_t checked_index(const iso_volume *vol, size_t i, size_t j, size_t k)
{
    assert(vol && vol->data);
    assert(i < vol->dims[0] && j < vol->dims[1] && k < vol->dims[2]);
    return iso_vol_index(vol, i, j, k);
}

double iso_vol_get(const iso_volume *vol, size_t i, size_t j, size_t k)
{
    return iso_vol_sample(vol, checked_index(vol, i, j, k));
}

/* Rounds to the nearest integer and clamps into [lo, hi]; NaN becomes 0 because an integer
 * type has no way to say "no value". */
static double to_integer(double value, double lo, double hi)
{
    if (value != value)
        return 0;
    value = floor(value + 0.5);
    return value < lo ? lo : value > hi ? hi : value;
}

void iso_vol_set(iso_volume *vol, size_t i, size_t j, size_t k, double value)
{
    size_t at = checked_index(vol, i, j, k);
    switch (vol->type) {
    case ISO_U8: ((uint8_t *)vol->data)[at] = (uint8_t)to_integer(value, 0, UINT8_MAX); break;
    case ISO_I8: ((int8_t *)vol->data)[at] = (int8_t)to_integer(value, INT8_MIN, INT8_MAX); break;
    case ISO_U16: ((uint16_t *)vol->data)[at] = (uint16_t)to_integer(value, 0, UINT16_MAX); break;
    case ISO_I16:
        ((int16_t *)vol->data)[at] = (int16_t)to_integer(value, INT16_MIN, INT16_MAX);
        break;
    case ISO_U32: ((uint32_t *)vol->data)[at] = (uint32_t)to_integer(value, 0, UINT32_MAX); break;
    case ISO_I32:
        ((int32_t *)vol->data)[at] = (int32_t)to_integer(value, INT32_MIN, INT32_MAX);
        break;
    case ISO_F32: ((float *)vol->data)[at] = (float)value; break;
    case ISO_F64: ((double *)vol->data)[at] = value; break;
    }
}

/* ---- boxes ---- */

/* One copy loop per voxel type so that the type switch runs once per box, not per sample:
 * extraction reads every brick through here. */
#define DEFINE_READ_BOX(NAME, T)                                                              \
    static void NAME(const iso_volume *vol, const size_t lo[3], const size_t hi[3],           \
                     double *out)                                                             \
    {                                                                                         \
        const T *p = (const T *)vol->data;                                                    \
        size_t nx = hi[0] - lo[0] + 1;                                                        \
        for (size_t k = lo[2]; k <= hi[2]; k++)                                               \
            for (size_t j = lo[1]; j <= hi[1]; j++) {                                         \
                const T *row = p + iso_vol_index(vol, lo[0], j, k);                           \
                for (size_t i = 0; i < nx; i++)                                               \
                    out[i] = (double)row[i];                                                  \
                out += nx;                                                                    \
            }                                                                                 \
    }

DEFINE_READ_BOX(read_box_u8, uint8_t)
DEFINE_READ_BOX(read_box_i8, int8_t)
DEFINE_READ_BOX(read_box_u16, uint16_t)
DEFINE_READ_BOX(read_box_i16, int16_t)
DEFINE_READ_BOX(read_box_u32, uint32_t)
DEFINE_READ_BOX(read_box_i32, int32_t)
DEFINE_READ_BOX(read_box_f32, float)
DEFINE_READ_BOX(read_box_f64, double)

void iso_vol_read_box(const iso_volume *vol, const size_t lo[3], const size_t hi[3],
                      double *out)
{
    assert(vol && vol->data && lo && hi && out);
    for (int d = 0; d < 3; d++)
        assert(lo[d] <= hi[d] && hi[d] < vol->dims[d]);
    switch (vol->type) {
    case ISO_U8: read_box_u8(vol, lo, hi, out); break;
    case ISO_I8: read_box_i8(vol, lo, hi, out); break;
    case ISO_U16: read_box_u16(vol, lo, hi, out); break;
    case ISO_I16: read_box_i16(vol, lo, hi, out); break;
    case ISO_U32: read_box_u32(vol, lo, hi, out); break;
    case ISO_I32: read_box_i32(vol, lo, hi, out); break;
    case ISO_F32: read_box_f32(vol, lo, hi, out); break;
    case ISO_F64: read_box_f64(vol, lo, hi, out); break;
    }
}

/* ---- statistics ---- */

typedef struct stats {
    double min, max, sum;
    size_t count; /* samples that are not NaN */
} stats;

/* Integer samples are summed exactly in int64 over chunks small enough that no chunk can
 * overflow (2^16 samples of at most 2^32), then the chunk sums go into a double: exact for
 * every volume under the 8 GiB default and fast enough to vectorise. */
#define STATS_CHUNK ((size_t)1 << 16)

#define DEFINE_STATS_INT(NAME, T)                                                             \
    static void NAME(const void *data, size_t n, stats *s)                                    \
    {                                                                                         \
        const T *p = (const T *)data;                                                         \
        T lo = p[0], hi = p[0];                                                               \
        double sum = 0;                                                                       \
        for (size_t at = 0; at < n; at += STATS_CHUNK) {                                      \
            size_t end = n - at < STATS_CHUNK ? n : at + STATS_CHUNK;                         \
            int64_t part = 0;                                                                 \
            for (size_t i = at; i < end; i++) {                                               \
                T v = p[i];                                                                   \
                lo = v < lo ? v : lo;                                                         \
                hi = v > hi ? v : hi;                                                         \
                part += v;                                                                    \
            }                                                                                 \
            sum += (double)part;                                                              \
        }                                                                                     \
        s->min = lo;                                                                          \
        s->max = hi;                                                                          \
        s->sum = sum;                                                                         \
        s->count = n;                                                                         \
    }

/* Float samples skip NaN; `v == v` is false only for NaN. */
#define DEFINE_STATS_FLOAT(NAME, T)                                                           \
    static void NAME(const void *data, size_t n, stats *s)                                    \
    {                                                                                         \
        const T *p = (const T *)data;                                                         \
        double lo = INFINITY, hi = -INFINITY, sum = 0;                                        \
        size_t count = 0;                                                                     \
        for (size_t i = 0; i < n; i++) {                                                      \
            double v = p[i];                                                                  \
            if (v == v) {                                                                     \
                lo = v < lo ? v : lo;                                                         \
                hi = v > hi ? v : hi;                                                         \
                sum += v;                                                                     \
                count++;                                                                      \
            }                                                                                 \
        }                                                                                     \
        s->min = lo;                                                                          \
        s->max = hi;                                                                          \
        s->sum = sum;                                                                         \
        s->count = count;                                                                     \
    }

DEFINE_STATS_INT(stats_u8, uint8_t)
DEFINE_STATS_INT(stats_i8, int8_t)
DEFINE_STATS_INT(stats_u16, uint16_t)
DEFINE_STATS_INT(stats_i16, int16_t)
DEFINE_STATS_INT(stats_u32, uint32_t)
DEFINE_STATS_INT(stats_i32, int32_t)
DEFINE_STATS_FLOAT(stats_f32, float)
DEFINE_STATS_FLOAT(stats_f64, double)

/* A volume whose samples are all NaN gets min = max = mean = 0 (and has_nan = 1): callers
 * print and serialise the stats, and NaN would leak into JSON. */
void iso_vol_update_stats(iso_volume *vol)
{
    stats s;
    size_t n;
    assert(vol && vol->data);
    n = iso_vol_count(vol);
    switch (vol->type) {
    case ISO_U8: stats_u8(vol->data, n, &s); break;
    case ISO_I8: stats_i8(vol->data, n, &s); break;
    case ISO_U16: stats_u16(vol->data, n, &s); break;
    case ISO_I16: stats_i16(vol->data, n, &s); break;
    case ISO_U32: stats_u32(vol->data, n, &s); break;
    case ISO_I32: stats_i32(vol->data, n, &s); break;
    case ISO_F32: stats_f32(vol->data, n, &s); break;
    case ISO_F64: stats_f64(vol->data, n, &s); break;
    default: assert(!"invalid voxel type"); return;
    }
    vol->has_nan = s.count < n;
    if (s.count == 0) {
        vol->value_min = vol->value_max = vol->value_mean = 0;
        return;
    }
    vol->value_min = s.min;
    vol->value_max = s.max;
    vol->value_mean = s.sum / (double)s.count;
}

/* ---- geometry ---- */

double iso_vol_min_spacing(const iso_volume *vol)
{
    double s = vol->spacing[0];
    for (int d = 1; d < 3; d++)
        if (vol->spacing[d] < s)
            s = vol->spacing[d];
    return s;
}

void iso_vol_affine(const iso_volume *vol, double affine[3][4])
{
    double zero[3] = {0, 0, 0}, origin[3];
    iso_vol_index_to_world(vol, zero, origin);
    for (int c = 0; c < 3; c++) {
        double unit[3] = {c == 0, c == 1, c == 2}, w[3];
        iso_vol_index_to_world(vol, unit, w);
        for (int r = 0; r < 3; r++)
            affine[r][c] = w[r] - origin[r];
    }
    for (int r = 0; r < 3; r++)
        affine[r][3] = origin[r];
}

int iso_vol_set_axes(iso_volume *vol, const char *code, iso_error *err)
{
    assert(vol && code);
    static const char letters[] = "LRPASI"; /* pairs: +x -x, +y -y, +z -z of LPS */
    double direction[3][3] = {{0}};
    int seen[3] = {0};
    size_t n = strlen(code);
    for (size_t a = 0; a < 3 && n == 3; a++) {
        const char *at = strchr(letters, toupper((unsigned char)code[a]));
        if (!at || !*at)
            break;
        int pair = (int)(at - letters) / 2;
        if (seen[pair]++)
            break;
        direction[pair][a] = (at - letters) % 2 ? -1 : 1;
    }
    if (n != 3 || !seen[0] || !seen[1] || !seen[2] || seen[0] + seen[1] + seen[2] != 3)
        return iso_error_set(err, ISO_E_ARGUMENT, "orientation \"%.16s\": three letters, one of L or R, "
                             "one of P or A, one of S or I (where the i, j, k axes point, e.g. LPI)", code);
    memcpy(vol->direction, direction, sizeof direction);
    vol->oriented = 1;
    return 0;
}

int iso_vol_set_affine(iso_volume *vol, const double affine[3][4], const char *what,
                       iso_error *err)
{
    double length[3];
    for (int c = 0; c < 3; c++) {
        length[c] = sqrt(affine[0][c] * affine[0][c] + affine[1][c] * affine[1][c] +
                         affine[2][c] * affine[2][c]);
        if (!isfinite(length[c]) || !(length[c] > 0) || !isfinite(affine[c][3]))
            return iso_error_set(err, ISO_E_FORMAT, "%s: axis %d of the index-to-world map is %s",
                                 what, c, isfinite(length[c]) && isfinite(affine[c][3]) ? "zero" : "not finite");
    }
    double det = affine[0][0] * (affine[1][1] * affine[2][2] - affine[1][2] * affine[2][1]) -
                 affine[0][1] * (affine[1][0] * affine[2][2] - affine[1][2] * affine[2][0]) +
                 affine[0][2] * (affine[1][0] * affine[2][1] - affine[1][1] * affine[2][0]);
    if (!(fabs(det) > 1e-12 * length[0] * length[1] * length[2]))
        return iso_error_set(err, ISO_E_FORMAT, "%s: the index-to-world map is singular (axes in one plane)", what);
    for (int c = 0; c < 3; c++) {
        vol->spacing[c] = length[c];
        for (int r = 0; r < 3; r++)
            vol->direction[r][c] = affine[r][c] / length[c];
    }
    for (int r = 0; r < 3; r++)
        vol->origin[r] = affine[r][3];
    return 0;
}

int iso_vol_frame(const iso_volume *vol, double a[3][3], double inv[3][3], double *det)
{
    double affine[3][4];
    iso_vol_affine(vol, affine);
    for (int r = 0; r < 3; r++)
        for (int c = 0; c < 3; c++)
            a[r][c] = affine[r][c];
    double d = a[0][0] * (a[1][1] * a[2][2] - a[1][2] * a[2][1]) - a[0][1] * (a[1][0] * a[2][2] - a[1][2] * a[2][0]) +
               a[0][2] * (a[1][0] * a[2][1] - a[1][1] * a[2][0]);
    if (det)
        *det = d;
    if (!(fabs(d) > 1e-300))
        return -1;
    for (int r = 0; r < 3; r++)
        for (int c = 0; c < 3; c++) {
            /* Cofactor of (c, r) over det: the adjugate's transpose. */
            int r1 = (c + 1) % 3, r2 = (c + 2) % 3, c1 = (r + 1) % 3, c2 = (r + 2) % 3;
            inv[r][c] = (a[r1][c1] * a[r2][c2] - a[r1][c2] * a[r2][c1]) / d;
        }
    return 0;
}
