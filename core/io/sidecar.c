/* sidecar.c: raw volumes with a JSON sidecar (see sidecar.h). */
#include "sidecar.h"

#include <inttypes.h>
#include <jansson.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <unistd.h>

#include "nrrd.h"

static const struct {
    const char *name;
    iso_voxel_type type;
} type_names[] = {
    {"uint8", ISO_U8}, {"int8", ISO_I8}, {"uint16", ISO_U16}, {"int16", ISO_I16},
    {"uint32", ISO_U32}, {"int32", ISO_I32}, {"float32", ISO_F32}, {"float64", ISO_F64},
};

/* "PATH.json" into buf; 0, or -1 when it does not fit. */
static int sidecar_path(const char *path, char *buf, size_t size)
{
    int n = snprintf(buf, size, "%s.json", path);
    return n < 0 || (size_t)n >= size ? -1 : 0;
}

static int has_sidecar(const char *path)
{
    char side[4096];
    size_t n = strlen(path);
    if (n > 5 && !strcmp(path + n - 5, ".json"))
        return 0; /* a sidecar is not a volume */
    return sidecar_path(path, side, sizeof side) == 0 && access(side, R_OK) == 0;
}

int iso_sidecar_recognises(const char *path)
{
    return has_sidecar(path);
}

/* Three finite numbers from a JSON array, or the default when absent. */
static int triple(const char *side, json_t *root, const char *key, double out[3], iso_error *err)
{
    json_t *a = json_object_get(root, key);
    if (!a)
        return 0;
    if (!json_is_array(a) || json_array_size(a) != 3)
        return iso_error_set(err, ISO_E_FORMAT, "%s: \"%s\" must be an array of three numbers", side, key);
    for (size_t i = 0; i < 3; i++) {
        json_t *v = json_array_get(a, i);
        if (!json_is_number(v) || !isfinite(json_number_value(v)))
            return iso_error_set(err, ISO_E_FORMAT, "%s: \"%s\"[%zu] is not a finite number", side, key, i);
        out[i] = json_number_value(v);
    }
    return 0;
}

static int read_type(const char *side, json_t *root, iso_nrrd_header *hdr, iso_error *err)
{
    const char *type = json_string_value(json_object_get(root, "type"));
    if (!type)
        return iso_error_set(err, ISO_E_FORMAT, "%s: \"type\" is required (uint8, int16, uint16, float32, ...)", side);
    for (size_t i = 0; i < sizeof type_names / sizeof type_names[0]; i++)
        if (!strcmp(type, type_names[i].name)) {
            hdr->type = type_names[i].type;
            return 0;
        }
    return iso_error_set(err, ISO_E_UNSUPPORTED, "%s: \"type\": '%s' is not uint8, int8, uint16, int16, uint32, int32, float32 or float64",
                         side, type);
}

static int read_layout(const char *side, json_t *root, iso_nrrd_header *hdr, iso_error *err)
{
    double dims[3] = {0, 0, 0};
    if (!json_object_get(root, "dims"))
        return iso_error_set(err, ISO_E_FORMAT, "%s: \"dims\" is required", side);
    int rc = triple(side, root, "dims", dims, err);
    for (int a = 0; a < 3 && !rc; a++) {
        if (dims[a] < 2 || dims[a] != floor(dims[a]) || dims[a] > 1e9)
            return iso_error_set(err, ISO_E_FORMAT, "%s: \"dims\"[%d] = %g is not a size of at least 2", side, a, dims[a]);
        hdr->dims[a] = (size_t)dims[a];
    }
    if (rc || (rc = read_type(side, root, hdr, err)))
        return rc;
    if (iso_vol_check_size(hdr->dims, hdr->type, UINT64_MAX, &hdr->data_bytes, NULL))
        return iso_error_set(err, ISO_E_LIMIT, "%s: \"dims\" overflow 64 bits", side);
    const char *endian = json_string_value(json_object_get(root, "endian"));
    if (!endian && iso_vol_type_size(hdr->type) > 1)
        return iso_error_set(err, ISO_E_FORMAT, "%s: \"endian\" (\"little\" or \"big\") is required for %s",
                             side, json_string_value(json_object_get(root, "type")));
    if (endian && strcmp(endian, "little") && strcmp(endian, "big"))
        return iso_error_set(err, ISO_E_FORMAT, "%s: \"endian\" must be \"little\" or \"big\", not '%s'", side, endian);
    hdr->big_endian = endian && !strcmp(endian, "big");
    const char *compression = json_string_value(json_object_get(root, "compression"));
    if (compression && strcmp(compression, "none") && strcmp(compression, "gzip") && strcmp(compression, "zlib"))
        return iso_error_set(err, ISO_E_UNSUPPORTED, "%s: \"compression\" must be none, gzip or zlib, not '%s'",
                             side, compression);
    hdr->encoding = compression && strcmp(compression, "none") ? ISO_NRRD_GZIP : ISO_NRRD_RAW;
    json_t *skip = json_object_get(root, "header_bytes");
    if (skip && (!json_is_integer(skip) || json_integer_value(skip) < 0))
        return iso_error_set(err, ISO_E_FORMAT, "%s: \"header_bytes\" must be a whole number >= 0", side);
    hdr->byte_skip = skip ? (int64_t)json_integer_value(skip) : 0;
    return 0;
}

