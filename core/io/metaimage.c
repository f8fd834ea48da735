/* metaimage.c: MetaImage headers (see metaimage.h). */
#include "metaimage.h"

#include <assert.h>
#include <errno.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <strings.h>

#include "nrrd.h"

#define LINE_MAX_BYTES 4096
#define HEADER_MAX_LINES 256

static const struct {
    const char *name;
    iso_voxel_type type;
} element_types[] = {
    {"MET_UCHAR", ISO_U8}, {"MET_CHAR", ISO_I8}, {"MET_USHORT", ISO_U16}, {"MET_SHORT", ISO_I16},
    {"MET_UINT", ISO_U32}, {"MET_INT", ISO_I32}, {"MET_FLOAT", ISO_F32}, {"MET_DOUBLE", ISO_F64},
};

/* What the header said, before it becomes an iso_nrrd_header. */
typedef struct mhd {
    int ndims, have_dims, have_type, channels;
    double dims[3], spacing[3], origin[3], matrix[9];
    int have_matrix;
    iso_voxel_type type;
} mhd;

/* Up to n numbers separated by blanks; returns how many were read (-1 on junk). */
static int numbers(const char *value, double *out, int n)
{
    int count = 0;
    const char *s = value;
    while (*s) {
        while (*s == ' ' || *s == '\t')
            s++;
        if (!*s)
            break;
        char *end;
        errno = 0;
        double v = strtod(s, &end);
        if (end == s || errno == ERANGE || count == n)
            return -1;
        out[count++] = v;
        s = end;
    }
    return count;
}

static int is_true(const char *value)
{
    return !strcasecmp(value, "True") || !strcmp(value, "1");
}

/* One "Key = Value" line; fills m or hdr. Returns 0, 1 when it was ElementDataFile (the
 * last line of a header), or an error. */
static int parse_field(const char *path, int line_no, const char *key, const char *value, mhd *m,
                       iso_nrrd_header *hdr, iso_error *err)
{
#define BAD(...) iso_error_set(err, ISO_E_FORMAT, "%s:%d: %s: " __VA_ARGS__)
    if (!strcmp(key, "ObjectType")) {
        if (strcmp(value, "Image"))
            return BAD("'%s' is not an image", path, line_no, key, value);
    } else if (!strcmp(key, "NDims")) {
        double n;
        if (numbers(value, &n, 1) != 1 || n != 3)
            return iso_error_set(err, ISO_E_UNSUPPORTED, "%s:%d: %s: %s dimensions; isoserve reads 3-D volumes",
                                 path, line_no, key, value);
        m->ndims = 3;
    } else if (!strcmp(key, "DimSize")) {
        if (numbers(value, m->dims, 3) != 3)
            return BAD("expected three sizes, not '%s'", path, line_no, key, value);
        m->have_dims = 1;
    } else if (!strcmp(key, "ElementType")) {
        for (size_t i = 0; i < sizeof element_types / sizeof element_types[0]; i++)
            if (!strcmp(value, element_types[i].name)) {
                m->type = element_types[i].type;
                m->have_type = 1;
            }
        if (!m->have_type)
            return iso_error_set(err, ISO_E_UNSUPPORTED, "%s:%d: %s: '%s' is not a scalar type isoserve reads",
                                 path, line_no, key, value);
    } else if (!strcmp(key, "ElementSpacing") || (!strcmp(key, "ElementSize") && m->spacing[0] == 0)) {
        if (numbers(value, m->spacing, 3) != 3)
            return BAD("expected three spacings, not '%s'", path, line_no, key, value);
        for (int a = 0; a < 3; a++)
            if (!(m->spacing[a] > 0) || !isfinite(m->spacing[a]))
                return BAD("spacing %g is zero, negative or not finite", path, line_no, key, m->spacing[a]);
    } else if (!strcmp(key, "Offset") || !strcmp(key, "Position") || !strcmp(key, "Origin")) {
        if (numbers(value, m->origin, 3) != 3 || !isfinite(m->origin[0] + m->origin[1] + m->origin[2]))
            return BAD("expected three finite numbers, not '%s'", path, line_no, key, value);
    } else if (!strcmp(key, "TransformMatrix") || !strcmp(key, "Rotation") || !strcmp(key, "Orientation")) {
        if (numbers(value, m->matrix, 9) != 9)
            return BAD("expected nine numbers, not '%s'", path, line_no, key, value);
        m->have_matrix = 1;
    } else if (!strcmp(key, "ElementByteOrderMSB") || !strcmp(key, "BinaryDataByteOrderMSB")) {
        hdr->big_endian = is_true(value);
    } else if (!strcmp(key, "CompressedData")) {
        hdr->encoding = is_true(value) ? ISO_NRRD_GZIP : ISO_NRRD_RAW;
    } else if (!strcmp(key, "HeaderSize")) {
        double n;
        if (numbers(value, &n, 1) != 1 || n < -1 || n != floor(n) || n > 1e15)
            return BAD("'%s' is not a byte count (or -1)", path, line_no, key, value);
        hdr->byte_skip = (int64_t)n;
    } else if (!strcmp(key, "ElementNumberOfChannels")) {
        double n;
        if (numbers(value, &n, 1) != 1 || n != 1)
            return iso_error_set(err, ISO_E_UNSUPPORTED, "%s:%d: %s: %s channels; isoserve reads scalar volumes",
                                 path, line_no, key, value);
    } else if (!strcmp(key, "ElementDataFile")) {
        return 1;
    }
    return 0;
#undef BAD
}

