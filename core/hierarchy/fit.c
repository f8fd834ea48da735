/* fit.c: a box's fit error over a block of samples, with an early exit (tree.h). */
#include "tree.h"

#include <assert.h>
#include <math.h>
#include <stddef.h>

#include "volume/volume.h"

double iso_fit_error_past(const iso_fit_block *block, const iso_box *box, double limit)
{
    /* 1 / the box's extent, by table: it is at most a brick's (the same quotients). */
    static const double reciprocal[ISO_BRICK_SAMPLES] = {0.0, 1.0, 1.0 / 2, 1.0 / 3, 1.0 / 4,
                                                         1.0 / 5, 1.0 / 6, 1.0 / 7, 1.0 / 8};
    double c[8], inv[3], worst = 0;
    const double *low = iso_fit_sample(block, box->lo[0], box->lo[1], box->lo[2]);
    size_t step[3] = {1, block->n[0], (size_t)block->n[0] * block->n[1]};
    _Static_assert(ISO_BRICK_CELLS == 8, "reciprocal[] lists 1/0..1/8");
    for (int d = 0; d < 3; d++) {
        assert(box->lo[d] >= block->lo[d] && box->hi[d] < block->lo[d] + block->n[d]);
        assert(box->hi[d] - box->lo[d] <= ISO_BRICK_CELLS);
        inv[d] = reciprocal[box->hi[d] - box->lo[d]];
        step[d] *= box->hi[d] - box->lo[d]; /* from the low corner to the high one */
    }
    for (int k = 0; k < 8; k++)
        c[k] = low[(k & 1 ? step[0] : 0) + (k & 2 ? step[1] : 0) + (k & 4 ? step[2] : 0)];
    uint32_t m[3];
    for (int d = 0; d < 3; d++)
        m[d] = (box->lo[d] + box->hi[d]) / 2;
    double at_middle = *iso_fit_sample(block, m[0], m[1], m[2]);
    double middle = fabs(at_middle - iso_tri_eval(c, (m[0] - box->lo[0]) * inv[0], (m[1] - box->lo[1]) * inv[1],
                                          (m[2] - box->lo[2]) * inv[2]));
    if (middle > limit)
        return middle;
    /* Rows walked by pointer, their x fractions computed once (the same products). */
    uint32_t nx = box->hi[0] - box->lo[0] + 1;
    double ux[ISO_BRICK_SAMPLES];
    for (uint32_t i = 0; i < nx; i++)
        ux[i] = i * inv[0];
    for (uint32_t z = box->lo[2]; z <= box->hi[2]; z++)
        for (uint32_t y = box->lo[1]; y <= box->hi[1]; y++) {
            double v = (y - box->lo[1]) * inv[1], t = (z - box->lo[2]) * inv[2];
            double a = iso_tri_eval(c, 0, v, t), e = iso_tri_eval(c, 1, v, t) - a;
            const double *row = iso_fit_sample(block, box->lo[0], y, z);
            if (block->integer_samples)
                for (uint32_t i = 0; i < nx; i++) {
                    double d = fabs(row[i] - (a + e * ux[i]));
                    worst = d > worst ? d : worst;
                }
            else
                for (uint32_t i = 0; i < nx; i++) {
                    double s = row[i], d = fabs(s - (a + e * ux[i]));
                    if (!(d <= worst))
                        worst = s != s ? INFINITY : d;
                }
            if (worst > limit)
                return worst;
        }
    return worst;
}
