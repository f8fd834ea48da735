/* lod_march.c: the tolerance path's brick kernel (lod_march.h), march.c's count-then-fill
 * shape with a stride per block.
 *
 * Every lattice set (an open face, edge or segment of a block's closed box, or a block's
 * open inside) has a stride: the finest of the blocks whose closed boxes hold it. A cell
 * of a unit (a block at stride 2^l, or a brick at 8) whose boundary sets all have its
 * stride is marching cubes' cell on its corners; any other is a transition cell
 * (transition.h), its finer sets' points on its boundary. Every crossing a cell uses lies
 * on a lattice edge of the finest stride of its set; it is owned, like march.c's, by the
 * brick holding its low end, numbered there in the order row (z * 9 + y), level (log2 of
 * its length), axis, x, and found by any brick from the owner's crossing rows by a
 * popcount.
 *
 * PASS 1 (select): the bricks whose [min, max] holds the level, in grid order.
 * PASS 2 (balance, lod_balance.c): a block that shares a crossed face or edge with a
 *   block more than one stride finer is refined, until none does. Then every transition
 *   cell's points are at most one stride finer than the cell.
 * PASS 3 (cells, threads): per brick, the rows its units read classified (a stride-1
 *   block's every row, a coarse unit's every stride or, with finer neighbours, every half
 *   stride); the stride-1 blocks' cells by rows as march.c; a coarse unit's cells one by
 *   one, each kept with its case. Every crossing a cell uses is marked: in the brick's own
 *   rows, or (on its upper faces) in rows its neighbour takes in PASS 4. A case with no
 *   triangulation refines the cell's block, and PASS 2 and 3 run again.
 * PASS 4 (number, threads): the marks of the lower neighbours' upper faces taken in; the
 *   owned crossings numbered.
 * PASS 5 (offsets): prefix sums give each brick its first vertex and triangle.
 * PASS 6 (generate, threads): per brick, its crossings' positions (index space) and
 *   error, the ids of the crossings on its upper faces from their owners, and its
 *   triangles in the order PASS 3 counted them.
 *
 * The layout of a brick's samples, rows and blocks around is lod_job.h's. */
#include "lod_march.h"

#include <assert.h>
#include <stddef.h>
#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "lod_job.h"
#include "mc.h"

#define CHUNK 32             /* bricks a thread takes at a time */
#define CORNER_POINTS (1u << 0 | 1u << 2 | 1u << 6 | 1u << 8 | 1u << 18 | 1u << 20 | 1u << 24 | 1u << 26)  /* a cell's 8 corners among its 27 points */

/* ---- tables, made once ---- */

static uint8_t bit_count[1 << S];
static uint64_t pair_spread[1 << S];
/* Per level, per marching cubes edge, its offset in an id table from the cell's corner 0
 * (in the cell's own lattice row); per level, per slot of transition.h, the same from the
 * cell's row at the slot's level. */
static int32_t edge_offset[LEVELS][12];
/* Per marching cubes case, the edges its corners cross: bit e. */
static uint16_t case_edges[256];
static int32_t slot_offset[LEVELS][ISO_TRANSITION_SLOTS];
static uint8_t slot_full[ISO_TRANSITION_SLOTS]; /* 1: a whole edge of the cell (level l), 0: a half (l - 1) */
/* Per face of a cell its 9 points (transition.h; centre 4), per edge its 3 (middle 1). */
static uint8_t face_points[6][9], edge_points[12][3];
static uint32_t face_mask[6], edge_mask[12];
/* The 18 points of a cell's boundary that are not corners (face centres, edge middles):
 * index, i, j, k. */
static uint8_t middle_points[18][4];
/* Per half stride (log2: 1, 2, 4), per point: its offset in a cell's rows and in x. */
static uint8_t point_row_at[3][ISO_TRANSITION_POINTS], point_x_at[3][ISO_TRANSITION_POINTS];

/* The id table of one brick: [axis][lattice row][x]. */
typedef struct id_table {
    uint32_t at[3][LEVEL_ROWS][S];
} id_table;

#define TABLE_AXIS (LEVEL_ROWS * S)

static void make_tables(void)
{
    for (unsigned w = 0; w < (1u << S); w++) {
        bit_count[w] = (uint8_t)((w & 1) + bit_count[w >> 1]);
        pair_spread[w] = 0;
        for (int x = 0; x < ISO_BRICK_CELLS; x++)
            pair_spread[w] |= (uint64_t)(w >> x & 3) << (8 * x);
    }
    const iso_transition_slot *slots = iso_transition_slots();
    for (int k = 0; k < ISO_TRANSITION_SLOTS; k++)
        slot_full[k] = slots[k].length == 2;
    for (unsigned c = 0; c < 256; c++)
        for (int e = 0; e < 12; e++)
            case_edges[c] |= (uint16_t)(((c >> iso_mc_edge_corner[e][0] ^ c >> iso_mc_edge_corner[e][1]) & 1) << e);
    for (int l = 0; l < LEVELS; l++) {
        int step = 1 << l, half = step / 2;
        for (int e = 0; e < 12; e++) {
            int lo = iso_mc_edge_corner[e][0], axis = e / 4;
            int x = (lo & 1) * step, y = (lo >> 1 & 1) * step, z = (lo >> 2 & 1) * step;
            edge_offset[l][e] = axis * TABLE_AXIS + ((z >> l) * level_width[l] + (y >> l)) * S + x;
        }
        for (int s = 0; s < ISO_TRANSITION_SLOTS && l > 0; s++) {
            const iso_transition_slot *t = &slots[s];
            int full = t->length == 2, sl = full ? l : l - 1;
            /* From the cell's own row at level sl (full: l, half: l - 1). */
            slot_offset[l][s] = t->axis * TABLE_AXIS + ((t->low[2] >> full) * level_width[sl] + (t->low[1] >> full)) * S +
                                t->low[0] * half;
        }
    }
    int middles = 0;
    for (unsigned p = 0; p < ISO_TRANSITION_POINTS; p++) {
        unsigned i = p % 3, j = p / 3 % 3, k = p / 9, ones = (i == 1) + (j == 1) + (k == 1);
        if (ones == 1 || ones == 2) {
            uint8_t q[4] = {(uint8_t)p, (uint8_t)i, (uint8_t)j, (uint8_t)k};
            memcpy(middle_points[middles++], q, sizeof q);
        }
    }
    for (int hl = 0; hl < 3; hl++)
        for (unsigned p = 0; p < ISO_TRANSITION_POINTS; p++) {
            point_row_at[hl][p] = (uint8_t)((p / 9 * S + p / 3 % 3) << hl);
            point_x_at[hl][p] = (uint8_t)(p % 3 << hl);
        }
    for (int f = 0; f < 6; f++) {
        int d = f / 2, u = (d + 1) % 3, v = (d + 2) % 3, n = 0;
        for (int j = 0; j < 3; j++)
            for (int i = 0; i < 3; i++) {
                int c[3];
                c[d] = 2 * (f & 1);
                c[u] = i;
                c[v] = j;
                face_points[f][n] = (uint8_t)iso_transition_point((unsigned)c[0], (unsigned)c[1], (unsigned)c[2]);
                face_mask[f] |= 1u << face_points[f][n++];
            }
    }
    for (int e = 0; e < 12; e++) {
        int a = e / 4, b = (a + 1) % 3, c = (a + 2) % 3;
        for (int k = 0; k < 3; k++) {
            int p[3];
            p[a] = k;
            p[b] = 2 * (e & 1);
            p[c] = 2 * (e >> 1 & 1);
            edge_points[e][k] = (uint8_t)iso_transition_point((unsigned)p[0], (unsigned)p[1], (unsigned)p[2]);
            edge_mask[e] |= 1u << edge_points[e][k];
        }
    }
}

