"""test_ladder.py: what `isoserve bench --distances` and bench_peer's ladder report, on a
sphere whose answer is known.

The volume is f = 23.5 - |x - c| (voxels from the centre c of a 48^3 grid) with spacing
0.5 mm, so the level 8 is a sphere of radius R = 15.5 voxels, 7.75 mm. A rung's mesh has
every vertex within its error bound e of the level, and f is a distance, so each vertex is
within e voxels of the sphere; a triangle lies in one cell of its brick's grid, stride at
most 8, so its points are at most (R - e) - sqrt((R - e)^2 - 8^2) further inside (the
triangle's points are convex combinations of its corners); and the exact surface, seen from
the centre, crosses the same band. So both ways every distance is at most
    e + (R - e) - sqrt((R - e)^2 - 64) + 0.25 voxel
(0.25 for the trilinear interpolant of f and the exact mesh's own chords), and half that in
mm. Checked: those bounds, mm = voxels x 0.5, p99 <= max, the fields bench_peer and the
docs read, shares and ratios that agree with the counts they come from."""

import json
import math
import os
import shutil
import subprocess
import sys
import tempfile

import numpy as np

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "support"))
from results import Results  # noqa: E402 - found through the path just set

BIN = os.path.abspath(os.environ.get("ISOSERVE_BIN", "build/isoserve"))
RESULTS = Results("ladder" + os.environ.get("ISO_SAN_SUFFIX", ""))
N, R0, LEVEL, SPACING = 48, 23.5, 8.0, 0.5
RADIUS = R0 - LEVEL
ROW_FIELDS = ("tolerance", "polygons", "extract_ms_with_minmax", "share_of_range", "share_of_exact_triangles",
              "exact_over_tolerance_time", "error_bound", "fit_error", "distance_mm", "distance_voxels", "coarse_share")


def write_sphere(directory):
    c = (N - 1) / 2
    z, y, x = np.mgrid[0:N, 0:N, 0:N].astype(np.float64)
    f = (R0 - np.sqrt((x - c) ** 2 + (y - c) ** 2 + (z - c) ** 2)).astype("<f4")
    f.tofile(os.path.join(directory, "sphere.raw"))
    header = os.path.join(directory, "sphere.nhdr")
    with open(header, "w") as h:
        h.write(f"NRRD0004\ntype: float\ndimension: 3\nsizes: {N} {N} {N}\n"
                f"spacings: {SPACING} {SPACING} {SPACING}\nencoding: raw\nendian: little\ndata file: sphere.raw\n")
    return header


def close(a, b):
    """Equal to the JSON's 8 significant digits."""
    return abs(a - b) <= 1e-6 * max(abs(a), abs(b), 1e-12)


def bound_voxels(e):
    inner = RADIUS - e
    return e + inner - math.sqrt(inner * inner - 64) + 0.25


def check_rows(doc):
    rows = doc["rows"]
    assert [round(r["share_of_range"], 6) for r in rows] == [0, 0.02, 0.05, 0.1], rows
    exact = rows[0]
    assert exact["distance_mm"] is None and exact["distance_voxels"] is None, "tolerance 0 is the reference"
    assert exact["share_of_exact_triangles"] == 1 and exact["polygons"] > 1000, exact
    for r in rows:
        missing = [k for k in ROW_FIELDS if k not in r]
        assert not missing, f"row {r['tolerance']} lacks {missing}"
        assert close(r["share_of_exact_triangles"], r["polygons"] / exact["polygons"]), r
        assert close(r["exact_over_tolerance_time"], exact["extract_ms_with_minmax"] / r["extract_ms_with_minmax"]), r
        assert 0 <= r["coarse_share"] <= 1 and (r["coarse_share"] > 0 or r["polygons"] == exact["polygons"]), r
    for r in rows[1:]:
        mm, vx = r["distance_mm"], r["distance_voxels"]
        e = r["error_bound"]
        assert e <= r["tolerance"], r
        for k in ("mean", "p99", "max"):
            assert close(mm[k], vx[k] * SPACING), (k, mm, vx)
        assert 0 <= vx["mean"] <= vx["max"] and vx["p99"] <= vx["max"], vx
        assert vx["max"] <= bound_voxels(e), f"tolerance {r['tolerance']:g}: max {vx['max']} voxels > {bound_voxels(e)}"
    coarse = rows[-1]
    assert coarse["polygons"] < exact["polygons"], "10% of the range coarsens some bricks"
    assert coarse["distance_voxels"]["mean"] > 0, "a coarsened surface is not the exact one"


