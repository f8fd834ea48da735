/* chain_file.c: a simplification chain written to a file and read back (see mesh.h).
 *
 * The file: a 72-byte header (magic, version, the size of a level record, the caller's
 * identity, counts, the caller's faithful triangle count, the payload's CRC-32 and the
 * header's), then the payload: one level
 * record per level (iso_mesh_chain_level as this build lays it out, its index pointer
 * zero), the positions (3 floats per vertex), and each level's indices (3 uint32 per
 * triangle) in order. Reading checks all of it, and every index against the vertex count,
 * before anything is used; a file of another version, another record layout or another
 * identity is stale (ISO_E_STALE), one whose sizes or checksums disagree is corrupt
 * (ISO_E_CORRUPT). Writing goes to a temporary file renamed into place, so a reader never
 * sees half a file. Level 0's search grid is not in the file: reading builds it again. */
#include "distance.h"

#include <errno.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <zlib.h>

#include "base/base.h"

#define CHAIN_MAGIC "ISOCHAIN"
#define CHAIN_VERSION 2u /* 2: the faithful triangle count, each level's value error */

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
    uint32_t payload_crc;
    uint32_t header_crc;     /* with this field zero */
} chain_header;

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

static uint32_t header_crc(chain_header h)
{
    h.header_crc = 0;
    return crc_of(0, &h, sizeof h);
}

/* The payload's parts in file order, for writing and for the checksum. */
static size_t parts_of(const iso_mesh_chain *c, iso_mesh_chain_level *records, iso_file_part *parts)
{
    size_t n = 0;
    for (int k = 0; k < c->levels; k++) {
        records[k] = c->level[k];
        records[k].indices = NULL;
    }
    parts[n++] = (iso_file_part){records, (size_t)c->levels * sizeof *records};
    parts[n++] = (iso_file_part){c->positions, 3 * c->vertex_count * sizeof *c->positions};
    for (int k = 0; k < c->levels; k++)
        parts[n++] = (iso_file_part){c->level[k].indices, 3 * c->level[k].triangle_count * sizeof(uint32_t)};
    return n;
}

int iso_mesh_chain_save(const iso_mesh_chain *chain, const char *path, uint64_t identity,
                        iso_error *err)
{
    iso_mesh_chain_level records[ISO_CHAIN_LEVELS + 1];
    iso_file_part parts[ISO_CHAIN_LEVELS + 4]; /* the header, then the payload */
    memset(records, 0, sizeof records);
    size_t n = parts_of(chain, records, parts + 1);
    chain_header h = {.version = CHAIN_VERSION, .record_bytes = sizeof(iso_mesh_chain_level),
                      .identity = identity, .vertex_count = chain->vertex_count,
                      .levels = (uint32_t)chain->levels, .closed = chain->closed,
                      .voxel_size = chain->voxel_size, .volume = chain->volume,
                      .faithful_triangles = chain->faithful_triangles};
    memcpy(h.magic, CHAIN_MAGIC, sizeof h.magic);
    for (size_t i = 1; i <= n; i++)
        h.payload_crc = crc_of(h.payload_crc, parts[i].data, parts[i].bytes);
    h.header_crc = header_crc(h);
    parts[0] = (iso_file_part){&h, sizeof h};
    return iso_file_replace(path, parts, n + 1, err);
}

/* Reads the whole file; *bytes its size. */
static int read_file(const char *path, unsigned char **out, size_t *bytes, iso_error *err)
{
    FILE *f = fopen(path, "rb");
    if (!f)
        return iso_error_set(err, ISO_E_IO, "%s: %s", path, strerror(errno));
    long size = fseek(f, 0, SEEK_END) == 0 ? ftell(f) : -1;
    unsigned char *data = size >= 0 ? malloc((size_t)size + 1) : NULL;
    int ok = data && fseek(f, 0, SEEK_SET) == 0 && fread(data, 1, (size_t)size, f) == (size_t)size;
    fclose(f);
    if (!ok) {
        free(data);
        return size < 0 ? iso_error_set(err, ISO_E_IO, "%s: cannot read it", path)
                        : iso_error_set(err, data ? ISO_E_IO : ISO_E_NOMEM, "%s: cannot read %ld bytes", path, size);
    }
    *out = data;
    *bytes = (size_t)size;
    return 0;
}

