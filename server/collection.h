/* collection.h: the volumes the daemon serves, loaded with their hierarchies.
 *
 * Preloading runs in its own thread while the HTTP server already answers (healthz says
 * 503 until it is done). Each catalog entry has one slot (its index in the catalog) with a
 * state, a reference count and a last-used stamp, all under the collection's lock. A
 * replica of a sharded deployment preloads only its share of the catalog and loads any
 * other entry on demand, at its first request (so that failover works), through the same
 * loader and hierarchy cache; loads are serialised per entry by the same lock.
 *
 * Bounded memory (max_resident_bytes): a request holds a reference to its volume from
 * srv_collection_acquire to srv_collection_release, a mesh job its own. After each load on
 * demand and each release of a volume's last holder, while the resident bytes (samples and
 * hierarchies) exceed the cap, the least recently used volume nobody holds is evicted: its memory freed, its slot idle again. Its
 * hierarchy file stays in the cache dir, so the next request reads it back instead of
 * building it. Volumes in use are never evicted, so the cap is a target they may exceed. */
#ifndef SRV_COLLECTION_H
#define SRV_COLLECTION_H

#include <pthread.h>
#include <stdatomic.h>
#include <stddef.h>
#include <stdint.h>

#include "catalog.h"
#include "document.h"
#include "hierarchy/tree.h"
#include "segment/segment.h"
#include "volume/volume.h"

#define SRV_HISTOGRAM_BINS 256
/* A hierarchy's temporary file unchanged for this long before a start has no writer left
 * (see srv_collection_preload). */
#define SRV_TEMP_STALE_S 60
/* After its source server (an archive) failed, an entry is tried again at a request no
 * sooner than SRV_RETRY_FIRST_S later, the wait doubling with each failure in a row up to
 * SRV_RETRY_MAX_S: an outage costs the archive one attempt per entry per wait, and a
 * recovered archive is used again within SRV_RETRY_MAX_S, without a restart. */
#define SRV_RETRY_FIRST_S 1
#define SRV_RETRY_MAX_S 30

typedef struct srv_volume {
    const srv_catalog_entry *entry;   /* borrowed from the catalog */
    iso_volume *vol;
    iso_tree *tree;
    iso_segmentation *seg;            /* a segmentation (catalog "labels", .seg.nrrd, DICOM
                                         SEG), else NULL: it owns vol and tree then (its
                                         first layer's) */
    char version[48];                 /* samples, geometry, segment table and algorithm: the
                                         ETag base */
    uint64_t histogram[SRV_HISTOGRAM_BINS];
    double levels[SRV_LEVELS_MAX];    /* the catalog's, else Otsu's */
    size_t level_count;
    int tree_from_file;               /* 1: read from the cache dir */
    int on_demand;                    /* 1: loaded at a request, not preloaded */
    int tree_unsaved;                 /* 1: built, but the cache dir refused the file (disk
                                         full, read-only): served from memory only, and so
                                         never evicted */
    size_t bytes;                     /* resident: samples and hierarchy */
    unsigned refs;                    /* requests and jobs holding it (under the lock) */
    unsigned long long last_used;     /* the collection's use counter at its last acquire */
} srv_volume;

typedef struct srv_preload_options {
    const char *cache_dir;            /* hierarchy files; NULL: always build */
    uint64_t max_volume_bytes;        /* 0: the core's default */
    const unsigned char *skip;        /* per catalog entry, 1: not preloaded here (another
                                         replica's shard); NULL: preload every entry */
    uint64_t max_resident_bytes;      /* 0: no limit; else loaded volumes are evicted least
                                         recently used above it (needs cache_dir) */
} srv_preload_options;

typedef struct srv_collection {
    srv_volume *volumes;              /* one slot per catalog entry, valid when LOADED */
    _Atomic size_t count;             /* loaded volumes */
    _Atomic size_t attempted;         /* catalog entries tried so far */
    size_t total;                     /* catalog entries */
    _Atomic int ready;                /* every entry tried */
    _Atomic int stop;                 /* set on shutdown: preloading ends after the volume at hand */
    _Atomic size_t on_demand;         /* volumes loaded at a request */
    _Atomic size_t unsaved;           /* hierarchies the cache dir refused (tree_unsaved) */
    _Atomic size_t resident;          /* bytes of the loaded volumes (srv_volume.bytes) */
    _Atomic size_t hierarchy_bytes;   /* of those, the hierarchies' */
    _Atomic unsigned long long evictions, trees_built, trees_read;
    unsigned long long uses;          /* acquires so far: the LRU clock (under the lock) */
    const srv_catalog *catalog;
    srv_preload_options options;      /* also for loads on demand */
    pthread_mutex_t lock;             /* guards the slots: state, volumes, refs */
    pthread_cond_t changed;           /* an entry's state changed */
    unsigned char *state;             /* per catalog entry: SRV_ENTRY_* */
    iso_error *failure;               /* per catalog entry: why it failed (SRV_ENTRY_FAILED) */
    unsigned char *upstream;          /* per catalog entry: 1 if its source server failed */
    double *retry_at;                 /* per catalog entry: when a failed source may be asked
                                         again (iso_clock_ms), after upstream failures */
    unsigned *attempts;               /* per catalog entry: upstream failures in a row */
} srv_collection;

