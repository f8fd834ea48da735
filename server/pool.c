/* pool.c: worker threads, a bounded queue and request coalescing (see pool.h). */
#include "pool.h"

#include <stdlib.h>
#include <string.h>

#include "base/base.h"

struct srv_job {
    char *key;
    srv_job_fn fn;
    void *arg;
    void (*free_arg)(void *);
    srv_body *body;            /* the result, once done */
    proto_problem problem;     /* the failure, once done without a body */
    int done, refs;            /* refs: waiters plus the pool while live */
    srv_job *next_queued, *next_live;
};

/* Frees a job nobody refers to any more. Lock held or job unreachable. */
static void job_free(srv_job *job)
{
    srv_body_release(job->body);
    if (job->free_arg)
        job->free_arg(job->arg);
    free(job->key);
    free(job);
}

static void unlink_live(srv_pool *pool, srv_job *job)
{
    srv_job **slot = &pool->live;
    while (*slot != job)
        slot = &(*slot)->next_live;
    *slot = job->next_live;
}

static void *worker(void *context)
{
    srv_pool *pool = context;
    pthread_mutex_lock(&pool->lock);
    for (;;) {
        while (!pool->queue_head && !pool->stopping)
            pthread_cond_wait(&pool->work, &pool->lock);
        srv_job *job = pool->queue_head;
        if (!job)
            break; /* stopping with an empty queue */
        pool->queue_head = job->next_queued;
        if (!pool->queue_head)
            pool->queue_tail = NULL;
        pool->queued--;
        pool->running++;
        pthread_mutex_unlock(&pool->lock);

        proto_problem problem = {0};
        srv_body *body = job->fn(job->arg, &problem);

        pthread_mutex_lock(&pool->lock);
        pool->running--;
        job->body = body;
        job->problem = problem;
        job->done = 1;
        unlink_live(pool, job);
        atomic_fetch_add(&pool->completed, 1);
        pthread_cond_broadcast(&pool->done);
        if (--job->refs == 0)
            job_free(job);
    }
    pthread_mutex_unlock(&pool->lock);
    return NULL;
}

int srv_pool_init(srv_pool *pool, size_t threads, size_t queue_capacity)
{
    memset(pool, 0, sizeof *pool);
    pool->queue_capacity = queue_capacity;
    pool->threads = calloc(threads, sizeof *pool->threads);
    if (!pool->threads)
        return ISO_E_NOMEM;
    pthread_mutex_init(&pool->lock, NULL);
    pthread_cond_init(&pool->work, NULL);
    pthread_cond_init(&pool->done, NULL);
    for (size_t i = 0; i < threads; i++) {
        if (pthread_create(&pool->threads[i], NULL, worker, pool)) {
            srv_pool_destroy(pool); /* EAGAIN: the system's thread or memory limit */
            return ISO_E_NOMEM;
        }
        pool->thread_count++;
    }
    return 0;
}

void srv_pool_destroy(srv_pool *pool)
{
    if (!pool->threads)
        return;
    pthread_mutex_lock(&pool->lock);
    pool->stopping = 1;
    pthread_cond_broadcast(&pool->work);
    pthread_mutex_unlock(&pool->lock);
    for (size_t i = 0; i < pool->thread_count; i++)
        pthread_join(pool->threads[i], NULL);
    free(pool->threads);
    pthread_cond_destroy(&pool->work);
    pthread_cond_destroy(&pool->done);
    pthread_mutex_destroy(&pool->lock);
    memset(pool, 0, sizeof *pool);
}

srv_job *srv_pool_submit(srv_pool *pool, const char *key, srv_job_fn fn, void *arg,
                         void (*free_arg)(void *), int *coalesced)
{
    *coalesced = 0;
    pthread_mutex_lock(&pool->lock);
    for (srv_job *live = pool->live; live; live = live->next_live)
        if (!strcmp(live->key, key)) {
            live->refs++;
            pthread_mutex_unlock(&pool->lock);
            atomic_fetch_add(&pool->coalesced, 1);
            *coalesced = 1;
            if (free_arg)
                free_arg(arg);
            return live;
        }
    srv_job *job = NULL;
    if (pool->queued < pool->queue_capacity && !pool->stopping)
        job = calloc(1, sizeof *job);
    if (job && !(job->key = strdup(key))) {
        free(job);
        job = NULL;
    }
    if (!job) {
        pthread_mutex_unlock(&pool->lock);
        atomic_fetch_add(&pool->rejected, 1);
        if (free_arg)
            free_arg(arg);
        return NULL;
    }
    job->fn = fn;
    job->arg = arg;
    job->free_arg = free_arg;
    job->refs = 2; /* the caller and the pool */
    job->next_live = pool->live;
    pool->live = job;
    if (pool->queue_tail)
        pool->queue_tail->next_queued = job;
    else
        pool->queue_head = job;
    pool->queue_tail = job;
    pool->queued++;
    atomic_fetch_add(&pool->submitted, 1);
    pthread_cond_signal(&pool->work);
    pthread_mutex_unlock(&pool->lock);
    return job;
}

srv_body *srv_pool_wait(srv_pool *pool, srv_job *job, proto_problem *problem)
{
    pthread_mutex_lock(&pool->lock);
    while (!job->done)
        pthread_cond_wait(&pool->done, &pool->lock);
    srv_body *body = job->body;
    if (body)
        srv_body_retain(body);
    else
        *problem = job->problem;
    pthread_mutex_unlock(&pool->lock);
    return body;
}

void srv_pool_release(srv_pool *pool, srv_job *job)
{
    pthread_mutex_lock(&pool->lock);
    if (--job->refs == 0)
        job_free(job);
    pthread_mutex_unlock(&pool->lock);
}

void srv_pool_load(srv_pool *pool, size_t *queued, size_t *running)
{
    pthread_mutex_lock(&pool->lock);
    *queued = pool->queued;
    *running = pool->running;
    pthread_mutex_unlock(&pool->lock);
}
