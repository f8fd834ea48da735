#!/usr/bin/env bash
# Runs every libFuzzer target of build/fuzz for SECONDS each (default 60; make fuzz passes
# FUZZ_SECONDS), from seeds made now (tests/fuzz/seeds.py) plus the corpus kept in
# build/fuzz/corpus/ between runs and the committed regression inputs. Prints one
# "fuzz TARGET: N executions in S s, K crashes" line per target; a crash's input is saved in
# build/fuzz/crashes/ and the run exits 1. Targets: see FUZZ_TARGETS in the Makefile.
set -uo pipefail
cd "$(dirname "$0")/../.."
seconds=${1:-60}
targets=(query nrrd nifti metaimage tree draco)
seeds=build/fuzz/seeds
mkdir -p build/fuzz/crashes
rm -rf "$seeds"
/usr/bin/python3 tests/fuzz/seeds.py "$seeds" build/isoserve || { echo "fuzz: seeds failed"; exit 1; }
export TMPDIR=${TMPDIR:-/tmp}
. tests/fuzz/options.sh
status=0
for t in "${targets[@]}"; do
    corpus=build/fuzz/corpus/$t
    mkdir -p "$corpus" "tests/fuzz/regressions/$t"
    log=build/fuzz/$t.log
    build/fuzz/fuzz_$t -max_total_time="$seconds" -timeout=10 \
        "${FUZZ_LIMITS[@]}" -print_final_stats=1 -artifact_prefix="build/fuzz/crashes/$t-" \
        "$corpus" "$seeds/$t" "tests/fuzz/regressions/$t" > "$log" 2>&1
    rc=$?
    execs=$(grep -o 'stat::number_of_executed_units: *[0-9]*' "$log" | grep -o '[0-9]*$')
    crashes=$(ls build/fuzz/crashes/ 2>/dev/null | grep -c "^$t-")
    echo "fuzz $t: ${execs:-?} executions in $seconds s, $crashes crash inputs in build/fuzz/crashes"
    if [ "$rc" -ne 0 ]; then
        echo "fuzz $t: exited with status $rc; the end of $log:"
        tail -25 "$log"
        status=1
    fi
done
exit $status
