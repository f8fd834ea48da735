/* test_segment.c: segmentations (core/segment, hierarchy/labels.h): the per-brick label
 * sets against scans of the bricks, in memory and through the hierarchy file; each
 * segment's surface against marching cubes' full scan of its indicator at 0.5, triangle
 * for triangle, on random label maps across brick boundaries; the cap closing segments at
 * the border; enclosed volumes within 1% of the voxel count on shapes built by hand;
 * smoothing closed; every segment at once equal to one at a time; Slicer's .seg.nrrd keys
 * and ITK-SNAP's label descriptions; CIELab colours; DICOM SEGs (BINARY, FRACTIONAL,
 * LABELMAP, overlapping) written by tests/support/dicom_seg.py give the label map's own
 * meshes, and bad ones precise errors. */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

#include "check.h"
#include "hierarchy/labels.h"
#include "segment/segment.h"
#include "surface.h"

/* A label map of random blobs: labels 0..labels-1, each sample the label of the nearest
 * of a few random centres (regions with boundaries at every angle). */
static iso_volume *blob_labels(const size_t n[3], iso_voxel_type type, int labels, int centres)
{
    iso_volume *vol = surface_make_volume(n[0], n[1], n[2], type);
    double c[64][3];
    int label[64];
    for (int k = 0; k < centres; k++) {
        for (int d = 0; d < 3; d++)
            c[k][d] = surface_uniform() * (double)n[d];
        label[k] = (int)(surface_uniform() * labels);
    }
    for (size_t z = 0; z < n[2]; z++)
        for (size_t y = 0; y < n[1]; y++)
            for (size_t x = 0; x < n[0]; x++) {
                int best = 0;
                double bd = INFINITY;
                for (int k = 0; k < centres; k++) {
                    double dx = (double)x - c[k][0], dy = (double)y - c[k][1], dz = (double)z - c[k][2];
                    double d = dx * dx + dy * dy + dz * dz;
                    if (d < bd)
                        bd = d, best = k;
                }
                iso_vol_set(vol, x, y, z, label[best]);
            }
    vol->labels = 1;
    iso_vol_update_stats(vol);
    return vol;
}

/* Every brick's set against a scan of its samples; the per-label lists against the sets. */
static void check_sets(const iso_volume *vol, const iso_label_sets *s)
{
    uint32_t count[3];
    iso_bricks_count(vol, count);
    size_t wrong = 0;
    for (uint32_t k = 0; k < count[2]; k++)
        for (uint32_t j = 0; j < count[1]; j++)
            for (uint32_t i = 0; i < count[0]; i++) {
                uint32_t b[3] = {i, j, k};
                size_t lo[3], hi[3], at = ((size_t)k * count[1] + j) * count[0] + i;
                iso_bricks_box(vol, b, lo, hi);
                char *seen = calloc(s->label_count, 1);
                for (size_t z = lo[2]; z <= hi[2]; z++)
                    for (size_t y = lo[1]; y <= hi[1]; y++)
                        for (size_t x = lo[0]; x <= hi[0]; x++)
                            seen[iso_label_index(s, (int64_t)iso_vol_get(vol, x, y, z))] = 1;
                uint32_t n = 0;
                for (uint32_t l = 0; l < s->label_count; l++) {
                    n += seen[l];
                    wrong += seen[l] != iso_label_brick_has(s, at, l);
                }
                wrong += n != iso_label_brick_count(s, at);
                free(seen);
            }
    CHECK_EQ(wrong, 0);
    for (uint32_t l = 0; l < s->label_count; l++)
        for (uint32_t h = s->holding_start[l]; h < s->holding_start[l + 1]; h++) {
            uint32_t at = s->holding[h] & ~ISO_LABEL_MIXED;
            CHECK(iso_label_brick_has(s, at, l));
            CHECK(!!(s->holding[h] & ISO_LABEL_MIXED) == (iso_label_brick_count(s, at) > 1));
            if (h > s->holding_start[l])
                CHECK((s->holding[h - 1] & ~ISO_LABEL_MIXED) < at);
        }
}

