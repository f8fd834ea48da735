/* collection.c: preloading volumes and hierarchies (see collection.h). */
#include "collection.h"

#include <ctype.h>
#include <dirent.h>
#include <errno.h>
#include <inttypes.h>
#ifdef __GLIBC__
#include <malloc.h>
#endif
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <time.h>
#include <unistd.h>

#include "cli.h"
#include "base/base.h"
#include "volume/volume.h"
#include "io/io.h"
#include "dicomweb.h"
#include "orthanc.h"

/* Bump when extraction or encoding changes what a mesh URL returns: it is part of every
 * volume's version, so ETags and caches in front of the server move on. */
#define SRV_MESH_ALGORITHM_VERSION 7

int srv_collection_init(srv_collection *c, const srv_catalog *catalog,
                        const srv_preload_options *options)
{
    memset(c, 0, sizeof *c);
    c->total = catalog->count;
    c->catalog = catalog;
    c->options = *options;
    c->volumes = calloc(catalog->count ? catalog->count : 1, sizeof *c->volumes);
    c->state = calloc(catalog->count ? catalog->count : 1, 1);
    c->upstream = calloc(catalog->count ? catalog->count : 1, 1);
    c->failure = calloc(catalog->count ? catalog->count : 1, sizeof *c->failure);
    c->retry_at = calloc(catalog->count ? catalog->count : 1, sizeof *c->retry_at);
    c->attempts = calloc(catalog->count ? catalog->count : 1, sizeof *c->attempts);
    if (!c->volumes || !c->state || !c->upstream || !c->failure ||
        !c->retry_at || !c->attempts ||
        pthread_mutex_init(&c->lock, NULL))
        goto err;
    if (pthread_cond_init(&c->changed, NULL)) {
        pthread_mutex_destroy(&c->lock);
        goto err;
    }
    return 0;
err:
    free(c->volumes);
    free(c->state);
    free(c->upstream);
    free(c->failure);
    free(c->retry_at);
    free(c->attempts);
    memset(c, 0, sizeof *c);
    return ISO_E_NOMEM;
}

/* A loaded volume's memory: its segmentation's (which holds the volume and tree), or the
 * volume and tree themselves. */
static void free_loaded(srv_volume *v)
{
    if (v->seg) {
        iso_seg_destroy(v->seg);
    } else {
        iso_tree_destroy(v->tree);
        iso_vol_destroy(v->vol);
    }
    v->seg = NULL;
    v->tree = NULL;
    v->vol = NULL;
}

void srv_collection_free(srv_collection *c)
{
    if (!c->volumes)
        return;
    for (size_t i = 0; i < c->total; i++) {
        if (c->state[i] != SRV_ENTRY_LOADED)
            continue;
        free_loaded(&c->volumes[i]);
    }
    free(c->volumes);
    free(c->state);
    free(c->upstream);
    free(c->failure);
    free(c->retry_at);
    free(c->attempts);
    pthread_cond_destroy(&c->changed);
    pthread_mutex_destroy(&c->lock);
    memset(c, 0, sizeof *c);
}

void srv_collection_lock(srv_collection *c)
{
    pthread_mutex_lock(&c->lock);
}

void srv_collection_unlock(srv_collection *c)
{
    pthread_mutex_unlock(&c->lock);
}

const srv_volume *srv_collection_loaded(const srv_collection *c, size_t i)
{
    return i < c->total && c->state[i] == SRV_ENTRY_LOADED ? &c->volumes[i] : NULL;
}

void srv_collection_retain(srv_collection *c, const srv_volume *v)
{
    pthread_mutex_lock(&c->lock);
    c->volumes[v - c->volumes].refs++;
    pthread_mutex_unlock(&c->lock);
}

static void evict_over_cap(srv_collection *c);

