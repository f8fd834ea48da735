/* glb_meshopt.c: the glTF 2.0 binary encoder whose buffer views are compressed with
 * meshoptimizer's vertex and index codecs (EXT_meshopt_compression) over quantized
 * attributes (KHR_mesh_quantization), as three.js's GLTFLoader + MeshoptDecoder read it.
 *
 * Passes, in order:
 *   0. number by first use: vertex v gets the next number at its first corner (those no
 *      triangle uses come last, in their order), the indices rewritten to the new
 *      numbers, each checked against the vertex count on the way. The index codec then
 *      codes most new vertices as its cheap "next vertex" (CThead skin's index stream
 *      27% smaller than in the extraction's order), and the vertex streams follow their
 *      triangles. One pass, before the others (both streams need it);
 *   1. quantize: (a) the positions' grid, the mesh's bounding cube, whose corner and step
 *      the node's translation and scale carry back to world units; (b) positions to
 *      qp-bit integers on the grid (uint16, four per vertex as the codec wants strides of
 *      4; above 16 bits, float positions unquantized), normals to signed normalized
 *      integers (int8 up to 8 bits, else int16 with the bits below qn cleared: zeros the
 *      codec's byte deltas compress to nothing);
 *   2. encode each stream (positions, normals, indices) straight into the glb's buffer,
 *      each at its own place, with the library's codecs' bytes found faster
 *      (glb_meshopt_codec.h). With two threads the indices (which need no quantizing) go
 *      on one while the other does pass 1 and the vertex streams; the bytes do not depend
 *      on the threads. The uncompressed layout lives in a second, fallback buffer that
 *      has no data (the extension is required);
 *   3. the JSON and the container's head (glb_container.h) written in front, the streams
 *      moved down behind it, each 4-byte aligned, and the unused end given back.
 * Every vertex and triangle is kept, the triangles in order (the index codec may start a
 * triangle at another corner, same winding), each corner with its vertex's attributes: a
 * loader gets the same mesh and its counts exactly, numbered by first use. */
#include "encode.h"
#include "base/base.h"
#include "glb_container.h"
#include "glb_meshopt_codec.h"
#include "gzip_parts.h"

#include <assert.h>
#include <math.h>
#include <meshoptimizer.h>
#include <pthread.h>
#include <stdint.h>
#include <stdlib.h>
#include <string.h>
#if defined(__SSE2__)
#include <emmintrin.h>
#endif

/* Below this many triangles one thread encodes it all: handing half to another thread
 * (waiting for it on a busy machine) would cost more than it saves. */
#define MESHOPT_TRIANGLES_PER_THREAD 100000

/* The position bits the uint16 components hold; more bits keep float positions. */
#define MESHOPT_POSITION_BITS_MAX 16

enum { VIEW_POSITION, VIEW_NORMAL, VIEW_INDEX, VIEW_COUNT };

/* One buffer view: its uncompressed data (stride bytes per element) and where its
 * compressed bytes go. */
typedef struct view {
    const void *data;
    size_t count, stride;
    int triangles;                   /* 1: the index codec, 0: the vertex codec */
    size_t offset, length;           /* in the fallback buffer (uncompressed) */
    size_t packed_offset, packed_length; /* in the BIN chunk */
    size_t bound;                    /* the codec's bound on packed_length */
    unsigned char *packed;           /* where the codec wrote it (in the glb's buffer) */
} view;

/* The quantized mesh and its JSON facts. */
typedef struct quantized {
    view views[VIEW_COUNT];
    int normals;                     /* 0: no normal view (its slot stays empty) */
    int float_positions;
    int normal_type;                 /* PROTO_GLTF_BYTE or PROTO_GLTF_SHORT */
    int index_type;                  /* PROTO_GLTF_UNSIGNED_SHORT or _INT */
    float origin[3], step;           /* world = origin + step * q */
    double extent, steps;            /* the grid: the cube's side, its steps (2^qp - 1) */
    double qmin[3], qmax[3];         /* the POSITION accessor's bounds, in its units */
} quantized;

/* lround(x) for |x| < 2^62 without a library call or a branch: halves away from zero. */
static inline long round_half_away(double x)
{
    double a = fabs(x);
    long k = (long)(a + 0.5);
    k -= (double)k - a > 0.5; /* a + 0.5 rounded up (a just under a half) */
    return x < 0 ? -k : k;
}

/* A position's step count on an axis: round((p - lo) / extent * steps), as Draco's grid
 * rounds it. */
