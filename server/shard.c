/* shard.c: nginx's consistent-hash ring, recomputed (see shard.h). */
#include "shard.h"

#include <stdlib.h>
#include <string.h>
#include <strings.h>
#include <zlib.h>

/* nginx splits a server name at the last ':' when only digits follow it ("unix:" names
 * have no port); the host, a NUL byte and the port seed every point of that peer. */
static uint32_t peer_seed(const char *name)
{
    size_t len = strlen(name), host_len = len;
    const char *host = name, *port = "";
    if (len >= 5 && !strncasecmp(name, "unix:", 5)) {
        host = name + 5;
        host_len = len - 5;
    } else {
        size_t digits = 0;
        while (digits < len && name[len - 1 - digits] >= '0' && name[len - 1 - digits] <= '9')
            digits++;
        if (digits < len && name[len - 1 - digits] == ':') {
            host_len = len - 1 - digits;
            port = name + len - digits;
        }
    }
    uLong crc = crc32(0L, (const Bytef *)host, (uInt)host_len);
    crc = crc32(crc, (const Bytef *)"", 1);
    return (uint32_t)crc32(crc, (const Bytef *)port, (uInt)strlen(port));
}

static int by_hash(const void *a, const void *b)
{
    const srv_shard_point *p = a, *q = b;
    if (p->hash != q->hash)
        return p->hash < q->hash ? -1 : 1;
    return p->peer < q->peer ? -1 : p->peer > q->peer;
}

/* Splits the comma-separated list into ring->peers; 0 or an error. */
static int split_peers(srv_shard_ring *ring, const char *peers, iso_error *err)
{
    size_t count = 1;
    for (const char *p = peers; *p; p++)
        count += *p == ',';
    if (count > SRV_SHARD_PEERS_MAX)
        return iso_error_set(err, ISO_E_ARGUMENT, "--shard-peers: %zu peers; at most %d",
                             count, SRV_SHARD_PEERS_MAX);
    ring->peers = calloc(count, sizeof *ring->peers);
    if (!ring->peers)
        return iso_error_set(err, ISO_E_NOMEM, "out of memory for the shard ring");
    for (const char *p = peers;; p++) {
        size_t len = strcspn(p, ",");
        if (len == 0)
            return iso_error_set(err, ISO_E_ARGUMENT, "--shard-peers %s: an empty peer name", peers);
        char *name = strndup(p, len);
        if (!name)
            return iso_error_set(err, ISO_E_NOMEM, "out of memory for the shard ring");
        ring->peers[ring->peer_count++] = name;
        for (size_t i = 0; i + 1 < ring->peer_count; i++)
            if (!strcmp(ring->peers[i], name))
                return iso_error_set(err, ISO_E_ARGUMENT, "--shard-peers: %s is named twice", name);
        p += len;
        if (!*p)
            return 0;
    }
}

int srv_shard_ring_init(srv_shard_ring *ring, const char *peers, iso_error *err)
{
    memset(ring, 0, sizeof *ring);
    int rc = split_peers(ring, peers, err);
    if (rc)
        goto err;
    ring->points = calloc(ring->peer_count * SRV_SHARD_POINTS_PER_PEER, sizeof *ring->points);
    if (!ring->points) {
        rc = iso_error_set(err, ISO_E_NOMEM, "out of memory for the shard ring");
        goto err;
    }
    for (size_t p = 0; p < ring->peer_count; p++) {
        uLong seed = peer_seed(ring->peers[p]);
        uint32_t prev = 0;
        for (int j = 0; j < SRV_SHARD_POINTS_PER_PEER; j++) {
            const Bytef le[4] = {(Bytef)(prev & 0xff), (Bytef)(prev >> 8 & 0xff),
                                 (Bytef)(prev >> 16 & 0xff), (Bytef)(prev >> 24)};
            prev = (uint32_t)crc32(seed, le, 4);
            ring->points[ring->point_count++] = (srv_shard_point){prev, (uint32_t)p};
        }
    }
    /* nginx merges equal points keeping one (which one its qsort leaves is unspecified;
     * with 160 points per peer a tie is a chance in tens of millions per pair). */
    qsort(ring->points, ring->point_count, sizeof *ring->points, by_hash);
    size_t kept = 1;
    for (size_t i = 1; i < ring->point_count; i++)
        if (ring->points[i].hash != ring->points[kept - 1].hash)
            ring->points[kept++] = ring->points[i];
    ring->point_count = kept;
    return 0;
err:
    srv_shard_ring_free(ring);
    return rc;
}

size_t srv_shard_owner(const srv_shard_ring *ring, const char *key)
{
    uint32_t h = (uint32_t)crc32(0L, (const Bytef *)key, (uInt)strlen(key));
    size_t lo = 0, hi = ring->point_count; /* the first point >= h */
    while (lo < hi) {
        size_t mid = lo + (hi - lo) / 2;
        if (ring->points[mid].hash < h)
            lo = mid + 1;
        else
            hi = mid;
    }
    return ring->points[lo % ring->point_count].peer;
}

void srv_shard_ring_free(srv_shard_ring *ring)
{
    if (!ring)
        return;
    for (size_t i = 0; ring->peers && i < ring->peer_count; i++)
        free(ring->peers[i]);
    free(ring->peers);
    free(ring->points);
    memset(ring, 0, sizeof *ring);
}