static void test_label_sets_match_scans(void)
{
    static const size_t sizes[][3] = {{37, 29, 23}, {9, 9, 9}, {2, 3, 17}, {41, 8, 33}};
    static const iso_voxel_type types[] = {ISO_U8, ISO_I16, ISO_U16, ISO_I32};
    for (int t = 0; t < 4 && !check_failed(); t++) {
        /* A few labels (lists) and many in a small volume (dense bricks: bitmaps). */
        iso_volume *vol = blob_labels(sizes[t], types[t], t == 3 ? 300 : 6, t == 3 ? 64 : 12);
        iso_tree *tree = surface_build(vol);
        CHECK(tree->labels != NULL);
        if (tree->labels)
            check_sets(vol, tree->labels);
        iso_tree_destroy(tree);
        iso_vol_destroy(vol);
    }
}

static void test_label_sets_through_the_file(void)
{
    size_t n[3] = {45, 30, 26};
    iso_volume *vol = blob_labels(n, ISO_U8, 9, 20);
    iso_tree *tree = surface_build(vol), *back = NULL;
    iso_error err;
    char path[4096];
    snprintf(path, sizeof path, "%s/labels.isotree", check_temp_dir());
    CHECK_OK(iso_tree_save(tree, path, &err), &err);
    CHECK_OK(iso_tree_load(vol, path, &back, &err), &err);
    if (back && back->labels) {
        const iso_label_sets *a = tree->labels, *b = back->labels;
        CHECK_EQ(a->label_count, b->label_count);
        CHECK(memcmp(a->values, b->values, a->label_count * 8) == 0);
        CHECK(memcmp(a->offset, b->offset, (a->brick_count + 1) * 4) == 0);
        CHECK(memcmp(a->words, b->words, a->word_count * 2) == 0);
        CHECK(memcmp(a->holding, b->holding, a->holding_start[a->label_count] * 4) == 0);
    }
    iso_tree_destroy(back);
    /* The same samples as a plain volume: its file has no sets, and a label volume refuses it. */
    vol->labels = 0;
    iso_tree *plain = surface_build(vol);
    CHECK(plain->labels == NULL);
    CHECK_OK(iso_tree_save(plain, path, &err), &err);
    vol->labels = 1;
    CHECK_EQ(iso_tree_load(vol, path, &back, &err), ISO_E_STALE);
    CHECK(strstr(err.message, "label sets") != NULL);
    iso_tree_destroy(plain);
    iso_tree_destroy(tree);
    iso_vol_destroy(vol);
}

/* A segmentation of vol (taken) whose trees are built. */
static iso_segmentation *segmentation_of(iso_volume *vol)
{
    iso_segmentation *seg = NULL;
    iso_error err;
    CHECK_OK(iso_seg_from_labels(vol, NULL, &seg, &err), &err);
    if (seg)
        CHECK_OK(iso_seg_build_trees(seg, 0, 2, NULL, NULL, &err), &err);
    return seg;
}

/* Segment s's indicator as a u8 volume of 0 and 1. */
static iso_volume *indicator(const iso_segmentation *seg, size_t s)
{
    const iso_volume *vol = seg->layers[0].vol;
    iso_volume *ind = surface_make_volume(vol->dims[0], vol->dims[1], vol->dims[2], ISO_U8);
    for (size_t i = 0; i < iso_vol_count(vol); i++)
        ((uint8_t *)ind->data)[i] = iso_vol_sample(vol, i) == (double)seg->segments[s].value;
    memcpy(ind->spacing, vol->spacing, sizeof ind->spacing);
    memcpy(ind->origin, vol->origin, sizeof ind->origin);
    memcpy(ind->direction, vol->direction, sizeof ind->direction);
    iso_vol_update_stats(ind);
    return ind;
}

static void check_same(const iso_mesh *a, const iso_mesh *b, const char *what)
{
    CHECKF(a->triangle_count == b->triangle_count && a->vertex_count == b->vertex_count,
           "%s: %zu triangles %zu vertices, expected %zu, %zu", what, a->triangle_count, a->vertex_count,
           b->triangle_count, b->vertex_count);
    if (a->triangle_count == b->triangle_count) {
        surface_triangle *x = surface_canonical_triangles(a), *y = surface_canonical_triangles(b);
        CHECKF(memcmp(x, y, a->triangle_count * sizeof *x) == 0, "%s: other triangles", what);
        free(x);
        free(y);
    }
}

