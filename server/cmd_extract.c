/* cmd_extract.c: `isoserve extract`: one iso-surface to a file and/or a JSON report,
 * through the request pipeline the server runs (pipeline.h). */
#include <jansson.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "extract/extract.h"
#include "mesh/mesh.h"
#include "cli.h"
#include "pipeline.h"

/* The measured distance between the exact and the simplified surface (mesh.h), in the
 * mesh's units: "from_exact" samples the exact surface, "to_exact" the simplified one;
 * "drawn_*": the points drawn by area for the percentile (0: every centroid). */
static json_t *distance_json(const iso_mesh_distance *d)
{
    return json_pack("{s:f, s:f, s:f, s:f, s:f, s:f, s:I, s:I, s:I, s:I, s:f}", "p99", d->p99,
                     "max", d->max, "p99_from_exact", d->p99_ab, "max_from_exact", d->max_ab,
                     "p99_to_exact", d->p99_ba, "max_to_exact", d->max_ba,
                     "samples_exact", (json_int_t)d->samples_a,
                     "samples_simplified", (json_int_t)d->samples_b,
                     "drawn_exact", (json_int_t)d->drawn_a,
                     "drawn_simplified", (json_int_t)d->drawn_b, "ms", d->ms);
}

/* Which level of the simplification chain answered, and the whole chain as measured. */
static json_t *chain_json(const proto_pipeline_result *res)
{
    const iso_mesh_chain *c = res->chain_built;
    json_t *levels = json_array();
    for (int k = 0; c && levels && k < c->levels; k++) {
        json_t *level = json_pack(
            "{s:I, s:f, s:f, s:f, s:I, s:I, s:I, s:I, s:f, s:f, s:f, s:f}", "triangles",
            (json_int_t)c->level[k].triangle_count, "p99", c->level[k].distance.p99,
            "max", isnan(c->level[k].distance.max) ? 0.0 : c->level[k].distance.max,
            "estimate", c->level[k].estimate,
            "edges", (json_int_t)c->level[k].edges,
            "nonmanifold_edges", (json_int_t)c->level[k].nonmanifold_edges,
            "pinch_vertices", (json_int_t)c->level[k].pinch_vertices,
            "folds_dropped", (json_int_t)c->level[k].folds_dropped,
            "offset", c->level[k].offset, "volume_change", c->level[k].volume_change,
            "simplify_ms", c->level[k].simplify_ms, "measure_ms", c->level[k].measure_ms);
        /* a partial chain's level measured without its maximum (mesh.h) */
        if (level && isnan(c->level[k].distance.max))
            json_object_set_new(level, "max", json_null());
        json_array_append_new(levels, level);
    }
    return json_pack("{s:i, s:I, s:b, s:I, s:I, s:I, s:I, s:f, s:f, s:o}", "level", res->chain_level,
                     "levels", (json_int_t)res->chain_levels, "partial", c ? c->partial : 0, "exact_triangles",
                     (json_int_t)res->exact_triangles, "edges", (json_int_t)res->pinches.edges,
                     "pinch_edges", (json_int_t)res->pinches.pinch_edges,
                     "pinch_vertices", (json_int_t)res->pinches.pinch_vertices,
                     "vertex_offset", res->vertex_offset,
                     "build_ms", c ? c->build_ms : 0.0,
                     "built", levels ? levels : json_null());
}

