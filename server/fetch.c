/* fetch.c: HTTP GETs, credentials and the series cache of the archive sources (see fetch.h). */
#include "fetch.h"

#include <dirent.h>
#include <errno.h>
#include <pthread.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <unistd.h>

#include "base/base.h"
#include "hash.h"
#include "segment/segment.h"

int srv_fetch_url_valid(const char *url)
{
    size_t skip = !strncmp(url, "http://", 7) ? 7 : !strncmp(url, "https://", 8) ? 8 : 0;
    if (!skip || !url[skip] || url[skip] == '/' || strlen(url) > 1024)
        return 0;
    for (const char *p = url; *p; p++)
        if ((unsigned char)*p <= ' ' || *p == '"' || *p == '\\' || *p == 0x7f || *p == '#' || *p == '?')
            return 0;
    return 1;
}

static pthread_once_t curl_once = PTHREAD_ONCE_INIT;
static CURLcode curl_init_rc;

static void init_curl(void)
{
    curl_init_rc = curl_global_init(CURL_GLOBAL_DEFAULT);
}

static size_t on_data(char *data, size_t size, size_t count, void *ctx)
{
    srv_fetch_sink *s = ctx;
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

/* The credentials file's first line: "bearer TOKEN" into an Authorization header, "basic
 * USER:PASSWORD" to libcurl. Never echoes the secret in a message. */
static int read_credentials(srv_fetch *f, const char *file, iso_error *err)
{
    FILE *in = fopen(file, "r");
    char line[1024] = "";
    if (!in)
        return iso_error_set(err, ISO_E_IO, "credentials %s: %s", file, strerror(errno));
    int got = fgets(line, sizeof line, in) != NULL;
    fclose(in);
    line[strcspn(line, "\r\n")] = '\0';
    if (got && !strncmp(line, "bearer ", 7) && line[7]) {
        snprintf(f->authorization, sizeof f->authorization, "Authorization: Bearer %s", line + 7);
        return 0;
    }
    if (got && !strncmp(line, "basic ", 6) && strchr(line + 6, ':')) {
        curl_easy_setopt(f->curl, CURLOPT_HTTPAUTH, (long)CURLAUTH_BASIC);
        curl_easy_setopt(f->curl, CURLOPT_USERPWD, line + 6);
        return 0;
    }
    return iso_error_set(err, ISO_E_FORMAT, "credentials %s: the first line must be \"bearer TOKEN\" or "
                         "\"basic USER:PASSWORD\"", file);
}

int srv_fetch_open(srv_fetch *f, const char *credentials, iso_error *err)
{
    memset(f, 0, sizeof *f);
    pthread_once(&curl_once, init_curl);
    f->curl = curl_init_rc == CURLE_OK ? curl_easy_init() : NULL;
    if (!f->curl)
        return iso_error_set(err, ISO_E_NOMEM, "libcurl cannot start");
    curl_easy_setopt(f->curl, CURLOPT_NOSIGNAL, 1L);           /* threads: no SIGALRM */
    curl_easy_setopt(f->curl, CURLOPT_CONNECTTIMEOUT, 10L);
    curl_easy_setopt(f->curl, CURLOPT_LOW_SPEED_LIMIT, 1L);    /* a stalled server: give up */
    curl_easy_setopt(f->curl, CURLOPT_LOW_SPEED_TIME, 60L);
    curl_easy_setopt(f->curl, CURLOPT_PROTOCOLS_STR, "http,https");
    curl_easy_setopt(f->curl, CURLOPT_FOLLOWLOCATION, 0L);
    int rc = credentials ? read_credentials(f, credentials, err) : 0;
    if (rc)
        srv_fetch_close(f);
    return rc;
}

void srv_fetch_close(srv_fetch *f)
{
    if (f->curl)
        curl_easy_cleanup(f->curl);
    memset(f, 0, sizeof *f);
}

int srv_fetch_get(srv_fetch *f, const char *what, const char *url, const char *accept,
                  srv_fetch_sink *s, iso_error *err, int *upstream)
{
    char why[CURL_ERROR_SIZE] = "", accept_header[300];
    long status = 0;
    struct curl_slist *headers = NULL, *more;
    if (accept) {
        snprintf(accept_header, sizeof accept_header, "Accept: %s", accept);
        headers = curl_slist_append(headers, accept_header);
    }
    if (f->authorization[0] && (more = curl_slist_append(headers, f->authorization)))
        headers = more;
    curl_easy_setopt(f->curl, CURLOPT_HTTPHEADER, headers);
    curl_easy_setopt(f->curl, CURLOPT_URL, url);
    curl_easy_setopt(f->curl, CURLOPT_WRITEFUNCTION, on_data);
    curl_easy_setopt(f->curl, CURLOPT_WRITEDATA, s);
    curl_easy_setopt(f->curl, CURLOPT_ERRORBUFFER, why);
    CURLcode rc = curl_easy_perform(f->curl);
    curl_easy_getinfo(f->curl, CURLINFO_RESPONSE_CODE, &status);
    char *type = NULL;
    curl_easy_getinfo(f->curl, CURLINFO_CONTENT_TYPE, &type);
    snprintf(s->content_type, sizeof s->content_type, "%s", type ? type : "");
    curl_easy_setopt(f->curl, CURLOPT_ERRORBUFFER, NULL);
    curl_easy_setopt(f->curl, CURLOPT_HTTPHEADER, NULL);
    curl_slist_free_all(headers);
    *upstream = 1;
    if (rc == CURLE_WRITE_ERROR && s->written >= s->limit)
        return iso_error_set(err, ISO_E_LIMIT, "%s %s: more than %llu bytes; over the volume limit", what, url,
                             (unsigned long long)s->limit);
    if (rc != CURLE_OK)
        return iso_error_set(err, ISO_E_IO, "%s %s: %s", what, url, why[0] ? why : curl_easy_strerror(rc));
    if (status != 200)
        return iso_error_set(err, ISO_E_IO, "%s %s: the server answered HTTP %ld", what, url, status);
    *upstream = 0;
    return 0;
}

/* ---------------------------------------------------------------- the series cache */

/* Removes dir and the files in it (one level: a fetch writes no subdirectory). */
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

/* The archive's part of a cache key: FNV-1a (64 bits) of its base URL, in hex. A series
 * names the same instances on any archive in principle, but two archives may hold
 * different versions of it (one corrected, say), and what one of them served must never
 * be read back as the other's. */
static void archive_key(const char *url, char key[17])
{
    snprintf(key, 17, "%016llx", (unsigned long long)srv_hash64(url));
}

/* Fetches into {final}.partial-PID, then renames it into place; parents made as needed. */
static int fetch_into_cache(const char *final, srv_fetch_series_fn fetch, void *context,
                            const iso_load_options *opt, iso_error *err, int *upstream)
{
    char partial[4200], parent[4200];
    snprintf(partial, sizeof partial, "%s.partial-%ld", final, (long)getpid());
    snprintf(parent, sizeof parent, "%s", final);
    for (char *p = parent + 1; (p = strchr(p, '/')); p++) { /* mkdir -p of final's parent */
        *p = '\0';
        if (mkdir(parent, 0755) && errno != EEXIST)
            return iso_error_set(err, ISO_E_IO, "%s: cannot create: %s", parent, strerror(errno));
        *p = '/';
    }
    if (mkdir(partial, 0755))
        return iso_error_set(err, ISO_E_IO, "%s: cannot create: %s", partial, strerror(errno));
    int rc = fetch(context, partial, opt, err, upstream);
    if (!rc && rename(partial, final) && errno != ENOTEMPTY && errno != EEXIST)
        rc = iso_error_set(err, ISO_E_IO, "%s: cannot rename into place: %s", final, strerror(errno));
    if (rc || access(partial, F_OK) == 0) /* failed, or another fetch got there first */
        remove_dir(partial);
    return rc;
}

/* The volume loader of srv_fetch_load. */
static int load_volume(void *out, const char *dir, const iso_load_options *opt, iso_error *err)
{
    return iso_load(dir, opt, (iso_volume **)out, err);
}

int srv_fetch_segmentation(void *out, const char *dir, const iso_load_options *opt, iso_error *err)
{
    return iso_seg_load(dir, NULL, opt, (iso_segmentation **)out, err);
}

int srv_fetch_load(const char *kind, const char *url, const char *name, const char *cache_dir,
                   srv_fetch_series_fn fetch, void *context, const iso_load_options *opt,
                   iso_volume **out, iso_error *err, int *upstream)
{
    *out = NULL;
    return srv_fetch_load_with(kind, url, name, cache_dir, fetch, context, opt, load_volume, out, err, upstream);
}

int srv_fetch_load_with(const char *kind, const char *url, const char *name, const char *cache_dir,
                        srv_fetch_series_fn fetch, void *context, const iso_load_options *opt,
                        srv_fetch_loader_fn load, void *out, iso_error *err, int *upstream)
{
    char dir[4096];
    int rc;
    struct stat st;
    *upstream = 0;
    if (cache_dir) {
        char key[17];
        archive_key(url, key);
        snprintf(dir, sizeof dir, "%s/%s/%s/%s", cache_dir, kind, key, name);
        rc = stat(dir, &st) == 0 && S_ISDIR(st.st_mode) ? 0 : fetch_into_cache(dir, fetch, context, opt, err, upstream);
    } else {
        const char *t = getenv("TMPDIR");
        snprintf(dir, sizeof dir, "%s/isoserve-%s-XXXXXX", t && *t ? t : "/tmp", kind);
        rc = mkdtemp(dir) ? fetch(context, dir, opt, err, upstream)
                          : iso_error_set(err, ISO_E_IO, "%s: cannot create: %s", dir, strerror(errno));
    }
    if (!rc)
        rc = load(out, dir, opt, err);
    if (!cache_dir)
        remove_dir(dir);
    return rc;
}
