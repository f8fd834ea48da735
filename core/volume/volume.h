/* volume.h: a volume in memory (samples, geometry, value statistics), the trilinear
 * interpolant every bound refers to, the value histogram and box-filter resampling.
 *
 * Ownership: iso_vol_* constructors return a volume the caller frees with iso_vol_free;
 * histograms and resampled volumes are new objects owned by the caller. Errors: ISO_E_*
 * codes through iso_error (ISO_E_LIMIT for sizes over the configured maximum, ISO_E_NOMEM).
 * Thread-safety: a volume is read-only once built and may be shared by any number of
 * threads. Cost: statistics and histograms are one pass over the samples; sample access and
 * interpolation are O(1). */
#ifndef ISO_VOLUME_H
#define ISO_VOLUME_H

#include <stddef.h>
#include <stdint.h>

#include "base/base.h"

/* A scalar volume, the input of everything else.
 *
 * Samples p[i][j][k] sit on a W_x x W_y x W_z grid, stored x fastest, then y, then z, in
 * their own voxel type and in host byte order (loaders swap on read). Index space has
 * sample (i,j,k) at point (i,j,k); world millimetres are
 *     world = origin + direction * (index * spacing)
 * with direction's columns the unit world directions of the i, j, k axes (identity unless
 * the file says otherwise; not necessarily orthogonal: a sheared affine from a NIfTI sform
 * keeps its shear). World space is LPS millimetres (DICOM, ITK, 3D Slicer's model files):
 * x grows to the patient's left, y to posterior, z to superior; loaders of RAS formats
 * (NIfTI) negate x and y. */

typedef enum iso_voxel_type {
    ISO_U8, ISO_I8, ISO_U16, ISO_I16, ISO_U32, ISO_I32, ISO_F32, ISO_F64
} iso_voxel_type;

typedef struct iso_volume {
    size_t dims[3];          /* samples per axis, each >= 2 */
    iso_voxel_type type;
    void *data;              /* dims[0]*dims[1]*dims[2] samples, host byte order */
    double spacing[3];       /* mm between samples along i, j, k (> 0) */
    double origin[3];        /* world mm of sample (0,0,0) */
    double direction[3][3];  /* direction[r][c]: row r of the matrix, column c is axis c */
    double value_min, value_max, value_mean; /* over all samples, set by iso_vol_update_stats */
    int has_nan;             /* float volumes: 1 if any sample is NaN (see iso_vol_update_stats) */
    char modality[17];       /* what the file says acquired it ("CT", "MR"; DICOM's Modality), or "" */
    char description[65];    /* the file's own words for it (DICOM's SeriesDescription), or "" */
    int labels;              /* 1: an integer label volume, each value naming a segment: its
                              * hierarchy keeps per brick the labels held (hierarchy/labels.h) */
    int oriented;            /* 1 when the file says how its axes lie in the patient (NRRD
                                space, NIfTI sform or qform, MetaImage TransformMatrix, a
                                sidecar's direction, DICOM); 0: direction is the identity
                                by convention, not by the file */
    int has_padding;         /* 1 when the file names a padding value (DICOM's Pixel Padding
                                Value (0028,0120)): samples outside the field of view */
    double padding;          /* that value, rescaled as the samples are */
} iso_volume;

/* Default cap on the bytes of one volume's samples: 8 GiB. */
#define ISO_VOL_DEFAULT_MAX_BYTES ((uint64_t)8 << 30)

/* Bytes of one sample of `type` (1, 2, 4 or 8). */
size_t iso_vol_type_size(iso_voxel_type type);
/* "u8", "i16", "f32", ... Never NULL. */
const char *iso_vol_type_name(iso_voxel_type type);
/* Parses the names above; returns 0 and sets *type, or -1 for an unknown name. */
int iso_vol_type_parse(const char *name, iso_voxel_type *type);
/* 1 for ISO_F32 and ISO_F64. */
int iso_vol_type_is_float(iso_voxel_type type);

/* The narrowest voxel type (narrow.c). Loaders that rescale stored values keep the volume
 * in the narrowest type that holds every value present, never losing one: CT in Hounsfield
 * units is int16, whatever bit range its files store. */

/* The narrowest type holding every value in [min, max] exactly when all are integers
 * (integral): the smallest integer type, the source's own first at its size, then unsigned,
 * then signed; float64 past 32 bits. Not integral: the source when it is a float type, else
 * float32. */
iso_voxel_type iso_vol_narrowest_type(double min, double max, int integral, iso_voxel_type source);
/* Converts vol's samples in place to `to`, with value = slope[k] * sample + intercept[k] on
 * slice k when slope is given (both NULL or both dims[2] long). The caller knows every new
 * value fits `to` (iso_vol_narrowest_type). A wider type grows the buffer (max_bytes as in
 * iso_vol_create; 0 = default), a narrower one shrinks it. Returns 0, ISO_E_LIMIT or
 * ISO_E_NOMEM (vol unchanged). Statistics are left to the caller. */
