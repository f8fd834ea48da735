/* mesh_job.c: extract, add normals, measure, encode, each step timed (see mesh_job.h). */
#include "mesh_job.h"

#include <math.h>
#include <pthread.h>
#include <stdlib.h>

#include "mesh/mesh.h"
#include "base/base.h"
#include "draco_shim.h"
#include "extract/extract.h"

void srv_mesh_job_free(void *arg)
{
    srv_mesh_job *job = arg;
    if (job)
        free(job->key);
    free(job);
}

/* Extraction, under the budget when one is asked: the ladder up to a faithful tolerance,
 * then meshoptimizer (mesh/mesh.h). */
static int extract(const srv_mesh_job *job, iso_mesh *mesh, iso_extract_stats *stats,
                   srv_body *facts, iso_error *err)
{
    const proto_mesh_request *r = &job->request;
    iso_extract_params params = {.level = r->level, .tolerance = r->tolerance, .cap = r->cap,
                                 .space = ISO_SPACE_WORLD};
    facts->tolerance = r->tolerance;
    if (!r->budget)
        return iso_extract(job->volume->tree, &params, mesh, stats, err);
    iso_budget_result chosen;
    int rc = iso_extract_budget_faithful(job->volume->tree, &params, r->budget, mesh, stats,
                                         &chosen, err);
    facts->tolerance = chosen.tolerance;
    facts->budget_fits = chosen.fits;
    facts->simplified = chosen.simplified;
    facts->simplify_error_mm = chosen.simplify.error;
    facts->simplify_error_voxels = chosen.simplify.error_voxels;
    return rc;
}

/* The measures of a mesh (edge census, area, enclosed volume): read-only on positions and
 * indices, so they run on their own thread beside normals and encoding, which write only
 * the normals and the output. */
typedef struct measure_job {
    const iso_volume *vol;
    const iso_mesh *mesh;
    iso_census census;
    double area, enclosed, ms;
    int rc;
    iso_error err;
} measure_job;

static void *measure(void *arg)
{
    measure_job *m = arg;
    double start = iso_clock_ms();
    m->rc = iso_census_compute(m->vol, m->mesh, ISO_SPACE_WORLD, &m->census, &m->err);
    if (!m->rc) {
        m->area = iso_mesh_area(m->mesh);
        m->enclosed = m->census.closed ? fabs(iso_mesh_enclosed_volume(m->mesh)) : 0;
    }
    m->ms = iso_clock_ms() - start;
    return NULL;
}

/* Encodes the mesh in the request's format; *speed is the Draco speed used (auto
 * resolved by the shim), -1 for PLY and STL. */
static int encode(const proto_mesh_request *r, const iso_mesh *mesh, unsigned char **out,
                  size_t *size, int *speed, iso_error *err)
{
    proto_encode_options opt;
    proto_encode_options_init(&opt);
    opt.position_bits = r->position_bits;
    opt.normal_bits = r->normal_bits;
    opt.speed = r->speed;
    proto_draco_info info = {.speed = -1};
    int rc;
    switch (r->format) {
    case PROTO_FORMAT_GLB: rc = proto_glb_encode_info(mesh, &opt, out, size, &info, err); break;
    case PROTO_FORMAT_PLY: rc = proto_encode_ply(mesh, out, size, err); break;
    case PROTO_FORMAT_STL: rc = proto_encode_stl(mesh, out, size, err); break;
    default: rc = proto_draco_encode_info(mesh, &opt, out, size, &info, err); break;
    }
    *speed = info.speed;
    return rc;
}

/* The problem body of a failed step. An allocation that failed is this request's
 * trouble, not the server's: its memory is freed by now and the other requests go on, so
 * it answers 503 (with Retry-After) naming the volume and the step that ran out. */
static srv_body *failed(const srv_mesh_job *job, int rc, const iso_error *err,
                        proto_problem *problem)
{
    const char *id = job->volume->entry->id, *why = err->message[0] ? err->message : iso_status_name(rc);
    if (rc == ISO_E_NOMEM)
        proto_problem_set(problem, 503, NULL, "%s: %s; a larger tolerance gives a smaller mesh",
                          id, why);
    else
        proto_problem_set(problem, 500, NULL, "%s: %s", id, why);
    return NULL;
}

srv_body *srv_mesh_job_run(void *arg, proto_problem *problem)
{
    srv_mesh_job *job = arg;
    const proto_mesh_request *r = &job->request;
    iso_mesh mesh;
    iso_mesh_init(&mesh);
    iso_extract_stats stats = {0};
    iso_error err = {0};
    srv_body facts = {.budget_fits = -1};
    unsigned char *data = NULL;
    size_t size = 0;

    double t0 = iso_clock_ms();
    int rc = extract(job, &mesh, &stats, &facts, &err);
    double t1 = iso_clock_ms();
    /* Refused before normals and encoding, which cost several times the extraction's
     * memory for a large mesh; the refusal is not cached, so a later, larger limit answers. */
    if (!rc && job->max_triangles && stats.triangles > job->max_triangles) {
        iso_mesh_free(&mesh);
        proto_problem_set(problem, 422, NULL,
                          "the mesh has %zu triangles, more than this server's limit of %zu; "
                          "a larger tolerance gives fewer", (size_t)stats.triangles,
                          job->max_triangles);
        return NULL;
    }
    /* Measures beside normals and encoding: on CThead skin they are a census of 760k
     * edges, 15 ms on one core, which a second core hides behind the encoding. If no
     * thread can start, they run here first. */
    measure_job m = {.vol = job->volume->vol, .mesh = &mesh};
    pthread_t measurer;
    int beside = !rc && pthread_create(&measurer, NULL, measure, &m) == 0;
    if (!rc && !beside)
        measure(&m);
    if (!rc && r->normals && mesh.vertex_count)
        rc = iso_normals_compute(job->volume->vol, &mesh, r->normals, ISO_SPACE_WORLD, 0, &err);
    double t2 = iso_clock_ms();
    int speed = -1;
    if (!rc)
        rc = encode(r, &mesh, &data, &size, &speed, &err);
    double t3 = iso_clock_ms();
    if (beside)
        pthread_join(measurer, NULL);
    if (!rc && m.rc) {
        rc = m.rc;
        err = m.err;
    }
    if (rc) {
        free(data);
        iso_mesh_free(&mesh);
        return failed(job, rc, &err, problem);
    }
    srv_body *body = srv_body_create(data, size);
    if (!body) {
        iso_mesh_free(&mesh);
        return failed(job, iso_error_set(&err, ISO_E_NOMEM, "out of memory keeping the body"),
                      &err, problem);
    }
    body->content_type = proto_format_content_type(r->format);
    body->triangles = stats.triangles;
    body->vertices = stats.vertices;
    body->cells_visited = stats.cells_visited;
    body->extract_ms = t1 - t0;
    body->normals_ms = t2 - t1;
    body->measure_ms = m.ms;
    body->encode_ms = t3 - t2;
    body->draco_speed = speed;
    body->error_bound = stats.error_bound;
    body->tolerance = facts.tolerance;
    body->budget_fits = facts.budget_fits;
    body->simplified = facts.simplified;
    body->simplify_error_mm = facts.simplify_error_mm;
    body->simplify_error_voxels = facts.simplify_error_voxels;
    body->area_mm2 = m.area;
    body->closed = m.census.closed;
    body->volume_mm3 = m.enclosed;
    iso_mesh_free(&mesh);
    if (job->cache)
        srv_cache_put(job->cache, job->key, body);
    return body;
}
