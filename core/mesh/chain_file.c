/* chain_file.c: a simplification chain written to a file, mapped back section by section
 * or read back whole (see mesh.h).
 *
 * The file (version 3): a 72-byte header (magic, version, the size of a level record, the
 * caller's identity, counts, the caller's faithful triangle count, the number of sections
 * and a CRC-32 of the header and the table), then the table: one entry per section (its
 * offset, bytes and CRC-32), then the sections, each at an offset that is a multiple of
 * CHAIN_ALIGN with zero bytes between: the level records (iso_mesh_chain_level as this
 * build lays it out, index pointers zero), the positions (3 floats per vertex), then each
 * level's indices (3 uint32 per triangle). A level is cut from the mapped file by reading
 * its own indices and the positions they use: nothing else of the file is touched.
 *
 * What is checked when. Mapping (iso_mesh_chain_map_open) checks the magic, version,
 * record size and identity (another one is stale: ISO_E_STALE), the header and table
 * checksum, that the sections follow one another, aligned, with the sizes the counts give,
 * up to the file's last byte exactly (a file cut short is corrupt), and the records'
 * checksum: O(levels), whatever the chain's size. Before a level is first cut from it
 * (iso_mesh_chain_map_check), the positions' checksum and that level's, and every one of
 * its indices against the vertex count: O(that level's triangles + vertices), once per
 * mapping. Reading whole (iso_mesh_chain_load) checks all of it, the zero padding too.
 * Writing goes to a temporary file renamed into place, so a reader never sees half a
 * file, and a mapping keeps the file it mapped even when a newer one replaces it. */
#include "distance.h"

#include <errno.h>
#include <fcntl.h>
#include <pthread.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/mman.h>
#include <sys/stat.h>
#include <unistd.h>
#include <zlib.h>

#include "base/base.h"

#define CHAIN_MAGIC "ISOCHAIN"
#define CHAIN_VERSION 4u /* 3: sections at aligned offsets, each with its own checksum; 4: levels
                           * 1/sqrt(2) apart, every component kept (a 3 is a halving chain) */
#define CHAIN_ALIGN 64u  /* a cache line: every array starts aligned for any element type */
#define CHAIN_SECTIONS_MAX (ISO_CHAIN_LEVELS + 3)

typedef struct chain_header {
    char magic[8];
    uint32_t version;
    uint32_t record_bytes;   /* sizeof(iso_mesh_chain_level) */
    uint64_t identity;
    uint64_t vertex_count;
    uint32_t levels;
    int32_t closed;
    double voxel_size;
    double volume;
    uint64_t faithful_triangles;
    uint32_t sections;       /* 2 + levels: records, positions, each level's indices */
    uint32_t header_crc;     /* of the header (this field zero) and the table */
} chain_header;

typedef struct chain_section {
    uint64_t offset, bytes;
    uint32_t crc, reserved;
} chain_section;

enum { SECTION_RECORDS = 0, SECTION_POSITIONS = 1, SECTION_LEVEL0 = 2 };

struct iso_mesh_chain_map {
    iso_mesh_chain chain;    /* positions and indices point into the mapping */
    const unsigned char *data;
    size_t bytes;
    chain_section table[CHAIN_SECTIONS_MAX];
    pthread_mutex_t lock;    /* guards the checks below */
    int positions_checked, bad;
    unsigned char level_checked[ISO_CHAIN_LEVELS + 1];
    char path[];
};

static uint32_t crc_of(uint32_t crc, const void *p, size_t n)
{
    const unsigned char *b = p;
    while (n) {
        size_t part = n > (1u << 30) ? (1u << 30) : n;
        crc = (uint32_t)crc32(crc, b, (uInt)part);
        b += part;
        n -= part;
    }
    return crc;
}

static uint32_t header_crc(chain_header h, const chain_section *table)
{
    h.header_crc = 0;
    return crc_of(crc_of(0, &h, sizeof h), table, h.sections * sizeof *table);
}

