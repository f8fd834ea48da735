/* cmd_bench.c: `isoserve bench`: the columns of Elber and Malzbender's Table 1 (tolerance,
 * polygons, cells visited, hierarchy build time, extraction time without and with min/max
 * pruning), full-scan marching cubes as the first row; a table on stdout, JSON on request.
 * With --distances, the tolerance ladder's geometric cost as well: each rung's symmetric
 * distance to the exact surface (mean, p99, max; iso_mesh_distance_compute) in mm and in
 * voxels of the smallest spacing, and its time against the exact path's.
 * Times are the best of --repeat runs, the rows taking turns (the build's of 1 +
 * --build-repeat, wall and CPU time): the machine is shared and noisy. A tolerance coarsens where it pays (extract.h),
 * or with --coarsen all everywhere it may; each row says how much it coarsened. */
#include <jansson.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

#include "cli.h"
#include "base/base.h"

typedef struct bench_row {
    double tolerance;
    iso_extract_stats pruned, unpruned;
    double best_pruned_ms, best_unpruned_ms;
    int measured;               /* distance below was measured (--distances, tolerance > 0) */
    iso_mesh_distance distance; /* to the exact surface, world mm */
} bench_row;

/* A figure that was not measured (baselines skipped), or is infinite (a distance to an
 * empty mesh), is null in the JSON: JSON has no infinity. */
static json_t *maybe_real(double x)
{
    return isfinite(x) ? json_real(x) : json_null();
}

/* One rung: a value, "N%" of the volume's value range, or "preview" (the client's first
 * mesh, iso_preview_tolerance). */
static int parse_tolerance(const char *tok, const iso_volume *vol, double *out)
{
    size_t len = strlen(tok);
    if (!strcmp(tok, "preview")) {
        *out = iso_preview_tolerance(vol);
        return 0;
    }
    if (len > 1 && tok[len - 1] == '%') {
        char number[64];
        if (len >= sizeof number)
            return ISO_E_ARGUMENT;
        memcpy(number, tok, len - 1);
        number[len - 1] = 0;
        double share;
        if (srv_parse_number(number, &share) || share < 0)
            return ISO_E_ARGUMENT;
        *out = share / 100 * (vol->value_max - vol->value_min);
        return 0;
    }
    return srv_parse_number(tok, out) || *out < 0 ? ISO_E_ARGUMENT : 0;
}

static int parse_tolerances(const char *text, const iso_volume *vol, double **out, size_t *count)
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
        if (parse_tolerance(tok, vol, &v[i])) {
            free(v);
            free(copy);
            return ISO_E_ARGUMENT;
        }
        i++;
    }
    free(copy);
    if (i != n) { /* an empty field: strtok_r skipped it */
        free(v);
        return ISO_E_ARGUMENT;
    }
    *out = v;
    *count = i;
    return 0;
}

/* Best of `repeat` extractions; the last one's surface stays in mesh (world mm). */
static int run(const iso_tree *tree, double level, double tolerance, int no_minmax, int threads,
               iso_coarsen coarsen, int repeat, iso_mesh *mesh, iso_extract_stats *st, double *best)
{
    iso_extract_params p = {.level = level, .tolerance = tolerance, .no_minmax = no_minmax,
                            .threads = threads, .coarsen = coarsen};
    iso_error err;
    *best = 1e300;
    for (int r = 0; r < repeat; r++) {
        if (iso_extract(tree, &p, mesh, st, &err))
            return srv_fail("bench: %s", err.message);
        if (st->extract_ms < *best)
            *best = st->extract_ms;
    }
    return 0;
}

/* CPU seconds of the whole process (all its threads) so far, in ms. */
static double cpu_ms(void)
{
    struct timespec t;
    clock_gettime(CLOCK_PROCESS_CPUTIME_ID, &t);
    return (double)t.tv_sec * 1e3 + (double)t.tv_nsec / 1e6;
}

/* The build's best wall time on the tree's thread count, of the first build (srv_open's)
 * and `repeat` more, and the best CPU time of those (on one thread the build's own work,
 * whatever else the machine runs; NAN without them). */