/* The last holder of a volume lets the cap be met again, if volumes in use exceeded it. */
void srv_collection_release(srv_collection *c, const srv_volume *v)
{
    if (!v)
        return;
    pthread_mutex_lock(&c->lock);
    if (--c->volumes[v - c->volumes].refs == 0)
        evict_over_cap(c);
    pthread_mutex_unlock(&c->lock);
}

/* A segmentation's identity beyond its first layer's samples: its other layers' samples,
 * and its table (numbers, names, colours, layers, values), which the scenes carry: "s" and
 * 8 hex digits (FNV-1a). */
static const char *table_hash(const iso_segmentation *seg)
{
    static _Thread_local char text[16];
    uint32_t h = 2166136261u;
    for (size_t s = 0; s < seg->segment_count; s++) {
        const iso_segment *sg = &seg->segments[s];
        const unsigned char *parts[5] = {(const unsigned char *)&sg->number, (const unsigned char *)sg->name,
                                         (const unsigned char *)sg->color, (const unsigned char *)&sg->layer,
                                         (const unsigned char *)&sg->value};
        const size_t sizes[5] = {sizeof sg->number, strlen(sg->name), sizeof sg->color, sizeof sg->layer,
                                 sizeof sg->value};
        for (int p = 0; p < 5; p++)
            for (size_t i = 0; i < sizes[p]; i++)
                h = (h ^ parts[p][i]) * 16777619u;
    }
    for (size_t l = 1; l < seg->layer_count; l++)
        h = (h ^ seg->layers[l].tree->volume_crc) * 16777619u;
    snprintf(text, sizeof text, "s%08x", (unsigned)h);
    return text;
}

/* FNV-1a over the geometry: spacing, origin and direction move every vertex. */
static uint32_t geometry_hash(const iso_volume *vol)
{
    uint32_t h = 2166136261u;
    const unsigned char *parts[3] = {(const unsigned char *)vol->spacing,
                                     (const unsigned char *)vol->origin,
                                     (const unsigned char *)vol->direction};
    const size_t sizes[3] = {sizeof vol->spacing, sizeof vol->origin, sizeof vol->direction};
    for (int p = 0; p < 3; p++)
        for (size_t i = 0; i < sizes[p]; i++)
            h = (h ^ parts[p][i]) * 16777619u;
    return h;
}

void srv_volume_describe(srv_volume *v, uint32_t volume_crc)
{
    const srv_catalog_entry *e = v->entry;
    snprintf(v->version, sizeof v->version, "%08x%08x%s-%d", (unsigned)volume_crc, (unsigned)geometry_hash(v->vol),
             v->seg ? table_hash(v->seg) : "", SRV_MESH_ALGORITHM_VERSION);
    iso_hist_compute(v->vol, SRV_HISTOGRAM_BINS, v->histogram);
    if (!v->vol->has_padding)
        v->vol->has_padding = iso_vol_find_padding(v->vol, v->histogram, SRV_HISTOGRAM_BINS, &v->vol->padding);
    uint64_t data_only[SRV_HISTOGRAM_BINS]; /* the levels skip padding; the histogram shows it */
    memcpy(data_only, v->histogram, sizeof data_only);
    if (v->vol->has_padding)
        iso_hist_drop_padding(data_only, SRV_HISTOGRAM_BINS, v->vol->value_min, v->vol->value_max, v->vol->padding);
    if (e->level_count) {
        memcpy(v->levels, e->levels, e->level_count * sizeof *v->levels);
        v->level_count = e->level_count;
    } else {
        v->level_count = iso_hist_suggest_levels(data_only, SRV_HISTOGRAM_BINS, v->vol->value_min,
                                                 v->vol->value_max, v->levels, SRV_LEVELS_MAX);
    }
}

