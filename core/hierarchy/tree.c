/* tree.c: building, saving and mapping the hierarchy of trilinear fits (see tree.h).
 *
 * PASS 1 (layout): walk the split rule breadth-first from the root, one box per node,
 *   until bricks; children of node n are appended together, at child[n] (kept only while
 *   building: a loaded tree walks the same rule again, and extraction needs no child).
 * PASS 2 (fit): deepest nodes first, each node's min, max and the Lemma 1 error of the
 *   trilinear through its corners: bricks by scanning their samples, the nodes above by
 *   their children's min and max and a branch and bound over the bricks below them for
 *   the error (error_by_bounds: the same figure a scan of the node's samples gives, bit
 *   for bit, from a fraction of them). A depth's nodes are shared by all cores.
 * The file is a 64-byte header (magic, version, volume identity, checksums) followed by
 * the nodes exactly as in memory, so loading is one mmap plus verification. */
#include "tree.h"

#include <assert.h>
#include <errno.h>
#include <fcntl.h>
#include <math.h>
#include <stdatomic.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/mman.h>
#include <sys/stat.h>
#include <unistd.h>
#include <zlib.h>

#include "base/base.h"
#include "labels.h"
#include "levels.h"
#include "volume/volume.h"

/* ---- boxes ---- */

iso_box iso_box_root(const iso_volume *vol)
{
    iso_box b;
    for (int d = 0; d < 3; d++) {
        b.lo[d] = 0;
        b.hi[d] = (uint32_t)(vol->dims[d] - 1);
    }
    return b;
}

int iso_box_split(const iso_box *box, iso_box *left, iso_box *right)
{
    int axis = 0;
    uint32_t longest = 0;
    for (int d = 0; d < 3; d++) {
        uint32_t n = box->hi[d] - box->lo[d];
        if (n > longest) {
            longest = n;
            axis = d;
        }
    }
    if (longest <= 1 && iso_box_cells(box) <= 1)
        return -1;
    /* Above brick size the split falls on a multiple of the brick (the root starts at 0,
     * so every stored box does too): stored leaves are then exactly the bricks of the
     * regular grid (tree.h), whatever the volume's dimensions, and extraction can hand a
     * leaf to the brick kernel as it is. Below, the paper's middle split. */
    uint32_t half = longest > ISO_TREE_BRICK
                        ? ISO_TREE_BRICK * ((longest + ISO_TREE_BRICK) / (2 * ISO_TREE_BRICK))
                        : longest / 2;
    uint32_t mid = box->lo[axis] + half;
    *left = *box;
    *right = *box;
    left->hi[axis] = mid;
    right->lo[axis] = mid;
    return axis;
}

int iso_box_is_brick(const iso_box *box)
{
    for (int d = 0; d < 3; d++)
        if (box->hi[d] - box->lo[d] > ISO_TREE_BRICK)
            return 0;
    return 1;
}

/* ---- scanning one box: min, max, Lemma 1 error ---- */

/* One function per voxel type; the trilinear is evaluated along each x-row as a line
 * between its values at the row's ends, so a sample costs a multiply-add and compares.
 * The trilinear is the frame's (through its 8 corners) and the samples are the range's,
 * a box inside the frame: a node's error is then the maximum of the same per-sample
 * figures over any boxes that cover it, bit for bit, whichever boxes are scanned. With
 * `full` 0 only the error is wanted, of samples known to be numbers: the loop is then a
 * multiply-add and a maximum per sample. */
