/* trilinear.h: one box's trilinear function and the bounds that make extraction provable.
 *
 * A trilinear T on a box is given by its 8 corner values c[k], corner k at local
 * coordinates (k & 1, (k >> 1) & 1, (k >> 2) & 1) in [0,1]^3. */
#ifndef ISO_TRILINEAR_H
#define ISO_TRILINEAR_H

/* T at local coordinates (u, v, w) in [0,1]^3. */
static inline double iso_tri_eval(const double c[8], double u, double v, double w)
{
    double x00 = c[0] + (c[1] - c[0]) * u, x10 = c[2] + (c[3] - c[2]) * u;
    double x01 = c[4] + (c[5] - c[4]) * u, x11 = c[6] + (c[7] - c[6]) * u;
    double y0 = x00 + (x10 - x00) * v, y1 = x01 + (x11 - x01) * v;
    return y0 + (y1 - y0) * w;
}

/* The paper's Lemma 2, for the corner tetrahedron u+v+w <= 1 at corner 0: with r the
 * residuals of corners 011, 101, 110, 111 (corner values minus the linear function
 * through corners 000, 100, 010, 001), |T - linear| <= (|r011|+|r101|+|r110|)/4 + |r111|/27
 * on that tetrahedron. */
double iso_tri_lemma2_corner(const double c[8]);

/* The same bound for the six Kuhn tetrahedra of the box (each the simplex
 * x_a >= x_b >= x_c for one order (a,b,c) of the axes, all sharing the diagonal 000-111),
 * which tile neighbouring boxes consistently. On the tetrahedron for order (a,b,c), with
 * l the linear through its vertices 000, e_a, e_a+e_b, 111 and r the residuals T - l of
 * the four other corners:
 *     |T - l| <= (|r[e_b]| + |r[e_a+e_c]|) / 4 + (|r[e_c]| + |r[e_b+e_c]|) * 4/27
 * (T - l = sum r_k B_k over the off corners, B_k the trilinear basis; the maxima of the
 * B_k over the tetrahedron are 1/4, 1/4, 4/27, 4/27), reached when one residual is alone.
 * iso_tri_kuhn_tet_bound is the bound of tetrahedron `order` (0..5, see iso_tri_kuhn_tet);
 * iso_tri_kuhn_bound the maximum over the six. */
double iso_tri_kuhn_tet_bound(const double c[8], int order);
double iso_tri_kuhn_bound(const double c[8]);

/* The Kuhn tetrahedron of axis order `order` (0..5): its 4 corner indices, in the order
 * 000, e_a, e_a+e_b, 111. */
void iso_tri_kuhn_tet(int order, int corners[4]);

#endif