static long position_step(float p, float lo, double extent, double steps)
{
    return round_half_away(((double)p - lo) / extent * steps);
}

/* Pass 1a, positions' grid: the bounding cube's corner and step (Draco's grid, so that
 * qp means the same for both codecs). Rounding is monotonic, so the accessor's bounds are
 * the box's corners' steps. */
static void position_grid(const iso_mesh *mesh, int bits, quantized *q)
{
    size_t n = mesh->vertex_count;
    const float *p = mesh->positions;
    float x0 = p[0], y0 = p[1], z0 = p[2], x1 = x0, y1 = y0, z1 = z0; /* in registers */
    for (size_t i = 1; i < n; i++) {
        const float *v = p + 3 * i;
        x0 = v[0] < x0 ? v[0] : x0, x1 = v[0] > x1 ? v[0] : x1;
        y0 = v[1] < y0 ? v[1] : y0, y1 = v[1] > y1 ? v[1] : y1;
        z0 = v[2] < z0 ? v[2] : z0, z1 = v[2] > z1 ? v[2] : z1;
    }
    const float lo[3] = {x0, y0, z0}, hi[3] = {x1, y1, z1};
    q->float_positions = bits > MESHOPT_POSITION_BITS_MAX;
    q->extent = 0;
    q->steps = q->float_positions ? 0 : (double)((1u << bits) - 1);
    for (int a = 0; a < 3; a++) {
        q->origin[a] = lo[a];
        q->extent = fmax(q->extent, (double)hi[a] - lo[a]);
    }
    q->step = q->extent > 0 && !q->float_positions ? (float)(q->extent / q->steps) : 1.0f;
    for (int a = 0; a < 3; a++) {
        if (q->float_positions)
            q->qmin[a] = lo[a], q->qmax[a] = hi[a];
        else
            q->qmin[a] = 0, q->qmax[a] = q->extent > 0 ? (double)position_step(hi[a], lo[a], q->extent, q->steps) : 0;
    }
}

/* Pass 1b, positions on the grid, vertex i being the mesh's order[i]: vertex i's component a
 * as its step count, clamped to the grid. The division is done as a product by its
 * inverse; a result within 1e-6 of a half step, where the two could round apart, is
 * redone as the division. */
static uint16_t position_component(float p, float lo, double extent, double steps, double inverse)
{
    double t = ((double)p - lo) * inverse; /* >= 0 */
    double half = t - (double)(long)t - 0.5;
    long r = fabs(half) < 1e-6 ? position_step(p, lo, extent, steps) : (long)(t + 0.5);
    return (uint16_t)(r > (long)steps ? (long)steps : r);
}

#if defined(__SSE2__)
/* position_component on a vertex's three components at once (two lanes of doubles, the
 * same operations in the same order, so the same results); 0 when one of them is near a
 * half step and needs the division. */
static inline int position_vertex_sse2(const float *p, __m128d lo01, __m128d lo2, __m128d inverse,
                                       __m128i steps, uint16_t *out)
{
    const __m128d half = _mm_set1_pd(0.5), near = _mm_set1_pd(1e-6), sign = _mm_set1_pd(-0.0);
    double xy;
    memcpy(&xy, p, sizeof xy);
    __m128d a = _mm_cvtps_pd(_mm_castpd_ps(_mm_set_sd(xy))), b = _mm_cvtps_pd(_mm_set_ss(p[2]));
    a = _mm_mul_pd(_mm_sub_pd(a, lo01), inverse);
    b = _mm_mul_pd(_mm_sub_pd(b, lo2), inverse); /* z, and 0 in the pad lane */
    __m128d fa = _mm_sub_pd(_mm_sub_pd(a, _mm_cvtepi32_pd(_mm_cvttpd_epi32(a))), half);
    __m128d fb = _mm_sub_pd(_mm_sub_pd(b, _mm_cvtepi32_pd(_mm_cvttpd_epi32(b))), half);
    if (_mm_movemask_pd(_mm_cmplt_pd(_mm_andnot_pd(sign, fa), near)) |
        _mm_movemask_pd(_mm_cmplt_pd(_mm_andnot_pd(sign, fb), near)))
        return 0;
    __m128i r = _mm_unpacklo_epi64(_mm_cvttpd_epi32(_mm_add_pd(a, half)), _mm_cvttpd_epi32(_mm_add_pd(b, half)));
    __m128i over = _mm_cmpgt_epi32(r, steps);
    r = _mm_or_si128(_mm_and_si128(over, steps), _mm_andnot_si128(over, r));
    /* 0..65535 to uint16 through the signed pack: shifted down by 32768 and back. */
    const __m128i bias32 = _mm_set1_epi32(32768), bias16 = _mm_set1_epi16(-32768);
    r = _mm_xor_si128(_mm_packs_epi32(_mm_sub_epi32(r, bias32), _mm_sub_epi32(r, bias32)), bias16);
    _mm_storel_epi64((__m128i *)(void *)out, r);
    return 1;
}
#endif

