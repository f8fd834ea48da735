/* cmd_bench.c: `isoserve bench`: the columns of Elber and Malzbender's Table 1 (tolerance,
 * polygons, cells visited, hierarchy build time, extraction time without and with min/max
 * pruning), full-scan marching cubes as the first row; a table on stdout, JSON on request.
 * Times are the best of --repeat runs: the machine is shared and noisy. */
#include <jansson.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "cli.h"
#include "base/base.h"

typedef struct bench_row {
    double tolerance;
    iso_extract_stats pruned, unpruned;
    double best_pruned_ms, best_unpruned_ms;
} bench_row;

/* A time that was not measured (baselines skipped) is null in the JSON. */
static json_t *maybe_real(double ms)
{
    return isnan(ms) ? json_null() : json_real(ms);
}

static int parse_tolerances(const char *text, double **out, size_t *count)
{
    size_t n = 1;
    for (const char *p = text; *p; p++)
        n += *p == ',';
    double *v = calloc(n, sizeof *v);
    char *copy = strdup(text);
    if (!v || !copy) {
        free(v);
        free(copy);
        return ISO_E_NOMEM;
    }
    size_t i = 0;
    for (char *save = NULL, *tok = strtok_r(copy, ",", &save); tok; tok = strtok_r(NULL, ",", &save)) {
        if (srv_parse_number(tok, &v[i]) || v[i] < 0) {
            free(v);
            free(copy);
            return ISO_E_ARGUMENT;
        }
        i++;
    }
    free(copy);
    *out = v;
    *count = i;
    return i ? 0 : ISO_E_ARGUMENT;
}

static int run(const iso_tree *tree, double level, double tolerance, int no_minmax, int threads,
               int repeat, iso_extract_stats *st, double *best)
{
    iso_extract_params p = {.level = level, .tolerance = tolerance, .no_minmax = no_minmax,
                            .threads = threads};
    iso_mesh mesh;
    iso_mesh_init(&mesh);
    iso_error err;
    *best = 1e300;
    for (int r = 0; r < repeat; r++) {
        if (iso_extract(tree, &p, &mesh, st, &err)) {
            iso_mesh_free(&mesh);
            return srv_fail("bench: %s", err.message);
        }
        if (st->extract_ms < *best)
            *best = st->extract_ms;
    }
    iso_mesh_free(&mesh);
    return 0;
}