static void test_segments_match_full_scan_of_indicator(void)
{
    static const size_t sizes[][3] = {{37, 29, 23}, {17, 18, 19}, {26, 9, 40}};
    static const iso_voxel_type types[] = {ISO_U8, ISO_U16, ISO_I32};
    for (int t = 0; t < 3 && !check_failed(); t++) {
        iso_segmentation *seg = segmentation_of(blob_labels(sizes[t], types[t], 7, 16));
        if (!seg)
            return;
        for (size_t s = 0; s < seg->segment_count && !check_failed(); s++) {
            iso_volume *ind = indicator(seg, s);
            iso_mesh want, got;
            iso_mesh_init(&want);
            iso_mesh_init(&got);
            iso_error err;
            iso_extract_stats st;
            CHECK_OK(iso_extract_full_scan(ind, 0.5, ISO_SPACE_INDEX, &want, NULL, &err), &err);
            for (int threads = 1; threads <= 2; threads++) {
                iso_seg_params p = {.space = ISO_SPACE_INDEX, .threads = threads};
                CHECK_OK(iso_seg_extract(seg, s, &p, &got, &st, &err), &err);
                check_same(&got, &want, seg->segments[s].name);
                CHECK(st.cells_visited > 0 || got.triangle_count == 0);
            }
            /* World positions: the index map, as for any volume. */
            iso_mesh world;
            iso_mesh_init(&world);
            iso_seg_params pw = {.space = ISO_SPACE_WORLD};
            CHECK_OK(iso_extract_full_scan(ind, 0.5, ISO_SPACE_WORLD, &want, NULL, &err), &err);
            CHECK_OK(iso_seg_extract(seg, s, &pw, &world, NULL, &err), &err);
            check_same(&world, &want, "world");
            iso_mesh_free(&world);
            iso_mesh_free(&want);
            iso_mesh_free(&got);
            iso_vol_destroy(ind);
        }
        iso_seg_destroy(seg);
    }
}

static void test_all_segments_at_once(void)
{
    size_t n[3] = {40, 33, 27};
    iso_segmentation *seg = segmentation_of(blob_labels(n, ISO_U8, 12, 30));
    if (!seg)
        return;
    iso_mesh *all = calloc(seg->segment_count, sizeof *all);
    iso_error err;
    iso_seg_params p = {.cap = 1, .threads = 2};
    CHECK_OK(iso_seg_extract_all(seg, NULL, 0, &p, all, NULL, &err), &err);
    for (size_t s = 0; s < seg->segment_count; s++) {
        iso_mesh one;
        iso_mesh_init(&one);
        CHECK_OK(iso_seg_extract(seg, s, &p, &one, NULL, &err), &err);
        check_same(&all[s], &one, "all at once");
        CHECK(all[s].triangle_count > 0);
        iso_mesh_free(&one);
        iso_mesh_free(&all[s]);
    }
    free(all);
    iso_seg_destroy(seg);
}

/* The census of a segment's mesh in index space: closed with cap. */
static iso_census census_of(const iso_segmentation *seg, const iso_mesh *m, iso_space space)
{
    iso_census c;
    iso_error err;
    CHECK_OK(iso_census_compute(seg->layers[0].vol, m, space, &c, &err), &err);
    return c;
}

static void test_cap_closes_segments_on_the_border(void)
{
    size_t n[3] = {30, 21, 19};
    iso_segmentation *seg = segmentation_of(blob_labels(n, ISO_U8, 5, 10));
    if (!seg)
        return;
    for (size_t s = 0; s < seg->segment_count; s++) {
        iso_mesh m;
        iso_mesh_init(&m);
        iso_error err;
        iso_seg_params p = {.cap = 1, .space = ISO_SPACE_INDEX};
        CHECK_OK(iso_seg_extract(seg, s, &p, &m, NULL, &err), &err);
        iso_census c = census_of(seg, &m, ISO_SPACE_INDEX);
        CHECKF(c.closed, "segment %u: open %zu boundary %zu nonmanifold %zu misoriented %zu degenerate %zu",
               seg->segments[s].number, c.open_edges, c.boundary_edges, c.nonmanifold_edges, c.misoriented_edges,
               c.degenerate_triangles);
        iso_mesh_free(&m);
    }
    iso_seg_destroy(seg);
}

