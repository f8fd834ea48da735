/* mesh.h: indexed triangle meshes, the output of extraction and the input of encoders.
 *
 * Positions are float x,y,z triples; triangles are uint32 index triples whose winding
 * (counter-clockwise seen from the side the normal points to) makes normals point from
 * higher values toward lower values. Normals, when present, are unit float triples per
 * vertex. A mesh owns its arrays; iso_mesh_destroy frees them. */
#ifndef ISO_MESH_H
#define ISO_MESH_H

#include <stddef.h>
#include <stdint.h>

#include "error.h"

typedef struct iso_mesh {
    float *positions;      /* 3 * vertex_count */
    float *normals;        /* 3 * vertex_count, or NULL */
    uint32_t *indices;     /* 3 * triangle_count */
    size_t vertex_count, triangle_count;
    size_t vertex_capacity, triangle_capacity;
} iso_mesh;

/* Initialises an empty mesh (no allocation). */
void iso_mesh_init(iso_mesh *mesh);
/* Frees the arrays and leaves an empty mesh; NULL is allowed. */
void iso_mesh_free(iso_mesh *mesh);
/* Empties the mesh but keeps its position and index arrays for reuse (normals are
 * freed): extracting again into the same mesh then faults no fresh pages in. */
void iso_mesh_clear(iso_mesh *mesh);
/* Makes room for at least the given totals. Returns 0 or ISO_E_NOMEM (mesh unchanged). */
int iso_mesh_reserve(iso_mesh *mesh, size_t vertices, size_t triangles);
/* Moves everything of `src` onto the end of `dst`, offsetting its indices; src is emptied
 * but keeps no memory. Returns 0 or ISO_E_NOMEM (both unchanged). */
int iso_mesh_append(iso_mesh *dst, iso_mesh *src);

/* Merges vertices with bit-identical positions and drops triangles that become degenerate
 * (two equal indices). Vertex order: first occurrence. O(V) expected, allocates a
 * temporary hash table of ~2V entries. Returns 0 or ISO_E_NOMEM (mesh unchanged). */
int iso_mesh_weld(iso_mesh *mesh);

/* Removes the vertices no triangle uses, keeping the others in order, and renumbers the
 * triangles. O(V + T), allocates a temporary V-entry table. Returns 0 or ISO_E_NOMEM
 * (mesh unchanged). */
int iso_mesh_drop_unused(iso_mesh *mesh);
/* The same with the caller's scratch: remap has vertex_count entries (it ends up holding
 * each old vertex's new index, UINT32_MAX for those dropped). Cannot fail. */
void iso_mesh_drop_unused_into(iso_mesh *mesh, uint32_t *remap);

/* Sum of triangle areas, in the square of the position unit. O(T). */
double iso_mesh_area(const iso_mesh *mesh);
/* Signed enclosed volume (divergence theorem), positive when normals point outward of
 * the enclosed region; meaningful for closed meshes. O(T). */
double iso_mesh_enclosed_volume(const iso_mesh *mesh);

/* Edge census after welding: edges used by one triangle, by three or more, and by exactly
 * two triangles in opposite directions. O(T) plus a sort of each vertex's few edges;
 * allocates 24 bytes per triangle and 8 per vertex for the call. Returns 0, ISO_E_NOMEM,
 * or ISO_E_ARGUMENT when an index is not below vertex_count (out is then undefined). */
typedef struct iso_mesh_edges {
    size_t edges, open, nonmanifold, misoriented;
    size_t open_excused; /* open edges the classifier accepted (counted apart from open) */
} iso_mesh_edges;
int iso_mesh_count_edges(const iso_mesh *mesh, iso_mesh_edges *out);
/* The same census, asking excuse(context, a, b) about every open edge (a, b): those it
 * answers 1 for count in open_excused instead of open (a volume border, for example). */
typedef int (*iso_mesh_edge_excuse_fn)(void *context, uint32_t a, uint32_t b);
int iso_mesh_count_edges_excusing(const iso_mesh *mesh, iso_mesh_edge_excuse_fn excuse,
                                  void *context, iso_mesh_edges *out);

/* Calls visit(context, lo, hi, forward, backward) once for every edge (lo < hi) with its
 * uses as lo->hi and as hi->lo, in order of lo, then hi. Allocates 24 bytes per triangle
 * and 8 per vertex for the call; returns 0, ISO_E_NOMEM or ISO_E_ARGUMENT (an index not
 * below vertex_count), nothing visited then. */
typedef void (*iso_mesh_edge_visit_fn)(void *context, uint32_t lo, uint32_t hi,
                                       uint32_t forward, uint32_t backward);
int iso_mesh_visit_edges(const iso_mesh *mesh, iso_mesh_edge_visit_fn visit, void *context);

/* 1 when triangle t has zero area: its edge vectors' cross product, in double from the
 * float positions, is exactly zero. */
int iso_mesh_zero_area(const iso_mesh *mesh, size_t t);

/* Axis-aligned bounds of the positions; min > max for an empty mesh. */
void iso_mesh_bounds(const iso_mesh *mesh, float min[3], float max[3]);

#endif
