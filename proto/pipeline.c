/* pipeline.c: extract, simplify, refuse, normals beside measures, encode (pipeline.h). */
#include "pipeline.h"

#include <assert.h>
#include <math.h>
#include <pthread.h>
#include <stdlib.h>
#include <string.h>

#include "base/base.h"
#include "draco_shim.h"

void proto_pipeline_request_init(proto_pipeline_request *req)
{
    /* Every coarse unit the tolerance allows: a request's time is mostly normals and
     * encoding, which follow the triangles, so the fewest triangles answer first even where
     * the coarse kernel is slower than the exact one (docs/performance.md). */
    *req = (proto_pipeline_request){.extract = {.space = ISO_SPACE_WORLD, .coarsen = ISO_COARSEN_ALL},
                                    .normals = 4, .distance = -1, .format = PROTO_FORMAT_DRACO};
    proto_encode_options_init(&req->encode);
}

void proto_pipeline_result_free(proto_pipeline_result *res)
{
    if (!res)
        return;
    iso_mesh_free(&res->mesh);
    iso_mesh_chain_destroy(res->chain_built);
    res->chain_built = NULL;
    free(res->bytes);
    res->bytes = NULL;
    res->size = 0;
    free(res->gzip);
    res->gzip = NULL;
    res->gzip_size = 0;
}

static double voxel_size(const iso_volume *vol, const proto_pipeline_request *req)
{
    return req->extract.space == ISO_SPACE_INDEX ? 1 : iso_vol_min_spacing(vol);
}

/* min_component in the mesh's units cubed: mm3, or index space's (a voxel encloses |det|
 * of the index-to-world map's mm3). */
static double component_volume(const iso_volume *vol, const proto_pipeline_request *req)
{
    double a[3][3], inv[3][3], det = 1;
    if (req->extract.space == ISO_SPACE_INDEX && iso_vol_frame(vol, a, inv, &det) == 0)
        return req->min_component / fabs(det);
    return req->min_component;
}

/* The closed components under req->min_component removed from mesh (none unless asked),
 * counted into *out. */
static int remove_components(const iso_volume *vol, const proto_pipeline_request *req, iso_mesh *mesh,
                             iso_mesh_components *out, iso_error *err)
{
    if (!(req->min_component > 0))
        return 0;
    if (iso_mesh_remove_components(mesh, component_volume(vol, req), out))
        return iso_error_set(err, ISO_E_NOMEM, "no memory to find the surface's %zu triangles' components",
                             mesh->triangle_count);
    return 0;
}

/* The surface a request names: the level's (extract.h), or a segment's (segment.h). */
static int surface(const iso_tree *tree, const proto_pipeline_request *req, iso_mesh *mesh,
                   iso_extract_stats *stats, iso_error *err)
{
    if (!req->segmentation)
        return iso_extract(tree, &req->extract, mesh, stats, err);
    iso_seg_params sp = {.smoothing = req->smoothing, .cap = req->extract.cap, .space = req->extract.space,
                         .threads = req->extract.threads};
    return iso_seg_extract(req->segmentation, req->segment, &sp, mesh, stats, err);
}

/* The normals of a request's surface: the B-spline of the volume's samples, or of the
 * segment's field (segment.h). */
static int surface_normals(const iso_volume *vol, const proto_pipeline_request *req, iso_mesh *mesh, int threads,
                           iso_error *err)
{
    if (!req->segmentation)
        return iso_normals_compute(vol, mesh, req->normals, req->extract.space, threads, err);
    iso_seg_params sp = {.smoothing = req->smoothing, .cap = req->extract.cap, .space = req->extract.space,
                         .threads = threads};
    return iso_seg_normals(req->segmentation, req->segment, &sp, mesh, req->normals, err);
}

/* An extraction's work added to the request's: cells and nodes visited count every
 * extraction a request ran, not only the one whose mesh answers. */
static void add_work(iso_extract_stats *to, const iso_extract_stats *from)
{
    to->nodes_visited += from->nodes_visited;
    to->cells_visited += from->cells_visited;
}

