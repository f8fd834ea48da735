/* dicom_seg.c: a DICOM Segmentation object as a segmentation (segment.h), on the grid of
 * the image series it references, in passes:
 *
 * PASS 1 (find): the SEG file: FILE.dcm, or the one SEG series in DIR (DIR#UID names one
 *   of several); its directory must hold the series it was derived from (Referenced Series
 *   Sequence), a CT or MR series.
 * PASS 2 (read): the object through GDCM's dataset API (io/dicom_gdcm.h): segments,
 *   frames, shared geometry, pixel data; the referenced series' geometry without its
 *   pixels (iso_dicom_geometry).
 * PASS 3 (place): each frame on a slice of that grid: its rows, columns, pixel spacing and
 *   orientation must be the series', its Image Position (Patient) a slice's first pixel
 *   (within 1% of a voxel); frames may be sparse (slices without the segment are absent).
 * PASS 4 (fill): BINARY frames (1 bit per pixel, packed across frames) into label maps,
 *   each pixel set taking its segment's number; segments that overlap go to layers of
 *   their own (a greedy colouring of the overlap graph, found in a first pass over the
 *   frames); FRACTIONAL frames into one fractional layer per segment (values 0..Maximum
 *   Fractional Value); LABELMAP frames (pixel = segment number) into one label map, where
 *   two frames giving one voxel two segments is an error.
 * Every inconsistency is an error naming the file, the frame and what is wrong; nothing
 * is guessed. */
#include "segment.h"

#include <dirent.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <strings.h>
#include <sys/stat.h>


#define MAX_FRAMES 1000000u

static int is_segmentation(const char *sop_class)
{
    return !strcmp(sop_class, ISO_GDCM_SEG_SOP_CLASS) || !strcmp(sop_class, ISO_GDCM_SEG_LABELMAP_SOP_CLASS);
}

/* Splits "DIR#UID" (or a file) into the directory, the file (or ""), the wanted UID. */
static int split(const char *path, char *dir, size_t dir_size, char *file, size_t file_size, char *uid,
                 size_t uid_size)
{
    char source[4096];
    const char *hash = strrchr(path, '#');
    size_t n = hash ? (size_t)(hash - path) : strlen(path);
    if (n == 0 || n >= sizeof source)
        return -1;
    memcpy(source, path, n);
    source[n] = '\0';
    snprintf(uid, uid_size, "%s", hash ? hash + 1 : "");
    struct stat st;
    if (stat(source, &st))
        return -1;
    if (S_ISDIR(st.st_mode)) {
        snprintf(dir, dir_size, "%s", source);
        file[0] = '\0';
        return 0;
    }
    snprintf(file, file_size, "%s", source);
    const char *slash = strrchr(source, '/');
    snprintf(dir, dir_size, "%.*s", slash ? (int)(slash - source) : 1, slash ? source : ".");
    return 0;
}

/* PASS 1 in a directory: the one SEG file of the wanted series (any, when uid is ""). */
static int find_seg_file(const char *path, const char *dir, const char *uid, char *file, size_t size, iso_error *err)
{
    DIR *d = opendir(dir);
    if (!d)
        return iso_error_set(err, ISO_E_IO, "%s: cannot open the directory", dir);
    struct dirent *ent;
    int found = 0, rc = 0;
    char first_uid[80] = "";
    while (!rc && (ent = readdir(d))) {
        if (ent->d_name[0] == '.')
            continue;
        char candidate[4096], sop[80], series[80], why[256] = "";
        snprintf(candidate, sizeof candidate, "%s/%s", dir, ent->d_name);
        struct stat st;
        if (stat(candidate, &st) || !S_ISREG(st.st_mode) ||
            iso_gdcm_seg_probe(candidate, sop, sizeof sop, series, sizeof series, why, sizeof why) != 0 ||
            !is_segmentation(sop) || (*uid && strcmp(uid, series)))
            continue;
        if (found && strcmp(first_uid, series))
            rc = iso_error_set(err, ISO_E_FORMAT, "%s: several segmentation series (%s, %s); name one as %s#SeriesInstanceUID",
                               path, first_uid, series, dir);
        else if (found)
            rc = iso_error_set(err, ISO_E_UNSUPPORTED, "%s: segmentation series %s has several instances (%s, %s); name one file",
                               path, series, file, candidate);
        snprintf(file, size, "%s", candidate);
        snprintf(first_uid, sizeof first_uid, "%s", series);
        found = 1;
    }
    closedir(d);
    if (!rc && !found)
        rc = iso_error_set(err, ISO_E_UNSUPPORTED, "%s: no DICOM Segmentation%s%s here", path, *uid ? " of series " : "", uid);
    return rc;
}

