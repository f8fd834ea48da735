/* gzip.c: a gzip member (RFC 1952) of a whole buffer with zlib, for HTTP's
 * Content-Encoding: gzip (see encode.h). */
#include "encode.h"

#include <assert.h>
#include <stdlib.h>
#include <zlib.h>

int proto_gzip(const unsigned char *in, size_t size, unsigned char **out, size_t *out_size,
               iso_error *err)
{
    assert(in && out && out_size);
    *out = NULL;
    *out_size = 0;
    z_stream z = {0};
    /* 15 + 16: a gzip header and trailer around the deflate stream; level 1, the fastest:
     * the bytes it leaves are the encoders' own entropy, which more effort barely cuts. */
    if (deflateInit2(&z, 1, Z_DEFLATED, 15 + 16, 8, Z_DEFAULT_STRATEGY) != Z_OK)
        return iso_error_set(err, ISO_E_NOMEM, "gzip: no memory for the compressor");
    size_t bound = deflateBound(&z, (uLong)size);
    unsigned char *buf = malloc(bound ? bound : 1);
    if (!buf || size > UINT32_MAX) {
        deflateEnd(&z);
        free(buf);
        return iso_error_set(err, buf ? ISO_E_LIMIT : ISO_E_NOMEM, "gzip: cannot compress %zu bytes", size);
    }
    z.next_in = (Bytef *)(uintptr_t)in;
    z.avail_in = (uInt)size;
    z.next_out = buf;
    z.avail_out = (uInt)bound;
    int rc = deflate(&z, Z_FINISH);
    size_t produced = bound - z.avail_out;
    deflateEnd(&z);
    if (rc != Z_STREAM_END) {
        free(buf);
        return iso_error_set(err, ISO_E_INTERNAL, "gzip: deflate ended with %d within its own bound", rc);
    }
    *out = buf;
    *out_size = produced;
    return 0;
}