static void quantize_positions(const iso_mesh *mesh, const uint32_t *order, const quantized *q, void *out)
{
    if (q->float_positions) {
        float *f = out;
        for (size_t i = 0; i < mesh->vertex_count; i++)
            memcpy(f + 3 * i, mesh->positions + 3 * (size_t)order[i], 12);
        return;
    }
    uint16_t *k = out;
    const double extent = q->extent, steps = q->steps, inverse = extent > 0 ? steps / extent : 0;
#if defined(__SSE2__)
    const __m128d lo01 = _mm_set_pd(q->origin[1], q->origin[0]), lo2 = _mm_set_pd(0, q->origin[2]);
    const __m128d inv = _mm_set1_pd(inverse);
    const __m128i top = _mm_set1_epi32((int)steps);
#endif
    for (size_t i = 0; i < mesh->vertex_count; i++) {
        const float *p = mesh->positions + 3 * (size_t)order[i];
#if defined(__SSE2__)
        if (position_vertex_sse2(p, lo01, lo2, inv, top, k + 4 * i))
            continue;
#endif
        for (int a = 0; a < 3; a++)
            k[4 * i + a] = position_component(p[a], q->origin[a], extent, steps, inverse);
        k[4 * i + 3] = 0;
    }
}

/* Pass 1b, normals (vertex i being the mesh's order[i]): int8 (stride 4) up to 8 bits, else int16
 * (stride 8) rounded to qn bits: round(x * max / grain) * grain, the grain a power of two
 * (so dividing by it is multiplying by its exact inverse). */
#if defined(__SSE2__)
/* round_half_away(v * max * inverse) * grain, clamped to +-top, on two lanes (the same
 * operations in the same order as the scalar loop, so the same results), in the low two
 * int32 lanes; *big set when a lane is past 2^16 steps, which the shift by the grain
 * could carry past int32 (the scalar loop then does the vertex). */
static inline __m128i normal_lanes(__m128d v, __m128d max, __m128d inverse, __m128i shift, __m128i top, int *big)
{
    const __m128d half = _mm_set1_pd(0.5), sign = _mm_set1_pd(-0.0), limit = _mm_set1_pd(1 << 16);
    v = _mm_mul_pd(_mm_mul_pd(v, max), inverse);
    __m128d a = _mm_andnot_pd(sign, v);
    *big |= _mm_movemask_pd(_mm_cmpge_pd(a, limit));
    __m128i k = _mm_cvttpd_epi32(_mm_add_pd(a, half));
    __m128i over = _mm_shuffle_epi32(_mm_castpd_si128(_mm_cmpgt_pd(_mm_sub_pd(_mm_cvtepi32_pd(k), a), half)),
                                     _MM_SHUFFLE(3, 3, 2, 0));
    k = _mm_add_epi32(k, over); /* a + 0.5 rounded up: one less */
    __m128i negative = _mm_shuffle_epi32(_mm_castpd_si128(_mm_cmplt_pd(v, _mm_setzero_pd())), _MM_SHUFFLE(3, 3, 2, 0));
    k = _mm_sub_epi32(_mm_xor_si128(k, negative), negative);
    k = _mm_sll_epi32(k, shift);
    __m128i high = _mm_cmpgt_epi32(k, top), bottom = _mm_sub_epi32(_mm_setzero_si128(), top);
    k = _mm_or_si128(_mm_and_si128(high, top), _mm_andnot_si128(high, k));
    __m128i low = _mm_cmplt_epi32(k, bottom);
    return _mm_or_si128(_mm_and_si128(low, bottom), _mm_andnot_si128(low, k));
}
#endif

