#!/usr/bin/env bash
# The README's run command: the daemon on the default collection (Debian's mricron-data
# brain templates and analytic phantoms), hierarchies cached in build/cache, on
# http://127.0.0.1:8080/ unless ISOSERVE_LISTEN says otherwise. Ctrl-C stops it cleanly.
set -euo pipefail
cd "$(dirname "$0")/.."
listen=${ISOSERVE_LISTEN:-127.0.0.1:8080}
echo "isoserve: open http://$listen/ in a browser (Ctrl-C stops the server)"
exec build/isoserve serve --listen "$listen" --cache-dir build/cache "$@"
