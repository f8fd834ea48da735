/* labels.c: the per-brick label sets of a label volume (labels.h).
 *
 * PASS 1 (collect, in the hierarchy's pass over the bricks, threads): each brick's
 *   distinct values; a uniform brick is found by one compare per sample, a brick of a
 *   few values by a linear search of those found, a dense one by a sort.
 * PASS 2 (number): every brick's values gathered, sorted, made unique: the labels.
 * PASS 3 (lay out): per brick its header and its list of label numbers, or a bitmap where
 *   that is shorter.
 * PASS 4 (derive): per label the bricks holding it, counted then filled in grid order. */
#include "labels.h"

#include <assert.h>
#include <stdlib.h>
#include <string.h>

#define INLINE_VALUES 6

typedef struct brick_values {
    uint16_t count;
    int64_t small[INLINE_VALUES];
    int64_t *more;          /* count > INLINE_VALUES: all of them, malloc'd */
} brick_values;

struct iso_label_builder {
    size_t brick_count;
    brick_values *bricks;
    int failed;             /* an allocation in a brick failed */
};

iso_label_builder *iso_label_builder_create(size_t brick_count)
{
    assert(brick_count < ISO_LABEL_MIXED);
    iso_label_builder *b = calloc(1, sizeof *b);
    if (!b)
        return NULL;
    b->brick_count = brick_count;
    b->bricks = calloc(brick_count ? brick_count : 1, sizeof *b->bricks);
    if (!b->bricks) {
        free(b);
        return NULL;
    }
    return b;
}

static int compare_i64(const void *a, const void *b)
{
    int64_t x = *(const int64_t *)a, y = *(const int64_t *)b;
    return (x > y) - (x < y);
}

/* Sorts n values in place and returns how many distinct ones lead it. */
static size_t sort_unique(int64_t *v, size_t n)
{
    if (n == 0)
        return 0;
    qsort(v, n, sizeof *v, compare_i64);
    size_t u = 1;
    for (size_t i = 1; i < n; i++)
        if (v[i] != v[u - 1])
            v[u++] = v[i];
    return u;
}

void iso_label_collect(iso_label_builder *builder, size_t b, const double *samples, size_t n)
{
    brick_values *bv = &builder->bricks[b];
    assert(b < builder->brick_count && n > 0 && bv->count == 0);
    double first = samples[0];
    size_t i = 1;
    while (i < n && samples[i] == first)
        i++;
    bv->small[0] = (int64_t)first;
    bv->count = 1;
    if (i == n)
        return; /* uniform: most bricks */
    for (; i < n; i++) {
        int64_t v = (int64_t)samples[i];
        int known = 0;
        for (int k = 0; k < bv->count && !known; k++)
            known = bv->small[k] == v;
        if (known)
            continue;
        if (bv->count == INLINE_VALUES)
            break; /* dense: sort them all */
        bv->small[bv->count++] = v;
    }
    if (i == n)
        return;
    int64_t *all = malloc(n * sizeof *all);
    if (!all) {
        builder->failed = 1;
        return;
    }
    for (size_t k = 0; k < n; k++)
        all[k] = (int64_t)samples[k];
    size_t u = sort_unique(all, n);
    int64_t *shrunk = realloc(all, u * sizeof *all);
    bv->more = shrunk ? shrunk : all;
    bv->count = (uint16_t)u;
}

static const int64_t *values_of(const brick_values *bv)
{
    return bv->count > INLINE_VALUES ? bv->more : bv->small;
}

long iso_label_index(const iso_label_sets *sets, int64_t value)
{
    size_t lo = 0, hi = sets->label_count;
    while (lo < hi) {
        size_t mid = lo + (hi - lo) / 2;
        if (sets->values[mid] < value)
            lo = mid + 1;
        else
            hi = mid;
    }
    return lo < sets->label_count && sets->values[lo] == value ? (long)lo : -1;
}

static size_t bitmap_words(uint32_t label_count)
{
    return (label_count + 15) / 16;
}

/* PASS 3's choice for a brick of n labels: its words, header included. */
static size_t brick_words(uint32_t label_count, size_t n, int *bitmap)
{
    *bitmap = bitmap_words(label_count) < n;
    return 1 + (*bitmap ? bitmap_words(label_count) : n);
}

