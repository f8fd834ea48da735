/* http.c: routes, responses and the request life cycle over libmicrohttpd (see http.h).
 *
 * A request's life: the access handler is called first with no state (we attach a
 * srv_request with its start time), then again to answer; the completion callback logs
 * it, counts it in the metrics and frees the state. Every response is created, given its
 * headers, queued and destroyed at once. */
#include "http.h"

#include <jansson.h>
#include <math.h>
#include <microhttpd.h>
#include <netdb.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <strings.h>
#include <time.h>
#include <unistd.h>

#include "base/base.h"
#include "document.h"
#include "hash.h"
#include "mesh_job.h"
#include "query.h"
#include "static_files.h"
#include "status.h"

#define MAX_PARAMS 32

typedef struct srv_request {
    double start;
    srv_route route;
    int status;
    size_t bytes;
    const srv_volume *volume;      /* the volume a response concerns (X-Iso-Load), or NULL */
    unsigned retry_after_s;        /* a 503's Retry-After when not the configured one, or 0 */
    char method[16];
    char path[256];
} srv_request;

static const char expose_headers[] =
    "ETag, X-Iso-Triangles, X-Iso-Vertices, X-Iso-Cells-Visited, X-Iso-Extract-Ms, "
    "X-Iso-Normals-Ms, X-Iso-Measure-Ms, X-Iso-Encode-Ms, X-Iso-Draco-Speed, X-Iso-Error-Bound, "
    "X-Iso-Tolerance, X-Iso-Area-Mm2, X-Iso-Volume-Mm3, X-Iso-Budget-Fits, X-Iso-Simplified, "
    "X-Iso-Simplify-Error-Mm, X-Iso-Simplify-Error-Voxels, X-Iso-Distance-Mm, "
    "X-Iso-Distance-Max-Mm, X-Iso-Distance-Voxels, X-Iso-Chain-Level, X-Iso-Exact-Triangles, "
    "X-Iso-Edges, X-Iso-Pinch-Edges, X-Iso-Pinch-Vertices, X-Iso-Vertex-Offset-Mm, "
    "X-Iso-Budget-Source, X-Iso-Budget-Other-Distance-Mm, X-Iso-Chain-Source, X-Iso-Chain-Load-Ms, "
    "X-Iso-Chain-Cut-Ms, X-Iso-Chain-Build-Ms, X-Iso-Components-Removed, X-Iso-Removed-Largest-Mm, "
    "X-Iso-Cache, X-Iso-Replica, X-Iso-Load, X-Iso-Total, Link";

/* ---------------------------------------------------------------- responses */

/* Set when adding a header to the response being built on this thread failed
 * (libmicrohttpd allocates every header). A response missing a header is not the answer
 * (a mesh without its error bound, a body without its type), so send_response answers
 * 503 instead. Each connection has a thread of its own (MHD_USE_THREAD_PER_CONNECTION),
 * which builds and queues its responses; on_request clears the flag for each request. */
static _Thread_local int header_failed;

static void add_header(struct MHD_Response *r, const char *name, const char *value)
{
    if (MHD_add_response_header(r, name, value) != MHD_YES)
        header_failed = 1;
}

static void add_cors(const srv_server *s, struct MHD_Connection *c, struct MHD_Response *r)
{
    const char *origin = MHD_lookup_connection_value(c, MHD_HEADER_KIND, "Origin");
    if (s->config.cors_origin_count == 0) {
        add_header(r, "Access-Control-Allow-Origin", "*");
    } else {
        add_header(r, "Vary", "Origin");
        for (size_t i = 0; origin && i < s->config.cors_origin_count; i++)
            if (!strcmp(origin, s->config.cors_origins[i]))
                add_header(r, "Access-Control-Allow-Origin", origin);
    }
    add_header(r, "Access-Control-Expose-Headers", expose_headers);
}

/* The answer when the HTTP layer itself cannot allocate (a request's record, a response,
 * a body): made once at start from a constant body, so sending it allocates nothing of
 * ours, and answered 503 with Retry-After like the other overload paths instead of
 * dropping the connection. */
static char out_of_memory_body[] = /* not const: MHD takes a void * it never writes */
    "{\"type\":\"urn:isoserve:problem:unavailable\",\"title\":\"Service Unavailable\","
    "\"status\":503,\"detail\":\"the server is out of memory; retry later\"}";

static enum MHD_Result send_out_of_memory(srv_server *s, struct MHD_Connection *c,
                                          srv_request *req)
{
    if (req)
        req->status = 503;
    if (!s->out_of_memory)
        return MHD_NO;
    return MHD_queue_response(c, 503, s->out_of_memory);
}

/* Queues r with status, records what the log and metrics need, destroys r. */
static enum MHD_Result send_response(srv_server *s, struct MHD_Connection *c, srv_request *req,
                                     int status, struct MHD_Response *r, size_t bytes)
{
    if (!r) {
        header_failed = 0;
        return send_out_of_memory(s, c, req);
    }
    add_cors(s, c, r);
    /* Which replica answered, and whether it had the volume preloaded (its shard) or
     * loaded it on demand (a failover): what a deployment behind nginx is checked by. */
    if (s->config.replica_name)
        add_header(r, "X-Iso-Replica", s->config.replica_name);
    if (req->volume)
        add_header(r, "X-Iso-Load", req->volume->on_demand ? "on-demand" : "preloaded");
    if (header_failed) {
        header_failed = 0;
        MHD_destroy_response(r);
        return send_out_of_memory(s, c, req);
    }
    req->status = status;
    req->bytes = bytes;
    enum MHD_Result ok = MHD_queue_response(c, (unsigned)status, r);
    MHD_destroy_response(r);
    return ok;
}

/* A response owning a malloc'd NUL-terminated text (freed with it, or here on failure). */
static struct MHD_Response *text_response(char *text, const char *content_type,
                                          const char *cache_control, size_t *size)
{
    if (!text)
        return NULL;
    *size = strlen(text);
    struct MHD_Response *r = MHD_create_response_from_buffer(*size, text, MHD_RESPMEM_MUST_FREE);
    if (!r) {
        free(text);
        return NULL;
    }
    add_header(r, MHD_HTTP_HEADER_CONTENT_TYPE, content_type);
    add_header(r, MHD_HTTP_HEADER_CACHE_CONTROL, cache_control);
    return r;
}

static void add_retry_after(const srv_server *s, struct MHD_Response *r, unsigned seconds)
{
    char retry[16];
    snprintf(retry, sizeof retry, "%u", seconds ? seconds : s->config.retry_after_s);
    add_header(r, MHD_HTTP_HEADER_RETRY_AFTER, retry);
}

static enum MHD_Result send_text(srv_server *s, struct MHD_Connection *c, srv_request *req,
                                 int status, char *text, const char *content_type,
                                 const char *cache_control)
{
    size_t size = 0;
    struct MHD_Response *r = text_response(text, content_type, cache_control, &size);
    return send_response(s, c, req, status, r, size);
}

