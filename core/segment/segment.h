/* segment.h: segmentations (label maps, 3D Slicer's .seg.nrrd, DICOM Segmentation objects):
 * their segments, named and coloured, each one's surface from the a-priori hierarchy.
 *
 * A segmentation is one or more layers on one grid, each an iso_volume, and a table of
 * segments. A labels layer is an integer label map (vol->labels): segment k is where the
 * layer equals its value, and its surface is the 0.5 iso-surface of that indicator
 * (marching cubes on the 0/1 volume: vertices at edge midpoints). A fractional layer (a
 * DICOM SEG of type FRACTIONAL) holds one segment's values 0..max_fraction, and its surface
 * is the iso-surface at max_fraction / 2, the ordinary scalar path. Layers exist because
 * segments may overlap (Slicer's layers, a BINARY SEG's overlapping segments): each layer's
 * segments do not.
 *
 * Ownership: a segmentation owns its layers' volumes and trees and its table
 * (iso_seg_destroy). Errors: ISO_E_* through iso_error, loaders' messages naming the file
 * and the place. Thread-safety: once loaded and its trees built, read-only: any number of
 * extractions may share it. Cost: a segment's surface costs its boundary bricks (the label
 * sets, hierarchy/labels.h) plus the output; the cap its bricks on the volume's border;
 * smoothing the box around its boundary bricks widened by 3 sigma. */
#ifndef ISO_SEGMENT_H
#define ISO_SEGMENT_H

#include <stddef.h>
#include <stdint.h>

#include "base/base.h"
#include "extract/extract.h"
#include "hierarchy/tree.h"
#include "io/io.h"
#include "mesh/mesh.h"
#include "volume/volume.h"

#define ISO_SEG_NAME_MAX 128
#define ISO_SEG_MAX 65535 /* segments in one segmentation */

typedef struct iso_segment {
    uint32_t number;              /* as its source numbers it: DICOM's Segment Number, the
                                   * label value of a label map, Slicer's index + 1 */
    char name[ISO_SEG_NAME_MAX];
    char category[ISO_SEG_NAME_MAX]; /* DICOM's property category (code meaning), or "" */
    char type[ISO_SEG_NAME_MAX];  /* DICOM's property type (code meaning), or "" */
    float color[3];               /* sRGB, 0..1 */
    uint32_t layer;               /* its layer */
    int64_t value;                /* its label value there (labels layers) */
    uint64_t voxels;              /* samples inside it (iso_seg_count_voxels) */
} iso_segment;

typedef enum iso_seg_layer_kind { ISO_SEG_LABELS, ISO_SEG_FRACTIONAL } iso_seg_layer_kind;

typedef struct iso_seg_layer {
    iso_volume *vol;              /* owned; labels layers have vol->labels set */
    iso_tree *tree;               /* owned, NULL until built (iso_seg_build_trees) */
    iso_seg_layer_kind kind;
    double max_fraction;          /* fractional: the value meaning 1 */
} iso_seg_layer;

typedef struct iso_segmentation {
    iso_seg_layer *layers;
    size_t layer_count;
    iso_segment *segments;        /* in the source's order */
    size_t segment_count;
    char source[32];              /* "labels", "seg.nrrd", "dicom-seg": where it came from */
} iso_segmentation;

/* An empty segmentation with room for `layers` layers (all NULL). NULL when out of memory. */
iso_segmentation *iso_seg_create(size_t layers);
/* Appends a segment (copied); 0 or ISO_E_NOMEM / ISO_E_LIMIT (over ISO_SEG_MAX). */
int iso_seg_add(iso_segmentation *seg, const iso_segment *segment, iso_error *err);
/* Frees everything it owns; NULL allowed. */
void iso_seg_destroy(iso_segmentation *seg);
/* The index of the segment numbered `number`, or -1. O(segments). */
long iso_seg_find(const iso_segmentation *seg, uint32_t number);

/* Builds the hierarchy of every layer from `first` on that has none (threads: 0 = all
 * cores; progress may be NULL). Returns the first failure's code. */
int iso_seg_build_trees(iso_segmentation *seg, size_t first, int threads, iso_progress_fn progress,
                        void *context, iso_error *err);
/* Counts each segment's samples (segment.voxels). O(samples of each layer). */
void iso_seg_count_voxels(iso_segmentation *seg);
/* A segment's volume in mm^3: its samples times the volume of a voxel (the spacing's
 * product scaled by the direction's determinant). */
double iso_seg_volume_mm3(const iso_segmentation *seg, size_t s);

/* Colours. */

/* DICOM's Recommended Display CIELab Value (three values scaled to 0..65535: L* = v0 * 100
 * / 65535, a* = v1 * 255 / 65535 - 128, b* likewise) to sRGB 0..1 (D65 white, the sRGB
 * transfer curve, clipped to the gamut). */
