/* dicomweb.c: QIDO-RS searches and WADO-RS series retrievals (see dicomweb.h). */
#include "dicomweb.h"

#include <errno.h>
#include <fcntl.h>
#include <jansson.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <strings.h>
#include <sys/mman.h>
#include <sys/stat.h>
#include <unistd.h>

#include "base/base.h"
#include "fetch.h"
#include "multipart.h"
#include "segment/segment.h"

/* A QIDO-RS answer: a few hundred bytes per series. */
#define QIDO_JSON_MAX ((uint64_t)64 << 20)
/* Besides the pixels, the answer carries each instance's header and its part's framing:
 * allowed on top of the volume cap (a few KB per instance in practice). */
#define ANSWER_ALLOWANCE ((uint64_t)256 << 20)
#define INSTANCES_MAX 20000

static const char ACCEPT_SERIES[] = "multipart/related; type=\"application/dicom\"; transfer-syntax=*";

int srv_dicomweb_uid_valid(const char *uid)
{
    size_t n = strlen(uid);
    return n >= 1 && n <= SRV_UID_MAX && strspn(uid, "0123456789.") == n;
}

/* The first value of attribute tag (8 hex digits) in a DICOM JSON object, as a string
 * (a person name's Alphabetic part), or NULL. */
static const char *first_value(json_t *item, const char *tag)
{
    json_t *v = json_array_get(json_object_get(json_object_get(item, tag), "Value"), 0);
    if (json_is_object(v))
        v = json_object_get(v, "Alphabetic");
    return json_string_value(v);
}

int srv_dicomweb_find(const char *url, const char *query, const char *credentials,
                      srv_dicomweb_series **out, size_t *count, iso_error *err, int *upstream)
{
    *out = NULL;
    *count = 0;
    *upstream = 0;
    srv_fetch f;
    int rc = srv_fetch_open(&f, credentials, err);
    if (rc)
        return rc;
    char target[2400];
    snprintf(target, sizeof target, "%s/series?%s%sincludefield=00080060&includefield=0008103E", url,
             query, query[0] ? "&" : "");
    srv_fetch_sink s = {.limit = QIDO_JSON_MAX};
    rc = srv_fetch_get(&f, "dicomweb", target, "application/dicom+json", &s, err, upstream);
    srv_fetch_close(&f);
    json_t *doc = rc ? NULL : json_loads(s.buf ? s.buf : "[]", 0, NULL);
    free(s.buf);
    if (rc)
        return rc;
    if (!json_is_array(doc)) {
        json_decref(doc);
        *upstream = 1;
        return iso_error_set(err, ISO_E_FORMAT, "dicomweb %s: not a DICOM JSON array of series", target);
    }
    size_t n = json_array_size(doc);
    *out = calloc(n ? n : 1, sizeof **out);
    if (!*out) {
        json_decref(doc);
        return iso_error_set(err, ISO_E_NOMEM, "out of memory reading %s", target);
    }
    for (size_t i = 0; i < n; i++) {
        json_t *item = json_array_get(doc, i);
        const char *study = first_value(item, "0020000D"), *series = first_value(item, "0020000E");
        const char *modality = first_value(item, "00080060"), *description = first_value(item, "0008103E");
        if (!study || !series || !srv_dicomweb_uid_valid(study) || !srv_dicomweb_uid_valid(series))
            continue;
        srv_dicomweb_series *e = &(*out)[(*count)++];
        snprintf(e->study, sizeof e->study, "%s", study);
        snprintf(e->series, sizeof e->series, "%s", series);
        snprintf(e->modality, sizeof e->modality, "%s", modality ? modality : "");
        snprintf(e->description, sizeof e->description, "%s", description ? description : "");
    }
    json_decref(doc);
    return 0;
}

/* ---------------------------------------------------------------- WADO-RS */

typedef struct wado_series {
    const char *url, *study, *series, *credentials;
    const char *prefix;  /* of the instances' file names ("" or NULL: none) */
    int with_reference;  /* a SEG: the series it references is fetched beside it */
} wado_series;

