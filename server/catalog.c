/* catalog.c: catalog files, volume directories and the default collection (see catalog.h). */
#include "catalog.h"

#include <dirent.h>
#include <jansson.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <unistd.h>

#include "io/io.h"
#include "segment/segment.h"
#include "dicomweb.h"
#include "fetch.h"
#include "hash.h"
#include "orthanc.h"

int srv_catalog_id_valid(const char *id)
{
    size_t n = strlen(id);
    if (n < 1 || n > SRV_ID_MAX || id[0] == '.') /* ".", ".." and hidden names: never path-like */
        return 0;
    return strspn(id, "ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789._-") == n;
}

static void free_entry(srv_catalog_entry *e)
{
    free(e->path);
    free(e->name);
    free(e->modality);
    free(e->orthanc_url);
    free(e->orthanc_series);
    free(e->dicomweb_url);
    free(e->dicomweb_study);
    free(e->dicomweb_series);
    free(e->dicomweb_credentials);
    free(e->labels_file);
}

void srv_catalog_free(srv_catalog *catalog)
{
    if (!catalog)
        return;
    for (size_t i = 0; i < catalog->count; i++)
        free_entry(&catalog->entries[i]);
    free(catalog->entries);
    free(catalog->slots);
    memset(catalog, 0, sizeof *catalog);
}

/* ---------------------------------------------------------------- the id index */

size_t srv_catalog_hash(const char *id)
{
    uint64_t h = srv_hash64(id);
    return (size_t)(h ^ (h >> 32));
}

size_t srv_catalog_find(const srv_catalog *catalog, const char *id)
{
    if (!catalog->slot_count)
        return catalog->count;
    size_t mask = catalog->slot_count - 1;
    for (size_t s = srv_catalog_hash(id) & mask;; s = (s + 1) & mask) {
        size_t at = catalog->slots[s];
        if (!at)
            return catalog->count;
        if (!strcmp(catalog->entries[at - 1].id, id))
            return at - 1;
    }
}

static int has_id(const srv_catalog *catalog, const char *id)
{
    return srv_catalog_find(catalog, id) < catalog->count;
}

/* Rebuilds the index for every entry, with at least twice as many slots (linear probing
 * stays short below half full). 0 or ISO_E_NOMEM. */
static int reindex(srv_catalog *catalog, size_t want, iso_error *err)
{
    size_t slots = 16;
    while (slots < 2 * want)
        slots *= 2;
    size_t *table = calloc(slots, sizeof *table);
    if (!table)
        return iso_error_set(err, ISO_E_NOMEM, "out of memory indexing the catalog");
    for (size_t i = 0; i < catalog->count; i++) {
        size_t s = srv_catalog_hash(catalog->entries[i].id) & (slots - 1);
        while (table[s])
            s = (s + 1) & (slots - 1);
        table[s] = i + 1;
    }
    free(catalog->slots);
    catalog->slots = table;
    catalog->slot_count = slots;
    return 0;
}

/* Appends an entry (copies every string). Returns 0, or ISO_E_NOMEM. */
static int add(srv_catalog *catalog, const char *id, const char *path, const char *name,
               const char *modality, const double *levels, size_t level_count, iso_error *err)
{
    if (catalog->count == catalog->capacity) {
        size_t cap = catalog->capacity ? 2 * catalog->capacity : 16;
        srv_catalog_entry *grown = realloc(catalog->entries, cap * sizeof *grown);
        if (!grown)
            return iso_error_set(err, ISO_E_NOMEM, "out of memory reading the catalog");
        catalog->entries = grown;
        catalog->capacity = cap;
    }
    if (2 * (catalog->count + 1) > catalog->slot_count && reindex(catalog, catalog->count + 1, err))
        return ISO_E_NOMEM;
    srv_catalog_entry *e = &catalog->entries[catalog->count];
    memset(e, 0, sizeof *e);
    snprintf(e->id, sizeof e->id, "%s", id);
    e->path = strdup(path);
    e->name = strdup(name ? name : "");
    e->modality = strdup(modality ? modality : "");
    if (!e->path || !e->name || !e->modality) {
        free(e->path);
        free(e->name);
        free(e->modality);
        return iso_error_set(err, ISO_E_NOMEM, "out of memory reading the catalog");
    }
    e->level_count = level_count < SRV_LEVELS_MAX ? level_count : SRV_LEVELS_MAX;
    if (e->level_count)
        memcpy(e->levels, levels, e->level_count * sizeof *levels);
    size_t s = srv_catalog_hash(e->id) & (catalog->slot_count - 1);
    while (catalog->slots[s])
        s = (s + 1) & (catalog->slot_count - 1);
    catalog->slots[s] = ++catalog->count;
    return 0;
}

