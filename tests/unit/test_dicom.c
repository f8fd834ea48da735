/* test_dicom.c: DICOM series through iso_load. Real files from Debian's python3-pydicom
 * (RT dose multi-frame in three transfer syntaxes, an MR slice in seven, a CT slice in HU)
 * and series written by tests/support/dicom_series.py: an enhanced multi-frame file, a
 * phantom in RLE, and the shared CThead and cranium scans (shuffled, RLE, oblique, a
 * missing slice, a mixed folder) that must load back equal to their NRRD sources, or fail
 * with a message naming the files. */
#include <errno.h>
#include <math.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <unistd.h>

#include "check.h"
#include "io/io.h"

#define PYDICOM_FILES "/usr/lib/python3/dist-packages/pydicom/data/test_files"
#define HELPER "/usr/bin/python3 tests/support/dicom_series.py"
#define UID_CTHEAD "1.2.826.0.1.3680043.8.498.1001"
#define UID_CRANIUM "1.2.826.0.1.3680043.8.498.1002"

/* Runs the series helper (its output into `out` when not NULL); 0 on success. */
static int helper(const char *out, const char *fmt, ...)
    __attribute__((format(printf, 2, 3)));
static int helper(const char *out, const char *fmt, ...)
{
    char args[2048], cmd[4096];
    va_list ap;
    va_start(ap, fmt);
    vsnprintf(args, sizeof args, fmt, ap);
    va_end(ap);
    snprintf(cmd, sizeof cmd, "%s %s > %s 2>&1", HELPER, args, out ? out : "/dev/null");
    return system(cmd);
}

/* pydicom and its test files are there (setup.sh installs python3-pydicom). */
static int have_pydicom(void)
{
    if (access(PYDICOM_FILES "/CT_small.dcm", R_OK) == 0 &&
        system("/usr/bin/python3 -c 'import pydicom, numpy' > /dev/null 2>&1") == 0)
        return 1;
    check_skip("needs Debian's python3-pydicom and python3-numpy");
    return 0;
}

static const char *tmp(const char *name)
{
    static char paths[8][512];
    static int next;
    char *p = paths[next++ % 8];
    snprintf(p, sizeof paths[0], "%s/%s", check_temp_dir(), name);
    return p;
}

static iso_volume *load(const char *path)
{
    iso_volume *vol = NULL;
    iso_error err = {0};
    int rc = iso_load(path, NULL, &vol, &err);
    CHECKF(rc == 0, "%s: %s", path, err.message);
    return vol;
}

/* Loads path expecting failure with every `want` fragment in the message. */
static void refuses(const char *path, const char *want1, const char *want2)
{
    iso_volume *vol = NULL;
    iso_error err = {0};
    int rc = iso_load(path, NULL, &vol, &err);
    CHECKF(rc < 0 && vol == NULL, "%s loaded", path);
    CHECKF(strstr(err.message, want1), "'%s' not in: %s", want1, err.message);
    CHECKF(!want2 || strstr(err.message, want2), "'%s' not in: %s", want2, err.message);
    iso_vol_destroy(vol);
}

/* Same dims and every sample equal by value (the types may differ: u16 raw vs HU i16). */
static void check_same_samples(const iso_volume *a, const iso_volume *b)
{
    CHECK(a && b);
    if (!a || !b)
        return;
    for (int d = 0; d < 3; d++)
        CHECK_EQ(a->dims[d], b->dims[d]);
    if (check_failed())
        return;
    size_t differ = 0;
    for (size_t k = 0; k < a->dims[2]; k++)
        for (size_t j = 0; j < a->dims[1]; j++)
            for (size_t i = 0; i < a->dims[0]; i++)
                differ += iso_vol_get(a, i, j, k) != iso_vol_get(b, i, j, k);
    CHECK_EQ(differ, 0);
}

/* Every sample against a float64 file (x fastest), within tol. */
static void check_against_raw(const iso_volume *vol, const char *raw, double tol)
{
    size_t n = iso_vol_count(vol);
    double *want = malloc(n * sizeof *want);
    FILE *f = fopen(raw, "rb");
    CHECKF(f && want && fread(want, sizeof *want, n, f) == n, "%s: cannot read %zu samples", raw, n);
    size_t bad = 0;
    for (size_t i = 0; !check_failed() && i < n; i++)
        bad += fabs(iso_vol_get(vol, i % vol->dims[0], i / vol->dims[0] % vol->dims[1],
                                i / (vol->dims[0] * vol->dims[1])) - want[i]) > tol;
    CHECK_EQ(bad, 0);
    if (f)
        fclose(f);
    free(want);
}

