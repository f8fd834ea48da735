/* collapse.h: the collapser behind iso_simplify_manifold, for callers that run several at
 * once in steps (the chain's slabs, chain.c). Internal to core/mesh. */
#ifndef ISO_MESH_COLLAPSE_H
#define ISO_MESH_COLLAPSE_H

#include "mesh.h"

typedef struct iso_collapser iso_collapser;

/* A collapser over mesh's triangles (copied) and positions (not copied: they must outlive
 * it unchanged); vertices on open edges, on edges not used once each way, or with more
 * than one fan of triangles stay where they are. *pinch_free receives 1 when no vertex
 * is of the last two kinds: no result then has a pinch. Returns 0 or ISO_E_NOMEM. */
int iso_collapser_create(const iso_mesh *mesh, iso_collapser **out, int *pinch_free);
/* Collapses, cheapest first, until at most target_triangles are left, the next collapse
 * would cost more than target_error (position units), or none is allowed. Returns the
 * triangles left. May be called again with other targets. */
size_t iso_collapser_run(iso_collapser *c, size_t target_triangles, double target_error);
/* From now on, collapses costing less than share (>= 0) times the cost where simplifying
 * to target_triangles (over all runs to come) is expected to stop go cheapest first only
 * by classes of a factor of 2, in vertex order within a class: memory order, much cheaper
 * than cost order on a large mesh. Those collapses are all made whatever their order; the
 * last ones, which decide the error, still go in cost order. Share 0 (the default): all
 * in cost order. */
void iso_collapser_coarse(iso_collapser *c, double share, size_t target_triangles);
/* The cost of the cheapest collapse waiting (a lower bound: it may be refused), INFINITY
 * when none waits. */
double iso_collapser_next(const iso_collapser *c);
/* Writes the triangles left, in their input order (3 indices each, the input mesh's
 * vertex numbers) into out, which holds the count iso_collapser_run returned. */
void iso_collapser_triangles(const iso_collapser *c, uint32_t *out);
/* The largest collapse cost so far (position units: meshoptimizer's kind of estimate),
 * and how many vertices left had a collapse refused for their topology. */
double iso_collapser_error(const iso_collapser *c);
size_t iso_collapser_refused(const iso_collapser *c);
void iso_collapser_destroy(iso_collapser *c);

#endif
