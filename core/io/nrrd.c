/* nrrd.c: the NRRD reader (see nrrd.h), after teem's format definition
 * (teem.sourceforge.net/nrrd/format.html), strict on what it needs and safe on hostile files. */
#include "nrrd.h"

#include <assert.h>
#include <ctype.h>
#include <errno.h>
#include <inttypes.h>
#include <math.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <strings.h>
#include <sys/stat.h>
#include <zlib.h>

/* NRRD allows up to 16 axes; we keep the per-axis values of at most 4 (3-D, or 4-D with a
 * first axis of one sample) and reject the rest when the dimension is read. */
#define MAX_AXES 4
/* Compressed bytes read per fread when inflating. */
#define GZIP_CHUNK ((size_t)256 << 10)

/* ---- the header parser ---- */

enum field_id {
    F_TYPE, F_DIMENSION, F_SIZES, F_ENDIAN, F_ENCODING, F_SPACINGS, F_SPACE_DIRECTIONS,
    F_SPACE_ORIGIN, F_SPACE_DIMENSION, F_BYTE_SKIP, F_LINE_SKIP, F_DATA_FILE, F_SPACE, F_COUNT
};

typedef struct parser {
    const char *path;          /* the header file, for messages */
    iso_error *err;
    int line_no;               /* 1-based line being parsed */
    int line_of[F_COUNT];      /* line that gave each field, 0 if not given */
    int dimension;             /* 0 until the dimension field is read */
    int64_t sizes[MAX_AXES];
    double spacings[MAX_AXES];
    double directions[MAX_AXES][3];
    int has_direction[MAX_AXES]; /* 0 for "none" */
    int have_endian;
    int space_ras;             /* "space: right-anterior-superior": flip x and y to LPS */
    iso_nrrd_header *hdr;
} parser;

/* Reports a problem with the field being parsed: "file:line: field 'name': what". */
static int field_error(parser *p, int code, const char *field, const char *fmt, ...)
#if defined(__GNUC__)
    __attribute__((format(printf, 4, 5)))
#endif
    ;
static int field_error(parser *p, int code, const char *field, const char *fmt, ...)
{
    char what[256];
    va_list ap;
    va_start(ap, fmt);
    vsnprintf(what, sizeof what, fmt, ap);
    va_end(ap);
    return iso_error_set(p->err, code, "%s:%d: field '%s': %s", p->path, p->line_no, field, what);
}

static const char *skip_blanks(const char *s)
{
    while (*s == ' ' || *s == '\t')
        s++;
    return s;
}

static int at_token_end(const char *s)
{
    return *s == '\0' || *s == ' ' || *s == '\t';
}

/* Parses a decimal integer after blanks and advances *s past it. Returns 0, ISO_E_FORMAT
 * when there is no whole integer, ISO_E_LIMIT when it does not fit in int64. */
static int parse_int(const char **s, int64_t *out)
{
    const char *c = skip_blanks(*s);
    uint64_t v = 0, limit = INT64_MAX;
    int neg = 0;
    if (*c == '+' || *c == '-')
        neg = *c++ == '-';
    if (!isdigit((unsigned char)*c))
        return ISO_E_FORMAT;
    if (neg)
        limit = (uint64_t)INT64_MAX + 1;
    for (; isdigit((unsigned char)*c); c++) {
        unsigned d = (unsigned)(*c - '0');
        if (v > (limit - d) / 10)
            return ISO_E_LIMIT;
        v = v * 10 + d;
    }
    if (!at_token_end(c))
        return ISO_E_FORMAT;
    /* -v computed in unsigned arithmetic so that INT64_MIN does not overflow. */
    *out = neg ? (int64_t)(0 - v) : (int64_t)v;
    *s = c;
    return ISO_OK;
}

/* Parses one whole number value (the field holds nothing else). */
static int parse_single_int(parser *p, const char *field, const char *value, int64_t *out)
{
    int rc = parse_int(&value, out);
    if (rc == ISO_OK && *skip_blanks(value) != '\0')
        rc = ISO_E_FORMAT;
    if (rc == ISO_E_LIMIT)
        return field_error(p, rc, field, "'%s' is too large", value);
    if (rc != ISO_OK)
        return field_error(p, rc, field, "'%s' is not an integer", value);
    return ISO_OK;
}

/* Parses "(a,b,c)" after blanks, advancing *s. Returns 0, ISO_E_FORMAT if malformed or not
 * finite, ISO_E_UNSUPPORTED for a well-formed vector of another length (a 2-D or 4-D
 * space). */
static int parse_vector(const char **s, double v[3])
{
    const char *c = skip_blanks(*s);
    int n = 0;
    if (*c++ != '(')
        return ISO_E_FORMAT;
    for (;;) {
        char *end;
        double x = strtod(c, &end);
        if (end == c || !isfinite(x))
            return ISO_E_FORMAT;
        if (n < 3)
            v[n] = x;
        n++;
        c = skip_blanks(end);
        if (*c == ')')
            break;
        if (*c != ',' || n >= 16)
            return ISO_E_FORMAT;
        c++;
    }
    c++;
    if (!at_token_end(c))
        return ISO_E_FORMAT;
    *s = c;
    return n == 3 ? ISO_OK : ISO_E_UNSUPPORTED;
}

/* Fields after which a value is needed per axis can only be parsed once the dimension is
 * known; NRRD requires the dimension field to come first for that reason. */
