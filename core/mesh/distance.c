/* distance.c: the measured distance between two surfaces, both ways (see mesh.h).
 *
 * Passes, for each direction (from a to b, then from b to a):
 *   1. grid: b's triangles binned into a uniform grid of cubic cells over both meshes'
 *      bounds (about one cell per triangle), cell by cell in one array;
 *   2. samples: every triangle of the source is cut into n x n similar sub-triangles, n the
 *      smallest whole number that makes their longest side at most `spacing`; each
 *      sub-triangle's centroid is a sample weighing its area, and every vertex the source
 *      uses is a sample of weight 0 (it counts for the maximum, not the percentile);
 *   3. nearest: each sample's exact distance to the nearest triangle of the target (point
 *      to triangle, in double), searching the grid's cells ring by ring around the sample's
 *      cell until no farther ring can hold anything nearer; samples are shared by threads;
 *   4. percentile: the smallest sample distance d such that samples of total weight at
 *      least 99% of all lie within d (a histogram finds d's bin, the bin is sorted), and
 *      the weighted mean of the distances. */
#include "mesh.h"

#include <math.h>
#include <stdint.h>
#include <stdlib.h>
#include <string.h>

#include "base/base.h"

#define GRID_SIDE_MAX 1024
#define HISTOGRAM_BINS 65536

typedef struct grid {
    double lo[3], h;
    int n[3];
    uint32_t *start; /* cells + 1 offsets into items */
    uint32_t *items; /* triangle indices */
    float *boxes;    /* per triangle: min x, y, z, max x, y, z */
} grid;

static void grid_free(grid *g)
{
    free(g->start);
    free(g->items);
    free(g->boxes);
}

static void triangle_corners(const iso_mesh *m, size_t t, double c[3][3])
{
    for (int k = 0; k < 3; k++) {
        const float *p = m->positions + 3 * (size_t)m->indices[3 * t + k];
        c[k][0] = p[0], c[k][1] = p[1], c[k][2] = p[2];
    }
}

static int cell_of(const grid *g, double x, int axis)
{
    double f = floor((x - g->lo[axis]) / g->h);
    if (!(f >= 0))
        return 0;
    return f >= g->n[axis] ? g->n[axis] - 1 : (int)f;
}

static size_t cell_index(const grid *g, int i, int j, int k)
{
    return ((size_t)k * (size_t)g->n[1] + (size_t)j) * (size_t)g->n[0] + (size_t)i;
}

/* The cell range a triangle's bounding box covers. */
static void triangle_cells(const grid *g, const iso_mesh *m, size_t t, int lo[3], int hi[3])
{
    double c[3][3];
    triangle_corners(m, t, c);
    for (int a = 0; a < 3; a++) {
        double mn = fmin(c[0][a], fmin(c[1][a], c[2][a])), mx = fmax(c[0][a], fmax(c[1][a], c[2][a]));
        lo[a] = cell_of(g, mn, a);
        hi[a] = cell_of(g, mx, a);
    }
}