/* The triangles of the mesh at the faithful tolerance (core/extract) into
 * res->faithful_triangles, extracted unless the request's chain knows them. */
static int faithful_triangles(const iso_tree *tree, const proto_pipeline_request *req,
                              proto_pipeline_result *res, iso_error *err)
{
    if (!res->faithful_triangles)
        res->faithful_triangles = req->chain ? req->chain->faithful_triangles : 0;
    if (res->faithful_triangles)
        return 0;
    iso_extract_params p = req->extract;
    p.tolerance = iso_budget_faithful_tolerance(tree->vol, p.tolerance);
    p.coarsen = ISO_COARSEN_ALL; /* the budget ladder's mesh (extract.h) */
    iso_mesh m;
    iso_extract_stats stats;
    iso_mesh_init(&m);
    int rc = iso_extract(tree, &p, &m, &stats, err);
    iso_mesh_free(&m);
    res->faithful_triangles = rc ? 0 : stats.triangles;
    /* The work is the request's; the mesh and its error bound are not the answer's. */
    if (!rc)
        add_work(&res->stats, &stats);
    return rc;
}

/* Does a budget need the chain: the mesh at the faithful tolerance is over it? Else the
 * ladder answers it without simplification. */
static int budget_needs_chain(const iso_tree *tree, const proto_pipeline_request *req,
                              proto_pipeline_result *res, int *needs, iso_error *err)
{
    int rc = faithful_triangles(tree, req, res, err);
    *needs = !rc && res->faithful_triangles > req->budget;
    return rc;
}

/* Each moved level's vertices' value error, measured once for the chain (mesh.h). A
 * segment's surface is not on a level of the samples: its moved vertices' distance is what
 * the chain measures, and their value error is not defined (0). */
static int value_errors(const iso_volume *vol, const proto_pipeline_request *req, iso_mesh_chain *chain,
                        iso_error *err)
{
    int rc = 0;
    iso_mesh m;
    iso_mesh_init(&m);
    for (int k = 1; !rc && k < chain->levels; k++)
        if (chain->level[k].value_error < 0 && req->segmentation)
            chain->level[k].value_error = 0;
        else if (chain->level[k].value_error < 0 && !(rc = iso_mesh_chain_mesh(chain, k, &m, err)))
            chain->level[k].value_error = iso_mesh_value_error(vol, &m, req->extract.space,
                                                               req->extract.level);
    iso_mesh_free(&m);
    return rc;
}

/* A chain just built keeps what later requests would otherwise find again: the faithful
 * mesh's triangle count (for budgets) and each moved level's vertices' value error. */
static int complete_chain(const iso_tree *tree, const iso_volume *vol,
                          const proto_pipeline_request *req, proto_pipeline_result *res,
                          iso_mesh_chain *chain, iso_error *err)
{
    int rc = req->segmentation ? 0 : faithful_triangles(tree, req, res, err); /* budgets only */
    chain->faithful_triangles = res->faithful_triangles;
    return rc ? rc : value_errors(vol, req, chain, err);
}

int proto_pipeline_chain_extend(const iso_volume *vol, const proto_pipeline_request *req, iso_mesh_chain *chain,
                                double distance, size_t triangles, iso_error *err)
{
    int rc = distance >= 0 || triangles
                 ? iso_mesh_chain_extend_until(chain, req->extract.threads, distance, triangles, err)
                 : iso_mesh_chain_extend(chain, req->extract.threads, err);
    return rc ? rc : value_errors(vol, req, chain, err);
}

/* The surface's chain, built here (res->chain_built): the whole chain, or with
 * req->chain_partial only down to the level the request needs; the surface first loses
 * the components req->min_component removes. */