enum {
    EX_LEVEL, EX_TOLERANCE, EX_OUT, EX_JSON, EX_NORMALS, EX_CAP, EX_BUDGET, EX_NO_SIMPLIFY, EX_SIMPLIFY,
    EX_DISTANCE, EX_MIN_COMPONENT, EX_THREADS, EX_HIERARCHY, EX_RESAMPLE, EX_INDEX_SPACE, EX_FULL_SCAN,
    EX_COARSEN, EX_OPTIONS
};
static const srv_option extract_options[EX_OPTIONS] = {
    [EX_LEVEL] = {"--level", "L", "the iso-level, in the volume's values (required)"},
    [EX_TOLERANCE] = {"--tolerance", "T", "the error bound in values, >= 0 (default 0: the exact surface)"},
    [EX_OUT] = {"-o", "OUT", "write the mesh: .ply, .stl, .obj, .drc, .glb, .meshopt.glb or .plain.glb (no extension)"},
    [EX_JSON] = {"--json", NULL, "print the counts, times, error bound, area and watertightness as JSON"},
    [EX_NORMALS] = {"--normals", "ORDER", "none, trilinear, triquadratic or tricubic (default)"},
    [EX_CAP] = {"--cap", NULL, "close the surface at the volume's border (a printable mesh)"},
    [EX_BUDGET] = {"--budget", "N", "at most N triangles: the finest faithful tolerance, else simplified"},
    [EX_NO_SIMPLIFY] = {"--no-simplify", NULL, "with --budget: climb the whole tolerance ladder instead"},
    [EX_SIMPLIFY] = {"--simplify", "N", "simplify the mesh to N triangles (meshoptimizer)"},
    [EX_DISTANCE] = {"--distance", "D", "the coarsest simplification of the surface within D mm of it (p99)"},
    [EX_MIN_COMPONENT] = {"--min-component", "V", "first remove the closed pieces of surface enclosing less than "
                          "V mm3 (default 0: every piece is kept)"},
    [EX_THREADS] = {"--threads", "N", "threads of the build and of exact extraction (default: all cores)"},
    [EX_HIERARCHY] = {"--hierarchy", "FILE", "read the hierarchy from a file `isoserve build` wrote"},
    [EX_RESAMPLE] = {"--resample", "WxHxD", "box-filter the volume to these dims first (or N for NxNxN)"},
    [EX_INDEX_SPACE] = {"--index-space", NULL, "positions in voxel indices, not world millimetres"},
    [EX_FULL_SCAN] = {"--full-scan", NULL, "march every cell, without the hierarchy (the baseline)"},
    [EX_COARSEN] = {"--coarsen", "WHEN", "all: the fewest triangles the tolerance allows (default); faster: "
                    "coarse only where extraction gains"},
};

static int srv_cmd_extract(int argc, char **argv);
const srv_command srv_extract_command = {
    "extract", "VOLUME --level L [options]",
    "One iso-surface, with its proven error bound, to a file and/or a JSON report.", extract_options,
    EX_OPTIONS, 1, srv_cmd_extract};

/* A whole number of triangles from 1 into *n; 0, or reported. */
static int parse_triangles(const char *option, const char *value, double *n)
{
    if (srv_parse_number(value, n) || *n < 1 || *n > 4294967295.0 || *n != floor(*n))
        return srv_fail("extract: %s '%s' must be a whole number of triangles from 1", option, value);
    return 0;
}

