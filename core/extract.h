/* extract.h: iso-surface extraction from the hierarchy, with a proven error bound.
 *
 * The guarantee: every output vertex v satisfies |f(v) - level| <= error_bound <= tolerance
 * (plus float rounding), f the trilinear interpolant of the full-resolution samples.
 * Tolerance 0 gives marching cubes' surface of the full-resolution data.
 *
 * Samples equal to the level count as below it (inside = value > level); NaN samples
 * count as below every level. */
#ifndef ISO_EXTRACT_H
#define ISO_EXTRACT_H

#include <stddef.h>

#include "error.h"
#include "mesh.h"
#include "tree.h"

typedef enum iso_space { ISO_SPACE_WORLD = 0, ISO_SPACE_INDEX = 1 } iso_space;

typedef struct iso_extract_params {
    double level;
    double tolerance;  /* >= 0, in the volume's value units */
    double fit_share;  /* share of the tolerance for the fit error, (0,1]; 0 = default 0.5 */
    int no_minmax;     /* 1: do not prune by min/max (the paper's middle time column) */
    iso_space space;   /* output positions in world mm (default) or index space */
} iso_extract_params;

typedef struct iso_extract_stats {
    size_t triangles, vertices;
    size_t nodes_visited;   /* hierarchy nodes examined, stored and on the fly */
    size_t cells_visited;   /* cells marched plus trilinear nodes polygonized (paper's column) */
    size_t nodes_polygonized;/* nodes larger than a cell emitted as one trilinear */
    double extract_ms;
    double error_bound;     /* max over emitted pieces of fit error + polygonization error */
} iso_extract_stats;

/* Extracts the iso-surface at params->level within params->tolerance into mesh (which is
 * emptied first), welded. stats may be NULL. Returns 0, ISO_E_ARGUMENT for a bad
 * parameter (NaN, negative tolerance), or ISO_E_NOMEM. */
int iso_extract(const iso_tree *tree, const iso_extract_params *params, iso_mesh *mesh,
                iso_extract_stats *stats, iso_error *err);

/* The baseline: marching cubes over every cell, no hierarchy. Same table, welding and
 * output space as iso_extract at tolerance 0. */
int iso_extract_full_scan(const iso_volume *vol, double level, iso_space space,
                          iso_mesh *mesh, iso_extract_stats *stats, iso_error *err);

#endif
