/* test_multipart.c: proto/multipart.c, the splitter of WADO-RS's multipart/related bodies:
 * boundaries from Content-Type, parts that hold the delimiter's prefixes, binary bytes and
 * CRLFs, preamble and epilogue, and malformed bodies refused with the byte where. */
#include <stdio.h>
#include <string.h>

#include "check.h"
#include "multipart.h"

typedef struct parts {
    size_t count;
    char type[4][64];
    size_t len[4];
    const char *body[4];
} parts;

static int collect(void *context, const char *headers, size_t header_len, const char *body, size_t body_len)
{
    parts *p = context;
    if (p->count == 4)
        return 7;
    if (proto_multipart_header(headers, header_len, "content-type", p->type[p->count], sizeof p->type[0]))
        p->type[p->count][0] = '\0';
    p->body[p->count] = body;
    p->len[p->count++] = body_len;
    return 0;
}

static void test_boundary_from_content_type(void)
{
    char b[PROTO_BOUNDARY_MAX + 1];
    CHECK(proto_multipart_boundary("multipart/related; type=\"application/dicom\"; boundary=abc-123", b) == 0);
    CHECK(!strcmp(b, "abc-123"));
    CHECK(proto_multipart_boundary("Multipart/Related;boundary=\"q u;o\";type=application/dicom", b) == 0);
    CHECK(!strcmp(b, "q u;o"));
    CHECK(proto_multipart_boundary("application/dicom; boundary=x", b) == -1);
    CHECK(proto_multipart_boundary("multipart/related; type=application/dicom", b) == -1);
    CHECK(proto_multipart_boundary("multipart/related; boundary=", b) == -1);
    CHECK(proto_multipart_boundary("multipart/related; boundary=\"open", b) == -1);
    char longer[200];
    snprintf(longer, sizeof longer, "multipart/related; boundary=%071d", 0); /* 71 bytes: one too many */
    CHECK(proto_multipart_boundary(longer, b) == -1);
}

static void test_parts_with_binary_bytes(void)
{
    /* The second part holds "\r\n--B" without the rest of the boundary, a NUL and CRLFs. */
    static const char body[] =
        "preamble\r\n--BOUND\r\nContent-Type: application/dicom\r\n\r\nDICM1"
        "\r\n--BOUND\r\nContent-Type: application/dicom\r\nX-Other: 1\r\n\r\nA\r\n--BOUN\0D\r\n\r\nZ"
        "\r\n--BOUND   \r\n\r\nno headers"
        "\r\n--BOUND--\r\nepilogue";
    parts p = {0};
    size_t where = 0;
    CHECK_EQ(proto_multipart_split(body, sizeof body - 1, "BOUND", collect, &p, &where), 0);
    CHECK_EQ(p.count, 3);
    CHECK(!strcmp(p.type[0], "application/dicom") && !strcmp(p.type[1], "application/dicom"));
    CHECK(p.type[2][0] == '\0');
    CHECK_EQ(p.len[0], 5);
    CHECK(!memcmp(p.body[0], "DICM1", 5));
    CHECK_EQ(p.len[1], 16);
    CHECK(!memcmp(p.body[1], "A\r\n--BOUN\0D\r\n\r\nZ", 16));
    CHECK_EQ(p.len[2], 10);
    CHECK(!memcmp(p.body[2], "no headers", 10));
    /* Opening the body directly, no preamble; an empty part. */
    static const char bare[] = "--b\r\n\r\n\r\n--b--";
    memset(&p, 0, sizeof p);
    CHECK_EQ(proto_multipart_split(bare, sizeof bare - 1, "b", collect, &p, &where), 0);
    CHECK_EQ(p.count, 1);
    CHECK_EQ(p.len[0], 0);
}

static void test_malformed_bodies(void)
{
    static const struct {
        const char *body;
        size_t where;
    } bad[] = {
        {"no delimiter at all", 0},
        {"--B\r\nContent-Type: x\r\n\r\ndata without an end", 24},   /* no next delimiter */
        {"--B\r\nContent-Type: x", 5},                               /* headers never end */
        {"--Bjunk\r\n\r\nx\r\n--B--", 3},                             /* a longer boundary */
    };
    for (size_t i = 0; i < sizeof bad / sizeof bad[0]; i++) {
        parts p = {0};
        size_t where = 999;
        CHECKF(proto_multipart_split(bad[i].body, strlen(bad[i].body), "B", collect, &p, &where) == -1, "body %zu", i);
        CHECKF(where == bad[i].where, "body %zu: where %zu, expected %zu", i, where, bad[i].where);
    }
    /* A callback that stops: its value comes back. */
    static const char many[] = "--B\r\n\r\n1\r\n--B\r\n\r\n2\r\n--B\r\n\r\n3\r\n--B\r\n\r\n4\r\n--B\r\n\r\n5\r\n--B--";
    parts p = {0};
    size_t where;
    CHECK_EQ(proto_multipart_split(many, sizeof many - 1, "B", collect, &p, &where), 7);
    CHECK_EQ(p.count, 4);
}

int main(void)
{
    CHECK_RUN(test_boundary_from_content_type);
    CHECK_RUN(test_parts_with_binary_bytes);
    CHECK_RUN(test_malformed_bodies);
    return check_finish();
}