/* Shapes by hand: a box and a ball, one inside and one touching the border, with anisotropic
 * spacing: enclosed volume within 1% of voxels x voxel volume; closed. */
static void test_enclosed_volumes_of_hand_made_shapes(void)
{
    size_t n[3] = {64, 60, 48};
    iso_volume *vol = surface_make_volume(n[0], n[1], n[2], ISO_U8);
    vol->spacing[0] = 0.8, vol->spacing[1] = 0.7, vol->spacing[2] = 1.5;
    for (size_t z = 0; z < n[2]; z++)
        for (size_t y = 0; y < n[1]; y++)
            for (size_t x = 0; x < n[0]; x++) {
                int box = x >= 5 && x < 35 && y >= 6 && y < 40 && z >= 3 && z < 25;
                double dx = (x - 44.0) * 0.8, dy = (y - 40.0) * 0.7, dz = (z - 30.0) * 1.5;
                int ball = dx * dx + dy * dy + dz * dz <= 14.0 * 14.0;
                int slab = z >= 40; /* touches the border on five sides */
                iso_vol_set(vol, x, y, z, slab ? 3 : ball ? 2 : box ? 1 : 0);
            }
    iso_vol_update_stats(vol);
    iso_segmentation *seg = segmentation_of(vol);
    if (!seg)
        return;
    iso_seg_count_voxels(seg);
    CHECK_EQ(seg->segment_count, 3);
    for (size_t s = 0; s < seg->segment_count; s++) {
        iso_mesh m;
        iso_mesh_init(&m);
        iso_error err;
        iso_seg_params p = {.cap = 1};
        CHECK_OK(iso_seg_extract(seg, s, &p, &m, NULL, &err), &err);
        iso_census c = census_of(seg, &m, ISO_SPACE_WORLD);
        CHECK(c.closed);
        double enclosed = fabs(iso_mesh_enclosed_volume(&m)), want = iso_seg_volume_mm3(seg, s);
        CHECKF(fabs(enclosed - want) <= 0.01 * want, "segment %s: enclosed %.1f mm3, voxels give %.1f",
               seg->segments[s].name, enclosed, want);
        /* Smoothed (1 mm): still closed, and near the same volume (a Gaussian shrinks convex
         * shapes a little). */
        p.smoothing = 1.0;
        CHECK_OK(iso_seg_extract(seg, s, &p, &m, NULL, &err), &err);
        c = census_of(seg, &m, ISO_SPACE_WORLD);
        CHECKF(c.closed, "smoothed %s: open %zu boundary %zu", seg->segments[s].name, c.open_edges, c.boundary_edges);
        enclosed = fabs(iso_mesh_enclosed_volume(&m));
        CHECKF(fabs(enclosed - want) <= 0.05 * want, "smoothed %s: enclosed %.1f mm3, voxels give %.1f",
               seg->segments[s].name, enclosed, want);
        /* Normals out of the segment: a vertex moved along its normal leaves it. */
        CHECK_OK(iso_seg_normals(seg, s, &p, &m, 4, &err), &err);
        CHECK(m.normals != NULL);
        iso_mesh_free(&m);
    }
    iso_seg_destroy(seg);
}