static int need_dimension(parser *p, const char *field)
{
    if (p->dimension == 0)
        return field_error(p, ISO_E_FORMAT, field, "given before the dimension field");
    return ISO_OK;
}

static int expect_end(parser *p, const char *field, const char *rest)
{
    if (*skip_blanks(rest) != '\0')
        return field_error(p, ISO_E_FORMAT, field, "unexpected text '%s' after %d values",
                           skip_blanks(rest), p->dimension);
    return ISO_OK;
}

/* ---- one handler per field ---- */

/* Every spelling teem accepts; type -1 marks the valid NRRD types isoserve cannot hold. */
static const struct {
    const char *name;
    int type;
} type_names[] = {
    {"signed char", ISO_I8}, {"int8", ISO_I8}, {"int8_t", ISO_I8},
    {"uchar", ISO_U8}, {"unsigned char", ISO_U8}, {"uint8", ISO_U8}, {"uint8_t", ISO_U8},
    {"short", ISO_I16}, {"short int", ISO_I16}, {"signed short", ISO_I16},
    {"signed short int", ISO_I16}, {"int16", ISO_I16}, {"int16_t", ISO_I16},
    {"ushort", ISO_U16}, {"unsigned short", ISO_U16}, {"unsigned short int", ISO_U16},
    {"uint16", ISO_U16}, {"uint16_t", ISO_U16},
    {"int", ISO_I32}, {"signed int", ISO_I32}, {"int32", ISO_I32}, {"int32_t", ISO_I32},
    {"uint", ISO_U32}, {"unsigned int", ISO_U32}, {"uint32", ISO_U32}, {"uint32_t", ISO_U32},
    {"float", ISO_F32}, {"double", ISO_F64},
    {"longlong", -1}, {"long long", -1}, {"long long int", -1}, {"signed long long", -1},
    {"signed long long int", -1}, {"int64", -1}, {"int64_t", -1},
    {"ulonglong", -1}, {"unsigned long long", -1}, {"unsigned long long int", -1},
    {"uint64", -1}, {"uint64_t", -1}, {"block", -1},
};

static int field_type(parser *p, const char *field, const char *value)
{
    for (size_t t = 0; t < sizeof type_names / sizeof type_names[0]; t++)
        if (strcasecmp(value, type_names[t].name) == 0) {
            if (type_names[t].type < 0)
                return field_error(p, ISO_E_UNSUPPORTED, field,
                                   "samples of type '%s' are not supported (8 to 32-bit "
                                   "integers, float and double are)", value);
            p->hdr->type = (iso_voxel_type)type_names[t].type;
            return ISO_OK;
        }
    return field_error(p, ISO_E_FORMAT, field, "unknown type '%s'", value);
}

static int field_dimension(parser *p, const char *field, const char *value)
{
    int64_t d;
    int rc = parse_single_int(p, field, value, &d);
    if (rc != ISO_OK)
        return rc;
    if (d < 1 || d > 16)
        return field_error(p, ISO_E_FORMAT, field, "%" PRId64 " is outside NRRD's 1..16", d);
    if (d != 3 && d != 4)
        return field_error(p, ISO_E_UNSUPPORTED, field,
                           "%" PRId64 "-D data is not supported (3-D volumes are, and 4-D "
                           "with one sample on the first axis)", d);
    p->dimension = (int)d;
    return ISO_OK;
}

static int field_sizes(parser *p, const char *field, const char *value)
{
    const char *s = value;
    int rc = need_dimension(p, field);
    for (int a = 0; rc == ISO_OK && a < p->dimension; a++) {
        rc = parse_int(&s, &p->sizes[a]);
        if (rc == ISO_E_LIMIT)
            return field_error(p, rc, field, "size %d is too large", a + 1);
        if (rc != ISO_OK)
            return field_error(p, rc, field, "expected %d positive integers in '%s'",
                               p->dimension, value);
        if (p->sizes[a] < 1)
            return field_error(p, ISO_E_FORMAT, field, "size %d is %" PRId64 ", not positive",
                               a + 1, p->sizes[a]);
    }
    return rc == ISO_OK ? expect_end(p, field, s) : rc;
}

static int field_endian(parser *p, const char *field, const char *value)
{
    if (strcasecmp(value, "little") == 0)
        p->hdr->big_endian = 0;
    else if (strcasecmp(value, "big") == 0)
        p->hdr->big_endian = 1;
    else
        return field_error(p, ISO_E_FORMAT, field, "'%s' is neither little nor big", value);
    p->have_endian = 1;
    return ISO_OK;
}

static int field_encoding(parser *p, const char *field, const char *value)
{
    static const char *const other[] = {"ascii", "text", "txt", "hex", "bzip2", "bz2", "zrl"};
    if (strcasecmp(value, "raw") == 0) {
        p->hdr->encoding = ISO_NRRD_RAW;
        return ISO_OK;
    }
    if (strcasecmp(value, "gzip") == 0 || strcasecmp(value, "gz") == 0) {
        p->hdr->encoding = ISO_NRRD_GZIP;
        return ISO_OK;
    }
    for (size_t e = 0; e < sizeof other / sizeof other[0]; e++)
        if (strcasecmp(value, other[e]) == 0)
            return field_error(p, ISO_E_UNSUPPORTED, field,
                               "encoding '%s' is not supported (raw and gzip are)", value);
    return field_error(p, ISO_E_FORMAT, field,
                       "unknown encoding '%s' (NRRD has raw, ascii, hex, gzip, bzip2, zrl)",
                       value);
}

