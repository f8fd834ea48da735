/* test_volume.c: volumes, the NRRD reader, analytic fields and the loader table, on
 * hand-built volumes with exact expected values and on the shared real scans. */
#include <inttypes.h>
#include <math.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <zlib.h>

#include "check.h"
#include "io/io.h"
#include "io/nrrd.h"
#include "sha256.h"
#include "volume/volume.h"

/* ---- helpers ---- */

static const iso_voxel_type all_types[] = {ISO_U8, ISO_I8, ISO_U16, ISO_I16,
                                           ISO_U32, ISO_I32, ISO_F32, ISO_F64};
#define TYPE_COUNT (sizeof all_types / sizeof all_types[0])

static int host_big_endian(void)
{
    const uint16_t one = 1;
    unsigned char first;
    memcpy(&first, &one, 1);
    return first == 0;
}

static void reverse(unsigned char *p, size_t n)
{
    for (size_t a = 0, b = n - 1; a < b; a++, b--) {
        unsigned char t = p[a];
        p[a] = p[b];
        p[b] = t;
    }
}

/* Stores n values as `type` samples in the given byte order, as a file would hold them. */
static void encode(iso_voxel_type type, int big_endian, const double *values, size_t n,
                   unsigned char *out)
{
    size_t size = iso_vol_type_size(type);
    for (size_t s = 0; s < n; s++, out += size) {
        double v = values[s];
        switch (type) {
        case ISO_U8: { uint8_t x = (uint8_t)v; memcpy(out, &x, size); } break;
        case ISO_I8: { int8_t x = (int8_t)v; memcpy(out, &x, size); } break;
        case ISO_U16: { uint16_t x = (uint16_t)v; memcpy(out, &x, size); } break;
        case ISO_I16: { int16_t x = (int16_t)v; memcpy(out, &x, size); } break;
        case ISO_U32: { uint32_t x = (uint32_t)v; memcpy(out, &x, size); } break;
        case ISO_I32: { int32_t x = (int32_t)v; memcpy(out, &x, size); } break;
        case ISO_F32: { float x = (float)v; memcpy(out, &x, size); } break;
        case ISO_F64: memcpy(out, &v, size); break;
        }
        if (big_endian != host_big_endian())
            reverse(out, size);
    }
}

/* Values that every type holds exactly, distinct per sample, negative for signed types. */
static double pattern(iso_voxel_type type, size_t i, size_t j, size_t k)
{
    double v = (double)(i + 3 * j + 15 * k);
    if (type == ISO_I8 || type == ISO_I16 || type == ISO_I32)
        v -= 50;
    if (type == ISO_F32 || type == ISO_F64)
        v = v * 0.25 - 7;
    return v;
}

static void tmp_path(char *buf, size_t cap, const char *name)
{
    snprintf(buf, cap, "%s/%s", check_temp_dir(), name);
}

static void write_file(const char *path, const void *a, size_t a_len, const void *b,
                       size_t b_len)
{
    check_write_file(path, a, a_len, b, b_len);
}

/* gzip-compresses into a malloc'd buffer (caller frees). */
static unsigned char *gzip(const void *data, size_t size, size_t *out_size)
{
    return check_deflate(data, size, 15 + 16, 6, out_size);
}

/* The 3x5x7 test volume's samples as `type` in the given byte order (caller frees). */
static unsigned char *pattern_bytes(iso_voxel_type type, int big_endian, size_t *size)
{
    double values[3 * 5 * 7];
    size_t n = 0;
    for (size_t k = 0; k < 7; k++)
        for (size_t j = 0; j < 5; j++)
            for (size_t i = 0; i < 3; i++)
                values[n++] = pattern(type, i, j, k);
    *size = n * iso_vol_type_size(type);
    unsigned char *out = malloc(*size);
    encode(type, big_endian, values, n, out);
    return out;
}

static void check_pattern(const iso_volume *vol, iso_voxel_type type)
{
    CHECK(vol != NULL);
    if (!vol)
        return;
    CHECK_EQ(vol->type, type);
    CHECK_EQ(vol->dims[0], 3);
    CHECK_EQ(vol->dims[1], 5);
    CHECK_EQ(vol->dims[2], 7);
    for (size_t k = 0; k < 7; k++)
        for (size_t j = 0; j < 5; j++)
            for (size_t i = 0; i < 3; i++)
                if (iso_vol_get(vol, i, j, k) != pattern(type, i, j, k)) {
                    CHECKF(0, "sample (%zu,%zu,%zu) is %g, expected %g", i, j, k,
                           iso_vol_get(vol, i, j, k), pattern(type, i, j, k));
                    return;
                }
}

static iso_volume *load_ok(const char *path)
{
    iso_volume *vol = NULL;
    iso_error err = {0, ""};
    CHECK_OK(iso_load(path, NULL, &vol, &err), &err);
    return vol;
}

/* Loads `path` expecting failure with `code`, a NULL volume and a message that names the
 * file (its last component) and contains `detail` when not NULL. */
static void expect_error(const char *path, uint64_t max_bytes, int code, const char *detail)
{
    iso_load_options opt = {.max_bytes = max_bytes};
    iso_volume *vol = (iso_volume *)&opt; /* must be overwritten with NULL */
    iso_error err = {0, ""};
    const char *base = strrchr(path, '/') ? strrchr(path, '/') + 1 : path;
    int rc = iso_load(path, &opt, &vol, &err);
    CHECKF(rc == code, "%s: expected %s, got %d (%s): %s", base, iso_status_name(code), rc,
           iso_status_name(rc), err.message);
    CHECK_EQ(err.code, rc);
    CHECK(vol == NULL);
    CHECKF(strstr(err.message, base) != NULL, "message does not name %s: %s", base, err.message);
    if (detail)
        CHECKF(strstr(err.message, detail) != NULL, "message lacks '%s': %s", detail,
               err.message);
}

/* Writes header + data as `name` in the temp dir; path receives its full name. */
static void write_temp(char path[512], const char *name, const char *header, const void *data,
                       size_t size)
{
    tmp_path(path, 512, name);
    write_file(path, header, strlen(header), data, size);
}

static iso_volume *load_temp(const char *name, const char *header, const void *data, size_t size)
{
    char path[512];
    write_temp(path, name, header, data, size);
    return load_ok(path);
}

static void expect_file_error(const char *name, const char *header, const void *data,
                              size_t size, uint64_t max_bytes, int code, const char *detail)
{
    char path[512];
    write_temp(path, name, header, data, size);
    expect_error(path, max_bytes, code, detail);
}

/* ---- volumes ---- */

static void test_type_names(void)
{
    static const size_t sizes[] = {1, 1, 2, 2, 4, 4, 4, 8};
    for (size_t t = 0; t < TYPE_COUNT; t++) {
        iso_voxel_type back = ISO_F64;
        const char *name = iso_vol_type_name(all_types[t]);
        CHECK_EQ(iso_vol_type_size(all_types[t]), sizes[t]);
        CHECK_EQ(iso_vol_type_parse(name, &back), 0);
        CHECK_EQ(back, all_types[t]);
        CHECK_EQ(iso_vol_type_is_float(all_types[t]), all_types[t] == ISO_F32 || all_types[t] == ISO_F64);
    }
    iso_voxel_type untouched = ISO_I16;
    CHECK(strcmp(iso_vol_type_name(ISO_U16), "u16") == 0);
    CHECK(strcmp(iso_vol_type_name(ISO_F32), "f32") == 0);
    CHECK_EQ(iso_vol_type_parse("float", &untouched), -1);
    CHECK_EQ(iso_vol_type_parse("", &untouched), -1);
    CHECK_EQ(untouched, ISO_I16);
    CHECK(iso_vol_type_name((iso_voxel_type)99) != NULL);
}

static void test_create_get_set(void)
{
    const size_t dims[3] = {3, 5, 7};
    iso_error err = {0, ""};
    iso_volume *vol = iso_vol_create(dims, ISO_U16, 0, &err);
    CHECKF(vol != NULL, "%s", err.message);
    if (!vol)
        return;
    CHECK_EQ(iso_vol_count(vol), 105);
    CHECK_EQ(iso_vol_index(vol, 2, 4, 6), 104);
    CHECK_EQ(iso_vol_index(vol, 1, 2, 3), 1 + 3 * 2 + 15 * 3);
    for (int d = 0; d < 3; d++) {
        CHECK_EQ(vol->dims[d], dims[d]);
        CHECK(vol->spacing[d] == 1 && vol->origin[d] == 0);
        for (int c = 0; c < 3; c++)
            CHECK(vol->direction[d][c] == (d == c));
    }
    CHECK(iso_vol_get(vol, 2, 4, 6) == 0); /* zero-filled */
    for (size_t k = 0; k < 7; k++)
        for (size_t j = 0; j < 5; j++)
            for (size_t i = 0; i < 3; i++)
                iso_vol_set(vol, i, j, k, (double)(i + 10 * j + 100 * k));
    CHECK(iso_vol_get(vol, 2, 4, 6) == 642);
    CHECK(iso_vol_get(vol, 1, 0, 3) == 301);
    CHECK_EQ(((const uint16_t *)vol->data)[iso_vol_index(vol, 1, 3, 5)], 531);
    iso_vol_destroy(vol);
    iso_vol_destroy(NULL);
}

