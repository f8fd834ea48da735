#!/usr/bin/env bash
# Runs every test, in two passes over the same suite:
#   normal: the unit binaries of build/ and the end-to-end scripts tests/*/test_*.sh (CLI,
#           HTTP, browser, scale-out, fuzz replay, soak) against build/isoserve;
#   asan:   the unit binaries of build/san and the same scripts against build/san/isoserve,
#           built with AddressSanitizer and UndefinedBehaviorSanitizer; any report stops the
#           process with a non-zero status, which the scripts check.
# Usage: tests/run.sh [all|normal|asan] (default all). Scripts learn the pass from
# ISOSERVE_BIN (the binary to run) and ISO_SAN_SUFFIX ("-san" in the asan pass, appended to
# their PASS/FAIL labels). Closes with "N passed, N failed, N skipped"; exit status 1 if
# anything failed. Each step's wall time is printed after it.
set -uo pipefail
cd "$(dirname "$0")/.."

mode=${1:-all}
case "$mode" in all|normal|asan) ;; *) echo "usage: tests/run.sh [all|normal|asan]" >&2; exit 2;; esac

log=$(mktemp)
trap 'rm -f "$log"' EXIT
status=0

run_one() { # label, command...
    local label=$1; shift
    local start=$SECONDS
    echo "== $label"
    "$@" 2>&1 | tee -a "$log"
    local rc=${PIPESTATUS[0]}
    if [ "$rc" -ne 0 ]; then
        echo "FAIL $label: exited with status $rc" | tee -a "$log"
        status=1
    fi
    echo "-- $label: $((SECONDS - start)) s"
}

normal_pass() {
    for t in build/tests/test_*; do
        [ -x "$t" ] && run_one "$(basename "$t")" "$t"
    done
    for t in tests/*/test_*.sh; do
        [ -f "$t" ] && run_one "$(basename "$t")" env ISOSERVE_BIN=build/isoserve ISO_SAN_SUFFIX= bash "$t"
    done
}

# halt_on_error makes every sanitizer report fatal (UBSan's included, although the build
# already has -fno-sanitize-recover), so "warnings" cannot scroll by unnoticed.
asan_pass() {
    if [ ! -x build/san/isoserve ]; then
        echo "FAIL asan.build: build/san/isoserve missing (run make sanitize)" | tee -a "$log"
        status=1
        return
    fi
    export ASAN_OPTIONS=detect_leaks=1:halt_on_error=1:abort_on_error=0
    export UBSAN_OPTIONS=print_stacktrace=1:halt_on_error=1
    for t in build/san/tests/test_*; do
        [ -x "$t" ] && run_one "$(basename "$t") (asan+ubsan)" "$t"
    done
    for t in tests/*/test_*.sh; do
        [ -f "$t" ] && run_one "$(basename "$t") (asan+ubsan)" \
            env ISOSERVE_BIN=build/san/isoserve ISO_SAN_SUFFIX=-san bash "$t"
    done
}

start=$SECONDS
[ "$mode" = asan ] || normal_pass
[ "$mode" = normal ] || asan_pass

passed=$(grep -c '^PASS ' "$log")
failed=$(grep -c '^FAIL ' "$log")
skipped=$(grep -c '^SKIP ' "$log")
[ "$failed" -eq 0 ] || status=1
echo
echo "tests/run.sh $mode: $((SECONDS - start)) s"
echo "$passed passed, $failed failed, $skipped skipped"
exit $status
