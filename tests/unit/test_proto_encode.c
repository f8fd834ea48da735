/* test_proto_encode.c: the mesh encoders (PLY, OBJ, STL, Draco, glb, meshopt glb) on hand-built meshes with
 * exact expected bytes, Draco round trips through our decoder and Debian's draco_decoder,
 * the glb container read back, garbage and truncated Draco input, and empty meshes. */
#include <math.h>
#include <meshoptimizer.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>
#include <zlib.h>

#include "check.h"
#include "draco_shim.h"
#include "encode.h"
#include "glb_meshopt_codec.h"

/* ---- helpers ---- */

static uint64_t rng_state = 0x9E3779B97F4A7C15ull;
static uint32_t rng(void) /* xorshift64*, fixed seed: failures reproduce */
{
    rng_state ^= rng_state >> 12;
    rng_state ^= rng_state << 25;
    rng_state ^= rng_state >> 27;
    return (uint32_t)((rng_state * 0x2545F4914F6CDD1Dull) >> 32);
}

/* A mesh owning copies of the given arrays (normals may be NULL). */
static void make_mesh(iso_mesh *m, const float *pos, const float *nrm, size_t nv,
                      const uint32_t *idx, size_t nt)
{
    iso_mesh_init(m);
    int rc = iso_mesh_reserve(m, nv, nt);
    CHECKF(rc == 0, "iso_mesh_reserve: %d", rc);
    if (rc)
        return;
    if (nrm) {
        m->normals = malloc((m->vertex_capacity ? m->vertex_capacity : 1) * 3 * sizeof(float));
        CHECK(m->normals != NULL);
        if (m->normals && nv)
            memcpy(m->normals, nrm, nv * 3 * sizeof(float));
    }
    if (nv)
        memcpy(m->positions, pos, nv * 3 * sizeof(float));
    if (nt)
        memcpy(m->indices, idx, nt * 3 * sizeof(uint32_t));
    m->vertex_count = nv;
    m->triangle_count = nt;
}

static const float tri_pos[] = {0, 0, 0, 1, 0, 0, 0, 1, 0};
static const uint32_t tri_idx[] = {0, 1, 2};

static const float tet_pos[] = {0, 0, 0, 2, 0, 0, 0, 3, 0, 0, 0, 4};
static const uint32_t tet_idx[] = {0, 2, 1, 0, 1, 3, 0, 3, 2, 1, 2, 3};

/* Unit octahedron: normals equal positions. */
static const float oct_pos[] = {1, 0, 0, -1, 0, 0, 0, 1, 0, 0, -1, 0, 0, 0, 1, 0, 0, -1};
static const uint32_t oct_idx[] = {0, 2, 4, 2, 1, 4, 1, 3, 4, 3, 0, 4,
                                   2, 0, 5, 1, 2, 5, 3, 1, 5, 0, 3, 5};

/* Torus of nu x nv quads, 2 * nu * nv triangles (250 x 200: 100,000), radii 30 and 10 mm,
 * normals outward: a closed surface like the iso-surfaces the service sends. */
static void make_torus(iso_mesh *m, size_t nu, size_t nv, int normals)
{
    const double R = 30, r = 10, pi = 3.14159265358979323846;
    size_t n = nu * nv;
    float *pos = malloc(n * 3 * sizeof *pos), *nrm = malloc(n * 3 * sizeof *nrm);
    uint32_t *idx = malloc(2 * n * 3 * sizeof *idx);
    CHECK(pos && nrm && idx);
    if (!pos || !nrm || !idx) {
        free(pos), free(nrm), free(idx);
        iso_mesh_init(m);
        return;
    }
    for (size_t i = 0; i < nu; i++)
        for (size_t j = 0; j < nv; j++) {
            double u = 2 * pi * (double)i / (double)nu, v = 2 * pi * (double)j / (double)nv;
            size_t k = 3 * (i * nv + j);
            pos[k] = (float)((R + r * cos(v)) * cos(u));
            pos[k + 1] = (float)((R + r * cos(v)) * sin(u));
            pos[k + 2] = (float)(r * sin(v));
            nrm[k] = (float)(cos(v) * cos(u));
            nrm[k + 1] = (float)(cos(v) * sin(u));
            nrm[k + 2] = (float)sin(v);
        }
    uint32_t *t = idx;
    for (size_t i = 0; i < nu; i++)
        for (size_t j = 0; j < nv; j++) {
            uint32_t a = (uint32_t)(i * nv + j), b = (uint32_t)(((i + 1) % nu) * nv + j),
                     c = (uint32_t)(((i + 1) % nu) * nv + (j + 1) % nv),
                     d = (uint32_t)(i * nv + (j + 1) % nv);
            *t++ = a, *t++ = b, *t++ = c;
            *t++ = a, *t++ = c, *t++ = d;
        }
    make_mesh(m, pos, normals ? nrm : NULL, n, idx, 2 * n);
    free(pos), free(nrm), free(idx);
}

static uint32_t get_u32(const unsigned char *p)
{
    return (uint32_t)p[0] | (uint32_t)p[1] << 8 | (uint32_t)p[2] << 16 | (uint32_t)p[3] << 24;
}

static float get_f32(const unsigned char *p)
{
    uint32_t v = get_u32(p);
    float f;
    memcpy(&f, &v, sizeof f);
    return f;
}

static double now_ms(void)
{
    struct timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return (double)ts.tv_sec * 1e3 + (double)ts.tv_nsec / 1e6;
}

/* ---- PLY ---- */

static void test_ply_triangle_exact(void)
{
    iso_mesh m;
    iso_error err;
    unsigned char *buf;
    size_t size;
    make_mesh(&m, tri_pos, NULL, 3, tri_idx, 1);
    CHECK_OK(proto_encode_ply(&m, &buf, &size, &err), &err);
    if (!buf) {
        iso_mesh_free(&m);
        return;
    }
    static const char header[] = "ply\n"
                                 "format binary_little_endian 1.0\n"
                                 "element vertex 3\n"
                                 "property float x\n"
                                 "property float y\n"
                                 "property float z\n"
                                 "element face 1\n"
                                 "property list uchar uint vertex_indices\n"
                                 "end_header\n";
    const size_t hlen = sizeof header - 1;
    CHECK_EQ(size, hlen + 3 * 12 + 13);
    CHECK(size >= hlen && memcmp(buf, header, hlen) == 0);
    if (!check_failed()) {
        const unsigned char *p = buf + hlen;
        for (int i = 0; i < 9; i++)
            CHECK(get_f32(p + 4 * i) == tri_pos[i]);
        p += 36;
        CHECK_EQ(p[0], 3);
        for (int i = 0; i < 3; i++)
            CHECK_EQ(get_u32(p + 1 + 4 * i), tri_idx[i]);
    }
    free(buf);
    iso_mesh_free(&m);
}

/* Reads a PLY from proto_encode_ply back, checking every value against the mesh. */
static void check_ply_payload(const iso_mesh *m, const unsigned char *buf, size_t size)
{
    const char *end = "end_header\n";
    const unsigned char *h = NULL;
    for (size_t i = 0; i + strlen(end) <= size && i < 1024; i++)
        if (memcmp(buf + i, end, strlen(end)) == 0) {
            h = buf + i + strlen(end);
            break;
        }
    CHECK(h != NULL);
    if (!h)
        return;
    const size_t stride = m->normals ? 24 : 12;
    CHECK_EQ(size, (size_t)(h - buf) + m->vertex_count * stride + m->triangle_count * 13);
    if (check_failed())
        return;
    size_t bad = 0;
    for (size_t v = 0; v < m->vertex_count; v++)
        for (int c = 0; c < 3; c++) {
            bad += get_f32(h + v * stride + 4 * c) != m->positions[3 * v + c];
            if (m->normals)
                bad += get_f32(h + v * stride + 12 + 4 * c) != m->normals[3 * v + c];
        }
    const unsigned char *f = h + m->vertex_count * stride;
    for (size_t t = 0; t < m->triangle_count; t++, f += 13) {
        bad += f[0] != 3;
        for (int c = 0; c < 3; c++)
            bad += get_u32(f + 1 + 4 * c) != m->indices[3 * t + c];
    }
    CHECK_EQ(bad, 0);
}

static void test_ply_normals_header_and_payload(void)
{
    iso_mesh m;
    iso_error err;
    unsigned char *buf;
    size_t size;
    make_mesh(&m, oct_pos, oct_pos, 6, oct_idx, 8);
    CHECK_OK(proto_encode_ply(&m, &buf, &size, &err), &err);
    if (!buf) {
        iso_mesh_free(&m);
        return;
    }
    static const char header[] = "ply\n"
                                 "format binary_little_endian 1.0\n"
                                 "element vertex 6\n"
                                 "property float x\n"
                                 "property float y\n"
                                 "property float z\n"
                                 "property float nx\n"
                                 "property float ny\n"
                                 "property float nz\n"
                                 "element face 8\n"
                                 "property list uchar uint vertex_indices\n"
                                 "end_header\n";
    CHECK(size >= sizeof header - 1 && memcmp(buf, header, sizeof header - 1) == 0);
    check_ply_payload(&m, buf, size);
    free(buf);
    iso_mesh_free(&m);
}

static void test_ply_100k_triangles_read_back(void)
{
    iso_mesh m;
    iso_error err;
    unsigned char *buf;
    size_t size;
    make_torus(&m, 250, 200, 0);
    CHECK_EQ(m.triangle_count, 100000);
    CHECK_OK(proto_encode_ply(&m, &buf, &size, &err), &err);
    if (buf) {
        check_ply_payload(&m, buf, size);
        free(buf);
    }
    iso_mesh_free(&m);
}

/* ---- OBJ ---- */

static void test_obj_triangle_exact(void)
{
    iso_mesh m;
    iso_error err;
    unsigned char *buf;
    size_t size;
    const float pos[] = {0, 0, 0, 1.5f, -0.25f, 0, 0, 1e-3f, 123456.789f};
    make_mesh(&m, pos, NULL, 3, tri_idx, 1);
    CHECK_OK(proto_encode_obj(&m, &buf, &size, &err), &err);
    if (!buf) {
        iso_mesh_free(&m);
        return;
    }
    static const char want[] = "# isoserve: 3 vertices, 1 triangles\n"
                               "v 0 0 0\n"
                               "v 1.5 -0.25 0\n"
                               "v 0 0.00100000005 123456.789\n"
                               "f 1 2 3\n";
    CHECKF(size == sizeof want - 1 && memcmp(buf, want, size) == 0, "got \"%.*s\"", (int)size,
           (const char *)buf);
    free(buf);
    iso_mesh_free(&m);
}

/* ---- STL ---- */

/* The octahedron: 84 + 8 * 50 bytes, every corner read back bit-exact, every facet
 * normal the outward unit normal (1,1,1)/sqrt(3) up to signs. */
static void test_stl_octahedron_exact(void)
{
    iso_mesh m;
    iso_error err;
    unsigned char *buf;
    size_t size;
    make_mesh(&m, oct_pos, NULL, 6, oct_idx, 8);
    CHECK_OK(proto_encode_stl(&m, &buf, &size, &err), &err);
    if (!buf) {
        iso_mesh_free(&m);
        return;
    }
    CHECK_EQ(size, 84 + 8 * 50);
    CHECK(memcmp(buf, "solid", 5) != 0);
    CHECK_EQ(get_u32(buf + 80), 8);
    for (size_t t = 0; t < 8; t++) {
        const unsigned char *rec = buf + 84 + 50 * t;
        double centroid[3] = {0, 0, 0};
        for (int c = 0; c < 3; c++)
            for (int k = 0; k < 3; k++) {
                float x = get_f32(rec + 12 + 12 * c + 4 * k);
                CHECK(x == oct_pos[3 * oct_idx[3 * t + c] + k]);
                centroid[k] += x;
            }
        double dot = 0;
        for (int k = 0; k < 3; k++) {
            float n = get_f32(rec + 4 * k);
            CHECK(fabsf(fabsf(n) - 0.57735027f) < 1e-6f);
            dot += n * centroid[k];
        }
        CHECK(dot > 0);
        CHECK(rec[48] == 0 && rec[49] == 0);
    }
    free(buf);
    iso_mesh_free(&m);
}

