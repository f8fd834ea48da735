/* chains.h: the registry of simplification chains (mesh.h) that distance= and budget=
 * requests are answered from, apart from the mesh cache, with a memory limit of its own.
 *
 * A chain is named by a spec: the volume's id and version and what the chain is of (level,
 * tolerance and cap, or a segment), which give its key, its file in the cache dir
 * ("<dir>/<id>.<16 hex digits>.isochain") and the identity the file must carry. An entry
 * is BUILDING (one caller, a request or the background builder, makes it; the others wait)
 * or READY: mapped from its file (iso_mesh_chain_map: nothing read but the header, the
 * table and the level records, each level checked before its first cut) or, without a
 * file, held in memory as built. A ready entry weighs its file's size (or the built
 * chain's bytes); above the limit, the least recently used entries nobody holds are
 * dropped (their files stay: the next request maps them again in well under a
 * millisecond).
 *
 * A request builds a chain only down to the level it needs (iso_mesh_chain_build_until):
 * that partial chain is READY in memory (never written: files hold complete chains) and
 * answers every request it covers (iso_mesh_chain_covers). A request it does not cover
 * extends it, and the background completer completes it, the same way: on a copy
 * (iso_mesh_chain_copy), by one caller at a time, while the entry keeps answering the
 * requests it covers; the extended chain then replaces the entry (a new entry under the
 * same key, written and mapped when complete), and readers of the old one keep it until
 * they release it. Why a copy rather than a lock readers hold while cutting: an extension
 * takes seconds, and the completer runs at the lowest priority, so a reader blocked on it
 * would wait behind idle work; with a copy no reader ever waits for levels it does not
 * need, nor sees a chain that is being written. Callers needing levels beyond it wait for
 * the extension in progress, then extend further if it still falls short. A file found corrupt, at mapping or at a level's first check, is reported,
 * removed and rebuilt, never served. One mutex guards the registry; there are a few
 * entries per volume, so lookups are linear. */
#ifndef SRV_CHAINS_H
#define SRV_CHAINS_H

#include <pthread.h>
#include <stdatomic.h>
#include <stddef.h>
#include <stdint.h>

#include "base/base.h"
#include "mesh/mesh.h"

#define SRV_CHAIN_KEY_MAX 400
#define SRV_CHAIN_PATH_MAX 4096

typedef struct srv_chain_spec {
    char key[SRV_CHAIN_KEY_MAX];   /* "chain:<id>/<version>?<params>" */
    char path[SRV_CHAIN_PATH_MAX]; /* its file; "" without a cache dir */
    uint64_t identity;             /* a hash of the key: the file must carry it */
    char id[128];                  /* the volume's, for messages */
} srv_chain_spec;

/* The spec of a chain of volume id at version, params saying what it is of
 * ("level=..&tolerance=..&cap=.." or a segment's); dir the cache dir or NULL. 0, or
 * ISO_E_ARGUMENT when a name does not fit. */
int srv_chain_spec_init(srv_chain_spec *spec, const char *dir, const char *id, const char *version,
                        const char *params);

/* The params of the chain of a level's surface: "level=L&tolerance=T&cap=0|1", every
 * number exact (%.17g), so that every route names one chain alike. */
void srv_chain_level_params(char *params, size_t size, double level, double tolerance, int cap);

typedef struct srv_chain srv_chain; /* an entry, held by a reference */

/* How a ready chain was found, for the headers. */
typedef enum srv_chain_source {
    SRV_CHAIN_MEMORY,  /* already in the registry */
    SRV_CHAIN_FILE,    /* mapped from its file now */
    SRV_CHAIN_WAITED,  /* built meanwhile by another request or in the background */
    SRV_CHAIN_BUILT,   /* built by this caller */
    SRV_CHAIN_PARTIAL, /* built by this caller down to its level only */
    SRV_CHAIN_EXTENDED /* a partial chain extended by this caller down to its level */
} srv_chain_source;
const char *srv_chain_source_name(srv_chain_source source);

/* The background builder's progress, under the registry's lock (chain_background.c). */
typedef struct srv_chain_progress {
    int enabled, running, finished;
    size_t planned, built, loaded, failed; /* chains of the suggested levels */
    char current[160];                     /* "<id> level <L>" while one is built, else "" */
    double current_since_ms;               /* iso_clock_ms when it began */
} srv_chain_progress;

typedef struct srv_chains {
    pthread_mutex_t lock;
    pthread_cond_t changed;         /* an entry became ready or was given up */
    srv_chain *entries;
    size_t bytes, limit, ready;     /* ready entries' weight, the limit, their count */
    unsigned long long clock;       /* the LRU clock */
    _Atomic unsigned long long evictions, mapped, built, corrupt;
    _Atomic unsigned long long extended, completed; /* partial chains extended, completed */
    srv_chain_progress progress;
    int completer;                  /* a background completer takes deferred work */
    struct srv_chain_deferred *deferred, **deferred_tail;
} srv_chains;

int srv_chains_init(srv_chains *r, size_t limit_bytes);
/* Frees every entry; none may be held. */
void srv_chains_destroy(srv_chains *r);

