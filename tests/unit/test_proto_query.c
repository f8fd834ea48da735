/* test_proto_query.c: the wire without sockets: mesh request parsing (every rejection with
 * its parameter), normalised keys, the JSON documents read back with jansson, problem
 * bodies; and the core helpers the server leans on: histograms, Otsu levels, budgets. */
#include <jansson.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "extract/extract.h"
#include "mesh/mesh.h"
#include "check.h"
#include "document.h"
#include "encode.h"
#include "io/io.h"
#include "volume/volume.h"
#include "query.h"
#include "hierarchy/tree.h"

#define P(k, v) ((proto_param){k, v})
#define COUNT(a) (sizeof(a) / sizeof((a)[0]))

static int parse(const proto_param *p, size_t n, proto_mesh_request *r, proto_problem *pr)
{
    memset(pr, 0, sizeof *pr);
    return proto_mesh_request_parse(p, n, r, pr);
}

/* distance=: millimetres, >= 0, not with budget; spelt in the key only when given, and a
 * key with it parses back to the same key; a small buffer gets the same length back. */
static void test_query_distance(void)
{
    proto_mesh_request r;
    proto_problem pr;
    proto_param none[] = {P("level", "700")};
    CHECK_EQ(parse(none, 1, &r, &pr), 0);
    CHECK(r.distance == -1);
    proto_param half[] = {P("level", "700"), P("distance", "0.50")};
    CHECK_EQ(parse(half, 2, &r, &pr), 0);
    CHECK(r.distance == 0.5);
    char key[512], again[512], small[100];
    size_t n = proto_mesh_request_key(&r, key, sizeof key);
    CHECKF(n == strlen(key) && strstr(key, "&measures=false&distance=0.5") &&
           !strcmp(strstr(key, "&distance="), "&distance=0.5"), "%s", key);
    CHECK_EQ(proto_mesh_request_key(&r, small, sizeof small), n);
    CHECK_EQ(strlen(small), sizeof small - 1);
    CHECK(!strncmp(small, key, sizeof small - 1));
    proto_param zero[] = {P("level", "700"), P("distance", "-0")};
    CHECK_EQ(parse(zero, 2, &r, &pr), 0);
    proto_mesh_request_key(&r, again, sizeof again);
    CHECKF(strstr(again, "&distance=0") && !signbit(r.distance), "%s", again);
    proto_param negative[] = {P("level", "700"), P("distance", "-1")};
    CHECK_EQ(parse(negative, 2, &r, &pr), -1);
    CHECK(pr.status == 400 && !strcmp(pr.parameter, "distance"));
    proto_param both[] = {P("level", "700"), P("budget", "100"), P("distance", "1")};
    CHECK_EQ(parse(both, 3, &r, &pr), -1);
    CHECKF(pr.status == 400 && !strcmp(pr.parameter, "distance") && strstr(pr.detail, "budget"), "%s", pr.detail);
}

/* min_component=: mm3, >= 0, with distance or budget or alone; spelt in the key only when
 * above 0, after distance; not on the all-segments route. */
static void test_query_min_component(void)
{
    proto_mesh_request r;
    proto_problem pr;
    proto_param none[] = {P("level", "700")};
    CHECK_EQ(parse(none, 1, &r, &pr), 0);
    CHECK(r.min_component == 0);
    char key[512], plain[512];
    proto_mesh_request_key(&r, plain, sizeof plain);
    CHECK(!strstr(plain, "min_component"));
    proto_param given[] = {P("level", "700"), P("distance", "1"), P("min_component", "2.5")};
    CHECK_EQ(parse(given, 3, &r, &pr), 0);
    CHECK(r.min_component == 2.5);
    size_t n = proto_mesh_request_key(&r, key, sizeof key);
    CHECKF(n == strlen(key) && !strcmp(strstr(key, "&distance="), "&distance=1&min_component=2.5"), "%s", key);
    proto_param zero[] = {P("level", "700"), P("min_component", "0")};
    CHECK_EQ(parse(zero, 2, &r, &pr), 0);
    proto_mesh_request_key(&r, key, sizeof key);
    CHECKF(!strcmp(key, plain), "%s", key);
    proto_param negative[] = {P("level", "700"), P("min_component", "-1")};
    CHECK_EQ(parse(negative, 2, &r, &pr), -1);
    CHECK(pr.status == 400 && !strcmp(pr.parameter, "min_component"));
    proto_param all[] = {P("min_component", "1")};
    memset(&pr, 0, sizeof pr);
    CHECK_EQ(proto_segment_request_parse(all, 1, 1, &r, &pr), -1);
    CHECK(pr.status == 400 && !strcmp(pr.parameter, "min_component"));
    CHECK_EQ(proto_segment_request_parse(all, 1, 0, &r, &pr), 0);
    CHECK(r.min_component == 1);
}