/* PASS 1. lo/hi: the bounds of everything that will be looked up. */
static int grid_build(grid *g, const iso_mesh *m, const float lo[3], const float hi[3])
{
    memset(g, 0, sizeof *g);
    double ext[3], volume = 1, longest = 0;
    for (int a = 0; a < 3; a++) {
        ext[a] = (double)hi[a] - lo[a];
        longest = fmax(longest, ext[a]);
    }
    /* About four cells per triangle: a cell then holds one or two triangles of a surface. */
    double cells = 4.0 * (double)(m->triangle_count ? m->triangle_count : 1);
    for (int a = 0; a < 3; a++)
        volume *= fmax(ext[a], longest / GRID_SIDE_MAX);
    g->h = fmax(cbrt(volume / cells), longest / GRID_SIDE_MAX);
    if (!(g->h > 0))
        g->h = 1;
    size_t total = 1;
    for (int a = 0; a < 3; a++) {
        g->lo[a] = lo[a];
        double n = floor(ext[a] / g->h) + 1;
        g->n[a] = n > GRID_SIDE_MAX ? GRID_SIDE_MAX : (int)n;
        total *= (size_t)g->n[a];
    }
    if (!(g->start = calloc(total + 1, sizeof *g->start)) ||
        !(g->boxes = malloc((6 * m->triangle_count + 1) * sizeof *g->boxes))) {
        grid_free(g);
        return ISO_E_NOMEM;
    }
    for (size_t t = 0; t < m->triangle_count; t++) {
        const uint32_t *v = m->indices + 3 * t;
        float *box = g->boxes + 6 * t;
        for (int a = 0; a < 3; a++) {
            float x = m->positions[3 * (size_t)v[0] + a], y = m->positions[3 * (size_t)v[1] + a];
            float z = m->positions[3 * (size_t)v[2] + a];
            box[a] = fminf(x, fminf(y, z));
            box[3 + a] = fmaxf(x, fmaxf(y, z));
        }
    }
    size_t items = 0;
    for (size_t t = 0; t < m->triangle_count; t++) {
        int a[3], b[3];
        triangle_cells(g, m, t, a, b);
        for (int k = a[2]; k <= b[2]; k++)
            for (int j = a[1]; j <= b[1]; j++)
                for (int i = a[0]; i <= b[0]; i++)
                    g->start[cell_index(g, i, j, k) + 1]++;
        items += (size_t)(b[0] - a[0] + 1) * (size_t)(b[1] - a[1] + 1) * (size_t)(b[2] - a[2] + 1);
    }
    if (items >= UINT32_MAX || !(g->items = malloc((items ? items : 1) * sizeof *g->items))) {
        grid_free(g);
        return ISO_E_NOMEM;
    }
    for (size_t c = 0; c < total; c++)
        g->start[c + 1] += g->start[c];
    uint32_t *fill = malloc(total * sizeof *fill);
    if (!fill) {
        grid_free(g);
        return ISO_E_NOMEM;
    }
    memcpy(fill, g->start, total * sizeof *fill);
    for (size_t t = 0; t < m->triangle_count; t++) {
        int a[3], b[3];
        triangle_cells(g, m, t, a, b);
        for (int k = a[2]; k <= b[2]; k++)
            for (int j = a[1]; j <= b[1]; j++)
                for (int i = a[0]; i <= b[0]; i++)
                    g->items[fill[cell_index(g, i, j, k)]++] = (uint32_t)t;
    }
    free(fill);
    return 0;
}

static double dot(const double a[3], const double b[3])
{
    return a[0] * b[0] + a[1] * b[1] + a[2] * b[2];
}

/* Squared distance from p to triangle c (the closest point by Voronoi region of the
 * triangle's features: corners, then edges, then the face). */
static double point_triangle_sq(const double p[3], const double c[3][3])
{
    double ab[3], ac[3], ap[3], bp[3], cp[3], q[3];
    for (int k = 0; k < 3; k++) {
        ab[k] = c[1][k] - c[0][k], ac[k] = c[2][k] - c[0][k];
        ap[k] = p[k] - c[0][k], bp[k] = p[k] - c[1][k], cp[k] = p[k] - c[2][k];
    }
    double d1 = dot(ab, ap), d2 = dot(ac, ap), d3 = dot(ab, bp), d4 = dot(ac, bp);
    double d5 = dot(ab, cp), d6 = dot(ac, cp);
    double va = d3 * d6 - d5 * d4, vb = d5 * d2 - d1 * d6, vc = d1 * d4 - d3 * d2;
    double s = 0, t = 0; /* q = a + s ab + t ac */
    if (d1 <= 0 && d2 <= 0)
        s = 0, t = 0;
    else if (d3 >= 0 && d4 <= d3)
        s = 1, t = 0;
    else if (d6 >= 0 && d5 <= d6)
        s = 0, t = 1;
    else if (vc <= 0 && d1 >= 0 && d3 <= 0)
        s = d1 / (d1 - d3), t = 0;
    else if (vb <= 0 && d2 >= 0 && d6 <= 0)
        s = 0, t = d2 / (d2 - d6);
    else if (va <= 0 && d4 - d3 >= 0 && d5 - d6 >= 0) {
        double w = (d4 - d3) / ((d4 - d3) + (d5 - d6));
        s = 1 - w, t = w;
    } else {
        double den = va + vb + vc;
        s = den != 0 ? vb / den : 0, t = den != 0 ? vc / den : 0;
    }
    for (int k = 0; k < 3; k++)
        q[k] = p[k] - (c[0][k] + s * ab[k] + t * ac[k]);
    return dot(q, q);
}

double iso_mesh_point_distance(const iso_mesh *mesh, const double p[3])
{
    double best = INFINITY;
    for (size_t t = 0; t < mesh->triangle_count; t++) {
        double c[3][3];
        triangle_corners(mesh, t, c);
        best = fmin(best, point_triangle_sq(p, c));
    }
    return sqrt(best);
}