static void test_seg_nrrd_keys_and_layers(void)
{
    /* Two layers (overlapping segments), u8, 4-D: the first axis holds the layers. */
    char path[4096];
    snprintf(path, sizeof path, "%s/two.seg.nrrd", check_temp_dir());
    const char *header = "NRRD0004\n"
                         "type: unsigned char\ndimension: 4\nsizes: 2 12 11 10\n"
                         "space: left-posterior-superior\n"
                         "space directions: none (0.5,0,0) (0,0.5,0) (0,0,2)\n"
                         "space origin: (10,20,30)\nkinds: list domain domain domain\nencoding: raw\n"
                         "Segment0_ID:=Segment_1\nSegment0_Name:=liver\nSegment0_Color:=0.8 0.4 0.2\n"
                         "Segment0_LabelValue:=1\nSegment0_Layer:=0\n"
                         "Segment1_ID:=Segment_2\nSegment1_Name:=tumour\nSegment1_Color:=1 1 0\n"
                         "Segment1_LabelValue:=1\nSegment1_Layer:=1\n"
                         "Segment2_Name:=kidney\nSegment2_LabelValue:=2\nSegment2_Layer:=0\n\n";
    size_t count = 12 * 11 * 10;
    unsigned char *data = calloc(2 * count, 1);
    for (size_t z = 2; z < 8; z++)
        for (size_t y = 2; y < 9; y++)
            for (size_t x = 1; x < 11; x++) {
                size_t i = (z * 11 + y) * 12 + x;
                data[2 * i] = x < 6 ? 1 : 2;                   /* liver | kidney */
                data[2 * i + 1] = x >= 3 && x < 5 && y < 5;     /* tumour inside the liver */
            }
    check_write_file(path, header, strlen(header), data, 2 * count);
    iso_segmentation *seg = NULL;
    iso_error err;
    CHECK_OK(iso_seg_load(path, NULL, NULL, &seg, &err), &err);
    if (seg) {
        CHECK_EQ(seg->layer_count, 2);
        CHECK_EQ(seg->segment_count, 3);
        CHECK(strcmp(seg->segments[0].name, "liver") == 0 && seg->segments[0].number == 1);
        CHECK(strcmp(seg->segments[1].name, "tumour") == 0 && seg->segments[1].layer == 1);
        CHECK(strcmp(seg->segments[2].name, "kidney") == 0 && seg->segments[2].value == 2);
        CHECK_NEAR(seg->segments[0].color[1], 0.4, 1e-6);
        CHECK_NEAR(seg->layers[0].vol->spacing[2], 2, 0);
        CHECK_NEAR(seg->layers[1].vol->origin[1], 20, 0);
        CHECK_OK(iso_seg_build_trees(seg, 0, 1, NULL, NULL, &err), &err);
        iso_seg_count_voxels(seg);
        CHECK_EQ(seg->segments[0].voxels, 6 * 7 * 5);
        CHECK_EQ(seg->segments[1].voxels, 6 * 3 * 2);
        CHECK_EQ(seg->segments[2].voxels, 6 * 7 * 5);
        for (size_t s = 0; s < 3; s++) {
            iso_mesh m;
            iso_mesh_init(&m);
            iso_seg_params p = {.cap = 1};
            CHECK_OK(iso_seg_extract(seg, s, &p, &m, NULL, &err), &err);
            CHECK(census_of(seg, &m, ISO_SPACE_WORLD).closed);
            iso_mesh_free(&m);
        }
        iso_seg_destroy(seg);
    }
    free(data);
    /* A bad layer number is a precise error. */
    snprintf(path, sizeof path, "%s/bad.seg.nrrd", check_temp_dir());
    const char *bad = "NRRD0004\ntype: uint8\ndimension: 3\nsizes: 3 3 3\nencoding: raw\n"
                      "Segment0_Name:=a\nSegment0_Layer:=4\n\n";
    unsigned char zeros[27] = {0};
    check_write_file(path, bad, strlen(bad), zeros, sizeof zeros);
    CHECK_EQ(iso_seg_load(path, NULL, NULL, &seg, &err), ISO_E_FORMAT);
    CHECK(strstr(err.message, "Segment0_Layer is 4") != NULL);
}

