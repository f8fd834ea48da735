/* mesh_job.c: a mesh request on a pool thread: the pipeline (pipeline.h), then the body
 * and its facts into the cache (see mesh_job.h). */
#include "mesh_job.h"

#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "base/base.h"
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
    req->chain_partial = 1; /* the rest of the chain is made in the background (chains.h) */
    req->distance = r->distance;
    req->min_component = r->min_component;
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

/* What a chain is of: the level's surface, or a segment's (its number and smoothing). */
static void chain_params(const srv_mesh_job *job, char *params, size_t size)
{
    const proto_mesh_request *r = &job->request;
    if (job->segment >= 0)
        snprintf(params, size, "segment=%u&smoothing=%.17g&cap=%d", job->volume->seg->segments[job->segment].number,
                 r->smoothing, r->cap);
    else
        srv_chain_level_params(params, size, r->level, r->tolerance, r->cap);
    size_t used = strlen(params); /* a chain of a surface with components removed is another */
    if (r->min_component > 0 && used < size)
        snprintf(params + used, size - used, "&min_component=%.17g", r->min_component);
}

/* The chain a request uses: its registry entry (held until chain_done), how it was found
 * and what that cost. */
typedef struct chain_use {
    srv_chain_spec spec;
    srv_chain *entry;
    srv_chain_source source;
    int k;                 /* the level checked for the cut */
    double load_ms;        /* mapping and checking the levels it cuts */
    double extend_ms;      /* extending a partial chain (SRV_CHAIN_EXTENDED) */
} chain_use;

/* A chain's extension (chains.h): TO_EXTEND entry *entry's chain copied, extended for
 * `distance` or `triangles` (neither: completed) on req's threads, then in the registry in
 * its place (written and mapped when complete); *entry becomes the new entry, with a
 * reference. On failure *entry is given back and NULL. ms: the time it took. */
static int extend_entry(const srv_volume *v, srv_chains *chains, const srv_chain_spec *spec,
                        const proto_pipeline_request *req, double distance, size_t triangles, srv_chain **entry,
                        double *ms, iso_error *err)
{
    double start = iso_clock_ms();
    iso_mesh_chain *copy = NULL;
    int rc = iso_mesh_chain_copy(srv_chain_owned(*entry), &copy, err);
    if (!rc && (rc = proto_pipeline_chain_extend(v->vol, req, copy, distance, triangles, err)))
        iso_mesh_chain_destroy(copy);
    srv_chain *now = NULL;
    if (!rc) {
        atomic_fetch_add(&chains->extended, 1);
        if (!(now = srv_chains_replace(chains, *entry, spec, copy)))
            rc = iso_error_set(err, ISO_E_NOMEM, "%s: the extended chain could not be kept", spec->id);
    } else {
        srv_chains_extend_abandon(chains, *entry);
    }
    srv_chains_release(chains, *entry);
    *entry = now;
    *ms = iso_clock_ms() - start;
    return rc;
}

/* A partial chain's completion, deferred to the background completer: the volume (held by
 * a reference) and the request whose surface the chain is of. */
struct srv_mesh_chain_task {
    srv_chain_deferred link; /* first: the registry queues it by this */
    srv_collection *collection;
    const srv_volume *volume;
    proto_pipeline_request req;
    srv_chain_spec spec;
};

/* After this request made or extended a partial chain: its completion goes to the
 * background completer when there is one (else later requests extend it as they need). */
static void defer_completion(const srv_mesh_job *job, const proto_pipeline_request *req, const chain_use *use)
{
    if (!use->entry || !srv_chain_partial(use->entry) || !job->collection)
        return;
    srv_mesh_chain_task *task = malloc(sizeof *task);
    if (!task)
        return; /* left partial: extended by the requests that need more */
    *task = (srv_mesh_chain_task){.collection = job->collection, .volume = job->volume, .req = *req,
                                  .spec = use->spec};
    task->req.chain = NULL;
    srv_collection_retain(job->collection, job->volume);
    if (!srv_chains_defer(job->chains, &task->link))
        srv_mesh_chain_task_free(task);
}

