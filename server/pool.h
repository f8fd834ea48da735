/* pool.h: the extraction pool: a fixed set of worker threads, a bounded queue, and
 * coalescing of identical requests.
 *
 * Extraction is CPU-bound, so the pool has about one thread per core and a bounded queue
 * in front: when the queue is full a new request is refused (the server answers 503 with
 * Retry-After) rather than piling up latency. A request whose key matches a job already
 * queued or running joins that job instead of adding one: N identical requests cost one
 * extraction. */
#ifndef SRV_POOL_H
#define SRV_POOL_H

#include <pthread.h>
#include <stdatomic.h>
#include <stddef.h>

#include "cache.h"
#include "query.h"

/* A job's work: returns a body (one reference, handed to the job) or NULL with problem
 * filled. Runs on a worker thread. */
typedef srv_body *(*srv_job_fn)(void *arg, proto_problem *problem);

typedef struct srv_job srv_job;

typedef struct srv_pool {
    pthread_mutex_t lock;
    pthread_cond_t work, done;
    pthread_t *threads;
    size_t thread_count, queue_capacity;
    srv_job *queue_head, *queue_tail;  /* waiting jobs, FIFO */
    srv_job *live;                     /* every queued or running job, for coalescing */
    size_t queued, running;
    int stopping;
    _Atomic unsigned long long submitted, coalesced, rejected, completed;
} srv_pool;

/* Starts the worker threads. 0, or ISO_E_NOMEM when memory or the system's thread limit ran out. */
int srv_pool_init(srv_pool *pool, size_t threads, size_t queue_capacity);
/* Lets queued jobs finish, then stops and joins the workers. */
void srv_pool_destroy(srv_pool *pool);

/* Submits work under key, or joins the live job with the same key (then *coalesced = 1 and
 * arg is freed with free_arg at once). Returns the job (the caller holds a reference), or
 * NULL when the queue is full (arg freed). */
srv_job *srv_pool_submit(srv_pool *pool, const char *key, srv_job_fn fn, void *arg,
                         void (*free_arg)(void *), int *coalesced);
/* Blocks until the job is done; returns its body retained for the caller (release it), or
 * NULL with *problem filled. */
srv_body *srv_pool_wait(srv_pool *pool, srv_job *job, proto_problem *problem);
/* Drops the caller's reference to the job. */
void srv_pool_release(srv_pool *pool, srv_job *job);

/* Jobs waiting and running now. */
void srv_pool_load(srv_pool *pool, size_t *queued, size_t *running);

#endif