static int field_spacings(parser *p, const char *field, const char *value)
{
    const char *s = value;
    int rc = need_dimension(p, field);
    for (int a = 0; rc == ISO_OK && a < p->dimension; a++) {
        char *end;
        double x = strtod(s, &end);
        if (end == s || !at_token_end(end))
            return field_error(p, ISO_E_FORMAT, field, "expected %d numbers in '%s'",
                               p->dimension, value);
        /* NaN means "no spacing" in NRRD; zero or infinite spacing has no meaning. */
        if (!isnan(x) && (!isfinite(x) || x == 0))
            return field_error(p, ISO_E_FORMAT, field, "spacing %d is %g", a + 1, x);
        p->spacings[a] = x;
        s = end;
    }
    return rc == ISO_OK ? expect_end(p, field, s) : rc;
}

static int field_space_directions(parser *p, const char *field, const char *value)
{
    const char *s = value;
    int rc = need_dimension(p, field);
    for (int a = 0; rc == ISO_OK && a < p->dimension; a++) {
        const char *t = skip_blanks(s);
        if (strncmp(t, "none", 4) == 0 && at_token_end(t + 4)) {
            p->has_direction[a] = 0;
            s = t + 4;
            continue;
        }
        rc = parse_vector(&s, p->directions[a]);
        if (rc == ISO_E_UNSUPPORTED)
            return field_error(p, rc, field, "only 3-D spaces are supported");
        if (rc != ISO_OK)
            return field_error(p, rc, field, "expected %d vectors '(x,y,z)' or 'none' in '%s'",
                               p->dimension, value);
        const double *v = p->directions[a];
        if (v[0] == 0 && v[1] == 0 && v[2] == 0)
            return field_error(p, ISO_E_FORMAT, field, "direction %d is the zero vector", a + 1);
        p->has_direction[a] = 1;
    }
    return rc == ISO_OK ? expect_end(p, field, s) : rc;
}

static int field_space_origin(parser *p, const char *field, const char *value)
{
    const char *s = value;
    int rc = parse_vector(&s, p->hdr->origin);
    if (rc == ISO_E_UNSUPPORTED)
        return field_error(p, rc, field, "only 3-D spaces are supported");
    if (rc != ISO_OK || *skip_blanks(s) != '\0')
        return field_error(p, ISO_E_FORMAT, field, "expected one vector '(x,y,z)', not '%s'",
                           value);
    return ISO_OK;
}

static int field_space_dimension(parser *p, const char *field, const char *value)
{
    int64_t d;
    int rc = parse_single_int(p, field, value, &d);
    if (rc == ISO_OK && d != 3)
        rc = field_error(p, ISO_E_UNSUPPORTED, field, "only 3-D spaces are supported, not %" PRId64,
                         d);
    return rc;
}

static int field_byte_skip(parser *p, const char *field, const char *value)
{
    int rc = parse_single_int(p, field, value, &p->hdr->byte_skip);
    if (rc == ISO_OK && p->hdr->byte_skip < -1)
        rc = field_error(p, ISO_E_FORMAT, field, "%" PRId64 " is below -1", p->hdr->byte_skip);
    return rc;
}

static int field_line_skip(parser *p, const char *field, const char *value)
{
    int rc = parse_single_int(p, field, value, &p->hdr->line_skip);
    if (rc == ISO_OK && p->hdr->line_skip < 0)
        rc = field_error(p, ISO_E_FORMAT, field, "%" PRId64 " is negative", p->hdr->line_skip);
    return rc;
}

/* The world space. isoserve's is LPS (volume.h): RAS headers are flipped on x and y;
 * scanner and unnamed 3-D spaces are taken as they are. */
static int field_space(parser *p, const char *field, const char *value)
{
    static const char *const ras[] = {"right-anterior-superior", "RAS"};
    static const char *const taken[] = {"left-posterior-superior", "LPS", "scanner-xyz",
                                        "3D-right-handed", "3D-left-handed"};
    for (size_t i = 0; i < 2; i++)
        if (!strcmp(value, ras[i])) {
            p->space_ras = 1;
            return ISO_OK;
        }
    for (size_t i = 0; i < 5; i++)
        if (!strcmp(value, taken[i]))
            return ISO_OK;
    return field_error(p, ISO_E_UNSUPPORTED, field, "'%s' is not a 3-D space isoserve knows", value);
}

/* A single data file beside the header: a plain name or a path below the header's
 * directory, never absolute and never through "..", so that a header cannot make the
 * server read other files (the file must also be a regular file, checked on open). The
 * multi-file forms ("LIST", or a printf format with a range) describe slices in separate
 * files. */
static int field_data_file(parser *p, const char *field, const char *value)
{
    const char *slash = strrchr(p->path, '/');
    size_t dir_len = slash ? (size_t)(slash - p->path) + 1 : 0;
    if (value[0] == '\0')
        return field_error(p, ISO_E_FORMAT, field, "no file name");
    if (value[0] == '/' || !strcmp(value, "..") || !strncmp(value, "../", 3) ||
        strstr(value, "/../") || (strlen(value) >= 3 && !strcmp(value + strlen(value) - 3, "/..")))
        return field_error(p, ISO_E_FORMAT, field,
                           "'%s' leaves the header's directory; the data file must sit beside it", value);
    if (strcmp(value, "LIST") == 0 || strncmp(value, "LIST ", 5) == 0 ||
        (strchr(value, '%') && strchr(value, ' ')))
        return field_error(p, ISO_E_UNSUPPORTED, field,
                           "data split over several files ('%s') is not supported", value);
    if (dir_len + strlen(value) >= sizeof p->hdr->data_path)
        return field_error(p, ISO_E_FORMAT, field, "path too long");
    memcpy(p->hdr->data_path, p->path, dir_len);
    strcpy(p->hdr->data_path + dir_len, value);
    p->hdr->detached = 1;
    return ISO_OK;
}