static void test_itksnap_descriptions(void)
{
    char path[4096];
    snprintf(path, sizeof path, "%s/labels.txt", check_temp_dir());
    const char *text = "################################################\n"
                       "# ITK-SnAP Label Description File\n"
                       "################################################\n"
                       "    0     0    0    0        0  0  0    \"Clear Label\"\n"
                       "    1   255    0    0        1  1  1    \"Left kidney\"\n"
                       "    3     0  128  255      0.5  1  1    \"Spleen, \\\"the\\\" one\"\n";
    check_write_file(path, text, strlen(text), NULL, 0);
    size_t n[3] = {6, 6, 6};
    iso_volume *vol = surface_make_volume(n[0], n[1], n[2], ISO_U8);
    iso_vol_set(vol, 1, 1, 1, 1);
    iso_vol_set(vol, 2, 2, 2, 3);
    iso_vol_set(vol, 3, 3, 3, 7);
    iso_vol_update_stats(vol);
    iso_segmentation *seg = NULL;
    iso_error err;
    CHECK_OK(iso_seg_from_labels(vol, path, &seg, &err), &err);
    if (seg) {
        CHECK_EQ(seg->segment_count, 3);
        CHECK(strcmp(seg->segments[0].name, "Left kidney") == 0);
        CHECK_NEAR(seg->segments[0].color[0], 1, 0);
        CHECK(strcmp(seg->segments[1].name, "Spleen, \\\"the\\\" one") == 0);
        CHECK_NEAR(seg->segments[1].color[2], 1, 0);
        CHECK(strcmp(seg->segments[2].name, "Segment 7") == 0); /* not described */
        iso_seg_destroy(seg);
    }
    /* The two-column form atlases ship (MRIcron's .nii.txt). */
    const char *columns = "0\tUnclassified\n1\tMiddle_cerebellar_peduncle\n7 Fornix (body)\n";
    check_write_file(path, columns, strlen(columns), NULL, 0);
    vol = surface_make_volume(n[0], n[1], n[2], ISO_U8);
    iso_vol_set(vol, 1, 1, 1, 1);
    iso_vol_set(vol, 2, 2, 2, 7);
    CHECK_OK(iso_seg_from_labels(vol, path, &seg, &err), &err);
    if (seg) {
        CHECK(strcmp(seg->segments[0].name, "Middle_cerebellar_peduncle") == 0);
        CHECK(strcmp(seg->segments[1].name, "Fornix (body)") == 0);
        iso_seg_destroy(seg);
    }
    const char *broken = "1 255 0 0 1 1 1 \"ok\"\n2 300 0 0 1 1 1 \"too red\"\n";
    check_write_file(path, broken, strlen(broken), NULL, 0);
    vol = surface_make_volume(n[0], n[1], n[2], ISO_U8);
    iso_vol_set(vol, 1, 1, 1, 2);
    CHECK_EQ(iso_seg_from_labels(vol, path, &seg, &err), ISO_E_FORMAT);
    CHECK(strstr(err.message, "labels.txt:2") != NULL);
    /* Float volumes are no label maps. */
    vol = surface_make_volume(n[0], n[1], n[2], ISO_F32);
    CHECK_EQ(iso_seg_from_labels(vol, NULL, &seg, &err), ISO_E_UNSUPPORTED);
}

/* CIELab of known sRGB colours, as DICOM scales it. */
static void test_cielab_to_srgb(void)
{
    static const struct {
        double L, a, b;
        float rgb[3];
    } cases[] = {{100, 0, 0, {1, 1, 1}}, {0, 0, 0, {0, 0, 0}}, {53.2408, 80.0925, 67.2032, {1, 0, 0}},
                 {87.7347, -86.1827, 83.1793, {0, 1, 0}}, {32.2970, 79.1875, -107.8602, {0, 0, 1}},
                 {53.585, 0.003, -0.006, {0.5f, 0.5f, 0.5f}}};
    for (size_t i = 0; i < sizeof cases / sizeof cases[0]; i++) {
        uint16_t lab[3] = {(uint16_t)lround(cases[i].L * 65535 / 100), (uint16_t)lround((cases[i].a + 128) * 65535 / 255),
                           (uint16_t)lround((cases[i].b + 128) * 65535 / 255)};
        float rgb[3];
        iso_seg_lab_to_srgb(lab, rgb);
        for (int c = 0; c < 3; c++)
            CHECK_NEAR(rgb[c], cases[i].rgb[c], 0.01);
    }
    CHECK_NEAR(iso_seg_srgb_to_linear(0.5f), 0.214, 0.001);
}


/* The folder of the phantom's SEG variant `name` (dicom_seg.py variants: binary,
 * fractional, labelmap, overlap, bad-*), every variant written once by one run of the
 * script; NULL after a skip line without pydicom. Tests may move files out of a copy. */
static const char *write_seg(const char *name)
{
    static char root[4096], dir[4400];
    static int state; /* 0 not tried, 1 written, -1 cannot */
    if (!state) {
        state = -1;
        if (system("/usr/bin/python3 -c 'import pydicom, numpy' > /dev/null 2>&1") == 0) {
            snprintf(root, sizeof root, "%s/segs", check_temp_dir());
            char cmd[8192];
            snprintf(cmd, sizeof cmd, "/usr/bin/python3 tests/support/dicom_seg.py variants %s > /dev/null 2>&1", root);
            CHECK_EQ(system(cmd), 0);
            state = 1;
        }
    }
    if (state < 0) {
        check_skip("needs Debian's python3-pydicom and python3-numpy");
        return NULL;
    }
    snprintf(dir, sizeof dir, "%s/%s", root, name);
    return dir;
}

