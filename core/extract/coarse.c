/* coarse.c: PASS 3 of the tolerance path (lod.h): a brick's coarse units (the brick at
 * stride 8, or its coarse blocks at their strides) cell after cell, regular cells by
 * marching cubes (mc.h) and transition cells where a cell meets finer lattice sets; with
 * the brick's sample cache and the vertex map that makes a crossing shared by cells once.
 * lod.c's extract() calls iso_coarse_brick per brick after PASS 2.
 *
 * Per brick (iso_coarse_brick, last in the file; callees come before their callers):
 *   1. classify: the brick's samples above the level as bit rows (classify_whole), its
 *      values cached on first use (sample);
 *   2. units: the brick whole at stride 8, or block after block at its stride
 *      (march_unit); a unit whose samples all lie on one side is skipped (box_mixed);
 *   3. strides: once per brick, when its first mixed unit needs them, the stride of every
 *      lattice set of its closed box (brick_around), which tells a regular cell from a
 *      transition cell (unit_uniform, cell_is_regular);
 *   4. cells: a regular cell by marching cubes (regular_cell); a transition cell
 *      (transition_cell) by its face squares (face_segments, region_segments,
 *      split_side, polygon_segments: mc.h's face rule), then its loops, each with a
 *      centre on the level (place_centre, centre_root), fanned (fan_loops).
 *   Every crossing is looked up by lattice segment (crossing, then the vertex map in
 *   make_crossing), taking PASS 2's vertex on a data edge where it made one. */
#include "lod_context.h"

#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "mc.h"

/* Steps placing a loop's centre on the level: 28 bisections leave 2^-28 of a brick's
 * diagonal, below a float's resolution at any index past 1; false position stops earlier,
 * once |f - level| is below 2^-32 of the values at its bracket's two ends. */
#define CENTRE_STEPS 28
#define CENTRE_STOP 0x1p-32

/* The unit at hand: the box of m[] blocks from block first[] (unit_box). */
static void unit_box(lod *c, const uint32_t first[3], const uint32_t m[3])
{
    for (int d = 0; d < 3; d++) {
        c->ulo[d] = first[d] * ISO_TREE_BLOCK;
        uint32_t end = (first[d] + m[d]) * ISO_TREE_BLOCK;
        c->uhi[d] = end < c->dims[d] - 1 ? end : c->dims[d] - 1;
    }
}

/* brick_around's minima over near[] (the block strides around the brick): class k along
 * an axis is held by near's entries (k + 1) / 2 to k / 2 + 1, both sides of a plane (k
 * even), the block itself inside it (k odd, one entry). The minimum over those, one axis at
 * a time. */
static void around_minima(lod *c, const uint8_t near[][BLOCKS_PER_BRICK + 2][BLOCKS_PER_BRICK + 2])
{
    enum { N = BLOCKS_PER_BRICK + 2, K = UNIT_CLASSES };
    uint8_t along_x[N][N][K], along_y[N][K][K];
    for (uint32_t z = 0; z < N; z++)
        for (uint32_t y = 0; y < N; y++)
            for (uint32_t k = 0; k < K; k++) {
                uint8_t a = near[z][y][(k + 1) / 2], b = near[z][y][k / 2 + 1];
                along_x[z][y][k] = a < b ? a : b;
            }
    for (uint32_t z = 0; z < N; z++)
        for (uint32_t k = 0; k < K; k++)
            for (uint32_t kx = 0; kx < K; kx++) {
                uint8_t a = along_x[z][(k + 1) / 2][kx], b = along_x[z][k / 2 + 1][kx];
                along_y[z][k][kx] = a < b ? a : b;
            }
    for (uint32_t kz = 0; kz < K; kz++)
        for (uint32_t ky = 0; ky < K; ky++)
            for (uint32_t kx = 0; kx < K; kx++) {
                uint8_t a = along_y[(kz + 1) / 2][ky][kx], b = along_y[kz / 2 + 1][ky][kx];
                c->around[kz][ky][kx] = a < b ? a : b;
            }
}

/* The strides of the lattice sets in the brick at hand's closed box (m[] blocks from block
 * first[]), by where a set lies per axis (class: a block plane, or strictly inside a
 * block; classes counted from the brick's low corner, so a block's classes are a window of
 * the brick's): the finest of the blocks holding it, whose closed boxes are [4i, 4i + 4]
 * per axis. With a cap, a set on the volume's border has stride 1: the cap's cells are
 * data cells. Made once per brick, on its first unit with samples on both sides. */
