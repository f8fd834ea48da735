/* query.c: parsing and validating mesh request parameters (see query.h). */
#include "query.h"

#include <errno.h>
#include <math.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <strings.h>

#include "encode.h"
#include "mesh/mesh.h"

int proto_problem_set(proto_problem *problem, int status, const char *parameter,
                      const char *fmt, ...)
{
    if (!problem)
        return -1;
    problem->status = status;
    snprintf(problem->parameter, sizeof problem->parameter, "%s", parameter ? parameter : "");
    va_list ap;
    va_start(ap, fmt);
    vsnprintf(problem->detail, sizeof problem->detail, fmt, ap);
    va_end(ap);
    return -1;
}

/* Values are echoed in problem details; long or odd ones are cut and flagged. */
static const char *shown(const char *value, char *buf, size_t size)
{
    size_t n = 0;
    for (const char *c = value; *c && n + 4 < size; c++)
        buf[n++] = (*c >= 0x20 && *c < 0x7f && *c != '"') ? *c : '?';
    buf[n] = '\0';
    if (strlen(value) >= size - 4)
        snprintf(buf + n, size - n, "...");
    return buf;
}

/* A decimal number, whole string: digits, sign, point, exponent. strtod alone would also
 * take hex, "inf", "nan" and leading blanks, which a URL should not carry. */
static int parse_decimal(const char *key, const char *value, double *out, proto_problem *problem)
{
    char buf[40];
    if (!value || !*value)
        return proto_problem_set(problem, 400, key, "%s needs a value, e.g. %s=100", key, key);
    if (!strcasecmp(value, "nan") || !strcasecmp(value, "inf") || !strcasecmp(value, "+inf") ||
        !strcasecmp(value, "-inf") || !strcasecmp(value, "infinity") ||
        !strcasecmp(value, "-infinity"))
        return proto_problem_set(problem, 400, key, "%s must be a finite number, not \"%s\"",
                                 key, shown(value, buf, sizeof buf));
    if (strspn(value, "0123456789+-.eE") != strlen(value))
        return proto_problem_set(problem, 400, key, "%s is not a number: \"%s\"", key,
                                 shown(value, buf, sizeof buf));
    char *end;
    errno = 0;
    double v = strtod(value, &end);
    if (end == value || *end)
        return proto_problem_set(problem, 400, key, "%s is not a number: \"%s\"", key,
                                 shown(value, buf, sizeof buf));
    if (errno == ERANGE || !isfinite(v))
        return proto_problem_set(problem, 400, key, "%s must be a finite number, not \"%s\"",
                                 key, shown(value, buf, sizeof buf));
    *out = v;
    return 0;
}

/* A whole number in [min, max]. */
static int parse_count(const char *key, const char *value, unsigned long min, unsigned long max,
                       unsigned long *out, proto_problem *problem)
{
    char buf[40];
    if (!value || !*value)
        return proto_problem_set(problem, 400, key, "%s needs a value", key);
    if (strspn(value, "0123456789") != strlen(value) || strlen(value) > 12)
        return proto_problem_set(problem, 400, key, "%s must be a whole number from %lu to %lu, not \"%s\"",
                                 key, min, max, shown(value, buf, sizeof buf));
    unsigned long v = strtoul(value, NULL, 10);
    if (v < min || v > max)
        return proto_problem_set(problem, 400, key, "%s must be from %lu to %lu, not %lu", key,
                                 min, max, v);
    *out = v;
    return 0;
}

static const char *const format_names[PROTO_FORMAT_COUNT] = {"draco", "glb", "ply", "stl",
                                                             "glb-meshopt", "glb-plain"};
static const char *const format_types[PROTO_FORMAT_COUNT] = {
    "application/x-draco", "model/gltf-binary", "application/x-ply", "model/stl",
    "model/gltf-binary", "model/gltf-binary"};
static const char *const format_extensions[PROTO_FORMAT_COUNT] = {"drc", "glb", "ply", "stl",
                                                                  "glb", "glb"};

const char *proto_format_name(proto_format format) { return format_names[format]; }
const char *proto_format_content_type(proto_format format) { return format_types[format]; }
const char *proto_format_extension(proto_format format) { return format_extensions[format]; }

/* The parameters, in the order the key lists them. */
enum { P_LEVEL, P_TOLERANCE, P_NORMALS, P_FORMAT, P_QP, P_QN, P_SPEED, P_BUDGET, P_CAP, P_MEASURES,
       P_DISTANCE, P_SMOOTHING, P_MIN_COMPONENT, P_COUNT };
static const char *const param_names[P_COUNT] = {"level", "tolerance", "normals", "format",
                                                 "qp", "qn", "speed", "budget", "cap",
                                                 "measures", "distance", "smoothing", "min_component"};

