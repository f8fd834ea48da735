/* shard.h: which replica preloads which volume. nginx in front of the replicas routes
 * /v1/volumes/{id}/... with `hash $volume_id consistent` (docker/nginx.conf); this module
 * computes the same ring, so that a replica started with --shard K/N --shard-peers LIST
 * preloads exactly the volumes nginx sends it first. Routing, not geometry.
 *
 * The ring (nginx's ngx_http_upstream_hash_module, ketama compatible with
 * Cache::Memcached::Fast): every peer "HOST:PORT" of weight 1 gets 160 points; point j is
 * CRC-32 of HOST, one NUL byte, PORT and the previous point as 4 little-endian bytes (0 for
 * the first). Points are sorted and equal ones merged. A key goes to the peer of the first
 * point >= CRC-32(key), wrapping to the first point. */
#ifndef SRV_SHARD_H
#define SRV_SHARD_H

#include <stddef.h>
#include <stdint.h>

#include "base/base.h"

#define SRV_SHARD_PEERS_MAX 1024
#define SRV_SHARD_POINTS_PER_PEER 160

typedef struct srv_shard_point {
    uint32_t hash;
    uint32_t peer;  /* index into peers */
} srv_shard_point;

typedef struct srv_shard_ring {
    char **peers;             /* the server strings, in the upstream block's order */
    size_t peer_count;
    srv_shard_point *points;  /* sorted by hash, no two equal */
    size_t point_count;
} srv_shard_ring;

/* Builds the ring of "HOST:PORT,HOST:PORT,..." (nginx's `server` names, exactly as written
 * in the upstream block, same order). Empty or duplicate names are an ISO_E_ARGUMENT. On
 * error nothing is left allocated. O(P log P) for P = 160 points per peer. */
int srv_shard_ring_init(srv_shard_ring *ring, const char *peers, iso_error *err);
/* The index of the peer nginx tries first for key. O(log P). */
size_t srv_shard_owner(const srv_shard_ring *ring, const char *key);
/* Accepts a zeroed or freed ring. */
void srv_shard_ring_free(srv_shard_ring *ring);

#endif