/* Removes the last entry added (its strings, its slot in the index). */
static void drop_last(srv_catalog *catalog)
{
    srv_catalog_entry *e = &catalog->entries[catalog->count - 1];
    size_t mask = catalog->slot_count - 1, s = srv_catalog_hash(e->id) & mask;
    while (catalog->slots[s] != catalog->count)
        s = (s + 1) & mask;
    /* Open addressing: the entries after it in its run are put back. */
    catalog->slots[s] = 0;
    for (size_t t = (s + 1) & mask; catalog->slots[t]; t = (t + 1) & mask) {
        size_t moved = catalog->slots[t];
        catalog->slots[t] = 0;
        size_t u = srv_catalog_hash(catalog->entries[moved - 1].id) & mask;
        while (catalog->slots[u])
            u = (u + 1) & mask;
        catalog->slots[u] = moved;
    }
    free_entry(e);
    catalog->count--;
}

/* ---------------------------------------------------------------- catalog files */

/* Joins a relative path to the catalog's directory; absolute paths and fields stay. */
static char *resolve(const char *catalog_file, const char *path)
{
    if (path[0] == '/' || !strncmp(path, "field:", 6))
        return strdup(path);
    const char *slash = strrchr(catalog_file, '/');
    int dir_len = slash ? (int)(slash - catalog_file) : 1;
    const char *dir = slash ? catalog_file : ".";
    size_t size = (size_t)dir_len + strlen(path) + 2;
    char *out = malloc(size);
    if (out)
        snprintf(out, size, "%.*s/%s", dir_len, dir, path);
    return out;
}

/* An "orthanc" member: {"url", "series"} checked; the URL without trailing slashes into
 * base, the REST URL of the series into rest (the entry's path). 0, or ISO_E_FORMAT when it
 * is bad. Both buffers hold SRV_REST_MAX bytes. */
#define SRV_REST_MAX 1200
static int read_orthanc(const char *file, const char *id, json_t *orthanc, char *base,
                        const char **series, char *rest, iso_error *err)
{
    const char *url = json_string_value(json_object_get(orthanc, "url"));
    *series = json_string_value(json_object_get(orthanc, "series"));
    if (!url || !*series || !srv_orthanc_url_valid(url) || !srv_orthanc_id_valid(*series))
        return iso_error_set(err, ISO_E_FORMAT, "%s: volume \"%s\": \"orthanc\" needs \"url\" "
                             "(http:// or https://) and \"series\" (an Orthanc id, [0-9a-f-])", file, id);
    size_t n = strlen(url); /* at most 1024: srv_orthanc_url_valid */
    while (n > 0 && url[n - 1] == '/')
        n--;
    snprintf(base, SRV_REST_MAX, "%.*s", (int)n, url);
    snprintf(rest, SRV_REST_MAX, "%.1100s/series/%.64s", base, *series);
    return 0;
}

/* Sets the last entry's Orthanc source. */
static int set_orthanc(srv_catalog *out, const char *url, const char *series, iso_error *err)
{
    srv_catalog_entry *e = &out->entries[out->count - 1];
    e->orthanc_url = strdup(url);
    e->orthanc_series = strdup(series);
    if (!e->orthanc_url || !e->orthanc_series)
        return iso_error_set(err, ISO_E_NOMEM, "out of memory reading the catalog");
    return 0;
}

