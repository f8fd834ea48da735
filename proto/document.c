/* document.c: the API's JSON documents, built with jansson (see document.h). */
#include "document.h"

#include <jansson.h>
#include <stdio.h>
#include <string.h>

#include "extract/extract.h"

const char *proto_status_phrase(int status)
{
    switch (status) {
    case 200: return "OK";
    case 204: return "No Content";
    case 304: return "Not Modified";
    case 400: return "Bad Request";
    case 404: return "Not Found";
    case 401: return "Unauthorized";
    case 405: return "Method Not Allowed";
    case 414: return "URI Too Long";
    case 422: return "Unprocessable Content";
    case 500: return "Internal Server Error";
    case 503: return "Service Unavailable";
    default: return "Error";
    }
}

const char *proto_value_type_name(iso_voxel_type type)
{
    static const char *const names[] = {"uint8", "int8", "uint16", "int16",
                                        "uint32", "int32", "float32", "float64"};
    return names[type];
}

/* Takes ownership of the object: dumps it compactly and releases it. */
static char *dump(json_t *root)
{
    if (!root)
        return NULL;
    char *text = json_dumps(root, JSON_COMPACT | JSON_REAL_PRECISION(17));
    json_decref(root);
    return text;
}

static json_t *triple(const double v[3])
{
    return json_pack("[fff]", v[0], v[1], v[2]);
}

/* The 4x4 index-to-world matrix, row-major, bottom row 0 0 0 1. */
static json_t *index_to_world(const iso_volume *vol)
{
    double m[3][4];
    iso_vol_affine(vol, m);
    json_t *a = json_array();
    for (int r = 0; r < 4; r++)
        for (int c = 0; c < 4; c++)
            json_array_append_new(a, json_real(r < 3 ? m[r][c] : c == 3));
    return a;
}

static json_t *volume_object(const proto_volume_doc *doc, int detail)
{
    const iso_volume *vol = doc->vol;
    json_t *levels = json_array();
    for (size_t i = 0; i < doc->level_count; i++)
        json_array_append_new(levels, json_real(doc->levels[i]));
    if (!vol) {
        json_t *summary = json_pack("{s:s, s:s, s:s, s:o}", "id", doc->id,
                                    "name", doc->name && *doc->name ? doc->name : doc->id,
                                    "modality", doc->modality ? doc->modality : "",
                                    "suggested_levels", levels);
        if (summary && doc->shard)
            json_object_set_new(summary, "shard", json_string(doc->shard));
        return summary;
    }
    json_t *o = json_pack("{s:s, s:s, s:s, s:[III], s:o, s:o, s:o, s:s, s:[ff], s:o, s:s}",
                          "id", doc->id, "name", doc->name && *doc->name ? doc->name : doc->id,
                          "modality", doc->modality ? doc->modality : "",
                          "dims", (json_int_t)vol->dims[0], (json_int_t)vol->dims[1],
                          (json_int_t)vol->dims[2],
                          "spacing", triple(vol->spacing), "origin", triple(vol->origin),
                          "index_to_world", index_to_world(vol),
                          "value_type", proto_value_type_name(vol->type),
                          "value_range", vol->value_min, vol->value_max,
                          "suggested_levels", levels, "version", doc->version);
    if (o && doc->shard)
        json_object_set_new(o, "shard", json_string(doc->shard));
    if (o && doc->segmentation) {
        json_object_set_new(o, "segments", json_integer((json_int_t)doc->segmentation->segment_count));
        json_object_set_new(o, "segmentation", json_string(doc->segmentation->source));
    }
    if (o)
        json_object_set_new(o, "orientation", json_string(doc->orientation ? doc->orientation
                                                          : vol->oriented ? "file" : "none"));
    if (!o || !detail)
        return o;
    if (vol->has_padding)
        json_object_set_new(o, "padding", json_real(vol->padding));
    json_t *counts = json_array();
    for (size_t b = 0; b < doc->histogram_bins; b++)
        json_array_append_new(counts, json_integer((json_int_t)doc->histogram[b]));
    json_object_set_new(o, "histogram", json_pack("{s:f, s:f, s:o}", "min", vol->value_min,
                                                  "max", vol->value_max, "counts", counts));
    json_object_set_new(o, "preview_tolerance", json_real(iso_preview_tolerance(vol)));
    json_object_set_new(o, "hierarchy",
                        json_pack("{s:I, s:I, s:f, s:b, s:f}", "nodes",
                                  (json_int_t)doc->hierarchy_nodes, "bytes",
                                  (json_int_t)doc->hierarchy_bytes, "ms", doc->hierarchy_ms,
                                  "from_file", doc->hierarchy_from_file, "share_of_volume",
                                  (double)doc->hierarchy_bytes /
                                      (double)(iso_vol_count(vol) * iso_vol_type_size(vol->type))));
    return o;
}