/* The header's checks, then the sizes the payload must have. */
static int check_header(const chain_header *h, size_t file_bytes, uint64_t identity, const char *path,
                        iso_error *err)
{
    if (file_bytes < sizeof *h || memcmp(h->magic, CHAIN_MAGIC, sizeof h->magic))
        return iso_error_set(err, ISO_E_FORMAT, "%s: not a chain file (bad magic)", path);
    if (h->header_crc != header_crc(*h))
        return iso_error_set(err, ISO_E_CORRUPT, "%s: header checksum mismatch", path);
    if (h->version != CHAIN_VERSION || h->record_bytes != sizeof(iso_mesh_chain_level))
        return iso_error_set(err, ISO_E_STALE, "%s: version %u (records of %u bytes), this build "
                             "reads version %u (%zu)", path, h->version, h->record_bytes,
                             CHAIN_VERSION, sizeof(iso_mesh_chain_level));
    if (h->identity != identity)
        return iso_error_set(err, ISO_E_STALE, "%s: made for another surface or volume version", path);
    if (h->levels < 1 || h->levels > ISO_CHAIN_LEVELS + 1 || h->vertex_count > UINT32_MAX ||
        !(h->voxel_size > 0))
        return iso_error_set(err, ISO_E_CORRUPT, "%s: %u levels, %llu vertices", path, h->levels,
                             (unsigned long long)h->vertex_count);
    return 0;
}

int iso_mesh_chain_load(const char *path, uint64_t identity, iso_mesh_chain **out, iso_error *err)
{
    *out = NULL;
    unsigned char *data = NULL;
    size_t bytes = 0;
    int rc = read_file(path, &data, &bytes, err);
    if (rc)
        return rc;
    chain_header h;
    memcpy(&h, data, bytes < sizeof h ? bytes : sizeof h);
    if ((rc = check_header(&h, bytes, identity, path, err))) {
        free(data);
        return rc;
    }
    iso_mesh_chain *c = calloc(1, sizeof *c);
    if (!c) {
        free(data);
        return iso_error_set(err, ISO_E_NOMEM, "out of memory loading %s", path);
    }
    const unsigned char *at = data + sizeof h, *end = data + bytes;
    size_t records = h.levels * sizeof(iso_mesh_chain_level);
    size_t positions = 3 * (size_t)h.vertex_count * sizeof(float);
    rc = (size_t)(end - at) < records + positions ? ISO_E_CORRUPT : 0;
    if (!rc) {
        memcpy(c->level, at, records);
        at += records;
        c->vertex_count = (size_t)h.vertex_count;
        c->voxel_size = h.voxel_size;
        c->volume = h.volume;
        c->closed = h.closed;
        c->faithful_triangles = (size_t)h.faithful_triangles;
        c->positions = malloc(positions + sizeof(float));
        if (!c->positions)
            rc = ISO_E_NOMEM;
        else
            memcpy(c->positions, at, positions), at += positions;
    }
    c->bytes = sizeof *c + positions;
    for (uint32_t k = 0; !rc && k < h.levels; k++) {
        iso_mesh_chain_level *lv = &c->level[k];
        size_t n = 3 * lv->triangle_count;
        if (lv->triangle_count > (size_t)(end - at) / (3 * sizeof(uint32_t))) {
            rc = ISO_E_CORRUPT;
            break;
        }
        if (!(lv->indices = malloc(n * sizeof *lv->indices + sizeof(uint32_t)))) {
            rc = ISO_E_NOMEM;
            break;
        }
        c->levels = (int)k + 1;
        memcpy(lv->indices, at, n * sizeof *lv->indices);
        at += n * sizeof *lv->indices;
        c->bytes += n * sizeof *lv->indices;
        for (size_t i = 0; i < n && !rc; i++)
            rc = lv->indices[i] < c->vertex_count ? 0 : ISO_E_CORRUPT;
    }
    if (!rc && (at != end || crc_of(0, data + sizeof h, bytes - sizeof h) != h.payload_crc))
        rc = ISO_E_CORRUPT;
    free(data);
    if (rc) {
        for (int k = c->levels; k <= ISO_CHAIN_LEVELS; k++)
            c->level[k].indices = NULL; /* records read but not filled: nothing to free */
        iso_mesh_chain_destroy(c);
        return rc == ISO_E_NOMEM ? iso_error_set(err, rc, "out of memory loading %s", path)
                                 : iso_error_set(err, rc, "%s: sizes, indices or checksum do not match", path);
    }
    c->levels = (int)h.levels;
    if (iso_mesh_chain_grid_build(c)) {
        iso_mesh_chain_destroy(c);
        return iso_error_set(err, ISO_E_NOMEM, "out of memory for the grid of %s", path);
    }
    *out = c;
    return 0;
}