static void brick_around(lod *c, const uint32_t first[3], const uint32_t m[3])
{
    enum { N = BLOCKS_PER_BRICK + 2 };
    /* The blocks from first - 1 to first + m per axis, ISO_TREE_LEVELS where there is none
     * (past first + m too: those entries only make classes past the brick's, unread). */
    uint8_t near[N][N][N];
    int have[3][N];
    for (int d = 0; d < 3; d++)
        for (uint32_t x = 0; x < N; x++)
            /* first + x - 1 as unsigned: the block before 0 wraps past the grid */
            have[d][x] = x < m[d] + 2 && first[d] + x - 1 < c->blocks[d];
    unsigned low = ISO_TREE_LEVELS, high = 0; /* near's least and largest strides */
    for (uint32_t z = 0; z < N; z++)
        for (uint32_t y = 0; y < N; y++) {
            uint8_t *out = near[z][y];
            if (!have[2][z] || !have[1][y]) {
                memset(out, ISO_TREE_LEVELS, N);
                high = ISO_TREE_LEVELS;
                continue;
            }
            const uint8_t *shift =
                c->shift + ((size_t)(first[2] + z - 1) * c->blocks[1] + (first[1] + y - 1)) * c->blocks[0] + first[0] - 1;
            for (uint32_t x = 0; x < N; x++) {
                out[x] = have[0][x] ? shift[x] : ISO_TREE_LEVELS;
                low = out[x] < low ? out[x] : low;
                high = out[x] > high ? out[x] : high;
            }
        }
    for (int d = 0; d < 3; d++) {
        for (uint32_t r = 0; r < c->n[d]; r++)
            c->point_class[d][r] = (uint8_t)(r == c->n[d] - 1 ? 2 * m[d] : r / ISO_TREE_BLOCK * 2 + (r % ISO_TREE_BLOCK != 0));
        for (uint32_t r = 0; r + 1 < c->n[d]; r++)
            c->span_class[d][r] = (uint8_t)(r / ISO_TREE_BLOCK * 2 + 1);
    }
    /* One stride all round (a stride-8 brick among its like, the preview's common case):
     * every minimum is that stride. */
    if (low == high)
        memset(c->around, (int)low, sizeof c->around);
    else
        around_minima(c, (const uint8_t(*)[N][N])near);
    /* With a cap, the sets on the volume's border. */
    for (int d = 0; d < 3 && c->cap; d++) {
        uint32_t P[2] = {2 * m[(d + 1) % 3] + 1, 2 * m[(d + 2) % 3] + 1};
        uint32_t ends[2] = {first[d] == 0 ? 0 : UINT32_MAX, first[d] + m[d] == c->blocks[d] ? 2 * m[d] : UINT32_MAX};
        for (int e = 0; e < 2; e++) {
            if (ends[e] == UINT32_MAX)
                continue;
            for (uint32_t i = 0; i < P[0]; i++)
                for (uint32_t j = 0; j < P[1]; j++) {
                    uint32_t k[3];
                    k[d] = ends[e];
                    k[(d + 1) % 3] = i;
                    k[(d + 2) % 3] = j;
                    c->around[k[2]][k[1]][k[0]] = 0;
                }
        }
    }
    c->around_stamp = c->stamp;
}

/* 1 if every lattice set in the closed box of the unit at hand (unit_box, inside the brick
 * at hand) has stride `shift`: every cell of it is regular. */
static int unit_uniform(const lod *c, unsigned shift)
{
    uint32_t k0[3], k1[3];
    for (int d = 0; d < 3; d++) {
        k0[d] = c->point_class[d][c->ulo[d] - c->lo[d]];
        k1[d] = c->point_class[d][c->uhi[d] - c->lo[d]];
    }
    for (uint32_t kz = k0[2]; kz <= k1[2]; kz++)
        for (uint32_t ky = k0[1]; ky <= k1[1]; ky++)
            for (uint32_t kx = k0[0]; kx <= k1[0]; kx++)
                if (c->around[kz][ky][kx] != shift)
                    return 0;
    return 1;
}

/* The stride (log2) of the lattice set with classes k[] in the unit at hand. */
static inline unsigned set_shift(const lod *c, const uint8_t k[3])
{
    return c->around[k[2]][k[1]][k[0]];
}

/* Sample p of the brick at hand's box, read from the volume on first use: a coarse brick
 * costs the samples its grid and its transition cells touch, each once. */
static double sample(lod *c, const uint32_t p[3])
{
    size_t local = ((size_t)(p[2] - c->lo[2]) * ISO_BRICK_SAMPLES + (p[1] - c->lo[1])) * ISO_BRICK_SAMPLES +
                   (p[0] - c->lo[0]);
    if (c->value_stamp[local] != c->stamp) {
        c->value_stamp[local] = c->stamp;
        c->value[local] = iso_vol_sample(c->vol, ((size_t)p[2] * c->dims[1] + p[1]) * c->dims[0] + p[0]);
    }
    return c->value[local];
}

/* 1 if sample p is above the level. */
static int above(lod *c, const uint32_t p[3])
{
    return c->rows[(p[2] - c->lo[2]) * ISO_BRICK_SAMPLES + (p[1] - c->lo[1])] >> (p[0] - c->lo[0]) & 1;
}

/* Classifies every sample of the brick at hand (march.c's rows, 8 at a time, cheaper than
 * its grid's samples one by one): a cell's case is then bits, and a transition cell whose
 * samples all lie on one side of the level has no segment. */
static void classify_whole(lod *c)
{
    size_t lo[3];
    uint8_t n[3];
    for (int d = 0; d < 3; d++) {
        lo[d] = c->lo[d];
        n[d] = (uint8_t)c->n[d];
    }
    iso_march_inside_rows(c->vol, c->level, lo, n, c->rows);
}

/* 1 if the box [lo, hi] (samples, inside the brick at hand) has samples on both sides of
 * the level. */