static int read_geometry(const char *side, json_t *root, iso_nrrd_header *hdr, iso_error *err)
{
    double spacing[3] = {1, 1, 1};
    int rc = triple(side, root, "spacing", spacing, err);
    if (!rc)
        rc = triple(side, root, "origin", hdr->origin, err);
    for (int a = 0; a < 3 && !rc; a++) {
        if (!(spacing[a] > 0))
            return iso_error_set(err, ISO_E_FORMAT, "%s: \"spacing\"[%d] = %g must be positive", side, a, spacing[a]);
        hdr->spacing[a] = spacing[a];
        hdr->direction[a][a] = 1;
    }
    json_t *dir = json_object_get(root, "direction");
    if (rc || !dir)
        return rc;
    if (!json_is_array(dir) || json_array_size(dir) != 3)
        return iso_error_set(err, ISO_E_FORMAT, "%s: \"direction\" must be three rows of three numbers", side);
    for (size_t r = 0; r < 3; r++) {
        json_t *row = json_array_get(dir, r);
        for (size_t c = 0; c < 3; c++) {
            json_t *v = json_array_get(row, c);
            if (!json_is_array(row) || json_array_size(row) != 3 || !json_is_number(v))
                return iso_error_set(err, ISO_E_FORMAT, "%s: \"direction\" must be three rows of three numbers", side);
            hdr->direction[r][c] = json_number_value(v);
        }
    }
    for (int c = 0; c < 3; c++) {
        double n = sqrt(hdr->direction[0][c] * hdr->direction[0][c] + hdr->direction[1][c] * hdr->direction[1][c] +
                        hdr->direction[2][c] * hdr->direction[2][c]);
        if (!(n > 0) || !isfinite(n))
            return iso_error_set(err, ISO_E_FORMAT, "%s: \"direction\" column %d is zero", side, c);
        for (int r = 0; r < 3; r++)
            hdr->direction[r][c] /= n;
    }
    hdr->oriented = 1;
    return 0;
}

/* Raw samples after "header_bytes" bytes: a skip past the end of the file is said as such
 * (a seek there fails with a bare EINVAL, or lands nowhere). Compressed data skips that
 * many inflated bytes, which the file's size does not bound: the inflater says how many
 * came out. */
static int check_header_bytes(const char *side, const char *path, const iso_nrrd_header *hdr,
                              iso_error *err)
{
    struct stat st;
    if (hdr->encoding != ISO_NRRD_RAW || hdr->byte_skip <= 0 || stat(path, &st) ||
        !S_ISREG(st.st_mode) || (uint64_t)hdr->byte_skip <= (uint64_t)st.st_size)
        return 0;
    return iso_error_set(err, ISO_E_TRUNCATED, "%s: \"header_bytes\" is %" PRId64 ", past the end "
                         "of %s (%" PRIdMAX " bytes)", side, hdr->byte_skip, path, (intmax_t)st.st_size);
}

int iso_sidecar_load(const char *path, const iso_load_options *opt, iso_volume **out, iso_error *err)
{
    char side[4096];
    if (sidecar_path(path, side, sizeof side))
        return iso_error_set(err, ISO_E_FORMAT, "%s: path too long", path);
    json_error_t jerr;
    json_t *root = json_load_file(side, JSON_REJECT_DUPLICATES, &jerr);
    if (!root)
        return iso_error_set(err, ISO_E_FORMAT, "%s:%d:%d: %s", side, jerr.line, jerr.column, jerr.text);
    iso_nrrd_header *hdr = calloc(1, sizeof *hdr);
    int rc = !hdr ? iso_error_set(err, ISO_E_NOMEM, "%s: out of memory", side)
             : !json_is_object(root) ? iso_error_set(err, ISO_E_FORMAT, "%s: not a JSON object", side)
                                     : read_layout(side, root, hdr, err);
    if (!rc)
        rc = read_geometry(side, root, hdr, err);
    json_decref(root);
    if (!rc)
        rc = check_header_bytes(side, path, hdr, err);
    if (!rc && strlen(path) >= sizeof hdr->data_path)
        rc = iso_error_set(err, ISO_E_FORMAT, "%s: path too long", path);
    if (!rc) {
        snprintf(hdr->data_path, sizeof hdr->data_path, "%s", path);
        rc = iso_nrrd_load_samples(path, hdr, opt, out, err);
    }
    free(hdr);
    return rc;
}
