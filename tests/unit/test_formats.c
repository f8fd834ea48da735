/* test_formats.c: volume formats read through the loader table: NIfTI-1 from Debian's
 * mricron-data (facts read independently from the header bytes), NIfTI files written
 * here by hand (rescaling, a sheared sform, RAS to LPS, a vertex landing where the sform
 * says), the shared scans against their NRRD twins, and hostile files refused by name. */
#include <math.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <zlib.h>

#include "check.h"
#include "extract/extract.h"
#include "io/io.h"
#include "hierarchy/tree.h"

#define MRICRON "/usr/share/mricron/templates/"

/* ---- NIfTI-1 single files written by hand (348-byte header, 4 bytes of extension flag) */

typedef struct nifti_spec {
    short dim[8];
    short datatype, bitpix;
    float pixdim[8];
    float slope, inter;
    short qform_code, sform_code;
    float srow[3][4];
} nifti_spec;

static void put16(unsigned char *h, int at, short v) { memcpy(h + at, &v, 2); }
static void put32f(unsigned char *h, int at, float v) { memcpy(h + at, &v, 4); }

/* Writes header + data_bytes of data; returns the path (static buffer per call site). */
static void write_nifti(const char *path, const nifti_spec *s, const void *data, size_t data_bytes)
{
    unsigned char h[352] = {0};
    int32_t size = 348;
    memcpy(h, &size, 4);
    for (int i = 0; i < 8; i++)
        put16(h, 40 + 2 * i, s->dim[i]);
    put16(h, 70, s->datatype);
    put16(h, 72, s->bitpix);
    for (int i = 0; i < 8; i++)
        put32f(h, 76 + 4 * i, s->pixdim[i]);
    put32f(h, 108, 352);
    put32f(h, 112, s->slope);
    put32f(h, 116, s->inter);
    put16(h, 252, s->qform_code);
    put16(h, 254, s->sform_code);
    for (int r = 0; r < 3; r++)
        for (int c = 0; c < 4; c++)
            put32f(h, 280 + 16 * r + 4 * c, s->srow[r][c]);
    memcpy(h + 344, "n+1", 4);
    FILE *f = fopen(path, "wb");
    CHECK(f != NULL);
    if (!f)
        return;
    CHECK(fwrite(h, 1, sizeof h, f) == sizeof h);
    if (data_bytes)
        CHECK(fwrite(data, 1, data_bytes, f) == data_bytes);
    fclose(f);
}

static char *temp_path(const char *name)
{
    static char buf[8][512];
    static int next;
    char *p = buf[next++ % 8];
    snprintf(p, 512, "%s/%s", check_temp_dir(), name);
    return p;
}

/* 6x5x4 int16 samples 10*i, rescaled by 2 and -5: level 25 crosses at i = 1.5. */
static nifti_spec ramp_spec(void)
{
    nifti_spec s = {.dim = {3, 6, 5, 4, 1, 1, 1, 1}, .datatype = 4, .bitpix = 16,
                    .pixdim = {1, 1, 1, 1, 1, 1, 1, 1}, .slope = 2, .inter = -5,
                    .sform_code = 2,
                    .srow = {{1.0f, 0.5f, 0, 10}, {0, 2.0f, 0, -20}, {0.2f, 0, 3.0f, 5}}};
    return s;
}

static void ramp_samples(int16_t *data)
{
    for (int k = 0; k < 4; k++)
        for (int j = 0; j < 5; j++)
            for (int i = 0; i < 6; i++)
                data[(k * 5 + j) * 6 + i] = (int16_t)(10 * i);
}

/* ---- tests */

/* Facts of Debian's ch2bet.nii.gz read from its header bytes with Python: 181x217x181
 * uint8, sform code 4 with srows (1,0,0,-90) (0,1,0,-125) (0,0,1,-71), samples summing to
 * 158526435, p(90,125,71) = 32 and p(100,100,90) = 49. */