static int box_mixed(const lod *c, const uint32_t lo[3], const uint32_t hi[3])
{
    unsigned x = lo[0] - c->lo[0], mask = ((1u << (hi[0] - lo[0] + 1)) - 1) << x, any = 0, all = mask;
    for (uint32_t z = lo[2] - c->lo[2]; z <= hi[2] - c->lo[2]; z++)
        for (uint32_t y = lo[1] - c->lo[1]; y <= hi[1] - c->lo[1]; y++) {
            unsigned row = c->rows[z * ISO_BRICK_SAMPLES + y] & mask;
            any |= row;
            all &= row;
            if (any && all != mask)
                return 1; /* boxes near the surface, the usual ones, are mixed early */
        }
    return 0;
}

/* f, the data's trilinear interpolant, at x inside the brick at hand. */
static double value_at(lod *c, const double x[3])
{
    uint32_t cell[3];
    double u[3];
    for (int d = 0; d < 3; d++) {
        double local = x[d] - c->lo[d];
        uint32_t i = local <= 0 ? 0 : (uint32_t)local;
        if (i + 1 >= c->n[d])
            i = c->n[d] - 2;
        cell[d] = c->lo[d] + i;
        u[d] = x[d] - cell[d];
    }
    /* A centre's root finder evaluates one data cell many times over. */
    if (c->corner_stamp != c->stamp || memcmp(cell, c->corner_cell, sizeof cell)) {
        /* Read straight from the volume: most of a centre's cells are read once. */
        size_t at = ((size_t)cell[2] * c->dims[1] + cell[1]) * c->dims[0] + cell[0], dy = c->dims[0],
               dz = (size_t)c->dims[0] * c->dims[1];
        for (int k = 0; k < 8; k++)
            c->corner[k] = iso_vol_sample(c->vol, at + (size_t)(k & 1) + (size_t)(k >> 1 & 1) * dy + (size_t)(k >> 2 & 1) * dz);
        memcpy(c->corner_cell, cell, sizeof cell);
        c->corner_stamp = c->stamp;
    }
    return iso_tri_eval(c->corner, u[0], u[1], u[2]);
}

static int grow_map(vertex_map *m)
{
    size_t capacity = m->mask ? 2 * (m->mask + 1) : 4096;
    uint64_t *keys = calloc(capacity, sizeof *keys);
    uint32_t *ids = malloc(capacity * sizeof *ids);
    if (!keys || !ids) {
        free(keys);
        free(ids);
        return ISO_E_NOMEM;
    }
    for (size_t i = 0; m->mask && i <= m->mask; i++) {
        if (!m->keys[i])
            continue;
        size_t at = (size_t)(m->keys[i] * UINT64_C(0x9E3779B97F4A7C15) >> 20) & (capacity - 1);
        while (keys[at])
            at = (at + 1) & (capacity - 1);
        keys[at] = m->keys[i];
        ids[at] = m->ids[i];
    }
    free(m->keys);
    free(m->ids);
    m->keys = keys;
    m->ids = ids;
    m->mask = capacity - 1;
    return 0;
}

static int add_vertex(lod *c, const double x[3], uint32_t *id)
{
    iso_mesh *mesh = c->mesh;
    if (mesh->vertex_count >= UINT32_MAX)
        return ISO_E_LIMIT;
    if (mesh->vertex_count == mesh->vertex_capacity &&
        iso_mesh_reserve(mesh, 2 * mesh->vertex_capacity + 1024, mesh->triangle_capacity))
        return ISO_E_NOMEM;
    float *p = mesh->positions + 3 * mesh->vertex_count;
    for (int d = 0; d < 3; d++)
        p[d] = (float)x[d];
    *id = (uint32_t)mesh->vertex_count++;
    return 0;
}

/* The vertex of the crossing on the lattice segment from p along axis, length long (the
 * brick at hand's first use of it): made on first use, where iso_mc_edge_t puts it between
 * the segment's two samples. */
static int make_crossing(lod *c, const uint32_t p[3], int axis, uint32_t length, uint32_t *id)
{
    int inner = 1; /* strictly inside the unit at hand across the axis: only it holds the segment */
    for (int d = 0; d < 3; d++)
        if (d != axis && (p[d] == c->ulo[d] || p[d] == c->uhi[d]))
            inner = 0;
    /* A data edge a stride-1 brick holds (or its ghost owns): march.c made its vertex. */
    if (!inner && length == 1 && c->fine && iso_march_part_vertex(c->fine, p, axis, id))
        return 0;
    vertex_map *m = &c->map;
    size_t at = 0;
    uint64_t key = (((((uint64_t)p[2] * c->dims[1] + p[1]) * c->dims[0] + p[0]) * 3 + (uint64_t)axis) << 4 |
                    length) + 1;
    if (!inner) {
        if (2 * (m->count + 1) > m->mask && grow_map(m))
            return ISO_E_NOMEM;
        at = (size_t)(key * UINT64_C(0x9E3779B97F4A7C15) >> 20) & m->mask;
        for (; m->keys[at]; at = (at + 1) & m->mask)
            if (m->keys[at] == key) {
                *id = m->ids[at];
                return 0;
            }
    }
    uint32_t q[3] = {p[0], p[1], p[2]};
    double len = (double)length, x[3] = {p[0], p[1], p[2]};
    q[axis] += length;
    double a = sample(c, p), b = sample(c, q), t = iso_mc_edge_t(a, b, c->level);
    x[axis] += t * len;
    int rc = add_vertex(c, x, id);
    if (rc)
        return rc;
    /* f is linear along a data edge: the interpolant's own error is f's. On a longer
     * segment, f at x is that of the data edge holding it. */
    double e = iso_mc_edge_error(a, b, t, c->level);
    if (length > 1) {
        uint32_t i = (uint32_t)(x[axis] - p[axis]), e0[3] = {p[0], p[1], p[2]}, e1[3];
        e0[axis] += i < length ? i : length - 1;
        memcpy(e1, e0, sizeof e1);
        e1[axis]++;
        e = iso_mc_edge_error(sample(c, e0), sample(c, e1), x[axis] - e0[axis], c->level);
    }
    c->error = e > c->error ? e : c->error; /* NaN (a NaN or infinite sample) proves nothing */
    if (inner)
        return 0; /* only this unit holds the segment: crossing's per-brick table is its map */
    m->keys[at] = key;
    m->ids[at] = *id;
    m->count++;
    return 0;
}

