/* segments.h: a segmentation's segments as one glTF binary, the all-segments request's
 * path from the hierarchy to the encoded scene (the server's segments job and the CLI's
 * `segments` command run it): extract, refuse past a limit, normals, encode and join
 * (segments.c). Thread-safe over a shared segmentation. */
#ifndef PROTO_SEGMENTS_H
#define PROTO_SEGMENTS_H

#include <stddef.h>

#include "encode.h"
#include "query.h"
#include "segment/segment.h"

typedef struct proto_segments_request {
    const iso_segmentation *segmentation;
    const size_t *which;        /* the segments' indices, in the scene's order */
    size_t count;
    iso_seg_params params;      /* smoothing, cap, space, threads (0: all cores) */
    int normals;                /* B-spline order: 0 none, 2, 3 or 4 */
    proto_format format;        /* PROTO_FORMAT_GLB (Draco) or PROTO_FORMAT_GLB_MESHOPT */
    proto_encode_options encode;
    size_t max_triangles;       /* refuse more in all (ISO_E_LIMIT); 0: no limit */
} proto_segments_request;

typedef struct proto_segments_result {
    unsigned char *bytes;       /* the glb (malloc'd) */
    size_t size;
    size_t triangles, vertices, cells_visited; /* over every segment */
    double extract_ms, normals_ms, encode_ms;  /* each step's wall time */
} proto_segments_result;

/* Returns 0 (res->bytes for the caller to free) or the failing step's ISO_E_* code, nothing
 * left allocated. */
int proto_segments_run(const proto_segments_request *req, proto_segments_result *res, iso_error *err);

#endif