static void test_query_defaults_and_values(void)
{
    proto_mesh_request r;
    proto_problem pr;
    proto_param only_level[] = {P("level", "700")};
    CHECK_EQ(parse(only_level, 1, &r, &pr), 0);
    CHECK(r.level == 700 && r.tolerance == 0 && r.normals == PROTO_NORMALS_DEFAULT);
    CHECK(r.format == PROTO_FORMAT_DRACO && r.position_bits == 14 && r.normal_bits == 10 && r.budget == 0);
    CHECK_EQ(r.speed, PROTO_DRACO_SPEED_AUTO);

    proto_param all[] = {P("budget", "20000"), P("qn", "8"), P("qp", "11"), P("format", "glb"),
                         P("normals", "none"), P("tolerance", "2.5e1"), P("level", "-142.5")};
    CHECK_EQ(parse(all, COUNT(all), &r, &pr), 0);
    CHECK(r.level == -142.5 && r.tolerance == 25 && r.normals == 0 && r.format == PROTO_FORMAT_GLB);
    CHECK(r.position_bits == 11 && r.normal_bits == 8 && r.budget == 20000);
    proto_param speeds[][2] = {{P("level", "1"), P("speed", "0")}, {P("level", "1"), P("speed", "10")},
                               {P("level", "1"), P("speed", "auto")}};
    const int want_speed[] = {0, 10, PROTO_DRACO_SPEED_AUTO};
    for (size_t i = 0; i < COUNT(want_speed); i++) {
        CHECK_EQ(parse(speeds[i], 2, &r, &pr), 0);
        CHECK_EQ(r.speed, want_speed[i]);
    }
    proto_param tri[] = {P("level", "1"), P("normals", "trilinear"), P("format", "ply")};
    CHECK_EQ(parse(tri, COUNT(tri), &r, &pr), 0);
    CHECK(r.normals == 2 && r.format == PROTO_FORMAT_PLY && r.cap == 0);
    proto_param printable[] = {P("level", "1"), P("cap", "true"), P("format", "stl")};
    CHECK_EQ(parse(printable, COUNT(printable), &r, &pr), 0);
    CHECK(r.cap == 1 && r.format == PROTO_FORMAT_STL);
    CHECK(!strcmp(proto_format_content_type(r.format), "model/stl"));
    proto_param open_again[] = {P("level", "1"), P("cap", "false")};
    CHECK_EQ(parse(open_again, COUNT(open_again), &r, &pr), 0);
    CHECK(r.cap == 0 && r.measures == 0);
    proto_param measured[] = {P("level", "1"), P("measures", "true")};
    CHECK_EQ(parse(measured, COUNT(measured), &r, &pr), 0);
    CHECK(r.measures == 1 && r.cap == 0);
}