static void quantize_normals(const iso_mesh *mesh, const uint32_t *order, int bits, void *out)
{
    const int wide = bits > 8;
    const double max = wide ? 32767 : 127;
    const long grain = wide ? 1L << (16 - bits) : 1, top = (long)max;
    const double inverse = 1.0 / (double)grain;
    if (wide) {
        int16_t *k = out;
#if defined(__SSE2__)
        const __m128d max2 = _mm_set1_pd(max), inverse2 = _mm_set1_pd(inverse);
        const __m128i shift = _mm_cvtsi32_si128(16 - bits), top4 = _mm_set1_epi32((int)top);
#endif
        for (size_t i = 0; i < mesh->vertex_count; i++) {
            const float *x = mesh->normals + 3 * (size_t)order[i];
#if defined(__SSE2__)
            double xy;
            memcpy(&xy, x, sizeof xy);
            int big = 0;
            __m128i lanes = _mm_unpacklo_epi64(
                normal_lanes(_mm_cvtps_pd(_mm_castpd_ps(_mm_set_sd(xy))), max2, inverse2, shift, top4, &big),
                normal_lanes(_mm_cvtps_pd(_mm_set_ss(x[2])), max2, inverse2, shift, top4, &big));
            if (!big) {
                _mm_storel_epi64((__m128i *)(void *)(k + 4 * i), _mm_packs_epi32(lanes, lanes));
                continue;
            }
#endif
            for (int a = 0; a < 3; a++) {
                long r = round_half_away((double)x[a] * max * inverse) * grain;
                k[4 * i + a] = (int16_t)(r > top ? top : r < -top ? -top : r);
            }
            k[4 * i + 3] = 0;
        }
    } else {
        int8_t *k = out;
        for (size_t i = 0; i < mesh->vertex_count; i++) {
            const float *x = mesh->normals + 3 * (size_t)order[i];
            for (int a = 0; a < 3; a++) {
                long r = round_half_away((double)x[a] * max);
                k[4 * i + a] = (int8_t)(r > top ? top : r < -top ? -top : r);
            }
            k[4 * i + 3] = 0;
        }
    }
}

/* Pass 2 for one view: its compressed bytes at v->packed (v->bound bytes there), padded
 * with zeros to 4 as the BIN chunk holds them (the codec's bound leaves 4 bytes of room). */
static void encode_view(view *v)
{
    v->packed_length = v->triangles ? proto_meshopt_encode_indices(v->packed, v->bound, v->data, v->count)
                                    : proto_meshopt_encode_vertices(v->packed, v->bound, v->data, v->count, v->stride);
    assert(v->packed_length > 0); /* the bounds are the codecs' own */
    memset(v->packed + v->packed_length, 0, proto_glb_pad4(v->packed_length) - v->packed_length);
}

/* Pass 0: order[new] = the old vertex, and the indices in the new numbers into
 * `renumbered`; `seen` (vertex_count entries) is scratch, old to new; order holds one
 * entry more than there are vertices. Returns the first corner whose index is not below
 * the vertex count (nothing numbered then), else the corner count. */
static size_t number_by_first_use(const iso_mesh *mesh, uint32_t *seen, uint32_t *order, uint32_t *renumbered)
{
    const size_t n = mesh->vertex_count, corners = 3 * mesh->triangle_count;
    const uint32_t *in = mesh->indices;
    memset(seen, 0xff, n * sizeof *seen);
    uint32_t next = 0;
    /* Without a branch on "new": a sixth of the corners are, in no pattern a predictor
     * learns. order[next] is written every time and kept when next moves on. */
    for (size_t i = 0; i < corners; i++) {
        uint32_t v = in[i];
        if (v >= n)
            return i;
        uint32_t k = seen[v], fresh = k == UINT32_MAX;
        k = fresh ? next : k;
        seen[v] = k;
        order[next] = v;
        next += fresh;
        renumbered[i] = k;
    }
    for (size_t v = 0; v < n && next < n; v++)
        if (seen[v] == UINT32_MAX)
            order[next++] = (uint32_t)v;
    return corners;
}

/* The encode as tasks for up to two threads (the caller's and one helper, see run()). */
enum { TASK_NUMBER, TASK_INDEX, TASK_NORMALS, TASK_POSITIONS, TASK_NORMAL_VIEW, TASK_POSITION_GZIP,
       TASK_INDEX_CODES_GZIP, TASK_INDEX_DATA_GZIP, TASK_COUNT };

/* What each task reads that another makes: the index view and both vertex views need the
 * numbering, the normal view needs the normals, the gzip parts of the positions and the
 * index their views. */
static const unsigned task_needs[TASK_COUNT] = {
    [TASK_INDEX] = 1u << TASK_NUMBER, [TASK_POSITIONS] = 1u << TASK_NUMBER,
    [TASK_NORMAL_VIEW] = 1u << TASK_NUMBER | 1u << TASK_NORMALS,
    [TASK_POSITION_GZIP] = 1u << TASK_POSITIONS, [TASK_INDEX_CODES_GZIP] = 1u << TASK_INDEX,
    [TASK_INDEX_DATA_GZIP] = 1u << TASK_INDEX};

