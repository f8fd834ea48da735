/* seg_nrrd.c: 3D Slicer's segmentation file (.seg.nrrd): a label map NRRD, 4-D with one
 * layer per slice of its first axis where segments overlap, whose header's key:=value
 * pairs describe each segment:
 *     Segment<i>_ID:=...   Segment<i>_Name:=liver   Segment<i>_Color:=0.86 0.46 0.39
 *     Segment<i>_LabelValue:=1   Segment<i>_Layer:=0
 * Segment i gets number i + 1. Files written before Slicer 4.11 have no LabelValue and
 * Layer: one layer per segment, its voxels 1. */
#include "segment.h"

#include <errno.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <strings.h>

#include "io/nrrd.h"

int iso_seg_nrrd_recognises(const char *path)
{
    size_t n = strlen(path), m = strlen(".seg.nrrd");
    return n > m && strcasecmp(path + n - m, ".seg.nrrd") == 0;
}

/* What the keys said about segment i; -1 where a key was absent. */
typedef struct described {
    char name[ISO_SEG_NAME_MAX];
    float color[3];
    int has_color, has_name;
    long long value, layer;
} described;

typedef struct keys {
    described *items;
    size_t count;    /* 1 + the highest index seen */
} keys;

static int grow(keys *k, size_t index, iso_error *err, const char *path)
{
    if (index >= ISO_SEG_MAX)
        return iso_error_set(err, ISO_E_LIMIT, "%s: segment index %zu past %u", path, index, ISO_SEG_MAX);
    if (index < k->count)
        return 0;
    described *grown = realloc(k->items, (index + 1) * sizeof *grown);
    if (!grown)
        return iso_error_set(err, ISO_E_NOMEM, "%s: out of memory", path);
    for (size_t i = k->count; i <= index; i++)
        grown[i] = (described){.value = -1, .layer = -1};
    k->items = grown;
    k->count = index + 1;
    return 0;
}

/* One "Segment<i>_<Field>:=value" line; other lines are not ours. */
static int parse_key(keys *k, const char *line, int line_no, const char *path, iso_error *err)
{
    unsigned long index;
    int used = 0;
    if (sscanf(line, "Segment%lu_%n", &index, &used) != 1 || used == 0)
        return 0;
    const char *field = line + used, *eq = strstr(field, ":=");
    if (!eq)
        return 0;
    const char *value = eq + 2;
    size_t field_len = (size_t)(eq - field);
#define IS(name) (field_len == sizeof name - 1 && !strncmp(field, name, field_len))
    if (!IS("Name") && !IS("Color") && !IS("LabelValue") && !IS("Layer"))
        return 0;
    int rc = grow(k, index, err, path);
    if (rc)
        return rc;
    described *d = &k->items[index];
    if (IS("Name")) {
        snprintf(d->name, sizeof d->name, "%s", value);
        d->has_name = 1;
    } else if (IS("Color")) {
        if (sscanf(value, "%f %f %f", &d->color[0], &d->color[1], &d->color[2]) != 3)
            return iso_error_set(err, ISO_E_FORMAT, "%s:%d: Segment%lu_Color is not three numbers", path, line_no, index);
        for (int c = 0; c < 3; c++)
            d->color[c] = d->color[c] < 0 ? 0 : d->color[c] > 1 ? 1 : d->color[c];
        d->has_color = 1;
    } else {
        long long v;
        char tail;
        if (sscanf(value, "%lld %c", &v, &tail) != 1 || v < 0)
            return iso_error_set(err, ISO_E_FORMAT, "%s:%d: Segment%lu_%.*s is not an integer >= 0", path, line_no,
                                 index, (int)field_len, field);
        if (IS("LabelValue"))
            d->value = v;
        else
            d->layer = v;
    }
#undef IS
    return 0;
}

/* The header's key:=value lines (up to the blank line that ends an attached header). */
static int read_keys(const char *path, keys *k, iso_error *err)
{
    FILE *f = fopen(path, "rb");
    if (!f)
        return iso_error_set(err, ISO_E_IO, "%s: cannot open: %s", path, strerror(errno));
    char *line = malloc(ISO_NRRD_MAX_LINE + 2);
    int rc = line ? 0 : iso_error_set(err, ISO_E_NOMEM, "%s: out of memory", path), line_no = 0;
    while (!rc && fgets(line, ISO_NRRD_MAX_LINE + 2, f)) {
        line_no++;
        size_t n = strcspn(line, "\r\n");
        if (n == 0)
            break;
        line[n] = '\0';
        rc = parse_key(k, line, line_no, path, err);
    }
    free(line);
    fclose(f);
    return rc;
}