/* Each bad request names the parameter and says why. */
static void test_query_rejections(void)
{
    static const struct {
        proto_param params[3];
        size_t count;
        const char *parameter, *words;
    } cases[] = {
        {{{"tolerance", "1"}}, 1, "level", "required"},
        {{{"level", NULL}}, 1, "level", "needs a value"},
        {{{"level", ""}}, 1, "level", "needs a value"},
        {{{"level", "abc"}}, 1, "level", "not a number"},
        {{{"level", "0x10"}}, 1, "level", "not a number"},
        {{{"level", " 7"}}, 1, "level", "not a number"},
        {{{"level", "7 "}}, 1, "level", "not a number"},
        {{{"level", "1e5e5"}}, 1, "level", "not a number"},
        {{{"level", "NaN"}}, 1, "level", "finite"},
        {{{"level", "inf"}}, 1, "level", "finite"},
        {{{"level", "-Infinity"}}, 1, "level", "finite"},
        {{{"level", "1e999"}}, 1, "level", "finite"},
        {{{"level", "1"}, {"tolerance", "-1"}}, 2, "tolerance", "from 0"},
        {{{"level", "1"}, {"tolerance", "1e31"}}, 2, "tolerance", "from 0"},
        {{{"level", "1"}, {"normals", "phong"}}, 2, "normals", "tricubic"},
        {{{"level", "1"}, {"format", "obj"}}, 2, "format", "draco, glb, glb-meshopt, glb-plain, ply or stl"},
        {{{"level", "1"}, {"cap", "yes"}}, 2, "cap", "true or false"},
        {{{"level", "1"}, {"cap", NULL}}, 2, "cap", "true or false"},
        {{{"level", "1"}, {"measures", "1"}}, 2, "measures", "true or false"},
        {{{"level", "1"}, {"qp", "7"}}, 2, "qp", "from 8 to 24"},
        {{{"level", "1"}, {"qp", "25"}}, 2, "qp", "from 8 to 24"},
        {{{"level", "1"}, {"qp", "12.5"}}, 2, "qp", "whole number"},
        {{{"level", "1"}, {"qn", "17"}}, 2, "qn", "from 6 to 16"},
        {{{"level", "1"}, {"speed", "11"}}, 2, "speed", "from 0 to 10"},
        {{{"level", "1"}, {"speed", "fast"}}, 2, "speed", "auto or a whole number from 0 to 10"},
        {{{"level", "1"}, {"speed", "-1"}}, 2, "speed", "auto or a whole number"},
        {{{"level", "1"}, {"speed", NULL}}, 2, "speed", "needs a value"},
        {{{"level", "1"}, {"budget", "0"}}, 2, "budget", "from 1"},
        {{{"level", "1"}, {"budget", "-5"}}, 2, "budget", "whole number"},
        {{{"level", "1"}, {"budget", "99999999999999"}}, 2, "budget", "whole number"},
        {{{"level", "1"}, {"level", "2"}}, 2, "level", "more than once"},
        {{{"level", "1"}, {"tolerance", "1"}, {"tolerance", "1"}}, 3, "tolerance", "more than once"},
        {{{"level", "1"}, {"tolerence", "1"}}, 2, "", "unknown parameter \"tolerence\""},
    };
    for (size_t i = 0; i < COUNT(cases); i++) {
        proto_mesh_request r;
        proto_problem pr;
        int rc = parse(cases[i].params, cases[i].count, &r, &pr);
        CHECKF(rc == -1 && pr.status == 400, "case %zu: rc %d status %d", i, rc, pr.status);
        CHECKF(!strcmp(pr.parameter, cases[i].parameter), "case %zu: parameter \"%s\", want \"%s\"",
               i, pr.parameter, cases[i].parameter);
        CHECKF(strstr(pr.detail, cases[i].words) != NULL, "case %zu: detail \"%s\" lacks \"%s\"", i,
               pr.detail, cases[i].words);
    }
}

/* Hostile values are echoed cut short and without control bytes or quotes. */
static void test_query_echo_is_bounded(void)
{
    char long_value[2000];
    memset(long_value, 'x', sizeof long_value - 1);
    long_value[sizeof long_value - 1] = '\0';
    long_value[3] = '\n';
    long_value[4] = '"';
    proto_param p[] = {P("level", "1"), P("format", long_value)};
    proto_mesh_request r;
    proto_problem pr;
    CHECK_EQ(parse(p, 2, &r, &pr), -1);
    CHECK(strlen(pr.detail) < sizeof pr.detail);
    CHECK(strchr(pr.detail, '\n') == NULL);
    CHECK(strstr(pr.detail, "...") != NULL);
}

/* The normalised key of a request that must parse. */
static void key_of(const proto_param *p, size_t n, char *key, size_t size)
{
    proto_mesh_request r;
    proto_problem pr;
    CHECK_EQ(parse(p, n, &r, &pr), 0);
    proto_mesh_request_key(&r, key, size);
}

