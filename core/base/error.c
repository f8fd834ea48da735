/* error.c: filling iso_error reports (see base.h). */
#include "base.h"

#include <stdarg.h>
#include <stdio.h>

int iso_error_set(iso_error *err, int code, const char *fmt, ...)
{
    if (err) {
        va_list ap;
        va_start(ap, fmt);
        err->code = code;
        vsnprintf(err->message, sizeof err->message, fmt, ap);
        va_end(ap);
    }
    return code;
}

const char *iso_status_name(int code)
{
    switch (code) {
    case ISO_OK: return "ok";
    case ISO_E_IO: return "i/o error";
    case ISO_E_FORMAT: return "format error";
    case ISO_E_TRUNCATED: return "truncated data";
    case ISO_E_UNSUPPORTED: return "unsupported";
    case ISO_E_LIMIT: return "size limit";
    case ISO_E_NOMEM: return "out of memory";
    case ISO_E_ARGUMENT: return "bad argument";
    case ISO_E_STALE: return "stale file";
    case ISO_E_CORRUPT: return "corrupt file";
    case ISO_E_INTERNAL: return "internal error";
    }
    return "unknown error";
}
