#!/usr/bin/env bash
# Hostile raw volumes with a JSON sidecar (core/io/sidecar.c, outside the core's unit tests):
# each is refused by `isoserve info` with exit status 1 and exactly the message expected,
# never a crash. The core loaders' hostile files are in tests/unit/test_hostile.c.
# Prints PASS/FAIL lines.
set -uo pipefail
cd "$(dirname "$0")/../.."
bin=${ISOSERVE_BIN:-build/isoserve}  # tests/run.sh's asan pass gives build/san/isoserve
tmp=$(mktemp -d)
trap 'rm -rf "$tmp"' EXIT
label="hostile${ISO_SAN_SUFFIX:-}"
status=0

# case NAME SIDECAR_JSON DATA_COMMAND EXPECTED_MESSAGE: writes $tmp/NAME.raw (from the
# command's stdout) and its sidecar, runs info, compares stderr with the message ($T is the
# directory).
case_() {
    local name=$1 side=$2 data=$3 want=$4
    eval "$data" > "$tmp/$name.raw"
    printf '%s' "$side" > "$tmp/$name.raw.json"
    local got rc
    got=$(cd "$tmp" && "$OLDPWD/$bin" info "$name.raw" 2>&1 >/dev/null)
    rc=$?
    if [ "$rc" -eq 1 ] && [ "$got" = "$want" ]; then
        echo "PASS $label.sidecar_$name"
    else
        echo "FAIL $label.sidecar_$name: status $rc, message \"$got\", want \"$want\""
        status=1
    fi
}
zeros() { head -c "$1" /dev/zero; }
# A gzip stream of N zero bytes stored uncompressed (level 0), cut after K bytes.
stored_gzip() { /usr/bin/python3 -c "import gzip,sys; sys.stdout.buffer.write(gzip.compress(bytes($1), compresslevel=0)[:$2])"; }

case_ lying '{"dims": [4, 4, 4], "type": "uint8"}' "zeros 10" \
    "isoserve: lying.raw: truncated raw data: expected 64 bytes of samples, found 10"
case_ overflow '{"dims": [1e9, 1e9, 1e9], "type": "float64", "endian": "little"}' "zeros 8" \
    'isoserve: overflow.raw.json: "dims" overflow 64 bits'
case_ tera '{"dims": [10000, 10000, 10000], "type": "uint8"}' "zeros 8" \
    "isoserve: tera.raw: 10000x10000x10000 u8 samples (1000000000000 bytes) exceed the limit of 8589934592 bytes"
case_ gzip_cut '{"dims": [4, 4, 4], "type": "uint8", "compression": "gzip"}' "stored_gzip 64 35" \
    "isoserve: gzip_cut.raw: truncated gzip data: expected 64 bytes of samples, found 20"
case_ gzip_junk '{"dims": [4, 4, 4], "type": "uint8", "compression": "gzip"}' "printf 'not gzip at all'" \
    "isoserve: gzip_junk.raw: corrupt gzip data after 0 bytes: incorrect header check"
case_ nan_dims '{"dims": [4, 4, NaN], "type": "uint8"}' "zeros 64" \
    "isoserve: nan_dims.raw.json:1:19: invalid token near 'NaN'"
case_ fraction '{"dims": [4, 4, 4.5], "type": "uint8"}' "zeros 64" \
    'isoserve: fraction.raw.json: "dims"[2] = 4.5 is not a size of at least 2'
case_ negative '{"dims": [4, -4, 4], "type": "uint8"}' "zeros 64" \
    'isoserve: negative.raw.json: "dims"[1] = -4 is not a size of at least 2'
case_ skip '{"dims": [4, 4, 4], "type": "uint8", "header_bytes": 10}' "zeros 64" \
    "isoserve: skip.raw: truncated raw data: expected 64 bytes of samples, found 54"
case_ skip_past '{"dims": [4, 4, 4], "type": "uint8", "header_bytes": 100}' "zeros 64" \
    'isoserve: skip_past.raw.json: "header_bytes" is 100, past the end of skip_past.raw (64 bytes)'
case_ skip_huge '{"dims": [4, 4, 4], "type": "uint8", "header_bytes": 9223372036854775807}' "zeros 64" \
    'isoserve: skip_huge.raw.json: "header_bytes" is 9223372036854775807, past the end of skip_huge.raw (64 bytes)'
case_ skip_gzip '{"dims": [4, 4, 4], "type": "uint8", "compression": "gzip", "header_bytes": 9223372036854775807}' \
    "stored_gzip 64 999" "isoserve: skip_gzip.raw: truncated gzip data: expected 64 bytes of samples, found 0"
case_ spacing '{"dims": [4, 4, 4], "type": "uint8", "spacing": [1, 0, 1]}' "zeros 64" \
    'isoserve: spacing.raw.json: "spacing"[1] = 0 must be positive'
case_ notjson '[1, 2' "zeros 64" \
    "isoserve: notjson.raw.json:1:5: ']' expected near end of file"
exit $status