/* An entry's life: IDLE -> LOADING -> LOADED or FAILED; LOADED -> IDLE when evicted;
 * FAILED -> IDLE when its source is asked again. */
enum { SRV_ENTRY_IDLE, SRV_ENTRY_LOADING, SRV_ENTRY_LOADED, SRV_ENTRY_FAILED };

/* Prepares an empty collection for the catalog (which must outlive it); options are
 * copied (their strings and skip array must outlive it too). 0 or ISO_E_NOMEM. */
int srv_collection_init(srv_collection *c, const srv_catalog *catalog,
                        const srv_preload_options *options);
/* First removes from the cache dir the temporary hierarchy files of catalog ids that a
 * killed writer left, unchanged for SRV_TEMP_STALE_S before now (each one logged, as are
 * the younger ones it keeps). Then loads every entry of the catalog in order (but those
 * the options skip): the volume, then its hierarchy from the cache dir when that file is
 * valid and newer than the volume, else built (progress on the terminal) and written there
 * atomically. A volume that fails to load is reported and skipped. With a cap on resident
 * bytes, preloading stops once they reach it (the rest load on demand). Sets ready at the
 * end. Blocking: run it in a thread; setting c->stop ends it after the volume at hand. */
void srv_collection_preload(srv_collection *c);
/* What srv_collection_acquire found; server/status.c maps it to an HTTP status. */
typedef enum srv_volume_state {
    SRV_VOLUME_READY,           /* loaded: *out is set */
    SRV_VOLUME_UNKNOWN,         /* the catalog has no such id */
    SRV_VOLUME_UPSTREAM_FAILED, /* its source server (an archive) was unreachable or answered an
                                   error: tried again after a backoff (SRV_RETRY_FIRST_S) */
    SRV_VOLUME_FAILED           /* loading or building failed otherwise */
} srv_volume_state;

/* The volume with this id, loaded now (as preloading would) if the catalog names it and
 * it is not loaded yet, with a reference the caller gives back with srv_collection_release
 * (it is not evicted until then); concurrent callers for one id wait for one load. Blocking for as
 * long as the load takes. A failure is reported on stderr; later calls fail at once, and
 * srv_collection_failure says why. An upstream failure is retried by the first call after
 * its backoff has passed; other failures are final (the files came and are bad). */
srv_volume_state srv_collection_acquire(srv_collection *c, const char *id, const srv_volume **out);
/* Another reference to a volume the caller holds (a job that may outlive its request). */
void srv_collection_retain(srv_collection *c, const srv_volume *v);
/* Gives back a reference of srv_collection_acquire or srv_collection_retain; NULL is a no-op. */
void srv_collection_release(srv_collection *c, const srv_volume *v);
/* The listing's view of the slots: between lock and unlock, srv_collection_loaded gives
 * the volume of catalog entry i if it is loaded (else NULL); it is not evicted meanwhile. */
void srv_collection_lock(srv_collection *c);
const srv_volume *srv_collection_loaded(const srv_collection *c, size_t i);
void srv_collection_unlock(srv_collection *c);
/* Copies why the entry with this id failed to load into why ("" if it did not fail).
 * Returns the seconds until it is tried again (at least 1), 0 when it will not be. */
unsigned srv_collection_failure(srv_collection *c, const char *id, char *why, size_t size);
void srv_collection_free(srv_collection *c);

/* What the API says of a volume beside its samples, set when it is loaded and by `isoserve
 * info` for the same file, so that the two agree: its version (the ETag base: samples
 * through volume_crc, the hierarchy's iso_tree_volume_crc, geometry and the mesh algorithm),
 * its histogram and its suggested levels (the catalog's, else Otsu's). */
void srv_volume_describe(srv_volume *v, uint32_t volume_crc);
/* The document /v1/volumes and /v1/volumes/{id} give of v (document.h), the hierarchy's
 * figures when v->tree is set: name and modality the catalog's where it gives them, else
 * the volume's own (a DICOM series' SeriesDescription and Modality). shard: the replica
 * that preloads it, or NULL. */
proto_volume_doc srv_volume_doc(const srv_volume *v, const char *shard);

#endif
