#!/usr/bin/env bash
# docker/base-image.sh: a Debian 12 base image made locally with debootstrap, for a machine
# that reaches Debian's package mirror but no container registry. Tagged as the names the
# Dockerfile's FROM lines use by default (debian:bookworm and debian:bookworm-slim), so
# `make image` then builds without pulling. One minimal root file system serves both: the
# slim stages only install what they need on top of it.
# Usage: docker/base-image.sh [MIRROR]   (root; debootstrap from Debian's package of that name)
set -euo pipefail
cd "$(dirname "$0")/.."
. docker/engine.sh
engine_pick || { echo "base-image: $ENGINE_WHY" >&2; exit 1; }
command -v debootstrap >/dev/null || { echo "base-image: debootstrap is not installed (apt-get install debootstrap)" >&2; exit 1; }
mirror=${1:-http://deb.debian.org/debian}
root=$(mktemp -d /tmp/isoserve-bookworm.XXXXXX)
trap 'rm -rf "$root"' EXIT
echo "base-image: debootstrap --variant=minbase bookworm from $mirror (about 200 MB, a minute or two)"
debootstrap --variant=minbase bookworm "$root" "$mirror" | grep -E '^I: (Retrieving Release|Unpacking the base|Base system)' || true
echo "base-image: importing into $ENGINE"
tar -C "$root" -c . | $ENGINE import - localhost/isoserve-base:bookworm >/dev/null
for name in debian:bookworm debian:bookworm-slim; do
    $ENGINE tag localhost/isoserve-base:bookworm "docker.io/library/$name"
done
echo "base-image: docker.io/library/debian:bookworm and :bookworm-slim now name the local base"
