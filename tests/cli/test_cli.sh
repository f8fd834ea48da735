#!/usr/bin/env bash
# End-to-end tests of the isoserve command line: files written and read back, JSON reports,
# hierarchy files, and clear failures on bad input. Prints PASS/FAIL/SKIP lines.
set -uo pipefail
cd "$(dirname "$0")/../.."
bin=${ISOSERVE_BIN:-build/isoserve}  # tests/run.sh's asan pass gives build/san/isoserve
py=/usr/bin/python3
tmp=$(mktemp -d)
trap 'rm -rf "$tmp"' EXIT
shared=${ISO_SHARED_VOLUMES:-../shared/volumes}

pass() { echo "PASS cli${ISO_SAN_SUFFIX:-}.$1"; }
fail() { echo "FAIL cli${ISO_SAN_SUFFIX:-}.$1: $2"; }
json() { "$py" -c "import json,sys; d=json.load(open(sys.argv[1])); print(eval(sys.argv[2]))" "$@"; }

# info reports the volume's shape and range, as /v1/volumes names them (test_http.py checks
# the two documents agree), and what only the command line tells.
if $bin info field:sphere:32x30x28 --json > "$tmp/info.json" &&
   [ "$(json "$tmp/info.json" "(d['id'], d['name'], d['dims'], d['value_type'], len(d['suggested_levels']), d['bytes'], d['path'])")" = \
     "('field-sphere-32x30x28', 'field-sphere-32x30x28', [32, 30, 28], 'float32', 2, 107520, 'field:sphere:32x30x28')" ]
then pass info; else fail info "$(cat "$tmp/info.json")"; fi

# extract writes a binary PLY whose counts and size match the JSON report.
if $bin extract field:sphere:40 --level 4 --tolerance 0.05 --normals none -o "$tmp/s.ply" --json > "$tmp/s.json"; then
    v=$(json "$tmp/s.json" "d['vertices']"); t=$(json "$tmp/s.json" "d['triangles']")
    header=$(head -c 400 "$tmp/s.ply" | "$py" -c "import sys; h=sys.stdin.buffer.read().split(b'end_header\n')[0]; print(len(h)+11)")
    hv=$(head -c 400 "$tmp/s.ply" | grep -a '^element vertex' | cut -d' ' -f3)
    ht=$(head -c 400 "$tmp/s.ply" | grep -a '^element face' | cut -d' ' -f3)
    size=$(stat -c %s "$tmp/s.ply")
    if [ "$v" = "$hv" ] && [ "$t" = "$ht" ] && [ "$t" -gt 100 ] &&
       [ "$size" -eq $((header + v * 12 + t * 13)) ] &&
       [ "$("$py" -c "print($(json "$tmp/s.json" "d['error_bound']") <= 0.05)")" = True ]; then
        pass extract_ply
    else fail extract_ply "json $v/$t, header $hv/$ht, size $size"; fi
else fail extract_ply "exit status $?"; fi

# A hierarchy file gives the same surface as a fresh build; a damaged one is refused by name.
if $bin build field:torus:48 -o "$tmp/t.isotree" > /dev/null &&
   a=$($bin extract field:torus:48 --level 1 --tolerance 0.2 --json | "$py" -c "import json,sys; print(json.load(sys.stdin)['triangles'])") &&
   b=$($bin extract field:torus:48 --level 1 --tolerance 0.2 --json --hierarchy "$tmp/t.isotree" | "$py" -c "import json,sys; print(json.load(sys.stdin)['triangles'])") &&
   [ "$a" = "$b" ]; then pass hierarchy_file; else fail hierarchy_file "fresh ${a:-?} vs file ${b:-?}"; fi
printf '\x55' | dd of="$tmp/t.isotree" bs=1 seek=100 conv=notrunc 2> /dev/null
if ! $bin extract field:torus:48 --level 1 --hierarchy "$tmp/t.isotree" 2> "$tmp/err" > /dev/null &&
   grep -q "t.isotree" "$tmp/err" && grep -qi "checksum" "$tmp/err"; then pass hierarchy_corrupt; else fail hierarchy_corrupt "$(cat "$tmp/err")"; fi
