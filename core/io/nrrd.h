/* nrrd.h: reading 3-D scalar NRRD files (teem's "Nearly Raw Raster Data"), attached (.nrrd)
 * or detached (.nhdr + data file), raw or gzip-encoded.
 *
 * Supported: magic NRRD0001..NRRD0005; every NRRD spelling of the 8- to 32-bit integer
 * types, float and double; dimension 3, or 4 with a first axis of values per sample (1 for
 * a scalar volume, a .seg.nrrd's layers); endian; encoding
 * raw, gzip (gz); spacings; space origin and space directions (spacing = column norms,
 * direction = normalised columns); byte skip (-1 for raw only) and line skip; a data file
 * path relative to the header's directory or absolute. Comments and key:=value pairs are
 * skipped, and so are fields that do not affect the samples (content, kinds, units, ...).
 * Not supported, reported as ISO_E_UNSUPPORTED: other encodings (ascii, hex, bzip2, ...),
 * 64-bit integers and block types, other dimensions, multi-file data ("data file: LIST",
 * format strings), non-3-D spaces. */
#ifndef ISO_NRRD_H
#define ISO_NRRD_H

#include <stdint.h>

#include "io.h"
#include "volume/volume.h"

/* Longest header line accepted, newline excluded: real headers stay under a few KB even
 * with long DWI gradient tables, and the cap keeps a hostile file from growing a buffer. */
#define ISO_NRRD_MAX_LINE 8192
/* Longest resolved data file path. */
#define ISO_NRRD_MAX_PATH 4096

typedef enum iso_nrrd_encoding { ISO_NRRD_RAW, ISO_NRRD_GZIP } iso_nrrd_encoding;

/* What a header says about its samples, with the geometry already reduced to 3 axes. */
/* Most values per sample a 4-D NRRD may hold (a .seg.nrrd's layers). */
#define ISO_NRRD_MAX_COMPONENTS 256

typedef struct iso_nrrd_header {
    size_t dims[3];
    size_t components;           /* values per sample: 1, or a 4-D file's first axis (its
                                  * samples then interleaved, value fastest); iso_nrrd_load
                                  * refuses more than 1, iso_nrrd_load_samples reads them as a
                                  * volume `components` times wider along x (0 counts as 1:
                                  * the other formats' headers leave it so) */
    iso_voxel_type type;
    uint64_t data_bytes;         /* dims product times the type size, overflow-checked */
    int big_endian;              /* byte order of the stored samples */
    iso_nrrd_encoding encoding;
    double spacing[3], origin[3], direction[3][3]; /* as in iso_volume */
    int oriented;                /* the header says how the axes lie (iso_volume.oriented) */
    int64_t byte_skip;           /* >= -1; -1: the samples are the last data_bytes of a raw file */
    int64_t line_skip;           /* >= 0 lines skipped before the byte skip */
    int detached;                /* 1 when a "data file:" field names the data */
    char data_path[ISO_NRRD_MAX_PATH]; /* the data file, resolved against the header's
                                        * directory; the header itself when attached */
    int64_t data_offset;         /* where the data (before any skip) starts in data_path */
} iso_nrrd_header;

/* Parses the header of `path` into *hdr without reading samples. O(header size). Returns
 * 0, ISO_E_IO (cannot open or read), ISO_E_FORMAT (malformed: the message gives file, line
 * and field), ISO_E_UNSUPPORTED or ISO_E_LIMIT (sizes overflow). Safe on untrusted files. */
int iso_nrrd_read_header(const char *path, iso_nrrd_header *hdr, iso_error *err);

/* Reads the samples a header describes (raw or gzip/zlib, byte and line skips, either
 * byte order) into a new volume with the header's geometry (stats not computed). The
 * MetaImage and raw+sidecar loaders fill an iso_nrrd_header and read through this too.
 * path names the volume in messages. Refuses more than opt->max_bytes before allocating,
 * and a data file that is not a regular file. */
int iso_nrrd_load_samples(const char *path, const iso_nrrd_header *hdr,
                          const iso_load_options *opt, iso_volume **out, iso_error *err);

/* Loads a whole NRRD volume into a new volume in host byte order (stats not computed).
 * opt may be NULL. Refuses volumes over opt->max_bytes before allocating. Returns the codes
 * of iso_nrrd_read_header plus ISO_E_TRUNCATED (the data ends early: the message gives the
 * bytes expected and found), ISO_E_FORMAT for corrupt gzip data and ISO_E_NOMEM. On failure
 * *out is NULL. Safe on untrusted files. */
int iso_nrrd_load(const char *path, const iso_load_options *opt, iso_volume **out,
                  iso_error *err);

#endif
