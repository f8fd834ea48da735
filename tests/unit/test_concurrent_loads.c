/* test_concurrent_loads.c: loads of different volumes of every format on different
 * threads at once (as a server's first requests for several volumes start them) give
 * exactly what the same loads give one after another. libnifti and GDCM keep settings in
 * process globals; run under the sanitizers (build/san) this also checks that nothing
 * else is shared. */
#include <pthread.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

#include "check.h"
#include "io/io.h"
#include "volume/volume.h"

#define MRICRON "/usr/share/mricron/templates/"
#define HELPER "/usr/bin/python3 tests/support/dicom_series.py"
#define FILES_MAX 12
#define THREADS_PER_FILE 2
#define ROUNDS 3

typedef struct job {
    const char *path;
    pthread_barrier_t *start;
    iso_volume *vol;
    int rc;
    iso_error err;
} job;

/* A small int16 ramp whose samples depend on seed: i + 7 j + 31 k + seed. */
static void ramp(int16_t *data, const size_t dims[3], int seed)
{
    for (size_t k = 0; k < dims[2]; k++)
        for (size_t j = 0; j < dims[1]; j++)
            for (size_t i = 0; i < dims[0]; i++)
                data[(k * dims[1] + j) * dims[0] + i] = (int16_t)(i + 7 * j + 31 * k + (size_t)seed);
}

/* A raw NRRD (nrrd) or a MetaImage with local data (mha) of ramp(seed). */
static void write_volume(const char *path, int mha, int seed)
{
    const size_t dims[3] = {17, 13, 11};
    int16_t data[17 * 13 * 11];
    ramp(data, dims, seed);
    char header[512];
    int n = mha ? snprintf(header, sizeof header,
                           "ObjectType = Image\nNDims = 3\nBinaryData = True\nBinaryDataByteOrderMSB = False\n"
                           "ElementSpacing = 1 1.5 2\nDimSize = 17 13 11\nElementType = MET_SHORT\n"
                           "ElementDataFile = LOCAL\n")
                : snprintf(header, sizeof header,
                           "NRRD0004\ntype: int16\ndimension: 3\nsizes: 17 13 11\nspacings: 1 1.5 2\n"
                           "encoding: raw\nendian: little\n\n");
    check_write_file(path, header, (size_t)n, data, sizeof data);
}

static void *run(void *arg)
{
    job *j = arg;
    pthread_barrier_wait(j->start);
    j->rc = iso_load(j->path, NULL, &j->vol, &j->err);
    return NULL;
}

static int same(const iso_volume *a, const iso_volume *b)
{
    return a && b && !memcmp(a->dims, b->dims, sizeof a->dims) && a->type == b->type &&
           !memcmp(a->spacing, b->spacing, sizeof a->spacing) &&
           !memcmp(a->data, b->data, iso_vol_count(a) * iso_vol_type_size(a->type));
}

/* The test's files: NIfTI from Debian's mricron-data, NRRD and MetaImage written here,
 * DICOM series written by the pydicom helper (when pydicom is installed). */
static size_t gather(const char *paths[FILES_MAX], char store[FILES_MAX][512], int *formats)
{
    static const char *nifti[] = {MRICRON "ch2bet.nii.gz", MRICRON "ch2.nii.gz", MRICRON "AICHAmc.nii.gz"};
    size_t n = 0;
    *formats = 0;
    for (size_t i = 0; i < 3; i++)
        if (!access(nifti[i], R_OK))
            paths[n++] = nifti[i];
    *formats += n > 1;
    for (int s = 0; s < 2; s++) {
        snprintf(store[n], 512, "%s/ramp%d.nrrd", check_temp_dir(), s);
        write_volume(store[n], 0, 100 * s);
        paths[n] = store[n], n++;
        snprintf(store[n], 512, "%s/ramp%d.mha", check_temp_dir(), s);
        write_volume(store[n], 1, 100 * s + 50);
        paths[n] = store[n], n++;
    }
    *formats += 2;
    size_t before = n;
    for (int s = 0; s < 2; s++) {
        char cmd[1200];
        snprintf(store[n], 512, "%s/dicom%d", check_temp_dir(), s);
        snprintf(cmd, sizeof cmd, "%s phantom %s %s > /dev/null 2>&1", HELPER, store[n], s ? "--rle" : "");
        if (system(cmd) == 0)
            paths[n] = store[n], n++;
    }
    *formats += n > before;
    return n;
}

/* Every file loaded by THREADS_PER_FILE threads at once, all released by one barrier,
 * ROUNDS times: each result equals the file's load on this thread alone. */
static void test_concurrent_first_loads(void)
{
    const char *paths[FILES_MAX];
    char store[FILES_MAX][512];
    int formats;
    size_t files = gather(paths, store, &formats);
    iso_volume *alone[FILES_MAX] = {0};
    for (size_t f = 0; f < files; f++) {
        iso_error err = {0};
        CHECK_OK(iso_load(paths[f], NULL, &alone[f], &err), &err);
    }
    size_t threads = files * THREADS_PER_FILE, matched = 0;
    job jobs[FILES_MAX * THREADS_PER_FILE];
    pthread_t tids[FILES_MAX * THREADS_PER_FILE];
    pthread_barrier_t start;
    for (int round = 0; round < ROUNDS && !check_failed(); round++) {
        pthread_barrier_init(&start, NULL, (unsigned)threads);
        for (size_t t = 0; t < threads; t++) {
            jobs[t] = (job){.path = paths[t % files], .start = &start};
            CHECK(pthread_create(&tids[t], NULL, run, &jobs[t]) == 0);
        }
        for (size_t t = 0; t < threads; t++)
            pthread_join(tids[t], NULL);
        pthread_barrier_destroy(&start);
        for (size_t t = 0; t < threads; t++) {
            CHECKF(jobs[t].rc == 0, "%s: %s", jobs[t].path, jobs[t].err.message);
            CHECKF(same(jobs[t].vol, alone[t % files]), "%s differs when loaded concurrently", jobs[t].path);
            matched += same(jobs[t].vol, alone[t % files]);
            iso_vol_destroy(jobs[t].vol);
        }
    }
    CHECK_EQ(matched, (size_t)ROUNDS * threads);
    for (size_t f = 0; f < files; f++)
        iso_vol_destroy(alone[f]);
    if (formats < 4)
        check_skip("only %d of 4 formats (NIfTI needs mricron-data, DICOM python3-pydicom)", formats);
}

int main(void)
{
    CHECK_RUN(test_concurrent_first_loads);
    return check_finish();
}
