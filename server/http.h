/* http.h: the daemon's HTTP side (libmicrohttpd): routing, responses, CORS, conditional
 * requests, the access log. It turns requests into calls on the collection, the cache and
 * the pool, and their answers into responses; it holds no algorithm.
 *
 * Threading: one thread per connection (libmicrohttpd's THREAD_PER_CONNECTION), so a
 * request waiting for its extraction blocks only its own connection; the extraction
 * itself runs on the pool, whose size bounds the CPU used. */
#ifndef SRV_HTTP_H
#define SRV_HTTP_H

#include <stdatomic.h>
#include <stddef.h>

#include "cache.h"
#include "chains.h"
#include "collection.h"
#include "base/base.h"
#include "metrics.h"
#include "pool.h"
#include "shard.h"

/* Longest request target (path plus query) accepted; longer ones get 414. */
#define SRV_URI_MAX 4096

typedef struct srv_http_config {
    const char *host;              /* numeric address or name to bind */
    unsigned port;                 /* 0: any free port (see srv_server.port) */
    const char *web_root;          /* resolved directory of the web client, or NULL */
    const char *const *cors_origins; /* allowed origins; none: "*" */
    size_t cors_origin_count;
    unsigned max_connections, connection_timeout_s;
    unsigned retry_after_s;        /* in 503 answers */
    const char *replica_name;      /* X-Iso-Replica on every response */
    const srv_shard_ring *shard_ring; /* sharded: /v1/volumes lists the catalog with each
                                         volume's shard; NULL: the loaded volumes in full */
    const char *token;             /* --token-file's token: /v1 and /metrics need
                                      "Authorization: Bearer TOKEN"; NULL: open */
    size_t max_triangles;          /* --max-triangles: larger meshes get 422; 0: no limit */
} srv_http_config;

struct MHD_Daemon;
struct MHD_Response;

typedef struct srv_server {
    srv_http_config config;
    srv_collection *collection;
    srv_cache *cache;
    srv_chains *chains;            /* distance= and budget= chains; NULL: built per request */
    srv_pool *pool;
    srv_metrics metrics;
    struct MHD_Daemon *daemon;
    struct MHD_Response *out_of_memory; /* the constant 503 of a failed allocation */
    unsigned port;                 /* the port bound */
    _Atomic int in_flight;         /* requests begun and not yet completed */
    int listen_socket;             /* after quiesce, closed by srv_http_stop */
} srv_server;

/* Starts listening; the caller has filled config, collection, cache and pool. */
int srv_http_start(srv_server *server, iso_error *err);
/* Stops accepting new connections; requests in flight go on. */
void srv_http_quiesce(srv_server *server);
/* Waits up to timeout_ms for requests in flight to complete; returns how many remain. */
int srv_http_drain(srv_server *server, double timeout_ms);
/* Closes every connection and stops the daemon's threads. */
void srv_http_stop(srv_server *server);

#endif
