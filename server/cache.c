/* cache.c: shared mesh bodies and their byte-bounded LRU cache (see cache.h). */
#include "cache.h"

#include <stdint.h>
#include <stdlib.h>
#include <string.h>

#include "mesh/mesh.h"

#include "base/base.h"
#include "hash.h"

struct srv_cache_item {
    char *key;
    uint64_t hash;
    srv_body *body;
    size_t bytes;                   /* what the cache counts for it (srv_body_bytes) */
    srv_cache_item *chain;          /* next in the bucket */
    srv_cache_item *newer, *older;  /* LRU list */
};

srv_body *srv_body_create(unsigned char *data, size_t size)
{
    srv_body *body = calloc(1, sizeof *body);
    if (!body) {
        free(data);
        return NULL;
    }
    atomic_init(&body->refs, 1);
    pthread_mutex_init(&body->gzip_lock, NULL);
    body->data = data;
    body->size = size;
    body->budget_fits = -1;
    body->draco_speed = -1;
    body->chain_level = -1;
    return body;
}

void srv_body_retain(srv_body *body)
{
    atomic_fetch_add(&body->refs, 1);
}

size_t srv_body_bytes(const srv_body *body)
{
    return body->size + body->gzip_size;
}

void srv_body_release(srv_body *body)
{
    if (body && atomic_fetch_sub(&body->refs, 1) == 1) {
        free(body->data);
        free(body->gzip_data);
        pthread_mutex_destroy(&body->gzip_lock);
        free(body);
    }
}

int srv_cache_init(srv_cache *cache, size_t limit_bytes)
{
    memset(cache, 0, sizeof *cache);
    cache->limit = limit_bytes;
    cache->bucket_count = 4096;
    cache->buckets = calloc(cache->bucket_count, sizeof *cache->buckets);
    if (!cache->buckets)
        return ISO_E_NOMEM;
    pthread_mutex_init(&cache->lock, NULL);
    return 0;
}

/* Unlinks item from its bucket and the LRU list. Lock held. */
static void unlink_item(srv_cache *cache, srv_cache_item *item)
{
    srv_cache_item **slot = &cache->buckets[item->hash % cache->bucket_count];
    while (*slot != item)
        slot = &(*slot)->chain;
    *slot = item->chain;
    if (item->newer)
        item->newer->older = item->older;
    else
        cache->newest = item->older;
    if (item->older)
        item->older->newer = item->newer;
    else
        cache->oldest = item->newer;
    cache->bytes -= item->bytes;
    cache->items--;
}

static void free_item(srv_cache_item *item)
{
    srv_body_release(item->body);
    free(item->key);
    free(item);
}

void srv_cache_destroy(srv_cache *cache)
{
    if (!cache->buckets)
        return;
    while (cache->oldest) {
        srv_cache_item *item = cache->oldest;
        unlink_item(cache, item);
        free_item(item);
    }
    free(cache->buckets);
    pthread_mutex_destroy(&cache->lock);
    memset(cache, 0, sizeof *cache);
}

static srv_cache_item *lookup(srv_cache *cache, const char *key, uint64_t hash)
{
    for (srv_cache_item *i = cache->buckets[hash % cache->bucket_count]; i; i = i->chain)
        if (i->hash == hash && !strcmp(i->key, key))
            return i;
    return NULL;
}

/* Puts item at the newest end of the LRU list. Lock held. */
static void push_newest(srv_cache *cache, srv_cache_item *item)
{
    item->newer = NULL;
    item->older = cache->newest;
    if (cache->newest)
        cache->newest->newer = item;
    cache->newest = item;
    if (!cache->oldest)
        cache->oldest = item;
}

/* Unlinks the least recently used items, never `keep`, until `more` bytes fit under the
 * limit; returns them chained onto `evicted`, to be freed outside the lock. Lock held. */
static srv_cache_item *evict(srv_cache *cache, size_t more, const srv_cache_item *keep,
                             srv_cache_item *evicted)
{
    srv_cache_item *victim = cache->oldest;
    while (victim && cache->bytes + more > cache->limit) {
        srv_cache_item *next = victim->newer;
        if (victim != keep) {
            unlink_item(cache, victim);
            victim->chain = evicted;
            evicted = victim;
            atomic_fetch_add(&cache->evictions, 1);
        }
        victim = next;
    }
    return evicted;
}

static void free_items(srv_cache_item *items)
{
    while (items) {
        srv_cache_item *next = items->chain;
        free_item(items);
        items = next;
    }
}

srv_body *srv_cache_get(srv_cache *cache, const char *key)
{
    uint64_t hash = srv_hash64(key);
    pthread_mutex_lock(&cache->lock);
    srv_cache_item *item = lookup(cache, key, hash);
    srv_body *body = NULL;
    if (item) {
        /* Move to the newest end: unlink from the list only (it stays in its bucket). */
        if (item != cache->newest) {
            item->newer->older = item->older;
            if (item->older)
                item->older->newer = item->newer;
            else
                cache->oldest = item->newer;
            push_newest(cache, item);
        }
        body = item->body;
        srv_body_retain(body);
    }
    pthread_mutex_unlock(&cache->lock);
    atomic_fetch_add(item ? &cache->hits : &cache->misses, 1);
    return body;
}

void srv_cache_put(srv_cache *cache, const char *key, srv_body *body)
{
    if (srv_body_bytes(body) > cache->limit)
        return;
    srv_cache_item *item = calloc(1, sizeof *item);
    char *copy = strdup(key);
    if (!item || !copy) { /* caching is an optimisation: without memory, skip it */
        free(item);
        free(copy);
        return;
    }
    item->key = copy;
    item->hash = srv_hash64(key);
    item->body = body;
    item->bytes = srv_body_bytes(body);
    srv_body_retain(body);
    srv_cache_item *evicted = NULL;
    pthread_mutex_lock(&cache->lock);
    srv_cache_item *old = lookup(cache, key, item->hash);
    if (old) {
        unlink_item(cache, old);
        old->chain = evicted;
        evicted = old;
    }
    evicted = evict(cache, item->bytes, NULL, evicted);
    srv_cache_item **slot = &cache->buckets[item->hash % cache->bucket_count];
    item->chain = *slot;
    *slot = item;
    push_newest(cache, item);
    cache->bytes += item->bytes;
    cache->items++;
    pthread_mutex_unlock(&cache->lock);
    free_items(evicted);
}

void srv_cache_grew(srv_cache *cache, const char *key, const srv_body *body)
{
    uint64_t hash = srv_hash64(key);
    srv_cache_item *evicted = NULL;
    pthread_mutex_lock(&cache->lock);
    srv_cache_item *item = lookup(cache, key, hash);
    if (item && item->body == body && srv_body_bytes(body) > item->bytes) {
        size_t more = srv_body_bytes(body) - item->bytes;
        evicted = evict(cache, more, item, NULL);
        item->bytes += more;
        cache->bytes += more;
    }
    pthread_mutex_unlock(&cache->lock);
    free_items(evicted);
}
