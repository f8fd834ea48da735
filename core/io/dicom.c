/* dicom.c: DICOM series as volumes (see io.h): choosing the series, sorting its frames
 * along the slice normal, checking the gaps, the world matrix and the rescaled samples.
 * GDCM (through dicom_gdcm.h) only reads headers and decodes pixels. */
#include "io.h"

#include <assert.h>
#include <dirent.h>
#include <errno.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <strings.h>
#include <sys/stat.h>

#include "dicom_gdcm.h"

/* Most frames one file may declare before anything is allocated for them. */
#define MAX_FRAMES_PER_FILE 65536

typedef struct dfile {
    char *path;
    iso_gdcm_header h;
} dfile;

typedef struct dframe {
    size_t file;        /* index into the series' files */
    unsigned index;     /* frame within that file */
    double pos[3];      /* LPS mm of the frame's first pixel */
    double along;       /* pos projected on the slice normal */
    double slope, intercept;
} dframe;

typedef struct series {
    const char *spec;   /* the name the caller gave, for messages */
    dfile *files;
    size_t count;
    size_t segmentations; /* Segmentation objects skipped: not images of the series */
    dframe *frames;
    size_t frame_count;
    double normal[3];
} series;

/* ---------------------------------------------------------------- names and files */

/* Splits "DIR#UID" into the source path and the wanted series UID ("" = the only one). */
static int split_spec(const char *spec, char *source, size_t size, const char **uid)
{
    const char *hash = strrchr(spec, '#');
    size_t n = hash ? (size_t)(hash - spec) : strlen(spec);
    if (n == 0 || n >= size)
        return -1;
    memcpy(source, spec, n);
    source[n] = '\0';
    *uid = hash ? hash + 1 : "";
    return 0;
}

static int is_dir(const char *path)
{
    struct stat st;
    return stat(path, &st) == 0 && S_ISDIR(st.st_mode);
}

static int has_dcm_suffix(const char *path)
{
    size_t n = strlen(path);
    return n > 4 && strcasecmp(path + n - 4, ".dcm") == 0;
}

int iso_dicom_recognises(const char *path)
{
    char source[4096];
    const char *uid;
    if (split_spec(path, source, sizeof source, &uid))
        return 0;
    if (is_dir(source))
        return 1;
    return !*uid && has_dcm_suffix(path);
}

static int has_magic(const char *path)
{
    FILE *f = fopen(path, "rb");
    char buf[132];
    int ok = f && fread(buf, 1, sizeof buf, f) == sizeof buf && !memcmp(buf + 128, "DICM", 4);
    if (f)
        fclose(f);
    return ok;
}

/* Calls fn for each regular, not hidden file of dir until fn returns non-zero (which is
 * returned); -1 if the directory cannot be opened. */
static int each_file(const char *dir, int (*fn)(void *ctx, const char *path), void *ctx)
{
    DIR *d = opendir(dir);
    if (!d)
        return -1;
    struct dirent *ent;
    int rc = 0;
    char path[4096];
    while (!rc && (ent = readdir(d))) {
        struct stat st;
        if (ent->d_name[0] == '.' ||
            snprintf(path, sizeof path, "%s/%s", dir, ent->d_name) >= (int)sizeof path ||
            stat(path, &st) || !S_ISREG(st.st_mode))
            continue;
        rc = fn(ctx, path);
    }
    closedir(d);
    return rc;
}

static int magic_found(void *ctx, const char *path)
{
    (void)ctx;
    return has_magic(path);
}

int iso_dicom_dir_has_files(const char *dir)
{
    return each_file(dir, magic_found, NULL) == 1;
}

typedef struct name_list {
    char **names;
    size_t count, capacity;
} name_list;

static int collect_name(void *ctx, const char *path)
{
    name_list *l = ctx;
    if (l->count == ISO_DICOM_MAX_FILES)
        return 2;
    if (l->count == l->capacity) {
        size_t cap = l->capacity ? 2 * l->capacity : 64;
        char **grown = realloc(l->names, cap * sizeof *grown);
        if (!grown)
            return 3;
        l->names = grown;
        l->capacity = cap;
    }
    return (l->names[l->count] = strdup(path)) ? (l->count++, 0) : 3;
}

