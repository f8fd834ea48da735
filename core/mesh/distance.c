/* distance.c: the measured distance between two surfaces, both ways (see mesh.h).
 *
 * Passes, for each direction (from a source surface to a target one):
 *   1. grid: the target's triangles (their corners and bounding boxes, sorted by cell)
 *      binned into a uniform grid of cubic cells (about four cells per triangle), and into
 *      one 8 times coarser for far points (iso_mesh_grid;
 *      a caller measuring many meshes against one keeps that one's grid);
 *   2. samples: every triangle of the source is cut into n x n similar sub-triangles, n the
 *      smallest whole number that makes their longest side at most `spacing`; each
 *      sub-triangle's centroid is a sample weighing its area, and every vertex the source
 *      uses is a sample of weight 0 (it counts for the maximum, not the percentile); a
 *      caller measuring one mesh against many counts its samples once (iso_mesh_samples);
 *   3. percentile samples: those centroids when there are at most `cap` of them; else
 *      `cap` points drawn by area, stratified: the source's area, triangle after triangle,
 *      cut into `cap` strata of equal area, and in each one a point uniformly random over
 *      the triangle the stratum's random abscissa falls in (a fixed seed per stratum, so
 *      the result is reproducible and the same on any number of threads);
 *   4. nearest: each percentile sample's exact distance to the nearest triangle of the
 *      target (point to triangle, in double): the fine grid's cells ring by ring around the
 *      sample's cell until no farther ring can hold anything nearer, or until one holds a
 *      triangle at distance d, then the cells of the box p +- d not scanned yet; when that
 *      box reaches past three rings, the coarse grid's likewise; the largest of these
 *      distances starts the maximum M. When the caller wants no mean and the points were
 *      drawn, each drawn point first gets a cheap bound (its hint's triangle, the nearest
 *      of its own cell), and only those that may lie in the top 1% are searched in full,
 *      largest bound first (select_top): the p99 and M come out the same bit for bit;
 *   5. maximum: every sample of pass 2 not measured in pass 4, searched only until some
 *      triangle lies within M (the nearest triangle of the previous sample is tried first):
 *      such a sample cannot raise the maximum; any other gets its exact distance and
 *      raises M. So the maximum is exact over all samples of both kinds. Samples go BLOCK
 *      source triangles (or vertices) at a time: when a target triangle lies within
 *      sqrt(M) - r of the centre of the block's box, r its half diagonal, no sample of the
 *      block can be farther than sqrt(M) (distance moves by at most the distance moved),
 *      and the block is skipped whole; so is a triangle of several samples by its own box,
 *      and a sample by its hint's nearest corner. Where M is large (specks of CT noise
 *      that vanish from a level keep it at tens of voxels), most blocks go so. A
 *      triangle's samples are visited each next to the one before (the hint is likelier
 *      to settle them). With an earlier
 *      measure to reuse (iso_mesh_distance_reuse: a chain's previous level), a source
 *      triangle identical to one of the earlier mesh's (same indices, same order, same
 *      positions, so the same samples) whose samples were all found within some distance
 *      u <= M is skipped whole: none of them can raise M. One whose samples lie on a
 *      target triangle of the same corners tries that triangle first;
 *   6. percentile: the smallest distance d such that percentile samples of total weight at
 *      least 99% of all lie within d (a histogram finds d's bin, the bin is sorted), and
 *      their weighted mean.
 * Sampling error of pass 3: each stratum holds one independent point, so the count of
 * samples within any distance has at most a binomial's variance, and the share of the
 * area within the reported p99 is 99% with a standard deviation of at most
 * sqrt(0.99 x 0.01 / cap) (0.078 percentage points at cap 16384). */
#include "distance.h"

#include <math.h>
#include <stdatomic.h>
#include <stdint.h>
#include <stdlib.h>
#include <string.h>

#include "base/base.h"

#define GRID_SIDE_MAX 1024
#define HISTOGRAM_BINS 65536
#define COARSE 8      /* the far grid's cell side, in fine cells */
#define FINE_RINGS 3  /* fine rings searched before the coarse grid takes over */
#define PROBE_CELLS 3 /* the widest box of fine cells PASS 5 probes first, a side */
#define NO_TRIANGLE UINT32_MAX
#define KNOWN_NONE (-1.0)
#define KNOWN_OWN (-2.0)
#define BLOCK 64 /* PASS 5: source triangles or vertices tried at once against one bound */

typedef struct grid {
    double lo[3], h;
    int n[3];
    uint32_t *start; /* cells + 1 offsets into items */
    uint32_t *items; /* triangle indices */
} grid;

struct iso_mesh_grid {
    size_t triangle_count;
    grid fine, coarse; /* their items are slots in corners */
    float *corners;    /* 9 per triangle, sorted by fine cell so that a cell's are together */
    float *boxes;      /* 6 per slot: its triangle's bounding box, lowest corner then highest */
};

static void grid_free(grid *g)
{
    free(g->start);
    free(g->items);
}

void iso_mesh_grid_destroy(iso_mesh_grid *g)
{
    if (!g)
        return;
    grid_free(&g->fine);
    grid_free(&g->coarse);
    free(g->corners);
    free(g->boxes);
    free(g);
}

static size_t grid_cells(const grid *g)
{
    return (size_t)g->n[0] * (size_t)g->n[1] * (size_t)g->n[2];
}

size_t iso_mesh_grid_bytes(const iso_mesh_grid *g)
{
    if (!g)
        return 0;
    size_t f = grid_cells(&g->fine), c = grid_cells(&g->coarse);
    size_t items = (size_t)g->fine.start[f] + g->coarse.start[c];
    return sizeof *g + 15 * g->triangle_count * sizeof(float) + (f + c + 2 + items) * sizeof(uint32_t);
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
    double f = (x - g->lo[axis]) / g->h;
    if (!(f >= 0))
        return 0;
    return f >= g->n[axis] ? g->n[axis] - 1 : (int)f; /* truncation: floor, f >= 0 */
}

static size_t cell_index(const grid *g, int i, int j, int k)
{
    return ((size_t)k * (size_t)g->n[1] + (size_t)j) * (size_t)g->n[0] + (size_t)i;
}

/* The cell range a triangle's bounding box b (6 floats) covers. */
static void box_cells(const grid *g, const float *b, int lo[3], int hi[3])
{
    for (int a = 0; a < 3; a++)
        lo[a] = cell_of(g, b[a], a), hi[a] = cell_of(g, b[3 + a], a);
}