def test_bench_distances(header, tmp):
    out = os.path.join(tmp, "bench.json")
    subprocess.run([BIN, "bench", header, "--level", str(LEVEL), "--tolerances", "0,2%,5%,10%", "--threads", "1",
                    "--repeat", "2", "--no-baselines", "--distances", "--coarsen", "all", "--json", out],
                   check=True, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    doc = json.load(open(out))
    assert doc["voxels"] == N ** 3 and doc["voxel_mm"] == SPACING, doc
    assert close(doc["hierarchy_percent"], 100 * doc["hierarchy_bytes"] / doc["volume_bytes"]), doc
    assert close(doc["build_s_per_1e7_voxels"], doc["build_ms"] / doc["voxels"] * 1e4), doc
    assert close(doc["build_cpu_s_per_1e7_voxels"], doc["build_cpu_ms"] / doc["voxels"] * 1e4), doc
    assert doc["build_ms"] > 0 and doc["build_cpu_ms"] > 0 and 0 < doc["hierarchy_percent"] < 100, doc
    assert close(doc["preview_tolerance"], doc["value_range"] / 2), doc
    check_rows(doc)


def test_rungs_as_shares_and_refusals(header, tmp):
    """A rung is a value, N% of the range or "preview"; anything else is refused with the
    option named; --build-repeat 0 times no extra build, so there is no CPU time."""
    out = os.path.join(tmp, "rungs.json")
    subprocess.run([BIN, "bench", header, "--level", str(LEVEL), "--tolerances", "0,1.5,25%,preview", "--repeat", "1",
                    "--no-baselines", "--build-repeat", "0", "--json", out],
                   check=True, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    doc = json.load(open(out))
    got = [r["tolerance"] for r in doc["rows"]]
    want = [0, 1.5, 0.25 * doc["value_range"], doc["preview_tolerance"]]
    assert all(close(g, w) or g == w == 0 for g, w in zip(got, want)) and len(got) == 4, (got, want)
    assert doc["build_cpu_ms"] is None and doc["build_ms"] > 0, doc
    for bad in ("-1", "5%%", "x%", "%", "preview2", "0,,1"):
        p = subprocess.run([BIN, "bench", header, "--level", str(LEVEL), "--tolerances", bad, "--repeat", "1"],
                           capture_output=True, text=True)
        assert p.returncode == 1 and "--tolerances" in p.stderr, (bad, p.returncode, p.stderr)


def test_peer_ladder(header, tmp):
    """bench_peer on the same volume: one case, its ladder with Flying Edges beside it."""
    out = os.path.join(tmp, "peer.json")
    env = dict(os.environ, ISO_BENCH_VOLUME=f"{header}:{LEVEL}", ISO_BENCH_REPEAT="1", ISO_BENCH_OUT=out,
               ISOSERVE_BIN=BIN)
    subprocess.run(["/usr/bin/python3", os.path.join(os.path.dirname(os.path.abspath(__file__)), "bench_peer.py")],
                   check=True, env=env, stdout=subprocess.DEVNULL)
    case = json.load(open(out))["cases"][0]
    for k in ("build_s_per_1e7_voxels", "build_cpu_s_per_1e7_voxels", "hierarchy_percent", "preview_tolerance", "faithful", "ladder"):
        assert k in case, f"case lacks {k}"
    ladder = case["ladder"]
    assert len(ladder) == 6 and ladder[-1]["tolerance"] == case["preview_tolerance"], ladder
    fe = case["threads"]["1"]["flying_edges_ms"]
    for r in ladder:
        assert close(r["flying_edges_over_isoserve"], fe / r["extract_ms_with_minmax"]), r
    for r in ladder[1:5]:  # the rungs up to 20%: distances measured; below the bound up to 10%
        assert r["distance_voxels"] is not None and r["distance_mm"] is not None, r
    assert case["threads"]["1"]["flying_edges_triangles"] > 0
    # As extraction answers: a rung coarsens nothing (the exact surface) or as every coarse
    # unit would; both on 1 and 2 threads, the same meshes.
    for n in ("1", "2"):
        t = case["threads"][n]
        assert len(t["rows"]) == len(t["rows_all"]) == 6, t
        for fast, every in zip(t["rows"], t["rows_all"]):
            assert fast["coarse_share"] == 0 and fast["polygons"] == t["rows"][0]["polygons"] or \
                fast["coarse_share"] == every["coarse_share"] and fast["polygons"] == every["polygons"], (fast, every)
        assert [r["polygons"] for r in t["rows_all"]] == [r["polygons"] for r in ladder], n


def main():
    tmp = tempfile.mkdtemp(prefix="isoserve-ladder-")
    header = write_sphere(tmp)
    RESULTS.check("bench_distances_on_a_sphere", lambda: test_bench_distances(header, tmp))
    RESULTS.check("rungs_as_shares_and_refusals", lambda: test_rungs_as_shares_and_refusals(header, tmp))
    RESULTS.check("peer_ladder_fields", lambda: test_peer_ladder(header, tmp))
    shutil.rmtree(tmp, ignore_errors=True)
    return 1 if RESULTS.failures else 0


if __name__ == "__main__":
    sys.exit(main())