/* The data file: LOCAL (after the header) or a name beside the header. */
static int data_file(const char *path, int line_no, const char *value, long header_end,
                     iso_nrrd_header *hdr, iso_error *err)
{
    if (!strcmp(value, "LOCAL")) {
        snprintf(hdr->data_path, sizeof hdr->data_path, "%s", path);
        hdr->data_offset = header_end;
        return 0;
    }
    if (!strncmp(value, "LIST", 4) || strchr(value, '%'))
        return iso_error_set(err, ISO_E_UNSUPPORTED, "%s:%d: ElementDataFile: slices in several files ('%s') are not supported",
                             path, line_no, value);
    if (!*value || value[0] == '/' || !strcmp(value, "..") || !strncmp(value, "../", 3) ||
        strstr(value, "/../"))
        return iso_error_set(err, ISO_E_FORMAT, "%s:%d: ElementDataFile: '%s' leaves the header's directory; the data file must sit beside it",
                             path, line_no, value);
    const char *slash = strrchr(path, '/');
    int dir_len = slash ? (int)(slash - path) + 1 : 0;
    if ((size_t)dir_len + strlen(value) >= sizeof hdr->data_path)
        return iso_error_set(err, ISO_E_FORMAT, "%s:%d: ElementDataFile: path too long", path, line_no);
    snprintf(hdr->data_path, sizeof hdr->data_path, "%.*s%s", dir_len, path, value);
    hdr->detached = 1;
    return 0;
}