/* Normals give `vn` lines and `f a//a` faces; every printed float reads back bit-exact. */
static void test_obj_normals_round_trip(void)
{
    iso_mesh m;
    iso_error err;
    unsigned char *buf;
    size_t size;
    make_torus(&m, 12, 8, 1);
    CHECK_OK(proto_encode_obj(&m, &buf, &size, &err), &err);
    if (!buf) {
        iso_mesh_free(&m);
        return;
    }
    char *text = malloc(size + 1);
    CHECK(text != NULL);
    if (text) {
        memcpy(text, buf, size);
        text[size] = 0;
        size_t v = 0, n = 0, f = 0, bad = 0;
        for (char *line = strtok(text, "\n"); line; line = strtok(NULL, "\n")) {
            float a[3];
            unsigned long i[6];
            if (sscanf(line, "v %f %f %f", &a[0], &a[1], &a[2]) == 3 && line[1] == ' ') {
                for (int c = 0; c < 3; c++)
                    bad += v < m.vertex_count && a[c] != m.positions[3 * v + c];
                v++;
            } else if (sscanf(line, "vn %f %f %f", &a[0], &a[1], &a[2]) == 3) {
                for (int c = 0; c < 3; c++)
                    bad += n < m.vertex_count && a[c] != m.normals[3 * n + c];
                n++;
            } else if (sscanf(line, "f %lu//%lu %lu//%lu %lu//%lu", &i[0], &i[1], &i[2], &i[3],
                              &i[4], &i[5]) == 6) {
                for (int c = 0; c < 3; c++)
                    bad += f < m.triangle_count && (i[2 * c] != i[2 * c + 1] ||
                                                    i[2 * c] != m.indices[3 * f + c] + 1ul);
                f++;
            } else {
                CHECKF(line[0] == '#', "unexpected line \"%s\"", line);
            }
        }
        CHECK_EQ(v, m.vertex_count);
        CHECK_EQ(n, m.vertex_count);
        CHECK_EQ(f, m.triangle_count);
        CHECK_EQ(bad, 0);
        free(text);
    }
    free(buf);
    iso_mesh_free(&m);
}

/* ---- Draco ---- */

/* Draco's quantization step: the grid is a cube with the largest extent of the bounding
 * box cut into 2^bits - 1 steps; a decoded position is within half a step of its original
 * per axis (plus float rounding, which dominates from about 20 bits on). */
static double quantization_step(const iso_mesh *m, int bits)
{
    float lo[3], hi[3];
    double range = 0;
    iso_mesh_bounds(m, lo, hi);
    for (int c = 0; c < 3; c++)
        if (hi[c] - lo[c] > range)
            range = hi[c] - lo[c];
    return range / (double)((1u << bits) - 1);
}

/* Original vertices bucketed on a coarse grid (cells no smaller than the tolerance, much
 * smaller than the meshes' edges), so a decoded vertex finds its original among the 27
 * cells around it. */
typedef struct cell {
    long long q[3];
    uint32_t id;
} cell;

typedef struct finder {
    cell *cells;
    size_t n;
    double min[3], size;
} finder;

static int cell_cmp(const void *a, const void *b)
{
    const cell *x = a, *y = b;
    for (int c = 0; c < 3; c++)
        if (x->q[c] != y->q[c])
            return x->q[c] < y->q[c] ? -1 : 1;
    return 0;
}

static void cell_key(const finder *f, const float *p, long long q[3])
{
    for (int c = 0; c < 3; c++)
        q[c] = (long long)floor(((double)p[c] - f->min[c]) / f->size);
}

static int finder_init(finder *f, const iso_mesh *m, double min_size)
{
    float lo[3], hi[3];
    iso_mesh_bounds(m, lo, hi);
    double range = 0;
    for (int c = 0; c < 3; c++) {
        f->min[c] = lo[c];
        if (hi[c] - lo[c] > range)
            range = hi[c] - lo[c];
    }
    f->size = fmax(range > 0 ? range / 1024 : 1, min_size);
    f->n = m->vertex_count;
    f->cells = malloc((f->n ? f->n : 1) * sizeof *f->cells);
    if (!f->cells)
        return -1;
    for (size_t v = 0; v < f->n; v++) {
        cell_key(f, m->positions + 3 * v, f->cells[v].q);
        f->cells[v].id = (uint32_t)v;
    }
    qsort(f->cells, f->n, sizeof *f->cells, cell_cmp);
    return 0;
}

/* The original vertex nearest to p (max-norm), or -1 if none is within the 27 cells. */
static long finder_nearest(const finder *f, const iso_mesh *m, const float *p, double *dist)
{
    long best = -1;
    long long q[3];
    cell_key(f, p, q);
    *dist = INFINITY;
    for (int d = 0; d < 27; d++) {
        cell key = {{q[0] + d % 3 - 1, q[1] + d / 3 % 3 - 1, q[2] + d / 9 - 1}, 0};
        const cell *hit = bsearch(&key, f->cells, f->n, sizeof *f->cells, cell_cmp);
        if (!hit)
            continue;
        while (hit > f->cells && cell_cmp(hit - 1, &key) == 0)
            hit--;
        for (; hit < f->cells + f->n && cell_cmp(hit, &key) == 0; hit++) {
            const float *o = m->positions + 3 * hit->id;
            double e = 0;
            for (int c = 0; c < 3; c++)
                e = fmax(e, fabs((double)p[c] - (double)o[c]));
            if (e < *dist)
                *dist = e, best = (long)hit->id;
        }
    }
    return best;
}

/* Triangles as sorted triples of original vertex ids, each rotated to start at its
 * smallest id so that winding still counts. */
static int tri_cmp(const void *a, const void *b)
{
    const uint32_t *x = a, *y = b;
    for (int c = 0; c < 3; c++)
        if (x[c] != y[c])
            return x[c] < y[c] ? -1 : 1;
    return 0;
}

static void canonical_triangles(uint32_t *t, size_t n)
{
    for (size_t i = 0; i < n; i++) {
        uint32_t *f = t + 3 * i;
        while (f[0] > f[1] || f[0] > f[2]) {
            uint32_t s = f[0];
            f[0] = f[1], f[1] = f[2], f[2] = s;
        }
    }
    qsort(t, n, 3 * sizeof *t, tri_cmp);
}

/* Checks that `dec` is `orig` after Draco: the same counts, every decoded position within
 * half a quantization step of its original (matched by position, since edgebreaker
 * reorders; each original matched once), normals within `normal_dot` of the original's,
 * and the same triangles with the same winding. */
static void check_draco_match(const iso_mesh *orig, const iso_mesh *dec, int bits,
                              double normal_dot)
{
    CHECK_EQ(dec->vertex_count, orig->vertex_count);
    CHECK_EQ(dec->triangle_count, orig->triangle_count);
    CHECK_EQ(dec->normals != NULL, orig->normals != NULL);
    if (check_failed())
        return;
    const size_t nv = orig->vertex_count, nt = orig->triangle_count;
    const double step = quantization_step(orig, bits);
    /* Half a step, plus float rounding of coordinates up to the mesh's size. */
    const double tol = step / 2 * (1 + 1e-6) + 1e-6 * step * (double)(1u << bits);
    finder f = {0};
    uint32_t *match = malloc((nv ? nv : 1) * sizeof *match);
    unsigned char *seen = calloc(nv ? nv : 1, 1);
    uint32_t *ta = malloc((nt ? nt : 1) * 3 * sizeof *ta);
    uint32_t *tb = malloc((nt ? nt : 1) * 3 * sizeof *tb);
    CHECK(match && seen && ta && tb && finder_init(&f, orig, tol) == 0);
    if (check_failed())
        goto done;
    size_t unmatched = 0, twice = 0, far = 0, bent = 0;
    double worst = 0;
    for (size_t v = 0; v < nv; v++) {
        double e;
        long id = finder_nearest(&f, orig, dec->positions + 3 * v, &e);
        if (id < 0) {
            unmatched++;
            match[v] = 0;
            continue;
        }
        match[v] = (uint32_t)id;
        twice += seen[id]++ != 0;
        worst = fmax(worst, e);
        far += e > tol;
        if (orig->normals) {
            const float *a = orig->normals + 3 * id, *b = dec->normals + 3 * v;
            bent += a[0] * b[0] + a[1] * b[1] + a[2] * b[2] < normal_dot;
        }
    }
    CHECKF(unmatched == 0, "%zu decoded vertices near no original", unmatched);
    CHECKF(twice == 0, "%zu originals matched twice", twice);
    CHECKF(far == 0, "%zu vertices beyond half a step (%g): worst %g", far, step / 2, worst);
    CHECKF(bent == 0, "%zu normals off by more than acos(%g)", bent, normal_dot);
    if (check_failed())
        goto done;
    memcpy(ta, orig->indices, nt * 3 * sizeof *ta);
    for (size_t i = 0; i < 3 * nt; i++)
        tb[i] = match[dec->indices[i]];
    canonical_triangles(ta, nt);
    canonical_triangles(tb, nt);
    CHECK(memcmp(ta, tb, nt * 3 * sizeof *ta) == 0);
done:
    free(f.cells), free(match), free(seen), free(ta), free(tb);
}

static void draco_round_trip(const iso_mesh *m, const proto_encode_options *opt,
                             double normal_dot)
{
    iso_error err;
    unsigned char *buf;
    size_t size;
    iso_mesh dec;
    CHECK_OK(proto_encode_draco(m, opt, &buf, &size, &err), &err);
    if (!buf)
        return;
    CHECK_OK(proto_draco_decode(buf, size, &dec, &err), &err);
    if (!check_failed())
        check_draco_match(m, &dec, opt ? opt->position_bits : PROTO_POSITION_BITS_DEFAULT,
                          normal_dot);
    iso_mesh_free(&dec);
    free(buf);
}

static void test_draco_round_trip_small_meshes(void)
{
    iso_mesh m;
    make_mesh(&m, tri_pos, NULL, 3, tri_idx, 1);
    draco_round_trip(&m, NULL, 0);
    iso_mesh_free(&m);
    make_mesh(&m, tet_pos, NULL, 4, tet_idx, 4);
    draco_round_trip(&m, NULL, 0);
    iso_mesh_free(&m);
    make_mesh(&m, oct_pos, oct_pos, 6, oct_idx, 8);
    draco_round_trip(&m, NULL, 0.9999);
    iso_mesh_free(&m);
}

/* Every position width and speed: edgebreaker (0..9) and the sequential coder (10). */
static void test_draco_round_trip_bits_and_speeds(void)
{
    iso_mesh m;
    make_torus(&m, 40, 30, 1);
    proto_encode_options opt;
    proto_encode_options_init(&opt);
    for (opt.position_bits = PROTO_POSITION_BITS_MIN;
         opt.position_bits <= PROTO_POSITION_BITS_MAX && !check_failed(); opt.position_bits += 4)
        draco_round_trip(&m, &opt, 0.999);
    proto_encode_options_init(&opt);
    for (opt.speed = PROTO_DRACO_SPEED_MIN; opt.speed <= PROTO_DRACO_SPEED_MAX && !check_failed();
         opt.speed++)
        draco_round_trip(&m, &opt, 0.9999);
    iso_mesh_free(&m);
}