static int by_name(const void *a, const void *b)
{
    return strcmp(*(char *const *)a, *(char *const *)b);
}

static void free_names(name_list *l)
{
    for (size_t i = 0; i < l->count; i++)
        free(l->names[i]);
    free(l->names);
}

/* The files of the source: the directory's (sorted by name, so that messages are stable),
 * or the one file. */
static int list_files(const char *spec, const char *source, name_list *l, iso_error *err)
{
    memset(l, 0, sizeof *l);
    if (!is_dir(source))
        return collect_name(l, source) ? iso_error_set(err, ISO_E_NOMEM, "%s: out of memory", spec) : 0;
    int rc = each_file(source, collect_name, l);
    if (rc == -1)
        return iso_error_set(err, ISO_E_IO, "%s: cannot open the directory: %s", spec, strerror(errno));
    if (rc == 2)
        return iso_error_set(err, ISO_E_LIMIT, "%s: more than %d files; a series directory holds one series' slices",
                             spec, ISO_DICOM_MAX_FILES);
    if (rc == 3)
        return iso_error_set(err, ISO_E_NOMEM, "%s: out of memory listing the files", spec);
    if (l->count) /* qsort wants a non-NULL array even for none */
        qsort(l->names, l->count, sizeof *l->names, by_name);
    return 0;
}

/* ---------------------------------------------------------------- headers and series */

static void free_series(series *s)
{
    for (size_t i = 0; i < s->count; i++) {
        free(s->files[i].path);
        iso_gdcm_header_free(&s->files[i].h);
    }
    free(s->files);
    free(s->frames);
    memset(s, 0, sizeof *s);
}

/* Reads every header; files that are not DICOM images are skipped. Takes the names. */
static int read_headers(const char *spec, name_list *l, series *all, const iso_load_options *opt,
                        iso_error *err)
{
    all->files = calloc(l->count ? l->count : 1, sizeof *all->files);
    if (!all->files)
        return iso_error_set(err, ISO_E_NOMEM, "%s: out of memory", spec);
    for (size_t i = 0; i < l->count; i++) {
        char why[300] = "";
        dfile *f = &all->files[all->count];
        int rc = iso_gdcm_read_header(l->names[i], MAX_FRAMES_PER_FILE, &f->h, why, sizeof why);
        if (opt && opt->progress)
            opt->progress(opt->progress_context, 0.5 * (double)(i + 1) / (double)l->count);
        if (rc == ISO_GDCM_NOT_DICOM)
            continue;
        if (rc != ISO_GDCM_OK)
            return iso_error_set(err, ISO_E_FORMAT, "%s: %s", l->names[i], why);
        if (!strcmp(f->h.sop_class, ISO_GDCM_SEG_SOP_CLASS) || !strcmp(f->h.sop_class, ISO_GDCM_SEG_LABELMAP_SOP_CLASS)) {
            iso_gdcm_header_free(&f->h); /* a segmentation of the images, loaded as one (segment.h) */
            all->segmentations++;
            continue;
        }
        f->path = l->names[i];
        l->names[i] = NULL;
        all->count++;
    }
    return 0;
}

/* "UID (N files), ..." of every series in all, for messages. */
static void describe_series(const series *all, char *out, size_t size)
{
    size_t used = 0;
    out[0] = '\0';
    for (size_t i = 0; i < all->count && used + 1 < size; i++) {
        const char *uid = all->files[i].h.series_uid;
        size_t seen = 0, n = 0;
        for (size_t j = 0; j < all->count; j++) {
            seen += j < i && !strcmp(all->files[j].h.series_uid, uid);
            n += !strcmp(all->files[j].h.series_uid, uid);
        }
        if (!seen)
            used += (size_t)snprintf(out + used, size - used, "%s%s (%zu files)", used ? ", " : "",
                                     *uid ? uid : "(no SeriesInstanceUID)", n);
    }
}

