/* glb_meshopt.c: the glTF 2.0 binary encoder whose buffer views are compressed with
 * meshoptimizer's vertex and index codecs (EXT_meshopt_compression) over quantized
 * attributes (KHR_mesh_quantization), as three.js's GLTFLoader + MeshoptDecoder read it.
 *
 * Passes, in order:
 *   1. quantize: positions to qp-bit integers on the mesh's bounding cube (uint16, four
 *      per vertex as the codec wants strides of 4), the node's translation and scale
 *      mapping them back to world units; above 16 bits, float positions unquantized.
 *      Normals to signed normalized integers: int8 up to 8 bits, else int16 with the
 *      bits below qn cleared (zeros the codec's byte deltas compress to nothing);
 *   2. encode each stream (positions, normals, indices) into the BIN chunk, each view
 *      4-byte aligned; the uncompressed layout lives in a second, fallback buffer that
 *      has no data (the extension is required). With two threads (opt->threads) the
 *      indices are encoded on one while the other quantizes and encodes the vertices;
 *      the bytes do not depend on it;
 *   3. the JSON and the container (glb_container.h).
 * Every vertex and triangle is kept, in order (the index codec may start a triangle at
 * another corner, same winding): a loader gets the mesh's counts exactly. */
#include "encode.h"
#include "base/base.h"
#include "glb_container.h"

#include <assert.h>
#include <math.h>
#include <meshoptimizer.h>
#include <stdint.h>
#include <stdlib.h>
#include <string.h>

/* Below this many triangles one thread encodes it all: handing half to another thread
 * (waiting for it on a busy machine) would cost more than it saves. */
#define MESHOPT_TRIANGLES_PER_THREAD 100000

/* The position bits the uint16 components hold; more bits keep float positions. */
#define MESHOPT_POSITION_BITS_MAX 16

enum { VIEW_POSITION, VIEW_NORMAL, VIEW_INDEX, VIEW_COUNT };

/* One buffer view: its uncompressed data (stride bytes per element) and where its
 * compressed bytes go. */
typedef struct view {
    void *data;
    size_t count, stride;
    int triangles;                   /* 1: the index codec, 0: the vertex codec */
    size_t offset, length;           /* in the fallback buffer (uncompressed) */
    size_t packed_offset, packed_length; /* in the BIN chunk */
} view;

/* The quantized mesh and its JSON facts. */
typedef struct quantized {
    view views[VIEW_COUNT];
    int normals;                     /* 0: no normal view (its slot stays empty) */
    int float_positions;
    int normal_type;                 /* PROTO_GLTF_BYTE or PROTO_GLTF_SHORT */
    int index_type;                  /* PROTO_GLTF_UNSIGNED_SHORT or _INT */
    float origin[3], step;           /* world = origin + step * q */
    double qmin[3], qmax[3];         /* the POSITION accessor's bounds, in its units */
} quantized;

static void quantized_free(quantized *q)
{
    for (int v = 0; v < VIEW_COUNT; v++)
        if (v != VIEW_INDEX)
            free(q->views[v].data);
}

/* lround(x) for |x| < 2^62 without a library call: rounding halves away from zero. */
static inline long round_half_away(double x)
{
    double a = fabs(x);
    long k = (long)(a + 0.5);
    if ((double)k - a > 0.5) /* a + 0.5 rounded up (a just under a half) */
        k--;
    return x < 0 ? -k : k;
}

/* Pass 1, positions: the bounding cube's corner and step (Draco's grid, so that qp
 * means the same for both codecs). */
static int quantize_positions(const iso_mesh *mesh, int bits, quantized *q)
{
    size_t n = mesh->vertex_count;
    const float *p = mesh->positions;
    float lo[3] = {p[0], p[1], p[2]}, hi[3] = {p[0], p[1], p[2]};
    for (size_t i = 1; i < n; i++)
        for (int a = 0; a < 3; a++) {
            float x = p[3 * i + a];
            lo[a] = x < lo[a] ? x : lo[a];
            hi[a] = x > hi[a] ? x : hi[a];
        }
    view *v = &q->views[VIEW_POSITION];
    v->count = n;
    if (bits > MESHOPT_POSITION_BITS_MAX) {
        q->float_positions = 1;
        v->stride = 12;
        v->data = malloc(n * 12);
        if (!v->data)
            return ISO_E_NOMEM;
        memcpy(v->data, p, n * 12);
        for (int a = 0; a < 3; a++)
            q->qmin[a] = lo[a], q->qmax[a] = hi[a];
        return 0;
    }
    double extent = 0, steps = (double)((1u << bits) - 1);
    for (int a = 0; a < 3; a++) {
        q->origin[a] = lo[a];
        extent = fmax(extent, (double)hi[a] - lo[a]);
    }
    q->step = extent > 0 ? (float)(extent / steps) : 1.0f;
    v->stride = 8;
    uint16_t *out = malloc(n * 8);
    if (!out)
        return ISO_E_NOMEM;
    v->data = out;
    long kmin[3] = {(long)steps, (long)steps, (long)steps}, kmax[3] = {0, 0, 0};
    for (size_t i = 0; i < n; i++) {
        for (int a = 0; a < 3; a++) {
            double t = extent > 0 ? ((double)p[3 * i + a] - lo[a]) / extent * steps : 0;
            long k = round_half_away(t);
            k = k < 0 ? 0 : k > (long)steps ? (long)steps : k;
            out[4 * i + a] = (uint16_t)k;
            kmin[a] = k < kmin[a] ? k : kmin[a];
            kmax[a] = k > kmax[a] ? k : kmax[a];
        }
        out[4 * i + 3] = 0;
    }
    for (int a = 0; a < 3; a++)
        q->qmin[a] = (double)kmin[a], q->qmax[a] = (double)kmax[a];
    return 0;
}

