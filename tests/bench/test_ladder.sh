#!/usr/bin/env bash
# The tolerance ladder's measurements (`isoserve bench --distances`, bench_peer.py's ladder)
# on an analytic sphere with known bounds: tests/bench/test_ladder.py. PASS/FAIL/SKIP lines.
set -uo pipefail
cd "$(dirname "$0")/../.."
/usr/bin/python3 tests/bench/test_ladder.py
