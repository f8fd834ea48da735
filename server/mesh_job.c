/* mesh_job.c: a mesh request on a pool thread: the pipeline (pipeline.h), then the body
 * and its facts into the cache (see mesh_job.h). */
#include "mesh_job.h"

#include <stdio.h>
#include <stdlib.h>
#include <unistd.h>

#include "base/base.h"
#include "hash.h"
#include "pipeline.h"
#include "segments.h"
#include "status.h"

void srv_mesh_job_free(void *arg)
{
    srv_mesh_job *job = arg;
    if (!job)
        return;
    if (job->collection)
        srv_collection_release(job->collection, job->volume);
    free(job->key);
    free(job);
}

/* The pipeline's request for this job: the API's parameters (the measures only when asked),
 * the server's triangle limit. */
static void pipeline_request(const srv_mesh_job *job, proto_pipeline_request *req)
{
    const proto_mesh_request *r = &job->request;
    proto_pipeline_request_init(req);
    req->extract.level = r->level;
    req->extract.tolerance = r->tolerance;
    req->extract.cap = r->cap;
    req->budget = r->budget;
    req->budget_chain = 1;
    req->distance = r->distance;
    req->max_triangles = job->max_triangles;
    req->normals = r->normals;
    req->measure = r->measures;
    req->format = r->format;
    req->encode.position_bits = r->position_bits;
    req->encode.normal_bits = r->normal_bits;
    req->encode.speed = r->speed;
    req->gzip = job->accept_gzip && r->format == PROTO_FORMAT_GLB_MESHOPT;
    if (job->segment >= 0) {
        req->segmentation = job->volume->seg;
        req->segment = (size_t)job->segment;
        req->smoothing = r->smoothing;
    }
}

/* What a chain is of: the level's surface, or a segment's (its number and smoothing). */
static void chain_params(const srv_mesh_job *job, char *params, size_t size)
{
    const proto_mesh_request *r = &job->request;
    if (job->segment >= 0)
        snprintf(params, size, "segment=%u&smoothing=%.17g&cap=%d", job->volume->seg->segments[job->segment].number,
                 r->smoothing, r->cap);
    else
        snprintf(params, size, "level=%.17g&tolerance=%.17g&cap=%d", r->level, r->tolerance, r->cap);
}

/* The problem body of a failed step, its status from status.h. An allocation that failed
 * is this request's trouble, not the server's: its memory is freed by now and the other
 * requests go on, so it answers 503 (with Retry-After) naming the volume and the step that
 * ran out. A mesh over --max-triangles answers 422 and is not cached, so a later, larger
 * limit answers. */
static srv_body *failed(const srv_mesh_job *job, int rc, const iso_error *err,
                        proto_problem *problem)
{
    const char *id = job->volume->entry->id, *why = err->message[0] ? err->message : iso_status_name(rc);
    int status = srv_status_http(rc);
    if (status == 503)
        proto_problem_set(problem, status, NULL, "%s: %s; a larger tolerance gives a smaller mesh",
                          id, why);
    else if (rc == ISO_E_LIMIT)
        proto_problem_set(problem, status, NULL, "%s", why);
    else
        proto_problem_set(problem, status, NULL, "%s: %s", id, why);
    return NULL;
}

/* A meshopt glb's bytes are not entropy coded, so gzip takes about a third off them
 * (Draco's are: gzip gains nothing there). Only those vary by Accept-Encoding. */
static int gzip_wanted(const srv_body *body, proto_format format)
{
    return format == PROTO_FORMAT_GLB_MESHOPT && body->size >= 1024;
}

/* Kept when it saves at least a twentieth of the body. */
static int gzip_pays(size_t gzip_size, size_t size)
{
    return gzip_size <= size - size / 20;
}

/* The gzip form the pipeline made with the body (the request accepted gzip), taken over
 * when it pays, so that the first response needs no second pass. */
static void take_gzip(srv_body *body, proto_pipeline_result *res)
{
    if (!body->gzip_wanted || !res->gzip)
        return;
    body->gzip_tried = 1;
    if (gzip_pays(res->gzip_size, body->size)) {
        body->gzip_data = res->gzip;
        body->gzip_size = res->gzip_size;
        body->gzip_ms = res->gzip_ms;
        res->gzip = NULL;
    }
}