/* Moves the files of the chosen series from all into s. */
static int choose_series(const char *spec, const char *uid, series *all, series *s, iso_error *err)
{
    char list[400], wanted[sizeof all->files[0].h.series_uid];
    describe_series(all, list, sizeof list);
    if (all->count == 0 && all->segmentations)
        return iso_error_set(err, ISO_E_UNSUPPORTED, "%s: a DICOM Segmentation, no image series: load it as a segmentation "
                             "(the catalog's \"labels\": true, or isoserve segments)", spec);
    if (all->count == 0)
        return iso_error_set(err, ISO_E_UNSUPPORTED, "%s: no DICOM image files (with the DICM preamble): not a volume isoserve reads",
                             spec); /* a folder of anything else is no format of ours */
    if (!*uid) {
        for (size_t i = 1; i < all->count; i++)
            if (strcmp(all->files[i].h.series_uid, all->files[0].h.series_uid))
                return iso_error_set(err, ISO_E_FORMAT, "%s: several series: %s; name one as %s#SeriesInstanceUID",
                                     spec, list, spec);
        uid = all->files[0].h.series_uid;
    }
    snprintf(wanted, sizeof wanted, "%s", uid); /* moving the files below clears the original */
    uid = wanted;
    s->files = calloc(all->count, sizeof *s->files);
    if (!s->files)
        return iso_error_set(err, ISO_E_NOMEM, "%s: out of memory", spec);
    for (size_t i = 0; i < all->count; i++)
        if (!strcmp(all->files[i].h.series_uid, uid)) {
            s->files[s->count++] = all->files[i];
            memset(&all->files[i], 0, sizeof all->files[i]);
        }
    if (!s->count)
        return iso_error_set(err, ISO_E_ARGUMENT, "%s: no series %s here; the folder holds %s", spec, uid, list);
    return 0;
}

/* Every file of the series must share the first one's pixel layout and plane geometry. */
static int check_consistent(const series *s, iso_error *err)
{
    const iso_gdcm_header *a = &s->files[0].h;
    if (a->samples_per_pixel != 1)
        return iso_error_set(err, ISO_E_UNSUPPORTED, "%s: %u samples per pixel (colour); isoserve reads scalar images",
                             s->files[0].path, a->samples_per_pixel);
    if (a->bits_allocated != 8 && a->bits_allocated != 16 && a->bits_allocated != 32)
        return iso_error_set(err, ISO_E_UNSUPPORTED, "%s: BitsAllocated %u; isoserve reads 8, 16 and 32",
                             s->files[0].path, a->bits_allocated);
    if (!(a->pixel_spacing[0] > 0 && a->pixel_spacing[1] > 0 && isfinite(a->pixel_spacing[0] + a->pixel_spacing[1])))
        return iso_error_set(err, ISO_E_FORMAT, "%s: PixelSpacing is missing or not positive", s->files[0].path);
    if (!a->has_orientation)
        return iso_error_set(err, ISO_E_FORMAT, "%s: ImageOrientationPatient is missing", s->files[0].path);
    for (size_t i = 1; i < s->count; i++) {
        const iso_gdcm_header *b = &s->files[i].h;
        double d = 0;
        for (int c = 0; c < 6; c++)
            d = fmax(d, fabs(a->orientation[c] - b->orientation[c]));
        if (b->rows != a->rows || b->columns != a->columns || b->bits_allocated != a->bits_allocated ||
            b->bits_stored != a->bits_stored || b->pixel_signed != a->pixel_signed ||
            b->samples_per_pixel != 1)
            return iso_error_set(err, ISO_E_FORMAT, "%s: %ux%u pixels of %u bits, unlike %s (%ux%u of %u bits)",
                                 s->files[i].path, b->columns, b->rows, b->bits_allocated, s->files[0].path,
                                 a->columns, a->rows, a->bits_allocated);
        if (d > 1e-4 || !b->has_orientation)
            return iso_error_set(err, ISO_E_FORMAT, "%s: ImageOrientationPatient differs from %s's",
                                 s->files[i].path, s->files[0].path);
        if (fabs(b->pixel_spacing[0] - a->pixel_spacing[0]) > 1e-6 * a->pixel_spacing[0] ||
            fabs(b->pixel_spacing[1] - a->pixel_spacing[1]) > 1e-6 * a->pixel_spacing[1])
            return iso_error_set(err, ISO_E_FORMAT, "%s: PixelSpacing %g\\%g differs from %s's %g\\%g",
                                 s->files[i].path, b->pixel_spacing[0], b->pixel_spacing[1], s->files[0].path,
                                 a->pixel_spacing[0], a->pixel_spacing[1]);
    }
    return 0;
}

