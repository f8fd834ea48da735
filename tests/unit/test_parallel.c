/* test_parallel.c: iso_parallel_run's promise, which every threaded pass relies on: each
 * share runs exactly once and the call returns only after all of them, whether the pool's
 * helpers are free, busy with other calls, or the call comes from inside a share. */
#include <pthread.h>
#include <stdatomic.h>
#include <string.h>

#include "check.h"
#include "base/base.h"

#define MOST ISO_PARALLEL_MAX_THREADS

typedef struct tally {
    atomic_int runs[MOST];
    atomic_int wrong_count; /* shares told a thread count other than the call's */
    int threads;
} tally;

static void count_share(void *context, int t, int threads)
{
    tally *c = context;
    if (threads != c->threads)
        atomic_fetch_add(&c->wrong_count, 1);
    atomic_fetch_add(&c->runs[t], 1);
}

static void check_once_each(tally *c)
{
    CHECK_EQ(atomic_load(&c->wrong_count), 0);
    for (int t = 0; t < MOST; t++)
        CHECKF(atomic_load(&c->runs[t]) == (t < c->threads), "%d threads: share %d ran %d times", c->threads, t,
               atomic_load(&c->runs[t]));
}

static void run_counted(int threads)
{
    tally c;
    memset(&c, 0, sizeof c);
    c.threads = iso_parallel_threads(threads);
    iso_parallel_run(threads, count_share, &c);
    check_once_each(&c);
}

/* 1 to 64 shares, more than this machine has cores: the caller runs what helpers do not. */
static void test_every_share_once(void)
{
    for (int round = 0; round < 20 && !check_failed(); round++)
        for (int threads = 1; threads <= MOST && !check_failed(); threads++)
            run_counted(threads);
    run_counted(0); /* all cores */
}

/* A share that itself runs a call (a pass inside a pass): no helper may be free for it. */
static void nested_share(void *context, int t, int threads)
{
    (void)t;
    (void)threads;
    atomic_int *inner_ok = context;
    tally c;
    memset(&c, 0, sizeof c);
    c.threads = 5;
    iso_parallel_run(5, count_share, &c);
    int ok = atomic_load(&c.wrong_count) == 0;
    for (int s = 0; s < MOST; s++)
        ok &= atomic_load(&c.runs[s]) == (s < 5);
    atomic_fetch_add(inner_ok, ok);
}

static void test_nested_calls_finish(void)
{
    atomic_int inner_ok = 0;
    iso_parallel_run(4, nested_share, &inner_ok);
    CHECK_EQ(atomic_load(&inner_ok), 4);
}

/* Calls from several threads at once, as the server's requests make them. */
static void *caller(void *arg)
{
    int *failures = arg;
    for (int round = 0; round < 200; round++) {
        tally c;
        memset(&c, 0, sizeof c);
        c.threads = 2 + round % 7;
        iso_parallel_run(c.threads, count_share, &c);
        int ok = atomic_load(&c.wrong_count) == 0;
        for (int t = 0; t < MOST; t++)
            ok &= atomic_load(&c.runs[t]) == (t < c.threads);
        *failures += !ok;
    }
    return NULL;
}

static void test_calls_side_by_side(void)
{
    pthread_t id[6];
    int failures[6] = {0}, started = 0;
    for (int i = 0; i < 6; i++)
        if (pthread_create(&id[i], NULL, caller, &failures[i]) == 0)
            started++;
        else
            break;
    CHECK_EQ(started, 6);
    for (int i = 0; i < started; i++) {
        pthread_join(id[i], NULL);
        CHECKF(failures[i] == 0, "caller %d: %d calls ran a share other than once", i, failures[i]);
    }
}

int main(void)
{
    CHECK_RUN(test_every_share_once);
    CHECK_RUN(test_nested_calls_finish);
    CHECK_RUN(test_calls_side_by_side);
    return check_finish();
}
