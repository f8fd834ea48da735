/* chain_background.c: the chains of every preloaded volume's suggested levels, built one
 * at a time on a thread of the lowest priority once preloading is done, then the partial
 * chains requests made, completed on the same thread (see chain_background.h). */
#define _GNU_SOURCE /* SCHED_IDLE */
#include "chain_background.h"

#include <pthread.h>
#include <sched.h>
#include <stdio.h>
#include <string.h>
#include <sys/resource.h>
#include <time.h>
#include <unistd.h>

#include "mesh_job.h"

/* This thread's priority: SCHED_IDLE (it runs only when a core would otherwise idle),
 * else nice 19. The build runs on this thread alone (threads 1), so that no share of it
 * lands on the core's helper threads, which run at normal priority. */
static void lowest_priority(void)
{
    struct sched_param none = {0};
    if (pthread_setschedparam(pthread_self(), SCHED_IDLE, &none) == 0)
        return;
    static int said;
    if (setpriority(PRIO_PROCESS, 0, 19) && !said++)
        fprintf(stderr, "isoserve: chains: cannot lower the background builder's priority\n");
}

static void set_progress(srv_chain_background *b, const char *current)
{
    pthread_mutex_lock(&b->chains->lock);
    snprintf(b->chains->progress.current, sizeof b->chains->progress.current, "%s", current);
    b->chains->progress.current_since_ms = iso_clock_ms();
    pthread_mutex_unlock(&b->chains->lock);
}

static void count(srv_chain_background *b, size_t *field)
{
    pthread_mutex_lock(&b->chains->lock);
    (*field)++;
    b->chains->progress.current[0] = '\0';
    pthread_mutex_unlock(&b->chains->lock);
}

/* The chains of one volume's suggested levels. */
static void build_volume(srv_chain_background *b, const srv_volume *v, size_t *done)
{
    srv_chain_progress *p = &b->chains->progress;
    for (size_t i = 0; i < v->level_count && !atomic_load(&b->stop); i++) {
        char what[160];
        snprintf(what, sizeof what, "%s level %g", v->entry->id, v->levels[i]);
        set_progress(b, what);
        lowest_priority(); /* again: a request that waited for the last chain raised it */
        iso_error err = {0};
        double ms;
        int rc = srv_mesh_chain_ensure(v, b->collection, b->chains, v->levels[i], 1, &ms, &err);
        ++*done;
        if (rc == 0) {
            fprintf(stderr, "isoserve: chains: %zu/%zu %s built in %.1f s\n", *done, p->planned, what, ms / 1000);
            count(b, &p->built);
        } else if (rc > 0) {
            count(b, &p->loaded); /* in its file, or a request builds it now */
        } else {
            fprintf(stderr, "isoserve: chains: %zu/%zu %s failed: %s\n", *done, p->planned, what, err.message);
            count(b, &p->failed);
        }
    }
}

/* Every preloaded volume's suggested levels' chains, one at a time. */
static void build_suggested(srv_chain_background *b)
{
    /* The preloaded volumes and their levels, counted first for the progress. */
    size_t total = b->collection->total, planned = 0, done = 0;
    srv_collection_lock(b->collection);
    for (size_t i = 0; i < total; i++) {
        const srv_volume *v = srv_collection_loaded(b->collection, i);
        planned += v && !v->on_demand && !v->seg ? v->level_count : 0;
    }
    srv_collection_unlock(b->collection);
    pthread_mutex_lock(&b->chains->lock);
    b->chains->progress.planned = planned;
    b->chains->progress.running = 1;
    pthread_mutex_unlock(&b->chains->lock);
    if (planned)
        fprintf(stderr, "isoserve: chains: %zu of the suggested levels, in the background\n", planned);
    for (size_t i = 0; i < total && !atomic_load(&b->stop); i++) {
        const srv_volume *v;
        const char *id = b->collection->catalog->entries[i].id;
        srv_collection_lock(b->collection);
        int preloaded = (v = srv_collection_loaded(b->collection, i)) && !v->on_demand && !v->seg;
        srv_collection_unlock(b->collection);
        /* A reference holds it while its chains are built (acquire does not load it again:
         * it is loaded; if it was evicted meanwhile, it is skipped). */
        if (!preloaded || srv_collection_acquire(b->collection, id, &v) != SRV_VOLUME_READY)
            continue;
        build_volume(b, v, &done);
        srv_collection_release(b->collection, v);
    }
    pthread_mutex_lock(&b->chains->lock);
    b->chains->progress.running = 0;
    b->chains->progress.finished = 1;
    b->chains->progress.current[0] = '\0';
    pthread_mutex_unlock(&b->chains->lock);
    if (planned && !atomic_load(&b->stop))
        fprintf(stderr, "isoserve: chains: done (%zu built, %zu there already, %zu failed)\n",
                b->chains->progress.built, b->chains->progress.loaded, b->chains->progress.failed);
}

