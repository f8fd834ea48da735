/* segment_internal.h: what the segment module's files share (not part of segment.h). */
#ifndef ISO_SEGMENT_INTERNAL_H
#define ISO_SEGMENT_INTERNAL_H

#include "segment.h"

/* Segment s's field on the box of samples lo..hi (inclusive, index space of its layer;
 * it may reach past the volume): the indicator (a fractional layer's values over
 * max_fraction) convolved with a Gaussian of sigma_mm (0: none), as a new f32 volume whose
 * sample (0,0,0) is the box's first and whose geometry places it where the layer's sample
 * lo is. Beyond the volume the field is 0 with cap, else the border's value. field.c. */
int iso_seg_field(const iso_segmentation *seg, size_t s, const long lo[3], const long hi[3], double sigma_mm,
                  int cap, iso_volume **out, iso_error *err);

#endif