/* The vertex of the crossing on the lattice segment from p along axis, length long, kept
 * per brick by the segment's low end, axis and length (most segments are asked for again:
 * by the other face holding a cell edge, the other square holding a side, the next cell;
 * a segment's length is its lattice set's stride, so one length per end and axis is all
 * a brick sees, and another one only goes the longer way). */
static int crossing(lod *c, const uint32_t p[3], int axis, uint32_t length, uint32_t *id)
{
    size_t local = (((size_t)(p[2] - c->lo[2]) * ISO_BRICK_SAMPLES + (p[1] - c->lo[1])) * ISO_BRICK_SAMPLES +
                    (p[0] - c->lo[0])) * 3 + (size_t)axis;
    if (c->seen_stamp[local] == c->stamp && c->seen_length[local] == length) {
        *id = c->seen_id[local];
        return 0;
    }
    int rc = make_crossing(c, p, axis, length, id);
    if (rc)
        return rc;
    c->seen_stamp[local] = c->stamp;
    c->seen_length[local] = (uint8_t)length;
    c->seen_id[local] = *id;
    return 0;
}

static int add_triangle(lod *c, uint32_t a, uint32_t b, uint32_t d)
{
    iso_mesh *mesh = c->mesh;
    if (mesh->triangle_count == mesh->triangle_capacity &&
        iso_mesh_reserve(mesh, mesh->vertex_capacity, 2 * mesh->triangle_capacity + 1024))
        return ISO_E_NOMEM;
    uint32_t *t = mesh->indices + 3 * mesh->triangle_count++;
    t[0] = a;
    t[1] = b;
    t[2] = d;
    return 0;
}

/* Marching cubes on the cell at o, size[] cells per axis. */
static int regular_cell(lod *c, const uint32_t o[3], const uint32_t size[3])
{
    unsigned x0 = o[0] - c->lo[0], x1 = x0 + size[0], index = 0;
    for (int k = 0; k < 4; k++) {
        unsigned row = c->rows[(o[2] - c->lo[2] + (k >> 1) * size[2]) * ISO_BRICK_SAMPLES + o[1] - c->lo[1] +
                               (k & 1) * size[1]];
        index |= ((row >> x0 & 1) | (row >> x1 & 1) << 1) << (2 * k);
    }
    if (index == 0 || index == 255)
        return 0;
    const iso_mc_case *cs = iso_mc_cases() + index;
    uint32_t edge_id[12];
    unsigned known = 0; /* bit e: edge_id[e] is the crossing's vertex */
    for (int t = 0; t < cs->triangle_count; t++) {
        uint32_t id[3];
        for (int i = 0; i < 3; i++) {
            int e = cs->edges[3 * t + i], lo = iso_mc_edge_corner[e][0];
            if (!(known >> e & 1)) {
                uint32_t p[3] = {o[0] + (lo & 1) * size[0], o[1] + ((lo >> 1) & 1) * size[1],
                                 o[2] + ((lo >> 2) & 1) * size[2]};
                int rc = crossing(c, p, e / 4, size[e / 4], &edge_id[e]);
                if (rc)
                    return rc;
                known |= 1u << e;
            }
            id[i] = edge_id[e];
        }
        int rc = add_triangle(c, id[0], id[1], id[2]);
        if (rc)
            return rc;
    }
    return 0;
}

/* 1 if every face of the cell at o (size[] cells per axis) and every edge and line in
 * them has the unit's stride `shift`: the classes of its closed faces (set_shift). */
static int cell_is_regular(const lod *c, const uint32_t o[3], const uint32_t size[3], unsigned shift)
{
    uint8_t first[3], last[3];
    for (int d = 0; d < 3; d++) {
        first[d] = c->point_class[d][o[d] - c->lo[d]];
        last[d] = c->point_class[d][o[d] + size[d] - c->lo[d]];
    }
    for (int a = 0; a < 3; a++) {
        int b = (a + 1) % 3, d2 = (a + 2) % 3;
        for (int side = 0; side < 2; side++) {
            uint8_t k[3];
            k[a] = side ? last[a] : first[a];
            for (k[b] = first[b]; k[b] <= last[b]; k[b]++)
                for (k[d2] = first[d2]; k[d2] <= last[d2]; k[d2]++)
                    if (set_shift(c, k) != shift)
                        return 0;
        }
    }
    return 1;
}

