#!/usr/bin/env bash
# DICOM series end to end (tests/dicom/test_orthanc.py): a series folder and the same
# series uploaded to a real Orthanc on 127.0.0.1 serve byte-identical meshes; Orthanc
# failures are 503 problems for that volume only, retried with backoff. Runs $ISOSERVE_BIN (tests/run.sh runs it
# once with the normal build and once with the ASan/UBSan build). PASS/FAIL/SKIP lines.
set -uo pipefail
cd "$(dirname "$0")/../.."
/usr/bin/python3 tests/dicom/test_orthanc.py
