/* io.h: opening a volume by name, whatever its source: NRRD, NIfTI-1/2, MetaImage, raw
 * samples with a JSON sidecar, a DICOM series, or an analytic field ("field:NAME").
 *
 * Ownership: a successful load gives the caller a new volume (iso_vol_free). Errors:
 * ISO_E_IO (cannot open or read, not a regular file), ISO_E_FORMAT, ISO_E_TRUNCATED,
 * ISO_E_UNSUPPORTED, ISO_E_LIMIT (over opt->max_bytes), ISO_E_NOMEM, each with a message
 * naming the file and the place. Every loader is safe on untrusted files.
 * Thread-safety: loads of different paths may run side by side. Cost: one read of the file
 * plus one pass for the statistics. */
#ifndef ISO_IO_H
#define ISO_IO_H

#include <stdint.h>

#include "volume/volume.h"

/* Opening a volume by name, whatever its format.
 *
 * A table of loaders (loader.c) is tried in order; each says whether it recognises a path
 * (by suffix, or by a prefix such as "field:"), then loads it. New formats add one row. */

typedef struct iso_load_options {
    uint64_t max_bytes; /* refuse volumes whose samples exceed this; 0 = ISO_VOL_DEFAULT_MAX_BYTES */
    /* Called with the fraction done during long loads (a DICOM series of many files);
     * NULL: none. */
    void (*progress)(void *context, double fraction);
    void *progress_context;
} iso_load_options;

/* Loads `path` (a file, a DICOM series directory "DIR[#SeriesInstanceUID]" (io.h), or
 * "field:NAME[:WxHxD]" for an analytic field, see io.h).
 * opt may be NULL. On success *out owns a new volume with its stats computed; on failure
 * *out is NULL and err names the file and the problem. A volume whose file rescales its
 * stored values (DICOM, NIfTI's scl_slope) comes in the narrowest voxel type that holds the
 * values present (iso_vol_rescale); others in the type the file stores. Safe on untrusted
 * files. */
int iso_load(const char *path, const iso_load_options *opt, iso_volume **out, iso_error *err);

/* 1 if some loader recognises `path` as a volume of its own (a detached NRRD's data file
 * is not one). Looks at the name only, and for DICOM at whether it names a directory. */
int iso_load_recognises(const char *path);

/* Analytic volumes for tests and demos, loaded as "field:NAME", "field:NAME:N" or
 * "field:NAME:WxHxD" (default 64^3).
 *
 * Index space, c = ((W-1)/2, (H-1)/2, (D-1)/2), R = min over axes of (dim-1)/2:
 *   sphere    f32  R - |p - c|: positive inside, level L is the sphere of radius R - L
 *   torus     f32  R/4 - distance to the ring of radius R/2 around c in the xy-plane
 *   ml        f32  Marschner and Lobb's test signal (1994) on [-1,1]^3, values in [0,1],
 *                  alpha 0.25, fM 6; level 0.5 is the usual one
 *   constant  u8   Elber and Malzbender's D1: every sample 1
 *   spike     f32  their D2: every sample 1 but p(0,0,0) = 0
 *   ijk       f32  their D3: p(i,j,k) = i*j*k, which one trilinear represents exactly */

#define ISO_FIELD_PREFIX "field:"
#define ISO_FIELD_DEFAULT_SIZE 64
#define ISO_FIELD_MAX_SIZE 4096

/* "sphere, torus, ml, constant, spike, ijk": the known names, for messages. Never NULL. */
const char *iso_field_names(void);

/* Builds field `name` (a name above, without the prefix) on a dims grid, each dim in
 * 2..ISO_FIELD_MAX_SIZE, unit spacing, zero origin; stats not computed. max_bytes 0 means
 * the default. Returns 0, ISO_E_ARGUMENT (unknown name, listing the known ones, or a bad
 * size), ISO_E_LIMIT or ISO_E_NOMEM. O(samples). */
int iso_field_create(const char *name, const size_t dims[3], uint64_t max_bytes,
                     iso_volume **out, iso_error *err);

/* Parses path "field:NAME[:N|:WxHxD]" and builds the field; opt may be NULL. Safe on
 * untrusted strings. On failure *out is NULL. */
int iso_field_load(const char *path, const iso_load_options *opt, iso_volume **out,
                   iso_error *err);

/* A DICOM series (a directory of slices, or one multi-frame file) as one volume.
 *
 * Names a loader accepts:
 *     DIR                  the one image series in DIR (files in DIR itself, not below)
 *     DIR#SERIES_UID       the series with that SeriesInstanceUID, when DIR holds several
 *     FILE.dcm             one file: a multi-frame image (enhanced CT/MR, RT dose, ...)
 * Files without the DICOM preamble ("DICM" at byte 128) and DICOM files without an image
 * (DICOMDIR, reports) are skipped. Pixels are decoded by GDCM (dicom_gdcm.h), whatever
 * the transfer syntax.
 *
 * Frames are sorted by ImagePositionPatient projected on the slice normal (the cross product
 * of the ImageOrientationPatient directions), never by file name or InstanceNumber. The
 * volume's axes: i along the row direction with PixelSpacing[1], j along the column
 * direction with PixelSpacing[0], k from the first slice to the last with the measured
 * mean gap; the world matrix keeps a gantry tilt as shear. Two slices at one position,
 * uneven gaps (a missing slice) and positions off the line are errors naming the files.
 * RescaleSlope/Intercept (per frame when they differ) are applied: the voxel type is the
 * stored one when the map is the identity, else the narrowest of i16, i32 that holds every
 * mapped value of the stored bit range when slope and intercept are integers (CT in HU),
 * else f32. */

/* Slice-position gaps may differ from their mean by this fraction before they are called
 * uneven (scanners round positions to about 1e-3 mm; a missing slice is a 100% gap). */
#define ISO_DICOM_GAP_TOLERANCE 0.01
/* Most files one series directory may hold; a bigger folder is refused, not crawled. */
#define ISO_DICOM_MAX_FILES 100000

/* 1 if `path` names a DICOM source: a directory (optionally with "#UID"), or a file
 * ending in .dcm. Looks at the file system (stat), not in the files. */
int iso_dicom_recognises(const char *path);
/* 1 if dir holds at least one file with the DICOM preamble (for directory scans). */
int iso_dicom_dir_has_files(const char *dir);
/* Loads the series (see above). Safe on untrusted files; respects opt->max_bytes.
 * Segmentation objects in a folder are not images of its series: they are skipped (and a
 * folder of nothing else is refused, saying it is a segmentation). */
int iso_dicom_load(const char *path, const iso_load_options *opt, iso_volume **out, iso_error *err);
/* What iso_dicom_load would give path's volume, without decoding a pixel: dims, spacing,
 * origin and direction into *shape (data NULL, no stats). The same checks and errors. */
int iso_dicom_geometry(const char *path, const iso_load_options *opt, iso_volume *shape, iso_error *err);

#endif
