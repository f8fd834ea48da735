/* multipart.h: splitting a multipart/related body (RFC 2046, as DICOMweb's WADO-RS sends a
 * series: one application/dicom part per instance) into its parts, without copying them.
 * The body may be untrusted: every boundary, header block and length is checked. */
#ifndef PROTO_MULTIPART_H
#define PROTO_MULTIPART_H

#include <stddef.h>

#define PROTO_BOUNDARY_MAX 70 /* RFC 2046's limit */

/* The boundary parameter of a Content-Type such as `multipart/related;
 * type="application/dicom"; boundary=XYZ` (quoted or not) into out (PROTO_BOUNDARY_MAX + 1
 * bytes). 0, or -1 when the type is not multipart or has no valid boundary. */
int proto_multipart_boundary(const char *content_type, char *out);

/* Called per part: its header block (the lines before the empty line, without it) and its
 * body, both pointing into the input. Returns 0 to go on, anything else to stop (returned). */
typedef int (*proto_multipart_part_fn)(void *context, const char *headers, size_t header_len,
                                       const char *body, size_t body_len);

/* Calls part for each part of body (len bytes) delimited by boundary, in order. Returns 0
 * when the closing delimiter was reached, what part returned if it stopped, or -1 when the
 * body is malformed (no opening delimiter, a part without its header block's end, no
 * closing delimiter): *where then says at which byte. */
int proto_multipart_split(const char *body, size_t len, const char *boundary,
                          proto_multipart_part_fn part, void *context, size_t *where);

/* A header's value in a part's header block (case-insensitive name), copied into out, or
 * -1 when absent. */
int proto_multipart_header(const char *headers, size_t header_len, const char *name, char *out,
                           size_t size);

#endif