static pthread_once_t tables_once = PTHREAD_ONCE_INIT;

/* ---- blocks and strides ---- */


/* The strides of the blocks around brick wb (near[][][]), and the finest of those that
 * share more than a corner with it. */

static void gather_near(const lod_job *job, work_brick *wb)
{
    unsigned hi, lo = iso_lod_bricks_around(job, wb->brick, &hi);
    if (lo == hi) { /* one stride all round */
        memset(wb->near, (int)lo, sizeof wb->near);
        wb->finest = (uint8_t)lo;
        wb->uniform = 1;
        return;
    }
    wb->uniform = 0;
    int from[3], to[3]; /* the near entries inside the grid, per axis */
    for (int d = 0; d < 3; d++) {
        uint32_t first = 2 * wb->brick[d], m = job->blocks[d] - first < 2 ? job->blocks[d] - first : 2;
        from[d] = first == 0;
        to[d] = (int)m + (first + m < job->blocks[d]);
    }
    memset(wb->near, NO_BLOCK, sizeof wb->near);
    unsigned finest = NO_BLOCK;
    for (int z = from[2]; z <= to[2]; z++)
        for (int y = from[1]; y <= to[1]; y++) {
            const uint8_t *row = job->shift + block_index(job, 2 * wb->brick[0] - 1 + (uint32_t)from[0],
                                                          2 * wb->brick[1] + (uint32_t)y - 1, 2 * wb->brick[2] + (uint32_t)z - 1);
            int outer = (y == 0 || y == 3) + (z == 0 || z == 3);
            for (int x = from[0]; x <= to[0]; x++, row++) {
                wb->near[z][y][x] = *row;
                if (outer + (x == 0 || x == 3) < 3 && *row < finest)
                    finest = *row;
            }
        }
    wb->finest = (uint8_t)finest;
}

/* The strides of the sets of a unit's closed box by class per axis (its low plane, its
 * inside, its high plane): [z][y][x]. The unit spans near entries [lo, hi] per axis (one
 * block, or the brick's two); a class is held by the entries it touches. */
typedef uint8_t unit_sets[3][3][3];

static void make_unit_sets(const work_brick *wb, const int lo[3], const int hi[3], unit_sets out)
{
    uint8_t along_x[NEAR][NEAR][3], along_y[NEAR][3][3];
    for (int z = lo[2] - 1; z <= hi[2] + 1; z++)
        for (int y = lo[1] - 1; y <= hi[1] + 1; y++) {
            const uint8_t *n = wb->near[z][y];
            uint8_t inside = n[lo[0]] < n[hi[0]] ? n[lo[0]] : n[hi[0]];
            along_x[z][y][0] = n[lo[0] - 1] < n[lo[0]] ? n[lo[0] - 1] : n[lo[0]];
            along_x[z][y][1] = inside;
            along_x[z][y][2] = n[hi[0] + 1] < n[hi[0]] ? n[hi[0] + 1] : n[hi[0]];
        }
    for (int z = lo[2] - 1; z <= hi[2] + 1; z++)
        for (int x = 0; x < 3; x++) {
            uint8_t a = along_x[z][lo[1] - 1][x], b = along_x[z][lo[1]][x], c = along_x[z][hi[1]][x],
                    d = along_x[z][hi[1] + 1][x];
            along_y[z][0][x] = a < b ? a : b;
            along_y[z][1][x] = b < c ? b : c;
            along_y[z][2][x] = c < d ? c : d;
        }
    for (int y = 0; y < 3; y++)
        for (int x = 0; x < 3; x++) {
            uint8_t a = along_y[lo[2] - 1][y][x], b = along_y[lo[2]][y][x], c = along_y[hi[2]][y][x],
                    d = along_y[hi[2] + 1][y][x];
            out[0][y][x] = a < b ? a : b;
            out[1][y][x] = b < c ? b : c;
            out[2][y][x] = c < d ? c : d;
        }
}

/* ---- PASS 3: count ---- */

/* Sets bit r of a row set. */
static inline void row_add(uint64_t rows[2], int r)
{
    rows[r / 64] |= (uint64_t)1 << (r % 64);
}

static inline int row_has(const uint64_t rows[2], int r)
{
    return (int)(rows[r / 64] >> (r % 64) & 1);
}

/* Marks the crossing on the edge of level l along axis a from brick-local sample (x, y, z)
 * as used: owned here, or on an upper face, its neighbour's. */
static inline void mark(work_brick *wb, int l, int a, int x, int y, int z)
{
    int r = level_row(l, y, z);
    if (x < wb->owned[0] && y < wb->owned[1] && z < wb->owned[2]) {
        wb->cross[a][r] |= (uint16_t)(1u << x);
        row_add(wb->marked_rows, r);
    } else {
        wb->foreign[a][r] |= (uint16_t)(1u << x);
        row_add(wb->foreign_rows, r);
    }
}

/* Marks a row's crossing edges `bits` of level 0 along axis a (row r = (y, z)). */
static inline void mark_row(work_brick *wb, int a, int y, int z, unsigned bits)
{
    if (!bits)
        return;
    int r = z * S + y; /* level 0's lattice rows are the brick's rows */
    if (y < wb->owned[1] && z < wb->owned[2]) {
        unsigned own = bits & ((1u << wb->owned[0]) - 1);
        if (own) {
            wb->cross[a][r] |= (uint16_t)own;
            row_add(wb->marked_rows, r);
        }
        bits &= ~own;
    }
    if (bits) {
        wb->foreign[a][r] |= (uint16_t)bits;
        row_add(wb->foreign_rows, r);
    }
}