/* An entry's "levels" (absent: none) into values. 0 or ISO_E_FORMAT. */
static int read_levels(const char *file, const char *id, json_t *levels, double values[SRV_LEVELS_MAX],
                       size_t *count, iso_error *err)
{
    *count = 0;
    if (levels && !json_is_array(levels))
        return iso_error_set(err, ISO_E_FORMAT, "%s: volume \"%s\": \"levels\" is not an array",
                             file, id);
    for (size_t i = 0; levels && i < json_array_size(levels) && *count < SRV_LEVELS_MAX; i++) {
        json_t *v = json_array_get(levels, i);
        if (!json_is_number(v))
            return iso_error_set(err, ISO_E_FORMAT, "%s: volume \"%s\": level %zu is not a number",
                                 file, id, i);
        values[(*count)++] = json_number_value(v);
    }
    return 0;
}

/* ---------------------------------------------------------------- DICOMweb entries */

/* Adds one DICOMweb series as a volume; its path is the WADO-RS URL, for people. */
static int add_dicomweb(srv_catalog *out, const char *id, const char *name, const char *modality,
                        const double *levels, size_t count, const char *url, const char *study,
                        const char *series, const char *credentials, iso_error *err)
{
    char path[1400];
    snprintf(path, sizeof path, "%.1100s/studies/%s/series/%s", url, study[0] ? study : "-", series);
    int rc = add(out, id, path, name, modality, levels, count, err);
    if (rc)
        return rc;
    srv_catalog_entry *e = &out->entries[out->count - 1];
    e->dicomweb_url = strdup(url);
    e->dicomweb_study = strdup(study);
    e->dicomweb_series = strdup(series);
    e->dicomweb_credentials = credentials ? strdup(credentials) : NULL;
    if (!e->dicomweb_url || !e->dicomweb_study || !e->dicomweb_series || (credentials && !e->dicomweb_credentials))
        return iso_error_set(err, ISO_E_NOMEM, "out of memory reading the catalog");
    return 0;
}

/* A query entry: each series QIDO-RS finds becomes a volume "ID-HASH" (HASH: 8 hex digits
 * of the series UID, so ids stay the same when the archive gains series). */
static int expand_query(const char *file, const char *id, const char *name, const double *levels,
                        size_t count, const char *url, const char *query, const char *credentials,
                        srv_catalog *out, iso_error *err)
{
    srv_dicomweb_series *found;
    size_t n;
    int upstream;
    iso_error why = {0};
    if (srv_dicomweb_find(url, query, credentials, &found, &n, &why, &upstream))
        return iso_error_set(err, ISO_E_FORMAT, "%s: volume \"%s\": the QIDO-RS query failed (%s); its series "
                             "are not served until a restart", file, id, why.message);
    int rc = 0;
    size_t added = 0;
    for (size_t i = 0; i < n && !rc; i++) {
        char sid[SRV_ID_MAX + 1], label[200];
        snprintf(sid, sizeof sid, "%.55s-%08x", id, (unsigned)(srv_catalog_hash(found[i].series) & 0xffffffffu));
        snprintf(label, sizeof label, "%s: %s", name ? name : id, found[i].description[0] ? found[i].description
                                                                                           : found[i].series);
        if (has_id(out, sid)) {
            fprintf(stderr, "isoserve: %s: volume \"%s\": series %s: id \"%s\" is taken; skipped\n", file, id,
                    found[i].series, sid);
            continue;
        }
        rc = add_dicomweb(out, sid, label, found[i].modality, levels, count, url, found[i].study,
                          found[i].series, credentials, err);
        added += !rc;
    }
    fprintf(stderr, "isoserve: %s: volume \"%s\": QIDO-RS %s/series?%s found %zu series\n", file, id, url,
            query, added);
    free(found);
    return rc;
}

