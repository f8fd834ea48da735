#!/usr/bin/env bash
# The simplification chain on disk (serve --cache-dir): tests/http/test_chain_file.py
# restarts an isoserve daemon ($ISOSERVE_BIN) between requests and checks that the chain is
# read back, and that corrupt or stale chain files are refused and rebuilt. PASS/FAIL lines.
set -uo pipefail
cd "$(dirname "$0")/../.."
status=0
/usr/bin/python3 tests/http/test_chain_file.py || status=1
exit $status