/* Integers round to nearest and clamp; NaN becomes 0; floats store as given. */
static void test_set_converts(void)
{
    const size_t dims[3] = {2, 2, 2};
    iso_volume *u8 = iso_vol_create(dims, ISO_U8, 0, NULL);
    iso_volume *i16 = iso_vol_create(dims, ISO_I16, 0, NULL);
    iso_volume *f32 = iso_vol_create(dims, ISO_F32, 0, NULL);
    CHECK(u8 && i16 && f32);
    if (!u8 || !i16 || !f32)
        goto done;
    iso_vol_set(u8, 0, 0, 0, 300);
    iso_vol_set(u8, 1, 0, 0, -5);
    iso_vol_set(u8, 0, 1, 0, 2.5);
    iso_vol_set(u8, 1, 1, 0, 2.49);
    iso_vol_set(u8, 0, 0, 1, NAN);
    CHECK(iso_vol_get(u8, 0, 0, 0) == 255);
    CHECK(iso_vol_get(u8, 1, 0, 0) == 0);
    CHECK(iso_vol_get(u8, 0, 1, 0) == 3);
    CHECK(iso_vol_get(u8, 1, 1, 0) == 2);
    CHECK(iso_vol_get(u8, 0, 0, 1) == 0);
    iso_vol_set(i16, 0, 0, 0, -40000);
    iso_vol_set(i16, 1, 0, 0, 40000);
    iso_vol_set(i16, 0, 1, 0, -2.6);
    CHECK(iso_vol_get(i16, 0, 0, 0) == -32768);
    CHECK(iso_vol_get(i16, 1, 0, 0) == 32767);
    CHECK(iso_vol_get(i16, 0, 1, 0) == -3);
    iso_vol_set(f32, 1, 1, 1, 1.5);
    iso_vol_set(f32, 0, 1, 1, NAN);
    CHECK(iso_vol_get(f32, 1, 1, 1) == 1.5);
    CHECK(isnan(iso_vol_get(f32, 0, 1, 1)));
done:
    iso_vol_destroy(u8);
    iso_vol_destroy(i16);
    iso_vol_destroy(f32);
}

static void test_read_box(void)
{
    const size_t dims[3] = {3, 5, 7};
    for (size_t t = 0; t < TYPE_COUNT && !check_failed(); t++) {
        iso_voxel_type type = all_types[t];
        iso_volume *vol = iso_vol_create(dims, type, 0, NULL);
        double out[3 * 5 * 7];
        CHECK(vol != NULL);
        if (!vol)
            return;
        for (size_t k = 0; k < 7; k++)
            for (size_t j = 0; j < 5; j++)
                for (size_t i = 0; i < 3; i++)
                    iso_vol_set(vol, i, j, k, pattern(type, i, j, k));
        const size_t boxes[][6] = {
            {0, 0, 0, 2, 4, 6}, {1, 2, 3, 2, 4, 6}, {0, 1, 2, 1, 3, 5}, {2, 4, 6, 2, 4, 6},
            {1, 0, 0, 1, 4, 0},
        };
        for (size_t b = 0; b < sizeof boxes / sizeof boxes[0]; b++) {
            const size_t *lo = boxes[b], *hi = boxes[b] + 3;
            size_t n = 0;
            iso_vol_read_box(vol, lo, hi, out);
            for (size_t k = lo[2]; k <= hi[2]; k++)
                for (size_t j = lo[1]; j <= hi[1]; j++)
                    for (size_t i = lo[0]; i <= hi[0]; i++, n++)
                        CHECKF(out[n] == pattern(type, i, j, k),
                               "%s box %zu: (%zu,%zu,%zu) read %g, expected %g",
                               iso_vol_type_name(type), b, i, j, k, out[n], pattern(type, i, j, k));
        }
        iso_vol_destroy(vol);
    }
}

static void test_check_size(void)
{
    iso_error err = {0, ""};
    uint64_t bytes = 0;
    const size_t huge[3] = {(size_t)1 << 40, (size_t)1 << 40, (size_t)1 << 40};
    const size_t max[3] = {SIZE_MAX, SIZE_MAX, 2};
    const size_t flat[3] = {4, 1, 4};
    const size_t ten[3] = {10, 10, 10};
    const size_t cube[3] = {256, 256, 256};

    CHECK_EQ(iso_vol_check_size(huge, ISO_U8, UINT64_MAX, &bytes, &err), ISO_E_LIMIT);
    CHECK_EQ(err.code, ISO_E_LIMIT);
    CHECKF(strstr(err.message, "1099511627776x1099511627776x1099511627776"), "%s", err.message);
    CHECK_EQ(iso_vol_check_size(max, ISO_F64, 0, &bytes, &err), ISO_E_LIMIT);
    CHECK_EQ(iso_vol_check_size(huge, ISO_U8, 0, NULL, NULL), ISO_E_LIMIT);
    CHECK_EQ(iso_vol_check_size(flat, ISO_U8, 0, &bytes, &err), ISO_E_ARGUMENT);
    CHECKF(strstr(err.message, "4x1x4"), "%s", err.message);

    CHECK_OK(iso_vol_check_size(ten, ISO_U16, 2000, &bytes, &err), &err);
    CHECK_EQ(bytes, 2000);
    CHECK_EQ(iso_vol_check_size(ten, ISO_U16, 1999, &bytes, &err), ISO_E_LIMIT);
    CHECKF(strstr(err.message, "10x10x10") && strstr(err.message, "1999"), "%s", err.message);
    CHECK_OK(iso_vol_check_size(cube, ISO_F64, 0, &bytes, &err), &err);
    CHECK_EQ(bytes, (uint64_t)256 * 256 * 256 * 8);

    /* The 8 GiB default, exactly at and just past it. */
    const size_t at_limit[3] = {2048, 2048, 2048};
    const size_t past_limit[3] = {2048, 2048, 2049};
    CHECK_OK(iso_vol_check_size(at_limit, ISO_U8, 0, &bytes, &err), &err);
    CHECK_EQ(bytes, ISO_VOL_DEFAULT_MAX_BYTES);
    CHECK_EQ(iso_vol_check_size(past_limit, ISO_U8, 0, &bytes, &err), ISO_E_LIMIT);

    err.code = 0;
    CHECK(iso_vol_create(huge, ISO_U8, 0, &err) == NULL);
    CHECK_EQ(err.code, ISO_E_LIMIT);
    CHECK(iso_vol_create(cube, ISO_U8, 1000, &err) == NULL);
    CHECK_EQ(err.code, ISO_E_LIMIT);
    CHECK(iso_vol_create(flat, ISO_U8, 0, NULL) == NULL);
}

static void test_stats(void)
{
    const size_t dims[3] = {2, 3, 2};
    iso_volume *vol = iso_vol_create(dims, ISO_F32, 0, NULL);
    iso_volume *ints = iso_vol_create(dims, ISO_I16, 0, NULL);
    CHECK(vol && ints);
    if (!vol || !ints)
        goto done;
    for (size_t n = 0; n < 12; n++) {
        ((float *)vol->data)[n] = (float)n - 3;
        ((int16_t *)ints->data)[n] = (int16_t)(n * 1000 - 5000);
    }
    ((float *)vol->data)[5] = NAN;
    iso_vol_update_stats(vol);
    CHECK(vol->has_nan == 1);
    CHECK(vol->value_min == -3);
    CHECK(vol->value_max == 8);
    CHECK_NEAR(vol->value_mean, (66.0 - 5 - 33) / 11, 1e-12);
    for (size_t n = 0; n < 12; n++)
        ((float *)vol->data)[n] = NAN;
    iso_vol_update_stats(vol);
    CHECK(vol->has_nan == 1 && vol->value_min == 0 && vol->value_max == 0 && vol->value_mean == 0);

    iso_vol_update_stats(ints);
    CHECK(ints->has_nan == 0);
    CHECK(ints->value_min == -5000);
    CHECK(ints->value_max == 6000);
    CHECK_NEAR(ints->value_mean, 500, 1e-12);
done:
    iso_vol_destroy(vol);
    iso_vol_destroy(ints);
}