typedef int (*field_fn)(parser *p, const char *field, const char *value);

/* Fields that matter for the samples or their geometry. Others (content, kinds, units,
 * labels, min, max, ...) are descriptive and skipped. */
static const struct {
    const char *name;
    enum field_id id;
    field_fn parse;
} fields[] = {
    {"type", F_TYPE, field_type},
    {"dimension", F_DIMENSION, field_dimension},
    {"sizes", F_SIZES, field_sizes},
    {"endian", F_ENDIAN, field_endian},
    {"encoding", F_ENCODING, field_encoding},
    {"spacings", F_SPACINGS, field_spacings},
    {"space directions", F_SPACE_DIRECTIONS, field_space_directions},
    {"space origin", F_SPACE_ORIGIN, field_space_origin},
    {"space dimension", F_SPACE_DIMENSION, field_space_dimension},
    {"byte skip", F_BYTE_SKIP, field_byte_skip},
    {"byteskip", F_BYTE_SKIP, field_byte_skip},
    {"line skip", F_LINE_SKIP, field_line_skip},
    {"lineskip", F_LINE_SKIP, field_line_skip},
    {"data file", F_DATA_FILE, field_data_file},
    {"datafile", F_DATA_FILE, field_data_file},
    {"space", F_SPACE, field_space},
};

/* Parses one header line after the magic: a comment, a key:=value pair, a field or (in an
 * attached header) the empty line that ends the header (handled by the caller). */
static int parse_line(parser *p, char *line)
{
    char *colon, *value, *end;
    if (line[0] == '#')
        return ISO_OK;
    colon = strchr(line, ':');
    if (!colon)
        return iso_error_set(p->err, ISO_E_FORMAT,
                             "%s:%d: '%.60s' is neither a field, a key:=value pair nor a comment",
                             p->path, p->line_no, line);
    if (colon[1] == '=')
        return ISO_OK;
    *colon = '\0';
    value = colon + 1;
    while (*value == ' ' || *value == '\t')
        value++;
    end = value + strlen(value);
    while (end > value && (end[-1] == ' ' || end[-1] == '\t'))
        *--end = '\0';
    for (size_t f = 0; f < sizeof fields / sizeof fields[0]; f++) {
        if (strcasecmp(line, fields[f].name) != 0)
            continue;
        int *seen = &p->line_of[fields[f].id];
        if (*seen)
            return field_error(p, ISO_E_FORMAT, line, "given twice (first on line %d)", *seen);
        *seen = p->line_no;
        return fields[f].parse(p, line, value);
    }
    return ISO_OK;
}

/* ---- reading lines ---- */

enum line_status { LINE_OK, LINE_EOF, LINE_TOO_LONG, LINE_BINARY, LINE_IO };

/* Reads one line into buf (ISO_NRRD_MAX_LINE + 1 bytes), without its "\n" or "\r\n". A
 * last line without a newline still counts. Control bytes other than tab make the line
 * binary: a header is text, and this is where a data file given as header is caught. */
static int read_line(FILE *f, char *buf)
{
    size_t len = 0;
    int c;
    while ((c = getc(f)) != EOF && c != '\n') {
        if ((c < 0x20 && c != '\t' && c != '\r') || c == 0x7f)
            return LINE_BINARY;
        if (len == ISO_NRRD_MAX_LINE)
            return LINE_TOO_LONG;
        buf[len++] = (char)c;
    }
    if (c == EOF && ferror(f))
        return LINE_IO;
    if (c == EOF && len == 0)
        return LINE_EOF;
    if (len > 0 && buf[len - 1] == '\r')
        len--;
    buf[len] = '\0';
    return LINE_OK;
}

static int line_error(parser *p, int status)
{
    switch (status) {
    case LINE_TOO_LONG:
        return iso_error_set(p->err, ISO_E_FORMAT, "%s:%d: header line longer than %d bytes",
                             p->path, p->line_no, ISO_NRRD_MAX_LINE);
    case LINE_BINARY:
        return iso_error_set(p->err, ISO_E_FORMAT,
                             "%s:%d: binary bytes in the header (is the blank line that ends "
                             "it missing?)", p->path, p->line_no);
    default:
        return iso_error_set(p->err, ISO_E_IO, "%s:%d: cannot read: %s", p->path, p->line_no,
                             strerror(errno));
    }
}

/* ---- after the header: required fields and geometry ---- */

static int missing(parser *p, const char *field)
{
    return iso_error_set(p->err, ISO_E_FORMAT,
                         "%s: header (%d lines) lacks the required field '%s'", p->path,
                         p->line_no, field);
}

