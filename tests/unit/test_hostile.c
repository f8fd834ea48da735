/* test_hostile.c: hostile volume and hierarchy files, each refused with the exact
 * message a user sees: headers that lie about their sizes, sizes whose product overflows,
 * a header claiming 10^12 voxels (refused under the memory limit before anything is
 * allocated or read), truncated gzip and zlib streams, truncated and corrupt hierarchy
 * files; and NaN samples in float volumes, which load and extract with the documented
 * behaviour (docs/security.md). The other refusals of each loader (test_volume.c,
 * test_formats.c) match words; these match the whole message. */
#include <math.h>
#include <nifti1.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <zlib.h>

#include "check.h"
#include "extract/extract.h"
#include "io/io.h"
#include "hierarchy/tree.h"
#include "volume/volume.h"

/* ---- files ---- */

static const char *temp_path(const char *name)
{
    static char path[8][512];
    static int next;
    char *p = path[next++ % 8];
    snprintf(p, sizeof path[0], "%s/%s", check_temp_dir(), name);
    return p;
}

/* Loads path with the given limit (0: the default) and checks code and whole message. The
 * expected message is a format with one %s, the file's path. */
static void expect_exact(const char *path, uint64_t max_bytes, int code, const char *format)
{
    iso_error err = {0};
    iso_volume *vol = NULL;
    iso_load_options opt = {.max_bytes = max_bytes};
    int rc = iso_load(path, &opt, &vol, &err);
    char want[1200];
    snprintf(want, sizeof want, format, path);
    CHECKF(rc == code && vol == NULL, "%s: rc %d, want %d (%s)", path, rc, code, err.message);
    CHECKF(!strcmp(err.message, want), "message\n  got  \"%s\"\n  want \"%s\"", err.message, want);
    iso_vol_destroy(vol);
}

static void expect_file(const char *name, const char *header, const void *data, size_t size,
                        uint64_t max_bytes, int code, const char *format)
{
    const char *path = temp_path(name);
    check_write_file(path, header, strlen(header), data, size);
    expect_exact(path, max_bytes, code, format);
}

/* ---- NRRD ---- */

static void test_nrrd_huge_header_refused_unread(void)
{
    /* 10^12 one-byte voxels and no data at all: the limit refuses it before the (absent)
     * samples are looked for, so the message is about the limit, not about truncation. */
    const char *h = "NRRD0004\ntype: uchar\ndimension: 3\nsizes: 10000 10000 10000\nencoding: raw\n\n";
    expect_file("tera.nrrd", h, NULL, 0, 0, ISO_E_LIMIT,
                "%s: 10000x10000x10000 u8 samples (1000000000000 bytes) exceed the limit of "
                "8589934592 bytes");
    /* The limit is the caller's (serve --max-volume-mb): 64 MiB refuses 512^3 bytes. */
    const char *m = "NRRD0004\ntype: uchar\ndimension: 3\nsizes: 512 512 512\nencoding: raw\n\n";
    expect_file("limit.nrrd", m, NULL, 0, (uint64_t)64 << 20, ISO_E_LIMIT,
                "%s: 512x512x512 u8 samples (134217728 bytes) exceed the limit of 67108864 bytes");
}

static void test_nrrd_overflow_and_lies(void)
{
    expect_file("overflow.nrrd",
                "NRRD0004\ntype: float\ndimension: 3\nsizes: 4294967296 4294967296 4294967296\n"
                "endian: little\nencoding: raw\n\n", NULL, 0, 0, ISO_E_LIMIT,
                "%s:4: field 'sizes': 4294967296x4294967296x4294967296 samples of type f32 "
                "overflow 64 bits");
    static const unsigned char ten[10] = {1, 2, 3, 4, 5, 6, 7, 8, 9, 10};
    expect_file("lying.nrrd", "NRRD0004\ntype: uchar\ndimension: 3\nsizes: 4 4 4\nencoding: raw\n\n",
                ten, sizeof ten, 0, ISO_E_TRUNCATED,
                "%s: truncated raw data: expected 64 bytes of samples, found 10");
    /* A detached header whose data file is shorter than the header says. */
    check_write_file(temp_path("short.raw"), ten, sizeof ten, NULL, 0);
    char want[1200];
    snprintf(want, sizeof want, "%s (data file of %%s): truncated raw data: expected 8000 bytes "
             "of samples, found 10", temp_path("short.raw"));
    expect_file("short.nhdr", "NRRD0004\ntype: uchar\ndimension: 3\nsizes: 20 20 20\nencoding: raw\n"
                "data file: short.raw\n", NULL, 0, 0, ISO_E_TRUNCATED, want);
}