/* The order in which each share takes the tasks: one starts the longest chain (the
 * numbering, then the index codec, sequential by its format, and its gzip parts), the other
 * the normals, which the index side does not read, then the vertex views; each then takes
 * what is left. The gzip parts of the positions and the index are tasks of their own, so
 * that whichever share is done first takes them: with tricubic normals the index side
 * ends first and takes the positions', with cheaper normals the other
 * share takes the index's. */
static const int task_order[2][TASK_COUNT] = {
    {TASK_NUMBER, TASK_INDEX, TASK_INDEX_CODES_GZIP, TASK_INDEX_DATA_GZIP, TASK_POSITION_GZIP, TASK_POSITIONS,
     TASK_NORMALS, TASK_NORMAL_VIEW},
    {TASK_NORMALS, TASK_POSITIONS, TASK_NORMAL_VIEW, TASK_POSITION_GZIP, TASK_INDEX_DATA_GZIP,
     TASK_INDEX_CODES_GZIP, TASK_NUMBER, TASK_INDEX}};

/* The gzip member's parts, in the glb's order: the container's head (deflated last, when
 * its JSON is known), the vertex views, the index view's header and codes (matched: the
 * codec's repeats), its data and table (Huffman only). */
enum { PART_HEAD, PART_POSITIONS, PART_NORMALS, PART_INDEX_CODES, PART_INDEX_DATA, PART_COUNT };

typedef struct pack_job {
    const iso_mesh *mesh;
    const proto_encode_options *opt;
    const proto_meshopt_run *run;    /* the normals to make first, gzip or not */
    quantized *q;
    void *positions, *normals;       /* the quantized data the views read */
    uint32_t *seen, *order, *renumbered; /* pass 0's tables */
    int shares;                      /* 1 or 2 */
    proto_deflate parts[PART_COUNT]; /* when gzipping */
    double normals_done;             /* iso_clock_ms() when the normals were there */
    pthread_mutex_t lock;            /* over the fields below */
    pthread_cond_t changed;
    unsigned claimed, done;          /* bit masks of tasks */
    int rc;                          /* the first failing task's */
    iso_error err;
} pack_job;

/* A padded stream's gzip part, when gzipping: the whole of a vertex view; the index view's
 * header and codes (a header byte, a code byte per triangle) or the rest. */
static void deflate_view(pack_job *job, int view_index, int part)
{
    view *v = &job->q->views[view_index];
    size_t padded = proto_glb_pad4(v->packed_length), codes = 1 + job->mesh->triangle_count;
    if (!job->run->gzip)
        return;
    proto_deflate *d = &job->parts[part];
    d->in = v->packed, d->size = padded;
    if (part == PART_INDEX_CODES)
        d->size = codes;
    else if (part == PART_INDEX_DATA)
        d->in += codes, d->size -= codes;
    proto_deflate_run(d);
}

/* One task; 0 or its error (into *err). */
static int run_task(pack_job *job, int task, iso_error *err)
{
    const iso_mesh *mesh = job->mesh;
    quantized *q = job->q;
    switch (task) {
    case TASK_NUMBER:
        if (number_by_first_use(mesh, job->seen, job->order, job->renumbered) < q->views[VIEW_INDEX].count)
            return proto_mesh_check_data(mesh, 0, err); /* says which index */
        return 0;
    case TASK_INDEX:
        encode_view(&q->views[VIEW_INDEX]);
        return 0;
    case TASK_INDEX_CODES_GZIP:
        deflate_view(job, VIEW_INDEX, PART_INDEX_CODES);
        return 0;
    case TASK_INDEX_DATA_GZIP:
        deflate_view(job, VIEW_INDEX, PART_INDEX_DATA);
        return 0;
    case TASK_NORMALS: {
        int rc = job->run->make_normals ? job->run->make_normals(job->run->context, job->shares > 1 ? 1 : job->opt->threads, err) : 0;
        job->normals_done = iso_clock_ms();
        return rc;
    }
    case TASK_POSITIONS:
        if (!proto_floats_finite(mesh->positions, 3 * mesh->vertex_count))
            return iso_error_set(err, ISO_E_ARGUMENT, "mesh has a non-finite position");
        position_grid(mesh, job->opt->position_bits, q);
        quantize_positions(mesh, job->order, q, job->positions);
        encode_view(&q->views[VIEW_POSITION]);
        return 0;
    case TASK_POSITION_GZIP:
        deflate_view(job, VIEW_POSITION, PART_POSITIONS);
        return 0;
    case TASK_NORMAL_VIEW:
        if (!q->normals)
            return 0;
        if (!mesh->normals)
            return iso_error_set(err, ISO_E_INTERNAL, "the normals were promised and not made");
        if (!proto_floats_finite(mesh->normals, 3 * mesh->vertex_count))
            return iso_error_set(err, ISO_E_ARGUMENT, "mesh has a non-finite normal");
        quantize_normals(mesh, job->order, job->opt->normal_bits, job->normals);
        encode_view(&q->views[VIEW_NORMAL]);
        deflate_view(job, VIEW_NORMAL, PART_NORMALS);
        return 0;
    }
    return 0;
}