/* Checks what the fields say together and reduces the axes to the three spatial ones. */
static int finish_header(parser *p)
{
    iso_nrrd_header *h = p->hdr;
    int a0;
    if (!p->line_of[F_TYPE])
        return missing(p, "type");
    if (!p->line_of[F_DIMENSION])
        return missing(p, "dimension");
    if (!p->line_of[F_SIZES])
        return missing(p, "sizes");
    if (!p->line_of[F_ENCODING])
        return missing(p, "encoding");
    p->line_no = p->line_of[F_SIZES];
    a0 = p->dimension - 3;
    h->components = 1;
    if (a0 == 1 && (p->sizes[0] < 1 || p->sizes[0] > ISO_NRRD_MAX_COMPONENTS))
        return field_error(p, ISO_E_UNSUPPORTED, "sizes",
                           "4-D data with %" PRId64 " values per sample (1 to %d are read)",
                           p->sizes[0], ISO_NRRD_MAX_COMPONENTS);
    if (a0 == 1)
        h->components = (size_t)p->sizes[0];
    for (int d = 0; d < 3; d++) {
        if (p->sizes[a0 + d] < 2)
            return field_error(p, ISO_E_UNSUPPORTED, "sizes",
                               "axis %d has %" PRId64 " sample; at least 2 are needed", d,
                               p->sizes[a0 + d]);
        if ((uint64_t)p->sizes[a0 + d] > SIZE_MAX)
            return field_error(p, ISO_E_LIMIT, "sizes", "size %" PRId64 " is too large",
                               p->sizes[a0 + d]);
        h->dims[d] = (size_t)p->sizes[a0 + d];
    }
    if (iso_vol_check_size(h->dims, h->type, UINT64_MAX, &h->data_bytes, NULL) != ISO_OK ||
        h->data_bytes > UINT64_MAX / h->components)
        return field_error(p, ISO_E_LIMIT, "sizes",
                           "%zux%zux%zu samples of type %s overflow 64 bits", h->dims[0],
                           h->dims[1], h->dims[2], iso_vol_type_name(h->type));
    h->data_bytes *= h->components;
    if (!p->have_endian && iso_vol_type_size(h->type) > 1)
        return missing(p, "endian");
    if (h->byte_skip == -1 && h->encoding != ISO_NRRD_RAW) {
        p->line_no = p->line_of[F_BYTE_SKIP];
        return field_error(p, ISO_E_UNSUPPORTED, "byte skip",
                           "-1 (data at the end of the file) works only with raw encoding");
    }

    /* Space directions carry spacing and orientation together; without them the
     * spacings field gives the spacing, and a negative spacing flips the axis. */
    for (int d = 0; d < 3; d++) {
        int a = a0 + d;
        if (p->line_of[F_SPACE_DIRECTIONS]) {
            const double *v = p->directions[a];
            double norm = sqrt(v[0] * v[0] + v[1] * v[1] + v[2] * v[2]);
            p->line_no = p->line_of[F_SPACE_DIRECTIONS];
            if (!p->has_direction[a])
                return field_error(p, ISO_E_FORMAT, "space directions",
                                   "spatial axis %d has no direction", a + 1);
            if (!isfinite(norm))
                return field_error(p, ISO_E_FORMAT, "space directions",
                                   "direction %d is too long", a + 1);
            h->spacing[d] = norm;
            for (int r = 0; r < 3; r++)
                h->direction[r][d] = v[r] / norm;
        } else if (p->line_of[F_SPACINGS] && !isnan(p->spacings[a])) {
            h->spacing[d] = fabs(p->spacings[a]);
            h->direction[d][d] = p->spacings[a] < 0 ? -1 : 1;
        }
    }
    /* A named space, or directions in one, place the axes in the patient; spacings alone
     * (even negative ones) only say how far apart the samples are. */
    h->oriented = p->line_of[F_SPACE] || p->line_of[F_SPACE_DIRECTIONS];
    if (p->space_ras)
        for (int r = 0; r < 2; r++) {
            h->origin[r] = -h->origin[r];
            for (int c = 0; c < 3; c++)
                h->direction[r][c] = -h->direction[r][c];
        }
    return ISO_OK;
}

int iso_nrrd_read_header(const char *path, iso_nrrd_header *hdr, iso_error *err)
{
    parser p;
    char *line = NULL;
    FILE *f;
    int rc = ISO_OK, status;
    assert(path && hdr);

    memset(hdr, 0, sizeof *hdr);
    for (int d = 0; d < 3; d++) {
        hdr->spacing[d] = 1;
        hdr->direction[d][d] = 1;
    }
    memset(&p, 0, sizeof p);
    p.path = path;
    p.err = err;
    p.hdr = hdr;
    for (int a = 0; a < MAX_AXES; a++)
        p.spacings[a] = NAN;

    f = fopen(path, "rb");
    if (!f)
        return iso_error_set(err, ISO_E_IO, "%s: cannot open: %s", path, strerror(errno));
    line = malloc(ISO_NRRD_MAX_LINE + 1);
    if (!line) {
        rc = iso_error_set(err, ISO_E_NOMEM, "%s: out of memory", path);
        goto done;
    }

    p.line_no = 1;
    status = read_line(f, line);
    if (status == LINE_IO) {
        rc = line_error(&p, status);
        goto done;
    }
    if (status != LINE_OK || strncmp(line, "NRRD000", 7) != 0 || line[7] < '1' ||
        line[7] > '5' || line[8] != '\0') {
        rc = iso_error_set(err, ISO_E_FORMAT,
                           "%s:1: not a NRRD file (no magic NRRD0001..NRRD0005)", path);
        goto done;
    }
    for (;;) {
        p.line_no++;
        status = read_line(f, line);
        if (status == LINE_EOF || (status == LINE_OK && line[0] == '\0'))
            break;
        if (status != LINE_OK) {
            rc = line_error(&p, status);
            goto done;
        }
        rc = parse_line(&p, line);
        if (rc != ISO_OK)
            goto done;
    }
    p.line_no--; /* the blank line or end of file is not a header line */
    rc = finish_header(&p);
    if (rc != ISO_OK)
        goto done;
    if (!hdr->detached) {
        off_t at = ftello(f);
        if (at < 0 || strlen(path) >= sizeof hdr->data_path) {
            rc = iso_error_set(err, ISO_E_IO, "%s: cannot locate the data after the header",
                               path);
            goto done;
        }
        strcpy(hdr->data_path, path);
        hdr->data_offset = at;
    }

done:
    free(line);
    fclose(f);
    return rc;
}