int iso_seg_dicom_referenced_series(const char *dir, char *uid, size_t size, iso_error *err)
{
    char file[4096], why[400] = "";
    int rc = find_seg_file(dir, dir, "", file, sizeof file, err);
    if (rc)
        return rc;
    iso_gdcm_seg s;
    if (iso_gdcm_seg_read(file, MAX_FRAMES, &s, why, sizeof why))
        return iso_error_set(err, ISO_E_FORMAT, "%s: %s", file, why);
    snprintf(uid, size, "%s", s.referenced_series);
    iso_gdcm_seg_free(&s);
    if (!uid[0])
        return iso_error_set(err, ISO_E_FORMAT, "%s: no Referenced Series Sequence: which images does it segment?", file);
    return 0;
}

int iso_seg_dicom_recognises(const char *path)
{
    char dir[4096], file[4096], uid[128];
    if (split(path, dir, sizeof dir, file, sizeof file, uid, sizeof uid))
        return 0;
    if (file[0]) {
        char sop[80], series[80], why[256];
        return iso_gdcm_seg_probe(file, sop, sizeof sop, series, sizeof series, why, sizeof why) == 0 &&
               is_segmentation(sop);
    }
    char found[4096];
    return find_seg_file(path, dir, uid, found, sizeof found, NULL) == 0;
}

/* The grid the SEG is placed on: the referenced series' geometry, and its inverse map. */
typedef struct grid {
    iso_volume shape;
    double inverse[3][3];   /* world direction to index, per unit of world offset */
} grid;

/* PASS 2's checks of the plane geometry against the grid. */
static int check_planes(const char *file, const iso_gdcm_seg *s, const grid *g, iso_error *err)
{
    const iso_volume *v = &g->shape;
    if (s->columns != v->dims[0] || s->rows != v->dims[1])
        return iso_error_set(err, ISO_E_FORMAT, "%s: frames of %ux%u pixels do not match the referenced series' %zux%zu",
                             file, s->columns, s->rows, v->dims[0], v->dims[1]);
    if (s->pixel_spacing[0] > 0 && (fabs(s->pixel_spacing[0] - v->spacing[1]) > 1e-3 * v->spacing[1] ||
                                    fabs(s->pixel_spacing[1] - v->spacing[0]) > 1e-3 * v->spacing[0]))
        return iso_error_set(err, ISO_E_FORMAT, "%s: Pixel Spacing %g\\%g does not match the referenced series' %g\\%g",
                             file, s->pixel_spacing[0], s->pixel_spacing[1], v->spacing[1], v->spacing[0]);
    if (s->has_orientation)
        for (int r = 0; r < 3; r++)
            if (fabs(s->orientation[r] - v->direction[r][0]) > 1e-4 || fabs(s->orientation[3 + r] - v->direction[r][1]) > 1e-4)
                return iso_error_set(err, ISO_E_FORMAT,
                                     "%s: Image Orientation (Patient) %g\\%g\\%g\\%g\\%g\\%g does not match the referenced series'",
                                     file, s->orientation[0], s->orientation[1], s->orientation[2], s->orientation[3],
                                     s->orientation[4], s->orientation[5]);
    return 0;
}

/* PASS 3: frame f's slice. */
static int place_frame(const char *file, const iso_gdcm_seg *s, const grid *g, unsigned f, size_t *slice,
                       iso_error *err)
{
    const iso_gdcm_seg_frame *fr = &s->frame[f];
    if (!fr->has_position)
        return iso_error_set(err, ISO_E_FORMAT, "%s: frame %u has no Plane Position (Image Position (Patient))", file, f + 1);
    double offset[3], index[3];
    for (int r = 0; r < 3; r++)
        offset[r] = fr->position[r] - g->shape.origin[r];
    for (int r = 0; r < 3; r++)
        index[r] = g->inverse[r][0] * offset[0] + g->inverse[r][1] * offset[1] + g->inverse[r][2] * offset[2];
    double k = round(index[2]);
    if (fabs(index[0]) > 0.01 || fabs(index[1]) > 0.01 || fabs(index[2] - k) > 0.01 || k < 0 ||
        k >= (double)g->shape.dims[2])
        return iso_error_set(err, ISO_E_FORMAT,
                             "%s: frame %u at (%g, %g, %g) mm lies on no slice of the referenced series (index %.3f, %.3f, %.3f)",
                             file, f + 1, fr->position[0], fr->position[1], fr->position[2], index[0], index[1], index[2]);
    *slice = (size_t)k;
    return 0;
}

