/* narrow.c: a volume kept in the narrowest voxel type that holds its values (volume.h).
 *
 * A CT series stored as 16 bits with a rescale intercept of -1024 holds Hounsfield units
 * from about -1024 to 3071: int16, where the stored bit range alone (-33792 .. 31743) asks
 * for int32 and doubles the memory and the bytes every extraction reads. So the type comes
 * from the values present: the smallest integer type whose range holds them when they are
 * all integers, else a float type. Converting in place keeps the peak at the larger of the
 * two buffers (forward when the type shrinks, backward after growing the buffer). */
#include "volume.h"

#include <assert.h>
#include <math.h>
#include <stdlib.h>
#include <string.h>

static int fits(iso_voxel_type type, double min, double max)
{
    static const double lo[] = {0, -128, 0, -32768, 0, -2147483648.0}, hi[] = {255, 127, 65535, 32767,
                                                                               4294967295.0, 2147483647.0};
    return type <= ISO_I32 && min >= lo[type] && max <= hi[type];
}

iso_voxel_type iso_vol_narrowest_type(double min, double max, int integral, iso_voxel_type source)
{
    if (!integral || !(min <= max))
        return iso_vol_type_is_float(source) ? source : ISO_F32;
    /* By size; at one size the source's own type first, then unsigned, then signed. */
    static const iso_voxel_type by_size[3][2] = {{ISO_U8, ISO_I8}, {ISO_U16, ISO_I16}, {ISO_U32, ISO_I32}};
    for (int s = 0; s < 3; s++) {
        if ((source == by_size[s][0] || source == by_size[s][1]) && fits(source, min, max))
            return source;
        for (int t = 0; t < 2; t++)
            if (fits(by_size[s][t], min, max))
                return by_size[s][t];
    }
    /* Integers past 32 bits: float64 holds them exactly up to 2^53. */
    return source == ISO_F32 ? ISO_F32 : ISO_F64;
}

static double read_at(const unsigned char *bytes, iso_voxel_type type, size_t i)
{
    switch (type) {
    case ISO_U8: return bytes[i];
    case ISO_I8: return (int8_t)bytes[i];
    case ISO_U16: { uint16_t v; memcpy(&v, bytes + 2 * i, 2); return v; }
    case ISO_I16: { int16_t v; memcpy(&v, bytes + 2 * i, 2); return v; }
    case ISO_U32: { uint32_t v; memcpy(&v, bytes + 4 * i, 4); return v; }
    case ISO_I32: { int32_t v; memcpy(&v, bytes + 4 * i, 4); return v; }
    case ISO_F32: { float v; memcpy(&v, bytes + 4 * i, 4); return v; }
    case ISO_F64: { double v; memcpy(&v, bytes + 8 * i, 8); return v; }
    }
    return 0;
}

/* value is one the type holds (the caller chose the type from the values). */
static void write_at(unsigned char *bytes, iso_voxel_type type, size_t i, double value)
{
    switch (type) {
    case ISO_U8: bytes[i] = (uint8_t)value; break;
    case ISO_I8: bytes[i] = (unsigned char)(int8_t)value; break;
    case ISO_U16: { uint16_t v = (uint16_t)value; memcpy(bytes + 2 * i, &v, 2); break; }
    case ISO_I16: { int16_t v = (int16_t)value; memcpy(bytes + 2 * i, &v, 2); break; }
    case ISO_U32: { uint32_t v = (uint32_t)value; memcpy(bytes + 4 * i, &v, 4); break; }
    case ISO_I32: { int32_t v = (int32_t)value; memcpy(bytes + 4 * i, &v, 4); break; }
    case ISO_F32: { float v = (float)value; memcpy(bytes + 4 * i, &v, 4); break; }
    case ISO_F64: memcpy(bytes + 8 * i, &value, 8); break;
    }
}

