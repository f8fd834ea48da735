#!/usr/bin/env bash
# Hostile clients and cache faults against real daemons on 127.0.0.1, driven by
# tests/http/test_hostile_http.py with $ISOSERVE_BIN (tests/run.sh: the normal build, then
# the ASan/UBSan build). Prints PASS/FAIL/SKIP lines.
set -uo pipefail
cd "$(dirname "$0")/../.."
exec /usr/bin/python3 tests/http/test_hostile_http.py