static int best_build(const srv_subject *s, int threads, int repeat, double *best, double *best_cpu)
{
    *best = s->tree->build_ms;
    *best_cpu = repeat ? INFINITY : NAN;
    for (int r = 0; r < repeat; r++) {
        iso_tree *tree;
        iso_error err;
        double cpu = cpu_ms();
        if (iso_tree_build(s->vol, threads, NULL, NULL, &tree, &err))
            return srv_fail("bench: %s", err.message);
        cpu = cpu_ms() - cpu;
        *best = tree->build_ms < *best ? tree->build_ms : *best;
        *best_cpu = cpu < *best_cpu ? cpu : *best_cpu;
        iso_tree_destroy(tree);
    }
    return 0;
}

/* One more run of row i's extraction, with and (baselines) without min/max pruning, its
 * best times kept; with exact (the tolerance-0 surface) also its distance to it. */
static int measure_row(const srv_subject *s, double level, int threads, iso_coarsen coarsen, int baselines,
                       const iso_mesh *exact, bench_row *row)
{
    iso_mesh mesh;
    iso_mesh_init(&mesh);
    iso_error err;
    double unpruned = NAN, pruned = NAN;
    int status = (baselines && run(s->tree, level, row->tolerance, 1, threads, coarsen, 1, &mesh, &row->unpruned,
                                   &unpruned)) ||
                 run(s->tree, level, row->tolerance, 0, threads, coarsen, 1, &mesh, &row->pruned, &pruned);
    row->best_unpruned_ms = fmin(row->best_unpruned_ms, unpruned); /* fmin skips NAN */
    row->best_pruned_ms = fmin(row->best_pruned_ms, pruned);
    if (status == 0 && exact && row->tolerance > 0) {
        /* The chain's sample spacing (mesh.h); all cores: the result does not depend on it. */
        double spacing = ISO_CHAIN_SPACING_VOXELS * iso_vol_min_spacing(s->vol);
        if (iso_mesh_distance_compute(&mesh, exact, spacing, 0, &row->distance, &err))
            status = srv_fail("bench: %s", err.message);
        row->measured = status == 0;
    }
    iso_mesh_free(&mesh);
    return status;
}

/* The exact path's time (the row at tolerance 0), NAN when the ladder has none. */
static double exact_ms(const bench_row *rows, size_t count)
{
    for (size_t i = 0; i < count; i++)
        if (rows[i].tolerance == 0)
            return rows[i].best_pruned_ms;
    return NAN;
}

static size_t exact_triangles(const bench_row *rows, size_t count)
{
    for (size_t i = 0; i < count; i++)
        if (rows[i].tolerance == 0)
            return rows[i].pruned.triangles;
    return 0;
}

static void print_table(const srv_subject *s, double level, const iso_extract_stats *full, double full_best,
                        const bench_row *rows, size_t count, double build_ms, double build_cpu_ms, int distances)
{
    const iso_volume *v = s->vol;
    size_t voxels = iso_vol_count(v), bytes = voxels * iso_vol_type_size(v->type);
    printf("%s at level %g: %zux%zux%zu %s, hierarchy %zu bytes (volume %zu, %.1f%%), built in %.1f ms, "
           "%.1f ms of CPU (%.2f and %.2f s per 10^7 voxels)\n",
           s->name, level, v->dims[0], v->dims[1], v->dims[2], iso_vol_type_name(v->type), iso_tree_memory(s->tree),
           bytes, 100.0 * (double)iso_tree_memory(s->tree) / (double)bytes, build_ms, build_cpu_ms,
           build_ms / (double)voxels * 1e4, build_cpu_ms / (double)voxels * 1e4);
    printf("%-16s %10s %12s %10s %12s %14s %12s %8s", "tolerance", "polygons", "cells", "nodes", "build ms",
           "no min/max ms", "min/max ms", "coarse %");
    if (distances)
        printf(" %7s %9s %8s %8s %8s %8s %8s %8s", "of exact", "exact/tol", "mean mm", "p99 mm", "max mm",
               "mean vx", "p99 vx", "max vx");
    printf("\n%-16s %10zu %12zu %10s %12s %14s %12.2f\n", "marching cubes", full->triangles,
           full->cells_visited, "-", "-", "-", full_best);
    double exact = exact_ms(rows, count), voxel = iso_vol_min_spacing(v);
    size_t exact_tri = exact_triangles(rows, count);
    for (size_t i = 0; i < count; i++) {
        const bench_row *r = &rows[i];
        printf("%-16g %10zu %12zu %10zu %12.1f %14.2f %12.2f %8.1f", r->tolerance, r->pruned.triangles,
               r->pruned.cells_visited, r->pruned.nodes_visited, build_ms, r->best_unpruned_ms, r->best_pruned_ms,
               100 * r->pruned.coarse_share);
        if (distances) {
            const iso_mesh_distance *d = &r->distance;
            printf(" %7.1f%% %9.2f %8.3f %8.3f %8.3f %8.3f %8.3f %8.3f",
                   exact_tri ? 100.0 * (double)r->pruned.triangles / (double)exact_tri : NAN,
                   exact / r->best_pruned_ms, d->mean, d->p99, d->max, d->mean / voxel, d->p99 / voxel,
                   d->max / voxel);
        }
        printf("\n");
    }
}

