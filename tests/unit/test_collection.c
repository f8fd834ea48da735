/* test_collection.c: the collection's bounded memory (server/collection.c, white-box):
 * with a cap on resident bytes, loads evict the least recently used volume nobody holds,
 * never a held one; a held volume stays valid past the cap; releasing the last holder
 * brings the resident bytes back under the cap; an evicted volume comes back with its
 * hierarchy read from the cache dir, never built twice; preloading stops at the cap. */
#include <stdio.h>
#include <string.h>

#include "check.h"
#include "collection.h"

#define ENTRIES 4

/* Four identical small fields (same bytes each), so that a cap of 2.5 volumes holds 2. */
static int read_catalog(srv_catalog *catalog)
{
    char file[512];
    snprintf(file, sizeof file, "%s/catalog.json", check_temp_dir());
    const char text[] = "{\"volumes\": [{\"id\": \"a\", \"path\": \"field:sphere:24\"},"
                        "{\"id\": \"b\", \"path\": \"field:sphere:24\"},"
                        "{\"id\": \"c\", \"path\": \"field:sphere:24\"},"
                        "{\"id\": \"d\", \"path\": \"field:sphere:24\"}]}\n";
    check_write_file(file, text, sizeof text - 1, NULL, 0);
    iso_error err = {0};
    int rc = srv_catalog_read(file, catalog, &err);
    CHECK_OK(rc, &err);
    return rc;
}

static const srv_volume *take(srv_collection *c, const char *id)
{
    const srv_volume *v = NULL;
    CHECK_EQ(srv_collection_acquire(c, id, &v), SRV_VOLUME_READY);
    CHECK(v && v->vol && v->tree && !strcmp(v->entry->id, id));
    return v;
}

static int state_of(const srv_collection *c, const char *id)
{
    return c->state[srv_catalog_find(c->catalog, id)];
}

static void test_eviction_least_recently_used(void)
{
    srv_catalog catalog;
    if (read_catalog(&catalog))
        return;
    char dir[512];
    snprintf(dir, sizeof dir, "%s/trees", check_temp_dir());
    srv_preload_options options = {.cache_dir = dir};
    srv_collection c;
    CHECK(srv_collection_init(&c, &catalog, &options) == 0);
    srv_collection_preload(&c); /* no cap yet: all four, hierarchies built and saved */
    CHECK_EQ(atomic_load(&c.count), ENTRIES);
    CHECK_EQ(atomic_load(&c.trees_built), ENTRIES);
    size_t bytes = c.volumes[0].bytes;
    CHECK(bytes > 24 * 24 * 24 * 4);
    CHECK_EQ(atomic_load(&c.resident), ENTRIES * bytes);

    c.options.max_resident_bytes = 2 * bytes + bytes / 2;
    const srv_volume *a = take(&c, "a");
    srv_collection_release(&c, take(&c, "b")); /* over the cap: c and d, least recent, go */
    CHECK_EQ(atomic_load(&c.evictions), 2);
    CHECK_EQ(state_of(&c, "c"), SRV_ENTRY_IDLE);
    CHECK_EQ(state_of(&c, "d"), SRV_ENTRY_IDLE);
    CHECK_EQ(atomic_load(&c.resident), 2 * bytes);

    /* c comes back from its file, and b, the least recent that nobody holds, goes. */
    srv_collection_release(&c, take(&c, "c"));
    CHECK_EQ(atomic_load(&c.trees_built), ENTRIES);
    CHECK_EQ(atomic_load(&c.trees_read), 1);
    CHECK_EQ(state_of(&c, "a"), SRV_ENTRY_LOADED); /* held: never the victim */
    CHECK_EQ(state_of(&c, "b"), SRV_ENTRY_IDLE);
    CHECK_EQ(atomic_load(&c.evictions), 3);
    CHECK(a->vol && a->tree);

    /* All held: the cap is exceeded while they are, and met again when they are released. */
    const srv_volume *held[ENTRIES];
    const char *ids[ENTRIES] = {"a", "b", "c", "d"};
    for (size_t i = 0; i < ENTRIES; i++)
        held[i] = take(&c, ids[i]);
    CHECK_EQ(atomic_load(&c.count), ENTRIES);
    CHECK_EQ(atomic_load(&c.resident), ENTRIES * bytes);
    srv_collection_retain(&c, held[3]); /* a mesh job's own reference */
    for (size_t i = 0; i < ENTRIES; i++)
        srv_collection_release(&c, held[i]);
    srv_collection_release(&c, a);
    CHECK_EQ(atomic_load(&c.count), 2); /* d is still held by the job */
    CHECK_EQ(state_of(&c, "d"), SRV_ENTRY_LOADED);
    CHECK(held[3]->vol && held[3]->tree);
    srv_collection_release(&c, held[3]);
    CHECK(atomic_load(&c.resident) <= c.options.max_resident_bytes);
    CHECK_EQ(atomic_load(&c.trees_built), ENTRIES); /* every later load read its file */
    CHECK_EQ(atomic_load(&c.trees_built) + atomic_load(&c.trees_read) - atomic_load(&c.count),
             atomic_load(&c.evictions)); /* every load but those still loaded was evicted */
    srv_collection_free(&c);

    /* Preloading with the cap stops once it is reached; the rest load on demand. */
    options.max_resident_bytes = 2 * bytes + bytes / 2;
    CHECK(srv_collection_init(&c, &catalog, &options) == 0);
    srv_collection_preload(&c);
    CHECK_EQ(atomic_load(&c.count), 3);
    CHECK_EQ(atomic_load(&c.ready), 1);
    CHECK_EQ(state_of(&c, "d"), SRV_ENTRY_IDLE);
    srv_collection_release(&c, take(&c, "d"));
    CHECK_EQ(atomic_load(&c.count), 2);
    CHECK_EQ(atomic_load(&c.trees_built), 0);
    srv_collection_free(&c);
    srv_catalog_free(&catalog);
}

int main(void)
{
    CHECK_RUN(test_eviction_least_recently_used);
    return check_finish();
}