if ! $bin extract field:torus:40 --level 1 --hierarchy "$tmp/t.isotree" 2> "$tmp/err" > /dev/null &&
   grep -q "t.isotree" "$tmp/err"; then pass hierarchy_other_volume; else fail hierarchy_other_volume "$(cat "$tmp/err")"; fi

# Bad input: a clear message and a non-zero status, never a crash.
# A sphere of radius R + 2 in a cube of half-side R is cut open by the faces: the census
# says where (border edges only); --cap closes it, and only then is there a volume to report.
if $bin extract field:sphere:32 --level -2 --tolerance 0.2 --normals none --json > "$tmp/o.json" &&
   $bin extract field:sphere:32 --level -2 --tolerance 0.2 --normals none --cap -o "$tmp/c.stl" --json > "$tmp/c.json"; then
    open_ok=$(json "$tmp/o.json" "d['open_edges'] == 0 and d['boundary_edges'] > 0 and d['nonmanifold_edges'] == 0 and not d['closed'] and d['enclosed_volume_mm3'] is None")
    cap_ok=$(json "$tmp/c.json" "d['open_edges'] == 0 and d['boundary_edges'] == 0 and d['closed'] and 0 < d['enclosed_volume_mm3'] < 31**3 and d['area_mm2'] > 0")
    t=$(json "$tmp/c.json" "d['triangles']"); size=$(stat -c %s "$tmp/c.stl")
    if [ "$open_ok" = True ] && [ "$cap_ok" = True ] && [ "$size" = $((84 + 50 * t)) ]; then pass cap_stl
    else fail cap_stl "open $open_ok, capped $cap_ok, stl $size bytes for $t triangles"; fi
else fail cap_stl "extract failed"; fi

check_refusal() { # name, expected text, command...
    local name=$1 want=$2; shift 2
    "$@" > /dev/null 2> "$tmp/err"; local rc=$?
    if [ $rc -ne 0 ] && [ $rc -lt 128 ] && grep -q -- "$want" "$tmp/err"; then pass "$name"; else fail "$name" "status $rc: $(cat "$tmp/err")"; fi
}
check_refusal missing_file "nosuch.nhdr" $bin extract "$tmp/nosuch.nhdr" --level 1
check_refusal bad_level "--level" $bin extract field:sphere:16 --level abc
check_refusal nan_level "--level" $bin extract field:sphere:16 --level nan
check_refusal negative_tolerance "--tolerance" $bin extract field:sphere:16 --level 1 --tolerance -1
check_refusal unknown_field "sphere" $bin info field:nosuchfield
# -o NAME.meshopt.glb: the fast codec's glb; three's GLTFLoader with MeshoptDecoder reads
# back exactly the CLI's triangles and vertices, with normals.
if [ -d web/node_modules/three ]; then
    if $bin extract field:sphere:40 --level 4 -o "$tmp/s.meshopt.glb" --json > "$tmp/m.json" &&
       got=$(node tests/http/gltf_load.mjs "$tmp/s.meshopt.glb" "$PWD/web" | cut -d' ' -f1-3) &&
       want=$("$py" -c "import json; d=json.load(open('$tmp/m.json')); print(d['triangles'], d['vertices'], 'true')") &&
       [ "$got" = "$want" ] && grep -aq EXT_meshopt_compression "$tmp/s.meshopt.glb"; then
        pass extract_meshopt_glb
    else fail extract_meshopt_glb "loaded '${got:-}', CLI says '${want:-}'"; fi
else
    echo "SKIP cli.extract_meshopt_glb: web/node_modules/three not installed (make node-deps)"
