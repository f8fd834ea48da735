/* volume_keep.c: a simplified closed surface moved along its normals until it encloses
 * the volume the exact one does (see mesh.h).
 *
 * Edge collapses onto existing vertices cut chords across convex parts and bridge concave
 * ones; on a small rounded surface the chords win and the volume shrinks (a few percent
 * for a blob of a few hundred triangles). The remedy keeps the shape: every vertex moves
 * by the same distance along its normal (the area-weighted mean of its triangles'), the
 * distance found by Newton's method on the signed enclosed volume, whose derivative along
 * the normals is about the area. Passes of iso_mesh_volume_offset:
 *   1. normals: each used vertex's unit normal from its triangles;
 *   2. solve: offset = offset + (target - V(offset)) / area, V measured on the moved copy,
 *      until V is within 1e-9 relative of the target or ISO_KEEP_VOLUME_STEPS steps. */
#include "mesh.h"

#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "base/base.h"

#define ISO_KEEP_VOLUME_STEPS 6

/* PASS 1: unit normals (3 doubles per vertex; zero for a vertex no triangle uses). */
static void vertex_normals(const iso_mesh *m, double *normals)
{
    memset(normals, 0, 3 * m->vertex_count * sizeof *normals);
    for (size_t t = 0; t < m->triangle_count; t++) {
        const uint32_t *f = m->indices + 3 * t;
        const float *a = m->positions + 3 * (size_t)f[0], *b = m->positions + 3 * (size_t)f[1],
                    *c = m->positions + 3 * (size_t)f[2];
        double u[3] = {b[0] - a[0], b[1] - a[1], b[2] - a[2]}, v[3] = {c[0] - a[0], c[1] - a[1], c[2] - a[2]};
        double n[3] = {u[1] * v[2] - u[2] * v[1], u[2] * v[0] - u[0] * v[2], u[0] * v[1] - u[1] * v[0]};
        for (int k = 0; k < 3; k++)
            for (int d = 0; d < 3; d++)
                normals[3 * (size_t)f[k] + d] += n[d];
    }
    for (size_t v = 0; v < m->vertex_count; v++) {
        double *n = normals + 3 * v, len = sqrt(n[0] * n[0] + n[1] * n[1] + n[2] * n[2]);
        for (int d = 0; d < 3; d++)
            n[d] = len > 0 ? n[d] / len : 0;
    }
}

static void move(const float *from, const double *normals, size_t vertex_count, double offset, float *to)
{
    for (size_t i = 0; i < 3 * vertex_count; i++)
        to[i] = (float)(from[i] + offset * normals[i]);
}

int iso_mesh_offset_along_normals(iso_mesh *mesh, double offset)
{
    if (offset == 0 || !mesh->vertex_count)
        return 0;
    double *normals = malloc(3 * mesh->vertex_count * sizeof *normals);
    if (!normals)
        return ISO_E_NOMEM;
    vertex_normals(mesh, normals);
    move(mesh->positions, normals, mesh->vertex_count, offset, mesh->positions);
    free(normals);
    return 0;
}

int iso_mesh_volume_offset(const iso_mesh *mesh, double target, double *offset)
{
    *offset = 0;
    double area = iso_mesh_area(mesh);
    if (!mesh->triangle_count || !(area > 0))
        return 0;
    double *normals = malloc((3 * mesh->vertex_count + 1) * sizeof *normals);
    iso_mesh moved = *mesh;
    moved.normals = NULL;
    moved.positions = malloc((3 * mesh->vertex_count + 1) * sizeof *moved.positions);
    if (!normals || !moved.positions) {
        free(normals);
        free(moved.positions);
        return ISO_E_NOMEM;
    }
    vertex_normals(mesh, normals); /* PASS 1 */
    double volume = iso_mesh_enclosed_volume(mesh), x = 0;
    for (int step = 0; step < ISO_KEEP_VOLUME_STEPS; step++) { /* PASS 2 */
        if (fabs(target - volume) <= 1e-9 * fabs(target))
            break;
        x += (target - volume) / area;
        move(mesh->positions, normals, mesh->vertex_count, x, moved.positions);
        volume = iso_mesh_enclosed_volume(&moved);
    }
    free(normals);
    free(moved.positions);
    *offset = x;
    return 0;
}