/* Every segment of a and b (by number) has the same mesh, triangle for triangle. */
static void check_same_segmentations(iso_segmentation *a, iso_segmentation *b, int cap)
{
    iso_error err;
    CHECK_OK(iso_seg_build_trees(a, 0, 1, NULL, NULL, &err), &err);
    CHECK_OK(iso_seg_build_trees(b, 0, 1, NULL, NULL, &err), &err);
    for (size_t s = 0; s < a->segment_count && !check_failed(); s++) {
        long t = iso_seg_find(b, a->segments[s].number);
        CHECK(t >= 0);
        if (t < 0)
            continue;
        iso_mesh x, y;
        iso_mesh_init(&x);
        iso_mesh_init(&y);
        iso_seg_params p = {.cap = cap};
        CHECK_OK(iso_seg_extract(a, s, &p, &x, NULL, &err), &err);
        CHECK_OK(iso_seg_extract(b, (size_t)t, &p, &y, NULL, &err), &err);
        CHECK(x.triangle_count > 0);
        check_same(&x, &y, a->segments[s].name);
        iso_mesh_free(&x);
        iso_mesh_free(&y);
    }
}

static iso_segmentation *load_or_fail(const char *path, const char *descriptions)
{
    iso_segmentation *seg = NULL;
    iso_error err;
    CHECK_OK(iso_seg_load(path, descriptions, NULL, &seg, &err), &err);
    return seg;
}

static void test_dicom_seg_gives_the_label_maps_meshes(void)
{
    static const char *const kinds[] = {"binary", "fractional", "labelmap"};
    static const char *const sources[] = {"BINARY", "FRACTIONAL", "LABELMAP"};
    for (int k = 0; k < 3 && !check_failed(); k++) {
        const char *dir = write_seg(kinds[k]);
        if (!dir)
            return;
        char ct[4200], labels[4200], names[4200];
        snprintf(ct, sizeof ct, "%s/ct", dir);
        snprintf(labels, sizeof labels, "%s/labels.nrrd", dir);
        snprintf(names, sizeof names, "%s/labels.txt", dir);
        CHECK(iso_seg_dicom_recognises(ct));
        CHECK(!iso_seg_dicom_recognises(labels));
        iso_segmentation *seg = load_or_fail(ct, NULL), *map = load_or_fail(labels, names);
        if (!seg || !map)
            return;
        CHECK(strcmp(seg->source, "dicom-seg") == 0);
        CHECKF(seg->segment_count == 3, "%s: %zu segments", sources[k], seg->segment_count);
        CHECK(strcmp(seg->segments[0].name, "shell") == 0 && strcmp(seg->segments[1].name, "core") == 0);
        CHECK(strcmp(seg->segments[1].type, "Bone marrow") == 0 && strcmp(seg->segments[2].category, "Physical object") == 0);
        CHECK_EQ(seg->layer_count, k == 1 ? 3 : 1);
        /* CIELab (34885, 53151, 50000) is sRGB (253, 13, 2): the shell's colour. */
        CHECK_NEAR(seg->segments[0].color[0] * 255, 253, 1.5);
        CHECK_NEAR(seg->segments[0].color[1] * 255, 13, 1.5);
        /* The grid is the CT's: origin, spacing. */
        CHECK_NEAR(seg->layers[0].vol->origin[2], 30, 1e-9);
        CHECK_NEAR(seg->layers[0].vol->spacing[2], 1.25, 1e-9);
        iso_seg_count_voxels(seg);
        iso_seg_count_voxels(map);
        for (size_t s = 0; s < 3; s++)
            CHECK_EQ(seg->segments[s].voxels, map->segments[s].voxels);
        check_same_segmentations(seg, map, 0);
        check_same_segmentations(seg, map, 1);
        iso_seg_destroy(seg);
        iso_seg_destroy(map);
    }
}

