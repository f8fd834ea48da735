/* fan.c: a node's surface as fans over the marching-squares loops of its faces (fan.h). */
#include "fan.h"

#include <assert.h>
#include <math.h>
#include <pthread.h>
#include <stdlib.h>
#include <string.h>

#include "mc.h"

/* A directed iso-segment on a face, from the crossing it starts at to the one it ends at;
 * a crossing is named by its grid edge: ((z * ny + y) * nx + x) * 3 + axis, (x, y, z)
 * the edge's low end. */
struct iso_fan_segment {
    uint64_t from, to;
    float from_position[3];
    double from_error;
    int used;
};

void iso_fan_scratch_free(iso_fan_scratch *s)
{
    free(s->inside);
    free(s->segments);
    free(s->slots);
    free(s->loop);
    free(s->lengths);
    memset(s, 0, sizeof *s);
}

static int grow(void **array, size_t *capacity, size_t needed, size_t item)
{
    if (needed <= *capacity)
        return 0;
    size_t n = *capacity ? *capacity : 64;
    while (n < needed)
        n *= 2;
    void *p = realloc(*array, n * item);
    if (!p)
        return ISO_E_NOMEM;
    *array = p;
    *capacity = n;
    return 0;
}

/* ---- PASS 1: marching squares on the faces ---- */

typedef struct face {
    const iso_volume *vol;
    double level;
    int axis, b, c;          /* the face is normal to axis; b, c span it, (b, c, axis) right-handed */
    uint32_t fixed;          /* the face's coordinate along axis */
    size_t step[2];          /* linear index steps along b and c */
} face;

/* The four grid edges of a face square, by their low corner's (b, c) offset and the axis
 * they run along (0: b, 1: c). */
typedef struct square_edge {
    uint32_t db, dc;
    int along;
} square_edge;

/* Side i of the walk (from corner i to i + 1, counter-clockwise seen from outside the
 * node: the corners (b, c) = (0,0) (1,0) (1,1) (0,1) on the high side, reversed on the low
 * side) as a grid edge. */
static const square_edge side_edge[2][4] = {
    {{0, 1, 0}, {1, 0, 1}, {0, 0, 0}, {0, 0, 1}},
    {{0, 0, 0}, {1, 0, 1}, {0, 1, 0}, {0, 0, 1}}};

/* The crossing on the grid edge e of the square with low corner (ib, ic), linear index
 * at: its key (fan.h: the low end's linear index * 3 + axis) and, if position is not
 * NULL, its position and |f - level| there, from the same doubles and iso_mc_edge_t as
 * every other module. */
static uint64_t crossing(const face *f, uint32_t ib, uint32_t ic, size_t at, const square_edge *e,
                         float position[3], double *error)
{
    size_t low = at + e->db * f->step[0] + e->dc * f->step[1];
    int d = e->along ? f->c : f->b;
    uint64_t key = (uint64_t)low * 3 + (uint64_t)d;
    if (!position)
        return key;
    double a = iso_vol_sample(f->vol, low), b = iso_vol_sample(f->vol, low + f->step[e->along]);
    double t = iso_mc_edge_t(a, b, f->level);
    uint32_t p[3];
    p[f->axis] = f->fixed;
    p[f->b] = ib + e->db;
    p[f->c] = ic + e->dc;
    for (int k = 0; k < 3; k++)
        position[k] = (float)((double)p[k] + (k == d ? t : 0.0));
    *error = iso_mc_edge_error(a, b, t, f->level);
    if (!(*error >= 0))
        *error = 0; /* a NaN end: no level to be off from */
    return key;
}

/* iso_mc_face_segments for the 16 corner cases, indexed by sum of inside[i] << i: the
 * face rule is asked once, not per square. */
typedef struct face_case {
    int segments, from[2], to[2];
} face_case;

static face_case face_table[16];
static pthread_once_t face_table_once = PTHREAD_ONCE_INIT;

static void build_face_table(void)
{
    for (int index = 0; index < 16; index++) {
        int inside[4] = {index & 1, index >> 1 & 1, index >> 2 & 1, index >> 3 & 1};
        face_case *fc = face_table + index;
        fc->segments = iso_mc_face_segments(inside, fc->from, fc->to);
    }
}

static const face_case *face_cases(void)
{
    pthread_once(&face_table_once, build_face_table);
    return face_table;
}