/* Integer sums go through chunks: a volume larger than one chunk must still sum exactly. */
static void test_stats_large(void)
{
    const size_t dims[3] = {300, 300, 5};
    iso_volume *vol = iso_vol_create(dims, ISO_U32, 0, NULL);
    CHECK(vol != NULL);
    if (!vol)
        return;
    uint32_t *p = vol->data;
    size_t n = iso_vol_count(vol);
    for (size_t s = 0; s < n; s++)
        p[s] = UINT32_MAX - (uint32_t)(s % 2);
    iso_vol_update_stats(vol);
    CHECK(vol->value_min == UINT32_MAX - 1.0);
    CHECK(vol->value_max == UINT32_MAX);
    CHECK_NEAR(vol->value_mean, UINT32_MAX - 0.5, 1e-6);
    iso_vol_destroy(vol);
}

static void test_index_to_world(void)
{
    const size_t dims[3] = {4, 4, 4};
    iso_volume *vol = iso_vol_create(dims, ISO_U8, 0, NULL);
    double world[3];
    CHECK(vol != NULL);
    if (!vol)
        return;
    vol->spacing[0] = 2, vol->spacing[1] = 3, vol->spacing[2] = 4;
    vol->origin[0] = 10, vol->origin[1] = 20, vol->origin[2] = 30;
    iso_vol_index_to_world(vol, (const double[3]){1, 1, 0.5}, world);
    CHECK(world[0] == 12 && world[1] == 23 && world[2] == 32);
    /* i runs along world y, j along world -x, k along z. */
    memset(vol->direction, 0, sizeof vol->direction);
    vol->direction[1][0] = 1;
    vol->direction[0][1] = -1;
    vol->direction[2][2] = 1;
    iso_vol_index_to_world(vol, (const double[3]){1, 2, 3}, world);
    CHECK(world[0] == 10 - 6 && world[1] == 20 + 2 && world[2] == 30 + 12);
    iso_vol_destroy(vol);
}

/* ---- NRRD ---- */

static const char *endian_line(iso_voxel_type type, int big)
{
    if (iso_vol_type_size(type) == 1)
        return "";
    return big ? "endian: big\n" : "endian: little\n";
}

/* The NRRD name of each type, for the round trips. */
static const char *nrrd_type(iso_voxel_type type)
{
    static const char *const names[] = {"uint8", "int8", "uint16", "int16",
                                        "uint32", "int32", "float", "double"};
    return names[type];
}

static void test_nrrd_attached_raw(void)
{
    for (size_t t = 0; t < TYPE_COUNT && !check_failed(); t++) {
        char name[64], header[256];
        size_t size;
        unsigned char *data = pattern_bytes(all_types[t], 0, &size);
        snprintf(name, sizeof name, "raw_%s.nrrd", iso_vol_type_name(all_types[t]));
        snprintf(header, sizeof header,
                 "NRRD0004\n# a comment\ntype: %s\ndimension: 3\nsizes: 3 5 7\n%sencoding: raw\n"
                 "content: test:=not a pair\nunit key:=value: with colons\n\n",
                 nrrd_type(all_types[t]), endian_line(all_types[t], 0));
        iso_volume *vol = load_temp(name, header, data, size);
        check_pattern(vol, all_types[t]);
        if (vol) {
            CHECK(vol->value_min == pattern(all_types[t], 0, 0, 0));
            CHECK(vol->value_max == pattern(all_types[t], 2, 4, 6));
        }
        iso_vol_destroy(vol);
        free(data);
    }
}

static void test_nrrd_attached_gzip(void)
{
    size_t size, zsize;
    unsigned char *data = pattern_bytes(ISO_F32, 0, &size);
    unsigned char *z = gzip(data, size, &zsize);
    const char *header = "NRRD0005\ntype: float\ndimension: 3\nsizes: 3 5 7\nendian: little\n"
                         "encoding: gzip\n\n";
    iso_volume *vol = load_temp("attached_gzip.nrrd", header, z, zsize);
    check_pattern(vol, ISO_F32);
    iso_vol_destroy(vol);

    /* CRLF line ends and "gz" spelling. */
    const char *crlf = "NRRD0004\r\ntype: float\r\ndimension: 3\r\nsizes: 3 5 7\r\n"
                       "endian: little\r\nencoding: gz\r\n\r\n";
    vol = load_temp("attached_crlf.nrrd", crlf, z, zsize);
    check_pattern(vol, ISO_F32);
    iso_vol_destroy(vol);
    free(z);
    free(data);
}

/* Writes `header` as dir/name, loads it and checks that it holds the i16 test pattern. */
static void check_detached_i16(const char *dir, const char *name, const char *header)
{
    char path[700];
    snprintf(path, sizeof path, "%s/%s", dir, name);
    write_file(path, header, strlen(header), NULL, 0);
    iso_volume *vol = load_ok(path);
    check_pattern(vol, ISO_I16);
    iso_vol_destroy(vol);
}

static void test_nrrd_detached(void)
{
    char dir[512], sub[600], data_path[700], header[1024];
    size_t size, zsize;
    unsigned char *data = pattern_bytes(ISO_I16, 1, &size), *padded, *z;
    tmp_path(dir, sizeof dir, "detached");
    snprintf(sub, sizeof sub, "%s/data", dir);
    CHECK(mkdir(dir, 0700) == 0 && mkdir(sub, 0700) == 0);

    /* Relative to the header's directory, not to the working directory. */
    snprintf(data_path, sizeof data_path, "%s/vol.raw", sub);
    write_file(data_path, data, size, NULL, 0);
    check_detached_i16(dir, "rel.nhdr", "NRRD0004\ntype: short\ndimension: 3\nsizes: 3 5 7\n"
                       "endian: big\nencoding: raw\ndata file: data/vol.raw\n");

    /* "datafile" spelling, with a blank line and trailing junk after it. */
    snprintf(header, sizeof header, "NRRD0003\ntype: short\ndimension: 3\nsizes: 3 5 7\n"
             "endian: big\nencoding: raw\ndatafile: data/vol.raw\n\nignored\n");
    check_detached_i16(dir, "spelling.nhdr", header);

    /* A header may not point outside its own directory (a format error), nor at a device
     * (an i/o error, as for the hierarchy file and every other loader). */
    static const struct { const char *name, *data, *detail; int code; } outside[] = {
        {"abs.nhdr", "/etc/hostname", "leaves the header's directory", ISO_E_FORMAT},
        {"up.nhdr", "../vol.raw", "leaves the header's directory", ISO_E_FORMAT},
        {"middle.nhdr", "data/../../vol.raw", "leaves the header's directory", ISO_E_FORMAT},
        {"device.nhdr", "zero", "not a regular file", ISO_E_IO},
    };
    char dev_link[1200];
    snprintf(dev_link, sizeof dev_link, "%s/zero", dir);
    CHECK(symlink("/dev/zero", dev_link) == 0);
    for (size_t i = 0; i < sizeof outside / sizeof outside[0]; i++) {
        char hpath[1200];
        snprintf(header, sizeof header, "NRRD0004\ntype: int16\ndimension: 3\nsizes: 3 5 7\n"
                 "endian: big\nencoding: raw\ndata file: %s\n", outside[i].data);
        snprintf(hpath, sizeof hpath, "%s/%s", dir, outside[i].name);
        write_file(hpath, header, strlen(header), NULL, 0);
        expect_error(hpath, 0, outside[i].code, outside[i].detail);
    }

    /* Line skip then byte skip, as for data behind a PGM header. */
    snprintf(data_path, sizeof data_path, "%s/skips.raw", sub);
    write_file(data_path, "P5 line one\nline two\nJUNK!", 26, data, size);
    check_detached_i16(dir, "skips.nhdr", "NRRD0004\ntype: int16\ndimension: 3\nsizes: 3 5 7\n"
                       "endian: big\nencoding: raw\nline skip: 2\nbyte skip: 5\n"
                       "data file: ./data/skips.raw\n");

    /* Byte skip -1: the samples are the file's last bytes. */
    check_detached_i16(dir, "tail.nhdr", "NRRD0004\ntype: int16\ndimension: 3\nsizes: 3 5 7\n"
                       "endian: big\nencoding: raw\nbyte skip: -1\ndata file: data/skips.raw\n");

    /* gzip with a byte skip, applied after decompression. */
    padded = malloc(size + 3);
    memcpy(padded, "abc", 3);
    memcpy(padded + 3, data, size);
    z = gzip(padded, size + 3, &zsize);
    snprintf(data_path, sizeof data_path, "%s/vol.raw.gz", sub);
    write_file(data_path, z, zsize, NULL, 0);
    check_detached_i16(dir, "gz.nhdr", "NRRD0004\ntype: int16\ndimension: 3\nsizes: 3 5 7\n"
                       "endian: big\nencoding: gzip\nbyte skip: 3\ndata file: data/vol.raw.gz\n");
    free(z);
    free(padded);
    free(data);
}

