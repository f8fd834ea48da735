/* cmd_serve.c: `isoserve serve`: options, start-up, preloading, and graceful shutdown.
 *
 * Order of events: parse options (each may also come from the environment, ISOSERVE_ and
 * the option's name in capitals, `--cache-dir` from ISOSERVE_CACHE_DIR; a flag wins), read
 * the catalog, with --shard work out which entries are this replica's, start the pool and
 * the HTTP server (healthz answers 503 while loading), preload in a thread, then wait for
 * SIGINT or SIGTERM. On a signal: stop accepting, let requests in flight finish (bounded
 * by --drain-seconds), stop, free, exit 0. */
#include <errno.h>
#include <limits.h>
#include <pthread.h>
#include <signal.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

#include "catalog.h"
#include "chain_background.h"
#include "chains.h"
#include "cli.h"
#include "collection.h"
#include "http.h"
#include "pool.h"
#include "shard.h"

#define MAX_ORIGINS 16

typedef struct serve_options {
    const char *catalog, *volumes, *cache_dir, *web_root;
    char host[256];
    unsigned port;
    long threads, queue, cache_mb, chain_mb, drain_seconds, max_connections, max_volume_mb;
    int chain_background;             /* --chain-background on|off */
    long max_resident_mb;             /* 0: no limit */
    long connection_timeout, max_triangles;
    const char *token_file;
    const char *origins[MAX_ORIGINS];
    size_t origin_count;
    long shard_self, shard_count;     /* --shard K/N; shard_count 0: not sharded */
    const char *shard_peers, *replica_name;
    int collection_from_env;          /* catalog or volumes came from the environment */
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

/* "K/N" with 0 <= K < N. */
static int parse_shard(const char *text, serve_options *o)
{
    char *end;
    errno = 0;
    long k = strtol(text, &end, 10), n = -1;
    if (!errno && end != text && *end == '/' && end[1]) {
        const char *rest = end + 1;
        n = strtol(rest, &end, 10);
        if (errno || *end || end == rest)
            n = -1;
    }
    if (n < 1 || n > SRV_SHARD_PEERS_MAX || k < 0 || k >= n)
        return srv_fail("--shard %s: expected K/N with 0 <= K < N <= %d, e.g. 0/3", text,
                        SRV_SHARD_PEERS_MAX);
    o->shard_self = k;
    o->shard_count = n;
    return 0;
}

/* One option and its value; 0, or 1 reported. from_env: it came from the environment. */
static int set_option(serve_options *o, const char *a, const char *v, int from_env)
{
    if (!strcmp(a, "--catalog") || !strcmp(a, "--volumes")) {
        if (!from_env && o->collection_from_env) /* a flag replaces the environment's choice */
            o->catalog = o->volumes = NULL;
        o->collection_from_env = from_env;
        if (!strcmp(a, "--catalog"))
            o->catalog = v;
        else
            o->volumes = v;
        return 0;
    }
    if (!strcmp(a, "--cache-dir")) o->cache_dir = v;
    else if (!strcmp(a, "--web-root")) o->web_root = v;
    else if (!strcmp(a, "--shard-peers")) o->shard_peers = v;
    else if (!strcmp(a, "--replica-name")) o->replica_name = v;
    else if (!strcmp(a, "--token-file")) o->token_file = v;
    else if (!strcmp(a, "--connection-timeout")) return parse_count(a, v, 1, 3600, &o->connection_timeout);
    else if (!strcmp(a, "--max-triangles")) return parse_count(a, v, 1, 1L << 40, &o->max_triangles);
    else if (!strcmp(a, "--shard")) return parse_shard(v, o);
    else if (!strcmp(a, "--listen")) return parse_listen(v, o);
    else if (!strcmp(a, "--threads")) return parse_count(a, v, 1, 256, &o->threads);
    else if (!strcmp(a, "--queue")) return parse_count(a, v, 0, 100000, &o->queue);
    else if (!strcmp(a, "--cache-mb")) return parse_count(a, v, 0, 1 << 20, &o->cache_mb);
    else if (!strcmp(a, "--chain-mb")) return parse_count(a, v, 0, 1 << 24, &o->chain_mb);
    else if (!strcmp(a, "--chain-background")) {
        if (strcmp(v, "on") && strcmp(v, "off"))
            return srv_fail("--chain-background %s: expected on or off", v);
        o->chain_background = !strcmp(v, "on");
    }
    else if (!strcmp(a, "--drain-seconds")) return parse_count(a, v, 0, 3600, &o->drain_seconds);
    else if (!strcmp(a, "--max-connections")) return parse_count(a, v, 1, 65536, &o->max_connections);
    else if (!strcmp(a, "--max-volume-mb")) return parse_count(a, v, 1, 1 << 24, &o->max_volume_mb);
    else if (!strcmp(a, "--max-resident-mb")) return parse_count(a, v, 0, 1L << 30, &o->max_resident_mb);
    else if (!strcmp(a, "--cors-origin")) {
        if (o->origin_count == MAX_ORIGINS)
            return srv_fail("--cors-origin: at most %d origins", MAX_ORIGINS);
        o->origins[o->origin_count++] = v;
    } else
        return srv_fail("serve: unknown option '%s'", a);
    return 0;
}

/* Every option of serve, each with a value; each may also come from ISOSERVE_<NAME> (see
 * the file's comment). set_option applies them by name. */
static const srv_option serve_options_table[] = {
    {"--catalog", "FILE", "the volumes to serve, a JSON catalog (docs/api.md)"},
    {"--volumes", "DIR", "serve every volume in DIR instead, ids from the file names"},
    {"--listen", "HOST:PORT", "where to listen (default 127.0.0.1:8080; port 0: any free port)"},
    {"--cache-dir", "DIR", "keep hierarchy files (and fetched DICOM series) here"},
    {"--web-root", "DIR", "the web client's files (default: web beside the executable)"},
    {"--threads", "N", "mesh workers, 1..256 (default: all cores)"},
    {"--queue", "N", "requests waiting for a worker before 503 (default 64)"},
    {"--cache-mb", "N", "the mesh cache's size in MB (default 256)"},
    {"--chain-mb", "N", "simplification chains kept mapped, in MB (default 2048; files stay in --cache-dir)"},
    {"--chain-background", "on|off", "build the suggested levels' chains after preloading (default on; partial chains are completed either way)"},
    {"--cors-origin", "ORIGIN", "allow this browser origin (repeatable, at most 16)"},
    {"--drain-seconds", "S", "on SIGTERM, how long requests in flight may finish (default 10)"},
    {"--max-connections", "N", "open connections at most (default 256)"},
    {"--connection-timeout", "S", "close a connection idle this long (default 30)"},
    {"--max-volume-mb", "N", "refuse volumes whose samples exceed this (default 8192)"},
    {"--max-resident-mb", "N", "evict least recently used volumes above this (needs --cache-dir; 0: no limit)"},
    {"--max-triangles", "N", "refuse meshes above this many triangles (422)"},
    {"--token-file", "FILE", "require this bearer token (the file's first line)"},
    {"--shard", "K/N", "this replica preloads shard K of N (with --shard-peers)"},
    {"--shard-peers", "HOST:PORT,...", "the N replicas, in shard order"},
    {"--replica-name", "NAME", "this replica's name in X-Iso-Replica"},
};
#define SERVE_OPTIONS (sizeof serve_options_table / sizeof serve_options_table[0])

static int srv_cmd_serve(int argc, char **argv);
const srv_command srv_serve_command = {
    "serve", "[options]",
    "The HTTP daemon: preloads the catalog's volumes and their hierarchies and answers mesh requests.\n"
    "Each option may also come from the environment: ISOSERVE_<OPTION>, e.g. ISOSERVE_CACHE_DIR.",
    serve_options_table, SERVE_OPTIONS, 0, srv_cmd_serve};

static int options_from_env(serve_options *o)
{
    for (size_t i = 0; i < SERVE_OPTIONS; i++) {
        const char *name = serve_options_table[i].name;
        char var[64] = "ISOSERVE_";
        size_t n = strlen(var);
        for (const char *p = name + 2; *p && n + 1 < sizeof var; p++)
            var[n++] = *p == '-' ? '_' : (char)(*p - 'a' + 'A');
        var[n] = '\0';
        const char *v = getenv(var);
        /* Empty or blank is unset: compose files default unset variables to " " (see
         * docker/compose.yaml). */
        if (v && v[strspn(v, " \t")] && set_option(o, name, v, 1))
            return srv_fail("(from the environment variable %s)", var);
    }
    return 0;
}

/* 0, 1 (reported), or -1 when --help printed the usage. */
static int parse_options(int argc, char **argv, serve_options *o)
{
    long cores = sysconf(_SC_NPROCESSORS_ONLN);
    *o = (serve_options){.host = "127.0.0.1", .port = 8080, .threads = cores > 0 ? cores : 1,
                         .queue = 64, .cache_mb = 256, .chain_mb = 2048, .chain_background = 1,
                         .drain_seconds = 10,
                         .max_connections = 256, .max_volume_mb = 8192,
                         .connection_timeout = 30};
    if (options_from_env(o))
        return 1;
    int i = 0, arg;
    const char *value;
    while ((arg = srv_next_arg(&srv_serve_command, argc, argv, &i, &value)) != SRV_ARG_END) {
        if (arg == SRV_ARG_HELP)
            return -1;
        if (arg == SRV_ARG_ERROR)
            return 1;
        if (arg == SRV_ARG_OPERAND)
            return srv_fail("serve: unexpected argument '%s' (serve takes options only)", value);
        if (set_option(o, serve_options_table[arg].name, value, 0))
            return 1;
    }
    if (o->catalog && o->volumes)
        return srv_fail("serve: give --catalog or --volumes, not both");
    if (o->max_resident_mb && !o->cache_dir)
        return srv_fail("serve: --max-resident-mb needs --cache-dir: an evicted volume's "
                        "hierarchy is read back from there, not built again");
    if (!o->shard_count != !o->shard_peers)
        return srv_fail("serve: --shard K/N and --shard-peers HOST:PORT,... go together");
    return 0;
}

/* The bearer token: the file's first line, without its line end. Refused when missing,
 * empty, or holding blanks or control bytes (which no header could carry intact). The
 * token itself is never printed, only the file's name. */
static int read_token(const char *path, char *token, size_t size)
{
    FILE *f = fopen(path, "r");
    if (!f)
        return srv_fail("--token-file %s: %s", path, strerror(errno));
    if (!fgets(token, (int)size, f))
        token[0] = '\0';
    int more = getc(f) != EOF && !strchr(token, '\n');
    fclose(f);
    token[strcspn(token, "\r\n")] = '\0';
    size_t n = strlen(token);
    if (more || n >= size - 1)
        return srv_fail("--token-file %s: the token is longer than %zu bytes", path, size - 2);
    if (n < 16)
        return srv_fail("--token-file %s: the token has %zu bytes; at least 16 are needed", path, n);
    for (size_t i = 0; i < n; i++)
        if ((unsigned char)token[i] <= 0x20 || token[i] == 0x7f)
            return srv_fail("--token-file %s: the token holds a blank or a control byte", path);
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

static void *preload_main(void *arg)
{
    srv_collection *c = arg;
    srv_collection_preload(c);
    if (!atomic_load(&c->stop))
        fprintf(stderr, "isoserve: ready: %zu of %zu volumes%s\n", atomic_load(&c->count),
                c->total, c->options.skip ? " (the others load on demand)" : "");
    return NULL;
}

/* With --shard K/N: the ring of --shard-peers and, per catalog entry, whether another
 * replica owns it (skip[i] = 1). Without: nothing. 0, or 1 reported. */
static int plan_shard(const serve_options *o, const srv_catalog *catalog, srv_shard_ring *ring,
                      unsigned char **skip)
{
    iso_error err;
    memset(ring, 0, sizeof *ring);
    *skip = NULL;
    if (!o->shard_count)
        return 0;
    if (srv_shard_ring_init(ring, o->shard_peers, &err))
        return srv_fail("%s", err.message);
    size_t peers = ring->peer_count;
    if (peers != (size_t)o->shard_count) {
        srv_shard_ring_free(ring);
        return srv_fail("--shard %ld/%ld: --shard-peers names %zu replicas, not %ld", o->shard_self,
                        o->shard_count, peers, o->shard_count);
    }
    if (!(*skip = calloc(catalog->count ? catalog->count : 1, 1))) {
        srv_shard_ring_free(ring);
        return srv_fail("serve: out of memory at start-up");
    }
    size_t own = 0;
    for (size_t i = 0; i < catalog->count; i++) {
        (*skip)[i] = srv_shard_owner(ring, catalog->entries[i].id) != (size_t)o->shard_self;
        own += !(*skip)[i];
    }
    fprintf(stderr, "isoserve: shard %ld/%ld (%s): preloads %zu of %zu volumes; loads the others "
            "on demand\n", o->shard_self, o->shard_count, ring->peers[o->shard_self], own,
            catalog->count);
    return 0;
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
    srv_chains chains;
    srv_chain_background background = {0};
    srv_pool pool;
    srv_server server = {0};
    srv_shard_ring ring;
    unsigned char *skip;
    iso_error err;
    if (plan_shard(o, catalog, &ring, &skip))
        return 1;
    /* The replica's name in X-Iso-Replica: given, else its peer name, else the host's. */
    char host_name[256] = "isoserve";
    const char *replica = o->replica_name ? o->replica_name
                          : o->shard_count ? ring.peers[o->shard_self] : host_name;
    if (!o->replica_name && !o->shard_count && gethostname(host_name, sizeof host_name))
        snprintf(host_name, sizeof host_name, "isoserve");
    host_name[sizeof host_name - 1] = '\0';
    static char token[1024];
    if (o->token_file && read_token(o->token_file, token, sizeof token)) {
        srv_shard_ring_free(&ring);
        free(skip);
        return 1;
    }
    char *root = web_root(o->web_root);
    srv_preload_options preload = {.cache_dir = o->cache_dir, .skip = skip,
                                   .max_volume_bytes = (uint64_t)o->max_volume_mb << 20,
                                   .max_resident_bytes = (uint64_t)o->max_resident_mb << 20};
    if (srv_collection_init(&collection, catalog, &preload) ||
        srv_cache_init(&cache, (size_t)o->cache_mb << 20) ||
        srv_chains_init(&chains, (size_t)o->chain_mb << 20) ||
        srv_pool_init(&pool, (size_t)o->threads, (size_t)o->queue)) {
        srv_shard_ring_free(&ring);
        free(skip);
        free(root);
        return srv_fail("serve: out of memory or threads at start-up");
    }
    server.config = (srv_http_config){
        .host = o->host, .port = o->port, .web_root = root, .cors_origins = o->origins,
        .cors_origin_count = o->origin_count, .max_connections = (unsigned)o->max_connections,
        .connection_timeout_s = (unsigned)o->connection_timeout, .retry_after_s = 1,
        .replica_name = replica, .shard_ring = o->shard_count ? &ring : NULL,
        .token = o->token_file ? token : NULL, .max_triangles = (size_t)o->max_triangles};
    server.collection = &collection;
    server.cache = &cache;
    server.chains = &chains;
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

    pthread_t preloader;
    if (pthread_create(&preloader, NULL, preload_main, &collection)) {
        srv_http_stop(&server);
        status = srv_fail("serve: cannot start the preloading thread");
        goto done;
    }
    if (srv_chain_background_start(&background, &collection, &chains, o->chain_background))
        fprintf(stderr, "isoserve: chains: no thread for the background builder; requests build them\n");
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
    /* A chain cannot be cut short, and a background one is only a head start: one still
     * building a second after the stop is dropped with the process (its temporary file is
     * removed at the next start), which exits without freeing what that thread uses. */
    if (srv_chain_background_stop(&background, 1000)) {
        fprintf(stderr, "isoserve: stopped (a background chain was dropped)\n");
        fflush(NULL);
        _exit(status);
    }
    fprintf(stderr, "isoserve: stopped\n");
done:
    srv_pool_destroy(&pool);
    srv_cache_destroy(&cache);
    srv_chains_destroy(&chains);
    srv_collection_free(&collection);
    srv_shard_ring_free(&ring);
    free(skip);
    free(root);
    return status;
}

static int srv_cmd_serve(int argc, char **argv)
{
    serve_options o;
    int parsed = parse_options(argc, argv, &o);
    if (parsed)
        return parsed < 0 ? 0 : 1; /* -1: --help answered */
    /* Block the stop signals before any thread starts, so that every thread inherits the
     * mask and only serve()'s sigwait takes them; a peer closing early must not kill us. */
    sigset_t stop_signals;
    sigemptyset(&stop_signals);
    sigaddset(&stop_signals, SIGINT);
    sigaddset(&stop_signals, SIGTERM);
    pthread_sigmask(SIG_BLOCK, &stop_signals, NULL);
    signal(SIGPIPE, SIG_IGN);
    /* Past a file size limit (ulimit -f) write() then fails with EFBIG, like a full disk,
     * and the hierarchy is served from memory; the default action would kill the server. */
    signal(SIGXFSZ, SIG_IGN);
    srv_keep_freed_memory();
    srv_catalog catalog;
    if (read_catalog(&o, &catalog))
        return 1;
    int status = serve(&o, &catalog);
    srv_catalog_free(&catalog);
    return status;
}