/* A byte skip past the end of the data is said as such, not as a failed seek. */
static void test_nrrd_byte_skip_past_end(void)
{
    static const unsigned char ten[10] = {1, 2, 3, 4, 5, 6, 7, 8, 9, 10};
    check_write_file(temp_path("skipped.raw"), ten, sizeof ten, NULL, 0);
    char want[1200];
    snprintf(want, sizeof want, "%s (data file of %%s): byte skip 9223372036854775807 is past the end of the "
             "file (10 bytes, data from byte 0)", temp_path("skipped.raw"));
    expect_file("huge_skip.nhdr", "NRRD0004\ntype: uchar\ndimension: 3\nsizes: 2 2 2\nencoding: raw\n"
                "byte skip: 9223372036854775807\ndata file: skipped.raw\n", NULL, 0, 0, ISO_E_TRUNCATED, want);
    snprintf(want, sizeof want, "%s (data file of %%s): byte skip 11 is past the end of the file (10 bytes, "
             "data from byte 0)", temp_path("skipped.raw"));
    expect_file("past_skip.nhdr", "NRRD0004\ntype: uchar\ndimension: 3\nsizes: 2 2 2\nencoding: raw\n"
                "byte skip: 11\ndata file: skipped.raw\n", NULL, 0, 0, ISO_E_TRUNCATED, want);
    /* Two bytes skipped leave eight: exactly the 2x2x2 samples, which load. */
    iso_volume *vol = NULL;
    iso_error err;
    const char *fits = "NRRD0004\ntype: uchar\ndimension: 3\nsizes: 2 2 2\nencoding: raw\nbyte skip: 2\n"
                       "data file: skipped.raw\n";
    check_write_file(temp_path("fits.nhdr"), fits, strlen(fits), NULL, 0);
    CHECK_OK(iso_load(temp_path("fits.nhdr"), NULL, &vol, &err), &err);
    CHECK(vol && ((const unsigned char *)vol->data)[0] == 3 && ((const unsigned char *)vol->data)[7] == 10);
    iso_vol_destroy(vol);
}

static void test_nrrd_truncated_gzip(void)
{
    unsigned char samples[4096];
    for (size_t i = 0; i < sizeof samples; i++)
        samples[i] = (unsigned char)(i * 7);
    size_t zsize;
    unsigned char *z = check_deflate(samples, sizeof samples, 15 + 16, 0, &zsize);
    const char *h = "NRRD0004\ntype: uchar\ndimension: 3\nsizes: 16 16 16\nencoding: gzip\n\n";
    /* The gzip header alone (10 bytes), then the header, one stored block's 5-byte header
     * and 1000 of its bytes: level 0 stores, so exactly 1000 samples come out. */
    expect_file("gzhead.nrrd", h, z, 10, 0, ISO_E_TRUNCATED,
                "%s: truncated gzip data: expected 4096 bytes of samples, found 0");
    expect_file("gzcut.nrrd", h, z, 10 + 5 + 1000, 0, ISO_E_TRUNCATED,
                "%s: truncated gzip data: expected 4096 bytes of samples, found 1000");
    free(z);
}

/* ---- NIfTI ---- */

/* A NIfTI-1 single file of float32 or uint8 samples: 348-byte header, 4 bytes of
 * extension flag, samples at 352. */