/* The same values stored big- and little-endian load equal, for every multi-byte type. */
static void test_nrrd_endian(void)
{
    for (size_t t = 0; t < TYPE_COUNT && !check_failed(); t++) {
        iso_volume *vols[2];
        for (int big = 0; big < 2; big++) {
            char name[64], header[256];
            size_t size;
            unsigned char *data = pattern_bytes(all_types[t], big, &size);
            snprintf(name, sizeof name, "endian_%s_%d.nrrd", iso_vol_type_name(all_types[t]), big);
            snprintf(header, sizeof header,
                     "NRRD0004\ntype: %s\ndimension: 3\nsizes: 3 5 7\n%sencoding: raw\n\n",
                     nrrd_type(all_types[t]), endian_line(all_types[t], big));
            vols[big] = load_temp(name, header, data, size);
            check_pattern(vols[big], all_types[t]);
            free(data);
        }
        if (vols[0] && vols[1])
            CHECK(memcmp(vols[0]->data, vols[1]->data, 105 * iso_vol_type_size(all_types[t])) == 0);
        iso_vol_destroy(vols[0]);
        iso_vol_destroy(vols[1]);
    }
}

static void test_nrrd_geometry(void)
{
    unsigned char data[2 * 3 * 4] = {0};
    double world[3];
    iso_volume *vol;

    const char *directions = "NRRD0005\ntype: uchar\ndimension: 3\nsizes: 2 3 4\n"
                             "space: left-posterior-superior\nspace directions: (0,2,0) "
                             "( -3 , 0 , 0 ) (0,0,1.5)\nspace origin: (1,-2,3.5)\n"
                             "encoding: raw\n\n";
    vol = load_temp("directions.nrrd", directions, data, sizeof data);
    if (vol) {
        CHECK(vol->spacing[0] == 2 && vol->spacing[1] == 3 && vol->spacing[2] == 1.5);
        CHECK(vol->origin[0] == 1 && vol->origin[1] == -2 && vol->origin[2] == 3.5);
        CHECK(vol->direction[0][0] == 0 && vol->direction[1][0] == 1 && vol->direction[2][0] == 0);
        CHECK(vol->direction[0][1] == -1 && vol->direction[1][1] == 0 && vol->direction[2][1] == 0);
        CHECK(vol->direction[0][2] == 0 && vol->direction[1][2] == 0 && vol->direction[2][2] == 1);
        CHECK_EQ(vol->oriented, 1);
        iso_vol_index_to_world(vol, (const double[3]){1, 2, 2}, world);
        CHECK_NEAR(world[0], 1 - 6, 1e-12);
        CHECK_NEAR(world[1], -2 + 2, 1e-12);
        CHECK_NEAR(world[2], 3.5 + 3, 1e-12);
    }
    iso_vol_destroy(vol);

    const char *spacings = "NRRD0004\ntype: uchar\ndimension: 3\nsizes: 2 3 4\n"
                           "spacings: 0.5 0.75 -2\nencoding: raw\n\n";
    vol = load_temp("spacings.nrrd", spacings, data, sizeof data);
    if (vol) {
        CHECK(vol->spacing[0] == 0.5 && vol->spacing[1] == 0.75 && vol->spacing[2] == 2);
        CHECK(vol->direction[2][2] == -1 && vol->direction[0][0] == 1);
        CHECK(vol->origin[0] == 0 && vol->origin[1] == 0 && vol->origin[2] == 0);
        CHECK_EQ(vol->oriented, 0); /* spacings place samples, not the patient */
    }
    iso_vol_destroy(vol);

    /* 4-D with one value per sample: the first axis drops out of sizes and geometry. */
    const char *four = "NRRD0004\ntype: uchar\ndimension: 4\nsizes: 1 2 3 4\n"
                       "spacings: nan 1 2 3\nencoding: raw\n\n";
    vol = load_temp("four.nrrd", four, data, sizeof data);
    if (vol) {
        CHECK(vol->dims[0] == 2 && vol->dims[1] == 3 && vol->dims[2] == 4);
        CHECK(vol->spacing[0] == 1 && vol->spacing[1] == 2 && vol->spacing[2] == 3);
    }
    iso_vol_destroy(vol);
}

/* Orientation codes: each letter the direction its axis runs toward, any order; anything
 * else refused with the volume unchanged. */
static void test_set_axes(void)
{
    iso_error err;
    size_t dims[3] = {2, 2, 2};
    iso_volume *vol = iso_vol_create(dims, ISO_U8, 0, &err);
    CHECK(vol != NULL);
    if (!vol)
        return;
    vol->spacing[2] = 2;
    vol->origin[0] = 5;
    CHECK_OK(iso_vol_set_axes(vol, "LPI", &err), &err);
    const double lpi[3][3] = {{1, 0, 0}, {0, 1, 0}, {0, 0, -1}};
    CHECK(memcmp(vol->direction, lpi, sizeof lpi) == 0);
    CHECK(vol->oriented == 1 && vol->spacing[2] == 2 && vol->origin[0] == 5);
    double world[3];
    iso_vol_index_to_world(vol, (const double[3]){1, 1, 1}, world);
    CHECK(world[0] == 6 && world[1] == 1 && world[2] == -2);
    CHECK_OK(iso_vol_set_axes(vol, "asr", &err), &err); /* i toward anterior, j superior, k right */
    const double asr[3][3] = {{0, 0, -1}, {-1, 0, 0}, {0, 1, 0}};
    CHECK(memcmp(vol->direction, asr, sizeof asr) == 0);
    static const char *const bad[] = {"", "LP", "LPSI", "LLS", "LRS", "LPX", "PAS", "SIL"};
    for (size_t b = 0; b < sizeof bad / sizeof *bad; b++) {
        CHECKF(iso_vol_set_axes(vol, bad[b], &err) == ISO_E_ARGUMENT, "\"%s\" accepted", bad[b]);
        CHECK(strstr(err.message, "one of L or R") != NULL);
    }
    CHECK(memcmp(vol->direction, asr, sizeof asr) == 0);
    iso_vol_destroy(vol);
}

/* Fills vol with air (10) around a ball of 900, and `pad` outside a circle of radius
 * 0.45 n in every k-slice (a CT's reconstruction circle) when pad is not NAN. */
static iso_volume *scan(size_t n, iso_voxel_type type, double pad, double ball_value)
{
    iso_error err;
    size_t dims[3] = {n, n, n / 2};
    iso_volume *vol = iso_vol_create(dims, type, 0, &err);
    if (!vol)
        return NULL;
    double c = (double)(n - 1) / 2;
    for (size_t k = 0; k < dims[2]; k++)
        for (size_t j = 0; j < n; j++)
            for (size_t i = 0; i < n; i++) {
                double r2 = (i - c) * (i - c) + (j - c) * (j - c), z = (double)k - (double)dims[2] / 2;
                double v = r2 + 4 * z * z < 0.09 * n * n ? ball_value : 10;
                if (!isnan(pad) && r2 > 0.2025 * n * n)
                    v = pad;
                iso_vol_set(vol, i, j, k, v);
            }
    iso_vol_update_stats(vol);
    return vol;
}

/* Padding is the end value that fills whole lines through the volume: the circle's
 * outside (at either end of the range, any type) is found; air around a ball, a rare
 * value, a volume without a spike at its ends are not. */
static void test_find_padding(void)
{
    uint64_t counts[256];
    double pad = 0;
    struct { iso_voxel_type type; double pad, ball; int found; } cases[] = {
        {ISO_I16, -2000, 900, 1}, {ISO_F32, -3024, 900, 1}, {ISO_U16, 65535, 900, 1},
        {ISO_I16, NAN, 900, 0},  /* air (the minimum) surrounds the ball: lines cross it */
        {ISO_U8, 0, 200, 1},     /* 0 outside the circle, air 10 inside: found */
    };
    for (size_t c = 0; c < sizeof cases / sizeof *cases; c++) {
        iso_volume *vol = scan(40, cases[c].type, cases[c].pad, cases[c].ball);
        CHECK(vol != NULL);
        if (!vol)
            continue;
        iso_hist_compute(vol, 256, counts);
        int found = iso_vol_find_padding(vol, counts, 256, &pad);
        CHECKF(found == cases[c].found && (!found || pad == cases[c].pad), "case %zu: found %d, padding %g",
               c, found, pad);
        iso_vol_destroy(vol);
    }
    /* The same circle, but a tenth of its lines crossed by tissue: not padding. */
    iso_volume *vol = scan(40, ISO_I16, -2000, 900);
    if (vol) {
        for (size_t j = 0; j < 40; j += 10)
            for (size_t i = 0; i < 40; i++)
                if (iso_vol_get(vol, i, j, 3) == -2000)
                    iso_vol_set(vol, i, j, 3, 50);
        iso_hist_compute(vol, 256, counts);
        CHECK_EQ(iso_vol_find_padding(vol, counts, 256, &pad), 0);
        iso_vol_destroy(vol);
    }
}

