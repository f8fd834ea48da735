#!/usr/bin/env bash
# The chains' registry, background builder and /chain route: tests/http/test_chains.py
# restarts an isoserve daemon ($ISOSERVE_BIN) and checks that the suggested levels' chains
# are built in the background, mapped after a restart, evicted under --chain-mb, and
# described by GET /v1/volumes/{id}/chain without building. PASS/FAIL lines.
set -uo pipefail
cd "$(dirname "$0")/../.."
status=0
/usr/bin/python3 tests/http/test_chains.py || status=1
exit $status
