/* label.c: one label's surface in a label volume (extract.h, iso_extract_label), in passes:
 *
 * PASS 1 (bricks): the label's bricks from the hierarchy's label sets (hierarchy/labels.h);
 *   those holding another label too are its boundary bricks, the only ones its surface
 *   crosses; those on the volume's border need the cap.
 * PASS 2 (march): the exact brick kernel on the boundary bricks with the indicator's
 *   classification, "sample == label" (march.h, iso_march_label): marching cubes' surface
 *   of the 0/1 indicator at 0.5, every vertex at its edge's midpoint.
 * PASS 3 (cap, if asked): marching cubes on the cells between the label's border samples
 *   (in its bricks on the border) and a virtual layer of 0 beyond them, welded to the
 *   surface in index space: the cap lies where the indicator crosses 0.5 toward the
 *   outside, half a voxel past the border samples.
 * PASS 4 (place): index space to world millimetres, as the exact kernel places vertices. */
#include "extract.h"

#include <stdlib.h>
#include <string.h>

#include "march.h"
#include "mc.h"

/* PASS 1: the label's bricks: sets->holding[*start .. *start + *count), none when no
 * sample holds it. */
static void label_bricks(const iso_tree *tree, int64_t value, size_t *start, size_t *count)
{
    const iso_label_sets *sets = tree->labels;
    long i = sets ? iso_label_index(sets, value) : -1;
    *start = *count = 0;
    if (i < 0)
        return;
    *start = sets->holding_start[i];
    *count = sets->holding_start[i + 1] - sets->holding_start[i];
}

/* PASS 3: the padded cells (lower corner -1 or n-1 on some axis) whose home is brick at:
 * per axis its cells, and the padded one below (first brick) or above (last brick). */
static int cap_brick(const iso_volume *vol, const iso_bricks *g, uint32_t at, int64_t value, iso_mesh *soup)
{
    static const double unit[3] = {1, 1, 1};
    uint32_t b[3] = {at % g->count[0], at / g->count[0] % g->count[1], at / g->count[0] / g->count[1]};
    size_t blo[3], bhi[3];
    iso_bricks_box(vol, b, blo, bhi);
    long from[3], to[3], n[3];
    for (int d = 0; d < 3; d++) {
        n[d] = (long)vol->dims[d];
        from[d] = b[d] == 0 ? -1 : (long)blo[d];
        to[d] = b[d] + 1 == g->count[d] ? n[d] - 1 : (long)bhi[d] - 1;
    }
    for (long k = from[2]; k <= to[2]; k++)
        for (long j = from[1]; j <= to[1]; j++)
            for (long i = from[0]; i <= to[0]; i++) {
                long c[3] = {i, j, k};
                int padded = 0;
                for (int d = 0; d < 3; d++)
                    padded |= c[d] == -1 || c[d] == n[d] - 1;
                if (!padded)
                    continue;
                double v[8];
                int ones = 0;
                for (int corner = 0; corner < 8; corner++) {
                    long p[3] = {i + (corner & 1), j + (corner >> 1 & 1), k + (corner >> 2 & 1)};
                    int inside = 1;
                    for (int d = 0; d < 3; d++)
                        inside &= p[d] >= 0 && p[d] < n[d];
                    v[corner] = inside && iso_vol_get(vol, (size_t)p[0], (size_t)p[1], (size_t)p[2]) == (double)value;
                    ones += v[corner] != 0;
                }
                if (!ones)
                    continue;
                double origin[3] = {(double)i, (double)j, (double)k};
                if (iso_mc_cell(v, 0.5, origin, unit, soup, NULL) < 0)
                    return ISO_E_NOMEM;
            }
    return 0;
}

int iso_extract_label(const iso_tree *tree, int64_t value, int cap, iso_space space, int threads, iso_mesh *mesh,
                      iso_extract_stats *stats, iso_error *err)
{
    iso_extract_stats local;
    double start_ms = iso_clock_ms();
    if (!stats)
        stats = &local;
    memset(stats, 0, sizeof *stats);
    if (!tree->labels)
        return iso_error_set(err, ISO_E_ARGUMENT, "not a label volume: its hierarchy has no label sets");
    size_t start, count;
    label_bricks(tree, value, &start, &count);
    uint32_t *listed = malloc((count ? count : 1) * sizeof *listed);
    if (!listed)
        return iso_error_set(err, ISO_E_NOMEM, "out of memory listing the segment's bricks");
    size_t n = 0;
    for (size_t k = 0; k < count; k++)
        if (tree->labels->holding[start + k] & ISO_LABEL_MIXED)
            listed[n++] = tree->labels->holding[start + k] & ~ISO_LABEL_MIXED;
    int world = space == ISO_SPACE_WORLD && !cap;
    iso_march_stats ms;
    int rc = iso_march_label(tree->vol, &tree->bricks, value, listed, n, world, threads, mesh, &ms, err);
    free(listed);
    if (rc)
        return rc;
    stats->nodes_visited = ms.bricks_active;
    stats->cells_visited = ms.cells_visited;
    for (size_t k = 0; cap && k < count && !rc; k++) {
        uint32_t at = tree->labels->holding[start + k] & ~ISO_LABEL_MIXED;
        if (iso_bricks_on_border(&tree->bricks, at))
            rc = cap_brick(tree->vol, &tree->bricks, at, value, mesh);
    }
    if (cap && (rc || iso_mesh_weld(mesh))) {
        iso_mesh_free(mesh);
        return iso_error_set(err, ISO_E_NOMEM, "out of memory capping the label's surface");
    }
    if (cap && space == ISO_SPACE_WORLD)
        iso_extract_to_world(tree->vol, mesh);
    else if (space == ISO_SPACE_WORLD)
        iso_extract_world_winding(tree->vol, mesh); /* placed by the kernel */
    stats->triangles = mesh->triangle_count;
    stats->vertices = mesh->vertex_count;
    stats->extract_ms = iso_clock_ms() - start_ms;
    return 0;
}

