/* surface.c: helpers for tests that check extracted surfaces (surface.h). */
#include "surface.h"

#include <math.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "check.h"
#include "io/io.h"
#include "extract/mc.h"
#include "volume/volume.h"

static uint64_t rng_state = 0x2545F4914F6CDD1Dull;

double surface_uniform(void)
{
    rng_state ^= rng_state >> 12;
    rng_state ^= rng_state << 25;
    rng_state ^= rng_state >> 27;
    return (double)((rng_state * 0x2545F4914F6CDD1Dull) >> 11) / 9007199254740992.0;
}

iso_volume *surface_make_volume(size_t nx, size_t ny, size_t nz, iso_voxel_type type)
{
    size_t dims[3] = {nx, ny, nz};
    iso_error err;
    iso_volume *vol = iso_vol_create(dims, type, 0, &err);
    CHECKF(vol != NULL, "iso_vol_create: %s", err.message);
    return vol;
}

size_t surface_unused_vertices(const iso_mesh *m)
{
    uint8_t *used = calloc(m->vertex_count + 1, 1);
    CHECKF(used != NULL, "no memory to count %zu vertices", m->vertex_count);
    if (!used)
        return 0;
    for (size_t i = 0; i < 3 * m->triangle_count; i++)
        used[m->indices[i]] = 1;
    size_t unused = 0;
    for (size_t v = 0; v < m->vertex_count; v++)
        unused += !used[v];
    free(used);
    return unused;
}

iso_volume *surface_random_volume(const size_t n[3], iso_voxel_type type, int steps)
{
    iso_volume *vol = surface_make_volume(n[0], n[1], n[2], type);
    for (size_t k = 0; vol && k < n[2]; k++)
        for (size_t j = 0; j < n[1]; j++)
            for (size_t i = 0; i < n[0]; i++)
                iso_vol_set(vol, i, j, k, steps ? floor(surface_uniform() * 4) : surface_uniform());
    if (vol)
        iso_vol_update_stats(vol);
    return vol;
}

iso_volume *surface_load_shared(const char *file)
{
    const char *dir = check_shared_volumes();
    if (!dir) {
        check_skip("needs ../shared/volumes (%s)", file);
        return NULL;
    }
    char path[4096];
    snprintf(path, sizeof path, "%s/%s", dir, file);
    iso_volume *vol = NULL;
    iso_error err;
    CHECK_OK(iso_load(path, NULL, &vol, &err), &err);
    return vol;
}

iso_tree *surface_build(const iso_volume *vol)
{
    iso_tree *tree = NULL;
    iso_error err;
    CHECK_OK(iso_tree_build(vol, 0, NULL, NULL, &tree, &err), &err);
    return tree;
}

double surface_interpolate(const iso_volume *vol, const float p[3])
{
    size_t base[3];
    double t[3];
    for (int d = 0; d < 3; d++) {
        double x = p[d];
        if (x < 0) x = 0;
        if (x > (double)(vol->dims[d] - 1)) x = (double)(vol->dims[d] - 1);
        size_t b = (size_t)floor(x);
        if (b >= vol->dims[d] - 1)
            b = vol->dims[d] - 2;
        base[d] = b;
        t[d] = x - (double)b;
    }
    double c[8];
    for (int k = 0; k < 8; k++)
        c[k] = iso_vol_get(vol, base[0] + (k & 1), base[1] + ((k >> 1) & 1), base[2] + ((k >> 2) & 1));
    return iso_tri_eval(c, t[0], t[1], t[2]);
}

double surface_worst_vertex_error(const iso_volume *vol, const iso_mesh *m, double level)
{
    double worst = 0;
    for (size_t v = 0; v < m->vertex_count; v++) {
        const float *p = m->positions + 3 * v;
        int outside = 0;
        for (int d = 0; d < 3; d++)
            outside |= p[d] < 0 || p[d] > (float)(vol->dims[d] - 1);
        if (outside)
            continue;
        double e = fabs(surface_interpolate(vol, p) - level);
        if (e > worst)
            worst = e;
    }
    return worst;
}

double surface_rounding_slack(const iso_volume *vol)
{
    double extent = (double)(vol->dims[0] + vol->dims[1] + vol->dims[2]);
    return 3.0 * extent * ldexp(1.0, -23) * (vol->value_max - vol->value_min) + 1e-9;
}

double surface_tie_allowance(const iso_volume *vol)
{
    return ISO_MC_END_GAP * (vol->value_max - vol->value_min);
}

static int compare_triangles(const void *a, const void *b)
{
    return memcmp(a, b, sizeof(surface_triangle));
}

surface_triangle *surface_canonical_triangles(const iso_mesh *m)
{
    surface_triangle *t = malloc((m->triangle_count ? m->triangle_count : 1) * sizeof *t);
    CHECK(t != NULL);
    if (!t)
        return NULL;
    for (size_t i = 0; i < m->triangle_count; i++) {
        const float *c[3];
        for (int k = 0; k < 3; k++)
            c[k] = m->positions + 3 * m->indices[3 * i + k];
        int first = 0;
        for (int k = 1; k < 3; k++)
            if (memcmp(c[k], c[first], 3 * sizeof(float)) < 0)
                first = k;
        for (int k = 0; k < 3; k++)
            memcpy(t[i].p + 3 * k, c[(first + k) % 3], 3 * sizeof(float));
    }
    qsort(t, m->triangle_count, sizeof *t, compare_triangles);
    return t;
}