/* One crossed data cell of the face with low corner (ib, ic) at linear index at, walked
 * as side_edge says: marching cubes' own face rule, so the cell on the other side of the
 * face, of any size, produces the same segments reversed. walk_case: the face_case
 * index of its corners in walk order. */
static int march_square(iso_fan_scratch *s, const face *f, const face_case *table, int high_side,
                        uint32_t ib, uint32_t ic, size_t at, unsigned walk_case)
{
    const face_case *fc = table + walk_case;
    if (grow((void **)&s->segments, &s->segment_capacity, s->segment_count + (size_t)fc->segments,
             sizeof *s->segments))
        return ISO_E_NOMEM;
    for (int r = 0; r < fc->segments; r++) {
        iso_fan_segment *g = s->segments + s->segment_count++;
        g->from = crossing(f, ib, ic, at, &side_edge[high_side][fc->from[r]], g->from_position, &g->from_error);
        g->to = crossing(f, ib, ic, at, &side_edge[high_side][fc->to[r]], NULL, NULL);
        g->used = 0;
    }
    return 0;
}

#define INSIDE_BITS(T)                                                                     \
    for (size_t c = 0; c < nc; c++) {                                                      \
        const T *p = (const T *)vol->data + at + c * step_c;                               \
        for (size_t w = 0, b = 0; w < words; w++) {                                        \
            uint64_t word = 0;                                                             \
            for (size_t end = nb - b < 64 ? nb : b + 64, k = 0; b < end; b++, k++)         \
                word |= (uint64_t)((double)p[b * step_b] > level) << k;                    \
            bits[c * words + w] = word;                                                    \
        }                                                                                  \
    }

/* Bit b of row c of bits (words per row): face sample (b, c) above the level (NaN is
 * not), (b, c) counted from the face's low corner `at` along the volume strides step_b,
 * step_c. The same doubles and comparison as everywhere else, with one type switch. */
static void inside_bits(const iso_volume *vol, double level, size_t at, size_t step_b, size_t step_c,
                        size_t nb, size_t nc, size_t words, uint64_t *bits)
{
    switch (vol->type) {
    case ISO_U8: INSIDE_BITS(uint8_t); break;
    case ISO_I8: INSIDE_BITS(int8_t); break;
    case ISO_U16: INSIDE_BITS(uint16_t); break;
    case ISO_I16: INSIDE_BITS(int16_t); break;
    case ISO_U32: INSIDE_BITS(uint32_t); break;
    case ISO_I32: INSIDE_BITS(int32_t); break;
    case ISO_F32: INSIDE_BITS(float); break;
    case ISO_F64: INSIDE_BITS(double); break;
    }
}

/* inside_bits from bits the caller holds: face line j is a row along b at (axis, c),
 * shifted down to the face's corner. */
static void known_bits(const iso_fan_inside *known, const uint32_t corner[3], int axis, int b, int c,
                       size_t nb, size_t nc, uint64_t *bits)
{
    uint32_t at[3];
    for (int d = 0; d < 3; d++)
        at[d] = corner[d] - known->origin[d];
    assert(at[b] + nb <= 16);
    const uint16_t *row = known->rows[b] + (size_t)at[axis] * known->stride + at[c];
    for (size_t j = 0; j < nc; j++)
        bits[j] = (uint64_t)(row[j] >> at[b]) & ((UINT64_C(1) << nb) - 1);
}

/* Word w of a bit row shifted down by one: bit b says sample b + 1. */
static uint64_t next_bits(const uint64_t *row, size_t w, size_t words)
{
    return (row[w] >> 1) | (w + 1 < words ? row[w + 1] << 63 : 0);
}

/* Marches one face. Its samples become bit rows (above the level or not), and the squares
 * whose corners straddle the level (few: the surface is a curve on the face) come out of
 * word operations, in the order b fastest; only those build segments. */
