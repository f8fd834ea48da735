/* census.c: the watertightness census of an extracted mesh (mesh.h). */
#include "mesh.h"

#include <math.h>
#include <stdlib.h>
#include <string.h>

/* Positions come back from world mm to index space through the inverse affine; a
 * coordinate within this of a border plane is on it (float rounding of mm positions is
 * about 1e-5 voxel; cap offsets are 2^-10 voxel and must not count as on the border). */
#define BORDER_SLACK 1e-4

typedef struct border_test {
    const iso_volume *vol;
    const iso_mesh *mesh;
    double inverse[3][3], origin[3]; /* index = inverse * (world - origin) */
    int world;
} border_test;

static void to_index(const border_test *b, uint32_t v, double index[3])
{
    const float *p = b->mesh->positions + 3 * (size_t)v;
    if (!b->world) {
        for (int d = 0; d < 3; d++)
            index[d] = p[d];
        return;
    }
    double w[3] = {p[0] - b->origin[0], p[1] - b->origin[1], p[2] - b->origin[2]};
    for (int r = 0; r < 3; r++)
        index[r] = b->inverse[r][0] * w[0] + b->inverse[r][1] * w[1] + b->inverse[r][2] * w[2];
}

/* Bit (2 d + side) set when the point lies on the low (side 0) or high border plane of axis d. */
static unsigned border_planes(const border_test *b, uint32_t v)
{
    double x[3];
    to_index(b, v, x);
    unsigned planes = 0;
    for (int d = 0; d < 3; d++) {
        if (fabs(x[d]) <= BORDER_SLACK)
            planes |= 1u << (2 * d);
        if (fabs(x[d] - (double)(b->vol->dims[d] - 1)) <= BORDER_SLACK)
            planes |= 1u << (2 * d + 1);
    }
    return planes;
}

static int on_border(void *context, uint32_t a, uint32_t b)
{
    const border_test *t = context;
    return (border_planes(t, a) & border_planes(t, b)) != 0;
}

static void invert(const double a[3][3], double out[3][3])
{
    double det = a[0][0] * (a[1][1] * a[2][2] - a[1][2] * a[2][1]) -
                 a[0][1] * (a[1][0] * a[2][2] - a[1][2] * a[2][0]) +
                 a[0][2] * (a[1][0] * a[2][1] - a[1][1] * a[2][0]);
    for (int r = 0; r < 3; r++)
        for (int c = 0; c < 3; c++) {
            /* Cofactor of (c, r), the transpose for the adjugate. */
            int r1 = (c + 1) % 3, r2 = (c + 2) % 3, c1 = (r + 1) % 3, c2 = (r + 2) % 3;
            out[r][c] = (a[r1][c1] * a[r2][c2] - a[r1][c2] * a[r2][c1]) / det;
        }
}

static size_t degenerate_triangles(const iso_mesh *m)
{
    size_t count = 0;
    for (size_t t = 0; t < m->triangle_count; t++)
        count += (size_t)iso_mesh_zero_area(m, t);
    return count;
}

/* Sets b's inverse map when its positions are world mm. */
static void world_to_index(const iso_volume *vol, border_test *b)
{
    if (!b->world)
        return;
    double affine[3][4], a[3][3];
    iso_vol_affine(vol, affine);
    for (int r = 0; r < 3; r++) {
        for (int c = 0; c < 3; c++)
            a[r][c] = affine[r][c];
        b->origin[r] = affine[r][3];
    }
    invert(a, b->inverse);
}

int iso_census_compute(const iso_volume *vol, const iso_mesh *mesh, iso_space space,
                       iso_census *out, iso_error *err)
{
    border_test b = {.vol = vol, .mesh = mesh, .world = space == ISO_SPACE_WORLD};
    world_to_index(vol, &b);
    iso_mesh_edges e;
    if (iso_mesh_count_edges_excusing(mesh, on_border, &b, &e))
        return iso_error_set(err, ISO_E_NOMEM, "out of memory counting edges");
    memset(out, 0, sizeof *out);
    out->edges = e.edges;
    out->open_edges = e.open;
    out->boundary_edges = e.open_excused;
    out->nonmanifold_edges = e.nonmanifold;
    out->misoriented_edges = e.misoriented;
    out->degenerate_triangles = degenerate_triangles(mesh);
    out->closed = mesh->triangle_count > 0 && !e.open && !e.open_excused && !e.nonmanifold &&
                  !e.misoriented && !out->degenerate_triangles;
    return 0;
}

/* The trilinear interpolant at index point x, samples outside repeating the border; NaN
 * when a corner is. */
static double trilinear(const iso_volume *vol, const double x[3])
{
    size_t lo[3];
    double t[3];
    for (int d = 0; d < 3; d++) {
        double top = (double)(vol->dims[d] - 1), c = x[d] < 0 ? 0 : x[d] > top ? top : x[d];
        lo[d] = (size_t)c;
        if (lo[d] + 1 > vol->dims[d] - 1)
            lo[d] = vol->dims[d] > 1 ? vol->dims[d] - 2 : 0;
        t[d] = vol->dims[d] > 1 ? c - (double)lo[d] : 0;
    }
    double f = 0;
    for (int k = 0; k < 8; k++) {
        size_t at[3];
        double w = 1;
        for (int d = 0; d < 3; d++) {
            int up = (k >> d) & 1;
            at[d] = lo[d] + (size_t)(up && vol->dims[d] > 1);
            w *= up ? t[d] : 1 - t[d];
        }
        if (w != 0)
            f += w * iso_vol_get(vol, at[0], at[1], at[2]);
    }
    return f;
}

double iso_mesh_value_error(const iso_volume *vol, const iso_mesh *mesh, iso_space space, double level)
{
    border_test b = {.vol = vol, .mesh = mesh, .world = space == ISO_SPACE_WORLD};
    world_to_index(vol, &b);
    unsigned char *used = calloc(mesh->vertex_count + 1, 1);
    if (!used)
        return 0;
    for (size_t i = 0; i < 3 * mesh->triangle_count; i++)
        used[mesh->indices[i]] = 1;
    double worst = 0;
    for (size_t v = 0; v < mesh->vertex_count; v++) {
        if (!used[v])
            continue;
        double x[3];
        to_index(&b, (uint32_t)v, x);
        double e = fabs(trilinear(vol, x) - level);
        if (e > worst) /* NaN compares false: skipped */
            worst = e;
    }
    free(used);
    return worst;
}