static void test_mricron_ch2bet(void)
{
    iso_error err;
    iso_volume *vol = NULL;
    if (!iso_load_recognises(MRICRON "ch2bet.nii.gz")) {
        CHECK(0);
        return;
    }
    CHECK_OK(iso_load(MRICRON "ch2bet.nii.gz", NULL, &vol, &err), &err);
    if (!vol)
        return;
    CHECK(vol->dims[0] == 181 && vol->dims[1] == 217 && vol->dims[2] == 181 && vol->type == ISO_U8);
    uint64_t sum = 0;
    const uint8_t *p = vol->data;
    for (size_t n = 0; n < iso_vol_count(vol); n++)
        sum += p[n];
    CHECK_EQ(sum, 158526435);
    CHECK_EQ(iso_vol_get(vol, 90, 125, 71), 32);
    CHECK_EQ(iso_vol_get(vol, 100, 100, 90), 49);
    CHECK(vol->value_min == 0 && vol->value_max == 133);
    CHECK_EQ(vol->oriented, 1); /* its sform */
    double a[3][4];
    iso_vol_affine(vol, a);
    /* RAS (1,0,0,-90) ... in LPS: x and y rows negated. */
    double want[3][4] = {{-1, 0, 0, 90}, {0, -1, 0, 125}, {0, 0, 1, -71}};
    for (int r = 0; r < 3; r++)
        for (int c = 0; c < 4; c++)
            CHECK_NEAR(a[r][c], want[r][c], 1e-9);
    iso_vol_destroy(vol);
}

/* Rescaled int16 becomes the narrowest type holding slope * v + inter, -5..95: int8; a vertex of the level-25
 * surface maps back through the file's own sform (RAS, converted here by hand) to i = 1.5. */
static void test_nifti_rescale_and_sform_vertex(void)
{
    iso_error err;
    int16_t data[120];
    ramp_samples(data);
    nifti_spec s = ramp_spec();
    const char *path = temp_path("ramp.nii");
    write_nifti(path, &s, data, sizeof data);
    iso_volume *vol = NULL;
    CHECK_OK(iso_load(path, NULL, &vol, &err), &err);
    if (!vol)
        return;
    CHECK(vol->type == ISO_I8);
    CHECK_NEAR(iso_vol_get(vol, 3, 2, 1), 2 * 30 - 5, 0);
    CHECK(vol->value_min == -5 && vol->value_max == 95);
    iso_tree *tree = NULL;
    CHECK_OK(iso_tree_build(vol, 0, NULL, NULL, &tree, &err), &err);
    iso_mesh mesh;
    iso_mesh_init(&mesh);
    iso_extract_params params = {.level = 25};
    CHECK_OK(iso_extract(tree, &params, &mesh, NULL, &err), &err);
    CHECK(mesh.vertex_count == 20); /* the plane i = 1.5 meets 5 x 4 sample rows */
    /* Invert the sform's 3x3 (upper triangular here but solved generally by Cramer). */
    double m[3][3], t[3];
    for (int r = 0; r < 3; r++) {
        for (int c = 0; c < 3; c++)
            m[r][c] = s.srow[r][c];
        t[r] = s.srow[r][3];
    }
    double det = m[0][0] * (m[1][1] * m[2][2] - m[1][2] * m[2][1]) - m[0][1] * (m[1][0] * m[2][2] - m[1][2] * m[2][0]) +
                 m[0][2] * (m[1][0] * m[2][1] - m[1][1] * m[2][0]);
    for (size_t v = 0; v < mesh.vertex_count; v++) {
        const float *w = mesh.positions + 3 * v;
        double ras[3] = {-w[0] - t[0], -w[1] - t[1], w[2] - t[2]}, idx[3];
        for (int c = 0; c < 3; c++) {
            double mc[3][3];
            memcpy(mc, m, sizeof mc);
            for (int r = 0; r < 3; r++)
                mc[r][c] = ras[r];
            idx[c] = (mc[0][0] * (mc[1][1] * mc[2][2] - mc[1][2] * mc[2][1]) -
                      mc[0][1] * (mc[1][0] * mc[2][2] - mc[1][2] * mc[2][0]) +
                      mc[0][2] * (mc[1][0] * mc[2][1] - mc[1][1] * mc[2][0])) / det;
        }
        CHECKF(fabs(idx[0] - 1.5) < 1e-4, "vertex %zu maps to i = %.6f", v, idx[0]);
        CHECKF(fabs(idx[1] - round(idx[1])) < 1e-4 && fabs(idx[2] - round(idx[2])) < 1e-4,
               "vertex %zu maps to j, k = %.6f, %.6f", v, idx[1], idx[2]);
    }
    iso_mesh_free(&mesh);
    iso_tree_destroy(tree);
    iso_vol_destroy(vol);
}