/* The stride-1 blocks' crossings: every crossing edge of their closed boxes, row by row
 * (fine: the stride-1 blocks, bit k). Per row, the samples of the boxes holding it and the
 * low ends of their edges along x; an edge along y or z belongs to a box holding both
 * its rows. */
static void mark_fine_blocks(work_brick *wb, unsigned fine)
{
    unsigned points[2], x_edges[2]; /* per x half of the brick */
    for (int h = 0; h < 2; h++) {
        int lo = h * HALF, hi = lo + HALF < wb->n[0] - 1 ? lo + HALF : wb->n[0] - 1;
        points[h] = lo > wb->n[0] - 1 ? 0 : ((1u << (hi + 1)) - 1) & ~((1u << lo) - 1);
        x_edges[h] = points[h] & ~(1u << hi);
    }
    /* By the y halves (bits) and z halves holding a row: the x masks of the stride-1 boxes. */
    uint16_t box_points[4][4], box_x[4][4];
    for (unsigned ym = 0; ym < 4; ym++)
        for (unsigned zm = 0; zm < 4; zm++) {
            unsigned p = 0, e = 0;
            for (unsigned k = 0; k < 8; k++)
                if ((fine >> k & 1) && (ym >> (k >> 1 & 1) & 1) && (zm >> (k >> 2) & 1)) {
                    p |= points[k & 1];
                    e |= x_edges[k & 1];
                }
            box_points[ym][zm] = (uint16_t)p;
            box_x[ym][zm] = (uint16_t)e;
        }
    /* Per y (and z): the halves holding that row, and the half holding the edge from it
     * to the next row (none from the last). */
    uint8_t at[3][S], from[3][S];
    for (int d = 1; d < 3; d++)
        for (int v = 0; v < wb->n[d]; v++) {
            at[d][v] = (uint8_t)((v <= HALF) | (v >= HALF && HALF < wb->n[d] - 1) << 1);
            from[d][v] = (uint8_t)(v + 1 >= wb->n[d] ? 0 : v < HALF ? 1 : 2);
        }
    for (int z = 0; z < wb->n[2]; z++)
        for (int y = 0; y < wb->n[1]; y++) {
            unsigned bx = box_x[at[1][y]][at[2][z]], by = box_points[from[1][y]][at[2][z]],
                     bz = box_points[at[1][y]][from[2][z]];
            if (!(bx | by | bz))
                continue;
            int r = z * S + y;
            unsigned row = wb->inside[r];
            mark_row(wb, 0, y, z, (row ^ (row >> 1)) & bx);
            if (by)
                mark_row(wb, 1, y, z, (row ^ wb->inside[r + 1]) & by);
            if (bz)
                mark_row(wb, 2, y, z, (row ^ wb->inside[r + S]) & bz);
        }
}

static void number_crossings(work_brick *wb)
{
    wb->crossing_rows[0] = wb->crossing_rows[1] = 0;
    uint32_t count = 0;
    for (int word = 0; word < 2; word++)
        for (uint64_t m = wb->marked_rows[word]; m; m &= m - 1) {
            int r = 64 * word + __builtin_ctzll(m);
            unsigned here = bit_count[wb->cross[0][r]] + bit_count[wb->cross[1][r]] + bit_count[wb->cross[2][r]];
            wb->row_base[r] = (uint16_t)count;
            count += here;
            wb->crossing_rows[r / 64] |= (uint64_t)(here != 0) << (r % 64);
        }
    wb->vertices = count;
}

typedef struct cell_row {
    unsigned a, b, c, d;
} cell_row;

static inline cell_row cell_row_at(const uint16_t *inside, int y, int z)
{
    cell_row q = {inside[z * S + y], inside[z * S + y + 1], inside[(z + 1) * S + y], inside[(z + 1) * S + y + 1]};
    return q;
}

static inline uint64_t row_cases(cell_row q)
{
    return pair_spread[q.a] | pair_spread[q.b] << 2 | pair_spread[q.c] << 4 | pair_spread[q.d] << 6;
}

/* The stride-1 cells to march: mixed cells of the stride-1 blocks, by rows as march.c. */
static uint32_t count_fine_cells(work_brick *wb, size_t *cells)
{
    const iso_mc_case *cases = iso_mc_cases();
    memset(wb->marching, 0, sizeof wb->marching);
    uint32_t triangles = 0;
    unsigned x_cells = (1u << (wb->n[0] - 1)) - 1;
    for (int z = 0; z + 1 < wb->n[2]; z++)
        for (int y = 0; y + 1 < wb->n[1]; y++) {
            const uint8_t *k = wb->near[1 + (z >= HALF)][1 + (y >= HALF)];
            unsigned fine = ((k[1] == 0 ? 0x0Fu : 0) | (k[2] == 0 ? 0xF0u : 0)) & x_cells;
            if (!fine)
                continue;
            *cells += (size_t)bit_count[fine];
            cell_row q = cell_row_at(wb->inside, y, z);
            unsigned any = q.a | q.b | q.c | q.d, all = q.a & q.b & q.c & q.d;
            unsigned mixed = ~((all & (all >> 1)) | (~any & ~(any >> 1))) & fine;
            int r = z * S + y;
            wb->marching[r] = (uint8_t)mixed;
            if (!mixed)
                continue;
            wb->marching_rows[r / 64] |= (uint64_t)1 << (r % 64);
            uint64_t row = row_cases(q);
            for (unsigned m = mixed; m; m &= m - 1)
                triangles += cases[(unsigned)(row >> (8 * __builtin_ctz(m))) & 0xFF].triangle_count;
        }
    return triangles;
}

/* 1 if the classified samples of a unit's box [lo, lo + side] (brick-local, clipped) at
 * multiples of its half stride lie on both sides of the level: every point its cells read
 * is one of them. */
static int box_mixed(const work_brick *wb, const uint64_t needed[2], const int lo[3], int side, int l)
{
    int step = 1 << l >> 1, hi[3];
    for (int d = 0; d < 3; d++)
        hi[d] = lo[d] + side < wb->n[d] - 1 ? lo[d] + side : wb->n[d] - 1;
    unsigned mask = 0;
    for (int x = lo[0]; x <= hi[0]; x += step)
        mask |= 1u << x;
    unsigned any = 0, all = mask;
    for (int z = lo[2]; z <= hi[2]; z += step)
        for (int y = lo[1]; y <= hi[1]; y += step) {
            int r = z * S + y;
            if (!row_has(needed, r))
                continue;
            unsigned row = wb->inside[r] & mask;
            any |= row;
            all &= row;
        }
    return any && all != mask;
}