/* ---------------------------------------------------------------- geometry */

static double dot(const double a[3], const double b[3])
{
    return a[0] * b[0] + a[1] * b[1] + a[2] * b[2];
}

/* The unit normal of the slice plane: row direction x column direction. */
static int slice_normal(series *s, iso_error *err)
{
    const double *o = s->files[0].h.orientation;
    double *n = s->normal;
    n[0] = o[1] * o[5] - o[2] * o[4];
    n[1] = o[2] * o[3] - o[0] * o[5];
    n[2] = o[0] * o[4] - o[1] * o[3];
    double len = sqrt(dot(n, n));
    if (!(len > 1e-6) || !isfinite(len))
        return iso_error_set(err, ISO_E_FORMAT, "%s: ImageOrientationPatient has parallel or zero directions",
                             s->files[0].path);
    for (int a = 0; a < 3; a++)
        n[a] /= len;
    return 0;
}

/* One dframe per frame of every file, with its position (RT dose: the file's position
 * moved along the normal by GridFrameOffsetVector). */
static int gather_frames(series *s, iso_error *err)
{
    size_t total = 0;
    for (size_t i = 0; i < s->count; i++)
        total += s->files[i].h.frames;
    s->frames = calloc(total ? total : 1, sizeof *s->frames);
    if (!s->frames)
        return iso_error_set(err, ISO_E_NOMEM, "%s: out of memory", s->spec);
    for (size_t i = 0; i < s->count; i++) {
        const iso_gdcm_header *h = &s->files[i].h;
        for (unsigned f = 0; f < h->frames; f++) {
            dframe *d = &s->frames[s->frame_count++];
            if (!h->frame[f].has_position)
                return iso_error_set(err, ISO_E_FORMAT, "%s: frame %u has no ImagePositionPatient",
                                     s->files[i].path, f + 1);
            double shift = h->grid_offsets ? h->grid_offsets[f] - h->grid_offsets[0] : 0;
            for (int a = 0; a < 3; a++)
                d->pos[a] = h->frame[f].position[a] + shift * s->normal[a];
            if (!isfinite(d->pos[0] + d->pos[1] + d->pos[2]))
                return iso_error_set(err, ISO_E_FORMAT, "%s: frame %u: ImagePositionPatient is not finite",
                                     s->files[i].path, f + 1);
            d->file = i;
            d->index = f;
            d->along = dot(d->pos, s->normal);
            d->slope = h->frame[f].slope;
            d->intercept = h->frame[f].intercept;
            if (!isfinite(d->slope) || d->slope == 0 || !isfinite(d->intercept))
                return iso_error_set(err, ISO_E_FORMAT, "%s: frame %u: RescaleSlope %g and RescaleIntercept %g: "
                                     "expected finite numbers and a slope other than 0",
                                     s->files[i].path, f + 1, d->slope, d->intercept);
        }
    }
    return 0;
}

static int by_along(const void *pa, const void *pb)
{
    const dframe *a = pa, *b = pb;
    if (a->along != b->along)
        return a->along < b->along ? -1 : 1;
    if (a->file != b->file)
        return a->file < b->file ? -1 : 1;
    return a->index < b->index ? -1 : a->index > b->index;
}

static int by_double(const void *a, const void *b)
{
    double x = *(const double *)a, y = *(const double *)b;
    return x < y ? -1 : x > y;
}

/* The median gap between neighbouring slices (after sorting): a missing slice cannot
 * move it, so it is what the other gaps are measured against. */
static double median_gap(const series *s)
{
    size_t n = s->frame_count - 1;
    double *gaps = malloc(n * sizeof *gaps);
    if (!gaps)
        return NAN;
    for (size_t k = 0; k < n; k++)
        gaps[k] = s->frames[k + 1].along - s->frames[k].along;
    qsort(gaps, n, sizeof *gaps, by_double);
    double m = gaps[n / 2];
    free(gaps);
    return m;
}

