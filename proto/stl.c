/* stl.c: binary STL, the format 3D printers and slicers take (see encode.h). */
#include "encode.h"
#include "bytes.h"

#include <assert.h>
#include <math.h>
#include <stdint.h>
#include <stdlib.h>
#include <string.h>

#define STL_HEADER 80
#define STL_TRIANGLE 50 /* normal, 3 vertices (12 floats), a 16-bit attribute count */

static unsigned char *put_u16(unsigned char *p, unsigned v)
{
    p[0] = (unsigned char)v;
    p[1] = (unsigned char)(v >> 8);
    return p + 2;
}

/* The facet normal from the winding (counter-clockwise seen from where it points), unit;
 * zero for a degenerate triangle, which slicers recompute anyway. */
static void facet_normal(const iso_mesh *m, size_t t, float n[3])
{
    const float *a = m->positions + 3 * (size_t)m->indices[3 * t];
    const float *b = m->positions + 3 * (size_t)m->indices[3 * t + 1];
    const float *c = m->positions + 3 * (size_t)m->indices[3 * t + 2];
    double u[3], v[3];
    for (int k = 0; k < 3; k++) {
        u[k] = (double)b[k] - a[k];
        v[k] = (double)c[k] - a[k];
    }
    double x = u[1] * v[2] - u[2] * v[1], y = u[2] * v[0] - u[0] * v[2], z = u[0] * v[1] - u[1] * v[0];
    double len = sqrt(x * x + y * y + z * z);
    n[0] = len > 0 ? (float)(x / len) : 0.0f;
    n[1] = len > 0 ? (float)(y / len) : 0.0f;
    n[2] = len > 0 ? (float)(z / len) : 0.0f;
}

int proto_encode_stl(const iso_mesh *mesh, unsigned char **out, size_t *out_size, iso_error *err)
{
    assert(mesh && out && out_size);
    *out = NULL;
    *out_size = 0;
    int rc = proto_mesh_check(mesh, 0, err);
    if (rc)
        return rc;
    if (mesh->triangle_count > (SIZE_MAX - STL_HEADER - 4) / STL_TRIANGLE)
        return iso_error_set(err, ISO_E_LIMIT, "STL of %zu triangles: too large", mesh->triangle_count);
    size_t size = STL_HEADER + 4 + mesh->triangle_count * STL_TRIANGLE;
    unsigned char *buf = malloc(size);
    if (!buf)
        return iso_error_set(err, ISO_E_NOMEM, "no memory for an STL of %zu bytes", size);
    /* The header must not start with "solid", or readers take the file for ASCII STL. */
    memset(buf, ' ', STL_HEADER);
    static const char title[] = "binary STL from isoserve, millimetres";
    memcpy(buf, title, sizeof title - 1);
    unsigned char *p = proto_put_u32(buf + STL_HEADER, (uint32_t)mesh->triangle_count);
    for (size_t t = 0; t < mesh->triangle_count; t++) {
        float n[3];
        facet_normal(mesh, t, n);
        for (int k = 0; k < 3; k++)
            p = proto_put_f32(p, n[k]);
        for (int corner = 0; corner < 3; corner++)
            for (int k = 0; k < 3; k++)
                p = proto_put_f32(p, mesh->positions[3 * (size_t)mesh->indices[3 * t + corner] + k]);
        p = put_u16(p, 0);
    }
    assert((size_t)(p - buf) == size);
    *out = buf;
    *out_size = size;
    return 0;
}