static void write_nifti(const char *path, const int dims[3], int datatype, const void *data,
                        size_t size, int gz)
{
    nifti_1_header h;
    memset(&h, 0, sizeof h);
    h.sizeof_hdr = 348;
    h.dim[0] = 3;
    for (int a = 0; a < 3; a++) {
        h.dim[a + 1] = (short)dims[a];
        h.pixdim[a + 1] = 1;
    }
    h.datatype = (short)datatype;
    h.bitpix = datatype == DT_FLOAT32 ? 32 : 8;
    h.vox_offset = 352;
    h.qform_code = 1;
    h.quatern_d = 0;
    memcpy(h.magic, "n+1", 4);
    unsigned char *file = calloc(1, 352 + size);
    CHECK(file != NULL);
    if (!file)
        return;
    memcpy(file, &h, sizeof h);
    memcpy(file + 352, data, size);
    if (!gz) {
        check_write_file(path, file, 352 + size, NULL, 0);
    } else {
        size_t zsize;
        unsigned char *z = check_deflate(file, 352 + size, 15 + 16, 6, &zsize);
        check_write_file(path, z, zsize / 2, NULL, 0); /* cut in the middle */
        free(z);
    }
    free(file);
}

static void test_nifti_hostile_exact(void)
{
    float samples[4 * 4 * 4] = {0};
    const int tera[3] = {10000, 10000, 10000}, lying[3] = {40, 40, 40};
    write_nifti(temp_path("tera.nii"), tera, DT_UINT8, samples, sizeof samples, 0);
    expect_exact(temp_path("tera.nii"), 0, ISO_E_LIMIT,
                 "%s: volume of 10000x10000x10000 u8 samples exceeds the limit of 8589934592 bytes");
    write_nifti(temp_path("lying.nii"), lying, DT_FLOAT32, samples, sizeof samples, 0);
    expect_exact(temp_path("lying.nii"), 0, ISO_E_TRUNCATED,
                 "%s: the samples cannot be read (file shorter than its header says?)");
    float more[32 * 32 * 32];
    for (size_t i = 0; i < sizeof more / sizeof more[0]; i++)
        more[i] = (float)i;
    const int cube[3] = {32, 32, 32};
    write_nifti(temp_path("cut.nii.gz"), cube, DT_FLOAT32, more, sizeof more, 1);
    expect_exact(temp_path("cut.nii.gz"), 0, ISO_E_TRUNCATED,
                 "%s: the samples cannot be read (file shorter than its header says?)");
}

/* ---- MetaImage ---- */

static void test_metaimage_hostile_exact(void)
{
    expect_file("tera.mhd", "NDims = 3\nDimSize = 10000 10000 10000\nElementType = MET_UCHAR\n"
                "ElementDataFile = LOCAL\n", NULL, 0, 0, ISO_E_LIMIT,
                "%s: 10000x10000x10000 u8 samples (1000000000000 bytes) exceed the limit of "
                "8589934592 bytes");
    expect_file("overflow.mhd", "NDims = 3\nDimSize = 1000000000 1000000000 1000000000\n"
                "ElementType = MET_DOUBLE\nElementDataFile = LOCAL\n", NULL, 0, 0, ISO_E_LIMIT,
                "%s: DimSize overflows 64 bits");
    static const unsigned char ten[10] = {0};
    expect_file("lying.mhd", "NDims = 3\nDimSize = 4 4 4\nElementType = MET_UCHAR\n"
                "ElementDataFile = LOCAL\n", ten, sizeof ten, 0, ISO_E_TRUNCATED,
                "%s: truncated raw data: expected 64 bytes of samples, found 10");
    unsigned char samples[4096] = {0};
    size_t zsize;
    unsigned char *z = check_deflate(samples, sizeof samples, 15, 0, &zsize);
    /* A zlib stream (2-byte header), one stored block's header and 100 bytes of it. */
    expect_file("cut.mha", "NDims = 3\nDimSize = 16 16 16\nElementType = MET_UCHAR\n"
                "CompressedData = True\nElementDataFile = LOCAL\n", z, 2 + 5 + 100, 0,
                ISO_E_TRUNCATED, "%s: truncated gzip data: expected 4096 bytes of samples, found 100");
    free(z);
}

/* ---- NaN samples ---- */