/* Without sform or qform codes the voxel sizes give a diagonal map (the library's method 1). */
static void test_nifti_pixdim_only(void)
{
    iso_error err;
    uint8_t data[120] = {0};
    nifti_spec s = {.dim = {3, 6, 5, 4, 1, 1, 1, 1}, .datatype = 2, .bitpix = 8,
                    .pixdim = {1, 0.5f, 2, 3, 1, 1, 1, 1}, .slope = 0};
    const char *path = temp_path("plain.nii");
    write_nifti(path, &s, data, sizeof data);
    iso_volume *vol = NULL;
    CHECK_OK(iso_load(path, NULL, &vol, &err), &err);
    if (!vol)
        return;
    CHECK(vol->type == ISO_U8);
    CHECK_NEAR(vol->spacing[0], 0.5, 1e-12);
    CHECK_NEAR(vol->spacing[1], 2, 1e-12);
    CHECK_NEAR(vol->spacing[2], 3, 1e-12);
    CHECK_EQ(vol->oriented, 0); /* qform_code and sform_code 0: NIfTI's "unknown" */
    iso_vol_destroy(vol);
}

static void expect_refusal(const char *name, const nifti_spec *s, const void *data, size_t bytes,
                           int code, const char *words)
{
    iso_error err = {0};
    const char *path = temp_path(name);
    write_nifti(path, s, data, bytes);
    iso_volume *vol = NULL;
    iso_load_options opt = {.max_bytes = 1 << 20};
    int rc = iso_load(path, &opt, &vol, &err);
    CHECKF(rc == code && vol == NULL, "%s: rc %d (want %d): %s", name, rc, code, err.message);
    CHECKF(strstr(err.message, name) != NULL, "%s: message does not name the file: %s", name, err.message);
    CHECKF(strstr(err.message, words) != NULL, "%s: message \"%s\" lacks \"%s\"", name, err.message, words);
    iso_vol_destroy(vol);
}

static void test_nifti_hostile(void)
{
    int16_t data[120];
    ramp_samples(data);
    nifti_spec s = ramp_spec();
    expect_refusal("truncated.nii", &s, data, 100, ISO_E_TRUNCATED, "cannot be read");
    nifti_spec big = s;
    big.dim[1] = big.dim[2] = big.dim[3] = 30000;
    expect_refusal("lying_dims.nii", &big, data, sizeof data, ISO_E_LIMIT, "");
    nifti_spec flat = s;
    flat.sform_code = 0;
    flat.pixdim[2] = 0;
    expect_refusal("zero_spacing.nii", &flat, data, sizeof data, ISO_E_FORMAT, "zero");
    nifti_spec singular = s;
    memset(singular.srow, 0, sizeof singular.srow);
    singular.srow[0][0] = singular.srow[1][0] = singular.srow[2][2] = 1;
    singular.srow[0][1] = singular.srow[1][1] = 1; /* j parallel to i */
    expect_refusal("singular_sform.nii", &singular, data, sizeof data, ISO_E_FORMAT, "singular");
    nifti_spec complex = s;
    complex.datatype = 32, complex.bitpix = 64;
    expect_refusal("complex.nii", &complex, data, sizeof data, ISO_E_UNSUPPORTED, "datatype 32");
    nifti_spec four = s;
    four.dim[0] = 4, four.dim[4] = 2;
    expect_refusal("four_d.nii", &four, data, sizeof data, ISO_E_UNSUPPORTED, "volumes along dimension 4");
    nifti_spec thin = s;
    thin.dim[3] = 1;
    expect_refusal("thin.nii", &thin, data, sizeof data, ISO_E_FORMAT, "at least 2");
    /* Not NIfTI at all. */
    const char *junk = temp_path("junk.nii");
    FILE *f = fopen(junk, "wb");
    if (f) {
        fputs("this is not a NIfTI header", f);
        fclose(f);
    }
    iso_error err = {0};
    iso_volume *vol = NULL;
    CHECK(iso_load(junk, NULL, &vol, &err) == ISO_E_FORMAT && vol == NULL && strstr(err.message, "junk.nii"));
}

/* NRRD's space directions and origin, in RAS and in LPS, give the affine the header
 * states, in LPS. */