/* Speed 10 keeps vertex and triangle order, so index i decodes near vertex i. */
static void test_draco_speed_10_keeps_order(void)
{
    iso_mesh m, dec;
    iso_error err;
    unsigned char *buf;
    size_t size;
    proto_encode_options opt;
    proto_encode_options_init(&opt);
    opt.speed = 10;
    make_mesh(&m, tet_pos, NULL, 4, tet_idx, 4);
    CHECK_OK(proto_encode_draco(&m, &opt, &buf, &size, &err), &err);
    if (!buf) {
        iso_mesh_free(&m);
        return;
    }
    CHECK_OK(proto_draco_decode(buf, size, &dec, &err), &err);
    if (!check_failed()) {
        double step = quantization_step(&m, opt.position_bits);
        CHECK_EQ(dec.vertex_count, 4);
        CHECK_EQ(dec.triangle_count, 4);
        for (size_t i = 0; i < 12 && !check_failed(); i++) {
            CHECK_NEAR(dec.positions[i], m.positions[i], step / 2 * 1.0001);
            CHECK_EQ(dec.indices[i], m.indices[i]);
        }
    }
    iso_mesh_free(&dec);
    free(buf);
    iso_mesh_free(&m);
}

/* The 100k-triangle torus: round trip, size against raw float32 + uint32 and encode time. */
static void test_draco_100k_triangles(void)
{
    iso_mesh m;
    iso_error err;
    unsigned char *buf;
    size_t size;
    make_torus(&m, 250, 200, 0);
    double t0 = now_ms();
    CHECK_OK(proto_encode_draco(&m, NULL, &buf, &size, &err), &err);
    double t1 = now_ms();
    if (!buf) {
        iso_mesh_free(&m);
        return;
    }
    size_t raw = m.vertex_count * 12 + m.triangle_count * 12;
    printf("  info: torus %zu vertices, %zu triangles, qp 14 speed 5: draco %zu bytes, raw "
           "%zu bytes (%.1f%%), encode %.1f ms\n", m.vertex_count, m.triangle_count, size, raw,
           100.0 * (double)size / (double)raw, t1 - t0);
    CHECK(size < raw / 4);
    iso_mesh dec;
    t0 = now_ms();
    CHECK_OK(proto_draco_decode(buf, size, &dec, &err), &err);
    t1 = now_ms();
    printf("  info: decode %.1f ms\n", t1 - t0);
    if (!check_failed())
        check_draco_match(&m, &dec, PROTO_POSITION_BITS_DEFAULT, 0);
    iso_mesh_free(&dec);
    free(buf);

    /* With normals, as the service sends them. */
    iso_mesh_free(&m);
    make_torus(&m, 250, 200, 1);
    t0 = now_ms();
    CHECK_OK(proto_encode_draco(&m, NULL, &buf, &size, &err), &err);
    t1 = now_ms();
    if (buf) {
        printf("  info: with normals (qn 10): draco %zu bytes, raw %zu bytes, encode %.1f ms\n",
               size, m.vertex_count * 24 + m.triangle_count * 12, t1 - t0);
        CHECK_OK(proto_draco_decode(buf, size, &dec, &err), &err);
        if (!check_failed())
            check_draco_match(&m, &dec, PROTO_POSITION_BITS_DEFAULT, 0.9999);
        iso_mesh_free(&dec);
        free(buf);
    }
    iso_mesh_free(&m);
}

static int write_file(const char *path, const unsigned char *buf, size_t size)
{
    FILE *f = fopen(path, "wb");
    if (!f)
        return -1;
    size_t n = fwrite(buf, 1, size, f);
    return (fclose(f) == 0 && n == size) ? 0 : -1;
}

/* Reads "element vertex N" and "element face T" from a PLY header. */
static int ply_counts(const char *path, long *vertices, long *faces)
{
    FILE *f = fopen(path, "rb");
    char line[256];
    *vertices = *faces = -1;
    if (!f)
        return -1;
    while (fgets(line, sizeof line, f) && strncmp(line, "end_header", 10) != 0) {
        sscanf(line, "element vertex %ld", vertices);
        sscanf(line, "element face %ld", faces);
    }
    fclose(f);
    return 0;
}

/* The same bytes decode with Debian's draco_decoder (the reference implementation). */
static void test_draco_decodes_with_draco_decoder(void)
{
    if (system("command -v draco_decoder >/dev/null 2>&1") != 0) {
        check_skip("draco_decoder is not installed (Debian package draco)");
        return;
    }
    iso_mesh m;
    make_torus(&m, 250, 200, 1);
    const iso_mesh *meshes[2] = {&m, NULL};
    iso_mesh oct;
    make_mesh(&oct, oct_pos, NULL, 6, oct_idx, 8);
    meshes[1] = &oct;
    for (int i = 0; i < 2 && !check_failed(); i++) {
        iso_error err;
        unsigned char *buf;
        size_t size;
        char drc[512], ply[512], cmd[1200];
        CHECK_OK(proto_encode_draco(meshes[i], NULL, &buf, &size, &err), &err);
        if (!buf)
            break;
        snprintf(drc, sizeof drc, "%s/mesh%d.drc", check_temp_dir(), i);
        snprintf(ply, sizeof ply, "%s/mesh%d.ply", check_temp_dir(), i);
        CHECK(write_file(drc, buf, size) == 0);
        free(buf);
        snprintf(cmd, sizeof cmd, "draco_decoder -i '%s' -o '%s' >/dev/null 2>&1", drc, ply);
        CHECKF(system(cmd) == 0, "%s failed", cmd);
        long nv, nf;
        CHECK(ply_counts(ply, &nv, &nf) == 0);
        CHECK_EQ(nv, meshes[i]->vertex_count);
        CHECK_EQ(nf, meshes[i]->triangle_count);
    }
    iso_mesh_free(&m);
    iso_mesh_free(&oct);
}

static void test_draco_refuses_bad_options_and_meshes(void)
{
    iso_mesh m;
    iso_error err;
    unsigned char *buf = (unsigned char *)&err; /* not NULL, to see the encoders clear it */
    size_t size = 1;
    proto_encode_options opt;
    make_mesh(&m, tet_pos, NULL, 4, tet_idx, 4);
    const int bad[][3] = {{7, 10, 5}, {25, 10, 5}, {14, 5, 5}, {14, 17, 5}, {14, 10, -2},
                          {14, 10, 11}};
    for (size_t i = 0; i < sizeof bad / sizeof bad[0]; i++) {
        opt.position_bits = bad[i][0], opt.normal_bits = bad[i][1], opt.speed = bad[i][2];
        CHECK_EQ(proto_encode_draco(&m, &opt, &buf, &size, &err), ISO_E_ARGUMENT);
        CHECK(buf == NULL && size == 0);
        CHECK_EQ(proto_encode_glb(&m, &opt, &buf, &size, &err), ISO_E_ARGUMENT);
    }
    m.indices[5] = 4; /* one past the last vertex */
    CHECK_EQ(proto_encode_draco(&m, NULL, &buf, &size, &err), ISO_E_ARGUMENT);
    CHECK_EQ(proto_encode_glb(&m, NULL, &buf, &size, &err), ISO_E_ARGUMENT);
    CHECK_EQ(proto_encode_ply(&m, &buf, &size, &err), ISO_E_ARGUMENT);
    CHECK_EQ(proto_encode_obj(&m, &buf, &size, &err), ISO_E_ARGUMENT);
    CHECK(strstr(err.message, "index 4") != NULL);
    m.indices[5] = 3;
    m.positions[4] = NAN;
    CHECK_EQ(proto_encode_draco(&m, NULL, &buf, &size, &err), ISO_E_ARGUMENT);
    CHECK_EQ(proto_encode_glb(&m, NULL, &buf, &size, &err), ISO_E_ARGUMENT);
    iso_mesh_free(&m);
}

/* Non-manifold and unused vertices: a bowtie of two tetrahedra sharing vertex 0, plus a
 * vertex no triangle uses and a degenerate triangle. Edgebreaker drops the unused vertex
 * and splits the shared one; what the shim reports must be what a decoder gets. */
static void test_draco_info_matches_decoder(void)
{
    const float pos[] = {0, 0, 0, 1, 0, 0, 0, 1, 0, 0, 0, 1, -1, 0, 0, 0, -1, 0, 0, 0, -1,
                         9, 9, 9};
    const uint32_t idx[] = {0, 2, 1, 0, 1, 3, 0, 3, 2, 1, 2, 3,
                            0, 4, 5, 0, 5, 6, 0, 6, 4, 4, 6, 5, 1, 1, 2};
    iso_mesh m;
    make_mesh(&m, pos, NULL, 8, idx, 9);
    proto_encode_options opt;
    proto_encode_options_init(&opt);
    for (opt.speed = 0; opt.speed <= 10 && !check_failed(); opt.speed += 5) {
        iso_error err;
        unsigned char *buf;
        size_t size;
        proto_draco_info info;
        iso_mesh dec;
        CHECK_OK(proto_draco_encode_info(&m, &opt, &buf, &size, &info, &err), &err);
        if (!buf)
            break;
        CHECK_OK(proto_draco_decode(buf, size, &dec, &err), &err);
        CHECK_EQ(info.points, dec.vertex_count);
        CHECK_EQ(info.faces, dec.triangle_count);
        CHECK_EQ(info.speed, opt.speed);
        CHECK_EQ(dec.triangle_count, 8);
        CHECK(dec.vertex_count >= 7 && dec.vertex_count <= 8);
        float lo[3], hi[3];
        iso_mesh_bounds(&dec, lo, hi);
        for (int c = 0; c < 3; c++)
            CHECK(info.min[c] == lo[c] && info.max[c] == hi[c]);
        iso_mesh_free(&dec);
        free(buf);
    }
    iso_mesh_free(&m);
}

/* Encodes m with speed `speed` (NULL options but the speed), checks the speed reported and
 * the round trip, and returns the size. */
static size_t encode_at_speed(const iso_mesh *m, int speed, int want, const char *what)
{
    iso_error err;
    unsigned char *buf;
    size_t size = 0;
    proto_draco_info info;
    proto_encode_options opt;
    proto_encode_options_init(&opt);
    opt.speed = speed;
    CHECK_OK(proto_draco_encode_info(m, &opt, &buf, &size, &info, &err), &err);
    CHECKF(info.speed == want, "%s: speed %d, want %d", what, info.speed, want);
    CHECK_EQ(info.faces, m->triangle_count);
    printf("  info: %s, %zu triangles, speed %d: %zu bytes (%.2f per triangle)\n", what,
           m->triangle_count, info.speed, size, (double)size / (double)m->triangle_count);
    free(buf);
    draco_round_trip(m, &opt, 0.999);
    return size;
}

/* Speed auto: 8 up to PROTO_DRACO_AUTO_SEQUENTIAL triangles, the sequential coder above with
 * its indices delta- and entropy-coded (as varints they alone take 9 bytes per triangle
 * here). A stream too small for Draco's sequential decoder (3 bytes per face) is made
 * again: at 8 under auto, with raw indices at 10 by name. All decode back to the mesh. */