/* A "dicomweb" entry: {"url", "credentials"?, "study"?, and "series" or "query"}. */
static int read_dicomweb(const char *file, size_t index, json_t *item, json_t *web, srv_catalog *out,
                         iso_error *err)
{
    const char *id = json_string_value(json_object_get(item, "id"));
    const char *url = json_string_value(json_object_get(web, "url"));
    const char *study = json_string_value(json_object_get(web, "study"));
    const char *series = json_string_value(json_object_get(web, "series"));
    const char *query = json_string_value(json_object_get(web, "query"));
    const char *cred = json_string_value(json_object_get(web, "credentials"));
    const char *name = json_string_value(json_object_get(item, "name"));
    if (!id || !srv_catalog_id_valid(id) || has_id(out, id))
        return iso_error_set(err, ISO_E_FORMAT, "%s: volume %zu: id is missing, taken or not [A-Za-z0-9._-]{1,64}",
                             file, index);
    if (!url || !srv_fetch_url_valid(url) || !series == !query || (series && !srv_dicomweb_uid_valid(series)) ||
        (study && !srv_dicomweb_uid_valid(study)) || (query && strpbrk(query, " \"#\\\r\n")) ||
        (json_object_get(web, "credentials") && !cred))
        return iso_error_set(err, ISO_E_FORMAT, "%s: volume \"%s\": \"dicomweb\" needs \"url\" (http:// or "
                             "https://) and either \"series\" (a UID, [0-9.], with \"study\" optional) or \"query\" "
                             "(a QIDO-RS query string); \"credentials\" names a file", file, id);
    double values[SRV_LEVELS_MAX];
    size_t count;
    int rc = read_levels(file, id, json_object_get(item, "levels"), values, &count, err);
    char base[1100], *cred_path = cred ? resolve(file, cred) : NULL;
    if (cred && !cred_path)
        return iso_error_set(err, ISO_E_NOMEM, "out of memory reading %s", file);
    size_t n = strlen(url);
    while (n > 0 && url[n - 1] == '/')
        n--;
    snprintf(base, sizeof base, "%.*s", (int)n, url);
    if (!rc && series)
        rc = add_dicomweb(out, id, name, json_string_value(json_object_get(item, "modality")), values, count,
                          base, study ? study : "", series, cred_path, err);
    else if (!rc)
        rc = expand_query(file, id, name, values, count, base, query, cred_path, out, err);
    free(cred_path);
    return rc;
}

/* One entry of a catalog file: 0 = added; ISO_E_FORMAT = the entry is bad (err says why;
 * the caller skips it); any other code stops the read. */
static int read_entry(const char *file, size_t index, json_t *item, srv_catalog *out,
                      iso_error *err)
{
    const char *id = json_string_value(json_object_get(item, "id"));
    const char *path = json_string_value(json_object_get(item, "path"));
    json_t *levels = json_object_get(item, "levels");
    json_t *orthanc = json_object_get(item, "orthanc");
    const char *series = NULL;
    char url[SRV_REST_MAX], rest[SRV_REST_MAX];
    json_t *web = json_object_get(item, "dicomweb");
    if (json_is_object(item) && web)
        return read_dicomweb(file, index, item, web, out, err);
    if (!json_is_object(item) || !id || (!path && !orthanc))
        return iso_error_set(err, ISO_E_FORMAT, "%s: volume %zu needs string fields \"id\" and "
                             "\"path\" (or \"orthanc\")", file, index);
    int rc = orthanc ? read_orthanc(file, id, orthanc, url, &series, rest, err) : 0;
    if (rc)
        return rc;
    if (!srv_catalog_id_valid(id) || has_id(out, id))
        return iso_error_set(err, ISO_E_FORMAT, "%s: volume %zu: id \"%s\" is %s", file, index, id,
                             has_id(out, id) ? "taken" : "not [A-Za-z0-9._-]{1,64}");
    double values[SRV_LEVELS_MAX];
    size_t count = 0;
    if ((rc = read_levels(file, id, levels, values, &count, err)))
        return rc;
    json_t *orientation = json_object_get(item, "orientation");
    iso_volume probe = {0};
    iso_error axes_err;
    if (orientation && (!json_is_string(orientation) ||
                        iso_vol_set_axes(&probe, json_string_value(orientation), &axes_err)))
        return iso_error_set(err, ISO_E_FORMAT, "%s: volume \"%s\": \"orientation\" must be three letters, one of "
                             "L or R, one of P or A, one of S or I: where the i, j, k axes point (e.g. \"LPI\")",
                             file, id);
    char *full = orthanc ? strdup(rest) : resolve(file, path);
    if (!full)
        return iso_error_set(err, ISO_E_NOMEM, "out of memory reading %s", file);
    rc = add(out, id, full, json_string_value(json_object_get(item, "name")),
             json_string_value(json_object_get(item, "modality")), values, count, err);
    free(full);
    if (!rc && orientation)
        snprintf(out->entries[out->count - 1].orientation, sizeof out->entries[0].orientation, "%s",
                 json_string_value(orientation));
    if (!rc && orthanc)
        rc = set_orthanc(out, url, series, err);
    return rc;
}