static void test_nrrd_space_directions(void)
{
    static const char *const spaces[] = {"right-anterior-superior", "left-posterior-superior"};
    for (int s = 0; s < 2; s++) {
        char header[512];
        int n = snprintf(header, sizeof header,
                         "NRRD0004\ntype: uint8\ndimension: 3\nsizes: 2 2 2\nencoding: raw\n"
                         "space: %s\nspace directions: (0.5,0.1,0) (0,2,0) (0,0,1)\n"
                         "space origin: (1,2,3)\n\n", spaces[s]);
        const char *path = temp_path(s ? "lps.nrrd" : "ras.nrrd");
        FILE *f = fopen(path, "wb");
        CHECK(f != NULL);
        if (!f)
            return;
        fwrite(header, 1, (size_t)n, f);
        fwrite("\1\2\3\4\5\6\7\10", 1, 8, f);
        fclose(f);
        iso_error err;
        iso_volume *vol = NULL;
        CHECK_OK(iso_load(path, NULL, &vol, &err), &err);
        if (!vol)
            return;
        double a[3][4], flip = s ? 1 : -1;
        iso_vol_affine(vol, a);
        double want[3][4] = {{0.5 * flip, 0, 0, 1 * flip}, {0.1 * flip, 2 * flip, 0, 2 * flip}, {0, 0, 1, 3}};
        for (int r = 0; r < 3; r++)
            for (int c = 0; c < 4; c++)
                CHECKF(fabs(a[r][c] - want[r][c]) < 1e-12, "%s: affine[%d][%d] = %g, want %g",
                       spaces[s], r, c, a[r][c], want[r][c]);
        iso_vol_destroy(vol);
    }
}

/* ---- MetaImage */

static void write_bytes(const char *path, const void *a, size_t a_len, const void *b, size_t b_len)
{
    FILE *f = fopen(path, "wb");
    CHECK(f != NULL);
    if (!f)
        return;
    CHECK(fwrite(a, 1, a_len, f) == a_len);
    if (b_len)
        CHECK(fwrite(b, 1, b_len, f) == b_len);
    fclose(f);
}

/* An .mha with zlib-compressed float samples after the header, axes permuted by the
 * TransformMatrix (i along world y, j along world -x) and an Offset. */
static void test_metaimage_local_compressed(void)
{
    float data[4 * 3 * 2];
    for (int n = 0; n < 24; n++)
        data[n] = (float)n * 0.5f;
    unsigned char packed[512];
    uLongf packed_size = sizeof packed;
    CHECK(compress(packed, &packed_size, (const Bytef *)data, sizeof data) == Z_OK);
    char header[512];
    int n = snprintf(header, sizeof header,
                     "ObjectType = Image\nNDims = 3\nBinaryData = True\nBinaryDataByteOrderMSB = False\n"
                     "CompressedData = True\nCompressedDataSize = %lu\nTransformMatrix = 0 1 0 -1 0 0 0 0 1\n"
                     "Offset = 10 -20 30\nElementSpacing = 0.5 2 3\nDimSize = 4 3 2\n"
                     "ElementType = MET_FLOAT\nElementDataFile = LOCAL\n", (unsigned long)packed_size);
    const char *path = temp_path("local.mha");
    write_bytes(path, header, (size_t)n, packed, packed_size);
    iso_error err;
    iso_volume *vol = NULL;
    CHECK_OK(iso_load(path, NULL, &vol, &err), &err);
    if (!vol)
        return;
    CHECK(vol->type == ISO_F32 && vol->dims[0] == 4 && vol->dims[1] == 3 && vol->dims[2] == 2);
    CHECK(memcmp(vol->data, data, sizeof data) == 0);
    double a[3][4];
    iso_vol_affine(vol, a);
    double want[3][4] = {{0, -2, 0, 10}, {0.5, 0, 0, -20}, {0, 0, 3, 30}};
    for (int r = 0; r < 3; r++)
        for (int c = 0; c < 4; c++)
            CHECKF(fabs(a[r][c] - want[r][c]) < 1e-12, "affine[%d][%d] = %g, want %g", r, c, a[r][c], want[r][c]);
    iso_vol_destroy(vol);
}

/* An .mhd with big-endian int16 samples in a file beside it. */
static void test_metaimage_detached_big_endian(void)
{
    unsigned char raw[2 * 2 * 2 * 2];
    for (int n = 0; n < 8; n++) {
        int v = n * 1000 - 3000;
        raw[2 * n] = (unsigned char)((v >> 8) & 0xff);
        raw[2 * n + 1] = (unsigned char)(v & 0xff);
    }
    write_bytes(temp_path("be.raw"), raw, sizeof raw, NULL, 0);
    const char *h = "NDims = 3\nDimSize = 2 2 2\nElementType = MET_SHORT\nElementByteOrderMSB = True\n"
                    "ElementDataFile = be.raw\n";
    write_bytes(temp_path("be.mhd"), h, strlen(h), NULL, 0);
    iso_error err;
    iso_volume *vol = NULL;
    CHECK_OK(iso_load(temp_path("be.mhd"), NULL, &vol, &err), &err);
    if (!vol)
        return;
    CHECK(vol->type == ISO_I16);
    CHECK_EQ(iso_vol_get(vol, 1, 1, 1), 4000);
    CHECK_EQ(iso_vol_get(vol, 0, 0, 0), -3000);
    iso_vol_destroy(vol);
}