static int march_face(iso_fan_scratch *s, const iso_volume *vol, const iso_box *box,
                      double level, const iso_fan_inside *known, int axis, int high_side)
{
    face f = {.vol = vol, .level = level, .axis = axis, .b = (axis + 1) % 3, .c = (axis + 2) % 3};
    f.fixed = high_side ? box->hi[axis] : box->lo[axis];
    size_t stride[3] = {1, vol->dims[0], vol->dims[0] * vol->dims[1]};
    size_t nb = box->hi[f.b] - box->lo[f.b] + 1, nc = box->hi[f.c] - box->lo[f.c] + 1;
    size_t words = (nb + 63) / 64;
    if (grow((void **)&s->inside, &s->inside_capacity, nc * words, sizeof *s->inside))
        return ISO_E_NOMEM;
    const face_case *table = face_cases();
    f.step[0] = stride[f.b];
    f.step[1] = stride[f.c];
    uint32_t corner[3];
    corner[axis] = f.fixed;
    corner[f.b] = box->lo[f.b];
    corner[f.c] = box->lo[f.c];
    size_t origin = iso_vol_index(vol, corner[0], corner[1], corner[2]);
    if (known)
        known_bits(known, corner, axis, f.b, f.c, nb, nc, s->inside);
    else
        inside_bits(vol, level, origin, f.step[0], f.step[1], nb, nc, words, s->inside);
    uint64_t squares_1 = (UINT64_C(1) << ((nb - 1) & 63)) - 1; /* the squares of a one-word line */
    for (size_t c = 0; c + 1 < nc; c++) {
        const uint64_t *row = s->inside + c * words, *next = row + words;
        if (words == 1 && !(((row[0] ^ next[0]) | (row[0] ^ row[0] >> 1) | (next[0] ^ next[0] >> 1)) & squares_1))
            continue; /* no crossed square between the two lines, the common case */
        for (size_t w = 0; w < words; w++) {
            uint64_t low0 = row[w], low1 = next[w];
            uint64_t high0 = next_bits(row, w, words), high1 = next_bits(next, w, words);
            /* Square b has corners b, b + 1 of both rows: crossed unless all four agree. */
            uint64_t crossed = (low0 ^ high0) | (low1 ^ high1) | (low0 ^ low1);
            size_t squares = nb - 1 - 64 * w; /* squares from this word on */
            if (squares < 64)
                crossed &= (UINT64_C(1) << squares) - 1;
            while (crossed) {
                int k = __builtin_ctzll(crossed);
                crossed &= crossed - 1;
                unsigned l0 = (unsigned)(low0 >> k & 1), l1 = (unsigned)(low1 >> k & 1);
                unsigned h0 = (unsigned)(high0 >> k & 1), h1 = (unsigned)(high1 >> k & 1);
                /* The corners in walk order (side_edge), as face_case bits. */
                unsigned walk_case = high_side ? l0 | h0 << 1 | h1 << 2 | l1 << 3
                                               : l1 | h1 << 1 | h0 << 2 | l0 << 3;
                size_t b = 64 * w + (size_t)k;
                if (march_square(s, &f, table, high_side, box->lo[f.b] + (uint32_t)b, box->lo[f.c] + (uint32_t)c,
                                 origin + b * f.step[0] + c * f.step[1], walk_case))
                    return ISO_E_NOMEM;
            }
        }
    }
    return 0;
}

/* ---- PASS 2: linking segments into loops ---- */

static size_t slot_of(uint64_t key, size_t mask)
{
    uint64_t h = key * 0x9E3779B97F4A7C15ull;
    return (size_t)(h ^ (h >> 29)) & mask;
}

static int index_segments(iso_fan_scratch *s)
{
    size_t capacity = 16;
    while (capacity < 2 * s->segment_count)
        capacity *= 2;
    if (grow((void **)&s->slots, &s->slot_capacity, capacity, sizeof *s->slots))
        return ISO_E_NOMEM;
    memset(s->slots, 0, capacity * sizeof *s->slots);
    s->slot_mask = capacity - 1;
    for (size_t i = 0; i < s->segment_count; i++) {
        size_t k = slot_of(s->segments[i].from, s->slot_mask);
        while (s->slots[k])
            k = (k + 1) & s->slot_mask;
        s->slots[k] = (uint32_t)(i + 1);
    }
    return 0;
}

static long find_segment(const iso_fan_scratch *s, uint64_t from)
{
    for (size_t k = slot_of(from, s->slot_mask); s->slots[k]; k = (k + 1) & s->slot_mask)
        if (s->segments[s->slots[k] - 1].from == from)
            return (long)s->slots[k] - 1;
    return -1;
}

/* Collects the loop starting at segment first into loop and sets *length to its length,
 * 0 when the chain does not close (cannot happen for a consistent face rule; refused
 * anyway). loop has room for every segment not yet used. */