/* A share takes, in its order, the first task not taken whose inputs are taken (being
 * made by a share that is running, so waiting for them cannot deadlock, whichever shares
 * run and when), waits for those inputs, runs it; until none is left. After a failure the
 * tasks left are taken and skipped. */
static void pack_share(void *context, int t, int threads)
{
    (void)threads;
    pack_job *job = context;
    const int *order = task_order[t % 2];
    pthread_mutex_lock(&job->lock);
    for (;;) {
        int task = -1;
        for (int k = 0; k < TASK_COUNT && task < 0; k++) {
            int c = order[k];
            if (!(job->claimed >> c & 1) && (task_needs[c] & ~job->claimed) == 0)
                task = c;
        }
        if (task < 0)
            break;
        job->claimed |= 1u << task;
        while ((task_needs[task] & ~job->done) != 0)
            pthread_cond_wait(&job->changed, &job->lock);
        int skip = job->rc != 0;
        pthread_mutex_unlock(&job->lock);
        iso_error err = {0};
        int rc = skip ? 0 : run_task(job, task, &err);
        pthread_mutex_lock(&job->lock);
        if (rc && !job->rc) {
            job->rc = rc;
            job->err = err;
        }
        job->done |= 1u << task;
        pthread_cond_broadcast(&job->changed);
    }
    pthread_mutex_unlock(&job->lock);
}

/* Lays out the views' compressed bytes in the BIN chunk, each 4-byte aligned, and the
 * fallback buffer; returns the BIN chunk's size. */