static void test_draco_auto_speed(void)
{
    CHECK_EQ(proto_draco_auto_speed(0), 8);
    CHECK_EQ(proto_draco_auto_speed(PROTO_DRACO_AUTO_SEQUENTIAL), 8);
    CHECK_EQ(proto_draco_auto_speed(PROTO_DRACO_AUTO_SEQUENTIAL + 1), 10);
    iso_mesh m;
    make_torus(&m, 40, 30, 1);
    encode_at_speed(&m, PROTO_DRACO_SPEED_AUTO, 8, "small torus");
    iso_mesh_free(&m);
    make_torus(&m, 402, 250, 1); /* 201,000 triangles */
    size_t smooth = encode_at_speed(&m, PROTO_DRACO_SPEED_AUTO, 8, "smooth torus, too compressible");
    size_t raw = encode_at_speed(&m, 10, 10, "smooth torus at 10");
    CHECK(raw > 9 * m.triangle_count && smooth < 3 * m.triangle_count);
    for (size_t i = 0; i < 3 * m.vertex_count; i++) /* +-0.5 of an 80-unit torus */
        m.positions[i] += (float)((double)(rng() % 1001) / 1000.0 - 0.5);
    size_t rough = encode_at_speed(&m, PROTO_DRACO_SPEED_AUTO, 10, "jittered torus");
    CHECKF(rough >= 3 * m.triangle_count && rough < 6 * m.triangle_count, "%zu bytes", rough);
    iso_mesh_free(&m);
}

/* Renumbers m's vertices by a random permutation: the same surface, indices all over. */
static void shuffle_vertices(iso_mesh *m)
{
    size_t n = m->vertex_count;
    uint32_t *perm = malloc((n ? n : 1) * sizeof *perm);
    float *pos = malloc((n ? n : 1) * 3 * sizeof *pos);
    float *nrm = m->normals ? malloc(n * 3 * sizeof *nrm) : NULL;
    CHECK(perm && pos && (nrm || !m->normals));
    if (check_failed()) {
        free(perm), free(pos), free(nrm);
        return;
    }
    for (size_t i = 0; i < n; i++)
        perm[i] = (uint32_t)i;
    for (size_t i = n; i > 1; i--) {
        size_t j = rng() % i;
        uint32_t s = perm[i - 1];
        perm[i - 1] = perm[j], perm[j] = s;
    }
    for (size_t v = 0; v < n; v++) {
        memcpy(pos + 3 * perm[v], m->positions + 3 * v, 3 * sizeof *pos);
        if (nrm)
            memcpy(nrm + 3 * perm[v], m->normals + 3 * v, 3 * sizeof *nrm);
    }
    for (size_t i = 0; i < 3 * m->triangle_count; i++)
        m->indices[i] = perm[m->indices[i]];
    memcpy(m->positions, pos, n * 3 * sizeof *pos);
    if (nrm)
        memcpy(m->normals, nrm, n * 3 * sizeof *nrm);
    free(perm), free(pos), free(nrm);
}

/* Under auto the sequential coder gets the points numbered in the order triangles first
 * use them (each triangle started at its cheapest corner), whatever the mesh's own order:
 * the decoded indices never skip ahead, the mesh decodes back whole, and the index deltas
 * of a shuffled mesh shrink. speed=10 by name keeps the shuffled order (and its bytes). */
static void test_draco_auto_numbers_by_first_use(void)
{
    iso_mesh m, dec;
    iso_error err;
    unsigned char *buf = NULL, *kept = NULL;
    size_t size = 0, kept_size = 0;
    proto_encode_options opt;
    proto_encode_options_init(&opt);
    make_torus(&m, 402, 250, 1); /* 201,000 triangles: auto takes the sequential coder */
    for (size_t i = 0; i < 3 * m.vertex_count; i++)
        m.positions[i] += (float)((double)(rng() % 1001) / 1000.0 - 0.5);
    shuffle_vertices(&m);
    proto_draco_info info;
    CHECK_OK(proto_draco_encode_info(&m, &opt, &buf, &size, &info, &err), &err);
    opt.speed = 10;
    CHECK_OK(proto_encode_draco(&m, &opt, &kept, &kept_size, &err), &err);
    if (check_failed())
        goto done;
    CHECK_EQ(info.speed, 10);
    CHECK_EQ(info.points, 100500);
    CHECK_EQ(info.faces, 201000);
    printf("  info: shuffled torus, 201000 triangles: auto %zu bytes, speed=10 in the mesh's "
           "order %zu bytes\n", size, kept_size);
    CHECKF(size * 10 < kept_size * 7, "auto %zu bytes, kept order %zu", size, kept_size);
    CHECK_OK(proto_draco_decode(buf, size, &dec, &err), &err);
    if (check_failed())
        goto done;
    uint32_t next = 0;
    size_t ahead = 0;
    for (size_t i = 0; i < 3 * dec.triangle_count; i++) {
        ahead += dec.indices[i] > next;
        if (dec.indices[i] == next)
            next++;
    }
    CHECKF(ahead == 0, "%zu indices skip ahead of first use", ahead);
    CHECK_EQ(next, 100500);
    check_draco_match(&m, &dec, opt.position_bits, 0.9999);
    iso_mesh_free(&dec);
done:
    free(buf);
    free(kept);
    iso_mesh_free(&m);
}

/* The sequential coder on two threads (connectivity and attributes apart, joined) writes
 * the bytes one thread writes: under auto and at speed 10 by name, with and without
 * normals; and they decode back to the mesh. Auto without normals makes a joined stream
 * under 3 bytes a face, which goes to edgebreaker (speed 8) as on one thread. */
static void test_draco_split_matches_one_encoder(void)
{
    iso_mesh m;
    make_torus(&m, 402, 250, 1); /* 201,000 triangles: auto takes the sequential coder */
    for (size_t i = 0; i < 3 * m.vertex_count; i++) /* rough enough for 3 bytes a face */
        m.positions[i] += (float)((double)(rng() % 3001) / 1000.0 - 1.5);
    shuffle_vertices(&m);
    for (int pass = 0; pass < 4 && !check_failed(); pass++) {
        if (pass == 2) { /* the same without normals */
            free(m.normals);
            m.normals = NULL;
        }
        proto_encode_options opt;
        proto_encode_options_init(&opt);
        opt.speed = pass % 2 ? 10 : PROTO_DRACO_SPEED_AUTO;
        unsigned char *one = NULL, *two = NULL;
        size_t one_size = 0, two_size = 0;
        proto_draco_info one_info, two_info;
        iso_error err;
        opt.threads = 1;
        CHECK_OK(proto_draco_encode_info(&m, &opt, &one, &one_size, &one_info, &err), &err);
        opt.threads = 2;
        CHECK_OK(proto_draco_encode_info(&m, &opt, &two, &two_size, &two_info, &err), &err);
        if (!check_failed()) {
            CHECKF(one_size == two_size && memcmp(one, two, one_size) == 0,
                   "pass %d: %zu bytes on one thread, %zu on two", pass, one_size, two_size);
            CHECK(memcmp(&one_info, &two_info, sizeof one_info) == 0);
            printf("  info: split pass %d: speed %d, %zu bytes\n", pass, two_info.speed, two_size);
            CHECK_EQ(two_info.speed, pass == 2 ? 8 : 10);
            CHECK_EQ(two_info.points, 100500);
            CHECK_EQ(two_info.faces, 201000);
        }
        iso_mesh dec;
        if (!check_failed()) {
            CHECK_OK(proto_draco_decode(two, two_size, &dec, &err), &err);
            if (!check_failed()) {
                check_draco_match(&m, &dec, opt.position_bits, 0.9999);
                iso_mesh_free(&dec);
            }
        }
        free(one);
        free(two);
    }
    iso_mesh_free(&m);
}

static void test_draco_decoder_refuses_garbage(void)
{
    iso_mesh m, dec;
    iso_error err;
    unsigned char *buf;
    size_t size;
    unsigned char junk[4096];

    /* Random bytes, and random bytes behind a valid Draco header. */
    for (int i = 0; i < 300 && !check_failed(); i++) {
        size_t n = 1 + rng() % sizeof junk;
        for (size_t k = 0; k < n; k++)
            junk[k] = (unsigned char)rng();
        if (i % 2 && n > 11)
            memcpy(junk, "DRACO\x02\x02\x01\x01\x00\x00", 11); /* mesh, edgebreaker */
        int rc = proto_draco_decode(junk, n, &dec, &err);
        CHECKF(rc == ISO_E_FORMAT, "garbage %d (%zu bytes) gave %d", i, n, rc);
        CHECK(dec.vertex_count == 0 && dec.positions == NULL);
        iso_mesh_free(&dec);
    }
    CHECK_EQ(proto_draco_decode("", 0, &dec, &err), ISO_E_FORMAT);

    /* Every truncation of a valid stream of a small mesh and a sample of a large one. */
    make_mesh(&m, oct_pos, oct_pos, 6, oct_idx, 8);
    for (int big = 0; big < 2 && !check_failed(); big++) {
        if (big) {
            iso_mesh_free(&m);
            make_torus(&m, 60, 40, 1);
        }
        CHECK_OK(proto_encode_draco(&m, NULL, &buf, &size, &err), &err);
        if (!buf)
            break;
        size_t step = big ? 1 + size / 300 : 1;
        for (size_t n = 0; n < size; n += n < 64 ? 1 : step) {
            int rc = proto_draco_decode(buf, n, &dec, &err);
            CHECKF(rc == ISO_E_FORMAT, "prefix of %zu of %zu bytes gave %d", n, size, rc);
            iso_mesh_free(&dec);
        }
        free(buf);
    }
    iso_mesh_free(&m);
}

/* Flipped bytes in a valid stream may still decode (Draco has no checksum); what must hold
 * is no crash, and a decoded mesh whose indices are in range. */
static void test_draco_decoder_survives_corruption(void)
{
    iso_mesh m, dec;
    iso_error err;
    unsigned char *buf;
    size_t size;
    make_torus(&m, 30, 20, 1);
    CHECK_OK(proto_encode_draco(&m, NULL, &buf, &size, &err), &err);
    if (!buf) {
        iso_mesh_free(&m);
        return;
    }
    unsigned char *copy = malloc(size);
    CHECK(copy != NULL);
    size_t decoded = 0;
    for (int i = 0; copy && i < 2000 && !check_failed(); i++) {
        memcpy(copy, buf, size);
        for (int k = 0; k < 1 + i % 4; k++)
            copy[rng() % size] ^= (unsigned char)(1u << (rng() % 8));
        int rc = proto_draco_decode(copy, size, &dec, &err);
        CHECKF(rc == 0 || rc == ISO_E_FORMAT, "corruption %d gave %d", i, rc);
        if (rc == 0) {
            decoded++;
            CHECK(proto_mesh_check(&dec, 0, &err) == 0);
        }
        iso_mesh_free(&dec);
    }
    printf("  info: %zu of 2000 corrupted streams still decoded\n", decoded);
    free(copy);
    free(buf);
    iso_mesh_free(&m);
}

/* ---- glb ---- */

/* The number after `key` in `json` (first occurrence after `from`), or -1. */
static double json_number(const char *json, const char *from, const char *key)
{
    const char *p = strstr(from ? from : json, key);
    return p ? strtod(p + strlen(key), NULL) : -1;
}

/* Parses a glb back: header, chunks, JSON; returns the JSON (malloc'd, NUL-terminated) and
 * the BIN chunk (pointer into buf, or NULL). */
