/* main.c: the isoserve binary: one entry point, a subcommand per task. */
#include <stdio.h>
#include <string.h>

#include "cli.h"

static const struct {
    const char *name;
    int (*run)(int argc, char **argv);
    const char *usage;
} commands[] = {
    {"info", srv_cmd_info, "info VOLUME [--json] [--resample WxHxD]"},
    {"build", srv_cmd_build, "build VOLUME -o FILE [--resample WxHxD] [--threads N]"},
    {"extract", srv_cmd_extract,
     "extract VOLUME --level L [--tolerance T] [-o OUT.ply|.obj|.drc|.glb|.meshopt.glb] [--json] [--hierarchy FILE]\n"
     "                 [--normals none|trilinear|triquadratic|tricubic] [--resample WxHxD]\n"
     "                 [--index-space] [--full-scan] [--cap] [--threads N]\n"
     "                 (--threads: build and exact extraction; default all cores)"},
    {"serve", srv_cmd_serve,
     "serve [--catalog FILE | --volumes DIR] [--listen 127.0.0.1:8080] [--cache-dir DIR]\n"
     "                 [--threads N] [--queue N] [--cache-mb N] [--cors-origin ORIGIN]...\n"
     "                 [--web-root DIR] [--drain-seconds N] [--max-connections N] [--max-volume-mb N]\n"
     "                 [--max-resident-mb N (needs --cache-dir; 0: no limit)]\n"
     "                 [--shard K/N --shard-peers HOST:PORT,...] [--replica-name NAME]\n"
     "                 (each option also from ISOSERVE_<OPTION>, e.g. ISOSERVE_CACHE_DIR)"},
    {"bench", srv_cmd_bench,
     "bench VOLUME --level L [--tolerances 0,5%,preview,...] [--json FILE] [--repeat N] [--resample WxHxD]\n"
     "                 [--threads N] [--no-baselines] [--distances] [--build-repeat N]"},
};

static int usage(FILE *to)
{
    fprintf(to, "isoserve: iso-surfaces of volumes with a proven error bound\n\nusage:\n");
    for (size_t i = 0; i < sizeof commands / sizeof commands[0]; i++)
        fprintf(to, "  isoserve %s\n", commands[i].usage);
    fprintf(to, "\nVOLUME is a file (.nrrd, .nhdr, .nii, .nii.gz, .mhd, .mha, raw with a .json sidecar)\n"
                "or field:NAME[:WxHxD] "
                "(sphere, torus, ml, constant, spike, ijk).\n");
    return to == stdout ? 0 : 2;
}

int main(int argc, char **argv)
{
    if (argc < 2)
        return usage(stderr);
    if (!strcmp(argv[1], "-h") || !strcmp(argv[1], "--help") || !strcmp(argv[1], "help"))
        return usage(stdout);
    for (size_t i = 0; i < sizeof commands / sizeof commands[0]; i++)
        if (!strcmp(argv[1], commands[i].name))
            return commands[i].run(argc - 2, argv + 2);
    fprintf(stderr, "isoserve: unknown command '%s'\n\n", argv[1]);
    return usage(stderr);
}
