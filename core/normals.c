/* normals.c: B-spline gradient normals (Elber and Malzbender, section 4; see normals.h).
 *
 * Uniform B-spline bases, per axis, at x = i + t (closed forms of the standard tables):
 *   order 2 (linear, support 2):    i = floor(x):   {1-t, t}
 *   order 3 (quadratic, support 3): i = round(x):   {(1/2-t)^2/2, 3/4-t^2, (1/2+t)^2/2}
 *                                   on samples i-1, i, i+1, t in [-1/2, 1/2]
 *   order 4 (cubic, support 4):     i = floor(x):   {(1-t)^3, 3t^3-6t^2+4, -3t^3+3t^2+3t+1, t^3}/6
 *                                   on samples i-1 .. i+2
 * with their derivatives in t. The gradient's component along an axis takes that axis's
 * derivative weights and the other two axes' weights. */
#include "normals.h"

#include <assert.h>
#include <math.h>
#include <stdlib.h>
#include <string.h>

static const char *const order_names[5] = {"none", NULL, "trilinear", "triquadratic", "tricubic"};

int iso_normals_order_from_name(const char *name)
{
    for (int o = 0; name && o < 5; o++)
        if (order_names[o] && !strcmp(name, order_names[o]))
            return o;
    return -1;
}

const char *iso_normals_name(int order)
{
    assert(order == 0 || (order >= 2 && order <= 4));
    return order_names[order];
}

/* Weights w and derivative weights d of one axis at coordinate x; *first is the sample of
 * weight 0 (may lie outside 0..n-1: callers clamp). */
static void basis(int order, double x, size_t n, long *first, double w[4], double d[4])
{
    if (order == 2) {
        double i = floor(x);
        if (i > (double)n - 2)
            i = (double)n - 2; /* the last sample plane belongs to the last cell */
        if (i < 0)
            i = 0;
        double t = x - i;
        *first = (long)i;
        w[0] = 1 - t, w[1] = t;
        d[0] = -1, d[1] = 1;
    } else if (order == 3) {
        double i = floor(x + 0.5), t = x - i;
        *first = (long)i - 1;
        w[0] = 0.5 * (0.5 - t) * (0.5 - t), w[1] = 0.75 - t * t, w[2] = 0.5 * (0.5 + t) * (0.5 + t);
        d[0] = t - 0.5, d[1] = -2 * t, d[2] = 0.5 + t;
    } else {
        double i = floor(x), t = x - i, s = 1 - t;
        *first = (long)i - 1;
        w[0] = s * s * s / 6;
        w[1] = (3 * t * t * t - 6 * t * t + 4) / 6;
        w[2] = (-3 * t * t * t + 3 * t * t + 3 * t + 1) / 6;
        w[3] = t * t * t / 6;
        d[0] = -s * s / 2;
        d[1] = (3 * t * t - 4 * t) / 2;
        d[2] = (-3 * t * t + 2 * t + 1) / 2;
        d[3] = t * t / 2;
    }
}

static size_t clamp_index(long i, size_t n)
{
    return i < 0 ? 0 : (size_t)i >= n ? n - 1 : (size_t)i;
}

/* The B-spline's gradient in index space at p. */
static void gradient(const iso_volume *vol, int order, const double p[3], double g[3])
{
    double w[3][4], d[3][4];
    long first[3];
    for (int a = 0; a < 3; a++)
        basis(order, p[a], vol->dims[a], &first[a], w[a], d[a]);
    g[0] = g[1] = g[2] = 0;
    for (int k = 0; k < order; k++) {
        size_t z = clamp_index(first[2] + k, vol->dims[2]);
        for (int j = 0; j < order; j++) {
            size_t y = clamp_index(first[1] + j, vol->dims[1]);
            for (int i = 0; i < order; i++) {
                double v = iso_vol_get(vol, clamp_index(first[0] + i, vol->dims[0]), y, z);
                if (v != v)
                    v = vol->value_min;
                g[0] += d[0][i] * w[1][j] * w[2][k] * v;
                g[1] += w[0][i] * d[1][j] * w[2][k] * v;
                g[2] += w[0][i] * w[1][j] * d[2][k] * v;
            }
        }
    }
}

