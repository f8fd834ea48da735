/* labels.h (part of the hierarchy's public header tree.h): per brick, which labels a label
 * volume's samples hold: the min/max grid's
 * counterpart for segmentations, built in the hierarchy's pass over the bricks and kept
 * in its file (tree.h).
 *
 * A label volume is an integer volume whose values name segments (vol->labels). Segment
 * k's surface is the 0.5 iso-surface of its indicator (sample == k), and a cell is crossed
 * exactly when its 8 corners hold k and some other value. A cell's corners are samples of
 * its brick (neighbouring bricks share their face samples, as in tree.h), so a brick needs
 * marching for k exactly when its samples hold k and another value, whatever its
 * neighbours hold: the label sets prune as the min/max grid does, with no false positive.
 *
 * Layout: the volume's distinct values, ascending, numbered 0..label_count-1 (at most
 * ISO_LABEL_MAX); per brick, at words[offset[b]], a header word (the number of labels n,
 * and ISO_LABEL_BITMAP when a bitmap follows) then either the n label numbers ascending
 * (a short list: most bricks hold one or two labels) or a bitmap of label_count bits in
 * 16-bit words, bit i of word i / 16 for label i (a dense brick, when the bitmap is the
 * shorter). Derived at build and load, not saved: per label the bricks holding it, for
 * extraction to visit a segment's bricks without a pass over the grid.
 *
 * Ownership: the sets belong to their tree (iso_tree_destroy frees them). Errors:
 * ISO_E_UNSUPPORTED (more than ISO_LABEL_MAX distinct values, or a float volume),
 * ISO_E_NOMEM, and ISO_E_CORRUPT for a file's inconsistent section. Thread-safety: read-only
 * once built. Cost: a pass over each brick's samples (uniform bricks stop at a compare
 * per sample), a sort of the distinct values; memory 4 bytes per brick for the offset and
 * 4 for a uniform brick's words. */
#ifndef ISO_LABELS_H
#define ISO_LABELS_H

#include <stddef.h>
#include <stdint.h>

#include "base/base.h"

#define ISO_LABEL_MAX 65535u          /* distinct values of a label volume */
#define ISO_LABEL_BITMAP 0x8000u      /* header flag: a bitmap follows */
#define ISO_LABEL_MIXED 0x80000000u   /* in `holding`: the brick holds another label too */

typedef struct iso_label_sets {
    uint32_t label_count;   /* distinct values */
    int64_t *values;        /* label_count, ascending */
    size_t brick_count;
    uint32_t *offset;       /* brick_count + 1, into words */
    uint16_t *words;        /* word_count */
    size_t word_count;
    /* Derived: label i's bricks are holding[holding_start[i] .. holding_start[i + 1]), grid
     * indices ascending, each or'ed with ISO_LABEL_MIXED when the brick holds another
     * label (those are the bricks its surface crosses). */
    uint32_t *holding_start;
    uint32_t *holding;
} iso_label_sets;

/* Collects the sets during a pass over the bricks: iso_label_collect may be called from
 * several threads at once, for different bricks. */
typedef struct iso_label_builder iso_label_builder;

/* For a grid of brick_count bricks (fewer than 2^31). NULL when out of memory. */
iso_label_builder *iso_label_builder_create(size_t brick_count);
/* Brick b's n samples (integers as doubles, any order). Thread-safe across bricks. */
void iso_label_collect(iso_label_builder *builder, size_t b, const double *samples, size_t n);
/* Numbers the labels, lays out the sets and derives the per-label lists into *out; frees
 * the builder whatever happens. Returns 0, ISO_E_UNSUPPORTED or ISO_E_NOMEM. */
int iso_label_builder_finish(iso_label_builder *builder, iso_label_sets *out, iso_error *err);

/* The label number of value v, or -1 if no sample holds it. O(log label_count). */
long iso_label_index(const iso_label_sets *sets, int64_t value);
/* 1 if brick b holds label number i. O(list) or O(1) for a bitmap. */
int iso_label_brick_has(const iso_label_sets *sets, size_t b, uint32_t i);
/* The number of labels brick b holds. */
uint32_t iso_label_brick_count(const iso_label_sets *sets, size_t b);

/* The section of a hierarchy file: its bytes, and writing it to out (which holds them).
 * iso_label_read checks and copies a section read from a file of `bytes` bytes for a grid
 * of brick_count bricks, deriving the lists: 0, ISO_E_CORRUPT (what and where in err) or
 * ISO_E_NOMEM. Safe on untrusted bytes. */
size_t iso_label_section_bytes(const iso_label_sets *sets);
void iso_label_section_write(const iso_label_sets *sets, unsigned char *out);
int iso_label_read(const unsigned char *section, size_t bytes, size_t brick_count, const char *path,
                   iso_label_sets *out, iso_error *err);

/* Bytes in memory, derived lists included. */
size_t iso_label_memory(const iso_label_sets *sets);
/* Frees the arrays; NULL and an empty set are allowed. */
void iso_label_free(iso_label_sets *sets);

#endif