/* Pass 1, normals: int8 (stride 4) up to 8 bits, else int16 (stride 8) rounded to qn bits. */
static int quantize_normals(const iso_mesh *mesh, int bits, quantized *q)
{
    size_t n = mesh->vertex_count;
    view *v = &q->views[VIEW_NORMAL];
    v->count = n;
    int wide = bits > 8;
    q->normal_type = wide ? PROTO_GLTF_SHORT : PROTO_GLTF_BYTE;
    v->stride = wide ? 8 : 4;
    v->data = malloc(n * v->stride);
    if (!v->data)
        return ISO_E_NOMEM;
    double max = wide ? 32767 : 127;
    long grain = wide ? 1L << (16 - bits) : 1, top = (long)max;
    for (size_t i = 0; i < n; i++)
        for (int a = 0; a < 4; a++) {
            double x = a < 3 ? mesh->normals[3 * i + a] : 0;
            long k = round_half_away(x * max / (double)grain) * grain;
            k = k > top ? top : k < -top ? -top : k;
            if (wide)
                ((int16_t *)v->data)[4 * i + a] = (int16_t)k;
            else
                ((int8_t *)v->data)[4 * i + a] = (int8_t)k;
        }
    return 0;
}

/* Pass 2 for one view: its compressed bytes into a buffer of their own (malloc'd). */
static int encode_view(const quantized *q, view *v, unsigned char **out)
{
    size_t bound = v->triangles ? meshopt_encodeIndexBufferBound(v->count, q->views[VIEW_POSITION].count)
                                : meshopt_encodeVertexBufferBound(v->count, v->stride);
    *out = malloc(bound);
    if (!*out)
        return ISO_E_NOMEM;
    v->packed_length = v->triangles ? meshopt_encodeIndexBuffer(*out, bound, v->data, v->count)
                                    : meshopt_encodeVertexBuffer(*out, bound, v->data, v->count, v->stride);
    assert(v->packed_length > 0); /* the bounds above are the codecs' own */
    return 0;
}

/* Passes 1 and 2 on up to two threads: the indices on one, the vertices (quantized, then
 * encoded) on the other. */
typedef struct pack_job {
    const iso_mesh *mesh;
    const proto_encode_options *opt;
    quantized *q;
    unsigned char *packed[VIEW_COUNT];
    int rc[2];
} pack_job;

static int pack_vertices(pack_job *job)
{
    quantized *q = job->q;
    int rc = quantize_positions(job->mesh, job->opt->position_bits, q);
    if (!rc)
        rc = encode_view(q, &q->views[VIEW_POSITION], &job->packed[VIEW_POSITION]);
    if (!rc && q->normals)
        rc = quantize_normals(job->mesh, job->opt->normal_bits, q);
    if (!rc && q->normals)
        rc = encode_view(q, &q->views[VIEW_NORMAL], &job->packed[VIEW_NORMAL]);
    return rc;
}

static void pack_share(void *context, int t, int threads)
{
    pack_job *job = context;
    if (t == 0)
        job->rc[0] = pack_vertices(job);
    if (t == threads - 1)
        job->rc[1] = encode_view(job->q, &job->q->views[VIEW_INDEX], &job->packed[VIEW_INDEX]);
}

/* Joins the views' compressed bytes into one buffer, each 4-byte aligned, and lays out the
 * fallback buffer. */