/* A float NRRD whose every sample inside a sphere is 10, outside 0, with a slab of NaN:
 * it loads, its statistics ignore the NaN, and extraction treats NaN as below every level
 * (extract.h): the surface stays finite, closes around the NaN slab's side, and its error
 * bound stays finite. */
static void test_nan_samples_defined(void)
{
    enum { N = 24 };
    float *v = malloc(sizeof(float) * N * N * N);
    CHECK(v != NULL);
    if (!v)
        return;
    for (int k = 0; k < N; k++)
        for (int j = 0; j < N; j++)
            for (int i = 0; i < N; i++) {
                double r = sqrt((i - 11.5) * (i - 11.5) + (j - 11.5) * (j - 11.5) + (k - 11.5) * (k - 11.5));
                v[(k * N + j) * N + i] = k >= 10 && k < 13 ? NAN : r < 8 ? 10.0f : 0.0f;
            }
    const char *path = temp_path("nan.nrrd");
    const char *h = "NRRD0004\ntype: float\ndimension: 3\nsizes: 24 24 24\nendian: little\nencoding: raw\n\n";
    check_write_file(path, h, strlen(h), v, sizeof(float) * N * N * N);
    free(v);
    iso_error err = {0};
    iso_volume *vol = NULL;
    CHECK_OK(iso_load(path, NULL, &vol, &err), &err);
    if (!vol)
        return;
    CHECK(vol->has_nan == 1 && vol->value_min == 0 && vol->value_max == 10);
    iso_tree *tree = NULL;
    CHECK_OK(iso_tree_build(vol, 0, NULL, NULL, &tree, &err), &err);
    for (int tol = 0; tree && tol <= 2; tol += 2) {
        iso_extract_params p = {.level = 5, .tolerance = tol, .space = ISO_SPACE_INDEX,
                                .coarsen = ISO_COARSEN_ALL};
        iso_mesh mesh;
        iso_mesh_init(&mesh);
        iso_extract_stats stats = {0};
        CHECK_OK(iso_extract(tree, &p, &mesh, &stats, &err), &err);
        CHECKF(stats.triangles > 500, "tolerance %d: %zu triangles", tol, (size_t)stats.triangles);
        int finite = 1;
        for (size_t i = 0; i < 3 * mesh.vertex_count; i++)
            finite &= isfinite(mesh.positions[i]) != 0;
        CHECKF(finite, "tolerance %d: a vertex is not finite", tol);
        CHECKF(isfinite(stats.error_bound) && stats.error_bound <= tol + 1e-9,
               "tolerance %d: error bound %g", tol, stats.error_bound);
        iso_mesh_free(&mesh);
    }
    iso_tree_destroy(tree);
    iso_vol_destroy(vol);
}

/* ---- hierarchy files ---- */

static long file_size(const char *path)
{
    FILE *f = fopen(path, "rb");
    long n = -1;
    if (f && fseek(f, 0, SEEK_END) == 0)
        n = ftell(f);
    if (f)
        fclose(f);
    return n;
}

static void expect_tree(const iso_volume *vol, const char *path, int code, const char *format)
{
    iso_error err = {0};
    iso_tree *tree = NULL;
    int rc = iso_tree_load(vol, path, &tree, &err);
    char want[1200];
    snprintf(want, sizeof want, format, path);
    CHECKF(rc == code && tree == NULL, "%s: rc %d, want %d (%s)", path, rc, code, err.message);
    CHECKF(!strcmp(err.message, want), "message\n  got  \"%s\"\n  want \"%s\"", err.message, want);
    iso_tree_destroy(tree);
}

/* The whole of path (its size in *n), or NULL after a CHECK failure; the caller frees it. */
static unsigned char *read_all(const char *path, long *n)
{
    *n = file_size(path);
    unsigned char *bytes = *n > 0 ? malloc((size_t)*n) : NULL;
    FILE *f = fopen(path, "rb");
    int ok = bytes && f && fread(bytes, 1, (size_t)*n, f) == (size_t)*n;
    CHECK(ok);
    if (f)
        fclose(f);
    if (!ok) {
        free(bytes);
        return NULL;
    }
    return bytes;
}