static char *glb_parse(const unsigned char *buf, size_t size, const unsigned char **bin,
                       size_t *bin_size)
{
    *bin = NULL;
    *bin_size = 0;
    CHECK(size >= 20);
    if (size < 20)
        return NULL;
    CHECK(memcmp(buf, "glTF", 4) == 0);
    CHECK_EQ(get_u32(buf + 4), 2);
    CHECK_EQ(get_u32(buf + 8), size);
    CHECK_EQ(size % 4, 0);
    size_t jlen = get_u32(buf + 12);
    CHECK(memcmp(buf + 16, "JSON", 4) == 0);
    CHECK(jlen % 4 == 0 && 20 + jlen <= size);
    if (check_failed())
        return NULL;
    const unsigned char *j = buf + 20;
    size_t at = 20 + jlen;
    if (at < size) {
        CHECK(at + 8 <= size);
        if (check_failed())
            return NULL;
        *bin_size = get_u32(buf + at);
        CHECK(memcmp(buf + at + 4, "BIN\0", 4) == 0);
        CHECK(*bin_size % 4 == 0 && at + 8 + *bin_size == size);
        *bin = buf + at + 8;
    }
    /* JSON padding is spaces; the text itself has no NUL. */
    CHECK(memchr(j, 0, jlen) == NULL);
    char *json = malloc(jlen + 1);
    CHECK(json != NULL);
    if (json) {
        memcpy(json, j, jlen);
        json[jlen] = 0;
        CHECK(jlen == 0 || json[jlen - 1] == '}' || json[jlen - 1] == ' ');
    }
    return json;
}

static void check_glb(const iso_mesh *m, const proto_encode_options *opt)
{
    iso_error err;
    unsigned char *buf;
    size_t size, bin_size;
    const unsigned char *bin;
    CHECK_OK(proto_encode_glb(m, opt, &buf, &size, &err), &err);
    if (!buf)
        return;
    char *json = glb_parse(buf, size, &bin, &bin_size);
    if (!json) {
        free(buf);
        return;
    }
    CHECK(strstr(json, "\"extensionsUsed\":[\"KHR_draco_mesh_compression\"]") != NULL);
    CHECK(strstr(json, "\"extensionsRequired\":[\"KHR_draco_mesh_compression\"]") != NULL);
    CHECK(strstr(json, "\"asset\":{\"version\":\"2.0\"") != NULL);
    CHECK(bin != NULL);
    const char *ext = strstr(json, "\"KHR_draco_mesh_compression\":{\"bufferView\":0");
    CHECK(ext != NULL);
    const char *views = strstr(json, "\"bufferViews\":");
    CHECK(views != NULL);
    if (!bin || !ext || !views)
        goto done;
    double off = json_number(json, views, "\"byteOffset\":");
    double len = json_number(json, views, "\"byteLength\":");
    double buflen = json_number(json, strstr(json, "\"buffers\":"), "\"byteLength\":");
    CHECK(off >= 0 && len > 0 && off + len <= (double)bin_size);
    CHECK(buflen >= off + len && buflen <= (double)bin_size && buflen + 4 > (double)bin_size);
    if (check_failed())
        goto done;
    iso_mesh dec;
    CHECK_OK(proto_draco_decode(bin + (size_t)off, (size_t)len, &dec, &err), &err);
    if (!check_failed()) {
        /* Accessors: POSITION (with min/max equal to the decoded bounds, bit for bit),
         * NORMAL when present, indices. */
        const char *acc = strstr(json, "\"accessors\":");
        CHECK(acc != NULL);
        CHECK(strstr(json, "\"componentType\":5126,\"count\":") != NULL);
        CHECK(strstr(json, "\"componentType\":5125,\"count\":") != NULL);
        CHECK_EQ(json_number(json, acc, "\"count\":"), dec.vertex_count);
        CHECK_EQ(json_number(json, strstr(json, "5125"), "\"count\":"), 3 * dec.triangle_count);
        CHECK_EQ(strstr(json, "\"NORMAL\"") != NULL, m->normals != NULL);
        float lo[3], hi[3];
        iso_mesh_bounds(&dec, lo, hi);
        const char *p = acc ? strstr(acc, "\"min\":[") : NULL, *q = acc ? strstr(acc, "\"max\":[") : NULL;
        CHECK(p && q);
        if (p && q) {
            char *e;
            p += 7, q += 7;
            for (int c = 0; c < 3; c++) {
                float a = strtof(p, &e), b;
                p = e + 1;
                b = strtof(q, &e);
                q = e + 1;
                CHECKF(a == lo[c] && b == hi[c], "axis %d: min/max %.9g %.9g, decoded %.9g %.9g",
                       c, a, b, lo[c], hi[c]);
            }
        }
        CHECK_EQ(dec.triangle_count, m->triangle_count);
    }
    iso_mesh_free(&dec);
    /* BIN padding is zeros. */
    for (size_t i = (size_t)(off + len); i < bin_size; i++)
        CHECK_EQ(bin[i], 0);
done:
    free(json);
    free(buf);
}

static void test_glb_container(void)
{
    iso_mesh m;
    make_mesh(&m, tri_pos, NULL, 3, tri_idx, 1);
    check_glb(&m, NULL);
    iso_mesh_free(&m);
    make_mesh(&m, oct_pos, oct_pos, 6, oct_idx, 8);
    check_glb(&m, NULL);
    iso_mesh_free(&m);
    proto_encode_options opt;
    proto_encode_options_init(&opt);
    make_torus(&m, 250, 200, 1);
    for (opt.speed = 0; opt.speed <= 10 && !check_failed(); opt.speed += 5)
        check_glb(&m, &opt);
    iso_mesh_free(&m);
}

/* ---- glb with EXT_meshopt_compression ---- */

/* The three numbers of "key":[a,b,c] in json. */
static int json_vec3_of(const char *json, const char *key, double v[3])
{
    const char *p = strstr(json, key);
    if (!p)
        return -1;
    p += strlen(key);
    for (int c = 0; c < 3; c++) {
        char *e;
        v[c] = strtod(p, &e);
        p = e + 1;
    }
    return 0;
}

/* The view of an EXT_meshopt_compression object, decoded with meshoptimizer's own decoders
 * into out (count * stride bytes). */
static void *meshopt_view(const char *ext, const unsigned char *bin, size_t bin_size,
                          size_t *count, size_t *stride)
{
    double off = json_number(ext, ext, "\"byteOffset\":"), len = json_number(ext, ext, "\"byteLength\":");
    *stride = (size_t)json_number(ext, ext, "\"byteStride\":");
    *count = (size_t)json_number(ext, ext, "\"count\":");
    CHECK(off >= 0 && len > 0 && off + len <= (double)bin_size && (size_t)off % 4 == 0);
    if (check_failed())
        return NULL;
    void *out = malloc(*count * *stride);
    CHECK(out != NULL);
    int triangles = strncmp(strstr(ext, "\"mode\":\"") + 8, "TRIANGLES", 9) == 0;
    int rc = triangles ? meshopt_decodeIndexBuffer(out, *count, *stride, bin + (size_t)off, (size_t)len)
                       : meshopt_decodeVertexBuffer(out, *count, *stride, bin + (size_t)off, (size_t)len);
    CHECKF(rc == 0, "meshopt decode: %d", rc);
    return out;
}

/* The numbering by first use the meshopt glb sends, computed the plain way: number[old]
 * is the new number of m's vertex old, order[new] the old vertex (the unused ones last,
 * in their order). */
static void first_use_numbering(const iso_mesh *m, uint32_t *number, uint32_t *order)
{
    uint32_t next = 0;
    for (size_t v = 0; v < m->vertex_count; v++)
        number[v] = UINT32_MAX;
    for (size_t i = 0; i < 3 * m->triangle_count; i++)
        if (number[m->indices[i]] == UINT32_MAX)
            number[m->indices[i]] = next++;
    for (size_t v = 0; v < m->vertex_count; v++)
        if (number[v] == UINT32_MAX)
            number[v] = next++;
    for (size_t v = 0; v < m->vertex_count; v++)
        order[number[v]] = (uint32_t)v;
}

/* The normals proto_encode_glb_meshopt_run asks for: a copy of `normals` given to `mesh`,
 * or the error `fail`; `calls` counts the asks. */
typedef struct given_normals {
    iso_mesh *mesh;
    const float *normals;
    int fail, calls, threads;
} given_normals;

static int give_normals(void *context, int threads, iso_error *err)
{
    given_normals *g = context;
    g->calls++;
    g->threads = threads;
    if (g->fail)
        return iso_error_set(err, g->fail, "no normals today");
    size_t bytes = 3 * g->mesh->vertex_count * sizeof(float);
    if (!(g->mesh->normals = malloc(bytes)))
        return iso_error_set(err, ISO_E_NOMEM, "no memory for normals");
    memcpy(g->mesh->normals, g->normals, bytes);
    return 0;
}

/* The pipeline's form of the encode (proto_encode_glb_meshopt_run) on `threads`: the
 * normals asked for once, on one thread when the encode has two (then beside the index
 * view) and on `threads` when it has one; the glb byte for byte `glb`; its gzip member
 * inflating to it; the steps' clocks in order. */
static void check_glb_meshopt_run(const iso_mesh *m, const proto_encode_options *opt, int threads,
                                  const unsigned char *glb, size_t glb_size)
{
    iso_error err;
    proto_encode_options o = *opt;
    o.threads = threads;
    iso_mesh c = *m;
    c.normals = NULL;
    given_normals g = {.mesh = &c, .normals = m->normals};
    proto_meshopt_run run = {.make_normals = m->normals ? give_normals : NULL, .context = &g, .gzip = 1};
    unsigned char *buf;
    size_t size;
    double start = iso_clock_ms();
    CHECK_OK(proto_encode_glb_meshopt_run(&c, &o, &run, &buf, &size, &err), &err);
    CHECKF(buf && size == glb_size && !memcmp(buf, glb, size), "%zu against %zu bytes", size, glb_size);
    CHECK_EQ(g.calls, m->normals ? 1 : 0);
    if (m->normals)
        CHECK_EQ(g.threads, threads == 2 && m->triangle_count >= 100000 ? 1 : threads);
    CHECK(run.gzip_bytes && run.gzip_size > 18);
    if (run.gzip_bytes)
        check_gunzip(run.gzip_bytes, run.gzip_size, glb, glb_size);
    CHECK(run.gzip_done >= run.glb_done && run.glb_done >= (m->normals ? run.normals_done : start) &&
          (!m->normals || run.normals_done >= start));
    free(run.gzip_bytes);
    free(buf);
    free(c.normals);
}

/* Encodes m, reads every view back with meshoptimizer's decoders, and checks the counts
 * exactly; the vertices numbered by first use: each triangle, in order, a rotation of m's
 * through that numbering; each decoded vertex's position within half a quantization step
 * of its m vertex's (exactly above 16 bits) and its normal within their quantization, so
 * that every corner gets its own vertex's attributes. One thread gives the same bytes as two.
 * Its gzip in pieces (the container and vertex streams Huffman-coded, the index view's
 * header and codes matched, its data Huffman-coded) inflates back to it. */