int srv_mesh_body_gzip(srv_body *body)
{
    if (!body->gzip_wanted)
        return 0;
    pthread_mutex_lock(&body->gzip_lock);
    int made_now = 0;
    if (!body->gzip_tried) {
        body->gzip_tried = 1;
        double start = iso_clock_ms();
        unsigned char *gz;
        size_t size;
        /* Failing to make it only leaves it out. */
        proto_gzip_piece pieces[PROTO_GZIP_PIECES_MAX];
        int count = proto_glb_meshopt_gzip_pieces(body->data, body->size, pieces);
        if (!proto_gzip_pieces(body->data, body->size, pieces, count, 0, &gz, &size, NULL)) {
            if (!gzip_pays(size, body->size)) {
                free(gz);
            } else {
                body->gzip_data = gz;
                body->gzip_size = size;
                body->gzip_ms = iso_clock_ms() - start;
                made_now = 1;
            }
        }
    }
    int made = body->gzip_data != NULL;
    pthread_mutex_unlock(&body->gzip_lock);
    return made ? 1 + made_now : 0;
}

/* The cache key of the simplification chain a request would use: one per (volume,
 * level, tolerance, cap), whatever the distance, budget or format. */
static void chain_key(const srv_mesh_job *job, char *key, size_t size)
{
    char params[160];
    chain_params(job, params, sizeof params);
    snprintf(key, size, "chain:%s/%s?%s", job->volume->entry->id, job->volume->version, params);
}

/* The chain's file beside the volume's hierarchy file in the cache dir:
 * "<dir>/<id>.<16 hex digits>.isochain", the digits a hash of the level, tolerance and cap
 * (the catalog's ids are file-name safe, so the path stays in the dir). Its identity, which
 * the file must carry, hashes the whole chain key, the volume's version included: a file
 * left from an older version of the volume is refused and rebuilt. 0 without a cache dir. */
static int chain_file(const srv_mesh_job *job, const char *key, char *path, size_t size, uint64_t *identity)
{
    const char *dir = job->collection ? job->collection->options.cache_dir : NULL;
    if (!dir)
        return 0;
    char params[160];
    chain_params(job, params, sizeof params);
    int n = snprintf(path, size, "%s/%s.%016llx.isochain", dir, job->volume->entry->id,
                     (unsigned long long)srv_hash64(params));
    *identity = srv_hash64(key);
    return n > 0 && (size_t)n < size;
}

/* A chain into the cache, in a body of no bytes that owns it and weighs what it holds;
 * without memory for that, it is dropped (a cache is optional). Returns the holder with a
 * reference for the caller (NULL when dropped: the chain is then destroyed unless kept). */
static srv_body *cache_chain(const srv_mesh_job *job, const char *key, iso_mesh_chain *chain)
{
    srv_body *holder = srv_body_create(NULL, 0);
    if (!holder) {
        iso_mesh_chain_destroy(chain);
        return NULL;
    }
    holder->chain = chain;
    holder->size = chain->bytes;
    srv_cache_put(job->cache, key, holder);
    return holder;
}

/* A chain the run built goes to the cache, and to its file when there is a cache dir (a
 * failure to write only costs the next start a rebuild). */
static void keep_chain(const srv_mesh_job *job, const char *key, proto_pipeline_result *res)
{
    if (!job->cache || !res->chain_built)
        return;
    char path[4096];
    uint64_t identity;
    iso_error err = {0};
    if (chain_file(job, key, path, sizeof path, &identity) &&
        iso_mesh_chain_save(res->chain_built, path, identity, &err))
        fprintf(stderr, "isoserve: %s: chain not written: %s\n", job->volume->entry->id, err.message);
    srv_body_release(cache_chain(job, key, res->chain_built));
    res->chain_built = NULL;
}

/* The chain from its file, when the cache has none: into the cache, with a reference for
 * the caller; NULL when there is no valid file (a stale or corrupt one is reported and
 * left to be rebuilt and overwritten). */
static srv_body *chain_from_file(const srv_mesh_job *job, const char *key)
{
    char path[4096];
    uint64_t identity;
    if (!chain_file(job, key, path, sizeof path, &identity) || access(path, F_OK))
        return NULL;
    iso_mesh_chain *chain;
    iso_error err = {0};
    if (iso_mesh_chain_load(path, identity, &chain, &err)) {
        fprintf(stderr, "isoserve: %s: %s; rebuilding the chain\n", job->volume->entry->id, err.message);
        return NULL;
    }
    return cache_chain(job, key, chain);
}

