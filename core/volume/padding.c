/* padding.c: finding the value a scanner writes outside its field of view (see volume.h).
 *
 * A CT reconstructs a circle; the corners of each slice get a padding value (-2000, -3024,
 * ...) that no tissue has. Such a value fills whole lines through the volume along the
 * slice axis and appears nowhere else, which a value of the anatomy (the 0 around a
 * skull-stripped brain, air at -1024) never does: those lines also cross tissue. One pass
 * records, per line along each axis, whether it met the candidate value and whether it met
 * anything else. */
#include "volume.h"

#include <assert.h>
#include <stdlib.h>
#include <string.h>

/* A candidate must hold this share of the samples (1/200) ... */
#define PADDING_MIN_SHARE 200
/* ... and at most 1/50 of the lines along some axis that meet it may meet anything else. */
#define PADDING_MIXED_SHARE 50

enum { SEEN_VALUE = 1, SEEN_OTHER = 2 };

/* Per axis a, lines[a] holds one state per line along a, indexed by the other two
 * coordinates: i-lines by (j, k), j-lines by (i, k), k-lines by (i, j). */
#define LINE_PASS(T)                                                                    \
    do {                                                                                \
        const T *s = (const T *)vol->data;                                              \
        const T v = (T)value;                                                           \
        for (size_t k = 0, at = 0; k < nz; k++)                                         \
            for (size_t j = 0; j < ny; j++)                                             \
                for (size_t i = 0; i < nx; i++, at++) {                                 \
                    unsigned char bit = s[at] == v ? SEEN_VALUE : SEEN_OTHER;           \
                    count += bit == SEEN_VALUE;                                         \
                    lines[0][k * ny + j] |= bit;                                        \
                    lines[1][k * nx + i] |= bit;                                        \
                    lines[2][j * nx + i] |= bit;                                        \
                }                                                                       \
    } while (0)

/* 1 when `value` fills whole lines along some axis and little else: see the top. */
static int fills_lines(const iso_volume *vol, double value, unsigned char *lines[3], size_t sizes[3])
{
    const size_t nx = vol->dims[0], ny = vol->dims[1], nz = vol->dims[2];
    for (int a = 0; a < 3; a++)
        memset(lines[a], 0, sizes[a]);
    size_t count = 0;
    switch (vol->type) {
    case ISO_U8:  LINE_PASS(uint8_t);  break;
    case ISO_I8:  LINE_PASS(int8_t);   break;
    case ISO_U16: LINE_PASS(uint16_t); break;
    case ISO_I16: LINE_PASS(int16_t);  break;
    case ISO_U32: LINE_PASS(uint32_t); break;
    case ISO_I32: LINE_PASS(int32_t);  break;
    case ISO_F32: LINE_PASS(float);    break;
    case ISO_F64: LINE_PASS(double);   break;
    }
    if (count * PADDING_MIN_SHARE < iso_vol_count(vol))
        return 0;
    for (int a = 0; a < 3; a++) {
        size_t met = 0, mixed = 0;
        for (size_t n = 0; n < sizes[a]; n++) {
            met += (lines[a][n] & SEEN_VALUE) != 0;
            mixed += lines[a][n] == (SEEN_VALUE | SEEN_OTHER);
        }
        if (met && mixed * PADDING_MIXED_SHARE <= met)
            return 1;
    }
    return 0;
}

int iso_vol_find_padding(const iso_volume *vol, const uint64_t *counts, size_t bins, double *padding)
{
    assert(vol && counts && bins >= 1 && padding);
    if (!(vol->value_max > vol->value_min))
        return 0;
    const size_t total = iso_vol_count(vol);
    /* The end bins bound the candidates' counts: most volumes stop here, without a pass. */
    const double ends[2] = {vol->value_min, vol->value_max};
    const uint64_t end_counts[2] = {counts[0], counts[bins - 1]};
    size_t sizes[3] = {vol->dims[1] * vol->dims[2], vol->dims[0] * vol->dims[2], vol->dims[0] * vol->dims[1]};
    unsigned char *lines[3] = {NULL, NULL, NULL};
    int found = 0;
    for (int e = 0; e < 2 && !found; e++) {
        if (end_counts[e] * PADDING_MIN_SHARE < total)
            continue;
        if (!lines[0]) {
            for (int a = 0; a < 3; a++)
                lines[a] = malloc(sizes[a]);
            if (!lines[0] || !lines[1] || !lines[2])
                break; /* no memory: no padding found, which only costs the levels' aim */
        }
        if (fills_lines(vol, ends[e], lines, sizes)) {
            *padding = ends[e];
            found = 1;
        }
    }
    for (int a = 0; a < 3; a++)
        free(lines[a]);
    return found;
}
