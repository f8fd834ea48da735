#!/usr/bin/env bash
# Runs every test: the unit binaries of the normal and the sanitizer build, then the
# end-to-end scripts tests/*/test_*.sh (CLI, HTTP, browser; they print the same PASS/FAIL/SKIP lines), and closes
# with "N passed, N failed, N skipped". Exit status 1 if anything failed.
set -uo pipefail
cd "$(dirname "$0")/.."

log=$(mktemp)
trap 'rm -f "$log"' EXIT
status=0

run_one() { # label, command...
    local label=$1; shift
    echo "== $label"
    "$@" 2>&1 | tee -a "$log"
    local rc=${PIPESTATUS[0]}
    if [ "$rc" -ne 0 ]; then
        echo "FAIL $label: exited with status $rc" | tee -a "$log"
        status=1
    fi
}

for t in build/tests/test_*; do
    [ -x "$t" ] && run_one "$(basename "$t")" "$t"
done
for t in build/san/tests/test_*; do
    [ -x "$t" ] && run_one "$(basename "$t") (asan+ubsan)" env ASAN_OPTIONS=detect_leaks=1 UBSAN_OPTIONS=print_stacktrace=1 "$t"
done
for t in tests/*/test_*.sh; do
    [ -f "$t" ] && run_one "$(basename "$t")" bash "$t"
done

passed=$(grep -c '^PASS ' "$log")
failed=$(grep -c '^FAIL ' "$log")
skipped=$(grep -c '^SKIP ' "$log")
[ "$failed" -eq 0 ] || status=1
echo
echo "$passed passed, $failed failed, $skipped skipped"
exit $status
