/* field.c: analytic volumes (see io.h): "ml" after Marschner and Lobb, "An Evaluation of
 * Reconstruction Filters for Volume Rendering" (Visualization '94); D1, D2 and D3 after
 * Elber and Malzbender's examples of data that defeat or suit a min/max hierarchy. */
#include "io.h"

#include <assert.h>
#include <ctype.h>
#include <math.h>
#include <stdio.h>
#include <string.h>

#define PI 3.14159265358979323846

/* Index-space landmarks shared by the fields. */
typedef struct frame {
    double c[3];       /* centre of the grid */
    double r;          /* largest radius that fits on every axis */
    double to_unit[3]; /* index to [-1,1]: x = i * to_unit - 1 */
} frame;

typedef double (*sample_fn)(const frame *fr, size_t i, size_t j, size_t k);

static double sample_sphere(const frame *fr, size_t i, size_t j, size_t k)
{
    double dx = (double)i - fr->c[0], dy = (double)j - fr->c[1], dz = (double)k - fr->c[2];
    return fr->r - sqrt(dx * dx + dy * dy + dz * dz);
}

static double sample_torus(const frame *fr, size_t i, size_t j, size_t k)
{
    double dx = (double)i - fr->c[0], dy = (double)j - fr->c[1], dz = (double)k - fr->c[2];
    double off_ring = sqrt(dx * dx + dy * dy) - fr->r / 2;
    return fr->r / 4 - sqrt(off_ring * off_ring + dz * dz);
}

/* Marschner and Lobb's signal: a slow sine along z plus a radial cosine chirp of
 * frequency fM that strains reconstruction filters near the Nyquist rate. */
static double sample_ml(const frame *fr, size_t i, size_t j, size_t k)
{
    const double alpha = 0.25, fm = 6;
    double x = (double)i * fr->to_unit[0] - 1, y = (double)j * fr->to_unit[1] - 1;
    double z = (double)k * fr->to_unit[2] - 1;
    double rho = cos(2 * PI * fm * cos(PI * sqrt(x * x + y * y) / 2));
    return (1 - sin(PI * z / 2) + alpha * (1 + rho)) / (2 * (1 + alpha));
}

static double sample_constant(const frame *fr, size_t i, size_t j, size_t k)
{
    (void)fr, (void)i, (void)j, (void)k;
    return 1;
}

static double sample_spike(const frame *fr, size_t i, size_t j, size_t k)
{
    (void)fr;
    return (i | j | k) ? 1 : 0;
}

static double sample_ijk(const frame *fr, size_t i, size_t j, size_t k)
{
    (void)fr;
    return (double)i * (double)j * (double)k;
}

static const struct {
    const char *name;
    iso_voxel_type type;
    sample_fn sample;
} fields[] = {
    {"sphere", ISO_F32, sample_sphere},
    {"torus", ISO_F32, sample_torus},
    {"ml", ISO_F32, sample_ml},
    {"constant", ISO_U8, sample_constant},
    {"spike", ISO_F32, sample_spike},
    {"ijk", ISO_F32, sample_ijk},
};

#define FIELD_COUNT (sizeof fields / sizeof fields[0])

const char *iso_field_names(void)
{
    return "sphere, torus, ml, constant, spike, ijk";
}

