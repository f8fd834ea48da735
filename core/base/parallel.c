/* parallel.c: a fork-join of one function over a few threads (see base.h).
 *
 * The helpers are a pool started on first use and kept for the process's life: starting
 * a thread per share cost 70-100 µs per call on the development machine, twice per exact
 * extraction (7-9% of aneurism's 2.2 ms on two threads). A call posts its shares 1..n-1,
 * runs share 0 itself, then runs every share no helper has taken yet, and only then
 * waits for the ones helpers hold. So a call never waits for a share nobody runs: with
 * fewer helpers than shares, with every helper busy on other calls (the server runs
 * requests side by side), or from inside a share (a nested call), it still finishes. */
#include "base.h"

#include <pthread.h>
#include <stddef.h>
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

/* One call's shares. It lives on the caller's stack: the caller returns only when every
 * share a helper took is finished, and a helper touches it only under the lock before
 * that. */
typedef struct call {
    iso_parallel_fn fn;
    void *context;
    int threads;
    int next;           /* the next share not yet taken */
    int held;           /* shares helpers have taken and not finished */
    struct call *later; /* the next call with shares to take */
} call;

static pthread_mutex_t lock = PTHREAD_MUTEX_INITIALIZER;
static pthread_cond_t work = PTHREAD_COND_INITIALIZER; /* a call was posted */
static pthread_cond_t done = PTHREAD_COND_INITIALIZER; /* a helper finished a share */
static call *waiting;                                  /* calls with shares to take, oldest first */

/* Takes the next share of the oldest call; the lock is held. Every call on the list has
 * one left (the last share taken, by a helper or by its caller, takes it off). */
static call *take(int *t)
{
    call *c = waiting;
    if (!c)
        return NULL;
    *t = c->next++;
    if (c->next == c->threads)
        waiting = c->later; /* its last share: off the list */
    return c;
}

static void *helper(void *unused)
{
    (void)unused;
    pthread_mutex_lock(&lock);
    for (;;) {
        int t;
        call *c = take(&t);
        if (!c) {
            pthread_cond_wait(&work, &lock);
            continue;
        }
        c->held++;
        pthread_mutex_unlock(&lock);
        c->fn(c->context, t, c->threads);
        pthread_mutex_lock(&lock);
        c->held--;
        pthread_cond_broadcast(&done);
    }
    return NULL;
}

/* As many helpers as other cores; fewer if some cannot start (then callers do more). */
static void start_helpers(void)
{
    pthread_attr_t attr;
    int ready = pthread_attr_init(&attr) == 0 && pthread_attr_setdetachstate(&attr, PTHREAD_CREATE_DETACHED) == 0;
    for (int i = 1; ready && i < iso_parallel_cores(); i++) {
        pthread_t id;
        if (pthread_create(&id, &attr, helper, NULL) != 0)
            break;
    }
    if (ready)
        pthread_attr_destroy(&attr);
}

/* Removes c from the waiting list if it is still there; the lock is held. */
static void withdraw(call *c)
{
    for (call **p = &waiting; *p; p = &(*p)->later)
        if (*p == c) {
            *p = c->later;
            return;
        }
}

void iso_parallel_run(int threads, iso_parallel_fn fn, void *context)
{
    static pthread_once_t once = PTHREAD_ONCE_INIT;
    threads = iso_parallel_threads(threads);
    if (threads == 1) {
        fn(context, 0, 1);
        return;
    }
    pthread_once(&once, start_helpers);
    call c = {fn, context, threads, 1, 0, NULL};
    pthread_mutex_lock(&lock);
    call **end = &waiting;
    while (*end)
        end = &(*end)->later;
    *end = &c;
    pthread_cond_broadcast(&work);
    pthread_mutex_unlock(&lock);

    fn(context, 0, threads);
    pthread_mutex_lock(&lock);
    while (c.next < threads) { /* shares no helper has taken: run them here */
        int t = c.next++;
        if (c.next == threads)
            withdraw(&c); /* a call on the list always has a share left to take */
        pthread_mutex_unlock(&lock);
        fn(context, t, threads);
        pthread_mutex_lock(&lock);
    }
    while (c.held > 0)
        pthread_cond_wait(&done, &lock);
    pthread_mutex_unlock(&lock);
}

int iso_parallel_next_chunk(atomic_size_t *next, size_t count, size_t chunk, size_t *begin, size_t *end)
{
    size_t first = atomic_fetch_add_explicit(next, chunk, memory_order_relaxed);
    if (first >= count)
        return 0;
    *begin = first;
    *end = count - first < chunk ? count : first + chunk;
    return 1;
}