int iso_vol_retype(iso_volume *vol, iso_voxel_type to, const double *slope, const double *intercept,
                   uint64_t max_bytes, iso_error *err)
{
    assert(vol && vol->data && (!slope) == (!intercept));
    iso_voxel_type from = vol->type;
    size_t n = iso_vol_count(vol), plane = vol->dims[0] * vol->dims[1];
    size_t from_size = iso_vol_type_size(from), to_size = iso_vol_type_size(to);
    if (to == from && !slope)
        return ISO_OK;
    if (to_size > from_size) {
        uint64_t bytes;
        int rc = iso_vol_check_size(vol->dims, to, max_bytes ? max_bytes : ISO_VOL_DEFAULT_MAX_BYTES, &bytes, err);
        if (rc)
            return rc;
        void *grown = realloc(vol->data, (size_t)bytes);
        if (!grown)
            return iso_error_set(err, ISO_E_NOMEM, "out of memory for %zux%zux%zu %s samples", vol->dims[0],
                                 vol->dims[1], vol->dims[2], iso_vol_type_name(to));
        vol->data = grown;
    }
    unsigned char *bytes = vol->data;
    /* Each sample is read before anything overwrites it: sample i's new bytes end at or
     * before the old bytes of i + 1 when shrinking, start at or after those of i - 1 when
     * growing. */
    for (size_t step = 0; step < n; step++) {
        size_t i = to_size > from_size ? n - 1 - step : step;
        double v = read_at(bytes, from, i);
        if (slope)
            v = slope[i / plane] * v + intercept[i / plane];
        write_at(bytes, to, i, v);
    }
    vol->type = to;
    if (to_size < from_size) {
        void *shrunk = realloc(vol->data, n * to_size);
        if (shrunk)
            vol->data = shrunk;
    }
    return ISO_OK;
}

/* The range of the rescaled values present, slice by slice (slice k: slope[k] * stored +
 * intercept[k]); whether all are integers (whole slope and intercept make them so,
 * otherwise each value is looked at); and whether float32 keeps every two distinct stored
 * values of a slice apart: they differ by |slope| at least, float32's spacing at |v| is at
 * most |v| 2^-23, so |v| / |slope| < 2^22 suffices. */
static void rescaled_range(const iso_volume *vol, const double *slope, const double *intercept, double *min,
                           double *max, int *integral, int *single)
{
    size_t plane = vol->dims[0] * vol->dims[1];
    *min = INFINITY, *max = -INFINITY, *integral = 1, *single = 1;
    for (size_t k = 0; k < vol->dims[2]; k++) {
        double lo = INFINITY, hi = -INFINITY;
        int whole = slope[k] == floor(slope[k]) && intercept[k] == floor(intercept[k]);
        for (size_t at = k * plane; at < (k + 1) * plane; at++) {
            double v = iso_vol_sample(vol, at);
            lo = v < lo ? v : lo;
            hi = v > hi ? v : hi;
            if (!whole && *integral) {
                double r = slope[k] * v + intercept[k];
                *integral = r == floor(r);
            }
        }
        double a = slope[k] * lo + intercept[k], b = slope[k] * hi + intercept[k];
        *min = fmin(*min, fmin(a, b));
        *max = fmax(*max, fmax(a, b));
        *single &= fmax(fabs(a), fabs(b)) < ldexp(fabs(slope[k]), 22);
    }
}

int iso_vol_rescale(iso_volume *vol, const double *slope, const double *intercept, uint64_t max_bytes,
                    iso_error *err)
{
    assert(!iso_vol_type_is_float(vol->type));
    int identity = 1;
    for (size_t k = 0; k < vol->dims[2]; k++) {
        assert(slope[k] != 0 && isfinite(slope[k]) && isfinite(intercept[k]));
        identity &= slope[k] == 1 && intercept[k] == 0;
    }
    double min, max;
    int integral, single;
    rescaled_range(vol, slope, intercept, &min, &max, &integral, &single);
    iso_voxel_type to = !integral ? (single ? ISO_F32 : ISO_F64) : iso_vol_narrowest_type(min, max, 1, vol->type);
    if (identity && to == vol->type)
        return ISO_OK;
    return iso_vol_retype(vol, to, identity ? NULL : slope, identity ? NULL : intercept, max_bytes, err);
}