/* Equal requests, however spelt, share a key; different ones do not. */
static void test_query_key_normalises(void)
{
    proto_param a[] = {P("level", "700"), P("tolerance", "0")};
    proto_param b[] = {P("format", "draco"), P("level", "700.0"), P("qp", "14"), P("normals", "tricubic")};
    proto_param c[] = {P("level", "700"), P("tolerance", "-0")};
    proto_param d[] = {P("level", "700.5")};
    proto_param e[] = {P("level", "700"), P("normals", "none"), P("qn", "12")};
    proto_param f[] = {P("level", "700"), P("normals", "none")};
    proto_param g[] = {P("level", "700"), P("cap", "true")};
    /* The Draco speed changes Draco and glb bytes, not PLY's or STL's. */
    proto_param h[] = {P("level", "700"), P("speed", "3")};
    proto_param i[] = {P("level", "700"), P("speed", "3"), P("format", "ply")};
    proto_param j[] = {P("level", "700"), P("format", "ply")};
    /* Nor do the quantization bits. */
    proto_param k[] = {P("level", "700"), P("qp", "11"), P("qn", "8"), P("format", "ply")};
    proto_param l[] = {P("level", "700"), P("qp", "11"), P("format", "stl")};
    proto_param m[] = {P("level", "700"), P("format", "stl")};
    proto_param q[] = {P("level", "700"), P("qp", "11")};
    /* The measures change the headers, not the bytes; a separate entry keeps them. */
    proto_param ms[] = {P("level", "700"), P("measures", "true")};
    proto_param mf[] = {P("level", "700"), P("measures", "false")};
    char kms[256], kmf[256];
    key_of(ms, COUNT(ms), kms, sizeof kms);
    key_of(mf, COUNT(mf), kmf, sizeof kmf);
    CHECKF(strstr(kms, "&measures=true") && strcmp(kms, kmf), "%s | %s", kms, kmf);
    char ka[256], kb[256], kc[256], kd[256], ke[256], kf[256], kg[256], kh[256], ki[256], kj[256];
    char kk[256], kl[256], km[256], kq[256];
    key_of(k, COUNT(k), kk, sizeof kk);
    key_of(l, COUNT(l), kl, sizeof kl);
    key_of(m, COUNT(m), km, sizeof km);
    key_of(q, COUNT(q), kq, sizeof kq);
    key_of(a, COUNT(a), ka, sizeof ka);
    key_of(b, COUNT(b), kb, sizeof kb);
    key_of(c, COUNT(c), kc, sizeof kc);
    key_of(d, COUNT(d), kd, sizeof kd);
    key_of(e, COUNT(e), ke, sizeof ke);
    key_of(f, COUNT(f), kf, sizeof kf);
    key_of(g, COUNT(g), kg, sizeof kg);
    key_of(h, COUNT(h), kh, sizeof kh);
    key_of(i, COUNT(i), ki, sizeof ki);
    key_of(j, COUNT(j), kj, sizeof kj);
    CHECKF(!strcmp(ka, kb) && !strcmp(ka, kc), "%s | %s | %s", ka, kb, kc);
    CHECK(strcmp(ka, kd) != 0);
    CHECKF(!strcmp(ke, kf), "normal bits do not matter without normals: %s | %s", ke, kf);
    CHECK(!strcmp(ka, "level=700&tolerance=0&normals=tricubic&format=draco&qp=14&qn=10&speed=auto&budget=0&cap=false&measures=false"));
    CHECK(strcmp(ka, kg) != 0);
    CHECKF(!strcmp(ka, kmf), "measures=false is the default: %s | %s", ka, kmf);
    CHECKF(strstr(kh, "&speed=3&") && strcmp(ka, kh), "%s", kh);
    CHECKF(!strcmp(ki, kj), "%s | %s", ki, kj);
    CHECKF(!strcmp(kk, kj), "qp and qn do not change PLY: %s | %s", kk, kj);
    CHECKF(!strcmp(kl, km), "qp does not change STL: %s | %s", kl, km);
    CHECKF(strcmp(kq, "level=700&tolerance=0&normals=tricubic&format=draco&qp=11&qn=10&speed=auto&budget=0&cap=false&measures=false") == 0, "%s", kq);
    proto_mesh_request r;
    proto_problem pr;
    CHECK_EQ(parse(f, COUNT(f), &r, &pr), 0);
    char small[8];
    CHECK_EQ(proto_mesh_request_key(&r, small, sizeof small), strlen(kf));
    CHECK_EQ(strlen(small), 7);
}

