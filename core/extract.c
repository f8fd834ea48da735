/* extract.c: iso-surface extraction over the hierarchy (Elber and Malzbender, with
 * Wilhelms and Van Gelder's min/max pruning), and the full-scan marching cubes baseline.
 *
 * Tolerance 0 takes the exact path instead (march.c): marching cubes over the bricks of
 * the regular min/max grid that hold the level, every crossing computed once and
 * indexed directly, on several threads; PASS 2 and 3 below then run only with a cap.
 *
 * PASS 1 (descend): from the root, skip every node whose [min, max] cannot hold the level;
 *   stop at the first node of at least MIN_FAN_CELLS cells whose fit error is within the
 *   fit share of the tolerance and whose face loops fan within the tolerance (fan.c);
 *   below stored bricks the same rule runs on the brick's samples, read once into a
 *   scratch block; single cells are marching cubes on the data itself. Every piece is
 *   appended to a triangle soup in index space. Fans and cells compute identical
 *   crossings on every shared face, so pieces of any size meet without cracks.
 * PASS 2 (cap, if asked): the cells between the volume's border samples and a virtual
 *   layer below every level around it, so the surface closes where it leaves the data.
 * PASS 3 (weld): vertices with bit-identical positions merge (mesh.c). Crossings are
 *   interpolated from the edge's low end by one function (mc.h), so they weld exactly.
 * PASS 4 (place): index space to world millimetres, if asked. */
#include "extract.h"

#include <assert.h>
#include <math.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

#include "clock.h"
#include "march.h"
#include "mc.h"
#include "trilinear.h"
#include "fan.h"

#define BRICK_SAMPLES ((ISO_TREE_BRICK + 1) * (ISO_TREE_BRICK + 1) * (ISO_TREE_BRICK + 1))

/* A fan emits about one triangle per loop vertex, marching cubes about two per crossed
 * cell: below 2x2x2 cells fanning a node saves nothing. */
#define MIN_FAN_CELLS 8
/* Share of the tolerance a fan's centre may be off the level (Newton lands far closer). */
#define CENTRE_SHARE (1.0 / 64)

typedef struct walk {
    const iso_tree *tree;
    const iso_volume *vol;
    double level, tolerance, fit_limit;
    int prune;
    iso_mesh *soup;
    iso_extract_stats *stats;
    iso_fan_scratch fan;
    /* The current brick's samples, x fastest, and where the brick starts. */
    double brick[BRICK_SAMPLES];
    uint32_t brick_lo[3], brick_n[3];
} walk;

static int active(const walk *w, double min, double max)
{
    return !w->prune || (min <= w->level && w->level < max);
}

static void raise_bound(iso_extract_stats *stats, double vertex_error)
{
    if (vertex_error > stats->error_bound)
        stats->error_bound = vertex_error;
}

static size_t brick_mc_triangles(const walk *w, const iso_box *b);

/* Emits box as fans over its face loops if it may; 1 done, 0 not, <0 error. Inside a
 * brick, where counting is cheap, a small node with a tangled surface can fan into more
 * triangles than its cells would give: it is refused then, so no tolerance ever costs
 * triangles. */
static int try_fan(walk *w, const iso_box *box, double fit_error, int in_brick)
{
    if (iso_box_cells(box) < MIN_FAN_CELLS || !(fit_error <= w->fit_limit))
        return 0;
    iso_fan_result fan;
    /* Centres must land on the surface, not merely within the tolerance of its level: a
     * centre left in a flat background would meet that loosely and still be far off. */
    double centre_limit = w->tolerance * CENTRE_SHARE;
    size_t max_triangles = in_brick ? brick_mc_triangles(w, box) : SIZE_MAX;
    int rc = iso_fan_polygonize(w->vol, box, w->level, centre_limit, max_triangles, &w->fan,
                                w->soup, &fan);
    if (rc == 1) {
        w->stats->nodes_polygonized++;
        w->stats->cells_visited++;
        raise_bound(w->stats, fan.vertex_error);
        if (fit_error > w->stats->fit_error)
            w->stats->fit_error = fit_error;
    }
    return rc;
}

/* ---- below a brick: the samples come from the scratch block ---- */

static double brick_at(const walk *w, uint32_t x, uint32_t y, uint32_t z)
{
    return w->brick[((size_t)(z - w->brick_lo[2]) * w->brick_n[1] + (y - w->brick_lo[1])) * w->brick_n[0] +
                    (x - w->brick_lo[0])];
}

static void brick_corners(const walk *w, const iso_box *b, double c[8])
{
    for (int k = 0; k < 8; k++)
        c[k] = brick_at(w, k & 1 ? b->hi[0] : b->lo[0], k & 2 ? b->hi[1] : b->lo[1],
                        k & 4 ? b->hi[2] : b->lo[2]);
}

