#!/usr/bin/env bash
# Lint of docker/ (Dockerfile, compose.yaml, nginx.conf) without a Docker engine; see
# tests/scale/lint_docker.py. Prints PASS/FAIL/SKIP lines.
set -uo pipefail
cd "$(dirname "$0")/../.."
# The lint runs no isoserve binary: the asan pass of tests/run.sh has nothing to add.
[ -z "${ISO_SAN_SUFFIX:-}" ] || exit 0
/usr/bin/python3 tests/scale/lint_docker.py
