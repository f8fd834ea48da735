/* file.c: a file replaced whole, never half-written: the parts go to a temporary file
 * beside it, which is synced and renamed over the old one, so a reader (or a server that
 * crashes mid-write) sees the old file or the new one, nothing in between. */
#include "base.h"

#include <errno.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

static int write_all(int fd, const void *buf, size_t n)
{
    const char *p = buf;
    while (n) {
        ssize_t w = write(fd, p, n);
        if (w < 0) {
            if (errno == EINTR)
                continue;
            return -1;
        }
        p += w;
        n -= (size_t)w;
    }
    return 0;
}

int iso_file_replace(const char *path, const iso_file_part *parts, size_t count, iso_error *err)
{
    size_t len = strlen(path);
    char *tmp = malloc(len + 16);
    if (!tmp)
        return iso_error_set(err, ISO_E_NOMEM, "out of memory saving %s", path);
    snprintf(tmp, len + 16, "%s.tmp.XXXXXX", path);
    int fd = mkstemp(tmp);
    if (fd < 0) {
        int e = errno;
        free(tmp);
        return iso_error_set(err, ISO_E_IO, "%s: cannot create a temporary file: %s", path, strerror(e));
    }
    int failed = 0;
    for (size_t i = 0; !failed && i < count; i++)
        failed = write_all(fd, parts[i].data, parts[i].bytes);
    if (failed || fsync(fd) != 0) {
        int e = errno;
        close(fd);
        unlink(tmp);
        free(tmp);
        return iso_error_set(err, ISO_E_IO, "%s: write failed: %s", path, strerror(e));
    }
    if (close(fd) != 0 || rename(tmp, path) != 0) {
        int e = errno;
        unlink(tmp);
        free(tmp);
        return iso_error_set(err, ISO_E_IO, "%s: cannot put the file in place: %s", path, strerror(e));
    }
    free(tmp);
    return 0;
}
