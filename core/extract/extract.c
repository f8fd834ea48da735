/* extract.c: iso-surface extraction over the hierarchy (Elber and Malzbender, with
 * Wilhelms and Van Gelder's min/max pruning), and the full-scan marching cubes baseline.
 *
 * PASS 1 (surface): at tolerance 0 the exact brick kernel (march.c): marching cubes over
 *   the bricks whose [min, max] holds the level, every crossing computed once. Above it,
 *   the bricks on their own coarse grids joined by transition cells (lod.h), in index
 *   space.
 * PASS 2 (cap, if asked): the cells between the volume's border samples and a virtual
 *   layer below every level around it, welded on in index space.
 * PASS 3 (place): index space to world millimetres, if asked (the kernel places its own
 *   vertices directly when there is no cap). */
#include "extract.h"

#include <math.h>
#include <stdlib.h>
#include <string.h>
#ifdef __SSE2__
#include <emmintrin.h>
#endif

#include "base/base.h"
#include "hierarchy/tree.h"
#include "lod.h"
#include "march.h"
#include "mc.h"

/* ---- PASS 2 and 3 ---- */

/* The value of padded sample (i, j, k): the volume's inside it, below every level on the
 * virtual layer one sample outside it. */
static double padded_value(const iso_volume *vol, long i, long j, long k)
{
    long p[3] = {i, j, k};
    for (int d = 0; d < 3; d++)
        if (p[d] < 0 || p[d] >= (long)vol->dims[d])
            return -INFINITY;
    return iso_vol_get(vol, (size_t)i, (size_t)j, (size_t)k);
}

/* PASS 2: marching cubes on the padded grid's cells that touch the virtual layer, i.e.
 * lower corners in -1..n-1 with some coordinate -1 or n-1: about two cells per border
 * sample. Their faces on the border carry the same crossings as the cells
 * inside, their crossings toward the virtual layer sit 1/1024 voxel outside the border
 * (iso_mc_edge_t), so the cap is flat against the border and seals the surface. The cap's
 * own vertices are on the border, not on the level: they do not enter the error bound. */
static int emit_caps(const iso_volume *vol, double level, iso_mesh *soup)
{
    static const double unit[3] = {1, 1, 1};
    long n[3] = {(long)vol->dims[0], (long)vol->dims[1], (long)vol->dims[2]};
    for (long k = -1; k < n[2]; k++)
        for (long j = -1; j < n[1]; j++) {
            int inner = k >= 0 && k < n[2] - 1 && j >= 0 && j < n[1] - 1;
            for (long i = -1; i < n[0]; i += inner && i == -1 ? n[0] : 1) {
                double v[8], origin[3] = {(double)i, (double)j, (double)k};
                for (int c = 0; c < 8; c++)
                    v[c] = padded_value(vol, i + (c & 1), j + ((c >> 1) & 1), k + ((c >> 2) & 1));
                if (iso_mc_cell(v, level, origin, unit, soup, NULL) < 0)
                    return ISO_E_NOMEM;
            }
        }
    return 0;
}

/* A mirrored index-to-world map (its determinant negative: one axis flipped, as in LPI or
 * a radiological NIfTI) turns every triangle inside out in world space. Swapping two
 * corners of each keeps mesh.h's winding: counter-clockwise seen from the lower values. */
void iso_extract_world_winding(const iso_volume *vol, iso_mesh *mesh)
{
    const double (*d)[3] = vol->direction;
    double det = d[0][0] * (d[1][1] * d[2][2] - d[1][2] * d[2][1]) -
                 d[0][1] * (d[1][0] * d[2][2] - d[1][2] * d[2][0]) +
                 d[0][2] * (d[1][0] * d[2][1] - d[1][1] * d[2][0]);
    if (!(det < 0))
        return;
    for (size_t t = 0; t < mesh->triangle_count; t++) {
        uint32_t *tri = mesh->indices + 3 * t;
        uint32_t b = tri[1];
        tri[1] = tri[2];
        tri[2] = b;
    }
}

/* PASS 3. With an identity direction iso_vol_index_to_world is origin + index * spacing
 * per axis, to the same bits (its other terms add +0 to a sum that is not -0), as march.c
 * places its vertices: one multiply-add per coordinate, over the whole array. */