/* The inside bits of the points `points` of the cell at corner c, half stride 2^hl. */
static uint32_t cell_inside(const work_brick *wb, const int c[3], int hl, uint32_t points)
{
    const uint16_t *rows = wb->inside + c[2] * S + c[1];
    const uint8_t *row_at = point_row_at[hl], *x_at = point_x_at[hl];
    unsigned row = 0;
    uint32_t in = 0;
    for (uint32_t m = points; m; m &= m - 1) {
        unsigned p = (unsigned)__builtin_ctz(m);
        row = rows[row_at[p]];
        in |= (uint32_t)(row >> (c[0] + x_at[p]) & 1) << p;
    }
    return in;
}

/* The points a transition cell at corner c and level l (a cell of a unit whose set
 * strides are `sets`, whose low corner is at lo) has on its boundary: the midpoints and
 * centres whose set is finer than the cell, where that set's points cross (a set whose
 * points all lie on one side holds no crossing, and leaving it out changes no face's
 * segments); with the inside bits of those and the corners. present = 0: a marching
 * cubes cell. */
static void transition_points(const work_brick *wb, const unit_sets sets, const int unit_lo[3], int unit_side,
                              const int c[3], int l, uint32_t *present, uint32_t *inside)
{
    int h = 1 << l >> 1, hl = l - 1;
    uint8_t cls[3][3]; /* per axis, the class of the cell's points 0, h, 2h */
    for (int d = 0; d < 3; d++)
        for (int i = 0; i < 3; i++) {
            int v = c[d] + i * h - unit_lo[d];
            cls[d][i] = (uint8_t)(v == 0 ? 0 : v == unit_side ? 2 : 1);
        }
    uint32_t finer = 0;
    for (int k = 0; k < 18; k++) {
        const uint8_t *q = middle_points[k];
        finer |= (uint32_t)(sets[cls[2][q[3]]][cls[1][q[2]]][cls[0][q[1]]] < l) << q[0];
    }
    if (!finer) {
        *present = 0;
        *inside = cell_inside(wb, c, hl, CORNER_POINTS);
        return;
    }
    uint32_t in = cell_inside(wb, c, hl, ((1u << ISO_TRANSITION_POINTS) - 1) & ~(1u << 13));
    uint32_t have = 0;
    for (int f = 0; f < 6; f++)
        if ((finer >> face_points[f][4] & 1) && (in & face_mask[f]) && (in & face_mask[f]) != face_mask[f])
            have |= face_mask[f];
    for (int e = 0; e < 12; e++)
        if ((finer >> edge_points[e][1] & 1) && (in & edge_mask[e]) && (in & edge_mask[e]) != edge_mask[e])
            have |= 1u << edge_points[e][1];
    *present = have & ~CORNER_POINTS;
    *inside = in & (have | CORNER_POINTS);
}

/* 1 if the samples of the cell at corner c and level l, every half stride, lie on both
 * sides of the level: else no point of it (corner or finer) crosses. */
static inline int cell_mixed(const work_brick *wb, const int c[3], int l)
{
    int h = 1 << l >> 1;
    unsigned mask = (1u | 1u << h | 1u << (2 * h)) << c[0], any = 0, all = mask;
    const uint16_t *r = wb->inside + c[2] * S + c[1];
    for (int k = 0; k < 3; k++)
        for (int j = 0; j < 3; j++) {
            unsigned row = r[(k * S + j) * h] & mask;
            any |= row;
            all &= row;
        }
    return any && all != mask;
}

/* Marching cubes' case of the cell at corner c with side `step`, from the rows. */
static inline unsigned cell_case(const work_brick *wb, const int c[3], int step)
{
    const uint16_t *r = wb->inside + c[2] * S + c[1];
    unsigned a = r[0] >> c[0], b = r[step] >> c[0], d = r[step * S] >> c[0], e = r[step * S + step] >> c[0];
    return (a & 1) | (a >> step & 1) << 1 | (b & 1) << 2 | (b >> step & 1) << 3 | (d & 1) << 4 | (d >> step & 1) << 5 |
           (e & 1) << 6 | (e >> step & 1) << 7;
}

static unsigned corner_case(uint32_t inside)
{
    static const uint8_t corner_point[8] = {0, 2, 6, 8, 18, 20, 24, 26};
    unsigned c = 0;
    for (int k = 0; k < 8; k++)
        c |= (inside >> corner_point[k] & 1) << k;
    return c;
}

static void record_infeasible(lod_job *job, size_t block)
{
    pthread_mutex_lock(&job->lock);
    if (job->infeasible_count == job->infeasible_capacity) {
        size_t capacity = job->infeasible_capacity ? 2 * job->infeasible_capacity : 64;
        size_t *grown = realloc(job->infeasible, capacity * sizeof *grown);
        if (!grown) {
            job->failed = 1;
            pthread_mutex_unlock(&job->lock);
            return;
        }
        job->infeasible = grown;
        job->infeasible_capacity = capacity;
    }
    job->infeasible[job->infeasible_count++] = block * LEVELS + job->shift[block];
    pthread_mutex_unlock(&job->lock);
}

/* One coarse cell into wb's records: its triangles counted, or its block recorded when its
 * case has no kept triangulation. sets: its unit's set strides, NULL if all are its own. */
static uint32_t count_cell(lod_job *job, work_brick *wb, cell_records *records, const unit_sets sets,
                           const int unit_lo[3], int unit_side, const int c[3], int l, size_t *transitions)
{
    if (records->count == records->capacity) {
        size_t capacity = records->capacity ? 2 * records->capacity : 4096;
        cell_record *grown = realloc(records->at, capacity * sizeof *grown);
        if (!grown) {
            job->failed = 1;
            return 0;
        }
        records->at = grown;
        records->capacity = capacity;
    }
    const iso_mc_case *cases = iso_mc_cases();
    uint32_t present = 0, inside = 0;
    if (sets)
        transition_points(wb, sets, unit_lo, unit_side, c, l, &present, &inside);
    cell_record *rec = &records->at[records->count];
    uint32_t triangles;
    rec->tc = NULL;
    if (!present) {
        unsigned mc = sets ? corner_case(inside) : cell_case(wb, c, 1 << l);
        rec->mc = (uint8_t)mc;
        triangles = cases[mc].triangle_count;
    } else {
        iso_transition_scratch scratch;
        const iso_transition_case *tc = iso_transition_get(present, inside, &scratch);
        (*transitions)++;
        if (!tc || tc == &scratch.built) {
            /* No triangulation, or one the memo could not keep (full, or out of memory):
             * the plan refines the block. */
            record_infeasible(job, block_index(job, 2 * wb->brick[0] + (c[0] >= HALF), 2 * wb->brick[1] + (c[1] >= HALF),
                                               2 * wb->brick[2] + (c[2] >= HALF)));
            return 0;
        }
        rec->tc = tc;
        triangles = tc->triangle_count;
    }
    if (!triangles)
        return 0;
    if (!present) {
        const uint16_t step = (uint16_t)(1 << l);
        for (unsigned e = case_edges[rec->mc]; e; e &= e - 1) {
            int k = __builtin_ctz(e), lo = iso_mc_edge_corner[k][0];
            mark(wb, l, k / 4, c[0] + (lo & 1) * step, c[1] + (lo >> 1 & 1) * step, c[2] + (lo >> 2 & 1) * step);
        }
    } else {
        const iso_transition_slot *slots = iso_transition_slots();
        int h = 1 << l >> 1;
        for (int k = 0; k < 3 * rec->tc->triangle_count; k++) {
            const iso_transition_slot *t = &slots[rec->tc->slot[k]];
            mark(wb, t->length == 2 ? l : l - 1, t->axis, c[0] + t->low[0] * h, c[1] + t->low[1] * h, c[2] + t->low[2] * h);
        }
    }
    rec->c[0] = (uint8_t)c[0];
    rec->c[1] = (uint8_t)c[1];
    rec->c[2] = (uint8_t)c[2];
    rec->l = (uint8_t)l;
    records->count++;
    wb->cell_count++;
    return triangles;
}

