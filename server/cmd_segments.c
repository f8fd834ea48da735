/* cmd_segments.c: `isoserve segments`: a segmentation's segments (a label map, a .seg.nrrd,
 * a DICOM SEG) with their surfaces: a table or a JSON report (per segment its name,
 * colour, voxels, volume, triangles, cells visited; the extraction of all of them timed,
 * best of --repeat), and the surfaces to a file: every segment as one glb scene, or one
 * segment (--segment N) in any format, through the server's own pipelines. */
#include <jansson.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "cli.h"
#include "pipeline.h"
#include "segments.h"
#include "segment/segment.h"

typedef struct segments_options {
    const char *path, *descriptions, *out;
    long number;           /* --segment: one segment by number, else -1 */
    iso_seg_params params;
    int repeat, as_json, normals;
} segments_options;

enum {
    SG_LABELS_FILE, SG_SEGMENT, SG_CAP, SG_SMOOTHING, SG_JSON, SG_OUT, SG_NORMALS, SG_THREADS, SG_REPEAT,
    SG_INDEX_SPACE, SG_OPTIONS
};
static const srv_option segments_options_table[SG_OPTIONS] = {
    [SG_LABELS_FILE] = {"--labels-file", "FILE", "names and colours of a label map's values (ITK-SNAP's, or IDX NAME lines)"},
    [SG_SEGMENT] = {"--segment", "N", "segment number N alone, through the mesh pipeline"},
    [SG_CAP] = {"--cap", NULL, "close the surfaces at the volume's border (half a voxel past it)"},
    [SG_SMOOTHING] = {"--smoothing", "MM", "a Gaussian of MM mm on each indicator before marching"},
    [SG_JSON] = {"--json", NULL, "print each segment's voxels, volume, triangles, cells visited as JSON"},
    [SG_OUT] = {"-o", "OUT", "every segment as one .glb or .meshopt.glb; with --segment, any mesh format"},
    [SG_NORMALS] = {"--normals", "ORDER", "none, trilinear, triquadratic or tricubic (default)"},
    [SG_THREADS] = {"--threads", "N", "threads sharing the segments (default: all cores)"},
    [SG_REPEAT] = {"--repeat", "N", "time the extraction of every segment N times, report the best"},
    [SG_INDEX_SPACE] = {"--index-space", NULL, "positions in voxel indices, not world millimetres"},
};

static int srv_cmd_segments(int argc, char **argv);
const srv_command srv_segments_command = {
    "segments", "SEGMENTATION [options]",
    "every segment of a label map, a .seg.nrrd or a DICOM SEG as its own surface (SEGMENTATION: one of those, "
    "a DICOM SEG as its file or its folder beside the series it references)",
    segments_options_table, SG_OPTIONS, 1, srv_cmd_segments};

static int parse(int argc, char **argv, segments_options *o)
{
    *o = (segments_options){.number = -1, .repeat = 1, .normals = 4};
    const char *value;
    int i = 0, arg;
    while ((arg = srv_next_arg(&srv_segments_command, argc, argv, &i, &value)) != SRV_ARG_END) {
        double v;
        switch (arg) {
        case SRV_ARG_HELP: return -1;
        case SRV_ARG_ERROR: return 1;
        case SG_JSON: o->as_json = 1; break;
        case SG_CAP: o->params.cap = 1; break;
        case SG_INDEX_SPACE: o->params.space = ISO_SPACE_INDEX; break;
        case SG_OUT: o->out = value; break;
        case SG_LABELS_FILE: o->descriptions = value; break;
        case SG_NORMALS:
            if ((o->normals = iso_normals_order_from_name(value)) < 0)
                return srv_fail("segments: --normals takes none, trilinear, triquadratic or tricubic");
            break;
        case SG_THREADS:
            if (srv_parse_threads("segments", value, &o->params.threads))
                return 1;
            break;
        case SG_SEGMENT:
            if (srv_parse_number(value, &v) || v < 0 || v > 4294967295.0 || v != (long)v)
                return srv_fail("segments: --segment takes a segment number");
            o->number = (long)v;
            break;
        case SG_SMOOTHING:
            if (srv_parse_number(value, &v) || v < 0 || v > 100)
                return srv_fail("segments: --smoothing takes millimetres, 0..100");
            o->params.smoothing = v;
            break;
        case SG_REPEAT:
            if (srv_parse_number(value, &v) || v < 1 || v > 1000 || v != (int)v)
                return srv_fail("segments: --repeat takes 1..1000");
            o->repeat = (int)v;
            break;
        default: /* SRV_ARG_OPERAND */
            if (o->path)
                return srv_fail("segments: unexpected argument '%s' (one SEGMENTATION)", value);
            o->path = value;
        }
    }
    if (!o->path)
        return srv_fail("segments: usage: isoserve segments %s (isoserve segments --help lists the options)",
                        srv_segments_command.synopsis);
    return 0;
}

