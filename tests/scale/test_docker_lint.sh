#!/usr/bin/env bash
# Lint of docker/ (Dockerfile, compose.yaml, nginx.conf) without a Docker engine; see
# tests/scale/lint_docker.py. Prints PASS/FAIL/SKIP lines.
set -uo pipefail
cd "$(dirname "$0")/../.."
/usr/bin/python3 tests/scale/lint_docker.py
