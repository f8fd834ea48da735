/* mesh_job.h: one mesh request's work on a pool thread: the request pipeline
 * (pipeline.h: extract, simplify, normals, measures, encode; or segments.h for every
 * segment of a segmentation as one scene), then the body and its facts into the cache,
 * without any HTTP. */
#ifndef SRV_MESH_JOB_H
#define SRV_MESH_JOB_H

#include "cache.h"
#include "chains.h"
#include "collection.h"
#include "query.h"

typedef struct srv_mesh_job {
    const srv_volume *volume;
    srv_collection *collection; /* holds a reference to volume, given back when freed */
    proto_mesh_request request;
    srv_cache *cache;       /* where the body goes when done; may be NULL */
    srv_chains *chains;     /* the chains distance= and budget= are cut from; NULL: built
                             * for the request and dropped */
    char *key;              /* the cache key (owned) */
    size_t max_triangles;   /* serve --max-triangles: a larger mesh is refused (422); 0: none */
    int accept_gzip;        /* the request accepts gzip: a meshopt body's gzip form is made
                             * with it, beside its encode, instead of after it */
    long segment;           /* the level's mesh (SRV_JOB_LEVEL), a segment's (its index in the
                             * volume's segmentation) or every segment's (SRV_JOB_SEGMENTS) */
} srv_mesh_job;

#define SRV_JOB_LEVEL (-2)
#define SRV_JOB_SEGMENTS (-1)

/* A job for the pool (see pool.h's srv_job_fn): arg is a srv_mesh_job. */
srv_body *srv_mesh_job_run(void *arg, proto_problem *problem);
/* The gzip form of a body whose format gains from it (gzip_wanted), made on the first
 * call, by one caller at a time: 0 none (not wanted, or not worth it), 1 there, 2 made by
 * this call (the body has grown: srv_cache_grew). */
int srv_mesh_body_gzip(srv_body *body);
/* The chain of v's surface at level (tolerance 0, no cap: what the viewer's Detail asks
 * first) built into the registry and its file (a partial one a request made there is
 * completed), unless it is there (or in its file) already or being built: 0 built, 1 there, 2 being built by another caller, else the error
 * (ISO_E_*). threads: for the build; 1 keeps it on the calling thread, whose (lowest)
 * priority it then has, and lets a request that waits for it raise that thread
 * (srv_chains_building_idle). ms: the build's time. */
int srv_mesh_chain_ensure(const srv_volume *v, srv_collection *collection, srv_chains *chains, double level,
                          int threads, double *ms, iso_error *err);
/* A partial chain's completion that a request deferred to the background completer
 * (chains.h: srv_chains_next_deferred). */
typedef struct srv_mesh_chain_task srv_mesh_chain_task;
/* Completes the task's chain if it is still partial and in the registry (waiting for an
 * extension in progress), on the calling thread alone, at its priority: 0 completed (and
 * written when there is a cache dir), 1 nothing left to do, else the error. ms: its time. */
int srv_mesh_chain_task_run(srv_mesh_chain_task *task, srv_chains *chains, double *ms, iso_error *err);
/* "<id> level <L>" or "<id> segment <n>": what the task completes, for messages. */
void srv_mesh_chain_task_name(const srv_mesh_chain_task *task, char *out, size_t size);
/* Frees a task, releasing its volume; NULL is a no-op. */
void srv_mesh_chain_task_free(srv_mesh_chain_task *task);
/* Frees a srv_mesh_job made with malloc, releasing its volume. */
void srv_mesh_job_free(void *arg);

#endif