static enum MHD_Result send_problem(srv_server *s, struct MHD_Connection *c, srv_request *req,
                                    const proto_problem *problem, const char *path)
{
    char *body = proto_json_problem(problem, path);
    if (!body) /* jansson refused a string (never expected): a fixed body still says what */
        body = strdup("{\"type\":\"urn:isoserve:problem:internal\",\"title\":\"Error\"}");
    size_t size = 0;
    struct MHD_Response *r = text_response(body, "application/problem+json", "no-store", &size);
    if (r && problem->status == 405)
        add_header(r, MHD_HTTP_HEADER_ALLOW, "GET, HEAD, OPTIONS");
    if (r && problem->status == 401)
        add_header(r, MHD_HTTP_HEADER_WWW_AUTHENTICATE, "Bearer realm=\"isoserve\"");
    if (r && problem->status == 503)
        add_retry_after(s, r, req ? req->retry_after_s : 0);
    return send_response(s, c, req, problem->status, r, size);
}

static enum MHD_Result fail(srv_server *s, struct MHD_Connection *c, srv_request *req,
                            const char *path, int status, const char *fmt, ...)
#if defined(__GNUC__)
    __attribute__((format(printf, 6, 7)))
#endif
    ;
static enum MHD_Result fail(srv_server *s, struct MHD_Connection *c, srv_request *req,
                            const char *path, int status, const char *fmt, ...)
{
    proto_problem problem = {.status = status};
    va_list ap;
    va_start(ap, fmt);
    vsnprintf(problem.detail, sizeof problem.detail, fmt, ap);
    va_end(ap);
    return send_problem(s, c, req, &problem, path);
}

/* ---------------------------------------------------------------- documents */

static proto_volume_doc doc_of(const srv_server *s, const srv_volume *v)
{
    const srv_shard_ring *ring = s->config.shard_ring;
    return srv_volume_doc(v, ring ? ring->peers[srv_shard_owner(ring, v->entry->id)] : NULL);
}

/* A page of /v1/volumes: ?limit=N (1..SRV_PAGE_MAX) and ?after=ID (the last id of the
 * previous page) pick positions [first, first + count) of the listing; without either, the
 * whole listing. */
#define SRV_PAGE_MAX 10000

typedef struct srv_page {
    size_t first, count, total;
} srv_page;

/* Reads limit and after; the position just after the id of after comes from position_of
 * (SIZE_MAX when the catalog has no such id). 0, or ISO_E_ARGUMENT with detail saying what
 * is wrong. */
static int read_page(struct MHD_Connection *c, const void *listing, size_t total,
                     size_t (*position_after)(const void *, const char *), srv_page *page,
                     char *detail, size_t size)
{
    const char *limit = MHD_lookup_connection_value(c, MHD_GET_ARGUMENT_KIND, "limit");
    const char *after = MHD_lookup_connection_value(c, MHD_GET_ARGUMENT_KIND, "after");
    *page = (srv_page){.first = 0, .count = total, .total = total};
    if (limit) {
        char *end;
        long n = strtol(limit, &end, 10);
        if (!*limit || *end || n < 1 || n > SRV_PAGE_MAX) {
            snprintf(detail, size, "limit must be an integer from 1 to %d", SRV_PAGE_MAX);
            return ISO_E_ARGUMENT;
        }
        page->count = (size_t)n;
    }
    if (after) {
        size_t first = srv_catalog_id_valid(after) ? position_after(listing, after) : SIZE_MAX;
        if (first > total) {
            snprintf(detail, size, "after: \"%.64s\" is not a volume id", after);
            return ISO_E_ARGUMENT;
        }
        page->first = first;
    }
    if (page->count > total - page->first)
        page->count = total - page->first;
    return 0;
}

/* Sends the list of docs (a page), with Link: rel="next" when more follow. */
static enum MHD_Result send_page(srv_server *s, struct MHD_Connection *c, srv_request *req,
                                 const proto_volume_doc *docs, const srv_page *page)
{
    size_t size = 0;
    struct MHD_Response *r = text_response(proto_json_volume_list(docs, page->count),
                                           "application/json", "no-cache", &size);
    char value[32];
    snprintf(value, sizeof value, "%zu", page->total);
    if (r)
        add_header(r, "X-Iso-Total", value);
    if (r && page->count && page->first + page->count < page->total) {
        char link[SRV_ID_MAX + 80];
        snprintf(link, sizeof link, "</v1/volumes?limit=%zu&after=%s>; rel=\"next\"", page->count,
                 docs[page->count - 1].id);
        add_header(r, "Link", link);
    }
    return send_response(s, c, req, 200, r, size);
}

static size_t catalog_position_after(const void *listing, const char *id)
{
    const srv_catalog *catalog = listing;
    size_t i = srv_catalog_find(catalog, id);
    return i < catalog->count ? i + 1 : SIZE_MAX;
}

/* The loaded volumes at one moment, in catalog order: their catalog indices. */
typedef struct srv_loaded_list {
    const srv_catalog *catalog;
    size_t *at, count;
} srv_loaded_list;

/* How many loaded volumes come up to and with catalog entry id (loaded or not: a volume
 * evicted between two pages leaves the paging where it was). */
static size_t loaded_position_after(const void *listing, const char *id)
{
    const srv_loaded_list *l = listing;
    size_t i = srv_catalog_find(l->catalog, id), lo = 0, hi = l->count;
    if (i == l->catalog->count)
        return SIZE_MAX;
    while (lo < hi) {
        size_t mid = lo + (hi - lo) / 2;
        if (l->at[mid] <= i)
            lo = mid + 1;
        else
            hi = mid;
    }
    return lo;
}

/* Sharded: the catalog, the same on every replica whatever it has loaded; each entry
 * names its shard. The volume's own document (routed to that shard) has the rest. */
static enum MHD_Result route_catalog(srv_server *s, struct MHD_Connection *c, srv_request *req)
{
    const srv_catalog *catalog = s->collection->catalog;
    const srv_shard_ring *ring = s->config.shard_ring;
    srv_page page;
    char detail[160];
    if (read_page(c, catalog, catalog->count, catalog_position_after, &page, detail, sizeof detail))
        return fail(s, c, req, "/v1/volumes", 400, "%s", detail);
    proto_volume_doc *docs = calloc(page.count ? page.count : 1, sizeof *docs);
    if (!docs)
        return send_out_of_memory(s, c, req);
    for (size_t i = 0; i < page.count; i++) {
        const srv_catalog_entry *e = &catalog->entries[page.first + i];
        docs[i] = (proto_volume_doc){.id = e->id, .name = e->name, .modality = e->modality,
                                     .levels = e->levels, .level_count = e->level_count,
                                     .shard = ring->peers[srv_shard_owner(ring, e->id)]};
    }
    enum MHD_Result ok = send_page(s, c, req, docs, &page);
    free(docs);
    return ok;
}

/* The volumes loaded now, in catalog order. The collection stays locked while their
 * documents are written, so none is evicted meanwhile. */