/* The segment table entry of Segment Number n, or -1. */
static long segment_of(const iso_gdcm_seg *s, unsigned n)
{
    for (unsigned i = 0; i < s->segment_count; i++)
        if (s->segments[i].number == n)
            return (long)i;
    return -1;
}

/* Pixel p of frame f, as stored: a bit (BINARY, packed across frames) or a byte/word. */
static unsigned pixel(const iso_gdcm_seg *s, size_t frame_pixels, unsigned f, size_t p)
{
    size_t at = (size_t)f * frame_pixels + p;
    if (s->bits_allocated == 1)
        return s->pixels[at / 8] >> (at % 8) & 1;
    if (s->bits_allocated == 16)
        return (unsigned)s->pixels[2 * at] | (unsigned)s->pixels[2 * at + 1] << 8;
    return s->pixels[at];
}

/* Frames, pixel data and segments hold together: every frame is there and names a segment. */
static int check_frames(const char *file, iso_gdcm_seg *s, int labelmap, iso_error *err)
{
    size_t frame_pixels = (size_t)s->rows * s->columns, total = frame_pixels * s->frames;
    if (s->bits_allocated != 1 && s->bits_allocated != 8 && s->bits_allocated != 16)
        return iso_error_set(err, ISO_E_UNSUPPORTED, "%s: %u bits per pixel (a SEG has 1, 8 or 16)", file, s->bits_allocated);
    if (s->bits_allocated == 1 && s->pixel_bytes == total) /* GDCM unpacked encapsulated bits to bytes */
        s->bits_allocated = 8;
    size_t need = s->bits_allocated == 1 ? (total + 7) / 8 : total * (s->bits_allocated / 8);
    if (s->pixel_bytes < need)
        return iso_error_set(err, ISO_E_TRUNCATED,
                             "%s: the pixel data holds %zu bytes; %u frames of %ux%u at %u bits need %zu (missing frames?)",
                             file, s->pixel_bytes, s->frames, s->columns, s->rows, s->bits_allocated, need);
    if (s->per_frame_items < s->frames)
        return iso_error_set(err, ISO_E_FORMAT, "%s: the Per-frame Functional Groups have %u items for %u frames", file,
                             s->per_frame_items, s->frames);
    for (unsigned i = 0; i < s->segment_count; i++) {
        if (s->segments[i].number == 0 || s->segments[i].number > ISO_SEG_MAX)
            return iso_error_set(err, ISO_E_FORMAT, "%s: Segment Number %u out of range 1..%u", file, s->segments[i].number,
                                 ISO_SEG_MAX);
        if (segment_of(s, s->segments[i].number) != (long)i)
            return iso_error_set(err, ISO_E_FORMAT, "%s: Segment Number %u is given twice", file, s->segments[i].number);
    }
    for (unsigned f = 0; f < s->frames && !labelmap; f++)
        if (segment_of(s, s->frame[f].segment) < 0)
            return iso_error_set(err, ISO_E_FORMAT,
                                 "%s: frame %u refers to segment %u, which the Segment Sequence (%u segments) does not hold",
                                 file, f + 1, s->frame[f].segment, s->segment_count);
    return 0;
}