static int build_chain(const iso_tree *tree, const iso_volume *vol, const proto_pipeline_request *req,
                       proto_pipeline_result *res, iso_error *err)
{
    int rc;
    if ((rc = surface(tree, req, &res->mesh, &res->stats, err)) ||
        (rc = remove_components(vol, req, &res->mesh, &res->components, err)))
        return rc;
    rc = req->chain_partial ? iso_mesh_chain_build_until(&res->mesh, voxel_size(vol, req), req->extract.threads,
                                                         req->budget ? -1 : req->distance, req->budget,
                                                         &res->chain_built, err)
                            : iso_mesh_chain_build(&res->mesh, voxel_size(vol, req), req->extract.threads,
                                                   &res->chain_built, err);
    if (rc)
        return rc;
    res->chain_built->min_component = req->min_component;
    res->chain_built->components = res->components;
    return complete_chain(tree, vol, req, res, res->chain_built, err);
}

/* Step 2 from the chain: the level that answers, copied out; built first when the caller
 * has none that answers the request as a full chain of the same surface would. A budget
 * below the coarsest level simplifies that level further. */
static int from_chain(const iso_tree *tree, const iso_volume *vol,
                      const proto_pipeline_request *req, proto_pipeline_result *res, iso_error *err)
{
    const iso_mesh_chain *chain = req->chain;
    int rc = 0;
    if (chain && (chain->min_component != req->min_component ||
                  !iso_mesh_chain_covers(chain, req->budget ? -1 : req->distance, req->budget)))
        chain = NULL;
    if (!chain) {
        if ((rc = build_chain(tree, vol, req, res, err)))
            return rc;
        chain = res->chain_built;
    }
    res->components = chain->components;
    int k = req->budget ? iso_mesh_chain_pick_budget(chain, req->budget)
                        : iso_mesh_chain_pick_distance(chain, req->distance);
    if ((rc = iso_mesh_chain_mesh(chain, k, &res->mesh, err)))
        return rc;
    res->chain_level = k;
    res->chain_levels = (size_t)chain->levels;
    res->exact_triangles = chain->level[0].triangle_count;
    res->distance = chain->level[k].distance;
    /* A level a build for another distance measured without its maximum: measured here,
     * as the chain would (the same p99 and maximum). */
    if (isnan(res->distance.max) &&
        (rc = iso_mesh_chain_distance(chain, &res->mesh, req->extract.threads, &res->distance, err)))
        return rc;
    res->distance_measured = 1;
    res->pinches = (iso_mesh_pinches){.edges = chain->level[k].edges,
                                      .pinch_edges = chain->level[k].nonmanifold_edges,
                                      .pinch_vertices = chain->level[k].pinch_vertices};
    /* A level moved to keep the enclosed volume: its vertices' value error, measured when
     * the chain was built, is what the error bound then promises. */
    res->vertex_offset = chain->level[k].offset;
    double value_error = chain->level[k].value_error;
    if (res->vertex_offset != 0)
        res->stats.error_bound = fmax(res->stats.error_bound,
                                      value_error >= 0 ? value_error
                                                       : iso_mesh_value_error(vol, &res->mesh, req->extract.space,
                                                                              req->extract.level));
    /* A level past 0 was simplified by meshoptimizer: its estimate, the largest of the
     * steps', stands beside the measured distance. */
    double estimate = 0;
    for (int j = 1; j <= k; j++)
        estimate = fmax(estimate, chain->level[j].estimate);
    res->chosen = (iso_budget_result){
        .tolerance = req->extract.tolerance, .fits = 1, .simplified = k > 0,
        .simplify = {.triangles_in = chain->level[0].triangle_count,
                     .vertices_in = chain->level[0].vertex_count, .error = estimate,
                     .error_voxels = estimate / chain->voxel_size, .scale = 1}};
    if (req->budget && res->mesh.triangle_count > req->budget) {
        iso_simplify_params sp = {.target_triangles = req->budget, .target_error = INFINITY,
                                  .lock_border = 1, .voxel_size = voxel_size(vol, req),
                                  .threads = req->extract.threads};
        if ((rc = iso_simplify_manifold(&res->mesh, &sp, &res->chosen.simplify, err)) ||
            ((rc = iso_mesh_find_pinches(&res->mesh, NULL, &res->pinches)) &&
             (rc = iso_error_set(err, rc, "no memory to count pinches"))) ||
            (rc = iso_mesh_chain_distance(chain, &res->mesh, req->extract.threads, &res->distance, err)))
            return rc;
        res->chosen.simplified = 1;
        res->chosen.fits = res->mesh.triangle_count <= req->budget;
    }
    res->stats.triangles = res->mesh.triangle_count;
    res->stats.vertices = res->mesh.vertex_count;
    return 0;
}

