/* cmd_extract.c: `isoserve extract`: one iso-surface to a file and/or a JSON report. */
#include <jansson.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "extract/extract.h"
#include "mesh/mesh.h"
#include "cli.h"
#include "encode.h"

static int ends_with(const char *s, const char *suffix)
{
    size_t n = strlen(s), m = strlen(suffix);
    return n >= m && !strcmp(s + n - m, suffix);
}

/* Writes the encoded mesh to path through a temporary file and rename, so a reader never
 * sees half a mesh. */
static int write_mesh(const iso_mesh *mesh, const char *path)
{
    unsigned char *bytes = NULL;
    size_t size = 0;
    iso_error err;
    int rc;
    if (ends_with(path, ".ply"))
        rc = proto_encode_ply(mesh, &bytes, &size, &err);
    else if (ends_with(path, ".obj"))
        rc = proto_encode_obj(mesh, &bytes, &size, &err);
    else if (ends_with(path, ".drc"))
        rc = proto_encode_draco(mesh, NULL, &bytes, &size, &err);
    else if (ends_with(path, ".glb"))
        rc = proto_encode_glb(mesh, NULL, &bytes, &size, &err);
    else if (ends_with(path, ".stl"))
        rc = proto_encode_stl(mesh, &bytes, &size, &err);
    else
        return srv_fail("%s: unknown output format (use .ply, .stl, .obj, .drc or .glb)", path);
    if (rc)
        return srv_fail("%s: %s", path, err.message);
    size_t len = strlen(path) + 8;
    char *tmp = malloc(len);
    FILE *f = tmp ? (snprintf(tmp, len, "%s.tmp", path), fopen(tmp, "wb")) : NULL;
    int ok = f && fwrite(bytes, 1, size, f) == size;
    ok = f && fclose(f) == 0 && ok;
    ok = ok && rename(tmp, path) == 0;
    if (!ok && tmp)
        remove(tmp);
    free(tmp);
    free(bytes);
    return ok ? 0 : srv_fail("%s: cannot write the mesh", path);
}