/* The brick's coarse units: the brick at stride 8 (one), or its blocks at strides 2 and
 * 4, each with its box, level and set strides (regular: all its own). */
typedef struct coarse_unit {
    int lo[3], side, l, regular;
    unit_sets sets;
} coarse_unit;

/* 1 if every block sharing a face or an edge with near entries [lo, hi] (a unit's own)
 * has stride l or coarser: then every set of the unit's box with more than a point has
 * its stride, and its cells are all marching cubes cells. */
static int unit_regular_near(const work_brick *wb, const int lo[3], const int hi[3], int l)
{
    for (int z = lo[2] - 1; z <= hi[2] + 1; z++)
        for (int y = lo[1] - 1; y <= hi[1] + 1; y++) {
            int out_yz = (y < lo[1] || y > hi[1]) + (z < lo[2] || z > hi[2]);
            const uint8_t *row = wb->near[z][y];
            if (out_yz == 2) { /* only the middle of the row shares an edge */
                for (int x = lo[0]; x <= hi[0]; x++)
                    if (row[x] < l)
                        return 0;
            } else {
                for (int x = lo[0] - 1; x <= hi[0] + 1; x++)
                    if (row[x] < l)
                        return 0;
            }
        }
    return 1;
}

static int coarse_units(work_brick *wb, coarse_unit *out)
{
    static const int own_lo[3] = {1, 1, 1}, own_hi[3] = {2, 2, 2};
    int count = 0;
    if (wb->near[1][1][1] == ISO_TREE_LEVELS) { /* a stride-8 brick is whole */
        coarse_unit *u = &out[count++];
        memset(u->lo, 0, sizeof u->lo);
        u->side = 2 * HALF;
        u->l = ISO_TREE_LEVELS;
        u->regular = wb->uniform || unit_regular_near(wb, own_lo, own_hi, u->l);
        if (!u->regular)
            make_unit_sets(wb, own_lo, own_hi, u->sets);
        return count;
    }
    for (int k = 0; k < 8; k++) {
        int at[3] = {1 + (k & 1), 1 + (k >> 1 & 1), 1 + (k >> 2)};
        int l = wb->near[at[2]][at[1]][at[0]];
        if (l == 0 || l == NO_BLOCK)
            continue;
        coarse_unit *u = &out[count++];
        u->lo[0] = (k & 1) * HALF;
        u->lo[1] = (k >> 1 & 1) * HALF;
        u->lo[2] = (k >> 2) * HALF;
        u->side = HALF;
        u->l = l;
        u->regular = wb->uniform || unit_regular_near(wb, at, at, l);
        if (!u->regular)
            make_unit_sets(wb, at, at, u->sets);
    }
    return count;
}

/* The rows of a unit's box [lo, lo + side] every `step` samples: its cells read those (a
 * transition unit's every half stride). */
static void unit_rows(const work_brick *wb, const int lo[3], int side, int step, uint64_t needed[2])
{
    for (int z = lo[2]; z <= lo[2] + side && z < wb->n[2]; z += step)
        for (int y = lo[1]; y <= lo[1] + side && y < wb->n[1]; y += step)
            row_add(needed, z * S + y);
}

/* The coarse units' cells whose units the level crosses, in a fixed order: units in order,
 * each unit's cells z, y, x. */
static uint32_t count_coarse_cells(lod_job *job, work_brick *wb, cell_records *records, const coarse_unit *units,
                                   int unit_count, const uint64_t needed[2], size_t *cells, size_t *transitions)
{
    uint32_t triangles = 0;
    for (int i = 0; i < unit_count; i++) {
        const coarse_unit *u = &units[i];
        if (!box_mixed(wb, needed, u->lo, u->side, u->l))
            continue;
        wb->coarse = 1;
        int step = 1 << u->l;
        for (int z = u->lo[2]; z < u->lo[2] + u->side && z + step < wb->n[2]; z += step)
            for (int y = u->lo[1]; y < u->lo[1] + u->side && y + step < wb->n[1]; y += step)
                for (int x = u->lo[0]; x < u->lo[0] + u->side && x + step < wb->n[0]; x += step) {
                    const int c[3] = {x, y, z};
                    (*cells)++;
                    if (!u->regular && !cell_mixed(wb, c, u->l))
                        continue;
                    triangles += count_cell(job, wb, records, u->regular ? NULL : u->sets, u->lo, u->side, c, u->l,
                                            transitions);
                }
    }
    return triangles;
}

static size_t count_brick(lod_job *job, work_brick *wb, cell_records *records, int t, size_t *transitions)
{
    gather_near(job, wb);
    coarse_unit units[8];
    int unit_count = coarse_units(wb, units);
    uint64_t needed[2] = {0, 0};
    for (int i = 0; i < unit_count; i++)
        unit_rows(wb, units[i].lo, units[i].side, 1 << units[i].l >> !units[i].regular, needed);
    unsigned fine = 0; /* the stride-1 blocks, bit k */
    for (int k = 0; k < 8; k++)
        if (!wb->near[1 + (k >> 2)][1 + (k >> 1 & 1)][1 + (k & 1)]) {
            const int lo[3] = {(k & 1) * HALF, (k >> 1 & 1) * HALF, (k >> 2) * HALF};
            unit_rows(wb, lo, HALF, 1, needed);
            fine |= 1u << k;
        }
    size_t lo[3], hi[3];
    iso_bricks_box(job->vol, wb->brick, lo, hi);
    memset(wb->inside, 0, sizeof wb->inside);
    iso_march_inside_rows_listed(job->vol, &job->threshold, lo, wb->n, needed, wb->inside);
    memset(wb->cross, 0, sizeof wb->cross);
    memset(wb->foreign, 0, sizeof wb->foreign);
    wb->marked_rows[0] = wb->marked_rows[1] = wb->foreign_rows[0] = wb->foreign_rows[1] = 0;
    size_t cells = 0;
    wb->coarse = 0;
    wb->cell_count = 0;
    wb->records_thread = (uint8_t)t;
    wb->records_first = (uint32_t)records->count;
    wb->marching_rows[0] = wb->marching_rows[1] = 0;
    wb->triangles = 0;
    if (fine) {
        wb->triangles += count_fine_cells(wb, &cells);
        mark_fine_blocks(wb, fine);
    }
    wb->triangles += count_coarse_cells(job, wb, records, units, unit_count, needed, &cells, transitions);
    return cells;
}