int srv_cmd_bench(int argc, char **argv)
{
    srv_open_options opt = {.want_tree = 1};
    double level = 0, *tolerances = NULL;
    size_t count = 0;
    int have_level = 0, repeat = 3, baselines = 1;
    const char *json_path = NULL, *tol_text = "0,6,10,15,25,50,75,100,200,300,400,500";
    srv_keep_freed_memory(); /* the server's allocator, as bench_peer tunes VTK's */
    for (int i = 0; i < argc; i++) {
        const char *a = argv[i], *value = i + 1 < argc ? argv[i + 1] : NULL;
        if (!strcmp(a, "--level") && value) {
            if (srv_parse_number(value, &level))
                return srv_fail("bench: --level '%s' is not a finite number", value);
            have_level = 1;
            i++;
        } else if (!strcmp(a, "--tolerances") && value)
            tol_text = argv[++i];
        else if (!strcmp(a, "--json") && value)
            json_path = argv[++i];
        else if (!strcmp(a, "--repeat") && value) {
            repeat = atoi(argv[++i]);
            if (repeat < 1 || repeat > 1000)
                return srv_fail("bench: --repeat must be 1..1000");
        } else if (!strcmp(a, "--resample") && value)
            opt.resample = argv[++i];
        else if (!strcmp(a, "--threads") && value) {
            if (srv_parse_threads("bench", argv[++i], &opt.threads))
                return 1;
        } else if (!strcmp(a, "--no-baselines"))
            baselines = 0;
        else if (a[0] == '-' || opt.path)
            return srv_fail("bench: unexpected argument '%s'", a);
        else
            opt.path = a;
    }
    if (!opt.path || !have_level)
        return srv_fail("bench: usage: isoserve bench VOLUME --level L [--tolerances 0,6,...] [--threads N] [--no-baselines]");
    if (parse_tolerances(tol_text, &tolerances, &count))
        return srv_fail("bench: --tolerances '%s': expected numbers >= 0 separated by commas", tol_text);
    srv_subject s;
    if (srv_open(&opt, &s)) {
        free(tolerances);
        return 1;
    }

    /* Row 0: marching cubes over every cell, no hierarchy. */
    iso_mesh mesh;
    iso_mesh_init(&mesh);
    iso_extract_stats full;
    iso_error err;
    double full_best = NAN;
    memset(&full, 0, sizeof full);
    for (int r = 0; baselines && r < repeat; r++) {
        if (iso_extract_full_scan(s.vol, level, ISO_SPACE_WORLD, &mesh, &full, &err)) {
            srv_close(&s);
            free(tolerances);
            return srv_fail("bench: %s", err.message);
        }
        if (!(full.extract_ms >= full_best))
            full_best = full.extract_ms;
    }
    iso_mesh_free(&mesh);

    bench_row *rows = calloc(count, sizeof *rows);
    int status = rows ? 0 : srv_fail("bench: out of memory");
    for (size_t i = 0; status == 0 && i < count; i++) {
        rows[i].tolerance = tolerances[i];
        rows[i].best_unpruned_ms = NAN;
        status = (baselines && run(s.tree, level, tolerances[i], 1, opt.threads, repeat, &rows[i].unpruned,
                                   &rows[i].best_unpruned_ms)) ||
                 run(s.tree, level, tolerances[i], 0, opt.threads, repeat, &rows[i].pruned, &rows[i].best_pruned_ms);
    }
    if (status == 0) {
        const iso_volume *v = s.vol;
        printf("%s at level %g: %zux%zux%zu %s, hierarchy %zu bytes (volume %zu), built in %.1f ms\n",
               opt.path, level, v->dims[0], v->dims[1], v->dims[2], iso_vol_type_name(v->type),
               iso_tree_memory(s.tree), iso_vol_count(v) * iso_vol_type_size(v->type), s.tree->build_ms);
        printf("%-16s %10s %12s %10s %12s %14s %12s\n", "tolerance", "polygons", "cells", "nodes",
               "build ms", "no min/max ms", "min/max ms");
        printf("%-16s %10zu %12zu %10s %12s %14s %12.2f\n", "marching cubes", full.triangles,
               full.cells_visited, "-", "-", "-", full_best);
        for (size_t i = 0; i < count; i++)
            printf("%-16g %10zu %12zu %10zu %12.1f %14.2f %12.2f\n", rows[i].tolerance,
                   rows[i].pruned.triangles, rows[i].pruned.cells_visited, rows[i].pruned.nodes_visited,
                   s.tree->build_ms, rows[i].best_unpruned_ms, rows[i].best_pruned_ms);
    }
    if (status == 0 && json_path) {
        json_t *list = json_array();
        for (size_t i = 0; i < count; i++)
            json_array_append_new(list, json_pack("{s:f, s:I, s:I, s:I, s:I, s:o, s:f, s:f}",
                "tolerance", rows[i].tolerance, "polygons", (json_int_t)rows[i].pruned.triangles,
                "cells_visited", (json_int_t)rows[i].pruned.cells_visited,
                "nodes_visited", (json_int_t)rows[i].pruned.nodes_visited,
                "cells_visited_without_minmax", (json_int_t)rows[i].unpruned.cells_visited,
                "extract_ms_without_minmax", maybe_real(rows[i].best_unpruned_ms),
                "extract_ms_with_minmax", rows[i].best_pruned_ms, "error_bound", rows[i].pruned.error_bound));
        const iso_volume *v = s.vol;
        json_t *doc = json_pack("{s:s, s:f, s:[I,I,I], s:I, s:I, s:f, s:i, s:{s:I, s:I, s:o}, s:o}",
            "volume", opt.path, "level", level, "dims", (json_int_t)v->dims[0], (json_int_t)v->dims[1],
            (json_int_t)v->dims[2], "hierarchy_bytes", (json_int_t)iso_tree_memory(s.tree),
            "volume_bytes", (json_int_t)(iso_vol_count(v) * iso_vol_type_size(v->type)),
            "build_ms", s.tree->build_ms, "threads", iso_parallel_threads(opt.threads),
            "marching_cubes", "polygons", (json_int_t)full.triangles,
            "cells_visited", (json_int_t)full.cells_visited, "extract_ms", maybe_real(full_best), "rows", list);
        if (!doc || json_dump_file(doc, json_path, JSON_INDENT(2) | JSON_REAL_PRECISION(8)))
            status = srv_fail("bench: cannot write %s", json_path);
        json_decref(doc);
    }
    free(rows);
    free(tolerances);
    srv_close(&s);
    return status;
}