proto_volume_doc srv_volume_doc(const srv_volume *v, const char *shard)
{
    /* The catalog's name and modality where it gives them, else the volume's own (a DICOM
     * series' description and modality), else the id and "" (document.c). */
    const srv_catalog_entry *e = v->entry;
    proto_volume_doc doc = {
        .shard = shard, .id = e->id, .name = e->name && *e->name ? e->name : v->vol->description,
        .modality = e->modality && *e->modality ? e->modality : v->vol->modality,
        .version = v->version, .vol = v->vol, .levels = v->levels, .level_count = v->level_count,
        .histogram = v->histogram, .histogram_bins = SRV_HISTOGRAM_BINS, .segmentation = v->seg,
        .orientation = e->orientation[0] ? "catalog" : v->vol->oriented ? "file" : "none"};
    if (v->tree) {
        doc.hierarchy_nodes = v->tree->node_count;
        doc.hierarchy_bytes = iso_tree_memory(v->tree);
        doc.hierarchy_ms = v->tree->build_ms;
        doc.hierarchy_from_file = v->tree_from_file;
    }
    return doc;
}

/* The hierarchy from the cache dir if it is there, valid and not older than the volume's
 * file; otherwise built and written back. Returns 0 or the build's ISO_E_* code, err
 * saying why (also reported on stderr). */
static int load_tree(srv_volume *v, const srv_preload_options *opt, char *label, iso_error *failure)
{
    iso_error err;
    char file[4096] = "";
    if (opt->cache_dir) {
        snprintf(file, sizeof file, "%s/%s.isotree", opt->cache_dir, v->entry->id);
        struct stat tree_st, vol_st;
        int newer = !stat(file, &tree_st) &&
                    (stat(v->entry->path, &vol_st) || tree_st.st_mtime >= vol_st.st_mtime);
        if (newer && !iso_tree_load(v->vol, file, &v->tree, &err)) {
            v->tree_from_file = 1;
            return 0;
        }
        if (newer)
            fprintf(stderr, "isoserve: %s: %s; rebuilding\n", v->entry->id, err.message);
    }
    int rc = iso_tree_build(v->vol, 0, srv_progress, label, &v->tree, failure);
    if (rc) {
        fprintf(stderr, "isoserve: %s: building the hierarchy: %s; skipped\n", v->entry->id,
                failure->message);
        return rc;
    }
    /* A full or read-only disk costs the next start a rebuild, nothing more: the tree in
     * memory is complete, and iso_tree_save leaves no partial file under the real name. */
    if (file[0] && iso_tree_save(v->tree, file, &err)) {
        v->tree_unsaved = 1;
        fprintf(stderr, "isoserve: %s: hierarchy not cached: %s; serving it from memory\n",
                v->entry->id, err.message);
    }
    return 0;
}

/* The entry's segmentation: a DICOM SEG from its archive (DICOMweb or Orthanc, with the
 * series it references), or from its path (a label map with its descriptions, a .seg.nrrd,
 * a DICOM SEG beside its CT). */
static int load_segmentation(const srv_catalog_entry *e, const srv_preload_options *opt, char *label,
                             iso_segmentation **seg, iso_error *err, int *upstream)
{
    iso_load_options lopt = {.max_bytes = opt->max_volume_bytes, .progress = srv_progress,
                             .progress_context = label};
    *upstream = 0;
    if (e->dicomweb_url)
        return srv_dicomweb_load_segmentation(e->dicomweb_url, e->dicomweb_study, e->dicomweb_series,
                                              e->dicomweb_credentials, opt->cache_dir, &lopt, seg, err, upstream);
    if (e->orthanc_url)
        return srv_orthanc_load_segmentation(e->orthanc_url, e->orthanc_series, opt->cache_dir, &lopt, seg, err, upstream);
    return iso_seg_load(e->path, e->labels_file, &lopt, seg, err);
}