typedef enum srv_chain_acquired {
    SRV_CHAIN_READY_NOW, /* *out is ready (srv_chain_get), with a reference */
    SRV_CHAIN_TO_BUILD,  /* *out is BUILDING and the caller's to build: srv_chains_publish
                          * or srv_chains_abandon, then srv_chains_release */
    SRV_CHAIN_TO_EXTEND, /* *out is a ready partial chain that does not answer the caller,
                          * who extends a copy of it (srv_chain_owned): srv_chains_replace
                          * or srv_chains_extend_abandon, then srv_chains_release */
    SRV_CHAIN_BUSY       /* another caller builds it and wait was 0: *out NULL */
} srv_chain_acquired;

/* The chain of spec for a caller that needs the levels answering `distance` (>= 0) or
 * `triangles` (> 0), or (distance < 0, triangles 0) the whole chain: ready in the
 * registry, else mapped from its file (a stale or corrupt file is reported and removed),
 * else the caller's to build; a partial one that does not answer the caller is the
 * caller's to extend. With wait, a chain another caller builds, or extends while it does
 * not answer, is waited for (*source then SRV_CHAIN_WAITED); load_ms: the time spent
 * mapping. Returns the outcome; ISO_E_NOMEM is reported as SRV_CHAIN_BUSY with *out NULL. */
srv_chain_acquired srv_chains_acquire(srv_chains *r, const srv_chain_spec *spec, double distance, size_t triangles,
                                      int wait, srv_chain **out, srv_chain_source *source, double *load_ms);
/* 1 when a ready entry holds a partial chain (in memory, levels still to make). */
int srv_chain_partial(const srv_chain *c);
/* A ready entry's chain when held in memory (partial ones are), else NULL. */
const iso_mesh_chain *srv_chain_owned(const srv_chain *c);
/* A ready entry's chain (read-only, shared). */
const iso_mesh_chain *srv_chain_get(const srv_chain *c);
/* Level k may be cut from it: checks a mapped chain's positions and level k once
 * (iso_mesh_chain_map_check); ms: the time that took. 0 or ISO_E_CORRUPT (the entry is
 * then unusable: srv_chains_discard it). */
int srv_chain_prepare(srv_chain *c, int k, double *ms, iso_error *err);
/* Level 0's search grid for the measures against it (a budget's): built once on a mapped
 * chain (level 0 checked first) and weighed with it; ms its time. 0, ISO_E_CORRUPT (as
 * srv_chain_prepare) or ISO_E_NOMEM. */
int srv_chain_prepare_grid(srv_chains *r, srv_chain *c, double *ms, iso_error *err);
/* The caller's built chain (taken over, even on failure) into its BUILDING entry: written
 * to spec's file when there is one (a failure is reported and only costs a rebuild after
 * a restart), then mapped from it, else kept as built; waiters wake. */
void srv_chains_publish(srv_chains *r, srv_chain *c, const srv_chain_spec *spec, iso_mesh_chain *built);
/* The caller's extended copy (taken over) replaces TO_EXTEND entry c: written and mapped
 * when complete (as srv_chains_publish), else kept in memory, as a new entry with the
 * caller's reference (c keeps its readers until they release it; the caller still releases
 * c); waiters wake. NULL when c was discarded meanwhile or no memory (the copy is dropped). */
srv_chain *srv_chains_replace(srv_chains *r, srv_chain *c, const srv_chain_spec *spec, iso_mesh_chain *extended);
/* The caller could not extend TO_EXTEND entry c: it stays as it was, waiters wake. */
void srv_chains_extend_abandon(srv_chains *r, srv_chain *c);
/* Work for the background completer, which runs it at the lowest priority: an opaque task
 * that starts with this link (mesh_job.h's). */
typedef struct srv_chain_deferred {
    struct srv_chain_deferred *next;
} srv_chain_deferred;
/* Queues task when a completer takes work (1; the registry holds it), else 0 (the caller
 * keeps it). */
int srv_chains_defer(srv_chains *r, srv_chain_deferred *task);
/* The next task, waiting up to timeout_ms for one; NULL when none came. */
srv_chain_deferred *srv_chains_next_deferred(srv_chains *r, double timeout_ms);
/* The caller builds its BUILDING entry, or extends its TO_EXTEND one, at the lowest
 * priority (the background builder): a request that waits for it raises the building
 * thread to the normal policy. */
void srv_chains_building_idle(srv_chains *r, srv_chain *c);
/* The caller could not build it: the entry goes, waiters wake (one of them builds). */
void srv_chains_abandon(srv_chains *r, srv_chain *c);
/* A ready entry found corrupt after mapping (why): reported, removed with spec's file; the
 * caller's reference is given back. */
void srv_chains_discard(srv_chains *r, srv_chain *c, const srv_chain_spec *spec, const char *why);
/* Gives back a reference; then evicts above the limit. NULL is a no-op. */
void srv_chains_release(srv_chains *r, srv_chain *c);

/* The partial chains the registry holds (in memory, to be completed). */
size_t srv_chains_partial_count(srv_chains *r);
/* What the registry knows of spec's chain without building anything: 2 ready (*out with a
 * reference, mapped from its file if need be), 1 building (*out, with a reference, the
 * partial chain when there is one: its levels so far, else NULL), 0 none. */
int srv_chains_peek(srv_chains *r, const srv_chain_spec *spec, srv_chain **out);

#endif
