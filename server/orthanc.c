/* orthanc.c: series fetched from Orthanc's REST API and cached on disk (see orthanc.h). */
#include "orthanc.h"

#include <errno.h>
#include <jansson.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "cli.h"
#include "base/base.h"
#include "fetch.h"
#include "segment/segment.h"

/* The series document lists ids only: a few hundred bytes per instance. */
#define SERIES_JSON_MAX ((size_t)16 << 20)
/* Besides its pixels an instance carries its header: allowed on top of the volume cap. */
#define HEADER_ALLOWANCE ((uint64_t)1 << 20)

int srv_orthanc_url_valid(const char *url)
{
    return srv_fetch_url_valid(url);
}

int srv_orthanc_id_valid(const char *id)
{
    size_t n = strlen(id);
    return n >= 1 && n <= 64 && strspn(id, "0123456789abcdef-") == n;
}

/* ---------------------------------------------------------------- the series */

/* The instance ids of the series, from GET {url}/series/{id}. */
static int list_instances(srv_fetch *f, const char *url, const char *series, json_t **ids, iso_error *err,
                          int *upstream)
{
    char target[1200];
    snprintf(target, sizeof target, "%s/series/%s", url, series);
    srv_fetch_sink s = {.limit = SERIES_JSON_MAX};
    int rc = srv_fetch_get(f, "orthanc", target, NULL, &s, err, upstream);
    json_t *doc = rc ? NULL : json_loads(s.buf ? s.buf : "", 0, NULL);
    free(s.buf);
    if (rc)
        return rc;
    json_t *list = json_object_get(doc, "Instances");
    *upstream = 1;
    if (!json_is_array(list) || json_array_size(list) == 0) {
        json_decref(doc);
        return iso_error_set(err, ISO_E_FORMAT, "orthanc %s: not a series document with \"Instances\"", target);
    }
    for (size_t i = 0; i < json_array_size(list); i++) {
        const char *id = json_string_value(json_array_get(list, i));
        if (!id || !srv_orthanc_id_valid(id)) {
            json_decref(doc);
            return iso_error_set(err, ISO_E_FORMAT, "orthanc %s: instance %zu has no valid id", target, i);
        }
    }
    *ids = json_incref(list);
    json_decref(doc);
    *upstream = 0;
    return 0;
}

/* Every instance's file into dir, with progress; budget caps the bytes of them all. */
static int fetch_instances(srv_fetch *f, const char *url, const char *series, json_t *ids, const char *dir,
                           uint64_t budget, iso_error *err, int *upstream)
{
    char label[160], target[1200], file[4096];
    snprintf(label, sizeof label, "isoserve: orthanc series %.20s...: fetching", series);
    size_t n = json_array_size(ids);
    uint64_t total = 0;
    for (size_t i = 0; i < n; i++) {
        const char *id = json_string_value(json_array_get(ids, i));
        snprintf(target, sizeof target, "%s/instances/%s/file", url, id);
        snprintf(file, sizeof file, "%s/%s.dcm", dir, id);
        srv_fetch_sink s = {.file = fopen(file, "wb"), .limit = budget - total};
        if (!s.file)
            return iso_error_set(err, ISO_E_IO, "%s: cannot write: %s", file, strerror(errno));
        int rc = srv_fetch_get(f, "orthanc", target, NULL, &s, err, upstream);
        if (fclose(s.file) && !rc)
            rc = iso_error_set(err, ISO_E_IO, "%s: cannot write: %s", file, strerror(errno));
        if (rc)
            return rc;
        total += s.written;
        srv_progress(label, (double)(i + 1) / (double)n);
    }
    return 0;
}

typedef struct orthanc_series {
    const char *url, *series;
    int with_reference;   /* a SEG: the series it references is fetched beside it */
} orthanc_series;

/* The Orthanc id of the series whose SeriesInstanceUID is uid, in the study of series
 * `beside` (GET {url}/series/{beside} for its ParentStudy, then GET
 * {url}/studies/{study}/series). */
