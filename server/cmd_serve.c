/* cmd_serve.c: `isoserve serve`: options, start-up, preloading, and graceful shutdown.
 *
 * Order of events: parse options, read the catalog, start the pool and the HTTP server
 * (healthz answers 503 while loading), preload in a thread, then wait for SIGINT or
 * SIGTERM. On a signal: stop accepting, let requests in flight finish (bounded by
 * --drain-seconds), stop, free, exit 0. */
#include <errno.h>
#include <limits.h>
#include <pthread.h>
#include <signal.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

#include "catalog.h"
#include "cli.h"
#include "collection.h"
#include "http.h"
#include "pool.h"

#define MAX_ORIGINS 16

typedef struct serve_options {
    const char *catalog, *volumes, *cache_dir, *web_root;
    char host[256];
    unsigned port;
    long threads, queue, cache_mb, drain_seconds, max_connections, max_volume_mb;
    const char *origins[MAX_ORIGINS];
    size_t origin_count;
} serve_options;

static int parse_count(const char *option, const char *text, long min, long max, long *out)
{
    char *end;
    errno = 0;
    long v = strtol(text, &end, 10);
    if (!*text || *end || errno || v < min || v > max)
        return srv_fail("%s %s: expected a whole number from %ld to %ld", option, text, min, max);
    *out = v;
    return 0;
}

/* "HOST:PORT" or "[IPv6]:PORT". */
static int parse_listen(const char *text, serve_options *o)
{
    const char *colon = text[0] == '[' ? strstr(text, "]:") : strrchr(text, ':');
    long port;
    if (!colon)
        return srv_fail("--listen %s: expected HOST:PORT, e.g. 127.0.0.1:8080", text);
    size_t host_len = text[0] == '[' ? (size_t)(colon - text - 1) : (size_t)(colon - text);
    const char *host = text[0] == '[' ? text + 1 : text;
    const char *port_text = colon + (text[0] == '[' ? 2 : 1);
    if (host_len == 0 || host_len >= sizeof o->host)
        return srv_fail("--listen %s: expected HOST:PORT, e.g. 127.0.0.1:8080", text);
    if (parse_count("--listen port", port_text, 0, 65535, &port))
        return 1;
    memcpy(o->host, host, host_len);
    o->host[host_len] = '\0';
    o->port = (unsigned)port;
    return 0;
}

static int parse_options(int argc, char **argv, serve_options *o)
{
    long cores = sysconf(_SC_NPROCESSORS_ONLN);
    *o = (serve_options){.host = "127.0.0.1", .port = 8080, .threads = cores > 0 ? cores : 1,
                         .queue = 64, .cache_mb = 256, .drain_seconds = 10,
                         .max_connections = 256, .max_volume_mb = 8192};
    for (int i = 0; i < argc; i++) {
        const char *a = argv[i], *v = i + 1 < argc ? argv[i + 1] : NULL;
        int rc = 0;
        if (!v)
            return srv_fail("serve: %s needs a value (or is not an option)", a);
        if (!strcmp(a, "--catalog")) o->catalog = v;
        else if (!strcmp(a, "--volumes")) o->volumes = v;
        else if (!strcmp(a, "--cache-dir")) o->cache_dir = v;
        else if (!strcmp(a, "--web-root")) o->web_root = v;
        else if (!strcmp(a, "--listen")) rc = parse_listen(v, o);
        else if (!strcmp(a, "--threads")) rc = parse_count(a, v, 1, 256, &o->threads);
        else if (!strcmp(a, "--queue")) rc = parse_count(a, v, 0, 100000, &o->queue);
        else if (!strcmp(a, "--cache-mb")) rc = parse_count(a, v, 0, 1 << 20, &o->cache_mb);
        else if (!strcmp(a, "--drain-seconds")) rc = parse_count(a, v, 0, 3600, &o->drain_seconds);
        else if (!strcmp(a, "--max-connections")) rc = parse_count(a, v, 1, 65536, &o->max_connections);
        else if (!strcmp(a, "--max-volume-mb")) rc = parse_count(a, v, 1, 1 << 24, &o->max_volume_mb);
        else if (!strcmp(a, "--cors-origin")) {
            if (o->origin_count == MAX_ORIGINS)
                return srv_fail("--cors-origin: at most %d origins", MAX_ORIGINS);
            o->origins[o->origin_count++] = v;
        } else
            return srv_fail("serve: unknown option '%s'", a);
        if (rc)
            return rc;
        i++;
    }
    if (o->catalog && o->volumes)
        return srv_fail("serve: give --catalog or --volumes, not both");
    return 0;
}

static int read_catalog(const serve_options *o, srv_catalog *catalog)
{
    iso_error err;
    int rc = o->catalog ? srv_catalog_read(o->catalog, catalog, &err)
             : o->volumes ? srv_catalog_scan(o->volumes, catalog, &err)
                          : srv_catalog_default(catalog, &err);
    if (rc)
        return srv_fail("%s", err.message);
    if (catalog->count == 0)
        fprintf(stderr, "isoserve: the catalog names no volume; serving an empty collection\n");
    return 0;
}