int iso_vol_retype(iso_volume *vol, iso_voxel_type to, const double *slope, const double *intercept,
                   uint64_t max_bytes, iso_error *err);
/* Rescales vol's stored integer samples, value = slope[k] * stored + intercept[k] on slice k
 * (DICOM's RescaleSlope and RescaleIntercept, NIfTI's scl_slope and scl_inter; each slope
 * finite and not 0), into the narrowest type that holds the values present: integers into
 * the smallest integer type (vol's own first at its size), others into float32 when it
 * keeps every two distinct stored values apart, else float64. Returns 0, ISO_E_LIMIT or
 * ISO_E_NOMEM (vol unchanged). O(N): one pass to find the range, one to convert. */
int iso_vol_rescale(iso_volume *vol, const double *slope, const double *intercept, uint64_t max_bytes,
                    iso_error *err);

/* Checks dims (each >= 2) and that the sample bytes fit in max_bytes without overflow;
 * on success stores the byte count in *bytes. Safe on untrusted sizes. */
int iso_vol_check_size(const size_t dims[3], iso_voxel_type type, uint64_t max_bytes,
                       uint64_t *bytes, iso_error *err);

/* Allocates a zero-filled volume with unit spacing, zero origin, identity direction.
 * Returns NULL (and fills err) if dims are invalid or exceed max_bytes (0 = default). */
iso_volume *iso_vol_create(const size_t dims[3], iso_voxel_type type, uint64_t max_bytes,
                           iso_error *err);
/* Frees the volume and its samples; NULL is allowed. */
void iso_vol_destroy(iso_volume *vol);

static inline size_t iso_vol_count(const iso_volume *vol)
{
    return vol->dims[0] * vol->dims[1] * vol->dims[2];
}
static inline size_t iso_vol_index(const iso_volume *vol, size_t i, size_t j, size_t k)
{
    return (k * vol->dims[1] + j) * vol->dims[0] + i;
}

/* Sample at linear index `at` of samples of the given type, unchecked. Called with a
 * constant type inside a function specialized per type, the switch folds away. */
static inline double iso_vol_sample_as(const void *data, iso_voxel_type type, size_t at)
{
    switch (type) {
    case ISO_U8: return ((const uint8_t *)data)[at];
    case ISO_I8: return ((const int8_t *)data)[at];
    case ISO_U16: return ((const uint16_t *)data)[at];
    case ISO_I16: return ((const int16_t *)data)[at];
    case ISO_U32: return ((const uint32_t *)data)[at];
    case ISO_I32: return ((const int32_t *)data)[at];
    case ISO_F32: return ((const float *)data)[at];
    case ISO_F64: return ((const double *)data)[at];
    }
    return 0;
}

/* Sample at linear index `at` (iso_vol_index), unchecked: for loops that know their
 * bounds. */
static inline double iso_vol_sample(const iso_volume *vol, size_t at)
{
    return iso_vol_sample_as(vol->data, vol->type, at);
}

/* Sample (i,j,k) as a double. Asserts the indices are inside. O(1), a switch per call:
 * for bulk access use iso_vol_read_box. */
double iso_vol_get(const iso_volume *vol, size_t i, size_t j, size_t k);
/* Stores value (converted to the voxel type, rounded and clamped for integers). */
void iso_vol_set(iso_volume *vol, size_t i, size_t j, size_t k, double value);

/* Copies the samples of the inclusive box lo..hi into out as doubles, x fastest.
 * out holds (hi[0]-lo[0]+1)*(hi[1]-lo[1]+1)*(hi[2]-lo[2]+1) doubles. Asserts the box is
 * inside the volume. */
void iso_vol_read_box(const iso_volume *vol, const size_t lo[3], const size_t hi[3],
                      double *out);

/* Recomputes value_min, value_max, value_mean and has_nan. NaN samples are ignored by
 * min/max/mean; they never count as above any level (see extract.h). O(N). */
void iso_vol_update_stats(iso_volume *vol);

/* The smallest of the three spacings: mm per voxel where a length in mm must be stated
 * in voxels without understating it along any axis. */
double iso_vol_min_spacing(const iso_volume *vol);
/* Index space (i,j,k may be fractional) to world millimetres. Inline because the brick
 * kernel places every vertex of a rotated volume through it. */