/* PASS 4. */
static int derive_holding(iso_label_sets *s)
{
    s->holding_start = calloc((size_t)s->label_count + 1, sizeof *s->holding_start);
    if (!s->holding_start)
        return ISO_E_NOMEM;
    size_t total = 0;
    for (size_t b = 0; b < s->brick_count; b++) {
        const uint16_t *w = s->words + s->offset[b];
        uint32_t n = w[0] & ~ISO_LABEL_BITMAP;
        total += n;
        if (w[0] & ISO_LABEL_BITMAP) {
            for (uint32_t i = 0; i < s->label_count; i++)
                s->holding_start[i + 1] += w[1 + i / 16] >> (i % 16) & 1;
        } else {
            for (uint32_t k = 0; k < n; k++)
                s->holding_start[w[1 + k] + 1]++;
        }
    }
    for (uint32_t i = 0; i < s->label_count; i++)
        s->holding_start[i + 1] += s->holding_start[i];
    s->holding = malloc((total ? total : 1) * sizeof *s->holding);
    uint32_t *fill = malloc(((size_t)s->label_count + 1) * sizeof *fill);
    if (!s->holding || !fill) {
        free(fill);
        return ISO_E_NOMEM;
    }
    memcpy(fill, s->holding_start, ((size_t)s->label_count + 1) * sizeof *fill);
    for (size_t b = 0; b < s->brick_count; b++) {
        const uint16_t *w = s->words + s->offset[b];
        uint32_t n = w[0] & ~ISO_LABEL_BITMAP, mark = (uint32_t)b | (n > 1 ? ISO_LABEL_MIXED : 0);
        if (w[0] & ISO_LABEL_BITMAP) {
            for (uint32_t i = 0; i < s->label_count; i++)
                if (w[1 + i / 16] >> (i % 16) & 1)
                    s->holding[fill[i]++] = mark;
        } else {
            for (uint32_t k = 0; k < n; k++)
                s->holding[fill[w[1 + k]]++] = mark;
        }
    }
    free(fill);
    return 0;
}

static void free_builder(iso_label_builder *builder)
{
    for (size_t b = 0; b < builder->brick_count; b++)
        if (builder->bricks[b].count > INLINE_VALUES)
            free(builder->bricks[b].more);
    free(builder->bricks);
    free(builder);
}

int iso_label_builder_finish(iso_label_builder *builder, iso_label_sets *out, iso_error *err)
{
    memset(out, 0, sizeof *out);
    iso_label_sets s = {.brick_count = builder->brick_count};
    int rc = 0;
    if (builder->failed) {
        rc = iso_error_set(err, ISO_E_NOMEM, "out of memory collecting the label sets");
        goto done;
    }
    /* PASS 2 */
    size_t total = 0;
    for (size_t b = 0; b < s.brick_count; b++)
        total += builder->bricks[b].count;
    int64_t *all = malloc((total ? total : 1) * sizeof *all);
    if (!all) {
        rc = iso_error_set(err, ISO_E_NOMEM, "out of memory numbering the labels");
        goto done;
    }
    for (size_t b = 0, at = 0; b < s.brick_count; b++) {
        memcpy(all + at, values_of(&builder->bricks[b]), builder->bricks[b].count * sizeof *all);
        at += builder->bricks[b].count;
    }
    size_t labels = sort_unique(all, total);
    if (labels > ISO_LABEL_MAX) {
        free(all);
        rc = iso_error_set(err, ISO_E_UNSUPPORTED,
                           "%zu distinct values: a label volume holds at most %u (is it an image, not labels?)",
                           labels, ISO_LABEL_MAX);
        goto done;
    }
    s.label_count = (uint32_t)labels;
    s.values = realloc(all, (labels ? labels : 1) * sizeof *all);
    if (!s.values)
        s.values = all;
    /* PASS 3 */
    s.offset = malloc((s.brick_count + 1) * sizeof *s.offset);
    if (!s.offset) {
        rc = iso_error_set(err, ISO_E_NOMEM, "out of memory laying out the label sets");
        goto done;
    }
    size_t words = 0;
    for (size_t b = 0; b < s.brick_count; b++) {
        int bitmap;
        s.offset[b] = (uint32_t)words;
        words += brick_words(s.label_count, builder->bricks[b].count, &bitmap);
    }
    s.offset[s.brick_count] = (uint32_t)words;
    s.word_count = words;
    s.words = calloc(words ? words : 1, sizeof *s.words);
    if (!s.words || words > UINT32_MAX) {
        rc = iso_error_set(err, ISO_E_NOMEM, "out of memory laying out the label sets");
        goto done;
    }
    for (size_t b = 0; b < s.brick_count; b++) {
        const brick_values *bv = &builder->bricks[b];
        int64_t sorted[INLINE_VALUES];
        const int64_t *v = values_of(bv);
        if (bv->count <= INLINE_VALUES) { /* the inline ones are in order of appearance */
            memcpy(sorted, v, bv->count * sizeof *sorted);
            sort_unique(sorted, bv->count);
            v = sorted;
        }
        int bitmap;
        brick_words(s.label_count, bv->count, &bitmap);
        uint16_t *w = s.words + s.offset[b];
        w[0] = (uint16_t)(bv->count | (bitmap ? ISO_LABEL_BITMAP : 0));
        for (uint16_t k = 0; k < bv->count; k++) {
            uint32_t i = (uint32_t)iso_label_index(&s, v[k]);
            if (bitmap)
                w[1 + i / 16] |= (uint16_t)(1u << (i % 16));
            else
                w[1 + k] = (uint16_t)i;
        }
    }
    /* PASS 4 */
    if (derive_holding(&s))
        rc = iso_error_set(err, ISO_E_NOMEM, "out of memory listing each label's bricks");
done:
    free_builder(builder);
    if (rc)
        iso_label_free(&s);
    else
        *out = s;
    return rc;
}

