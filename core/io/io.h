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

/* NRRD headers' key:=value pairs and multi-valued samples, for 3D Slicer's segmentations
 * (core/segment reads their meaning). */

/* Calls fn(context, key, value, line, err) for each "key:=value" line of path's NRRD header
 * (until the blank line that ends it), in order; stops at fn's first non-zero return,
 * which it returns. 0, ISO_E_IO or ISO_E_NOMEM otherwise. */
int iso_nrrd_key_values(const char *path,
                        int (*fn)(void *context, const char *key, const char *value, int line, iso_error *err),
                        void *context, iso_error *err);
/* A NRRD's samples as layers: a 3-D file is one volume, a 4-D file whose first axis holds
 * N values per sample (N <= 256) N volumes, value v of every sample in layer v; each with
 * the file's geometry and its stats. *layers is a malloc'd array of *count volumes. The
 * errors of iso_nrrd_load. */
int iso_nrrd_load_layers(const char *path, const iso_load_options *opt, iso_volume ***layers, size_t *count,
                         iso_error *err);

/* DICOM Segmentation objects (PS3.3 A.51, C.8.20): what a SEG says (its segments, its
 * type, its frames' places and segments, the shared plane geometry, the series it was
 * derived from) and its pixel data as stored, read with GDCM's dataset API. Placing the
 * frames on a grid is core/segment/dicom_seg.c's job. */

/* Segmentation Storage, and Label Map Segmentation Storage (2024). */
#define ISO_GDCM_SEG_SOP_CLASS "1.2.840.10008.5.1.4.1.1.66.4"
#define ISO_GDCM_SEG_LABELMAP_SOP_CLASS "1.2.840.10008.5.1.4.1.1.66.7"

typedef struct iso_gdcm_seg_segment {
    unsigned number;          /* Segment Number (0062,0004) */
    char label[128];          /* Segment Label (0062,0005) */
    char category[128];       /* Segmented Property Category (0062,0003) > Code Meaning */
    char type[128];           /* Segmented Property Type (0062,000F) > Code Meaning */
    uint16_t lab[3];          /* Recommended Display CIELab Value (0062,000D) */
    int has_lab;
} iso_gdcm_seg_segment;

typedef struct iso_gdcm_seg_frame {
    double position[3];       /* Plane Position (0020,9113) > Image Position (Patient) */
    int has_position;
    unsigned segment;         /* Segment Identification (0062,000A) > Referenced Segment Number; 0 if absent */
} iso_gdcm_seg_frame;

typedef struct iso_gdcm_seg {
    char sop_class[80], series_uid[80];
    char referenced_series[80];   /* Referenced Series Sequence (0008,1115) > SeriesInstanceUID */
    char type[16];                /* Segmentation Type (0062,0001): BINARY, FRACTIONAL, LABELMAP */
    unsigned rows, columns, frames, bits_allocated;
    double max_fraction;          /* Maximum Fractional Value (0062,000E) */
    double pixel_spacing[2];      /* shared Pixel Measures: between rows, between columns */
    double orientation[6];        /* shared Plane Orientation (0020,9116) */
    int has_orientation;
    unsigned per_frame_items;     /* items in Per-frame Functional Groups (5200,9230) */
    iso_gdcm_seg_segment *segments; /* segment_count, malloc'd */
    unsigned segment_count;
    iso_gdcm_seg_frame *frame;   /* frames entries, malloc'd */
    unsigned char *pixels;        /* the Pixel Data as stored (1-bit packed, or 8/16-bit), malloc'd */
    size_t pixel_bytes;
} iso_gdcm_seg;

/* Reads SOP Class and Series UIDs only (the header up to them): 0, 1 when path is no
 * DICOM file, -1 with why. */
int iso_gdcm_seg_probe(const char *path, char *sop_class, size_t sop_size, char *series_uid, size_t series_size,
                        char *why, size_t why_size);
/* Reads the whole object, pixel data included (uncompressed or deflated; an encapsulated
 * one is decoded by GDCM). max_frames caps NumberOfFrames. 0, or -1 with why. On success
 * free with iso_gdcm_seg_free. */
int iso_gdcm_seg_read(const char *path, unsigned max_frames, iso_gdcm_seg *out, char *why, size_t why_size);
void iso_gdcm_seg_free(iso_gdcm_seg *seg);

#endif
