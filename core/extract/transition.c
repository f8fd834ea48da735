/* transition.c: transition cells' cases (transition.h), built from face rules on first use
 * and kept in a memo that any thread reads without a lock.
 *
 * Building a case, in order:
 *   1. faces: each of the 6 faces is one polygon (its corners and the midpoints present on
 *      its edges, counter-clockwise seen from outside) or, refined, 4 squares around its
 *      centre;
 *   2. segments: mc.h's face rule on every polygon: a run of inside corners is entered
 *      across one side and left across another, and its segment runs from the side where
 *      it is left to the side where it was entered. Every crossing lies on one side of two
 *      polygons that walk it in opposite directions, so it ends one segment and starts one;
 *   3. loops: the segments chained, reversed as mc.c reverses its loops so that normals
 *      point to lower values; a loop of two (a run along one split edge, cut off by the
 *      edge itself on both faces) holds no surface;
 *   4. triangles: each loop triangulated by dynamic programming over its chords, with the
 *      rules transition.h states, the first valid chord taken at each step. */
#include "transition.h"

#include <pthread.h>
#include <stdatomic.h>
#include <stdlib.h>
#include <string.h>

#include "mc.h"

#define NONE 0xFF
#define FACES 6

static iso_transition_slot slots[ISO_TRANSITION_SLOTS];
static uint8_t slot_between[ISO_TRANSITION_POINTS][ISO_TRANSITION_POINTS];
static uint8_t slot_faces[ISO_TRANSITION_SLOTS]; /* bit f: the slot lies in face f */

/* Face f = 2 d + side holds the points whose coordinate d is 2 side. */
static int face_holds(int f, const int c[3])
{
    return c[f / 2] == 2 * (f & 1);
}

static void add_slot(int *count, int axis, int length, const int low[3])
{
    iso_transition_slot *s = &slots[*count];
    s->axis = (uint8_t)axis;
    s->length = (uint8_t)length;
    int high[3] = {low[0], low[1], low[2]};
    high[axis] += length;
    for (int d = 0; d < 3; d++)
        s->low[d] = (uint8_t)low[d];
    unsigned a = iso_transition_point((unsigned)low[0], (unsigned)low[1], (unsigned)low[2]);
    unsigned b = iso_transition_point((unsigned)high[0], (unsigned)high[1], (unsigned)high[2]);
    slot_between[a][b] = slot_between[b][a] = (uint8_t)*count;
    for (int f = 0; f < FACES; f++)
        if (face_holds(f, low) && face_holds(f, high))
            slot_faces[*count] |= (uint8_t)(1u << f);
    (*count)++;
}

/* The 48 half edges (both ends on the boundary, the edge in a face), then the 12 whole
 * edges, in a fixed order. */
static void make_slots(void)
{
    memset(slot_between, NONE, sizeof slot_between);
    int count = 0;
    for (int axis = 0; axis < 3; axis++)
        for (int from = 0; from < 2; from++)
            for (int v = 0; v < 3; v++)
                for (int u = 0; u < 3; u++) {
                    if (u == 1 && v == 1)
                        continue;
                    int low[3];
                    low[axis] = from;
                    low[(axis + 1) % 3] = u;
                    low[(axis + 2) % 3] = v;
                    add_slot(&count, axis, 1, low);
                }
    for (int axis = 0; axis < 3; axis++)
        for (int v = 0; v < 3; v += 2)
            for (int u = 0; u < 3; u += 2) {
                int low[3];
                low[axis] = 0;
                low[(axis + 1) % 3] = u;
                low[(axis + 2) % 3] = v;
                add_slot(&count, axis, 2, low);
            }
}

/* ---- building a case ---- */

typedef struct builder {
    uint32_t present, inside, refined; /* refined: bit f for each refined face */
    uint8_t next[ISO_TRANSITION_SLOTS];
    uint8_t segment[ISO_TRANSITION_SLOTS][ISO_TRANSITION_SLOTS / 8 + 1]; /* bit: u-v is a segment */
} builder;

static int is_segment(const builder *b, unsigned u, unsigned v)
{
    return b->segment[u][v / 8] >> (v % 8) & 1;
}

/* Step 2 on one polygon of n points: each run's segment, from the side where it is left to
 * the side where it was entered. */