/* The item's "labels" (true, false, or a descriptions file) on the entries it added. */
static int read_labels(const char *file, size_t index, json_t *item, srv_catalog *out, size_t first,
                       iso_error *err)
{
    json_t *labels = json_object_get(item, "labels");
    if (!labels || json_is_false(labels))
        return 0;
    if (!json_is_true(labels) && !json_is_string(labels))
        return iso_error_set(err, ISO_E_FORMAT, "%s: volume %zu: \"labels\" is true, false or a label "
                             "descriptions file", file, index);
    for (size_t i = first; i < out->count; i++) {
        srv_catalog_entry *e = &out->entries[i];
        e->labels = 1;
        if (json_is_string(labels) && !(e->labels_file = resolve(file, json_string_value(labels))))
            return iso_error_set(err, ISO_E_NOMEM, "out of memory reading %s", file);
    }
    return 0;
}

int srv_catalog_read(const char *file, srv_catalog *out, iso_error *err)
{
    memset(out, 0, sizeof *out);
    json_error_t jerr;
    json_t *root = json_load_file(file, JSON_REJECT_DUPLICATES, &jerr);
    if (!root)
        return iso_error_set(err, ISO_E_FORMAT, "%s:%d:%d: %s", file, jerr.line, jerr.column,
                             jerr.text);
    json_t *list = json_is_array(root) ? root : json_object_get(root, "volumes");
    if (!json_is_array(list)) {
        json_decref(root);
        return iso_error_set(err, ISO_E_FORMAT,
                             "%s: expected {\"volumes\": [...]} or an array of volumes", file);
    }
    int rc = 0;
    for (size_t i = 0; i < json_array_size(list) && !rc; i++) {
        iso_error entry_err = {0};
        size_t first = out->count;
        rc = read_entry(file, i, json_array_get(list, i), out, &entry_err);
        if (!rc)
            rc = read_labels(file, i, json_array_get(list, i), out, first, &entry_err);
        if (rc == ISO_E_FORMAT) /* a bad "labels" takes back what its item added */
            while (out->count > first)
                drop_last(out);
        if (rc == ISO_E_FORMAT) { /* one bad entry does not hide the others */
            fprintf(stderr, "isoserve: %s; skipped\n", entry_err.message);
            rc = 0;
        } else if (rc && err) {
            *err = entry_err;
        }
    }
    json_decref(root);
    if (rc)
        srv_catalog_free(out);
    return rc;
}

/* ---------------------------------------------------------------- directories */

void srv_catalog_id_of(const char *file_name, char *id, size_t size)
{
    snprintf(id, size, "%s", file_name);
    char *dot = strrchr(id, '.');
    if (dot && dot != id && (!strcmp(dot, ".gz") || !strcmp(dot, ".bz2") || !strcmp(dot, ".zst"))) {
        *dot = '\0';
        dot = strrchr(id, '.');
    }
    if (dot && dot != id)
        *dot = '\0';
}

