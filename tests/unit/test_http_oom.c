/* test_http_oom.c: allocation failures while the HTTP layer answers. A server (the real
 * server/ objects: http.c, the collection, the cache, the pool) runs in this process on
 * loopback; for each request kind the test counts the allocations the request makes, then
 * repeats it once per allocation with exactly that one failing. Every answer must be the
 * request's usual status or 503 with Retry-After (as other overload answers), a complete
 * HTTP response on the open connection: never a dropped connection, never a crash, and the
 * server answers the next request as before.
 *
 * The client side uses no allocator: requests are formatted before arming, sockets and
 * buffers are static. Each request goes on a connection that has already carried one
 * answered request, so the connection's own set-up (libmicrohttpd's pool) is not what
 * fails. The failures come from tests/support/alloc; under ASan the test says SKIP. */
#include <arpa/inet.h>
#include <netinet/in.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <strings.h>
#include <sys/socket.h>
#include <unistd.h>

#include "alloc_fail.h"
#include "cache.h"
#include "catalog.h"
#include "check.h"
#include "collection.h"
#include "http.h"
#include "pool.h"

#if ALLOC_FAIL_AVAILABLE

static unsigned port;

/* One HTTP response as read off the wire. */
typedef struct response {
    int status;         /* 0: the connection closed before a complete response */
    int retry_after;    /* the header was there */
    int header_count;   /* header lines: an answer missing one is not the whole answer */
    size_t body_size;
} response;

static int connect_loopback(void)
{
    int fd = socket(AF_INET, SOCK_STREAM, 0);
    struct sockaddr_in addr = {.sin_family = AF_INET, .sin_port = htons((unsigned short)port)};
    inet_pton(AF_INET, "127.0.0.1", &addr.sin_addr);
    if (fd >= 0 && connect(fd, (struct sockaddr *)&addr, sizeof addr)) {
        close(fd);
        return -1;
    }
    return fd;
}

static int send_all(int fd, const char *text)
{
    size_t n = strlen(text);
    while (n) {
        ssize_t w = send(fd, text, n, MSG_NOSIGNAL);
        if (w <= 0)
            return -1;
        text += w;
        n -= (size_t)w;
    }
    return 0;
}

/* The value of header name in the head (NUL-terminated), or NULL. */
static const char *header(const char *head, const char *name)
{
    size_t n = strlen(name);
    for (const char *line = strstr(head, "\r\n"); line; line = strstr(line + 2, "\r\n"))
        if (!strncasecmp(line + 2, name, n) && line[2 + n] == ':')
            return line + 3 + n;
    return NULL;
}

/* Reads one response framed by Content-Length (every answer of the server has one). */
static response read_response(int fd)
{
    static char buf[1 << 20];
    response r = {0};
    size_t have = 0, head = 0;
    while (!head) {
        ssize_t n = recv(fd, buf + have, sizeof buf - 1 - have, 0);
        if (n <= 0)
            return r;
        have += (size_t)n;
        buf[have] = '\0';
        char *end = strstr(buf, "\r\n\r\n");
        if (end)
            head = (size_t)(end - buf) + 4;
    }
    char saved = buf[head - 2];
    buf[head - 2] = '\0'; /* the head alone, for header() */
    const char *length = header(buf, "Content-Length");
    r.retry_after = header(buf, "Retry-After") != NULL;
    for (const char *line = strstr(buf, "\r\n"); line; line = strstr(line + 2, "\r\n"))
        r.header_count++;
    size_t want = head + (length ? strtoul(length, NULL, 10) : 0);
    buf[head - 2] = saved;
    if (!length || sscanf(buf, "HTTP/1.1 %d", &r.status) != 1)
        return (response){0};
    while (have < want) { /* the body: counted, not kept beyond the buffer */
        ssize_t n = recv(fd, buf + (have < sizeof buf - 1 ? have : 0),
                         have < sizeof buf - 1 ? sizeof buf - 1 - have : sizeof buf - 1, 0);
        if (n <= 0)
            return (response){0};
        have += (size_t)n;
    }
    r.body_size = want - head;
    return r;
}

/* Sends target on a connection that first carried an unarmed /healthz, with allocation
 * fail_at failing (-1: none); *calls receives the allocations made meanwhile. */