static int parse_one(int which, const char *value, proto_mesh_request *out, proto_problem *problem)
{
    const char *key = param_names[which];
    char buf[40];
    unsigned long n;
    switch (which) {
    case P_LEVEL:
        if (parse_decimal(key, value, &out->level, problem))
            return -1;
        if (fabs(out->level) > PROTO_VALUE_MAX)
            return proto_problem_set(problem, 400, key, "level must be within +-%g", PROTO_VALUE_MAX);
        out->level += 0.0;
        return 0;
    case P_TOLERANCE:
    case P_DISTANCE:
    case P_MIN_COMPONENT: {
        double *v = which == P_TOLERANCE ? &out->tolerance : which == P_DISTANCE ? &out->distance
                                                                                 : &out->min_component;
        if (parse_decimal(key, value, v, problem))
            return -1;
        if (!(*v >= 0) || *v > PROTO_TOLERANCE_MAX)
            return proto_problem_set(problem, 400, key, "%s must be from 0 to %g, not %s", key,
                                     PROTO_TOLERANCE_MAX, shown(value, buf, sizeof buf));
        *v += 0.0; /* -0 and 0 are one request */
        return 0;
    }
    case P_SMOOTHING:
        if (parse_decimal(key, value, &out->smoothing, problem))
            return -1;
        if (!(out->smoothing >= 0) || out->smoothing > PROTO_SMOOTHING_MAX)
            return proto_problem_set(problem, 400, key, "smoothing must be from 0 to %g mm, not %s",
                                     PROTO_SMOOTHING_MAX, shown(value, buf, sizeof buf));
        out->smoothing += 0.0;
        return 0;
    case P_NORMALS:
        out->normals = value ? iso_normals_order_from_name(value) : -1;
        if (out->normals < 0)
            return proto_problem_set(problem, 400, key,
                                     "normals must be none, trilinear, triquadratic or tricubic, not \"%s\"",
                                     shown(value ? value : "", buf, sizeof buf));
        return 0;
    case P_FORMAT:
        for (int f = 0; f < PROTO_FORMAT_COUNT; f++)
            if (value && !strcmp(value, format_names[f])) {
                out->format = (proto_format)f;
                return 0;
            }
        return proto_problem_set(problem, 400, key, "format must be draco, glb, glb-meshopt, glb-plain, ply or stl, not \"%s\"",
                                 shown(value ? value : "", buf, sizeof buf));
    case P_CAP:
    case P_MEASURES:
        if (value && (!strcmp(value, "true") || !strcmp(value, "false"))) {
            *(which == P_CAP ? &out->cap : &out->measures) = value[0] == 't';
            return 0;
        }
        return proto_problem_set(problem, 400, key, "%s must be true or false, not \"%s\"", key,
                                 shown(value ? value : "", buf, sizeof buf));
    case P_QP:
        if (parse_count(key, value, PROTO_POSITION_BITS_MIN, PROTO_POSITION_BITS_MAX, &n, problem))
            return -1;
        out->position_bits = (int)n;
        return 0;
    case P_QN:
        if (parse_count(key, value, PROTO_NORMAL_BITS_MIN, PROTO_NORMAL_BITS_MAX, &n, problem))
            return -1;
        out->normal_bits = (int)n;
        return 0;
    case P_SPEED:
        if (value && !strcmp(value, "auto")) {
            out->speed = PROTO_DRACO_SPEED_AUTO;
            return 0;
        }
        if (value && strspn(value, "0123456789") != strlen(value))
            return proto_problem_set(problem, 400, key, "speed must be auto or a whole number "
                                     "from %d to %d, not \"%s\"", PROTO_DRACO_SPEED_MIN,
                                     PROTO_DRACO_SPEED_MAX, shown(value, buf, sizeof buf));
        if (parse_count(key, value, PROTO_DRACO_SPEED_MIN, PROTO_DRACO_SPEED_MAX, &n, problem))
            return -1;
        out->speed = (int)n;
        return 0;
    case P_BUDGET:
    default:
        if (parse_count(key, value, 1, PROTO_BUDGET_MAX, &n, problem))
            return -1;
        out->budget = (uint32_t)n;
        return 0;
    }
}

/* The parameters one route takes: the level's mesh, a segment's, or every segment's. */
typedef enum route_kind { ROUTE_LEVEL, ROUTE_SEGMENT, ROUTE_SEGMENTS } route_kind;

static int takes(route_kind route, int which)
{
    if (route == ROUTE_LEVEL)
        return which != P_SMOOTHING;
    if (which == P_LEVEL || which == P_TOLERANCE || which == P_BUDGET)
        return 0;
    return route == ROUTE_SEGMENT || (which != P_DISTANCE && which != P_MEASURES && which != P_MIN_COMPONENT);
}

