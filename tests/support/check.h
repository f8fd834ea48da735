/* check.h: the unit-test harness. Each test is a void function run by CHECK_RUN; it prints
 * one line per test, "PASS name", "FAIL name: file:line: what" or "SKIP name: why", which
 * tests/run.sh counts into the closing "N passed, N failed, N skipped" line. */
#ifndef ISO_CHECK_H
#define ISO_CHECK_H

#include <stddef.h>

void check_fail_at(const char *file, int line, const char *fmt, ...)
#if defined(__GNUC__)
    __attribute__((format(printf, 3, 4)))
#endif
    ;
/* Marks the running test as skipped with a reason (a missing data set, say). */
void check_skip(const char *fmt, ...)
#if defined(__GNUC__)
    __attribute__((format(printf, 1, 2)))
#endif
    ;
/* 1 once the running test has failed: long tests use it to stop early. */
int check_failed(void);
void check_run(const char *name, void (*fn)(void));
/* Prints nothing more; returns the process exit status (1 if any test failed). */
int check_finish(void);

/* Directory of the shared real volumes ($ISO_SHARED_VOLUMES or ../shared/volumes), or NULL
 * when it does not exist (a user's clone): tests then skip, saying so. */
const char *check_shared_volumes(void);
/* A fresh temporary directory for this process, removed by check_finish. */
const char *check_temp_dir(void);

/* Writes a then b (b_len may be 0) to path; failures are CHECK failures. */
void check_write_file(const char *path, const void *a, size_t a_len, const void *b, size_t b_len);
/* Compresses data with zlib's deflate into a malloc'd buffer (caller frees): window 15 + 16
 * for gzip framing, 15 for zlib; level 0 stores the bytes as they are, so a stream cut at a
 * known offset inflates to a known number of bytes. Failures are CHECK failures. */
unsigned char *check_deflate(const void *data, size_t size, int window, int level,
                             size_t *out_size);
/* The gzip member gz (one, nothing after it) inflates with zlib to exactly want's size
 * bytes; failures are CHECK failures. */
void check_gunzip(const void *gz, size_t gz_size, const void *want, size_t size);

#define CHECK(cond) \
    do { if (!(cond)) check_fail_at(__FILE__, __LINE__, "%s", #cond); } while (0)
#define CHECKF(cond, ...) \
    do { if (!(cond)) check_fail_at(__FILE__, __LINE__, __VA_ARGS__); } while (0)
#define CHECK_EQ(a, b) \
    do { long long _a = (long long)(a), _b = (long long)(b); \
         if (_a != _b) check_fail_at(__FILE__, __LINE__, "%s == %s: %lld != %lld", #a, #b, _a, _b); } while (0)
#define CHECK_NEAR(a, b, eps) \
    do { double _a = (double)(a), _b = (double)(b), _e = (double)(eps); \
         if (!(_a - _b <= _e && _b - _a <= _e)) \
             check_fail_at(__FILE__, __LINE__, "%s ~ %s: %.9g vs %.9g (eps %g)", #a, #b, _a, _b, _e); } while (0)
#define CHECK_OK(expr, errp) \
    do { int _rc = (expr); \
         if (_rc != 0) check_fail_at(__FILE__, __LINE__, "%s returned %d: %s", #expr, _rc, (errp)->message); } while (0)
#define CHECK_RUN(fn) check_run(#fn, fn)

#endif