/* The entry's volume: from its archive (DICOMweb or Orthanc, and the cache dir), or its path. */
static int load_volume(const srv_catalog_entry *e, const srv_preload_options *opt, char *label,
                       iso_volume **vol, iso_error *err, int *upstream)
{
    iso_load_options lopt = {.max_bytes = opt->max_volume_bytes, .progress = srv_progress,
                             .progress_context = label};
    *upstream = 0;
    if (e->dicomweb_url)
        return srv_dicomweb_load(e->dicomweb_url, e->dicomweb_study, e->dicomweb_series, e->dicomweb_credentials,
                                 opt->cache_dir, &lopt, vol, err, upstream);
    if (e->orthanc_url)
        return srv_orthanc_load(e->orthanc_url, e->orthanc_series, opt->cache_dir, &lopt, vol, err, upstream);
    return iso_load(e->path, &lopt, vol, err);
}

/* Loads one entry into v; 0, or the ISO_E_* code of the load or the build when it is
 * skipped (reported, and said in err). */
static int load_one(srv_volume *v, const srv_catalog_entry *e, const srv_preload_options *opt,
                    size_t index, size_t total, iso_error *err, int *upstream)
{
    memset(v, 0, sizeof *v);
    v->entry = e;
    double start = iso_clock_ms();
    char label[160];
    snprintf(label, sizeof label, "isoserve: [%zu/%zu] %s: loading", index + 1, total, e->id);
    int rc = e->labels ? load_segmentation(e, opt, label, &v->seg, err, upstream)
                       : load_volume(e, opt, label, &v->vol, err, upstream);
    /* The catalog's axes for a file that does not say them: every layer of a segmentation. */
    for (size_t l = 0; !rc && e->orientation[0] && l < (v->seg ? v->seg->layer_count : 1); l++)
        if ((rc = iso_vol_set_axes(v->seg ? v->seg->layers[l].vol : v->vol, e->orientation, err)))
            free_loaded(v); /* the catalog checked the code: not expected */
    if (rc) {
        fprintf(stderr, "isoserve: volume \"%s\": %s; skipped\n", e->id, err->message);
        return rc;
    }
    if (v->seg)
        v->vol = v->seg->layers[0].vol;
    snprintf(label, sizeof label, "isoserve: [%zu/%zu] %s: hierarchy", index + 1, total, e->id);
    rc = load_tree(v, opt, label, err);
    if (!rc && v->seg) {
        v->seg->layers[0].tree = v->tree;
        if ((rc = iso_seg_build_trees(v->seg, 1, 0, srv_progress, label, err)))
            fprintf(stderr, "isoserve: %s: building a layer's hierarchy: %s; skipped\n", e->id, err->message);
        else
            iso_seg_count_voxels(v->seg);
    }
    if (rc) {
        if (v->seg && !v->seg->layers[0].tree)
            iso_tree_destroy(v->tree);
        v->tree = v->seg ? NULL : v->tree;
        free_loaded(v);
        return rc;
    }
    v->bytes = 0;
    for (size_t l = 0; l < (v->seg ? v->seg->layer_count : 1); l++) {
        const iso_volume *vol = v->seg ? v->seg->layers[l].vol : v->vol;
        const iso_tree *tree = v->seg ? v->seg->layers[l].tree : v->tree;
        v->bytes += iso_vol_count(vol) * iso_vol_type_size(vol->type) + iso_tree_memory(tree);
    }
    srv_volume_describe(v, v->tree->volume_crc);
    fprintf(stderr, "isoserve: [%zu/%zu] %s: %zux%zux%zu %s, hierarchy %s in %.0f ms (%zu KB)\n",
            index + 1, total, e->id, v->vol->dims[0], v->vol->dims[1], v->vol->dims[2],
            iso_vol_type_name(v->vol->type), v->tree_from_file ? "read" : "built",
            iso_clock_ms() - start, iso_tree_memory(v->tree) / 1024);
    return 0;
}

/* The wait after the n-th upstream failure in a row (n >= 1). */
static unsigned backoff_s(unsigned n)
{
    unsigned s = SRV_RETRY_FIRST_S;
    while (--n && s < SRV_RETRY_MAX_S)
        s *= 2;
    return s < SRV_RETRY_MAX_S ? s : SRV_RETRY_MAX_S;
}