/* The table: a segment per item, named by its label, coloured by its CIELab. */
static int add_segments(iso_segmentation *seg, const iso_gdcm_seg *s, const unsigned *layer_of, iso_error *err)
{
    for (unsigned i = 0; i < s->segment_count; i++) {
        const iso_gdcm_seg_segment *d = &s->segments[i];
        iso_segment sg = {.number = d->number, .value = d->number, .layer = layer_of ? layer_of[i] : 0};
        snprintf(sg.name, sizeof sg.name, "%s", d->label[0] ? d->label : "Segment");
        if (!d->label[0])
            snprintf(sg.name, sizeof sg.name, "Segment %u", d->number);
        snprintf(sg.category, sizeof sg.category, "%s", d->category);
        snprintf(sg.type, sizeof sg.type, "%s", d->type);
        if (d->has_lab)
            iso_seg_lab_to_srgb(d->lab, sg.color);
        else
            iso_seg_default_color(i, sg.color);
        if (!strcmp(s->type, "FRACTIONAL"))
            sg.value = 0;
        int rc = iso_seg_add(seg, &sg, err);
        if (rc)
            return rc;
    }
    return 0;
}

/* A layer on the grid, its voxels zero. */
static iso_volume *layer_volume(const grid *g, iso_voxel_type type, const iso_load_options *opt, iso_error *err)
{
    iso_volume *v = iso_vol_create(g->shape.dims, type, opt ? opt->max_bytes : 0, err);
    if (!v)
        return NULL;
    memcpy(v->spacing, g->shape.spacing, sizeof v->spacing);
    memcpy(v->origin, g->shape.origin, sizeof v->origin);
    memcpy(v->direction, g->shape.direction, sizeof v->direction);
    return v;
}

/* PASS 4 for BINARY: the overlap graph (a first pass writing the first segment of each
 * voxel), each segment's layer by greedy colouring, then the layers. */
static int fill_binary(const char *file, const iso_gdcm_seg *s, const size_t *slice, const grid *g,
                       const iso_load_options *opt, iso_segmentation **out, iso_error *err)
{
    const size_t frame_pixels = (size_t)s->rows * s->columns, n = s->segment_count;
    iso_voxel_type type = n <= 255 ? ISO_U8 : ISO_U16;
    iso_volume *first = layer_volume(g, type, opt, err);
    unsigned char *overlap = calloc(n * n, 1);
    unsigned *layer_of = calloc(n, sizeof *layer_of);
    int rc = first && overlap && layer_of ? 0 : iso_error_set(err, ISO_E_NOMEM, "%s: out of memory", file);
    for (unsigned f = 0; !rc && f < s->frames; f++) {
        unsigned a = (unsigned)segment_of(s, s->frame[f].segment) + 1;
        size_t base = slice[f] * frame_pixels;
        for (size_t p = 0; p < frame_pixels; p++) {
            if (!pixel(s, frame_pixels, f, p))
                continue;
            unsigned held = (unsigned)iso_vol_sample(first, base + p);
            if (!held && type == ISO_U8)
                ((uint8_t *)first->data)[base + p] = (uint8_t)a;
            else if (!held)
                ((uint16_t *)first->data)[base + p] = (uint16_t)a;
            else if (held != a)
                overlap[(held - 1) * n + (a - 1)] = overlap[(a - 1) * n + (held - 1)] = 1;
        }
    }
    unsigned layers = 0;
    for (size_t i = 0; !rc && i < n; i++) {
        unsigned l = 0;
        for (int taken = 1; taken; l += taken) {
            taken = 0;
            for (size_t j = 0; j < i && !taken; j++)
                taken = overlap[i * n + j] && layer_of[j] == l;
        }
        layer_of[i] = l;
        layers = l + 1 > layers ? l + 1 : layers;
    }
    iso_segmentation *seg = rc ? NULL : iso_seg_create(layers);
    if (!rc && !seg)
        rc = iso_error_set(err, ISO_E_NOMEM, "%s: out of memory", file);
    for (unsigned l = 0; !rc && l < layers; l++) {
        /* Without overlaps the first pass's map is the one layer. */
        iso_volume *v = layers == 1 ? first : layer_volume(g, type, opt, err);
        if (!v) {
            rc = err ? err->code : ISO_E_NOMEM;
            break;
        }
        if (v == first)
            first = NULL;
        v->labels = 1;
        seg->layers[l] = (iso_seg_layer){.vol = v, .kind = ISO_SEG_LABELS};
    }
    for (unsigned f = 0; !rc && layers > 1 && f < s->frames; f++) {
        size_t i = (size_t)segment_of(s, s->frame[f].segment), base = slice[f] * frame_pixels;
        iso_volume *v = seg->layers[layer_of[i]].vol;
        for (size_t p = 0; p < frame_pixels; p++) {
            if (!pixel(s, frame_pixels, f, p))
                continue;
            if (type == ISO_U8)
                ((uint8_t *)v->data)[base + p] = (uint8_t)(i + 1);
            else
                ((uint16_t *)v->data)[base + p] = (uint16_t)(i + 1);
        }
    }
    /* Values are 1 + the segment's index; the table says its number. */
    if (!rc)
        rc = add_segments(seg, s, layer_of, err);
    for (size_t i = 0; !rc && i < seg->segment_count; i++)
        seg->segments[i].value = (int64_t)i + 1;
    iso_vol_destroy(first);
    free(overlap);
    free(layer_of);
    if (rc) {
        iso_seg_destroy(seg);
        return rc;
    }
    *out = seg;
    return 0;
}