static int march_cell(walk *w, uint32_t x, uint32_t y, uint32_t z)
{
    double v[8], origin[3] = {x, y, z};
    static const double unit[3] = {1, 1, 1};
    for (int k = 0; k < 8; k++)
        v[k] = brick_at(w, x + (k & 1), y + ((k >> 1) & 1), z + ((k >> 2) & 1));
    w->stats->cells_visited++;
    int rc = iso_mc_cell(v, w->level, origin, unit, w->soup, &w->stats->error_bound);
    return rc < 0 ? rc : 0;
}

static void scan_brick_box(const walk *w, const iso_box *b, const double c[8], double *mn,
                           double *mx, double *er)
{
    double lo = INFINITY, hi = -INFINITY, worst = 0;
    double n[3];
    for (int d = 0; d < 3; d++)
        n[d] = b->hi[d] - b->lo[d];
    for (uint32_t z = b->lo[2]; z <= b->hi[2]; z++)
        for (uint32_t y = b->lo[1]; y <= b->hi[1]; y++)
            for (uint32_t x = b->lo[0]; x <= b->hi[0]; x++) {
                double s = brick_at(w, x, y, z);
                double t = iso_tri_eval(c, (x - b->lo[0]) / n[0], (y - b->lo[1]) / n[1],
                                        (z - b->lo[2]) / n[2]);
                double d = fabs(s - t);
                if (s < lo) lo = s;
                if (s > hi) hi = s;
                if (d > worst || s != s) worst = s != s ? INFINITY : d;
            }
    *mn = lo;
    *mx = hi;
    *er = worst;
}

/* Triangles marching cubes would give for the box's cells. */
static size_t brick_mc_triangles(const walk *w, const iso_box *b)
{
    const iso_mc_case *cases = iso_mc_cases();
    size_t count = 0;
    for (uint32_t z = b->lo[2]; z < b->hi[2]; z++)
        for (uint32_t y = b->lo[1]; y < b->hi[1]; y++)
            for (uint32_t x = b->lo[0]; x < b->hi[0]; x++) {
                double v[8];
                for (int k = 0; k < 8; k++)
                    v[k] = brick_at(w, x + (k & 1), y + ((k >> 1) & 1), z + ((k >> 2) & 1));
                count += cases[iso_mc_case_index(v, w->level)].triangle_count;
            }
    return count;
}

static int visit_sub(walk *w, const iso_box *box);

static int visit_sub_children(walk *w, const iso_box *box)
{
    iso_box left, right;
    if (iso_box_split(box, &left, &right) < 0)
        return march_cell(w, box->lo[0], box->lo[1], box->lo[2]);
    int rc = visit_sub(w, &left);
    return rc ? rc : visit_sub(w, &right);
}

static int visit_sub(walk *w, const iso_box *box)
{
    w->stats->nodes_visited++;
    if (iso_box_cells(box) == 1) {
        double c[8], lo = INFINITY, hi = -INFINITY;
        brick_corners(w, box, c);
        for (int k = 0; k < 8; k++) {
            if (c[k] < lo) lo = c[k];
            if (c[k] > hi) hi = c[k];
        }
        return active(w, lo, hi) ? march_cell(w, box->lo[0], box->lo[1], box->lo[2]) : 0;
    }
    double c[8], mn, mx, er;
    brick_corners(w, box, c);
    scan_brick_box(w, box, c, &mn, &mx, &er);
    if (!active(w, mn, mx))
        return 0;
    int rc = try_fan(w, box, er, 1);
    if (rc)
        return rc < 0 ? rc : 0;
    return visit_sub_children(w, box);
}

static int visit_brick(walk *w, const iso_box *box)
{
    size_t lo[3], hi[3];
    for (int d = 0; d < 3; d++) {
        lo[d] = box->lo[d];
        hi[d] = box->hi[d];
        w->brick_lo[d] = box->lo[d];
        w->brick_n[d] = box->hi[d] - box->lo[d] + 1;
    }
    iso_vol_read_box(w->vol, lo, hi, w->brick);
    return visit_sub_children(w, box);
}

/* ---- stored nodes ---- */

static int visit_node(walk *w, uint32_t index, const iso_box *box)
{
    const iso_tree_node *node = &w->tree->nodes[index];
    w->stats->nodes_visited++;
    if (!active(w, node->min, node->max))
        return 0;
    int rc = try_fan(w, box, node->err, 0);
    if (rc)
        return rc < 0 ? rc : 0;
    if (!node->first_child)
        return visit_brick(w, box);
    iso_box left, right;
    iso_box_split(box, &left, &right);
    rc = visit_node(w, node->first_child, &left);
    return rc ? rc : visit_node(w, node->first_child + 1, &right);
}

