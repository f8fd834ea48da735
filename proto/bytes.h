/* bytes.h: little-endian writers shared by proto's binary encoders (PLY, glb); internal to
 * proto/, not part of its public header. Byte by byte, so the output is little endian
 * whatever the host. The caller sizes the buffer; each returns the position after. */
#ifndef PROTO_BYTES_H
#define PROTO_BYTES_H

#include <stdint.h>
#include <string.h>

static inline unsigned char *proto_put_u32(unsigned char *p, uint32_t v)
{
    p[0] = (unsigned char)v;
    p[1] = (unsigned char)(v >> 8);
    p[2] = (unsigned char)(v >> 16);
    p[3] = (unsigned char)(v >> 24);
    return p + 4;
}

static inline unsigned char *proto_put_f32(unsigned char *p, float f)
{
    uint32_t v;
    memcpy(&v, &f, sizeof v);
    return proto_put_u32(p, v);
}

#endif
