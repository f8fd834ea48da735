/* test_oom.c: allocation failures along one mesh request's path. The steps of the request
 * pipeline (proto/pipeline.c, which the server and the CLI run: extraction, exact or
 * through the hierarchy or under a triangle budget, simplified by meshoptimizer when the
 * faithful ladder cannot meet it; normals; the edge census; the Draco, glb, meshopt glb, PLY and STL
 * encoders) and the Draco decoder are
 * run once to count their allocations, then once per allocation with exactly that one
 * failing: each run must either succeed with the same mesh (the failure was absorbed, e.g.
 * a helper thread that could not start) or return ISO_E_NOMEM with a message that says
 * memory ran out; never another code, never a crash, and never a block left behind.
 *
 * The failures come from tests/support/alloc (every library of the process, libdraco's
 * operator new included: a failing operator new throws std::bad_alloc inside libdraco,
 * which the extern "C" shim must turn into ISO_E_NOMEM). Under ASan the test says SKIP. */
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "mesh/mesh.h"
#include "alloc_fail.h"
#include "check.h"
#include "encode.h"
#include "pipeline.h"
#include "extract/extract.h"
#include "io/io.h"
#include "hierarchy/tree.h"

#if ALLOC_FAIL_AVAILABLE
/* ---- one request through the pipeline the server and the CLI run ---- */

typedef struct request {
    const char *name;
    double level, tolerance;
    size_t budget;     /* 0: none */
    int normals;       /* 0, 2, 3 or 4 */
    proto_format format;
} request;

/* One request as server/mesh_job.c makes it (measures included); frees everything before
 * returning. *triangles and *bytes say what came out (on success). */
static int run_request(const iso_tree *tree, const request *r, size_t *triangles, size_t *bytes,
                       iso_error *err)
{
    proto_pipeline_request req;
    proto_pipeline_request_init(&req);
    req.extract.level = r->level;
    req.extract.tolerance = r->tolerance;
    req.extract.threads = 1;
    req.budget = r->budget;
    req.normals = r->normals;
    req.measure = 1;
    req.format = r->format;
    proto_pipeline_result res;
    int rc = proto_pipeline_run(tree, tree->vol, &req, &res, err);
    *triangles = rc ? 0 : res.mesh.triangle_count;
    *bytes = rc ? 0 : res.size;
    proto_pipeline_result_free(&res);
    return rc;
}

/* ---- the sweep ---- */

/* An 11x10x9 sphere field and its hierarchy, or NULL (a CHECK failed). */
static iso_tree *sphere_tree(iso_volume **vol)
{
    static const size_t dims[3] = {11, 10, 9};
    iso_error err = {0};
    iso_tree *tree = NULL;
    *vol = NULL;
    CHECK_OK(iso_field_create("sphere", dims, 0, vol, &err), &err);
    if (!*vol)
        return NULL;
    iso_vol_update_stats(*vol);
    CHECK_OK(iso_tree_build(*vol, 1, NULL, NULL, &tree, &err), &err);
    return tree;
}

/* What one run gives, compared between the clean run and those with a failure absorbed. */
typedef struct outcome {
    size_t triangles, bytes;
} outcome;

/* One run of the code under test: frees everything it allocates before returning. */
typedef int (*run_fn)(const void *context, outcome *out, iso_error *err);

static int run_request_fn(const void *context, outcome *out, iso_error *err)
{
    const struct { const iso_tree *tree; const request *r; } *c = context;
    return run_request(c->tree, c->r, &out->triangles, &out->bytes, err);
}

typedef struct decode_input {
    const unsigned char *data;
    size_t size;
} decode_input;

static int run_decode_fn(const void *context, outcome *out, iso_error *err)
{
    const decode_input *in = context;
    iso_mesh decoded;
    int rc = proto_draco_decode(in->data, in->size, &decoded, err);
    *out = (outcome){decoded.triangle_count, decoded.vertex_count};
    iso_mesh_free(&decoded);
    return rc;
}

/* Runs fn once per allocation it makes, that allocation failing: each run either fails
 * with ISO_E_NOMEM saying so or gives the clean run's outcome, and leaves no block behind.
 * At least one failure must reach the caller. */