static void collect_loop(iso_fan_scratch *s, size_t first, uint32_t *loop, size_t *length)
{
    size_t n = 0;
    long at = (long)first;
    while (at >= 0 && !s->segments[at].used) {
        s->segments[at].used = 1;
        loop[n++] = (uint32_t)at;
        at = find_segment(s, s->segments[at].to);
    }
    *length = at == (long)first ? n : 0;
}

/* Triangles a loop of n >= 3 vertices fans into. */
static size_t loop_triangles(size_t n)
{
    return n == 3 ? 1 : n;
}

/* Links every segment into loops, one after another in s->loop, their lengths in
 * s->lengths: 1 done, 0 refused (a loop that does not close or has fewer than three
 * vertices, or more than max_triangles in all: the fans would be refused for it),
 * ISO_E_NOMEM. */
static int link_loops(iso_fan_scratch *s, size_t max_triangles)
{
    if (index_segments(s) ||
        grow((void **)&s->loop, &s->loop_capacity, s->segment_count, sizeof *s->loop) ||
        grow((void **)&s->lengths, &s->length_capacity, s->segment_count / 3, sizeof *s->lengths))
        return ISO_E_NOMEM;
    size_t filled = 0, triangles = 0;
    s->loop_count = 0;
    for (size_t i = 0; i < s->segment_count; i++) {
        if (s->segments[i].used)
            continue;
        size_t n;
        collect_loop(s, i, s->loop + filled, &n);
        if (n < 3)
            return 0;
        triangles += loop_triangles(n);
        if (triangles > max_triangles)
            return 0;
        filled += n;
        s->lengths[s->loop_count++] = (uint32_t)n;
    }
    return 1;
}

/* ---- PASS 3: fans ---- */

#define READ_CORNERS(T)                                                                  \
    do {                                                                                 \
        const T *p = (const T *)vol->data + at;                                          \
        c[0] = p[0], c[1] = p[1], c[2] = p[ny], c[3] = p[ny + 1];                        \
        c[4] = p[nz], c[5] = p[nz + 1], c[6] = p[nz + ny], c[7] = p[nz + ny + 1];        \
    } while (0)

/* The 8 samples of the cell whose low corner has linear index at (inside the volume),
 * corner k at offset (k & 1, (k >> 1) & 1, (k >> 2) & 1): one type switch, not eight. */
static void cell_corners(const iso_volume *vol, size_t at, double c[8])
{
    size_t ny = vol->dims[0], nz = vol->dims[0] * vol->dims[1]; /* the y and z strides */
    assert(at + nz + ny + 1 < iso_vol_count(vol));
    switch (vol->type) {
    case ISO_U8: READ_CORNERS(uint8_t); break;
    case ISO_I8: READ_CORNERS(int8_t); break;
    case ISO_U16: READ_CORNERS(uint16_t); break;
    case ISO_I16: READ_CORNERS(int16_t); break;
    case ISO_U32: READ_CORNERS(uint32_t); break;
    case ISO_I32: READ_CORNERS(int32_t); break;
    case ISO_F32: READ_CORNERS(float); break;
    case ISO_F64:
    default: READ_CORNERS(double); break; /* the types are all above */
    }
}

/* The volume as the fans sample it, with the last cell read: the fold checks of a fan and
 * the Newton steps of a centre mostly stay in one cell. */
typedef struct field {
    const iso_volume *vol;
    size_t at;   /* the cell's low corner, linear index; SIZE_MAX before the first */
    double c[8]; /* its samples (cell_corners) */
} field;

/* f and its gradient at index-space point p (the trilinear of the cell holding p). */
static double field_at(field *fd, const double p[3], double gradient[3])
{
    const iso_volume *vol = fd->vol;
    size_t cell[3];
    double u[3];
    for (int d = 0; d < 3; d++) {
        /* floor, as a signed conversion (x86 has no unsigned one): below 0 (and NaN) the
         * cell is clamped to 0 anyway; p is an index-space point, far below 2^63. */
        double x = p[d] > 0 ? (double)(int64_t)p[d] : 0;
        if (x > (double)vol->dims[d] - 2)
            x = (double)vol->dims[d] - 2;
        cell[d] = (size_t)(int64_t)x;
        u[d] = p[d] - x;
    }
    size_t at = iso_vol_index(vol, cell[0], cell[1], cell[2]);
    if (at != fd->at) {
        cell_corners(vol, at, fd->c);
        fd->at = at;
    }
    const double *c = fd->c;
    double x00 = c[0] + (c[1] - c[0]) * u[0], x10 = c[2] + (c[3] - c[2]) * u[0];
    double x01 = c[4] + (c[5] - c[4]) * u[0], x11 = c[6] + (c[7] - c[6]) * u[0];
    double y0 = x00 + (x10 - x00) * u[1], y1 = x01 + (x11 - x01) * u[1];
    /* d/dx: the same interpolation in y, z of the x differences. */
    double d00 = c[1] - c[0], d10 = c[3] - c[2], d01 = c[5] - c[4], d11 = c[7] - c[6];
    double dy0 = d00 + (d10 - d00) * u[1], dy1 = d01 + (d11 - d01) * u[1];
    gradient[0] = dy0 + (dy1 - dy0) * u[2];
    double e0 = x10 - x00, e1 = x11 - x01;
    gradient[1] = e0 + (e1 - e0) * u[2];
    gradient[2] = y1 - y0;
    return y0 + (y1 - y0) * u[2];
}