/* The volume document parses back with every field the API promises. */
static void test_volume_document(void)
{
    iso_error err;
    size_t dims[3] = {4, 3, 2};
    iso_volume *vol = iso_vol_create(dims, ISO_U16, 0, &err);
    CHECK(vol != NULL);
    if (!vol)
        return;
    vol->spacing[0] = 0.5, vol->spacing[1] = 2, vol->spacing[2] = 3;
    vol->origin[0] = 10, vol->origin[1] = -20, vol->origin[2] = 30;
    for (size_t k = 0; k < 2; k++)
        for (size_t j = 0; j < 3; j++)
            for (size_t i = 0; i < 4; i++)
                iso_vol_set(vol, i, j, k, (double)(i + 10 * j + 100 * k));
    iso_vol_update_stats(vol);
    uint64_t hist[4];
    iso_hist_compute(vol, 4, hist);
    double levels[] = {50, 120.5};
    proto_volume_doc doc = {.id = "tiny", .name = "Tiny <test>", .modality = "CT", .version = "abc-1",
                            .vol = vol, .levels = levels, .level_count = 2, .histogram = hist,
                            .histogram_bins = 4, .hierarchy_nodes = 1, .hierarchy_bytes = 16,
                            .hierarchy_ms = 0.25, .hierarchy_from_file = 1};
    char *text = proto_json_volume(&doc, 1);
    json_error_t jerr;
    json_t *o = text ? json_loads(text, 0, &jerr) : NULL;
    CHECKF(o != NULL, "document does not parse: %s", text ? jerr.text : "NULL");
    if (o) {
        CHECK(!strcmp(json_string_value(json_object_get(o, "id")), "tiny"));
        CHECK(!strcmp(json_string_value(json_object_get(o, "name")), "Tiny <test>"));
        CHECK(!strcmp(json_string_value(json_object_get(o, "value_type")), "uint16"));
        CHECK_EQ(json_integer_value(json_array_get(json_object_get(o, "dims"), 2)), 2);
        CHECK(json_real_value(json_array_get(json_object_get(o, "value_range"), 1)) == 123);
        CHECK(json_real_value(json_array_get(json_object_get(o, "suggested_levels"), 1)) == 120.5);
        json_t *m = json_object_get(o, "index_to_world");
        CHECK_EQ(json_array_size(m), 16);
        /* Diagonal spacing, origin in the last column, bottom row 0 0 0 1. */
        double want[16] = {0.5, 0, 0, 10, 0, 2, 0, -20, 0, 0, 3, 30, 0, 0, 0, 1};
        for (int i = 0; i < 16; i++)
            CHECKF(json_number_value(json_array_get(m, (size_t)i)) == want[i], "m[%d] = %g", i,
                   json_number_value(json_array_get(m, (size_t)i)));
        json_t *h = json_object_get(o, "histogram");
        CHECK_EQ(json_array_size(json_object_get(h, "counts")), 4);
        json_int_t total = 0;
        for (size_t b = 0; b < 4; b++)
            total += json_integer_value(json_array_get(json_object_get(h, "counts"), b));
        CHECK_EQ(total, 24);
        CHECK(json_is_true(json_object_get(json_object_get(o, "hierarchy"), "from_file")));
        json_decref(o);
    }
    free(text);
    text = proto_json_volume_list(&doc, 1);
    o = text ? json_loads(text, 0, &jerr) : NULL;
    CHECK(o != NULL && json_array_size(json_object_get(o, "volumes")) == 1);
    CHECK(o && !json_object_get(json_array_get(json_object_get(o, "volumes"), 0), "histogram"));
    json_decref(o);
    free(text);
    iso_vol_destroy(vol);
}

static void test_problem_body(void)
{
    proto_problem pr;
    proto_problem_set(&pr, 400, "level", "level is required");
    char *text = proto_json_problem(&pr, "/v1/volumes/x/mesh");
    json_error_t jerr;
    json_t *o = text ? json_loads(text, 0, &jerr) : NULL;
    CHECK(o != NULL);
    if (o) {
        CHECK_EQ(json_integer_value(json_object_get(o, "status")), 400);
        CHECK(!strcmp(json_string_value(json_object_get(o, "title")), "Bad Request"));
        CHECK(!strcmp(json_string_value(json_object_get(o, "parameter")), "level"));
        CHECK(!strcmp(json_string_value(json_object_get(o, "detail")), "level is required"));
        CHECK(!strcmp(json_string_value(json_object_get(o, "instance")), "/v1/volumes/x/mesh"));
        CHECK(strstr(json_string_value(json_object_get(o, "type")), "bad-parameter") != NULL);
        json_decref(o);
    }
    free(text);
    proto_problem_set(&pr, 503, NULL, "busy");
    text = proto_json_problem(&pr, NULL);
    CHECK(text && !strstr(text, "parameter") && strstr(text, "\"status\":503"));
    free(text);
}