static int srv_cmd_extract(int argc, char **argv)
{
    srv_open_options opt = {.want_tree = 1};
    iso_extract_params params = {.coarsen = ISO_COARSEN_ALL}; /* a file wants the fewest triangles */
    const char *out = NULL, *value;
    int as_json = 0, have_level = 0, full_scan = 0, normals = 4; /* tricubic by default */
    int no_simplify = 0, i = 0, arg;
    double budget = 0, simplify = 0; /* triangles; 0: none */
    double distance = -1;            /* position units; < 0: none */
    double min_component = 0;        /* mm3; 0: none */
    while ((arg = srv_next_arg(&srv_extract_command, argc, argv, &i, &value)) != SRV_ARG_END) {
        switch (arg) {
        case SRV_ARG_HELP: return 0;
        case SRV_ARG_ERROR: return 1;
        case EX_JSON: as_json = 1; break;
        case EX_INDEX_SPACE: params.space = ISO_SPACE_INDEX; break;
        case EX_FULL_SCAN: full_scan = 1; break;
        case EX_CAP: params.cap = 1; break;
        case EX_COARSEN:
            if (srv_parse_coarsen("extract", value, &params.coarsen))
                return 1;
            break;
        case EX_NO_SIMPLIFY: no_simplify = 1; break;
        case EX_BUDGET:
            if (parse_triangles("--budget", value, &budget))
                return 1;
            break;
        case EX_SIMPLIFY:
            if (parse_triangles("--simplify", value, &simplify))
                return 1;
            break;
        case EX_DISTANCE:
            if (srv_parse_number(value, &distance) || distance < 0)
                return srv_fail("extract: --distance '%s' must be a finite number >= 0", value);
            break;
        case EX_MIN_COMPONENT:
            if (srv_parse_number(value, &min_component) || min_component < 0)
                return srv_fail("extract: --min-component '%s' must be a finite number of mm3 >= 0", value);
            break;
        case EX_THREADS:
            if (srv_parse_threads("extract", value, &params.threads))
                return 1;
            opt.threads = params.threads;
            break;
        case EX_LEVEL:
            if (srv_parse_number(value, &params.level))
                return srv_fail("extract: --level '%s' is not a finite number", value);
            have_level = 1;
            break;
        case EX_TOLERANCE:
            if (srv_parse_number(value, &params.tolerance) || params.tolerance < 0)
                return srv_fail("extract: --tolerance '%s' must be a finite number >= 0", value);
            break;
        case EX_NORMALS:
            if ((normals = iso_normals_order_from_name(value)) < 0)
                return srv_fail("extract: --normals '%s': expected none, trilinear, triquadratic or tricubic", value);
            break;
        case EX_OUT: out = value; break;
        case EX_HIERARCHY: opt.hierarchy = value; break;
        case EX_RESAMPLE: opt.resample = value; break;
        default: /* SRV_ARG_OPERAND */
            if (opt.path)
                return srv_fail("extract: unexpected argument '%s' (one VOLUME)", value);
            opt.path = value;
        }
    }
    if (!opt.path || !have_level)
        return srv_fail("extract: usage: isoserve extract %s (isoserve extract --help lists the options)",
                        srv_extract_command.synopsis);
    if (full_scan && (params.cap || budget))
        return srv_fail("extract: %s needs the hierarchy; drop --full-scan", params.cap ? "--cap" : "--budget");
    if (budget && simplify)
        return srv_fail("extract: --budget chooses its own simplification; drop --simplify");
    if (distance >= 0 && (budget || simplify || full_scan))
        return srv_fail("extract: --distance chooses the mesh itself; drop %s",
                        budget ? "--budget" : simplify ? "--simplify" : "--full-scan");
    if (no_simplify && !budget)
        return srv_fail("extract: --no-simplify goes with --budget");
    int format = srv_format_of_path(out);
    if (format < 0)
        return srv_fail("%s: unknown output format (use .ply, .stl, .obj, .drc, .glb, .meshopt.glb or .plain.glb)", out);
    opt.want_tree = !full_scan;
    srv_subject s;
    if (srv_open(&opt, &s))
        return 1;
    proto_pipeline_request req;
    proto_pipeline_request_init(&req);
    req.extract = params;
    req.full_scan = full_scan;
    req.budget = (size_t)budget;
    req.budget_ladder_only = no_simplify;
    req.simplify = (size_t)simplify;
    req.distance = distance;
    req.chain_partial = 1; /* nothing keeps the chain: build what the request needs */
    req.min_component = min_component;
    req.budget_chain = !no_simplify;
    req.normals = normals;
    req.measure = as_json;
    req.format = (proto_format)format;
    req.encode.threads = params.threads;
    proto_pipeline_result res;
    iso_error err;
    if (proto_pipeline_run(s.tree, s.vol, &req, &res, &err)) {
        srv_close(&s);
        return srv_fail("%s: %s", opt.path, err.message);
    }
    const iso_extract_stats st = res.stats;
    const iso_budget_result chosen = res.chosen;
    int status = out ? srv_write_file(res.bytes, res.size, out) : 0;
    if (as_json && status == 0) {
        size_t volume_bytes = iso_vol_count(s.vol) * iso_vol_type_size(s.vol->type);
        int world = params.space == ISO_SPACE_WORLD;
        json_t *doc = json_pack(
            "{s:s, s:f, s:f, s:I, s:I, s:I, s:I, s:I, s:f, s:f, s:f, s:f, s:I, s:I, s:s, s:s}",
            "volume", opt.path, "level", params.level, "tolerance", chosen.tolerance,
            "triangles", (json_int_t)st.triangles, "vertices", (json_int_t)st.vertices,
            "cells_visited", (json_int_t)st.cells_visited, "nodes_visited", (json_int_t)st.nodes_visited,
            "nodes_polygonized", (json_int_t)st.nodes_polygonized, "extract_ms", st.extract_ms,
            "build_ms", s.tree ? s.tree->build_ms : 0.0, "error_bound", st.error_bound,
            "area", res.area, "hierarchy_bytes", (json_int_t)(s.tree ? iso_tree_memory(s.tree) : 0),
            "volume_bytes", (json_int_t)volume_bytes, "space",
            world ? "world_mm" : "index", "normals", iso_normals_name(normals));
        json_object_set_new(doc, "coarse_share", json_real(st.coarse_share));
        const iso_census *census = &res.census;
        json_t *watertight = json_pack("{s:I, s:I, s:I, s:I, s:I, s:b}",
            "open_edges", (json_int_t)census->open_edges,
            "boundary_edges", (json_int_t)census->boundary_edges,
            "nonmanifold_edges", (json_int_t)census->nonmanifold_edges,
            "misoriented_edges", (json_int_t)census->misoriented_edges,
            "degenerate_triangles", (json_int_t)census->degenerate_triangles,
            "closed", census->closed);
        /* Index space has no millimetres: area_mm2 is null there, area is in its units. */
        if (doc)
            json_object_set_new(doc, "area_mm2", world ? json_real(res.area) : json_null());
        if (doc)
            json_object_set_new(doc, "fit_error", json_real(st.fit_error));
        if (doc && budget)
            json_object_set_new(doc, "budget", json_pack("{s:I, s:b, s:i, s:s?, s:f}", "triangles", (json_int_t)budget,
                                                         "fits", chosen.fits, "extractions", chosen.extractions,
                                                         "source", res.budget_source,
                                                         "other_p99", res.budget_other_p99));
        if (doc && chosen.simplified)
            json_object_set_new(doc, "simplify", json_pack(
                "{s:I, s:I, s:f, s:f, s:f, s:I, s:I, s:I}", "triangles_in", (json_int_t)chosen.simplify.triangles_in,
                "vertices_in", (json_int_t)chosen.simplify.vertices_in, "error", chosen.simplify.error,
                "error_voxels", chosen.simplify.error_voxels, "ms", chosen.simplify.ms,
                "folds_dropped", (json_int_t)chosen.simplify.folds_dropped,
                "nonmanifold_edges", (json_int_t)chosen.simplify.nonmanifold_edges,
                "unpaired_edges", (json_int_t)chosen.simplify.unpaired_edges));
        if (doc && chosen.simplified && chosen.simplify.measured)
            json_object_set_new(json_object_get(doc, "simplify"), "distance",
                                distance_json(&chosen.simplify.distance));
        if (doc && res.distance_measured)
            json_object_set_new(doc, "distance", distance_json(&res.distance));
        if (doc && res.chain_level >= 0)
            json_object_set_new(doc, "chain", chain_json(&res));
        /* --min-component's removals; "removed_largest": the largest removed piece's
         * bounding-box diagonal, in the mesh's units (mm in world space). */
        if (doc && min_component > 0)
            json_object_set_new(doc, "components", json_pack(
                "{s:f, s:I, s:I, s:I, s:f}", "min_component_mm3", min_component,
                "before", (json_int_t)res.components.components, "removed", (json_int_t)res.components.removed,
                "removed_triangles", (json_int_t)res.components.removed_triangles,
                "removed_largest", res.components.removed_largest));
        if (doc && watertight)
            json_object_update(doc, watertight);
        json_decref(watertight);
        /* Only a closed surface encloses anything; index space has no millimetres. */
        if (doc)
            json_object_set_new(doc, "enclosed_volume_mm3",
                                census->closed && world ? json_real(res.enclosed_volume) : json_null());
        char *text = doc ? json_dumps(doc, JSON_COMPACT | JSON_REAL_PRECISION(10)) : NULL;
        if (text)
            puts(text);
        else
            status = srv_fail("%s: out of memory writing the report", opt.path);
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
    proto_pipeline_result_free(&res);
    srv_close(&s);
    return status;
}