fi
# The Khronos glTF validator finds no error and no warning in either codec's glb, with and
# without normals, nor in an empty one; a meshopt glb's index stream says version 1 (0xe1,
# what EXT_meshopt_compression's TRIANGLES mode requires).
if [ -d web/node_modules/gltf-validator ]; then
    if $bin extract field:sphere:40 --level 4 -o "$tmp/v.meshopt.glb" > /dev/null &&
       $bin extract field:sphere:40 --level 4 --normals none -o "$tmp/vn.meshopt.glb" > /dev/null &&
       $bin extract field:sphere:40 --level 4 -o "$tmp/v.glb" > /dev/null &&
       $bin extract field:sphere:40 --level 1000 -o "$tmp/ve.meshopt.glb" > /dev/null &&
       got=$(node tests/http/gltf_validate.mjs "$PWD/web" "$tmp/v.meshopt.glb" "$tmp/vn.meshopt.glb" "$tmp/v.glb" \
             "$tmp/ve.meshopt.glb" 2> "$tmp/err" | tr '\n' ' ') &&
       [ "$got" = "0 0 0xe1 0 0 0xe1 0 0 - 0 0 - " ]; then
        pass gltf_validator
    else fail gltf_validator "got '${got:-}': $(cat "$tmp/err")"; fi
else
    echo "SKIP cli.gltf_validator: web/node_modules/gltf-validator not installed (make node-deps)"
fi
check_refusal unknown_format "unknown output format" $bin extract field:sphere:16 --level 1 -o "$tmp/x.xyz"
check_refusal cap_full_scan "--cap needs the hierarchy" $bin extract field:sphere:16 --level 1 --cap --full-scan
check_refusal budget_zero "whole number of triangles from 1" $bin extract field:sphere:16 --level 1 --budget 0
check_refusal no_simplify_alone "--no-simplify goes with --budget" $bin extract field:sphere:16 --level 1 --no-simplify

# --budget: on a sphere the faithful ladder (up to range / 32) stays above 300 triangles, so
# 300 are met by the exact mesh's simplification chain, its finest level within the budget
# (level 11: 10172 / 2^5.5 = 224 at most, level 10's 316 > 300 above it), measured; --no-simplify climbs the whole
# ladder instead, whose coarse rungs (bricks at their coarsest levels, 320 triangles: the
# border's clipped bricks cannot take stride 8) meet 330.
if $bin extract field:sphere:40 --level 3 --budget 300 --normals none --json > "$tmp/bs.json" &&
   $bin extract field:sphere:40 --level 3 --budget 330 --no-simplify --normals none --json > "$tmp/bl.json" &&
   [ "$(json "$tmp/bs.json" "(d['triangles'], d['tolerance'], d['budget']['fits'], d['chain']['level'], d['chain']['built'][10]['triangles'] > 300, d['distance']['p99'] > 0, d['closed'])")" = "(224, 0.0, True, 11, True, True, True)" ] &&
   [ "$(json "$tmp/bl.json" "(d['triangles'] <= 330, d['tolerance'] > 1.03, d['budget']['fits'], 'simplify' in d)")" = "(True, True, True, False)" ]; then
    pass budget_simplifies
else
    fail budget_simplifies "$(cat "$tmp/bs.json" "$tmp/bl.json")"
fi
# --distance: the coarsest chain level whose measured p99 is within D (levels' p99 grow with
# k on a sphere), its distance the level's, closed; 0 is the exact mesh itself.
check_refusal distance_with_budget "--distance chooses the mesh itself" $bin extract field:sphere:16 --level 1 --distance 1 --budget 9
if $bin extract field:sphere:40 --level 3 --distance 0.3 --normals none --json > "$tmp/dd.json" &&
   $bin extract field:sphere:40 --level 3 --distance 0 --normals none --json > "$tmp/d0.json" &&
   $bin extract field:sphere:40 --level 3 --normals none --json > "$tmp/dx.json" &&
   [ "$(json "$tmp/dd.json" "(d['chain']['level'] == max(k for k, b in enumerate(d['chain']['built']) if b['p99'] <= 0.3), d['chain']['level'] >= 2, d['distance']['p99'] == d['chain']['built'][d['chain']['level']]['p99'], d['triangles'] == d['chain']['built'][d['chain']['level']]['triangles'], d['closed'])")" = "(True, True, True, True, True)" ] &&
   [ "$(json "$tmp/d0.json" "(d['chain']['level'], d['distance']['max'], d['triangles'])")" = "(0, 0.0, $(json "$tmp/dx.json" "d['triangles']"))" ]; then
    pass distance_from_chain