#define DEFINE_SCAN(NAME, T)                                                                  \
    static inline __attribute__((always_inline)) void NAME##_any(const iso_volume *vol, const iso_box *f, const iso_box *b,   \
                                  double *mn, double *mx, double *er, const int full)          \
    {                                                                                          \
        const T *p = (const T *)vol->data;                                                     \
        size_t nx = vol->dims[0], nxy = vol->dims[0] * vol->dims[1];                           \
        double c[8], lo = INFINITY, hi = -INFINITY, worst = 0;                                 \
        int nan = 0;                                                                           \
        for (int k = 0; k < 8; k++)                                                            \
            c[k] = (double)p[(k & 4 ? f->hi[2] : f->lo[2]) * nxy +                             \
                             (size_t)(k & 2 ? f->hi[1] : f->lo[1]) * nx + (k & 1 ? f->hi[0] : f->lo[0])]; \
        double inv[3];                                                                         \
        for (int d = 0; d < 3; d++)                                                            \
            inv[d] = f->hi[d] > f->lo[d] ? 1.0 / (f->hi[d] - f->lo[d]) : 0.0;                  \
        for (uint32_t z = b->lo[2]; z <= b->hi[2]; z++) {                                      \
            double w = (z - f->lo[2]) * inv[2];                                                \
            for (uint32_t y = b->lo[1]; y <= b->hi[1]; y++) {                                  \
                double v = (y - f->lo[1]) * inv[1];                                            \
                double a = iso_tri_eval(c, 0, v, w), e = iso_tri_eval(c, 1, v, w) - a;         \
                const T *row = p + z * nxy + (size_t)y * nx;                                   \
                for (uint32_t x = b->lo[0]; x <= b->hi[0]; x++) {                              \
                    double s = (double)row[x];                                                 \
                    double d = fabs(s - (a + e * ((x - f->lo[0]) * inv[0])));                  \
                    worst = d > worst ? d : worst;                                             \
                    if (full) {                                                                \
                        if (s < lo) lo = s;                                                    \
                        if (s > hi) hi = s;                                                    \
                        if (s != s) nan = 1;                                                   \
                    }                                                                          \
                }                                                                              \
            }                                                                                  \
        }                                                                                      \
        *mn = lo;                                                                              \
        *mx = hi;                                                                              \
        *er = nan ? INFINITY : worst;                                                          \
    }                                                                                          \
    static void NAME(const iso_volume *vol, const iso_box *f, const iso_box *b, double *mn,    \
                     double *mx, double *er)                                                   \
    {                                                                                          \
        NAME##_any(vol, f, b, mn, mx, er, 1);                                                  \
    }                                                                                          \
    static double NAME##_err(const iso_volume *vol, const iso_box *f, const iso_box *b)        \
    {                                                                                          \
        double mn, mx, er;                                                                     \
        NAME##_any(vol, f, b, &mn, &mx, &er, 0);                                               \
        return er;                                                                             \
    }

DEFINE_SCAN(scan_u8, uint8_t)
DEFINE_SCAN(scan_i8, int8_t)
DEFINE_SCAN(scan_u16, uint16_t)
DEFINE_SCAN(scan_i16, int16_t)
DEFINE_SCAN(scan_u32, uint32_t)
DEFINE_SCAN(scan_i32, int32_t)
DEFINE_SCAN(scan_f32, float)
DEFINE_SCAN(scan_f64, double)

/* The error alone of range's samples (numbers, no NaN) against frame's trilinear. */
static double scan_error(const iso_volume *vol, const iso_box *frame, const iso_box *range)
{
    switch (vol->type) {
    case ISO_U8: return scan_u8_err(vol, frame, range);
    case ISO_I8: return scan_i8_err(vol, frame, range);
    case ISO_U16: return scan_u16_err(vol, frame, range);
    case ISO_I16: return scan_i16_err(vol, frame, range);
    case ISO_U32: return scan_u32_err(vol, frame, range);
    case ISO_I32: return scan_i32_err(vol, frame, range);
    case ISO_F32: return scan_f32_err(vol, frame, range);
    case ISO_F64: return scan_f64_err(vol, frame, range);
    }
    return INFINITY;
}

void iso_tree_scan_box(const iso_volume *vol, const iso_box *box, double *min, double *max,
                       double *err)
{
    switch (vol->type) {
    case ISO_U8: scan_u8(vol, box, box, min, max, err); break;
    case ISO_I8: scan_i8(vol, box, box, min, max, err); break;
    case ISO_U16: scan_u16(vol, box, box, min, max, err); break;
    case ISO_I16: scan_i16(vol, box, box, min, max, err); break;
    case ISO_U32: scan_u32(vol, box, box, min, max, err); break;
    case ISO_I32: scan_i32(vol, box, box, min, max, err); break;
    case ISO_F32: scan_f32(vol, box, box, min, max, err); break;
    case ISO_F64: scan_f64(vol, box, box, min, max, err); break;
    }
}

/* ---- PASS 1: layout ---- */

typedef struct layout {
    iso_tree_node *nodes;
    iso_box *boxes;
    uint32_t *child; /* node n's children are child[n] and child[n] + 1; 0: a brick leaf */
    size_t count, capacity;
} layout;

static void layout_free(layout *l)
{
    free(l->nodes);
    free(l->boxes);
    free(l->child);
}

static int layout_push(layout *l, const iso_box *b)
{
    if (l->count == l->capacity) {
        size_t cap = l->capacity ? l->capacity * 2 : 1024;
        iso_tree_node *n = realloc(l->nodes, cap * sizeof *n);
        if (!n)
            return ISO_E_NOMEM;
        l->nodes = n;
        iso_box *bx = realloc(l->boxes, cap * sizeof *bx);
        if (!bx)
            return ISO_E_NOMEM;
        l->boxes = bx;
        uint32_t *ch = realloc(l->child, cap * sizeof *ch);
        if (!ch)
            return ISO_E_NOMEM;
        l->child = ch;
        l->capacity = cap;
    }
    memset(&l->nodes[l->count], 0, sizeof l->nodes[0]);
    l->child[l->count] = 0;
    l->boxes[l->count++] = *b;
    return 0;
}

