#!/usr/bin/env bash
# The layout's promises, checked on the sources:
#   - core/ is split by stage (base, io, volume, hierarchy, extract, mesh, and segment, the
#     segmentations built on them), each with one public header; a stage's other headers are its own: nothing outside the stage
#     includes them (the unit tests and their support code are white-box and may);
#   - core/ speaks neither HTTP nor the API's JSON: no libmicrohttpd, libcurl or jansson
#     in core/, except jansson in io/sidecar.c, which reads the sidecar file format;
#   - server/ and proto/ include core only through the public headers.
# PASS/FAIL lines, one per promise.
set -uo pipefail
cd "$(dirname "$0")/../.."

pass() { echo "PASS layout${ISO_SAN_SUFFIX:-}.$1"; }
fail() { echo "FAIL layout${ISO_SAN_SUFFIX:-}.$1: $2"; }

stages="base io volume hierarchy extract mesh segment"
public="base/base.h io/io.h volume/volume.h hierarchy/tree.h extract/extract.h mesh/mesh.h segment/segment.h"

# 1. The folders are exactly the stages, and each holds its public header.
found=$(find core -mindepth 1 -maxdepth 1 -type d -printf '%f\n' | sort | tr '\n' ' ')
want=$(echo $stages | tr ' ' '\n' | sort | tr '\n' ' ')
loose=$(find core -maxdepth 1 -type f | tr '\n' ' ')
missing=""
for h in $public; do [ -f "core/$h" ] || missing="$missing $h"; done
if [ "$found" = "$want" ] && [ -z "$loose" ] && [ -z "$missing" ]; then pass stages
else fail stages "folders '$found' (want '$want'), loose files '$loose', missing '$missing'"; fi

# 2. Includes of a stage's headers from outside it name its public header only. A
#    quoted include with a slash names another stage's header ("mesh/mesh.h").
bad=""
for f in $(find core server proto tests/fuzz -name '*.c' -o -name '*.h' -o -name '*.cc' | sort); do
    own=""
    case "$f" in core/*/*) own=$(echo "$f" | cut -d/ -f2);; esac
    while IFS= read -r inc; do
        st=${inc%%/*}
        case " $stages " in *" $st "*) ;; *) continue;; esac
        [ "$st" = "$own" ] && { bad="$bad $f:$inc(own stage: include it by name)"; continue; }
        case " $public " in *" $inc "*) ;; *) bad="$bad $f:$inc";; esac
    done < <(sed -n 's/^#include "\([^"]*\/[^"]*\)".*/\1/p' "$f")
done
if [ -z "$bad" ]; then pass public_headers_only; else fail public_headers_only "$bad"; fi

# 3. A header named without a folder from outside core/ would bypass the check above.
bare=""
for f in $(find server proto tests/support tests/fuzz tests/unit -name '*.c' -o -name '*.h' -o -name '*.cc' | sort); do
    while IFS= read -r inc; do
        [ -n "$(find core -name "$inc" -print -quit)" ] && bare="$bare $f:$inc"
    done < <(sed -n 's/^#include "\([^"/]*\)".*/\1/p' "$f")
done
if [ -z "$bare" ]; then pass core_headers_by_folder; else fail core_headers_by_folder "$bare"; fi

# 4. No HTTP and no API JSON in core/.
http=$(grep -rlE '#include <(microhttpd|curl/curl)\.h>' core | tr '\n' ' ')
json=$(grep -rl '#include <jansson.h>' core | grep -v '^core/io/sidecar.c$' | tr '\n' ' ')
if [ -z "$http$json" ]; then pass core_has_no_http_or_json
else fail core_has_no_http_or_json "http: '$http' json: '$json'"; fi