int iso_label_brick_has(const iso_label_sets *sets, size_t b, uint32_t i)
{
    const uint16_t *w = sets->words + sets->offset[b];
    if (w[0] & ISO_LABEL_BITMAP)
        return i < sets->label_count && (w[1 + i / 16] >> (i % 16) & 1);
    for (uint32_t k = 0; k < (w[0] & ~ISO_LABEL_BITMAP); k++)
        if (w[1 + k] == i)
            return 1;
    return 0;
}

uint32_t iso_label_brick_count(const iso_label_sets *sets, size_t b)
{
    return sets->words[sets->offset[b]] & ~ISO_LABEL_BITMAP;
}

/* ---- the file's section: a 24-byte head (magic, label count, brick count, word count),
 * the values, the offsets, the words, zero-padded to 8 bytes ---- */

#define SECTION_MAGIC 0x534c424cu /* "LBLS" */
#define SECTION_HEAD 24

static size_t section_bytes(uint32_t labels, size_t bricks, size_t words)
{
    size_t n = SECTION_HEAD + (size_t)labels * 8 + (bricks + 1) * 4 + words * 2;
    return (n + 7) & ~(size_t)7;
}

size_t iso_label_section_bytes(const iso_label_sets *sets)
{
    return section_bytes(sets->label_count, sets->brick_count, sets->word_count);
}

void iso_label_section_write(const iso_label_sets *sets, unsigned char *out)
{
    size_t bytes = iso_label_section_bytes(sets);
    memset(out, 0, bytes);
    uint32_t head32[2] = {SECTION_MAGIC, sets->label_count};
    uint64_t head64[2] = {sets->brick_count, sets->word_count};
    memcpy(out, head32, 8);
    memcpy(out + 8, head64, 16);
    unsigned char *p = out + SECTION_HEAD;
    memcpy(p, sets->values, (size_t)sets->label_count * 8);
    p += (size_t)sets->label_count * 8;
    memcpy(p, sets->offset, (sets->brick_count + 1) * 4);
    p += (sets->brick_count + 1) * 4;
    memcpy(p, sets->words, sets->word_count * 2);
}

