/* trilinear.h: one box's trilinear function, the fit the hierarchy measures nodes against.
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

#endif