/* Every segment as one glb scene (segments.h). */
static srv_body *segments_run(srv_mesh_job *job, proto_problem *problem)
{
    const iso_segmentation *seg = job->volume->seg;
    const proto_mesh_request *r = &job->request;
    size_t *which = malloc((seg->segment_count ? seg->segment_count : 1) * sizeof *which);
    iso_error err = {0};
    if (!which)
        return failed(job, iso_error_set(&err, ISO_E_NOMEM, "out of memory for the segments"), &err, problem);
    for (size_t s = 0; s < seg->segment_count; s++)
        which[s] = s;
    proto_segments_request req = {.segmentation = seg, .which = which, .count = seg->segment_count,
                                  .params = {.smoothing = r->smoothing, .cap = r->cap}, .normals = r->normals,
                                  .format = r->format, .max_triangles = job->max_triangles};
    proto_encode_options_init(&req.encode);
    req.encode.position_bits = r->position_bits;
    req.encode.normal_bits = r->normal_bits;
    req.encode.speed = r->speed;
    proto_segments_result res;
    int rc = proto_segments_run(&req, &res, &err);
    free(which);
    if (rc)
        return failed(job, rc, &err, problem);
    srv_body *body = srv_body_create(res.bytes, res.size);
    if (!body)
        return failed(job, iso_error_set(&err, ISO_E_NOMEM, "out of memory keeping the body"), &err, problem);
    body->content_type = proto_format_content_type(r->format);
    body->gzip_wanted = gzip_wanted(body, r->format);
    body->triangles = res.triangles;
    body->vertices = res.vertices;
    body->cells_visited = res.cells_visited;
    body->extract_ms = res.extract_ms;
    body->normals_ms = res.normals_ms;
    body->encode_ms = res.encode_ms;
    body->draco_speed = -1;
    body->budget_fits = -1;
    body->chain_level = -1;
    if (job->cache)
        srv_cache_put(job->cache, job->key, body);
    return body;
}

srv_body *srv_mesh_job_run(void *arg, proto_problem *problem)
{
    srv_mesh_job *job = arg;
    if (job->segment == SRV_JOB_SEGMENTS)
        return segments_run(job, problem);
    proto_pipeline_request req;
    proto_pipeline_result res;
    iso_error err = {0};
    pipeline_request(job, &req);
    char key[400] = "";
    srv_body *chain = NULL;
    if (job->cache && (req.distance >= 0 || req.budget)) {
        chain_key(job, key, sizeof key);
        if ((chain = srv_cache_get(job->cache, key)) || (chain = chain_from_file(job, key)))
            req.chain = chain->chain;
    }
    int rc = proto_pipeline_run(job->volume->tree, job->volume->vol, &req, &res, &err);
    srv_body_release(chain);
    if (rc)
        return failed(job, rc, &err, problem);
    keep_chain(job, key, &res);
    srv_body *body = srv_body_create(res.bytes, res.size); /* takes the bytes, even failing */
    res.bytes = NULL;
    if (!body) {
        proto_pipeline_result_free(&res);
        return failed(job, iso_error_set(&err, ISO_E_NOMEM, "out of memory keeping the body"),
                      &err, problem);
    }
    body->content_type = proto_format_content_type(req.format);
    body->gzip_wanted = gzip_wanted(body, req.format);
    take_gzip(body, &res);
    body->triangles = res.stats.triangles;
    body->vertices = res.stats.vertices;
    body->cells_visited = res.stats.cells_visited;
    body->extract_ms = res.extract_ms + res.simplify_ms;
    body->normals_ms = res.normals_ms;
    body->measure_ms = res.measure_ms;
    body->encode_ms = res.encode_ms;
    body->draco_speed = res.draco_speed;
    body->error_bound = res.stats.error_bound;
    body->tolerance = res.chosen.tolerance;
    body->budget_fits = req.budget ? res.chosen.fits : -1;
    body->simplified = res.chosen.simplified;
    body->simplify_error_mm = res.chosen.simplify.error;
    body->simplify_error_voxels = res.chosen.simplify.error_voxels;
    body->measured = res.measured;
    body->distance_measured = res.distance_measured;
    body->distance_mm = res.distance.p99;
    body->distance_max_mm = res.distance.max;
    body->distance_voxels = res.distance.p99 / iso_vol_min_spacing(job->volume->vol);
    body->chain_level = res.chain_level;
    body->exact_triangles = res.exact_triangles;
    body->edges = res.pinches.edges;
    body->pinch_edges = res.pinches.pinch_edges;
    body->pinch_vertices = res.pinches.pinch_vertices;
    body->vertex_offset_mm = res.vertex_offset;
    body->budget_source = res.budget_source;
    body->budget_other_mm = res.budget_other_p99;
    body->area_mm2 = res.area;
    body->closed = res.census.closed;
    body->volume_mm3 = res.enclosed_volume;
    proto_pipeline_result_free(&res);
    if (job->cache)
        srv_cache_put(job->cache, job->key, body);
    return body;
}