static enum MHD_Result route_volumes(srv_server *s, struct MHD_Connection *c, srv_request *req)
{
    if (s->config.shard_ring)
        return route_catalog(s, c, req);
    srv_collection *col = s->collection;
    srv_loaded_list list = {.catalog = col->catalog, .at = malloc((col->total ? col->total : 1) * sizeof *list.at)};
    proto_volume_doc *docs = NULL;
    if (!list.at)
        return send_out_of_memory(s, c, req);
    srv_collection_lock(col);
    for (size_t i = 0; i < col->total; i++)
        if (srv_collection_loaded(col, i))
            list.at[list.count++] = i;
    srv_page page;
    char detail[160];
    enum MHD_Result ok;
    if (read_page(c, &list, list.count, loaded_position_after, &page, detail, sizeof detail)) {
        srv_collection_unlock(col);
        ok = fail(s, c, req, "/v1/volumes", 400, "%s", detail);
    } else if (!(docs = calloc(page.count ? page.count : 1, sizeof *docs))) {
        srv_collection_unlock(col);
        ok = send_out_of_memory(s, c, req);
    } else {
        for (size_t i = 0; i < page.count; i++)
            docs[i] = doc_of(s, srv_collection_loaded(col, list.at[page.first + i]));
        ok = send_page(s, c, req, docs, &page);
        srv_collection_unlock(col);
    }
    free(docs);
    free(list.at);
    return ok;
}

static enum MHD_Result route_volume(srv_server *s, struct MHD_Connection *c, srv_request *req,
                                    const srv_volume *v)
{
    proto_volume_doc doc = doc_of(s, v);
    return send_text(s, c, req, 200, proto_json_volume(&doc, 1), "application/json", "no-cache");
}

static enum MHD_Result route_health(srv_server *s, struct MHD_Connection *c, srv_request *req)
{
    int ready = atomic_load(&s->collection->ready);
    char *text = proto_json_health(ready, atomic_load(ready ? &s->collection->count
                                                            : &s->collection->attempted),
                                   s->collection->total);
    size_t size = 0;
    struct MHD_Response *r = text_response(text, "application/json", "no-store", &size);
    if (r && !ready)
        add_retry_after(s, r, 0);
    return send_response(s, c, req, ready ? 200 : 503, r, size);
}

static enum MHD_Result route_metrics(srv_server *s, struct MHD_Connection *c, srv_request *req)
{
    srv_metrics_gauges g = {0};
    g.cache_hits = atomic_load(&s->cache->hits);
    g.cache_misses = atomic_load(&s->cache->misses);
    g.cache_evictions = atomic_load(&s->cache->evictions);
    pthread_mutex_lock(&s->cache->lock);
    g.cache_bytes = s->cache->bytes;
    g.cache_items = s->cache->items;
    pthread_mutex_unlock(&s->cache->lock);
    g.cache_limit = s->cache->limit;
    srv_pool_load(s->pool, &g.queue_length, &g.extractions_running);
    g.queue_capacity = s->pool->queue_capacity;
    g.workers = s->pool->thread_count;
    g.extractions_total = atomic_load(&s->pool->completed);
    g.coalesced_total = atomic_load(&s->pool->coalesced);
    g.rejected_total = atomic_load(&s->pool->rejected);
    g.hierarchy_bytes = atomic_load(&s->collection->hierarchy_bytes);
    g.resident_bytes = atomic_load(&s->collection->resident);
    g.resident_limit = s->collection->options.max_resident_bytes;
    g.volume_evictions = atomic_load(&s->collection->evictions);
    g.hierarchies_built = atomic_load(&s->collection->trees_built);
    g.hierarchies_read = atomic_load(&s->collection->trees_read);
    g.hierarchies_unsaved = atomic_load(&s->collection->unsaved);
    g.volumes = atomic_load(&s->collection->count);
    g.volumes_on_demand = atomic_load(&s->collection->on_demand);
    g.volumes_total = s->collection->total;
    g.ready = atomic_load(&s->collection->ready);
    size_t size;
    char *text = srv_metrics_render(&s->metrics, &g, &size);
    return send_text(s, c, req, 200, text, "text/plain; version=0.0.4; charset=utf-8", "no-store");
}

/* ---------------------------------------------------------------- meshes */

typedef struct param_list {
    proto_param items[MAX_PARAMS];
    size_t count, overflow;
} param_list;

static enum MHD_Result collect_param(void *cls, enum MHD_ValueKind kind, const char *key,
                                     const char *value)
{
    (void)kind;
    param_list *list = cls;
    if (list->count < MAX_PARAMS)
        list->items[list->count++] = (proto_param){key, value};
    else
        list->overflow++;
    return MHD_YES;
}

/* The strong ETag of a mesh: the volume's version and a hash of the normalised request. */
static void mesh_etag(const srv_volume *v, const char *normalised, char *etag, size_t size)
{
    snprintf(etag, size, "\"%s-%016llx\"", v->version, (unsigned long long)srv_hash64(normalised));
}

/* If-None-Match holds etag (or "*"): RFC 9110's weak comparison, which If-None-Match uses. */
static int etag_matches(const char *header, const char *etag)
{
    if (!header)
        return 0;
    size_t n = strlen(etag);
    for (const char *p = header; *p;) {
        p += strspn(p, " \t,");
        if (*p == '*')
            return 1;
        if (!strncmp(p, "W/", 2))
            p += 2;
        if (!strncmp(p, etag, n) && (p[n] == '\0' || p[n] == ',' || p[n] == ' ' || p[n] == '\t'))
            return 1;
        p += strcspn(p, ",");
    }
    return 0;
}

/* A segmentation's segments: cacheable like its meshes (the document changes with the
 * volume's version, which covers the segment table). */
static enum MHD_Result route_segments(srv_server *s, struct MHD_Connection *c, srv_request *req,
                                      const srv_volume *v)
{
    char etag[96];
    mesh_etag(v, "segments", etag, sizeof etag);
    const char *if_none_match = MHD_lookup_connection_value(c, MHD_HEADER_KIND, MHD_HTTP_HEADER_IF_NONE_MATCH);
    if (etag_matches(if_none_match, etag)) {
        struct MHD_Response *r = MHD_create_response_from_buffer(0, NULL, MHD_RESPMEM_PERSISTENT);
        if (r)
            add_header(r, MHD_HTTP_HEADER_ETAG, etag);
        return send_response(s, c, req, 304, r, 0);
    }
    size_t size = 0;
    struct MHD_Response *r = text_response(proto_json_segments(v->entry->id, v->seg), "application/json",
                                           "no-cache", &size);
    if (r)
        add_header(r, MHD_HTTP_HEADER_ETAG, etag);
    return send_response(s, c, req, 200, r, size);
}

static void add_number(struct MHD_Response *r, const char *name, const char *fmt, double value)
{
    char text[48];
    snprintf(text, sizeof text, fmt, value);
    add_header(r, name, text);
}

static void release_body(void *cls)
{
    srv_body_release(cls);
}

