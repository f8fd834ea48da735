/* chains.c: the registry of simplification chains (see chains.h). */
#include "chains.h"

#include <errno.h>
#include <sched.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>
#include <unistd.h>

#include "hash.h"

enum { ENTRY_BUILDING, ENTRY_READY };

struct srv_chain {
    srv_chain *next;
    char key[SRV_CHAIN_KEY_MAX];
    int state;
    int listed;                 /* on the registry's list (0: discarded, freed at refs 0) */
    unsigned refs;
    unsigned long long used;    /* the LRU clock at its last acquire */
    iso_mesh_chain_map *map;    /* mapped from its file, or */
    iso_mesh_chain *owned;      /* held as built (no file) */
    size_t bytes;               /* what it weighs against the limit */
    int partial;                /* READY, owned, built only down to a request's level */
    int extending;              /* a partial one's copy is being extended (one caller) */
    pthread_t builder;          /* while BUILDING or extending at the lowest priority */
    int idle_builder;
};

const char *srv_chain_source_name(srv_chain_source source)
{
    static const char *const names[] = {"memory", "file", "waited", "built", "partial", "extended"};
    return names[source];
}

void srv_chain_level_params(char *params, size_t size, double level, double tolerance, int cap)
{
    snprintf(params, size, "level=%.17g&tolerance=%.17g&cap=%d", level, tolerance, cap);
}

int srv_chain_spec_init(srv_chain_spec *spec, const char *dir, const char *id, const char *version,
                        const char *params)
{
    memset(spec, 0, sizeof *spec);
    int n = snprintf(spec->key, sizeof spec->key, "chain:%s/%s?%s", id, version, params);
    int m = snprintf(spec->id, sizeof spec->id, "%s", id);
    int p = dir ? snprintf(spec->path, sizeof spec->path, "%s/%s.%016llx.isochain", dir, id,
                           (unsigned long long)srv_hash64(params))
                : 0;
    spec->identity = srv_hash64(spec->key);
    if (n < 0 || (size_t)n >= sizeof spec->key || m < 0 || (size_t)m >= sizeof spec->id || p < 0 ||
        (size_t)p >= sizeof spec->path)
        return ISO_E_ARGUMENT;
    return 0;
}

int srv_chains_init(srv_chains *r, size_t limit_bytes)
{
    memset(r, 0, sizeof *r);
    r->limit = limit_bytes;
    if (pthread_mutex_init(&r->lock, NULL))
        return ISO_E_NOMEM;
    if (pthread_cond_init(&r->changed, NULL)) {
        pthread_mutex_destroy(&r->lock);
        return ISO_E_NOMEM;
    }
    return 0;
}

static void entry_free(srv_chain *e)
{
    iso_mesh_chain_map_close(e->map);
    iso_mesh_chain_destroy(e->owned);
    free(e);
}

void srv_chains_destroy(srv_chains *r)
{
    for (srv_chain *e = r->entries, *next; e; e = next) {
        next = e->next;
        entry_free(e);
    }
    r->entries = NULL;
    pthread_cond_destroy(&r->changed);
    pthread_mutex_destroy(&r->lock);
}

static srv_chain *find(srv_chains *r, const char *key)
{
    for (srv_chain *e = r->entries; e; e = e->next)
        if (!strcmp(e->key, key))
            return e;
    return NULL;
}

/* Takes e off the list (lock held); its weight goes with it. */
static void unlist(srv_chains *r, srv_chain *e)
{
    for (srv_chain **p = &r->entries; *p; p = &(*p)->next)
        if (*p == e) {
            *p = e->next;
            break;
        }
    if (e->state == ENTRY_READY) {
        r->bytes -= e->bytes;
        r->ready--;
    }
    e->listed = 0;
}

/* Drops the least recently used ready entries nobody holds while over the limit (lock
 * held); returns them chained, to be freed outside the lock. */
static srv_chain *evict(srv_chains *r)
{
    srv_chain *gone = NULL;
    while (r->bytes > r->limit) {
        srv_chain *victim = NULL;
        for (srv_chain *e = r->entries; e; e = e->next)
            if (e->state == ENTRY_READY && !e->refs && (!victim || e->used < victim->used))
                victim = e;
        if (!victim)
            break;
        unlist(r, victim);
        victim->next = gone;
        gone = victim;
        atomic_fetch_add(&r->evictions, 1);
    }
    return gone;
}