static void check_axes(const iso_volume *v, const double want[3][3])
{
    for (int r = 0; r < 3; r++)
        for (int c = 0; c < 3; c++)
            CHECK_NEAR(v->direction[r][c], want[r][c], 1e-9);
}

/* ---------------------------------------------------------------- pydicom's files */

/* RT dose: 15 frames placed by GridFrameOffsetVector, scaled by DoseGridScaling; the RLE
 * and big-endian copies decode to the same samples. */
static void test_rtdose_multiframe(void)
{
    if (!have_pydicom())
        return;
    CHECK_EQ(helper(NULL, "pixels %s/rtdose.dcm %s", PYDICOM_FILES, tmp("dose.raw")), 0);
    iso_volume *v = load(PYDICOM_FILES "/rtdose.dcm");
    iso_volume *rle = load(PYDICOM_FILES "/rtdose_rle.dcm");
    iso_volume *be = load(PYDICOM_FILES "/rtdose_expb.dcm");
    if (v && rle && be) {
        CHECK_EQ(v->dims[0], 10);
        CHECK_EQ(v->dims[1], 10);
        CHECK_EQ(v->dims[2], 15);
        CHECK_EQ(v->type, ISO_F32);
        CHECK_NEAR(v->spacing[0], 10, 1e-9);
        CHECK_NEAR(v->spacing[2], 5, 1e-9);
        CHECK_NEAR(v->origin[0], 189.43125, 1e-9);
        CHECK_NEAR(v->origin[2], -761.87, 1e-9);
        check_against_raw(v, tmp("dose.raw"), 1e-7);
        CHECK(memcmp(v->data, rle->data, iso_vol_count(v) * 4) == 0);
        CHECK(memcmp(v->data, be->data, iso_vol_count(v) * 4) == 0);
    }
    iso_vol_destroy(v);
    iso_vol_destroy(rle);
    iso_vol_destroy(be);
}

/* MR_small in seven transfer syntaxes, each restacked into three slices: all equal the
 * uncompressed one, which equals pydicom's decoding, with PixelSpacing and the position. */
static void test_mr_transfer_syntaxes(void)
{
    static const char *variants[] = {"MR_small_bigendian", "MR_small_expb", "MR_small_implicit", "MR_small_RLE",
                                     "MR_small_jpeg_ls_lossless", "MR_small_jp2klossless"};
    if (!have_pydicom())
        return;
    CHECK_EQ(helper(NULL, "restack %s/MR_small.dcm %s 3", PYDICOM_FILES, tmp("mr")), 0);
    CHECK_EQ(helper(NULL, "pixels %s/MR_small.dcm %s", PYDICOM_FILES, tmp("mr.raw")), 0);
    iso_volume *ref = load(tmp("mr"));
    if (!ref)
        return;
    CHECK_EQ(ref->dims[0], 64);
    CHECK_EQ(ref->dims[2], 3);
    CHECK_EQ(ref->type, ISO_I16);
    CHECK_NEAR(ref->spacing[0], 0.3125, 1e-9);
    CHECK_NEAR(ref->spacing[2], 2.5, 1e-6);
    CHECK_NEAR(ref->origin[0], -83.9063, 1e-9);
    CHECK_NEAR(ref->origin[2], 6.6406, 1e-9);
    iso_volume slice0 = *ref;
    slice0.dims[2] = 1; /* the first slice only: the raw file holds one */
    check_against_raw(&slice0, tmp("mr.raw"), 0);
    for (size_t i = 0; i < sizeof variants / sizeof variants[0]; i++) {
        char src[512];
        snprintf(src, sizeof src, "%s/%s.dcm", PYDICOM_FILES, variants[i]);
        CHECK_EQ(helper(NULL, "restack %s %s 3", src, tmp(variants[i])), 0);
        iso_volume *v = load(tmp(variants[i]));
        CHECKF(v && v->type == ref->type && !memcmp(v->data, ref->data, iso_vol_count(ref) * 2),
               "%s differs from MR_small", variants[i]);
        iso_vol_destroy(v);
    }
    iso_vol_destroy(ref);
}