static void check_glb_meshopt(const iso_mesh *m, int qp, int qn)
{
    iso_error err;
    proto_encode_options opt;
    proto_encode_options_init(&opt);
    opt.position_bits = qp, opt.normal_bits = qn;
    unsigned char *buf, *one;
    size_t size, bin_size, one_size;
    const unsigned char *bin;
    CHECK_OK(proto_encode_glb_meshopt(m, &opt, &buf, &size, &err), &err);
    if (!buf)
        return;
    opt.threads = 1;
    CHECK_OK(proto_encode_glb_meshopt(m, &opt, &one, &one_size, &err), &err);
    CHECK(one && one_size == size && !memcmp(one, buf, size));
    free(one);
    check_glb_meshopt_run(m, &opt, 2, buf, size);
    check_glb_meshopt_run(m, &opt, 1, buf, size);
    proto_gzip_piece pieces[PROTO_GZIP_PIECES_MAX];
    int count = proto_glb_meshopt_gzip_pieces(buf, size, pieces);
    /* The vertex streams, the index stream's header (its first byte: 0xe1, version 1, as
     * EXT_meshopt_compression's TRIANGLES mode requires) and a code per triangle, its data. */
    CHECK_EQ(count, !m->triangle_count ? 1 : 3);
    if (count == 3) {
        CHECK(pieces[0].end < size && buf[pieces[0].end] == 0xe1);
        CHECK_EQ(pieces[1].end - pieces[0].end, 1 + m->triangle_count);
        CHECK(pieces[1].end < size && pieces[2].end == size);
        CHECK(pieces[0].huffman && !pieces[1].huffman && pieces[2].huffman);
    }
    unsigned char *gz;
    size_t gz_size;
    CHECK_OK(proto_gzip_pieces(buf, size, pieces, count, 2, &gz, &gz_size, &err), &err);
    if (gz)
        check_gunzip(gz, gz_size, buf, size);
    free(gz);
    char *json = glb_parse(buf, size, &bin, &bin_size);
    CHECK(json && bin);
    if (!json || !bin)
        goto done;
    CHECK(strstr(json, "\"extensionsRequired\":[\"EXT_meshopt_compression\",\"KHR_mesh_quantization\"]"));
    CHECK(strstr(json, "{\"EXT_meshopt_compression\":{\"fallback\":true}}"));
    const char *ext[3] = {NULL, NULL, NULL};
    const char *from = json;
    for (int v = 0; v < 3; v++) {
        ext[v] = strstr(from, "\"EXT_meshopt_compression\":{\"buffer\":0");
        from = ext[v] ? ext[v] + 1 : from;
    }
    const int normals = m->normals != NULL;
    CHECK(ext[0] && ext[1] && (ext[2] != NULL) == normals);
    if (check_failed())
        goto done;
    size_t nv, ps, nn = 0, ns = 0, ni, is;
    void *pos = meshopt_view(ext[0], bin, bin_size, &nv, &ps);
    void *nrm = normals ? meshopt_view(ext[1], bin, bin_size, &nn, &ns) : NULL;
    void *idx = meshopt_view(ext[normals ? 2 : 1], bin, bin_size, &ni, &is);
    CHECK_EQ(nv, m->vertex_count);
    CHECK_EQ(ni, 3 * m->triangle_count);
    CHECK_EQ(is, m->vertex_count <= 65535 ? 2 : 4);
    CHECK_EQ(ps, qp > 16 ? 12 : 8);
    uint32_t *number = malloc(2 * nv * sizeof *number + 1), *order = number + nv;
    CHECK(number != NULL);
    if (check_failed() || !pos || !idx || (normals && !nrm))
        goto decoded;
    first_use_numbering(m, number, order);
    /* The index codec may start a triangle at another corner; the winding stays. */
    for (size_t t = 0; t < ni / 3; t++) {
        uint32_t k[3], want[3];
        for (int c = 0; c < 3; c++) {
            k[c] = is == 2 ? ((uint16_t *)idx)[3 * t + c] : ((uint32_t *)idx)[3 * t + c];
            want[c] = number[m->indices[3 * t + c]];
        }
        int r = 0;
        while (r < 3 && (k[r] != want[0] || k[(r + 1) % 3] != want[1] || k[(r + 2) % 3] != want[2]))
            r++;
        if (r == 3) {
            CHECKF(0, "triangle %zu: %u %u %u, not a rotation of %u %u %u (first use)", t, k[0], k[1], k[2],
                   want[0], want[1], want[2]);
            break;
        }
    }
    double origin[3] = {0, 0, 0}, scale[3] = {1, 1, 1};
    if (qp <= 16) {
        CHECK(json_vec3_of(json, "\"translation\":[", origin) == 0);
        CHECK(json_vec3_of(json, "\"scale\":[", scale) == 0);
    }
    double worst = 0, lo[3] = {1e300, 1e300, 1e300}, hi[3] = {-1e300, -1e300, -1e300};
    for (size_t v = 0; v < nv; v++)
        for (int a = 0; a < 3; a++) {
            double q = qp > 16 ? ((float *)pos)[3 * v + a] : ((uint16_t *)pos)[4 * v + a];
            lo[a] = fmin(lo[a], q), hi[a] = fmax(hi[a], q);
            worst = fmax(worst, fabs(origin[a] + scale[a] * q - m->positions[3 * order[v] + a]));
        }
    CHECKF(qp > 16 ? worst == 0 : worst <= scale[0] * 0.5001 + 1e-5, "qp %d: position off by %g, step %g",
           qp, worst, scale[0]);
    /* Exactly Draco's grid: lround((p - lo) / extent * (2^qp - 1)) on the bounding cube. */
    if (qp <= 16) {
        float blo[3], bhi[3];
        for (int a = 0; a < 3; a++) {
            blo[a] = bhi[a] = m->positions[a];
            for (size_t v = 1; v < nv; v++)
                blo[a] = fminf(blo[a], m->positions[3 * v + a]), bhi[a] = fmaxf(bhi[a], m->positions[3 * v + a]);
        }
        double extent = fmax(fmax((double)bhi[0] - blo[0], (double)bhi[1] - blo[1]), (double)bhi[2] - blo[2]);
        double steps = ldexp(1, qp) - 1;
        size_t off_grid = 0;
        for (size_t v = 0; v < nv; v++)
            for (int a = 0; a < 3; a++) {
                long want = extent > 0 ? lround(((double)m->positions[3 * order[v] + a] - blo[a]) / extent * steps) : 0;
                off_grid += ((uint16_t *)pos)[4 * v + a] != want;
            }
        CHECKF(off_grid == 0, "qp %d: %zu components off the grid", qp, off_grid);
    }
    double amin[3], amax[3];
    CHECK(json_vec3_of(json, "\"min\":[", amin) == 0 && json_vec3_of(json, "\"max\":[", amax) == 0);
    for (int a = 0; a < 3; a++)
        CHECKF((float)amin[a] == (float)lo[a] && (float)amax[a] == (float)hi[a], "axis %d: accessor %g..%g, data %g..%g", a,
               amin[a], amax[a], lo[a], hi[a]);
    if (normals) {
        CHECK_EQ(ns, qn > 8 ? 8 : 4);
        double step = qn > 8 ? ldexp(1, 16 - qn) / 32767 : 1.0 / 127, off = 0;
        size_t off_grid = 0;
        for (size_t v = 0; v < nn; v++)
            for (int a = 0; a < 3; a++) {
                double x = qn > 8 ? ((int16_t *)nrm)[4 * v + a] / 32767.0 : ((int8_t *)nrm)[4 * v + a] / 127.0;
                const double n = m->normals[3 * order[v] + a];
                off = fmax(off, fabs(x - fmin(fmax(n, -1), 1))); /* past +-1: clamped */
                long grain = qn > 8 ? 1L << (16 - qn) : 1;
                long top = qn > 8 ? 32767 : 127;
                long want = lround(n * (double)top / (double)grain) * grain;
                want = want > top ? top : want < -top ? -top : want;
                long got = qn > 8 ? ((int16_t *)nrm)[4 * v + a] : ((int8_t *)nrm)[4 * v + a];
                off_grid += got != want;
            }
        CHECKF(off <= step * 0.5001 + 1e-6, "qn %d: normal off by %g, step %g", qn, off, step);
        CHECKF(off_grid == 0, "qn %d: %zu components not lround(x * max / grain) * grain within +-max", qn, off_grid);
    }
decoded:
    free(number);
    free(pos);
    free(nrm);
    free(idx);
done:
    free(json);
    free(buf);
}

static void test_glb_meshopt_round_trip(void)
{
    iso_mesh m;
    make_mesh(&m, tri_pos, NULL, 3, tri_idx, 1);
    check_glb_meshopt(&m, 14, 10);
    iso_mesh_free(&m);
    make_mesh(&m, oct_pos, oct_pos, 6, oct_idx, 8);
    check_glb_meshopt(&m, 14, 8);
    iso_mesh_free(&m);
    /* 70,000 vertices: 32-bit indices. */
    make_torus(&m, 350, 200, 1);
    for (int qp = 12; qp <= 20 && !check_failed(); qp += 4)
        for (int qn = 8; qn <= 12; qn += 2)
            check_glb_meshopt(&m, qp, qn);
    iso_mesh_free(&m);
    make_torus(&m, 100, 60, 0);
    check_glb_meshopt(&m, 14, 10);
    iso_mesh_free(&m);
    /* The torus's triangles shuffled: an index stream of free indices, over 256 KB. */
    make_torus(&m, 350, 200, 1);
    for (size_t t = m.triangle_count - 1; t > 0; t--) {
        size_t u = rng() % (t + 1);
        for (int c = 0; c < 3; c++) {
            uint32_t x = m.indices[3 * t + c];
            m.indices[3 * t + c] = m.indices[3 * u + c];
            m.indices[3 * u + c] = x;
        }
    }
    check_glb_meshopt(&m, 14, 10);
    /* Its vertices shuffled too: positions and normals must follow their vertex. */
    float *pos = malloc(m.vertex_count * 12), *nrm = malloc(m.vertex_count * 12);
    uint32_t *to = malloc(m.vertex_count * 4);
    CHECK(pos && nrm && to);
    if (pos && nrm && to) {
        for (size_t v = 0; v < m.vertex_count; v++)
            to[v] = (uint32_t)v;
        for (size_t v = m.vertex_count - 1; v > 0; v--) {
            size_t u = rng() % (v + 1);
            uint32_t x = to[v];
            to[v] = to[u], to[u] = x;
        }
        for (size_t v = 0; v < m.vertex_count; v++) {
            memcpy(pos + 3 * to[v], m.positions + 3 * v, 12);
            memcpy(nrm + 3 * to[v], m.normals + 3 * v, 12);
        }
        memcpy(m.positions, pos, m.vertex_count * 12);
        memcpy(m.normals, nrm, m.vertex_count * 12);
        for (size_t i = 0; i < 3 * m.triangle_count; i++)
            m.indices[i] = to[m.indices[i]];
        check_glb_meshopt(&m, 14, 10);
        check_glb_meshopt(&m, 20, 8);
    }
    free(pos);
    free(nrm);
    free(to);
    /* Normal components on half steps of the 10-bit grid (rounded away from zero), and past
     * +-1 (clamped), some far past what int32 holds once scaled: the vectorized quantizing
     * gives every one the scalar rounding. */
    for (size_t i = 0; i < 3 * m.vertex_count; i++) {
        if (i % 5 == 0)
            m.normals[i] = (float)(((double)(long)(m.normals[i] * 511) + (m.normals[i] < 0 ? -0.5 : 0.5)) * 64 / 32767);
        else if (i % 7 == 0)
            m.normals[i] = i % 2 ? 1e12f : -7e4f;
        else if (i % 11 == 0)
            m.normals[i] = i % 2 ? 1.5f : -1.0001f;
    }
    check_glb_meshopt(&m, 14, 10);
    check_glb_meshopt(&m, 14, 16);
    unsigned char *glb;
    size_t size;
    iso_error err;
    CHECK_OK(proto_encode_glb_meshopt(&m, NULL, &glb, &size, &err), &err);
    proto_gzip_piece pieces[PROTO_GZIP_PIECES_MAX];
    if (glb)
        CHECK_EQ(proto_glb_meshopt_gzip_pieces(glb, size, pieces), 3);
    free(glb);
    iso_mesh_free(&m);
}