/* PASS 1: a grid's cells, `per_triangle` per triangle over lo..hi. */
static int grid_shape(grid *g, size_t triangles, const float lo[3], const float hi[3],
                      double per_triangle, size_t *total)
{
    memset(g, 0, sizeof *g);
    double ext[3], volume = 1, longest = 0;
    for (int a = 0; a < 3; a++) {
        ext[a] = (double)hi[a] - lo[a];
        longest = fmax(longest, ext[a]);
    }
    double cells = fmax(1, per_triangle * (double)triangles);
    for (int a = 0; a < 3; a++)
        volume *= fmax(ext[a], longest / GRID_SIDE_MAX);
    g->h = fmax(cbrt(volume / cells), longest / GRID_SIDE_MAX);
    if (!(g->h > 0))
        g->h = 1;
    *total = 1;
    for (int a = 0; a < 3; a++) {
        g->lo[a] = lo[a];
        double n = floor(ext[a] / g->h) + 1;
        g->n[a] = n > GRID_SIDE_MAX ? GRID_SIDE_MAX : n < 1 ? 1 : (int)n;
        *total *= (size_t)g->n[a];
    }
    return (g->start = calloc(*total + 1, sizeof *g->start)) ? 0 : ISO_E_NOMEM;
}

/* PASS 1: the triangles (their boxes, 6 floats each) binned into g's cells; each one's cell
 * range found once (a side holds at most GRID_SIDE_MAX cells). */
static int grid_fill(grid *g, const float *boxes, size_t triangles, size_t total)
{
    size_t items = 0;
    uint16_t *range = malloc((6 * triangles + 1) * sizeof *range);
    if (!range)
        return ISO_E_NOMEM;
    for (size_t t = 0; t < triangles; t++) {
        int a[3], b[3];
        box_cells(g, boxes + 6 * t, a, b);
        for (int k = 0; k < 3; k++)
            range[6 * t + (size_t)k] = (uint16_t)a[k], range[6 * t + 3 + (size_t)k] = (uint16_t)b[k];
        for (int k = a[2]; k <= b[2]; k++)
            for (int j = a[1]; j <= b[1]; j++)
                for (int i = a[0]; i <= b[0]; i++)
                    g->start[cell_index(g, i, j, k) + 1]++;
        items += (size_t)(b[0] - a[0] + 1) * (size_t)(b[1] - a[1] + 1) * (size_t)(b[2] - a[2] + 1);
    }
    uint32_t *fill = malloc(total * sizeof *fill);
    if (items >= UINT32_MAX || !fill || !(g->items = malloc((items ? items : 1) * sizeof *g->items))) {
        free(range);
        free(fill);
        return ISO_E_NOMEM;
    }
    for (size_t c = 0; c < total; c++)
        g->start[c + 1] += g->start[c];
    memcpy(fill, g->start, total * sizeof *fill);
    for (size_t t = 0; t < triangles; t++) {
        const uint16_t *r = range + 6 * t;
        for (int k = r[2]; k <= r[5]; k++)
            for (int j = r[1]; j <= r[4]; j++)
                for (int i = r[0]; i <= r[3]; i++)
                    g->items[fill[cell_index(g, i, j, k)]++] = (uint32_t)t;
    }
    free(range);
    free(fill);
    return 0;
}

/* PASS 1: the mesh's corners into out, sorted by the fine cell of their first corner
 * (a counting sort), so that the triangles a cell lists lie together in memory. */
static int sort_corners(const grid *g, const iso_mesh *m, size_t total, float *out)
{
    uint32_t *count = calloc(total + 1, sizeof *count);
    uint32_t *cell = malloc((m->triangle_count + 1) * sizeof *cell);
    if (!count || !cell) {
        free(count);
        free(cell);
        return ISO_E_NOMEM;
    }
    for (size_t t = 0; t < m->triangle_count; t++) {
        const float *p = m->positions + 3 * (size_t)m->indices[3 * t];
        cell[t] = (uint32_t)cell_index(g, cell_of(g, p[0], 0), cell_of(g, p[1], 1), cell_of(g, p[2], 2));
        count[cell[t] + 1]++;
    }
    for (size_t c = 0; c < total; c++)
        count[c + 1] += count[c];
    for (size_t t = 0; t < m->triangle_count; t++) {
        float *c = out + 9 * (size_t)count[cell[t]]++;
        for (int k = 0; k < 3; k++)
            memcpy(c + 3 * k, m->positions + 3 * (size_t)m->indices[3 * t + k], 3 * sizeof(float));
    }
    free(count);
    free(cell);
    return 0;
}

/* PASS 1: each slot's bounding box, from its corners. */
static void boxes_of(const float *corners, size_t triangles, float *boxes)
{
    for (size_t t = 0; t < triangles; t++) {
        const float *c = corners + 9 * t;
        float *b = boxes + 6 * t;
        for (int a = 0; a < 3; a++) {
            float x = c[a], y = c[3 + a], z = c[6 + a];
            b[a] = x < y ? (x < z ? x : z) : (y < z ? y : z);
            b[3 + a] = x > y ? (x > z ? x : z) : (y > z ? y : z);
        }
    }
}

