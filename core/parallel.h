/* parallel.h: running one function on several threads, for the passes of build and
 * extraction that split their work into independent ranges. */
#ifndef ISO_PARALLEL_H
#define ISO_PARALLEL_H

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

#endif