/* CT_small: one slice is no volume (said so); two of it are, in Hounsfield units. */
static void test_ct_slice_in_hu(void)
{
    if (!have_pydicom())
        return;
    refuses(PYDICOM_FILES "/CT_small.dcm", "one slice", "a volume needs at least 2");
    CHECK_EQ(helper(NULL, "restack %s/CT_small.dcm %s 2", PYDICOM_FILES, tmp("ct")), 0);
    CHECK_EQ(helper(NULL, "pixels %s/CT_small.dcm %s", PYDICOM_FILES, tmp("ct.raw")), 0);
    iso_volume *v = load(tmp("ct"));
    if (!v)
        return;
    /* 16 signed stored bits - 1024 would not fit int16; the values present do. */
    CHECK_EQ(v->type, ISO_I16);
    iso_volume slice0 = *v;
    slice0.dims[2] = 1;
    check_against_raw(&slice0, tmp("ct.raw"), 0);
    iso_vol_destroy(v);
}

/* ---------------------------------------------------------------- written series */

/* Enhanced multi-frame: per-frame positions (frames stored shuffled) and per-frame
 * rescale intercepts from the functional groups; sample (i,j,k) = i + 16j + 256k - 1000. */
static void test_enhanced_multiframe(void)
{
    if (!have_pydicom())
        return;
    CHECK_EQ(helper(NULL, "enhanced %s", tmp("enhanced.dcm")), 0);
    iso_volume *v = load(tmp("enhanced.dcm"));
    if (!v)
        return;
    CHECK_EQ(v->dims[0], 12);
    CHECK_EQ(v->dims[1], 10);
    CHECK_EQ(v->dims[2], 8);
    CHECK_NEAR(v->spacing[0], 0.25, 1e-12);
    CHECK_NEAR(v->spacing[1], 0.5, 1e-12);
    CHECK_NEAR(v->spacing[2], 3, 1e-12);
    CHECK_NEAR(v->origin[2], 3, 1e-12);
    size_t bad = 0;
    for (size_t k = 0; k < 8; k++)
        for (size_t j = 0; j < 10; j++)
            for (size_t i = 0; i < 12; i++)
                bad += iso_vol_get(v, i, j, k) != (double)i + 16.0 * j + 256.0 * k - 1000;
    CHECK_EQ(bad, 0);
    iso_vol_destroy(v);
}

/* The synthetic phantom in RLE Lossless, HU through a -1024 intercept on 12 stored bits:
 * i16 samples equal to the phantom's. */
static void test_phantom_rle(void)
{
    if (!have_pydicom())
        return;
    CHECK_EQ(helper(NULL, "phantom %s --rle", tmp("phantom")), 0);
    CHECK_EQ(helper(NULL, "phantom-raw %s", tmp("phantom.raw")), 0);
    iso_volume *v = load(tmp("phantom"));
    if (!v)
        return;
    CHECK_EQ(v->type, ISO_I16);
    CHECK_EQ(v->dims[0], 40);
    CHECK_EQ(v->dims[1], 36);
    CHECK_EQ(v->dims[2], 24);
    CHECK_NEAR(v->spacing[0], 0.8, 1e-12);
    CHECK_NEAR(v->spacing[2], 1.25, 1e-9);
    FILE *f = fopen(tmp("phantom.raw"), "rb");
    int16_t *want = malloc(iso_vol_count(v) * 2);
    CHECK(f && want && fread(want, 2, iso_vol_count(v), f) == iso_vol_count(v));
    CHECK(want && memcmp(want, v->data, iso_vol_count(v) * 2) == 0);
    if (f)
        fclose(f);
    free(want);
    iso_vol_destroy(v);
}

/* Series of 12 and 16 stored bits, signed and unsigned, with and without a rescale: each
 * comes back in the narrowest type that holds the values present, every value exact, with
 * the instances' Modality and SeriesDescription. The third is the shape of most scanners'
 * CT (16 unsigned stored bits, intercept -1024), int16 although its stored range is not. */
