#!/usr/bin/env bash
# `make test-image`: the real images, built and run (named run_image.sh, not test_*.sh, so
# that tests/run.sh and `make test` leave it out: it takes minutes).
# With $CONTAINER (docker or podman): `make image`, then one replica on a free port
# (/healthz 200 once preloaded, a mesh of the default collection decodes as PLY), then the
# compose stack (docker compose, or Debian's podman-compose) on a free port: a mesh through
# the front, then one replica stopped and the same volume's new mesh still answered
# (failover). Containers and the stack are removed at the end. PASS/FAIL/SKIP lines.
set -uo pipefail
cd "$(dirname "$0")/../.."
C=${CONTAINER:-$(command -v docker || command -v podman || true)}
if [ -z "$C" ]; then echo "SKIP image.all: neither docker nor podman is installed"; exit 0; fi
if ! "$C" info >/dev/null 2>&1; then echo "SKIP image.all: $C cannot run containers here ($C info fails)"; exit 0; fi
if [ "$(basename "$C")" = docker ] && docker compose version >/dev/null 2>&1; then COMPOSE=(docker compose)
elif command -v podman-compose >/dev/null; then COMPOSE=(podman-compose)
else COMPOSE=(); fi
fail=0
pass() { echo "PASS image.$1"; }
failed() { echo "FAIL image.$1: $2"; fail=1; }
port() { python3 -c 'import socket; s=socket.socket(); s.bind(("127.0.0.1", 0)); print(s.getsockname()[1])'; }
wait_200() { # URL SECONDS
    for _ in $(seq "$2"); do
        [ "$(curl -s -o /dev/null -w '%{http_code}' "$1")" = 200 ] && return 0
        sleep 1
    done
    return 1
}
name=isoserve-test-$$
cleanup() {
    "$C" rm -f "$name" >/dev/null 2>&1
    [ ${#COMPOSE[@]} -gt 0 ] && (cd docker && ISOSERVE_PORT=${front:-0} "${COMPOSE[@]}" -p "$name" down -v >/dev/null 2>&1)
}
trap cleanup EXIT

echo "image: building with $C (progress below)"
if make image CONTAINER="$C"; then pass build; else failed build "make image failed"; exit 1; fi

p=$(port)
"$C" run -d --name "$name" -p "127.0.0.1:$p:8080" isoserve:latest >/dev/null
if wait_200 "http://127.0.0.1:$p/healthz" 300; then pass replica_healthz; else failed replica_healthz "$("$C" logs "$name" 2>&1 | tail -5)"; fi
if curl -fsS "http://127.0.0.1:$p/v1/volumes/sphere/mesh?level=20&format=ply&normals=none" | head -c 3 | grep -q ply
then pass replica_mesh; else failed replica_mesh "no PLY mesh of sphere"; fi
health=$("$C" inspect --format '{{json .Config.Healthcheck}}' isoserve:latest 2>/dev/null)
case "$health" in *healthz*) pass image_keeps_healthcheck ;; *) failed image_keeps_healthcheck "$health" ;; esac
"$C" rm -f "$name" >/dev/null

if [ ${#COMPOSE[@]} -eq 0 ]; then echo "SKIP image.compose: neither docker compose nor podman-compose"; exit $fail; fi
front=$(port)
(cd docker && ISOSERVE_PORT=$front "${COMPOSE[@]}" -p "$name" up -d) >/dev/null 2>&1
mesh="http://127.0.0.1:$front/v1/volumes/torus/mesh?level=0&format=ply&normals=none"
if wait_200 "$mesh" 300; then pass compose_mesh_through_front; else failed compose_mesh_through_front "no 200 in 300 s"; fi
replica=$(curl -s -D - -o /dev/null "http://127.0.0.1:$front/v1/volumes/torus" | tr -d '\r' | sed -n 's/^X-Iso-Replica: //Ip')
if [ -n "$replica" ]; then
    (cd docker && "${COMPOSE[@]}" -p "$name" stop "$replica") >/dev/null 2>&1
    start=$(date +%s%N)
    code=$(curl -s -o /dev/null -w '%{http_code}' "http://127.0.0.1:$front/v1/volumes/torus/mesh?level=1&format=ply&normals=none")
    ms=$(( ($(date +%s%N) - start) / 1000000 ))
    if [ "$code" = 200 ]; then pass "compose_failover_after_stopping_$replica"; echo "INFO image.failover: ${ms} ms"
    else failed compose_failover "HTTP $code after stopping $replica"; fi
else
    failed compose_failover "no X-Iso-Replica on the volume's document"
fi
exit $fail
