/* fetch.h: what every archive source (orthanc.c, dicomweb.c) shares: HTTP GETs through
 * libcurl into memory or a file under a byte limit, optional credentials read from a file,
 * and a series' files fetched into a folder, kept in the cache dir under a key that names
 * the archive, then loaded as a DICOM series (core/io/io.h).
 *
 * Errors set *upstream to 1 when the archive was unreachable or answered an error (the
 * collection retries those after a backoff), 0 when what came did not make a volume. */
#ifndef SRV_FETCH_H
#define SRV_FETCH_H

#include <curl/curl.h>
#include <stdint.h>
#include <stdio.h>

#include "io/io.h"
#include "volume/volume.h"

/* Where a GET's body goes: a growing NUL-terminated buffer (file NULL) or a file. */
typedef struct srv_fetch_sink {
    char *buf;
    size_t len, cap;
    FILE *file;
    uint64_t written, limit;   /* the transfer fails past limit bytes */
    char content_type[256];    /* the answer's Content-Type, set by srv_fetch_get, or "" */
} srv_fetch_sink;

/* A libcurl handle with the sources' settings and the credentials' header. */
typedef struct srv_fetch {
    CURL *curl;
    char authorization[1100];  /* "Authorization: Bearer ..." or "" (basic goes to libcurl) */
} srv_fetch;

/* Opens f with the sources' settings (timeouts, http/https only, no redirects).
 * credentials: a file whose first line is "bearer TOKEN" or "basic USER:PASSWORD" (read
 * now, so a rotated secret is used at the next load), or NULL. 0 or an ISO_E_* code. */
int srv_fetch_open(srv_fetch *f, const char *credentials, iso_error *err);
void srv_fetch_close(srv_fetch *f);
/* GET url into s (what: "orthanc", "dicomweb", for messages); accept: an Accept header's
 * value or NULL. 0, or an error naming the URL and the cause, *upstream set. */
int srv_fetch_get(srv_fetch *f, const char *what, const char *url, const char *accept,
                  srv_fetch_sink *s, iso_error *err, int *upstream);

/* Fetches a series' files into an existing empty folder. */
typedef int (*srv_fetch_series_fn)(void *context, const char *dir, const iso_load_options *opt,
                                   iso_error *err, int *upstream);

/* The series `name` of the archive at url (kind: "orthanc", "dicomweb": the cache's
 * subfolder): with a cache dir read from {cache}/{kind}/{archive}/{name}/ when there,
 * else fetched there by fetch (under a temporary name, renamed when complete); {archive}
 * is a hash of url, so two archives holding the same series never share files. Without a
 * cache dir, fetched into a temporary folder removed after loading. */
int srv_fetch_load(const char *kind, const char *url, const char *name, const char *cache_dir,
                   srv_fetch_series_fn fetch, void *context, const iso_load_options *opt,
                   iso_volume **out, iso_error *err, int *upstream);

/* srv_fetch_load with another loader of the folder (a segmentation, say): load(out, dir,
 * opt, err) makes what the caller gets. */
typedef int (*srv_fetch_loader_fn)(void *out, const char *dir, const iso_load_options *opt, iso_error *err);
int srv_fetch_load_with(const char *kind, const char *url, const char *name, const char *cache_dir,
                        srv_fetch_series_fn fetch, void *context, const iso_load_options *opt,
                        srv_fetch_loader_fn load, void *out, iso_error *err, int *upstream);

/* The loader of a segmentation's folder (a DICOM SEG beside the series it references):
 * out is an iso_segmentation ** (segment/segment.h). */
int srv_fetch_segmentation(void *out, const char *dir, const iso_load_options *opt, iso_error *err);

/* 1 if url is http:// or https:// followed by a host (no spaces, quotes, control bytes,
 * query or fragment; at most 1024 bytes). */
int srv_fetch_url_valid(const char *url);

#endif
