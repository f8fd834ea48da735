#!/usr/bin/env bash
# The fuzz targets in the test suite: every committed regression input
# (tests/fuzz/regressions/TARGET/*) is replayed through its target once, then each target
# runs for ISO_FUZZ_SECONDS (default 10) from fresh seeds (tests/fuzz/run.sh). The fuzz
# binaries are ASan/UBSan builds already, so tests/run.sh's asan pass has nothing to add.
# Prints PASS/FAIL lines.
set -uo pipefail
cd "$(dirname "$0")/../.."
[ -z "${ISO_SAN_SUFFIX:-}" ] || exit 0
. tests/fuzz/options.sh
status=0
for t in query nrrd nifti metaimage tree draco; do
    if [ ! -x "build/fuzz/fuzz_$t" ]; then
        echo "FAIL fuzz.$t: build/fuzz/fuzz_$t missing (make fuzz-build; needs clang)"
        status=1
        continue
    fi
    inputs=(tests/fuzz/regressions/$t/*)
    if [ -e "${inputs[0]}" ]; then
        if out=$(TMPDIR=${TMPDIR:-/tmp} "build/fuzz/fuzz_$t" "${FUZZ_LIMITS[@]}" "${inputs[@]}" 2>&1); then
            echo "PASS fuzz.${t}_regressions (${#inputs[@]} inputs)"
        else
            echo "FAIL fuzz.${t}_regressions: $(echo "$out" | grep -m1 -E 'ERROR|SUMMARY|runtime error')"
            status=1
        fi
    fi
done
out=$(bash tests/fuzz/run.sh "${ISO_FUZZ_SECONDS:-10}" 2>&1)
rc=$?
echo "$out" | grep '^fuzz ' | sed 's/^/INFO /'
for t in query nrrd nifti metaimage tree draco; do
    line=$(echo "$out" | grep "^fuzz $t: .*executions" | head -1)
    if [ "$rc" -eq 0 ] || ! echo "$out" | grep -q "^fuzz $t: exited"; then
        [ -n "$line" ] && echo "PASS fuzz.$t" || { echo "FAIL fuzz.$t: did not run"; status=1; }
    else
        echo "FAIL fuzz.$t: $(echo "$out" | grep -A30 "^fuzz $t: exited" | grep -m1 -E 'ERROR|runtime error|deadly' )"
        status=1
    fi
done
exit $status