/* PASS 4 for FRACTIONAL: a layer per segment, its frames' values. */
static int fill_fractional(const char *file, const iso_gdcm_seg *s, const size_t *slice, const grid *g,
                           const iso_load_options *opt, iso_segmentation **out, iso_error *err)
{
    const size_t frame_pixels = (size_t)s->rows * s->columns;
    if (!(s->max_fraction > 0) || s->bits_allocated != 8)
        return iso_error_set(err, ISO_E_FORMAT, "%s: a FRACTIONAL segmentation needs 8-bit frames and a Maximum Fractional "
                             "Value > 0 (has %u bits, %g)", file, s->bits_allocated, s->max_fraction);
    iso_segmentation *seg = iso_seg_create(s->segment_count);
    if (!seg)
        return iso_error_set(err, ISO_E_NOMEM, "%s: out of memory", file);
    unsigned *layer_of = calloc(s->segment_count, sizeof *layer_of);
    int rc = layer_of ? 0 : iso_error_set(err, ISO_E_NOMEM, "%s: out of memory", file);
    for (unsigned i = 0; !rc && i < s->segment_count; i++) {
        layer_of[i] = i;
        iso_volume *v = layer_volume(g, ISO_U8, opt, err);
        if (!v) {
            rc = err ? err->code : ISO_E_NOMEM;
            break;
        }
        seg->layers[i] = (iso_seg_layer){.vol = v, .kind = ISO_SEG_FRACTIONAL, .max_fraction = s->max_fraction};
    }
    for (unsigned f = 0; !rc && f < s->frames; f++) {
        iso_volume *v = seg->layers[segment_of(s, s->frame[f].segment)].vol;
        memcpy((uint8_t *)v->data + slice[f] * frame_pixels, s->pixels + (size_t)f * frame_pixels, frame_pixels);
    }
    if (!rc)
        rc = add_segments(seg, s, layer_of, err);
    free(layer_of);
    if (rc) {
        iso_seg_destroy(seg);
        return rc;
    }
    *out = seg;
    return 0;
}

/* PASS 4 for LABELMAP: one label map; two frames may not put two segments on one voxel. */
static int fill_labelmap(const char *file, const iso_gdcm_seg *s, const size_t *slice, const grid *g,
                         const iso_load_options *opt, iso_segmentation **out, iso_error *err)
{
    const size_t frame_pixels = (size_t)s->rows * s->columns;
    iso_segmentation *seg = iso_seg_create(1);
    iso_volume *v = seg ? layer_volume(g, s->bits_allocated == 16 ? ISO_U16 : ISO_U8, opt, err) : NULL;
    int rc = seg && v ? 0 : iso_error_set(err, ISO_E_NOMEM, "%s: out of memory", file);
    if (!rc) {
        v->labels = 1;
        seg->layers[0] = (iso_seg_layer){.vol = v, .kind = ISO_SEG_LABELS};
    } else {
        iso_vol_destroy(v);
    }
    for (unsigned f = 0; !rc && f < s->frames; f++)
        for (size_t p = 0; !rc && p < frame_pixels; p++) {
            unsigned value = pixel(s, frame_pixels, f, p), held = (unsigned)iso_vol_sample(v, slice[f] * frame_pixels + p);
            if (!value)
                continue;
            if (segment_of(s, value) < 0)
                rc = iso_error_set(err, ISO_E_FORMAT, "%s: frame %u holds segment %u, which the Segment Sequence does not",
                                   file, f + 1, value);
            else if (held && held != value)
                rc = iso_error_set(err, ISO_E_FORMAT,
                                   "%s: frame %u puts segment %u where another frame put segment %u (slice %zu, pixel %zu): "
                                   "overlapping segments in a label map SEG",
                                   file, f + 1, value, held, slice[f], p);
            else if (s->bits_allocated == 16)
                ((uint16_t *)v->data)[slice[f] * frame_pixels + p] = (uint16_t)value;
            else
                ((uint8_t *)v->data)[slice[f] * frame_pixels + p] = (uint8_t)value;
        }
    if (!rc)
        rc = add_segments(seg, s, NULL, err);
    if (rc) {
        iso_seg_destroy(seg);
        return rc;
    }
    *out = seg;
    return 0;
}

