/* lod_job.h: what the coarse kernel's passes share (lod_march.c, lod_balance.c): a brick's
 * lattice layout, the per-brick work and the job. Private to core/extract.
 *
 * Layout: a brick has at most 9 x 9 x 9 samples; bit x of row z * 9 + y is sample (x, y,
 * z), brick-local. Its blocks around: near[z][y][x], index 0 the block before its first
 * along the axis, 1 and 2 its own, 3 the next brick's first. */
#ifndef ISO_LOD_JOB_H
#define ISO_LOD_JOB_H

#include <pthread.h>
#include <stdatomic.h>
#include <stddef.h>
#include <stdint.h>

#include "lod_march.h"
#include "march.h"
#include "transition.h"

#define S ISO_BRICK_SAMPLES
#define ROWS (S * S)
#define LEVELS (ISO_TREE_LEVELS + 1)
#define HALF ISO_TREE_BLOCK  /* a block's side in cells */
#define NEAR 4
#define NO_BLOCK 7           /* the stride of a block past the grid: above every real one */
#define MAX_THREADS ISO_PARALLEL_MAX_THREADS

/* A brick's lattice rows of every level, one after the other: level l's rows are those
 * whose y and z are multiples of 2^l, (9 >> l... 9, 5, 3, 2 per axis), 119 in all. Edges of
 * level l lie in its rows. */
#define LEVEL_ROWS 119
static const uint8_t level_base[LEVELS] = {0, 81, 106, 115}, level_width[LEVELS] = {9, 5, 3, 2};

static inline int level_row(int l, int y, int z)
{
    return level_base[l] + (z >> l) * level_width[l] + (y >> l);
}

/* The level, y and z of lattice row r. */
static inline void row_of(int r, int *l, int *y, int *z)
{
    int k = r < 81 ? 0 : r < 106 ? 1 : r < 115 ? 2 : 3, i = r - level_base[k];
    *l = k;
    *y = i % level_width[k] << k;
    *z = i / level_width[k] << k;
}

/* A coarse cell with triangles: its corner (brick-local), stride level, and its case:
 * marching cubes' (tc NULL) or a transition cell's. */
typedef struct cell_record {
    uint8_t c[3], l, mc;
    const iso_transition_case *tc;
} cell_record;

typedef struct work_brick {
    uint32_t brick[3];
    uint8_t n[3];            /* samples per axis, 2..9 */
    uint8_t owned[3];        /* samples 0..owned-1 per axis are this brick's */
    uint8_t finest;          /* log2 of the finest stride around: rows classified every 2^finest */
    uint8_t records_thread;  /* its coarse cells with triangles: that thread's records */
    uint16_t cell_count;     /* from records_first on */
    uint32_t records_first;
    uint8_t coarse;          /* 1 if the level crosses a coarse unit of its own */
    uint8_t uniform;         /* every block around it has one stride */
    uint32_t vertices, triangles;
    size_t first_vertex, first_triangle;
    uint8_t near[NEAR][NEAR][NEAR];
    uint16_t inside[ROWS];
    uint16_t cross[3][LEVEL_ROWS];      /* owned crossings used, per axis and lattice row */
    uint16_t foreign[3][LEVEL_ROWS];    /* crossings used on its upper faces, owned by neighbours */
    uint64_t marked_rows[2], foreign_rows[2]; /* lattice rows with some */
    uint16_t row_base[LEVEL_ROWS];      /* owned crossings numbered before lattice row r */
    uint8_t marching[ROWS];             /* bit x: stride-1 cell (x, y, z) to march */
    uint64_t crossing_rows[2], marching_rows[2];
} work_brick;

/* One thread's coarse cell records, for the bricks it counted. */
typedef struct cell_records {
    cell_record *at;
    size_t count, capacity;
} cell_records;

typedef struct lod_job {
    const iso_lod_march_params *params;
    const iso_volume *vol;
    const iso_bricks *bricks;
    double level;
    iso_march_threshold threshold;
    uint8_t *shift;
    uint32_t blocks[3];
    work_brick *work;
    size_t work_count;
    int32_t *slot;            /* per brick of the grid: its index in work, or -1 */
    uint8_t *brick_lo, *brick_hi; /* per brick of the grid: its blocks' finest and coarsest strides */
    iso_mesh *mesh;
    double error[MAX_THREADS];
    size_t cells[MAX_THREADS], transitions[MAX_THREADS];
    cell_records records[MAX_THREADS];
    atomic_size_t next;
    /* Blocks (with their stride then) a cell of had no kept triangulation; under the lock. */
    pthread_mutex_t lock;
    size_t *infeasible;
    size_t infeasible_count, infeasible_capacity;
    int failed;               /* ISO_E_NOMEM recording one */
} lod_job;

static inline size_t block_index(const lod_job *job, uint32_t x, uint32_t y, uint32_t z)
{
    return ((size_t)z * job->blocks[1] + y) * job->blocks[0] + x;
}

/* PASS 2 (lod_balance.c). The finest and coarsest stride of every selected brick's blocks,
 * into brick_lo and brick_hi. */
void iso_lod_brick_ranges(lod_job *job);

/* The finest stride of the blocks of brick b and its 26 neighbours (from brick_lo), and
 * into *hi_around (unless NULL) the coarsest. */
unsigned iso_lod_bricks_around(const lod_job *job, const uint32_t b[3], unsigned *hi_around);

/* Refines the plan (job->shift) until no two blocks more than one stride apart share a
 * face or edge the level crosses; given `start` (blocks * LEVELS + their stride then, of
 * cells without a triangulation), refines those one stride first. Adds the blocks changed
 * to *refined. Returns 0 or ISO_E_NOMEM. */
int iso_lod_balance(lod_job *job, const size_t *start, size_t start_count, size_t *refined);

#endif
