#!/usr/bin/env bash
# Segmentations end to end (tests/dicom/test_segmentation.py): a label map, a .seg.nrrd and
# DICOM SEGs written with pydicom, from a folder, Orthanc and DICOMweb, through the segment
# routes. Runs $ISOSERVE_BIN (tests/run.sh runs it once with the normal build and once with
# the ASan/UBSan build). PASS/FAIL/SKIP lines.
set -uo pipefail
cd "$(dirname "$0")/../.."
/usr/bin/python3 tests/dicom/test_segmentation.py