/* The squared distance from p to cell (i, j, k)'s box. */
static double cell_gap_sq(const grid *g, const double p[3], const int cell[3])
{
    double sum = 0;
    for (int a = 0; a < 3; a++) {
        double lo = g->lo[a] + cell[a] * g->h, hi = lo + g->h;
        double gap = p[a] < lo ? lo - p[a] : p[a] > hi ? p[a] - hi : 0;
        sum += gap * gap;
    }
    return sum;
}

/* PASS 3 for one point: the cells at Chebyshev distance r from p's cell, r = 0, 1, ...,
 * each skipped when its box is no nearer than the best triangle yet; the search ends when
 * the box of rings 0..r, where the grid goes on, is farther from p than the best. */
static double nearest(const grid *g, const iso_mesh *m, const double p[3])
{
    int c[3];
    for (int a = 0; a < 3; a++)
        c[a] = cell_of(g, p[a], a);
    double best = INFINITY;
    for (int r = 0;; r++) {
        int lo[3], hi[3], whole = 1;
        double reach = INFINITY; /* from p to where ring r + 1 begins */
        for (int a = 0; a < 3; a++) {
            lo[a] = c[a] - r < 0 ? 0 : c[a] - r;
            hi[a] = c[a] + r >= g->n[a] ? g->n[a] - 1 : c[a] + r;
            if (lo[a] > 0)
                reach = fmin(reach, p[a] - (g->lo[a] + lo[a] * g->h)), whole = 0;
            if (hi[a] < g->n[a] - 1)
                reach = fmin(reach, g->lo[a] + (hi[a] + 1) * g->h - p[a]), whole = 0;
        }
        for (int k = lo[2]; k <= hi[2]; k++)
            for (int j = lo[1]; j <= hi[1]; j++) {
                /* Rows inside the ring's shell touch it only at their two ends. */
                int shell = abs(k - c[2]) == r || abs(j - c[1]) == r;
                for (int i = lo[0]; i <= hi[0]; i++) {
                    if (!shell && abs(i - c[0]) != r) {
                        if (i < c[0] + r && c[0] + r <= hi[0]) {
                            i = c[0] + r - 1;
                            continue;
                        }
                        break;
                    }
                    size_t at = cell_index(g, i, j, k);
                    int cell[3] = {i, j, k};
                    if (g->start[at] == g->start[at + 1] || cell_gap_sq(g, p, cell) >= best)
                        continue;
                    for (uint32_t e = g->start[at]; e < g->start[at + 1]; e++) {
                        /* A triangle whose box is no nearer than the best is skipped. */
                        const float *box = g->boxes + 6 * (size_t)g->items[e];
                        double gap = 0;
                        for (int a = 0; a < 3; a++) {
                            double below = box[a] - p[a], above = p[a] - box[3 + a];
                            double d = below > 0 ? below : above > 0 ? above : 0;
                            gap += d * d;
                        }
                        if (gap >= best)
                            continue;
                        double tc[3][3];
                        triangle_corners(m, g->items[e], tc);
                        double d = point_triangle_sq(p, tc);
                        if (d < best)
                            best = d;
                    }
                }
            }
        if (whole || (reach > 0 && best <= reach * reach))
            break;
    }
    return sqrt(best);
}

/* How many sub-triangles a side of triangle t is cut into (PASS 2). */
static int subdivisions(const iso_mesh *m, size_t t, double spacing)
{
    double c[3][3], longest = 0;
    triangle_corners(m, t, c);
    for (int e = 0; e < 3; e++) {
        double d[3];
        for (int k = 0; k < 3; k++)
            d[k] = c[(e + 1) % 3][k] - c[e][k];
        longest = fmax(longest, sqrt(dot(d, d)));
    }
    double n = spacing > 0 ? ceil(longest / spacing) : 1;
    return n < 1 ? 1 : n > 256 ? 256 : (int)n;
}

typedef struct direction {
    const iso_mesh *src, *dst;
    const grid *g;
    double spacing;
    const size_t *first;      /* per source triangle: its first sample */
    const uint32_t *vertices; /* the source's used vertices */
    size_t vertex_count;
    float *dist, *weight;     /* per sample; vertex samples after the triangles' */
} direction;

