/* extract.c: segment surfaces (segment.h), in passes:
 *
 * PASS 1 (bricks): the segment's bricks from its layer's label sets (hierarchy/labels.h):
 *   those holding its label and another are its boundary bricks, the only ones its
 *   surface crosses; those on the volume's border need the cap.
 * PASS 2 (march): without smoothing, the label's surface (extract.h, iso_extract_label:
 *   the exact brick kernel on the boundary bricks with "sample == label" as its
 *   classification, capped and placed: passes 2 to 4 here). With smoothing, the field (field.c: the indicator convolved with the Gaussian) on the box of
 *   the boundary bricks widened by the kernel, marched at 0.5 by the ordinary kernel over
 *   that field's own min/max bricks. A fractional layer's segment is the ordinary
 *   extraction of its layer at max_fraction / 2 (extract.h).
 * PASS 3 (cap, if asked and not smoothed): marching cubes on the cells between the border
 *   samples of the segment's border bricks and a virtual layer of 0 beyond them, welded to
 *   the surface in index space: the cap lies where the indicator crosses 0.5 toward the
 *   outside, half a voxel past the border samples (a smoothed field is 0 beyond the border
 *   already, and its box reaches past it).
 * PASS 4 (place): index space to world millimetres, as the exact kernel places vertices. */
#include "segment_internal.h"

#include <math.h>
#include <stdatomic.h>
#include <stdlib.h>
#include <string.h>


/* The label's bricks in its layer's label sets: holding[*start .. *start + *count). */
static void label_bricks(const iso_tree *tree, int64_t value, size_t *start, size_t *count)
{
    long i = tree->labels ? iso_label_index(tree->labels, value) : -1;
    *start = *count = 0;
    if (i >= 0) {
        *start = tree->labels->holding_start[i];
        *count = tree->labels->holding_start[i + 1] - tree->labels->holding_start[i];
    }
}

/* The box (samples, inclusive) of the segment's boundary bricks, and with cap of its
 * bricks on the border too; 0 when there are none. */
static int boundary_box(const iso_seg_layer *layer, int64_t value, int cap, long lo[3], long hi[3])
{
    size_t start, count;
    label_bricks(layer->tree, value, &start, &count);
    const iso_bricks *g = &layer->tree->bricks;
    int any = 0;
    for (size_t k = 0; k < count; k++) {
        uint32_t at = layer->tree->labels->holding[start + k];
        if (!(at & ISO_LABEL_MIXED) && !(cap && iso_bricks_on_border(g, at & ~ISO_LABEL_MIXED)))
            continue;
        at &= ~ISO_LABEL_MIXED;
        uint32_t b[3] = {at % g->count[0], at / g->count[0] % g->count[1], at / g->count[0] / g->count[1]};
        size_t blo[3], bhi[3];
        iso_bricks_box(layer->vol, b, blo, bhi);
        for (int d = 0; d < 3; d++) {
            lo[d] = any && lo[d] < (long)blo[d] ? lo[d] : (long)blo[d];
            hi[d] = any && hi[d] > (long)bhi[d] ? hi[d] : (long)bhi[d];
        }
        any = 1;
    }
    return any;
}

/* A fractional layer's box: the whole volume (its tree prunes inside it). */
static void whole_box(const iso_volume *vol, long lo[3], long hi[3])
{
    for (int d = 0; d < 3; d++)
        lo[d] = 0, hi[d] = (long)vol->dims[d] - 1;
}

/* The box widened by `margin` samples (past the border only with cap, by one more). */
static void widen(const iso_volume *vol, long margin, int cap, long lo[3], long hi[3])
{
    for (int d = 0; d < 3; d++) {
        long last = (long)vol->dims[d] - 1;
        lo[d] -= margin;
        hi[d] += margin;
        long low = cap ? -(margin + 1) : 0, high = cap ? last + margin + 1 : last;
        if (cap && lo[d] <= 0)
            lo[d] = low;
        if (cap && hi[d] >= last)
            hi[d] = high;
        lo[d] = lo[d] < low ? low : lo[d];
        hi[d] = hi[d] > high ? high : hi[d];
    }
}

