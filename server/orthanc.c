/* orthanc.c: series fetched from Orthanc's REST API and cached on disk (see orthanc.h). */
#include "orthanc.h"

#include <curl/curl.h>
#include <dirent.h>
#include <errno.h>
#include <jansson.h>
#include <pthread.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <unistd.h>

#include "cli.h"
#include "base/base.h"

/* The series document lists ids only: a few hundred bytes per instance. */
#define SERIES_JSON_MAX ((size_t)16 << 20)
/* Besides its pixels an instance carries its header: allowed on top of the volume cap. */
#define HEADER_ALLOWANCE ((uint64_t)1 << 20)

int srv_orthanc_url_valid(const char *url)
{
    size_t skip = !strncmp(url, "http://", 7) ? 7 : !strncmp(url, "https://", 8) ? 8 : 0;
    if (!skip || !url[skip] || url[skip] == '/' || strlen(url) > 1024)
        return 0;
    for (const char *p = url; *p; p++)
        if ((unsigned char)*p <= ' ' || *p == '"' || *p == '\\' || *p == 0x7f || *p == '#' || *p == '?')
            return 0;
    return 1;
}

int srv_orthanc_id_valid(const char *id)
{
    size_t n = strlen(id);
    return n >= 1 && n <= 64 && strspn(id, "0123456789abcdef-") == n;
}

static pthread_once_t curl_once = PTHREAD_ONCE_INIT;
static CURLcode curl_init_rc;

static void init_curl(void)
{
    curl_init_rc = curl_global_init(CURL_GLOBAL_DEFAULT);
}

/* ---------------------------------------------------------------- one request */

typedef struct sink {
    char *buf;      /* memory target (the series JSON), or NULL */
    size_t len, cap;
    FILE *file;     /* file target (an instance), or NULL */
    uint64_t written, limit;
} sink;

static size_t on_data(char *data, size_t size, size_t count, void *ctx)
{
    sink *s = ctx;
    size_t n = size * count;
    if (s->written + n > s->limit)
        return 0; /* aborts the transfer: over the limit */
    s->written += n;
    if (s->file)
        return fwrite(data, 1, n, s->file);
    if (s->len + n + 1 > s->cap) {
        size_t cap = (s->len + n + 1) * 2;
        char *grown = realloc(s->buf, cap);
        if (!grown)
            return 0;
        s->buf = grown;
        s->cap = cap;
    }
    memcpy(s->buf + s->len, data, n);
    s->len += n;
    s->buf[s->len] = '\0';
    return n;
}

/* GET url into the sink; 0, or an error naming the URL and the cause (*upstream set). */
static int get(CURL *curl, const char *url, sink *s, iso_error *err, int *upstream)
{
    char why[CURL_ERROR_SIZE] = "";
    long status = 0;
    curl_easy_setopt(curl, CURLOPT_URL, url);
    curl_easy_setopt(curl, CURLOPT_WRITEFUNCTION, on_data);
    curl_easy_setopt(curl, CURLOPT_WRITEDATA, s);
    curl_easy_setopt(curl, CURLOPT_ERRORBUFFER, why);
    CURLcode rc = curl_easy_perform(curl);
    curl_easy_getinfo(curl, CURLINFO_RESPONSE_CODE, &status);
    curl_easy_setopt(curl, CURLOPT_ERRORBUFFER, NULL);
    *upstream = 1;
    if (rc == CURLE_WRITE_ERROR && s->written >= s->limit)
        return iso_error_set(err, ISO_E_LIMIT, "orthanc %s: more than %llu bytes; over the volume limit", url,
                             (unsigned long long)s->limit);
    if (rc != CURLE_OK)
        return iso_error_set(err, ISO_E_IO, "orthanc %s: %s", url, why[0] ? why : curl_easy_strerror(rc));
    if (status != 200)
        return iso_error_set(err, ISO_E_IO, "orthanc %s: the server answered HTTP %ld", url, status);
    *upstream = 0;
    return 0;
}

static CURL *open_curl(iso_error *err)
{
    pthread_once(&curl_once, init_curl);
    CURL *curl = curl_init_rc == CURLE_OK ? curl_easy_init() : NULL;
    if (!curl) {
        iso_error_set(err, ISO_E_NOMEM, "orthanc: libcurl cannot start");
        return NULL;
    }
    curl_easy_setopt(curl, CURLOPT_NOSIGNAL, 1L);           /* threads: no SIGALRM */
    curl_easy_setopt(curl, CURLOPT_CONNECTTIMEOUT, 10L);
    curl_easy_setopt(curl, CURLOPT_LOW_SPEED_LIMIT, 1L);    /* a stalled server: give up */
    curl_easy_setopt(curl, CURLOPT_LOW_SPEED_TIME, 60L);
    curl_easy_setopt(curl, CURLOPT_PROTOCOLS_STR, "http,https");
    curl_easy_setopt(curl, CURLOPT_FOLLOWLOCATION, 0L);
    return curl;
}

/* ---------------------------------------------------------------- the series */