static void sweep(const char *name, run_fn fn, const void *context)
{
    iso_error err = {0};
    outcome want = {0}, got = {0};
    /* Unarmed first: whatever a library allocates once and keeps is allocated now. */
    CHECK_OK(fn(context, &want, &err), &err);
    alloc_fail_arm(-1);
    int rc = fn(context, &got, &err);
    long leaked = alloc_fail_live(), total = alloc_fail_disarm();
    CHECKF(rc == 0 && leaked == 0 && got.triangles == want.triangles && total > 0,
           "%s: clean run: rc %d, %ld blocks left, %zu triangles, %ld allocations", name, rc,
           leaked, got.triangles, total);
    long nomem = 0;
    for (long n = 0; n < total && !check_failed(); n++) {
        memset(&err, 0, sizeof err);
        got = (outcome){0};
        alloc_fail_arm(n);
        rc = fn(context, &got, &err);
        leaked = alloc_fail_live();
        alloc_fail_disarm();
        if (rc == 0)
            CHECKF(got.triangles == want.triangles && got.bytes == want.bytes,
                   "%s, allocation %ld failing: succeeded with %zu triangles, %zu bytes; want %zu, %zu",
                   name, n, got.triangles, got.bytes, want.triangles, want.bytes);
        else
            CHECKF(rc == ISO_E_NOMEM && strstr(err.message, "memory"),
                   "%s, allocation %ld failing: code %d \"%s\", want ISO_E_NOMEM saying memory ran out",
                   name, n, rc, err.message);
        CHECKF(leaked == 0, "%s, allocation %ld of %ld failing (\"%s\"): %ld blocks left behind",
               name, n, total, err.message, leaked);
        nomem += rc != 0;
    }
    printf("  %s: %ld allocations, %ld failures answered ISO_E_NOMEM, %ld absorbed\n", name,
           total, nomem, total - nomem);
    CHECKF(nomem > 0, "%s: no allocation failure reached the caller", name);
}

static void test_request_path_allocation_failures(void)
{
    iso_volume *vol;
    iso_tree *tree = sphere_tree(&vol);
    /* Level 1.5 cuts the sphere inside the grid; each request takes another route through
     * the steps, between them every encoder and normals order. */
    static const request requests[] = {
        {"exact, tricubic normals, draco", 1.5, 0, 0, 4, PROTO_FORMAT_DRACO},
        {"hierarchy, trilinear normals, glb", 1.5, 0.3, 0, 2, PROTO_FORMAT_GLB},
        {"budget 60, triquadratic normals, ply", 1.5, 0, 60, 3, PROTO_FORMAT_PLY},
        {"hierarchy, no normals, stl", 1.5, 0.3, 0, 0, PROTO_FORMAT_STL},
        {"exact, tricubic normals, meshopt glb", 1.5, 0, 0, 4, PROTO_FORMAT_GLB_MESHOPT},
    };
    for (size_t i = 0; tree && i < sizeof requests / sizeof requests[0] && !check_failed(); i++) {
        struct { const iso_tree *tree; const request *r; } context = {tree, &requests[i]};
        sweep(requests[i].name, run_request_fn, &context);
    }
    iso_tree_destroy(tree);
    iso_vol_destroy(vol);
}

/* The decoder's side of the shim: libdraco allocates with operator new throughout. */
static void test_draco_decode_allocation_failures(void)
{
    iso_volume *vol;
    iso_tree *tree = sphere_tree(&vol);
    iso_error err = {0};
    iso_mesh mesh;
    iso_mesh_init(&mesh);
    iso_extract_params params = {.level = 1.5, .space = ISO_SPACE_WORLD, .threads = 1};
    decode_input in = {0};
    unsigned char *data = NULL;
    if (tree) {
        CHECK_OK(iso_extract(tree, &params, &mesh, NULL, &err), &err);
        CHECK_OK(iso_normals_compute(vol, &mesh, 4, ISO_SPACE_WORLD, 0, &err), &err);
        CHECK_OK(proto_encode_draco(&mesh, NULL, &data, &in.size, &err), &err);
    }
    in.data = data;
    if (data)
        sweep("draco decode", run_decode_fn, &in);
    free(data);
    iso_mesh_free(&mesh);
    iso_tree_destroy(tree);
    iso_vol_destroy(vol);
}

int main(void)
{
    CHECK_RUN(test_request_path_allocation_failures);
    CHECK_RUN(test_draco_decode_allocation_failures);
    return check_finish();
}
#else
static void test_allocation_failures(void)
{
    check_skip("the sanitizer build's malloc is ASan's, which this test would have to replace");
}

int main(void)
{
    CHECK_RUN(test_allocation_failures);
    return check_finish();
}
#endif
