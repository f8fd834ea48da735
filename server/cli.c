/* cli.c: helpers shared by the subcommands (see cli.h). */
#include "cli.h"

#include <errno.h>
#include <malloc.h>
#include <math.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>
#include <unistd.h>

#include "base/base.h"
#include "io/io.h"
#include "volume/volume.h"
#include "query.h"

int srv_fail(const char *fmt, ...)
{
    va_list ap;
    fputs("isoserve: ", stderr);
    va_start(ap, fmt);
    vfprintf(stderr, fmt, ap);
    va_end(ap);
    fputc('\n', stderr);
    return 1;
}

void srv_progress(void *label, double fraction)
{
    static int tty = -1;
    if (tty < 0)
        tty = isatty(STDERR_FILENO);
    if (!tty)
        return;
    fprintf(stderr, "\r%s: %3d%%", (const char *)label, (int)(fraction * 100 + 0.5));
    if (fraction >= 1)
        fputc('\n', stderr);
    fflush(stderr);
}

const char srv_volume_help[] =
    "VOLUME is a file (.nrrd, .nhdr, .nii, .nii.gz, .mhd, .mha, raw samples with a NAME.json sidecar),\n"
    "a DICOM series (a directory, DIR#SeriesInstanceUID, or a multi-frame FILE.dcm),\n"
    "or field:NAME[:WxHxD] (sphere, torus, ml, constant, spike, ijk).\n";

int srv_next_arg(const srv_command *cmd, int argc, char **argv, int *i, const char **value)
{
    *value = NULL;
    if (*i >= argc)
        return SRV_ARG_END;
    const char *a = argv[(*i)++];
    if (!strcmp(a, "-h") || !strcmp(a, "--help")) {
        srv_usage(cmd, stdout);
        return SRV_ARG_HELP;
    }
    if (a[0] != '-' || !a[1]) {
        *value = a;
        return SRV_ARG_OPERAND;
    }
    for (size_t k = 0; k < cmd->option_count; k++) {
        const srv_option *o = &cmd->options[k];
        if (strcmp(a, o->name))
            continue;
        if (o->value && *i >= argc) {
            srv_fail("%s: %s needs a value (%s)", cmd->name, a, o->value);
            return SRV_ARG_ERROR;
        }
        if (o->value)
            *value = argv[(*i)++];
        return (int)k;
    }
    srv_fail("%s: unknown option '%s' (isoserve %s --help lists them)", cmd->name, a, cmd->name);
    return SRV_ARG_ERROR;
}

void srv_usage(const srv_command *cmd, FILE *to)
{
    const char help[] = "-h, --help";
    int width = (int)sizeof help - 1;
    char left[96];
    for (size_t k = 0; k < cmd->option_count; k++) {
        const srv_option *o = &cmd->options[k];
        int n = snprintf(left, sizeof left, "%s%s%s", o->name, o->value ? " " : "", o->value ? o->value : "");
        width = n > width ? n : width;
    }
    fprintf(to, "usage: isoserve %s %s\n\n%s\n\noptions:\n", cmd->name, cmd->synopsis, cmd->summary);
    for (size_t k = 0; k < cmd->option_count; k++) {
        const srv_option *o = &cmd->options[k];
        snprintf(left, sizeof left, "%s%s%s", o->name, o->value ? " " : "", o->value ? o->value : "");
        fprintf(to, "  %-*s  %s\n", width, left, o->help);
    }
    fprintf(to, "  %-*s  %s\n", width, help, "this text");
    if (cmd->takes_volume)
        fprintf(to, "\n%s", srv_volume_help);
}

int srv_parse_number(const char *text, double *out)
{
    char *end;
    errno = 0;
    double v = strtod(text, &end);
    if (!*text || *end || errno == ERANGE || !isfinite(v))
        return ISO_E_ARGUMENT;
    *out = v;
    return 0;
}

int srv_parse_threads(const char *command, const char *text, int *threads)
{
    char *end;
    errno = 0;
    long n = strtol(text, &end, 10);
    if (!*text || *end || errno || n < 1 || n > 256)
        return srv_fail("%s: --threads '%s': expected a whole number from 1 to 256", command, text);
    *threads = (int)n;
    return 0;
}