void iso_extract_to_world(const iso_volume *vol, iso_mesh *mesh)
{
    int aligned = 1;
    for (int r = 0; r < 3; r++)
        for (int c = 0; c < 3; c++)
            aligned &= vol->direction[r][c] == (r == c);
    if (aligned) {
        float *p = mesh->positions;
        const double o0 = vol->origin[0], o1 = vol->origin[1], o2 = vol->origin[2];
        const double s0 = vol->spacing[0], s1 = vol->spacing[1], s2 = vol->spacing[2];
        size_t v = 0;
#ifdef __SSE2__
        /* Two vertices (six coordinates) at a time, the same multiply and add per lane. */
        const __m128d s01 = _mm_set_pd(s1, s0), s20 = _mm_set_pd(s0, s2), s12 = _mm_set_pd(s2, s1);
        const __m128d o01 = _mm_set_pd(o1, o0), o20 = _mm_set_pd(o0, o2), o12 = _mm_set_pd(o2, o1);
        for (; v + 2 <= mesh->vertex_count; v += 2, p += 6) {
            double last; /* the second vertex's y and z, as one 8-byte lane */
            memcpy(&last, p + 4, sizeof last);
            __m128 a = _mm_loadu_ps(p), b = _mm_castpd_ps(_mm_set_sd(last));
            __m128d xy = _mm_add_pd(o01, _mm_mul_pd(_mm_cvtps_pd(a), s01));
            __m128d zx = _mm_add_pd(o20, _mm_mul_pd(_mm_cvtps_pd(_mm_movehl_ps(a, a)), s20));
            __m128d yz = _mm_add_pd(o12, _mm_mul_pd(_mm_cvtps_pd(b), s12));
            _mm_storeu_ps(p, _mm_movelh_ps(_mm_cvtpd_ps(xy), _mm_cvtpd_ps(zx)));
            last = _mm_cvtsd_f64(_mm_castps_pd(_mm_cvtpd_ps(yz)));
            memcpy(p + 4, &last, sizeof last);
        }
#endif
        for (; v < mesh->vertex_count; v++, p += 3) {
            p[0] = (float)(o0 + (double)p[0] * s0);
            p[1] = (float)(o1 + (double)p[1] * s1);
            p[2] = (float)(o2 + (double)p[2] * s2);
        }
        iso_extract_world_winding(vol, mesh);
        return;
    }
    for (size_t v = 0; v < mesh->vertex_count; v++) {
        float *p = mesh->positions + 3 * v;
        double index[3] = {p[0], p[1], p[2]}, world[3];
        iso_vol_index_to_world(vol, index, world);
        for (int d = 0; d < 3; d++)
            p[d] = (float)world[d];
    }
    iso_extract_world_winding(vol, mesh);
}

/* space: where the positions are now; asked: where the caller wants them (world positions
 * placed by the kernel arrive as ISO_SPACE_INDEX, already placed). */
static int finish(const iso_volume *vol, iso_space space, iso_space asked, int weld, iso_mesh *mesh,
                  iso_extract_stats *stats, double start, iso_error *err)
{
    if (weld && iso_mesh_weld(mesh))
        return iso_error_set(err, ISO_E_NOMEM, "out of memory welding the mesh");
    if (space == ISO_SPACE_WORLD)
        iso_extract_to_world(vol, mesh); /* the positions, and the winding */
    else if (asked == ISO_SPACE_WORLD)
        iso_extract_world_winding(vol, mesh); /* placed by the kernel: the winding only */
    stats->triangles = mesh->triangle_count;
    stats->vertices = mesh->vertex_count;
    stats->extract_ms = iso_clock_ms() - start;
    return 0;
}

/* PASS 2 and 3 after either surface. placed: the positions are world mm already. */
static int cap_and_finish(const iso_volume *vol, const iso_extract_params *params, int placed,
                          iso_mesh *mesh, iso_extract_stats *stats, double start, iso_error *err)
{
    if (params->cap && emit_caps(vol, params->level, mesh)) {
        iso_mesh_free(mesh);
        return iso_error_set(err, ISO_E_NOMEM, "out of memory capping the surface");
    }
    return finish(vol, placed ? ISO_SPACE_INDEX : params->space, params->space, params->cap, mesh, stats,
                  start, err);
}

/* The exact path: the kernel, then the cap and placement. */
static int march_and_finish(const iso_tree *tree, const iso_extract_params *params, iso_mesh *mesh,
                            iso_extract_stats *stats, double start, iso_error *err)
{
    /* With a cap the march stays in index space, so that the cap's vertices weld to it. */
    int world = params->space == ISO_SPACE_WORLD && !params->cap;
    iso_march_stats ms;
    int rc = iso_march_bricks(tree->vol, &tree->bricks, params->level, !params->no_minmax, world,
                              params->threads, mesh, &ms, err);
    if (rc)
        return rc;
    stats->nodes_visited += ms.bricks_active;
    stats->cells_visited = ms.cells_visited;
    stats->error_bound = ms.error_bound;
    return cap_and_finish(tree->vol, params, world, mesh, stats, start, err);
}

