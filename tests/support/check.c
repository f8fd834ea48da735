/* check.c: the unit-test harness (see check.h). */
#include "check.h"

#include <stdarg.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <unistd.h>
#include <zlib.h>

static const char *current_name;
static int current_failed, current_skipped, any_failed;
static char skip_reason[256];
static char temp_dir[256];

void check_fail_at(const char *file, int line, const char *fmt, ...)
{
    va_list ap;
    /* Only the first failure of a test is printed on the FAIL line; later ones add detail. */
    printf("%s %s: %s:%d: ", current_failed ? "  also" : "FAIL", current_name, file, line);
    va_start(ap, fmt);
    vprintf(fmt, ap);
    va_end(ap);
    printf("\n");
    fflush(stdout);
    current_failed = 1;
}

void check_skip(const char *fmt, ...)
{
    va_list ap;
    va_start(ap, fmt);
    vsnprintf(skip_reason, sizeof skip_reason, fmt, ap);
    va_end(ap);
    current_skipped = 1;
}

int check_failed(void)
{
    return current_failed;
}

void check_run(const char *name, void (*fn)(void))
{
    current_name = name;
    current_failed = current_skipped = 0;
    fn();
    if (current_failed)
        any_failed = 1;
    else if (current_skipped)
        printf("SKIP %s: %s\n", name, skip_reason);
    else
        printf("PASS %s\n", name);
    fflush(stdout);
}

const char *check_shared_volumes(void)
{
    const char *dir = getenv("ISO_SHARED_VOLUMES");
    struct stat st;
    if (!dir || !*dir)
        dir = "../shared/volumes";
    if (stat(dir, &st) != 0 || !S_ISDIR(st.st_mode))
        return NULL;
    return dir;
}

const char *check_temp_dir(void)
{
    if (!temp_dir[0]) {
        snprintf(temp_dir, sizeof temp_dir, "/tmp/isoserve-test-XXXXXX");
        if (!mkdtemp(temp_dir)) {
            perror("mkdtemp");
            exit(2);
        }
    }
    return temp_dir;
}

int check_finish(void)
{
    if (temp_dir[0]) {
        char cmd[300];
        snprintf(cmd, sizeof cmd, "rm -rf '%s'", temp_dir);
        if (system(cmd) != 0)
            fprintf(stderr, "could not remove %s\n", temp_dir);
    }
    return any_failed ? 1 : 0;
}

unsigned char *check_deflate(const void *data, size_t size, int window, int level,
                             size_t *out_size)
{
    z_stream zs;
    memset(&zs, 0, sizeof zs);
    CHECK(deflateInit2(&zs, level, Z_DEFLATED, window, 8, Z_DEFAULT_STRATEGY) == Z_OK);
    size_t cap = deflateBound(&zs, (uLong)size) + 64;
    unsigned char *out = malloc(cap);
    CHECK(out != NULL);
    if (!out) {
        deflateEnd(&zs);
        return NULL;
    }
    zs.next_in = (Bytef *)(uintptr_t)data; /* zlib's API is not const-correct */
    zs.avail_in = (uInt)size;
    zs.next_out = out;
    zs.avail_out = (uInt)cap;
    CHECK(deflate(&zs, Z_FINISH) == Z_STREAM_END);
    *out_size = cap - zs.avail_out;
    deflateEnd(&zs);
    return out;
}

void check_gunzip(const void *gz, size_t gz_size, const void *want, size_t size)
{
    unsigned char *out = malloc(size + 1);
    z_stream z = {0};
    CHECK(out && inflateInit2(&z, 16 + 15) == Z_OK);
    if (!out)
        return;
    z.next_in = (Bytef *)(uintptr_t)gz;
    z.avail_in = (uInt)gz_size;
    z.next_out = out;
    z.avail_out = (uInt)size + 1;
    int rc = inflate(&z, Z_FINISH);
    CHECKF(rc == Z_STREAM_END && z.avail_in == 0 && z.total_out == size, "inflate %d, %u left, %lu out of %zu", rc,
           z.avail_in, z.total_out, size);
    CHECK(z.total_out != size || !size || !memcmp(out, want, size));
    inflateEnd(&z);
    free(out);
}

void check_write_file(const char *path, const void *a, size_t a_len, const void *b, size_t b_len)
{
    FILE *f = fopen(path, "wb");
    CHECKF(f != NULL, "cannot create %s", path);
    if (!f)
        return;
    CHECK(fwrite(a, 1, a_len, f) == a_len);
    if (b_len)
        CHECK(fwrite(b, 1, b_len, f) == b_len);
    CHECK(fclose(f) == 0);
}