static void measure_part(void *context, int part, int parts)
{
    direction *d = context;
    const iso_mesh *m = d->src;
    size_t t0 = m->triangle_count * (size_t)part / (size_t)parts;
    size_t t1 = m->triangle_count * (size_t)(part + 1) / (size_t)parts;
    for (size_t t = t0; t < t1; t++) {
        double c[3][3], u[3], v[3], x[3];
        triangle_corners(m, t, c);
        for (int k = 0; k < 3; k++)
            u[k] = c[1][k] - c[0][k], v[k] = c[2][k] - c[0][k];
        x[0] = u[1] * v[2] - u[2] * v[1], x[1] = u[2] * v[0] - u[0] * v[2], x[2] = u[0] * v[1] - u[1] * v[0];
        int n = (int)(d->first[t + 1] - d->first[t]);
        n = (int)lround(sqrt((double)n));
        double w = 0.5 * sqrt(dot(x, x)) / ((double)n * n);
        size_t s = d->first[t];
        /* Upward sub-triangles (i, j), i + j < n, centroid (i + 1/3, j + 1/3) / n; downward
         * ones, i + j < n - 1, centroid (i + 2/3, j + 2/3) / n. */
        for (int down = 0; down < 2; down++)
            for (int i = 0; i < n; i++)
                for (int j = 0; i + j < n - down; j++) {
                    double a = (i + (down ? 2.0 : 1.0) / 3) / n, b = (j + (down ? 2.0 : 1.0) / 3) / n;
                    double p[3];
                    for (int k = 0; k < 3; k++)
                        p[k] = c[0][k] + a * u[k] + b * v[k];
                    d->dist[s] = (float)nearest(d->g, d->dst, p);
                    d->weight[s++] = (float)w;
                }
    }
    size_t base = d->first[m->triangle_count];
    size_t v0 = d->vertex_count * (size_t)part / (size_t)parts;
    size_t v1 = d->vertex_count * (size_t)(part + 1) / (size_t)parts;
    for (size_t i = v0; i < v1; i++) {
        const float *f = m->positions + 3 * (size_t)d->vertices[i];
        double p[3] = {f[0], f[1], f[2]};
        d->dist[base + i] = (float)nearest(d->g, d->dst, p);
        d->weight[base + i] = 0;
    }
}

static int compare_floats(const void *pa, const void *pb)
{
    float a = *(const float *)pa, b = *(const float *)pb;
    return (a > b) - (a < b);
}

/* PASS 4: the weighted 99th percentile, the maximum, the weighted mean and the total
 * weight (the source's area). Returns 0 or ISO_E_NOMEM. */
static int percentile(const float *dist, const float *weight, size_t n, double *p99, double *max,
                      double *mean, double *area)
{
    double total = 0, top = 0, sum = 0;
    for (size_t i = 0; i < n; i++) {
        total += weight[i];
        sum += (double)dist[i] * weight[i];
        top = fmax(top, dist[i]);
    }
    *max = top;
    *p99 = 0;
    *mean = total > 0 ? sum / total : 0;
    *area = total;
    if (!(top > 0) || !(total > 0))
        return 0;
    double *bins = calloc(HISTOGRAM_BINS, sizeof *bins);
    if (!bins)
        return ISO_E_NOMEM;
    double scale = HISTOGRAM_BINS / top;
    for (size_t i = 0; i < n; i++) {
        int b = (int)(dist[i] * scale);
        bins[b >= HISTOGRAM_BINS ? HISTOGRAM_BINS - 1 : b] += weight[i];
    }
    double goal = 0.99 * total, below = 0;
    int bin = 0;
    while (bin < HISTOGRAM_BINS - 1 && below + bins[bin] < goal)
        below += bins[bin++];
    free(bins);
    /* The samples of that bin, (distance, weight) pairs, sorted by distance. */
    size_t count = 0;
    for (size_t i = 0; i < n; i++) {
        int b = (int)(dist[i] * scale);
        count += (b >= HISTOGRAM_BINS ? HISTOGRAM_BINS - 1 : b) == bin;
    }
    float *pairs = malloc((count ? count : 1) * 2 * sizeof *pairs);
    if (!pairs)
        return ISO_E_NOMEM;
    size_t k = 0;
    for (size_t i = 0; i < n; i++) {
        int b = (int)(dist[i] * scale);
        if ((b >= HISTOGRAM_BINS ? HISTOGRAM_BINS - 1 : b) == bin)
            pairs[2 * k] = dist[i], pairs[2 * k + 1] = weight[i], k++;
    }
    qsort(pairs, count, 2 * sizeof *pairs, compare_floats);
    *p99 = count ? pairs[2 * (count - 1)] : top;
    for (size_t i = 0; i < count; i++) {
        below += pairs[2 * i + 1];
        if (below >= goal) {
            *p99 = pairs[2 * i];
            break;
        }
    }
    free(pairs);
    return 0;
}