/* {mean, p99, max} of d divided by unit, or null when not measured. */
static json_t *distance_json(const bench_row *r, double unit)
{
    if (!r->measured)
        return json_null();
    return json_pack("{s:o, s:o, s:o}", "mean", maybe_real(r->distance.mean / unit),
                     "p99", maybe_real(r->distance.p99 / unit), "max", maybe_real(r->distance.max / unit));
}

static json_t *row_json(const srv_subject *s, const bench_row *r, double exact, size_t exact_tri)
{
    const iso_volume *v = s->vol;
    double range = v->value_max - v->value_min;
    json_t *o = json_pack("{s:f, s:I, s:I, s:I, s:I, s:o, s:f, s:f}", "tolerance", r->tolerance,
        "polygons", (json_int_t)r->pruned.triangles, "cells_visited", (json_int_t)r->pruned.cells_visited,
        "nodes_visited", (json_int_t)r->pruned.nodes_visited,
        "cells_visited_without_minmax", (json_int_t)r->unpruned.cells_visited,
        "extract_ms_without_minmax", maybe_real(r->best_unpruned_ms),
        "extract_ms_with_minmax", r->best_pruned_ms, "error_bound", r->pruned.error_bound);
    json_object_set_new(o, "share_of_range", range > 0 ? json_real(r->tolerance / range) : json_null());
    json_object_set_new(o, "share_of_exact_triangles",
                        exact_tri ? json_real((double)r->pruned.triangles / (double)exact_tri) : json_null());
    json_object_set_new(o, "exact_over_tolerance_time", maybe_real(exact / r->best_pruned_ms));
    json_object_set_new(o, "fit_error", maybe_real(r->pruned.fit_error));
    json_object_set_new(o, "coarse_share", json_real(r->pruned.coarse_share));
    json_object_set_new(o, "distance_mm", distance_json(r, 1));
    json_object_set_new(o, "distance_voxels", distance_json(r, iso_vol_min_spacing(v)));
    return o;
}