static void face_rule(builder *b, const unsigned *polygon, int n)
{
    int entry[4], leave[4], entries = 0, leaves = 0;
    for (int i = 0; i < n; i++) {
        int here = (int)(b->inside >> polygon[i] & 1), next = (int)(b->inside >> polygon[(i + 1) % n] & 1);
        if (!here && next)
            entry[entries++] = i;
        else if (here && !next)
            leave[leaves++] = i;
    }
    for (int r = 0; r < entries; r++) {
        int best = -1, best_gap = n + 1;
        for (int l = 0; l < leaves; l++) {
            int gap = (leave[l] - entry[r] + n) % n;
            if (gap < best_gap) {
                best_gap = gap;
                best = leave[l];
            }
        }
        unsigned from = slot_between[polygon[best]][polygon[(best + 1) % n]];
        unsigned to = slot_between[polygon[entry[r]]][polygon[(entry[r] + 1) % n]];
        b->next[from] = (uint8_t)to;
        b->segment[from][to / 8] |= (uint8_t)(1u << (to % 8));
        b->segment[to][from / 8] |= (uint8_t)(1u << (from % 8));
    }
}

/* Step 1 and 2 for face f. */
static void face_segments(builder *b, int f)
{
    int d = f / 2, side = f & 1, u = (d + 1) % 3, v = (d + 2) % 3;
    /* The ring of the face in (u, v), counter-clockwise seen from +d; (u, v, d) is
     * right-handed, so the low face (side 0) walks it the other way. */
    static const int ring[8][2] = {{0, 0}, {1, 0}, {2, 0}, {2, 1}, {2, 2}, {1, 2}, {0, 2}, {0, 1}};
    unsigned points[8];
    for (int i = 0; i < 8; i++) {
        int c[3];
        c[d] = 2 * side;
        c[u] = ring[i][0];
        c[v] = ring[i][1];
        points[i] = iso_transition_point((unsigned)c[0], (unsigned)c[1], (unsigned)c[2]);
    }
    int c[3] = {1, 1, 1};
    c[d] = 2 * side;
    unsigned centre = iso_transition_point((unsigned)c[0], (unsigned)c[1], (unsigned)c[2]);
    if (b->present >> centre & 1) {
        b->refined |= 1u << f;
        /* The four squares: corner 2q of the ring, the points after it, and the centre. */
        for (int q = 0; q < 4; q++) {
            unsigned square[4] = {points[2 * q], points[(2 * q + 1) % 8], centre, points[(2 * q + 7) % 8]};
            if (!side) {
                unsigned t = square[1];
                square[1] = square[3];
                square[3] = t;
            }
            face_rule(b, square, 4);
        }
        return;
    }
    unsigned polygon[8];
    int n = 0;
    for (int i = 0; i < 8; i++) {
        int k = side ? i : (8 - i) % 8;
        if (!(k & 1) || (b->present >> points[k] & 1))
            polygon[n++] = points[k];
    }
    face_rule(b, polygon, n);
}

/* 1 if two slots lie on the same line, one of the cell's edges. */
static int on_one_cell_edge(unsigned s, unsigned t)
{
    const iso_transition_slot *a = &slots[s], *b = &slots[t];
    if (a->axis != b->axis || __builtin_popcount(slot_faces[s]) != 2)
        return 0;
    for (int d = 0; d < 3; d++)
        if (d != a->axis && a->low[d] != b->low[d])
            return 0;
    return 1;
}

/* May u-v be a chord? Not a segment, not in a face that is not refined, not along an
 * edge of the cell. */
static int chord_allowed(const builder *b, unsigned u, unsigned v)
{
    if (is_segment(b, u, v))
        return 0;
    if (slot_faces[u] & slot_faces[v] & ~b->refined)
        return 0;
    return !on_one_cell_edge(u, v);
}

/* In face f's plane: can points on the open slots u, v, w ever be collinear? Their 2-D
 * cross product is multilinear in the three positions along the slots, so over the open
 * cube of positions it vanishes only if its values at the 8 corners (the slots' ends)
 * take both signs, or are all 0. */
static int can_be_collinear(int f, unsigned u, unsigned v, unsigned w)
{
    int d = f / 2, x = (d + 1) % 3, y = (d + 2) % 3;
    const unsigned s[3] = {u, v, w};
    int end[3][2][2]; /* [slot][end][x, y] */
    for (int k = 0; k < 3; k++) {
        const iso_transition_slot *t = &slots[s[k]];
        for (int e = 0; e < 2; e++) {
            int c[3] = {t->low[0], t->low[1], t->low[2]};
            c[t->axis] += e * t->length;
            end[k][e][0] = c[x];
            end[k][e][1] = c[y];
        }
    }
    int positive = 0, negative = 0;
    for (int corner = 0; corner < 8; corner++) {
        const int *a = end[0][corner & 1], *p = end[1][corner >> 1 & 1], *q = end[2][corner >> 2];
        int cross = (p[0] - a[0]) * (q[1] - a[1]) - (p[1] - a[1]) * (q[0] - a[0]);
        positive |= cross > 0;
        negative |= cross < 0;
    }
    return (positive && negative) || (!positive && !negative);
}

