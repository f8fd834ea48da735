/* histogram.c: value histograms and Otsu-suggested levels (see volume.h). */
#include "volume.h"

#include <assert.h>
#include <math.h>
#include <string.h>

/* One typed pass per voxel type: the switch stays outside the loop. */
#define HIST_PASS(T)                                                                   \
    do {                                                                               \
        const T *s = (const T *)vol->data;                                             \
        for (size_t n = 0; n < count; n++) {                                           \
            double v = (double)s[n];                                                   \
            if (v != v)                                                                \
                continue;                                                              \
            double b = (v - min) * scale;                                              \
            size_t bin = b <= 0 ? 0 : b >= (double)last ? last : (size_t)b;            \
            counts[bin]++;                                                             \
        }                                                                              \
    } while (0)

void iso_hist_compute(const iso_volume *vol, size_t bins, uint64_t *counts)
{
    assert(vol && counts && bins >= 1);
    memset(counts, 0, bins * sizeof *counts);
    const double min = vol->value_min, max = vol->value_max;
    const size_t count = iso_vol_count(vol), last = bins - 1;
    const double scale = max > min ? (double)bins / (max - min) : 0;
    switch (vol->type) {
    case ISO_U8:  HIST_PASS(uint8_t);  break;
    case ISO_I8:  HIST_PASS(int8_t);   break;
    case ISO_U16: HIST_PASS(uint16_t); break;
    case ISO_I16: HIST_PASS(int16_t);  break;
    case ISO_U32: HIST_PASS(uint32_t); break;
    case ISO_I32: HIST_PASS(int32_t);  break;
    case ISO_F32: HIST_PASS(float);    break;
    case ISO_F64: HIST_PASS(double);   break;
    }
}

size_t iso_hist_drop_padding(uint64_t *counts, size_t bins, double min, double max, double padding)
{
    assert(counts && bins >= 1);
    if (!(max > min) || !(padding >= min && padding <= max))
        return 0;
    double b = (padding - min) * (double)bins / (max - min);
    size_t bin = b >= (double)(bins - 1) ? bins - 1 : (size_t)b;
    uint64_t dropped = counts[bin];
    counts[bin] = 0;
    return (size_t)dropped;
}

/* Otsu's prefix sums live on the stack; more bins than this are refused. */
#define HIST_MAX_BINS 1024

/* Between-class variance terms: with prefix sums P (counts) and S (count * bin), a class
 * of bins [a, b) contributes S(a,b)^2 / P(a,b); Otsu maximises the sum over classes. */
static double class_term(const double *p, const double *s, size_t a, size_t b)
{
    double w = p[b] - p[a];
    if (w <= 0)
        return -1;
    double m = s[b] - s[a];
    return m * m / w;
}

size_t iso_hist_suggest_levels(const uint64_t *counts, size_t bins, double min, double max,
                               double *levels, size_t max_levels)
{
    assert(counts && bins >= 1 && (levels || max_levels == 0));
    if (!(max > min) || bins < 3 || bins > HIST_MAX_BINS || max_levels == 0)
        return 0;
    double p[HIST_MAX_BINS + 1], s[HIST_MAX_BINS + 1];
    p[0] = s[0] = 0;
    for (size_t b = 0; b < bins; b++) {
        p[b + 1] = p[b] + (double)counts[b];
        s[b + 1] = s[b] + (double)counts[b] * ((double)b + 0.5);
    }
    /* Thresholds t1 < t2 split the bins into [0,t1), [t1,t2), [t2,bins). */
    double best = -1;
    size_t t1best = 0, t2best = 0;
    for (size_t t1 = 1; t1 + 1 < bins; t1++) {
        double c0 = class_term(p, s, 0, t1);
        if (c0 < 0)
            continue;
        for (size_t t2 = t1 + 1; t2 < bins; t2++) {
            double c1 = class_term(p, s, t1, t2), c2 = class_term(p, s, t2, bins);
            if (c1 < 0 || c2 < 0)
                continue;
            if (c0 + c1 + c2 > best) {
                best = c0 + c1 + c2;
                t1best = t1;
                t2best = t2;
            }
        }
    }
    const double width = (max - min) / (double)bins;
    if (best < 0) {
        /* Fewer than three non-empty classes: two-class Otsu. */
        for (size_t t = 1; t < bins; t++) {
            double c0 = class_term(p, s, 0, t), c1 = class_term(p, s, t, bins);
            if (c0 >= 0 && c1 >= 0 && c0 + c1 > best) {
                best = c0 + c1;
                t1best = t;
            }
        }
        if (best < 0)
            return 0;
        levels[0] = min + (double)t1best * width;
        return 1;
    }
    levels[0] = min + (double)t1best * width;
    if (max_levels < 2)
        return 1;
    levels[1] = min + (double)t2best * width;
    return 2;
}