/* Every segment's surface, best wall time of `repeat`; meshes and stats of the last run. */
static int extract_all(const iso_segmentation *seg, const segments_options *o, iso_mesh *meshes,
                       iso_extract_stats *stats, double *best, double *runs)
{
    iso_error err;
    *best = 0;
    for (int r = 0; r < o->repeat; r++) {
        double t0 = iso_clock_ms();
        if (iso_seg_extract_all(seg, NULL, 0, &o->params, meshes, stats, &err))
            return srv_fail("%s: %s", o->path, err.message);
        runs[r] = iso_clock_ms() - t0;
        *best = r == 0 || runs[r] < *best ? runs[r] : *best;
    }
    return 0;
}

static json_t *report(const iso_segmentation *seg, const segments_options *o, const iso_mesh *meshes,
                      const iso_extract_stats *stats, double best, const double *runs, double load_ms, double build_ms)
{
    const iso_volume *vol = seg->layers[0].vol;
    json_t *list = json_array(), *times = json_array();
    size_t triangles = 0, cells = 0;
    for (size_t s = 0; s < seg->segment_count; s++) {
        const iso_segment *sg = &seg->segments[s];
        json_array_append_new(list, json_pack("{s:I, s:s, s:[f,f,f], s:I, s:f, s:I, s:I, s:I, s:f}",
                                              "number", (json_int_t)sg->number, "name", sg->name, "color",
                                              (double)sg->color[0], (double)sg->color[1], (double)sg->color[2],
                                              "voxels", (json_int_t)sg->voxels, "volume_ml",
                                              iso_seg_volume_mm3(seg, s) / 1000, "triangles",
                                              (json_int_t)meshes[s].triangle_count, "vertices",
                                              (json_int_t)meshes[s].vertex_count, "cells_visited",
                                              (json_int_t)stats[s].cells_visited, "extract_ms", stats[s].extract_ms));
        triangles += meshes[s].triangle_count;
        cells += stats[s].cells_visited;
    }
    for (int r = 0; r < o->repeat; r++)
        json_array_append_new(times, json_real(runs[r]));
    return json_pack("{s:s, s:s, s:[I,I,I], s:s, s:I, s:I, s:o, s:f, s:o, s:I, s:I, s:I, s:f, s:f, s:b, s:f}",
                     "segmentation", o->path, "source", seg->source, "dims", (json_int_t)vol->dims[0],
                     (json_int_t)vol->dims[1], (json_int_t)vol->dims[2], "type", iso_vol_type_name(vol->type),
                     "layers", (json_int_t)seg->layer_count, "threads",
                     (json_int_t)iso_parallel_threads(o->params.threads), "segments", list, "extract_ms", best,
                     "extract_ms_runs", times, "triangles", (json_int_t)triangles, "cells_visited",
                     (json_int_t)cells, "voxels", (json_int_t)iso_vol_count(vol), "load_ms", load_ms, "build_ms",
                     build_ms, "cap", o->params.cap, "smoothing", o->params.smoothing);
}

/* -o for every segment: one glb scene (.glb Draco, .meshopt.glb meshopt). */
static int write_scene(const iso_segmentation *seg, const segments_options *o)
{
    int format = srv_format_of_path(o->out);
    if (format != PROTO_FORMAT_GLB && format != PROTO_FORMAT_GLB_MESHOPT)
        return srv_fail("%s: every segment goes into one .glb or .meshopt.glb (--segment N for one in another format)",
                        o->out);
    size_t *which = malloc((seg->segment_count ? seg->segment_count : 1) * sizeof *which);
    if (!which)
        return srv_fail("out of memory");
    for (size_t s = 0; s < seg->segment_count; s++)
        which[s] = s;
    proto_segments_request req = {.segmentation = seg, .which = which, .count = seg->segment_count,
                                  .params = o->params, .normals = o->normals, .format = (proto_format)format};
    proto_encode_options_init(&req.encode);
    proto_segments_result res;
    iso_error err;
    int rc = proto_segments_run(&req, &res, &err);
    free(which);
    if (rc)
        return srv_fail("%s: %s", o->path, err.message);
    rc = srv_write_file(res.bytes, res.size, o->out);
    free(res.bytes);
    return rc;
}

/* --segment N: that segment alone, in the format the output names, through the mesh
 * request's pipeline. */