/* One direction: from src's surface to dst's. */
static int one_way(const iso_mesh *src, const iso_mesh *dst, const float lo[3], const float hi[3],
                   double spacing, int threads, double *p99, double *max, double *mean, double *area,
                   size_t *samples)
{
    *p99 = *max = *mean = *area = 0;
    *samples = 0;
    if (!src->triangle_count)
        return 0;
    if (!dst->triangle_count) {
        *p99 = *max = *mean = INFINITY;
        return 0;
    }
    grid g;
    int rc = grid_build(&g, dst, lo, hi);
    if (rc)
        return rc;
    size_t *first = malloc((src->triangle_count + 1) * sizeof *first);
    unsigned char *used = calloc(src->vertex_count ? src->vertex_count : 1, 1);
    uint32_t *vertices = NULL;
    float *dist = NULL, *weight = NULL;
    rc = ISO_E_NOMEM;
    if (!first || !used)
        goto done;
    first[0] = 0;
    size_t vertex_count = 0;
    for (size_t t = 0; t < src->triangle_count; t++) {
        size_t n = (size_t)subdivisions(src, t, spacing);
        first[t + 1] = first[t] + n * n;
        for (int k = 0; k < 3; k++)
            if (!used[src->indices[3 * t + k]])
                used[src->indices[3 * t + k]] = 1, vertex_count++;
    }
    if (!(vertices = malloc((vertex_count ? vertex_count : 1) * sizeof *vertices)))
        goto done;
    for (size_t v = 0, i = 0; v < src->vertex_count; v++)
        if (used[v])
            vertices[i++] = (uint32_t)v;
    size_t n = first[src->triangle_count] + vertex_count;
    if (!(dist = malloc(n * sizeof *dist)) || !(weight = malloc(n * sizeof *weight)))
        goto done;
    direction d = {.src = src, .dst = dst, .g = &g, .spacing = spacing, .first = first,
                   .vertices = vertices, .vertex_count = vertex_count, .dist = dist, .weight = weight};
    iso_parallel_run(iso_parallel_threads(threads), measure_part, &d);
    rc = percentile(dist, weight, n, p99, max, mean, area);
    *samples = n;
done:
    grid_free(&g);
    free(first);
    free(used);
    free(vertices);
    free(dist);
    free(weight);
    return rc;
}

static void union_bounds(const iso_mesh *a, const iso_mesh *b, float lo[3], float hi[3])
{
    float l2[3], h2[3];
    iso_mesh_bounds(a, lo, hi);
    iso_mesh_bounds(b, l2, h2);
    for (int k = 0; k < 3; k++)
        lo[k] = lo[k] < l2[k] ? lo[k] : l2[k], hi[k] = hi[k] > h2[k] ? hi[k] : h2[k];
}

int iso_mesh_distance_compute(const iso_mesh *a, const iso_mesh *b, double spacing, int threads,
                              iso_mesh_distance *out, iso_error *err)
{
    double start = iso_clock_ms();
    *out = (iso_mesh_distance){0};
    if (!(spacing > 0) || !isfinite(spacing))
        return iso_error_set(err, ISO_E_ARGUMENT, "distance: sample spacing %g must be > 0", spacing);
    float lo[3], hi[3];
    union_bounds(a, b, lo, hi);
    double area_a, area_b;
    int rc = one_way(a, b, lo, hi, spacing, threads, &out->p99_ab, &out->max_ab, &out->mean_ab, &area_a,
                     &out->samples_a);
    if (!rc)
        rc = one_way(b, a, lo, hi, spacing, threads, &out->p99_ba, &out->max_ba, &out->mean_ba, &area_b,
                     &out->samples_b);
    if (rc)
        return iso_error_set(err, rc, "distance: no memory for %zu and %zu triangles",
                             a->triangle_count, b->triangle_count);
    out->p99 = fmax(out->p99_ab, out->p99_ba);
    out->max = fmax(out->max_ab, out->max_ba);
    /* Pooled by area, so the mean is over both surfaces alike; an empty side is INFINITY
     * away from the other (above), and so is the mean. */
    out->mean = area_a + area_b > 0 && isfinite(out->mean_ab) && isfinite(out->mean_ba)
                    ? (out->mean_ab * area_a + out->mean_ba * area_b) / (area_a + area_b)
                    : fmax(out->mean_ab, out->mean_ba);
    out->ms = iso_clock_ms() - start;
    return 0;
}