static void test_rescaled_series_types(void)
{
    static const struct {
        const char *args, *values; /* the series, and its values: the phantom's HU scaled */
        iso_voxel_type type;
    } cases[] = {
        {"--bits=12 --intercept=-1024", "", ISO_I16},
        {"--bits=12 --signed", "", ISO_I16},
        {"--bits=16 --intercept=-1024", "", ISO_I16},
        {"--bits=16 --signed --intercept=-1024", "", ISO_I16},
        {"--bits=16 --signed", "", ISO_I16},
        {"--bits=12 --offset=1000", "--offset=1000", ISO_U16},
        {"--bits=16 --offset=33000 --intercept=-1024", "--offset=33000", ISO_U16},
        {"--bits=16 --scale=0.1 --offset=100", "--scale=0.1 --offset=100", ISO_U8},
        {"--bits=16 --signed --scale=0.1 --intercept=-50", "--scale=0.1", ISO_I8},
        {"--bits=12 --signed --scale=40 --slope=40", "--scale=40", ISO_I32},
        {"--bits=16 --offset=0.5 --intercept=-1024.5 --slope=0.5", "--offset=0.5", ISO_F32},
    };
    const size_t count = sizeof cases / sizeof cases[0];
    if (!have_pydicom())
        return;
    FILE *batch = fopen(tmp("rescaled.batch"), "w"); /* one helper process writes them all */
    CHECK(batch != NULL);
    if (!batch)
        return;
    for (size_t c = 0; c < count; c++) {
        fprintf(batch, "ct %s/rescaled%zu %s\n", check_temp_dir(), c, cases[c].args);
        fprintf(batch, "ct-raw %s/rescaled%zu.raw %s\n", check_temp_dir(), c, cases[c].values);
    }
    fclose(batch);
    CHECK_EQ(helper(NULL, "batch %s", tmp("rescaled.batch")), 0);
    for (size_t c = 0; c < count; c++) {
        char dir[64], raw[64], description[128] = "";
        snprintf(dir, sizeof dir, "rescaled%zu", c);
        snprintf(raw, sizeof raw, "rescaled%zu.raw", c);
        iso_volume *v = load(tmp(dir));
        if (!v)
            continue;
        CHECKF(v->type == cases[c].type, "%s: %s, not %s", cases[c].args, iso_vol_type_name(v->type),
               iso_vol_type_name(cases[c].type));
        check_against_raw(v, tmp(raw), 0);
        CHECK(!strcmp(v->modality, "CT"));
        snprintf(description, sizeof description, "ct %s-bit", strstr(cases[c].args, "=16") ? "16" : "12");
        CHECKF(!strncmp(v->description, description, strlen(description)), "description '%s'", v->description);
        iso_vol_destroy(v);
    }
}

/* PixelPaddingValue: stored 0 outside the phantom's circle, -1024 HU once rescaled, is the
 * volume's padding (the levels the server suggests skip it); without the tag, none. */
static void test_padding_value(void)
{
    if (!have_pydicom())
        return;
    CHECK_EQ(helper(NULL, "phantom %s --padding", tmp("padded")), 0);
    iso_volume *v = load(tmp("padded"));
    if (v) {
        CHECK_EQ(v->has_padding, 1);
        CHECK_EQ(v->padding, -1024);
        CHECK_EQ(v->value_min, -1024);
        CHECK_EQ(v->oriented, 1);
        iso_vol_destroy(v);
    }
    CHECK_EQ(helper(NULL, "phantom %s", tmp("unpadded")), 0);
    v = load(tmp("unpadded"));
    if (v) {
        CHECK_EQ(v->has_padding, 0);
        iso_vol_destroy(v);
    }
}

static void copy_file(const char *from, const char *to, long keep)
{
    FILE *in = fopen(from, "rb"), *out = fopen(to, "wb");
    char buf[4096];
    size_t n;
    long total = 0;
    while (in && out && (n = fread(buf, 1, sizeof buf, in)) > 0 && (keep < 0 || total < keep)) {
        size_t w = keep >= 0 && total + (long)n > keep ? (size_t)(keep - total) : n;
        CHECK(fwrite(buf, 1, w, out) == w);
        total += (long)w;
    }
    CHECK(in && out);
    if (in)
        fclose(in);
    if (out)
        fclose(out);
}