static void add_cache_headers(struct MHD_Response *r, const char *etag)
{
    add_header(r, MHD_HTTP_HEADER_ETAG, etag);
    add_header(r, MHD_HTTP_HEADER_CACHE_CONTROL, "public, max-age=31536000, immutable");
}

/* The request's Accept-Encoding names gzip with a weight above 0 (RFC 9110 12.5.3). */
static int accepts_gzip(struct MHD_Connection *c)
{
    const char *h = MHD_lookup_connection_value(c, MHD_HEADER_KIND, MHD_HTTP_HEADER_ACCEPT_ENCODING);
    for (const char *p = h; p && *p;) {
        p += strspn(p, " \t,");
        size_t n = strcspn(p, ",;");
        while (n && (p[n - 1] == ' ' || p[n - 1] == '\t'))
            n--;
        int gzip = n == 4 && !strncasecmp(p, "gzip", 4);
        p += strcspn(p, ",;");
        int zero = 0;
        if (*p == ';') {
            const char *q = strstr(p, "q=");
            const char *end = p + strcspn(p, ",");
            zero = q && q < end && strtod(q + 2, NULL) == 0;
            p = end;
        }
        if (gzip)
            return !zero;
    }
    return 0;
}

/* The gzip representation's ETag: the identity one's with "-gz" before the closing quote. */
static void gzip_etag(const char *etag, char *out, size_t size)
{
    snprintf(out, size, "%.*s-gz\"", (int)strlen(etag) - 1, etag);
}

/* Sends a body (cached under key), gzipped when its format gains from gzip and the client
 * accepts it: the gzip form is made for the first such client and cached with the body.
 * Takes over the caller's reference. */
static enum MHD_Result send_body(srv_server *s, struct MHD_Connection *c, srv_request *req,
                                 srv_body *body, const char *key, const char *etag,
                                 const char *file_name, int hit)
{
    int gzip = body->gzip_wanted && accepts_gzip(c) ? srv_mesh_body_gzip(body) : 0;
    if (gzip == 2)
        srv_cache_grew(s->cache, key, body);
    char gz_etag[112];
    if (gzip) {
        gzip_etag(etag, gz_etag, sizeof gz_etag);
        etag = gz_etag;
    }
    struct MHD_Response *r = MHD_create_response_from_buffer_with_free_callback_cls(
        gzip ? body->gzip_size : body->size, gzip ? body->gzip_data : body->data, release_body, body);
    if (!r) {
        srv_body_release(body);
        return send_out_of_memory(s, c, req);
    }
    add_header(r, MHD_HTTP_HEADER_CONTENT_TYPE, body->content_type);
    add_cache_headers(r, etag);
    if (body->gzip_wanted)
        add_header(r, MHD_HTTP_HEADER_VARY, "Accept-Encoding");
    if (gzip)
        add_header(r, MHD_HTTP_HEADER_CONTENT_ENCODING, "gzip");
    char disposition[160];
    snprintf(disposition, sizeof disposition, "inline; filename=\"%s\"", file_name);
    add_header(r, "Content-Disposition", disposition);
    add_number(r, "X-Iso-Triangles", "%.0f", (double)body->triangles);
    add_number(r, "X-Iso-Vertices", "%.0f", (double)body->vertices);
    add_number(r, "X-Iso-Cells-Visited", "%.0f", (double)body->cells_visited);
    add_number(r, "X-Iso-Extract-Ms", "%.3f", body->extract_ms);
    add_number(r, "X-Iso-Normals-Ms", "%.3f", body->normals_ms);
    add_number(r, "X-Iso-Encode-Ms", "%.3f", body->encode_ms);
    if (body->draco_speed >= 0)
        add_number(r, "X-Iso-Draco-Speed", "%.0f", body->draco_speed);
    add_number(r, "X-Iso-Error-Bound", "%.9g", body->error_bound);
    add_number(r, "X-Iso-Tolerance", "%.17g", body->tolerance);
    if (body->distance_measured) {
        add_number(r, "X-Iso-Distance-Mm", "%.6g", body->distance_mm);
        add_number(r, "X-Iso-Distance-Max-Mm", "%.6g", body->distance_max_mm);
        add_number(r, "X-Iso-Distance-Voxels", "%.6g", body->distance_voxels);
    }
    if (body->chain_level >= 0) {
        add_number(r, "X-Iso-Chain-Level", "%.0f", (double)body->chain_level);
        if (body->chain_source) {
            add_header(r, "X-Iso-Chain-Source", body->chain_source);
            add_number(r, "X-Iso-Chain-Load-Ms", "%.3f", body->chain_load_ms);
            add_number(r, "X-Iso-Chain-Cut-Ms", "%.3f", body->chain_cut_ms);
            add_number(r, "X-Iso-Chain-Build-Ms", "%.3f", body->chain_build_ms);
        }
        add_number(r, "X-Iso-Exact-Triangles", "%.0f", (double)body->exact_triangles);
        add_number(r, "X-Iso-Edges", "%.0f", (double)body->edges);
        add_number(r, "X-Iso-Pinch-Edges", "%.0f", (double)body->pinch_edges);
        add_number(r, "X-Iso-Pinch-Vertices", "%.0f", (double)body->pinch_vertices);
        add_number(r, "X-Iso-Vertex-Offset-Mm", "%.6g", body->vertex_offset_mm);
    }
    if (body->min_component_asked) {
        add_number(r, "X-Iso-Components-Removed", "%.0f", (double)body->components_removed);
        add_number(r, "X-Iso-Removed-Largest-Mm", "%.6g", body->removed_largest_mm);
    }
    if (body->measured) {
        add_number(r, "X-Iso-Measure-Ms", "%.3f", body->measure_ms);
        add_number(r, "X-Iso-Area-Mm2", "%.6g", body->area_mm2);
        add_header(r, "X-Iso-Closed", body->closed ? "true" : "false");
        if (body->closed)
            add_number(r, "X-Iso-Volume-Mm3", "%.6g", body->volume_mm3);
    }
    if (body->budget_fits >= 0) {
        add_header(r, "X-Iso-Budget-Fits", body->budget_fits ? "true" : "false");
        add_header(r, "X-Iso-Simplified", body->simplified ? "true" : "false");
        if (body->budget_source)
            add_header(r, "X-Iso-Budget-Source", body->budget_source);
        if (body->budget_source && body->budget_other_mm >= 0)
            add_number(r, "X-Iso-Budget-Other-Distance-Mm", "%.6g", body->budget_other_mm);
    }
    if (body->simplified) {
        add_number(r, "X-Iso-Simplify-Error-Mm", "%.6g", body->simplify_error_mm);
        add_number(r, "X-Iso-Simplify-Error-Voxels", "%.6g", body->simplify_error_voxels);
    }
    if (gzip)
        add_number(r, "X-Iso-Gzip-Ms", "%.3f", body->gzip_ms);
    add_header(r, "X-Iso-Cache", hit ? "hit" : "miss");
    return send_response(s, c, req, 200, r, gzip ? body->gzip_size : body->size);
}

