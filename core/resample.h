/* resample.h: a volume filtered to other dimensions (the paper's "filtered down" 3dhead,
 * and the scaling ladders of the benchmarks). */
#ifndef ISO_RESAMPLE_H
#define ISO_RESAMPLE_H

#include "volume.h"

/* A new f32 volume of the given dims covering the same world box: each output sample is
 * the mean of the input samples within half an output spacing of its position (a box
 * filter, so shrinking averages instead of aliasing; growing interpolates trilinearly).
 * Spacing grows by the ratio, origin and direction stay. NULL and err on bad dims or
 * memory. O(input + output * footprint). */
iso_volume *iso_resample(const iso_volume *vol, const size_t dims[3], iso_error *err);

#endif