/* "file" or "file frame N" of a frame, for messages. */
static void frame_name(const series *s, const dframe *d, char *out, size_t size)
{
    if (s->files[d->file].h.frames > 1)
        snprintf(out, size, "%s frame %u", s->files[d->file].path, d->index + 1);
    else
        snprintf(out, size, "%s", s->files[d->file].path);
}

/* Sorted along the normal: no two at one place, every gap the median one. */
static int check_gaps(const series *s, iso_error *err)
{
    double m = median_gap(s);
    char a[300], b[300];
    if (isnan(m))
        return iso_error_set(err, ISO_E_NOMEM, "%s: out of memory", s->spec);
    for (size_t k = 0; k + 1 < s->frame_count; k++) {
        const dframe *p = &s->frames[k], *q = &s->frames[k + 1];
        double gap = q->along - p->along;
        if (gap > 1e-4 && fabs(gap - m) <= ISO_DICOM_GAP_TOLERANCE * m)
            continue;
        frame_name(s, p, a, sizeof a);
        frame_name(s, q, b, sizeof b);
        if (gap <= 1e-4)
            return iso_error_set(err, ISO_E_FORMAT, "%s: two slices at one position (%.4g mm along the normal): %s and %s",
                                 s->spec, p->along, a, b);
        return iso_error_set(err, ISO_E_FORMAT,
                             "%s: uneven slice spacing: the gap between %s (at %.4g mm) and %s (at %.4g mm) is %.4g mm, "
                             "the series' other gaps %.4g mm%s",
                             s->spec, a, p->along, b, q->along, gap, m, gap > 1.5 * m ? " (a missing slice?)" : "");
    }
    return 0;
}

/* Every slice on the line from the first to the last (a tilted gantry's line is fine). */
static int check_line(const series *s, const double step[3], iso_error *err)
{
    const double *p0 = s->frames[0].pos;
    double tolerance = fmax(ISO_DICOM_GAP_TOLERANCE * sqrt(dot(step, step)), 1e-3);
    for (size_t k = 1; k + 1 < s->frame_count; k++) {
        double d[3];
        for (int a = 0; a < 3; a++)
            d[a] = s->frames[k].pos[a] - (p0[a] + (double)k * step[a]);
        if (sqrt(dot(d, d)) > tolerance) {
            char name[300];
            frame_name(s, &s->frames[k], name, sizeof name);
            return iso_error_set(err, ISO_E_FORMAT, "%s: %s lies %.3g mm off the line through the first and last slices",
                                 s->spec, name, sqrt(dot(d, d)));
        }
    }
    return 0;
}

/* Sorts the frames and sets the world matrix: the row and column directions scaled by
 * PixelSpacing, and the measured step from slice to slice. */
static int set_geometry(series *s, iso_volume *vol, iso_error *err)
{
    const iso_gdcm_header *h = &s->files[0].h;
    size_t n = s->frame_count;
    double step[3], affine[3][4];
    qsort(s->frames, n, sizeof *s->frames, by_along);
    int rc = check_gaps(s, err);
    for (int a = 0; a < 3; a++)
        step[a] = (s->frames[n - 1].pos[a] - s->frames[0].pos[a]) / (double)(n - 1);
    if (rc || (rc = check_line(s, step, err)))
        return rc;
    for (int r = 0; r < 3; r++) {
        affine[r][0] = h->orientation[r] * h->pixel_spacing[1];
        affine[r][1] = h->orientation[3 + r] * h->pixel_spacing[0];
        affine[r][2] = step[r];
        affine[r][3] = s->frames[0].pos[r];
    }
    return iso_vol_set_affine(vol, affine, s->spec, err);
}

/* ---------------------------------------------------------------- samples */

static iso_voxel_type stored_type(const iso_gdcm_header *h)
{
    switch (h->bits_allocated) {
    case 8: return h->pixel_signed ? ISO_I8 : ISO_U8;
    case 16: return h->pixel_signed ? ISO_I16 : ISO_U16;
    default: return h->pixel_signed ? ISO_I32 : ISO_U32;
    }
}

static unsigned bits_stored(const iso_gdcm_header *h)
{
    return h->bits_stored && h->bits_stored <= h->bits_allocated ? h->bits_stored : h->bits_allocated;
}

/* Sample i of a decoded frame as stored: only the low BitsStored bits count (the rest
 * may hold overlays), sign-extended for signed pixels. */