/* A mesh route: the level's mesh (segment SRV_JOB_LEVEL), a segment's (its index) or
 * every segment's (SRV_JOB_SEGMENTS): parameters, ETag and 304, cache, the job. */
static enum MHD_Result route_mesh(srv_server *s, struct MHD_Connection *c, srv_request *req,
                                  const srv_volume *v, const char *path, long segment)
{
    param_list params = {0};
    MHD_get_connection_values(c, MHD_GET_ARGUMENT_KIND, collect_param, &params);
    if (params.overflow)
        return fail(s, c, req, path, 400, "more than %d query parameters", MAX_PARAMS);
    proto_mesh_request mr;
    proto_problem problem = {0};
    if (segment == SRV_JOB_LEVEL ? proto_mesh_request_parse(params.items, params.count, &mr, &problem)
                                 : proto_segment_request_parse(params.items, params.count, segment == SRV_JOB_SEGMENTS,
                                                               &mr, &problem))
        return send_problem(s, c, req, &problem, path);

    char normalised[320], key[512], etag[96], gz_etag[112], file_name[160];
    size_t used = proto_mesh_request_key(&mr, normalised, sizeof normalised);
    if (segment != SRV_JOB_LEVEL && used < sizeof normalised)
        snprintf(normalised + used, sizeof normalised - used, segment >= 0 ? "&segment=%u" : "&segments=all",
                 segment >= 0 ? v->seg->segments[segment].number : 0);
    snprintf(key, sizeof key, "%s/%s?%s", v->entry->id, v->version, normalised);
    mesh_etag(v, normalised, etag, sizeof etag);
    if (segment == SRV_JOB_LEVEL)
        snprintf(file_name, sizeof file_name, "%s-%g.%s", v->entry->id, mr.level, proto_format_extension(mr.format));
    else if (segment >= 0)
        snprintf(file_name, sizeof file_name, "%s-segment-%u.%s", v->entry->id, v->seg->segments[segment].number,
                 proto_format_extension(mr.format));
    else
        snprintf(file_name, sizeof file_name, "%s-segments.%s", v->entry->id, proto_format_extension(mr.format));

    /* Either representation the client holds is current. */
    const char *if_none_match = MHD_lookup_connection_value(c, MHD_HEADER_KIND, MHD_HTTP_HEADER_IF_NONE_MATCH);
    gzip_etag(etag, gz_etag, sizeof gz_etag);
    if (etag_matches(if_none_match, etag) || etag_matches(if_none_match, gz_etag)) {
        struct MHD_Response *r = MHD_create_response_from_buffer(0, NULL, MHD_RESPMEM_PERSISTENT);
        if (r)
            add_cache_headers(r, etag);
        return send_response(s, c, req, 304, r, 0);
    }
    srv_body *body = srv_cache_get(s->cache, key);
    if (body)
        return send_body(s, c, req, body, key, etag, file_name, 1);

    srv_mesh_job *work = calloc(1, sizeof *work);
    if (!work || !(work->key = strdup(key))) {
        free(work);
        return fail(s, c, req, path, 503, "%s: out of memory starting the extraction", v->entry->id);
    }
    work->volume = v;
    work->collection = s->collection;
    srv_collection_retain(s->collection, v); /* the job may outlive this request */
    work->request = mr;
    work->cache = s->cache;
    work->chains = s->chains;
    work->max_triangles = s->config.max_triangles;
    work->accept_gzip = accepts_gzip(c);
    work->segment = segment;
    int coalesced;
    srv_job *job = srv_pool_submit(s->pool, key, srv_mesh_job_run, work, srv_mesh_job_free, &coalesced);
    if (!job)
        return fail(s, c, req, path, 503,
                    "the extraction queue is full (%zu waiting); retry in %u s",
                    s->pool->queue_capacity, s->config.retry_after_s);
    body = srv_pool_wait(s->pool, job, &problem);
    srv_pool_release(s->pool, job);
    if (!body)
        return send_problem(s, c, req, &problem, path);
    return send_body(s, c, req, body, key, etag, file_name, 0);
}

/* ---------------------------------------------------------------- chains */

/* GET /v1/volumes/{id}/chain?level=L&tolerance=T[&cap=true]: what the registry holds of
 * that chain, never building it: {state, exact_triangles, levels: [{triangles,
 * distance_p99_mm, distance_max_mm}], level 0 first}. The parameters are a mesh request's,
 * parsed alike, so that the chain named is the one a distance= request of them uses. */
static enum MHD_Result route_chain(srv_server *s, struct MHD_Connection *c, srv_request *req,
                                   const srv_volume *v, const char *path)
{
    param_list params = {0};
    MHD_get_connection_values(c, MHD_GET_ARGUMENT_KIND, collect_param, &params);
    if (params.overflow)
        return fail(s, c, req, path, 400, "more than %d query parameters", MAX_PARAMS);
    for (size_t i = 0; i < params.count; i++)
        if (strcmp(params.items[i].key, "level") && strcmp(params.items[i].key, "tolerance") &&
            strcmp(params.items[i].key, "cap"))
            return fail(s, c, req, path, 400, "unknown parameter \"%s\"; the chain takes level, tolerance and cap",
                        params.items[i].key);
    proto_mesh_request mr;
    proto_problem problem = {0};
    if (proto_mesh_request_parse(params.items, params.count, &mr, &problem))
        return send_problem(s, c, req, &problem, path);
    char chain_params[160];
    srv_chain_spec spec;
    srv_chain_level_params(chain_params, sizeof chain_params, mr.level, mr.tolerance, mr.cap);
    if (!s->chains || srv_chain_spec_init(&spec, s->collection->options.cache_dir, v->entry->id, v->version,
                                          chain_params))
        return fail(s, c, req, path, 503, "%s: this server keeps no chains", v->entry->id);
    srv_chain *entry;
    int state = srv_chains_peek(s->chains, &spec, &entry);
    json_t *levels = json_array(), *doc = json_pack("{s:s, s:f, s:f, s:b}", "state",
                                                    state == 2 ? "ready" : state == 1 ? "building" : "none",
                                                    "level", mr.level, "tolerance", mr.tolerance, "cap", mr.cap);
    const iso_mesh_chain *chain = entry ? srv_chain_get(entry) : NULL;
    for (int k = 0; chain && levels && k < chain->levels; k++) {
        const iso_mesh_chain_level *lv = &chain->level[k];
        double p99 = k ? lv->distance.p99 : 0, max = k ? lv->distance.max : 0;
        json_array_append_new(levels, json_pack("{s:I, s:o, s:o}", "triangles", (json_int_t)lv->triangle_count,
                                                "distance_p99_mm", isfinite(p99) ? json_real(p99) : json_null(),
                                                "distance_max_mm", isfinite(max) ? json_real(max) : json_null()));
    }
    if (doc && levels) {
        json_object_set_new(doc, "exact_triangles",
                            chain ? json_integer((json_int_t)chain->level[0].triangle_count) : json_null());
        json_object_set(doc, "levels", levels);
    }
    json_decref(levels);
    srv_chains_release(s->chains, entry);
    char *text = doc ? json_dumps(doc, JSON_COMPACT) : NULL;
    json_decref(doc);
    return send_text(s, c, req, 200, text, "application/json", "no-store");
}

