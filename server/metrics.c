/* metrics.c: counters and their Prometheus text exposition (see metrics.h). */
#include "metrics.h"

#include <stdio.h>
#include <stdlib.h>
#include <string.h>

static const char *const route_names[SRV_ROUTE_COUNT] = {
    "volumes", "volume", "mesh", "healthz", "metrics", "static", "other", "segments", "segment_mesh", "chain", "status"};
static const int status_codes[SRV_STATUS_SLOTS - 1] = {200, 204, 304, 400, 404, 405,
                                                       414, 500, 503, 206};
/* Upper bounds in seconds. */
static const double latency_bounds[SRV_LATENCY_BUCKETS] = {
    0.0005, 0.001, 0.0025, 0.005, 0.01, 0.025, 0.05, 0.1, 0.25, 0.5, 1, 2.5, 5, 10};

void srv_metrics_init(srv_metrics *m)
{
    memset(m, 0, sizeof *m);
}

static int status_slot(int status)
{
    for (int s = 0; s < SRV_STATUS_SLOTS - 1; s++)
        if (status_codes[s] == status)
            return s;
    return SRV_STATUS_SLOTS - 1;
}

void srv_metrics_request(srv_metrics *m, srv_route route, int status, double ms, size_t bytes)
{
    atomic_fetch_add(&m->requests[route][status_slot(status)], 1);
    int b = 0;
    while (b < SRV_LATENCY_BUCKETS && ms / 1000 > latency_bounds[b])
        b++;
    atomic_fetch_add(&m->latency[route][b], 1);
    atomic_fetch_add(&m->latency_us_sum[route], (unsigned long long)(ms * 1000));
    atomic_fetch_add(&m->bytes_out, bytes);
}

static void requests(FILE *f, srv_metrics *m)
{
    fputs("# HELP isoserve_http_requests_total HTTP requests answered, by route and status.\n"
          "# TYPE isoserve_http_requests_total counter\n", f);
    for (int r = 0; r < SRV_ROUTE_COUNT; r++)
        for (int s = 0; s < SRV_STATUS_SLOTS; s++) {
            unsigned long long n = atomic_load(&m->requests[r][s]);
            if (!n)
                continue;
            if (s < SRV_STATUS_SLOTS - 1)
                fprintf(f, "isoserve_http_requests_total{route=\"%s\",status=\"%d\"} %llu\n",
                        route_names[r], status_codes[s], n);
            else
                fprintf(f, "isoserve_http_requests_total{route=\"%s\",status=\"other\"} %llu\n",
                        route_names[r], n);
        }
}

static void latency(FILE *f, srv_metrics *m)
{
    fputs("# HELP isoserve_http_request_duration_seconds Time from a request's arrival to its "
          "response being queued.\n# TYPE isoserve_http_request_duration_seconds histogram\n", f);
    for (int r = 0; r < SRV_ROUTE_COUNT; r++) {
        unsigned long long cumulative = 0;
        for (int b = 0; b <= SRV_LATENCY_BUCKETS; b++) {
            cumulative += atomic_load(&m->latency[r][b]);
            if (b < SRV_LATENCY_BUCKETS)
                fprintf(f, "isoserve_http_request_duration_seconds_bucket{route=\"%s\",le=\"%g\"} %llu\n",
                        route_names[r], latency_bounds[b], cumulative);
            else
                fprintf(f, "isoserve_http_request_duration_seconds_bucket{route=\"%s\",le=\"+Inf\"} %llu\n",
                        route_names[r], cumulative);
        }
        fprintf(f, "isoserve_http_request_duration_seconds_sum{route=\"%s\"} %.6f\n",
                route_names[r], (double)atomic_load(&m->latency_us_sum[r]) / 1e6);
        fprintf(f, "isoserve_http_request_duration_seconds_count{route=\"%s\"} %llu\n",
                route_names[r], cumulative);
    }
}

/* One metric with its HELP and TYPE lines. */
static void metric(FILE *f, const char *name, const char *type, const char *help, double value)
{
    fprintf(f, "# HELP %s %s\n# TYPE %s %s\n%s %.17g\n", name, help, name, type, name, value);
}

