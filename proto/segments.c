/* segments.c: many segments' surfaces as one glb (segments.h), in steps:
 *   1. extract: every segment asked, the segments shared among the threads
 *      (iso_seg_extract_all);
 *   2. refuse: more triangles in all than the caller's limit stops here;
 *   3. normals: each mesh's from its segment's field, the meshes shared among the threads;
 *   4. encode: each mesh as its own glb (Draco or meshopt), shared the same way, then joined
 *      into one scene (glb_scene.c): a node per segment, named, its colour as material.
 * Each step is timed (wall). */
#include "segments.h"

#include <stdatomic.h>
#include <stdlib.h>
#include <string.h>

#include "draco_shim.h"

typedef struct step_job {
    const proto_segments_request *req;
    const size_t *which;
    iso_mesh *meshes;
    unsigned char **glb;
    size_t *glb_size;
    int encode;                 /* 0: normals, 1: encode */
    atomic_size_t next;
    atomic_int rc;
    iso_error err[ISO_PARALLEL_MAX_THREADS];
} step_job;

/* Steps 3 and 4 for mesh k, on one thread. */
static int one_mesh(step_job *job, size_t k, iso_error *err)
{
    const proto_segments_request *req = job->req;
    iso_mesh *m = &job->meshes[k];
    if (!job->encode) {
        if (!req->normals || !m->vertex_count)
            return 0;
        iso_seg_params sp = req->params;
        sp.threads = 1;
        return iso_seg_normals(req->segmentation, job->which[k], &sp, m, req->normals, err);
    }
    proto_encode_options opt = req->encode;
    opt.threads = 1;
    if (req->format == PROTO_FORMAT_GLB_MESHOPT)
        return proto_encode_glb_meshopt(m, &opt, &job->glb[k], &job->glb_size[k], err);
    return proto_glb_encode_info(m, &opt, &job->glb[k], &job->glb_size[k], NULL, err);
}

static void step_share(void *context, int t, int threads)
{
    (void)threads;
    step_job *job = context;
    for (;;) {
        size_t k = atomic_fetch_add(&job->next, 1);
        if (k >= job->req->count || atomic_load(&job->rc))
            return;
        int rc = one_mesh(job, k, &job->err[t]);
        if (rc) {
            int none = 0;
            atomic_compare_exchange_strong(&job->rc, &none, rc);
            return;
        }
    }
}

/* Runs one of steps 3 and 4 over every mesh; 0 or the first failure (into err). */
static int run_step(step_job *job, int encode, iso_error *err)
{
    job->encode = encode;
    atomic_store(&job->next, 0);
    int threads = iso_parallel_threads(job->req->params.threads);
    if ((size_t)threads > job->req->count)
        threads = job->req->count ? (int)job->req->count : 1;
    iso_parallel_run(threads, step_share, job);
    int rc = atomic_load(&job->rc);
    for (int t = 0; rc && t < threads; t++)
        if (job->err[t].code == rc) {
            if (err)
                *err = job->err[t];
            break;
        }
    return rc;
}

int proto_segments_run(const proto_segments_request *req, proto_segments_result *res, iso_error *err)
{
    memset(res, 0, sizeof *res);
    size_t n = req->count;
    step_job *job = calloc(1, sizeof *job);
    iso_mesh *meshes = calloc(n ? n : 1, sizeof *meshes);
    iso_extract_stats *stats = calloc(n ? n : 1, sizeof *stats);
    unsigned char **glb = calloc(n ? n : 1, sizeof *glb);
    size_t *glb_size = calloc(n ? n : 1, sizeof *glb_size);
    proto_scene_part *parts = calloc(n ? n : 1, sizeof *parts);
    int rc = 0;
    if (!job || !meshes || !stats || !glb || !glb_size || !parts)
        rc = iso_error_set(err, ISO_E_NOMEM, "out of memory for %zu segments", n);
    double t0 = iso_clock_ms();
    if (!rc)
        rc = iso_seg_extract_all(req->segmentation, req->which, n, &req->params, meshes, stats, err);
    double t1 = iso_clock_ms();
    res->extract_ms = t1 - t0;
    for (size_t k = 0; !rc && k < n; k++) {
        res->triangles += meshes[k].triangle_count;
        res->vertices += meshes[k].vertex_count;
        res->cells_visited += stats[k].cells_visited;
    }
    if (!rc && req->max_triangles && res->triangles > req->max_triangles)
        rc = iso_error_set(err, ISO_E_LIMIT, "the segments' meshes have %zu triangles, more than this server's "
                           "limit of %zu", res->triangles, req->max_triangles);
    if (!rc) {
        job->req = req;
        job->which = req->which;
        job->meshes = meshes;
        job->glb = glb;
        job->glb_size = glb_size;
        rc = run_step(job, 0, err);
    }
    double t2 = iso_clock_ms();
    res->normals_ms = t2 - t1;
    if (!rc)
        rc = run_step(job, 1, err);
    for (size_t k = 0; !rc && k < n; k++) {
        const iso_segment *s = &req->segmentation->segments[req->which[k]];
        parts[k] = (proto_scene_part){.glb = glb[k], .size = glb_size[k], .name = s->name, .number = s->number};
        memcpy(parts[k].color, s->color, sizeof parts[k].color);
    }
    if (!rc)
        rc = proto_glb_scene(parts, n, &res->bytes, &res->size, err);
    res->encode_ms = iso_clock_ms() - t2;
    for (size_t k = 0; k < n && meshes && glb; k++) {
        iso_mesh_free(&meshes[k]);
        free(glb[k]);
    }
    free(job);
    free(meshes);
    free(stats);
    free(glb);
    free(glb_size);
    free(parts);
    if (rc) {
        free(res->bytes);
        res->bytes = NULL;
        res->size = 0;
    }
    return rc;
}
