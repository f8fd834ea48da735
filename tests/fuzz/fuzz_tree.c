/* fuzz_tree.c: libFuzzer target for the hierarchy-file reader (core/hierarchy/tree.c's
 * iso_tree_load): the input is a hierarchy file for a fixed 12^3 sphere. It must be
 * refused with an error or, when it passes every check, be the very tree iso_tree_build
 * makes; extraction from an accepted tree must run. */
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

#include "extract/extract.h"
#include "io/io.h"
#include "hierarchy/tree.h"

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size);

static iso_volume *vol;
static iso_tree *built;
static char path[256];

static void setup(void)
{
    iso_error err;
    if (iso_load("field:sphere:12", NULL, &vol, &err) || iso_tree_build(vol, 0, NULL, NULL, &built, &err))
        abort();
    const char *dir = getenv("TMPDIR");
    snprintf(path, sizeof path, "%s/isoserve-fuzz-%d.isotree", dir ? dir : "/tmp", (int)getpid());
}

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size)
{
    if (!vol)
        setup();
    FILE *f = fopen(path, "wb");
    if (!f || (size && fwrite(data, 1, size, f) != size))
        abort();
    fclose(f);
    iso_tree *tree = NULL;
    iso_error err;
    if (iso_tree_load(vol, path, &tree, &err) == 0) {
        if (tree->node_count != built->node_count ||
            memcmp(tree->nodes, built->nodes, iso_tree_bytes(built)) != 0)
            abort(); /* checksums passed on a tree that is not the volume's: impossible by CRC */
        iso_mesh mesh;
        iso_mesh_init(&mesh);
        iso_extract_params p = {.level = 4, .tolerance = 0.5, .coarsen = ISO_COARSEN_ALL};
        iso_extract_stats stats;
        if (iso_extract(tree, &p, &mesh, &stats, &err) != 0)
            abort();
        iso_mesh_free(&mesh);
        iso_tree_destroy(tree);
    } else if (tree) {
        abort();
    }
    unlink(path);
    return 0;
}