char *srv_metrics_render(srv_metrics *m, const srv_metrics_gauges *g, size_t *size)
{
    char *text = NULL;
    FILE *f = open_memstream(&text, size);
    if (!f)
        return NULL;
    requests(f, m);
    latency(f, m);
    metric(f, "isoserve_http_response_bytes_total", "counter", "Body bytes sent.",
           (double)atomic_load(&m->bytes_out));
    metric(f, "isoserve_mesh_cache_hits_total", "counter", "Mesh requests answered from the cache.",
           (double)g->cache_hits);
    metric(f, "isoserve_mesh_cache_misses_total", "counter", "Mesh requests not in the cache.",
           (double)g->cache_misses);
    metric(f, "isoserve_mesh_cache_evictions_total", "counter", "Bodies evicted to stay in bounds.",
           (double)g->cache_evictions);
    metric(f, "isoserve_mesh_cache_bytes", "gauge", "Bytes of cached bodies.", (double)g->cache_bytes);
    metric(f, "isoserve_mesh_cache_items", "gauge", "Cached bodies.", (double)g->cache_items);
    metric(f, "isoserve_mesh_cache_limit_bytes", "gauge", "The cache's bound (--cache-mb).",
           (double)g->cache_limit);
    metric(f, "isoserve_extractions_total", "counter", "Extractions run (coalesced requests share one).",
           (double)g->extractions_total);
    metric(f, "isoserve_coalesced_requests_total", "counter",
           "Mesh requests that joined an identical extraction already in flight.",
           (double)g->coalesced_total);
    metric(f, "isoserve_rejected_requests_total", "counter",
           "Mesh requests refused with 503 because the extraction queue was full.",
           (double)g->rejected_total);
    metric(f, "isoserve_extractions_in_flight", "gauge", "Extractions running now.",
           (double)g->extractions_running);
    metric(f, "isoserve_extraction_queue_length", "gauge", "Extractions waiting for a worker.",
           (double)g->queue_length);
    metric(f, "isoserve_extraction_queue_capacity", "gauge", "Queue bound (--queue).",
           (double)g->queue_capacity);
    metric(f, "isoserve_extraction_workers", "gauge", "Extraction threads (--threads).",
           (double)g->workers);
    metric(f, "isoserve_hierarchy_bytes", "gauge", "Bytes of all loaded hierarchies.",
           (double)g->hierarchy_bytes);
    metric(f, "isoserve_hierarchies_unsaved", "gauge",
           "Hierarchies built but not written to --cache-dir (disk full, read-only): served "
           "from memory, rebuilt at the next start.", (double)g->hierarchies_unsaved);
    metric(f, "isoserve_hierarchies_built_total", "counter",
           "Hierarchies built from a volume's samples.", (double)g->hierarchies_built);
    metric(f, "isoserve_hierarchies_read_total", "counter",
           "Hierarchies read back from --cache-dir (at a start, or after an eviction).",
           (double)g->hierarchies_read);
    metric(f, "isoserve_resident_bytes", "gauge",
           "Bytes of the loaded volumes: samples and hierarchies.", (double)g->resident_bytes);
    metric(f, "isoserve_resident_limit_bytes", "gauge", "Their bound (--max-resident-mb); 0: none.",
           (double)g->resident_limit);
    metric(f, "isoserve_volume_evictions_total", "counter",
           "Loaded volumes evicted, least recently used, to stay under --max-resident-mb.",
           (double)g->volume_evictions);
    metric(f, "isoserve_volumes_loaded", "gauge", "Volumes being served.", (double)g->volumes);
    metric(f, "isoserve_volumes_loaded_on_demand", "gauge",
           "Of those, volumes of another shard loaded at a request.", (double)g->volumes_on_demand);
    metric(f, "isoserve_volumes_in_catalog", "gauge", "Volumes the catalog names.",
           (double)g->volumes_total);
    metric(f, "isoserve_ready", "gauge", "1 once preloading is done.", g->ready);
    if (fclose(f)) {
        free(text);
        return NULL;
    }
    return text;
}
