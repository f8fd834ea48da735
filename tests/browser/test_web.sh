#!/usr/bin/env bash
# The web client in headless Chromium against a real daemon on loopback (test_web.mjs).
# Prints PASS/FAIL lines.
set -uo pipefail
cd "$(dirname "$0")/../.."
if [ ! -x /usr/bin/chromium ] || [ ! -d web/node_modules/playwright-core ]; then
    echo "FAIL web.setup: needs /usr/bin/chromium and web/node_modules (make test installs both)"
    exit 1
fi
exec node tests/browser/test_web.mjs