/* GET /v1/status: the background work, the chains' registry and the mesh cache. */
static enum MHD_Result route_status(srv_server *s, struct MHD_Connection *c, srv_request *req)
{
    json_t *doc = NULL;
    if (s->chains) {
        srv_chains *r = s->chains;
        pthread_mutex_lock(&r->lock);
        srv_chain_progress p = r->progress;
        size_t bytes = r->bytes, ready = r->ready, limit = r->limit;
        pthread_mutex_unlock(&r->lock);
        size_t partial = srv_chains_partial_count(r);
        json_t *current = p.current[0] ? json_pack("{s:s, s:f}", "chain", p.current, "seconds",
                                                   (iso_clock_ms() - p.current_since_ms) / 1000)
                                       : json_null();
        doc = json_pack("{s:{s:s, s:I, s:I, s:I, s:I, s:o}, s:{s:I, s:I, s:I, s:I, s:I, s:I, s:I, s:I, s:I, s:I}}",
                        "background", "state", !p.enabled ? "off" : p.finished ? "done" : p.running ? "building"
                                                                                          : "waiting",
                        "planned", (json_int_t)p.planned, "built", (json_int_t)p.built, "there_already",
                        (json_int_t)p.loaded, "failed", (json_int_t)p.failed, "current", current,
                        "chains", "ready", (json_int_t)ready, "partial", (json_int_t)partial, "bytes", (json_int_t)bytes, "limit_bytes",
                        (json_int_t)limit, "mapped", (json_int_t)atomic_load(&r->mapped), "built",
                        (json_int_t)atomic_load(&r->built), "evictions", (json_int_t)atomic_load(&r->evictions),
                        "corrupt", (json_int_t)atomic_load(&r->corrupt), "extended",
                        (json_int_t)atomic_load(&r->extended), "completed", (json_int_t)atomic_load(&r->completed));
    } else {
        doc = json_pack("{s:{s:s}}", "background", "state", "off");
    }
    char *text = doc ? json_dumps(doc, JSON_COMPACT) : NULL;
    json_decref(doc);
    return send_text(s, c, req, 200, text, "application/json", "no-store");
}

/* ---------------------------------------------------------------- routing */

static enum MHD_Result route_static(srv_server *s, struct MHD_Connection *c, srv_request *req,
                                    const char *path)
{
    int fd;
    size_t size;
    const char *type;
    if (!s->config.web_root || srv_static_open(s->config.web_root, path, &fd, &size, &type))
        return fail(s, c, req, path, 404, "nothing at %s", path);
    struct MHD_Response *r = MHD_create_response_from_fd(size, fd);
    if (!r) {
        close(fd);
        return send_out_of_memory(s, c, req);
    }
    add_header(r, MHD_HTTP_HEADER_CONTENT_TYPE, type);
    add_header(r, MHD_HTTP_HEADER_CACHE_CONTROL, "no-cache");
    return send_response(s, c, req, 200, r, size);
}

static enum MHD_Result preflight(srv_server *s, struct MHD_Connection *c, srv_request *req)
{
    struct MHD_Response *r = MHD_create_response_from_buffer(0, NULL, MHD_RESPMEM_PERSISTENT);
    if (!r)
        return send_out_of_memory(s, c, req);
    add_header(r, "Access-Control-Allow-Methods", "GET, HEAD, OPTIONS");
    add_header(r, "Access-Control-Allow-Headers", "If-None-Match, Authorization");
    add_header(r, "Access-Control-Max-Age", "86400");
    add_header(r, MHD_HTTP_HEADER_ALLOW, "GET, HEAD, OPTIONS");
    return send_response(s, c, req, 204, r, 0);
}

static enum MHD_Result add_length(void *cls, enum MHD_ValueKind kind, const char *key, const char *value)
{
    (void)kind;
    *(size_t *)cls += strlen(key) + (value ? strlen(value) + 1 : 0) + 1;
    return MHD_YES;
}

/* The resources under a volume. */
enum { PATH_NONE, PATH_VOLUME, PATH_MESH, PATH_SEGMENTS, PATH_SEGMENTS_MESH, PATH_SEGMENT_MESH, PATH_CHAIN };

/* "/segments/{n}/mesh": n a segment number (digits, no sign or leading zero past one
 * digit), into *number; 0 when the path is not that. */
static int segment_mesh_path(const char *rest, unsigned long *number)
{
    static const char prefix[] = "/segments/";
    if (strncmp(rest, prefix, sizeof prefix - 1))
        return 0;
    const char *digits = rest + sizeof prefix - 1;
    size_t n = strspn(digits, "0123456789");
    if (n == 0 || n > 10 || (n > 1 && digits[0] == '0') || strcmp(digits + n, "/mesh"))
        return 0;
    *number = strtoul(digits, NULL, 10);
    return *number <= UINT32_MAX;
}

/* Splits "/v1/volumes/{id}[/mesh | /chain | /segments | /segments/mesh | /segments/{n}/mesh]" into
 * the id and the resource (PATH_*; *number for a segment's mesh). */
static int volume_path(const char *path, char *id, size_t size, unsigned long *number)
{
    static const char prefix[] = "/v1/volumes/";
    if (strncmp(path, prefix, sizeof prefix - 1))
        return 0;
    const char *start = path + sizeof prefix - 1;
    const char *slash = strchr(start, '/');
    size_t len = slash ? (size_t)(slash - start) : strlen(start);
    if (len == 0 || len >= size)
        return 0;
    memcpy(id, start, len);
    id[len] = '\0';
    if (!slash)
        return PATH_VOLUME;
    if (!strcmp(slash, "/mesh"))
        return PATH_MESH;
    if (!strcmp(slash, "/chain"))
        return PATH_CHAIN;
    if (!strcmp(slash, "/segments"))
        return PATH_SEGMENTS;
    if (!strcmp(slash, "/segments/mesh"))
        return PATH_SEGMENTS_MESH;
    return segment_mesh_path(slash, number) ? PATH_SEGMENT_MESH : PATH_NONE;
}

/* 1 when a and b (b_len bytes) are equal, in a time that depends on b_len only: the
 * configured token's length, not where a guess first differs. */
static int token_equal(const char *a, size_t a_len, const char *b, size_t b_len)
{
    unsigned diff = a_len != b_len;
    for (size_t i = 0; i < b_len; i++)
        diff |= (unsigned char)b[i] ^ (unsigned char)(i < a_len ? a[i] : 0);
    return diff == 0;
}

/* With --token-file, "Authorization: Bearer TOKEN" (scheme case-insensitive, RFC 6750).
 * The header's value is never logged or echoed. */