static void free_list(srv_chain *e)
{
    for (srv_chain *next; e; e = next) {
        next = e->next;
        entry_free(e);
    }
}

/* A new BUILDING entry with the caller's reference (lock held); make_ready turns it ready. */
static srv_chain *entry_new(srv_chains *r, const char *key)
{
    srv_chain *e = calloc(1, sizeof *e);
    if (!e)
        return NULL;
    snprintf(e->key, sizeof e->key, "%s", key);
    e->state = ENTRY_BUILDING;
    e->listed = 1;
    e->refs = 1;
    e->used = ++r->clock;
    e->next = r->entries;
    r->entries = e;
    return e;
}

static void make_ready(srv_chains *r, srv_chain *e, size_t bytes)
{
    e->state = ENTRY_READY;
    e->bytes = bytes;
    r->bytes += bytes;
    r->ready++;
}

/* spec's file mapped (lock held): 1 and *map, or 0 (none; a bad one reported and removed). */
static int map_file(srv_chains *r, const srv_chain_spec *spec, iso_mesh_chain_map **map)
{
    *map = NULL;
    if (!spec->path[0] || access(spec->path, F_OK))
        return 0;
    iso_error err = {0};
    int rc = iso_mesh_chain_map_open(spec->path, spec->identity, map, &err);
    if (!rc)
        return 1;
    fprintf(stderr, "isoserve: %s: %s; rebuilding the chain\n", spec->id, err.message);
    if (rc == ISO_E_CORRUPT || rc == ISO_E_FORMAT)
        atomic_fetch_add(&r->corrupt, 1);
    if (rc != ISO_E_NOMEM && rc != ISO_E_IO && unlink(spec->path) && errno != ENOENT)
        fprintf(stderr, "isoserve: %s: cannot remove %s: %s\n", spec->id, spec->path, strerror(errno));
    return 0;
}

/* Does ready entry e answer a caller that needs `distance` or `triangles` (neither: the
 * whole chain)? A partial one only as far as it goes (iso_mesh_chain_covers). */
static int answers(const srv_chain *e, double distance, size_t triangles)
{
    return !e->partial || ((distance >= 0 || triangles) && iso_mesh_chain_covers(e->owned, distance, triangles));
}

/* A request waits for a background build or extension: that thread runs at the request's
 * priority from now on (it goes back to the lowest for its next chain), so that other work
 * cannot hold the request up behind it. Failing that, it is only slower. */
static void raise_builder(srv_chain *e)
{
    if (e->idle_builder) {
        struct sched_param normal = {0};
        pthread_setschedparam(e->builder, SCHED_OTHER, &normal);
        e->idle_builder = 0;
    }
}

srv_chain_acquired srv_chains_acquire(srv_chains *r, const srv_chain_spec *spec, double distance, size_t triangles,
                                      int wait, srv_chain **out, srv_chain_source *source, double *load_ms)
{
    *out = NULL;
    *load_ms = 0;
    *source = SRV_CHAIN_MEMORY;
    pthread_mutex_lock(&r->lock);
    srv_chain *e;
    while ((e = find(r, spec->key)) &&
           (e->state == ENTRY_BUILDING || (e->extending && !answers(e, distance, triangles)))) {
        if (!wait) {
            pthread_mutex_unlock(&r->lock);
            return SRV_CHAIN_BUSY;
        }
        *source = SRV_CHAIN_WAITED;
        raise_builder(e);
        pthread_cond_wait(&r->changed, &r->lock);
    }
    srv_chain_acquired outcome = SRV_CHAIN_READY_NOW;
    if (e) {
        e->refs++;
        e->used = ++r->clock;
        if (!answers(e, distance, triangles)) { /* a partial chain, extended by this caller */
            e->extending = 1;
            e->idle_builder = 0;
            outcome = SRV_CHAIN_TO_EXTEND;
        }
    } else {
        double start = iso_clock_ms();
        iso_mesh_chain_map *map;
        int found = map_file(r, spec, &map);
        e = entry_new(r, spec->key);
        if (!e) {
            iso_mesh_chain_map_close(map);
            pthread_mutex_unlock(&r->lock);
            return SRV_CHAIN_BUSY;
        }
        if (found) {
            e->map = map;
            make_ready(r, e, iso_mesh_chain_map_bytes(map));
            atomic_fetch_add(&r->mapped, 1);
            *source = SRV_CHAIN_FILE;
        } else {
            outcome = SRV_CHAIN_TO_BUILD;
            *source = SRV_CHAIN_BUILT;
        }
        *load_ms = iso_clock_ms() - start;
    }
    pthread_mutex_unlock(&r->lock);
    *out = e;
    return outcome;
}