void srv_mesh_chain_task_name(const srv_mesh_chain_task *task, char *out, size_t size)
{
    if (task->req.segmentation)
        snprintf(out, size, "%s segment %u", task->spec.id, task->req.segmentation->segments[task->req.segment].number);
    else
        snprintf(out, size, "%s level %g", task->spec.id, task->req.extract.level);
}

void srv_mesh_chain_task_free(srv_mesh_chain_task *task)
{
    if (!task)
        return;
    srv_collection_release(task->collection, task->volume);
    free(task);
}

int srv_mesh_chain_task_run(srv_mesh_chain_task *task, srv_chains *chains, double *ms, iso_error *err)
{
    srv_chain *entry;
    srv_chain_source source;
    double load_ms;
    *ms = 0;
    /* Waits for a request's extension in progress, then completes what is left. */
    srv_chain_acquired got = srv_chains_acquire(chains, &task->spec, -1, 0, 1, &entry, &source, &load_ms);
    if (got == SRV_CHAIN_TO_BUILD)
        srv_chains_abandon(chains, entry); /* evicted meanwhile: the next request builds it */
    if (got != SRV_CHAIN_TO_EXTEND) {
        srv_chains_release(chains, entry);
        return 1;
    }
    srv_chains_building_idle(chains, entry);
    task->req.extract.threads = 1; /* on this thread alone, at its (lowest) priority */
    int rc = extend_entry(task->volume, chains, &task->spec, &task->req, -1, 0, &entry, ms, err);
    srv_chains_release(chains, entry);
    return rc;
}

/* The levels a request cuts are checked before the pipeline reads them: the one it picks,
 * and for a budget level 0 with its grid (a budget measures against it). 0, or the check's
 * error. */
static int prepare_levels(const srv_mesh_job *job, const iso_mesh_chain *chain, chain_use *use, iso_error *err)
{
    const proto_mesh_request *r = &job->request;
    use->k = r->budget ? iso_mesh_chain_pick_budget(chain, r->budget) : iso_mesh_chain_pick_distance(chain, r->distance);
    double ms = 0, ms0 = 0;
    int rc = srv_chain_prepare(use->entry, use->k, &ms, err);
    if (!rc && r->budget)
        rc = srv_chain_prepare_grid(job->chains, use->entry, &ms0, err);
    use->load_ms += ms + ms0;
    return rc;
}

/* The registry's chain for the request, its levels checked; NULL when this request builds
 * it (use->source SRV_CHAIN_BUILT, use->entry the entry to publish to) or when no entry
 * can be had (built here, not kept). A partial chain that falls short of the request is
 * extended first (use->source SRV_CHAIN_EXTENDED). A chain found corrupt is discarded and
 * built. */
static const iso_mesh_chain *chain_for(const srv_mesh_job *job, const proto_pipeline_request *req, chain_use *use)
{
    char params[160];
    chain_params(job, params, sizeof params);
    const char *dir = job->collection ? job->collection->options.cache_dir : NULL;
    if (srv_chain_spec_init(&use->spec, dir, job->volume->entry->id, job->volume->version, params))
        return NULL;
    for (int attempt = 0; attempt < 2; attempt++) {
        double load_ms;
        double distance = req->budget ? -1 : req->distance;
        srv_chain_acquired got = srv_chains_acquire(job->chains, &use->spec, distance, req->budget, 1, &use->entry,
                                                    &use->source, &load_ms);
        use->load_ms += load_ms;
        iso_error err = {0};
        if (got == SRV_CHAIN_TO_EXTEND) {
            use->source = SRV_CHAIN_EXTENDED;
            if (extend_entry(job->volume, job->chains, &use->spec, req, distance, req->budget, &use->entry,
                             &use->extend_ms, &err))
                fprintf(stderr, "isoserve: %s: chain not extended: %s\n", use->spec.id, err.message);
            if (!use->entry)
                return NULL; /* the request builds its own, not kept */
            /* Its completion is queued already, since the build that made it partial. */
        } else if (got != SRV_CHAIN_READY_NOW) {
            return NULL;
        }
        const iso_mesh_chain *chain = srv_chain_get(use->entry);
        if (!prepare_levels(job, chain, use, &err))
            return chain;
        srv_chains_discard(job->chains, use->entry, &use->spec, err.message);
        use->entry = NULL;
    }
    return NULL;
}