else
    fail distance_from_chain "$(cat "$tmp/dd.json" "$tmp/d0.json")"
fi
# ijk's surface at 3000 is open strips: simplified far enough, a level has every vertex on a
# border, so the next step's heap is empty (it crashed the collapser). The chain then ends
# at that level; a distance of 1000 mm asks for all of it.
if $bin extract field:ijk:32 --level 3000 --distance 1000 --normals none --json > "$tmp/lk.json" &&
   [ "$(json "$tmp/lk.json" "(d['chain']['level'] == len(d['chain']['built']) - 1, d['triangles'] == d['chain']['built'][-1]['triangles'], all(a['triangles'] >= b['triangles'] > 0 for a, b in zip(d['chain']['built'], d['chain']['built'][1:])), len(d['chain']['built']) > 2)")" = "(True, True, True, True)" ]; then
    pass distance_all_locked
else
    fail distance_all_locked "$(cat "$tmp/lk.json")"
fi
# --distance builds the chain only down to the level it needs (the first one beyond D),
# marked partial. --min-component V: closed pieces enclosing less than V mm3 go first,
# counted in "components"; the sphere (radius 16.5: a bounding-box diagonal of 57 mm)
# stays under V = 1, goes under V = 1e9.
check_refusal min_component_negative "--min-component '-1'" $bin extract field:sphere:16 --level 1 --min-component -1
if $bin extract field:sphere:40 --level 3 --distance 0.1 --min-component 1 --normals none --json > "$tmp/mc1.json" &&
   $bin extract field:sphere:40 --level 3 --min-component 1e9 --normals none --json > "$tmp/mc9.json" &&
   [ "$(json "$tmp/dd.json" "(d['chain']['partial'], d['chain']['built'][-1]['p99'] > 0.3, len(d['chain']['built']) == d['chain']['level'] + 2)")" = "(True, True, True)" ] &&
   [ "$(json "$tmp/mc1.json" "(d['components'], d['chain']['level'] > 0)")" = "({'min_component_mm3': 1.0, 'before': 1, 'removed': 0, 'removed_triangles': 0, 'removed_largest': 0.0}, True)" ] &&
   [ "$(json "$tmp/mc9.json" "(d['components']['removed'], d['components']['removed_triangles'] == $(json "$tmp/dx.json" "d['triangles']"), 57 < d['components']['removed_largest'] < 58, d['triangles'])")" = "(1, True, True, 0)" ]; then
    pass min_component
else
    fail min_component "$(cat "$tmp/dd.json" "$tmp/mc1.json" "$tmp/mc9.json")"
fi
printf 'NRRD0004\ntype: float\ndimension: 3\nsizes: 4 4 4\nencoding: raw\n\nshort' > "$tmp/short.nrrd"
check_refusal truncated_nrrd "short.nrrd" $bin extract "$tmp/short.nrrd" --level 1

# bench prints the paper's Table 1 columns and writes one JSON row per tolerance.
if $bin bench field:ml:40 --level 0.5 --tolerances 0,0.01,0.1 --repeat 1 --json "$tmp/b.json" > "$tmp/b.txt" &&
   grep -q "marching cubes" "$tmp/b.txt" && [ "$(json "$tmp/b.json" "len(d['rows'])")" = 3 ] &&
   [ "$(json "$tmp/b.json" "d['rows'][0]['polygons'] == d['marching_cubes']['polygons']")" = True ]; then
    pass bench_table
else fail bench_table "$(cat "$tmp/b.txt")"; fi