/* Three flat classes of 100 samples at 0, 100 and 200: Otsu's thresholds fall between. */
static void test_otsu_levels(void)
{
    uint64_t counts[256] = {0};
    counts[0] = 100, counts[128] = 100, counts[255] = 100;
    double levels[4];
    size_t n = iso_hist_suggest_levels(counts, 256, 0, 200, levels, 4);
    CHECK_EQ(n, 2);
    CHECKF(levels[0] > 0 && levels[0] <= 100.5 && levels[1] > 100 && levels[1] <= 200,
           "levels %g %g", levels[0], levels[1]);
    uint64_t two[256] = {0};
    two[10] = 5, two[200] = 7;
    CHECK_EQ(iso_hist_suggest_levels(two, 256, 0, 255, levels, 4), 1);
    CHECK(levels[0] > 10 && levels[0] <= 201);
    uint64_t one[256] = {0};
    one[3] = 9;
    CHECK_EQ(iso_hist_suggest_levels(one, 256, 0, 255, levels, 4), 0);
    CHECK_EQ(iso_hist_suggest_levels(counts, 256, 5, 5, levels, 4), 0);
}

/* A CT whose corners hold -2000 (outside the reconstruction circle): Otsu on every bin puts
 * its first level between the padding and air, which draws the circle; with the padding's
 * bin dropped the levels fall between air, soft tissue and bone. */
static void test_levels_skip_padding(void)
{
    uint64_t counts[256] = {0};
    const double min = -2000, max = 3000, width = (max - min) / 256;
    size_t air = (size_t)((-1000 - min) / width), soft = (size_t)((40 - min) / width),
           bone = (size_t)((1200 - min) / width);
    counts[0] = 4000000;
    for (int d = -2; d <= 2; d++) {
        counts[air + d] = 500000;
        counts[soft + d] = 300000;
        counts[bone + d] = 60000;
    }
    double levels[2];
    CHECK_EQ(iso_hist_suggest_levels(counts, 256, min, max, levels, 2), 2);
    CHECKF(levels[0] < -1000, "with padding the first level %g sits below air", levels[0]);
    CHECK_EQ(iso_hist_drop_padding(counts, 256, min, max, -2000), 4000000);
    CHECK_EQ(counts[0], 0);
    CHECK_EQ(iso_hist_suggest_levels(counts, 256, min, max, levels, 2), 2);
    CHECKF(levels[0] > -1000 && levels[0] < 40 && levels[1] > 40 && levels[1] < 1200, "levels %g %g",
           levels[0], levels[1]);
    /* The maximum's bin, and a value outside the range (nothing dropped). */
    counts[255] = 7;
    CHECK_EQ(iso_hist_drop_padding(counts, 256, min, max, 3000), 7);
    CHECK_EQ(iso_hist_drop_padding(counts, 256, min, max, -3024), 0);
}

/* The histogram counts every sample once, the maximum in the last bin, NaN nowhere. */
static void test_histogram_counts(void)
{
    iso_error err;
    size_t dims[3] = {5, 2, 2};
    iso_volume *vol = iso_vol_create(dims, ISO_F32, 0, &err);
    CHECK(vol != NULL);
    if (!vol)
        return;
    float *s = vol->data;
    for (int i = 0; i < 20; i++)
        s[i] = (float)i;
    s[7] = NAN;
    iso_vol_update_stats(vol);
    uint64_t counts[4];
    iso_hist_compute(vol, 4, counts);
    /* 0..19 without 7, over [0,19], width 4.75: bins hold 0-4, 5-9 (less 7), 10-14, 15-19. */
    CHECK_EQ(counts[0], 5);
    CHECK_EQ(counts[1], 4);
    CHECK_EQ(counts[2], 5);
    CHECK_EQ(counts[3], 5);
    iso_vol_destroy(vol);
}

