/* table.c: a segmentation's layers and segment table: made, grown, freed, counted. */
#include "segment.h"

#include <math.h>
#include <stdlib.h>
#include <string.h>


iso_segmentation *iso_seg_create(size_t layers)
{
    iso_segmentation *seg = calloc(1, sizeof *seg);
    if (!seg)
        return NULL;
    seg->layers = calloc(layers ? layers : 1, sizeof *seg->layers);
    if (!seg->layers) {
        free(seg);
        return NULL;
    }
    seg->layer_count = layers;
    return seg;
}

int iso_seg_add(iso_segmentation *seg, const iso_segment *segment, iso_error *err)
{
    if (seg->segment_count >= ISO_SEG_MAX)
        return iso_error_set(err, ISO_E_LIMIT, "more than %u segments", ISO_SEG_MAX);
    /* Grown by doubling: the count is a power of two whenever the array is full. */
    size_t n = seg->segment_count;
    if ((n & (n - 1)) == 0) {
        iso_segment *grown = realloc(seg->segments, (n ? 2 * n : 1) * sizeof *grown);
        if (!grown)
            return iso_error_set(err, ISO_E_NOMEM, "out of memory for %zu segments", n + 1);
        seg->segments = grown;
    }
    seg->segments[seg->segment_count++] = *segment;
    return 0;
}

void iso_seg_destroy(iso_segmentation *seg)
{
    if (!seg)
        return;
    for (size_t l = 0; l < seg->layer_count; l++) {
        iso_tree_destroy(seg->layers[l].tree);
        iso_vol_destroy(seg->layers[l].vol);
    }
    free(seg->layers);
    free(seg->segments);
    free(seg);
}

long iso_seg_find(const iso_segmentation *seg, uint32_t number)
{
    for (size_t s = 0; s < seg->segment_count; s++)
        if (seg->segments[s].number == number)
            return (long)s;
    return -1;
}

int iso_seg_build_trees(iso_segmentation *seg, size_t first, int threads, iso_progress_fn progress,
                        void *context, iso_error *err)
{
    for (size_t l = first; l < seg->layer_count; l++) {
        iso_seg_layer *layer = &seg->layers[l];
        if (layer->tree)
            continue;
        int rc = iso_tree_build(layer->vol, threads, progress, context, &layer->tree, err);
        if (rc)
            return rc;
    }
    return 0;
}

/* A labels layer's samples per label value: a run of equal samples costs a compare each,
 * a new value one look-up of its segment. */
static void count_labels(iso_segmentation *seg, size_t l)
{
    const iso_volume *vol = seg->layers[l].vol;
    size_t n = iso_vol_count(vol);
    long current = -1;
    double last = NAN;
    for (size_t i = 0; i < n; i++) {
        double v = iso_vol_sample(vol, i);
        if (v != last) {
            last = v;
            current = -1;
            for (size_t s = 0; s < seg->segment_count; s++)
                if (seg->segments[s].layer == l && (double)seg->segments[s].value == v) {
                    current = (long)s;
                    break;
                }
        }
        if (current >= 0)
            seg->segments[current].voxels++;
    }
}

void iso_seg_count_voxels(iso_segmentation *seg)
{
    for (size_t s = 0; s < seg->segment_count; s++)
        seg->segments[s].voxels = 0;
    for (size_t l = 0; l < seg->layer_count; l++) {
        const iso_seg_layer *layer = &seg->layers[l];
        if (layer->kind == ISO_SEG_LABELS) {
            count_labels(seg, l);
            continue;
        }
        /* A fractional layer: the samples its surface encloses, those above half. */
        uint64_t above = 0;
        size_t n = iso_vol_count(layer->vol);
        for (size_t i = 0; i < n; i++)
            above += iso_vol_sample(layer->vol, i) > layer->max_fraction / 2;
        for (size_t s = 0; s < seg->segment_count; s++)
            if (seg->segments[s].layer == l)
                seg->segments[s].voxels = above;
    }
}

double iso_seg_volume_mm3(const iso_segmentation *seg, size_t s)
{
    const iso_volume *vol = seg->layers[seg->segments[s].layer].vol;
    double a[3][3], inv[3][3], det = 0;
    iso_vol_frame(vol, a, inv, &det); /* det A is a voxel's volume (spacing and shear) */
    return (double)seg->segments[s].voxels * fabs(det);
}
