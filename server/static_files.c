/* static_files.c: safe static file lookup for the web client (see static_files.h). */
#include "static_files.h"

#include <fcntl.h>
#include <limits.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <unistd.h>

#include "base/base.h"

static const struct {
    const char *suffix, *type;
} content_types[] = {
    {".html", "text/html; charset=utf-8"},
    {".js", "text/javascript; charset=utf-8"},
    {".mjs", "text/javascript; charset=utf-8"},
    {".css", "text/css; charset=utf-8"},
    {".json", "application/json"},
    {".wasm", "application/wasm"},
    {".png", "image/png"},
    {".svg", "image/svg+xml"},
    {".ico", "image/x-icon"},
    {".txt", "text/plain; charset=utf-8"},
};

static const char *type_of(const char *path)
{
    size_t n = strlen(path);
    for (size_t i = 0; i < sizeof content_types / sizeof content_types[0]; i++) {
        size_t s = strlen(content_types[i].suffix);
        if (n >= s && !strcmp(path + n - s, content_types[i].suffix))
            return content_types[i].type;
    }
    return "application/octet-stream";
}

/* Every segment a plain name: not empty, not starting with '.', no '\\'. */
static int path_allowed(const char *url_path)
{
    if (url_path[0] != '/' || strchr(url_path, '\\'))
        return 0;
    for (const char *seg = url_path + 1; *seg;) {
        const char *end = strchr(seg, '/');
        size_t len = end ? (size_t)(end - seg) : strlen(seg);
        if (len == 0 || seg[0] == '.')
            return 0;
        seg += len + (end != NULL);
    }
    return 1;
}

int srv_static_open(const char *root, const char *url_path, int *fd, size_t *size,
                    const char **content_type)
{
    *fd = -1;
    if (!strcmp(url_path, "/"))
        url_path = "/index.html";
    if (!path_allowed(url_path) || strlen(root) + strlen(url_path) >= PATH_MAX)
        return ISO_E_IO;
    char joined[PATH_MAX], resolved[PATH_MAX];
    size_t root_len = strlen(root), path_len = strlen(url_path);
    memcpy(joined, root, root_len);
    memcpy(joined + root_len, url_path, path_len + 1);
    if (!realpath(joined, resolved) || strncmp(resolved, root, root_len) ||
        resolved[root_len] != '/')
        return ISO_E_IO;
    int f = open(resolved, O_RDONLY | O_CLOEXEC);
    struct stat st;
    if (f < 0)
        return ISO_E_IO;
    if (fstat(f, &st) || !S_ISREG(st.st_mode)) {
        close(f);
        return ISO_E_IO;
    }
    *fd = f;
    *size = (size_t)st.st_size;
    *content_type = type_of(resolved);
    return 0;
}
