/* obj.c: the Wavefront OBJ text encoder (positions, optional normals, 1-based triangles). */
#include "encode.h"

#include <assert.h>
#include <stdio.h>
#include <stdlib.h>

/* Longest lines: "%.9g" of a float is at most 15 characters ("-1.17549435e-38"), a 1-based
 * uint32 index at most 10 digits. One allocation of the bound, then a shrink. */
enum { OBJ_VERTEX_LINE_MAX = 2 + 3 * 16 + 1, OBJ_FACE_LINE_MAX = 2 + 3 * 23 + 1,
       OBJ_HEADER_MAX = 96 };

/* Appends one formatted line; the bound above makes running out of room a bug. */
#define OBJ_PUT(...) do { \
        int n_ = snprintf(p, (size_t)(end - p), __VA_ARGS__); \
        assert(n_ >= 0 && n_ < end - p); \
        p += n_; \
    } while (0)

int proto_encode_obj(const iso_mesh *mesh, unsigned char **out, size_t *out_size,
                     iso_error *err)
{
    assert(mesh && out && out_size);
    *out = NULL;
    *out_size = 0;
    int rc = proto_mesh_check(mesh, 0, err);
    if (rc)
        return rc;

    const size_t nv = mesh->vertex_count, nt = mesh->triangle_count;
    const size_t vlines = mesh->normals ? 2 : 1;
    if (nv > (SIZE_MAX / 2 - OBJ_HEADER_MAX) / (vlines * OBJ_VERTEX_LINE_MAX) ||
        nt > (SIZE_MAX / 2) / OBJ_FACE_LINE_MAX)
        return iso_error_set(err, ISO_E_LIMIT, "OBJ of %zu vertices, %zu triangles: too large",
                             nv, nt);
    size_t bound = OBJ_HEADER_MAX + nv * vlines * OBJ_VERTEX_LINE_MAX + nt * OBJ_FACE_LINE_MAX;
    char *buf = malloc(bound), *p = buf, *end = buf + bound;
    if (!buf)
        return iso_error_set(err, ISO_E_NOMEM, "no memory for an OBJ of up to %zu bytes", bound);

    OBJ_PUT("# isoserve: %zu vertices, %zu triangles\n", nv, nt);
    for (size_t v = 0; v < nv; v++) {
        const float *x = mesh->positions + 3 * v;
        OBJ_PUT("v %.9g %.9g %.9g\n", x[0], x[1], x[2]);
    }
    if (mesh->normals)
        for (size_t v = 0; v < nv; v++) {
            const float *n = mesh->normals + 3 * v;
            OBJ_PUT("vn %.9g %.9g %.9g\n", n[0], n[1], n[2]);
        }
    for (size_t t = 0; t < nt; t++) {
        /* OBJ counts from 1; the check above keeps index + 1 within uint32. */
        unsigned long a = mesh->indices[3 * t] + 1UL, b = mesh->indices[3 * t + 1] + 1UL,
                      c = mesh->indices[3 * t + 2] + 1UL;
        if (mesh->normals)
            OBJ_PUT("f %lu//%lu %lu//%lu %lu//%lu\n", a, a, b, b, c, c);
        else
            OBJ_PUT("f %lu %lu %lu\n", a, b, c);
    }

    size_t size = (size_t)(p - buf);
    char *shrunk = realloc(buf, size);
    if (shrunk) /* a failed shrink leaves the bigger buffer, which is still right */
        buf = shrunk;
    *out = (unsigned char *)buf;
    *out_size = size;
    return 0;
}