/* Bad series fail with what and where: no files, a truncated slice, two slices at one
 * place, a colour image, a series id that is not there, the memory cap. */
static void test_hostile_series(void)
{
    if (!have_pydicom())
        return;
    CHECK_EQ(helper(tmp("order.txt"), "phantom %s", tmp("bad")), 0);
    mkdir(tmp("empty"), 0755);
    refuses(tmp("empty"), "no DICOM image files", NULL);
    char first[600], name[64];
    FILE *f = fopen(tmp("order.txt"), "r");
    int k = -1;
    CHECK(f && fscanf(f, "%d %63s", &k, name) == 2 && k == 0);
    if (f)
        fclose(f);
    snprintf(first, sizeof first, "%s/%s", tmp("bad"), name);
    copy_file(first, tmp("bad/zz-copy.dcm"), -1);
    refuses(tmp("bad"), "two slices at one position", "zz-copy.dcm");
    copy_file(first, tmp("bad/zz-copy.dcm"), 2000); /* the header, then half the pixels */
    refuses(tmp("bad"), "zz-copy.dcm", NULL);
    unlink(tmp("bad/zz-copy.dcm"));
    char spec[700];
    snprintf(spec, sizeof spec, "%s#1.2.3.4", tmp("bad"));
    refuses(spec, "no series 1.2.3.4", "24 files");
    iso_load_options small = {.max_bytes = 10000};
    iso_volume *v = NULL;
    iso_error err = {0};
    CHECK_EQ(iso_load(tmp("bad"), &small, &v, &err), ISO_E_LIMIT);
    CHECK(v == NULL);
    mkdir(tmp("rgb"), 0755);
    copy_file(PYDICOM_FILES "/SC_rgb_rle.dcm", tmp("rgb/a.dcm"), -1);
    refuses(tmp("rgb"), "samples per pixel", "a.dcm");
}

/* ---------------------------------------------------------------- the shared scans */

static const char *shared_series(const char *which)
{
    const char *dir = check_shared_volumes();
    if (!dir) {
        check_skip("needs ../shared/volumes");
        return NULL;
    }
    if (!have_pydicom())
        return NULL;
    static char ct[512], cr[512]; /* written once; tmp()'s buffers are reused */
    int is_ct = !strcmp(which, "ct");
    if (is_ct && !ct[0]) {
        snprintf(ct, sizeof ct, "%s", tmp("cthead"));
        CHECK_EQ(helper(tmp("ct-order.txt"), "nrrd %s/CThead_256x256x113_u16be.nhdr %s --uid=%s", dir, ct,
                        UID_CTHEAD), 0);
    }
    if (!is_ct && !cr[0]) { /* another seed: other file names, so that both fit one folder */
        snprintf(cr, sizeof cr, "%s", tmp("cranium"));
        CHECK_EQ(helper(NULL, "nrrd %s/cranium_256x256x108_i16le.nhdr %s --rle --hu --oblique --seed=2 --uid=%s",
                        dir, cr, UID_CRANIUM), 0);
    }
    return is_ct ? ct : cr;
}

static iso_volume *shared_nrrd(const char *name)
{
    char path[512];
    snprintf(path, sizeof path, "%s/%s", check_shared_volumes(), name);
    return load(path);
}

/* CThead, file names and InstanceNumbers shuffled: the same u16 samples as the NRRD. */
static void test_shared_cthead_shuffled(void)
{
    const char *dir = shared_series("ct");
    if (!dir)
        return;
    iso_volume *v = load(dir), *src = shared_nrrd("CThead_256x256x113_u16be.nhdr");
    static const double identity[3][3] = {{1, 0, 0}, {0, 1, 0}, {0, 0, 1}};
    if (v && src) {
        CHECK_EQ(v->type, ISO_U16);
        CHECK(memcmp(v->data, src->data, iso_vol_count(src) * 2) == 0);
        for (int a = 0; a < 3; a++)
            CHECK_NEAR(v->spacing[a], src->spacing[a], 1e-9);
        check_axes(v, identity);
        CHECK_NEAR(v->origin[0], 10, 1e-9);
        CHECK_NEAR(v->origin[1], -20, 1e-9);
        CHECK_NEAR(v->origin[2], 30, 1e-9);
    }
    iso_vol_destroy(v);
    iso_vol_destroy(src);
}