static int lay_out(const iso_volume *vol, layout *l)
{
    iso_box root = iso_box_root(vol);
    if (layout_push(l, &root))
        return ISO_E_NOMEM;
    for (size_t n = 0; n < l->count; n++) {
        iso_box left, right, box = l->boxes[n];
        if (iso_box_is_brick(&box))
            continue;
        iso_box_split(&box, &left, &right);
        l->child[n] = (uint32_t)l->count;
        if (layout_push(l, &left) || layout_push(l, &right))
            return ISO_E_NOMEM;
    }
    return 0;
}

/* ---- PASS 2: fit, deepest nodes first ---- */

/* What the fit pass shares: the layout, and per brick (the stored leaves) the min and max
 * of each of its octants (the halves of its box per axis, sharing the middle plane), for
 * bounds finer than a brick's own. */
typedef struct fit_ctx {
    const iso_volume *vol;
    layout *l;
    uint32_t count[3];          /* bricks per axis */
    float *oct_min, *oct_max;   /* 8 per brick, x fastest, rounded outward */
    iso_label_builder *labels;  /* a label volume's sets, collected from the same samples */
} fit_ctx;

typedef struct fit_job {
    fit_ctx *f;
    size_t first, last;  /* this round's nodes: one depth of the breadth-first order */
    atomic_size_t next;  /* next node of the round to claim */
} fit_job;

enum { FIT_CHUNK = 16, FIT_STACK = 128 };

typedef struct pending {
    uint32_t node;
    double bound; /* of |p - T| over its box (bound_below) */
} pending;

/* The brick grid's index of a stored leaf's box. */
static size_t brick_of(const uint32_t count[3], const iso_box *box)
{
    return ((size_t)(box->lo[2] / ISO_TREE_BRICK) * count[1] + box->lo[1] / ISO_TREE_BRICK) * count[0] +
           box->lo[0] / ISO_TREE_BRICK;
}

/* Octant o of box: per axis a, the lower half [lo, mid] if bit a of o is 0, else [mid, hi]. */
static iso_box octant(const iso_box *box, int o)
{
    iso_box b;
    for (int a = 0; a < 3; a++) {
        uint32_t mid = box->lo[a] + (box->hi[a] - box->lo[a]) / 2;
        b.lo[a] = o >> a & 1 ? mid : box->lo[a];
        b.hi[a] = o >> a & 1 ? box->hi[a] : mid;
    }
    return b;
}

/* A brick's octants' min and max (NaN samples ignored: the bounds that read them are used
 * only where no NaN is); and a label volume's labels in the brick, from the same read. */
static void leaf_octants(fit_ctx *f, const iso_box *box)
{
    double samples[ISO_BRICK_SAMPLES * ISO_BRICK_SAMPLES * ISO_BRICK_SAMPLES];
    size_t lo[3] = {box->lo[0], box->lo[1], box->lo[2]}, hi[3] = {box->hi[0], box->hi[1], box->hi[2]};
    iso_vol_read_box(f->vol, lo, hi, samples);
    size_t nx = hi[0] - lo[0] + 1, ny = hi[1] - lo[1] + 1, at = brick_of(f->count, box) * 8;
    if (f->labels)
        iso_label_collect(f->labels, brick_of(f->count, box), samples, nx * ny * (hi[2] - lo[2] + 1));
    for (int o = 0; o < 8; o++) {
        iso_box b = octant(box, o);
        double mn = INFINITY, mx = -INFINITY;
        for (uint32_t z = b.lo[2]; z <= b.hi[2]; z++)
            for (uint32_t y = b.lo[1]; y <= b.hi[1]; y++) {
                const double *row = samples + ((z - box->lo[2]) * ny + (y - box->lo[1])) * nx - box->lo[0];
                for (uint32_t x = b.lo[0]; x <= b.hi[0]; x++) {
                    mn = row[x] < mn ? row[x] : mn;
                    mx = row[x] > mx ? row[x] : mx;
                }
            }
        f->oct_min[at + (size_t)o] = iso_float_down(mn);
        f->oct_max[at + (size_t)o] = iso_float_up(mx);
    }
}

/* T (the frame's trilinear: corners c, inv = 1 / its extents) at sample (x, y, z). */
static double frame_eval(const iso_box *frame, const double c[8], const double inv[3], uint32_t x, uint32_t y,
                         uint32_t z)
{
    return iso_tri_eval(c, (x - frame->lo[0]) * inv[0], (y - frame->lo[1]) * inv[1], (z - frame->lo[2]) * inv[2]);
}

/* An upper bound on |p(s) - T(s)| over the samples s of node q's box, T the frame's
 * trilinear: T on q's box lies between its values at q's corners, and the samples between
 * q's min and max; and |p - T| <= |p - T_q| + |T_q - T|, the first at most q's error, the
 * second trilinear, so largest at q's corners, where T_q is p. The smaller of the two. */