# A tolerance coarsens every unit it may (the fewest triangles) unless --coarsen faster, which
# keeps the exact surface where coarse units would not pay (here: too few stride-8 bricks).
if $bin extract field:ml:40 --level 0.5 --tolerance 0.3 --json > "$tmp/ca.json" &&
   $bin extract field:ml:40 --level 0.5 --tolerance 0.3 --coarsen faster --json > "$tmp/cf.json" &&
   $bin extract field:ml:40 --level 0.5 --json > "$tmp/c0.json" &&
   [ "$(json "$tmp/ca.json" "(d['coarse_share'] > 0.5, d['triangles'] * 2 < $(json "$tmp/c0.json" "d['triangles']"), d['error_bound'] <= 0.3, d['open_edges'], d['nonmanifold_edges'])")" = "(True, True, True, 0, 0)" ] &&
   [ "$(json "$tmp/cf.json" "(d['coarse_share'], d['triangles'], d['error_bound'])")" = "(0.0, $(json "$tmp/c0.json" "d['triangles']"), 0.0)" ]; then
    pass coarsen_choice
else
    fail coarsen_choice "$(cat "$tmp/ca.json" "$tmp/cf.json")"
fi
check_refusal coarsen_unknown "coarsen 'sometimes': expected faster or all" \
    $bin extract field:ml:40 --level 0.5 --coarsen sometimes

# The paper's data set: tolerance 0 through the hierarchy is the full-scan surface.
if [ -d "$shared" ]; then
    head=$shared/CThead_256x256x113_u16be.nhdr
    a=$($bin extract "$head" --level 1500 --json | "$py" -c "import json,sys; d=json.load(sys.stdin); print(d['triangles'], d['vertices'])")
    b=$($bin extract "$head" --level 1500 --json --full-scan | "$py" -c "import json,sys; d=json.load(sys.stdin); print(d['triangles'], d['vertices'])")
    if [ -n "$a" ] && [ "$a" = "$b" ]; then pass cthead_tolerance0_is_full_scan; else fail cthead_tolerance0_is_full_scan "$a vs $b"; fi
else
    echo "SKIP cli.cthead_tolerance0_is_full_scan: needs $shared"
fi

# segments: Debian's JHU white-matter atlas as a label map with its names: every segment at
# once (their triangles add up to the scene's), one segment closed to an STL, and refusals.
jhu=/usr/share/mricron/templates/JHU-WhiteMatter-labels-1mm.nii.gz
if [ -f "$jhu" ]; then
    if $bin segments "$jhu" --labels-file "${jhu%.gz}.txt" --json -o "$tmp/jhu.glb" > "$tmp/jhu.json" &&
       [ "$(json "$tmp/jhu.json" "len(d['segments'])")" = 48 ] &&
       [ "$(json "$tmp/jhu.json" "d['segments'][2]['name']")" = Genu_of_corpus_callosum ] &&
       [ "$(json "$tmp/jhu.json" "sum(s['triangles'] for s in d['segments']) == d['triangles'] > 100000")" = True ] &&
       [ "$(head -c 4 "$tmp/jhu.glb")" = glTF ]; then
        pass segments_all
    else fail segments_all "$(head -c 600 "$tmp/jhu.json")"; fi
    if $bin segments "$jhu" --segment 3 --cap --smoothing 1 --json -o "$tmp/genu.stl" > "$tmp/genu.json" &&
       [ "$(json "$tmp/genu.json" "d['closed'] and d['triangles'] > 1000")" = True ] &&
       [ "$(stat -c %s "$tmp/genu.stl")" -eq $((84 + 50 * $(json "$tmp/genu.json" "d['triangles']"))) ]; then
        pass segments_one_closed
    else fail segments_one_closed "$(cat "$tmp/genu.json")"; fi
    check_refusal segments_unknown_number "no segment numbered 99" $bin segments "$jhu" --segment 99
    check_refusal segments_scene_format "one .glb or .meshopt.glb" $bin segments "$jhu" -o "$tmp/all.ply"
else
    echo "SKIP cli.segments: needs Debian's mricron-data"
fi
check_refusal segments_float_volume "holds integers" $bin segments field:sphere:16
