/* status.c: ISO_E_* codes to HTTP statuses (see status.h). */
#include "status.h"

#include "base/base.h"
#include "collection.h"

int srv_status_http(int code)
{
    switch (code) {
    case ISO_E_NOMEM: return 503;
    case ISO_E_LIMIT: return 422;
    case ISO_E_ARGUMENT: return 400;
    case ISO_E_IO: return 502;
    case ISO_E_FORMAT:
    case ISO_E_TRUNCATED:
    case ISO_E_UNSUPPORTED:
    case ISO_E_STALE:
    case ISO_E_CORRUPT: return 422;
    default: return 500;
    }
}

int srv_status_volume_http(int state)
{
    switch (state) {
    case SRV_VOLUME_READY: return 200;
    case SRV_VOLUME_UNKNOWN: return 404;
    case SRV_VOLUME_UPSTREAM_FAILED: return 503; /* with Retry-After: retried after a backoff */
    default: return 500;
    }
}