int srv_chain_partial(const srv_chain *c)
{
    return c->partial;
}

const iso_mesh_chain *srv_chain_get(const srv_chain *c)
{
    return c->map ? iso_mesh_chain_map_chain(c->map) : c->owned;
}

int srv_chain_prepare(srv_chain *c, int k, double *ms, iso_error *err)
{
    double start = iso_clock_ms();
    int rc = c->map ? iso_mesh_chain_map_check(c->map, k, err) : 0;
    *ms = iso_clock_ms() - start;
    return rc;
}

int srv_chain_prepare_grid(srv_chains *r, srv_chain *c, double *ms, iso_error *err)
{
    double start = iso_clock_ms();
    int rc = c->map ? iso_mesh_chain_map_grid(c->map, err) : 0;
    if (!rc && c->map) {
        pthread_mutex_lock(&r->lock);
        size_t now = iso_mesh_chain_map_bytes(c->map);
        if (c->listed && c->state == ENTRY_READY)
            r->bytes += now - c->bytes;
        c->bytes = now;
        pthread_mutex_unlock(&r->lock);
    }
    *ms = iso_clock_ms() - start;
    return rc;
}

/* A built or extended chain's map from spec's file, written now when the chain is
 * complete and there is a file; NULL when it stays in memory (partial, no cache dir, or
 * the write failed: reported, it only costs a rebuild after a restart). */
static iso_mesh_chain_map *save(const srv_chain_spec *spec, const iso_mesh_chain *built)
{
    iso_error err = {0};
    iso_mesh_chain_map *map = NULL;
    if (!spec->path[0] || !iso_mesh_chain_complete(built))
        return NULL;
    if (iso_mesh_chain_save(built, spec->path, spec->identity, &err))
        fprintf(stderr, "isoserve: %s: chain not written: %s\n", spec->id, err.message);
    else if (iso_mesh_chain_map_open(spec->path, spec->identity, &map, &err))
        fprintf(stderr, "isoserve: %s: the chain just written cannot be mapped: %s\n", spec->id, err.message);
    return map;
}

/* Entry e (lock held, not yet ready) holds the chain: mapped (built is then the caller's
 * to destroy, outside the lock: the file holds it now), or built as it is. */
static void hold(srv_chains *r, srv_chain *e, iso_mesh_chain_map *map, iso_mesh_chain *built)
{
    e->map = map;
    e->owned = map ? NULL : built;
    e->partial = !map && !iso_mesh_chain_complete(built);
    make_ready(r, e, map ? iso_mesh_chain_map_bytes(map) : built->bytes);
}

void srv_chains_publish(srv_chains *r, srv_chain *c, const srv_chain_spec *spec, iso_mesh_chain *built)
{
    iso_mesh_chain_map *map = save(spec, built);
    pthread_mutex_lock(&r->lock);
    hold(r, c, map, built);
    atomic_fetch_add(&r->built, 1);
    pthread_cond_broadcast(&r->changed);
    pthread_mutex_unlock(&r->lock);
    if (map)
        iso_mesh_chain_destroy(built);
}

const iso_mesh_chain *srv_chain_owned(const srv_chain *c)
{
    return c->owned;
}

srv_chain *srv_chains_replace(srv_chains *r, srv_chain *c, const srv_chain_spec *spec, iso_mesh_chain *extended)
{
    iso_mesh_chain_map *map = save(spec, extended);
    pthread_mutex_lock(&r->lock);
    c->extending = 0;
    c->idle_builder = 0;
    srv_chain *e = c->listed ? entry_new(r, c->key) : NULL;
    if (e) {
        unlist(r, c); /* its readers keep it until they release it */
        hold(r, e, map, extended);
        e->used = c->used;
        if (!e->partial)
            atomic_fetch_add(&r->completed, 1);
    }
    pthread_cond_broadcast(&r->changed);
    pthread_mutex_unlock(&r->lock);
    if (!e) /* discarded meanwhile, or no memory: dropped */
        iso_mesh_chain_map_close(map);
    if (!e || map)
        iso_mesh_chain_destroy(extended);
    return e;
}

