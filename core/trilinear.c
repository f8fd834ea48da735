/* trilinear.c: Lemma 2 style bounds for linear pieces of a trilinear (Elber and
 * Malzbender, Section 3), for the paper's corner tetrahedron and for Kuhn tetrahedra. */
#include "trilinear.h"

#include <math.h>

static const int axis_orders[6][3] = {
    {0, 1, 2}, {0, 2, 1}, {1, 0, 2}, {1, 2, 0}, {2, 0, 1}, {2, 1, 0}};

double iso_tri_lemma2_corner(const double c[8])
{
    /* Linear through corners 0, 1 (x), 2 (y), 4 (z): l = c0 + dx u + dy v + dz w. */
    double dx = c[1] - c[0], dy = c[2] - c[0], dz = c[4] - c[0];
    double r011 = c[6] - (c[0] + dy + dz), r101 = c[5] - (c[0] + dx + dz);
    double r110 = c[3] - (c[0] + dx + dy), r111 = c[7] - (c[0] + dx + dy + dz);
    return (fabs(r011) + fabs(r101) + fabs(r110)) / 4.0 + fabs(r111) / 27.0;
}

void iso_tri_kuhn_tet(int order, int corners[4])
{
    int a = 1 << axis_orders[order][0], b = 1 << axis_orders[order][1];
    corners[0] = 0;
    corners[1] = a;
    corners[2] = a | b;
    corners[3] = 7;
}

double iso_tri_kuhn_tet_bound(const double c[8], int order)
{
    int a = 1 << axis_orders[order][0], b = 1 << axis_orders[order][1], cc = 1 << axis_orders[order][2];
    /* l(x) = c0 + ga x_a + gb x_b + gc x_c, fixed by the tetrahedron's vertices. */
    double ga = c[a] - c[0], gb = c[a | b] - c[a], gc = c[7] - c[a | b];
    double r_b = c[b] - (c[0] + gb), r_ac = c[a | cc] - (c[0] + ga + gc);
    double r_c = c[cc] - (c[0] + gc), r_bc = c[b | cc] - (c[0] + gb + gc);
    return (fabs(r_b) + fabs(r_ac)) / 4.0 + (fabs(r_c) + fabs(r_bc)) * (4.0 / 27.0);
}

double iso_tri_kuhn_bound(const double c[8])
{
    double worst = 0;
    for (int o = 0; o < 6; o++) {
        double bound = iso_tri_kuhn_tet_bound(c, o);
        if (bound > worst)
            worst = bound;
    }
    return worst;
}
