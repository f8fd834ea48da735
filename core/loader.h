/* loader.h: opening a volume by name, whatever its format.
 *
 * A table of loaders (loader.c) is tried in order; each says whether it recognises a path
 * (by suffix, or by a prefix such as "field:"), then loads it. New formats add one row. */
#ifndef ISO_LOADER_H
#define ISO_LOADER_H

#include <stdint.h>

#include "volume.h"

typedef struct iso_load_options {
    uint64_t max_bytes; /* refuse volumes whose samples exceed this; 0 = ISO_VOL_DEFAULT_MAX_BYTES */
    /* Called with the fraction done during long loads (a DICOM series of many files);
     * NULL: none. */
    void (*progress)(void *context, double fraction);
    void *progress_context;
} iso_load_options;

/* Loads `path` (a file, a DICOM series directory "DIR[#SeriesInstanceUID]" (dicom.h), or
 * "field:NAME[:WxHxD]" for an analytic field, see field.h).
 * opt may be NULL. On success *out owns a new volume with its stats computed; on failure
 * *out is NULL and err names the file and the problem. Safe on untrusted files. */
int iso_load(const char *path, const iso_load_options *opt, iso_volume **out, iso_error *err);

/* 1 if some loader recognises `path` as a volume of its own (a detached NRRD's data file
 * is not one). Looks at the name only, and for DICOM at whether it names a directory. */
int iso_load_recognises(const char *path);

#endif
