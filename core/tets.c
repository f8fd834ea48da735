/* tets.c: marching tetrahedra over a subdivided trilinear node, the Lemma 2 way. */
#include "tets.h"

#include <string.h>

#include "trilinear.h"

typedef struct grid {
    const double *c;   /* the node's corner values */
    double lo[3], size[3];
    uint32_t s[3];     /* sub-boxes per axis */
} grid;

static double grid_value(const grid *g, const uint32_t at[3])
{
    return iso_tri_eval(g->c, (double)at[0] / g->s[0], (double)at[1] / g->s[1],
                        (double)at[2] / g->s[2]);
}

/* Corner values of sub-box (x,y,z) in the corner order of trilinear.h. */
static void sub_box_corners(const grid *g, uint32_t x, uint32_t y, uint32_t z, double v[8])
{
    for (int k = 0; k < 8; k++) {
        uint32_t at[3] = {x + (k & 1), y + ((k >> 1) & 1), z + ((k >> 2) & 1)};
        v[k] = grid_value(g, at);
    }
}

static double worst_bound(const grid *g, size_t *examined)
{
    double worst = 0, v[8];
    for (uint32_t z = 0; z < g->s[2]; z++)
        for (uint32_t y = 0; y < g->s[1]; y++)
            for (uint32_t x = 0; x < g->s[0]; x++) {
                sub_box_corners(g, x, y, z, v);
                double b = iso_tri_kuhn_bound(v);
                if (b > worst)
                    worst = b;
            }
    *examined += (size_t)g->s[0] * g->s[1] * g->s[2];
    return worst;
}

typedef struct tet_vertex {
    uint32_t at[3]; /* grid point */
    double value;
} tet_vertex;

static int precedes(const tet_vertex *a, const tet_vertex *b)
{
    for (int d = 2; d >= 0; d--)
        if (a->at[d] != b->at[d])
            return a->at[d] < b->at[d];
    return 0;
}

/* The crossing on edge (a,b), always interpolated from the lower grid point so that the
 * tetrahedra sharing an edge produce bit-identical positions. */
static void crossing(const grid *g, const tet_vertex *a, const tet_vertex *b, double level,
                     float out[3])
{
    if (precedes(b, a)) {
        const tet_vertex *t = a;
        a = b;
        b = t;
    }
    double t = (level - a->value) / (b->value - a->value);
    for (int d = 0; d < 3; d++) {
        double pa = g->lo[d] + g->size[d] * a->at[d] / g->s[d];
        double pb = g->lo[d] + g->size[d] * b->at[d] / g->s[d];
        out[d] = (float)(pa + t * (pb - pa));
    }
}

static int emit_triangle(iso_mesh *soup, float p[3][3], const double toward_low[3])
{
    double u[3], w[3];
    for (int d = 0; d < 3; d++) {
        u[d] = (double)p[1][d] - p[0][d];
        w[d] = (double)p[2][d] - p[0][d];
    }
    double n[3] = {u[1] * w[2] - u[2] * w[1], u[2] * w[0] - u[0] * w[2], u[0] * w[1] - u[1] * w[0]};
    int flip = n[0] * toward_low[0] + n[1] * toward_low[1] + n[2] * toward_low[2] < 0;
    if (iso_mesh_reserve(soup, soup->vertex_count + 3, soup->triangle_count + 1))
        return ISO_E_NOMEM;
    size_t base = soup->vertex_count;
    for (int k = 0; k < 3; k++) {
        int from = flip && k ? 3 - k : k;
        for (int d = 0; d < 3; d++)
            soup->positions[3 * (base + k) + d] = p[from][d];
        soup->indices[3 * soup->triangle_count + k] = (uint32_t)(base + k);
    }
    soup->vertex_count += 3;
    soup->triangle_count++;
    return 0;
}

/* One tetrahedron: its level set under the linear interpolant is a triangle (one vertex
 * apart) or a quad (two and two). Winding follows the direction from the inside vertices'
 * centroid to the outside ones', which is downhill for a linear function. */