/* Every NRRD spelling of the supported types parses to its voxel type. */
static void test_nrrd_type_spellings(void)
{
    static const struct {
        const char *spelling;
        iso_voxel_type type;
    } cases[] = {
        {"uchar", ISO_U8}, {"unsigned char", ISO_U8}, {"uint8", ISO_U8}, {"uint8_t", ISO_U8},
        {"signed char", ISO_I8}, {"int8", ISO_I8}, {"int8_t", ISO_I8},
        {"short", ISO_I16}, {"short int", ISO_I16}, {"signed short", ISO_I16},
        {"signed short int", ISO_I16}, {"int16", ISO_I16}, {"int16_t", ISO_I16},
        {"ushort", ISO_U16}, {"unsigned short", ISO_U16}, {"unsigned short int", ISO_U16},
        {"uint16", ISO_U16}, {"uint16_t", ISO_U16},
        {"int", ISO_I32}, {"signed int", ISO_I32}, {"int32", ISO_I32}, {"int32_t", ISO_I32},
        {"uint", ISO_U32}, {"unsigned int", ISO_U32}, {"uint32", ISO_U32}, {"uint32_t", ISO_U32},
        {"float", ISO_F32}, {"double", ISO_F64},
    };
    char path[512], header[256];
    iso_nrrd_header hdr;
    iso_error err = {0, ""};
    tmp_path(path, sizeof path, "spelling.nhdr");
    for (size_t c = 0; c < sizeof cases / sizeof cases[0]; c++) {
        snprintf(header, sizeof header, "NRRD0004\ntype: %s\ndimension: 3\nsizes: 2 2 2\n"
                 "endian: little\nencoding: raw\ndata file: x.raw\n", cases[c].spelling);
        write_file(path, header, strlen(header), NULL, 0);
        CHECK_OK(iso_nrrd_read_header(path, &hdr, &err), &err);
        CHECKF(hdr.type == cases[c].type, "'%s' read as %s", cases[c].spelling,
               iso_vol_type_name(hdr.type));
        CHECK_EQ(hdr.data_bytes, 8 * iso_vol_type_size(cases[c].type));
        CHECK(hdr.detached == 1 && strstr(hdr.data_path, "/x.raw") != NULL);
    }
}

/* Hostile or broken headers: each fails with its status and a message naming the file. */
static void test_nrrd_bad_headers(void)
{
    static const unsigned char bytes[8] = {1, 2, 3, 4, 5, 6, 7, 8};
    static const struct {
        const char *name, *header;
        int code;
        const char *detail;
    } cases[] = {
        {"magic.nrrd", "NRRD0009\ntype: uchar\n\n", ISO_E_FORMAT, "magic"},
        {"magic2.nrrd", "P5 2 2\n255\n", ISO_E_FORMAT, "magic"},
        {"empty.nrrd", "", ISO_E_FORMAT, "magic"},
        {"nosizes.nrrd", "NRRD0004\ntype: uchar\ndimension: 3\nencoding: raw\n\n", ISO_E_FORMAT,
         "sizes"},
        {"notype.nrrd", "NRRD0004\ndimension: 3\nsizes: 2 2 2\nencoding: raw\n\n", ISO_E_FORMAT,
         "type"},
        {"noencoding.nrrd", "NRRD0004\ntype: uchar\ndimension: 3\nsizes: 2 2 2\n\n",
         ISO_E_FORMAT, "encoding"},
        {"noendian.nrrd", "NRRD0004\ntype: short\ndimension: 3\nsizes: 2 2 2\nencoding: raw\n\n",
         ISO_E_FORMAT, "endian"},
        {"dim2.nrrd", "NRRD0004\ntype: uchar\ndimension: 2\nsizes: 2 2\nencoding: raw\n\n",
         ISO_E_UNSUPPORTED, ":3:"},
        {"dim0.nrrd", "NRRD0004\ntype: uchar\ndimension: 0\n\n", ISO_E_FORMAT, "dimension"},
        {"dimx.nrrd", "NRRD0004\ntype: uchar\ndimension: three\n\n", ISO_E_FORMAT, "dimension"},
        {"dim4.nrrd", "NRRD0004\ntype: uchar\ndimension: 4\nsizes: 3 2 2 2\nencoding: raw\n\n",
         ISO_E_UNSUPPORTED, "sizes"},
        {"type.nrrd", "NRRD0004\ntype: quaternion\ndimension: 3\nsizes: 2 2 2\nencoding: raw\n\n",
         ISO_E_FORMAT, ":2: field 'type'"},
        {"int64.nrrd", "NRRD0004\ntype: int64\ndimension: 3\nsizes: 2 2 2\nencoding: raw\n\n",
         ISO_E_UNSUPPORTED, "int64"},
        {"encoding.nrrd", "NRRD0004\ntype: uchar\ndimension: 3\nsizes: 2 2 2\nencoding: lzma\n\n",
         ISO_E_FORMAT, ":5: field 'encoding'"},
        {"bzip2.nrrd", "NRRD0004\ntype: uchar\ndimension: 3\nsizes: 2 2 2\nencoding: bzip2\n\n",
         ISO_E_UNSUPPORTED, "bzip2"},
        {"ascii.nrrd", "NRRD0004\ntype: uchar\ndimension: 3\nsizes: 2 2 2\nencoding: ascii\n\n",
         ISO_E_UNSUPPORTED, "ascii"},
        {"overflow.nrrd", "NRRD0004\ntype: uchar\ndimension: 3\nsizes: 1099511627776 "
         "1099511627776 1099511627776\nencoding: raw\n\n", ISO_E_LIMIT, "sizes"},
        {"bignum.nrrd", "NRRD0004\ntype: uchar\ndimension: 3\nsizes: 2 2 "
         "99999999999999999999999\nencoding: raw\n\n", ISO_E_LIMIT, ":4:"},
        {"negsize.nrrd", "NRRD0004\ntype: uchar\ndimension: 3\nsizes: 2 -2 2\nencoding: raw\n\n",
         ISO_E_FORMAT, "sizes"},
        {"fewsizes.nrrd", "NRRD0004\ntype: uchar\ndimension: 3\nsizes: 2 2\nencoding: raw\n\n",
         ISO_E_FORMAT, "sizes"},
        {"manysizes.nrrd", "NRRD0004\ntype: uchar\ndimension: 3\nsizes: 2 2 2 2\nencoding: raw\n\n",
         ISO_E_FORMAT, "sizes"},
        {"size1.nrrd", "NRRD0004\ntype: uchar\ndimension: 3\nsizes: 2 1 2\nencoding: raw\n\n",
         ISO_E_UNSUPPORTED, "sizes"},
        {"order.nrrd", "NRRD0004\ntype: uchar\nsizes: 2 2 2\ndimension: 3\nencoding: raw\n\n",
         ISO_E_FORMAT, "before the dimension"},
        {"twice.nrrd", "NRRD0004\ntype: uchar\ndimension: 3\nsizes: 2 2 2\ntype: uchar\n"
         "encoding: raw\n\n", ISO_E_FORMAT, "twice"},
        {"noline.nrrd", "NRRD0004\ntype: uchar\nthis line has no colon\n\n", ISO_E_FORMAT, ":3:"},
        {"endian.nrrd", "NRRD0004\ntype: short\ndimension: 3\nsizes: 2 2 2\nendian: middle\n"
         "encoding: raw\n\n", ISO_E_FORMAT, "endian"},
        {"spacing0.nrrd", "NRRD0004\ntype: uchar\ndimension: 3\nsizes: 2 2 2\nspacings: 1 0 1\n"
         "encoding: raw\n\n", ISO_E_FORMAT, "spacings"},
        {"direction.nrrd", "NRRD0004\ntype: uchar\ndimension: 3\nsizes: 2 2 2\n"
         "space directions: (1,0,0) (0,1,0 (0,0,1)\nencoding: raw\n\n", ISO_E_FORMAT,
         "space directions"},
        {"direction0.nrrd", "NRRD0004\ntype: uchar\ndimension: 3\nsizes: 2 2 2\n"
         "space directions: (1,0,0) (0,0,0) (0,0,1)\nencoding: raw\n\n", ISO_E_FORMAT, "zero"},
        {"space2d.nrrd", "NRRD0004\ntype: uchar\ndimension: 3\nsizes: 2 2 2\n"
         "space directions: (1,0) (0,1) (1,1)\nencoding: raw\n\n", ISO_E_UNSUPPORTED, "3-D"},
        {"origin.nrrd", "NRRD0004\ntype: uchar\ndimension: 3\nsizes: 2 2 2\n"
         "space origin: (1,nan,0)\nencoding: raw\n\n", ISO_E_FORMAT, "space origin"},
        {"byteskip.nrrd", "NRRD0004\ntype: uchar\ndimension: 3\nsizes: 2 2 2\nbyte skip: -2\n"
         "encoding: raw\n\n", ISO_E_FORMAT, "byte skip"},
        {"gzskip.nrrd", "NRRD0004\ntype: uchar\ndimension: 3\nsizes: 2 2 2\nbyte skip: -1\n"
         "encoding: gzip\n\n", ISO_E_UNSUPPORTED, "byte skip"},
        {"list.nhdr", "NRRD0004\ntype: uchar\ndimension: 3\nsizes: 2 2 2\nencoding: raw\n"
         "data file: LIST\nslice1.raw\n", ISO_E_UNSUPPORTED, "data file"},
        {"format.nhdr", "NRRD0004\ntype: uchar\ndimension: 3\nsizes: 2 2 2\nencoding: raw\n"
         "data file: slice%03d.raw 1 2 1\n", ISO_E_UNSUPPORTED, "data file"},
        {"nodata.nhdr", "NRRD0004\ntype: uchar\ndimension: 3\nsizes: 2 2 2\nencoding: raw\n"
         "data file: missing.raw\n", ISO_E_IO, "missing.raw"},
        {"binary.nrrd", "NRRD0004\ntype: uchar\x01\x02\xff\n\n", ISO_E_FORMAT, "binary"},
        {"nohead.nrrd", "NRRD0004\ntype: uchar\ndimension: 3\nsizes: 2 2 2\nencoding: raw\n"
         "\x01\x02\x03\x04\x05\x06\x07\x08", ISO_E_FORMAT, ":6:"},
    };
    for (size_t c = 0; c < sizeof cases / sizeof cases[0]; c++)
        expect_file_error(cases[c].name, cases[c].header, NULL, 0, 0, cases[c].code,
                          cases[c].detail);
    /* The same file is fine once its header is complete: the failures above are the
     * header's, not the harness's. */
    const char *good = "NRRD0004\ntype: uchar\ndimension: 3\nsizes: 2 2 2\nencoding: raw\n\n";
    iso_vol_destroy(load_temp("good.nrrd", good, bytes, sizeof bytes));
    expect_error("/nonexistent/dir/vol.nrrd", 0, ISO_E_IO, "vol.nrrd");
    expect_error(check_temp_dir(), 0, ISO_E_UNSUPPORTED, NULL); /* no suffix: no loader */
}

