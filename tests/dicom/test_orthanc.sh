#!/usr/bin/env bash
# DICOM series end to end (tests/dicom/test_orthanc.py): a series folder and the same
# series uploaded to a real Orthanc on 127.0.0.1 serve byte-identical meshes; Orthanc
# failures are 502 problems for that volume only. Run with the normal build, then with
# the ASan/UBSan build when it exists. Prints PASS/FAIL/SKIP lines.
set -uo pipefail
cd "$(dirname "$0")/../.."
status=0
/usr/bin/python3 tests/dicom/test_orthanc.py || status=1
if [ -x build/san/isoserve ]; then
    ASAN_OPTIONS=detect_leaks=1 UBSAN_OPTIONS=print_stacktrace=1 ISOSERVE_BIN=build/san/isoserve \
        ISO_TEST_LABEL=dicom-san /usr/bin/python3 tests/dicom/test_orthanc.py || status=1
fi
exit $status