static uint64_t align_up(uint64_t n)
{
    return (n + CHAIN_ALIGN - 1) / CHAIN_ALIGN * CHAIN_ALIGN;
}

/* The sections' data in file order, and the table that places them. */
static uint32_t sections_of(const iso_mesh_chain *c, iso_mesh_chain_level *records, iso_file_part *data,
                            chain_section *table)
{
    uint32_t n = 0;
    for (int k = 0; k < c->levels; k++) {
        records[k] = c->level[k];
        records[k].indices = NULL;
    }
    data[n++] = (iso_file_part){records, (size_t)c->levels * sizeof *records};
    data[n++] = (iso_file_part){c->positions, 3 * c->vertex_count * sizeof *c->positions};
    for (int k = 0; k < c->levels; k++)
        data[n++] = (iso_file_part){c->level[k].indices, 3 * c->level[k].triangle_count * sizeof(uint32_t)};
    uint64_t at = align_up(sizeof(chain_header) + n * sizeof *table);
    for (uint32_t i = 0; i < n; i++) {
        table[i] = (chain_section){.offset = at, .bytes = data[i].bytes,
                                  .crc = crc_of(0, data[i].data, data[i].bytes)};
        at = align_up(at + data[i].bytes);
    }
    return n;
}

int iso_mesh_chain_save(const iso_mesh_chain *chain, const char *path, uint64_t identity,
                        iso_error *err)
{
    static const unsigned char zeros[CHAIN_ALIGN];
    iso_mesh_chain_level records[ISO_CHAIN_LEVELS + 1];
    iso_file_part data[CHAIN_SECTIONS_MAX], parts[2 + 2 * CHAIN_SECTIONS_MAX];
    chain_section table[CHAIN_SECTIONS_MAX];
    memset(records, 0, sizeof records);
    memset(table, 0, sizeof table);
    uint32_t n = sections_of(chain, records, data, table);
    chain_header h = {.version = CHAIN_VERSION, .record_bytes = sizeof(iso_mesh_chain_level),
                      .identity = identity, .vertex_count = chain->vertex_count,
                      .levels = (uint32_t)chain->levels, .closed = chain->closed,
                      .voxel_size = chain->voxel_size, .volume = chain->volume,
                      .faithful_triangles = chain->faithful_triangles, .sections = n};
    memcpy(h.magic, CHAIN_MAGIC, sizeof h.magic);
    h.header_crc = header_crc(h, table);
    size_t count = 0;
    uint64_t at = sizeof h + n * sizeof *table;
    parts[count++] = (iso_file_part){&h, sizeof h};
    parts[count++] = (iso_file_part){table, n * sizeof *table};
    for (uint32_t i = 0; i < n; i++) {
        parts[count++] = (iso_file_part){zeros, (size_t)(table[i].offset - at)};
        parts[count++] = data[i];
        at = table[i].offset + table[i].bytes;
    }
    return iso_file_replace(path, parts, count, err);
}

/* The header's own checks: what the file is, whose, and of which layout. */
static int check_header(const chain_header *h, size_t file_bytes, const char *path, iso_error *err)
{
    if (file_bytes < sizeof *h || memcmp(h->magic, CHAIN_MAGIC, sizeof h->magic))
        return iso_error_set(err, ISO_E_FORMAT, "%s: not a chain file (bad magic)", path);
    if (h->version != CHAIN_VERSION || h->record_bytes != sizeof(iso_mesh_chain_level))
        return iso_error_set(err, ISO_E_STALE, "%s: version %u (records of %u bytes), this build "
                             "reads version %u (%zu)", path, h->version, h->record_bytes,
                             CHAIN_VERSION, sizeof(iso_mesh_chain_level));
    if (h->sections < SECTION_LEVEL0 + 1 || h->sections > CHAIN_SECTIONS_MAX ||
        file_bytes < sizeof *h + h->sections * sizeof(chain_section))
        return iso_error_set(err, ISO_E_CORRUPT, "%s: %u sections in %zu bytes", path, h->sections, file_bytes);
    return 0;
}

