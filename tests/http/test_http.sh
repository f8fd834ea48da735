#!/usr/bin/env bash
# HTTP integration tests: real isoserve daemons on 127.0.0.1 (free ports chosen at run
# time), driven by tests/http/test_http.py, once with the normal build and once with the
# ASan/UBSan build (a leak or a race the sanitizers see makes the daemon exit non-zero,
# which the tests check). Prints PASS/FAIL/SKIP lines.
set -uo pipefail
cd "$(dirname "$0")/../.."
status=0
/usr/bin/python3 tests/http/test_http.py || status=1
if [ -x build/san/isoserve ]; then
    ASAN_OPTIONS=detect_leaks=1 UBSAN_OPTIONS=print_stacktrace=1 ISOSERVE_BIN=build/san/isoserve \
        ISO_TEST_LABEL=http-san /usr/bin/python3 tests/http/test_http.py || status=1
fi
exit $status