static int one_segment(const iso_segmentation *seg, const segments_options *o)
{
    long s = iso_seg_find(seg, (uint32_t)o->number);
    if (s < 0)
        return srv_fail("%s: no segment numbered %ld", o->path, o->number);
    int format = srv_format_of_path(o->out);
    if (format < 0)
        return srv_fail("%s: unknown output format (use .ply, .stl, .obj, .drc, .glb or .meshopt.glb)", o->out);
    proto_pipeline_request req;
    proto_pipeline_request_init(&req);
    req.segmentation = seg;
    req.segment = (size_t)s;
    req.smoothing = o->params.smoothing;
    req.extract.cap = o->params.cap;
    req.extract.space = o->params.space;
    req.extract.threads = o->params.threads;
    req.normals = o->normals;
    req.measure = 1;
    req.format = (proto_format)format;
    proto_pipeline_result res;
    iso_error err;
    if (proto_pipeline_run(seg->layers[seg->segments[s].layer].tree, NULL, &req, &res, &err))
        return srv_fail("%s: %s", o->path, err.message);
    int rc = o->out ? srv_write_file(res.bytes, res.size, o->out) : 0;
    const iso_segment *sg = &seg->segments[s];
    if (o->as_json) {
        json_t *doc = json_pack("{s:I, s:s, s:I, s:I, s:I, s:f, s:b, s:f, s:f, s:f}", "number", (json_int_t)sg->number,
                                "name", sg->name, "triangles", (json_int_t)res.stats.triangles, "vertices",
                                (json_int_t)res.stats.vertices, "cells_visited", (json_int_t)res.stats.cells_visited,
                                "extract_ms", res.extract_ms, "closed", res.census.closed, "area_mm2", res.area,
                                "enclosed_volume_mm3", res.enclosed_volume, "volume_mm3", iso_seg_volume_mm3(seg, (size_t)s));
        char *text = json_dumps(doc, JSON_COMPACT);
        puts(text);
        free(text);
        json_decref(doc);
    } else {
        printf("%u %s: %zu triangles, %zu cells visited, %.2f ms, %s, enclosed %.1f mm3 (voxels %.1f mm3)\n",
               sg->number, sg->name, res.stats.triangles, res.stats.cells_visited, res.extract_ms,
               res.census.closed ? "closed" : "open", res.enclosed_volume, iso_seg_volume_mm3(seg, (size_t)s));
    }
    proto_pipeline_result_free(&res);
    return rc;
}

static int srv_cmd_segments(int argc, char **argv)
{
    segments_options o;
    int parsed = parse(argc, argv, &o);
    if (parsed)
        return parsed < 0 ? 0 : 1; /* -1: --help was answered */
    iso_error err;
    iso_segmentation *seg;
    double t0 = iso_clock_ms();
    iso_load_options lopt = {.progress = srv_progress, .progress_context = (void *)"loading"};
    if (iso_seg_load(o.path, o.descriptions, &lopt, &seg, &err))
        return srv_fail("%s", err.message);
    double t1 = iso_clock_ms();
    if (iso_seg_build_trees(seg, 0, o.params.threads, srv_progress, (void *)"building hierarchy", &err)) {
        iso_seg_destroy(seg);
        return srv_fail("%s: %s", o.path, err.message);
    }
    double t2 = iso_clock_ms();
    iso_seg_count_voxels(seg);
    int rc = 0;
    if (o.number >= 0) {
        rc = one_segment(seg, &o);
        iso_seg_destroy(seg);
        return rc;
    }
    iso_mesh *meshes = calloc(seg->segment_count ? seg->segment_count : 1, sizeof *meshes);
    iso_extract_stats *stats = calloc(seg->segment_count ? seg->segment_count : 1, sizeof *stats);
    double *runs = calloc((size_t)o.repeat, sizeof *runs), best = 0;
    if (!meshes || !stats || !runs)
        rc = srv_fail("out of memory");
    if (!rc)
        rc = extract_all(seg, &o, meshes, stats, &best, runs);
    if (!rc && o.as_json) {
        json_t *doc = report(seg, &o, meshes, stats, best, runs, t1 - t0, t2 - t1);
        char *text = json_dumps(doc, JSON_COMPACT);
        puts(text);
        free(text);
        json_decref(doc);
    } else if (!rc) {
        printf("%s: %zu segments, all extracted in %.2f ms (best of %d, %d threads)\n", o.path, seg->segment_count,
               best, o.repeat, iso_parallel_threads(o.params.threads));
        for (size_t s = 0; s < seg->segment_count; s++)
            printf("  %5u  %-32s  #%02x%02x%02x  %10llu voxels  %9.2f mL  %8zu triangles  %9zu cells\n",
                   seg->segments[s].number, seg->segments[s].name, (unsigned)(seg->segments[s].color[0] * 255 + 0.5f),
                   (unsigned)(seg->segments[s].color[1] * 255 + 0.5f), (unsigned)(seg->segments[s].color[2] * 255 + 0.5f),
                   (unsigned long long)seg->segments[s].voxels, iso_seg_volume_mm3(seg, s) / 1000,
                   meshes[s].triangle_count, stats[s].cells_visited);
    }
    for (size_t s = 0; meshes && s < seg->segment_count; s++)
        iso_mesh_free(&meshes[s]);
    free(meshes);
    free(stats);
    free(runs);
    if (!rc && o.out)
        rc = write_scene(seg, &o);
    iso_seg_destroy(seg);
    return rc;
}
