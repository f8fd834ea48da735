/* hash.h: the server's one string hash, FNV-1a (64 bits), for what it names by a short
 * digest: the memory cache's buckets, ETags, the catalog's id index and ids made from
 * UIDs, chain files and fetched archives' folders. Its values name files on disk, so they
 * must never change. It is fast and well spread, not a defence against chosen collisions. */
#ifndef SRV_HASH_H
#define SRV_HASH_H

#include <stdint.h>

/* FNV-1a of a NUL-terminated string's bytes. */
uint64_t srv_hash64(const char *s);

#endif