static int triangle_allowed(const builder *b, unsigned u, unsigned v, unsigned w)
{
    unsigned common = slot_faces[u] & slot_faces[v] & slot_faces[w];
    if (common & ~b->refined)
        return 0;
    for (int f = 0; f < FACES; f++)
        if ((common >> f & 1) && can_be_collinear(f, u, v, w))
            return 0;
    return 1;
}

/* Step 4 on one loop of n slots: 1 and its triangles appended to out, or 0. */
static int triangulate(const builder *b, const uint8_t *loop, int n, iso_transition_case *out)
{
    if (n > ISO_TRANSITION_SLOTS || out->triangle_count + (n - 2) > ISO_TRANSITION_MAX_TRIANGLES)
        return 0;
    static _Thread_local uint8_t ok[ISO_TRANSITION_SLOTS][ISO_TRANSITION_SLOTS];
    static _Thread_local uint8_t choice[ISO_TRANSITION_SLOTS][ISO_TRANSITION_SLOTS];
    for (int length = 1; length < n; length++)
        for (int i = 0; i + length < n; i++) {
            int j = i + length;
            ok[i][j] = length == 1;
            for (int k = i + 1; k < j && !ok[i][j]; k++) {
                if (!ok[i][k] || !ok[k][j])
                    continue;
                if ((k != i + 1 && !chord_allowed(b, loop[i], loop[k])) ||
                    (k != j - 1 && !chord_allowed(b, loop[k], loop[j])))
                    continue;
                if (!triangle_allowed(b, loop[i], loop[k], loop[j]))
                    continue;
                ok[i][j] = 1;
                choice[i][j] = (uint8_t)k;
            }
        }
    if (!ok[0][n - 1])
        return 0;
    /* The chosen triangles, by an explicit stack of sub-polygons. */
    uint8_t stack[2 * ISO_TRANSITION_SLOTS];
    int top = 0;
    stack[top++] = 0;
    stack[top++] = (uint8_t)(n - 1);
    while (top) {
        int j = stack[--top], i = stack[--top];
        if (j - i < 2)
            continue;
        int k = choice[i][j];
        uint8_t *t = out->slot + 3 * out->triangle_count++;
        t[0] = loop[i];
        t[1] = loop[k];
        t[2] = loop[j];
        stack[top++] = (uint8_t)i;
        stack[top++] = (uint8_t)k;
        stack[top++] = (uint8_t)k;
        stack[top++] = (uint8_t)j;
    }
    return 1;
}

/* Builds the case into out; returns 0 if it has no triangulation. */
static int build(uint32_t present, uint32_t inside, iso_transition_case *out)
{
    builder b;
    memset(&b, 0, sizeof b);
    memset(b.next, NONE, sizeof b.next);
    b.present = present;
    b.inside = inside;
    for (int f = 0; f < FACES; f++)
        face_segments(&b, f);
    out->triangle_count = 0;
    uint8_t done[ISO_TRANSITION_SLOTS] = {0};
    for (unsigned start = 0; start < ISO_TRANSITION_SLOTS; start++) {
        if (b.next[start] == NONE || done[start])
            continue;
        uint8_t loop[ISO_TRANSITION_SLOTS], reversed[ISO_TRANSITION_SLOTS];
        int n = 0;
        for (unsigned s = start; !done[s]; s = b.next[s]) {
            if (b.next[s] == NONE)
                return 0; /* a segment that does not chain: cannot happen for a valid key */
            done[s] = 1;
            loop[n++] = (uint8_t)s;
        }
        if (n == 2)
            continue;
        for (int k = 0; k < n; k++)
            reversed[k] = loop[n - 1 - k];
        if (!triangulate(&b, reversed, n, out))
            return 0;
    }
    return 1;
}

/* ---- the memo ---- */

/* Open addressing on 64-bit keys (0: empty). A reader loads a key with acquire order and
 * then its case, which the writer stored first; writers hold the lock. A full table is
 * copied into one twice its size, published whole; old tables stay readable (and
 * reachable) for readers still probing them. */
typedef struct memo_table {
    size_t mask, count;
    _Atomic uint64_t *keys; /* calloc's zeros are empty keys */
    const iso_transition_case **cases;
    struct memo_table *older;
} memo_table;

static _Atomic(memo_table *) memo;
static pthread_mutex_t memo_lock = PTHREAD_MUTEX_INITIALIZER;
static const iso_transition_case infeasible = {.triangle_count = 0xFF};

/* Cases live in chunks that never move. */
typedef struct chunk {
    struct chunk *next;
    size_t used;
    unsigned char bytes[1 << 16];
} chunk;
static chunk *chunks;
static size_t memo_cases;