void srv_chains_extend_abandon(srv_chains *r, srv_chain *c)
{
    pthread_mutex_lock(&r->lock);
    c->extending = 0;
    c->idle_builder = 0;
    pthread_cond_broadcast(&r->changed);
    pthread_mutex_unlock(&r->lock);
}

void srv_chains_building_idle(srv_chains *r, srv_chain *c)
{
    pthread_mutex_lock(&r->lock);
    c->builder = pthread_self();
    c->idle_builder = 1;
    pthread_mutex_unlock(&r->lock);
}

void srv_chains_abandon(srv_chains *r, srv_chain *c)
{
    pthread_mutex_lock(&r->lock);
    if (c->listed)
        unlist(r, c);
    pthread_cond_broadcast(&r->changed);
    pthread_mutex_unlock(&r->lock);
}

void srv_chains_discard(srv_chains *r, srv_chain *c, const srv_chain_spec *spec, const char *why)
{
    fprintf(stderr, "isoserve: %s: %s; rebuilding the chain\n", spec->id, why);
    atomic_fetch_add(&r->corrupt, 1);
    pthread_mutex_lock(&r->lock);
    /* The file is the one this entry mapped while the entry is listed: no rebuild of its
     * key can have replaced it yet. */
    int mine = c->listed;
    if (mine)
        unlist(r, c);
    if (mine && spec->path[0] && unlink(spec->path) && errno != ENOENT)
        fprintf(stderr, "isoserve: %s: cannot remove %s: %s\n", spec->id, spec->path, strerror(errno));
    pthread_mutex_unlock(&r->lock);
    srv_chains_release(r, c);
}

void srv_chains_release(srv_chains *r, srv_chain *c)
{
    if (!c)
        return;
    pthread_mutex_lock(&r->lock);
    int last = --c->refs == 0 && !c->listed;
    srv_chain *gone = evict(r);
    pthread_mutex_unlock(&r->lock);
    if (last)
        entry_free(c);
    free_list(gone);
}

int srv_chains_peek(srv_chains *r, const srv_chain_spec *spec, srv_chain **out)
{
    *out = NULL;
    pthread_mutex_lock(&r->lock);
    srv_chain *e = find(r, spec->key);
    int state = e ? (e->state == ENTRY_READY && !e->partial ? 2 : 1) : 0;
    if (e && e->state == ENTRY_READY) {
        e->refs++;
        e->used = ++r->clock;
    } else if (!e) {
        iso_mesh_chain_map *map;
        if (map_file(r, spec, &map) && (e = entry_new(r, spec->key))) {
            e->map = map;
            make_ready(r, e, iso_mesh_chain_map_bytes(map));
            atomic_fetch_add(&r->mapped, 1);
            state = 2;
        } else {
            iso_mesh_chain_map_close(map);
        }
    }
    pthread_mutex_unlock(&r->lock);
    *out = state == 2 || (e && e->partial) ? e : NULL;
    return state;
}

int srv_chains_defer(srv_chains *r, srv_chain_deferred *task)
{
    pthread_mutex_lock(&r->lock);
    int taken = r->completer;
    if (taken) {
        task->next = NULL;
        *(r->deferred ? r->deferred_tail : &r->deferred) = task;
        r->deferred_tail = &task->next;
        pthread_cond_broadcast(&r->changed);
    }
    pthread_mutex_unlock(&r->lock);
    return taken;
}

srv_chain_deferred *srv_chains_next_deferred(srv_chains *r, double timeout_ms)
{
    struct timespec until;
    clock_gettime(CLOCK_REALTIME, &until); /* the condition's clock */
    long long ns = until.tv_nsec + (long long)(timeout_ms * 1e6);
    until.tv_sec += (time_t)(ns / 1000000000);
    until.tv_nsec = (long)(ns % 1000000000);
    pthread_mutex_lock(&r->lock);
    while (!r->deferred && pthread_cond_timedwait(&r->changed, &r->lock, &until) == 0)
        ;
    srv_chain_deferred *task = r->deferred;
    if (task)
        r->deferred = task->next;
    pthread_mutex_unlock(&r->lock);
    return task;
}

size_t srv_chains_partial_count(srv_chains *r)
{
    size_t n = 0;
    pthread_mutex_lock(&r->lock);
    for (const srv_chain *e = r->entries; e; e = e->next)
        n += e->state == ENTRY_READY && e->partial;
    pthread_mutex_unlock(&r->lock);
    return n;
}