/* The loop's centroid, moved by Newton steps on f toward the level, kept inside box.
 * Returns |f(centre) - level| (NaN when f is NaN there). */
static double place_centre(field *fd, const iso_box *box, double level,
                           const iso_fan_scratch *s, const uint32_t *loop, size_t n, double centre[3])
{
    for (int d = 0; d < 3; d++)
        centre[d] = 0;
    for (size_t i = 0; i < n; i++)
        for (int d = 0; d < 3; d++)
            centre[d] += s->segments[loop[i]].from_position[d];
    for (int d = 0; d < 3; d++)
        centre[d] /= (double)n;
    double g[3], r = field_at(fd, centre, g) - level;
    for (int step = 0; step < 12 && fabs(r) > 1e-12 * (1 + fabs(level)); step++) {
        double gg = g[0] * g[0] + g[1] * g[1] + g[2] * g[2];
        if (!(gg > 0))
            break;
        for (int d = 0; d < 3; d++) {
            centre[d] -= r * g[d] / gg;
            if (centre[d] < box->lo[d])
                centre[d] = box->lo[d];
            if (centre[d] > box->hi[d])
                centre[d] = box->hi[d];
        }
        r = field_at(fd, centre, g) - level;
    }
    return fabs(r);
}

/* 1 if the triangle has area and faces down the gradient of f (normals point toward lower
 * values, as marching cubes' do); a fan over a loop that folds fails this somewhere. */
static int sound_triangle(field *fd, const float *a, const float *b, const float *c)
{
    double u[3], v[3], m[3], g[3];
    for (int d = 0; d < 3; d++) {
        u[d] = (double)b[d] - a[d];
        v[d] = (double)c[d] - a[d];
        m[d] = ((double)a[d] + b[d] + c[d]) / 3;
    }
    double n[3] = {u[1] * v[2] - u[2] * v[1], u[2] * v[0] - u[0] * v[2], u[0] * v[1] - u[1] * v[0]};
    if (n[0] == 0 && n[1] == 0 && n[2] == 0)
        return 0;
    field_at(fd, m, g);
    return n[0] * g[0] + n[1] * g[1] + n[2] * g[2] < 0;
}

void iso_fan_output_free(iso_fan_output *out)
{
    free(out->corners);
    free(out->centres);
    memset(out, 0, sizeof *out);
}

void iso_fan_edge_of_key(const iso_volume *vol, uint64_t key, uint32_t corner[3], int *axis)
{
    uint64_t at = key / 3;
    *axis = (int)(key % 3);
    corner[0] = (uint32_t)(at % vol->dims[0]);
    at /= vol->dims[0];
    corner[1] = (uint32_t)(at % vol->dims[1]);
    corner[2] = (uint32_t)(at / vol->dims[1]);
}

static int emit_triangle(iso_fan_output *out, uint64_t a, uint64_t b, uint64_t c)
{
    if (grow((void **)&out->corners, &out->triangle_capacity, out->triangle_count + 1, 3 * sizeof *out->corners))
        return ISO_E_NOMEM;
    uint64_t *t = out->corners + 3 * out->triangle_count++;
    t[0] = a;
    t[1] = b;
    t[2] = c;
    return 0;
}

static int add_centre(iso_fan_output *out, const double centre[3], uint64_t *ref)
{
    if (grow((void **)&out->centres, &out->centre_capacity, out->centre_count + 1, 3 * sizeof *out->centres))
        return ISO_E_NOMEM;
    for (int d = 0; d < 3; d++)
        out->centres[3 * out->centre_count + (size_t)d] = (float)centre[d];
    *ref = ISO_FAN_CENTRE | out->centre_count++;
    return 0;
}