static response request(const char *target, long fail_at, long *calls)
{
    static char warm[] = "GET /healthz HTTP/1.1\r\nHost: test\r\n\r\n";
    char text[512];
    snprintf(text, sizeof text, "GET %s HTTP/1.1\r\nHost: test\r\nConnection: close\r\n\r\n", target);
    response r = {0};
    int fd = connect_loopback();
    if (fd < 0 || send_all(fd, warm) || read_response(fd).status != 200) {
        if (fd >= 0)
            close(fd);
        return r;
    }
    alloc_fail_arm(fail_at);
    if (!send_all(fd, text))
        r = read_response(fd);
    *calls = alloc_fail_disarm();
    close(fd);
    return r;
}

/* Runs target once per allocation it makes, that one failing. */
static void sweep(const char *target, int want_status)
{
    long total = 0, calls = 0, unavailable = 0;
    response clean = request(target, -1, &total);
    CHECKF(clean.status == want_status, "%s: clean run answered %d, want %d", target, clean.status,
           want_status);
    for (long n = 0; n < total + 8 && !check_failed(); n++) { /* +8: threads vary a little */
        response r = request(target, n, &calls);
        CHECKF(r.status == want_status || (r.status == 503 && r.retry_after),
               "%s, allocation %ld of %ld failing: %s %d%s", target, n, calls,
               r.status ? "answered" : "no complete response, status", r.status,
               r.status == 503 ? " without Retry-After" : "");
        CHECKF(r.status != want_status || r.header_count == clean.header_count,
               "%s, allocation %ld failing: answered %d with %d header lines, want all %d",
               target, n, r.status, r.header_count, clean.header_count);
        unavailable += r.status == 503;
        response after = request(target, -1, &calls);
        CHECKF(after.status == want_status, "%s: after allocation %ld failed, the next request "
               "answered %d, want %d", target, n, after.status, want_status);
    }
    printf("  %s: %ld allocations, %ld answered 503\n", target, total, unavailable);
    CHECKF(unavailable > 0, "%s: no allocation failure reached the answer", target);
}

static void test_http_allocation_failures(void)
{
    char dir[] = "/tmp/isoserve-http-oom-XXXXXX", file[64];
    CHECK(mkdtemp(dir) != NULL);
    snprintf(file, sizeof file, "%s/catalog.json", dir);
    FILE *f = fopen(file, "w");
    CHECK(f != NULL);
    if (!f)
        return;
    fputs("{\"volumes\": [{\"id\": \"sphere\", \"path\": \"field:sphere:24\"}]}\n", f);
    fclose(f);

    srv_catalog catalog;
    srv_collection collection;
    srv_cache cache;
    srv_pool pool;
    srv_server server = {0};
    iso_error err = {0};
    srv_preload_options preload = {0};
    CHECK_OK(srv_catalog_read(file, &catalog, &err), &err);
    CHECK(srv_collection_init(&collection, &catalog, &preload) == 0);
    srv_collection_preload(&collection);
    CHECK(srv_cache_init(&cache, 0) == 0); /* no cache: every mesh request runs a job */
    CHECK(srv_pool_init(&pool, 1, 4) == 0);
    server.config = (srv_http_config){.host = "127.0.0.1", .retry_after_s = 1,
                                      .replica_name = "test", .max_connections = 16,
                                      .connection_timeout_s = 10};
    server.collection = &collection;
    server.cache = &cache;
    server.pool = &pool;
    CHECK_OK(srv_http_start(&server, &err), &err);
    port = server.port;

    if (!check_failed()) {
        sweep("/v1/volumes", 200);
        sweep("/v1/volumes/sphere", 200);
        sweep("/v1/volumes/sphere/mesh?level=5&format=ply&measures=true", 200);
        sweep("/v1/volumes/sphere/mesh?level=5&tolerance=2&format=glb&normals=triquadratic", 200);
        sweep("/v1/volumes/nothing", 404);
        sweep("/metrics", 200);
    }
    srv_http_quiesce(&server);
    srv_http_drain(&server, 5000);
    srv_http_stop(&server);
    srv_pool_destroy(&pool);
    srv_cache_destroy(&cache);
    srv_collection_free(&collection);
    srv_catalog_free(&catalog);
    remove(file);
    rmdir(dir);
}

int main(void)
{
    CHECK_RUN(test_http_allocation_failures);
    return check_finish();
}
#else
static void test_http_allocation_failures(void)
{
    check_skip("the sanitizer build's malloc is ASan's, which this test would have to replace");
}

int main(void)
{
    CHECK_RUN(test_http_allocation_failures);
    return check_finish();
}
#endif