/* The partial chains requests made (srv_chains_defer), completed one at a time until the
 * stop: each is written beside the hierarchy and mapped, replacing the one in memory. */
static void complete_deferred(srv_chain_background *b)
{
    while (!atomic_load(&b->stop)) {
        srv_mesh_chain_task *task = (srv_mesh_chain_task *)srv_chains_next_deferred(b->chains, 100);
        if (!task)
            continue;
        lowest_priority(); /* again: a request that waited for the last one raised it */
        char what[160];
        srv_mesh_chain_task_name(task, what, sizeof what);
        set_progress(b, what);
        iso_error err = {0};
        double ms;
        int rc = srv_mesh_chain_task_run(task, b->chains, &ms, &err);
        if (rc == 0)
            fprintf(stderr, "isoserve: chains: %s completed in %.1f s\n", what, ms / 1000);
        else if (rc < 0)
            fprintf(stderr, "isoserve: chains: %s not completed: %s\n", what, err.message);
        set_progress(b, "");
        srv_mesh_chain_task_free(task);
    }
}

static void *background_main(void *arg)
{
    srv_chain_background *b = arg;
    lowest_priority();
    while (!atomic_load(&b->collection->ready) && !atomic_load(&b->stop)) {
        struct timespec pause = {0, 100 * 1000 * 1000};
        nanosleep(&pause, NULL);
    }
    if (b->suggested)
        build_suggested(b);
    complete_deferred(b);
    atomic_store(&b->finished, 1);
    return NULL;
}

int srv_chain_background_start(srv_chain_background *b, srv_collection *collection, srv_chains *chains,
                               int suggested)
{
    memset(b, 0, sizeof *b);
    b->collection = collection;
    b->chains = chains;
    b->suggested = suggested;
    if (pthread_create(&b->thread, NULL, background_main, b))
        return ISO_E_NOMEM;
    pthread_mutex_lock(&chains->lock);
    chains->progress.enabled = suggested;
    chains->completer = 1;
    pthread_mutex_unlock(&chains->lock);
    b->started = 1;
    return 0;
}

int srv_chain_background_stop(srv_chain_background *b, double timeout_ms)
{
    if (!b->started)
        return 0;
    pthread_mutex_lock(&b->chains->lock);
    b->chains->completer = 0; /* no more work queued */
    pthread_mutex_unlock(&b->chains->lock);
    atomic_store(&b->stop, 1);
    double until = iso_clock_ms() + timeout_ms;
    while (!atomic_load(&b->finished) && iso_clock_ms() < until) {
        struct timespec pause = {0, 20 * 1000 * 1000};
        nanosleep(&pause, NULL);
    }
    if (!atomic_load(&b->finished))
        return 1;
    pthread_join(b->thread, NULL);
    b->started = 0;
    /* What was left queued: its volumes' references go back, the chains stay partial. */
    srv_chain_deferred *task;
    while ((task = srv_chains_next_deferred(b->chains, 0)))
        srv_mesh_chain_task_free((srv_mesh_chain_task *)task);
    return 0;
}