/* Steps 1 and 2 for a budget: the chain's finest level that fits (from_chain) and, when
 * the faithful tolerance's mesh fits too, the ladder's mesh, measured against the chain's
 * level 0 like the levels are; the closer one (p99 both ways) answers. */
static int budget_by_measure(const iso_tree *tree, const iso_volume *vol,
                             const proto_pipeline_request *req, int needs_chain,
                             proto_pipeline_result *res, iso_error *err)
{
    iso_mesh_clear(&res->mesh);
    int rc = from_chain(tree, vol, req, res, err);
    res->budget_source = "chain";
    res->budget_other_p99 = -1;
    if (rc || needs_chain)
        return rc;
    const iso_mesh_chain *chain = res->chain_built ? res->chain_built : req->chain;
    iso_mesh_components removed = {0};
    iso_mesh ladder;
    iso_mesh_init(&ladder);
    iso_extract_stats stats;
    iso_budget_result chosen = {.tolerance = req->extract.tolerance, .fits = -1};
    iso_mesh_distance d;
    if ((rc = iso_extract_budget_faithful(tree, &req->extract, req->budget, &ladder, &stats, &chosen, err)) ||
        (rc = remove_components(vol, req, &ladder, &removed, err)) ||
        (rc = iso_mesh_chain_distance(chain, &ladder, req->extract.threads, &d, err))) {
        iso_mesh_free(&ladder);
        return rc;
    }
    /* The ladder's extraction is this request's work whichever mesh answers. */
    iso_extract_stats before = res->stats;
    add_work(&res->stats, &stats);
    if (!chosen.fits || d.p99 >= res->distance.p99) {
        res->budget_other_p99 = chosen.fits ? d.p99 : -1;
        iso_mesh_free(&ladder);
        return 0;
    }
    res->budget_other_p99 = res->distance.p99;
    iso_mesh_free(&res->mesh);
    res->mesh = ladder;
    res->stats = stats;
    res->stats.triangles = ladder.triangle_count;
    res->stats.vertices = ladder.vertex_count;
    res->components = removed;
    add_work(&res->stats, &before);
    res->chosen = chosen;
    res->distance = d;
    res->chain_level = -1;
    res->vertex_offset = 0;
    res->budget_source = "tolerance";
    if ((rc = iso_mesh_find_pinches(&res->mesh, NULL, &res->pinches)))
        return iso_error_set(err, rc, "no memory to count pinches");
    return 0;
}

/* Step 1: the exact surface, the hierarchy's within the tolerance, or a budget's. */
static int extract(const iso_tree *tree, const iso_volume *vol,
                   const proto_pipeline_request *req, proto_pipeline_result *res,
                   iso_error *err)
{
    const iso_extract_params *p = &req->extract;
    res->chosen = (iso_budget_result){.tolerance = p->tolerance, .fits = -1};
    if (req->full_scan)
        return iso_extract_full_scan(vol, p->level, p->space, &res->mesh, &res->stats, err);
    if (!req->budget)
        return surface(tree, req, &res->mesh, &res->stats, err);
    if (req->budget_ladder_only)
        return iso_extract_budget(tree, p, req->budget, &res->mesh, &res->stats, &res->chosen,
                                  err);
    return iso_extract_budget_faithful(tree, p, req->budget, &res->mesh, &res->stats,
                                       &res->chosen, err);
}

/* Step 2: an explicit simplification, with no error limit and the open edges (on the
 * volume's border) locked so that the border still matches the neighbouring volume. */
