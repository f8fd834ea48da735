#!/usr/bin/env bash
# Scale-out tests without a Docker engine: tests/scale/test_scale.py runs three sharded
# isoserve replicas and Debian's nginx with docker/nginx.conf on 127.0.0.1 and checks
# routing, nginx's mesh cache and failover with $ISOSERVE_BIN (tests/run.sh: once with the
# normal build and once with the ASan/UBSan build; loads on demand run in request threads,
# and a leak or an error the sanitizers see makes a replica exit non-zero, which the test
# checks). The processes it
# starts are listed in a file; whatever happens to the Python side, the trap stops each
# of them by its PID. Prints PASS/FAIL/SKIP lines.
set -uo pipefail
cd "$(dirname "$0")/../.."
pids=$(mktemp)
cleanup() {
    while read -r pid; do
        [ -n "$pid" ] && kill -KILL "$pid" 2>/dev/null
    done < "$pids"
    rm -f "$pids"
}
trap cleanup EXIT
trap 'exit 130' INT TERM
status=0
ISO_SCALE_PIDS=$pids /usr/bin/python3 tests/scale/test_scale.py || status=1
exit $status