/* ---- the shared pieces of the threaded passes ---- */

typedef struct range {
    size_t begin, end;
} range;

static int next_chunk(lod_job *job, range *r)
{
    return iso_parallel_next_chunk(&job->next, job->work_count, CHUNK, &r->begin, &r->end);
}

static void run_bricks(lod_job *job, int threads, iso_parallel_fn fn)
{
    int used = job->work_count < (size_t)threads ? (job->work_count ? (int)job->work_count : 1) : threads;
    atomic_store_explicit(&job->next, 0, memory_order_relaxed);
    iso_parallel_run(used, fn, job);
}

static void count_share(void *context, int t, int threads)
{
    lod_job *job = context;
    range r;
    size_t cells = 0, transitions = 0;
    (void)threads;
    job->records[t].count = 0;
    while (next_chunk(job, &r))
        for (size_t i = r.begin; i < r.end; i++)
            cells += count_brick(job, &job->work[i], &job->records[t], t, &transitions);
    job->cells[t] = cells;
    job->transitions[t] = transitions;
}

/* ---- PASS 4: number ---- */

static void take_marks(const lod_job *job, work_brick *wb)
{
    const iso_bricks *g = job->bricks;
    for (int d = 1; d < 8; d++) {
        int dx = d & 1, dy = d >> 1 & 1, dz = d >> 2;
        if ((dx && !wb->brick[0]) || (dy && !wb->brick[1]) || (dz && !wb->brick[2]))
            continue;
        uint32_t b[3] = {wb->brick[0] - (uint32_t)dx, wb->brick[1] - (uint32_t)dy, wb->brick[2] - (uint32_t)dz};
        int32_t slot = job->slot[((size_t)b[2] * g->count[1] + b[1]) * g->count[0] + b[0]];
        if (slot < 0)
            continue;
        const work_brick *from = &job->work[slot];
        for (int word = 0; word < 2; word++)
            for (uint64_t m = from->foreign_rows[word]; m; m &= m - 1) {
                int r = 64 * word + __builtin_ctzll(m), l, y, z;
                row_of(r, &l, &y, &z);
                if ((y >= from->owned[1]) != dy || (z >= from->owned[2]) != dz)
                    continue;
                int to = level_row(l, y - dy * ISO_BRICK_CELLS, z - dz * ISO_BRICK_CELLS);
                for (int a = 0; a < 3; a++) {
                    unsigned bits = from->foreign[a][r];
                    bits = dx ? bits >> from->owned[0] & 1 : bits & ((1u << from->owned[0]) - 1);
                    if (!bits)
                        continue;
                    wb->cross[a][to] |= (uint16_t)bits;
                    row_add(wb->marked_rows, to);
                }
            }
    }
}

static void number_share(void *context, int t, int threads)
{
    lod_job *job = context;
    range r;
    (void)t;
    (void)threads;
    while (next_chunk(job, &r))
        for (size_t i = r.begin; i < r.end; i++) {
            take_marks(job, &job->work[i]);
            number_crossings(&job->work[i]);
        }
}

/* ---- PASS 5: generate ---- */

/* Positions of the brick's owned crossings, in numbering order, and their ids; returns
 * the largest |f(v) - level|: on a data edge the crossing's own, on a longer one f on the
 * data edge the vertex lies on. One copy per voxel type (the sample reads without a
 * switch; integer samples skip the infinity tests). */
static inline __attribute__((always_inline)) double place_vertices_as(const lod_job *job, const work_brick *wb,
                                                                      id_table *table, const iso_voxel_type type)
{
    const iso_volume *vol = job->vol;
    const int integer = type != ISO_F32 && type != ISO_F64;
    const double level = job->level;
    const size_t step_of[3] = {1, vol->dims[0], vol->dims[0] * vol->dims[1]};
    float *p = job->mesh->positions + 3 * wb->first_vertex;
    uint32_t id = (uint32_t)wb->first_vertex;
    double worst = 0;
    size_t lo[3] = {(size_t)wb->brick[0] * ISO_BRICK_CELLS, (size_t)wb->brick[1] * ISO_BRICK_CELLS,
                    (size_t)wb->brick[2] * ISO_BRICK_CELLS};
    for (int word = 0; word < 2; word++)
        for (uint64_t rows = wb->crossing_rows[word]; rows; rows &= rows - 1) {
            int r = 64 * word + __builtin_ctzll(rows), l, y, z;
            row_of(r, &l, &y, &z);
            double cy = (double)(lo[1] + (size_t)y), cz = (double)(lo[2] + (size_t)z);
            size_t row_at = ((lo[2] + (size_t)z) * vol->dims[1] + lo[1] + (size_t)y) * vol->dims[0] + lo[0];
            size_t length = (size_t)1 << l;
            for (int a = 0; a < 3; a++)
                for (unsigned m = wb->cross[a][r]; m; m &= m - 1) {
                    int x = __builtin_ctz(m);
                    table->at[a][r][x] = id++;
                    size_t at = row_at + (size_t)x, far = at + length * step_of[a];
                    double from = iso_vol_sample_as(vol->data, type, at), to = iso_vol_sample_as(vol->data, type, far);
                    double t = integer ? iso_mc_edge_t_finite(from, to, level) : iso_mc_edge_t(from, to, level), e;
                    if (l == 0) {
                        e = iso_mc_edge_error(from, to, t, level);
                    } else {
                        double along = t * (double)length;
                        size_t k = (size_t)along;
                        k = k < length ? k : length - 1;
                        double f0 = iso_vol_sample_as(vol->data, type, at + k * step_of[a]);
                        double f1 = iso_vol_sample_as(vol->data, type, at + (k + 1) * step_of[a]);
                        e = fabs(f0 + (along - (double)k) * (f1 - f0) - level);
                    }
                    worst = e > worst ? e : worst;
                    double index[3] = {(double)(lo[0] + (size_t)x), cy, cz};
                    index[a] += t * (double)length;
                    p[0] = (float)index[0];
                    p[1] = (float)index[1];
                    p[2] = (float)index[2];
                    p += 3;
                }
        }
    assert(p == job->mesh->positions + 3 * (wb->first_vertex + wb->vertices));
    return worst;
}