/* Loads catalog entry i, idle and claimed by the caller, who holds the lock: marks it
 * loading, loads it without the lock, then publishes it in its slot (or marks it failed)
 * and wakes the waiters. Returns with the lock held. */
static void load_locked(srv_collection *c, size_t i, int on_demand)
{
    c->state[i] = SRV_ENTRY_LOADING;
    pthread_mutex_unlock(&c->lock);

    srv_volume v;
    iso_error err = {0};
    int upstream = 0;
    int failed = load_one(&v, &c->catalog->entries[i], &c->options, i, c->total, &err, &upstream) != 0;
    v.on_demand = on_demand;

    pthread_mutex_lock(&c->lock);
    if (!failed) {
        v.last_used = ++c->uses;
        c->volumes[i] = v;
        atomic_fetch_add(&c->count, 1);
        atomic_fetch_add(&c->resident, v.bytes);
        atomic_fetch_add(&c->hierarchy_bytes, iso_tree_memory(v.tree));
        atomic_fetch_add(v.tree_from_file ? &c->trees_read : &c->trees_built, 1);
        if (on_demand)
            atomic_fetch_add(&c->on_demand, 1);
        if (v.tree_unsaved)
            atomic_fetch_add(&c->unsaved, 1);
    }
    c->state[i] = failed ? SRV_ENTRY_FAILED : SRV_ENTRY_LOADED;
    if (failed) {
        c->failure[i] = err;
        c->upstream[i] = (unsigned char)upstream;
        c->attempts[i] = upstream ? c->attempts[i] + 1 : 0;
        if (upstream)
            c->retry_at[i] = iso_clock_ms() + 1000.0 * backoff_s(c->attempts[i]);
    } else {
        c->attempts[i] = 0;
    }
    pthread_cond_broadcast(&c->changed);
}

/* Preloading's load of entry i, unless a request has it or had it already. */
static void load_entry(srv_collection *c, size_t i)
{
    pthread_mutex_lock(&c->lock);
    if (c->state[i] == SRV_ENTRY_IDLE)
        load_locked(c, i, 0);
    pthread_mutex_unlock(&c->lock);
}

/* The least recently used loaded volume that nobody holds and whose hierarchy is on file
 * (an unsaved one would have to be built again), or total. Lock held. */
static size_t eviction_victim(const srv_collection *c)
{
    size_t victim = c->total;
    for (size_t i = 0; i < c->total; i++) {
        const srv_volume *v = &c->volumes[i];
        if (c->state[i] == SRV_ENTRY_LOADED && !v->refs && !v->tree_unsaved &&
            (victim == c->total || v->last_used < c->volumes[victim].last_used))
            victim = i;
    }
    return victim;
}

/* glibc keeps freed blocks in its arenas (one per thread that allocated, and volumes are
 * loaded by request threads) instead of unmapping them once its mmap threshold has grown
 * past a volume's size: malloc_trim hands those pages back, so that the process's RSS
 * follows the resident bytes down after an eviction. */
static void give_back_freed_memory(void)
{
#ifdef __GLIBC__
    malloc_trim(0);
#endif
}

/* While the resident bytes exceed the cap, evicts the least recently used volume nobody
 * holds; its memory is freed without the lock. Lock held on entry and on return. */
