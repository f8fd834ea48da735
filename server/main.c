/* main.c: the isoserve binary: one entry point, a subcommand per task. Each command's
 * options and usage come from its own table (cli.h), so `isoserve CMD --help` lists exactly
 * what CMD parses. */
#include <stdio.h>
#include <string.h>

#include "cli.h"

static const srv_command *const commands[] = {&srv_info_command, &srv_build_command, &srv_extract_command,
                                              &srv_serve_command, &srv_segments_command, &srv_bench_command};
#define COMMAND_COUNT (sizeof commands / sizeof commands[0])

static const srv_command *find_command(const char *name)
{
    for (size_t i = 0; i < COMMAND_COUNT; i++)
        if (!strcmp(name, commands[i]->name))
            return commands[i];
    return NULL;
}

static int usage(FILE *to)
{
    fprintf(to, "isoserve: iso-surfaces of volumes with a proven error bound\n\nusage:\n");
    for (size_t i = 0; i < COMMAND_COUNT; i++)
        fprintf(to, "  isoserve %-8s %s\n", commands[i]->name, commands[i]->synopsis);
    fprintf(to, "\nisoserve COMMAND --help (or isoserve help COMMAND) gives a command's options.\n\n%s",
            srv_volume_help);
    return to == stdout ? 0 : 2;
}

int main(int argc, char **argv)
{
    if (argc < 2)
        return usage(stderr);
    const char *first = argv[1];
    if (!strcmp(first, "-h") || !strcmp(first, "--help") || !strcmp(first, "help")) {
        if (argc < 3)
            return usage(stdout);
        const srv_command *cmd = find_command(argv[2]);
        if (!cmd) {
            fprintf(stderr, "isoserve: unknown command '%s'\n\n", argv[2]);
            return usage(stderr);
        }
        srv_usage(cmd, stdout);
        return 0;
    }
    const srv_command *cmd = find_command(first);
    if (cmd)
        return cmd->run(argc - 2, argv + 2);
    fprintf(stderr, "isoserve: unknown command '%s'\n\n", first);
    return usage(stderr);
}