static void test_metaimage_hostile(void)
{
    unsigned char raw[8] = {0};
    write_bytes(temp_path("ok.raw"), raw, sizeof raw, NULL, 0);
    static const struct {
        const char *name, *header, *words;
        int code;
    } cases[] = {
        {"abs.mhd", "NDims = 3\nDimSize = 2 2 2\nElementType = MET_UCHAR\nElementDataFile = /etc/hostname\n",
         "leaves the header's directory", ISO_E_FORMAT},
        {"up.mhd", "NDims = 3\nDimSize = 2 2 2\nElementType = MET_UCHAR\nElementDataFile = ../ok.raw\n",
         "leaves the header's directory", ISO_E_FORMAT},
        {"list.mhd", "NDims = 3\nDimSize = 2 2 2\nElementType = MET_UCHAR\nElementDataFile = LIST\n",
         "several files", ISO_E_UNSUPPORTED},
        {"long.mhd", "NDims = 3\nDimSize = 2 2 2\nElementType = MET_LONG\nElementDataFile = ok.raw\n",
         "MET_LONG", ISO_E_UNSUPPORTED},
        {"flat.mhd", "NDims = 2\nDimSize = 2 2\nElementType = MET_UCHAR\nElementDataFile = ok.raw\n",
         "3-D", ISO_E_UNSUPPORTED},
        {"thin.mhd", "NDims = 3\nDimSize = 2 1 2\nElementType = MET_UCHAR\nElementDataFile = ok.raw\n",
         "at least 2", ISO_E_FORMAT},
        {"zero.mhd", "NDims = 3\nDimSize = 2 2 2\nElementSpacing = 1 0 1\nElementType = MET_UCHAR\nElementDataFile = ok.raw\n",
         "zero, negative", ISO_E_FORMAT},
        {"negative.mhd", "NDims = 3\nDimSize = 2 2 2\nElementSpacing = 1 -2 1\nElementType = MET_UCHAR\nElementDataFile = ok.raw\n",
         "zero, negative", ISO_E_FORMAT},
        {"lying.mhd", "NDims = 3\nDimSize = 2 2 3\nElementType = MET_UCHAR\nElementDataFile = ok.raw\n",
         "", ISO_E_TRUNCATED},
        {"huge.mhd", "NDims = 3\nDimSize = 100000 100000 100000\nElementType = MET_UCHAR\nElementDataFile = ok.raw\n",
         "exceed the limit", ISO_E_LIMIT},
        {"nodata.mhd", "NDims = 3\nDimSize = 2 2 2\nElementType = MET_UCHAR\n", "without ElementDataFile", ISO_E_FORMAT},
        {"junk.mhd", "\x7f\x45LF binary", "Key = Value", ISO_E_FORMAT},
        {"channels.mhd", "NDims = 3\nDimSize = 2 2 2\nElementNumberOfChannels = 3\nElementType = MET_UCHAR\nElementDataFile = ok.raw\n",
         "channels", ISO_E_UNSUPPORTED},
    };
    for (size_t i = 0; i < sizeof cases / sizeof cases[0]; i++) {
        const char *path = temp_path(cases[i].name);
        write_bytes(path, cases[i].header, strlen(cases[i].header), NULL, 0);
        iso_error err = {0};
        iso_volume *vol = NULL;
        iso_load_options opt = {.max_bytes = 1 << 20};
        int rc = iso_load(path, &opt, &vol, &err);
        CHECKF(rc == cases[i].code && vol == NULL, "%s: rc %d (want %d): %s", cases[i].name, rc, cases[i].code, err.message);
        CHECKF(strstr(err.message, cases[i].name) != NULL && strstr(err.message, cases[i].words) != NULL,
               "%s: message \"%s\" lacks the file or \"%s\"", cases[i].name, err.message, cases[i].words);
        iso_vol_destroy(vol);
    }
}