static uint64_t key_of(uint32_t present, uint32_t inside)
{
    const uint32_t corners = (1u << 0) | (1u << 2) | (1u << 6) | (1u << 8) | (1u << 18) | (1u << 20) | (1u << 24) |
                             (1u << 26);
    present |= corners;
    return (uint64_t)present << 27 | (inside & present);
}

static size_t slot_of(uint64_t key, size_t mask)
{
    return (size_t)(key * UINT64_C(0x9E3779B97F4A7C15) >> 24) & mask;
}

static const iso_transition_case *probe(const memo_table *t, uint64_t key)
{
    if (!t)
        return NULL;
    for (size_t i = slot_of(key, t->mask);; i = (i + 1) & t->mask) {
        uint64_t k = atomic_load_explicit(&t->keys[i], memory_order_acquire);
        if (k == key)
            return t->cases[i];
        if (!k)
            return NULL;
    }
}

static void place(memo_table *t, uint64_t key, const iso_transition_case *c)
{
    size_t i = slot_of(key, t->mask);
    while (atomic_load_explicit(&t->keys[i], memory_order_relaxed))
        i = (i + 1) & t->mask;
    t->cases[i] = c;
    atomic_store_explicit(&t->keys[i], key, memory_order_release);
    t->count++;
}

static memo_table *new_table(size_t size)
{
    memo_table *t = calloc(1, sizeof *t);
    if (!t)
        return NULL;
    t->keys = calloc(size, sizeof(uint64_t));
    t->cases = calloc(size, sizeof *t->cases);
    if (!t->keys || !t->cases) {
        free(t->keys);
        free(t->cases);
        free(t);
        return NULL;
    }
    t->mask = size - 1;
    return t;
}

/* A table with room for one more case (the current one, or its copy at twice the size);
 * NULL if memory runs out. Under the lock. */
static memo_table *table_with_room(void)
{
    memo_table *t = atomic_load_explicit(&memo, memory_order_relaxed);
    if (t && 2 * (t->count + 1) <= t->mask + 1)
        return t;
    memo_table *bigger = new_table(t ? 2 * (t->mask + 1) : 4096);
    if (!bigger)
        return NULL;
    for (size_t i = 0; t && i <= t->mask; i++) {
        uint64_t k = atomic_load_explicit(&t->keys[i], memory_order_relaxed);
        if (k)
            place(bigger, k, t->cases[i]);
    }
    bigger->older = t;
    atomic_store_explicit(&memo, bigger, memory_order_release);
    return bigger;
}

/* Room for a case of n triangles in the chunks; NULL if memory runs out. Under the lock. */
static iso_transition_case *case_room(unsigned triangles)
{
    size_t bytes = (1 + 3 * (size_t)triangles + 7) & ~(size_t)7;
    if (!chunks || chunks->used + bytes > sizeof chunks->bytes) {
        chunk *c = malloc(sizeof *c);
        if (!c)
            return NULL;
        c->next = chunks;
        c->used = 0;
        chunks = c;
    }
    iso_transition_case *room = (iso_transition_case *)(void *)(chunks->bytes + chunks->used);
    chunks->used += bytes;
    return room;
}

static pthread_once_t slots_once = PTHREAD_ONCE_INIT;

const iso_transition_slot *iso_transition_slots(void)
{
    pthread_once(&slots_once, make_slots);
    return slots;
}

const iso_transition_case *iso_transition_get(uint32_t present, uint32_t inside, iso_transition_scratch *scratch)
{
    pthread_once(&slots_once, make_slots);
    uint64_t key = key_of(present, inside);
    const iso_transition_case *found = probe(atomic_load_explicit(&memo, memory_order_acquire), key);
    if (found)
        return found == &infeasible ? NULL : found;
    pthread_mutex_lock(&memo_lock);
    found = probe(atomic_load_explicit(&memo, memory_order_relaxed), key);
    if (!found) {
        int feasible = build(present | (uint32_t)(key >> 27), inside, &scratch->built);
        memo_table *t = memo_cases < ISO_TRANSITION_MEMO ? table_with_room() : NULL;
        iso_transition_case *kept = t && feasible ? case_room(scratch->built.triangle_count) : NULL;
        if (kept)
            memcpy(kept, &scratch->built, 1 + 3 * (size_t)scratch->built.triangle_count);
        found = feasible ? (kept ? kept : &scratch->built) : &infeasible;
        if (t && (kept || !feasible)) {
            place(t, key, found);
            memo_cases++;
        }
    }
    pthread_mutex_unlock(&memo_lock);
    return found == &infeasible ? NULL : found;
}