/* ---- reading the samples ---- */

/* Names the data file in messages, and the header too when they differ. */
static void data_name(const iso_nrrd_header *hdr, const char *path, char *buf, size_t cap)
{
    if (hdr->detached)
        snprintf(buf, cap, "%s (data file of %s)", hdr->data_path, path);
    else
        snprintf(buf, cap, "%s", path);
}

static int truncated(const char *name, const char *what, uint64_t expected, uint64_t found,
                     iso_error *err)
{
    return iso_error_set(err, ISO_E_TRUNCATED,
                         "%s: truncated %s: expected %" PRIu64 " bytes of samples, found %" PRIu64,
                         name, what, expected, found);
}

/* Moves f from the data offset past the line skip and, for raw data, the byte skip. */
static int seek_to_samples(FILE *f, const iso_nrrd_header *hdr, const char *name, iso_error *err)
{
    if (fseeko(f, (off_t)hdr->data_offset, SEEK_SET) != 0)
        return iso_error_set(err, ISO_E_IO, "%s: cannot seek: %s", name, strerror(errno));
    for (int64_t n = 0; n < hdr->line_skip; n++) {
        int c;
        while ((c = getc(f)) != EOF && c != '\n')
            ;
        if (c == EOF) {
            if (ferror(f))
                return iso_error_set(err, ISO_E_IO, "%s: cannot read: %s", name,
                                     strerror(errno));
            return iso_error_set(err, ISO_E_TRUNCATED,
                                 "%s: data ends within the %" PRId64 " skipped lines", name,
                                 hdr->line_skip);
        }
    }
    if (hdr->encoding != ISO_NRRD_RAW || hdr->byte_skip == 0)
        return ISO_OK;
    if (hdr->byte_skip == -1) {
        struct stat st;
        if (fstat(fileno(f), &st) != 0 || !S_ISREG(st.st_mode))
            return iso_error_set(err, ISO_E_IO,
                                 "%s: byte skip -1 needs a regular file to measure", name);
        if ((uint64_t)st.st_size < hdr->data_bytes)
            return truncated(name, "raw data", hdr->data_bytes, (uint64_t)st.st_size, err);
        if (fseeko(f, (off_t)(st.st_size - (off_t)hdr->data_bytes), SEEK_SET) != 0)
            return iso_error_set(err, ISO_E_IO, "%s: cannot seek: %s", name, strerror(errno));
        return ISO_OK;
    }
    /* A skip past the end would fail with a bare EINVAL (or land nowhere): say so. */
    struct stat st;
    off_t at = ftello(f);
    if (at >= 0 && fstat(fileno(f), &st) == 0 && S_ISREG(st.st_mode) &&
        (uint64_t)hdr->byte_skip > (uint64_t)(st.st_size > at ? st.st_size - at : 0))
        return iso_error_set(err, ISO_E_TRUNCATED, "%s: byte skip %" PRId64 " is past the end of the file (%" PRIdMAX
                             " bytes, data from byte %" PRIdMAX ")", name, hdr->byte_skip, (intmax_t)st.st_size,
                             (intmax_t)at);
    if (fseeko(f, (off_t)hdr->byte_skip, SEEK_CUR) != 0)
        return iso_error_set(err, ISO_E_IO, "%s: cannot seek: %s", name, strerror(errno));
    return ISO_OK;
}

/* Catches short raw data before the samples are allocated, when the file can be measured. */
static int check_raw_length(FILE *f, const iso_nrrd_header *hdr, const char *name,
                            iso_error *err)
{
    struct stat st;
    off_t at = ftello(f);
    if (at < 0 || fstat(fileno(f), &st) != 0 || !S_ISREG(st.st_mode))
        return ISO_OK;
    uint64_t left = st.st_size > at ? (uint64_t)(st.st_size - at) : 0;
    if (left < hdr->data_bytes)
        return truncated(name, "raw data", hdr->data_bytes, left, err);
    return ISO_OK;
}

static int read_raw(FILE *f, const iso_nrrd_header *hdr, void *dst, const char *name,
                    iso_error *err)
{
    size_t got = fread(dst, 1, (size_t)hdr->data_bytes, f);
    if (got == hdr->data_bytes)
        return ISO_OK;
    if (ferror(f))
        return iso_error_set(err, ISO_E_IO, "%s: cannot read: %s", name, strerror(errno));
    return truncated(name, "raw data", hdr->data_bytes, got, err);
}

/* Inflates gzip (or zlib) data from f: the first byte_skip decompressed bytes are
 * discarded, as NRRD applies the byte skip after decompression; the next data_bytes go to
 * dst. Concatenated gzip members are read as one stream, like gunzip does. */
