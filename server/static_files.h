/* static_files.h: the web client's files, served from one directory (--web-root).
 *
 * A URL path maps to a regular file under the root only: no "..", no hidden names, no
 * backslashes or NUL, no symbolic link leading outside (checked on the resolved path), so
 * a request never reads anything else. "/" is index.html. */
#ifndef SRV_STATIC_FILES_H
#define SRV_STATIC_FILES_H

#include <stddef.h>

/* Opens the file for url_path under root (an absolute, resolved directory). Returns 0
 * with *fd open (the caller closes it or hands it to the response), its size and
 * Content-Type; ISO_E_IO when there is no such file or the path is refused (the HTTP
 * layer answers 404 either way, so a refused path looks like a missing one). */
int srv_static_open(const char *root, const char *url_path, int *fd, size_t *size,
                    const char **content_type);

#endif