/* The web client's directory: --web-root, else `web` beside the executable if there. */
static char *web_root(const char *given)
{
    char exe[PATH_MAX], guess[PATH_MAX + 8];
    if (given) {
        char *resolved = realpath(given, NULL);
        if (!resolved)
            srv_fail("--web-root %s: %s; the web client is not served", given, strerror(errno));
        return resolved;
    }
    ssize_t n = readlink("/proc/self/exe", exe, sizeof exe - 1);
    if (n <= 0)
        return NULL;
    exe[n] = '\0';
    char *slash = strrchr(exe, '/');
    if (slash)
        *slash = '\0';
    snprintf(guess, sizeof guess, "%s/web", exe);
    return realpath(guess, NULL);
}

typedef struct preload_task {
    srv_collection *collection;
    const srv_catalog *catalog;
    srv_preload_options options;
} preload_task;

static void *preload_main(void *arg)
{
    preload_task *t = arg;
    srv_collection_preload(t->collection, t->catalog, &t->options);
    if (!atomic_load(&t->collection->stop))
        fprintf(stderr, "isoserve: ready: %zu of %zu volumes\n",
                atomic_load(&t->collection->count), t->collection->total);
    return NULL;
}

static int is_loopback(const char *host)
{
    return !strcmp(host, "localhost") || !strncmp(host, "127.", 4) || !strcmp(host, "::1");
}

/* Runs until SIGINT or SIGTERM; the signals are blocked in every thread and taken here. */
static int serve(const serve_options *o, srv_catalog *catalog)
{
    srv_collection collection;
    srv_cache cache;
    srv_pool pool;
    srv_server server = {0};
    iso_error err;
    char *root = web_root(o->web_root);
    if (srv_collection_init(&collection, catalog) || srv_cache_init(&cache, (size_t)o->cache_mb << 20) ||
        srv_pool_init(&pool, (size_t)o->threads, (size_t)o->queue))
        return srv_fail("serve: out of memory or threads at start-up");
    server.config = (srv_http_config){
        .host = o->host, .port = o->port, .web_root = root, .cors_origins = o->origins,
        .cors_origin_count = o->origin_count, .max_connections = (unsigned)o->max_connections,
        .connection_timeout_s = 30, .retry_after_s = 1};
    server.collection = &collection;
    server.cache = &cache;
    server.pool = &pool;
    int status = 0;
    if (srv_http_start(&server, &err)) {
        status = srv_fail("%s", err.message);
        goto done;
    }
    fprintf(stderr, "isoserve: listening on http://%s%s%s:%u/%s\n", strchr(o->host, ':') ? "[" : "",
            o->host, strchr(o->host, ':') ? "]" : "", server.port,
            is_loopback(o->host) ? "" : " (not loopback: reachable from other machines)");
    if (!root)
        fprintf(stderr, "isoserve: no web client found (build it with make, or give --web-root)\n");

    preload_task task = {&collection, catalog,
                         {.cache_dir = o->cache_dir,
                          .max_volume_bytes = (uint64_t)o->max_volume_mb << 20}};
    pthread_t preloader;
    if (pthread_create(&preloader, NULL, preload_main, &task)) {
        srv_http_stop(&server);
        status = srv_fail("serve: cannot start the preloading thread");
        goto done;
    }
    sigset_t stop_signals;
    sigemptyset(&stop_signals);
    sigaddset(&stop_signals, SIGINT);
    sigaddset(&stop_signals, SIGTERM);
    int signal_number = 0;
    sigwait(&stop_signals, &signal_number);
    fprintf(stderr, "isoserve: %s: no new connections; finishing %d requests in flight\n",
            strsignal(signal_number), atomic_load(&server.in_flight));
    atomic_store(&collection.stop, 1);
    srv_http_quiesce(&server);
    int left = srv_http_drain(&server, (double)o->drain_seconds * 1000);
    if (left)
        fprintf(stderr, "isoserve: %d requests still running after %ld s are cut off\n", left,
                o->drain_seconds);
    srv_http_stop(&server);
    pthread_join(preloader, NULL);
    fprintf(stderr, "isoserve: stopped\n");
done:
    srv_pool_destroy(&pool);
    srv_cache_destroy(&cache);
    srv_collection_free(&collection);
    free(root);
    return status;
}

int srv_cmd_serve(int argc, char **argv)
{
    serve_options o;
    if (parse_options(argc, argv, &o))
        return 1;
    /* Block the stop signals before any thread starts, so that every thread inherits the
     * mask and only serve()'s sigwait takes them; a peer closing early must not kill us. */
    sigset_t stop_signals;
    sigemptyset(&stop_signals);
    sigaddset(&stop_signals, SIGINT);
    sigaddset(&stop_signals, SIGTERM);
    pthread_sigmask(SIG_BLOCK, &stop_signals, NULL);
    signal(SIGPIPE, SIG_IGN);
    srv_catalog catalog;
    if (read_catalog(&o, &catalog))
        return 1;
    int status = serve(&o, &catalog);
    srv_catalog_free(&catalog);
    return status;
}