/* cranium in RLE, stored as raw + 1024 on 12 bits, as a sagittal stack: the HU samples
 * come back as i16 equal to the NRRD's, with rows along +y, columns along -z, slices -x. */
static void test_shared_cranium_rle_oblique(void)
{
    const char *dir = shared_series("cr");
    if (!dir)
        return;
    iso_volume *v = load(dir), *src = shared_nrrd("cranium_256x256x108_i16le.nhdr");
    static const double axes[3][3] = {{0, 0, -1}, {1, 0, 0}, {0, -1, 0}};
    if (v && src) {
        CHECK_EQ(v->type, ISO_I16);
        check_same_samples(v, src);
        for (int a = 0; a < 3; a++)
            CHECK_NEAR(v->spacing[a], src->spacing[a], 1e-6);
        check_axes(v, axes);
    }
    iso_vol_destroy(v);
    iso_vol_destroy(src);
}

/* Slice 50 of CThead missing: refused, naming the files on either side of the gap. */
static void test_shared_missing_slice(void)
{
    const char *dir = shared_series("ct");
    if (!dir)
        return;
    char names[113][64], path[1024], link[1024], missing[512];
    int k;
    snprintf(missing, sizeof missing, "%s", tmp("ct-missing"));
    FILE *f = fopen(tmp("ct-order.txt"), "r");
    for (int i = 0; f && i < 113; i++)
        CHECK(fscanf(f, "%d %63s", &k, names[i]) == 2 && k == i);
    if (f)
        fclose(f);
    mkdir(missing, 0755);
    for (int i = 0; i < 113 && !check_failed(); i++) {
        snprintf(path, sizeof path, "%s/%s", dir, names[i]);
        snprintf(link, sizeof link, "%s/%s", missing, names[i]);
        CHECK(i == 50 || symlink(path, link) == 0);
    }
    refuses(missing, "uneven slice spacing", "(a missing slice?)");
    refuses(missing, names[49], names[51]);
}

/* CThead and cranium in one folder: which one is asked; each loads by its UID. */
static void test_shared_mixed_folder(void)
{
    const char *ct = shared_series("ct"), *cr = shared_series("cr");
    if (!ct || !cr)
        return;
    char cmd[2048], spec[1024];
    mkdir(tmp("mixed"), 0755);
    snprintf(cmd, sizeof cmd, "ln -s %s/*.dcm %s/*.dcm %s/", ct, cr, tmp("mixed"));
    CHECK_EQ(system(cmd), 0);
    refuses(tmp("mixed"), "several series: ", "#SeriesInstanceUID");
    refuses(tmp("mixed"), UID_CTHEAD " (113 files)", UID_CRANIUM " (108 files)");
    iso_volume *src = shared_nrrd("CThead_256x256x113_u16be.nhdr");
    snprintf(spec, sizeof spec, "%s#%s", tmp("mixed"), UID_CTHEAD);
    iso_volume *v = load(spec);
    if (v && src)
        CHECK(v->type == ISO_U16 && memcmp(v->data, src->data, iso_vol_count(src) * 2) == 0);
    iso_vol_destroy(v);
    iso_vol_destroy(src);
    src = shared_nrrd("cranium_256x256x108_i16le.nhdr");
    snprintf(spec, sizeof spec, "%s#%s", tmp("mixed"), UID_CRANIUM);
    v = load(spec);
    check_same_samples(v, src);
    iso_vol_destroy(v);
    iso_vol_destroy(src);
}

int main(void)
{
    CHECK_RUN(test_rtdose_multiframe);
    CHECK_RUN(test_mr_transfer_syntaxes);
    CHECK_RUN(test_ct_slice_in_hu);
    CHECK_RUN(test_rescaled_series_types);
    CHECK_RUN(test_enhanced_multiframe);
    CHECK_RUN(test_phantom_rle);
    CHECK_RUN(test_padding_value);
    CHECK_RUN(test_hostile_series);
    CHECK_RUN(test_shared_cthead_shuffled);
    CHECK_RUN(test_shared_cranium_rle_oblique);
    CHECK_RUN(test_shared_missing_slice);
    CHECK_RUN(test_shared_mixed_folder);
    return check_finish();
}