/* A budget gets the finest ladder tolerance that fits, and the mesh there fits it. */
static void test_budget_picks_finest_fit(void)
{
    iso_error err;
    iso_volume *vol = NULL;
    iso_tree *tree = NULL;
    CHECK_OK(iso_field_load("field:ml:48", NULL, &vol, &err), &err);
    if (!vol)
        return;
    iso_vol_update_stats(vol);
    CHECK_OK(iso_tree_build(vol, 0, NULL, NULL, &tree, &err), &err);
    iso_mesh mesh;
    iso_mesh_init(&mesh);
    iso_extract_stats full = {0}, st = {0};
    iso_extract_params params = {.level = 0.5, .coarsen = ISO_COARSEN_ALL}; /* the ladder's rungs */
    CHECK_OK(iso_extract(tree, &params, &mesh, &full, &err), &err);
    /* Watertight meshes keep every crossing on a fanned node's faces, so even the coarsest
     * rung keeps most of this wavy field's triangles: aim between it and the exact mesh. */
    iso_extract_params coarsest = params;
    coarsest.tolerance = vol->value_max - vol->value_min;
    iso_extract_stats coarse = {0};
    CHECK_OK(iso_extract(tree, &coarsest, &mesh, &coarse, &err), &err);
    CHECKF(coarse.triangles < full.triangles * 9 / 10, "coarsest %zu of %zu triangles",
           coarse.triangles, full.triangles);
    size_t budget = (full.triangles + coarse.triangles) / 2;
    iso_budget_result res;
    CHECK_OK(iso_extract_budget(tree, &params, budget, &mesh, &st, &res, &err), &err);
    CHECKF(res.fits && st.triangles <= budget && mesh.triangle_count == st.triangles,
           "budget %zu: fits %d, %zu triangles", budget, res.fits, st.triangles);
    CHECK(res.tolerance > 0 && st.error_bound <= res.tolerance);
    /* The rung below does not fit: the choice is the finest. */
    iso_extract_params finer = params;
    finer.tolerance = res.tolerance / 2;
    iso_extract_stats st2 = {0};
    CHECK_OK(iso_extract(tree, &finer, &mesh, &st2, &err), &err);
    CHECKF(st2.triangles > budget, "tolerance %g also fits (%zu)", finer.tolerance, st2.triangles);
    /* The cells visited are the search's: the answer's rung and every rung tried before. */
    iso_extract_params chosen = params;
    chosen.tolerance = res.tolerance;
    iso_extract_stats answer = {0};
    CHECK_OK(iso_extract(tree, &chosen, &mesh, &answer, &err), &err);
    CHECKF(res.extractions > 1 && st.cells_visited > answer.cells_visited + full.cells_visited / 2,
           "%d extractions visited %zu cells; the answer's alone %zu, the exact one %zu",
           res.extractions, st.cells_visited, answer.cells_visited, full.cells_visited);
    /* A generous budget keeps the requested tolerance and runs once. */
    CHECK_OK(iso_extract_budget(tree, &params, full.triangles, &mesh, &st, &res, &err), &err);
    CHECK(res.fits && res.tolerance == 0 && res.extractions == 1 && st.triangles == full.triangles);
    CHECK_EQ(st.cells_visited, full.cells_visited);
    /* An impossible budget returns the coarsest rung's mesh and says it does not fit. */
    CHECK_OK(iso_extract_budget(tree, &params, 1, &mesh, &st, &res, &err), &err);
    CHECK(!res.fits || st.triangles <= 1);
    iso_mesh_free(&mesh);
    iso_tree_destroy(tree);
    iso_vol_destroy(vol);
}

int main(void)
{
    CHECK_RUN(test_query_defaults_and_values);
    CHECK_RUN(test_query_rejections);
    CHECK_RUN(test_query_echo_is_bounded);
    CHECK_RUN(test_query_key_normalises);
    CHECK_RUN(test_volume_document);
    CHECK_RUN(test_problem_body);
    CHECK_RUN(test_otsu_levels);
    CHECK_RUN(test_histogram_counts);
    CHECK_RUN(test_levels_skip_padding);
    CHECK_RUN(test_budget_picks_finest_fit);
    CHECK_RUN(test_query_distance);
    CHECK_RUN(test_query_min_component);
    return check_finish();
}