static int authorized(const srv_server *s, struct MHD_Connection *c)
{
    const char *token = s->config.token;
    if (!token)
        return 1;
    const char *h = MHD_lookup_connection_value(c, MHD_HEADER_KIND, MHD_HTTP_HEADER_AUTHORIZATION);
    if (!h || strncasecmp(h, "Bearer ", 7))
        return 0;
    h += 7;
    h += strspn(h, " ");
    return token_equal(h, strlen(h), token, strlen(token));
}

/* /healthz stays open for load balancers' probes (it tells readiness and counts, no
 * volume); the web client's files are public code. The API and /metrics need the token. */
static int needs_token(const char *path)
{
    return !strcmp(path, "/metrics") || !strncmp(path, "/v1/", 4) || !strcmp(path, "/v1");
}

static enum MHD_Result route(srv_server *s, struct MHD_Connection *c, srv_request *req,
                             const char *path, const char *method)
{
    if (!strcmp(method, "OPTIONS"))
        return preflight(s, c, req);
    if (strcmp(method, "GET") && strcmp(method, "HEAD"))
        return fail(s, c, req, path, 405, "%s is not allowed here; use GET", method);
    size_t length = strlen(path);
    MHD_get_connection_values(c, MHD_GET_ARGUMENT_KIND, add_length, &length);
    if (length > SRV_URI_MAX)
        return fail(s, c, req, NULL, 414, "the request target is %zu bytes; at most %d are accepted",
                    length, SRV_URI_MAX);
    if (!strcmp(path, "/healthz")) {
        req->route = SRV_ROUTE_HEALTH;
        return route_health(s, c, req);
    }
    if (needs_token(path) && !authorized(s, c)) {
        const char *given = MHD_lookup_connection_value(c, MHD_HEADER_KIND, MHD_HTTP_HEADER_AUTHORIZATION);
        return fail(s, c, req, path, 401, given ? "the bearer token is not this server's"
                                                : "this server needs \"Authorization: Bearer TOKEN\"");
    }
    if (!strcmp(path, "/metrics")) {
        req->route = SRV_ROUTE_METRICS;
        return route_metrics(s, c, req);
    }
    if (strncmp(path, "/v1/", 4) && strcmp(path, "/v1")) {
        req->route = SRV_ROUTE_STATIC;
        return route_static(s, c, req, path);
    }
    if (!atomic_load(&s->collection->ready))
        return fail(s, c, req, path, 503, "preloading: %zu of %zu volumes done",
                    atomic_load(&s->collection->attempted), s->collection->total);
    if (!strcmp(path, "/v1/volumes")) {
        req->route = SRV_ROUTE_VOLUMES;
        return route_volumes(s, c, req);
    }
    if (!strcmp(path, "/v1/status")) {
        req->route = SRV_ROUTE_STATUS;
        return route_status(s, c, req);
    }
    char id[SRV_ID_MAX + 2];
    unsigned long number = 0;
    int kind = volume_path(path, id, sizeof id, &number);
    if (!kind)
        return fail(s, c, req, path, 404, "no such resource; the API is /v1/volumes, "
                    "/v1/volumes/{id}, /v1/volumes/{id}/mesh, /v1/volumes/{id}/chain, /v1/volumes/{id}/segments, "
                    "/v1/volumes/{id}/segments/mesh, /v1/volumes/{id}/segments/{n}/mesh and /v1/status");
    req->route = kind == PATH_VOLUME ? SRV_ROUTE_VOLUME : kind == PATH_MESH ? SRV_ROUTE_MESH
               : kind == PATH_CHAIN ? SRV_ROUTE_CHAIN : kind == PATH_SEGMENTS ? SRV_ROUTE_SEGMENTS : SRV_ROUTE_SEGMENT_MESH;
    if (!srv_catalog_id_valid(id))
        return fail(s, c, req, path, 404, "no volume \"(not a valid id)\"; /v1/volumes lists them");
    const srv_volume *v;
    srv_volume_state state = srv_collection_acquire(s->collection, id, &v); /* loads another shard's volume */
    if (state == SRV_VOLUME_UNKNOWN)
        return fail(s, c, req, path, 404, "no volume \"%s\"; /v1/volumes lists them", id);
    if (state != SRV_VOLUME_READY) {
        char why[sizeof ((iso_error *)0)->message];
        req->retry_after_s = srv_collection_failure(s->collection, id, why, sizeof why);
        return fail(s, c, req, path, srv_status_volume_http(state), "volume \"%s\" could not be loaded: %s%s",
                    id, why, req->retry_after_s ? "; its source is asked again after Retry-After" : "");
    }
    req->volume = v;
    if (kind == PATH_VOLUME)
        return route_volume(s, c, req, v);
    if (kind == PATH_MESH)
        return route_mesh(s, c, req, v, path, SRV_JOB_LEVEL);
    if (kind == PATH_CHAIN)
        return route_chain(s, c, req, v, path);
    if (!v->seg)
        return fail(s, c, req, path, 404, "volume \"%s\" is not a segmentation (the catalog's \"labels\": true "
                    "declares a label map one)", id);
    if (kind == PATH_SEGMENTS)
        return route_segments(s, c, req, v);
    if (kind == PATH_SEGMENTS_MESH)
        return route_mesh(s, c, req, v, path, SRV_JOB_SEGMENTS);
    long segment = iso_seg_find(v->seg, (uint32_t)number);
    if (segment < 0)
        return fail(s, c, req, path, 404, "volume \"%s\" has no segment %lu; /v1/volumes/%s/segments lists them",
                    id, number, id);
    return route_mesh(s, c, req, v, path, segment);
}

/* ---------------------------------------------------------------- life cycle */

static int hex_digit(char ch)
{
    return ch >= '0' && ch <= '9' ? ch - '0' : ch >= 'a' && ch <= 'f' ? ch - 'a' + 10
         : ch >= 'A' && ch <= 'F' ? ch - 'A' + 10 : -1;
}

/* libmicrohttpd's unescaping of the path and the query, less "%00" and "%2F": a decoded
 * NUL would end the C string early ("/v1/volumes/x%00/anything" read as "/v1/volumes/x"),
 * and a decoded slash would let one path segment pose as two ("/v1/volumes/x%2Fmesh" as
 * the mesh of x). Kept as the three characters, they make an id invalid, as they should;
 * no query value needs either. */
static size_t unescape(void *cls, struct MHD_Connection *c, char *s)
{
    (void)cls;
    (void)c;
    char *out = s;
    for (const char *in = s; *in;) {
        int hi = in[0] == '%' ? hex_digit(in[1]) : -1, lo = hi >= 0 ? hex_digit(in[2]) : -1;
        int byte = hi * 16 + lo;
        if (lo >= 0 && byte != 0 && byte != '/') {
            *out++ = (char)byte;
            in += 3;
        } else {
            *out++ = *in++;
        }
    }
    *out = '\0';
    return (size_t)(out - s);
}