static int simplify(const iso_volume *vol, const proto_pipeline_request *req,
                    proto_pipeline_result *res, iso_error *err)
{
    iso_simplify_params sp = {
        .target_triangles = req->simplify, .target_error = INFINITY, .lock_border = 1,
        .measure = req->measure, .threads = req->extract.threads,
        .voxel_size = req->extract.space == ISO_SPACE_INDEX ? 1 : iso_vol_min_spacing(vol)};
    int rc = iso_simplify(&res->mesh, &sp, &res->chosen.simplify, err);
    res->chosen.simplified = rc == 0;
    res->distance = res->chosen.simplify.distance;
    res->distance_measured = res->chosen.simplify.measured;
    res->stats.triangles = res->mesh.triangle_count;
    res->stats.vertices = res->mesh.vertex_count;
    return rc;
}

/* Step 4's measures: read-only on positions and indices, so they run on their own thread
 * beside normals and encoding, which write only the normals and the output. */
typedef struct measure_job {
    const iso_volume *vol;
    const iso_mesh *mesh;
    iso_space space;
    iso_census census;
    double area, enclosed, ms;
    int rc;
    iso_error err;
} measure_job;

static void *measure(void *arg)
{
    measure_job *m = arg;
    double start = iso_clock_ms();
    m->rc = iso_census_compute(m->vol, m->mesh, m->space, &m->census, &m->err);
    if (!m->rc) {
        m->area = iso_mesh_area(m->mesh);
        m->enclosed = m->census.closed ? fabs(iso_mesh_enclosed_volume(m->mesh)) : 0;
    }
    m->ms = iso_clock_ms() - start;
    return NULL;
}

/* Step 5. */
static int encode(const proto_pipeline_request *req, proto_pipeline_result *res,
                  iso_error *err)
{
    proto_draco_info info = {.speed = -1};
    int rc = 0;
    switch (req->format) {
    case PROTO_FORMAT_DRACO:
        rc = proto_draco_encode_info(&res->mesh, &req->encode, &res->bytes, &res->size, &info, err);
        break;
    case PROTO_FORMAT_GLB:
        rc = proto_glb_encode_info(&res->mesh, &req->encode, &res->bytes, &res->size, &info, err);
        break;
    case PROTO_FORMAT_GLB_MESHOPT: break; /* with the normals, in meshopt_steps */
    case PROTO_FORMAT_GLB_PLAIN: rc = proto_encode_glb_plain(&res->mesh, &res->bytes, &res->size, err); break;
    case PROTO_FORMAT_PLY: rc = proto_encode_ply(&res->mesh, &res->bytes, &res->size, err); break;
    case PROTO_FORMAT_STL: rc = proto_encode_stl(&res->mesh, &res->bytes, &res->size, err); break;
    case PROTO_FORMAT_OBJ: rc = proto_encode_obj(&res->mesh, &res->bytes, &res->size, err); break;
    case PROTO_FORMAT_NONE: break;
    }
    res->draco_speed = info.speed;
    return rc;
}

/* The normals for the meshopt encoder, which asks for them on the thread it gives them. */
typedef struct normals_job {
    const iso_volume *vol;
    const proto_pipeline_request *req;
    iso_mesh *mesh;
} normals_job;

static int make_normals(void *context, int threads, iso_error *err)
{
    normals_job *n = context;
    return surface_normals(n->vol, n->req, n->mesh, threads, err);
}

/* Steps 4 and 5 for the meshopt glb: the encoder numbers and codes the index view (which
 * does not read the normals) on one thread while the normals are made on the other, then
 * codes the vertex views, and makes the gzip member when asked, each stream deflated on the
 * thread that coded it (proto_encode_glb_meshopt_run). The steps overlap; each one's time
 * is counted from the end of the one before, so that they add up to the request's. */