static long long raw_sample(const void *frame, iso_voxel_type type, size_t i, unsigned bits)
{
    unsigned long long u;
    switch (type) {
    case ISO_U8: case ISO_I8: u = ((const uint8_t *)frame)[i]; break;
    case ISO_U16: case ISO_I16: u = ((const uint16_t *)frame)[i]; break;
    default: u = ((const uint32_t *)frame)[i]; break;
    }
    u &= bits >= 64 ? ~0ULL : (1ULL << bits) - 1;
    int is_signed = type == ISO_I8 || type == ISO_I16 || type == ISO_I32;
    if (is_signed && (u >> (bits - 1)) & 1)
        return (long long)u - (long long)(1ULL << bits);
    return (long long)u;
}

/* Places decoded frame f of a file into slice k of vol as stored (vol has the stored
 * type): the rescale comes after every frame is in (rescale). */
static void place_frame(iso_volume *vol, size_t k, const void *frame, const iso_gdcm_header *h)
{
    size_t n = vol->dims[0] * vol->dims[1];
    unsigned bits = bits_stored(h);
    if (bits == h->bits_allocated) {
        memcpy((char *)vol->data + k * n * iso_vol_type_size(vol->type), frame, n * iso_vol_type_size(vol->type));
        return;
    }
    for (size_t i = 0; i < n; i++)
        iso_vol_set(vol, i % vol->dims[0], i / vol->dims[0], k, (double)raw_sample(frame, vol->type, i, bits));
}

/* Decodes each file once and places its frames where sorting put them. */
static int read_samples(const series *s, iso_volume *vol, const iso_load_options *opt, iso_error *err)
{
    const iso_gdcm_header *h0 = &s->files[0].h;
    size_t frame_bytes = (size_t)h0->rows * h0->columns * (h0->bits_allocated / 8);
    for (size_t f = 0; f < s->count; f++) {
        const dfile *file = &s->files[f];
        size_t bytes = frame_bytes * file->h.frames;
        /* The file's frames are slices of vol, whose size was checked: this cannot trip
         * unless the bookkeeping is wrong, and then it must not write past a buffer. */
        if (bytes / frame_bytes != file->h.frames || bytes > iso_vol_count(vol) * 4)
            return iso_error_set(err, ISO_E_LIMIT, "%s: %u frames do not fit the volume", file->path, file->h.frames);
        void *buf = malloc(bytes);
        char why[300] = "";
        if (!buf)
            return iso_error_set(err, ISO_E_NOMEM, "%s: out of memory for %zu bytes of pixels", file->path, bytes);
        if (iso_gdcm_read_pixels(file->path, &file->h, buf, bytes, why, sizeof why)) {
            free(buf);
            return iso_error_set(err, ISO_E_FORMAT, "%s: %s", file->path, why);
        }
        for (size_t k = 0; k < s->frame_count; k++)
            if (s->frames[k].file == f)
                place_frame(vol, k, (const char *)buf + s->frames[k].index * frame_bytes, &file->h);
        free(buf);
        if (opt && opt->progress)
            opt->progress(opt->progress_context, 0.5 + 0.5 * (double)(f + 1) / (double)s->count);
    }
    return 0;
}

/* The stored samples in vol (one slice per sorted frame) to their rescaled values, in the
 * narrowest type that holds them (volume.h). */
static int rescale(const series *s, iso_volume *vol, uint64_t max_bytes, iso_error *err)
{
    size_t n = s->frame_count;
    double *slope = malloc(2 * n * sizeof *slope);
    if (!slope)
        return iso_error_set(err, ISO_E_NOMEM, "%s: out of memory", s->spec);
    double *intercept = slope + n;
    for (size_t k = 0; k < n; k++) {
        slope[k] = s->frames[k].slope;
        intercept[k] = s->frames[k].intercept;
    }
    iso_error why = {0};
    int rc = iso_vol_rescale(vol, slope, intercept, max_bytes, &why);
    if (rc)
        rc = iso_error_set(err, rc, "%s: %s", s->spec, why.message);
    free(slope);
    return rc;
}

/* Copies text into a volume's field: printable ASCII only (DICOM strings may come in other
 * character sets, and a document is UTF-8), others as '?'. */