/* PASS 2 with smoothing (or a fractional layer smoothed): the field's own surface at 0.5. */
static int march_smoothed(const iso_segmentation *seg, size_t s, const iso_seg_params *p, iso_mesh *mesh,
                          iso_extract_stats *stats, iso_error *err)
{
    const iso_segment *segment = &seg->segments[s];
    const iso_seg_layer *layer = &seg->layers[segment->layer];
    long lo[3], hi[3];
    if (layer->kind == ISO_SEG_FRACTIONAL)
        whole_box(layer->vol, lo, hi);
    else if (!boundary_box(layer, segment->value, p->cap, lo, hi)) {
        iso_mesh_clear(mesh);
        return 0;
    }
    long margin = 0;
    for (int d = 0; d < 3; d++) {
        long r = (long)ceil(3 * p->smoothing / layer->vol->spacing[d]);
        margin = r > margin ? r : margin;
    }
    widen(layer->vol, margin, p->cap, lo, hi);
    iso_volume *field;
    int rc = iso_seg_field(seg, s, lo, hi, p->smoothing, p->cap, &field, err);
    if (rc)
        return rc;
    rc = iso_extract_exact(field, 0.5, p->space, p->threads, mesh, stats, err);
    iso_vol_destroy(field);
    if (rc)
        return rc;
    if (p->space == ISO_SPACE_INDEX)
        for (size_t v = 0; v < mesh->vertex_count; v++)
            for (int d = 0; d < 3; d++)
                mesh->positions[3 * v + d] += (float)lo[d];
    return 0;
}

static int check(const iso_segmentation *seg, size_t s, const iso_seg_params *p, iso_error *err)
{
    if (s >= seg->segment_count)
        return iso_error_set(err, ISO_E_ARGUMENT, "no segment %zu (there are %zu)", s, seg->segment_count);
    if (!(p->smoothing >= 0) || !isfinite(p->smoothing))
        return iso_error_set(err, ISO_E_ARGUMENT, "smoothing must be a finite number of mm >= 0");
    const iso_seg_layer *layer = &seg->layers[seg->segments[s].layer];
    if (!layer->tree || (layer->kind == ISO_SEG_LABELS && !layer->tree->labels))
        return iso_error_set(err, ISO_E_INTERNAL, "segment %u's layer has no hierarchy with label sets",
                             seg->segments[s].number);
    return 0;
}

int iso_seg_extract(const iso_segmentation *seg, size_t s, const iso_seg_params *params, iso_mesh *mesh,
                    iso_extract_stats *stats, iso_error *err)
{
    iso_extract_stats local;
    double start = iso_clock_ms();
    if (!stats)
        stats = &local;
    memset(stats, 0, sizeof *stats);
    int rc = check(seg, s, params, err);
    if (rc)
        return rc;
    const iso_segment *segment = &seg->segments[s];
    const iso_seg_layer *layer = &seg->layers[segment->layer];
    if (params->smoothing > 0)
        rc = march_smoothed(seg, s, params, mesh, stats, err);
    else if (layer->kind == ISO_SEG_LABELS)
        rc = iso_extract_label(layer->tree, segment->value, params->cap, params->space, params->threads, mesh, stats, err);
    else {
        iso_extract_params ep = {.level = layer->max_fraction / 2, .cap = params->cap, .space = params->space,
                                 .threads = params->threads};
        rc = iso_extract(layer->tree, &ep, mesh, stats, err);
    }
    if (rc)
        return rc;
    stats->triangles = mesh->triangle_count;
    stats->vertices = mesh->vertex_count;
    stats->extract_ms = iso_clock_ms() - start;
    return 0;
}

typedef struct all_job {
    const iso_segmentation *seg;
    const size_t *which;
    size_t count;
    iso_seg_params params;
    iso_mesh *meshes;
    iso_extract_stats *stats;
    atomic_size_t next;
    atomic_int rc;
    iso_error err[ISO_PARALLEL_MAX_THREADS];
} all_job;

static void extract_share(void *context, int t, int threads)
{
    (void)threads;
    all_job *job = context;
    for (;;) {
        size_t k = atomic_fetch_add(&job->next, 1);
        if (k >= job->count || atomic_load(&job->rc))
            return;
        size_t s = job->which ? job->which[k] : k;
        int rc = iso_seg_extract(job->seg, s, &job->params, &job->meshes[k], &job->stats[k], &job->err[t]);
        if (rc) {
            int none = 0;
            atomic_compare_exchange_strong(&job->rc, &none, rc);
            return;
        }
    }
}