/* The layers, split from the interleaved volume (value fastest). */
static int split_layers(iso_volume *wide, const iso_nrrd_header *hdr, iso_segmentation *seg, iso_error *err,
                        const char *path)
{
    size_t layers = hdr->components, size = iso_vol_type_size(hdr->type);
    size_t count = hdr->dims[0] * hdr->dims[1] * hdr->dims[2];
    for (size_t l = 0; l < layers; l++) {
        iso_volume *vol = layers == 1 ? wide : iso_vol_create(hdr->dims, hdr->type, 0, err);
        if (!vol)
            return err ? err->code : ISO_E_NOMEM;
        if (layers > 1) {
            const unsigned char *from = (const unsigned char *)wide->data + l * size;
            unsigned char *to = vol->data;
            for (size_t i = 0; i < count; i++)
                memcpy(to + i * size, from + i * layers * size, size);
        }
        memcpy(vol->spacing, hdr->spacing, sizeof vol->spacing);
        memcpy(vol->origin, hdr->origin, sizeof vol->origin);
        memcpy(vol->direction, hdr->direction, sizeof vol->direction);
        vol->labels = 1;
        iso_vol_update_stats(vol);
        seg->layers[l] = (iso_seg_layer){.vol = vol, .kind = ISO_SEG_LABELS};
    }
    (void)path;
    return 0;
}

int iso_seg_nrrd_load(const char *path, const iso_load_options *opt, iso_segmentation **out, iso_error *err)
{
    *out = NULL;
    iso_nrrd_header *hdr = malloc(sizeof *hdr);
    if (!hdr)
        return iso_error_set(err, ISO_E_NOMEM, "%s: out of memory", path);
    keys k = {0};
    iso_volume *wide = NULL;
    iso_segmentation *seg = NULL;
    int rc = iso_nrrd_read_header(path, hdr, err);
    if (!rc && iso_vol_type_is_float(hdr->type))
        rc = iso_error_set(err, ISO_E_UNSUPPORTED, "%s: a segmentation holds integers, not %s samples", path,
                           iso_vol_type_name(hdr->type));
    if (!rc)
        rc = read_keys(path, &k, err);
    if (!rc && k.count == 0)
        rc = iso_error_set(err, ISO_E_FORMAT, "%s: no Segment<i>_... keys in the header: not a 3D Slicer segmentation",
                           path);
    if (!rc)
        rc = iso_nrrd_load_samples(path, hdr, opt, &wide, err);
    if (!rc && !(seg = iso_seg_create(hdr->components)))
        rc = iso_error_set(err, ISO_E_NOMEM, "%s: out of memory", path);
    if (!rc) {
        snprintf(seg->source, sizeof seg->source, "seg.nrrd");
        rc = split_layers(wide, hdr, seg, err, path);
        if (hdr->components == 1)
            wide = NULL; /* layer 0 now */
    }
    /* Pre-4.11 files: a layer per segment, no values. */
    int per_layer = k.count == hdr->components && hdr->components > 1;
    for (size_t i = 0; !rc && i < k.count; i++) {
        described *d = &k.items[i];
        iso_segment sg = {.number = (uint32_t)(i + 1)};
        sg.value = d->value >= 0 ? d->value : per_layer ? 1 : (long long)(i + 1);
        sg.layer = (uint32_t)(d->layer >= 0 ? d->layer : per_layer ? (long long)i : 0);
        if (sg.layer >= hdr->components) {
            rc = iso_error_set(err, ISO_E_FORMAT, "%s: Segment%zu_Layer is %u, the file has %zu layer(s)", path, i,
                               sg.layer, hdr->components);
            break;
        }
        if (d->has_name)
            snprintf(sg.name, sizeof sg.name, "%s", d->name);
        else
            snprintf(sg.name, sizeof sg.name, "Segment_%zu", i + 1);
        if (d->has_color)
            memcpy(sg.color, d->color, sizeof sg.color);
        else
            iso_seg_default_color(i, sg.color);
        rc = iso_seg_add(seg, &sg, err);
    }
    iso_vol_destroy(wide);
    free(k.items);
    free(hdr);
    if (rc) {
        iso_seg_destroy(seg);
        return rc;
    }
    *out = seg;
    return 0;
}