int srv_cmd_extract(int argc, char **argv)
{
    srv_open_options opt = {.want_tree = 1};
    iso_extract_params params = {0};
    const char *out = NULL;
    int as_json = 0, have_level = 0, full_scan = 0, normals = 4; /* tricubic by default */
    int no_simplify = 0;
    double budget = 0, simplify = 0; /* triangles; 0: none */
    for (int i = 0; i < argc; i++) {
        const char *a = argv[i], *value = i + 1 < argc ? argv[i + 1] : NULL;
        if (!strcmp(a, "--json"))
            as_json = 1;
        else if (!strcmp(a, "--index-space"))
            params.space = ISO_SPACE_INDEX;
        else if (!strcmp(a, "--full-scan"))
            full_scan = 1;
        else if (!strcmp(a, "--cap"))
            params.cap = 1;
        else if (!strcmp(a, "--no-simplify"))
            no_simplify = 1;
        else if ((!strcmp(a, "--budget") || !strcmp(a, "--simplify")) && value) {
            double *n = !strcmp(a, "--budget") ? &budget : &simplify;
            if (srv_parse_number(value, n) || *n < 1 || *n > 4294967295.0 || *n != floor(*n))
                return srv_fail("extract: %s '%s' must be a whole number of triangles from 1", a, value);
            i++;
        }
        else if (!strcmp(a, "--threads") && value) {
            if (srv_parse_threads("extract", argv[++i], &params.threads))
                return 1;
            opt.threads = params.threads;
        }
        else if (!strcmp(a, "--level") && value) {
            if (srv_parse_number(value, &params.level))
                return srv_fail("extract: --level '%s' is not a finite number", value);
            have_level = 1;
            i++;
        } else if (!strcmp(a, "--tolerance") && value) {
            if (srv_parse_number(value, &params.tolerance) || params.tolerance < 0)
                return srv_fail("extract: --tolerance '%s' must be a finite number >= 0", value);
            i++;
        } else if (!strcmp(a, "--normals") && value) {
            if ((normals = iso_normals_order_from_name(value)) < 0)
                return srv_fail("extract: --normals '%s': expected none, trilinear, triquadratic or tricubic", value);
            i++;
        } else if (!strcmp(a, "-o") && value)
            out = argv[++i];
        else if (!strcmp(a, "--hierarchy") && value)
            opt.hierarchy = argv[++i];
        else if (!strcmp(a, "--resample") && value)
            opt.resample = argv[++i];
        else if (a[0] == '-' || opt.path)
            return srv_fail("extract: unexpected argument '%s'", a);
        else
            opt.path = a;
    }
    if (!opt.path || !have_level)
        return srv_fail("extract: usage: isoserve extract VOLUME --level L [--tolerance T] [--cap] [--threads N] "
                        "[--budget N [--no-simplify]] [--simplify N] "
                        "[--normals none|trilinear|triquadratic|tricubic] [-o OUT.ply|.stl|.obj|.drc|.glb] [--json]");
    if (full_scan && (params.cap || budget))
        return srv_fail("extract: %s needs the hierarchy; drop --full-scan", params.cap ? "--cap" : "--budget");
    if (budget && simplify)
        return srv_fail("extract: --budget chooses its own simplification; drop --simplify");
    if (no_simplify && !budget)
        return srv_fail("extract: --no-simplify goes with --budget");
    opt.want_tree = !full_scan;
    srv_subject s;
    if (srv_open(&opt, &s))
        return 1;
    iso_mesh mesh;
    iso_mesh_init(&mesh);
    iso_extract_stats st;
    iso_error err;
    iso_budget_result chosen = {.tolerance = params.tolerance, .fits = -1};
    int rc = full_scan ? iso_extract_full_scan(s.vol, params.level, params.space, &mesh, &st, &err)
             : !budget ? iso_extract(s.tree, &params, &mesh, &st, &err)
             : no_simplify ? iso_extract_budget(s.tree, &params, (size_t)budget, &mesh, &st, &chosen, &err)
                           : iso_extract_budget_faithful(s.tree, &params, (size_t)budget, &mesh, &st, &chosen, &err);
    if (!rc && simplify) {
        /* An explicit simplification: no error limit, the open edges (on the border) locked. */
        iso_simplify_params sp = {.target_triangles = (size_t)simplify, .target_error = INFINITY,
                                  .voxel_size = params.space == ISO_SPACE_INDEX ? 1 : iso_vol_min_spacing(s.vol),
                                  .lock_border = 1};
        rc = iso_simplify(&mesh, &sp, &chosen.simplify, &err);
        chosen.simplified = !rc;
        st.triangles = mesh.triangle_count;
        st.vertices = mesh.vertex_count;
    }
    if (!rc && normals)
        rc = iso_normals_compute(s.vol, &mesh, normals, params.space, params.threads, &err);
    if (rc) {
        srv_close(&s);
        return srv_fail("%s: %s", opt.path, err.message);
    }
    int status = out ? write_mesh(&mesh, out) : 0;
    iso_census census;
    if (as_json && status == 0 && iso_census_compute(s.vol, &mesh, params.space, &census, &err))
        status = srv_fail("%s: %s", opt.path, err.message);
    if (as_json && status == 0) {
        size_t volume_bytes = iso_vol_count(s.vol) * iso_vol_type_size(s.vol->type);
        double area = iso_mesh_area(&mesh);
        json_t *doc = json_pack(
            "{s:s, s:f, s:f, s:I, s:I, s:I, s:I, s:I, s:f, s:f, s:f, s:f, s:f, s:I, s:I, s:s, s:s}",
            "volume", opt.path, "level", params.level, "tolerance", chosen.tolerance,
            "triangles", (json_int_t)st.triangles, "vertices", (json_int_t)st.vertices,
            "cells_visited", (json_int_t)st.cells_visited, "nodes_visited", (json_int_t)st.nodes_visited,
            "nodes_polygonized", (json_int_t)st.nodes_polygonized, "extract_ms", st.extract_ms,
            "build_ms", s.tree ? s.tree->build_ms : 0.0, "error_bound", st.error_bound,
            "area", area, "area_mm2", area, "hierarchy_bytes", (json_int_t)(s.tree ? iso_tree_memory(s.tree) : 0),
            "volume_bytes", (json_int_t)volume_bytes, "space",
            params.space == ISO_SPACE_INDEX ? "index" : "world_mm", "normals", iso_normals_name(normals));
        json_t *watertight = json_pack("{s:I, s:I, s:I, s:I, s:I, s:b}",
            "open_edges", (json_int_t)census.open_edges,
            "boundary_edges", (json_int_t)census.boundary_edges,
            "nonmanifold_edges", (json_int_t)census.nonmanifold_edges,
            "misoriented_edges", (json_int_t)census.misoriented_edges,
            "degenerate_triangles", (json_int_t)census.degenerate_triangles,
            "closed", census.closed);
        if (doc)
            json_object_set_new(doc, "fit_error", json_real(st.fit_error));
        if (doc && budget)
            json_object_set_new(doc, "budget", json_pack("{s:I, s:b, s:i}", "triangles", (json_int_t)budget,
                                                         "fits", chosen.fits, "extractions", chosen.extractions));
        if (doc && chosen.simplified)
            json_object_set_new(doc, "simplify", json_pack(
                "{s:I, s:I, s:f, s:f, s:f, s:I, s:I, s:I}", "triangles_in", (json_int_t)chosen.simplify.triangles_in,
                "vertices_in", (json_int_t)chosen.simplify.vertices_in, "error", chosen.simplify.error,
                "error_voxels", chosen.simplify.error_voxels, "ms", chosen.simplify.ms,
                "folds_dropped", (json_int_t)chosen.simplify.folds_dropped,
                "nonmanifold_edges", (json_int_t)chosen.simplify.nonmanifold_edges,
                "unpaired_edges", (json_int_t)chosen.simplify.unpaired_edges));
        if (doc && watertight)
            json_object_update(doc, watertight);
        json_decref(watertight);
        /* Only a closed surface encloses anything; index space has no millimetres. */
        if (doc)
            json_object_set_new(doc, "enclosed_volume_mm3",
                                census.closed && params.space == ISO_SPACE_WORLD
                                    ? json_real(fabs(iso_mesh_enclosed_volume(&mesh)))
                                    : json_null());
        char *text = doc ? json_dumps(doc, JSON_COMPACT | JSON_REAL_PRECISION(10)) : NULL;
        if (text)
            puts(text);
        free(text);
        json_decref(doc);
    } else if (status == 0) {
        printf("%zu triangles, %zu vertices, %zu cells visited, error bound %g, %.2f ms\n",
               st.triangles, st.vertices, st.cells_visited, st.error_bound, st.extract_ms);
        if (budget)
            printf("budget %.0f: %s at tolerance %g\n", budget, chosen.fits ? "fits" : "does not fit",
                   chosen.tolerance);
        if (chosen.simplified)
            printf("simplified from %zu triangles in %.2f ms, error %g (%g voxels, meshoptimizer's estimate)\n",
                   chosen.simplify.triangles_in, chosen.simplify.ms, chosen.simplify.error,
                   chosen.simplify.error_voxels);
    }
    iso_mesh_free(&mesh);
    srv_close(&s);
    return status;
}