static size_t layout(quantized *q)
{
    size_t offset = 0, used = 0;
    for (int i = 0; i < VIEW_COUNT; i++) {
        view *v = &q->views[i];
        if (!v->packed)
            continue;
        v->offset = offset;
        v->length = v->count * v->stride;
        offset += proto_glb_pad4(v->length);
        v->packed_offset = used;
        used += proto_glb_pad4(v->packed_length);
    }
    return used;
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

/* Each view's codec bound, and where in the glb's buffer (after room for the container's
 * head) its codec writes. Returns the buffer's size. */
static size_t plan_buffer(quantized *q, const proto_encode_options *opt)
{
    view *pos = &q->views[VIEW_POSITION], *nrm = &q->views[VIEW_NORMAL], *idx = &q->views[VIEW_INDEX];
    pos->stride = opt->position_bits > MESHOPT_POSITION_BITS_MAX ? 12 : 8;
    nrm->stride = opt->normal_bits > 8 ? 8 : 4;
    pos->bound = meshopt_encodeVertexBufferBound(pos->count, pos->stride);
    nrm->bound = q->normals ? meshopt_encodeVertexBufferBound(nrm->count, nrm->stride) : 0;
    idx->bound = meshopt_encodeIndexBufferBound(idx->count, pos->count);
    size_t at = PROTO_GLB_HEAD_MAX;
    for (int i = 0; i < VIEW_COUNT; i++)
        if (q->views[i].bound)
            at += q->views[i].bound + 4; /* a view padded to 4 never reaches the next */
    return at;
}

/* The most input bytes of each gzip part (the streams at their codecs' bounds, padded),
 * into room[]; returns the sum of their deflate bounds. */
static size_t part_rooms(const quantized *q, size_t triangles, size_t room[PART_COUNT])
{
    room[PART_HEAD] = PROTO_GLB_HEAD_MAX;
    room[PART_POSITIONS] = q->views[VIEW_POSITION].bound + 4;
    room[PART_NORMALS] = q->normals ? q->views[VIEW_NORMAL].bound + 4 : 0;
    room[PART_INDEX_CODES] = 1 + triangles;
    room[PART_INDEX_DATA] = q->views[VIEW_INDEX].bound + 4;
    size_t total = 0;
    for (int i = 0; i < PART_COUNT; i++)
        total += proto_deflate_bound(room[i]);
    return total;
}

/* Pass 3: the JSON and the head in front of the streams, which move down behind it; the
 * buffer shrunk to the glb. With gzip, the head deflated and the parts joined. */
static int assemble(pack_job *job, unsigned char *buf, proto_meshopt_run *run, unsigned char **out,
                    size_t *out_size, iso_error *err)
{
    quantized *q = job->q;
    size_t bin_size = layout(q), size;
    proto_glb_json json = {.len = 0};
    json_mesh(&json, q, bin_size);
    int rc = proto_glb_size(&json, bin_size, &size, err);
    if (rc)
        return rc;
    size_t head = proto_glb_head(&json, bin_size, buf);
    if (run->gzip) {
        proto_deflate *d = &job->parts[PART_HEAD];
        d->in = buf, d->size = head;
        proto_deflate_run(d);
    }
    for (int i = 0; i < VIEW_COUNT; i++) {
        view *v = &q->views[i];
        if (v->packed)
            memmove(buf + head + v->packed_offset, v->packed, proto_glb_pad4(v->packed_length));
    }
    assert(head + bin_size == size);
    run->glb_done = iso_clock_ms();
    if (run->gzip) {
        /* The parts, no normals' part without normals; the member joined from them. */
        proto_deflate parts[PART_COUNT];
        int n = 0;
        for (int i = 0; i < PART_COUNT; i++)
            if (i != PART_NORMALS || q->normals)
                parts[n++] = job->parts[i];
        rc = proto_gzip_join(parts, n, &run->gzip_bytes, &run->gzip_size, err);
        run->gzip_done = iso_clock_ms();
        if (rc)
            return rc;
    }
    unsigned char *shrunk = realloc(buf, size);
    *out = shrunk ? shrunk : buf;
    *out_size = size;
    return 0;
}

int proto_encode_glb_meshopt_run(const iso_mesh *mesh, const proto_encode_options *opt,
                                 proto_meshopt_run *run, unsigned char **out, size_t *out_size,
                                 iso_error *err)
{
    assert(mesh && run && out && out_size);
    *out = NULL;
    *out_size = 0;
    run->gzip_bytes = NULL;
    run->gzip_size = 0;
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
    int rc = proto_mesh_check_counts(mesh, err);
    if (rc)
        return rc;
    if (mesh->triangle_count == 0) {
        /* Nothing to overlap: the normals, then the empty glb (and its gzip). */
        if (run->make_normals && (rc = run->make_normals(run->context, opt->threads, err)))
            return rc;
        run->normals_done = iso_clock_ms();
        proto_glb_json json = {.len = 0};
        if ((rc = proto_mesh_check_data(mesh, 1, err)))
            return rc;
        proto_glb_json_empty(&json);
        rc = proto_glb_write(&json, NULL, 0, out, out_size, err);
        run->glb_done = iso_clock_ms();
        if (!rc && run->gzip && (rc = proto_gzip(*out, *out_size, &run->gzip_bytes, &run->gzip_size, err))) {
            free(*out);
            *out = NULL;
            *out_size = 0;
        }
        run->gzip_done = iso_clock_ms();
        return rc;
    }
    quantized q = {.normals = mesh->normals != NULL || run->make_normals};
    q.index_type = mesh->vertex_count <= UINT16_MAX ? PROTO_GLTF_UNSIGNED_SHORT : PROTO_GLTF_UNSIGNED_INT;
    q.views[VIEW_POSITION].count = q.views[VIEW_NORMAL].count = mesh->vertex_count;
    q.views[VIEW_INDEX] = (view){.count = 3 * mesh->triangle_count,
                                 .stride = q.index_type == PROTO_GLTF_UNSIGNED_SHORT ? 2 : 4,
                                 .triangles = 1};
    /* One buffer for the glb: the codecs write into it where plan_buffer says, then the
     * streams move down behind the head and the rest is given back. */
    size_t capacity = plan_buffer(&q, opt);
    size_t position_bytes = mesh->vertex_count * q.views[VIEW_POSITION].stride;
    size_t vertex_bytes = position_bytes + mesh->vertex_count * q.views[VIEW_NORMAL].stride;
    pack_job job = {.mesh = mesh, .opt = opt, .run = run, .q = &q, .shares = 1,
                    .lock = PTHREAD_MUTEX_INITIALIZER, .changed = PTHREAD_COND_INITIALIZER};
    /* The quantized streams, then pass 0's tables: seen and order (a vertex each, order
     * one more), the renumbered indices; then the gzip parts' room. Taken before the glb's
     * buffer, which outlives the call (a server caches it): the scratch of the call before,
     * freed, then fits it again, and its pages are not faulted in anew. */
    size_t tables = vertex_bytes + (2 * mesh->vertex_count + 1 + 3 * mesh->triangle_count) * 4;
    size_t rooms[PART_COUNT], parts_room = run->gzip ? part_rooms(&q, mesh->triangle_count, rooms) : 0;
    unsigned char *scratch = malloc(tables + parts_room);
    unsigned char *buf = malloc(capacity);
    if (!buf || !scratch) {
        free(buf);
        free(scratch);
        return iso_error_set(err, ISO_E_NOMEM, "no memory to encode a glb of %zu vertices", mesh->vertex_count);
    }
    job.positions = scratch;
    job.normals = scratch + position_bytes;
    job.seen = (uint32_t *)(void *)(scratch + vertex_bytes);
    job.order = job.seen + mesh->vertex_count;
    job.renumbered = job.order + mesh->vertex_count + 1;
    if (run->gzip) {
        unsigned char *room = scratch + tables;
        for (int i = 0; i < PART_COUNT; i++) {
            job.parts[i] = (proto_deflate){.out = room, .huffman = i != PART_INDEX_CODES,
                                           .last = i == PART_INDEX_DATA};
            room += proto_deflate_bound(rooms[i]);
        }
    }
    q.views[VIEW_POSITION].data = job.positions;
    q.views[VIEW_NORMAL].data = job.normals;
    q.views[VIEW_INDEX].data = job.renumbered;
    q.normal_type = opt->normal_bits > 8 ? PROTO_GLTF_SHORT : PROTO_GLTF_BYTE;
    size_t at = PROTO_GLB_HEAD_MAX;
    for (int i = 0; i < VIEW_COUNT; i++)
        if (q.views[i].bound) {
            q.views[i].packed = buf + at;
            at += q.views[i].bound + 4;
        }
    int threads = iso_parallel_threads(opt->threads);
    if (threads > 1 && mesh->triangle_count >= MESHOPT_TRIANGLES_PER_THREAD)
        job.shares = 2;
    iso_parallel_run(job.shares, pack_share, &job);
    pthread_mutex_destroy(&job.lock);
    pthread_cond_destroy(&job.changed);
    run->normals_done = job.normals_done;
    rc = job.rc;
    if (rc && err)
        *err = job.err;
    if (!rc)
        rc = assemble(&job, buf, run, out, out_size, err);
    free(scratch);
    if (rc) {
        free(buf);
        free(run->gzip_bytes);
        run->gzip_bytes = NULL;
        run->gzip_size = 0;
    }
    return rc;
}

int proto_encode_glb_meshopt(const iso_mesh *mesh, const proto_encode_options *opt,
                             unsigned char **out, size_t *out_size, iso_error *err)
{
    proto_meshopt_run run = {.gzip = 0};
    return proto_encode_glb_meshopt_run(mesh, opt, &run, out, out_size, err);
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
    /* The index stream (glb_meshopt_index.c): a header byte, a code byte per triangle,
     * then the data (varints of the vertices the FIFOs miss) and a 16-byte table. Matches
     * take 40% off the codes, against 10% more off the data than Huffman codes alone,
     * which per byte saved costs about 10 times what the other streams' coding does. */
    static const char count_key[] = ",\"count\":";
    const char *count_at = mode + sizeof triangles - 1, *json_end = json + json_length;
    if ((size_t)(json_end - count_at) <= sizeof count_key - 1 || memcmp(count_at, count_key, sizeof count_key - 1))
        return 1;
    size_t corners = 0;
    for (const char *d = count_at + sizeof count_key - 1; d < json_end && *d >= '0' && *d <= '9'; d++)
        corners = corners * 10 + (size_t)(*d - '0');
    size_t codes = start + 1 + corners / 3;
    if (codes > size)
        return 1;
    pieces[0] = (proto_gzip_piece){.end = start, .huffman = 1};
    pieces[1] = (proto_gzip_piece){.end = codes};
    pieces[2] = (proto_gzip_piece){.end = size, .huffman = 1};
    return 3;
}