/* Turns what the header said into the sample reader's header. */
static int finish(const char *path, const mhd *m, iso_nrrd_header *hdr, iso_error *err)
{
    if (!m->have_dims || !m->have_type)
        return iso_error_set(err, ISO_E_FORMAT, "%s: %s is missing", path, m->have_dims ? "ElementType" : "DimSize");
    for (int a = 0; a < 3; a++) {
        if (m->dims[a] < 2 || m->dims[a] != floor(m->dims[a]) || m->dims[a] > 1e9)
            return iso_error_set(err, ISO_E_FORMAT, "%s: DimSize: %g is not a size of at least 2", path, m->dims[a]);
        hdr->dims[a] = (size_t)m->dims[a];
    }
    hdr->type = m->type;
    if (iso_vol_check_size(hdr->dims, hdr->type, UINT64_MAX, &hdr->data_bytes, NULL))
        return iso_error_set(err, ISO_E_LIMIT, "%s: DimSize overflows 64 bits", path);
    for (int a = 0; a < 3; a++) {
        hdr->spacing[a] = m->spacing[a] > 0 ? m->spacing[a] : 1;
        hdr->origin[a] = m->origin[a];
        const double *axis = m->have_matrix ? m->matrix + 3 * a : NULL;
        double norm = axis ? sqrt(axis[0] * axis[0] + axis[1] * axis[1] + axis[2] * axis[2]) : 1;
        if (!(norm > 0) || !isfinite(norm))
            return iso_error_set(err, ISO_E_FORMAT, "%s: TransformMatrix: axis %d has no direction", path, a);
        for (int r = 0; r < 3; r++)
            hdr->direction[r][a] = axis ? axis[r] / norm : r == a;
    }
    hdr->oriented = m->have_matrix;
    if (hdr->byte_skip == -1 && hdr->encoding != ISO_NRRD_RAW)
        return iso_error_set(err, ISO_E_UNSUPPORTED, "%s: HeaderSize -1 works only with uncompressed data", path);
    return 0;
}

/* Reads the header lines up to ElementDataFile. */
static int read_header(const char *path, FILE *f, iso_nrrd_header *hdr, iso_error *err)
{
    mhd m = {0};
    char line[LINE_MAX_BYTES];
    for (int line_no = 1; line_no <= HEADER_MAX_LINES; line_no++) {
        if (!fgets(line, sizeof line, f))
            return iso_error_set(err, ISO_E_FORMAT, "%s: the header ends without ElementDataFile", path);
        size_t n = strlen(line);
        if (n == sizeof line - 1 && line[n - 1] != '\n')
            return iso_error_set(err, ISO_E_FORMAT, "%s:%d: line longer than %d bytes (not a MetaImage header?)",
                                 path, line_no, LINE_MAX_BYTES);
        if (memchr(line, '\0', n) != NULL || strlen(line) != n)
            return iso_error_set(err, ISO_E_FORMAT, "%s:%d: binary bytes in the header", path, line_no);
        while (n && (line[n - 1] == '\n' || line[n - 1] == '\r' || line[n - 1] == ' '))
            line[--n] = '\0';
        if (!n)
            continue;
        char *eq = strchr(line, '=');
        if (!eq)
            return iso_error_set(err, ISO_E_FORMAT, "%s:%d: expected 'Key = Value', not '%.60s'", path, line_no, line);
        char *key_end = eq;
        while (key_end > line && key_end[-1] == ' ')
            key_end--;
        *key_end = '\0';
        char *value = eq + 1;
        while (*value == ' ' || *value == '\t')
            value++;
        int rc = parse_field(path, line_no, line, value, &m, hdr, err);
        if (rc < 0)
            return rc;
        if (rc == 1) {
            if ((rc = data_file(path, line_no, value, ftell(f), hdr, err)))
                return rc;
            return finish(path, &m, hdr, err);
        }
    }
    return iso_error_set(err, ISO_E_FORMAT, "%s: more than %d header lines without ElementDataFile", path,
                         HEADER_MAX_LINES);
}

int iso_metaimage_load(const char *path, const iso_load_options *opt, iso_volume **out,
                       iso_error *err)
{
    assert(path && out);
    *out = NULL;
    FILE *f = fopen(path, "rb");
    if (!f)
        return iso_error_set(err, ISO_E_IO, "%s: cannot open: %s", path, strerror(errno));
    iso_nrrd_header *hdr = calloc(1, sizeof *hdr); /* about 4 KB of path: off the stack */
    int rc = hdr ? read_header(path, f, hdr, err) : iso_error_set(err, ISO_E_NOMEM, "%s: out of memory", path);
    fclose(f);
    if (rc == 0)
        rc = iso_nrrd_load_samples(path, hdr, opt, out, err);
    free(hdr);
    return rc;
}