int iso_extract(const iso_tree *tree, const iso_extract_params *params, iso_mesh *mesh,
                iso_extract_stats *stats, iso_error *err)
{
    iso_extract_stats local;
    double start = iso_clock_ms();
    if (!stats)
        stats = &local;
    memset(stats, 0, sizeof *stats);
    if (!isfinite(params->level))
        return iso_error_set(err, ISO_E_ARGUMENT, "level must be a finite number");
    if (!(params->tolerance >= 0) || !isfinite(params->tolerance))
        return iso_error_set(err, ISO_E_ARGUMENT, "tolerance must be a finite number >= 0");
    /* The root's bounds answer a level outside the data with one node. */
    const iso_tree_node *root = &tree->nodes[0];
    if (!params->no_minmax && !params->cap && !(root->min <= params->level && params->level < root->max)) {
        stats->nodes_visited = 1;
        iso_mesh_clear(mesh);
        return finish(tree->vol, params->space, params->space, 0, mesh, stats, start, err);
    }
    if (params->tolerance > 0) {
        int exact;
        int rc = iso_lod_extract(tree, params, &exact, mesh, stats, err);
        if (rc || !exact)
            return rc ? rc : cap_and_finish(tree->vol, params, 0, mesh, stats, start, err);
    }
    stats->nodes_visited = 1;
    return march_and_finish(tree, params, mesh, stats, start, err);
}

int iso_extract_exact(const iso_volume *vol, double level, iso_space space, int threads, iso_mesh *mesh,
                      iso_extract_stats *stats, iso_error *err)
{
    iso_extract_stats local;
    double start = iso_clock_ms();
    if (!stats)
        stats = &local;
    memset(stats, 0, sizeof *stats);
    iso_bricks bricks;
    int rc = iso_bricks_build(vol, threads, &bricks, err);
    if (rc)
        return rc;
    iso_march_stats ms;
    rc = iso_march_bricks(vol, &bricks, level, 1, space == ISO_SPACE_WORLD, threads, mesh, &ms, err);
    iso_bricks_free(&bricks);
    if (rc)
        return rc;
    stats->nodes_visited = ms.bricks_active;
    stats->cells_visited = ms.cells_visited;
    stats->error_bound = ms.error_bound;
    return finish(vol, ISO_SPACE_INDEX, space, 0, mesh, stats, start, err);
}

int iso_extract_full_scan(const iso_volume *vol, double level, iso_space space,
                          iso_mesh *mesh, iso_extract_stats *stats, iso_error *err)
{
    iso_extract_stats local;
    double start = iso_clock_ms();
    if (!stats)
        stats = &local;
    memset(stats, 0, sizeof *stats);
    if (!isfinite(level))
        return iso_error_set(err, ISO_E_ARGUMENT, "level must be a finite number");
    size_t nx = vol->dims[0], ny = vol->dims[1], nz = vol->dims[2];
    double *slab = malloc(2 * nx * ny * sizeof *slab);
    if (!slab)
        return iso_error_set(err, ISO_E_NOMEM, "out of memory");
    iso_mesh_free(mesh);
    static const double unit[3] = {1, 1, 1};
    int rc = 0;
    /* Two slices at a time, converted once; each cell reads its 8 corners from them. */
    for (size_t z = 0; z + 1 < nz && rc >= 0; z++) {
        size_t lo[3] = {0, 0, z}, hi[3] = {nx - 1, ny - 1, z + 1};
        iso_vol_read_box(vol, lo, hi, slab);
        for (size_t y = 0; y + 1 < ny && rc >= 0; y++)
            for (size_t x = 0; x + 1 < nx && rc >= 0; x++) {
                double v[8], origin[3] = {(double)x, (double)y, (double)z};
                for (int k = 0; k < 8; k++)
                    v[k] = slab[((size_t)((k >> 2) & 1) * ny + y + ((k >> 1) & 1)) * nx + x + (k & 1)];
                rc = iso_mc_cell(v, level, origin, unit, mesh, &stats->error_bound);
            }
    }
    free(slab);
    stats->cells_visited = (nx - 1) * (ny - 1) * (nz - 1);
    if (rc < 0) {
        iso_mesh_free(mesh);
        return iso_error_set(err, ISO_E_NOMEM, "out of memory extracting the surface");
    }
    return finish(vol, space, space, 1, mesh, stats, start, err);
}