static double bound_below(const iso_volume *vol, const iso_box *frame, const double c[8], const double inv[3],
                          const iso_tree_node *q, const iso_box *qb)
{
    double tmin = INFINITY, tmax = -INFINITY, dev = 0;
    for (int k = 0; k < 8; k++) {
        uint32_t x = k & 1 ? qb->hi[0] : qb->lo[0], y = k & 2 ? qb->hi[1] : qb->lo[1];
        uint32_t z = k & 4 ? qb->hi[2] : qb->lo[2];
        double t = frame_eval(frame, c, inv, x, y, z);
        double d = fabs(iso_vol_get(vol, x, y, z) - t);
        tmin = t < tmin ? t : tmin;
        tmax = t > tmax ? t : tmax;
        dev = d > dev ? d : dev;
    }
    double by_range = fmax((double)q->max - tmin, tmax - (double)q->min);
    return fmin(by_range, (double)q->err + dev);
}

/* A brick below the frame: its octants bounded by their own min and max against T at
 * their corners (T's 27 values on the brick's halving grid), the likeliest first, and only
 * those that could beat *best scanned. */
static void scan_brick(const fit_ctx *f, const iso_box *frame, const double c[8], const double inv[3],
                       const iso_box *box, double margin, double *best)
{
    uint32_t g[3][3];
    for (int a = 0; a < 3; a++)
        g[a][0] = box->lo[a], g[a][1] = box->lo[a] + (box->hi[a] - box->lo[a]) / 2, g[a][2] = box->hi[a];
    double t[27];
    for (int k = 0; k < 27; k++)
        t[k] = frame_eval(frame, c, inv, g[0][k % 3], g[1][k / 3 % 3], g[2][k / 9]);
    size_t at = brick_of(f->count, box) * 8;
    double ub[8];
    int order[8];
    for (int o = 0; o < 8; o++) {
        double tmin = INFINITY, tmax = -INFINITY;
        for (int k = 0; k < 8; k++) {
            double v = t[((o >> 2 & 1) + (k >> 2 & 1)) * 9 + ((o >> 1 & 1) + (k >> 1 & 1)) * 3 + (o & 1) + (k & 1)];
            tmin = v < tmin ? v : tmin;
            tmax = v > tmax ? v : tmax;
        }
        ub[o] = fmax((double)f->oct_max[at + (size_t)o] - tmin, tmax - (double)f->oct_min[at + (size_t)o]);
        int i = o;
        for (; i > 0 && ub[order[i - 1]] < ub[o]; i--)
            order[i] = order[i - 1];
        order[i] = o;
    }
    for (int i = 0; i < 8; i++) {
        if (ub[order[i]] + margin <= *best)
            break;
        iso_box b = octant(box, order[i]);
        double e = scan_error(f->vol, frame, &b);
        *best = e > *best ? e : *best;
    }
}

/* Node n's error, the largest |p(s) - T(s)| over its samples, T the trilinear through its
 * corners: the children's boxes cover n's, so it is the largest of the same figures over
 * the bricks below n. A branch and bound finds it: a subtree whose bound cannot beat the
 * largest figure found so far is skipped, and the brick octants that can are scanned
 * against n's trilinear (scan_error, the very figures a scan of n's whole box computes;
 * the maximum does not depend on the order). `margin` covers the rounding of the bounds:
 * far above it, at a billionth of the largest magnitude, far below any difference that
 * matters. */
static double error_by_bounds(const fit_ctx *f, size_t n)
{
    const iso_box *frame = &f->l->boxes[n];
    const iso_tree_node *nodes = f->l->nodes;
    double c[8], inv[3], best = 0;
    for (int k = 0; k < 8; k++)
        c[k] = iso_vol_get(f->vol, k & 1 ? frame->hi[0] : frame->lo[0], k & 2 ? frame->hi[1] : frame->lo[1],
                           k & 4 ? frame->hi[2] : frame->lo[2]);
    for (int d = 0; d < 3; d++)
        inv[d] = frame->hi[d] > frame->lo[d] ? 1.0 / (frame->hi[d] - frame->lo[d]) : 0.0;
    double margin = 1e-9 * fmax(fabs((double)nodes[n].min), fabs((double)nodes[n].max));
    pending stack[FIT_STACK];
    int top = 0;
    stack[top++] = (pending){(uint32_t)n, INFINITY};
    while (top) {
        uint32_t q = stack[--top].node;
        if (stack[top].bound + margin <= best)
            continue;
        if (q != n && !f->l->child[q]) {
            scan_brick(f, frame, c, inv, &f->l->boxes[q], margin, &best);
            continue;
        }
        /* The child with the larger bound goes on top: it is the likelier to raise best. */
        uint32_t ch[2] = {f->l->child[q], f->l->child[q] + 1};
        double b[2];
        for (int i = 0; i < 2; i++)
            b[i] = bound_below(f->vol, frame, c, inv, &nodes[ch[i]], &f->l->boxes[ch[i]]);
        int big = b[1] > b[0];
        assert(top + 2 <= FIT_STACK);
        for (int i = 0; i < 2; i++) {
            int k = i ? big : !big;
            if (b[k] + margin > best)
                stack[top++] = (pending){ch[k], b[k]};
        }
    }
    return best;
}

