/* ply.c: the binary little-endian PLY encoder, and the option defaults and mesh checks that
 * every encoder of encode.h shares. */
#include "encode.h"
#include "bytes.h"

#include <assert.h>
#include <math.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#if defined(__SSE2__)
#include <emmintrin.h>
#endif

void proto_encode_options_init(proto_encode_options *opt)
{
    assert(opt);
    opt->position_bits = PROTO_POSITION_BITS_DEFAULT;
    opt->normal_bits = PROTO_NORMAL_BITS_DEFAULT;
    opt->speed = PROTO_DRACO_SPEED_DEFAULT;
    opt->threads = 0;
}

/* Every value finite: its exponent bits not all ones. Four values at a time, without a
 * branch per value: every value of every mesh is checked before encoding, and the compiler
 * vectorizes neither a loop that stops at the first bad value nor one that counts them. */
int proto_floats_finite(const float *v, size_t n)
{
    const uint32_t exponent = 0x7f800000u;
    uint32_t bad = 0;
    size_t i = 0;
#if defined(__SSE2__)
    const __m128i e = _mm_set1_epi32((int)exponent);
    __m128i any = _mm_setzero_si128();
    for (; i + 4 <= n; i += 4) {
        __m128i x = _mm_and_si128(_mm_loadu_si128((const __m128i *)(const void *)(v + i)), e);
        any = _mm_or_si128(any, _mm_cmpeq_epi32(x, e));
    }
    bad = (uint32_t)_mm_movemask_epi8(any);
#endif
    for (; i < n; i++) {
        uint32_t bits;
        memcpy(&bits, v + i, sizeof bits);
        bad |= (bits & exponent) == exponent;
    }
    return !bad;
}

int proto_mesh_check_counts(const iso_mesh *mesh, iso_error *err)
{
    assert(mesh);
    assert(mesh->vertex_count == 0 || mesh->positions);
    assert(mesh->triangle_count == 0 || mesh->indices);
    /* Draco numbers corners (3 per triangle) with uint32, PLY and glTF indices are uint32. */
    if (mesh->vertex_count > UINT32_MAX || mesh->triangle_count > UINT32_MAX / 3)
        return iso_error_set(err, ISO_E_LIMIT, "mesh of %zu vertices, %zu triangles: too large"
                             " to encode", mesh->vertex_count, mesh->triangle_count);
    return 0;
}

int proto_mesh_check_data(const iso_mesh *mesh, int finite, iso_error *err)
{
    for (size_t i = 0; i < 3 * mesh->triangle_count; i++)
        if (mesh->indices[i] >= mesh->vertex_count)
            return iso_error_set(err, ISO_E_ARGUMENT, "triangle %zu: index %u >= %zu vertices",
                                 i / 3, mesh->indices[i], mesh->vertex_count);
    if (finite && !proto_floats_finite(mesh->positions, 3 * mesh->vertex_count))
        return iso_error_set(err, ISO_E_ARGUMENT, "mesh has a non-finite position");
    if (finite && mesh->normals && !proto_floats_finite(mesh->normals, 3 * mesh->vertex_count))
        return iso_error_set(err, ISO_E_ARGUMENT, "mesh has a non-finite normal");
    return 0;
}

int proto_mesh_check(const iso_mesh *mesh, int finite, iso_error *err)
{
    int rc = proto_mesh_check_counts(mesh, err);
    return rc ? rc : proto_mesh_check_data(mesh, finite, err);
}

int proto_encode_ply(const iso_mesh *mesh, unsigned char **out, size_t *out_size,
                     iso_error *err)
{
    assert(mesh && out && out_size);
    *out = NULL;
    *out_size = 0;
    int rc = proto_mesh_check(mesh, 0, err);
    if (rc)
        return rc;

    const int has_normals = mesh->normals != NULL;
    char header[512];
    int hlen = snprintf(header, sizeof header,
                        "ply\n"
                        "format binary_little_endian 1.0\n"
                        "element vertex %zu\n"
                        "property float x\n"
                        "property float y\n"
                        "property float z\n"
                        "%s"
                        "element face %zu\n"
                        "property list uchar uint vertex_indices\n"
                        "end_header\n",
                        mesh->vertex_count,
                        has_normals ? "property float nx\n"
                                      "property float ny\n"
                                      "property float nz\n" : "",
                        mesh->triangle_count);
    assert(hlen > 0 && (size_t)hlen < sizeof header);

    /* Counts fit uint32 (checked above), so only a 32-bit size_t can overflow here. */
    const size_t vbytes = has_normals ? 24 : 12, fbytes = 1 + 12;
    if (mesh->vertex_count > (SIZE_MAX - (size_t)hlen) / 2 / vbytes ||
        mesh->triangle_count > (SIZE_MAX - (size_t)hlen) / 2 / fbytes)
        return iso_error_set(err, ISO_E_LIMIT, "PLY of %zu vertices, %zu triangles: too large",
                             mesh->vertex_count, mesh->triangle_count);
    size_t size = (size_t)hlen + mesh->vertex_count * vbytes + mesh->triangle_count * fbytes;
    unsigned char *buf = malloc(size);
    if (!buf)
        return iso_error_set(err, ISO_E_NOMEM, "no memory for a PLY of %zu bytes", size);

    unsigned char *p = buf;
    memcpy(p, header, (size_t)hlen);
    p += hlen;
    for (size_t v = 0; v < mesh->vertex_count; v++) {
        for (int c = 0; c < 3; c++)
            p = proto_put_f32(p, mesh->positions[3 * v + c]);
        if (has_normals)
            for (int c = 0; c < 3; c++)
                p = proto_put_f32(p, mesh->normals[3 * v + c]);
    }
    for (size_t t = 0; t < mesh->triangle_count; t++) {
        *p++ = 3;
        for (int c = 0; c < 3; c++)
            p = proto_put_u32(p, mesh->indices[3 * t + c]);
    }
    assert((size_t)(p - buf) == size);
    *out = buf;
    *out_size = size;
    return 0;
}
