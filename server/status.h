/* status.h: the one place where core's ISO_E_* codes become HTTP statuses.
 *
 * core/ and proto/ report failures as ISO_E_* codes with a message; server/ functions
 * return 0 or such a code too, and only the HTTP layer turns one into a status, here. */
#ifndef SRV_STATUS_H
#define SRV_STATUS_H

/* The HTTP status answering a request that failed with `code` (an ISO_E_* value):
 *   ISO_E_NOMEM                   503: this request's memory ran out; retry later
 *   ISO_E_LIMIT                   422: the answer is over a configured limit
 *   ISO_E_ARGUMENT                400: the request's parameters
 *   ISO_E_IO                      502: the source (file system, archive) failed
 *   ISO_E_FORMAT, _TRUNCATED,
 *   _UNSUPPORTED, _STALE, _CORRUPT 422: the volume's data cannot be served
 *   ISO_E_INTERNAL and unknown    500 */
int srv_status_http(int code);

/* The HTTP status for a volume that is not ready (an srv_volume_state other than READY):
 * UNKNOWN 404, UPSTREAM_FAILED 503 with Retry-After (its archive failed; asked again after
 * a backoff), FAILED 500 (the server's own data or hierarchy could not be loaded: not the
 * request's fault). */
int srv_status_volume_http(int state);

#endif