/* A brick: one scan of its samples, and its octants' bounds. Above: min and max from the
 * children's (outward rounding commutes with min and max), the error by bounds when every
 * figure below is finite, else (NaN or infinite samples, or magnitudes where the bounds'
 * rounding could matter) a scan of the whole box, which gives INFINITY for a NaN as a
 * brick's scan does. */
static void fit_node(fit_ctx *f, size_t n)
{
    layout *l = f->l;
    iso_tree_node *node = &l->nodes[n];
    double mn, mx, er;
    if (!l->child[n]) {
        iso_tree_scan_box(f->vol, &l->boxes[n], &mn, &mx, &er);
        node->min = mn <= mx ? iso_float_down(mn) : INFINITY; /* all-NaN box: never active */
        node->max = mn <= mx ? iso_float_up(mx) : -INFINITY;
        node->err = iso_float_up(er);
        leaf_octants(f, &l->boxes[n]);
        return;
    }
    const iso_tree_node *a = &l->nodes[l->child[n]], *b = a + 1;
    node->min = a->min < b->min ? a->min : b->min;
    node->max = a->max > b->max ? a->max : b->max;
    double magnitude = fmax(fabs((double)node->min), fabs((double)node->max));
    if (isfinite(a->err) && isfinite(b->err) && magnitude < 1e30)
        er = error_by_bounds(f, n);
    else
        iso_tree_scan_box(f->vol, &l->boxes[n], &mn, &mx, &er);
    node->err = iso_float_up(er);
}

static void fit_round(void *context, int t, int threads)
{
    (void)t;
    (void)threads;
    fit_job *job = context;
    for (;;) {
        size_t first = job->first + atomic_fetch_add(&job->next, FIT_CHUNK);
        if (first >= job->last)
            return;
        size_t last = first + FIT_CHUNK < job->last ? first + FIT_CHUNK : job->last;
        for (size_t n = first; n < last; n++)
            fit_node(job->f, n);
    }
}

/* Depth by depth from the deepest (children come after their parent in the breadth-first
 * order, so each depth is a run of nodes and the one below it is done); a depth's nodes
 * are independent and shared by the threads. */
static int fit_all(const iso_volume *vol, layout *l, int threads, iso_progress_fn progress, void *context,
                   iso_label_builder *labels)
{
    fit_ctx f = {.vol = vol, .l = l, .labels = labels};
    iso_bricks_count(vol, f.count);
    size_t bricks = (size_t)f.count[0] * f.count[1] * f.count[2];
    unsigned char *depth = malloc(l->count);
    f.oct_min = malloc(bricks * 8 * sizeof *f.oct_min);
    f.oct_max = malloc(bricks * 8 * sizeof *f.oct_max);
    if (!depth || !f.oct_min || !f.oct_max) {
        free(depth);
        free(f.oct_min);
        free(f.oct_max);
        return ISO_E_NOMEM;
    }
    depth[0] = 0;
    for (size_t n = 0; n < l->count; n++)
        if (l->child[n])
            depth[l->child[n]] = depth[l->child[n] + 1] = (unsigned char)(depth[n] + 1);
    fit_job job = {.f = &f};
    for (size_t last = l->count; last > 0;) {
        size_t first = last;
        while (first > 0 && depth[first - 1] == depth[last - 1])
            first--;
        job.first = first;
        job.last = last;
        atomic_init(&job.next, 0);
        iso_parallel_run(threads, fit_round, &job);
        if (progress)
            progress(context, (double)(l->count - first) / (double)l->count);
        last = first;
    }
    free(depth);
    free(f.oct_min);
    free(f.oct_max);
    return 0;
}

/* The min/max grid of bricks (tree.h): the stored leaves are exactly the bricks, and
 * without NaN (integer samples) a brick's bounds are its leaf's, rounded the same way; so
 * they are copied rather than scanned again. Float samples may hold NaN, which the grid
 * marks differently (min -INFINITY): those are scanned. */
static int bricks_from_leaves(const iso_volume *vol, const iso_tree *tree, const layout *l, int threads,
                              iso_bricks *bricks, iso_error *err)
{
    if (iso_vol_type_is_float(vol->type))
        return iso_bricks_build(vol, threads, bricks, err);
    iso_bricks b;
    int rc = iso_bricks_alloc(vol, &b, err);
    if (rc)
        return rc;
    for (size_t n = 0; n < tree->node_count; n++) {
        if (l->child[n])
            continue;
        size_t at = brick_of(b.count, &l->boxes[n]);
        b.min[at] = tree->nodes[n].min;
        b.max[at] = tree->nodes[n].max;
    }
    *bricks = b;
    return 0;
}