static enum MHD_Result on_request(void *cls, struct MHD_Connection *c, const char *url,
                                  const char *method, const char *version,
                                  const char *upload_data, size_t *upload_size, void **req_cls)
{
    (void)version;
    (void)upload_data;
    srv_server *s = cls;
    srv_request *req = *req_cls;
    if (!req) {
        req = calloc(1, sizeof *req);
        if (!req)
            return send_out_of_memory(s, c, NULL);
        req->start = iso_clock_ms();
        req->route = SRV_ROUTE_OTHER;
        snprintf(req->method, sizeof req->method, "%s", method);
        snprintf(req->path, sizeof req->path, "%s", url);
        atomic_fetch_add(&s->in_flight, 1);
        *req_cls = req;
        return MHD_YES;
    }
    if (*upload_size) { /* GET takes no body: read and drop it */
        *upload_size = 0;
        return MHD_YES;
    }
    header_failed = 0;
    return route(s, c, req, url, method);
}

/* The access log: one line per request on stderr. Control bytes in the path are masked.
 * The line is formatted here and written with one write(2): fprintf on the unbuffered
 * stderr holds the stream's lock across its write system call, and with a thread per
 * connection that lock was where cached requests queued (2.5 futex calls per request). A
 * write of under PIPE_BUF bytes to a pipe is atomic, so lines never interleave. */
static void log_request(const srv_request *req, double ms)
{
    char when[32], path[256], line[512];
    time_t now = time(NULL);
    struct tm tm;
    strftime(when, sizeof when, "%Y-%m-%dT%H:%M:%SZ", gmtime_r(&now, &tm));
    size_t n = 0;
    for (const char *p = req->path; *p && n + 1 < sizeof path; p++)
        path[n++] = (*p > 0x20 && *p < 0x7f) ? *p : '?';
    path[n] = '\0';
    int len = snprintf(line, sizeof line, "%s %s %s %d %zu %.1fms\n", when, req->method, path,
                       req->status, req->bytes, ms);
    if (len < 0)
        return;
    if ((size_t)len >= sizeof line) { /* cut, but still one line */
        len = (int)sizeof line - 1;
        line[len - 1] = '\n';
    }
    for (ssize_t off = 0, w; off < len; off += w) /* the log is best effort: stop on error */
        if ((w = write(STDERR_FILENO, line + off, (size_t)(len - off))) <= 0)
            break;
}

static void on_completed(void *cls, struct MHD_Connection *c, void **req_cls,
                         enum MHD_RequestTerminationCode code)
{
    (void)c;
    srv_server *s = cls;
    srv_request *req = *req_cls;
    if (!req)
        return;
    double ms = iso_clock_ms() - req->start;
    if (code != MHD_REQUEST_TERMINATED_COMPLETED_OK && req->status == 0)
        req->status = 499; /* the client left, or the connection failed, before an answer */
    log_request(req, ms);
    srv_metrics_request(&s->metrics, req->route, req->status, ms, req->bytes);
    srv_collection_release(s->collection, req->volume);
    free(req);
    *req_cls = NULL;
    atomic_fetch_sub(&s->in_flight, 1);
}

int srv_http_start(srv_server *s, iso_error *err)
{
    srv_metrics_init(&s->metrics);
    s->listen_socket = -1;
    char port[16];
    snprintf(port, sizeof port, "%u", s->config.port);
    struct addrinfo hints = {.ai_family = AF_UNSPEC, .ai_socktype = SOCK_STREAM,
                             .ai_flags = AI_PASSIVE}, *addr;
    int gai = getaddrinfo(s->config.host, port, &hints, &addr);
    if (gai)
        return iso_error_set(err, ISO_E_ARGUMENT, "--listen %s: %s", s->config.host, gai_strerror(gai));
    unsigned flags = MHD_USE_THREAD_PER_CONNECTION | MHD_USE_INTERNAL_POLLING_THREAD |
                     MHD_USE_POLL | MHD_USE_ITC | MHD_USE_ERROR_LOG;
    if (addr->ai_family == AF_INET6)
        flags |= MHD_USE_IPv6;
    s->out_of_memory = MHD_create_response_from_buffer(sizeof out_of_memory_body - 1,
                                                       out_of_memory_body,
                                                       MHD_RESPMEM_PERSISTENT);
    if (!s->out_of_memory) {
        freeaddrinfo(addr);
        return iso_error_set(err, ISO_E_NOMEM, "out of memory starting the HTTP server");
    }
    header_failed = 0;
    add_header(s->out_of_memory, MHD_HTTP_HEADER_CONTENT_TYPE, "application/problem+json");
    add_header(s->out_of_memory, MHD_HTTP_HEADER_CACHE_CONTROL, "no-store");
    add_retry_after(s, s->out_of_memory, 0);
    if (header_failed) {
        header_failed = 0;
        MHD_destroy_response(s->out_of_memory);
        s->out_of_memory = NULL;
        freeaddrinfo(addr);
        return iso_error_set(err, ISO_E_NOMEM, "out of memory starting the HTTP server");
    }
    s->daemon = MHD_start_daemon(
        flags, (uint16_t)s->config.port, NULL, NULL, on_request, s,
        MHD_OPTION_SOCK_ADDR, addr->ai_addr,
        MHD_OPTION_NOTIFY_COMPLETED, on_completed, s,
        MHD_OPTION_CONNECTION_LIMIT, s->config.max_connections,
        MHD_OPTION_CONNECTION_TIMEOUT, s->config.connection_timeout_s,
        MHD_OPTION_CONNECTION_MEMORY_LIMIT, (size_t)64 * 1024,
        MHD_OPTION_UNESCAPE_CALLBACK, unescape, NULL,
        MHD_OPTION_END);
    freeaddrinfo(addr);
    if (!s->daemon) {
        MHD_destroy_response(s->out_of_memory);
        s->out_of_memory = NULL;
    }
    if (!s->daemon)
        return iso_error_set(err, ISO_E_IO, "cannot listen on %s:%u (in use, or not an address of "
                             "this machine)", s->config.host, s->config.port);
    const union MHD_DaemonInfo *info = MHD_get_daemon_info(s->daemon, MHD_DAEMON_INFO_BIND_PORT);
    s->port = info ? info->port : s->config.port;
    return 0;
}

void srv_http_quiesce(srv_server *s)
{
    if (s->daemon && s->listen_socket < 0)
        s->listen_socket = MHD_quiesce_daemon(s->daemon);
}

int srv_http_drain(srv_server *s, double timeout_ms)
{
    double until = iso_clock_ms() + timeout_ms;
    while (atomic_load(&s->in_flight) > 0 && iso_clock_ms() < until)
        usleep(10000);
    return atomic_load(&s->in_flight);
}

void srv_http_stop(srv_server *s)
{
    if (s->daemon)
        MHD_stop_daemon(s->daemon);
    if (s->out_of_memory)
        MHD_destroy_response(s->out_of_memory);
    s->out_of_memory = NULL;
    if (s->listen_socket >= 0)
        close(s->listen_socket);
    s->daemon = NULL;
    s->listen_socket = -1;
}