/* The linear part A of index-to-world (columns: world steps of i, j, k) and its inverse. */
static int world_frame(const iso_volume *vol, double a[3][3], double inv[3][3], double origin[3])
{
    double affine[3][4];
    iso_vol_affine(vol, affine);
    for (int r = 0; r < 3; r++) {
        for (int c = 0; c < 3; c++)
            a[r][c] = affine[r][c];
        origin[r] = affine[r][3];
    }
    double det = a[0][0] * (a[1][1] * a[2][2] - a[1][2] * a[2][1]) -
                 a[0][1] * (a[1][0] * a[2][2] - a[1][2] * a[2][0]) +
                 a[0][2] * (a[1][0] * a[2][1] - a[1][1] * a[2][0]);
    if (!(fabs(det) > 1e-300))
        return -1;
    for (int r = 0; r < 3; r++)
        for (int c = 0; c < 3; c++) {
            /* Cofactor of (c, r) over det: the adjugate's transpose. */
            int r1 = (c + 1) % 3, r2 = (c + 2) % 3, c1 = (r + 1) % 3, c2 = (r + 2) % 3;
            inv[r][c] = (a[r1][c1] * a[r2][c2] - a[r1][c2] * a[r2][c1]) / det;
        }
    return 0;
}

int iso_normals_compute(const iso_volume *vol, iso_mesh *mesh, int order, iso_space space,
                        iso_error *err)
{
    assert(vol && mesh);
    if (order == 0) {
        free(mesh->normals);
        mesh->normals = NULL;
        return 0;
    }
    if (order < 2 || order > 4)
        return iso_error_set(err, ISO_E_ARGUMENT, "normals: order %d is not 2, 3 or 4", order);
    double a[3][3], inv[3][3], origin[3];
    if (world_frame(vol, a, inv, origin))
        return iso_error_set(err, ISO_E_ARGUMENT, "normals: the volume's index-to-world map is singular");
    size_t capacity = mesh->vertex_capacity > mesh->vertex_count ? mesh->vertex_capacity : mesh->vertex_count;
    float *normals = realloc(mesh->normals, (capacity ? capacity : 1) * 3 * sizeof *normals);
    if (!normals)
        return iso_error_set(err, ISO_E_NOMEM, "normals: out of memory for %zu vertices", mesh->vertex_count);
    mesh->normals = normals;
    for (size_t v = 0; v < mesh->vertex_count; v++) {
        double p[3], q[3], g[3], n[3];
        for (int c = 0; c < 3; c++)
            q[c] = mesh->positions[3 * v + c];
        if (space == ISO_SPACE_WORLD)
            for (int r = 0; r < 3; r++)
                p[r] = inv[r][0] * (q[0] - origin[0]) + inv[r][1] * (q[1] - origin[1]) +
                       inv[r][2] * (q[2] - origin[2]);
        else
            memcpy(p, q, sizeof p);
        gradient(vol, order, p, g);
        if (g[0] == 0 && g[1] == 0 && g[2] == 0 && order != 2)
            gradient(vol, 2, p, g);
        /* World gradient = A^-T times the index gradient. */
        for (int c = 0; c < 3; c++)
            n[c] = space == ISO_SPACE_WORLD ? -(inv[0][c] * g[0] + inv[1][c] * g[1] + inv[2][c] * g[2])
                                            : -g[c];
        double len = sqrt(n[0] * n[0] + n[1] * n[1] + n[2] * n[2]);
        if (!(len > 0) || !isfinite(len)) {
            n[0] = n[1] = 0, n[2] = 1, len = 1;
        }
        for (int c = 0; c < 3; c++)
            normals[3 * v + c] = (float)(n[c] / len);
    }
    return 0;
}
