/* catalog.h: which volumes the daemon serves: read from a catalog file (JSON), found in a
 * directory, or the default collection. A catalog only names volumes; loading them is
 * collection.c's job. Requests name volumes by id, never by path. */
#ifndef SRV_CATALOG_H
#define SRV_CATALOG_H

#include <stddef.h>

#include "base/base.h"

#define SRV_ID_MAX 64
#define SRV_LEVELS_MAX 8

typedef struct srv_catalog_entry {
    char id[SRV_ID_MAX + 1];  /* [A-Za-z0-9._-]{1,64} */
    char *path;               /* file path, DICOM series directory or field:NAME[:N]; for an
                                 Orthanc series its REST URL (for people, never opened) */
    char *orthanc_url;        /* an Orthanc series: the server's base URL, else NULL */
    char *orthanc_series;     /* ... and the series' Orthanc id */
    char *dicomweb_url;       /* a DICOMweb series: the archive's base URL, else NULL */
    char *dicomweb_study;     /* ... its study UID ("": looked up by QIDO-RS) */
    char *dicomweb_series;    /* ... its series UID */
    char *dicomweb_credentials; /* ... a credentials file (dicomweb.h), or NULL */
    char *name;               /* for people; "" when the catalog gives none (then the
                                 volume's own description, else the id, is shown) */
    char *modality;           /* "CT", "MR", "phantom", ... or "" */
    double levels[SRV_LEVELS_MAX];
    size_t level_count;       /* 0: suggest levels from the histogram */
    int labels;               /* a segmentation (segment/segment.h): a label map ("labels":
                                 true or a descriptions file), a .seg.nrrd, a DICOM SEG */
    char *labels_file;        /* its label descriptions (ITK-SNAP's, or "IDX NAME"), or NULL */
    char orientation[4];      /* "" or where the i, j, k axes point ("LPI": iso_vol_set_axes),
                                 for a file that does not say it */
} srv_catalog_entry;

typedef struct srv_catalog {
    srv_catalog_entry *entries;
    size_t count, capacity;
    size_t *slots;            /* the id index: open addressing, entry index + 1, 0 empty */
    size_t slot_count;        /* a power of two, at least twice count */
} srv_catalog;

/* 1 if id matches [A-Za-z0-9._-]{1,64}. */
int srv_catalog_id_valid(const char *id);

/* Reads a catalog file: {"volumes": [{"id", "path", "name"?, "modality"?, "levels"?,
 * "labels"?, "orientation"?}, ...]} (or the array alone); "labels": true declares a label
 * map (or a DICOM SEG) a segmentation, a string names its label descriptions too (relative
 * to the catalog). Relative paths are taken from the catalog's directory. Instead of
 * "path", "orthanc": {"url": "http://host:8042", "series": "ORTHANC-SERIES-ID"} names a
 * series on an Orthanc server (orthanc.h), and "dicomweb": {"url", "credentials"?, "study"?,
 * "series"} one on a DICOMweb archive (dicomweb.h); with "query" (a QIDO-RS query string)
 * instead of "series", every series the archive finds at start becomes a volume "ID-HASH".
 * A bad entry (bad id, duplicate id, no path, a
 * bad Orthanc URL or id) is reported on stderr with its position and skipped; a file that
 * is not such JSON is an error. */
int srv_catalog_read(const char *file, srv_catalog *out, iso_error *err);

/* The id srv_catalog_scan gives a file: its name without the last extension, and without
 * one more when the last was a compression suffix ("brain.nii.gz" -> "brain"). */
void srv_catalog_id_of(const char *file_name, char *id, size_t size);

/* Every loadable file of dir (not hidden, not the data file of a detached header) becomes
 * a volume whose id is its file name without its extension(s): "head.nhdr" -> "head",
 * "brain.nii.gz" -> "brain"; a 3D Slicer segmentation ("liver.seg.nrrd" -> "liver.seg") is a
 * segmentation; so does every subdirectory holding DICOM files (a series,
 * named by the subdirectory). Files whose id is not valid or is taken are reported and
 * skipped. Entries are sorted by id. */
int srv_catalog_scan(const char *dir, srv_catalog *out, iso_error *err);

/* The default collection: Debian's mricron-data brain templates (those installed) and
 * analytic phantoms, each with suggested levels. */
int srv_catalog_default(srv_catalog *out, iso_error *err);

/* srv_hash64 (hash.h) of an id folded to a size_t: the id index's hash, also for ids made
 * from UIDs. */
size_t srv_catalog_hash(const char *id);

/* The index of the entry with this id, or catalog->count: one hash probe sequence, never a
 * scan (a catalog may hold 100,000 studies and every request looks its volume up). */
size_t srv_catalog_find(const srv_catalog *catalog, const char *id);

void srv_catalog_free(srv_catalog *catalog);

#endif