/* ---- the passes after descent ---- */

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
 * sample. Their faces on the border carry the same crossings as the cells and fans
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

static void to_world(const iso_volume *vol, iso_mesh *mesh)
{
    for (size_t v = 0; v < mesh->vertex_count; v++) {
        float *p = mesh->positions + 3 * v;
        double index[3] = {p[0], p[1], p[2]}, world[3];
        iso_vol_index_to_world(vol, index, world);
        for (int d = 0; d < 3; d++)
            p[d] = (float)world[d];
    }
}

static int finish(const iso_volume *vol, iso_space space, int weld, iso_mesh *mesh,
                  iso_extract_stats *stats, double start, iso_error *err)
{
    if (weld && iso_mesh_weld(mesh))
        return iso_error_set(err, ISO_E_NOMEM, "out of memory welding the mesh");
    if (space == ISO_SPACE_WORLD)
        to_world(vol, mesh);
    stats->triangles = mesh->triangle_count;
    stats->vertices = mesh->vertex_count;
    stats->extract_ms = iso_clock_ms() - start;
    return 0;
}

/* Tolerance 0: the exact path, then the cap's cells welded onto it if asked. */
static int extract_exact(const iso_tree *tree, const iso_extract_params *params, iso_mesh *mesh,
                         iso_extract_stats *stats, double start, iso_error *err)
{
    /* The root's bounds answer a level outside the data with one node, as the descent does. */
    const iso_tree_node *root = &tree->nodes[0];
    stats->nodes_visited = 1;
    if (!params->no_minmax && !(root->min <= params->level && params->level < root->max) &&
        !params->cap) {
        iso_mesh_free(mesh);
        return finish(tree->vol, params->space, 0, mesh, stats, start, err);
    }
    iso_march_stats ms;
    /* With a cap the march stays in index space, so that the cap's vertices weld to it. */
    int world = params->space == ISO_SPACE_WORLD && !params->cap;
    int rc = iso_march_bricks(tree->vol, &tree->bricks, params->level, !params->no_minmax, world,
                              params->threads, mesh, &ms, err);
    if (rc)
        return rc;
    stats->nodes_visited += iso_bricks_total(&tree->bricks);
    stats->cells_visited = ms.cells_visited;
    stats->error_bound = ms.error_bound;
    if (params->cap && emit_caps(tree->vol, params->level, mesh)) {
        iso_mesh_free(mesh);
        return iso_error_set(err, ISO_E_NOMEM, "out of memory capping the surface");
    }
    /* Positions the march placed in world mm already are left as they are. */
    return finish(tree->vol, world ? ISO_SPACE_INDEX : params->space, params->cap, mesh, stats, start, err);
}

int iso_extract(const iso_tree *tree, const iso_extract_params *params, iso_mesh *mesh,
                iso_extract_stats *stats, iso_error *err)
{
    static walk zero_walk;
    iso_extract_stats local;
    double start = iso_clock_ms();
    if (!stats)
        stats = &local;
    memset(stats, 0, sizeof *stats);
    if (!isfinite(params->level))
        return iso_error_set(err, ISO_E_ARGUMENT, "level must be a finite number");
    if (!(params->tolerance >= 0) || !isfinite(params->tolerance))
        return iso_error_set(err, ISO_E_ARGUMENT, "tolerance must be a finite number >= 0");
    double share = params->fit_share == 0 ? 1.0 : params->fit_share;
    if (!(share > 0 && share <= 1))
        return iso_error_set(err, ISO_E_ARGUMENT, "fit share must be in (0, 1]");

    if (params->tolerance == 0)
        return extract_exact(tree, params, mesh, stats, start, err);
    walk *w = malloc(sizeof *w);
    if (!w)
        return iso_error_set(err, ISO_E_NOMEM, "out of memory");
    *w = zero_walk;
    w->tree = tree;
    w->vol = tree->vol;
    w->level = params->level;
    w->tolerance = params->tolerance;
    w->fit_limit = share * params->tolerance;
    w->prune = !params->no_minmax;
    w->soup = mesh;
    w->stats = stats;
    iso_mesh_clear(mesh);
    iso_box root = iso_box_root(tree->vol);
    int rc = visit_node(w, 0, &root);
    if (!rc && params->cap)
        rc = emit_caps(tree->vol, params->level, mesh);
    iso_fan_scratch_free(&w->fan);
    free(w);
    if (rc) {
        iso_mesh_free(mesh);
        return iso_error_set(err, ISO_E_NOMEM, "out of memory extracting the surface");
    }
    return finish(tree->vol, params->space, 1, mesh, stats, start, err);
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
    return finish(vol, space, 1, mesh, stats, start, err);
}
