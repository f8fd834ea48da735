/* multipart.c: multipart/related bodies split in place (see multipart.h). */
#include "multipart.h"

#include <string.h>
#include <strings.h>

int proto_multipart_boundary(const char *content_type, char *out)
{
    if (strncasecmp(content_type, "multipart/", 10))
        return -1;
    for (const char *p = strchr(content_type, ';'); p; p = strchr(p + 1, ';')) {
        const char *q = p + 1;
        q += strspn(q, " \t");
        if (strncasecmp(q, "boundary=", 9))
            continue;
        q += 9;
        int quoted = *q == '"';
        q += quoted;
        size_t n = quoted ? strcspn(q, "\"") : strcspn(q, " \t;");
        if (n == 0 || n > PROTO_BOUNDARY_MAX || (quoted && q[n] != '"'))
            return -1;
        memcpy(out, q, n);
        out[n] = '\0';
        return 0;
    }
    return -1;
}

/* The first occurrence of needle (n >= 1 bytes) in hay (len bytes) at or after from, or
 * NULL (memmem is a GNU extension). */
static const char *find(const char *hay, size_t len, size_t from, const char *needle, size_t n)
{
    while (from + n <= len) {
        const char *p = memchr(hay + from, needle[0], len - from - n + 1);
        if (!p)
            return NULL;
        if (!memcmp(p, needle, n))
            return p;
        from = (size_t)(p - hay) + 1;
    }
    return NULL;
}

int proto_multipart_split(const char *body, size_t len, const char *boundary,
                          proto_multipart_part_fn part, void *context, size_t *where)
{
    char delim[PROTO_BOUNDARY_MAX + 5] = "\r\n--";
    size_t blen = strlen(boundary);
    if (blen == 0 || blen > PROTO_BOUNDARY_MAX)
        return *where = 0, -1;
    memcpy(delim + 4, boundary, blen);
    size_t dlen = blen + 4;
    /* The first delimiter may open the body (no CRLF before it: a preamble is optional). */
    size_t at;
    if (len >= dlen - 2 && !memcmp(body, delim + 2, dlen - 2)) {
        at = dlen - 2;
    } else {
        const char *first = find(body, len, 0, delim, dlen);
        if (!first)
            return *where = 0, -1;
        at = (size_t)(first - body) + dlen;
    }
    for (;;) {
        if (len - at >= 2 && !memcmp(body + at, "--", 2))
            return 0; /* the closing delimiter; an epilogue may follow */
        while (at < len && (body[at] == ' ' || body[at] == '\t')) /* transport padding */
            at++;
        if (len - at < 2 || memcmp(body + at, "\r\n", 2))
            return *where = at, -1;
        size_t start = at + 2;
        const char *blank = find(body, len, start, "\r\n\r\n", 4);
        size_t header_len, content;
        if (len - start >= 2 && !memcmp(body + start, "\r\n", 2)) { /* no headers at all */
            header_len = 0;
            content = start + 2;
        } else if (blank) {
            header_len = (size_t)(blank - body) - start;
            content = (size_t)(blank - body) + 4;
        } else {
            return *where = start, -1;
        }
        const char *next = find(body, len, content, delim, dlen);
        if (!next)
            return *where = content, -1;
        int rc = part(context, body + start, header_len, body + content, (size_t)(next - body) - content);
        if (rc)
            return rc;
        at = (size_t)(next - body) + dlen;
    }
}

int proto_multipart_header(const char *headers, size_t header_len, const char *name, char *out,
                           size_t size)
{
    size_t n = strlen(name), at = 0;
    while (at < header_len) {
        const char *eol = find(headers, header_len, at, "\r\n", 2);
        size_t line = eol ? (size_t)(eol - headers) - at : header_len - at;
        const char *l = headers + at;
        if (line > n && !strncasecmp(l, name, n) && l[n] == ':') {
            size_t v = n + 1;
            while (v < line && (l[v] == ' ' || l[v] == '\t'))
                v++;
            size_t end = line;
            while (end > v && (l[end - 1] == ' ' || l[end - 1] == '\t'))
                end--;
            size_t copy = end - v < size - 1 ? end - v : size - 1;
            memcpy(out, l + v, copy);
            out[copy] = '\0';
            return 0;
        }
        at += line + 2;
    }
    return -1;
}
