/* metrics.h: what /metrics reports, in Prometheus' text format: requests by route and
 * status, a latency histogram, bytes out, and gauges read from the cache, the pool and the
 * collection when scraped. Counters are atomics: recording costs no lock. */
#ifndef SRV_METRICS_H
#define SRV_METRICS_H

#include <stdatomic.h>
#include <stddef.h>

typedef enum srv_route {
    SRV_ROUTE_VOLUMES, SRV_ROUTE_VOLUME, SRV_ROUTE_MESH, SRV_ROUTE_HEALTH,
    SRV_ROUTE_METRICS, SRV_ROUTE_STATIC, SRV_ROUTE_OTHER, SRV_ROUTE_SEGMENTS, SRV_ROUTE_SEGMENT_MESH,
    SRV_ROUTE_CHAIN, SRV_ROUTE_STATUS, SRV_ROUTE_COUNT
} srv_route;

#define SRV_STATUS_SLOTS 11  /* the statuses the server sends, plus "other" */
#define SRV_LATENCY_BUCKETS 14

typedef struct srv_metrics {
    _Atomic unsigned long long requests[SRV_ROUTE_COUNT][SRV_STATUS_SLOTS];
    _Atomic unsigned long long latency[SRV_ROUTE_COUNT][SRV_LATENCY_BUCKETS + 1]; /* +Inf */
    _Atomic unsigned long long latency_us_sum[SRV_ROUTE_COUNT];
    _Atomic unsigned long long bytes_out;
} srv_metrics;

/* Values read at scrape time from the other modules. */
typedef struct srv_metrics_gauges {
    unsigned long long cache_hits, cache_misses, cache_evictions;
    size_t cache_bytes, cache_items, cache_limit;
    size_t queue_length, queue_capacity, extractions_running, workers;
    unsigned long long extractions_total, coalesced_total, rejected_total;
    size_t hierarchy_bytes, hierarchies_unsaved, volumes, volumes_on_demand, volumes_total;
    size_t resident_bytes, resident_limit;
    unsigned long long volume_evictions, hierarchies_built, hierarchies_read;
    int ready;
} srv_metrics_gauges;

void srv_metrics_init(srv_metrics *m);
/* Records one finished request. */
void srv_metrics_request(srv_metrics *m, srv_route route, int status, double ms, size_t bytes);
/* The exposition text (malloc'd, NUL-terminated), or NULL on no memory. */
char *srv_metrics_render(srv_metrics *m, const srv_metrics_gauges *g, size_t *size);

#endif