static int add_segment(lod *c, loop_segment s)
{
    if (c->segment_count == c->segment_capacity) {
        size_t more = c->segment_capacity ? 2 * c->segment_capacity : 256;
        loop_segment *grown = realloc(c->segments, more * sizeof *grown);
        if (!grown)
            return ISO_E_NOMEM;
        c->segments = grown;
        c->segment_capacity = more;
    }
    c->segments[c->segment_count++] = s;
    return 0;
}

/* Polygon points of one face square: its corners counter-clockwise from outside the cell,
 * each side split at its own stride. At most 4 * 8 points. */
#define MAX_POLYGON (4 * ISO_BRICK_CELLS)

/* Appends to points[] the points strictly between p and q (a square's side, along one
 * axis) where the side is split: at the multiples of each stretch's own stride, the
 * stride of the lattice set that holds it (a side may cross a block plane, and a stride-8
 * side holds stretches of two blocks; the volume's last sample may end it off them).
 * Returns the new count. */
static int split_side(const lod *c, const uint32_t p[3], const uint32_t q[3], uint32_t points[][3], int m)
{
    int axis = p[0] != q[0] ? 0 : p[1] != q[1] ? 1 : 2;
    uint8_t k[3];
    for (int d = 0; d < 3; d++)
        if (d != axis)
            k[d] = c->point_class[d][p[d] - c->lo[d]];
    if (q[axis] > p[axis]) {
        for (uint32_t x = p[axis];;) {
            k[axis] = c->span_class[axis][x - c->lo[axis]];
            uint32_t step = 1u << set_shift(c, k);
            x = (x / step + 1) * step;
            if (x >= q[axis])
                break;
            memcpy(points[m], p, sizeof points[0]);
            points[m++][axis] = x;
        }
    } else {
        for (uint32_t x = p[axis];;) {
            k[axis] = c->span_class[axis][x - 1 - c->lo[axis]];
            uint32_t step = 1u << set_shift(c, k);
            x = (x - 1) / step * step;
            if (x <= q[axis])
                break;
            memcpy(points[m], p, sizeof points[0]);
            points[m++][axis] = x;
        }
    }
    return m;
}

/* The segments of one polygon of a transition cell's face (m points, in order), by mc.h's
 * face rule. */
static int polygon_segments(lod *c, const uint32_t points[][3], int m)
{
    /* Crossings in order around the polygon: which were entries, and their vertices. */
    uint32_t id[MAX_POLYGON];
    int entry[MAX_POLYGON], inside[MAX_POLYGON], n = 0, at[MAX_POLYGON];
    for (int i = 0; i < m; i++)
        inside[i] = above(c, points[i]);
    for (int i = 0; i < m; i++) {
        int j = (i + 1) % m;
        if (inside[i] == inside[j])
            continue;
        const uint32_t *lo = points[i], *hi = points[j];
        int axis = 0;
        for (int d = 0; d < 3; d++)
            if (lo[d] != hi[d])
                axis = d;
        if (lo[axis] > hi[axis]) {
            const uint32_t *t = lo;
            lo = hi;
            hi = t;
        }
        int rc = crossing(c, lo, axis, hi[axis] - lo[axis], &id[n]);
        if (rc)
            return rc;
        entry[n] = inside[j];
        at[n] = i;
        n++;
    }
    /* Crossings alternate entry and exit: the one after an entry leaves its run. */
    for (int r = 0; r < n; r++) {
        if (!entry[r])
            continue;
        int leave = (r + 1) % n, i = at[r];
        loop_segment s = {.from = id[leave], .to = id[r]};
        const uint32_t *in = points[(i + 1) % m], *out = points[i];
        memcpy(s.above, in, sizeof s.above);
        memcpy(s.below, out, sizeof s.below);
        int rc = add_segment(c, s);
        if (rc)
            return rc;
    }
    return 0;
}

/* The point on the segment from a (strictly inside the cell, fa = f(a) - level) to the
 * loop sample b (fb = f(b) - level of the other sign) where f = level, by false position
 * with the Illinois rule (the end that stays is halved in weight, so both ends close in):
 * a few trilinear evaluations where bisection takes CENTRE_STEPS. Every point tried lies
 * strictly between a and b, hence strictly inside the cell; the one nearest the level is
 * kept, and its |f - level| returned. */
static double centre_root(lod *c, const double a[3], double fa, const double b[3], double fb, double x[3])
{
    double s0 = 0, s1 = 1, g0 = fa, g1 = fb, best = fabs(fa), stop = CENTRE_STOP * (fabs(fa) + fabs(fb));
    int kept = 0; /* which end stayed last: -1 the low one, +1 the high one */
    memcpy(x, a, 3 * sizeof *x);
    for (int step = 0; step < CENTRE_STEPS && best > stop; step++) {
        double s = (s0 * g1 - s1 * g0) / (g1 - g0), p[3];
        if (!(s > s0 && s < s1))
            s = 0.5 * (s0 + s1);
        if (!(s > s0 && s < s1))
            break; /* the bracket is below a double's resolution */
        for (int d = 0; d < 3; d++)
            p[d] = a[d] + s * (b[d] - a[d]);
        double g = value_at(c, p) - c->level;
        if (fabs(g) < best) {
            best = fabs(g);
            memcpy(x, p, 3 * sizeof *x);
        }
        if ((g > 0) == (g0 > 0)) {
            s0 = s;
            g0 = g;
            if (kept > 0)
                g1 *= 0.5;
            kept = 1;
        } else {
            s1 = s;
            g1 = g;
            if (kept < 0)
                g0 *= 0.5;
            kept = -1;
        }
    }
    return best;
}