static double place_vertices(const lod_job *job, const work_brick *wb, id_table *table)
{
    switch (job->vol->type) {
    case ISO_U8: return place_vertices_as(job, wb, table, ISO_U8);
    case ISO_I8: return place_vertices_as(job, wb, table, ISO_I8);
    case ISO_U16: return place_vertices_as(job, wb, table, ISO_U16);
    case ISO_I16: return place_vertices_as(job, wb, table, ISO_I16);
    case ISO_U32: return place_vertices_as(job, wb, table, ISO_U32);
    case ISO_I32: return place_vertices_as(job, wb, table, ISO_I32);
    case ISO_F32: return place_vertices_as(job, wb, table, ISO_F32);
    case ISO_F64: return place_vertices_as(job, wb, table, ISO_F64);
    }
    return 0;
}

/* The bricks whose rows the upper faces of wb reach: by k = up_x | up_y << 1 | up_z << 2
 * (NULL where there is none selected). */
static void upper_neighbours(const lod_job *job, const work_brick *wb, const work_brick *out[8])
{
    const iso_bricks *g = job->bricks;
    for (int k = 0; k < 8; k++) {
        uint32_t b[3] = {wb->brick[0] + (uint32_t)(k & 1), wb->brick[1] + (uint32_t)(k >> 1 & 1),
                         wb->brick[2] + (uint32_t)(k >> 2)};
        out[k] = NULL;
        if (b[0] < g->count[0] && b[1] < g->count[1] && b[2] < g->count[2]) {
            int32_t slot = job->slot[((size_t)b[2] * g->count[1] + b[1]) * g->count[0] + b[0]];
            out[k] = slot >= 0 ? &job->work[slot] : NULL;
        }
    }
}

/* The first id of lattice row r's crossings along axis a in brick wb. */
static inline uint32_t row_first(const work_brick *wb, int r, int a)
{
    uint32_t before = wb->row_base[r];
    for (int k = 0; k < a; k++)
        before += bit_count[wb->cross[k][r]];
    return (uint32_t)(wb->first_vertex + before);
}

/* The ids of the crossings the brick's cells use on its upper faces, owned by its
 * neighbours: each the owner's row's first id plus the crossings before it in the row. */
static void fill_shared_ids(const lod_job *job, const work_brick *wb, id_table *table)
{
    const uint8_t *o = wb->owned;
    const work_brick *near[8];
    upper_neighbours(job, wb, near);
    for (int word = 0; word < 2; word++)
        for (uint64_t m = wb->foreign_rows[word]; m; m &= m - 1) {
            int r = 64 * word + __builtin_ctzll(m), l, y, z;
            row_of(r, &l, &y, &z);
            int up = (y >= o[1]) << 1 | (z >= o[2]) << 2;
            int owner_row = level_row(l, y - (up >> 1 & 1) * ISO_BRICK_CELLS, z - (up >> 2) * ISO_BRICK_CELLS);
            for (int a = 0; a < 3; a++)
                for (unsigned bits = wb->foreign[a][r]; bits; bits &= bits - 1) {
                    int x = __builtin_ctz(bits), k = up | (x >= o[0]);
                    const work_brick *owner = near[k];
                    int ox = x - (k & 1) * ISO_BRICK_CELLS;
                    assert(owner && (owner->cross[a][owner_row] >> ox & 1));
                    unsigned owned_row = owner->cross[a][owner_row];
                    table->at[a][r][x] = row_first(owner, owner_row, a) + bit_count[owned_row & ((1u << ox) - 1)];
                }
        }
}

static void emit_triangles(lod_job *job, const work_brick *wb, const id_table *table)
{
    const iso_mc_case *cases = iso_mc_cases();
    const uint32_t *ids = &table->at[0][0][0];
    uint32_t *out = job->mesh->indices + 3 * wb->first_triangle;
    for (int word = 0; word < 2; word++)
        for (uint64_t rows = wb->marching_rows[word]; rows; rows &= rows - 1) {
            int r = 64 * word + __builtin_ctzll(rows);
            uint64_t row = row_cases(cell_row_at(wb->inside, r % S, r / S));
            for (unsigned m = wb->marching[r]; m; m &= m - 1) {
                int x = __builtin_ctz(m);
                const iso_mc_case *mc = &cases[(unsigned)(row >> (8 * x)) & 0xFF];
                const uint32_t *cell = ids + r * S + x;
                for (int k = 0; k < 3 * mc->triangle_count; k++)
                    *out++ = cell[edge_offset[0][mc->edges[k]]];
            }
        }
    /* A brick without coarse cells may have a thread with no records at all (NULL). */
    const cell_record *cell = wb->cell_count ? job->records[wb->records_thread].at + wb->records_first : NULL;
    for (int i = 0; i < wb->cell_count; i++, cell++) {
        int l = cell->l;
        /* The cell's own lattice row at its level, and at the level below (its halves). */
        const uint32_t *whole = ids + (level_base[l] + (cell->c[2] >> l) * level_width[l] + (cell->c[1] >> l)) * S + cell->c[0];
        if (!cell->tc) {
            const iso_mc_case *mc = &cases[cell->mc];
            const int32_t *offset = edge_offset[l];
            for (int k = 0; k < 3 * mc->triangle_count; k++)
                *out++ = whole[offset[mc->edges[k]]];
            continue;
        }
        const uint32_t *half = ids + (level_base[l - 1] + (cell->c[2] >> (l - 1)) * level_width[l - 1] + (cell->c[1] >> (l - 1))) * S + cell->c[0];
        const int32_t *offset = slot_offset[l];
        for (int k = 0; k < 3 * cell->tc->triangle_count; k++) {
            int slot = cell->tc->slot[k];
            *out++ = (slot_full[slot] ? whole : half)[offset[slot]];
        }
    }
    assert(out == job->mesh->indices + 3 * (wb->first_triangle + wb->triangles));
}

static void generate_share(void *context, int t, int threads)
{
    lod_job *job = context;
    double worst = 0;
    id_table *table = malloc(sizeof *table);
    range r;
    (void)threads;
    if (!table) {
        job->error[t] = NAN; /* reported as out of memory by the caller */
        return;
    }
    while (next_chunk(job, &r))
        for (size_t i = r.begin; i < r.end; i++) {
            const work_brick *wb = &job->work[i];
            if (wb->vertices) {
                double e = place_vertices(job, wb, table);
                worst = e > worst ? e : worst;
            }
            if (wb->triangles) {
                fill_shared_ids(job, wb, table);
                emit_triangles(job, wb, table);
            }
        }
    free(table);
    job->error[t] = worst;
}

