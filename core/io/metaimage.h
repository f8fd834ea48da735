/* metaimage.h: ITK's MetaImage volumes, .mhd (header with a separate data file) and .mha
 * (data after the header, "ElementDataFile = LOCAL").
 *
 * Read: NDims 3, DimSize, ElementType (MET_UCHAR .. MET_DOUBLE), ElementSpacing (or
 * ElementSize), Offset (or Position, Origin), TransformMatrix (or Rotation, Orientation:
 * three consecutive numbers per axis, the axis's world direction), ElementByteOrderMSB /
 * BinaryDataByteOrderMSB, CompressedData (zlib), HeaderSize, ElementNumberOfChannels 1.
 * World space is ITK's LPS, isoserve's own. The data file must sit beside the header
 * (no absolute path, no "..") and be a regular file; lists of slice files are refused.
 * The samples are read by the NRRD module's reader (nrrd.h), one reader for all. */
#ifndef ISO_METAIMAGE_H
#define ISO_METAIMAGE_H

#include "io.h"
#include "volume/volume.h"

/* Loads path; opt may be NULL. On failure *out is NULL and err names the file, the line
 * and the field. Safe on untrusted files. */
int iso_metaimage_load(const char *path, const iso_load_options *opt, iso_volume **out,
                       iso_error *err);

#endif