static void copy_label(char *out, size_t size, const char *text)
{
    size_t n = 0;
    for (; text[n] && n + 1 < size; n++)
        out[n] = text[n] >= 0x20 && text[n] < 0x7f ? text[n] : '?';
    out[n] = '\0';
}

/* ---------------------------------------------------------------- the loader */

/* From the chosen series to the volume: geometry first, so that a bad series fails
 * before anything big is allocated or decoded. With shape, the geometry alone goes there
 * (no sample read). */
static int build_volume(series *s, const iso_load_options *opt, iso_volume **out, iso_volume *shape,
                        iso_error *err)
{
    int rc = check_consistent(s, err);
    if (!rc)
        rc = slice_normal(s, err);
    if (!rc)
        rc = gather_frames(s, err);
    if (!rc && s->frame_count < 2)
        rc = iso_error_set(err, ISO_E_FORMAT, "%s: one slice (%s); a volume needs at least 2", s->spec,
                           s->files[0].path);
    if (rc)
        return rc;
    const iso_gdcm_header *h = &s->files[0].h;
    size_t dims[3] = {h->columns, h->rows, s->frame_count};
    iso_volume probe = {.dims = {dims[0], dims[1], dims[2]}};
    if ((rc = set_geometry(s, &probe, err)))
        return rc;
    if (shape) {
        *shape = probe;
        return 0;
    }
    uint64_t bytes, max_bytes = opt && opt->max_bytes ? opt->max_bytes : ISO_VOL_DEFAULT_MAX_BYTES;
    iso_error size_err;
    iso_voxel_type type = stored_type(h);
    if (iso_vol_check_size(dims, type, max_bytes, &bytes, &size_err))
        return iso_error_set(err, ISO_E_LIMIT, "%s: %s", s->spec, size_err.message);
    iso_volume *vol = iso_vol_create(dims, type, max_bytes, err);
    if (!vol)
        return err ? err->code : ISO_E_NOMEM;
    memcpy(vol->spacing, probe.spacing, sizeof vol->spacing);
    memcpy(vol->origin, probe.origin, sizeof vol->origin);
    memcpy(vol->direction, probe.direction, sizeof vol->direction);
    copy_label(vol->modality, sizeof vol->modality, h->modality);
    copy_label(vol->description, sizeof vol->description, h->series_description);
    vol->oriented = 1; /* ImageOrientationPatient is required to get here */
    if (h->has_padding) {
        vol->has_padding = 1;
        vol->padding = s->frames[0].slope * h->padding + s->frames[0].intercept;
    }
    if ((rc = read_samples(s, vol, opt, err)) || (rc = rescale(s, vol, max_bytes, err))) {
        iso_vol_destroy(vol);
        return rc;
    }
    *out = vol;
    return 0;
}

/* iso_dicom_load, or with shape its geometry alone. */
static int load(const char *path, const iso_load_options *opt, iso_volume **out, iso_volume *shape, iso_error *err)
{
    char source[4096];
    const char *uid;
    if (split_spec(path, source, sizeof source, &uid))
        return iso_error_set(err, ISO_E_ARGUMENT, "%s: expected DIR, DIR#SeriesInstanceUID or FILE.dcm", path);
    name_list names;
    series all = {.spec = path}, chosen = {.spec = path};
    int rc = list_files(path, source, &names, err);
    if (!rc)
        rc = read_headers(path, &names, &all, opt, err);
    free_names(&names);
    if (!rc)
        rc = choose_series(path, uid, &all, &chosen, err);
    free_series(&all);
    if (!rc)
        rc = build_volume(&chosen, opt, out, shape, err);
    free_series(&chosen);
    return rc;
}

int iso_dicom_load(const char *path, const iso_load_options *opt, iso_volume **out, iso_error *err)
{
    assert(path && out);
    *out = NULL;
    return load(path, opt, out, NULL, err);
}

int iso_dicom_geometry(const char *path, const iso_load_options *opt, iso_volume *shape, iso_error *err)
{
    assert(path && shape);
    memset(shape, 0, sizeof *shape);
    iso_volume *none = NULL;
    return load(path, opt, &none, shape, err);
}
