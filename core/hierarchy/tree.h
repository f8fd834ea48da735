/* tree.h: the hierarchy stage: per volume, min/max over a regular grid of bricks and an
 * a-priori kd-tree of trilinear fits above them, built once, stored in a file, mapped back.
 *
 * Ownership: iso_tree_build and iso_tree_load give the caller a tree (iso_tree_free) that
 * refers to, but does not own, its volume; the volume must outlive it. Errors: ISO_E_NOMEM,
 * ISO_E_IO, and for files ISO_E_FORMAT / ISO_E_STALE / ISO_E_CORRUPT with the offset.
 * Thread-safety: a built or loaded tree is read-only and shared by any number of
 * extractions. Cost: the build is a few passes over the samples (the bricks' own fits,
 * their min/max grid, their coarse levels, and the bricks that the fits above them cannot
 * rule out); memory 12 bytes per node (about 2 per brick), 8 per brick for its min/max and
 * 17 for its level codes: under 10% of a byte volume's samples, 5% of a 16-bit one's. */
#ifndef ISO_TREE_H
#define ISO_TREE_H

#include <stddef.h>
#include <stdint.h>

#include "base/base.h"
#include "labels.h"
#include "volume/volume.h"

/* Min and max of the samples over a regular grid of bricks, the flat bottom
 * level of the hierarchy that exact extraction prunes with (march.h).
 *
 * Brick (i, j, k) holds the cells whose lower corner is in [8i, 8i+8) x [8j, 8j+8) x
 * [8k, 8k+8), clipped to the volume, and so the samples [8i, min(8i+8, n-1)] per axis:
 * neighbouring bricks share their face samples. A level can cross a cell of a brick only if
 * min <= level < max (a sample is inside when above the level). Floats are rounded outward
 * and a NaN sample (below every level) makes min -inf, so pruning never drops a crossing.
 * Memory: 8 bytes per brick, 1/64 byte per voxel. */

#define ISO_BRICK_CELLS 8
#define ISO_BRICK_SAMPLES (ISO_BRICK_CELLS + 1)

typedef struct iso_bricks {
    uint32_t count[3];  /* bricks per axis: ceil((dims - 1) / 8) */
    float *min, *max;   /* count[0] * count[1] * count[2], x fastest */
} iso_bricks;

/* Scans vol on `threads` threads (0 = all cores). O(N). On failure *bricks is empty. */
int iso_bricks_build(const iso_volume *vol, int threads, iso_bricks *bricks, iso_error *err);
/* The grid's arrays for vol, bounds not set: for a builder that knows them otherwise (the
 * hierarchy's leaves). ISO_E_ARGUMENT or ISO_E_NOMEM; on failure *bricks is empty. */
int iso_bricks_alloc(const iso_volume *vol, iso_bricks *bricks, iso_error *err);
/* Frees the arrays; NULL and an empty grid are allowed. */
void iso_bricks_free(iso_bricks *bricks);

static inline size_t iso_bricks_total(const iso_bricks *b)
{
    return (size_t)b->count[0] * b->count[1] * b->count[2];
}

/* Bricks per axis of vol's grid, ceil((dims - 1) / 8); 0 on an axis of fewer than 2 samples. */
void iso_bricks_count(const iso_volume *vol, uint32_t count[3]);

/* 1 if brick `at` (grid index, x fastest) is on the grid's border along some axis. */
int iso_bricks_on_border(const iso_bricks *bricks, size_t at);

/* The inclusive sample box of brick (i, j, k): lo = 8 * index, hi clipped to dims - 1. */
void iso_bricks_box(const iso_volume *vol, const uint32_t brick[3], size_t lo[3], size_t hi[3]);

/* tree.h: the a-priori hierarchy of trilinear fits (Elber and Malzbender, Algorithm 2 with
 * Algorithm 1's min/max bounds; docs/algorithm.md).
 *
 * An implicit binary kd-tree over the volume's samples. A node is an inclusive box of
 * samples lo..hi; the root is the whole volume. A node splits its longest side in cells
 * (ties: x before y before z) at mid = lo + cells/2, and both children keep the sample
 * plane at mid. Above brick size mid is rounded to the nearest multiple of ISO_TREE_BRICK
 * (at least one brick), so the stored leaves are exactly the regular grid's bricks
 * (above). Boxes are never stored: they follow from the root and the path.
 *
 * Stored nodes go down to bricks: a node whose every side is at most ISO_TREE_BRICK cells
 * is a stored leaf. Below a brick, extraction continues the same split rule on the fly,
 * scanning the brick's samples (at most (ISO_TREE_BRICK+1)^3), so the tree costs
 * ~2/500 nodes per voxel, 12 bytes each, instead of two per voxel.
 *
 * Each stored node keeps min and max of its samples and its fit error
 *     err = max over samples s in the box of |p(s) - T(s)|,
 * T the trilinear through the box's 8 corner samples. By Lemma 1 (all cells of the box are
 * trilinear and so is T restricted to any cell, so their difference peaks at samples)
 * err bounds |f - T| over the whole box, f the data's own trilinear interpolant.
 * Floats are rounded outward (min down, max and err up), so pruning stays conservative. */