void iso_seg_lab_to_srgb(const uint16_t lab[3], float rgb[3]);
/* The colour of the n-th segment that names none (a fixed palette, repeated). */
void iso_seg_default_color(size_t n, float rgb[3]);
/* sRGB 0..1 to linear light (glTF's baseColorFactor). */
float iso_seg_srgb_to_linear(float c);

/* Loading. */

/* A label map's table: one segment per distinct non-zero value of vol (0 is the
 * background), numbered and named by its value ("Segment 7") with the palette's colours,
 * unless `descriptions` names an ITK-SNAP label description file (lines "IDX R G B A VIS
 * MSH \"LABEL\"", colours 0..255) or a two-column "IDX NAME" list (atlases' .txt), whose
 * labels name (and colour) the values it lists (the others keep the defaults; its label 0
 * is the background). Takes vol (sets vol->labels;
 * freed on failure too). Returns 0, ISO_E_UNSUPPORTED (not integers, too many labels),
 * ISO_E_FORMAT (a bad description file, with its line) or ISO_E_IO. */
int iso_seg_from_labels(iso_volume *vol, const char *descriptions, iso_segmentation **out, iso_error *err);

/* 1 if path names a 3D Slicer segmentation (a name ending in .seg.nrrd). */
int iso_seg_nrrd_recognises(const char *path);
/* A .seg.nrrd: its label map (3-D, or 4-D with one layer per slice of the first axis when
 * segments overlap), segments from its Segment<i>_ID/_Name/_Color/_LabelValue/_Layer
 * header keys (number i + 1; a value absent from every sample still lists the segment). */
int iso_seg_nrrd_load(const char *path, const iso_load_options *opt, iso_segmentation **out, iso_error *err);

/* 1 if path names a DICOM Segmentation: a .dcm file whose SOP class is Segmentation
 * Storage, or "DIR#UID" / "DIR" with such a series in DIR. Looks into the files. */
int iso_seg_dicom_recognises(const char *path);
/* A DICOM SEG (core/segment/dicom_seg.cc): FILE.dcm, DIR#SEG_SERIES_UID, or DIR holding one
 * SEG series; its frames placed on the grid of the CT or MR series it references, which
 * must be in the same directory (its geometry, read from its files' headers). See
 * docs/dicom.md. */
int iso_seg_dicom_load(const char *path, const iso_load_options *opt, iso_segmentation **out, iso_error *err);

/* The SeriesInstanceUID of the series the one DICOM SEG in dir references (what an
 * archive must send beside it). 0, or an error naming the file. */
int iso_seg_dicom_referenced_series(const char *dir, char *uid, size_t size, iso_error *err);

/* Any segmentation source: a .seg.nrrd, a DICOM SEG, or any other volume as a label map
 * (with ITK-SNAP descriptions when `descriptions` is not NULL). */
int iso_seg_load(const char *path, const char *descriptions, const iso_load_options *opt,
                 iso_segmentation **out, iso_error *err);

/* Surfaces. */

typedef struct iso_seg_params {
    double smoothing;   /* Gaussian sigma in mm on the indicator before marching; 0: none */
    int cap;            /* 1: closed at the volume's border (the indicator is 0 beyond it:
                         * the cap lies half a voxel outside the border samples) */
    iso_space space;    /* world mm (default) or index space */
    int threads;        /* 0 = all cores; the mesh does not depend on it */
} iso_seg_params;

/* Segment s's surface into mesh (emptied first). Without smoothing, a labels segment's is
 * marching cubes' surface of its indicator at 0.5 over its boundary bricks (the cells its
 * corners' labels split), exactly, triangle for triangle; with smoothing, the 0.5
 * iso-surface of the indicator convolved with the Gaussian, over the box of those bricks
 * widened by 3 sigma; closed wherever it does not meet the border, and with cap there too.
 * stats: cells_visited counts the cells classified, nodes_visited the bricks. Returns 0,
 * ISO_E_ARGUMENT (no such segment, a bad smoothing), ISO_E_LIMIT or ISO_E_NOMEM. */
int iso_seg_extract(const iso_segmentation *seg, size_t s, const iso_seg_params *params, iso_mesh *mesh,
                    iso_extract_stats *stats, iso_error *err);
/* Many segments' surfaces at once: those of the `count` indices in `which` (NULL: every
 * segment, count ignored) into meshes[k] (each emptied first), the segments shared among
 * params->threads, one per thread at a time; stats per mesh (may be NULL). On failure
 * every mesh is freed. */
int iso_seg_extract_all(const iso_segmentation *seg, const size_t *which, size_t count, const iso_seg_params *params,
                        iso_mesh *meshes, iso_extract_stats *stats, iso_error *err);
/* Normals of segment s's mesh (from iso_seg_extract with the same params): the gradient of
 * the order-`order` B-spline (mesh.h) of the field its surface comes from (the indicator,
 * smoothed when asked; a fractional layer's values), pointing out of the segment. */
int iso_seg_normals(const iso_segmentation *seg, size_t s, const iso_seg_params *params, iso_mesh *mesh,
                    int order, iso_error *err);

#endif