/* After the pipeline: a chain this request built goes to the registry (and its file);
 * the entry is given back. */
static void chain_done(const srv_mesh_job *job, const proto_pipeline_request *req, chain_use *use,
                       proto_pipeline_result *res, int rc)
{
    if (!use->entry)
        return;
    if (use->source == SRV_CHAIN_BUILT) {
        if (!rc && res->chain_built) {
            if (!iso_mesh_chain_complete(res->chain_built)) /* levels or maxima left */
                use->source = SRV_CHAIN_PARTIAL;
            srv_chains_publish(job->chains, use->entry, &use->spec, res->chain_built);
            res->chain_built = NULL;
            defer_completion(job, req, use);
        } else {
            srv_chains_abandon(job->chains, use->entry);
        }
    }
    srv_chains_release(job->chains, use->entry);
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
    chain_use use = {.k = -1};
    if (job->chains && (req.distance >= 0 || req.budget))
        req.chain = chain_for(job, &req, &use);
    int rc = proto_pipeline_run(job->volume->tree, job->volume->vol, &req, &res, &err);
    chain_done(job, &req, &use, &res, rc);
    if (rc)
        return failed(job, rc, &err, problem);
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
    if (use.entry || use.source == SRV_CHAIN_BUILT || use.source == SRV_CHAIN_PARTIAL) {
        int built = use.source == SRV_CHAIN_BUILT || use.source == SRV_CHAIN_PARTIAL;
        body->chain_source = srv_chain_source_name(use.source);
        body->chain_load_ms = use.load_ms;
        body->chain_cut_ms = built ? 0 : res.simplify_ms;
        body->chain_build_ms = built ? res.simplify_ms : use.extend_ms;
    }
    body->exact_triangles = res.exact_triangles;
    body->edges = res.pinches.edges;
    body->pinch_edges = res.pinches.pinch_edges;
    body->pinch_vertices = res.pinches.pinch_vertices;
    body->vertex_offset_mm = res.vertex_offset;
    body->min_component_asked = req.min_component > 0;
    body->components_removed = res.components.removed;
    body->removed_largest_mm = res.components.removed_largest;
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

int srv_mesh_chain_ensure(const srv_volume *v, srv_collection *collection, srv_chains *chains, double level,
                          int threads, double *ms, iso_error *err)
{
    char params[160];
    srv_chain_spec spec;
    srv_chain_level_params(params, sizeof params, level, 0, 0);
    if (srv_chain_spec_init(&spec, collection->options.cache_dir, v->entry->id, v->version, params))
        return iso_error_set(err, ISO_E_ARGUMENT, "%s: the chain's name is too long", v->entry->id);
    srv_chain *entry;
    srv_chain_source source;
    double load_ms;
    *ms = 0;
    srv_chain_acquired got = srv_chains_acquire(chains, &spec, -1, 0, 0, &entry, &source, &load_ms);
    if (got != SRV_CHAIN_TO_BUILD && got != SRV_CHAIN_TO_EXTEND) {
        srv_chains_release(chains, entry);
        return got == SRV_CHAIN_READY_NOW ? 1 : 2;
    }
    if (threads == 1)
        srv_chains_building_idle(chains, entry);
    proto_pipeline_request req;
    proto_pipeline_result res;
    proto_pipeline_request_init(&req);
    req.extract.level = level;
    req.extract.threads = threads;
    if (got == SRV_CHAIN_TO_EXTEND) { /* a request's partial chain: completed here */
        int rc = extend_entry(v, chains, &spec, &req, -1, 0, &entry, ms, err);
        srv_chains_release(chains, entry);
        return rc;
    }
    req.distance = 0; /* level 0 answers: the chain is what is wanted */
    req.normals = 0;
    req.format = PROTO_FORMAT_NONE;
    double start = iso_clock_ms();
    int rc = proto_pipeline_run(v->tree, v->vol, &req, &res, err);
    *ms = iso_clock_ms() - start;
    if (!rc && res.chain_built) {
        srv_chains_publish(chains, entry, &spec, res.chain_built);
        res.chain_built = NULL;
    } else {
        srv_chains_abandon(chains, entry);
    }
    srv_chains_release(chains, entry);
    if (!rc)
        proto_pipeline_result_free(&res);
    return rc;
}