int iso_seg_extract_all(const iso_segmentation *seg, const size_t *which, size_t count, const iso_seg_params *params,
                        iso_mesh *meshes, iso_extract_stats *stats, iso_error *err)
{
    if (!which)
        count = seg->segment_count;
    iso_extract_stats *own = NULL;
    if (!stats && !(stats = own = calloc(count ? count : 1, sizeof *stats)))
        return iso_error_set(err, ISO_E_NOMEM, "out of memory for %zu segments' stats", count);
    all_job *job = calloc(1, sizeof *job);
    if (!job) {
        free(own);
        return iso_error_set(err, ISO_E_NOMEM, "out of memory extracting the segments");
    }
    job->seg = seg;
    job->which = which;
    job->count = count;
    job->params = *params;
    job->params.threads = 1; /* the segments are the parallel work */
    job->meshes = meshes;
    job->stats = stats;
    int threads = iso_parallel_threads(params->threads);
    if ((size_t)threads > count)
        threads = count ? (int)count : 1;
    iso_parallel_run(threads, extract_share, job);
    int rc = atomic_load(&job->rc);
    if (rc) {
        for (int t = 0; t < threads; t++)
            if (job->err[t].code == rc) {
                if (err)
                    *err = job->err[t];
                break;
            }
        for (size_t k = 0; k < count; k++)
            iso_mesh_free(&meshes[k]);
    }
    free(job);
    free(own);
    return rc;
}

int iso_seg_normals(const iso_segmentation *seg, size_t s, const iso_seg_params *params, iso_mesh *mesh,
                    int order, iso_error *err)
{
    int rc = check(seg, s, params, err);
    if (rc || !mesh->vertex_count || order == 0)
        return rc ? rc : iso_normals_compute(seg->layers[0].vol, mesh, 0, params->space, params->threads, err);
    const iso_segment *segment = &seg->segments[s];
    const iso_seg_layer *layer = &seg->layers[segment->layer];
    if (layer->kind == ISO_SEG_FRACTIONAL && params->smoothing == 0)
        return iso_normals_compute(layer->vol, mesh, order, params->space, params->threads, err);
    long lo[3], hi[3];
    if (layer->kind == ISO_SEG_FRACTIONAL)
        whole_box(layer->vol, lo, hi);
    else if (!boundary_box(layer, segment->value, params->cap, lo, hi))
        return iso_error_set(err, ISO_E_ARGUMENT, "segment %u has no surface to give normals", segment->number);
    /* The B-spline of order 4 reads two samples either side of a vertex's cell. */
    long margin = 3;
    for (int d = 0; d < 3; d++) {
        long r = (long)ceil(3 * params->smoothing / layer->vol->spacing[d]) + 3;
        margin = r > margin ? r : margin;
    }
    widen(layer->vol, margin, params->cap, lo, hi);
    iso_volume *field;
    if ((rc = iso_seg_field(seg, s, lo, hi, params->smoothing, params->cap, &field, err)))
        return rc;
    if (params->space == ISO_SPACE_WORLD) {
        rc = iso_normals_compute(field, mesh, order, params->space, params->threads, err);
        iso_vol_destroy(field);
        return rc;
    }
    /* Index space: the field's indices are the layer's less lo, on a copy of the positions
     * (the mesh's stay bit for bit). */
    iso_mesh shifted = *mesh;
    shifted.normals = NULL;
    shifted.positions = malloc(mesh->vertex_capacity * 3 * sizeof *shifted.positions);
    if (!shifted.positions) {
        iso_vol_destroy(field);
        return iso_error_set(err, ISO_E_NOMEM, "out of memory for segment %u's normals", segment->number);
    }
    for (size_t v = 0; v < mesh->vertex_count; v++)
        for (int d = 0; d < 3; d++)
            shifted.positions[3 * v + d] = mesh->positions[3 * v + d] - (float)lo[d];
    rc = iso_normals_compute(field, &shifted, order, params->space, params->threads, err);
    free(shifted.positions);
    iso_vol_destroy(field);
    if (!rc) {
        free(mesh->normals);
        mesh->normals = shifted.normals;
    }
    return rc;
}