int iso_field_create(const char *name, const size_t dims[3], uint64_t max_bytes,
                     iso_volume **out, iso_error *err)
{
    iso_volume *vol;
    iso_error local;
    frame fr;
    size_t f;
    assert(name && dims && out);
    *out = NULL;
    for (f = 0; f < FIELD_COUNT && strcmp(name, fields[f].name) != 0; f++)
        ;
    if (f == FIELD_COUNT)
        return iso_error_set(err, ISO_E_ARGUMENT, "unknown field '%.64s' (known: %s)", name,
                             iso_field_names());
    for (int d = 0; d < 3; d++)
        if (dims[d] < 2 || dims[d] > ISO_FIELD_MAX_SIZE)
            return iso_error_set(err, ISO_E_ARGUMENT,
                                 "field size %zux%zux%zu: each axis must be 2..%d", dims[0],
                                 dims[1], dims[2], ISO_FIELD_MAX_SIZE);
    vol = iso_vol_create(dims, fields[f].type, max_bytes, &local);
    if (!vol)
        return iso_error_set(err, local.code, "%s", local.message);

    fr.r = INFINITY;
    for (int d = 0; d < 3; d++) {
        double half = (double)(dims[d] - 1) / 2;
        fr.c[d] = half;
        fr.r = half < fr.r ? half : fr.r;
        fr.to_unit[d] = 2 / (double)(dims[d] - 1);
    }
    /* Samples go straight into the typed array in storage order: iso_vol_set's checks per
     * sample would cost more than the cheap fields themselves. */
    assert(vol->type == ISO_U8 || vol->type == ISO_F32);
    size_t n = 0;
    for (size_t k = 0; k < dims[2]; k++)
        for (size_t j = 0; j < dims[1]; j++)
            for (size_t i = 0; i < dims[0]; i++, n++) {
                double v = fields[f].sample(&fr, i, j, k);
                if (vol->type == ISO_U8)
                    ((uint8_t *)vol->data)[n] = (uint8_t)v;
                else
                    ((float *)vol->data)[n] = (float)v;
            }
    *out = vol;
    return ISO_OK;
}

/* Parses "N" or "WxHxD"; returns 0 or -1. Stops a number as soon as it passes the largest
 * size, so no digit string can overflow. */
static int parse_size(const char *s, size_t dims[3])
{
    int n = 0;
    for (;;) {
        size_t v = 0;
        if (!isdigit((unsigned char)*s))
            return -1;
        for (; isdigit((unsigned char)*s); s++) {
            v = v * 10 + (size_t)(*s - '0');
            if (v > ISO_FIELD_MAX_SIZE)
                return -1;
        }
        if (n == 3)
            return -1;
        dims[n++] = v;
        if (*s == '\0')
            break;
        if (*s++ != 'x')
            return -1;
    }
    if (n == 2)
        return -1;
    if (n == 1)
        dims[1] = dims[2] = dims[0];
    return 0;
}

int iso_field_load(const char *path, const iso_load_options *opt, iso_volume **out,
                   iso_error *err)
{
    const size_t prefix = sizeof ISO_FIELD_PREFIX - 1;
    size_t dims[3] = {ISO_FIELD_DEFAULT_SIZE, ISO_FIELD_DEFAULT_SIZE, ISO_FIELD_DEFAULT_SIZE};
    char name[32];
    const char *spec, *colon;
    size_t len;
    iso_error local;
    int rc;
    assert(path && out);
    *out = NULL;
    if (strncmp(path, ISO_FIELD_PREFIX, prefix) != 0)
        return iso_error_set(err, ISO_E_ARGUMENT, "'%.64s' does not start with %s", path,
                             ISO_FIELD_PREFIX);
    spec = path + prefix;
    colon = strchr(spec, ':');
    len = colon ? (size_t)(colon - spec) : strlen(spec);
    if (len >= sizeof name)
        return iso_error_set(err, ISO_E_ARGUMENT, "%.64s: unknown field (known: %s)", path,
                             iso_field_names());
    memcpy(name, spec, len);
    name[len] = '\0';
    if (colon && parse_size(colon + 1, dims) != 0)
        return iso_error_set(err, ISO_E_ARGUMENT,
                             "%.64s: bad size '%.32s': expected N or WxHxD, each 2..%d", path,
                             colon + 1, ISO_FIELD_MAX_SIZE);
    rc = iso_field_create(name, dims, opt ? opt->max_bytes : 0, out, &local);
    if (rc != ISO_OK)
        return iso_error_set(err, rc, "%.64s: %s", path, local.message);
    return ISO_OK;
}
