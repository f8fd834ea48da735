/* parallel.c: a fork-join of one function over a few threads (see parallel.h). Threads
 * are started per call: at two to a few dozen threads that costs tens of microseconds,
 * small against the passes that use it, and keeps no pool alive between requests. */
#include "parallel.h"

#include <pthread.h>
#include <unistd.h>

#define MAX_THREADS ISO_PARALLEL_MAX_THREADS

int iso_parallel_cores(void)
{
    long n = sysconf(_SC_NPROCESSORS_ONLN);
    return n < 1 ? 1 : n > MAX_THREADS ? MAX_THREADS : (int)n;
}

int iso_parallel_threads(int requested)
{
    if (requested <= 0)
        return iso_parallel_cores();
    return requested > MAX_THREADS ? MAX_THREADS : requested;
}

typedef struct share {
    iso_parallel_fn fn;
    void *context;
    int t, threads;
} share;

static void *run_share(void *arg)
{
    share *s = arg;
    s->fn(s->context, s->t, s->threads);
    return NULL;
}

void iso_parallel_run(int threads, iso_parallel_fn fn, void *context)
{
    threads = iso_parallel_threads(threads);
    share shares[MAX_THREADS];
    pthread_t tid[MAX_THREADS];
    int started[MAX_THREADS] = {0};
    for (int t = 1; t < threads; t++) {
        shares[t] = (share){fn, context, t, threads};
        started[t] = pthread_create(&tid[t], NULL, run_share, &shares[t]) == 0;
    }
    fn(context, 0, threads);
    for (int t = 1; t < threads; t++) {
        if (started[t])
            pthread_join(tid[t], NULL);
        else
            fn(context, t, threads);
    }
}