typedef struct part_writer {
    const char *dir, *prefix;
    size_t written;
    iso_error *err;
} part_writer;

/* One part of the answer: an instance, written as {dir}/{n}.dcm. */
static int write_part(void *context, const char *headers, size_t header_len, const char *body, size_t len)
{
    part_writer *w = context;
    char type[128], file[4200];
    if (!proto_multipart_header(headers, header_len, "Content-Type", type, sizeof type) &&
        strncasecmp(type, "application/dicom", 17))
        return iso_error_set(w->err, ISO_E_FORMAT, "part %zu is %s, not application/dicom", w->written + 1, type);
    if (w->written == INSTANCES_MAX)
        return iso_error_set(w->err, ISO_E_LIMIT, "more than %d instances", INSTANCES_MAX);
    snprintf(file, sizeof file, "%s/%s%06zu.dcm", w->dir, w->prefix, w->written);
    FILE *out = fopen(file, "wb");
    int ok = out && fwrite(body, 1, len, out) == len;
    if (out && fclose(out))
        ok = 0;
    if (!ok)
        return iso_error_set(w->err, ISO_E_IO, "%s: cannot write: %s", file, strerror(errno));
    w->written++;
    return 0;
}

/* Splits the multipart answer in file into the instances' files of dir. */
static int split_answer(const char *file, const char *content_type, const char *dir, const char *prefix,
                        const char *target, iso_error *err, int *upstream)
{
    char boundary[PROTO_BOUNDARY_MAX + 1];
    *upstream = 1; /* what the archive sent is not what it should be */
    if (proto_multipart_boundary(content_type, boundary))
        return iso_error_set(err, ISO_E_FORMAT, "dicomweb %s: answered \"%s\", not multipart/related with a boundary",
                             target, content_type);
    int fd = open(file, O_RDONLY);
    struct stat st;
    if (fd < 0 || fstat(fd, &st) || st.st_size == 0) {
        if (fd >= 0)
            close(fd);
        return iso_error_set(err, ISO_E_FORMAT, "dicomweb %s: an empty answer", target);
    }
    void *map = mmap(NULL, (size_t)st.st_size, PROT_READ, MAP_PRIVATE, fd, 0);
    close(fd);
    if (map == MAP_FAILED)
        return iso_error_set(err, ISO_E_IO, "%s: cannot map: %s", file, strerror(errno));
    part_writer w = {.dir = dir, .prefix = prefix ? prefix : "", .err = err};
    iso_error why = {0};
    size_t where = 0;
    w.err = &why;
    int rc = proto_multipart_split(map, (size_t)st.st_size, boundary, write_part, &w, &where);
    munmap(map, (size_t)st.st_size);
    if (rc == -1)
        return iso_error_set(err, ISO_E_FORMAT, "dicomweb %s: malformed multipart answer at byte %zu", target, where);
    if (rc)
        return iso_error_set(err, rc, "dicomweb %s: %s", target, why.message);
    if (w.written == 0)
        return iso_error_set(err, ISO_E_FORMAT, "dicomweb %s: no instances in the answer", target);
    *upstream = 0;
    return 0;
}

/* The series' study from a QIDO-RS lookup by series UID. */
static int find_study(const wado_series *w, char study[SRV_UID_MAX + 1], iso_error *err, int *upstream)
{
    char query[100];
    srv_dicomweb_series *found;
    size_t n;
    snprintf(query, sizeof query, "SeriesInstanceUID=%s", w->series);
    int rc = srv_dicomweb_find(w->url, query, w->credentials, &found, &n, err, upstream);
    if (rc)
        return rc;
    if (n)
        snprintf(study, SRV_UID_MAX + 1, "%s", found[0].study);
    free(found);
    if (!n) {
        *upstream = 1;
        return iso_error_set(err, ISO_E_IO, "dicomweb %s: no series %s", w->url, w->series);
    }
    return 0;
}