static int join(quantized *q, unsigned char *const packed[VIEW_COUNT], unsigned char **out, size_t *out_size)
{
    size_t total = 0, offset = 0;
    for (int i = 0; i < VIEW_COUNT; i++)
        if (packed[i])
            total += proto_glb_pad4(q->views[i].packed_length);
    unsigned char *buf = malloc(total ? total : 1);
    if (!buf)
        return ISO_E_NOMEM;
    size_t used = 0;
    for (int i = 0; i < VIEW_COUNT; i++) {
        view *v = &q->views[i];
        if (!packed[i])
            continue;
        v->offset = offset;
        v->length = v->count * v->stride;
        offset += proto_glb_pad4(v->length);
        v->packed_offset = used;
        memcpy(buf + used, packed[i], v->packed_length);
        used += v->packed_length;
        while (used % 4)
            buf[used++] = 0;
    }
    *out = buf;
    *out_size = used;
    return 0;
}

/* Passes 1 and 2: the BIN chunk's bytes. */
static int pack(const iso_mesh *mesh, const proto_encode_options *opt, quantized *q, unsigned char **out,
                size_t *out_size)
{
    pack_job job = {.mesh = mesh, .opt = opt, .q = q};
    int threads = iso_parallel_threads(opt->threads);
    if (mesh->triangle_count < MESHOPT_TRIANGLES_PER_THREAD)
        threads = 1;
    iso_parallel_run(threads > 1 ? 2 : 1, pack_share, &job);
    int rc = job.rc[0] ? job.rc[0] : job.rc[1];
    if (!rc)
        rc = join(q, job.packed, out, out_size);
    for (int i = 0; i < VIEW_COUNT; i++)
        free(job.packed[i]);
    return rc;
}

static void json_view(proto_glb_json *j, const view *v, int target)
{
    proto_glb_json_add(j, "{\"buffer\":1,\"byteOffset\":%zu,\"byteLength\":%zu,", v->offset, v->length);
    if (!v->triangles)
        proto_glb_json_add(j, "\"byteStride\":%zu,", v->stride);
    proto_glb_json_add(j, "\"target\":%d,\"extensions\":{\"EXT_meshopt_compression\":{\"buffer\":0,"
                          "\"byteOffset\":%zu,\"byteLength\":%zu,\"byteStride\":%zu,\"mode\":\"%s\","
                          "\"count\":%zu}}}",
                       target, v->packed_offset, v->packed_length, v->stride,
                       v->triangles ? "TRIANGLES" : "ATTRIBUTES", v->count);
}

/* Pass 3's JSON: node (dequantizing), mesh, accessors, views, the two buffers. */
static void json_mesh(proto_glb_json *j, const quantized *q, size_t bin_size)
{
    const int normals = q->normals;
    const view *views = q->views;
    proto_glb_json_add(j, "{\"asset\":{\"version\":\"2.0\",\"generator\":\"isoserve\"},"
                          "\"extensionsUsed\":[\"EXT_meshopt_compression\",\"KHR_mesh_quantization\"],"
                          "\"extensionsRequired\":[\"EXT_meshopt_compression\",\"KHR_mesh_quantization\"],"
                          "\"scene\":0,\"scenes\":[{\"nodes\":[0]}],\"nodes\":[{\"mesh\":0");
    if (!q->float_positions)
        proto_glb_json_add(j, ",\"translation\":[%.9g,%.9g,%.9g],\"scale\":[%.9g,%.9g,%.9g]",
                           q->origin[0], q->origin[1], q->origin[2], q->step, q->step, q->step);
    proto_glb_json_add(j, "}],\"meshes\":[{\"primitives\":[{\"attributes\":{\"POSITION\":0%s},"
                          "\"indices\":%d,\"mode\":%d}]}],",
                       normals ? ",\"NORMAL\":1" : "", normals ? 2 : 1, PROTO_GLTF_TRIANGLES);
    proto_glb_json_add(j, "\"accessors\":[{\"bufferView\":0,\"componentType\":%d,\"count\":%zu,"
                          "\"type\":\"VEC3\",\"min\":[%.9g,%.9g,%.9g],\"max\":[%.9g,%.9g,%.9g]}",
                       q->float_positions ? PROTO_GLTF_FLOAT : PROTO_GLTF_UNSIGNED_SHORT,
                       views[VIEW_POSITION].count, q->qmin[0], q->qmin[1], q->qmin[2], q->qmax[0],
                       q->qmax[1], q->qmax[2]);
    if (normals)
        proto_glb_json_add(j, ",{\"bufferView\":1,\"componentType\":%d,\"normalized\":true,"
                              "\"count\":%zu,\"type\":\"VEC3\"}",
                           q->normal_type, views[VIEW_NORMAL].count);
    proto_glb_json_add(j, ",{\"bufferView\":%d,\"componentType\":%d,\"count\":%zu,\"type\":\"SCALAR\"}],"
                          "\"bufferViews\":[",
                       normals ? 2 : 1, q->index_type, views[VIEW_INDEX].count);
    json_view(j, &views[VIEW_POSITION], 34962);
    if (normals) {
        proto_glb_json_add(j, ",");
        json_view(j, &views[VIEW_NORMAL], 34962);
    }
    proto_glb_json_add(j, ",");
    json_view(j, &views[VIEW_INDEX], 34963);
    const view *last = &views[VIEW_INDEX];
    proto_glb_json_add(j, "],\"buffers\":[{\"byteLength\":%zu},{\"byteLength\":%zu,"
                          "\"extensions\":{\"EXT_meshopt_compression\":{\"fallback\":true}}}]}",
                       bin_size, last->offset + proto_glb_pad4(last->length));
}