int iso_tree_build(const iso_volume *vol, int threads, iso_progress_fn progress, void *context,
                   iso_tree **out, iso_error *err)
{
    double start = iso_clock_ms();
    layout l = {0};
    iso_tree *tree = NULL;
    *out = NULL;
    for (int d = 0; d < 3; d++)
        if (vol->dims[d] < 2 || vol->dims[d] > UINT32_MAX)
            return iso_error_set(err, ISO_E_ARGUMENT, "volume dimension %zu out of range", vol->dims[d]);
    if (vol->labels && iso_vol_type_is_float(vol->type))
        return iso_error_set(err, ISO_E_UNSUPPORTED, "a label volume holds integers, not %s samples",
                             iso_vol_type_name(vol->type));
    if (lay_out(vol, &l))
        goto nomem;
    if (l.count > UINT32_MAX)
        goto nomem;
    threads = iso_parallel_threads(threads);
    iso_label_builder *labels = NULL;
    if (vol->labels) {
        uint32_t count[3];
        iso_bricks_count(vol, count);
        if (!(labels = iso_label_builder_create((size_t)count[0] * count[1] * count[2])))
            goto nomem;
    }
    if (fit_all(vol, &l, threads, progress, context, labels)) {
        if (labels) {
            iso_label_sets none;
            iso_label_builder_finish(labels, &none, NULL);
            iso_label_free(&none);
        }
        goto nomem;
    }

    tree = calloc(1, sizeof *tree);
    if (!tree)
        goto nomem;
    tree->vol = vol;
    tree->nodes = l.nodes;
    tree->node_count = l.count;
    tree->volume_crc = iso_tree_volume_crc(vol);
    l.nodes = NULL;
    int rc = 0;
    if (labels) {
        tree->labels = calloc(1, sizeof *tree->labels);
        if (!tree->labels) {
            iso_label_sets none;
            iso_label_builder_finish(labels, &none, NULL);
            iso_label_free(&none);
            rc = iso_error_set(err, ISO_E_NOMEM, "out of memory building the label sets");
        } else {
            rc = iso_label_builder_finish(labels, tree->labels, err);
        }
    }
    if (!rc)
        rc = bricks_from_leaves(vol, tree, &l, threads, &tree->bricks, err);
    iso_tree_scale_make((double)tree->nodes[0].max - (double)tree->nodes[0].min, &tree->scale);
    if (!rc)
        rc = iso_levels_build(vol, &tree->bricks, &tree->scale, threads, &tree->level_code, err);
    layout_free(&l);
    if (rc) {
        iso_tree_destroy(tree);
        return rc;
    }
    tree->build_ms = iso_clock_ms() - start;
    *out = tree;
    return 0;
nomem:
    layout_free(&l);
    return iso_error_set(err, ISO_E_NOMEM, "out of memory building the hierarchy");
}

void iso_tree_destroy(iso_tree *tree)
{
    if (!tree)
        return;
    if (tree->mapping)
        munmap(tree->mapping, tree->mapping_bytes);
    else
        free(tree->nodes);
    iso_bricks_free(&tree->bricks);
    free(tree->level_code);
    iso_label_free(tree->labels);
    free(tree->labels);
    free(tree);
}

size_t iso_tree_bytes(const iso_tree *tree)
{
    return tree->node_count * sizeof(iso_tree_node);
}

size_t iso_tree_memory(const iso_tree *tree)
{
    return iso_tree_bytes(tree) + iso_bricks_total(&tree->bricks) * (2 * sizeof(float) + ISO_TREE_CODES) +
           sizeof tree->scale + iso_label_memory(tree->labels);
}

uint32_t iso_tree_volume_crc(const iso_volume *vol)
{
    uint64_t head[4] = {vol->dims[0], vol->dims[1], vol->dims[2], (uint64_t)vol->type};
    uLong crc = crc32(0L, (const Bytef *)head, sizeof head);
    const unsigned char *p = vol->data;
    size_t left = iso_vol_count(vol) * iso_vol_type_size(vol->type);
    while (left) {
        size_t n = left > (1u << 30) ? (1u << 30) : left;
        crc = crc32(crc, p, (uInt)n);
        p += n;
        left -= n;
    }
    return (uint32_t)crc;
}

/* ---- the file ---- */

#define TREE_MAGIC "ISOTREE"
/* 2: splits above brick size aligned to the brick grid; 3: the bricks' fan floors after
 * the nodes; 4: the bricks' level errors instead (tree.h), so that loading need not
 * compute them again; 5: those errors in 2 bytes each; 6: one-byte codes, per block at
 * levels 1 and 2 and per brick at level 3; 7: nodes of 12 bytes (no child index: the
 * layout follows from the dims); 8: a label volume's per-brick label sets after
 * the level codes (labels.h). An older file is refused as stale, and the caller rebuilds it. */