static int parse_params(route_kind route, const proto_param *params, size_t count, proto_mesh_request *out,
                        int seen[P_COUNT], proto_problem *problem)
{
    static const char *const taken[] = {
        "level, tolerance, normals, format, qp, qn, speed, budget, cap, measures, distance and min_component",
        "normals, format, qp, qn, speed, cap, measures, distance, smoothing and min_component",
        "normals, format (glb or glb-meshopt), qp, qn, speed, cap and smoothing"};
    char buf[40];
    *out = (proto_mesh_request){.normals = PROTO_NORMALS_DEFAULT,
                                .format = route == ROUTE_SEGMENTS ? PROTO_FORMAT_GLB : PROTO_FORMAT_DRACO,
                                .position_bits = PROTO_POSITION_BITS_DEFAULT,
                                .normal_bits = PROTO_NORMAL_BITS_DEFAULT,
                                .speed = PROTO_DRACO_SPEED_DEFAULT, .distance = -1};
    for (size_t i = 0; i < count; i++) {
        const char *key = params[i].key ? params[i].key : "";
        int which = 0;
        while (which < P_COUNT && strcmp(key, param_names[which]))
            which++;
        if (which < P_COUNT && !takes(route, which))
            return proto_problem_set(problem, 400, key,
                                     "%s does not apply here: a segment's surface is its indicator's 0.5 "
                                     "iso-surface; this route takes %s", key, taken[route]);
        if (which == P_COUNT)
            return proto_problem_set(problem, 400, NULL,
                                     "unknown parameter \"%s\"; %s takes %s",
                                     shown(key, buf, sizeof buf), route == ROUTE_LEVEL ? "the mesh" : "this route",
                                     taken[route]);
        if (seen[which]++)
            return proto_problem_set(problem, 400, key, "%s is given more than once", key);
        if (parse_one(which, params[i].value, out, problem))
            return -1;
    }
    if (route == ROUTE_SEGMENTS && out->format != PROTO_FORMAT_GLB && out->format != PROTO_FORMAT_GLB_MESHOPT)
        return proto_problem_set(problem, 400, "format", "every segment comes as one glTF scene: format must be "
                                 "glb (Draco) or glb-meshopt, not %s", format_names[out->format]);
    return 0;
}

int proto_segment_request_parse(const proto_param *params, size_t count, int all, proto_mesh_request *out,
                                proto_problem *problem)
{
    int seen[P_COUNT] = {0};
    return parse_params(all ? ROUTE_SEGMENTS : ROUTE_SEGMENT, params, count, out, seen, problem);
}

int proto_mesh_request_parse(const proto_param *params, size_t count, proto_mesh_request *out,
                             proto_problem *problem)
{
    int seen[P_COUNT] = {0};
    if (parse_params(ROUTE_LEVEL, params, count, out, seen, problem))
        return -1;
    if (!seen[P_LEVEL])
        return proto_problem_set(problem, 400, "level", "level is required, e.g. ?level=700");
    if (seen[P_DISTANCE] && seen[P_BUDGET])
        return proto_problem_set(problem, 400, "distance", "distance and budget each choose the "
                                 "mesh; give one of them");
    return 0;
}

size_t proto_mesh_request_key(const proto_mesh_request *req, char *buf, size_t size)
{
    /* PLY and STL are lossless: Draco's options (speed, qp, qn) do not change their bytes,
     * so the key spells them at their defaults (qn as 0) and "format=ply&qp=11" hits
     * "format=ply"'s entry; meshopt takes qp and qn but no speed. The key stays a query
     * that parses back to itself. */
    int draco = req->format == PROTO_FORMAT_DRACO || req->format == PROTO_FORMAT_GLB;
    int quantized = draco || req->format == PROTO_FORMAT_GLB_MESHOPT;
    char speed[8] = "auto";
    if (draco && req->speed != PROTO_DRACO_SPEED_AUTO)
        snprintf(speed, sizeof speed, "%d", req->speed);
    int n = snprintf(buf, size,
                     "level=%.17g&tolerance=%.17g&normals=%s&format=%s&qp=%d&qn=%d&speed=%s&budget=%u&cap=%s"
                     "&measures=%s",
                     req->level, req->tolerance, iso_normals_name(req->normals),
                     format_names[req->format], quantized ? req->position_bits : PROTO_POSITION_BITS_DEFAULT,
                     quantized && req->normals ? req->normal_bits : 0, speed, req->budget,
                     req->cap ? "true" : "false", req->measures ? "true" : "false");
    /* distance is spelt only when asked: keys of requests without it stay as they were. */
    if (n >= 0 && req->distance >= 0) {
        size_t used = (size_t)n < size ? (size_t)n : size;
        int more = snprintf(buf ? buf + used : NULL, size - used, "&distance=%.17g", req->distance);
        n = more < 0 ? more : n + more;
    }
    if (n >= 0 && req->min_component > 0) {
        size_t used = (size_t)n < size ? (size_t)n : size;
        int more = snprintf(buf ? buf + used : NULL, size - used, "&min_component=%.17g", req->min_component);
        n = more < 0 ? more : n + more;
    }
    if (n >= 0 && req->smoothing > 0) {
        size_t used = (size_t)n < size ? (size_t)n : size;
        int more = snprintf(buf ? buf + used : NULL, size - used, "&smoothing=%.17g", req->smoothing);
        n = more < 0 ? more : n + more;
    }
    return n < 0 ? 0 : (size_t)n;
}
