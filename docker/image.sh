#!/usr/bin/env bash
# docker/image.sh: builds isoserve's images from the repository root: isoserve:latest (the
# server, the Dockerfile's last stage) and isoserve-front:latest (nginx and the web client),
# the two compose.yaml runs. With docker when its engine answers, else with podman, given
# --format docker so that the HEALTHCHECKs stay in the image (podman's default OCI format
# drops them). BASE_IMAGE and SLIM_IMAGE, when set, are passed as build arguments (a local
# or mirrored Debian 12; docker/base-image.sh makes one with debootstrap).
# Usage: docker/image.sh    (make image)
set -euo pipefail
cd "$(dirname "$0")/.."
. docker/engine.sh
engine_pick || { echo "image: $ENGINE_WHY" >&2; exit 1; }
slim=${SLIM_IMAGE:-debian:bookworm-slim}
if ! $ENGINE image inspect "$slim" >/dev/null 2>&1 && ! $ENGINE pull -q "$slim" >/dev/null 2>&1; then
    echo "image: no $slim here and none can be pulled; docker/base-image.sh makes one (see docs/scaling.md)" >&2
    exit 1
fi
engine_can_run "$slim" || { echo "image: $ENGINE_WHY" >&2; exit 1; }
# The web client's package comes from the host (docker/Dockerfile says why).
make -s node-deps
args=()
[ "$ENGINE" = podman ] && args+=(--format docker)
[ -n "${BASE_IMAGE:-}" ] && args+=(--build-arg "BASE_IMAGE=$BASE_IMAGE")
[ -n "${SLIM_IMAGE:-}" ] && args+=(--build-arg "SLIM_IMAGE=$SLIM_IMAGE")
for target in front isoserve; do
    name=$([ $target = front ] && echo isoserve-front || echo isoserve)
    echo "image: $ENGINE build --target $target -t $name:latest (the build stage compiles everything once)"
    start=$SECONDS
    log=build/containers/$name.build.log
    mkdir -p build/containers
    # The steps as progress; the whole output in the log.
    $ENGINE build "${args[@]}" -f docker/Dockerfile --target $target -t $name:latest . 2>&1 |
        tee "$log" | grep -E --line-buffered '(STEP|Step) [0-9]+/[0-9]+' || true
    status=${PIPESTATUS[0]}
    if [ "$status" -ne 0 ]; then
        tail -20 "$log" >&2
        echo "image: building $name failed (exit $status); the whole output is in $log" >&2
        exit 1
    fi
    size=$($ENGINE image inspect --format '{{.Size}}' $name:latest)
    echo "image: $name:latest, $((size / 1000000)) MB, built in $((SECONDS - start)) s"
done