static void test_overlapping_binary_segments_take_layers(void)
{
    const char *dir = write_seg("overlap");
    if (!dir)
        return;
    char ct[4200];
    snprintf(ct, sizeof ct, "%s/ct", dir);
    iso_segmentation *seg = load_or_fail(ct, NULL);
    if (!seg)
        return;
    CHECK_EQ(seg->segment_count, 4);
    CHECK_EQ(seg->layer_count, 2);
    CHECK(seg->segments[3].layer != seg->segments[1].layer && seg->segments[3].layer != seg->segments[0].layer);
    iso_seg_count_voxels(seg);
    CHECK_EQ(seg->segments[3].voxels, 8 * 8 * 8);
    iso_error err;
    CHECK_OK(iso_seg_build_trees(seg, 0, 1, NULL, NULL, &err), &err);
    iso_mesh m;
    iso_mesh_init(&m);
    iso_seg_params p = {.cap = 1};
    CHECK_OK(iso_seg_extract(seg, 3, &p, &m, NULL, &err), &err);
    CHECK(census_of(seg, &m, ISO_SPACE_WORLD).closed);
    /* An 8^3 box: marching cubes bevels its 12 edges (1/8 voxel of section each) and its
     * corners, 12.5 of 512 voxels. */
    double bevelled = (512 - 12 * 8 * 0.125 + 8 * (0.125 - 1.0 / 48)) / 512 * iso_seg_volume_mm3(seg, 3);
    CHECK_NEAR(fabs(iso_mesh_enclosed_volume(&m)), bevelled, 0.002 * bevelled);
    iso_mesh_free(&m);
    iso_seg_destroy(seg);
}

static void test_bad_segs_are_precise_errors(void)
{
    static const struct {
        const char *flag, *says;
        int code;
    } cases[] = {{"bad-frames", "missing frames", ISO_E_TRUNCATED},
                 {"bad-segment", "refers to segment 9", ISO_E_FORMAT},
                 {"bad-position", "lies on no slice of the referenced series", ISO_E_FORMAT},
                 {"bad-spacing", "does not match the referenced series", ISO_E_FORMAT},
                 {"bad-overlap", "overlapping segments in a label map SEG", ISO_E_FORMAT}};
    for (size_t i = 0; i < sizeof cases / sizeof cases[0]; i++) {
        const char *dir = write_seg(cases[i].flag);
        if (!dir)
            return;
        char ct[4200];
        snprintf(ct, sizeof ct, "%s/ct", dir);
        iso_segmentation *seg = NULL;
        iso_error err = {0};
        int rc = iso_seg_load(ct, NULL, NULL, &seg, &err);
        CHECKF(rc == cases[i].code && strstr(err.message, cases[i].says) && strstr(err.message, "seg.dcm"),
               "%s: %d %s", cases[i].flag, rc, err.message);
        CHECK(seg == NULL);
    }
    /* The SEG's CT must be there: without it, the error names the series it needs (a
     * variant of its own, its SEG moved away from its CT). */
    const char *dir = write_seg("bad-frames");
    if (!dir)
        return;
    char cmd[16384], lone[4200];
    snprintf(lone, sizeof lone, "%s/lone", dir);
    snprintf(cmd, sizeof cmd, "mkdir -p %s && mv %s/ct/seg.dcm %s/", lone, dir, lone);
    CHECK_EQ(system(cmd), 0);
    iso_segmentation *seg = NULL;
    iso_error err = {0};
    CHECK(iso_seg_load(lone, NULL, NULL, &seg, &err) != 0);
    /* (That SEG is also a bad one: the missing CT is found first.) */
    CHECKF(strstr(err.message, "must be beside it") != NULL, "%s", err.message);
}

int main(void)
{
    CHECK_RUN(test_label_sets_match_scans);
    CHECK_RUN(test_label_sets_through_the_file);
    CHECK_RUN(test_segments_match_full_scan_of_indicator);
    CHECK_RUN(test_all_segments_at_once);
    CHECK_RUN(test_cap_closes_segments_on_the_border);
    CHECK_RUN(test_enclosed_volumes_of_hand_made_shapes);
    CHECK_RUN(test_seg_nrrd_keys_and_layers);
    CHECK_RUN(test_itksnap_descriptions);
    CHECK_RUN(test_cielab_to_srgb);
    CHECK_RUN(test_dicom_seg_gives_the_label_maps_meshes);
    CHECK_RUN(test_overlapping_binary_segments_take_layers);
    CHECK_RUN(test_bad_segs_are_precise_errors);
    return check_finish();
}
