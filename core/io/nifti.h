/* nifti.h: NIfTI-1 and NIfTI-2 volumes (.nii, .nii.gz) through Debian's NIfTI library
 * (libnifti2, which reads both versions), not a parser of our own.
 *
 * Samples keep their type unless scl_slope/scl_inter rescale them, in which case they
 * become float32 (float64 for 32-bit integers and doubles) holding slope * v + inter.
 * Geometry: the sform when its code is set, else the qform (the library's qto_xyz, which
 * falls back to the voxel sizes), converted from NIfTI's RAS to isoserve's LPS (volume.h).
 * 4-D files with more than one volume, complex, RGB and 64-bit integer data are refused. */
#ifndef ISO_NIFTI_H
#define ISO_NIFTI_H

#include "io.h"
#include "volume/volume.h"

/* Loads path; opt may be NULL. Checks the header's size against opt->max_bytes before
 * reading any sample. On failure *out is NULL and err names the file and the problem.
 * Not thread-safe (the library keeps a global debug level): load from one thread. */
int iso_nifti_load(const char *path, const iso_load_options *opt, iso_volume **out,
                   iso_error *err);

#endif
