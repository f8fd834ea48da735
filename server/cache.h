/* cache.h: encoded mesh bodies and the LRU cache that keeps them.
 *
 * A body is shared: the cache holds one reference, every response being sent holds one,
 * and it is freed when the last lets go, so eviction never pulls bytes from under a
 * response in flight. The cache is bounded in bytes (the bodies' sizes) and evicts the
 * least recently used bodies first; one mutex guards it (operations are O(1) expected). */
#ifndef SRV_CACHE_H
#define SRV_CACHE_H

#include <pthread.h>
#include <stdatomic.h>
#include <stddef.h>

/* One encoded mesh and what its headers say about it. */
typedef struct srv_body {
    _Atomic int refs;
    unsigned char *data;
    size_t size;
    int gzip_wanted;                /* the format gains from gzip: its responses vary by
                                     * Accept-Encoding, the gzip form made on first demand */
    pthread_mutex_t gzip_lock;      /* held while the gzip form is made */
    int gzip_tried;                 /* under gzip_lock: the gzip form was made or refused */
    unsigned char *gzip_data;       /* the same bytes gzipped (malloc'd), or NULL */
    size_t gzip_size;
    const char *content_type;       /* static string */
    size_t triangles, vertices, cells_visited;
    double extract_ms, normals_ms, measure_ms, encode_ms, gzip_ms; /* the job's steps, in order */
    double error_bound, tolerance, area_mm2;
    int draco_speed;                /* the Draco speed used (draco and glb); -1 otherwise */
    int measured;                   /* the request asked for the measures (area_mm2, closed, volume_mm3) */
    double volume_mm3;              /* enclosed volume; meaningful only when closed */
    int closed;                     /* no open or non-manifold edge */
    int budget_fits;                /* -1: no budget asked; else 0 or 1 */
    int simplified;                 /* the budget was met by meshoptimizer (mesh/mesh.h) */
    double simplify_error_mm, simplify_error_voxels; /* its error estimate, when simplified */
    int distance_measured;          /* the four below were measured (mesh.h) */
    double distance_mm, distance_max_mm; /* p99 both ways, and max, from the exact surface */
    double distance_voxels;         /* distance_mm in voxels (the smallest spacing) */
    int chain_level;                /* the chain level answered (0: exact), -1: none */
    size_t exact_triangles;         /* the exact surface's triangles, when from a chain */
    size_t edges, pinch_edges, pinch_vertices; /* the answer's, when from a chain (mesh.h) */
    double vertex_offset_mm;        /* its vertices' move along the normals (0: none) */
    int min_component_asked;        /* min_component was given: the two below count */
    size_t components_removed;      /* closed components it removed */
    double removed_largest_mm;      /* the largest one's bounding-box diagonal (0: none) */
    const char *budget_source;      /* static: "chain" or "tolerance" (pipeline.h), or NULL */
    double budget_other_mm;         /* the measured p99 of the candidate not chosen, or -1 */
    const char *chain_source;       /* static: how the chain was had (chains.h), or NULL */
    double chain_load_ms;           /* mapping it and checking the levels cut */
    double chain_cut_ms;            /* cutting the level (0 when built here) */
    double chain_build_ms;          /* building it, when this request did */
} srv_body;

/* A body owning data (malloc'd, taken over), with one reference. NULL on no memory (data
 * is freed then). */
srv_body *srv_body_create(unsigned char *data, size_t size);
void srv_body_retain(srv_body *body);
/* The bytes the cache counts for it: both encodings. */
size_t srv_body_bytes(const srv_body *body);
/* Drops a reference; frees at zero. NULL is allowed. */
void srv_body_release(srv_body *body);

typedef struct srv_cache_item srv_cache_item;

typedef struct srv_cache {
    pthread_mutex_t lock;
    srv_cache_item **buckets;
    size_t bucket_count;
    srv_cache_item *newest, *oldest;  /* the LRU list */
    size_t bytes, limit, items;
    _Atomic unsigned long long hits, misses, evictions;
} srv_cache;

/* limit_bytes 0 disables caching (every get misses, put keeps nothing). 0 or ISO_E_NOMEM. */
int srv_cache_init(srv_cache *cache, size_t limit_bytes);
void srv_cache_destroy(srv_cache *cache);
/* The body cached under key, retained for the caller (release it), or NULL. Counts a hit
 * or a miss. */
srv_body *srv_cache_get(srv_cache *cache, const char *key);
/* Caches body under key (the cache retains it), replacing an older body under the same
 * key and evicting old ones until the total fits. A body larger than the whole limit is
 * not cached. */
void srv_cache_put(srv_cache *cache, const char *key, srv_body *body);
/* body, cached under key, has grown (its gzip form was made after it was cached): counts
 * its new bytes and evicts older bodies until the total fits again. Nothing if key now
 * holds another body or none. */
void srv_cache_grew(srv_cache *cache, const char *key, const srv_body *body);

#endif
