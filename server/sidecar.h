/* sidecar.h: raw sample files described by a small JSON sidecar, and the one entry point
 * through which the daemon and the CLI open volumes.
 *
 * A raw volume is two files: NAME.raw (any extension: the samples, nothing else) and
 * NAME.raw.json beside it:
 *     {"dims": [256, 256, 113], "type": "uint16", "endian": "big",
 *      "spacing": [1, 1, 2], "origin": [0, 0, 0],
 *      "direction": [[1,0,0],[0,1,0],[0,0,1]], "header_bytes": 0, "compression": "none"}
 * dims and type are required; endian is required for multi-byte types; the rest default
 * to unit spacing, zero origin, identity direction (columns: the axes' world directions,
 * LPS), no header bytes, no compression ("gzip" or "zlib" for compressed samples). The
 * volume is named by its raw file; the sidecar alone is not a volume. JSON lives here,
 * not in core/ (which has none): the sidecar becomes an iso_nrrd_header and core's one
 * sample reader does the rest. */
#ifndef SRV_SIDECAR_H
#define SRV_SIDECAR_H

#include "loader.h"
#include "volume.h"

/* Like iso_load, plus raw files with a sidecar. */
int srv_load_volume(const char *path, const iso_load_options *opt, iso_volume **out,
                    iso_error *err);
/* Like iso_load_recognises, plus raw files whose sidecar exists (this one looks at the
 * file system). */
int srv_load_recognises(const char *path);

#endif
