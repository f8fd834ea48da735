/* mc.c: marching cubes for one cell, the case table derived at start-up from face rules. */
#include "mc.h"

#include <assert.h>
#include <pthread.h>
#include <string.h>

const uint8_t iso_mc_edge_corner[12][2] = {
    /* along x: y,z bits */ {0, 1}, {2, 3}, {4, 5}, {6, 7},
    /* along y: z,x bits */ {0, 2}, {4, 6}, {1, 3}, {5, 7},
    /* along z: x,y bits */ {0, 4}, {1, 5}, {2, 6}, {3, 7}};

static iso_mc_case cases[256];
static pthread_once_t cases_once = PTHREAD_ONCE_INIT;

static int edge_between(int p, int q)
{
    for (int e = 0; e < 12; e++)
        if ((iso_mc_edge_corner[e][0] == p && iso_mc_edge_corner[e][1] == q) ||
            (iso_mc_edge_corner[e][0] == q && iso_mc_edge_corner[e][1] == p))
            return e;
    return -1;
}

/* 1 if edges a and b lie in a common face of the cell (they share a fixed coordinate). */
static int share_face(int a, int b)
{
    int pa = iso_mc_edge_corner[a][0], pb = iso_mc_edge_corner[b][0];
    for (int d = 0; d < 3; d++)
        if (d != a / 4 && d != b / 4 && ((pa >> d) & 1) == ((pb >> d) & 1))
            return 1;
    return 0;
}

/* Triangulates the polygon v[0..n) (in order) so that no new diagonal lies in a face of
 * the cell: such a diagonal could meet the neighbouring cell's own diagonal on that face
 * and give an edge with four triangles. Exhaustive search over the triangle on edge
 * (v0, v1); loops have at most 12 vertices and the table is built once. */
static int triangulate(const int *v, int n, iso_mc_case *out)
{
    if (n < 3)
        return 1;
    uint8_t saved = out->triangle_count;
    for (int k = 2; k < n; k++) {
        /* Triangle (v0, v1, vk): the sides v1-vk and vk-v0 are diagonals unless adjacent. */
        if ((k != 2 && share_face(v[1], v[k])) || (k != n - 1 && share_face(v[k], v[0])))
            continue;
        uint8_t *t = out->edges + 3 * out->triangle_count++;
        t[0] = (uint8_t)v[0];
        t[1] = (uint8_t)v[1];
        t[2] = (uint8_t)v[k];
        int right[12], left[12], nr = 0, nl = 0;
        for (int i = 1; i <= k; i++)
            right[nr++] = v[i];
        for (int i = k; i < n; i++)
            left[nl++] = v[i];
        left[nl++] = v[0];
        if (triangulate(right, nr, out) && triangulate(left, nl, out))
            return 1;
        out->triangle_count = saved;
    }
    return 0;
}

int iso_mc_face_segments(const int inside[4], int from[2], int to[2])
{
    int entry[2], leave[2], entries = 0, leaves = 0;
    for (int i = 0; i < 4; i++) {
        int next = (i + 1) % 4;
        if (!inside[i] && inside[next])
            entry[entries++] = i;
        else if (inside[i] && !inside[next])
            leave[leaves++] = i;
    }
    for (int r = 0; r < entries; r++) {
        /* The run that starts at entry[r] ends at the first leave after it. */
        int best = -1, best_gap = 5;
        for (int l = 0; l < leaves; l++) {
            int gap = (leave[l] - entry[r] + 4) % 4;
            if (gap < best_gap) {
                best_gap = gap;
                best = leave[l];
            }
        }
        from[r] = best;
        to[r] = entry[r];
    }
    return entries;
}

/* For every face, walking its corners counter-clockwise as seen from outside the cell, a
 * run of inside corners is entered through one crossing edge and left through another;
 * the iso-segment goes from the leaving edge back to the entering one. Each crossing edge
 * is shared by two faces that walk it in opposite directions, so it ends exactly one
 * segment and starts exactly one: the segments chain into closed loops. Seen from the
 * inside corners the loops run counter-clockwise; they are triangulated reversed so that
 * normals point toward lower values. */
static void build_case(unsigned index, iso_mc_case *out)
{
    int next[12];
    memset(next, -1, sizeof next);
    for (int axis = 0; axis < 3; axis++)
        for (int side = 0; side < 2; side++) {
            int b = (axis + 1) % 3, c = (axis + 2) % 3, q[4];
            static const int bc[4][2] = {{0, 0}, {1, 0}, {1, 1}, {0, 1}};
            for (int i = 0; i < 4; i++) {
                int at = side ? i : 3 - i; /* (b,c,axis) is right-handed: reverse on the low side */
                q[i] = (side << axis) | (bc[at][0] << b) | (bc[at][1] << c);
            }
            int inside[4], from[2], to[2];
            for (int i = 0; i < 4; i++)
                inside[i] = (index >> q[i]) & 1;
            int segments = iso_mc_face_segments(inside, from, to);
            for (int r = 0; r < segments; r++) {
                int best = from[r];
                int e_in = edge_between(q[to[r]], q[(to[r] + 1) % 4]);
                int e_out = edge_between(q[best], q[(best + 1) % 4]);
                next[e_out] = e_in;
            }
        }
    int done[12] = {0};
    out->triangle_count = 0;
    for (int start = 0; start < 12; start++) {
        if (next[start] < 0 || done[start])
            continue;
        int loop[12], reversed[12], n = 0;
        for (int e = start; !done[e]; e = next[e]) {
            done[e] = 1;
            loop[n++] = e;
        }
        for (int k = 0; k < n; k++)
            reversed[k] = loop[n - 1 - k];
        int ok = triangulate(reversed, n, out);
        assert(ok && "every loop of the 256 cases has a triangulation off the faces");
        (void)ok;
    }
}

static void build_cases(void)
{
    for (unsigned i = 0; i < 256; i++)
        build_case(i, &cases[i]);
}

const iso_mc_case *iso_mc_cases(void)
{
    pthread_once(&cases_once, build_cases);
    return cases;
}

int iso_mc_cell(const double v[8], double level, const double origin[3], const double size[3],
                iso_mesh *soup, double *vertex_error)
{
    const iso_mc_case *cs = iso_mc_cases() + iso_mc_case_index(v, level);
    if (!cs->triangle_count)
        return 0;
    size_t n = 3u * cs->triangle_count;
    if (iso_mesh_reserve(soup, soup->vertex_count + n, soup->triangle_count + cs->triangle_count))
        return ISO_E_NOMEM;
    float *p = soup->positions + 3 * soup->vertex_count;
    uint32_t *idx = soup->indices + 3 * soup->triangle_count;
    for (size_t k = 0; k < n; k++) {
        int e = cs->edges[k], axis = e / 4;
        int lo = iso_mc_edge_corner[e][0];
        double a = v[lo], b = v[iso_mc_edge_corner[e][1]];
        double t = iso_mc_edge_t(a, b, level);
        if (vertex_error) {
            double error = iso_mc_edge_error(a, b, t, level);
            if (error > *vertex_error)
                *vertex_error = error;
        }
        for (int d = 0; d < 3; d++) {
            double x = origin[d] + (double)((lo >> d) & 1) * size[d];
            if (d == axis)
                x += t * size[d];
            p[3 * k + d] = (float)x;
        }
        idx[k] = (uint32_t)(soup->vertex_count + k);
    }
    soup->vertex_count += n;
    soup->triangle_count += cs->triangle_count;
    return (int)cs->triangle_count;
}