static void test_nrrd_bad_data(void)
{
    size_t size, zsize;
    unsigned char *data = pattern_bytes(ISO_U16, 0, &size); /* 210 bytes */
    unsigned char *z = gzip(data, size, &zsize);
    const char *raw = "NRRD0004\ntype: uint16\ndimension: 3\nsizes: 3 5 7\nendian: little\n"
                      "encoding: raw\n\n";
    const char *gz = "NRRD0004\ntype: uint16\ndimension: 3\nsizes: 3 5 7\nendian: little\n"
                     "encoding: gzip\n\n";
    const char *big = "NRRD0004\ntype: uint8\ndimension: 3\nsizes: 16 16 16\nencoding: raw\n\n";

    expect_file_error("short.nrrd", raw, data, 100, 0, ISO_E_TRUNCATED, "expected 210 bytes");
    expect_file_error("short2.nrrd", raw, data, 100, 0, ISO_E_TRUNCATED, "found 100");
    expect_file_error("nodata.nrrd", raw, NULL, 0, 0, ISO_E_TRUNCATED, "found 0");
    expect_file_error("shortgz.nrrd", gz, z, zsize / 2, 0, ISO_E_TRUNCATED, "expected 210");
    expect_file_error("emptygz.nrrd", gz, NULL, 0, 0, ISO_E_TRUNCATED, "found 0");
    expect_file_error("notgz.nrrd", gz, data, size, 0, ISO_E_FORMAT, "gzip");
    {
        unsigned char *bad = malloc(zsize);
        memcpy(bad, z, zsize);
        for (size_t b = 12; b < zsize - 8; b++)
            bad[b] ^= 0x5a;
        expect_file_error("corruptgz.nrrd", gz, bad, zsize, 0, ISO_E_FORMAT, NULL);
        free(bad);
    }
    /* Over the caller's limit: refused before any allocation, even with no data at all. */
    expect_file_error("limit.nrrd", big, NULL, 0, 1000, ISO_E_LIMIT, "4096 bytes");
    expect_file_error("limit2.nrrd", big, NULL, 0, 4095, ISO_E_LIMIT, "4095");

    /* Line skip past the end of a detached file. */
    {
        char data_path[512];
        const char *hdr = "NRRD0004\ntype: uint16\ndimension: 3\nsizes: 3 5 7\n"
                          "endian: little\nencoding: raw\nline skip: 5\ndata file: lines.raw\n";
        tmp_path(data_path, sizeof data_path, "lines.raw");
        write_file(data_path, "one\ntwo\n", 8, NULL, 0);
        expect_file_error("lines.nhdr", hdr, NULL, 0, 0, ISO_E_TRUNCATED, "lines.raw");
    }
    /* Byte skip -1 on a file shorter than the samples. */
    expect_file_error("tail.nrrd", "NRRD0004\ntype: uint16\ndimension: 3\nsizes: 3 5 7\n"
                      "endian: little\nencoding: raw\nbyte skip: -1\n\n", data, 50, 0,
                      ISO_E_TRUNCATED, NULL);
    free(z);
    free(data);
}

/* A header line of 100 KB is refused at the line cap, with its line number. */
static void test_nrrd_long_line(void)
{
    size_t n = 100 * 1024;
    char *header = malloc(n + 64);
    strcpy(header, "NRRD0004\ncontent: ");
    size_t at = strlen(header);
    memset(header + at, 'x', n);
    strcpy(header + at + n, "\ntype: uchar\n\n");
    expect_file_error("longline.nrrd", header, NULL, 0, 0, ISO_E_FORMAT, ":2:");
    /* A long comment is no exception. */
    header[9] = '#';
    expect_file_error("longcomment.nrrd", header, NULL, 0, 0, ISO_E_FORMAT, "longer than");
    /* Nor is the first line: that one cannot even be NRRD. */
    memset(header, 'N', n);
    header[n] = '\0';
    expect_file_error("longmagic.nrrd", header, NULL, 0, 0, ISO_E_FORMAT, ":1:");
    free(header);
}

/* Random bytes, with and without a valid magic in front, never load and never crash. */
static void test_nrrd_garbage(void)
{
    unsigned char junk[4096];
    uint32_t x = 12345;
    for (int round = 0; round < 50 && !check_failed(); round++) {
        for (size_t b = 0; b < sizeof junk; b++) {
            x = x * 1664525u + 1013904223u;
            junk[b] = (unsigned char)(x >> 24);
        }
        size_t len = 1 + (x >> 8) % sizeof junk;
        char name[64];
        snprintf(name, sizeof name, "garbage%d.nrrd", round);
        expect_file_error(name, round % 2 ? "NRRD0004\n" : "", junk, len, 0, ISO_E_FORMAT, NULL);
    }
}

/* Truncating a valid header at every byte gives a status, never a crash or a volume. */
static void test_nrrd_every_prefix(void)
{
    const char *full = "NRRD0004\ntype: int16\ndimension: 3\nsizes: 3 5 7\nendian: big\n"
                       "space directions: (1,0,0) (0,2,0) (0,0,3)\nspace origin: (0,0,0)\n"
                       "encoding: raw\n\n";
    size_t size, len = strlen(full);
    unsigned char *data = pattern_bytes(ISO_I16, 1, &size);
    char path[512];
    iso_volume *vol = NULL;
    iso_error err;
    tmp_path(path, sizeof path, "prefix.nrrd");
    for (size_t cut = 0; cut < len; cut++) {
        write_file(path, full, cut, NULL, 0);
        CHECKF(iso_load(path, NULL, &vol, &err) != ISO_OK, "prefix of %zu bytes loaded", cut);
        CHECK(vol == NULL);
        iso_vol_destroy(vol);
    }
    write_file(path, full, len, data, size);
    vol = load_ok(path);
    check_pattern(vol, ISO_I16);
    iso_vol_destroy(vol);
    free(data);
}

/* ---- fields ---- */

