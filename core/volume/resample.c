/* resample.c: box-filter resampling of a volume to new dimensions (see volume.h). */
#include "volume.h"

#include <string.h>

#include <math.h>
#include <stdlib.h>

/* Source sample range [first, last] averaged for output index o along one axis. */
static void footprint(size_t in, size_t out, size_t o, size_t *first, size_t *last, double *at)
{
    double ratio = (double)(in - 1) / (double)(out - 1);
    double centre = o * ratio, half = ratio > 1 ? ratio / 2 : 0;
    double lo = ceil(centre - half), hi = floor(centre + half);
    if (lo < 0) lo = 0;
    if (hi > (double)(in - 1)) hi = (double)(in - 1);
    if (hi < lo) hi = lo;
    *first = (size_t)lo;
    *last = (size_t)hi;
    *at = centre;
}

iso_volume *iso_resample(const iso_volume *vol, const size_t dims[3], iso_error *err)
{
    iso_volume *out = iso_vol_create(dims, ISO_F32, 0, err);
    if (!out)
        return NULL;
    for (int d = 0; d < 3; d++) {
        out->spacing[d] = vol->spacing[d] * (double)(vol->dims[d] - 1) / (double)(dims[d] - 1);
        out->origin[d] = vol->origin[d];
        for (int c = 0; c < 3; c++)
            out->direction[d][c] = vol->direction[d][c];
    }
    memcpy(out->modality, vol->modality, sizeof out->modality);
    memcpy(out->description, vol->description, sizeof out->description);
    out->oriented = vol->oriented;
    float *dst = out->data;
    for (size_t z = 0; z < dims[2]; z++)
        for (size_t y = 0; y < dims[1]; y++)
            for (size_t x = 0; x < dims[0]; x++) {
                size_t f[3], l[3], o[3] = {x, y, z};
                double at[3];
                for (int d = 0; d < 3; d++)
                    footprint(vol->dims[d], dims[d], o[d], &f[d], &l[d], &at[d]);
                double sum = 0;
                size_t n = 0;
                if (f[0] == l[0] && f[1] == l[1] && f[2] == l[2] &&
                    (at[0] != f[0] || at[1] != f[1] || at[2] != f[2])) {
                    /* Growing: no sample in the footprint, interpolate trilinearly. */
                    size_t b[3];
                    double t[3];
                    for (int d = 0; d < 3; d++) {
                        b[d] = (size_t)floor(at[d]);
                        if (b[d] >= vol->dims[d] - 1) b[d] = vol->dims[d] - 2;
                        t[d] = at[d] - (double)b[d];
                    }
                    for (int k = 0; k < 8; k++) {
                        double w = (k & 1 ? t[0] : 1 - t[0]) * (k & 2 ? t[1] : 1 - t[1]) * (k & 4 ? t[2] : 1 - t[2]);
                        sum += w * iso_vol_get(vol, b[0] + (k & 1), b[1] + ((k >> 1) & 1), b[2] + ((k >> 2) & 1));
                    }
                    n = 1;
                } else {
                    for (size_t k = f[2]; k <= l[2]; k++)
                        for (size_t j = f[1]; j <= l[1]; j++)
                            for (size_t i = f[0]; i <= l[0]; i++, n++)
                                sum += iso_vol_get(vol, i, j, k);
                }
                dst[iso_vol_index(out, x, y, z)] = (float)(sum / (double)n);
            }
    iso_vol_update_stats(out);
    return out;
}