/* Pieces of any sizes (empty ones too), either strategy, one to four, on one or two
 * threads: one gzip member that inflates to the input. The meshopt split names the index
 * view's first byte (the index codec's header, 0xe1), and nothing in bytes that
 * are not a meshopt glb. */
static void test_gzip_pieces(void)
{
    iso_error err;
    size_t size = (1u << 20) + 300000; /* above gzip.c's bytes per thread */
    unsigned char *in = malloc(size);
    CHECK(in != NULL);
    if (!in)
        return;
    for (size_t i = 0; i < size; i++)
        in[i] = (unsigned char)(i < size / 2 ? rng() % 7 : (i / 3) % 251);
    const size_t cuts[][3] = {{size, 0, 0}, {0, size, 0}, {1000, 1000, size / 2}, {size / 3, size / 2, size - 1}};
    for (int count = 1; count <= PROTO_GZIP_PIECES_MAX; count++)
        for (int c = 0; c < 4; c++)
            for (int threads = 1; threads <= 2; threads++) {
                proto_gzip_piece pieces[PROTO_GZIP_PIECES_MAX];
                for (int i = 0; i < count; i++)
                    pieces[i] = (proto_gzip_piece){.end = i < 3 ? cuts[c][i] : size, .huffman = (i + c) % 2};
                for (int i = 1; i < count; i++)
                    if (pieces[i].end < pieces[i - 1].end)
                        pieces[i].end = pieces[i - 1].end;
                unsigned char *gz;
                size_t gz_size;
                CHECK_OK(proto_gzip_pieces(in, size, pieces, count, threads, &gz, &gz_size, &err), &err);
                if (gz)
                    check_gunzip(gz, gz_size, in, size);
                free(gz);
            }
    /* Huffman-only pieces whose codes need folding back to 15 bits (counts of
     * Fibonacci numbers: 23 symbols, an unlimited code 22 bits deep), one byte value only,
     * every byte value equally often, and blocks' edges (64 KB) inside the pieces. */
    size_t fib_size = 0;
    for (uint32_t a = 1, b = 1, sym = 0; sym < 23; sym++, b = a + b, a = b - a)
        for (uint32_t k = 0; k < a; k++)
            in[fib_size++] = (unsigned char)(sym * 11);
    const size_t sizes[] = {fib_size, 70000, 200000};
    for (int c = 0; c < 3; c++) {
        if (c == 1)
            memset(in, 'a', sizes[c]);
        if (c == 2)
            for (size_t i = 0; i < sizes[c]; i++)
                in[i] = (unsigned char)rng();
        for (int last = 0; last < 2; last++) {
            proto_gzip_piece pieces[2] = {{.end = last ? 0 : sizes[c], .huffman = 1}, {.end = sizes[c], .huffman = 1}};
            unsigned char *gz;
            size_t gz_size;
            CHECK_OK(proto_gzip_pieces(in, sizes[c], pieces, 2, 1, &gz, &gz_size, &err), &err);
            if (gz)
                check_gunzip(gz, gz_size, in, sizes[c]);
            CHECKF(!gz || gz_size < sizes[c] / 8 * (c == 2 ? 9 : c == 1 ? 1 : 5) + 400, "case %d: %zu bytes of %zu", c,
                   gz_size, sizes[c]);
            free(gz);
        }
    }
    unsigned char *gz;
    size_t gz_size;
    CHECK_OK(proto_gzip(in, 0, &gz, &gz_size, &err), &err);
    if (gz)
        check_gunzip(gz, gz_size, in, 0);
    free(gz);
    proto_gzip_piece pieces[PROTO_GZIP_PIECES_MAX];
    CHECK_EQ(proto_glb_meshopt_gzip_pieces(in, size, pieces), 1);
    CHECK_EQ(pieces[0].end, size);
    free(in);

    iso_mesh m;
    make_torus(&m, 100, 60, 1);
    unsigned char *glb;
    CHECK_OK(proto_encode_glb_meshopt(&m, NULL, &glb, &size, &err), &err);
    if (glb) {
        CHECK_EQ(proto_glb_meshopt_gzip_pieces(glb, size, pieces), 3);
        CHECKF(glb[pieces[0].end] == 0xe1, "index view starts with %#x", glb[pieces[0].end]);
        /* The index view is the BIN chunk's last: it runs to the end but for its padding. */
        size_t encoded = meshopt_encodeIndexBufferBound(3 * m.triangle_count, m.vertex_count);
        CHECK(size - pieces[0].end <= encoded + 3);
        glb[0] = 'x';
        CHECK_EQ(proto_glb_meshopt_gzip_pieces(glb, size, pieces), 1);
    }
    free(glb);
    iso_mesh_free(&m);
}

/* proto_meshopt_encode_indices against meshoptimizer's own encoder at version 1 (the
 * version EXT_meshopt_compression names): the same bytes for the torus (edge FIFO hits),
 * triangle soups of near and far indices (misses, free indices of one to five varint
 * bytes, fans that reuse a vertex past the FIFO's 16, vertices at FIFO ages 13 and 14,
 * which version 1 codes as free), strips whose free corners step by one up and down
 * (version 1's codes 13 and 14), meshes numbered from 0 one after another (version 1's
 * reset), degenerate and repeated triangles, and no triangles; 0 for a buffer too small;
 * and the stream decodes back to the same triangles (each may start at another corner). */
static void check_index_codec(const uint32_t *idx, size_t count, size_t vertices, const char *what)
{
    size_t bound = meshopt_encodeIndexBufferBound(count, vertices);
    unsigned char *want = malloc(bound), *got = malloc(bound);
    uint32_t *back = malloc((count ? count : 1) * sizeof *back);
    CHECK(want && got && back);
    if (want && got && back) {
        size_t n = meshopt_encodeIndexBuffer(want, bound, idx, count);
        size_t m = proto_meshopt_encode_indices(got, bound, idx, count);
        CHECKF(n > 0 && m == n && !memcmp(want, got, n), "%s: %zu bytes, the library's %zu", what, m, n);
        CHECKF(m > 0 && got[0] == 0xe1, "%s: header %#x", what, m ? got[0] : 0);
        CHECK_EQ(proto_meshopt_encode_indices(got, count / 3 + 16, idx, count), 0);
        CHECK_EQ(meshopt_decodeIndexBuffer(back, count, sizeof *back, want, n), 0);
        size_t wrong = 0;
        for (size_t t = 0; t < count; t += 3) {
            int same = 0;
            for (int r = 0; r < 3; r++)
                same |= back[t] == idx[t + r] && back[t + 1] == idx[t + (r + 1) % 3] &&
                        back[t + 2] == idx[t + (r + 2) % 3];
            wrong += !same;
        }
        CHECKF(wrong == 0, "%s: %zu triangles decode wrong", what, wrong);
    }
    free(want);
    free(got);
    free(back);
}

/* Renumbers idx by first use (what the glb sends): its first triangle becomes (0,1,2). */
static void number_by_first_use(uint32_t *idx, size_t count, size_t vertices)
{
    uint32_t *number = malloc(vertices * sizeof *number), next = 0;
    CHECK(number != NULL);
    if (!number)
        return;
    memset(number, 0xff, vertices * sizeof *number);
    for (size_t i = 0; i < count; i++) {
        if (number[idx[i]] == UINT32_MAX)
            number[idx[i]] = next++;
        idx[i] = number[idx[i]];
    }
    free(number);
}

/* A strip of `triangles` over free indices from `first` stepping by `step` (+1 or -1): each
 * triangle shares an edge with the one before, its new corner the last free index +- 1. */
static void make_strip(uint32_t *idx, size_t triangles, uint32_t first, int step)
{
    for (size_t t = 0; t < triangles; t++) {
        uint32_t v = first + (uint32_t)((int)t * step);
        uint32_t u = v + (uint32_t)step, w = v + (uint32_t)(2 * step);
        if (t % 2 == 0)
            idx[3 * t] = v, idx[3 * t + 1] = u, idx[3 * t + 2] = w;
        else
            idx[3 * t] = u, idx[3 * t + 1] = v, idx[3 * t + 2] = w;
    }
}

static void test_meshopt_index_codec(void)
{
    meshopt_encodeIndexVersion(1);
    iso_mesh m;
    make_torus(&m, 350, 200, 0);
    check_index_codec(m.indices, 3 * m.triangle_count, m.vertex_count, "torus");
    /* The torus's triangles in reverse, and every third one rotated: other corners start. */
    size_t count = 3 * m.triangle_count;
    uint32_t *idx = malloc(2 * count * sizeof *idx);
    CHECK(idx != NULL);
    if (idx) {
        for (size_t t = 0; t < m.triangle_count; t++)
            for (int c = 0; c < 3; c++)
                idx[3 * t + c] = m.indices[3 * (m.triangle_count - 1 - t) + (c + t) % 3];
        check_index_codec(idx, count, m.vertex_count, "torus reversed and rotated");
        /* Numbered by first use, twice in a row: the second copy starts with a reset. */
        memcpy(idx, m.indices, count * sizeof *idx);
        number_by_first_use(idx, count, m.vertex_count);
        memcpy(idx + count, idx, count * sizeof *idx);
        CHECK(idx[0] == 0 && idx[1] == 1 && idx[2] == 2);
        check_index_codec(idx, 2 * count, m.vertex_count, "torus by first use, twice");
    }
    iso_mesh_free(&m);
    free(idx);
    const size_t soup = 60000;
    idx = malloc(3 * soup * sizeof *idx);
    CHECK(idx != NULL);
    if (!idx)
        return;
    /* Strips over free indices, up and down, from far and near: codes 13 and 14, and a
     * 0,1,2 triangle in the middle of another mesh (a reset only once vertex 0 is past). */
    make_strip(idx, 500, 1000000, 1);
    make_strip(idx + 1500, 500, 5000000, -1);
    make_strip(idx + 3000, 500, 0, 1);
    make_strip(idx + 4500, 500, 700, -1);
    idx[6000] = 0, idx[6001] = 1, idx[6002] = 2;
    make_strip(idx + 6003, 499, 4000, 1);
    idx[7500] = 1, idx[7501] = 2, idx[7502] = 0; /* the same triangle rotated: a reset too */
    check_index_codec(idx, 7503, 5000002, "strips and resets");
    const uint32_t spans[] = {8, 20, 40, 300, 70000, 1u << 30};
    for (int s = 0; s < 6; s++) {
        uint32_t base = 0;
        for (size_t t = 0; t < soup; t++) {
            uint32_t span = spans[s];
            if (t % 97 == 0)
                base = rng() % (span < 1000 ? 1000 : span);
            for (int c = 0; c < 3; c++)
                idx[3 * t + c] = base + rng() % span;
            if (t % 13 == 0) /* degenerate */
                idx[3 * t + 1] = idx[3 * t];
            if (t % 29 == 1) /* repeated */
                memcpy(idx + 3 * t, idx + 3 * t - 3, 3 * sizeof *idx);
            if (t % 7 == 2) /* a neighbour across an edge of the last triangle */
                idx[3 * t] = idx[3 * t - 2], idx[3 * t + 1] = idx[3 * t - 3];
            if (t % 5 == 3 && t >= 20) /* a fan around a vertex 20 triangles back */
                idx[3 * t] = idx[3 * t - 60];
            if (t % 11 == 4 && t >= 5) /* a vertex 13 or 14 pushes back */
                idx[3 * t + 2] = idx[3 * t - 13 - t % 2];
        }
        char what[64];
        snprintf(what, sizeof what, "soup of span %u", spans[s]);
        check_index_codec(idx, 3 * soup, (size_t)(1u << 30) + 70000, what);
    }
    check_index_codec(idx, 0, 1, "no triangles");
    free(idx);
}