static int read_gzip(FILE *f, const iso_nrrd_header *hdr, unsigned char *dst, const char *name,
                     iso_error *err)
{
    unsigned char scratch[4096];
    uint64_t skip = (uint64_t)hdr->byte_skip, want = skip + hdr->data_bytes, done = 0;
    z_stream zs;
    unsigned char *in = malloc(GZIP_CHUNK);
    int rc = ISO_OK;

    memset(&zs, 0, sizeof zs);
    if (!in)
        return iso_error_set(err, ISO_E_NOMEM, "%s: out of memory", name);
    if (inflateInit2(&zs, 15 + 32) != Z_OK) { /* 15 + 32: gzip or zlib header */
        free(in);
        return iso_error_set(err, ISO_E_NOMEM, "%s: cannot start zlib", name);
    }
    while (done < want) {
        uint64_t room;
        int z;
        if (zs.avail_in == 0) {
            size_t n = fread(in, 1, GZIP_CHUNK, f);
            if (n == 0) {
                if (ferror(f))
                    rc = iso_error_set(err, ISO_E_IO, "%s: cannot read: %s", name,
                                       strerror(errno));
                else
                    rc = truncated(name, "gzip data", hdr->data_bytes,
                                   done > skip ? done - skip : 0, err);
                break;
            }
            zs.next_in = in;
            zs.avail_in = (uInt)n;
        }
        if (done < skip) {
            room = skip - done < sizeof scratch ? skip - done : sizeof scratch;
            zs.next_out = scratch;
        } else {
            room = want - done;
            zs.next_out = dst + (done - skip);
        }
        if (room > (1u << 30)) /* avail_out is an unsigned int */
            room = 1u << 30;
        zs.avail_out = (uInt)room;
        z = inflate(&zs, Z_NO_FLUSH);
        done += room - zs.avail_out;
        if (z == Z_STREAM_END) {
            if (done < want && inflateReset(&zs) != Z_OK) {
                rc = iso_error_set(err, ISO_E_NOMEM, "%s: zlib reset failed", name);
                break;
            }
        } else if (z == Z_MEM_ERROR) {
            rc = iso_error_set(err, ISO_E_NOMEM, "%s: out of memory in zlib", name);
            break;
        } else if (z != Z_OK && !(z == Z_BUF_ERROR && zs.avail_in == 0)) {
            rc = iso_error_set(err, ISO_E_FORMAT, "%s: corrupt gzip data after %" PRIu64
                               " bytes: %s", name, done, zs.msg ? zs.msg : "inflate failed");
            break;
        }
    }
    inflateEnd(&zs);
    free(in);
    return rc;
}

static int host_is_big_endian(void)
{
    const uint16_t one = 1;
    unsigned char first;
    memcpy(&first, &one, 1);
    return first == 0;
}

/* Reverses the bytes of each sample; memcpy keeps it free of alignment assumptions and
 * compiles to bswap instructions. */
static void swap_samples(void *data, size_t count, size_t size)
{
    unsigned char *p = data;
    if (size == 2) {
        for (size_t i = 0; i < count; i++, p += 2) {
            uint16_t v;
            memcpy(&v, p, 2);
            v = (uint16_t)(v << 8 | v >> 8);
            memcpy(p, &v, 2);
        }
    } else if (size == 4) {
        for (size_t i = 0; i < count; i++, p += 4) {
            uint32_t v;
            memcpy(&v, p, 4);
            v = (v << 24) | ((v << 8) & 0xff0000u) | ((v >> 8) & 0xff00u) | (v >> 24);
            memcpy(p, &v, 4);
        }
    } else if (size == 8) {
        for (size_t i = 0; i < count; i++, p += 8) {
            uint64_t v, r = 0;
            memcpy(&v, p, 8);
            for (int b = 0; b < 8; b++, v >>= 8)
                r = (r << 8) | (v & 0xff);
            memcpy(p, &r, 8);
        }
    }
}

int iso_nrrd_load_samples(const char *path, const iso_nrrd_header *hdr,
                          const iso_load_options *opt, iso_volume **out, iso_error *err)
{
    iso_volume *vol = NULL;
    FILE *f = NULL;
    char name[ISO_NRRD_MAX_PATH + 64];
    uint64_t max_bytes = opt && opt->max_bytes ? opt->max_bytes : ISO_VOL_DEFAULT_MAX_BYTES;
    int rc;
    assert(path && hdr && out);
    *out = NULL;
    if (hdr->data_bytes > max_bytes)
        return iso_error_set(err, ISO_E_LIMIT,
                             "%s: %zux%zux%zu %s samples (%" PRIu64 " bytes) exceed the limit of %"
                             PRIu64 " bytes", path, hdr->dims[0], hdr->dims[1], hdr->dims[2],
                             iso_vol_type_name(hdr->type), hdr->data_bytes, max_bytes);
    data_name(hdr, path, name, sizeof name);
    f = fopen(hdr->data_path, "rb");
    if (!f)
        return iso_error_set(err, ISO_E_IO, "%s: cannot open: %s", name, strerror(errno));
    struct stat st;
    if (fstat(fileno(f), &st) || !S_ISREG(st.st_mode)) {
        rc = iso_error_set(err, ISO_E_IO, "%s: not a regular file", name);
        goto fail;
    }
    rc = seek_to_samples(f, hdr, name, err);
    if (rc == ISO_OK && hdr->encoding == ISO_NRRD_RAW)
        rc = check_raw_length(f, hdr, name, err);
    if (rc != ISO_OK)
        goto fail;
    /* Several values per sample (a .seg.nrrd's layers) come in as a volume that many
     * times wider along x, interleaved as stored; the caller splits them. */
    size_t dims[3] = {hdr->dims[0] * (hdr->components ? hdr->components : 1), hdr->dims[1], hdr->dims[2]};
    vol = iso_vol_create(dims, hdr->type, max_bytes, NULL);
    if (!vol) {
        rc = iso_error_set(err, ISO_E_NOMEM, "%s: out of memory for %" PRIu64 " bytes of samples",
                           path, hdr->data_bytes);
        goto fail;
    }
    if (hdr->encoding == ISO_NRRD_RAW)
        rc = read_raw(f, hdr, vol->data, name, err);
    else
        rc = read_gzip(f, hdr, vol->data, name, err);
    if (rc != ISO_OK)
        goto fail;
    if (iso_vol_type_size(hdr->type) > 1 && hdr->big_endian != host_is_big_endian())
        swap_samples(vol->data, iso_vol_count(vol), iso_vol_type_size(hdr->type));
    memcpy(vol->spacing, hdr->spacing, sizeof vol->spacing);
    memcpy(vol->origin, hdr->origin, sizeof vol->origin);
    memcpy(vol->direction, hdr->direction, sizeof vol->direction);
    vol->oriented = hdr->oriented;
    fclose(f);
    *out = vol;
    return ISO_OK;

fail:
    fclose(f);
    iso_vol_destroy(vol);
    return rc;
}