static int meshopt_steps(const iso_volume *vol, const proto_pipeline_request *req,
                         proto_pipeline_result *res, double start, iso_error *err)
{
    normals_job n = {.vol = vol, .req = req, .mesh = &res->mesh};
    proto_meshopt_run run = {.make_normals = req->normals && res->mesh.vertex_count ? make_normals : NULL,
                             .context = &n, .gzip = req->gzip};
    int rc = proto_encode_glb_meshopt_run(&res->mesh, &req->encode, &run, &res->bytes, &res->size, err);
    if (rc)
        return rc;
    double normals_done = run.make_normals ? run.normals_done : start;
    res->normals_ms = normals_done - start;
    res->encode_ms = run.glb_done - normals_done;
    res->gzip = run.gzip_bytes;
    res->gzip_size = run.gzip_size;
    res->gzip_ms = req->gzip ? run.gzip_done - run.glb_done : 0;
    return 0;
}

/* Steps 4 and 5: normals and encoding here, the measures beside them when asked. If no
 * thread can start, the measures run here first: the result is the same. */
static int finish(const iso_volume *vol, const proto_pipeline_request *req,
                  proto_pipeline_result *res, iso_error *err)
{
    measure_job m = {.vol = vol, .mesh = &res->mesh, .space = req->extract.space};
    pthread_t measurer;
    int beside = req->measure && pthread_create(&measurer, NULL, measure, &m) == 0;
    if (req->measure && !beside)
        measure(&m);
    double t0 = iso_clock_ms();
    int rc = 0;
    if (req->format == PROTO_FORMAT_GLB_MESHOPT) {
        rc = meshopt_steps(vol, req, res, t0, err);
    } else {
        if (req->normals && res->mesh.vertex_count)
            rc = surface_normals(vol, req, &res->mesh, req->extract.threads, err);
        double t1 = iso_clock_ms();
        if (!rc)
            rc = encode(req, res, err);
        res->normals_ms = t1 - t0;
        res->encode_ms = iso_clock_ms() - t1;
    }
    if (beside)
        pthread_join(measurer, NULL);
    if (!rc && req->measure && m.rc) {
        rc = m.rc;
        if (err)
            *err = m.err;
    }
    res->measure_ms = m.ms;
    res->measured = req->measure && !rc;
    res->census = m.census;
    res->area = m.area;
    res->enclosed_volume = m.enclosed;
    return rc;
}

int proto_pipeline_run(const iso_tree *tree, const iso_volume *vol,
                       const proto_pipeline_request *req, proto_pipeline_result *res,
                       iso_error *err)
{
    assert(req && res && (req->full_scan ? vol != NULL : tree != NULL));
    if (!vol)
        vol = tree->vol;
    memset(res, 0, sizeof *res);
    iso_mesh_init(&res->mesh);
    res->draco_speed = -1;
    double t0 = iso_clock_ms();
    res->chain_level = -1;
    int rc = 0, chained = !req->full_scan && req->distance >= 0, needs_chain = 0;
    int measured_budget = !req->full_scan && req->budget && req->budget_chain && !req->budget_ladder_only;
    if (measured_budget)
        rc = budget_needs_chain(tree, req, res, &needs_chain, err);
    if (!rc && !chained && !measured_budget && !(rc = extract(tree, vol, req, res, err)) &&
        !(rc = remove_components(vol, req, &res->mesh, &res->components, err))) {
        res->stats.triangles = res->mesh.triangle_count;
        res->stats.vertices = res->mesh.vertex_count;
    }
    double t1 = iso_clock_ms();
    if (!rc && measured_budget)
        rc = budget_by_measure(tree, vol, req, needs_chain, res, err);
    else if (!rc && chained)
        rc = from_chain(tree, vol, req, res, err);
    else if (!rc && req->simplify)
        rc = simplify(vol, req, res, err);
    res->extract_ms = t1 - t0;
    res->simplify_ms = iso_clock_ms() - t1;
    if (!rc && req->max_triangles && res->stats.triangles > req->max_triangles)
        rc = iso_error_set(err, ISO_E_LIMIT, "the mesh has %zu triangles, more than this server's "
                           "limit of %zu; a larger tolerance gives fewer", res->stats.triangles,
                           req->max_triangles);
    if (!rc)
        rc = finish(vol, req, res, err);
    if (rc)
        proto_pipeline_result_free(res);
    return rc;
}
