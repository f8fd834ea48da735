#!/usr/bin/env bash
# The container images, built and run for real (make test-image; not part of make test: the
# build alone takes minutes). With docker, or podman where docker has no engine:
#   1. docker/image.sh builds isoserve and isoserve-front (a local Debian base is made with
#      docker/base-image.sh first when none is there and none can be pulled);
#   2. the server image: no test tool inside, a HEALTHCHECK kept, runs as a non-root user;
#   3. one replica on loopback: /healthz, the catalog, a mesh, the engine's health status;
#   4. the compose stack (three replicas and nginx) with docker compose or podman-compose:
#      /healthz through the front, a mesh, then the replica that served it removed: the
#      next mesh of that volume comes from another replica (loaded on demand), with the
#      time the failover took printed.
# Says SKIP (and exits 0) where nothing can run containers. Ends "N passed, N failed".
set -uo pipefail
cd "$(dirname "$0")/../.."
. docker/engine.sh

passed=0 failed=0
pass() { echo "PASS image.$1"; passed=$((passed + 1)); }
fail() { echo "FAIL image.$1: $2"; failed=$((failed + 1)); }
finish() { echo "$passed passed, $failed failed"; [ "$failed" -eq 0 ]; exit $?; }

if ! engine_pick; then
    echo "SKIP image: $ENGINE_WHY"
    echo "0 passed, 0 failed, 1 skipped"
    exit 0
fi
echo "INFO image.engine: $ENGINE${COMPOSE:+, $COMPOSE}"

slim=${SLIM_IMAGE:-debian:bookworm-slim}
if ! $ENGINE image inspect "$slim" >/dev/null 2>&1 && ! $ENGINE pull -q "$slim" >/dev/null 2>&1; then
    bash docker/base-image.sh || { fail base_image "no $slim and docker/base-image.sh failed"; finish; }
fi
if ! engine_can_run "$slim"; then
    echo "SKIP image: $ENGINE_WHY"
    echo "0 passed, 0 failed, 1 skipped"
    exit 0
fi

# ---- 1. build
if bash docker/image.sh; then pass build; else fail build "docker/image.sh failed"; finish; fi

# ---- 2. what is in the server image
inspect() { $ENGINE image inspect --format "$1" isoserve:latest; }
health=$(inspect '{{json .Config.Healthcheck}}')
case "$health" in *healthz*) pass healthcheck_kept ;; *) fail healthcheck_kept "the image has no HEALTHCHECK: $health" ;; esac
user=$(inspect '{{.Config.User}}')
[ -n "$user" ] && [ "$user" != root ] && [ "$user" != 0 ] && pass non_root || fail non_root "runs as '$user'"
tools=$($ENGINE run --rm --entrypoint sh isoserve:latest -c \
    'find / -xdev \( -name "playwright*" -o -name draco3d -o -name node \) 2>/dev/null | head -3' 2>/dev/null)
[ -z "$tools" ] && pass no_test_tools || fail no_test_tools "found $tools"

# ---- 3. one replica
port_one=18480
name_one=isoserve-image-check
cleanup_one() { $ENGINE rm -f "$name_one" >/dev/null 2>&1; }
cleanup_one
wait_ok() { # URL, seconds: 0 once it answers 200
    local deadline=$((SECONDS + $2))
    while [ $SECONDS -lt $deadline ]; do
        [ "$(curl -s -o /dev/null -w '%{http_code}' "$1")" = 200 ] && return 0
        sleep 1
    done
    return 1
}
mesh_check() { # label, URL: a 200 Draco mesh with triangles; prints its headers' replica
    local headers
    headers=$(curl -s -D - -o /tmp/isoserve-image-mesh.drc "$2")
    local status triangles
    status=$(echo "$headers" | head -1 | awk '{print $2}')
    triangles=$(echo "$headers" | tr -d '\r' | awk -F': ' 'tolower($1)=="x-iso-triangles"{print $2}')
    if [ "$status" = 200 ] && [ "${triangles:-0}" -gt 0 ]; then
        pass "$1"
    else
        fail "$1" "status $status, ${triangles:-no} triangles"
    fi
    echo "$headers" | tr -d '\r' | awk -F': ' 'tolower($1)=="x-iso-replica"{print $2}' > /tmp/isoserve-image-replica
}
# Without systemd podman cannot schedule the health checks (it says so on every start);
# the check below runs them itself.
$ENGINE run -d --name "$name_one" -p 127.0.0.1:$port_one:8080 isoserve:latest 2>&1 >/dev/null |
    grep -v 'systemd connection' >&2
if wait_ok "http://127.0.0.1:$port_one/healthz" 600; then
    pass one.healthz
    curl -s "http://127.0.0.1:$port_one/v1/volumes" | grep -q '"sphere"' && pass one.catalog ||
        fail one.catalog "/v1/volumes lacks the sphere phantom"
    mesh_check one.mesh "http://127.0.0.1:$port_one/v1/volumes/sphere/mesh?level=20"
    state=""
    for _ in $(seq 1 40); do # the engine's own check runs every 10 s
        state=$($ENGINE inspect --format '{{.State.Health.Status}}' "$name_one" 2>/dev/null)
        [ "$state" = healthy ] && break
        [ "$ENGINE" = podman ] && $ENGINE healthcheck run "$name_one" >/dev/null 2>&1
        sleep 1
    done
    [ "$state" = healthy ] && pass one.engine_health || fail one.engine_health "health status '$state'"
else
    fail one.healthz "no 200 from /healthz in 600 s: $($ENGINE logs --tail 5 "$name_one" 2>&1)"
fi
cleanup_one

# ---- 4. the compose stack
if [ -z "$COMPOSE" ]; then
    fail compose "no compose command for $ENGINE (docker compose, or apt-get install podman-compose)"
    finish
fi
port_stack=18481
project=isoserve-image-check
compose() { (cd docker && ISOSERVE_PORT=$port_stack $COMPOSE -p "$project" "$@"); }
cleanup_stack() { compose down -v >/dev/null 2>&1; }
cleanup_stack
trap 'cleanup_one; cleanup_stack' EXIT
if [ "$ENGINE" = podman ]; then
    compose up -d --no-build >/dev/null 2>&1 || compose up -d >/dev/null 2>&1
else
    compose up -d --no-build >/dev/null 2>&1
fi
front=http://127.0.0.1:$port_stack
if wait_ok "$front/healthz" 600; then
    pass stack.healthz
    mesh_check stack.mesh "$front/v1/volumes/torus/mesh?level=0"
    owner=$(cut -d: -f1 /tmp/isoserve-image-replica)
    if [ -n "$owner" ]; then
        container=$($ENGINE ps --format '{{.Names}}' | grep -E "(^|[_-])${owner}([_-]|$)" | head -1)
        $ENGINE rm -f "$container" >/dev/null 2>&1
        start=$(date +%s.%N)
        mesh_check stack.failover_mesh "$front/v1/volumes/torus/mesh?level=4"
        took=$(echo "$(date +%s.%N) - $start" | bc)
        other=$(cut -d: -f1 /tmp/isoserve-image-replica)
        [ -n "$other" ] && [ "$other" != "$owner" ] && pass stack.failover_replica ||
            fail stack.failover_replica "served by '$other' after '$owner' ($container) was removed"
        echo "INFO image.failover_seconds: $took (the first request after $owner vanished)"
    else
        fail stack.failover_replica "the mesh named no replica"
    fi
else
    fail stack.healthz "no 200 from the front's /healthz in 600 s"
fi
finish
