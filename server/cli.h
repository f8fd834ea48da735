/* cli.h: what the isoserve subcommands share: argument helpers, opening a volume with
 * its hierarchy, progress on the terminal. */
#ifndef SRV_CLI_H
#define SRV_CLI_H

#include <stddef.h>
#include <stdio.h>

#include "extract/extract.h"
#include "hierarchy/tree.h"
#include "volume/volume.h"

/* A volume opened for a command: the volume (resampled if asked) and its hierarchy (read
 * from a file if asked, else built with progress on stderr). */
typedef struct srv_subject {
    iso_volume *vol;
    iso_tree *tree;
    const char *name;
    double load_ms;
} srv_subject;

typedef struct srv_open_options {
    const char *path;
    const char *resample;  /* "WxHxD" or NULL */
    const char *hierarchy; /* file written by `isoserve build`, or NULL */
    int want_tree;
    int threads;           /* for the hierarchy build; 0 = all cores */
} srv_open_options;

/* A command's options, one table read by both its parser (srv_next_arg) and its usage
 * text (srv_usage): an option the parser takes is in the usage, and nothing else is. */
typedef struct srv_option {
    const char *name;    /* "--level", "-o" */
    const char *value;   /* the value's placeholder ("L", "FILE"); NULL for a flag */
    const char *help;    /* what it does, one line */
} srv_option;

typedef struct srv_command {
    const char *name;        /* "extract" */
    const char *synopsis;    /* what follows the name: "VOLUME --level L [options]" */
    const char *summary;     /* what the command does, one sentence */
    const srv_option *options;
    size_t option_count;
    int takes_volume;        /* 1: its operand is a VOLUME (the usage says what one is) */
    int (*run)(int argc, char **argv);
} srv_command;

/* What srv_next_arg found besides an option (whose index in the table it returns). */
enum {
    SRV_ARG_END = -1,     /* no more arguments */
    SRV_ARG_OPERAND = -2, /* an argument that is no option, in *value */
    SRV_ARG_HELP = -3,    /* -h or --help: the usage went to stdout; exit 0 */
    SRV_ARG_ERROR = -4    /* an unknown option or a missing value: said on stderr; exit 1 */
};

/* The next argument of argv from *i on (start at 0): an option of cmd's table (its index;
 * its value, the next argument whatever it looks like, in *value) or one of SRV_ARG_*. */
int srv_next_arg(const srv_command *cmd, int argc, char **argv, int *i, const char **value);
/* The command's usage: synopsis, summary, one line per option, what a VOLUME is. */
void srv_usage(const srv_command *cmd, FILE *to);
/* What a VOLUME argument may be, for the usage texts. */
extern const char srv_volume_help[];

extern const srv_command srv_info_command, srv_build_command, srv_extract_command,
    srv_bench_command, srv_serve_command, srv_segments_command;

/* "--threads N": N in 1..256 into *threads; 0, or prints the problem and returns 1. */
int srv_parse_threads(const char *command, const char *text, int *threads);

/* "--coarsen WHEN": faster or all (extract.h's iso_coarsen); 0, or prints the problem and
 * returns 1. */
int srv_parse_coarsen(const char *command, const char *text, iso_coarsen *coarsen);

/* A mesh request allocates and frees tens of MB (the mesh, the vertex map, the edge census,
 * Draco's corner tables). With glibc's defaults the large blocks are fresh mmaps and
 * freed memory above 128 KiB is handed back, so every request faults its pages in again
 * (docs/performance.md measures the cost). Blocks up to 32 MiB (glibc's limit) then come
 * from the heap, and freed memory stays for the next request: the process keeps its peak.
 * `serve` sets this, and `bench`, which measures what the server does. */
void srv_keep_freed_memory(void);

/* Returns 0, or prints "isoserve: <what>" on stderr and returns 1. */
int srv_open(const srv_open_options *opt, srv_subject *out);
void srv_close(srv_subject *s);

/* "WxHxD" or "N" into dims; 0 or ISO_E_ARGUMENT. */
int srv_parse_dims(const char *text, size_t dims[3]);
/* A finite double, whole string; 0 or ISO_E_ARGUMENT. */
int srv_parse_number(const char *text, double *out);
/* Prints "isoserve: ..." to stderr; returns 1 (the exit status of a failed command). */
int srv_fail(const char *fmt, ...)
#if defined(__GNUC__)
    __attribute__((format(printf, 1, 2)))
#endif
    ;

/* The format an output file's suffix names (.ply, .obj, .drc, .meshopt.glb, .glb, .stl),
 * PROTO_FORMAT_NONE for no path; -1 for a suffix isoserve does not write. */
int srv_format_of_path(const char *path);
/* Writes bytes to path through a temporary file and rename, so that a reader never sees
 * half a file; 0, or prints the problem and returns 1. */
int srv_write_file(const unsigned char *bytes, size_t size, const char *path);

/* Progress for long steps: drawn on stderr only when it is a terminal. */
void srv_progress(void *label, double fraction);


#endif
