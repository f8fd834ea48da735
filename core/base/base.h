/* base.h: what every stage of the core shares: the error report and status codes, the
 * thread pool, files replaced whole, the monotonic clock and outward rounding of doubles to
 * floats.
 *
 * Ownership: nothing here allocates for the caller; iso_error is a caller-owned value.
 * Errors: fallible core functions return 0 or a negative ISO_E_* code and fill an optional
 * iso_error. Thread-safety: every function may be called from any thread; the pool's helper
 * threads are started once per process and shared by all calls. Cost: O(1) except
 * iso_parallel_run, which costs what its function does, and iso_file_replace, which costs
 * its bytes and one fsync. */
#ifndef ISO_BASE_H
#define ISO_BASE_H

#include <math.h>
#include <stddef.h>
#include <time.h>

/* The error report every fallible core function fills.
 *
 * Functions return 0 on success and a negative ISO_E* code on failure; when the caller
 * passes a non-NULL iso_error, it receives the code and a message that says what failed
 * and where (file name, header line, byte offset). server/ maps codes to HTTP statuses. */

enum iso_status {
    ISO_OK = 0,
    ISO_E_IO = -1,          /* a file could not be opened, read or written */
    ISO_E_FORMAT = -2,      /* the bytes do not follow the format (malformed header, bad value) */
    ISO_E_TRUNCATED = -3,   /* the data ends before the header says it should */
    ISO_E_UNSUPPORTED = -4, /* a valid but unsupported feature (encoding, type, dimension) */
    ISO_E_LIMIT = -5,       /* sizes overflow or exceed the configured memory limit */
    ISO_E_NOMEM = -6,       /* an allocation failed */
    ISO_E_ARGUMENT = -7,    /* a parameter out of its documented range */
    ISO_E_STALE = -8,       /* a hierarchy file does not belong to this volume */
    ISO_E_CORRUPT = -9,     /* a checksum does not match */
    ISO_E_INTERNAL = -10    /* a broken invariant of isoserve itself (a bug): never the
                             * caller's input, never a lack of memory */
};

typedef struct iso_error {
    int code;
    char message[512];
} iso_error;

/* Fills err (if not NULL) with code and a printf-style message; returns code so that
 * callers can write `return iso_error_set(err, ISO_E_FORMAT, "...", ...);`. */
int iso_error_set(iso_error *err, int code, const char *fmt, ...)
#if defined(__GNUC__)
    __attribute__((format(printf, 3, 4)))
#endif
    ;

/* A short English name for a status code ("format error", ...). Never NULL. */
const char *iso_status_name(int code);

/* Running one function on several threads, for the passes of build and
 * extraction that split their work into independent ranges. */

/* The most threads any pass uses. */
#define ISO_PARALLEL_MAX_THREADS 64

/* Cores online, 1..64: what "all cores" (threads = 0) means everywhere. */
int iso_parallel_cores(void);

/* Resolves a requested thread count: 0 means all cores; the result is 1..64. */
int iso_parallel_threads(int requested);

/* Calls fn(context, t, threads) for t = 0..threads-1, on the caller and the process's
 * helper threads (one per other core, started on the first call and kept), and returns
 * when all are done. Shares no helper is free to take the caller runs itself, so every t
 * runs exactly once whatever happens, calls may run side by side or inside a share, and
 * fn must not wait for another share of its own call. */
typedef void (*iso_parallel_fn)(void *context, int t, int threads);
void iso_parallel_run(int threads, iso_parallel_fn fn, void *context);

#ifndef __cplusplus /* C11 atomics; the C++ shims (Draco, meshoptimizer) do not hand out work */
#include <stdatomic.h>
/* Work handed out `chunk` items at a time from a counter the shares have in common (each
 * share loops until it returns 0; the caller sets *next to 0 before the run): sets
 * [*begin, *end) to the next chunk of 0..count - 1 and returns 1, or returns 0 when none is
 * left. Chunks rather than a fixed split let a free core take more when another process
 * holds one. */
int iso_parallel_next_chunk(atomic_size_t *next, size_t count, size_t chunk, size_t *begin, size_t *end);
#endif

/* Files written whole (hierarchies, chains): a reader sees the old bytes or the new. */

/* One run of bytes of a file, written in order with the others. */
typedef struct iso_file_part {
    const void *data;
    size_t bytes;
} iso_file_part;

/* Writes the parts, in order, to a temporary file beside path, syncs it and renames it
 * over path. Returns 0, ISO_E_NOMEM or ISO_E_IO (err says which step failed and why); on
 * failure path is untouched and the temporary file removed. */
int iso_file_replace(const char *path, const iso_file_part *parts, size_t count, iso_error *err);

/* The monotonic clock behind every *_ms figure (build, extract, load times). */

/* Milliseconds on CLOCK_MONOTONIC: only differences mean anything. */
static inline double iso_clock_ms(void)
{
    struct timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return ts.tv_sec * 1e3 + ts.tv_nsec / 1e6;
}

/* Doubles to floats rounded outward, so that bounds stored as floats (min, max,
 * fit error) keep "min <= level < max" and "err <= tolerance" conservative. */

static inline float iso_float_down(double x)
{
    float f = (float)x;
    return (double)f > x ? nextafterf(f, -INFINITY) : f;
}

static inline float iso_float_up(double x)
{
    float f = (float)x;
    return (double)f < x ? nextafterf(f, INFINITY) : f;
}

#endif