#define TREE_VERSION 8

typedef struct tree_header {
    char magic[8];          /* "ISOTREE\0" */
    uint32_t version;
    uint32_t brick;
    uint64_t dims[3];
    uint32_t type;
    uint32_t volume_crc;    /* iso_tree_volume_crc of the volume it was built from */
    uint64_t node_count;
    uint32_t node_crc;      /* CRC-32 of the bytes after the header: nodes, level codes, labels */
    uint32_t header_crc;    /* CRC-32 of the header with this field zero */
} tree_header;

_Static_assert(sizeof(tree_header) == 64, "the header is 64 bytes so nodes stay aligned");

static uint32_t header_crc(tree_header h)
{
    h.header_crc = 0;
    return (uint32_t)crc32(0L, (const Bytef *)&h, sizeof h);
}

int iso_tree_save(const iso_tree *tree, const char *path, iso_error *err)
{
    tree_header h;
    memset(&h, 0, sizeof h);
    memcpy(h.magic, TREE_MAGIC, sizeof TREE_MAGIC);
    h.version = TREE_VERSION;
    h.brick = ISO_TREE_BRICK;
    for (int d = 0; d < 3; d++)
        h.dims[d] = tree->vol->dims[d];
    h.type = (uint32_t)tree->vol->type;
    h.volume_crc = tree->volume_crc;
    h.node_count = tree->node_count;
    size_t code_bytes = iso_bricks_total(&tree->bricks) * ISO_TREE_CODES;
    size_t label_bytes = tree->labels ? iso_label_section_bytes(tree->labels) : 0;
    unsigned char *label_section = label_bytes ? malloc(label_bytes) : NULL;
    if (label_bytes && !label_section)
        return iso_error_set(err, ISO_E_NOMEM, "out of memory writing %s", path);
    if (label_section)
        iso_label_section_write(tree->labels, label_section);
    uLong crc = crc32(0L, (const Bytef *)tree->nodes, (uInt)iso_tree_bytes(tree));
    crc = crc32(crc, (const Bytef *)tree->level_code, (uInt)code_bytes);
    h.node_crc = (uint32_t)crc32(crc, label_section ? label_section : (const Bytef *)"", (uInt)label_bytes);
    h.header_crc = header_crc(h);

    iso_file_part parts[] = {{&h, sizeof h},
                             {tree->nodes, iso_tree_bytes(tree)},
                             {tree->level_code, code_bytes},
                             {label_section, label_bytes}};
    int rc = iso_file_replace(path, parts, sizeof parts / sizeof *parts, err);
    free(label_section);
    return rc;
}

/* The nodes must be as many as lay_out gives for these dims, with sane values: a file
 * that passes its checksums but was written by a different rule is still refused. */
static int check_structure(const iso_volume *vol, const iso_tree_node *nodes, size_t count,
                           const char *path, iso_error *err)
{
    layout l = {0};
    if (lay_out(vol, &l)) {
        layout_free(&l);
        return iso_error_set(err, ISO_E_NOMEM, "out of memory checking %s", path);
    }
    int rc = 0;
    if (l.count != count)
        rc = iso_error_set(err, ISO_E_CORRUPT, "%s: %zu nodes, the volume's hierarchy has %zu", path, count, l.count);
    for (size_t n = 0; rc == 0 && n < count; n++) {
        const iso_tree_node *node = &nodes[n];
        if (!(node->err >= 0) || (node->min > node->max && !(node->min == INFINITY && node->max == -INFINITY)))
            rc = iso_error_set(err, ISO_E_CORRUPT, "%s: node %zu is inconsistent", path, n);
    }
    layout_free(&l);
    return rc;
}