static void evict_over_cap(srv_collection *c)
{
    const uint64_t cap = c->options.max_resident_bytes;
    while (cap && atomic_load(&c->resident) > cap) {
        size_t i = eviction_victim(c);
        if (i == c->total)
            return; /* all in use: the cap is exceeded until they are released */
        srv_volume v = c->volumes[i];
        memset(&c->volumes[i], 0, sizeof c->volumes[i]);
        c->state[i] = SRV_ENTRY_IDLE;
        atomic_fetch_sub(&c->count, 1);
        atomic_fetch_sub(&c->resident, v.bytes);
        atomic_fetch_sub(&c->hierarchy_bytes, iso_tree_memory(v.tree));
        atomic_fetch_add(&c->evictions, 1);
        if (v.on_demand)
            atomic_fetch_sub(&c->on_demand, 1);
        pthread_mutex_unlock(&c->lock);
        fprintf(stderr, "isoserve: %s: evicted (%zu KB; resident %zu KB, cap %" PRIu64 " KB)\n",
                v.entry->id, v.bytes / 1024, atomic_load(&c->resident) / 1024, cap / 1024);
        free_loaded(&v);
        give_back_freed_memory();
        pthread_mutex_lock(&c->lock);
    }
}

/* A temporary file of iso_tree_save or iso_mesh_chain_save for a catalog id:
 * "ID.isotree.tmp." or "ID.<16 hex digits>.isochain.tmp." (mesh_job.c), then mkstemp's six
 * letters or digits. Nothing else in the cache dir is ever removed. */
static int is_tree_temporary(const srv_catalog *catalog, const char *name)
{
    static const char *const infixes[] = {".isotree.tmp.", ".isochain.tmp."};
    const size_t n = strlen(name);
    for (int i = 0; i < 2; i++) {
        const size_t tail = strlen(infixes[i]) + 6, hex = i ? 17 : 0; /* ".<16 hex>" */
        if (n <= tail + hex || strncmp(name + n - tail, infixes[i], tail - 6))
            continue;
        int ok = 1;
        for (const char *p = name + n - 6; *p; p++)
            ok &= isalnum((unsigned char)*p) != 0;
        for (size_t j = n - tail - hex + 1; hex && j < n - tail; j++)
            ok &= isxdigit((unsigned char)name[j]) != 0;
        ok &= !hex || name[n - tail - hex] == '.';
        char id[SRV_ID_MAX + 1];
        size_t len = n - tail - hex;
        if (!ok || len > SRV_ID_MAX)
            continue;
        memcpy(id, name, len);
        id[len] = '\0';
        if (srv_catalog_find(catalog, id) < catalog->count)
            return 1;
    }
    return 0;
}

/* Removes the temporary hierarchy files a killed writer left (iso_tree_save renames its
 * file into place, so only a crash or kill -9 between mkstemp and rename leaves one).
 * Replicas may share the directory, so the writer may live in another process this one
 * cannot see: a file goes only when it was last changed SRV_TEMP_STALE_S before this
 * start. A writer writes and fsyncs in one go, so its file changes until moments before
 * the rename; and were a slow writer's file removed all the same, its rename would fail
 * and it would serve from memory, never leave a wrong file. Each decision is logged. */
static void remove_stale_temporaries(const srv_collection *c, time_t started)
{
    const char *dir = c->options.cache_dir;
    DIR *d = opendir(dir);
    if (!d)
        return; /* mkdir's message said why */
    for (struct dirent *e; (e = readdir(d));) {
        char path[4096];
        struct stat st;
        if (!is_tree_temporary(c->catalog, e->d_name) ||
            snprintf(path, sizeof path, "%s/%s", dir, e->d_name) >= (int)sizeof path ||
            lstat(path, &st) || !S_ISREG(st.st_mode))
            continue;
        long idle = (long)difftime(started, st.st_mtime);
        if (idle < SRV_TEMP_STALE_S)
            fprintf(stderr, "isoserve: %s: kept: changed %ld s ago, its writer may still be at "
                    "work (stale after %d s)\n", path, idle, SRV_TEMP_STALE_S);
        else if (unlink(path))
            fprintf(stderr, "isoserve: %s: stale temporary file not removed: %s\n", path,
                    strerror(errno));
        else
            fprintf(stderr, "isoserve: %s: removed, a stale temporary file (%" PRIdMAX " bytes, "
                    "unchanged for %ld s: its writer is gone)\n", path, (intmax_t)st.st_size, idle);
    }
    closedir(d);
}