#define ISO_TREE_BRICK ISO_BRICK_CELLS /* the stored leaves are the grid's bricks */

/* The coarse levels. Level l (1..ISO_TREE_LEVELS) of a box of samples is its sample grid
 * taken every 2^l samples per axis; its error is Lemma 1 over each cell of that grid,
 *     err_l = max over samples s of the box |p(s) - T_l(s)|,
 * T_l the trilinear through the corners of the level's cell holding s: it bounds |f - T_l|
 * over the whole box, so a surface marched on the level's grid has every vertex on a grid
 * edge within err_l of the level (extract.h). Levels 1 and 2 (strides 2 and 4) are kept per
 * block, the brick's 2 x 2 x 2 sub-boxes of ISO_TREE_BLOCK cells per axis; level 3 (stride
 * 8) per brick: extraction then coarsens a block where its own cells fit, not only where
 * the whole brick's do. In a box clipped by the volume's border the level's last cell per
 * axis ends at the last sample, narrower (the same grid extraction marches). Computed in
 * the build and saved with the nodes, so extraction chooses each block's level a-priori,
 * reading no fine sample of a block it coarsens.
 *
 * Each error is kept as a one-byte code, rounded up (an error is never understated): code
 * k > 0 stands for R 2^((k - 238) / 16), R the root's max - min, so codes step by 4.4% from
 * 3.5e-5 R to 2 R; 0 is an exact 0 (constant boxes, and no level crosses those), 255 is
 * INFINITY (a NaN sample, or a volume with infinite samples). 17 bytes per brick. */
#define ISO_TREE_LEVELS 3
#define ISO_TREE_BLOCK 4
#define ISO_TREE_BLOCK_LEVELS 2 /* levels 1 .. 2 per block; level 3 per brick */
#define ISO_TREE_CODES (1 + 8 * ISO_TREE_BLOCK_LEVELS) /* per brick: level 3, then per block */

/* The values the 256 codes stand for, from the root's range (above). */
typedef struct iso_tree_scale {
    double value[256];
} iso_tree_scale;

/* The scale of a tree whose root spans range = max - min (rounded outward as stored). */
void iso_tree_scale_make(double range, iso_tree_scale *scale);
/* The smallest code whose value is >= e (255 for NaN or past 2 R). */
uint8_t iso_tree_code(const iso_tree_scale *scale, double e);

typedef struct iso_box {
    uint32_t lo[3], hi[3]; /* inclusive sample indices; hi[a] - lo[a] cells along a */
} iso_box;

/* A node, in breadth-first order of the split rule from the root (children appended
 * together, so the order follows from the dims alone and no child index is kept). */
typedef struct iso_tree_node {
    float min, max, err;
} iso_tree_node;

typedef struct iso_tree {
    const iso_volume *vol;  /* not owned; must outlive the tree */
    iso_tree_node *nodes;   /* node 0 is the root; breadth-first order */
    size_t node_count;
    uint32_t volume_crc;    /* CRC-32 of dims, type and samples: ties a file to its volume */
    double build_ms;        /* time to build (or to load and verify the file) */
    iso_bricks bricks;      /* regular min/max grid for exact extraction; computed, not saved */
    uint8_t *level_code;    /* per brick, ISO_TREE_CODES codes (iso_tree_level_error); saved */
    iso_tree_scale scale;   /* what the codes stand for */
    iso_label_sets *labels; /* per brick the labels held, for a label volume
                                    * (vol->labels; hierarchy/labels.h), else NULL; saved */
    void *mapping;          /* file mapping when loaded with iso_tree_load, else NULL */
    size_t mapping_bytes;
} iso_tree;

/* Called during long builds with the fraction done, 0..1. */
typedef void (*iso_progress_fn)(void *context, double fraction);

/* Builds the hierarchy of vol on `threads` threads (0 = all cores). O(N log(N / brick^3))
 * time at worst (every depth scanning all its samples: noise), a few passes over N on real
 * scans, where bounds rule out most bricks; O(N / brick^3) memory. progress may be NULL. */
