/* components.c: a mesh's connected components counted, and its small closed ones removed
 * on request (see mesh.h).
 *
 * Passes of iso_mesh_remove_components:
 *   1. label: union-find over the triangles' corners, each vertex's component numbered in
 *      order of first use;
 *   2. measure: per component its signed enclosed volume (divergence theorem) and bounds;
 *      an edge not used exactly once each way marks its component open;
 *   3. remove: the triangles of the closed components enclosing less than the minimum go,
 *      and the vertices no triangle uses any more with them. */
#include "mesh.h"

#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "base/base.h"

static uint32_t root_of(uint32_t *parent, uint32_t v)
{
    while (parent[v] != v) {
        parent[v] = parent[parent[v]]; /* path halving */
        v = parent[v];
    }
    return v;
}

/* PASS 1: label[v] = v's component (0..count-1, in order of first use by a triangle),
 * UINT32_MAX for an unused vertex; parent is scratch (vertex_count entries). Returns the
 * count. */
static size_t label_components(const iso_mesh *mesh, uint32_t *parent, uint32_t *label)
{
    for (size_t v = 0; v < mesh->vertex_count; v++)
        parent[v] = (uint32_t)v, label[v] = UINT32_MAX;
    for (size_t t = 0; t < mesh->triangle_count; t++) {
        const uint32_t *f = mesh->indices + 3 * t;
        for (int k = 1; k < 3; k++) {
            uint32_t a = root_of(parent, f[0]), b = root_of(parent, f[k]);
            if (a != b)
                parent[a < b ? b : a] = a < b ? a : b;
        }
    }
    size_t count = 0; /* label[root] numbers the root's component, then every vertex's */
    for (size_t i = 0; i < 3 * mesh->triangle_count; i++) {
        uint32_t r = root_of(parent, mesh->indices[i]);
        if (label[r] == UINT32_MAX)
            label[r] = (uint32_t)count++;
    }
    for (size_t v = 0; v < mesh->vertex_count; v++)
        if (label[v] == UINT32_MAX || parent[v] != v)
            label[v] = label[root_of(parent, (uint32_t)v)];
    return count;
}

int iso_mesh_count_components(const iso_mesh *mesh, size_t *count)
{
    size_t n = mesh->vertex_count ? mesh->vertex_count : 1;
    uint32_t *parent = malloc(n * sizeof *parent), *label = malloc(n * sizeof *label);
    *count = 0;
    if (!parent || !label) {
        free(parent);
        free(label);
        return ISO_E_NOMEM;
    }
    *count = label_components(mesh, parent, label);
    free(parent);
    free(label);
    return 0;
}

/* PASS 2 per component. */
typedef struct component {
    double volume;           /* signed, enclosed (6 times it while summed) */
    float lo[3], hi[3];
    int open;
} component;

typedef struct open_marks {
    const uint32_t *label;
    component *parts;
} open_marks;

static void mark_open(void *context, uint32_t lo, uint32_t hi, uint32_t forward, uint32_t backward)
{
    open_marks *m = context;
    (void)hi;
    if (forward != 1 || backward != 1)
        m->parts[m->label[lo]].open = 1;
}

static void measure_components(const iso_mesh *mesh, const uint32_t *label, component *parts, size_t count)
{
    for (size_t c = 0; c < count; c++)
        parts[c] = (component){.lo = {INFINITY, INFINITY, INFINITY}, .hi = {-INFINITY, -INFINITY, -INFINITY}};
    for (size_t t = 0; t < mesh->triangle_count; t++) {
        const uint32_t *f = mesh->indices + 3 * t;
        const float *a = mesh->positions + 3 * (size_t)f[0], *b = mesh->positions + 3 * (size_t)f[1],
                    *c = mesh->positions + 3 * (size_t)f[2];
        component *part = &parts[label[f[0]]];
        part->volume += (double)a[0] * ((double)b[1] * c[2] - (double)b[2] * c[1]) +
                        (double)a[1] * ((double)b[2] * c[0] - (double)b[0] * c[2]) +
                        (double)a[2] * ((double)b[0] * c[1] - (double)b[1] * c[0]);
        for (int k = 0; k < 3; k++)
            for (int d = 0; d < 3; d++) {
                float x = mesh->positions[3 * (size_t)f[k] + d];
                part->lo[d] = fminf(part->lo[d], x);
                part->hi[d] = fmaxf(part->hi[d], x);
            }
    }
    for (size_t c = 0; c < count; c++)
        parts[c].volume /= 6;
}

int iso_mesh_remove_components(iso_mesh *mesh, double min_volume, iso_mesh_components *out)
{
    *out = (iso_mesh_components){0};
    size_t n = mesh->vertex_count ? mesh->vertex_count : 1;
    uint32_t *parent = malloc(n * sizeof *parent), *label = malloc(n * sizeof *label);
    component *parts = NULL;
    int rc = ISO_E_NOMEM;
    if (!parent || !label)
        goto done;
    size_t count = label_components(mesh, parent, label); /* PASS 1 */
    out->components = count;
    if (!(min_volume > 0) || !count) {
        rc = 0;
        goto done;
    }
    if (!(parts = malloc(count * sizeof *parts)))
        goto done;
    measure_components(mesh, label, parts, count); /* PASS 2 */
    open_marks marks = {.label = label, .parts = parts};
    if (iso_mesh_visit_edges(mesh, mark_open, &marks))
        goto done;
    size_t kept = 0; /* PASS 3 */
    for (size_t c = 0; c < count; c++) {
        component *part = &parts[c];
        part->open |= fabs(part->volume) >= min_volume; /* open now means: kept */
        if (part->open)
            continue;
        out->removed++;
        double d[3] = {part->hi[0] - part->lo[0], part->hi[1] - part->lo[1], part->hi[2] - part->lo[2]};
        out->removed_largest = fmax(out->removed_largest, sqrt(d[0] * d[0] + d[1] * d[1] + d[2] * d[2]));
    }
    for (size_t t = 0; t < mesh->triangle_count; t++) {
        const uint32_t *f = mesh->indices + 3 * t;
        if (parts[label[f[0]]].open)
            memmove(mesh->indices + 3 * kept++, f, 3 * sizeof *f);
    }
    out->removed_triangles = mesh->triangle_count - kept;
    mesh->triangle_count = kept;
    if (out->removed)
        iso_mesh_drop_unused_into(mesh, parent);
    rc = 0;
done:
    free(parent);
    free(label);
    free(parts);
    return rc;
}