/* A point on f = level for a loop: its vertices' mean pulled a quarter of the way to the
 * cell's centre (strictly inside the cell), then moved toward the nearest of the loop's
 * samples strictly on the other side of the level (centre_root). The root is then strictly
 * inside too, never on a face, so no fan triangle lies flat in one. Without such a sample
 * (a tie: a sample exactly on the level) the nearest sample is approached by bisection only
 * to ISO_MC_END_GAP of the way, as crossings are. Returns |f(x) - level| at the point. */
static double place_centre(lod *c, const uint32_t *loop, size_t n, const loop_segment *const *ends,
                           const double middle[3], double x[3])
{
    const float *pos = c->mesh->positions;
    double a[3] = {0, 0, 0};
    for (size_t i = 0; i < n; i++)
        for (int d = 0; d < 3; d++)
            a[d] += pos[3 * loop[i] + d];
    for (int d = 0; d < 3; d++)
        a[d] = 0.75 * a[d] / (double)n + 0.25 * middle[d];
    double fa = value_at(c, a) - c->level, fb = 0;
    int a_above = fa > 0;
    double best = INFINITY, b[3] = {a[0], a[1], a[2]};
    int strict = 0;
    for (size_t i = 0; i < n && fa != 0; i++) {
        const uint32_t *p = a_above ? ends[i]->below : ends[i]->above;
        double fp = sample(c, p) - c->level, dist = 0;
        int opposite = a_above ? fp < 0 : fp > 0;
        if (strict && !opposite)
            continue;
        for (int d = 0; d < 3; d++)
            dist += (p[d] - a[d]) * (p[d] - a[d]);
        if (dist < best || (opposite && !strict)) {
            best = dist;
            strict = opposite;
            fb = fp;
            for (int d = 0; d < 3; d++)
                b[d] = opposite ? p[d] : a[d] + (1 - ISO_MC_END_GAP) * (p[d] - a[d]);
        }
    }
    if (strict)
        return centre_root(c, a, fa, b, fb, x);
    double at_a = fa;
    for (int step = 0; step < CENTRE_STEPS && fa != 0; step++) {
        double mid[3], v;
        for (int d = 0; d < 3; d++)
            mid[d] = 0.5 * (a[d] + b[d]);
        if (((v = value_at(c, mid)) > c->level) == a_above) {
            memcpy(a, mid, sizeof a);
            at_a = v - c->level;
        } else {
            memcpy(b, mid, sizeof b);
        }
    }
    /* The end still on a's side: b may be the sample itself after a tie. */
    memcpy(x, a, 3 * sizeof *x);
    return fabs(at_a);
}

/* Chains the cell's segments into loops and fans each, reversed so that normals point
 * toward lower values (as mc.c does). */
static int fan_loops(lod *c, const double middle[3], iso_error *err)
{
    size_t count = c->segment_count;
    if (c->loop_capacity < count) {
        free(c->loop);
        c->loop = malloc(count * sizeof *c->loop);
        if (!c->loop)
            return ISO_E_NOMEM;
        c->loop_capacity = count;
    }
    for (size_t start = 0; start < count; start++) {
        if (c->segments[start].used)
            continue;
        size_t n = 0;
        loop_segment *s = &c->segments[start];
        while (!s->used) {
            s->used = 1;
            c->loop[n++] = s->from;
            loop_segment *next = NULL;
            for (size_t k = 0; k < count && !next; k++)
                if (c->segments[k].from == s->to)
                    next = &c->segments[k];
            if (!next)
                return iso_error_set(err, ISO_E_INTERNAL, "a transition cell's loop does not close");
            s = next;
        }
        if (s != &c->segments[start])
            return iso_error_set(err, ISO_E_INTERNAL, "a transition cell's loop does not close");
        /* Two segments between the same two crossings: a run of inside samples along one
         * subdivided edge, cut off on both faces by the edge itself. The neighbours across
         * those faces hold the same two segments, reversed: the surface creases along the
         * edge and this cell holds none of it. */
        if (n == 2)
            continue;
        uint32_t *r = c->loop;
        for (size_t i = 0; i < n / 2; i++) {
            uint32_t t = r[i];
            r[i] = r[n - 1 - i];
            r[n - 1 - i] = t;
        }
        int rc;
        if (n == 3) {
            rc = add_triangle(c, r[0], r[1], r[2]);
        } else {
            /* The segments whose ends these loop vertices are, for the centre. */
            const loop_segment *seg[64];
            size_t m = 0;
            for (size_t k = 0; k < count && m < 64; k++)
                for (size_t i = 0; i < n; i++)
                    if (c->segments[k].to == r[i]) {
                        seg[m++] = &c->segments[k];
                        break;
                    }
            double x[3], e = place_centre(c, r, m < n ? m : n, seg, middle, x);
            uint32_t centre;
            rc = add_vertex(c, x, &centre);
            if (e > c->error)
                c->error = e; /* NaN (a NaN or infinite sample nearby) proves nothing and is left out */
            for (size_t i = 0; i < n && !rc; i++)
                rc = add_triangle(c, centre, r[i], r[(i + 1) % n]);
        }
        if (rc)
            return iso_error_set(err, rc, "out of memory extracting the surface");
    }
    return 0;
}