void srv_collection_preload(srv_collection *c)
{
    time_t started = time(NULL);
    const char *dir = c->options.cache_dir;
    if (dir && mkdir(dir, 0755) && errno != EEXIST)
        fprintf(stderr, "isoserve: --cache-dir %s: %s; hierarchies will not be cached\n", dir,
                strerror(errno));
    if (dir)
        remove_stale_temporaries(c, started);
    const uint64_t cap = c->options.max_resident_bytes;
    for (size_t i = 0; i < c->total && !atomic_load(&c->stop); i++) {
        if (cap && atomic_load(&c->resident) >= cap) {
            fprintf(stderr, "isoserve: %zu volumes preloaded fill --max-resident-mb; the other "
                    "%zu load on demand\n", atomic_load(&c->count), c->total - i);
            break;
        }
        if (!c->options.skip || !c->options.skip[i])
            load_entry(c, i);
        atomic_store(&c->attempted, i + 1);
    }
    atomic_store(&c->attempted, c->total);
    atomic_store(&c->ready, 1);
}

unsigned srv_collection_failure(srv_collection *c, const char *id, char *why, size_t size)
{
    size_t i = srv_catalog_find(c->catalog, id);
    unsigned wait = 0;
    snprintf(why, size, "%s", "");
    if (i == c->total)
        return 0;
    pthread_mutex_lock(&c->lock);
    if (c->state[i] == SRV_ENTRY_FAILED) {
        snprintf(why, size, "%s", c->failure[i].message);
        if (c->upstream[i]) {
            double left = (c->retry_at[i] - iso_clock_ms()) / 1000.0;
            wait = left < 1 ? 1 : (unsigned)(left + 0.999);
        }
    }
    pthread_mutex_unlock(&c->lock);
    return wait;
}

/* An entry whose source failed and whose backoff has passed goes back to idle, so that
 * this request loads it again. */
static void rearm_if_due(srv_collection *c, size_t i)
{
    pthread_mutex_lock(&c->lock);
    if (c->state[i] == SRV_ENTRY_FAILED && c->upstream[i] && iso_clock_ms() >= c->retry_at[i]) {
        c->state[i] = SRV_ENTRY_IDLE;
        fprintf(stderr, "isoserve: volume \"%s\": asking its source again (failure %u in a row)\n",
                c->catalog->entries[i].id, c->attempts[i]);
    }
    pthread_mutex_unlock(&c->lock);
}

srv_volume_state srv_collection_acquire(srv_collection *c, const char *id, const srv_volume **out)
{
    *out = NULL;
    size_t i = srv_catalog_find(c->catalog, id);
    if (i == c->total)
        return SRV_VOLUME_UNKNOWN;
    rearm_if_due(c, i);
    pthread_mutex_lock(&c->lock);
    int loaded_here = 0;
    for (;;) {
        if (c->state[i] == SRV_ENTRY_LOADED) {
            c->volumes[i].refs++;
            c->volumes[i].last_used = ++c->uses;
            *out = &c->volumes[i];
            break;
        }
        if (c->state[i] == SRV_ENTRY_FAILED)
            break;
        if (c->state[i] == SRV_ENTRY_LOADING) /* another request's load of the same entry */
            pthread_cond_wait(&c->changed, &c->lock);
        else { /* idle: never loaded, or evicted */
            load_locked(c, i, 1);
            loaded_here = 1;
        }
    }
    if (loaded_here) /* held now, so the new volume is not its own victim */
        evict_over_cap(c);
    int upstream = c->upstream[i];
    pthread_mutex_unlock(&c->lock);
    return *out ? SRV_VOLUME_READY : upstream ? SRV_VOLUME_UPSTREAM_FAILED : SRV_VOLUME_FAILED;
}
