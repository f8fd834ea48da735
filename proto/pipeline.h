/* pipeline.h: one mesh request from the hierarchy to encoded bytes, the one path that
 * the server's mesh jobs, the CLI's extract and the allocation-failure sweep all run:
 *
 *   1. extract: exact, within a value tolerance, or under a triangle budget (the ladder,
 *      then simplification when the ladder cannot meet it);
 *   2. simplify: to an explicit triangle count, when asked; or answer from the surface's
 *      simplification chain (mesh.h) for a geometric tolerance (distance) or for a budget
 *      the faithful tolerances cannot meet;
 *   3. refuse: a mesh over the caller's triangle limit stops here (ISO_E_LIMIT), before
 *      the steps that cost several times the extraction's memory;
 *   4. normals, and beside them on a thread of their own the measures (edge census, area,
 *      enclosed volume), which read only positions and indices;
 *   5. encode, in the request's format (or not at all, PROTO_FORMAT_NONE); a meshopt glb
 *      overlaps it with step 4's normals, and makes its gzip member too when asked.
 * Each step is timed. Errors are the steps' own ISO_E_* codes; ISO_E_NOMEM always leaves
 * nothing allocated behind. Thread-safe over a shared tree and volume. */
#ifndef PROTO_PIPELINE_H
#define PROTO_PIPELINE_H

#include <stddef.h>

#include "encode.h"
#include "extract/extract.h"
#include "hierarchy/tree.h"
#include "mesh/mesh.h"
#include "query.h"
#include "segment/segment.h"

typedef struct proto_pipeline_request {
    iso_extract_params extract; /* level, tolerance, cap, space, threads */
    int full_scan;              /* 1: marching cubes over every cell, no hierarchy */
    size_t budget;              /* at most this many triangles; 0: no budget */
    int budget_ladder_only;     /* 1: the tolerance ladder alone, never simplification */
    size_t simplify;            /* simplify to this many triangles; 0: no */
    double distance;            /* >= 0: the smallest chain level within this measured p99
                                 * distance, in position units; < 0 (the default): none */
    int budget_chain;           /* 1: a budget the faithful ladder cannot meet is answered
                                 * from the chain instead of a fresh simplification */
    const iso_mesh_chain *chain;/* the chain of (level, tolerance, cap, space, min_component)
                                 * when the caller has one; NULL: built here when needed.
                                 * One built with another min_component, or partial and not
                                 * covering the request (iso_mesh_chain_covers), is not used */
    int chain_partial;          /* 1: a chain built here stops at the request's level
                                 * (iso_mesh_chain_build_until; the caller may extend it);
                                 * 0: the whole chain */
    double min_component;       /* > 0: the surface's closed components enclosing less than
                                 * this many mm3 are removed before anything else is done
                                 * with it (iso_mesh_remove_components); 0: none */
    size_t max_triangles;       /* refuse a larger mesh (ISO_E_LIMIT); 0: no limit */
    int normals;                /* B-spline order: 0 none, 2, 3 or 4 */
    int measure;                /* 1: census, area, enclosed volume */
    proto_format format;        /* PROTO_FORMAT_NONE: keep the mesh, encode nothing */
    proto_encode_options encode;/* Draco and glb options */
    int gzip;                   /* 1: a meshopt glb's gzip member too (the others: ignored) */
    /* A segment's surface instead of the level's (segment.h): extract.level and tolerance
     * are then unused, cap, space and threads apply, normals come from the segment's
     * field; the chain (distance) is the segment's. No budget (a caller's rule). */
    const iso_segmentation *segmentation;
    size_t segment;             /* its index in segmentation->segments */
    double smoothing;           /* Gaussian sigma in mm, 0: none */
} proto_pipeline_request;

