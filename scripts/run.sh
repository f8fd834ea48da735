#!/usr/bin/env bash
# The README's run command until the HTTP server exists: the default volume's surface,
# extracted with the hierarchy, written to build/default.ply, with its report.
set -euo pipefail
cd "$(dirname "$0")/.."
volume=${ISOSERVE_VOLUME:-field:ml:128}
level=${ISOSERVE_LEVEL:-0.5}
tolerance=${ISOSERVE_TOLERANCE:-0.01}
build/isoserve info "$volume"
build/isoserve extract "$volume" --level "$level" --tolerance "$tolerance" -o build/default.ply --json
echo "wrote build/default.ply"
