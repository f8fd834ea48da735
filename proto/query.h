/* query.h: the mesh request's query parameters, parsed and validated without sockets.
 *
 * The server hands over the decoded (key, value) pairs of a request in arrival order; this
 * module checks each one and either fills a proto_mesh_request or says, in a proto_problem,
 * which parameter is wrong and why (the body of a 400 response). It also gives the request's
 * normalised form, the key of caches and ETags: two URLs asking for the same mesh
 * (level=700 and level=700.0, parameters in another order, defaults spelt out or not) have
 * the same key. */
#ifndef PROTO_QUERY_H
#define PROTO_QUERY_H

#include <stddef.h>
#include <stdint.h>

typedef enum proto_format {
    PROTO_FORMAT_DRACO,
    PROTO_FORMAT_GLB,
    PROTO_FORMAT_PLY,
    PROTO_FORMAT_STL,
    PROTO_FORMAT_GLB_MESHOPT,              /* glb, EXT_meshopt_compression (encode.h) */
    PROTO_FORMAT_GLB_PLAIN,                /* glb without extensions (encode.h) */
    PROTO_FORMAT_COUNT,                    /* the formats the API serves end here */
    PROTO_FORMAT_OBJ = PROTO_FORMAT_COUNT, /* OBJ text: the CLI writes it, the API does not */
    PROTO_FORMAT_NONE                      /* no encoding (pipeline.h keeps the mesh) */
} proto_format;

/* One query parameter; value is NULL for a bare key ("?level"). */
typedef struct proto_param {
    const char *key;
    const char *value;
} proto_param;

/* Limits of the parameters the API accepts. */
#define PROTO_BUDGET_MAX 100000000u  /* triangles */
#define PROTO_TOLERANCE_MAX 1e30     /* beyond this a tolerance means nothing for any volume */
#define PROTO_VALUE_MAX 1e300        /* |level| */
#define PROTO_SMOOTHING_MAX 100.0    /* mm: a segment's Gaussian sigma */

typedef struct proto_mesh_request {
    double level;
    double tolerance;      /* >= 0; default 0 */
    int normals;           /* B-spline order: 0 none, 2 trilinear, 3 triquadratic, 4 tricubic */
    proto_format format;   /* default draco */
    int position_bits;     /* qp, default 14 */
    int normal_bits;       /* qn, default 10 */
    int speed;             /* Draco speed 0..10, or PROTO_DRACO_SPEED_AUTO (-1, default) */
    uint32_t budget;       /* triangles; 0 = no budget */
    double distance;       /* geometric tolerance, mm (measured p99 both ways); -1 = none */
    int cap;               /* cap=true: closed at the volume's border; default false */
    int measures;          /* measures=true: area, enclosed volume and the edge census in the
                            * headers; they cost more than the extraction, so only on request */
    double smoothing;      /* the segment routes: Gaussian sigma in mm, 0 (default) none */
    double min_component;  /* mm3: closed components enclosing less are removed first; 0
                            * (default) none */
} proto_mesh_request;

/* What went wrong with a request, for an application/problem+json body (RFC 9457). */
typedef struct proto_problem {
    int status;            /* HTTP status */
    char parameter[32];    /* the offending query parameter, or "" */
    char detail[256];      /* one sentence for a person */
} proto_problem;

/* The default normals order of mesh requests: tricubic, the smoothest shading. */
#define PROTO_NORMALS_DEFAULT 4

/* Parses the parameters of /v1/volumes/{id}/mesh. Returns 0 and fills *out, or -1 and fills
 * *problem (status 400, the parameter, the reason: missing, not a number, not finite, out
 * of range, unknown value, unknown parameter, given twice). Safe on any input. */
int proto_mesh_request_parse(const proto_param *params, size_t count, proto_mesh_request *out,
                             proto_problem *problem);

/* Parses the parameters of /v1/volumes/{id}/segments/{n}/mesh (all = 0) or
 * /v1/volumes/{id}/segments/mesh (all = 1): the mesh's parameters but level, tolerance and
 * budget (the segment defines its surface), plus smoothing; the all-segments route takes
 * neither distance nor measures, and formats glb (its default) and glb-meshopt only.
 * Returns 0 or -1 with a 400 problem naming the parameter. */
int proto_segment_request_parse(const proto_param *params, size_t count, int all, proto_mesh_request *out,
                                proto_problem *problem);

/* The normalised form of a request ("level=700&tolerance=0&normals=tricubic&..."), every
 * parameter present, numbers printed so that they round-trip. Writes at most size bytes
 * (NUL included) and returns the length it needs, like snprintf. */
size_t proto_mesh_request_key(const proto_mesh_request *req, char *buf, size_t size);

/* "draco", "glb", "ply", "stl", "glb-meshopt"; the Content-Type and the file name
 * extension ("drc", "glb", ...) of each. */
const char *proto_format_name(proto_format format);
const char *proto_format_content_type(proto_format format);
const char *proto_format_extension(proto_format format);

/* Fills a problem (status, parameter may be NULL, printf-style detail); returns -1. */
int proto_problem_set(proto_problem *problem, int status, const char *parameter,
                      const char *fmt, ...)
#if defined(__GNUC__)
    __attribute__((format(printf, 4, 5)))
#endif
    ;

#endif