/* Retrieves the series into dir (which exists): an srv_fetch_series_fn. */
static int fetch_series(void *context, const char *dir, const iso_load_options *opt, iso_error *err,
                        int *upstream)
{
    const wado_series *w = context;
    char study[SRV_UID_MAX + 1], target[1400], file[4200];
    snprintf(study, sizeof study, "%s", w->study ? w->study : "");
    int rc = study[0] ? 0 : find_study(w, study, err, upstream);
    if (rc)
        return rc;
    snprintf(target, sizeof target, "%s/studies/%s/series/%s", w->url, study, w->series);
    snprintf(file, sizeof file, "%s/.answer", dir);
    srv_fetch f;
    if ((rc = srv_fetch_open(&f, w->credentials, err)))
        return rc;
    uint64_t cap = opt && opt->max_bytes ? opt->max_bytes : ISO_VOL_DEFAULT_MAX_BYTES;
    srv_fetch_sink s = {.file = fopen(file, "wb"), .limit = cap + ANSWER_ALLOWANCE};
    double start = iso_clock_ms();
    if (!s.file)
        rc = iso_error_set(err, ISO_E_IO, "%s: cannot write: %s", file, strerror(errno));
    else
        rc = srv_fetch_get(&f, "dicomweb", target, ACCEPT_SERIES, &s, err, upstream);
    if (s.file && fclose(s.file) && !rc)
        rc = iso_error_set(err, ISO_E_IO, "%s: cannot write: %s", file, strerror(errno));
    srv_fetch_close(&f);
    if (!rc)
        rc = split_answer(file, s.content_type, dir, w->prefix, target, err, upstream);
    unlink(file);
    if (!rc)
        fprintf(stderr, "isoserve: dicomweb %s: %llu bytes fetched in %.0f ms\n", target,
                (unsigned long long)s.written, iso_clock_ms() - start);
    if (rc || !w->with_reference)
        return rc;
    /* A segmentation: the series it was derived from, found by QIDO-RS, beside it. */
    char reference[SRV_UID_MAX + 1];
    if ((rc = iso_seg_dicom_referenced_series(dir, reference, sizeof reference, err)))
        return rc;
    if (!srv_dicomweb_uid_valid(reference))
        return iso_error_set(err, ISO_E_FORMAT, "dicomweb %s: the segmentation references \"%s\", not a UID", target,
                             reference);
    wado_series ref = {.url = w->url, .series = reference, .credentials = w->credentials, .prefix = "ref-"};
    return fetch_series(&ref, dir, opt, err, upstream);
}

int srv_dicomweb_load_segmentation(const char *url, const char *study, const char *series, const char *credentials,
                                   const char *cache_dir, const iso_load_options *opt, iso_segmentation **out,
                                   iso_error *err, int *upstream)
{
    *out = NULL;
    *upstream = 0;
    if (!srv_fetch_url_valid(url) || !srv_dicomweb_uid_valid(series) || (study && study[0] && !srv_dicomweb_uid_valid(study)))
        return iso_error_set(err, ISO_E_ARGUMENT, "dicomweb \"%s\" series \"%s\": not an http(s) URL and DICOM UIDs",
                             url, series);
    wado_series w = {url, study, series, credentials, "", 1};
    return srv_fetch_load_with("dicomweb", url, series, cache_dir, fetch_series, &w, opt, srv_fetch_segmentation, out, err,
                               upstream);
}

int srv_dicomweb_load(const char *url, const char *study, const char *series, const char *credentials,
                      const char *cache_dir, const iso_load_options *opt, iso_volume **out,
                      iso_error *err, int *upstream)
{
    *out = NULL;
    *upstream = 0;
    if (!srv_fetch_url_valid(url) || !srv_dicomweb_uid_valid(series) || (study && study[0] && !srv_dicomweb_uid_valid(study)))
        return iso_error_set(err, ISO_E_ARGUMENT, "dicomweb \"%s\" series \"%s\": not an http(s) URL and DICOM UIDs",
                             url, series);
    wado_series w = {url, study, series, credentials, "", 0};
    return srv_fetch_load("dicomweb", url, series, cache_dir, fetch_series, &w, opt, out, err, upstream);
}