int proto_encode_glb_meshopt(const iso_mesh *mesh, const proto_encode_options *opt,
                             unsigned char **out, size_t *out_size, iso_error *err)
{
    assert(mesh && out && out_size);
    *out = NULL;
    *out_size = 0;
    proto_encode_options defaults;
    if (!opt) {
        proto_encode_options_init(&defaults);
        opt = &defaults;
    }
    if (opt->position_bits < PROTO_POSITION_BITS_MIN || opt->position_bits > PROTO_POSITION_BITS_MAX ||
        opt->normal_bits < PROTO_NORMAL_BITS_MIN || opt->normal_bits > PROTO_NORMAL_BITS_MAX)
        return iso_error_set(err, ISO_E_ARGUMENT, "position bits %d or normal bits %d outside %d..%d, %d..%d",
                             opt->position_bits, opt->normal_bits, PROTO_POSITION_BITS_MIN,
                             PROTO_POSITION_BITS_MAX, PROTO_NORMAL_BITS_MIN, PROTO_NORMAL_BITS_MAX);
    int rc = proto_mesh_check(mesh, 1, err);
    if (rc)
        return rc;
    proto_glb_json json = {.len = 0};
    if (mesh->triangle_count == 0) {
        proto_glb_json_empty(&json);
        return proto_glb_write(&json, NULL, 0, out, out_size, err);
    }
    const int normals = mesh->normals != NULL;
    quantized q = {.normals = normals};
    q.index_type = mesh->vertex_count <= UINT16_MAX ? PROTO_GLTF_UNSIGNED_SHORT : PROTO_GLTF_UNSIGNED_INT;
    q.views[VIEW_INDEX] = (view){.data = mesh->indices, .count = 3 * mesh->triangle_count,
                                 .stride = q.index_type == PROTO_GLTF_UNSIGNED_SHORT ? 2 : 4,
                                 .triangles = 1};
    unsigned char *bin = NULL;
    size_t bin_size = 0;
    rc = pack(mesh, opt, &q, &bin, &bin_size);
    if (rc) {
        quantized_free(&q);
        return iso_error_set(err, rc, "no memory to encode a glb of %zu vertices", mesh->vertex_count);
    }
    json_mesh(&json, &q, bin_size);
    rc = proto_glb_write(&json, bin, bin_size, out, out_size, err);
    free(bin);
    quantized_free(&q);
    return rc;
}

int proto_glb_meshopt_gzip_pieces(const unsigned char *glb, size_t size,
                                  proto_gzip_piece pieces[PROTO_GZIP_PIECES_MAX])
{
    pieces[0] = (proto_gzip_piece){.end = size};
    /* The header (12 bytes), the JSON chunk's length and type, its text, the BIN chunk's. */
    if (size < 20 || memcmp(glb, "glTF", 4))
        return 1;
    size_t json_length = (size_t)glb[12] | (size_t)glb[13] << 8 | (size_t)glb[14] << 16 | (size_t)glb[15] << 24;
    if (json_length > size - 28)
        return 1;
    /* The index view (json_view's text): the BIN chunk's last, after the vertex streams. */
    const char *json = (const char *)glb + 20, *mode = NULL;
    static const char triangles[] = "\"mode\":\"TRIANGLES\"", key[] = "\"EXT_meshopt_compression\":{\"buffer\":0,\"byteOffset\":";
    for (size_t i = 0; i + sizeof triangles - 1 <= json_length && !mode; i++)
        if (!memcmp(json + i, triangles, sizeof triangles - 1))
            mode = json + i;
    const char *number = NULL;
    for (const char *p = json; mode && p + sizeof key - 1 < mode; p++)
        if (!memcmp(p, key, sizeof key - 1))
            number = p + sizeof key - 1;
    if (!number)
        return 1;
    size_t offset = 0;
    for (; number < mode && *number >= '0' && *number <= '9'; number++)
        offset = offset * 10 + (size_t)(*number - '0');
    size_t start = 20 + json_length + 8 + offset;
    if (start >= size)
        return 1;
    pieces[0] = (proto_gzip_piece){.end = start, .huffman = 1};
    pieces[1] = (proto_gzip_piece){.end = size};
    return 2;
}