int iso_tree_build(const iso_volume *vol, int threads, iso_progress_fn progress, void *context,
                   iso_tree **out, iso_error *err);
/* Frees the tree (or unmaps its file). NULL is allowed. */
void iso_tree_destroy(iso_tree *tree);
/* Bytes the tree's nodes occupy (what its file holds after the header, before the bricks'
 * level errors). */
size_t iso_tree_bytes(const iso_tree *tree);
/* Bytes the tree occupies in memory: its nodes, its brick grid and the bricks' level errors. */
size_t iso_tree_memory(const iso_tree *tree);

/* CRC-32 identifying the volume's dims, type and samples (the hierarchy file's key). O(N). */
uint32_t iso_tree_volume_crc(const iso_volume *vol);

/* Writes the tree to path atomically (temporary file in the same directory, fsync,
 * rename): a reader never sees a partial file. */
int iso_tree_save(const iso_tree *tree, const char *path, iso_error *err);
/* Maps a hierarchy file written by iso_tree_save for vol. Checks magic, version, sizes,
 * the node checksum, node structure, and that it was built from this volume (dims, type,
 * sample CRC): ISO_E_FORMAT/ISO_E_CORRUPT/ISO_E_STALE otherwise. Safe on untrusted files. */
int iso_tree_load(const iso_volume *vol, const char *path, iso_tree **out, iso_error *err);

/* Fit error of brick `brick` (index in the grid, x fastest) at level 3. */
static inline double iso_tree_level_error(const iso_tree *tree, size_t brick)
{
    return tree->scale.value[tree->level_code[brick * ISO_TREE_CODES]];
}

/* Fit error of block `block` (0..7: x | y << 1 | z << 2 within the brick) of brick `brick`
 * at level l, 1..ISO_TREE_BLOCK_LEVELS. A brick with fewer than 8 blocks (clipped to one
 * block along an axis) has 0 for those it lacks. */
static inline double iso_tree_block_error(const iso_tree *tree, size_t brick, int block, int l)
{
    return tree->scale.value[tree->level_code[brick * ISO_TREE_CODES + 1 + (size_t)block * ISO_TREE_BLOCK_LEVELS +
                                              (size_t)(l - 1)]];
}

/* The root box of vol. */
iso_box iso_box_root(const iso_volume *vol);
/* Cells in the box. */
static inline uint64_t iso_box_cells(const iso_box *b)
{
    return (uint64_t)(b->hi[0] - b->lo[0]) * (b->hi[1] - b->lo[1]) * (b->hi[2] - b->lo[2]);
}
/* Splits box by the tree's rule into left (lower half) and right. Returns the split axis,
 * or -1 for a single cell (which does not split). */
int iso_box_split(const iso_box *box, iso_box *left, iso_box *right);
/* 1 if the box is a stored leaf (every side <= ISO_TREE_BRICK cells). */
int iso_box_is_brick(const iso_box *box);

/* Min, max and Lemma 1 fit error of the box's samples, computed by scanning them. O(box). */
void iso_tree_scan_box(const iso_volume *vol, const iso_box *box, double *min, double *max,
                       double *err);

/* A box's fit error (Lemma 1) over a block of samples already read as doubles, with
 * an early exit: what the build computes for each brick's coarse levels.
 *
 * The block is a brick's samples, x fastest: n[a] samples per axis from lo[a]. A box inside
 * it spans at most ISO_BRICK_CELLS cells per axis. */

typedef struct iso_fit_block {
    const double *samples; /* n[0] * n[1] * n[2], x fastest */
    uint32_t lo[3];        /* the block's first sample per axis */
    uint32_t n[3];         /* its samples per axis, at most ISO_BRICK_SAMPLES */
    int integer_samples;   /* no NaN or infinity can occur: a branch-free maximum */
} iso_fit_block;

/* The block's sample at (x, y, z), a point inside it. */
static inline const double *iso_fit_sample(const iso_fit_block *b, uint32_t x, uint32_t y, uint32_t z)
{
    return b->samples + ((size_t)(z - b->lo[2]) * b->n[1] + (y - b->lo[1])) * b->n[0] + (x - b->lo[0]);
}

/* max |p(s) - T(s)| over the samples s of box, T the trilinear through its 8 corners; or
 * any value above limit as soon as one row shows the error passes it (INFINITY if a sample
 * is NaN). The middle sample is tried first: where the data strays from its corners'
 * trilinear most often, so most boxes that will not fit are refused after one sample. */
double iso_fit_error_past(const iso_fit_block *block, const iso_box *box, double limit);

#endif