/* Brick b's words [from, to) are a header and a list or bitmap consistent with it. */
static int brick_valid(const iso_label_sets *s, uint32_t from, uint32_t to)
{
    if (to <= from)
        return 0;
    const uint16_t *w = s->words + from;
    uint32_t n = w[0] & ~ISO_LABEL_BITMAP, len = to - from;
    if (n == 0)
        return 0;
    if (w[0] & ISO_LABEL_BITMAP) {
        if (len != 1 + bitmap_words(s->label_count))
            return 0;
        uint32_t set = 0;
        for (uint32_t k = 0; k + 1 < len; k++) {
            set += (uint32_t)__builtin_popcount(w[1 + k]);
            if (k == len - 2 && s->label_count % 16 && (w[1 + k] >> (s->label_count % 16)))
                return 0; /* a bit past the last label */
        }
        return set == n;
    }
    if (len != 1 + n)
        return 0;
    for (uint32_t k = 0; k < n; k++)
        if (w[1 + k] >= s->label_count || (k && w[k] >= w[1 + k]))
            return 0;
    return 1;
}

int iso_label_read(const unsigned char *section, size_t bytes, size_t brick_count, const char *path,
                   iso_label_sets *out, iso_error *err)
{
    memset(out, 0, sizeof *out);
    uint32_t head32[2];
    uint64_t head64[2];
    if (bytes < SECTION_HEAD)
        return iso_error_set(err, ISO_E_CORRUPT, "%s: label section of %zu bytes, shorter than its head", path, bytes);
    memcpy(head32, section, 8);
    memcpy(head64, section + 8, 16);
    if (head32[0] != SECTION_MAGIC || head64[0] != brick_count || head32[1] > ISO_LABEL_MAX ||
        head64[1] > UINT32_MAX || section_bytes(head32[1], brick_count, (size_t)head64[1]) != bytes)
        return iso_error_set(err, ISO_E_CORRUPT, "%s: label section's head does not match its %zu bytes and %zu bricks",
                             path, bytes, brick_count);
    iso_label_sets s = {.label_count = head32[1], .brick_count = brick_count, .word_count = (size_t)head64[1]};
    s.values = malloc(((size_t)s.label_count + 1) * 8);
    s.offset = malloc((brick_count + 1) * 4);
    s.words = malloc((s.word_count + 1) * 2);
    if (!s.values || !s.offset || !s.words) {
        iso_label_free(&s);
        return iso_error_set(err, ISO_E_NOMEM, "out of memory reading %s's label sets", path);
    }
    const unsigned char *p = section + SECTION_HEAD;
    memcpy(s.values, p, (size_t)s.label_count * 8);
    p += (size_t)s.label_count * 8;
    memcpy(s.offset, p, (brick_count + 1) * 4);
    p += (brick_count + 1) * 4;
    memcpy(s.words, p, s.word_count * 2);
    int rc = 0;
    for (uint32_t i = 1; i < s.label_count && !rc; i++)
        if (s.values[i - 1] >= s.values[i])
            rc = iso_error_set(err, ISO_E_CORRUPT, "%s: label values not ascending at %u", path, i);
    if (!rc && (s.offset[0] != 0 || s.offset[brick_count] != s.word_count))
        rc = iso_error_set(err, ISO_E_CORRUPT, "%s: label offsets do not span the words", path);
    for (size_t b = 0; b < brick_count && !rc; b++)
        if (s.offset[b + 1] > s.word_count || !brick_valid(&s, s.offset[b], s.offset[b + 1]))
            rc = iso_error_set(err, ISO_E_CORRUPT, "%s: label set of brick %zu is inconsistent", path, b);
    if (!rc && derive_holding(&s))
        rc = iso_error_set(err, ISO_E_NOMEM, "out of memory reading %s's label sets", path);
    if (rc)
        iso_label_free(&s);
    else
        *out = s;
    return rc;
}

size_t iso_label_memory(const iso_label_sets *sets)
{
    if (!sets)
        return 0;
    size_t held = sets->holding_start ? sets->holding_start[sets->label_count] : 0;
    return (size_t)sets->label_count * 8 + (sets->brick_count + 1) * 4 + sets->word_count * 2 +
           ((size_t)sets->label_count + 1) * 4 + held * 4;
}

void iso_label_free(iso_label_sets *sets)
{
    if (!sets)
        return;
    free(sets->values);
    free(sets->offset);
    free(sets->words);
    free(sets->holding_start);
    free(sets->holding);
    memset(sets, 0, sizeof *sets);
}
