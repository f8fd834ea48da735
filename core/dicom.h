/* dicom.h: a DICOM series (a directory of slices, or one multi-frame file) as one volume.
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
#ifndef ISO_DICOM_H
#define ISO_DICOM_H

#include "loader.h"
#include "volume.h"

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
/* Loads the series (see above). Safe on untrusted files; respects opt->max_bytes. */
int iso_dicom_load(const char *path, const iso_load_options *opt, iso_volume **out, iso_error *err);

#endif
