#!/usr/bin/env bash
# A 20-second version of the soak bench (tests/bench/bench_soak.py; `make bench` runs it for
# 5 minutes): mixed cached and uncached mesh requests on loopback, no status but 200, 304
# or a deliberate 503, no file-descriptor leak, a clean exit. Prints a PASS/FAIL line.
set -uo pipefail
cd "$(dirname "$0")/../.."
label="soak${ISO_SAN_SUFFIX:-}"
out=$(/usr/bin/python3 -c "
import sys; sys.path.insert(0, 'tests/bench')
import bench_soak
report, problems = bench_soak.soak(${ISO_SOAK_SECONDS:-20}, '$label')
print('PROBLEMS ' + '; '.join(problems))
" 2>&1)
echo "$out" | grep '^INFO'
problems=$(echo "$out" | grep '^PROBLEMS' | sed 's/^PROBLEMS //')
if echo "$out" | grep -q '^PROBLEMS $'; then
    echo "PASS $label.short_soak"
else
    echo "FAIL $label.short_soak: ${problems:-$(echo "$out" | tail -5)}"
    exit 1
fi
