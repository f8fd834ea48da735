/* fuzz_load.c: libFuzzer target for one volume loader, chosen at build time by the file
 * suffix FUZZ_SUFFIX (".nrrd", ".nii", ".mha"): the input is written to a file of that
 * suffix (the loaders read paths, as the server does) and loaded through iso_load under a
 * 64 MiB limit. Any outcome but a volume or an error report is a bug; a volume's samples
 * are read once so that a wrong size shows up under ASan. */
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

#include "io/io.h"

#ifndef FUZZ_SUFFIX
#error "build with -DFUZZ_SUFFIX=\".nrrd\" (or .nii, .mha)"
#endif

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size);

static char path[256];

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size)
{
    if (!path[0]) {
        const char *dir = getenv("TMPDIR");
        snprintf(path, sizeof path, "%s/isoserve-fuzz-%d" FUZZ_SUFFIX, dir ? dir : "/tmp", (int)getpid());
    }
    FILE *f = fopen(path, "wb");
    if (!f)
        abort();
    if (size && fwrite(data, 1, size, f) != size)
        abort();
    fclose(f);
    iso_load_options opt = {.max_bytes = (uint64_t)64 << 20};
    iso_volume *vol = NULL;
    iso_error err;
    int rc = iso_load(path, &opt, &vol, &err);
    if (rc == ISO_OK) {
        volatile double sum = 0;
        sum += iso_vol_get(vol, vol->dims[0] - 1, vol->dims[1] - 1, vol->dims[2] - 1);
        (void)sum;
        iso_vol_destroy(vol);
    } else if (vol || !err.message[0]) {
        abort();
    }
    unlink(path);
    return 0;
}