static int write_json(const char *path, const srv_subject *s, double level, int threads, iso_coarsen coarsen,
                      const iso_extract_stats *full, double full_best, const bench_row *rows, size_t count,
                      double build_ms, double build_cpu_ms)
{
    const iso_volume *v = s->vol;
    size_t voxels = iso_vol_count(v), bytes = voxels * iso_vol_type_size(v->type);
    double exact = exact_ms(rows, count);
    size_t exact_tri = exact_triangles(rows, count);
    json_t *list = json_array();
    for (size_t i = 0; i < count; i++)
        json_array_append_new(list, row_json(s, &rows[i], exact, exact_tri));
    json_t *doc = json_pack("{s:s, s:f, s:[I,I,I], s:I, s:I, s:f, s:i, s:{s:I, s:I, s:o}, s:o}",
        "volume", s->name, "level", level, "dims", (json_int_t)v->dims[0], (json_int_t)v->dims[1],
        (json_int_t)v->dims[2], "hierarchy_bytes", (json_int_t)iso_tree_memory(s->tree),
        "volume_bytes", (json_int_t)bytes, "build_ms", build_ms, "threads", iso_parallel_threads(threads),
        "marching_cubes", "polygons", (json_int_t)full->triangles,
        "cells_visited", (json_int_t)full->cells_visited, "extract_ms", maybe_real(full_best), "rows", list);
    int status = 0;
    if (doc) {
        json_object_set_new(doc, "voxels", json_integer((json_int_t)voxels));
        json_object_set_new(doc, "coarsen", json_string(coarsen == ISO_COARSEN_ALL ? "all" : "faster"));
        json_object_set_new(doc, "value_range", json_real(v->value_max - v->value_min));
        json_object_set_new(doc, "voxel_mm", json_real(iso_vol_min_spacing(v)));
        json_object_set_new(doc, "preview_tolerance", json_real(iso_preview_tolerance(v)));
        json_object_set_new(doc, "build_s_per_1e7_voxels", json_real(build_ms / (double)voxels * 1e4));
        json_object_set_new(doc, "build_cpu_ms", maybe_real(build_cpu_ms));
        json_object_set_new(doc, "build_cpu_s_per_1e7_voxels", maybe_real(build_cpu_ms / (double)voxels * 1e4));
        json_object_set_new(doc, "hierarchy_percent", json_real(100.0 * (double)iso_tree_memory(s->tree) / (double)bytes));
    }
    if (!doc || json_dump_file(doc, path, JSON_INDENT(2) | JSON_REAL_PRECISION(8)))
        status = srv_fail("bench: cannot write %s", path);
    json_decref(doc);
    return status;
}

/* Row 0 of the table: marching cubes over every cell, no hierarchy. */
static int full_scan(const srv_subject *s, double level, int repeat, int baselines, iso_extract_stats *full,
                     double *best)
{
    iso_mesh mesh;
    iso_mesh_init(&mesh);
    iso_error err;
    *best = NAN;
    memset(full, 0, sizeof *full);
    for (int r = 0; baselines && r < repeat; r++) {
        if (iso_extract_full_scan(s->vol, level, ISO_SPACE_WORLD, &mesh, full, &err)) {
            iso_mesh_free(&mesh);
            return srv_fail("bench: %s", err.message);
        }
        if (!(full->extract_ms >= *best))
            *best = full->extract_ms;
    }
    iso_mesh_free(&mesh);
    return 0;
}

enum {
    BENCH_LEVEL, BENCH_TOLERANCES, BENCH_JSON, BENCH_REPEAT, BENCH_BUILD_REPEAT, BENCH_THREADS, BENCH_NO_BASELINES,
    BENCH_DISTANCES, BENCH_RESAMPLE, BENCH_COARSEN, BENCH_OPTIONS
};
static const srv_option bench_options[BENCH_OPTIONS] = {
    [BENCH_LEVEL] = {"--level", "L", "the iso-level (required)"},
    [BENCH_TOLERANCES] = {"--tolerances", "LIST", "values, N% of the value range or preview, comma-separated"},
    [BENCH_JSON] = {"--json", "FILE", "also write the results as JSON"},
    [BENCH_REPEAT] = {"--repeat", "N", "runs per measurement, the best kept, 1..1000 (default 3)"},
    [BENCH_BUILD_REPEAT] = {"--build-repeat", "N", "builds timed beyond the first, 0..100 (default 1)"},
    [BENCH_THREADS] = {"--threads", "N", "threads of the build and of exact extraction (default: all cores)"},
    [BENCH_NO_BASELINES] = {"--no-baselines", NULL, "skip the full-scan and unpruned runs"},
    [BENCH_DISTANCES] = {"--distances", NULL, "add each tolerance's distance to the exact surface"},
    [BENCH_RESAMPLE] = {"--resample", "WxHxD", "box-filter the volume to these dims first (or N for NxNxN)"},
    [BENCH_COARSEN] = {"--coarsen", "WHEN", "faster: where coarse units beat the exact path (default); all: fewest "
                       "triangles"},
};

static int srv_cmd_bench(int argc, char **argv);
const srv_command srv_bench_command = {
    "bench", "VOLUME --level L [options]",
    "Times the build and extraction at each tolerance against the full scan, and prints a table.",
    bench_options, BENCH_OPTIONS, 1, srv_cmd_bench};