/* proto_meshopt_encode_vertices against meshoptimizer's own encoder (version 0): the same
 * bytes for strides 4 to 64, counts around the 16-vertex groups and the blocks (256
 * vertices for strides up to 32, fewer above), over smooth bytes (small deltas: the 2-
 * and 4-bit groups and their whole bytes), constant ones (zero groups) and random ones
 * (8-bit groups); and 0 for a buffer too small or a stride the codec does not take. */
static void test_meshopt_vertex_codec(void)
{
    const size_t most = 5000, strides[] = {4, 8, 12, 16, 32, 64};
    const size_t counts[] = {0, 1, 15, 16, 17, 255, 256, 257, 1000, 4099, 5000};
    unsigned char *v = malloc(most * 64);
    CHECK(v != NULL);
    if (!v)
        return;
    for (int kind = 0; kind < 3 && !check_failed(); kind++) {
        for (size_t i = 0; i < most * 64; i++)
            v[i] = kind == 0 ? (unsigned char)(rng() % 7 + i / 64 % 3) : kind == 1 ? 42 : (unsigned char)rng();
        for (int a = 0; a < 6; a++)
            for (int c = 0; c < 11; c++) {
                size_t bound = meshopt_encodeVertexBufferBound(counts[c], strides[a]);
                unsigned char *want = malloc(bound), *got = malloc(bound);
                CHECK(want && got);
                if (want && got) {
                    size_t n = meshopt_encodeVertexBuffer(want, bound, v, counts[c], strides[a]);
                    size_t m = proto_meshopt_encode_vertices(got, bound, v, counts[c], strides[a]);
                    CHECKF(n > 0 && m == n && !memcmp(want, got, n), "kind %d, %zu vertices of %zu bytes: %zu bytes, the library's %zu",
                           kind, counts[c], strides[a], m, n);
                    CHECK_EQ(proto_meshopt_encode_vertices(got, strides[a], v, counts[c], strides[a]), 0);
                }
                free(want);
                free(got);
            }
    }
    unsigned char out[64];
    CHECK_EQ(proto_meshopt_encode_vertices(out, sizeof out, v, 1, 6), 0);
    free(v);
}

/* The meshopt glb numbers vertices by first use, the unused ones last in their order:
 * seven vertices, two unused, three triangles, each vertex's normal its own. */
static void test_glb_meshopt_first_use(void)
{
    static const float p[] = {0, 0, 0, 1, 0, 0, 0, 1, 0, 0, 0, 1, 1, 1, 0, 1, 0, 1, 0, 1, 1};
    static const float n[] = {1, 0, 0, 0, 1, 0, 0, 0, 1, -1, 0, 0, 0, -1, 0, 0, 0, -1, 0.6f, 0.8f, 0};
    static const uint32_t idx[] = {4, 2, 5, 2, 4, 0, 6, 0, 4};
    static const uint32_t want[] = {4, 2, 5, 0, 6, 1, 3};
    iso_mesh m;
    make_mesh(&m, p, n, 7, idx, 3);
    uint32_t number[7], order[7];
    first_use_numbering(&m, number, order);
    for (int v = 0; v < 7; v++)
        CHECKF(order[v] == want[v], "new vertex %d: old %u, want %u", v, order[v], want[v]);
    check_glb_meshopt(&m, 14, 10);
    check_glb_meshopt(&m, 14, 8);
    check_glb_meshopt(&m, 20, 10);
    iso_mesh_free(&m);
}

static void test_glb_meshopt_refuses_and_empties(void)
{
    iso_error err;
    unsigned char *buf;
    size_t size, bin_size;
    const unsigned char *bin;
    iso_mesh m;
    make_mesh(&m, oct_pos, oct_pos, 6, oct_idx, 8);
    proto_encode_options opt;
    proto_encode_options_init(&opt);
    opt.position_bits = 25;
    CHECK_EQ(proto_encode_glb_meshopt(&m, &opt, &buf, &size, &err), ISO_E_ARGUMENT);
    CHECK(buf == NULL && size == 0);
    /* The numbering checks every index; the other thread the values. */
    m.positions[4] = NAN;
    CHECK_EQ(proto_encode_glb_meshopt(&m, NULL, &buf, &size, &err), ISO_E_ARGUMENT);
    CHECK(buf == NULL && strstr(err.message, "non-finite position"));
    m.indices[22] = 6;
    CHECK_EQ(proto_encode_glb_meshopt(&m, NULL, &buf, &size, &err), ISO_E_ARGUMENT);
    CHECKF(buf == NULL && strstr(err.message, "triangle 7: index 6 >= 6"), "%s", err.message);
    m.positions[4] = 0;
    m.indices[0] = 6;
    CHECK_EQ(proto_encode_glb_meshopt(&m, NULL, &buf, &size, &err), ISO_E_ARGUMENT);
    iso_mesh_free(&m);
    make_mesh(&m, oct_pos, oct_pos, 6, oct_idx, 8);
    /* The pipeline's form: the normals' own failure, and normals made non-finite. */
    iso_mesh c = m;
    c.normals = NULL;
    given_normals g = {.mesh = &c, .normals = m.normals, .fail = ISO_E_NOMEM};
    proto_meshopt_run run = {.make_normals = give_normals, .context = &g, .gzip = 1};
    CHECK_EQ(proto_encode_glb_meshopt_run(&c, NULL, &run, &buf, &size, &err), ISO_E_NOMEM);
    CHECK(buf == NULL && size == 0 && run.gzip_bytes == NULL && strstr(err.message, "no normals today"));
    m.normals[7] = INFINITY;
    g.fail = 0;
    CHECK_EQ(proto_encode_glb_meshopt_run(&c, NULL, &run, &buf, &size, &err), ISO_E_ARGUMENT);
    CHECK(buf == NULL && run.gzip_bytes == NULL && strstr(err.message, "non-finite normal"));
    free(c.normals);
    m.normals[7] = 0;
    m.triangle_count = 0;
    CHECK_OK(proto_encode_glb_meshopt(&m, NULL, &buf, &size, &err), &err);
    char *json = buf ? glb_parse(buf, size, &bin, &bin_size) : NULL;
    CHECK(json && !bin && strstr(json, "\"scenes\":[{}]"));
    free(json);
    free(buf);
    iso_mesh_free(&m);
}

/* ---- empty meshes ---- */

static void test_empty_mesh_gives_valid_files(void)
{
    iso_error err;
    unsigned char *buf;
    size_t size, bin_size;
    const unsigned char *bin;
    iso_mesh m, dec;
    /* No vertices at all, vertices but no triangles, and only a degenerate triangle. */
    const uint32_t degenerate[] = {0, 1, 1};
    for (int kind = 0; kind < 3 && !check_failed(); kind++) {
        make_mesh(&m, tri_pos, NULL, kind ? 3 : 0, degenerate, kind == 2 ? 1 : 0);

        CHECK_OK(proto_encode_ply(&m, &buf, &size, &err), &err);
        if (buf) {
            char want[64];
            snprintf(want, sizeof want, "element vertex %zu\n", m.vertex_count);
            CHECK(strstr((const char *)buf, want) != NULL);
            snprintf(want, sizeof want, "element face %zu\n", m.triangle_count);
            CHECK(strstr((const char *)buf, want) != NULL);
            check_ply_payload(&m, buf, size);
            free(buf);
        }

        CHECK_OK(proto_encode_obj(&m, &buf, &size, &err), &err);
        if (buf) {
            CHECK(size > 0 && buf[0] == '#' && buf[size - 1] == '\n');
            free(buf);
        }

        /* Draco: a stream that decodes to an empty mesh, here and with draco_decoder. */
        CHECK_OK(proto_encode_draco(&m, NULL, &buf, &size, &err), &err);
        if (buf) {
            CHECK_OK(proto_draco_decode(buf, size, &dec, &err), &err);
            CHECK_EQ(dec.vertex_count, 0);
            CHECK_EQ(dec.triangle_count, 0);
            iso_mesh_free(&dec);
            char drc[512], ply[512], cmd[1200];
            snprintf(drc, sizeof drc, "%s/empty%d.drc", check_temp_dir(), kind);
            snprintf(ply, sizeof ply, "%s/empty%d.ply", check_temp_dir(), kind);
            CHECK(write_file(drc, buf, size) == 0);
            snprintf(cmd, sizeof cmd, "draco_decoder -i '%s' -o '%s' >/dev/null 2>&1", drc, ply);
            if (kind == 0 && system("command -v draco_decoder >/dev/null 2>&1") == 0) {
                long nv, nf;
                CHECKF(system(cmd) == 0, "%s failed", cmd);
                CHECK(ply_counts(ply, &nv, &nf) == 0);
                CHECK(nv == 0 && nf == 0);
            }
            free(buf);
        }

        /* glb: a container with a scene and no mesh, no BIN chunk. */
        CHECK_OK(proto_encode_glb(&m, NULL, &buf, &size, &err), &err);
        if (buf) {
            char *json = glb_parse(buf, size, &bin, &bin_size);
            CHECK(json != NULL && bin == NULL);
            if (json) {
                CHECK(strstr(json, "\"asset\":{\"version\":\"2.0\"") != NULL);
                CHECK(strstr(json, "\"scenes\":[{}]") != NULL);
                CHECK(strstr(json, "meshes") == NULL && strstr(json, "accessors") == NULL);
            }
            free(json);
            free(buf);
        }
        iso_mesh_free(&m);
    }
}

int main(void)
{
    CHECK_RUN(test_ply_triangle_exact);
    CHECK_RUN(test_ply_normals_header_and_payload);
    CHECK_RUN(test_ply_100k_triangles_read_back);
    CHECK_RUN(test_obj_triangle_exact);
    CHECK_RUN(test_stl_octahedron_exact);
    CHECK_RUN(test_obj_normals_round_trip);
    CHECK_RUN(test_draco_round_trip_small_meshes);
    CHECK_RUN(test_draco_round_trip_bits_and_speeds);
    CHECK_RUN(test_draco_speed_10_keeps_order);
    CHECK_RUN(test_draco_auto_speed);
    CHECK_RUN(test_draco_auto_numbers_by_first_use);
    CHECK_RUN(test_draco_split_matches_one_encoder);
    CHECK_RUN(test_draco_100k_triangles);
    CHECK_RUN(test_draco_decodes_with_draco_decoder);
    CHECK_RUN(test_draco_refuses_bad_options_and_meshes);
    CHECK_RUN(test_draco_info_matches_decoder);
    CHECK_RUN(test_draco_decoder_refuses_garbage);
    CHECK_RUN(test_draco_decoder_survives_corruption);
    CHECK_RUN(test_glb_container);
    CHECK_RUN(test_glb_meshopt_round_trip);
    CHECK_RUN(test_meshopt_index_codec);
    CHECK_RUN(test_meshopt_vertex_codec);
    CHECK_RUN(test_glb_meshopt_first_use);
    CHECK_RUN(test_glb_meshopt_refuses_and_empties);
    CHECK_RUN(test_gzip_pieces);
    CHECK_RUN(test_empty_mesh_gives_valid_files);
    return check_finish();
}
