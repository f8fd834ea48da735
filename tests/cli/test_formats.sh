#!/usr/bin/env bash
# Raw volumes with a JSON sidecar through the CLI (core/io/sidecar.c reads the sidecar):
# a good pair loads with its geometry, extraction lands where the sidecar says, and
# hostile sidecars fail with a message naming the file and the field. PASS/FAIL lines.
set -uo pipefail
cd "$(dirname "$0")/../.."
bin=${ISOSERVE_BIN:-build/isoserve}  # tests/run.sh's asan pass gives build/san/isoserve
py=/usr/bin/python3
tmp=$(mktemp -d)
trap 'rm -rf "$tmp"' EXIT

pass() { echo "PASS formats${ISO_SAN_SUFFIX:-}.$1"; }
fail() { echo "FAIL formats${ISO_SAN_SUFFIX:-}.$1: $2"; }

# 8x6x5 big-endian uint16 samples 100*i, spacing (0.5, 2, 3), origin (10, 20, 30).
"$py" - "$tmp/ramp.raw" <<'PY'
import struct, sys
with open(sys.argv[1], "wb") as f:
    for k in range(5):
        for j in range(6):
            for i in range(8):
                f.write(struct.pack(">H", 100 * i))
PY
cat > "$tmp/ramp.raw.json" <<'JSON'
{"dims": [8, 6, 5], "type": "uint16", "endian": "big", "spacing": [0.5, 2, 3], "origin": [10, 20, 30]}
JSON
if $bin info "$tmp/ramp.raw" --json > "$tmp/info.json" 2> "$tmp/err" &&
   [ "$("$py" -c "import json; d=json.load(open('$tmp/info.json')); print(d['dims'], d['value_type'], d['value_range'])")" != "" ] &&
   grep -q '"value_type":"uint16"' "$tmp/info.json"; then pass sidecar_info; else fail sidecar_info "$(cat "$tmp/info.json" "$tmp/err")"; fi

# Level 250 crosses at i = 2.5: world x = 10 + 0.5 * 2.5 = 11.25 for every vertex.
if $bin extract "$tmp/ramp.raw" --level 250 -o "$tmp/r.ply" --normals none > /dev/null 2> "$tmp/err"; then
    xs=$("$py" - "$tmp/r.ply" <<'PY'
import struct, sys
data = open(sys.argv[1], "rb").read()
head, _, body = data.partition(b"end_header\n")
n = int([l for l in head.split(b"\n") if l.startswith(b"element vertex")][0].split()[2])
xs = {round(struct.unpack_from("<fff", body, 12 * v)[0], 4) for v in range(n)}
ys = [struct.unpack_from("<fff", body, 12 * v)[1] for v in range(n)]
print(sorted(xs), n, min(ys), max(ys))
PY
)
    if [ "$xs" = "[11.25] 30 20.0 30.0" ]; then pass sidecar_world_vertex; else fail sidecar_world_vertex "$xs"; fi
else fail sidecar_world_vertex "$(cat "$tmp/err")"; fi

# Hostile sidecars: each refused with the sidecar named and the reason given.
refuse() { # name, expected text, sidecar JSON
    local name=$1 want=$2
    cp "$tmp/ramp.raw" "$tmp/$name.raw"
    printf '%s' "$3" > "$tmp/$name.raw.json"
    $bin info "$tmp/$name.raw" > /dev/null 2> "$tmp/err"; local rc=$?
    if [ $rc -ne 0 ] && [ $rc -lt 128 ] && grep -q "$name.raw" "$tmp/err" && grep -q -- "$want" "$tmp/err"; then
        pass "refuses_$name"; else fail "refuses_$name" "status $rc: $(cat "$tmp/err")"; fi
}
refuse no_dims '"dims" is required' '{"type": "uint16", "endian": "big"}'
refuse bad_type "is not uint8" '{"dims": [8,6,5], "type": "complex", "endian": "big"}'
refuse no_endian '"endian"' '{"dims": [8,6,5], "type": "uint16"}'
refuse zero_spacing 'must be positive' '{"dims": [8,6,5], "type": "uint16", "endian": "big", "spacing": [1,0,1]}'
refuse negative_spacing 'must be positive' '{"dims": [8,6,5], "type": "uint16", "endian": "big", "spacing": [1,-1,1]}'
refuse lying_dims 'truncated' '{"dims": [8,6,50], "type": "uint16", "endian": "big"}'
refuse thin '"dims"\[2\] = 1' '{"dims": [8,6,1], "type": "uint16", "endian": "big"}'
refuse not_json 'not_json.raw.json:1' '{"dims": [8,6,5], "type": '
refuse duplicate 'duplicate' '{"dims": [8,6,5], "dims": [8,6,5], "type": "uint16", "endian": "big"}'
# Normals: tricubic by default, written into the PLY; a bad name is refused by option.
if $bin extract field:sphere:32 --level 4 -o "$tmp/n.ply" > /dev/null 2> "$tmp/err" &&
   head -c 400 "$tmp/n.ply" | grep -aq "property float nx"; then pass normals_default_in_ply; else fail normals_default_in_ply "$(cat "$tmp/err")"; fi
if ! $bin extract field:sphere:32 --level 4 --normals bogus > /dev/null 2> "$tmp/err" &&
   grep -q -- "--normals 'bogus'" "$tmp/err"; then pass normals_bad_name; else fail normals_bad_name "$(cat "$tmp/err")"; fi
exit 0
