/* cmd_volume.c: `isoserve info` (what a volume is) and `isoserve build` (its hierarchy
 * file). */
#include <jansson.h>
#include <stdio.h>
#include <string.h>

#include "cli.h"
#include "collection.h"

/* The id `serve --volumes` would give the volume (catalog.h), its characters outside
 * [A-Za-z0-9._-] made '-' (a field: or DIR#UID argument has some). */
static void id_of_path(const char *path, char id[SRV_ID_MAX + 1])
{
    const char *slash = strrchr(path, '/');
    const char *base = slash && slash[1] ? slash + 1 : path;
    char whole[4096];
    srv_catalog_id_of(base, whole, sizeof whole);
    size_t n = strnlen(whole, SRV_ID_MAX);
    memcpy(id, whole, n);
    id[n] = '\0';
    for (char *c = id; *c; c++)
        if (!strchr("abcdefghijklmnopqrstuvwxyzABCDEFGHIJKLMNOPQRSTUVWXYZ0123456789._-", *c))
            *c = '-';
}

/* The volume's entry of /v1/volumes when served with `serve --volumes` (the same code builds
 * it: srv_volume_describe, srv_volume_doc), plus what only the command line tells: the path,
 * the samples' bytes, their mean and whether any is NaN. NULL when memory runs out. */
static char *info_json(const srv_subject *s)
{
    srv_catalog_entry entry = {.name = "", .modality = ""};
    id_of_path(s->name, entry.id);
    srv_volume v = {.entry = &entry, .vol = s->vol};
    srv_volume_describe(&v, iso_tree_volume_crc(s->vol));
    proto_volume_doc doc = srv_volume_doc(&v, NULL);
    char *text = proto_json_volume(&doc, 0);
    json_t *o = text ? json_loads(text, 0, NULL) : NULL;
    free(text);
    const iso_volume *vol = s->vol;
    if (o && json_object_update_new(o, json_pack("{s:s, s:I, s:f, s:b}", "path", s->name, "bytes",
                                                 (json_int_t)(iso_vol_count(vol) * iso_vol_type_size(vol->type)),
                                                 "value_mean", vol->value_mean, "has_nan", vol->has_nan))) {
        json_decref(o);
        return NULL;
    }
    text = o ? json_dumps(o, JSON_COMPACT | JSON_REAL_PRECISION(17)) : NULL;
    json_decref(o);
    return text;
}

enum { INFO_JSON, INFO_RESAMPLE, INFO_OPTIONS };
static const srv_option info_options[INFO_OPTIONS] = {
    [INFO_JSON] = {"--json", NULL, "print what /v1/volumes says of the volume, as JSON"},
    [INFO_RESAMPLE] = {"--resample", "WxHxD", "box-filter the volume to these dims first (or N for NxNxN)"},
};

static int srv_cmd_info(int argc, char **argv);
const srv_command srv_info_command = {
    "info", "VOLUME [options]", "What a volume is: dims, voxel type, geometry, value range, suggested levels.",
    info_options, INFO_OPTIONS, 1, srv_cmd_info};

static int srv_cmd_info(int argc, char **argv)
{
    srv_open_options opt = {0};
    int as_json = 0, i = 0, arg;
    const char *value;
    while ((arg = srv_next_arg(&srv_info_command, argc, argv, &i, &value)) != SRV_ARG_END) {
        if (arg == SRV_ARG_HELP || arg == SRV_ARG_ERROR)
            return arg == SRV_ARG_ERROR;
        if (arg == INFO_JSON)
            as_json = 1;
        else if (arg == INFO_RESAMPLE)
            opt.resample = value;
        else if (opt.path)
            return srv_fail("info: unexpected argument '%s' (one VOLUME)", value);
        else
            opt.path = value;
    }
    if (!opt.path)
        return srv_fail("info: which VOLUME?");
    srv_subject s;
    if (srv_open(&opt, &s))
        return 1;
    int status = 0;
    if (as_json) {
        char *text = info_json(&s);
        if (text)
            puts(text);
        else
            status = srv_fail("%s: out of memory writing the report", s.name);
        free(text);
    } else {
        const iso_volume *v = s.vol;
        printf("%s\n  dims     %zu x %zu x %zu\n  type     %s\n  spacing  %g x %g x %g mm\n"
               "  origin   %g, %g, %g mm\n  values   %g .. %g (mean %g)%s\n",
               s.name, v->dims[0], v->dims[1], v->dims[2], iso_vol_type_name(v->type),
               v->spacing[0], v->spacing[1], v->spacing[2], v->origin[0], v->origin[1],
               v->origin[2], v->value_min, v->value_max, v->value_mean, v->has_nan ? ", has NaN samples" : "");
        if (v->modality[0] || v->description[0])
            printf("  series   %s%s%s\n", v->modality, v->modality[0] && v->description[0] ? ", " : "",
                   v->description);
    }
    srv_close(&s);
    return status;
}

enum { BUILD_OUT, BUILD_RESAMPLE, BUILD_THREADS, BUILD_OPTIONS };
static const srv_option build_options[BUILD_OPTIONS] = {
    [BUILD_OUT] = {"-o", "FILE.isotree", "where to write the hierarchy (required)"},
    [BUILD_RESAMPLE] = {"--resample", "WxHxD", "box-filter the volume to these dims first (or N for NxNxN)"},
    [BUILD_THREADS] = {"--threads", "N", "threads of the build, 1..256 (default: all cores)"},
};

static int srv_cmd_build(int argc, char **argv);
const srv_command srv_build_command = {
    "build", "VOLUME -o FILE.isotree [options]",
    "Builds the volume's hierarchy into a file that `extract --hierarchy` and the server's cache read back.",
    build_options, BUILD_OPTIONS, 1, srv_cmd_build};

static int srv_cmd_build(int argc, char **argv)
{
    srv_open_options opt = {.want_tree = 1};
    const char *out = NULL, *value;
    int i = 0, arg;
    while ((arg = srv_next_arg(&srv_build_command, argc, argv, &i, &value)) != SRV_ARG_END) {
        if (arg == SRV_ARG_HELP || arg == SRV_ARG_ERROR)
            return arg == SRV_ARG_ERROR;
        if (arg == BUILD_OUT)
            out = value;
        else if (arg == BUILD_RESAMPLE)
            opt.resample = value;
        else if (arg == BUILD_THREADS) {
            if (srv_parse_threads("build", value, &opt.threads))
                return 1;
        } else if (opt.path)
            return srv_fail("build: unexpected argument '%s' (one VOLUME)", value);
        else
            opt.path = value;
    }
    if (!opt.path || !out)
        return srv_fail("build: usage: isoserve build %s", srv_build_command.synopsis);
    srv_subject s;
    if (srv_open(&opt, &s))
        return 1;
    iso_error err;
    int rc = iso_tree_save(s.tree, out, &err);
    if (rc == 0) {
        size_t vb = iso_vol_count(s.vol) * iso_vol_type_size(s.vol->type);
        printf("%s: %zu nodes, %zu bytes (%.2f%% of the volume's %zu bytes), built in %.1f ms\n",
               out, s.tree->node_count, iso_tree_bytes(s.tree), 100.0 * (double)iso_tree_bytes(s.tree) / (double)vb,
               vb, s.tree->build_ms);
    }
    srv_close(&s);
    return rc ? srv_fail("%s", err.message) : 0;
}
