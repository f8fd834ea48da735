/* sidecar.h: raw sample files described by a small JSON sidecar.
 *
 * A raw volume is two files: NAME.raw (any extension: the samples, nothing else) and
 * NAME.raw.json beside it:
 *     {"dims": [256, 256, 113], "type": "uint16", "endian": "big",
 *      "spacing": [1, 1, 2], "origin": [0, 0, 0],
 *      "direction": [[1,0,0],[0,1,0],[0,0,1]], "header_bytes": 0, "compression": "none"}
 * dims and type are required; endian is required for multi-byte types; the rest default
 * to unit spacing, zero origin, identity direction (columns: the axes' world directions,
 * LPS), no header bytes, no compression ("gzip" or "zlib" for compressed samples). The
 * volume is named by its raw file; the sidecar alone is not a volume. The sidecar is a
 * file format, read with jansson like any other header; it becomes an iso_nrrd_header and
 * the one sample reader (raw.h) does the rest. */
#ifndef ISO_SIDECAR_H
#define ISO_SIDECAR_H

#include "io.h"
#include "volume/volume.h"

/* 1 if PATH.json exists and is readable and PATH is not itself a ".json" file: unlike the
 * other loaders' tests, this one looks at the file system. */
int iso_sidecar_recognises(const char *path);
/* Loads the raw samples as the sidecar describes them (core's one sample reader). */
int iso_sidecar_load(const char *path, const iso_load_options *opt, iso_volume **out,
                     iso_error *err);

#endif