/* ---- the passes in order ---- */

static float float_at_or_below(double level)
{
    float f = (float)level;
    return (double)f > level ? nextafterf(f, -INFINITY) : f;
}

/* PASS 1. */
static int select_bricks(lod_job *job)
{
    const iso_bricks *g = job->bricks;
    size_t total = iso_bricks_total(g), n = 0;
    float level = float_at_or_below(job->level);
    job->slot = malloc(total * sizeof *job->slot);
    if (!job->slot)
        return ISO_E_NOMEM;
    for (size_t at = 0; at < total; at++) {
        int on = job->params->visit_all || ((g->min[at] <= level) & (g->max[at] > level));
        job->slot[at] = on ? (int32_t)n : -1;
        n += (size_t)on;
    }
    job->work = malloc((n ? n : 1) * sizeof *job->work);
    if (!job->work)
        return ISO_E_NOMEM;
    job->work_count = n;
    for (size_t at = 0; at < total; at++) {
        if (job->slot[at] < 0)
            continue;
        work_brick *wb = &job->work[job->slot[at]];
        wb->brick[0] = (uint32_t)(at % g->count[0]);
        wb->brick[1] = (uint32_t)(at / g->count[0] % g->count[1]);
        wb->brick[2] = (uint32_t)(at / g->count[0] / g->count[1]);
        size_t lo[3], hi[3];
        iso_bricks_box(job->vol, wb->brick, lo, hi);
        for (int d = 0; d < 3; d++) {
            wb->n[d] = (uint8_t)(hi[d] - lo[d] + 1);
            wb->owned[d] = (uint8_t)(wb->brick[d] + 1 == g->count[d] ? wb->n[d] : wb->n[d] - 1);
        }
    }
    return 0;
}

static int lay_out_mesh(lod_job *job)
{
    size_t vertices = 0, triangles = 0;
    for (size_t i = 0; i < job->work_count; i++) {
        job->work[i].first_vertex = vertices;
        job->work[i].first_triangle = triangles;
        vertices += job->work[i].vertices;
        triangles += job->work[i].triangles;
    }
    if (vertices > UINT32_MAX)
        return ISO_E_LIMIT;
    iso_mesh_clear(job->mesh);
    if (iso_mesh_reserve(job->mesh, vertices, triangles))
        return ISO_E_NOMEM;
    job->mesh->vertex_count = vertices;
    job->mesh->triangle_count = triangles;
    return 0;
}

static void sum_stats(const lod_job *job, iso_lod_march_stats *stats)
{
    for (int t = 0; t < MAX_THREADS; t++) {
        stats->error_bound = job->error[t] > stats->error_bound ? job->error[t] : stats->error_bound;
        stats->cells += job->cells[t];
        stats->transition_cells += job->transitions[t];
    }
    stats->bricks = job->work_count;
    for (size_t i = 0; i < job->work_count; i++) {
        const work_brick *wb = &job->work[i];
        for (int k = 0; k < 8; k++) {
            int s = wb->near[1 + (k >> 2)][1 + (k >> 1 & 1)][1 + (k & 1)];
            if (s != NO_BLOCK) {
                stats->blocks++;
                stats->coarse_blocks += s != 0;
            }
        }
        stats->coarse_bricks += wb->coarse;
    }
}

static int run_passes(lod_job *job, iso_lod_march_stats *stats)
{
    int threads = iso_parallel_threads(job->params->threads);
    int rc = select_bricks(job);
    if (rc)
        return rc;
    size_t total_bricks = iso_bricks_total(job->bricks);
    job->brick_lo = malloc(total_bricks ? total_bricks : 1);
    job->brick_hi = malloc(total_bricks ? total_bricks : 1);
    if (!job->brick_lo || !job->brick_hi)
        return ISO_E_NOMEM;
    memset(job->brick_lo, ISO_TREE_LEVELS, total_bricks);
    memset(job->brick_hi, ISO_TREE_LEVELS, total_bricks);
    iso_lod_brick_ranges(job);
    rc = iso_lod_balance(job, NULL, 0, &stats->refined);
    while (!rc) {
        iso_lod_brick_ranges(job);
        job->infeasible_count = 0;
        memset(job->transitions, 0, sizeof job->transitions);
        memset(job->cells, 0, sizeof job->cells);
        run_bricks(job, threads, count_share);
        if (job->failed)
            return ISO_E_NOMEM;
        if (!job->infeasible_count)
            break;
        rc = iso_lod_balance(job, job->infeasible, job->infeasible_count, &stats->refined);
    }
    if (rc)
        return rc;
    run_bricks(job, threads, number_share);
    rc = lay_out_mesh(job);
    if (rc)
        return rc;
    run_bricks(job, threads, generate_share);
    for (int t = 0; t < MAX_THREADS; t++)
        if (job->error[t] != job->error[t])
            return ISO_E_NOMEM;
    sum_stats(job, stats);
    return 0;
}

int iso_lod_march(const iso_lod_march_params *params, iso_mesh *mesh, iso_lod_march_stats *stats, iso_error *err)
{
    pthread_once(&tables_once, make_tables);
    memset(stats, 0, sizeof *stats);
    lod_job *job = calloc(1, sizeof *job);
    if (!job) {
        iso_mesh_free(mesh);
        return iso_error_set(err, ISO_E_NOMEM, "out of memory extracting the surface");
    }
    job->params = params;
    job->vol = params->tree->vol;
    job->bricks = &params->tree->bricks;
    job->level = params->level;
    iso_march_threshold_make(job->vol, job->level, &job->threshold);
    job->shift = params->shift;
    job->mesh = mesh;
    pthread_mutex_init(&job->lock, NULL);
    for (int d = 0; d < 3; d++)
        job->blocks[d] = (uint32_t)((job->vol->dims[d] - 1 + HALF - 1) / HALF);
    int rc = run_passes(job, stats);
    pthread_mutex_destroy(&job->lock);
    for (int t = 0; t < MAX_THREADS; t++)
        free(job->records[t].at);
    free(job->infeasible);
    free(job->brick_lo);
    free(job->brick_hi);
    free(job->slot);
    free(job->work);
    free(job);
    if (rc) {
        iso_mesh_free(mesh);
        if (rc == ISO_E_LIMIT)
            return iso_error_set(err, rc, "the surface needs more than 2^32 - 1 vertices");
        return iso_error_set(err, ISO_E_NOMEM, "out of memory extracting the surface");
    }
    return 0;
}