/* The shared scans: the original NIfTI equals its NRRD twin voxel for voxel. */
static void test_shared_nifti_twins(void)
{
    const char *dir = check_shared_volumes();
    if (!dir) {
        check_skip("needs ../shared/volumes");
        return;
    }
    char nii[600], nrrd[600];
    snprintf(nii, sizeof nii, "%s/orig/ch2bet.nii.gz", dir);
    snprintf(nrrd, sizeof nrrd, "%s/ch2bet_181x217x181_u8.nhdr", dir);
    iso_error err;
    iso_volume *a = NULL, *b = NULL;
    CHECK_OK(iso_load(nii, NULL, &a, &err), &err);
    CHECK_OK(iso_load(nrrd, NULL, &b, &err), &err);
    if (a && b) {
        CHECK(a->type == b->type && a->dims[0] == b->dims[0] && a->dims[1] == b->dims[1] && a->dims[2] == b->dims[2]);
        CHECK(memcmp(a->data, b->data, iso_vol_count(a)) == 0);
    }
    iso_vol_destroy(a);
    iso_vol_destroy(b);
    /* avg152T1: the same voxels up to the stored orientation (a flip of some axes). */
    snprintf(nii, sizeof nii, "%s/orig/avg152T1_RL_nifti.nii.gz", dir);
    snprintf(nrrd, sizeof nrrd, "%s/avg152T1_91x109x91_u8.nhdr", dir);
    a = b = NULL;
    CHECK_OK(iso_load(nii, NULL, &a, &err), &err);
    CHECK_OK(iso_load(nrrd, NULL, &b, &err), &err);
    if (a && b && a->dims[0] == b->dims[0] && a->dims[1] == b->dims[1] && a->dims[2] == b->dims[2]) {
        int matched = 0;
        for (int flips = 0; flips < 8 && !matched; flips++) {
            int same = 1;
            for (size_t k = 0; k < a->dims[2] && same; k++)
                for (size_t j = 0; j < a->dims[1] && same; j++)
                    for (size_t i = 0; i < a->dims[0] && same; i++) {
                        size_t fi = flips & 1 ? a->dims[0] - 1 - i : i, fj = flips & 2 ? a->dims[1] - 1 - j : j,
                               fk = flips & 4 ? a->dims[2] - 1 - k : k;
                        same = iso_vol_get(a, i, j, k) == iso_vol_get(b, fi, fj, fk);
                    }
            matched = same;
        }
        CHECKF(matched, "avg152T1: no axis flip makes the NIfTI equal its NRRD twin");
    } else {
        CHECK(0);
    }
    iso_vol_destroy(a);
    iso_vol_destroy(b);
}

/* HeadMRVolume.mhd reads as 48x62x42 uint8 at 4 mm, its samples the .raw file's bytes. */
static void test_shared_metaimage(void)
{
    const char *dir = check_shared_volumes();
    if (!dir) {
        check_skip("needs ../shared/volumes");
        return;
    }
    char mhd[600], raw[600];
    snprintf(mhd, sizeof mhd, "%s/orig/HeadMRVolume.mhd", dir);
    snprintf(raw, sizeof raw, "%s/orig/HeadMRVolume.raw", dir);
    iso_error err;
    iso_volume *vol = NULL;
    CHECK_OK(iso_load(mhd, NULL, &vol, &err), &err);
    if (!vol)
        return;
    CHECK(vol->dims[0] == 48 && vol->dims[1] == 62 && vol->dims[2] == 42 && vol->type == ISO_U8);
    CHECK(vol->spacing[0] == 4 && vol->spacing[1] == 4 && vol->spacing[2] == 4);
    FILE *f = fopen(raw, "rb");
    CHECK(f != NULL);
    if (f) {
        unsigned char *bytes = malloc(iso_vol_count(vol) + 1);
        CHECK(bytes && fread(bytes, 1, iso_vol_count(vol) + 1, f) == iso_vol_count(vol));
        CHECK(bytes && memcmp(bytes, vol->data, iso_vol_count(vol)) == 0);
        free(bytes);
        fclose(f);
    }
    iso_vol_destroy(vol);
}

int main(void)
{
    CHECK_RUN(test_mricron_ch2bet);
    CHECK_RUN(test_nifti_rescale_and_sform_vertex);
    CHECK_RUN(test_nifti_pixdim_only);
    CHECK_RUN(test_nifti_hostile);
    CHECK_RUN(test_nrrd_space_directions);
    CHECK_RUN(test_metaimage_local_compressed);
    CHECK_RUN(test_metaimage_detached_big_endian);
    CHECK_RUN(test_metaimage_hostile);
    CHECK_RUN(test_shared_nifti_twins);
    CHECK_RUN(test_shared_metaimage);
    return check_finish();
}
