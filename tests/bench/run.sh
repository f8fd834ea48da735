#!/usr/bin/env bash
# `make bench`: every benchmark, each printing a table and writing JSON under bench/results/.
# Figures are ratios measured side by side in one run: the machine is shared and noisy.
set -euo pipefail
cd "$(dirname "$0")/../.."
mkdir -p bench/results
for b in tests/bench/bench_*.py; do
    echo "== $(basename "$b")"
    /usr/bin/python3 "$b"
done
# The web client in headless Chromium: request to drawn, per codec and link, and dragging.
echo "== bench_browser.mjs"
node tests/bench/bench_browser.mjs