/* Emits the loop (n >= 3 vertices, segment indices): 1 done, 0 refused, ISO_E_NOMEM. Triangles are
 * (centre, next, this): each face segment this -> next is then used as next -> this, the
 * direction marching cubes' own triangles give it. */
static int fan_loop(field *fd, const iso_box *box, double level, double vertex_limit,
                    const iso_fan_scratch *s, const uint32_t *loop, size_t n, iso_fan_output *out, iso_fan_result *result)
{
    for (size_t i = 0; i < n; i++)
        if (s->segments[loop[i]].from_error > result->vertex_error)
            result->vertex_error = s->segments[loop[i]].from_error;
    if (n == 3) {
        const float *a = s->segments[loop[0]].from_position, *b = s->segments[loop[1]].from_position,
                    *c = s->segments[loop[2]].from_position;
        if (!sound_triangle(fd, c, b, a))
            return 0;
        result->triangles++;
        return emit_triangle(out, s->segments[loop[2]].from, s->segments[loop[1]].from,
                             s->segments[loop[0]].from) ? ISO_E_NOMEM : 1;
    }
    double centre[3];
    double error = place_centre(fd, box, level, s, loop, n, centre);
    if (!(error <= vertex_limit))
        return 0;
    if (error > result->vertex_error)
        result->vertex_error = error;
    float c[3] = {(float)centre[0], (float)centre[1], (float)centre[2]};
    for (size_t i = 0; i < n; i++) {
        const float *here = s->segments[loop[i]].from_position;
        const float *next = s->segments[loop[(i + 1) % n]].from_position;
        if (!sound_triangle(fd, c, next, here))
            return 0;
    }
    uint64_t centre_ref;
    if (add_centre(out, centre, &centre_ref))
        return ISO_E_NOMEM;
    for (size_t i = 0; i < n; i++)
        if (emit_triangle(out, centre_ref, s->segments[loop[(i + 1) % n]].from, s->segments[loop[i]].from))
            return ISO_E_NOMEM;
    result->triangles += loop_triangles(n);
    return 1;
}

/* The fewest triangles s crossings can fan into: each starts one segment, so closed loops
 * of at least three vertices share them, a loop of three giving one triangle and a longer
 * loop n (around its centre). Loops of three are the cheapest; a remainder of one or two
 * crossings makes one of them a 4- or 5-loop. Below three crossings no fan is possible:
 * SIZE_MAX. */
static size_t fewest_triangles(size_t s)
{
    if (s < 3)
        return SIZE_MAX;
    static const size_t remainder[3] = {0, 3, 4};
    return s / 3 + remainder[s % 3];
}

int iso_fan_polygonize(const iso_volume *vol, const iso_box *box, double level,
                       double vertex_limit, size_t max_triangles, const iso_fan_inside *known,
                       iso_fan_scratch *s, iso_fan_output *out, iso_fan_result *result)
{
    assert(iso_box_cells(box) >= 2);
    memset(result, 0, sizeof *result);
    s->segment_count = 0;
    for (int axis = 0; axis < 3; axis++)
        for (int side = 0; side < 2; side++)
            if (march_face(s, vol, box, level, known, axis, side))
                return ISO_E_NOMEM;
    /* Refusals the crossings decide already, before linking and fanning: no loop at all
     * (the node holds the level, its range says, but no face crosses it: the surface is a
     * closed piece inside, which a fan cannot show), loops too short, or more triangles
     * than allowed. */
    if (fewest_triangles(s->segment_count) > max_triangles || s->segment_count < 3)
        return 0;
    int rc = link_loops(s, max_triangles);
    if (rc != 1)
        return rc;
    size_t centres_before = out->centre_count, triangles_before = out->triangle_count;
    const uint32_t *loop = s->loop;
    field fd = {.vol = vol, .at = SIZE_MAX};
    for (size_t i = 0; i < s->loop_count && rc == 1; loop += s->lengths[i++]) {
        rc = fan_loop(&fd, box, level, vertex_limit, s, loop, s->lengths[i], out, result);
        result->loops++;
    }
    if (rc != 1) {
        out->centre_count = centres_before;
        out->triangle_count = triangles_before;
        memset(result, 0, sizeof *result);
    }
    return rc;
}
