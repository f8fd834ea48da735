/* document.h: the JSON documents of the API (jansson): the collection, one volume, the
 * health and problem bodies. Builders take plain data and return a malloc'd NUL-terminated
 * string (free with free()), or NULL when memory runs out. No sockets, no globals. */
#ifndef PROTO_DOCUMENT_H
#define PROTO_DOCUMENT_H

#include <stddef.h>
#include <stdint.h>

#include "query.h"
#include "segment/segment.h"
#include "volume/volume.h"

/* What the API says about one volume. Strings are borrowed. */
typedef struct proto_volume_doc {
    const char *id, *name, *modality;
    const char *version;          /* changes whenever the samples do (ETag base) */
    const iso_volume *vol;        /* dims, type, range, geometry; NULL: a catalog entry not
                                     loaded here (a summary: id, name, modality, levels, shard) */
    const char *shard;            /* the replica that preloads it (sharded), or NULL */
    const char *orientation;      /* who placed the axes in the patient: "file", "catalog",
                                     "none" (identity by convention); NULL with vol NULL */
    const double *levels;         /* suggested levels */
    size_t level_count;
    /* Detail only (proto_json_volume with detail set): */
    const uint64_t *histogram;    /* histogram_bins counts over [value_min, value_max] */
    size_t histogram_bins;
    size_t hierarchy_nodes, hierarchy_bytes;
    double hierarchy_ms;          /* build, or load and verify, time */
    int hierarchy_from_file;      /* 1: read from the cache dir */
    const iso_segmentation *segmentation; /* a segmentation's, else NULL */
} proto_volume_doc;

/* One volume: id, name, modality, dims, spacing, origin, index_to_world (row-major 4x4,
 * LPS mm), orientation, value_type, value_range, suggested_levels, version; a
 * segmentation's also "segments" (how many) and "segmentation" (its source: labels,
 * seg.nrrd, dicom-seg); with detail also histogram {min, max, counts}, padding (when the
 * file names one) and hierarchy {nodes, bytes, ms, from_file}. */
char *proto_json_volume(const proto_volume_doc *doc, int detail);
/* A segmentation's segments: {"volume": id, "source", "layers", "segments": [{"number",
 * "name", "category", "type", "color" (sRGB 0..1), "color_hex" ("#rrggbb"), "voxels",
 * "volume_ml", "layer"}...]}, in the table's order. Volumes in mL: voxels times a voxel's
 * volume (segment.h). */
char *proto_json_segments(const char *id, const iso_segmentation *seg);

/* {"volumes": [...]} of the summaries (catalog summaries for docs without vol). */
char *proto_json_volume_list(const proto_volume_doc *docs, size_t count);
/* {"status": "ready", "volumes": loaded, "in_catalog": total} or
 * {"status": "loading", "loaded": entries tried, "total": total}. */
char *proto_json_health(int ready, size_t loaded, size_t total);
/* RFC 9457 body: type, title (the status's reason phrase), status, detail, and parameter
 * when the problem names one; instance is the request path (may be NULL). */
char *proto_json_problem(const proto_problem *problem, const char *instance);

/* The reason phrase of an HTTP status ("Bad Request"); "Error" for unknown ones. */
const char *proto_status_phrase(int status);
/* The API's name of a voxel type ("uint16", "float32", ...). */
const char *proto_value_type_name(iso_voxel_type type);

#endif