static int march_tet(const grid *g, const tet_vertex t[4], double level, iso_mesh *soup)
{
    int in[4], n_in = 0;
    double toward_low[3] = {0, 0, 0};
    for (int k = 0; k < 4; k++) {
        in[k] = t[k].value > level;
        n_in += in[k];
    }
    if (n_in == 0 || n_in == 4)
        return 0;
    for (int k = 0; k < 4; k++)
        for (int d = 0; d < 3; d++)
            toward_low[d] += (in[k] ? -1.0 / n_in : 1.0 / (4 - n_in)) * g->size[d] * t[k].at[d] / g->s[d];
    float p[4][3];
    if (n_in == 1 || n_in == 3) {
        int apart = 0;
        while (in[apart] != (n_in == 1))
            apart++;
        for (int k = 0, m = 0; k < 4; k++)
            if (k != apart)
                crossing(g, &t[apart], &t[k], level, p[m++]);
        return emit_triangle(soup, p, toward_low);
    }
    int a = -1, b = -1, c = -1, d = -1;
    for (int k = 0; k < 4; k++) {
        if (in[k]) { if (a < 0) a = k; else b = k; }
        else { if (c < 0) c = k; else d = k; }
    }
    crossing(g, &t[a], &t[c], level, p[0]);
    crossing(g, &t[a], &t[d], level, p[1]);
    crossing(g, &t[b], &t[d], level, p[2]);
    crossing(g, &t[b], &t[c], level, p[3]);
    float q[3][3] = {{p[0][0], p[0][1], p[0][2]}, {p[2][0], p[2][1], p[2][2]}, {p[3][0], p[3][1], p[3][2]}};
    int rc = emit_triangle(soup, p, toward_low);
    return rc ? rc : emit_triangle(soup, q, toward_low);
}

static int emit_sub_box(const grid *g, uint32_t x, uint32_t y, uint32_t z, double level,
                        iso_mesh *soup)
{
    tet_vertex corner[8];
    int above = 0;
    for (int k = 0; k < 8; k++) {
        corner[k].at[0] = x + (k & 1);
        corner[k].at[1] = y + ((k >> 1) & 1);
        corner[k].at[2] = z + ((k >> 2) & 1);
        corner[k].value = grid_value(g, corner[k].at);
        above += corner[k].value > level;
    }
    if (above == 0 || above == 8)
        return 0;
    for (int o = 0; o < 6; o++) {
        int idx[4];
        tet_vertex t[4];
        iso_tri_kuhn_tet(o, idx);
        for (int k = 0; k < 4; k++)
            t[k] = corner[idx[k]];
        int rc = march_tet(g, t, level, soup);
        if (rc < 0)
            return rc;
    }
    return 0;
}

int iso_tets_polygonize(const double c[8], const iso_box *box, double level, double budget,
                        iso_mesh *soup, double *delta, size_t *sub_boxes)
{
    grid g = {.c = c, .s = {1, 1, 1}};
    uint32_t cells[3];
    for (int d = 0; d < 3; d++) {
        g.lo[d] = box->lo[d];
        cells[d] = box->hi[d] - box->lo[d];
        g.size[d] = cells[d];
    }
    *delta = 0;
    /* T is a convex combination of its corners: with all of them on one side it has no
     * level set in the box. */
    int above = 0;
    for (int k = 0; k < 8; k++)
        above += c[k] > level;
    if (above == 0 || above == 8)
        return 1;
    uint64_t node_cells = (uint64_t)cells[0] * cells[1] * cells[2];
    if (node_cells < 8)
        return 0;
    for (;;) {
        double bound = worst_bound(&g, sub_boxes);
        if (bound <= budget) {
            *delta = bound;
            break;
        }
        /* Six tetrahedra give about twice the triangles marching cubes gives for one box,
         * so sub-boxes under eight cells would give more triangles than marching the
         * cells themselves: the caller's children do better. */
        uint32_t next[3];
        uint64_t sub_count = 1;
        for (int d = 0; d < 3; d++) {
            next[d] = g.s[d] * 2 < cells[d] ? g.s[d] * 2 : cells[d];
            sub_count *= next[d];
        }
        if (8 * sub_count > node_cells || (next[0] == g.s[0] && next[1] == g.s[1] && next[2] == g.s[2]))
            return 0;
        memcpy(g.s, next, sizeof next);
    }
    for (uint32_t z = 0; z < g.s[2]; z++)
        for (uint32_t y = 0; y < g.s[1]; y++)
            for (uint32_t x = 0; x < g.s[0]; x++) {
                int rc = emit_sub_box(&g, x, y, z, level, soup);
                if (rc < 0)
                    return rc;
            }
    return 1;
}