static iso_volume *field_ok(const char *spec, iso_voxel_type type, size_t w, size_t h, size_t d)
{
    iso_volume *vol = load_ok(spec);
    if (!vol)
        return NULL;
    CHECK_EQ(vol->type, type);
    CHECKF(vol->dims[0] == w && vol->dims[1] == h && vol->dims[2] == d,
           "%s: dims %zux%zux%zu", spec, vol->dims[0], vol->dims[1], vol->dims[2]);
    return vol;
}

static void test_field_sphere(void)
{
    iso_volume *vol = field_ok("field:sphere:65", ISO_F32, 65, 65, 65);
    if (vol) {
        CHECK(iso_vol_get(vol, 32, 32, 32) == 32); /* R at the centre */
        CHECK(iso_vol_get(vol, 32, 32, 0) == 0);   /* on the sphere of radius R */
        CHECK(iso_vol_get(vol, 35, 36, 32) == 27); /* distance 5 from the centre */
        CHECK_NEAR(iso_vol_get(vol, 0, 0, 0), 32 - sqrt(3) * 32, 1e-5);
        CHECK(vol->value_max == 32);
    }
    iso_vol_destroy(vol);
    vol = field_ok("field:sphere", ISO_F32, 64, 64, 64);
    if (vol)
        CHECK_NEAR(iso_vol_get(vol, 31, 31, 31), 31.5 - sqrt(0.75), 1e-5);
    iso_vol_destroy(vol);
    /* Not cubic: R from the shortest axis, centre per axis. */
    vol = field_ok("field:sphere:9x11x13", ISO_F32, 9, 11, 13);
    if (vol) {
        CHECK(iso_vol_get(vol, 4, 5, 6) == 4);
        CHECK(iso_vol_get(vol, 4, 5, 2) == 0);
    }
    iso_vol_destroy(vol);
}

static void test_field_torus(void)
{
    iso_volume *vol = field_ok("field:torus:33", ISO_F32, 33, 33, 33);
    if (vol) {
        /* c = 16, R = 16: ring radius 8, tube radius 4. */
        CHECK(iso_vol_get(vol, 24, 16, 16) == 4);
        CHECK(iso_vol_get(vol, 16, 8, 16) == 4);
        CHECK(iso_vol_get(vol, 28, 16, 16) == 0);
        CHECK(iso_vol_get(vol, 24, 16, 20) == 0);
        CHECK(iso_vol_get(vol, 16, 16, 16) == -4);
    }
    iso_vol_destroy(vol);
}

static void test_field_ml(void)
{
    iso_volume *vol = field_ok("field:ml:33", ISO_F32, 33, 33, 33);
    if (vol) {
        CHECK(vol->value_min >= 0 && vol->value_max <= 1);
        CHECK(vol->value_min < 0.05 && vol->value_max > 0.95);
        /* Centre: x = y = z = 0, rho = cos(12 pi) = 1, f = (1 + 0.5) / 2.5. */
        CHECK_NEAR(iso_vol_get(vol, 16, 16, 16), 0.6, 1e-6);
        /* Bottom corner column x = y = 0, z = -1: (2 + 0.5) / 2.5 = 1. */
        CHECK_NEAR(iso_vol_get(vol, 16, 16, 0), 1, 1e-6);
        CHECK(!vol->has_nan);
    }
    iso_vol_destroy(vol);
}

/* Elber and Malzbender's D1, D2 and D3. */
static void test_field_paper_sets(void)
{
    iso_volume *vol = field_ok("field:constant:8", ISO_U8, 8, 8, 8);
    if (vol) {
        for (size_t n = 0; n < iso_vol_count(vol); n++)
            if (((const uint8_t *)vol->data)[n] != 1) {
                CHECKF(0, "D1 sample %zu is not 1", n);
                break;
            }
        CHECK(vol->value_min == 1 && vol->value_max == 1 && vol->value_mean == 1);
    }
    iso_vol_destroy(vol);

    vol = field_ok("field:spike:4x5x6", ISO_F32, 4, 5, 6);
    if (vol) {
        CHECK(iso_vol_get(vol, 0, 0, 0) == 0);
        CHECK(iso_vol_get(vol, 1, 0, 0) == 1 && iso_vol_get(vol, 0, 0, 1) == 1);
        CHECK(iso_vol_get(vol, 3, 4, 5) == 1);
        CHECK(vol->value_min == 0 && vol->value_max == 1);
        CHECK_NEAR(vol->value_mean, 119.0 / 120, 1e-12);
    }
    iso_vol_destroy(vol);

    vol = field_ok("field:ijk:5x6x7", ISO_F32, 5, 6, 7);
    if (vol) {
        for (size_t k = 0; k < 7; k++)
            for (size_t j = 0; j < 6; j++)
                for (size_t i = 0; i < 5; i++)
                    CHECK(iso_vol_get(vol, i, j, k) == (double)(i * j * k));
        CHECK(vol->value_max == 4 * 5 * 6);
    }
    iso_vol_destroy(vol);
}

static void test_field_errors(void)
{
    expect_error("field:cube", 0, ISO_E_ARGUMENT, "sphere, torus, ml, constant, spike, ijk");
    expect_error("field:", 0, ISO_E_ARGUMENT, "known");
    expect_error("field:averyveryveryverylongnamethatisnotafieldatall", 0, ISO_E_ARGUMENT,
                 "sphere");
    expect_error("field:sphere:1", 0, ISO_E_ARGUMENT, "2..4096");
    expect_error("field:sphere:4097", 0, ISO_E_ARGUMENT, "bad size");
    expect_error("field:sphere:3x3", 0, ISO_E_ARGUMENT, "bad size");
    expect_error("field:sphere:3x3x3x3", 0, ISO_E_ARGUMENT, "bad size");
    expect_error("field:sphere:abc", 0, ISO_E_ARGUMENT, "bad size");
    expect_error("field:sphere:", 0, ISO_E_ARGUMENT, "bad size");
    expect_error("field:sphere:99999999999999999999999", 0, ISO_E_ARGUMENT, "bad size");
    expect_error("field:sphere:-8", 0, ISO_E_ARGUMENT, "bad size");
    expect_error("field:sphere:4096", 0, ISO_E_LIMIT, "field:sphere:4096");
    expect_error("field:sphere:16", 1000, ISO_E_LIMIT, "1000");
    iso_volume *vol = NULL;
    CHECK_EQ(iso_field_create("nope", (const size_t[3]){4, 4, 4}, 0, &vol, NULL), ISO_E_ARGUMENT);
    CHECK(vol == NULL);
}

/* ---- the loader table ---- */

static void test_recognises(void)
{
    CHECK(iso_load_recognises("a/b/head.nhdr"));
    CHECK(iso_load_recognises("head.nrrd"));
    CHECK(iso_load_recognises("HEAD.NRRD"));
    CHECK(iso_load_recognises("field:sphere"));
    CHECK(iso_load_recognises("field:whatever:12"));
    CHECK(!iso_load_recognises("head.raw"));
    CHECK(!iso_load_recognises("head.raw.gz"));
    CHECK(!iso_load_recognises("head.nrrd.bak"));
    CHECK(!iso_load_recognises(".nrrd"));
    CHECK(!iso_load_recognises(""));
    CHECK(!iso_load_recognises("fields/x.txt"));
}

/* ---- sha256 ---- */

static void hash_hex(const void *data, size_t size, char hex[65])
{
    sha256_ctx ctx;
    unsigned char digest[32];
    sha256_init(&ctx);
    sha256_update(&ctx, data, size);
    sha256_final(&ctx, digest);
    sha256_hex(digest, hex);
}

static void test_sha256(void)
{
    char hex[65];
    hash_hex("", 0, hex);
    CHECK(strcmp(hex, "e3b0c44298fc1c149afbf4c8996fb92427ae41e4649b934ca495991b7852b855") == 0);
    hash_hex("abc", 3, hex);
    CHECK(strcmp(hex, "ba7816bf8f01cfea414140de5dae2223b00361a396177a9cb410ff61f20015ad") == 0);
    const char *two_blocks = "abcdbcdecdefdefgefghfghighijhijkijkljklmklmnlmnomnopnopq";
    hash_hex(two_blocks, strlen(two_blocks), hex);
    CHECK(strcmp(hex, "248d6a61d20638b8e5c026930c3e6039a33ce45964ff2167f6ecedd419db06c1") == 0);
    /* A million 'a's fed in uneven pieces crosses every block boundary case. */
    {
        static char a[1024];
        sha256_ctx ctx;
        unsigned char digest[32];
        size_t fed = 0, piece = 1;
        memset(a, 'a', sizeof a);
        sha256_init(&ctx);
        while (fed < 1000000) {
            size_t n = piece < 1000000 - fed ? piece : 1000000 - fed;
            sha256_update(&ctx, a, n);
            fed += n;
            piece = piece % 997 + 7;
        }
        sha256_final(&ctx, digest);
        sha256_hex(digest, hex);
        CHECK(strcmp(hex, "cdc76e5c9914fb9281a1c7e284d73e67f1809a48a497200e046d39ccc7112cd0") == 0);
    }
}