static int srv_cmd_bench(int argc, char **argv)
{
    srv_open_options opt = {.want_tree = 1};
    double level = 0, *tolerances = NULL;
    size_t count = 0;
    int have_level = 0, repeat = 3, baselines = 1, distances = 0, build_repeat = 1, at = 0, arg;
    iso_coarsen coarsen = ISO_COARSEN_WHERE_FASTER;
    const char *json_path = NULL, *tol_text = "0,6,10,15,25,50,75,100,200,300,400,500", *value;
    srv_keep_freed_memory(); /* the server's allocator, as bench_peer tunes VTK's */
    while ((arg = srv_next_arg(&srv_bench_command, argc, argv, &at, &value)) != SRV_ARG_END) {
        switch (arg) {
        case SRV_ARG_HELP: return 0;
        case SRV_ARG_ERROR: return 1;
        case BENCH_LEVEL:
            if (srv_parse_number(value, &level))
                return srv_fail("bench: --level '%s' is not a finite number", value);
            have_level = 1;
            break;
        case BENCH_TOLERANCES: tol_text = value; break;
        case BENCH_JSON: json_path = value; break;
        case BENCH_REPEAT:
            repeat = atoi(value);
            if (repeat < 1 || repeat > 1000)
                return srv_fail("bench: --repeat must be 1..1000");
            break;
        case BENCH_BUILD_REPEAT:
            build_repeat = atoi(value);
            if (build_repeat < 0 || build_repeat > 100)
                return srv_fail("bench: --build-repeat must be 0..100");
            break;
        case BENCH_RESAMPLE: opt.resample = value; break;
        case BENCH_THREADS:
            if (srv_parse_threads("bench", value, &opt.threads))
                return 1;
            break;
        case BENCH_NO_BASELINES: baselines = 0; break;
        case BENCH_DISTANCES: distances = 1; break;
        case BENCH_COARSEN:
            if (srv_parse_coarsen("bench", value, &coarsen))
                return 1;
            break;
        default: /* SRV_ARG_OPERAND */
            if (opt.path)
                return srv_fail("bench: unexpected argument '%s' (one VOLUME)", value);
            opt.path = value;
        }
    }
    if (!opt.path || !have_level)
        return srv_fail("bench: usage: isoserve bench %s (isoserve bench --help lists the options)",
                        srv_bench_command.synopsis);
    srv_subject s;
    if (srv_open(&opt, &s))
        return 1;
    if (parse_tolerances(tol_text, s.vol, &tolerances, &count)) {
        srv_close(&s);
        return srv_fail("bench: --tolerances '%s': expected numbers >= 0, N%% of the value range or "
                        "'preview', separated by commas", tol_text);
    }
    iso_extract_stats full;
    double full_best, build_ms = 0, build_cpu_ms = 0;
    bench_row *rows = calloc(count, sizeof *rows);
    iso_mesh exact;
    iso_mesh_init(&exact);
    iso_extract_stats exact_stats;
    double exact_best;
    int status = rows ? 0 : srv_fail("bench: out of memory");
    if (status == 0)
        status = best_build(&s, opt.threads, build_repeat, &build_ms, &build_cpu_ms) ||
                 full_scan(&s, level, repeat, baselines, &full, &full_best) ||
                 (distances && run(s.tree, level, 0, 0, opt.threads, coarsen, 1, &exact, &exact_stats, &exact_best));
    for (size_t i = 0; status == 0 && i < count; i++) {
        rows[i].tolerance = tolerances[i];
        rows[i].best_unpruned_ms = rows[i].best_pruned_ms = NAN;
    }
    /* The rows take turns, so that a change in the machine's load falls on all of them:
     * their ratios are what the bench is read for. */
    for (int r = 0; status == 0 && r < repeat; r++)
        for (size_t i = 0; status == 0 && i < count; i++)
            status = measure_row(&s, level, opt.threads, coarsen, baselines,
                                 distances && r == repeat - 1 ? &exact : NULL, &rows[i]);
    if (status == 0)
        print_table(&s, level, &full, full_best, rows, count, build_ms, build_cpu_ms, distances);
    if (status == 0 && json_path)
        status = write_json(json_path, &s, level, opt.threads, coarsen, &full, full_best, rows, count, build_ms, build_cpu_ms);
    iso_mesh_free(&exact);
    free(rows);
    free(tolerances);
    srv_close(&s);
    return status;
}
