/* field.c: a segment's field on a box of the grid, as a float volume of its own: the
 * indicator of a label (1 where the layer holds it), optionally convolved with a
 * Gaussian, for the smoothed surface and for normals. The box may reach past the volume's
 * border: there the indicator is 0 when the surface is capped (the segment ends at the
 * border), else the border's value repeated (the surface meets the border).
 *
 * PASS 1 (fill): the indicator on the box widened by the kernel's radius per axis.
 * PASS 2 (convolve, when sigma > 0): the truncated, normalised Gaussian along x, then y,
 *   then z, each pass over the rows of the box it still needs; a row holding one value
 *   stays as it is.
 * The field's geometry is the volume's with its origin at the box's first sample, so a
 * point has the same world position in both. */
#include "segment_internal.h"

#include <math.h>
#include <stdlib.h>
#include <string.h>

/* The kernel's radius in samples along axis d: 3 sigma. */
static long radius(const iso_volume *vol, double sigma_mm, int d)
{
    return sigma_mm > 0 ? (long)ceil(3 * sigma_mm / vol->spacing[d]) : 0;
}

/* The kernel's 2r + 1 weights, summing to 1. */
static void weights(double sigma_samples, long r, float *w)
{
    double sum = 0;
    for (long i = -r; i <= r; i++)
        sum += exp(-0.5 * (double)(i * i) / (sigma_samples * sigma_samples));
    for (long i = -r; i <= r; i++)
        w[i + r] = (float)(exp(-0.5 * (double)(i * i) / (sigma_samples * sigma_samples)) / sum);
}

/* One pass along axis d over a dense array of n[] floats: out = in convolved, rows
 * clamped at their ends (the box already holds every sample the kernel needs but at its
 * outermost rows, which the surface never reaches). */
static void convolve(const float *in, float *out, const long n[3], int d, const float *w, long r)
{
    long stride = d == 0 ? 1 : d == 1 ? n[0] : n[0] * n[1], len = n[d];
    long rows = n[0] * n[1] * n[2] / len;
    for (long row = 0; row < rows; row++) {
        long base;
        if (d == 0)
            base = row * n[0];
        else if (d == 1)
            base = (row / n[0]) * n[0] * n[1] + row % n[0];
        else
            base = row;
        const float *p = in + base;
        float *q = out + base;
        float first = p[0];
        long k = 1;
        while (k < len && p[k * stride] == first)
            k++;
        if (k == len) { /* a row of one value: the same after any normalised kernel */
            for (long i = 0; i < len; i++)
                q[i * stride] = first;
            continue;
        }
        for (long i = 0; i < len; i++) {
            double sum = 0;
            for (long j = -r; j <= r; j++) {
                long at = i + j < 0 ? 0 : i + j >= len ? len - 1 : i + j;
                sum += (double)w[j + r] * p[at * stride];
            }
            q[i * stride] = (float)sum;
        }
    }
}

int iso_seg_field(const iso_segmentation *seg, size_t s, const long lo[3], const long hi[3], double sigma_mm,
                  int cap, iso_volume **out, iso_error *err)
{
    const iso_segment *segment = &seg->segments[s];
    const iso_seg_layer *layer = &seg->layers[segment->layer];
    const iso_volume *vol = layer->vol;
    *out = NULL;
    long r[3], n[3], from[3];
    size_t dims[3];
    for (int d = 0; d < 3; d++) {
        r[d] = radius(vol, sigma_mm, d);
        from[d] = lo[d] - r[d];
        n[d] = hi[d] - lo[d] + 1 + 2 * r[d];
        dims[d] = (size_t)(hi[d] - lo[d] + 1);
    }
    iso_volume *field = iso_vol_create(dims, ISO_F32, 0, err);
    if (!field)
        return err ? err->code : ISO_E_NOMEM;
    size_t total = (size_t)(n[0] * n[1] * n[2]);
    float *a = malloc(total * sizeof *a), *b = sigma_mm > 0 ? malloc(total * sizeof *b) : NULL;
    if (!a || (sigma_mm > 0 && !b)) {
        free(a);
        free(b);
        iso_vol_destroy(field);
        return iso_error_set(err, ISO_E_NOMEM, "out of memory for segment %u's field", segment->number);
    }
    /* PASS 1 */
    const int fractional = layer->kind == ISO_SEG_FRACTIONAL;
    for (long z = 0; z < n[2]; z++)
        for (long y = 0; y < n[1]; y++)
            for (long x = 0; x < n[0]; x++) {
                long p[3] = {from[0] + x, from[1] + y, from[2] + z};
                int outside = 0;
                for (int d = 0; d < 3; d++) {
                    if (p[d] < 0 || p[d] >= (long)vol->dims[d]) {
                        outside = 1;
                        p[d] = p[d] < 0 ? 0 : (long)vol->dims[d] - 1;
                    }
                }
                float v = 0;
                if (!(outside && cap)) {
                    double sample = iso_vol_get(vol, (size_t)p[0], (size_t)p[1], (size_t)p[2]);
                    v = fractional ? (float)(sample / layer->max_fraction) : (float)(sample == (double)segment->value);
                }
                a[(z * n[1] + y) * n[0] + x] = v;
            }
    /* PASS 2 */
    if (sigma_mm > 0) {
        float *w = malloc((size_t)(2 * (r[0] > r[1] ? (r[0] > r[2] ? r[0] : r[2]) : (r[1] > r[2] ? r[1] : r[2])) + 1) *
                          sizeof *w);
        if (!w) {
            free(a);
            free(b);
            iso_vol_destroy(field);
            return iso_error_set(err, ISO_E_NOMEM, "out of memory for segment %u's field", segment->number);
        }
        float *in = a, *outp = b;
        for (int d = 0; d < 3; d++) {
            weights(sigma_mm / vol->spacing[d], r[d], w);
            convolve(in, outp, n, d, w, r[d]);
            float *t = in;
            in = outp;
            outp = t;
        }
        free(w);
        if (in != a) {
            memcpy(a, in, total * sizeof *a);
        }
    }
    float *dst = field->data;
    for (size_t z = 0; z < dims[2]; z++)
        for (size_t y = 0; y < dims[1]; y++)
            memcpy(dst + (z * dims[1] + y) * dims[0],
                   a + (((long)z + r[2]) * n[1] + (long)y + r[1]) * n[0] + r[0], dims[0] * sizeof *dst);
    free(a);
    free(b);
    field->spacing[0] = vol->spacing[0], field->spacing[1] = vol->spacing[1], field->spacing[2] = vol->spacing[2];
    memcpy(field->direction, vol->direction, sizeof field->direction);
    double index[3] = {(double)lo[0], (double)lo[1], (double)lo[2]};
    iso_vol_index_to_world(vol, index, field->origin);
    iso_vol_update_stats(field);
    *out = field;
    return 0;
}
