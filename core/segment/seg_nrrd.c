/* seg_nrrd.c: 3D Slicer's segmentation file (.seg.nrrd): a label map NRRD, 4-D with one
 * layer per slice of its first axis where segments overlap, whose header's key:=value
 * pairs describe each segment:
 *     Segment<i>_ID:=...   Segment<i>_Name:=liver   Segment<i>_Color:=0.86 0.46 0.39
 *     Segment<i>_LabelValue:=1   Segment<i>_Layer:=0
 * Segment i gets number i + 1. Files written before Slicer 4.11 have no LabelValue and
 * Layer: one layer per segment, its voxels 1. */
#include "segment.h"

#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <strings.h>


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

/* What parse_key needs besides the pair. */
typedef struct key_reader {
    keys *k;
    const char *path;
} key_reader;

/* One "Segment<i>_<Field>:=value" pair; other pairs are not ours. */
static int parse_key(void *context, const char *key, const char *value, int line_no, iso_error *err)
{
    key_reader *r = context;
    keys *k = r->k;
    const char *path = r->path;
    unsigned long index;
    int used = 0;
    if (sscanf(key, "Segment%lu_%n", &index, &used) != 1 || used == 0)
        return 0;
    const char *field = key + used;
    size_t field_len = strlen(field);
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

int iso_seg_nrrd_load(const char *path, const iso_load_options *opt, iso_segmentation **out, iso_error *err)
{
    *out = NULL;
    keys k = {0};
    key_reader reader = {&k, path};
    iso_volume **layers = NULL;
    size_t layer_count = 0;
    iso_segmentation *seg = NULL;
    int rc = iso_nrrd_key_values(path, parse_key, &reader, err);
    if (!rc && k.count == 0)
        rc = iso_error_set(err, ISO_E_FORMAT, "%s: no Segment<i>_... keys in the header: not a 3D Slicer segmentation",
                           path);
    if (!rc)
        rc = iso_nrrd_load_layers(path, opt, &layers, &layer_count, err);
    if (!rc && iso_vol_type_is_float(layers[0]->type))
        rc = iso_error_set(err, ISO_E_UNSUPPORTED, "%s: a segmentation holds integers, not %s samples", path,
                           iso_vol_type_name(layers[0]->type));
    if (!rc && !(seg = iso_seg_create(layer_count)))
        rc = iso_error_set(err, ISO_E_NOMEM, "%s: out of memory", path);
    for (size_t l = 0; l < layer_count; l++) {
        if (seg) {
            layers[l]->labels = 1;
            seg->layers[l] = (iso_seg_layer){.vol = layers[l], .kind = ISO_SEG_LABELS};
        } else {
            iso_vol_destroy(layers[l]);
        }
    }
    free(layers);
    if (seg)
        snprintf(seg->source, sizeof seg->source, "seg.nrrd");
    /* Pre-4.11 files: a layer per segment, no values. */
    int per_layer = k.count == layer_count && layer_count > 1;
    for (size_t i = 0; !rc && i < k.count; i++) {
        described *d = &k.items[i];
        iso_segment sg = {.number = (uint32_t)(i + 1)};
        sg.value = d->value >= 0 ? d->value : per_layer ? 1 : (long long)(i + 1);
        sg.layer = (uint32_t)(d->layer >= 0 ? d->layer : per_layer ? (long long)i : 0);
        if (sg.layer >= layer_count) {
            rc = iso_error_set(err, ISO_E_FORMAT, "%s: Segment%zu_Layer is %u, the file has %zu layer(s)", path, i,
                               sg.layer, layer_count);
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
    free(k.items);
    if (rc) {
        iso_seg_destroy(seg);
        return rc;
    }
    *out = seg;
    return 0;
}