int iso_seg_dicom_load(const char *path, const iso_load_options *opt, iso_segmentation **out, iso_error *err)
{
    *out = NULL;
    char dir[4096], file[4096], uid[128], why[400] = "";
    if (split(path, dir, sizeof dir, file, sizeof file, uid, sizeof uid))
        return iso_error_set(err, ISO_E_IO, "%s: no such file or directory", path);
    int rc = file[0] ? 0 : find_seg_file(path, dir, uid, file, sizeof file, err);
    if (rc)
        return rc;
    /* PASS 2 */
    iso_gdcm_seg s;
    if (iso_gdcm_seg_read(file, MAX_FRAMES, &s, why, sizeof why))
        return iso_error_set(err, ISO_E_FORMAT, "%s: %s", file, why);
    int labelmap = !strcmp(s.type, "LABELMAP");
    if (!is_segmentation(s.sop_class))
        rc = iso_error_set(err, ISO_E_FORMAT, "%s: SOP class %s is not a Segmentation", file, s.sop_class);
    else if (strcmp(s.type, "BINARY") && strcmp(s.type, "FRACTIONAL") && !labelmap)
        rc = iso_error_set(err, ISO_E_UNSUPPORTED, "%s: Segmentation Type \"%s\" (BINARY, FRACTIONAL and LABELMAP are read)",
                           file, s.type);
    else if (!s.referenced_series[0])
        rc = iso_error_set(err, ISO_E_FORMAT, "%s: no Referenced Series Sequence: which images does it segment?", file);
    grid g;
    memset(&g, 0, sizeof g);
    char reference[4300];
    snprintf(reference, sizeof reference, "%s#%s", dir, s.referenced_series);
    iso_error ref_err;
    if (!rc && iso_dicom_geometry(reference, opt, &g.shape, &ref_err))
        rc = iso_error_set(err, ref_err.code == ISO_E_ARGUMENT ? ISO_E_FORMAT : ref_err.code,
                           "%s: the series it references (%s) must be beside it in %s: %s", file, s.referenced_series, dir,
                           ref_err.message);
    double frame[3][3];
    if (!rc && iso_vol_frame(&g.shape, frame, g.inverse, NULL))
        rc = iso_error_set(err, ISO_E_FORMAT, "%s: the referenced series' geometry is singular", reference);
    if (!rc)
        rc = check_frames(file, &s, labelmap, err);
    if (!rc)
        rc = check_planes(file, &s, &g, err);
    /* PASS 3 */
    size_t *slice = rc ? NULL : malloc((s.frames ? s.frames : 1) * sizeof *slice);
    if (!rc && !slice)
        rc = iso_error_set(err, ISO_E_NOMEM, "%s: out of memory", file);
    for (unsigned f = 0; !rc && f < s.frames; f++)
        rc = place_frame(file, &s, &g, f, &slice[f], err);
    /* PASS 4 */
    iso_segmentation *seg = NULL;
    if (!rc)
        rc = labelmap ? fill_labelmap(file, &s, slice, &g, opt, &seg, err)
           : !strcmp(s.type, "FRACTIONAL") ? fill_fractional(file, &s, slice, &g, opt, &seg, err)
                                           : fill_binary(file, &s, slice, &g, opt, &seg, err);
    free(slice);
    iso_gdcm_seg_free(&s);
    if (rc || !seg)
        return rc ? rc : iso_error_set(err, ISO_E_INTERNAL, "%s: no segmentation made", file);
    snprintf(seg->source, sizeof seg->source, "dicom-seg");
    for (size_t l = 0; l < seg->layer_count; l++)
        iso_vol_update_stats(seg->layers[l].vol);
    *out = seg;
    return 0;
}
