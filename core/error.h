/* error.h: the error report every fallible core function fills.
 *
 * Functions return 0 on success and a negative ISO_E* code on failure; when the caller
 * passes a non-NULL iso_error, it receives the code and a message that says what failed
 * and where (file name, header line, byte offset). server/ maps codes to HTTP statuses. */
#ifndef ISO_ERROR_H
#define ISO_ERROR_H

#include <stddef.h>

enum iso_status {
    ISO_OK = 0,
    ISO_E_IO = -1,          /* a file could not be opened, read or written */
    ISO_E_FORMAT = -2,      /* the bytes do not follow the format (malformed header, bad value) */
    ISO_E_TRUNCATED = -3,   /* the data ends before the header says it should */
    ISO_E_UNSUPPORTED = -4, /* a valid but unsupported feature (encoding, type, dimension) */
    ISO_E_LIMIT = -5,       /* sizes overflow or exceed the configured memory limit */
    ISO_E_NOMEM = -6,       /* an allocation failed */
    ISO_E_ARGUMENT = -7,    /* a parameter out of its documented range */
    ISO_E_STALE = -8,       /* a hierarchy file does not belong to this volume */
    ISO_E_CORRUPT = -9      /* a checksum does not match */
};

typedef struct iso_error {
    int code;
    char message[512];
} iso_error;

/* Fills err (if not NULL) with code and a printf-style message; returns code so that
 * callers can write `return iso_error_set(err, ISO_E_FORMAT, "...", ...);`. */
int iso_error_set(iso_error *err, int code, const char *fmt, ...)
#if defined(__GNUC__)
    __attribute__((format(printf, 3, 4)))
#endif
    ;

/* A short English name for a status code ("format error", ...). Never NULL. */
const char *iso_status_name(int code);

#endif