/* The header's checksum, identity and counts, then the table: sections in order, aligned,
 * the sizes the counts give, ending at the file's end. */
static int check_layout(const iso_mesh_chain_map *m, const chain_header *h, uint64_t identity, iso_error *err)
{
    const chain_section *t = m->table;
    if (h->header_crc != header_crc(*h, t))
        return iso_error_set(err, ISO_E_CORRUPT, "%s: header checksum mismatch", m->path);
    if (h->identity != identity)
        return iso_error_set(err, ISO_E_STALE, "%s: made for another surface or volume version", m->path);
    if (h->levels < 1 || h->levels > ISO_CHAIN_LEVELS + 1 || h->sections != h->levels + SECTION_LEVEL0 ||
        h->vertex_count > UINT32_MAX || !(h->voxel_size > 0))
        return iso_error_set(err, ISO_E_CORRUPT, "%s: %u levels, %llu vertices", m->path, h->levels,
                             (unsigned long long)h->vertex_count);
    uint64_t at = sizeof *h + h->sections * sizeof *t;
    for (uint32_t i = 0; i < h->sections; i++) {
        if (t[i].offset != align_up(at) || t[i].bytes > m->bytes || t[i].offset > m->bytes - t[i].bytes)
            return iso_error_set(err, ISO_E_CORRUPT, "%s: section %u out of place (file of %zu bytes: cut "
                                 "short?)", m->path, i, m->bytes);
        at = t[i].offset + t[i].bytes;
    }
    if (at != m->bytes)
        return iso_error_set(err, ISO_E_CORRUPT, "%s: %zu bytes where the table says %llu", m->path, m->bytes,
                             (unsigned long long)at);
    if (t[SECTION_RECORDS].bytes != h->levels * (uint64_t)sizeof(iso_mesh_chain_level) ||
        t[SECTION_POSITIONS].bytes != 3 * h->vertex_count * sizeof(float))
        return iso_error_set(err, ISO_E_CORRUPT, "%s: section sizes do not match the counts", m->path);
    return 0;
}

/* The records into the chain, checked against their checksum and their sections. */
static int take_records(iso_mesh_chain_map *m, const chain_header *h, iso_error *err)
{
    const chain_section *t = m->table;
    iso_mesh_chain *c = &m->chain;
    if (crc_of(0, m->data + t[SECTION_RECORDS].offset, t[SECTION_RECORDS].bytes) != t[SECTION_RECORDS].crc)
        return iso_error_set(err, ISO_E_CORRUPT, "%s: level records' checksum mismatch", m->path);
    memcpy(c->level, m->data + t[SECTION_RECORDS].offset, t[SECTION_RECORDS].bytes);
    c->levels = (int)h->levels;
    c->vertex_count = (size_t)h->vertex_count;
    c->voxel_size = h->voxel_size;
    c->volume = h->volume;
    c->closed = h->closed;
    c->faithful_triangles = (size_t)h->faithful_triangles;
    c->positions = (float *)(uintptr_t)(m->data + t[SECTION_POSITIONS].offset); /* read-only */
    c->grid = NULL;
    c->bytes = m->bytes;
    for (int k = 0; k < c->levels; k++) {
        const chain_section *s = &t[SECTION_LEVEL0 + k];
        iso_mesh_chain_level *lv = &c->level[k];
        if (s->bytes != 3 * (uint64_t)lv->triangle_count * sizeof(uint32_t))
            return iso_error_set(err, ISO_E_CORRUPT, "%s: level %d's size does not match its record", m->path, k);
        lv->indices = (uint32_t *)(uintptr_t)(m->data + s->offset);
    }
    return 0;
}