typedef struct proto_pipeline_result {
    iso_mesh mesh;              /* the final mesh, normals included when asked */
    unsigned char *bytes;       /* the encoded mesh (malloc'd), NULL for PROTO_FORMAT_NONE */
    size_t size;
    unsigned char *gzip;        /* its gzip member when asked (malloc'd), else NULL */
    size_t gzip_size;
    iso_extract_stats stats;    /* triangles and vertices: the final mesh's */
    iso_budget_result chosen;   /* the tolerance used; for a budget, fits and extractions;
                                 * `simplified` and `simplify` when the mesh was simplified */
    int measured;               /* the three measures below were computed */
    iso_census census;
    double area;                /* in the mesh's units squared */
    double enclosed_volume;     /* |signed volume| of a closed mesh, else 0 */
    int draco_speed;            /* the Draco speed used (auto resolved), -1 for the others */
    int chain_level;            /* the chain level answered (0: exact), -1: not from a chain */
    size_t chain_levels;        /* how many levels that chain has */
    size_t exact_triangles;     /* that chain's level 0 */
    iso_mesh_pinches pinches;   /* the answer's pinches, when from a chain */
    const char *budget_source;  /* a budget's answer: "chain" (a level of the simplification
                                 * chain) or "tolerance" (the value-tolerance ladder's mesh),
                                 * whichever fits and is closer to the exact surface by
                                 * measurement; NULL when no budget was asked */
    double budget_other_p99;    /* the measured p99 distance of the one not chosen; -1 when
                                 * there was none (the ladder did not fit) */
    double vertex_offset;       /* the chain level's move along its normals that keeps a
                                 * closed surface's volume (mesh.h), position units; 0: every
                                 * vertex is an exact-surface vertex */
    size_t faithful_triangles;  /* the mesh at the faithful tolerance has this many
                                 * triangles: the chain's count when req->chain has one,
                                 * else found here when a budget needed it */
    iso_mesh_components components; /* what min_component removed (zero when not asked);
                                 * removed_largest in the mesh's units (mm in world space) */
    int distance_measured;      /* `distance` below holds the final mesh's measured distance
                                 * from the surface of req->extract (a = that surface) */
    iso_mesh_distance distance;
    iso_mesh_chain *chain_built;/* a chain built by this run (owned; the caller may take it
                                 * and set this to NULL, else result_free destroys it) */
    /* Each step's wall time. The meshopt glb's steps overlap (normals beside the index
     * view, gzip beside the encode): normals, encode and gzip are each counted from the end
     * of the step before, so that the steps add up to the request's time. */
    double extract_ms, simplify_ms, normals_ms, measure_ms, encode_ms, gzip_ms;
} proto_pipeline_result;

/* Fills the defaults: world space, all cores, every coarse unit the tolerance allows
 * (ISO_COARSEN_ALL), no budget, tricubic normals, no measures, Draco with
 * proto_encode_options_init's options. */
void proto_pipeline_request_init(proto_pipeline_request *req);

/* Runs the steps above for tree (or vol alone when req->full_scan). On success *res owns
 * the mesh and the bytes (proto_pipeline_result_free); on failure nothing is left to free
 * and the code is the failing step's: ISO_E_ARGUMENT, ISO_E_NOMEM, ISO_E_LIMIT (over
 * req->max_triangles, the message saying both counts). */
int proto_pipeline_run(const iso_tree *tree, const iso_volume *vol,
                       const proto_pipeline_request *req, proto_pipeline_result *res,
                       iso_error *err);

/* Frees what a successful run left in res; an emptied result may be freed again. */
void proto_pipeline_result_free(proto_pipeline_result *res);

/* Extends a partial chain that req's surface built (iso_mesh_chain_extend_until to
 * `distance` or `triangles`; both unset, distance < 0 and triangles 0: the whole chain,
 * iso_mesh_chain_extend) on req->extract.threads, and measures the new moved levels' value
 * error as a build does. In place: the caller keeps every reader off `chain` meanwhile.
 * 0, ISO_E_NOMEM. */
int proto_pipeline_chain_extend(const iso_volume *vol, const proto_pipeline_request *req, iso_mesh_chain *chain,
                                double distance, size_t triangles, iso_error *err);

#endif