/* The instance ids of the series, from GET {url}/series/{id}. */
static int list_instances(CURL *curl, const char *url, const char *series, json_t **ids, iso_error *err,
                          int *upstream)
{
    char target[1200];
    snprintf(target, sizeof target, "%s/series/%s", url, series);
    sink s = {.limit = SERIES_JSON_MAX};
    int rc = get(curl, target, &s, err, upstream);
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
static int fetch_instances(CURL *curl, const char *url, const char *series, json_t *ids, const char *dir,
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
        sink s = {.file = fopen(file, "wb"), .limit = budget - total};
        if (!s.file)
            return iso_error_set(err, ISO_E_IO, "%s: cannot write: %s", file, strerror(errno));
        int rc = get(curl, target, &s, err, upstream);
        if (fclose(s.file) && !rc)
            rc = iso_error_set(err, ISO_E_IO, "%s: cannot write: %s", file, strerror(errno));
        if (rc)
            return rc;
        total += s.written;
        srv_progress(label, (double)(i + 1) / (double)n);
    }
    return 0;
}

/* Removes dir and the files in it (one level: the fetch writes no subdirectory). */
static void remove_dir(const char *dir)
{
    DIR *d = opendir(dir);
    struct dirent *ent;
    char path[4096];
    while (d && (ent = readdir(d)))
        if (strcmp(ent->d_name, ".") && strcmp(ent->d_name, "..") &&
            snprintf(path, sizeof path, "%s/%s", dir, ent->d_name) < (int)sizeof path)
            unlink(path);
    if (d)
        closedir(d);
    rmdir(dir);
}

/* Lists and fetches the series into dir (which exists). */
static int fetch_series(const char *url, const char *series, const char *dir, const iso_load_options *opt,
                        iso_error *err, int *upstream)
{
    CURL *curl = open_curl(err);
    if (!curl)
        return ISO_E_NOMEM;
    json_t *ids = NULL;
    double start = iso_clock_ms();
    int rc = list_instances(curl, url, series, &ids, err, upstream);
    uint64_t cap = opt && opt->max_bytes ? opt->max_bytes : ISO_VOL_DEFAULT_MAX_BYTES;
    if (!rc)
        rc = fetch_instances(curl, url, series, ids, dir, cap + HEADER_ALLOWANCE * json_array_size(ids), err,
                             upstream);
    if (!rc)
        fprintf(stderr, "isoserve: orthanc %s/series/%s: %zu instances fetched in %.0f ms\n", url, series,
                json_array_size(ids), iso_clock_ms() - start);
    json_decref(ids);
    curl_easy_cleanup(curl);
    return rc;
}

/* The archive's part of a cache key: FNV-1a (64 bits) of its base URL, in hex. A series id
 * names the same instances on any Orthanc, but two archives may hold different versions of
 * a series (one corrected, say), and what one of them served must never be read back as
 * the other's. */
static void archive_key(const char *url, char key[17])
{
    uint64_t h = 14695981039346656037ull;
    for (const unsigned char *p = (const unsigned char *)url; *p; p++)
        h = (h ^ *p) * 1099511628211ull;
    snprintf(key, 17, "%016llx", (unsigned long long)h);
}

/* Fetches into {cache}/orthanc/{archive}/{series}.partial-PID, then renames it into place. */
static int fetch_into_cache(const char *url, const char *series, const char *cache_dir, const char *final,
                            const iso_load_options *opt, iso_error *err, int *upstream)
{
    char parent[4096], archive[4200], partial[4200], key[17];
    archive_key(url, key);
    snprintf(parent, sizeof parent, "%s/orthanc", cache_dir);
    snprintf(archive, sizeof archive, "%s/orthanc/%s", cache_dir, key);
    snprintf(partial, sizeof partial, "%s.partial-%ld", final, (long)getpid());
    if ((mkdir(cache_dir, 0755) && errno != EEXIST) || (mkdir(parent, 0755) && errno != EEXIST) ||
        (mkdir(archive, 0755) && errno != EEXIST) || mkdir(partial, 0755))
        return iso_error_set(err, ISO_E_IO, "%s: cannot create: %s", partial, strerror(errno));
    int rc = fetch_series(url, series, partial, opt, err, upstream);
    if (!rc && rename(partial, final) && errno != ENOTEMPTY && errno != EEXIST)
        rc = iso_error_set(err, ISO_E_IO, "%s: cannot rename into place: %s", final, strerror(errno));
    if (rc || access(partial, F_OK) == 0) /* failed, or another fetch got there first */
        remove_dir(partial);
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
    char dir[4096];
    int rc;
    struct stat st;
    if (cache_dir) {
        char key[17];
        archive_key(url, key);
        snprintf(dir, sizeof dir, "%s/orthanc/%s/%s", cache_dir, key, series);
        rc = stat(dir, &st) == 0 && S_ISDIR(st.st_mode) ? 0
                                                        : fetch_into_cache(url, series, cache_dir, dir, opt, err, upstream);
    } else {
        const char *t = getenv("TMPDIR");
        snprintf(dir, sizeof dir, "%s/isoserve-orthanc-XXXXXX", t && *t ? t : "/tmp");
        rc = mkdtemp(dir) ? fetch_series(url, series, dir, opt, err, upstream)
                          : iso_error_set(err, ISO_E_IO, "%s: cannot create: %s", dir, strerror(errno));
    }
    if (!rc)
        rc = iso_load(dir, opt, out, err);
    if (!cache_dir)
        remove_dir(dir);
    return rc;
}
