#!/usr/bin/env bash
# Checks that two builds make the same meshes: for a change meant to leave every mesh as it
# was (a faster tolerance path, a refactor), the binary PLY bytes, the triangle count, the
# error bound and the capped census of OLD and NEW agree on analytic fields and, where the
# shared volumes are present, CThead (skin and bone) and engine, at several tolerances,
# capped and not. Prints PASS/FAIL/SKIP lines and ends with a count.
#   scripts/same_meshes.sh OLD_ISOSERVE NEW_ISOSERVE
set -uo pipefail
old=${1:?usage: same_meshes.sh OLD_ISOSERVE NEW_ISOSERVE}
new=${2:?usage: same_meshes.sh OLD_ISOSERVE NEW_ISOSERVE}
shared=${ISO_SHARED_VOLUMES:-../shared/volumes}
py=/usr/bin/python3
tmp=$(mktemp -d)
trap 'rm -rf "$tmp"' EXIT
passed=0 failed=0

summary() { "$py" -c "import json,sys; d=json.load(open(sys.argv[1])); print(d['triangles'], d['vertices'], repr(d['error_bound']), d['closed'], d['enclosed_volume_mm3'])" "$1"; }

# same NAME EXTRACT-ARGS...: both builds on one case, one thread (the coarse pass's order).
same() {
    local name=$1 o n
    shift
    for b in old new; do
        local bin=$old
        [ $b = new ] && bin=$new
        if ! "$bin" extract "$@" --threads 1 --normals none -o "$tmp/$b.ply" --json > "$tmp/$b.json" 2> "$tmp/$b.err"; then
            echo "FAIL same_meshes.$name: $b failed: $(head -c 300 "$tmp/$b.err")"
            failed=$((failed + 1))
            return
        fi
    done
    o=$(summary "$tmp/old.json")
    n=$(summary "$tmp/new.json")
    if [ "$o" != "$n" ]; then
        echo "FAIL same_meshes.$name: triangles, vertices, error bound, closed, volume $o against $n"
        failed=$((failed + 1))
    elif ! cmp -s "$tmp/old.ply" "$tmp/new.ply"; then
        echo "FAIL same_meshes.$name: same counts ($o) but the PLY bytes differ"
        failed=$((failed + 1))
    else
        echo "PASS same_meshes.$name ($o)"
        passed=$((passed + 1))
    fi
}

for field in sphere:40 torus:48 ml:40; do
    for t in 0.05 0.2 0.5 1.5; do
        same "$field.$t" "field:$field" --level 0.5 --tolerance "$t"
        same "$field.$t.cap" "field:$field" --level 0.5 --tolerance "$t" --cap
    done
done

ct=$shared/CThead_256x256x113_u16be.nhdr
if [ -f "$ct" ]; then
    "$old" build "$ct" -o "$tmp/ct.hier" > /dev/null
    for level in 700 1500; do
        for t in 0 100 327 654 1635 3272; do
            same "cthead.$level.$t" "$ct" --hierarchy "$tmp/ct.hier" --level $level --tolerance $t
        done
        same "cthead.$level.654.cap" "$ct" --hierarchy "$tmp/ct.hier" --level $level --tolerance 654 --cap
    done
    for t in 3 10 30; do
        same "engine.$t" "$shared/engine_256x256x128_u8.nhdr" --level 80 --tolerance $t
    done
else
    echo "SKIP same_meshes.cthead: needs $shared"
fi
echo "same_meshes: $passed passed, $failed failed"
[ $failed -eq 0 ]