/* The segments of the squares of [b0, b1) x [c0, c1) (along axes b and d2) of a transition
 * cell's face in `plane` across axis a (side 1 the high one), squares of stride f: each
 * square's sides split at their own strides (split_side). A square whose sides hold no
 * crossing is skipped before its polygon is built: its corners alike and every sample of
 * its box alike (a side of one cell is never split, so then the corners are its box), or,
 * built, its corners alike and no side split. */
static int region_segments(lod *c, int a, int side, uint32_t plane, const uint32_t from[2], const uint32_t to[2],
                           uint32_t f)
{
    static const int bc[4][2] = {{0, 0}, {1, 0}, {1, 1}, {0, 1}};
    int b = (a + 1) % 3, d2 = (a + 2) % 3;
    for (uint32_t jc = from[1]; jc < to[1]; jc += f)
        for (uint32_t jb = from[0]; jb < to[0]; jb += f) {
            uint32_t wb = to[0] - jb < f ? to[0] - jb : f, wc = to[1] - jc < f ? to[1] - jc : f;
            uint32_t corner[4][3];
            unsigned alike = 0;
            for (int k = 0; k < 4; k++) {
                int q = side ? k : 3 - k; /* (b, c, a) is right-handed: reversed below */
                corner[k][a] = plane;
                corner[k][b] = jb + wb * (uint32_t)bc[q][0];
                corner[k][d2] = jc + wc * (uint32_t)bc[q][1];
                alike += (unsigned)above(c, corner[k]);
            }
            alike = alike == 0 || alike == 4;
            if (alike) {
                if (wb == 1 && wc == 1)
                    continue;
                uint32_t box_lo[3], box_hi[3];
                for (int d = 0; d < 3; d++) {
                    box_lo[d] = corner[0][d] < corner[2][d] ? corner[0][d] : corner[2][d];
                    box_hi[d] = corner[0][d] < corner[2][d] ? corner[2][d] : corner[0][d];
                }
                if (!box_mixed(c, box_lo, box_hi))
                    continue;
            }
            uint32_t points[MAX_POLYGON][3];
            int m = 0;
            for (int k = 0; k < 4; k++) {
                memcpy(points[m++], corner[k], sizeof points[0]);
                /* A side inside the region has the region's stride, no longer than the
                 * side: only the region's own border may be split, and a side of one
                 * cell never is. */
                int across = k % 2 ? b : d2, at = k % 2 ? 0 : 1;
                if ((k % 2 ? wc : wb) > 1 && (corner[k][across] == from[at] || corner[k][across] == to[at]))
                    m = split_side(c, corner[k], corner[(k + 1) % 4], points, m);
            }
            if (alike && m == 4)
                continue;
            int rc = polygon_segments(c, (const uint32_t(*)[3])points, m);
            if (rc)
                return rc;
        }
    return 0;
}

/* The segments of one face of a transition cell, across axis a (side 1 the high one): the
 * face in regions, one per block face it spans (a face of stride 8 is one region), each
 * cut into squares of its own stride. */
static int face_segments(lod *c, const uint32_t o[3], const uint32_t size[3], int a, int side)
{
    int b = (a + 1) % 3, d2 = (a + 2) % 3;
    uint32_t plane = o[a] + size[a] * (uint32_t)side;
    uint8_t k[3];
    k[a] = c->point_class[a][plane - c->lo[a]];
    k[b] = c->span_class[b][o[b] - c->lo[b]];
    k[d2] = c->span_class[d2][o[d2] - c->lo[d2]];
    if (set_shift(c, k) == ISO_TREE_LEVELS) {
        /* Every block holding the first region has stride 8, so the brick across does: the
         * face is one region. */
        uint32_t from[2] = {o[b], o[d2]}, to[2] = {o[b] + size[b], o[d2] + size[d2]};
        return region_segments(c, a, side, plane, from, to, 1u << ISO_TREE_LEVELS);
    }
    for (uint32_t rc0 = o[d2]; rc0 < o[d2] + size[d2]; rc0 = (rc0 / ISO_TREE_BLOCK + 1) * ISO_TREE_BLOCK)
        for (uint32_t rb0 = o[b]; rb0 < o[b] + size[b]; rb0 = (rb0 / ISO_TREE_BLOCK + 1) * ISO_TREE_BLOCK) {
            uint32_t rb1 = (rb0 / ISO_TREE_BLOCK + 1) * ISO_TREE_BLOCK, rc1 = (rc0 / ISO_TREE_BLOCK + 1) * ISO_TREE_BLOCK;
            uint32_t from[2] = {rb0, rc0}, to[2] = {rb1 < o[b] + size[b] ? rb1 : o[b] + size[b],
                                                   rc1 < o[d2] + size[d2] ? rc1 : o[d2] + size[d2]};
            k[b] = c->span_class[b][rb0 - c->lo[b]];
            k[d2] = c->span_class[d2][rc0 - c->lo[d2]];
            int rc = region_segments(c, a, side, plane, from, to, 1u << set_shift(c, k));
            if (rc)
                return rc;
        }
    return 0;
}