int iso_mesh_chain_map_open(const char *path, uint64_t identity, iso_mesh_chain_map **out, iso_error *err)
{
    *out = NULL;
    int fd = open(path, O_RDONLY | O_CLOEXEC);
    if (fd < 0)
        return iso_error_set(err, ISO_E_IO, "%s: %s", path, strerror(errno));
    struct stat st;
    if (fstat(fd, &st) || st.st_size < 0) {
        int e = errno;
        close(fd);
        return iso_error_set(err, ISO_E_IO, "%s: %s", path, strerror(e));
    }
    size_t bytes = (size_t)st.st_size;
    chain_header h = {0};
    if (bytes >= sizeof h && pread(fd, &h, sizeof h, 0) != (ssize_t)sizeof h)
        bytes = 0;
    int rc = check_header(&h, bytes, path, err);
    void *data = rc ? MAP_FAILED : mmap(NULL, bytes, PROT_READ, MAP_PRIVATE, fd, 0);
    int map_errno = errno;
    close(fd); /* the mapping keeps the file */
    if (rc)
        return rc;
    if (data == MAP_FAILED)
        return iso_error_set(err, map_errno == ENOMEM ? ISO_E_NOMEM : ISO_E_IO, "%s: cannot map it: %s", path,
                             strerror(map_errno));
    iso_mesh_chain_map *m = calloc(1, sizeof *m + strlen(path) + 1);
    if (!m) {
        munmap(data, bytes);
        return iso_error_set(err, ISO_E_NOMEM, "out of memory mapping %s", path);
    }
    m->data = data;
    m->bytes = bytes;
    strcpy(m->path, path);
    pthread_mutex_init(&m->lock, NULL);
    memcpy(m->table, m->data + sizeof h, h.sections * sizeof *m->table);
    if ((rc = check_layout(m, &h, identity, err)) || (rc = take_records(m, &h, err))) {
        iso_mesh_chain_map_close(m);
        return rc;
    }
    *out = m;
    return 0;
}

const iso_mesh_chain *iso_mesh_chain_map_chain(const iso_mesh_chain_map *m)
{
    return &m->chain;
}

size_t iso_mesh_chain_map_bytes(const iso_mesh_chain_map *m)
{
    return m->chain.bytes;
}

/* A section's checksum; for a level's, every index below the vertex count too. */
static int check_section(const iso_mesh_chain_map *m, uint32_t i, iso_error *err)
{
    const chain_section *s = &m->table[i];
    if (crc_of(0, m->data + s->offset, s->bytes) != s->crc)
        return i == SECTION_POSITIONS
                   ? iso_error_set(err, ISO_E_CORRUPT, "%s: the positions' checksum mismatch", m->path)
                   : iso_error_set(err, ISO_E_CORRUPT, "%s: level %u's checksum mismatch", m->path,
                                   i - SECTION_LEVEL0);
    if (i < SECTION_LEVEL0)
        return 0;
    const iso_mesh_chain_level *lv = &m->chain.level[i - SECTION_LEVEL0];
    uint32_t worst = 0;
    for (size_t j = 0; j < 3 * lv->triangle_count; j++)
        worst = lv->indices[j] > worst ? lv->indices[j] : worst;
    if (lv->triangle_count && worst >= m->chain.vertex_count)
        return iso_error_set(err, ISO_E_CORRUPT, "%s: level %u has index %u of %zu vertices", m->path,
                             i - SECTION_LEVEL0, worst, m->chain.vertex_count);
    return 0;
}

int iso_mesh_chain_map_check(iso_mesh_chain_map *m, int k, iso_error *err)
{
    if (k < 0 || k >= m->chain.levels)
        return iso_error_set(err, ISO_E_ARGUMENT, "chain: no level %d (it has %d)", k, m->chain.levels);
    pthread_mutex_lock(&m->lock);
    int rc = m->bad ? iso_error_set(err, ISO_E_CORRUPT, "%s: found corrupt before", m->path) : 0;
    if (!rc && !m->positions_checked && !(rc = check_section(m, SECTION_POSITIONS, err)))
        m->positions_checked = 1;
    if (!rc && !m->level_checked[k] && !(rc = check_section(m, SECTION_LEVEL0 + (uint32_t)k, err)))
        m->level_checked[k] = 1;
    m->bad = rc != 0;
    pthread_mutex_unlock(&m->lock);
    return rc;
}

