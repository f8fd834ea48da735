# docker/engine.sh: picks the container engine for docker/image.sh and the image test, and
# makes a rootful podman work on a restricted host. Sourced; sets ENGINE (docker or podman)
# and COMPOSE (the matching compose command), or leaves ENGINE empty with ENGINE_WHY saying
# why nothing can run containers here.
#
# ISOSERVE_ENGINE=docker|podman chooses. Otherwise docker when its engine answers (the
# client alone is not enough), else podman.
#
# A restricted host (a container itself, without CAP_SYS_RESOURCE or with cgroups v1 and v2
# mixed) refuses podman's defaults: crun cannot raise RLIMIT_NOFILE/NPROC to podman's
# defaults there, nor run on "hybrid" cgroups. Then a containers.conf of ours (under
# build/containers, through CONTAINERS_CONF, never the system's) asks for runc and for the
# host's own limits.

engine_pick() {
    ENGINE="" COMPOSE="" ENGINE_WHY=""
    local want=${ISOSERVE_ENGINE:-}
    if [ -z "$want" ] || [ "$want" = docker ]; then
        if command -v docker >/dev/null && docker info >/dev/null 2>&1; then
            ENGINE=docker
            if docker compose version >/dev/null 2>&1; then COMPOSE="docker compose"; fi
            return 0
        fi
        [ "$want" = docker ] && { ENGINE_WHY="docker has no engine here (docker info fails)"; return 1; }
    fi
    if command -v podman >/dev/null; then
        ENGINE=podman
        if command -v podman-compose >/dev/null; then COMPOSE="podman-compose"; fi
        return 0
    fi
    ENGINE_WHY="neither a docker engine nor podman is here (apt-get install podman podman-compose)"
    return 1
}

# Runs `true` in image $1; on podman, falls back to our containers.conf when the defaults
# are refused. 0 when a container runs.
engine_can_run() {
    local image=$1 out
    out=$($ENGINE run --rm "$image" true 2>&1) && return 0
    [ "$ENGINE" = podman ] || { ENGINE_WHY="$ENGINE run fails: $out"; return 1; }
    case "$out" in
    *setrlimit*|*cgroups*|*cgroup*) ;;
    *) ENGINE_WHY="podman run fails: $out"; return 1 ;;
    esac
    command -v runc >/dev/null || { ENGINE_WHY="podman run fails ($out) and runc, which works where crun cannot, is not installed (apt-get install runc)"; return 1; }
    local dir root
    root=$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)
    dir="$root/build/containers"
    mkdir -p "$dir"
    # nproc: the hard limit itself is refused in a user namespace; a fixed ceiling is not.
    cat > "$dir/containers.conf" <<CONF
# Written by docker/engine.sh for a restricted host: runc instead of crun, the host's own
# open-file limit instead of podman's default, a fixed process limit.
[containers]
default_ulimits = ["nofile=$(ulimit -Hn):$(ulimit -Hn)", "nproc=4096:4096"]

[engine]
runtime = "runc"
CONF
    export CONTAINERS_CONF="$dir/containers.conf"
    out=$($ENGINE run --rm "$image" true 2>&1) && return 0
    ENGINE_WHY="podman run fails even with $CONTAINERS_CONF: $out"
    return 1
}