static int by_id(const void *a, const void *b)
{
    return strcmp(((const srv_catalog_entry *)a)->id, ((const srv_catalog_entry *)b)->id);
}

int srv_catalog_scan(const char *dir, srv_catalog *out, iso_error *err)
{
    memset(out, 0, sizeof *out);
    DIR *d = opendir(dir);
    if (!d)
        return iso_error_set(err, ISO_E_IO, "%s: cannot open the directory: %m", dir);
    struct dirent *ent;
    int rc = 0;
    while (rc == 0 && (ent = readdir(d))) {
        if (ent->d_name[0] == '.')
            continue;
        size_t size = strlen(dir) + strlen(ent->d_name) + 2;
        char *path = malloc(size);
        if (!path) {
            rc = iso_error_set(err, ISO_E_NOMEM, "out of memory scanning %s", dir);
            break;
        }
        snprintf(path, size, "%s/%s", dir, ent->d_name);
        struct stat st;
        char id[256];
        srv_catalog_id_of(ent->d_name, id, sizeof id);
        int series = !stat(path, &st) && S_ISDIR(st.st_mode) && iso_dicom_dir_has_files(path);
        if (stat(path, &st) || !(S_ISREG(st.st_mode) || series) || !iso_load_recognises(path))
            ; /* not a volume of its own */
        else if (!srv_catalog_id_valid(id) || has_id(out, id))
            fprintf(stderr, "isoserve: %s: id \"%s\" is %s; skipped\n", path, id,
                    has_id(out, id) ? "taken by another file" : "not [A-Za-z0-9._-]{1,64}");
        else if (!(rc = add(out, id, path, NULL, NULL, NULL, 0, err)))
            out->entries[out->count - 1].labels = iso_seg_nrrd_recognises(path);
        free(path);
    }
    closedir(d);
    if (rc) {
        srv_catalog_free(out);
        return rc;
    }
    qsort(out->entries, out->count, sizeof *out->entries, by_id);
    rc = reindex(out, out->count, err); /* the sort moved every entry */
    if (rc)
        srv_catalog_free(out);
    return rc;
}

/* ---------------------------------------------------------------- default collection */

#define MRICRON "/usr/share/mricron/templates/"

static const struct {
    const char *id, *path, *name, *modality;
    double levels[2];   /* brain surface and white matter for the templates */
    size_t level_count; /* 0: Otsu on the histogram */
} default_volumes[] = {
    {"ch2bet", MRICRON "ch2bet.nii.gz", "Colin 27 T1 brain, skull stripped (mricron)", "MR", {30, 90}, 2},
    {"ch2", MRICRON "ch2.nii.gz", "Colin 27 T1 head (mricron)", "MR", {0}, 0},
    {"ch2better", MRICRON "ch2better.nii.gz", "Colin 27 T1 brain, 0.5 mm (mricron)", "MR", {30, 95}, 2},
    {"marschner-lobb", "field:ml:128", "Marschner-Lobb test signal", "phantom", {0.5}, 1},
    {"torus", "field:torus:128", "Torus", "phantom", {0, 8}, 2},
    {"sphere", "field:sphere:96", "Sphere", "phantom", {0, 20}, 2},
};

int srv_catalog_default(srv_catalog *out, iso_error *err)
{
    memset(out, 0, sizeof *out);
    for (size_t i = 0; i < sizeof default_volumes / sizeof default_volumes[0]; i++) {
        if (strncmp(default_volumes[i].path, "field:", 6) && access(default_volumes[i].path, R_OK)) {
            fprintf(stderr, "isoserve: %s: not installed (Debian package mricron-data); skipped\n",
                    default_volumes[i].path);
            continue;
        }
        int rc = add(out, default_volumes[i].id, default_volumes[i].path, default_volumes[i].name,
                     default_volumes[i].modality, default_volumes[i].levels,
                     default_volumes[i].level_count, err);
        if (rc) {
            srv_catalog_free(out);
            return rc;
        }
    }
    return 0;
}