char *proto_json_volume(const proto_volume_doc *doc, int detail)
{
    return dump(volume_object(doc, detail));
}

char *proto_json_segments(const char *id, const iso_segmentation *seg)
{
    json_t *list = json_array();
    for (size_t i = 0; list && i < seg->segment_count; i++) {
        const iso_segment *s = &seg->segments[i];
        char hex[8];
        snprintf(hex, sizeof hex, "#%02x%02x%02x", (unsigned)(s->color[0] * 255 + 0.5f),
                 (unsigned)(s->color[1] * 255 + 0.5f), (unsigned)(s->color[2] * 255 + 0.5f));
        json_array_append_new(list, json_pack("{s:I, s:s, s:s, s:s, s:[f,f,f], s:s, s:I, s:f, s:I}", "number",
                                              (json_int_t)s->number, "name", s->name, "category", s->category,
                                              "type", s->type, "color", (double)s->color[0], (double)s->color[1],
                                              (double)s->color[2], "color_hex", hex, "voxels", (json_int_t)s->voxels,
                                              "volume_ml", iso_seg_volume_mm3(seg, i) / 1000, "layer",
                                              (json_int_t)s->layer));
    }
    return dump(json_pack("{s:s, s:s, s:I, s:o}", "volume", id, "source", seg->source, "layers",
                          (json_int_t)seg->layer_count, "segments", list));
}

char *proto_json_volume_list(const proto_volume_doc *docs, size_t count)
{
    json_t *list = json_array();
    for (size_t i = 0; i < count; i++)
        json_array_append_new(list, volume_object(&docs[i], 0));
    return dump(json_pack("{s:o}", "volumes", list));
}

char *proto_json_health(int ready, size_t loaded, size_t total)
{
    if (ready)
        return dump(json_pack("{s:s, s:I, s:I}", "status", "ready", "volumes", (json_int_t)loaded,
                              "in_catalog", (json_int_t)total));
    return dump(json_pack("{s:s, s:I, s:I}", "status", "loading", "loaded", (json_int_t)loaded,
                          "total", (json_int_t)total));
}

/* Problem types name the kind of failure; clients branch on them rather than on detail. */
static const char *problem_type(int status)
{
    switch (status) {
    case 400: return "urn:isoserve:problem:bad-parameter";
    case 404: return "urn:isoserve:problem:not-found";
    case 401: return "urn:isoserve:problem:unauthorized";
    case 405: return "urn:isoserve:problem:method-not-allowed";
    case 414: return "urn:isoserve:problem:uri-too-long";
    case 422: return "urn:isoserve:problem:mesh-too-large";
    case 503: return "urn:isoserve:problem:unavailable";
    default: return "urn:isoserve:problem:internal";
    }
}

char *proto_json_problem(const proto_problem *problem, const char *instance)
{
    json_t *o = json_pack("{s:s, s:s, s:i, s:s}", "type", problem_type(problem->status),
                          "title", proto_status_phrase(problem->status), "status",
                          problem->status, "detail", problem->detail);
    if (o && problem->parameter[0])
        json_object_set_new(o, "parameter", json_string(problem->parameter));
    if (o && instance)
        json_object_set_new(o, "instance", json_string(instance));
    return dump(o);
}