static inline void iso_vol_index_to_world(const iso_volume *vol, const double index[3], double world[3])
{
    double scaled[3];
    for (int c = 0; c < 3; c++)
        scaled[c] = index[c] * vol->spacing[c];
    for (int r = 0; r < 3; r++)
        world[r] = vol->origin[r] + vol->direction[r][0] * scaled[0] +
                   vol->direction[r][1] * scaled[1] + vol->direction[r][2] * scaled[2];
}
/* Sets spacing, direction and origin from a 3x4 affine [A | origin] (world = A index +
 * origin): spacing = the column lengths, direction = the unit columns. Refuses (with
 * ISO_E_FORMAT, `what` naming the source in the message) a non-finite or singular A.
 * The volume is unchanged on error. */
int iso_vol_set_affine(iso_volume *vol, const double affine[3][4], const char *what,
                       iso_error *err);
/* The linear part A of index-to-world (A's columns: the world steps of i, j, k), its
 * inverse (world offsets to index offsets) and det A. Returns 0, or -1 when A is singular
 * (|det| <= 1e-300); inv is then unset. */
int iso_vol_frame(const iso_volume *vol, double a[3][3], double inv[3][3], double *det);

/* Points the i, j, k axes where a three-letter code says (DICOM's sense: each letter is
 * the patient direction its axis runs toward: L or R, P or A, S or I, one of each pair, in
 * any order; "LPS" is the identity, "LPI" flips k): for files that do not say it. Spacing
 * and origin stay; the volume becomes oriented. ISO_E_ARGUMENT, the volume unchanged, for
 * any other code. */
int iso_vol_set_axes(iso_volume *vol, const char *code, iso_error *err);
/* The same map as a 3x4 affine matrix [A | origin], world = A * index + origin, read off
 * iso_vol_index_to_world so that the two always agree. */
void iso_vol_affine(const iso_volume *vol, double affine[3][4]);

/* A volume's value histogram and the iso-levels it suggests.
 *
 * Clients draw the histogram behind their level slider; the suggested levels come from
 * three-class Otsu thresholding (Otsu 1979, the multi-level form of Liao et al. 2001) on
 * that histogram: for CT the classes are air / soft tissue / bone, so the two thresholds
 * land between them (skin and bone surfaces); for MRI, background / grey / white matter. */

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

/* Clears, in counts (iso_hist_compute's bins over [min, max]), the bin of the padding
 * value, so that levels suggested from them never sit between padding and data (a level
 * there draws the field of view's border, not the anatomy). Returns the count it cleared;
 * 0 for a padding value outside [min, max]. O(1). */
size_t iso_hist_drop_padding(uint64_t *counts, size_t bins, double min, double max, double padding);

/* The value a scanner wrote outside its field of view, when the file does not name it
 * (DICOM's Pixel Padding Value does: the loader sets has_padding): the value at an end of
 * the range that holds at least 0.5% of the samples and fills whole lines through the
 * volume along some axis, at most 2% of the lines that meet it meeting any other value (a
 * CT's reconstruction circle, repeated on every slice; the 0 around a skull-stripped brain
 * or air at -1024 also cross tissue on their lines, so they are not padding). counts: the
 * volume's histogram over `bins` bins (iso_hist_compute), which spares the pass when no
 * end bin holds that share. Returns 1 and sets *padding, or 0. O(N) when an end bin
 * qualifies, with scratch of one byte per line along each axis. */
int iso_vol_find_padding(const iso_volume *vol, const uint64_t *counts, size_t bins, double *padding);

/* A volume filtered to other dimensions (the paper's "filtered down" 3dhead,
 * and the scaling ladders of the benchmarks). */

/* A new f32 volume of the given dims covering the same world box: each output sample is
 * the mean of the input samples within half an output spacing of its position (a box
 * filter, so shrinking averages instead of aliasing; growing interpolates trilinearly).
 * Spacing grows by the ratio, origin and direction stay. NULL and err on bad dims or
 * memory. O(input + output * footprint). */
iso_volume *iso_resample(const iso_volume *vol, const size_t dims[3], iso_error *err);

/* One box's trilinear function, the fit the hierarchy measures nodes against.
 *
 * A trilinear T on a box is given by its 8 corner values c[k], corner k at local
 * coordinates (k & 1, (k >> 1) & 1, (k >> 2) & 1) in [0,1]^3. */

/* T at local coordinates (u, v, w) in [0,1]^3. */
static inline double iso_tri_eval(const double c[8], double u, double v, double w)
{
    double x00 = c[0] + (c[1] - c[0]) * u, x10 = c[2] + (c[3] - c[2]) * u;
    double x01 = c[4] + (c[5] - c[4]) * u, x11 = c[6] + (c[7] - c[6]) * u;
    double y0 = x00 + (x10 - x00) * v, y1 = x01 + (x11 - x01) * v;
    return y0 + (y1 - y0) * w;
}

#endif
