#!/usr/bin/env bash
# Bounded memory (--max-resident-mb): tests/http/test_resident.py runs one isoserve daemon
# with 50 volumes and a cap that holds 5, with $ISOSERVE_BIN (tests/run.sh: the normal build
# and the ASan/UBSan build, where a leak or an error makes the daemon exit non-zero, which
# the test checks). PASS/FAIL lines.
set -uo pipefail
cd "$(dirname "$0")/../.."
status=0
/usr/bin/python3 tests/http/test_resident.py || status=1
exit $status
