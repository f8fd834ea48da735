#!/usr/bin/env bash
# HTTP integration tests: real isoserve daemons on 127.0.0.1 (free ports chosen at run
# time), driven by tests/http/test_http.py with $ISOSERVE_BIN (tests/run.sh runs it once with
# the normal build and once with the ASan/UBSan build, where a leak or an error the
# sanitizers see makes the daemon exit non-zero, which the tests check). PASS/FAIL/SKIP lines.
set -uo pipefail
cd "$(dirname "$0")/../.."
status=0
/usr/bin/python3 tests/http/test_http.py || status=1
exit $status
