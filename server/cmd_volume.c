/* cmd_volume.c: `isoserve info` (what a volume is) and `isoserve build` (its hierarchy
 * file). */
#include <jansson.h>
#include <stdio.h>
#include <string.h>

#include "cli.h"

static json_t *volume_json(const srv_subject *s)
{
    const iso_volume *v = s->vol;
    return json_pack("{s:s, s:[I,I,I], s:s, s:[f,f,f], s:[f,f,f], s:f, s:f, s:f, s:I, s:b}",
                     "volume", s->name, "dims", (json_int_t)v->dims[0], (json_int_t)v->dims[1],
                     (json_int_t)v->dims[2], "type", iso_vol_type_name(v->type), "spacing",
                     v->spacing[0], v->spacing[1], v->spacing[2], "origin", v->origin[0],
                     v->origin[1], v->origin[2], "min", v->value_min, "max", v->value_max, "mean",
                     v->value_mean, "bytes", (json_int_t)(iso_vol_count(v) * iso_vol_type_size(v->type)),
                     "has_nan", v->has_nan);
}

int srv_cmd_info(int argc, char **argv)
{
    srv_open_options opt = {0};
    int as_json = 0;
    for (int i = 0; i < argc; i++) {
        if (!strcmp(argv[i], "--json"))
            as_json = 1;
        else if (!strcmp(argv[i], "--resample") && i + 1 < argc)
            opt.resample = argv[++i];
        else if (argv[i][0] == '-' || opt.path)
            return srv_fail("info: unexpected argument '%s'", argv[i]);
        else
            opt.path = argv[i];
    }
    if (!opt.path)
        return srv_fail("info: which VOLUME?");
    srv_subject s;
    if (srv_open(&opt, &s))
        return 1;
    json_t *doc = volume_json(&s);
    if (as_json) {
        char *text = json_dumps(doc, JSON_COMPACT);
        puts(text);
        free(text);
    } else {
        const iso_volume *v = s.vol;
        printf("%s\n  dims     %zu x %zu x %zu\n  type     %s\n  spacing  %g x %g x %g mm\n"
               "  origin   %g, %g, %g mm\n  values   %g .. %g (mean %g)%s\n",
               s.name, v->dims[0], v->dims[1], v->dims[2], iso_vol_type_name(v->type),
               v->spacing[0], v->spacing[1], v->spacing[2], v->origin[0], v->origin[1],
               v->origin[2], v->value_min, v->value_max, v->value_mean, v->has_nan ? ", has NaN samples" : "");
    }
    json_decref(doc);
    srv_close(&s);
    return 0;
}

int srv_cmd_build(int argc, char **argv)
{
    srv_open_options opt = {.want_tree = 1};
    const char *out = NULL;
    for (int i = 0; i < argc; i++) {
        if (!strcmp(argv[i], "-o") && i + 1 < argc)
            out = argv[++i];
        else if (!strcmp(argv[i], "--resample") && i + 1 < argc)
            opt.resample = argv[++i];
        else if (!strcmp(argv[i], "--threads") && i + 1 < argc) {
            if (srv_parse_threads("build", argv[++i], &opt.threads))
                return 1;
        } else if (argv[i][0] == '-' || opt.path)
            return srv_fail("build: unexpected argument '%s'", argv[i]);
        else
            opt.path = argv[i];
    }
    if (!opt.path || !out)
        return srv_fail("build: usage: isoserve build VOLUME -o FILE");
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