int srv_parse_coarsen(const char *command, const char *text, iso_coarsen *coarsen)
{
    if (!strcmp(text, "faster"))
        *coarsen = ISO_COARSEN_WHERE_FASTER;
    else if (!strcmp(text, "all"))
        *coarsen = ISO_COARSEN_ALL;
    else
        return srv_fail("%s: --coarsen '%s': expected faster or all", command, text);
    return 0;
}

int srv_parse_dims(const char *text, size_t dims[3])
{
    unsigned long long v[3];
    int n = 0;
    char tail;
    if (sscanf(text, "%llux%llux%llu%c", &v[0], &v[1], &v[2], &tail) == 3)
        n = 3;
    else if (sscanf(text, "%llu%c", &v[0], &tail) == 1) {
        v[1] = v[2] = v[0];
        n = 3;
    }
    for (int d = 0; d < n; d++) {
        if (v[d] < 2 || v[d] > 65536)
            return ISO_E_ARGUMENT;
        dims[d] = (size_t)v[d];
    }
    return n == 3 ? 0 : ISO_E_ARGUMENT;
}

int srv_open(const srv_open_options *opt, srv_subject *out)
{
    iso_error err;
    double start = iso_clock_ms();
    memset(out, 0, sizeof *out);
    out->name = opt->path;
    char label[] = "loading"; /* drawn only for slow loads that report progress (DICOM series) */
    iso_load_options lopt = {.progress = srv_progress, .progress_context = label};
    if (iso_load(opt->path, &lopt, &out->vol, &err))
        return srv_fail("%s", err.message);
    if (opt->resample) {
        size_t dims[3];
        if (srv_parse_dims(opt->resample, dims))
            return srv_fail("--resample %s: expected WxHxD with each size 2..65536", opt->resample);
        iso_volume *small = iso_resample(out->vol, dims, &err);
        if (!small)
            return srv_fail("%s: resampling: %s", opt->path, err.message);
        iso_vol_destroy(out->vol);
        out->vol = small;
    }
    out->load_ms = iso_clock_ms() - start;
    if (!opt->want_tree)
        return 0;
    int rc = opt->hierarchy ? iso_tree_load(out->vol, opt->hierarchy, &out->tree, &err)
                            : iso_tree_build(out->vol, opt->threads, srv_progress, (void *)"building hierarchy", &out->tree, &err);
    if (rc) {
        srv_close(out);
        return srv_fail("%s", err.message);
    }
    return 0;
}

void srv_close(srv_subject *s)
{
    iso_tree_destroy(s->tree);
    iso_vol_destroy(s->vol);
    memset(s, 0, sizeof *s);
}

/* Returns of mallopt are ignored: it is a tuning, and sanitizers stub it. */
void srv_keep_freed_memory(void)
{
    mallopt(M_MMAP_THRESHOLD, 32 << 20);
    mallopt(M_TRIM_THRESHOLD, 1 << 30);
}

static int ends_with(const char *s, const char *suffix)
{
    size_t n = strlen(s), m = strlen(suffix);
    return n >= m && !strcmp(s + n - m, suffix);
}

int srv_format_of_path(const char *path)
{
    static const struct { const char *suffix; proto_format format; } formats[] = {
        {".ply", PROTO_FORMAT_PLY}, {".obj", PROTO_FORMAT_OBJ}, {".drc", PROTO_FORMAT_DRACO},
        {".meshopt.glb", PROTO_FORMAT_GLB_MESHOPT}, {".plain.glb", PROTO_FORMAT_GLB_PLAIN},
        {".glb", PROTO_FORMAT_GLB},
        {".stl", PROTO_FORMAT_STL}};
    if (!path)
        return PROTO_FORMAT_NONE;
    for (size_t i = 0; i < sizeof formats / sizeof formats[0]; i++)
        if (ends_with(path, formats[i].suffix))
            return (int)formats[i].format;
    return -1;
}

int srv_write_file(const unsigned char *bytes, size_t size, const char *path)
{
    size_t len = strlen(path) + 8;
    char *tmp = malloc(len);
    FILE *f = tmp ? (snprintf(tmp, len, "%s.tmp", path), fopen(tmp, "wb")) : NULL;
    int ok = f && fwrite(bytes, 1, size, f) == size;
    ok = f && fclose(f) == 0 && ok;
    ok = ok && rename(tmp, path) == 0;
    if (!ok && tmp)
        remove(tmp);
    free(tmp);
    return ok ? 0 : srv_fail("%s: cannot write the mesh", path);
}