static int find_in_study(srv_fetch *f, const char *url, const char *beside, const char *uid, char *id, size_t size,
                         iso_error *err, int *upstream)
{
    char target[1200];
    snprintf(target, sizeof target, "%s/series/%s", url, beside);
    srv_fetch_sink s = {.limit = SERIES_JSON_MAX};
    int rc = srv_fetch_get(f, "orthanc", target, NULL, &s, err, upstream);
    json_t *doc = rc ? NULL : json_loads(s.buf ? s.buf : "", 0, NULL);
    free(s.buf);
    const char *study = json_string_value(json_object_get(doc, "ParentStudy"));
    if (!rc && (!study || !srv_orthanc_id_valid(study)))
        rc = iso_error_set(err, ISO_E_FORMAT, "orthanc %s: no \"ParentStudy\"", target);
    if (!rc) {
        snprintf(target, sizeof target, "%s/studies/%s/series", url, study);
        s = (srv_fetch_sink){.limit = SERIES_JSON_MAX};
        rc = srv_fetch_get(f, "orthanc", target, NULL, &s, err, upstream);
    }
    json_t *list = rc ? NULL : json_loads(s.buf ? s.buf : "", 0, NULL);
    if (!rc)
        free(s.buf);
    json_decref(doc);
    size_t i;
    json_t *item;
    id[0] = '\0';
    json_array_foreach(list, i, item) {
        const char *series_uid = json_string_value(json_object_get(json_object_get(item, "MainDicomTags"), "SeriesInstanceUID"));
        const char *series_id = json_string_value(json_object_get(item, "ID"));
        if (series_uid && series_id && !strcmp(series_uid, uid) && srv_orthanc_id_valid(series_id))
            snprintf(id, size, "%s", series_id);
    }
    json_decref(list);
    if (!rc && !id[0])
        rc = iso_error_set(err, ISO_E_FORMAT, "orthanc %s: the segmentation's study holds no series %s (the images it "
                           "segments)", target, uid);
    return rc;
}

/* Lists and fetches the series into dir (which exists): an srv_fetch_series_fn. */
static int fetch_series(void *context, const char *dir, const iso_load_options *opt, iso_error *err,
                        int *upstream)
{
    const orthanc_series *o = context;
    srv_fetch f;
    int rc = srv_fetch_open(&f, NULL, err);
    if (rc)
        return rc;
    json_t *ids = NULL;
    double start = iso_clock_ms();
    rc = list_instances(&f, o->url, o->series, &ids, err, upstream);
    uint64_t cap = opt && opt->max_bytes ? opt->max_bytes : ISO_VOL_DEFAULT_MAX_BYTES;
    if (!rc)
        rc = fetch_instances(&f, o->url, o->series, ids, dir, cap + HEADER_ALLOWANCE * json_array_size(ids), err,
                             upstream);
    if (!rc)
        fprintf(stderr, "isoserve: orthanc %s/series/%s: %zu instances fetched in %.0f ms\n", o->url, o->series,
                json_array_size(ids), iso_clock_ms() - start);
    json_decref(ids);
    /* A segmentation: the series it was derived from, beside it. */
    char reference[80], id[80];
    if (!rc && o->with_reference && !(rc = iso_seg_dicom_referenced_series(dir, reference, sizeof reference, err)) &&
        !(rc = find_in_study(&f, o->url, o->series, reference, id, sizeof id, err, upstream)) &&
        !(rc = list_instances(&f, o->url, id, &ids, err, upstream))) {
        rc = fetch_instances(&f, o->url, id, ids, dir, cap + HEADER_ALLOWANCE * json_array_size(ids), err, upstream);
        json_decref(ids);
    }
    srv_fetch_close(&f);
    return rc;
}

int srv_orthanc_load(const char *url, const char *series, const char *cache_dir,
                     const iso_load_options *opt, iso_volume **out, iso_error *err, int *upstream)
{
    *out = NULL;
    *upstream = 0;
    if (!srv_orthanc_url_valid(url) || !srv_orthanc_id_valid(series))
        return iso_error_set(err, ISO_E_ARGUMENT, "orthanc \"%s\" series \"%s\": not an http(s) URL and an Orthanc id",
                             url, series);
    orthanc_series o = {url, series, 0};
    return srv_fetch_load("orthanc", url, series, cache_dir, fetch_series, &o, opt, out, err, upstream);
}

int srv_orthanc_load_segmentation(const char *url, const char *series, const char *cache_dir,
                                  const iso_load_options *opt, iso_segmentation **out, iso_error *err, int *upstream)
{
    *out = NULL;
    *upstream = 0;
    if (!srv_orthanc_url_valid(url) || !srv_orthanc_id_valid(series))
        return iso_error_set(err, ISO_E_ARGUMENT, "orthanc \"%s\" series \"%s\": not an http(s) URL and an Orthanc id",
                             url, series);
    orthanc_series o = {url, series, 1};
    return srv_fetch_load_with("orthanc", url, series, cache_dir, fetch_series, &o, opt, srv_fetch_segmentation, out, err,
                               upstream);
}