/* ---- the shared real volumes ---- */

typedef struct manifest_row {
    char name[128], dtype[8];
    size_t dims[3];
    double spacing[3], min, max, mean;
    uint64_t raw_bytes;
    char sha16[17];
} manifest_row;

static int parse_row(char *line, manifest_row *row)
{
    char dims[64], spacing[64];
    if (sscanf(line, "%127s %63s %7s %63s %" SCNu64 " %*s %lf %lf %lf %16s", row->name, dims,
               row->dtype, spacing, &row->raw_bytes, &row->min, &row->max, &row->mean,
               row->sha16) != 9)
        return -1;
    if (sscanf(dims, "%zux%zux%zu", &row->dims[0], &row->dims[1], &row->dims[2]) != 3)
        return -1;
    if (sscanf(spacing, "%lfx%lfx%lf", &row->spacing[0], &row->spacing[1], &row->spacing[2]) != 3)
        return -1;
    return 0;
}

/* numpy's "<u2", ">i2", "|u1", "<f4" to our type and the file's byte order. */
static int parse_dtype(const char *dtype, iso_voxel_type *type, int *big)
{
    static const struct {
        const char *code;
        iso_voxel_type type;
    } codes[] = {{"u1", ISO_U8}, {"i1", ISO_I8}, {"u2", ISO_U16}, {"i2", ISO_I16},
                 {"u4", ISO_U32}, {"i4", ISO_I32}, {"f4", ISO_F32}, {"f8", ISO_F64}};
    *big = dtype[0] == '>';
    for (size_t c = 0; c < sizeof codes / sizeof codes[0]; c++)
        if (strcmp(dtype + 1, codes[c].code) == 0) {
            *type = codes[c].type;
            return 0;
        }
    return -1;
}

/* sha256 of the samples written back in the file's byte order, as the manifest hashed
 * the raw on-disk bytes. */
static void samples_sha(const iso_volume *vol, int big_endian, char hex[65])
{
    static unsigned char chunk[1 << 16];
    size_t size = iso_vol_type_size(vol->type);
    size_t total = iso_vol_count(vol) * size, per = sizeof chunk / size * size;
    const unsigned char *p = vol->data;
    sha256_ctx ctx;
    unsigned char digest[32];
    sha256_init(&ctx);
    for (size_t at = 0; at < total; at += per) {
        size_t n = total - at < per ? total - at : per;
        memcpy(chunk, p + at, n);
        if (size > 1 && big_endian != host_big_endian())
            for (size_t s = 0; s < n; s += size)
                reverse(chunk + s, size);
        sha256_update(&ctx, chunk, n);
    }
    sha256_final(&ctx, digest);
    sha256_hex(digest, hex);
}

/* Padding in the shared scans: the bunny's -2000 and the quarter head's 0 outside their scan
 * circles, and the 255 that fills whole columns of the avg152T1 copy; nothing in the
 * others (skull-stripped brains' 0 and CT air included). The bunny's first suggested level
 * drew its circle (below air); without the padding the levels fall between air (~30) and
 * the ceramic (~2330), where the bunny is. */
static void check_shared_padding(const iso_volume *vol, const char *name)
{
    static const struct { const char *prefix; double value; } padded[] = {
        {"bunny", -2000}, {"headsq", 0}, {"avg152T1", 255}};
    uint64_t counts[256];
    iso_hist_compute(vol, 256, counts);
    double padding = 0, want = NAN, with[2], without[2];
    for (size_t p = 0; p < sizeof padded / sizeof *padded; p++)
        if (!strncmp(name, padded[p].prefix, strlen(padded[p].prefix)))
            want = padded[p].value;
    int found = iso_vol_find_padding(vol, counts, 256, &padding);
    CHECKF(found == !isnan(want) && (!found || padding == want), "%s: padding found %d (%g)", name, found, padding);
    int bunny = strncmp(name, "bunny", 5) == 0;
    if (!bunny)
        return;
    CHECK_EQ(iso_hist_suggest_levels(counts, 256, vol->value_min, vol->value_max, with, 2), 2);
    iso_hist_drop_padding(counts, 256, vol->value_min, vol->value_max, padding);
    CHECK_EQ(iso_hist_suggest_levels(counts, 256, vol->value_min, vol->value_max, without, 2), 2);
    CHECKF(with[0] < -1000 && without[0] > 100 && without[1] < 2300 && without[0] < without[1],
           "bunny: levels %g %g with the padding, %g %g without", with[0], with[1], without[0], without[1]);
}

static void test_shared_manifest(void)
{
    const char *dir = check_shared_volumes();
    char path[1024], line[1024];
    int rows = 0;
    FILE *f;
    if (!dir) {
        check_skip("no shared volumes (set ISO_SHARED_VOLUMES or put them in ../shared/volumes)");
        return;
    }
    snprintf(path, sizeof path, "%s/MANIFEST.tsv", dir);
    f = fopen(path, "r");
    CHECKF(f != NULL, "cannot open %s", path);
    if (!f)
        return;
    CHECK(fgets(line, sizeof line, f) != NULL); /* column names */
    while (fgets(line, sizeof line, f)) {
        manifest_row row;
        iso_voxel_type type;
        int big;
        char hex[65];
        if (parse_row(line, &row) != 0 || parse_dtype(row.dtype, &type, &big) != 0) {
            CHECKF(0, "bad manifest line: %s", line);
            continue;
        }
        rows++;
        snprintf(path, sizeof path, "%s/%s.nhdr", dir, row.name);
        CHECK(iso_load_recognises(path));
        iso_volume *vol = load_ok(path);
        if (!vol)
            continue;
        CHECKF(vol->type == type, "%s: type %s", row.name, iso_vol_type_name(vol->type));
        for (int d = 0; d < 3; d++) {
            CHECKF(vol->dims[d] == row.dims[d], "%s: dim %d is %zu", row.name, d, vol->dims[d]);
            CHECK_NEAR(vol->spacing[d], row.spacing[d], 1e-6 * row.spacing[d]);
        }
        CHECK_EQ(iso_vol_count(vol) * iso_vol_type_size(vol->type), row.raw_bytes);
        CHECKF(fabs(vol->value_min - row.min) <= 5e-4 && fabs(vol->value_max - row.max) <= 5e-4,
               "%s: range %g..%g, manifest %g..%g", row.name, vol->value_min, vol->value_max,
               row.min, row.max);
        CHECKF(fabs(vol->value_mean - row.mean) <= 5e-4 + 1e-9, "%s: mean %.6f, manifest %.3f",
               row.name, vol->value_mean, row.mean);
        CHECK(!vol->has_nan);
        samples_sha(vol, big, hex);
        CHECKF(strncmp(hex, row.sha16, 16) == 0, "%s: sha256 %.16s, manifest %s", row.name, hex,
               row.sha16);
        check_shared_padding(vol, row.name);
        iso_vol_destroy(vol);
    }
    fclose(f);
    CHECKF(rows >= 12, "only %d manifest rows", rows);
}

int main(void)
{
    CHECK_RUN(test_type_names);
    CHECK_RUN(test_create_get_set);
    CHECK_RUN(test_set_converts);
    CHECK_RUN(test_read_box);
    CHECK_RUN(test_check_size);
    CHECK_RUN(test_stats);
    CHECK_RUN(test_stats_large);
    CHECK_RUN(test_index_to_world);
    CHECK_RUN(test_set_axes);
    CHECK_RUN(test_find_padding);
    CHECK_RUN(test_nrrd_attached_raw);
    CHECK_RUN(test_nrrd_attached_gzip);
    CHECK_RUN(test_nrrd_detached);
    CHECK_RUN(test_nrrd_endian);
    CHECK_RUN(test_nrrd_geometry);
    CHECK_RUN(test_nrrd_type_spellings);
    CHECK_RUN(test_nrrd_bad_headers);
    CHECK_RUN(test_nrrd_bad_data);
    CHECK_RUN(test_nrrd_long_line);
    CHECK_RUN(test_nrrd_garbage);
    CHECK_RUN(test_nrrd_every_prefix);
    CHECK_RUN(test_field_sphere);
    CHECK_RUN(test_field_torus);
    CHECK_RUN(test_field_ml);
    CHECK_RUN(test_field_paper_sets);
    CHECK_RUN(test_field_errors);
    CHECK_RUN(test_recognises);
    CHECK_RUN(test_sha256);
    CHECK_RUN(test_shared_manifest);
    return check_finish();
}