int iso_mesh_chain_map_grid(iso_mesh_chain_map *m, iso_error *err)
{
    int rc = iso_mesh_chain_map_check(m, 0, err);
    pthread_mutex_lock(&m->lock);
    if (!rc && !m->chain.grid && iso_mesh_chain_grid_build(&m->chain))
        rc = iso_error_set(err, ISO_E_NOMEM, "%s: no memory for level 0's grid", m->path);
    pthread_mutex_unlock(&m->lock);
    return rc;
}

void iso_mesh_chain_map_close(iso_mesh_chain_map *m)
{
    if (!m)
        return;
    iso_mesh_grid_destroy(m->chain.grid);
    munmap((void *)(uintptr_t)m->data, m->bytes);
    pthread_mutex_destroy(&m->lock);
    free(m);
}

/* Every byte between the sections is zero (a reader of the whole file checks them all). */
static int padding_zero(const iso_mesh_chain_map *m)
{
    uint64_t at = sizeof(chain_header) + (size_t)(m->chain.levels + SECTION_LEVEL0) * sizeof(chain_section);
    for (int i = 0; i < m->chain.levels + SECTION_LEVEL0; i++) {
        for (uint64_t b = at; b < m->table[i].offset; b++)
            if (m->data[b])
                return 0;
        at = m->table[i].offset + m->table[i].bytes;
    }
    return 1;
}

/* The mapped chain copied into memory of its own, for iso_mesh_chain_destroy. */
static int copy_chain(const iso_mesh_chain *from, iso_mesh_chain **out)
{
    iso_mesh_chain *c = calloc(1, sizeof *c);
    if (!c)
        return ISO_E_NOMEM;
    *c = *from;
    size_t positions = 3 * from->vertex_count * sizeof(float);
    c->levels = 0;
    c->bytes = sizeof *c + positions;
    c->positions = malloc(positions + sizeof(float));
    int rc = c->positions ? 0 : ISO_E_NOMEM;
    if (!rc)
        memcpy(c->positions, from->positions, positions);
    for (int k = 0; !rc && k < from->levels; k++) {
        size_t n = 3 * from->level[k].triangle_count * sizeof(uint32_t);
        if (!(c->level[k].indices = malloc(n + sizeof(uint32_t)))) {
            rc = ISO_E_NOMEM;
            break;
        }
        memcpy(c->level[k].indices, from->level[k].indices, n);
        c->levels = k + 1;
        c->bytes += n;
    }
    if (!rc)
        rc = iso_mesh_chain_grid_build(c);
    if (rc) {
        for (int k = c->levels; k <= ISO_CHAIN_LEVELS; k++)
            c->level[k].indices = NULL; /* copied records, not filled: nothing to free */
        iso_mesh_chain_destroy(c);
        return rc;
    }
    *out = c;
    return 0;
}

int iso_mesh_chain_load(const char *path, uint64_t identity, iso_mesh_chain **out, iso_error *err)
{
    *out = NULL;
    iso_mesh_chain_map *m;
    int rc = iso_mesh_chain_map_open(path, identity, &m, err);
    if (rc)
        return rc;
    for (int k = 0; !rc && k < m->chain.levels; k++)
        rc = iso_mesh_chain_map_check(m, k, err);
    if (!rc && !padding_zero(m))
        rc = iso_error_set(err, ISO_E_CORRUPT, "%s: bytes between sections are not zero", path);
    if (!rc && (rc = copy_chain(&m->chain, out)))
        iso_error_set(err, rc, "out of memory loading %s", path);
    iso_mesh_chain_map_close(m);
    return rc;
}