int iso_tree_load(const iso_volume *vol, const char *path, iso_tree **out, iso_error *err)
{
    double start = iso_clock_ms();
    *out = NULL;
    int fd = open(path, O_RDONLY | O_CLOEXEC);
    if (fd < 0)
        return iso_error_set(err, ISO_E_IO, "%s: %s", path, strerror(errno));
    struct stat st;
    if (fstat(fd, &st) != 0 || !S_ISREG(st.st_mode)) {
        close(fd);
        return iso_error_set(err, ISO_E_IO, "%s: not a regular file", path);
    }
    if ((uint64_t)st.st_size < sizeof(tree_header)) {
        close(fd);
        return iso_error_set(err, ISO_E_FORMAT, "%s: %lld bytes, shorter than the 64-byte header",
                             path, (long long)st.st_size);
    }
    size_t bytes = (size_t)st.st_size;
    void *map = mmap(NULL, bytes, PROT_READ, MAP_PRIVATE, fd, 0);
    close(fd);
    if (map == MAP_FAILED)
        return iso_error_set(err, ISO_E_IO, "%s: mmap failed: %s", path, strerror(errno));

    tree_header h;
    memcpy(&h, map, sizeof h);
    uint32_t count[3];
    iso_bricks_count(vol, count);
    size_t codes = (size_t)count[0] * count[1] * count[2] * ISO_TREE_CODES; /* per brick (tree.h) */
    int rc = 0;
    if (memcmp(h.magic, TREE_MAGIC, sizeof TREE_MAGIC) != 0)
        rc = iso_error_set(err, ISO_E_FORMAT, "%s: not a hierarchy file (bad magic)", path);
    else if (h.version != TREE_VERSION)
        rc = iso_error_set(err, ISO_E_STALE, "%s: version %u, this build reads version %u", path, h.version, TREE_VERSION);
    else if (header_crc(h) != h.header_crc)
        rc = iso_error_set(err, ISO_E_CORRUPT, "%s: header checksum mismatch", path);
    else if (h.brick != ISO_TREE_BRICK)
        rc = iso_error_set(err, ISO_E_STALE, "%s: brick size %u, this build uses %d", path, h.brick, ISO_TREE_BRICK);
    else if (h.dims[0] != vol->dims[0] || h.dims[1] != vol->dims[1] || h.dims[2] != vol->dims[2] ||
             h.type != (uint32_t)vol->type)
        rc = iso_error_set(err, ISO_E_STALE, "%s: built for a %llux%llux%llu volume of another shape or type",
                           path, (unsigned long long)h.dims[0], (unsigned long long)h.dims[1],
                           (unsigned long long)h.dims[2]);
    else if (h.node_count > (bytes - sizeof h) / sizeof(iso_tree_node) ||
             sizeof h + h.node_count * sizeof(iso_tree_node) + codes > bytes)
        rc = iso_error_set(err, ISO_E_CORRUPT,
                           "%s: %zu bytes do not hold the %llu nodes the header announces and %zu level errors",
                           path, bytes, (unsigned long long)h.node_count, codes);
    else if (vol->labels && sizeof h + h.node_count * sizeof(iso_tree_node) + codes == bytes)
        rc = iso_error_set(err, ISO_E_STALE, "%s: built without the label sets this label volume needs", path);
    else if ((uint32_t)crc32(0L, (const Bytef *)map + sizeof h, (uInt)(bytes - sizeof h)) != h.node_crc)
        rc = iso_error_set(err, ISO_E_CORRUPT, "%s: node checksum mismatch", path);
    else if (h.volume_crc != iso_tree_volume_crc(vol))
        rc = iso_error_set(err, ISO_E_STALE, "%s: built from different samples than this volume", path);
    else
        rc = check_structure(vol, (const iso_tree_node *)((const char *)map + sizeof h), h.node_count, path, err);
    if (rc) {
        munmap(map, bytes);
        return rc;
    }
    iso_tree *tree = calloc(1, sizeof *tree);
    if (!tree) {
        munmap(map, bytes);
        return iso_error_set(err, ISO_E_NOMEM, "out of memory loading %s", path);
    }
    tree->vol = vol;
    tree->nodes = (iso_tree_node *)((char *)map + sizeof h);
    tree->node_count = h.node_count;
    tree->volume_crc = h.volume_crc;
    tree->mapping = map;
    tree->mapping_bytes = bytes;
    /* Every byte is a code (tree.h): a forged one can only be caught by rebuilding. */
    tree->level_code = malloc(codes ? codes : 1);
    if (!tree->level_code) {
        iso_tree_destroy(tree);
        return iso_error_set(err, ISO_E_NOMEM, "out of memory loading %s", path);
    }
    memcpy(tree->level_code, (const char *)map + sizeof h + h.node_count * sizeof(iso_tree_node), codes);
    size_t label_at = sizeof h + h.node_count * sizeof(iso_tree_node) + codes;
    if (label_at < bytes && vol->labels) {
        tree->labels = calloc(1, sizeof *tree->labels);
        if (!tree->labels) {
            iso_tree_destroy(tree);
            return iso_error_set(err, ISO_E_NOMEM, "out of memory loading %s", path);
        }
        if ((rc = iso_label_read((const unsigned char *)map + label_at, bytes - label_at, codes / ISO_TREE_CODES,
                                 path, tree->labels, err))) {
            iso_tree_destroy(tree);
            return rc;
        }
    }
    iso_tree_scale_make((double)tree->nodes[0].max - (double)tree->nodes[0].min, &tree->scale);
    if ((rc = iso_bricks_build(vol, 0, &tree->bricks, err))) {
        iso_tree_destroy(tree);
        return rc;
    }
    tree->build_ms = iso_clock_ms() - start;
    *out = tree;
    return 0;
}
