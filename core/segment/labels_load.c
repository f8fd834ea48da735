/* labels_load.c: a label map as a segmentation: one segment per distinct non-zero value,
 * named and coloured by an ITK-SNAP label description file when one is given. */
#include "segment.h"

#include <errno.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>


/* The distinct values of vol, ascending, into *values (malloc'd): a run of equal samples
 * costs a compare each, a new value a bisection and an insertion. */
static int distinct_values(const iso_volume *vol, int64_t **values, size_t *count, iso_error *err)
{
    size_t n = iso_vol_count(vol), have = 0, room = 64;
    int64_t *v = malloc(room * sizeof *v);
    if (!v)
        return iso_error_set(err, ISO_E_NOMEM, "out of memory listing the labels");
    double last = NAN;
    for (size_t i = 0; i < n; i++) {
        double sample = iso_vol_sample(vol, i);
        if (sample == last)
            continue;
        last = sample;
        int64_t x = (int64_t)sample;
        size_t lo = 0, hi = have;
        while (lo < hi) {
            size_t mid = lo + (hi - lo) / 2;
            if (v[mid] < x)
                lo = mid + 1;
            else
                hi = mid;
        }
        if (lo < have && v[lo] == x)
            continue;
        if (have == ISO_LABEL_MAX) {
            free(v);
            return iso_error_set(err, ISO_E_UNSUPPORTED,
                                 "more than %u distinct values: not a label map (is it an image?)", ISO_LABEL_MAX);
        }
        if (have == room) {
            int64_t *grown = realloc(v, 2 * room * sizeof *v);
            if (!grown) {
                free(v);
                return iso_error_set(err, ISO_E_NOMEM, "out of memory listing the labels");
            }
            v = grown;
            room *= 2;
        }
        memmove(v + lo + 1, v + lo, (have - lo) * sizeof *v);
        v[lo] = x;
        have++;
    }
    *values = v;
    *count = have;
    return 0;
}

/* ITK-SNAP's label description file: '#' comments, then per line
 *     IDX  R  G  B  A  VIS  MSH  "LABEL"
 * (colours 0..255, A opacity 0..1); or the two-column lists atlases ship (MRIcron's
 * .nii.txt), "IDX NAME", which name without colouring. Applies each line to the segment
 * whose value is IDX. */
static int read_descriptions(const char *path, iso_segmentation *seg, iso_error *err)
{
    FILE *f = fopen(path, "r");
    if (!f)
        return iso_error_set(err, ISO_E_IO, "%s: cannot open: %s", path, strerror(errno));
    char line[1024];
    int rc = 0, line_no = 0;
    while (!rc && fgets(line, sizeof line, f)) {
        line_no++;
        if (!strchr(line, '\n') && !feof(f)) {
            rc = iso_error_set(err, ISO_E_FORMAT, "%s:%d: line longer than %zu bytes", path, line_no, sizeof line - 2);
            break;
        }
        char *p = line;
        while (*p == ' ' || *p == '\t')
            p++;
        if (*p == '#' || *p == '\n' || *p == '\r' || *p == '\0')
            continue;
        long idx, r, g, b, vis, mesh;
        double alpha;
        int used = 0, named = 0;
        if (sscanf(p, "%ld %ld %ld %ld %lf %ld %ld %n", &idx, &r, &g, &b, &alpha, &vis, &mesh, &used) != 7 ||
            p[used] != '"') {
            /* The two-column form: "IDX NAME" (a value and the rest of the line). */
            if (sscanf(p, "%ld %n", &idx, &named) != 1 || named == 0 || p[named] == '\0' || p[named] == '\n' ||
                (p[named] >= '0' && p[named] <= '9') || p[named] == '"') {
                rc = iso_error_set(err, ISO_E_FORMAT, "%s:%d: expected IDX R G B A VIS MSH \"LABEL\" or IDX NAME",
                                   path, line_no);
                break;
            }
            char *name = p + named;
            name[strcspn(name, "\r\n")] = '\0';
            for (size_t s = 0; s < seg->segment_count; s++)
                if (seg->segments[s].value == idx)
                    snprintf(seg->segments[s].name, sizeof seg->segments[s].name, "%s", name);
            continue;
        }
        char *name = p + used + 1, *end = strrchr(name, '"');
        if (!end || idx < 0 || r < 0 || r > 255 || g < 0 || g > 255 || b < 0 || b > 255) {
            rc = iso_error_set(err, ISO_E_FORMAT, "%s:%d: a label index >= 0, colours 0..255 and a quoted label expected",
                               path, line_no);
            break;
        }
        *end = '\0';
        for (size_t s = 0; s < seg->segment_count; s++) {
            iso_segment *sg = &seg->segments[s];
            if (sg->value != idx)
                continue;
            snprintf(sg->name, sizeof sg->name, "%s", name);
            sg->color[0] = (float)r / 255, sg->color[1] = (float)g / 255, sg->color[2] = (float)b / 255;
        }
    }
    if (!rc && ferror(f))
        rc = iso_error_set(err, ISO_E_IO, "%s: cannot read: %s", path, strerror(errno));
    fclose(f);
    return rc;
}

int iso_seg_from_labels(iso_volume *vol, const char *descriptions, iso_segmentation **out, iso_error *err)
{
    *out = NULL;
    if (iso_vol_type_is_float(vol->type)) {
        iso_error_set(err, ISO_E_UNSUPPORTED, "a label map holds integers, not %s samples", iso_vol_type_name(vol->type));
        iso_vol_destroy(vol);
        return ISO_E_UNSUPPORTED;
    }
    iso_segmentation *seg = iso_seg_create(1);
    if (!seg) {
        iso_vol_destroy(vol);
        return iso_error_set(err, ISO_E_NOMEM, "out of memory for a segmentation");
    }
    vol->labels = 1;
    seg->layers[0] = (iso_seg_layer){.vol = vol, .kind = ISO_SEG_LABELS};
    snprintf(seg->source, sizeof seg->source, "labels");
    int64_t *values = NULL;
    size_t count = 0;
    int rc = distinct_values(vol, &values, &count, err);
    for (size_t i = 0; !rc && i < count; i++) {
        if (values[i] == 0)
            continue; /* the background */
        iso_segment sg = {.number = (uint32_t)values[i], .value = values[i]};
        if (values[i] < 0 || values[i] > UINT32_MAX)
            sg.number = (uint32_t)(seg->segment_count + 1);
        snprintf(sg.name, sizeof sg.name, "Segment %lld", (long long)values[i]);
        iso_seg_default_color(seg->segment_count, sg.color);
        rc = iso_seg_add(seg, &sg, err);
    }
    free(values);
    if (!rc && descriptions)
        rc = read_descriptions(descriptions, seg, err);
    if (rc) {
        iso_seg_destroy(seg);
        return rc;
    }
    *out = seg;
    return 0;
}