/* Copies src to dst keeping `keep` bytes (all if < 0), with byte `flip` (if >= 0) inverted. */
static void damaged_copy(const char *src, const char *dst, long keep, long flip)
{
    long n;
    unsigned char *bytes = read_all(src, &n);
    if (!bytes)
        return;
    if (flip >= 0)
        bytes[flip] ^= 0xff;
    check_write_file(dst, bytes, keep < 0 ? (size_t)n : (size_t)keep, NULL, 0);
    free(bytes);
}

static void test_tree_file_damage_exact(void)
{
    iso_error err = {0};
    iso_volume *vol = NULL;
    CHECK_OK(iso_load("field:ml:40", NULL, &vol, &err), &err);
    iso_tree *tree = NULL;
    if (vol)
        CHECK_OK(iso_tree_build(vol, 0, NULL, NULL, &tree, &err), &err);
    if (!tree) {
        iso_vol_destroy(vol);
        return;
    }
    const char *good = temp_path("ml.isotree");
    CHECK_OK(iso_tree_save(tree, good, &err), &err);
    long size = file_size(good);
    size_t bricks = iso_bricks_total(&tree->bricks);
    long levels = ISO_TREE_CODES * (long)bricks; /* one-byte level codes per brick and block */
    CHECK_EQ(size, 64 + 12 * (long)tree->node_count + levels); /* nodes, then level errors */
    char format[256];
    const char *bad = temp_path("bad.isotree");

    damaged_copy(good, bad, size - 16, -1); /* the last 16 level codes missing */
    snprintf(format, sizeof format,
             "%%s: %ld bytes do not hold the %zu nodes the header announces and %zu level errors", size - 16,
             tree->node_count, (size_t)ISO_TREE_CODES * bricks);
    expect_tree(vol, bad, ISO_E_CORRUPT, format);
    damaged_copy(good, bad, size - levels - 3, -1); /* cut mid-node, no level errors */
    snprintf(format, sizeof format,
             "%%s: %ld bytes do not hold the %zu nodes the header announces and %zu level errors",
             size - levels - 3, tree->node_count, (size_t)ISO_TREE_CODES * bricks);
    expect_tree(vol, bad, ISO_E_CORRUPT, format);
    damaged_copy(good, bad, 40, -1);
    expect_tree(vol, bad, ISO_E_FORMAT, "%s: 40 bytes, shorter than the 64-byte header");
    damaged_copy(good, bad, 0, -1);
    expect_tree(vol, bad, ISO_E_FORMAT, "%s: 0 bytes, shorter than the 64-byte header");
    damaged_copy(good, bad, -1, size - 5); /* a byte of a level error: the checksum covers them */
    expect_tree(vol, bad, ISO_E_CORRUPT, "%s: node checksum mismatch");
    damaged_copy(good, bad, -1, 64 + 5); /* a byte of the first node */
    expect_tree(vol, bad, ISO_E_CORRUPT, "%s: node checksum mismatch");
    damaged_copy(good, bad, -1, 16); /* dims[0] in the header */
    expect_tree(vol, bad, ISO_E_CORRUPT, "%s: header checksum mismatch");
    damaged_copy(good, bad, -1, 0);
    expect_tree(vol, bad, ISO_E_FORMAT, "%s: not a hierarchy file (bad magic)");
    /* The good file still loads: the refusals were the damage's. */
    iso_tree *back = NULL;
    CHECK_OK(iso_tree_load(vol, good, &back, &err), &err);
    iso_tree_destroy(back);
    iso_tree_destroy(tree);
    iso_vol_destroy(vol);
}

int main(void)
{
    CHECK_RUN(test_nrrd_huge_header_refused_unread);
    CHECK_RUN(test_nrrd_overflow_and_lies);
    CHECK_RUN(test_nrrd_byte_skip_past_end);
    CHECK_RUN(test_nrrd_truncated_gzip);
    CHECK_RUN(test_nifti_hostile_exact);
    CHECK_RUN(test_metaimage_hostile_exact);
    CHECK_RUN(test_nan_samples_defined);
    CHECK_RUN(test_tree_file_damage_exact);
    return check_finish();
}