int iso_mesh_grid_build(const iso_mesh *mesh, const float lo[3], const float hi[3],
                        iso_mesh_grid **out)
{
    iso_mesh_grid *g = calloc(1, sizeof *g);
    *out = NULL;
    size_t T = mesh->triangle_count, fine = 0, coarse = 0;
    if (!g)
        return ISO_E_NOMEM;
    if (!(g->corners = malloc((9 * T + 1) * sizeof *g->corners)) ||
        !(g->boxes = malloc((6 * T + 1) * sizeof *g->boxes))) {
        iso_mesh_grid_destroy(g);
        return ISO_E_NOMEM;
    }
    g->triangle_count = T;
    if (grid_shape(&g->fine, T, lo, hi, 4.0, &fine) ||
        grid_shape(&g->coarse, T, lo, hi, 4.0 / (COARSE * COARSE * COARSE), &coarse) ||
        sort_corners(&g->fine, mesh, fine, g->corners)) {
        iso_mesh_grid_destroy(g);
        return ISO_E_NOMEM;
    }
    boxes_of(g->corners, T, g->boxes);
    if (grid_fill(&g->fine, g->boxes, T, fine) || grid_fill(&g->coarse, g->boxes, T, coarse)) {
        iso_mesh_grid_destroy(g);
        return ISO_E_NOMEM;
    }
    *out = g;
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

/* A nearest-triangle search's state: the best squared distance and its triangle. */
typedef struct search {
    double best;
    uint32_t triangle;
    double stop; /* any triangle within this (squared) ends the search; 0: the nearest */
} search;

static void corners_of(const float *f, double c[3][3])
{
    for (int k = 0; k < 3; k++)
        c[k][0] = f[3 * k], c[k][1] = f[3 * k + 1], c[k][2] = f[3 * k + 2];
}

/* The squared distance from p to box b (6 floats: lowest corner, highest). */
static inline double box_gap_sq(const float *b, const double p[3])
{
    double gap = 0;
    for (int a = 0; a < 3; a++) {
        double below = b[a] - p[a], above = p[a] - b[3 + a];
        double d = below > 0 ? below : above > 0 ? above : 0;
        gap += d * d;
    }
    return gap;
}

/* The triangles of cell `at`, each skipped when its box is no nearer than the best. */
static void search_cell(const grid *g, const iso_mesh_grid *ix, size_t at, const double p[3],
                        search *s)
{
    for (uint32_t e = g->start[at]; e < g->start[at + 1]; e++) {
        const float *f = ix->corners + 9 * (size_t)g->items[e];
        if (box_gap_sq(ix->boxes + 6 * (size_t)g->items[e], p) >= s->best)
            continue;
        double tc[3][3];
        corners_of(f, tc);
        double d = point_triangle_sq(p, tc);
        if (d < s->best) {
            s->best = d, s->triangle = g->items[e];
            if (d <= s->stop)
                return;
        }
    }
}

/* The cells of box lo..hi (cell ranges) not within Chebyshev distance `done` of cell c,
 * each skipped when it holds nothing or is no nearer than the best. */
static void search_box(const grid *g, const iso_mesh_grid *ix, const double p[3], const int c[3],
                       int done, const int lo[3], const int hi[3], search *s)
{
    for (int k = lo[2]; k <= hi[2]; k++)
        for (int j = lo[1]; j <= hi[1]; j++) {
            int inner = abs(k - c[2]) <= done && abs(j - c[1]) <= done;
            for (int i = lo[0]; i <= hi[0]; i++) {
                if (inner && abs(i - c[0]) <= done) {
                    i = c[0] + done; /* the rows' scanned middle */
                    continue;
                }
                size_t at = cell_index(g, i, j, k);
                int cell[3] = {i, j, k};
                if (g->start[at] != g->start[at + 1] && cell_gap_sq(g, p, cell) < s->best) {
                    search_cell(g, ix, at, p, s);
                    if (s->best <= s->stop)
                        return;
                }
            }
        }
}

/* PASS 4 in one grid: the cells at Chebyshev distance r from p's cell, r = 0, 1, ...,
 * `rings`, until some triangle is found at distance d; then the cells of the box p +- d
 * not scanned yet (a nearer triangle must cross one of them), when that box is at most
 * `rings` + 1 cells from p's cell. Returns 1 when the search is over: the best is the
 * nearest, or within `stop`; 0 when it must go on in a coarser grid. */
static int search_rings(const grid *g, const iso_mesh_grid *ix, const double p[3], int rings,
                        search *s)
{
    int c[3];
    for (int a = 0; a < 3; a++)
        c[a] = cell_of(g, p[a], a);
    double entry = s->best; /* a bound brought in is no reason to scan its whole box */
    for (int r = 0;; r++) {
        if (s->best <= s->stop)
            return 1;
        if (s->best < entry) {
            double d = sqrt(s->best);
            int lo[3], hi[3], within = 1;
            for (int a = 0; a < 3; a++) {
                lo[a] = cell_of(g, p[a] - d, a), hi[a] = cell_of(g, p[a] + d, a);
                within &= c[a] - lo[a] <= rings && hi[a] - c[a] <= rings;
            }
            if (!within)
                return 0;
            search_box(g, ix, p, c, r - 1, lo, hi, s);
            return 1;
        }
        if (r == rings)
            return 0;
        int lo[3], hi[3], whole = 1;
        double reach = INFINITY; /* from p to where ring r + 1 begins */
        for (int a = 0; a < 3; a++) {
            lo[a] = c[a] - r < 0 ? 0 : c[a] - r;
            hi[a] = c[a] + r >= g->n[a] ? g->n[a] - 1 : c[a] + r;
            double to_lo = p[a] - (g->lo[a] + lo[a] * g->h);
            double to_hi = g->lo[a] + (hi[a] + 1) * g->h - p[a];
            if (lo[a] > 0)
                reach = to_lo < reach ? to_lo : reach, whole = 0;
            if (hi[a] < g->n[a] - 1)
                reach = to_hi < reach ? to_hi : reach, whole = 0;
        }
        search_box(g, ix, p, c, r - 1, lo, hi, s);
        if (whole || (reach > 0 && s->best <= reach * reach))
            return 1;
    }
}

/* The nearest triangle's squared distance, or any triangle's within `stop` (squared; 0:
 * the nearest); s may come in with a bound already (a triangle and its distance). */
static void nearest(const iso_mesh_grid *ix, const double p[3], double stop, search *s)
{
    s->stop = stop;
    if (!search_rings(&ix->fine, ix, p, FINE_RINGS, s))
        search_rings(&ix->coarse, ix, p, INT32_MAX, s);
}

/* PASS 5's first try in one fine cell: the first of its triangles within `stop` (squared)
 * of p, trying only those whose boxes lie that close. Returns 1 with s holding it, else 0. */
static int probe_cell(const iso_mesh_grid *ix, size_t at, const double p[3], double stop, search *s)
{
    const grid *g = &ix->fine;
    for (uint32_t e = g->start[at]; e < g->start[at + 1]; e++) {
        if (box_gap_sq(ix->boxes + 6 * (size_t)g->items[e], p) > stop)
            continue;
        double tc[3][3];
        corners_of(ix->corners + 9 * (size_t)g->items[e], tc);
        double d = point_triangle_sq(p, tc);
        if (d <= stop) {
            s->best = d, s->triangle = g->items[e];
            return 1;
        }
    }
    return 0;
}

/* PASS 5's first try: any triangle within `stop` (squared) of p, among the fine cells the
 * box p +- sqrt(stop) covers (when it covers at most PROBE_CELLS a side), p's own cell
 * first. Returns 1 with s holding the one found, else 0 with s untouched: the search must
 * then find the nearest. */
static int probe(const iso_mesh_grid *ix, const double p[3], double stop, search *s)
{
    const grid *g = &ix->fine;
    double r = sqrt(stop);
    r = r < g->h ? r : g->h; /* most samples lie much nearer than the maximum */
    int lo[3], hi[3], c[3];
    for (int a = 0; a < 3; a++)
        c[a] = cell_of(g, p[a], a);
    /* The box p +- r, r at most a cell, spans at most PROBE_CELLS cells a side: p's own
     * cell, which settles most samples, is tried before the box's range is found. */
    size_t own = cell_index(g, c[0], c[1], c[2]);
    if (probe_cell(ix, own, p, stop, s))
        return 1;
    for (int a = 0; a < 3; a++) {
        lo[a] = cell_of(g, p[a] - r, a), hi[a] = cell_of(g, p[a] + r, a);
        if (hi[a] - lo[a] >= PROBE_CELLS)
            return 0;
    }
    for (int k = lo[2]; k <= hi[2]; k++)
        for (int j = lo[1]; j <= hi[1]; j++)
            for (int i = lo[0]; i <= hi[0]; i++) {
                int cell[3] = {i, j, k};
                size_t at = cell_index(g, i, j, k);
                if (at != own && g->start[at] != g->start[at + 1] && cell_gap_sq(g, p, cell) <= stop &&
                    probe_cell(ix, at, p, stop, s))
                    return 1;
            }
    return 0;
}

/* How many sub-triangles a side of triangle t is cut into (PASS 2). */
static int subdivisions(const double c[3][3], double spacing)
{
    double longest = 0;
    for (int e = 0; e < 3; e++) {
        double d[3];
        for (int k = 0; k < 3; k++)
            d[k] = c[(e + 1) % 3][k] - c[e][k];
        double l = dot(d, d);
        longest = l > longest ? l : longest;
    }
    if (longest <= spacing * spacing * (1 - 1e-9)) /* uncut, whatever the rounding below */
        return 1;
    double n = spacing > 0 ? ceil(sqrt(longest) / spacing) : 1;
    return n < 1 ? 1 : n > 256 ? 256 : (int)n;
}

static double triangle_area(const double c[3][3])
{
    double u[3], v[3], x[3];
    for (int k = 0; k < 3; k++)
        u[k] = c[1][k] - c[0][k], v[k] = c[2][k] - c[0][k];
    x[0] = u[1] * v[2] - u[2] * v[1], x[1] = u[2] * v[0] - u[0] * v[2], x[2] = u[0] * v[1] - u[1] * v[0];
    return 0.5 * sqrt(dot(x, x));
}

typedef struct direction {
    const iso_mesh *src;
    const iso_mesh_grid *dst;
    const size_t *first;      /* per source triangle: its first centroid sample */
    const double *area;       /* per source triangle: the area before it (cap + 1 entries) */
    const uint32_t *vertices; /* the source's used vertices not on the target (PASS 2) */
    size_t vertex_count;
    const double *known;      /* per source triangle, or NULL: KNOWN_NONE, KNOWN_OWN (its
                               * samples lie on the target's triangle of the same
                               * corners), or a squared bound of its samples' distances */
    double *bound;            /* out per source triangle, or NULL: the same, found here */
    size_t drawn;             /* PASS 3 points drawn (0: the centroids are the samples) */
    float *dist, *weight;     /* per percentile sample */
    double start_max;         /* the largest percentile sample's distance (PASS 5) */
    int exhaustive;           /* PASS 5 without block tests (for checks) */
    int select;               /* PASS 4 by select_top (drawn points, no mean wanted) */
    const float *block_boxes; /* PASS 5's boxes of whole blocks (iso_mesh_samples), or NULL */
    atomic_size_t next_chunk; /* PASS 5's next chunk to claim (measure_max) */
    double part_max[ISO_PARALLEL_MAX_THREADS];
    int part_failed[ISO_PARALLEL_MAX_THREADS]; /* a share had no memory for its points */
} direction;

/* PASS 2's centroid samples of triangle c cut n x n, and their weight (area / n^2). */
static int centroids(const double c[3][3], int n, double (*out)[3])
{
    double u[3], v[3];
    for (int k = 0; k < 3; k++)
        u[k] = c[1][k] - c[0][k], v[k] = c[2][k] - c[0][k];
    int s = 0;
    /* Upward sub-triangles (i, j), i + j < n, centroid (i + 1/3, j + 1/3) / n; downward
     * ones, i + j < n - 1, centroid (i + 2/3, j + 2/3) / n. */
    for (int down = 0; down < 2; down++)
        for (int i = 0; i < n; i++)
            for (int j = 0; i + j < n - down; j++, s++) {
                double a = (i + (down ? 2.0 : 1.0) / 3) / n, b = (j + (down ? 2.0 : 1.0) / 3) / n;
                for (int k = 0; k < 3; k++)
                    out[s][k] = c[0][k] + a * u[k] + b * v[k];
            }
    return s;
}

/* splitmix64: the stratum's random numbers, from its index alone. */
static uint64_t mix(uint64_t x)
{
    x += 0x9e3779b97f4a7c15u;
    x = (x ^ (x >> 30)) * 0xbf58476d1ce4e5b9u;
    x = (x ^ (x >> 27)) * 0x94d049bb133111ebu;
    return x ^ (x >> 31);
}

static double unit(uint64_t x)
{
    return (double)(x >> 11) * 0x1.0p-53;
}

/* PASS 3 for stratum i: a point uniformly random by area in its triangle. */
static void draw(const direction *d, size_t i, double p[3])
{
    size_t T = d->src->triangle_count;
    double total = d->area[T];
    double at = ((double)i + unit(mix(2 * i))) * total / (double)d->drawn;
    size_t lo = 0, hi = T - 1; /* the last triangle whose area begins at or before `at` */
    while (lo < hi) {
        size_t mid = lo + (hi - lo + 1) / 2;
        if (d->area[mid] <= at)
            lo = mid;
        else
            hi = mid - 1;
    }
    uint64_t r = mix(2 * i + 1);
    double s = sqrt(unit(r)), t = unit(mix(r));
    double c[3][3];
    triangle_corners(d->src, lo, c);
    for (int k = 0; k < 3; k++)
        p[k] = (1 - s) * c[0][k] + s * (1 - t) * c[1][k] + s * t * c[2][k];
}

/* PASS 4's cheap bound when selecting (direction.select): the distance to the hint's
 * triangle or to the nearest of p's own fine cell, whichever is less; the hint becomes
 * that triangle. */
static void bound_nearby(const iso_mesh_grid *ix, const double p[3], uint32_t *hint, search *s)
{
    const grid *g = &ix->fine;
    if (*hint != NO_TRIANGLE) {
        double tc[3][3];
        corners_of(ix->corners + 9 * (size_t)*hint, tc);
        s->best = point_triangle_sq(p, tc), s->triangle = *hint;
    }
    search_cell(g, ix, cell_index(g, cell_of(g, p[0], 0), cell_of(g, p[1], 1), cell_of(g, p[2], 2)), p, s);
    *hint = s->triangle;
}

/* A drawn point and its bound, in a max-heap by bound for select_top. */
typedef struct ranked {
    float bound;
    uint32_t at;
} ranked;

static void sift_down(ranked *h, size_t n, size_t i)
{
    ranked v = h[i];
    for (size_t c = 2 * i + 1; c < n; i = c, c = 2 * c + 1) {
        c += c + 1 < n && h[c + 1].bound > h[c].bound;
        if (h[c].bound <= v.bound)
            break;
        h[i] = h[c];
    }
    h[i] = v;
}

/* A min-heap of n floats: v pushed, the least dropped past `cap` of them. */
static void heap_push(float *h, size_t *n, size_t cap, float v)
{
    size_t i = *n;
    if (i == cap) {
        if (v <= h[0])
            return;
        i = 0; /* v replaces the least and sinks */
        for (size_t c = 1; c < cap; i = c, c = 2 * c + 1) {
            c += c + 1 < cap && h[c + 1] < h[c];
            if (h[c] >= v)
                break;
            h[i] = h[c];
        }
        h[i] = v;
        return;
    }
    for (++*n; i > 0 && h[(i - 1) / 2] > v; i = (i - 1) / 2)
        h[i] = h[(i - 1) / 2];
    h[i] = v;
}

/* PASS 4's selection, after the cheap bounds (d->dist holds them): the drawn points weigh
 * 1 each, so the 99th percentile is the K-th largest distance, K = drawn - ceil(0.99
 * drawn) + 1. Points are measured exactly in order of their bounds, largest first, until
 * the next bound lies below the K-th largest exact distance so far (theta, with a margin
 * for rounding): no point left can be farther than theta, so theta is the K-th largest of
 * all, and each point left keeps its bound, which is below it. The percentile and the
 * largest distance of pass 6 are then what measuring every point gives, bit for bit;
 * the mean is not (the caller did not ask for it). Returns 0 or ISO_E_NOMEM. */
static int select_top(direction *d)
{
    size_t n = d->drawn, K = n - (size_t)ceil(0.99 * (double)n) + 1, count = 0;
    ranked *order = malloc(n * sizeof *order);
    float *heap = malloc(K * sizeof *heap);
    if (!order || !heap) {
        free(order);
        free(heap);
        return ISO_E_NOMEM;
    }
    for (size_t i = 0; i < n; i++)
        order[i] = (ranked){d->dist[i], (uint32_t)i};
    for (size_t i = n / 2; i-- > 0;)
        sift_down(order, n, i);
    for (size_t left = n; left > 0; left--) {
        if (count == K && (double)order[0].bound * (1 + 1e-6) < heap[0])
            break;
        uint32_t at = order[0].at;
        order[0] = order[left - 1];
        sift_down(order, left - 1, 0);
        double p[3];
        draw(d, at, p);
        search s = {INFINITY, NO_TRIANGLE, 0};
        nearest(d->dst, p, 0, &s);
        d->dist[at] = (float)sqrt(s.best);
        heap_push(heap, &count, K, d->dist[at]);
    }
    free(order);
    free(heap);
    return 0;
}

/* PASS 4 on one thread's share of the percentile samples. */
static void measure_percentile(void *context, int part, int parts)
{
    direction *d = context;
    const iso_mesh *m = d->src;
    if (d->drawn) {
        size_t i0 = d->drawn * (size_t)part / (size_t)parts, i1 = d->drawn * (size_t)(part + 1) / (size_t)parts;
        uint32_t hint = NO_TRIANGLE;
        for (size_t i = i0; i < i1; i++) {
            double p[3];
            draw(d, i, p);
            search s = {INFINITY, NO_TRIANGLE, 0};
            if (d->select)
                bound_nearby(d->dst, p, &hint, &s);
            else
                nearest(d->dst, p, 0, &s);
            d->dist[i] = (float)sqrt(s.best);
            d->weight[i] = 1;
        }
        return;
    }
    size_t t0 = m->triangle_count * (size_t)part / (size_t)parts;
    size_t t1 = m->triangle_count * (size_t)(part + 1) / (size_t)parts;
    double (*pts)[3] = malloc(256 * 256 * sizeof *pts);
    d->part_failed[part] = !pts;
    for (size_t t = t0; pts && t < t1; t++) {
        double c[3][3];
        triangle_corners(m, t, c);
        int n = (int)lround(sqrt((double)(d->first[t + 1] - d->first[t])));
        int count = centroids(c, n, pts);
        double w = triangle_area(c) / ((double)n * n), bound = 0;
        for (int k = 0; k < count; k++) {
            search s = {INFINITY, NO_TRIANGLE, 0};
            nearest(d->dst, pts[k], 0, &s);
            d->dist[d->first[t] + (size_t)k] = (float)sqrt(s.best);
            d->weight[d->first[t] + (size_t)k] = (float)w;
            bound = s.best > bound ? s.best : bound;
        }
        if (d->bound)
            d->bound[t] = bound;
    }
    free(pts);
}

/* PASS 5 for one point: raises *max (squared) when p lies farther from the target.
 * Returns the square of a distance p does not exceed (its own when it raised *max). */
static double raise_max(const iso_mesh_grid *dst, const double p[3], uint32_t *hint, double *max)
{
    search s = {INFINITY, NO_TRIANGLE, 0};
    if (*hint != NO_TRIANGLE) {
        double tc[3][3], corner = INFINITY;
        corners_of(dst->corners + 9 * (size_t)*hint, tc);
        for (int k = 0; k < 3; k++) { /* a corner within the maximum settles it cheaper */
            double x = p[0] - tc[k][0], y = p[1] - tc[k][1], z = p[2] - tc[k][2];
            double e = x * x + y * y + z * z;
            corner = e < corner ? e : corner;
        }
        if (corner <= *max)
            return corner;
        s.best = point_triangle_sq(p, tc), s.triangle = *hint;
        if (s.best <= *max)
            return s.best;
    }
    if (probe(dst, p, *max, &s)) {
        *hint = s.triangle;
        return s.best;
    }
    nearest(dst, p, *max, &s);
    *hint = s.triangle;
    if (s.best > *max)
        *max = s.best;
    return s.best;
}

/* PASS 5's block test. The points of a block (a run of source triangles' corners, or of
 * vertices) lie in box lo..hi, whose half diagonal is r from its centre c; distance to a
 * surface grows by at most the distance moved, so when some target triangle lies within
 * sqrt(max) - r of c, no point of the block (nor any sample inside its triangles) lies
 * farther than sqrt(max) from the target, and none can raise the maximum. The previous
 * witness (*hint) is tried first, then the fine cells around c. A slack of 1e-7 of the
 * coordinates' size keeps rounding from letting a sample past the bound. Returns 1 with
 * *bound the square of a distance no point of the block exceeds, else 0. */
static int block_within(const iso_mesh_grid *dst, const float lo[3], const float hi[3], double max,
                        uint32_t *hint, double *bound)
{
    double c[3], r = 0, size = 0;
    for (int a = 0; a < 3; a++) {
        double half = 0.5 * ((double)hi[a] - lo[a]);
        c[a] = 0.5 * ((double)hi[a] + lo[a]);
        r += half * half;
        size = fmax(size, fabs(c[a]) + half);
    }
    r = sqrt(r) + 1e-7 * size;
    double room = sqrt(max) - r;
    if (!(room > 0))
        return 0;
    search s = {INFINITY, NO_TRIANGLE, 0};
    if (*hint != NO_TRIANGLE) {
        double tc[3][3];
        corners_of(dst->corners + 9 * (size_t)*hint, tc);
        s.best = point_triangle_sq(c, tc), s.triangle = *hint;
    }
    if (!(s.best <= room * room) && !probe(dst, c, room * room, &s))
        return 0;
    *hint = s.triangle;
    double u = sqrt(s.best) + r;
    *bound = u * u;
    return 1;
}

/* The box of the n points positions[3 v[i]] (lo, hi), i < n: in six scalars, so that the
 * compiler keeps them in registers (the points could alias arrays). */
static void points_box(const float *positions, const uint32_t *v, size_t n, float lo[3], float hi[3])
{
    float x0 = INFINITY, y0 = INFINITY, z0 = INFINITY, x1 = -INFINITY, y1 = -INFINITY, z1 = -INFINITY;
    for (size_t i = 0; i < n; i++) {
        const float *p = positions + 3 * (size_t)v[i];
        float x = p[0], y = p[1], z = p[2];
        x0 = x < x0 ? x : x0, y0 = y < y0 ? y : y0, z0 = z < z0 ? z : z0;
        x1 = x > x1 ? x : x1, y1 = y > y1 ? y : y1, z1 = z > z1 ? z : z1;
    }
    lo[0] = x0, lo[1] = y0, lo[2] = z0, hi[0] = x1, hi[1] = y1, hi[2] = z1;
}

/* The box of source triangles t0..t1 - 1's corners. */
static void triangles_box(const iso_mesh *m, size_t t0, size_t t1, float lo[3], float hi[3])
{
    points_box(m->positions, m->indices + 3 * t0, 3 * (t1 - t0), lo, hi);
}

/* PASS 5 for source triangle t's centroids (pts: room for them). A triangle whose known
 * bound is within *max cannot raise it and is skipped; so is one of several samples whose
 * corners pass the block test alone. One whose samples lie on the target's triangle of
 * the same corners tries that triangle first. Returns the square of a distance none of
 * its samples exceeds. */
static double raise_max_triangle(const direction *d, size_t t, double (*pts)[3], uint32_t *hint,
                                 double *max)
{
    double known = d->known ? d->known[t] : KNOWN_NONE, bound = 0, c[3][3];
    if (known >= 0 && known <= *max)
        return known;
    int n = (int)lround(sqrt((double)(d->first[t + 1] - d->first[t])));
    float lo[3], hi[3];
    if (n > 1 && known != KNOWN_OWN && !d->exhaustive) {
        triangles_box(d->src, t, t + 1, lo, hi);
        if (block_within(d->dst, lo, hi, *max, hint, &bound))
            return bound;
    }
    triangle_corners(d->src, t, c);
    centroids(c, n, pts);
    /* In an order where each sample lies next to the one before, so that its nearest
     * triangle is the likelier hint: row by row (rows start at `up` and `down` in pts),
     * each row's upward and downward sub-triangles alternating, every other row backwards. */
    for (int i = 0, up = 0, down = n * (n + 1) / 2; i < n; up += n - i, down += n - 1 - i, i++)
        for (int q = 0, m = 2 * (n - i) - 1; q < m; q++) {
            int r = i % 2 ? m - 1 - q : q, k = r % 2 ? down + r / 2 : up + r / 2;
            double own = known == KNOWN_OWN ? point_triangle_sq(pts[k], c) : INFINITY;
            double u = own <= *max ? own : raise_max(d->dst, pts[k], hint, max);
            bound = u > bound ? u : bound;
        }
    return bound;
}

/* PASS 5 for source triangles t0..t1 - 1: a block test over them all first (a skipped
 * triangle's bound is the smaller of the block's and what was known of it), else each on
 * its own. */
static void raise_max_block(const direction *d, size_t t0, size_t t1, double (*pts)[3], uint32_t *hint,
                            double *max)
{
    float lo[3], hi[3];
    double u;
    if (d->block_boxes && t0 % BLOCK == 0 && t1 - t0 == BLOCK) {
        memcpy(lo, d->block_boxes + 6 * (t0 / BLOCK), sizeof lo);
        memcpy(hi, d->block_boxes + 6 * (t0 / BLOCK) + 3, sizeof hi);
    } else {
        triangles_box(d->src, t0, t1, lo, hi);
    }
    if (!d->exhaustive && block_within(d->dst, lo, hi, *max, hint, &u)) {
        for (size_t t = t0; d->bound && t < t1; t++) {
            double known = d->known ? d->known[t] : KNOWN_NONE;
            d->bound[t] = known >= 0 && known < u ? known : u;
        }
        return;
    }
    for (size_t t = t0; t < t1; t++) {
        double bound = raise_max_triangle(d, t, pts, hint, max);
        if (d->bound)
            d->bound[t] = bound;
    }
}

/* PASS 5 for the used vertices i0..i1 - 1 of the list: a block test, else each on its own. */
static void raise_max_vertices(const direction *d, size_t i0, size_t i1, uint32_t *hint, double *max)
{
    const float *positions = d->src->positions;
    float lo[3], hi[3];
    double u;
    points_box(positions, d->vertices + i0, i1 - i0, lo, hi);
    if (!d->exhaustive && block_within(d->dst, lo, hi, *max, hint, &u))
        return;
    for (size_t i = i0; i < i1; i++) {
        const float *f = positions + 3 * (size_t)d->vertices[i];
        double p[3] = {f[0], f[1], f[2]};
        raise_max(d->dst, p, hint, max);
    }
}

/* PASS 5 on one thread's share: chunks of CHUNK_BLOCKS blocks of the centroids (when pass 3
 * drew its own points), then of the vertices, claimed in turn, so that no thread idles while
 * another still has blocks the bounds do not settle (where they do varies a lot along a
 * surface). Each thread keeps its own maximum and hint; the maximum is exact whichever
 * thread measures which sample, so the result is the same on any number of threads. */
#define CHUNK_BLOCKS 16
static void measure_max(void *context, int part, int parts)
{
    direction *d = context;
    const iso_mesh *m = d->src;
    (void)parts;
    double max = d->start_max * d->start_max;
    uint32_t hint = NO_TRIANGLE;
    double (*pts)[3] = d->drawn ? malloc(256 * 256 * sizeof *pts) : NULL;
    const size_t chunk = CHUNK_BLOCKS * BLOCK;
    size_t triangle_chunks = d->drawn ? (m->triangle_count + chunk - 1) / chunk : 0;
    size_t chunks = triangle_chunks + (d->vertex_count + chunk - 1) / chunk;
    for (size_t c; (c = atomic_fetch_add(&d->next_chunk, 1)) < chunks;) {
        if (c < triangle_chunks && !pts)
            continue; /* part_failed: the measure reports no memory */
        size_t n = c < triangle_chunks ? m->triangle_count : d->vertex_count;
        size_t i0 = (c < triangle_chunks ? c : c - triangle_chunks) * chunk, i1 = i0 + chunk < n ? i0 + chunk : n;
        for (size_t i = i0; i < i1; i += BLOCK) { /* blocks from 0, as the cached boxes */
            size_t e = i + BLOCK < i1 ? i + BLOCK : i1;
            if (c < triangle_chunks)
                raise_max_block(d, i, e, pts, &hint, &max);
            else
                raise_max_vertices(d, i, e, &hint, &max);
        }
    }
    d->part_max[part] = sqrt(max);
    d->part_failed[part] |= d->drawn && !pts;
    free(pts);
}

static int compare_floats(const void *pa, const void *pb)
{
    float a = *(const float *)pa, b = *(const float *)pb;
    return (a > b) - (a < b);
}

/* PASS 6: the weighted 99th percentile and mean. Returns 0 or ISO_E_NOMEM. */
static int percentile(const float *dist, const float *weight, size_t n, double *p99, double *mean)
{
    double total = 0, top = 0, sum = 0;
    for (size_t i = 0; i < n; i++) {
        total += weight[i];
        sum += (double)dist[i] * weight[i];
        top = top > dist[i] ? top : dist[i];
    }
    *p99 = 0;
    *mean = total > 0 ? sum / total : 0;
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

typedef struct one_way_result {
    double p99, max, mean, area;
    size_t samples, drawn;
} one_way_result;

/* PASS 2: per source triangle its first centroid sample and the area before it (first and
 * area: triangle_count + 1 entries). */
static void count_samples(const iso_mesh *src, double spacing, size_t *first, double *area)
{
    first[0] = 0, area[0] = 0;
    for (size_t t = 0; t < src->triangle_count; t++) {
        double c[3][3];
        triangle_corners(src, t, c);
        size_t n = (size_t)subdivisions(c, spacing);
        first[t + 1] = first[t] + n * n;
        area[t + 1] = area[t] + triangle_area(c);
    }
}

struct iso_mesh_samples {
    double spacing;
    size_t triangle_count;
    size_t *first;
    double *area;
    float lo[3], hi[3];
    float *boxes; /* 6 per whole BLOCK of triangles from 0 (PASS 5's blocks) */
};

int iso_mesh_samples_build(const iso_mesh *mesh, double spacing, iso_mesh_samples **out)
{
    iso_mesh_samples *s = calloc(1, sizeof *s);
    *out = NULL;
    size_t blocks = mesh->triangle_count / BLOCK;
    if (!s || !(s->first = malloc((mesh->triangle_count + 1) * sizeof *s->first)) ||
        !(s->area = malloc((mesh->triangle_count + 1) * sizeof *s->area)) ||
        !(s->boxes = malloc((6 * blocks + 1) * sizeof *s->boxes))) {
        iso_mesh_samples_destroy(s);
        return ISO_E_NOMEM;
    }
    s->spacing = spacing;
    s->triangle_count = mesh->triangle_count;
    count_samples(mesh, spacing, s->first, s->area);
    for (size_t b = 0; b < blocks; b++)
        triangles_box(mesh, b * BLOCK, (b + 1) * BLOCK, s->boxes + 6 * b, s->boxes + 6 * b + 3);
    iso_mesh_bounds(mesh, s->lo, s->hi);
    *out = s;
    return 0;
}

void iso_mesh_samples_destroy(iso_mesh_samples *s)
{
    if (!s)
        return;
    free(s->first);
    free(s->area);
    free(s->boxes);
    free(s);
}

/* PASS 2: the vertices src uses (*used_count) and of them those to measure: when the
 * target shares the source's positions array, a vertex both use lies on the target, at
 * distance 0. Returns 0 or ISO_E_NOMEM. */
static int enumerate(const iso_mesh *src, const iso_mesh *dst, uint32_t **vertices, size_t *vertex_count,
                     size_t *used_count)
{
    unsigned char *used = calloc(src->vertex_count ? src->vertex_count : 1, 1);
    if (!used)
        return ISO_E_NOMEM;
    if (dst->positions == src->positions)
        for (size_t i = 0; i < 3 * dst->triangle_count; i++)
            if (dst->indices[i] < src->vertex_count)
                used[dst->indices[i]] = 2;
    size_t count = 0, all = 0;
    for (size_t i = 0; i < 3 * src->triangle_count; i++) {
        unsigned char *u = &used[src->indices[i]];
        if (!(*u & 1))
            count += !*u, all++, *u |= 1;
    }
    if (!(*vertices = malloc((count ? count : 1) * sizeof **vertices))) {
        free(used);
        return ISO_E_NOMEM;
    }
    for (size_t v = 0, i = 0; v < src->vertex_count; v++)
        if (used[v] == 1)
            (*vertices)[i++] = (uint32_t)v;
    *vertex_count = count;
    *used_count = all;
    free(used);
    return 0;
}

/* PASS 2 with reuse: per triangle of src, what the prior measure knows of it (the
 * direction's `known`): a hash of the prior's triangles by their three indices in order.
 * Returns 0 or ISO_E_NOMEM. */
static int match_prior(const iso_mesh *src, const iso_mesh *dst, const iso_mesh_distance_reuse *reuse,
                       double *known)
{
    size_t slots = 2;
    while (slots < 2 * reuse->prior_triangles)
        slots *= 2;
    uint32_t *table = malloc(slots * sizeof *table);
    if (!table)
        return ISO_E_NOMEM;
    memset(table, 0xff, slots * sizeof *table);
    const uint32_t *pi = reuse->prior_indices;
    for (size_t t = 0; t < reuse->prior_triangles; t++) {
        size_t at = (size_t)mix(((uint64_t)pi[3 * t] << 32 | pi[3 * t + 1]) ^ mix(pi[3 * t + 2])) & (slots - 1);
        while (table[at] != UINT32_MAX)
            at = (at + 1) & (slots - 1);
        table[at] = (uint32_t)t;
    }
    /* Samples lie on the target's triangles only when both share the positions. */
    int own = !reuse->prior_bound && src->positions == dst->positions;
    for (size_t t = 0; t < src->triangle_count; t++) {
        const uint32_t *v = src->indices + 3 * t;
        size_t at = (size_t)mix(((uint64_t)v[0] << 32 | v[1]) ^ mix(v[2])) & (slots - 1);
        known[t] = KNOWN_NONE;
        for (; table[at] != UINT32_MAX; at = (at + 1) & (slots - 1)) {
            const uint32_t *q = pi + 3 * (size_t)table[at];
            if (q[0] == v[0] && q[1] == v[1] && q[2] == v[2]) {
                known[t] = reuse->prior_bound ? reuse->prior_bound[table[at]] : own ? KNOWN_OWN : KNOWN_NONE;
                break;
            }
        }
    }
    free(table);
    return 0;
}

/* One direction: from src's surface to dst's (its grid given), with what an earlier
 * measure knows of src's triangles (reuse, or NULL) and src's samples (cached, or NULL:
 * counted here). */
static int one_way(const iso_mesh *src, const iso_mesh *dst_mesh, const iso_mesh_grid *dst,
                   double spacing, size_t cap, int threads, const iso_mesh_distance_reuse *reuse,
                   const iso_mesh_samples *cached, one_way_result *out)
{
    *out = (one_way_result){0};
    if (!src->triangle_count)
        return 0;
    if (!dst->triangle_count) {
        out->p99 = out->max = out->mean = INFINITY;
        return 0;
    }
    if (cached && (cached->spacing != spacing || cached->triangle_count != src->triangle_count))
        cached = NULL;
    size_t *own_first = cached ? NULL : malloc((src->triangle_count + 1) * sizeof *own_first);
    double *own_area = cached ? NULL : malloc((src->triangle_count + 1) * sizeof *own_area);
    const size_t *first = cached ? cached->first : own_first;
    const double *area = cached ? cached->area : own_area;
    uint32_t *vertices = NULL;
    float *dist = NULL, *weight = NULL;
    double *known = NULL;
    size_t vertex_count = 0, used_count = 0;
    int rc = ISO_E_NOMEM;
    if (!first || !area || enumerate(src, dst_mesh, &vertices, &vertex_count, &used_count))
        goto done;
    if (!cached)
        count_samples(src, spacing, own_first, own_area);
    if (reuse && reuse->prior_indices &&
        (!(known = malloc(src->triangle_count * sizeof *known)) || match_prior(src, dst_mesh, reuse, known)))
        goto done;
    size_t centroids_n = first[src->triangle_count];
    size_t drawn = centroids_n > cap && area[src->triangle_count] > 0 ? cap : 0;
    size_t n = drawn ? drawn : centroids_n;
    if (!(dist = malloc((n ? n : 1) * sizeof *dist)) || !(weight = malloc((n ? n : 1) * sizeof *weight)))
        goto done;
    if (reuse && reuse->bound)
        for (size_t t = 0; t < src->triangle_count; t++)
            reuse->bound[t] = INFINITY; /* nothing known until a pass finds it */
    direction d = {.src = src, .dst = dst, .first = first, .area = area, .vertices = vertices,
                   .vertex_count = vertex_count, .drawn = drawn, .dist = dist, .weight = weight,
                   .known = known, .bound = reuse ? reuse->bound : NULL,
                   .exhaustive = reuse && reuse->exhaustive,
                   .select = drawn && reuse && reuse->without_mean && !reuse->exhaustive,
                   .block_boxes = cached ? cached->boxes : NULL};
    int workers = iso_parallel_threads(threads);
    iso_parallel_run(workers, measure_percentile, &d); /* PASS 3, 4 */
    for (int w = 0; w < workers; w++)
        if (d.part_failed[w])
            goto done;
    if (d.select && select_top(&d))
        goto done;
    for (size_t i = 0; i < n; i++)
        d.start_max = d.start_max > dist[i] ? d.start_max : dist[i];
    atomic_init(&d.next_chunk, 0);
    if (!(reuse && reuse->without_max))
        iso_parallel_run(workers, measure_max, &d); /* PASS 5 */
    out->max = reuse && reuse->without_max ? NAN : d.start_max;
    for (int w = 0; w < workers; w++) {
        if (d.part_failed[w])
            goto done;
        if (!isnan(out->max))
            out->max = out->max > d.part_max[w] ? out->max : d.part_max[w];
    }
    if ((rc = percentile(dist, weight, n, &out->p99, &out->mean))) /* PASS 6 */
        goto done;
    if (d.select)
        out->mean = NAN;
    out->area = area[src->triangle_count];
    out->samples = centroids_n + used_count;
    out->drawn = drawn;
done:
    free(own_first);
    free(own_area);
    free(known);
    free(vertices);
    free(dist);
    free(weight);
    return rc;
}

/* The box of a and b (a's from its samples when they are given). */
static void union_bounds(const iso_mesh *a, const iso_mesh_samples *sa, const iso_mesh *b, float lo[3],
                         float hi[3])
{
    float l2[3], h2[3];
    if (sa && sa->triangle_count == a->triangle_count) {
        memcpy(lo, sa->lo, sizeof sa->lo);
        memcpy(hi, sa->hi, sizeof sa->hi);
    } else {
        iso_mesh_bounds(a, lo, hi);
    }
    iso_mesh_bounds(b, l2, h2);
    for (int k = 0; k < 3; k++)
        lo[k] = lo[k] < l2[k] ? lo[k] : l2[k], hi[k] = hi[k] > h2[k] ? hi[k] : h2[k];
}

int iso_mesh_distance_between(const iso_mesh *a, const iso_mesh_grid *ga, const iso_mesh *b,
                              const iso_mesh_grid *gb, double spacing, size_t cap, int threads,
                              const iso_mesh_distance_reuse *reuse, iso_mesh_distance *out,
                              iso_error *err)
{
    double start = iso_clock_ms();
    *out = (iso_mesh_distance){0};
    if (!(spacing > 0) || !isfinite(spacing))
        return iso_error_set(err, ISO_E_ARGUMENT, "distance: sample spacing %g must be > 0", spacing);
    if (cap < 1)
        return iso_error_set(err, ISO_E_ARGUMENT, "distance: the sample cap must be at least 1");
    const iso_mesh_samples *sa = reuse ? reuse->a_samples : NULL;
    float lo[3], hi[3];
    union_bounds(a, sa, b, lo, hi);
    iso_mesh_grid *own_a = NULL, *own_b = NULL;
    int rc = 0;
    if ((!ga && (rc = iso_mesh_grid_build(a, lo, hi, &own_a))) ||
        (!gb && (rc = iso_mesh_grid_build(b, lo, hi, &own_b))))
        goto done;
    one_way_result ab, ba;
    iso_mesh_distance_reuse plain = {.exhaustive = reuse && reuse->exhaustive,
                                     .without_max = reuse && reuse->without_max,
                                     .without_mean = reuse && reuse->without_mean};
    if ((rc = one_way(a, b, gb ? gb : own_b, spacing, cap, threads, &plain, sa, &ab)) ||
        (rc = one_way(b, a, ga ? ga : own_a, spacing, cap, threads, reuse, NULL, &ba)))
        goto done;
    out->p99_ab = ab.p99, out->max_ab = ab.max, out->samples_a = ab.samples, out->drawn_a = ab.drawn;
    out->p99_ba = ba.p99, out->max_ba = ba.max, out->samples_b = ba.samples, out->drawn_b = ba.drawn;
    out->p99 = fmax(out->p99_ab, out->p99_ba);
    out->max = fmax(out->max_ab, out->max_ba);
    out->mean_ab = ab.mean, out->mean_ba = ba.mean;
    /* Pooled by area, so the mean is over both surfaces alike; an empty side is INFINITY
     * away from the other (above), and so is the mean. */
    out->mean = isnan(ab.mean) || isnan(ba.mean) ? NAN
                : ab.area + ba.area > 0 && isfinite(ab.mean) && isfinite(ba.mean)
                    ? (ab.mean * ab.area + ba.mean * ba.area) / (ab.area + ba.area)
                    : fmax(ab.mean, ba.mean);
done:
    iso_mesh_grid_destroy(own_a);
    iso_mesh_grid_destroy(own_b);
    out->ms = iso_clock_ms() - start;
    if (rc)
        return iso_error_set(err, rc, "distance: no memory for %zu and %zu triangles",
                             a->triangle_count, b->triangle_count);
    return 0;
}

int iso_mesh_distance_compute(const iso_mesh *a, const iso_mesh *b, double spacing, int threads,
                              iso_mesh_distance *out, iso_error *err)
{
    return iso_mesh_distance_between(a, NULL, b, NULL, spacing, ISO_DISTANCE_SAMPLES, threads,
                                     NULL, out, err);
}