int iso_nrrd_load(const char *path, const iso_load_options *opt, iso_volume **out,
                  iso_error *err)
{
    assert(path && out);
    *out = NULL;
    iso_nrrd_header *hdr = malloc(sizeof *hdr); /* about 4 KB of path: kept off small thread stacks */
    if (!hdr)
        return iso_error_set(err, ISO_E_NOMEM, "%s: out of memory", path);
    int rc = iso_nrrd_read_header(path, hdr, err);
    if (rc == ISO_OK && hdr->components != 1)
        rc = iso_error_set(err, ISO_E_UNSUPPORTED,
                           "%s: field 'sizes': 4-D data with %zu values per sample (a scalar volume has 1; a 3D Slicer "
                           "segmentation's layers are read as a .seg.nrrd)", path, hdr->components);
    if (rc == ISO_OK)
        rc = iso_nrrd_load_samples(path, hdr, opt, out, err);
    free(hdr);
    return rc;
}

int iso_nrrd_key_values(const char *path,
                        int (*fn)(void *context, const char *key, const char *value, int line, iso_error *err),
                        void *context, iso_error *err)
{
    FILE *f = fopen(path, "rb");
    if (!f)
        return iso_error_set(err, ISO_E_IO, "%s: cannot open: %s", path, strerror(errno));
    char *line = malloc(ISO_NRRD_MAX_LINE + 1);
    int rc = line ? 0 : iso_error_set(err, ISO_E_NOMEM, "%s: out of memory", path), line_no = 0;
    while (!rc) {
        line_no++;
        int status = read_line(f, line);
        if (status != LINE_OK || line[0] == '\0')
            break; /* the header's end (or what iso_nrrd_read_header reports) */
        char *eq = line[0] == '#' ? NULL : strstr(line, ":=");
        if (!eq)
            continue;
        *eq = '\0';
        rc = fn(context, line, eq + 2, line_no, err);
    }
    free(line);
    fclose(f);
    return rc;
}

int iso_nrrd_load_layers(const char *path, const iso_load_options *opt, iso_volume ***out, size_t *count,
                         iso_error *err)
{
    *out = NULL;
    *count = 0;
    iso_nrrd_header *hdr = malloc(sizeof *hdr);
    if (!hdr)
        return iso_error_set(err, ISO_E_NOMEM, "%s: out of memory", path);
    iso_volume *wide = NULL;
    int rc = iso_nrrd_read_header(path, hdr, err);
    if (!rc)
        rc = iso_nrrd_load_samples(path, hdr, opt, &wide, err);
    size_t layers = rc ? 0 : hdr->components, size = rc ? 0 : iso_vol_type_size(hdr->type);
    size_t samples = rc ? 0 : hdr->dims[0] * hdr->dims[1] * hdr->dims[2];
    iso_volume **list = rc ? NULL : calloc(layers, sizeof *list);
    if (!rc && !list)
        rc = iso_error_set(err, ISO_E_NOMEM, "%s: out of memory", path);
    /* Each layer's samples from the interleaved ones (value fastest); one is the file's own. */
    for (size_t l = 0; !rc && l < layers; l++) {
        iso_volume *vol = layers == 1 ? wide : iso_vol_create(hdr->dims, hdr->type, opt ? opt->max_bytes : 0, err);
        if (!vol) {
            rc = err ? err->code : ISO_E_NOMEM;
            break;
        }
        if (layers > 1) {
            const unsigned char *from = (const unsigned char *)wide->data + l * size;
            unsigned char *to = vol->data;
            for (size_t i = 0; i < samples; i++)
                memcpy(to + i * size, from + i * layers * size, size);
        }
        vol->dims[0] = hdr->dims[0];
        memcpy(vol->spacing, hdr->spacing, sizeof vol->spacing);
        memcpy(vol->origin, hdr->origin, sizeof vol->origin);
        memcpy(vol->direction, hdr->direction, sizeof vol->direction);
        iso_vol_update_stats(vol);
        list[l] = vol;
    }
    if (layers == 1)
        wide = NULL;
    iso_vol_destroy(wide);
    free(hdr);
    if (rc) {
        for (size_t l = 0; list && l < layers; l++)
            iso_vol_destroy(list[l]);
        free(list);
        return rc;
    }
    *out = list;
    *count = layers;
    return 0;
}
