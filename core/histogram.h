/* histogram.h: a volume's value histogram and the iso-levels it suggests.
 *
 * Clients draw the histogram behind their level slider; the suggested levels come from
 * three-class Otsu thresholding (Otsu 1979, the multi-level form of Liao et al. 2001) on
 * that histogram: for CT the classes are air / soft tissue / bone, so the two thresholds
 * land between them (skin and bone surfaces); for MRI, background / grey / white matter. */
#ifndef ISO_HISTOGRAM_H
#define ISO_HISTOGRAM_H

#include <stddef.h>
#include <stdint.h>

#include "volume.h"

/* Counts the samples of vol into `bins` equal bins over [value_min, value_max] (the
 * volume's stats, see iso_vol_update_stats): bin b covers
 * [min + b * width, min + (b + 1) * width), the last bin includes value_max. NaN samples
 * are not counted. counts holds `bins` entries (bins >= 1). A constant volume puts every
 * sample in bin 0. O(N). */
void iso_hist_compute(const iso_volume *vol, size_t bins, uint64_t *counts);

/* The two thresholds of three-class Otsu on the histogram, as values (bin boundaries
 * mapped back through min and max). Writes at most max_levels levels (ascending) and
 * returns how many: 2 normally, 1 when only two classes exist, 0 for an empty or
 * single-valued histogram, and for more than 1024 bins. O(bins^2). */
size_t iso_hist_suggest_levels(const uint64_t *counts, size_t bins, double min, double max,
                               double *levels, size_t max_levels);

#endif