/* A cell whose faces or edges are finer than itself: face squares, loops, fans. A face
 * whose samples all lie on one side of the level holds no segment and is skipped. */
static int transition_cell(lod *c, const uint32_t o[3], const uint32_t size[3], iso_error *err)
{
    c->segment_count = 0;
    for (int a = 0; a < 3; a++)
        for (int side = 0; side < 2; side++) {
            uint32_t lo[3], hi[3];
            for (int d = 0; d < 3; d++) {
                lo[d] = d == a ? o[d] + size[d] * (uint32_t)side : o[d];
                hi[d] = d == a ? lo[d] : o[d] + size[d];
            }
            if (!box_mixed(c, lo, hi))
                continue;
            int rc = face_segments(c, o, size, a, side);
            if (rc)
                return iso_error_set(err, rc, "out of memory extracting the surface");
        }
    if (!c->segment_count)
        return 0;
    double middle[3];
    for (int d = 0; d < 3; d++)
        middle[d] = o[d] + 0.5 * size[d];
    return fan_loops(c, middle, err);
}

/* The cells of the unit of m[] blocks from block first[] at stride 2^shift, the last per
 * axis narrower where the unit ends off the stride: marching cubes where a cell is
 * regular, else a transition cell. A unit whose samples all lie on one side of the level
 * holds no crossing and is skipped whole (its cells still count as visited). */
static int march_unit(lod *c, const uint32_t first[3], const uint32_t m[3], unsigned shift, iso_error *err)
{
    uint32_t s = 1u << shift;
    unit_box(c, first, m);
    if (!box_mixed(c, c->ulo, c->uhi)) {
        size_t cells = 1;
        for (int d = 0; d < 3; d++)
            cells *= (c->uhi[d] - c->ulo[d] + s - 1) / s;
        c->cells += cells;
        return 0;
    }
    if (c->around_stamp != c->stamp)
        brick_around(c, c->brick_first, c->brick_m);
    int uniform = unit_uniform(c, shift); /* every cell is regular */
    /* Whether a cell is regular depends only on which of the unit's planes it touches. */
    int8_t by_touch[64];
    memset(by_touch, -1, sizeof by_touch);
    for (uint32_t z = c->ulo[2]; z < c->uhi[2]; z += s)
        for (uint32_t y = c->ulo[1]; y < c->uhi[1]; y += s)
            for (uint32_t x = c->ulo[0]; x < c->uhi[0]; x += s) {
                uint32_t o[3] = {x, y, z}, size[3], far[3];
                unsigned touch = 0;
                for (int d = 0; d < 3; d++) {
                    size[d] = c->uhi[d] - o[d] < s ? c->uhi[d] - o[d] : s;
                    far[d] = o[d] + size[d];
                    touch |= (unsigned)(o[d] == c->ulo[d]) << (2 * d) | (unsigned)(far[d] == c->uhi[d]) << (2 * d + 1);
                }
                c->cells++;
                if (by_touch[touch] < 0)
                    by_touch[touch] = (int8_t)(uniform || cell_is_regular(c, o, size, shift));
                int rc;
                if (by_touch[touch]) {
                    rc = regular_cell(c, o, size);
                    if (rc)
                        return iso_error_set(err, rc, rc == ISO_E_LIMIT ? "more than 2^32 - 1 vertices"
                                                                         : "out of memory extracting the surface");
                } else if (box_mixed(c, o, far) && (rc = transition_cell(c, o, size, err))) {
                    return rc;
                }
            }
    return 0;
}

/* Brick b, not wholly stride 1: its samples classified once, then at stride 8 whole, or
 * block after block at the block's own stride (its stride-1 blocks are PASS 2's). */
int iso_coarse_brick(lod *c, const uint32_t b[3], iso_error *err)
{
    size_t lo[3], hi[3];
    iso_bricks_box(c->vol, b, lo, hi);
    for (int d = 0; d < 3; d++) {
        c->lo[d] = (uint32_t)lo[d];
        c->hi[d] = (uint32_t)hi[d];
        c->n[d] = (uint32_t)(hi[d] - lo[d] + 1);
    }
    c->stamp++;
    classify_whole(c);
    uint32_t *first = c->brick_first, *m = c->brick_m;
    brick_blocks(c, b, first, m);
    if (c->shift[block_index(c, first)] == ISO_TREE_LEVELS)
        return march_unit(c, first, m, ISO_TREE_LEVELS, err);
    static const uint32_t one[3] = {1, 1, 1};
    for (uint32_t z = 0; z < m[2]; z++)
        for (uint32_t y = 0; y < m[1]; y++)
            for (uint32_t x = 0; x < m[0]; x++) {
                uint32_t q[3] = {first[0] + x, first[1] + y, first[2] + z};
                unsigned shift = c->shift[block_index(c, q)];
                if (!shift)
                    continue;
                int rc = march_unit(c, q, one, shift, err);
                if (rc)
                    return rc;
            }
    return 0;
}

void iso_coarse_free(lod *c)
{
    free(c->map.keys);
    free(c->map.ids);
    free(c->segments);
    free(c->loop);
    c->map.keys = NULL;
    c->map.ids = NULL;
    c->segments = NULL;
    c->loop = NULL;
}
