"""Benchmark against the peers a user would pick instead, in one run on one machine:
VTK's vtkFlyingEdges3D (full scan, 1 and 2 threads) and vtkContourFilter with vtkSpanSpace
(a preprocessed scalar tree), next to isoserve's exact path and its tolerance ladder.

Per case: isoserve's hierarchy build on one thread (best of 4 wall times and of 3 CPU
times, seconds per 10^7 voxels; target <= 1) and its bytes against the volume's (target <= 10%); the exact path on 1 and 2
threads against Flying Edges; then the ladder: 0, 2%, 5%, 10% and 20% of the value range and
the client's preview tolerance (half of it), on 1 and 2 threads, twice: as extraction
answers by default (`--coarsen faster`: coarse units only where they beat the exact kernel;
target: every rung >= 0.95x the exact path's speed) and with every coarse unit the tolerance
allows (`--coarsen all`, what the server sends), each rung's share of blocks coarsened,
triangles (and share of the exact ones), time against the exact path and against Flying
Edges, and (all, one thread) its symmetric distance to the exact surface (mean, p99, max over
both surfaces, measured by `isoserve bench --distances`, core/mesh/distance.c), in mm and in
voxels of the smallest spacing. Then scaling: CThead and ch2better resampled to four sizes, time and cells visited
against voxels with the fitted exponent. Prints tables, writes bench/results/peer.json and
bench/results/scaling.png (beside the JSON).

Without ../shared/volumes it says so and runs what this machine has: Debian's
mricron-data Colin27 brains (ch2better, ch2bet), no scaling. ISO_BENCH_CASES="CThead
skin,aneurism" picks cases by label; ISO_BENCH_VOLUME=FILE:LEVEL runs one given volume
(NRRD or NIfTI) instead; ISO_BENCH_OUT names the JSON written.

Both sides get their best set-up: VTK's SMP backend Sequential for 1 thread and TBB for 2,
glibc malloc tuned (no mmap, no trim) so output pages stay mapped between runs; isoserve's
own best-of-N timer, with the mesh array reused in the same way. Times are best of
ISO_BENCH_REPEAT runs, measured alternately."""

import ctypes
import gzip
import json
import os
import re
import subprocess
import sys
import tempfile
import time

from provenance import provenance  # tests/bench/provenance.py, beside this file  # noqa: E402

import numpy as np
from vtkmodules.util import numpy_support
import vtkmodules.all as vtk

BIN = os.path.abspath(os.environ.get("ISOSERVE_BIN", "build/isoserve"))
SHARED = os.environ.get("ISO_SHARED_VOLUMES", "../shared/volumes")
REPEAT = int(os.environ.get("ISO_BENCH_REPEAT", "7"))
THREADS = (1, 2)

CASES = [  # file, level, label
    ("CThead_256x256x113_u16be.nhdr", 700, "CThead skin"),
    ("CThead_256x256x113_u16be.nhdr", 1500, "CThead bone"),
    ("cranium_256x256x108_i16le.nhdr", -142, "cranium skin"),
    ("cranium_256x256x108_i16le.nhdr", 300, "cranium bone"),
    ("ch2better_301x370x316_u8.nhdr", 30, "ch2better"),
    ("bonsai_256x256x256_u8.nhdr", 40, "bonsai"),
    ("aneurism_256x256x256_u8.nhdr", 120, "aneurism"),
    ("engine_256x256x128_u8.nhdr", 80, "engine"),
    ("bunny_512x512x361_i16le.nhdr", 1700, "bunny"),  # the hold-out class, 512^2
]
# Without the shared scans: Debian's mricron-data (README.md's default collection).
DEBIAN = "/usr/share/mricron/templates"
DEBIAN_CASES = [("ch2better.nii.gz", 30, "ch2better (Debian)"), ("ch2bet.nii.gz", 30, "ch2bet (Debian)")]
# The ladder, as `isoserve bench --tolerances` reads it: shares of the value range and the
# client's preview tolerance (iso_preview_tolerance, half the range).
LADDER = "0,2%,5%,10%,20%,preview"
TARGET_BUILD_S = 1.0      # per 10^7 voxels, one thread
TARGET_HIERARCHY = 10.0   # % of the volume's bytes
TARGET_RUNG_SPEED = 0.95  # a rung's speed against the exact path's, --coarsen faster


def tune_malloc():
    libc = ctypes.CDLL("libc.so.6")
    M_TRIM_THRESHOLD, M_MMAP_MAX = -1, -4
    libc.mallopt(M_MMAP_MAX, 0)
    libc.mallopt(M_TRIM_THRESHOLD, 1 << 30)


def read_nrrd(path):
    """The shared volumes' NRRD headers: sizes, type, endian, spacings, gzip data file."""
    fields = {}
    for line in open(path):
        m = re.match(r"([^:#]+):\s*(.*)", line.strip())
        if m:
            fields[m.group(1).strip()] = m.group(2).strip()
    sizes = [int(v) for v in fields["sizes"].split()]
    dtype = {"uint8": "u1", "uint16": "u2", "int16": "i2", "float": "f4"}[fields["type"]]
    dtype = (">" if fields.get("endian") == "big" else "<") + dtype
    data = os.path.join(os.path.dirname(path), fields["data file"])
    raw = gzip.open(data).read() if fields.get("encoding") == "gzip" else open(data, "rb").read()
    array = np.frombuffer(raw, dtype=dtype).astype(np.dtype(dtype).newbyteorder("="))
    spacing = [float(v) for v in fields.get("spacings", "1 1 1").split()]
    return array, sizes, spacing


def read_nifti(path):
    """A NIfTI file through VTK's reader: its samples, sizes and spacing."""
    r = vtk.vtkNIFTIImageReader()
    r.SetFileName(path)
    r.Update()
    img = r.GetOutput()
    array = numpy_support.vtk_to_numpy(img.GetPointData().GetScalars()).copy()
    return array, list(img.GetDimensions()), list(img.GetSpacing())


def read_volume(path):
    return read_nifti(path) if path.endswith((".nii", ".nii.gz")) else read_nrrd(path)


def image_data(array, sizes, spacing):
    img = vtk.vtkImageData()
    img.SetDimensions(*sizes)
    img.SetSpacing(*spacing)
    scalars = numpy_support.numpy_to_vtk(array, deep=True)
    scalars.SetName("v")
    img.GetPointData().SetScalars(scalars)
    return img


def set_threads(n):
    vtk.vtkSMPTools.SetBackend("Sequential" if n == 1 else "TBB")
    vtk.vtkSMPTools.Initialize(n)


def flying_edges(img, level, threads):
    set_threads(threads)
    fe = vtk.vtkFlyingEdges3D()
    fe.SetInputData(img)
    fe.SetValue(0, level)
    fe.ComputeNormalsOff()
    fe.ComputeGradientsOff()
    fe.ComputeScalarsOff()
    best = float("inf")
    for _ in range(REPEAT):
        fe.Modified()
        t = time.perf_counter()
        fe.Update()
        best = min(best, (time.perf_counter() - t) * 1e3)
    return best, fe.GetOutput().GetNumberOfPolys()


def span_space(img, level):
    """vtkContourFilter over vtkSpanSpace: the first update builds the tree and answers;
    later levels only query it (the tree is kept while the input is unchanged)."""
    set_threads(1)
    cf = vtk.vtkContourFilter()
    cf.SetInputData(img)
    cf.UseScalarTreeOn()
    tree = vtk.vtkSpanSpace()
    cf.SetScalarTree(tree)
    cf.ComputeNormalsOff()
    cf.ComputeScalarsOff()
    cf.SetValue(0, level)
    t = time.perf_counter()
    cf.Update()
    first = (time.perf_counter() - t) * 1e3
    triangles = cf.GetOutput().GetNumberOfPolys()
    queries = []
    for k in range(3):
        cf.SetValue(0, level + 0.25 * (k + 1))
        t = time.perf_counter()
        cf.Update()
        queries.append((time.perf_counter() - t) * 1e3)
    return {"first_update_ms": first, "query_ms": min(queries), "triangles": triangles}


def isoserve_bench(path, level, tolerances, threads, resample=None, distances=False, builds=1, coarsen="faster"):
    """`isoserve bench` on the preloaded hierarchy; tolerances as its --tolerances reads them;
    the build timed 1 + `builds` times."""
    with tempfile.NamedTemporaryFile(suffix=".json") as out:
        args = [BIN, "bench", path, "--level", str(level), "--tolerances", tolerances,
                "--threads", str(threads), "--repeat", str(REPEAT), "--no-baselines", "--json", out.name,
                "--build-repeat", str(builds), "--coarsen", coarsen]
        if resample:
            args += ["--resample", resample]
        if distances:
            args.append("--distances")
        subprocess.run(args, check=True, stdout=subprocess.DEVNULL)
        return json.load(open(out.name))


def run_case(path, level, label):
    print(f"-- {label}", flush=True)
    array, sizes, spacing = read_volume(path)
    img = image_data(array, sizes, spacing)
    case = {"case": label, "file": os.path.basename(path), "level": level, "dims": sizes,
            "voxels": int(array.size), "volume_bytes": int(array.nbytes), "threads": {}}
    for n in THREADS:
        fe_ms, fe_tri = flying_edges(img, level, n)
        # The ladder as extraction answers it, then with every coarse unit (distances on one
        # thread: the meshes do not depend on the threads).
        iso = isoserve_bench(path, level, LADDER, n, builds=3 if n == 1 else 0)
        fe_again, _ = flying_edges(img, level, n)  # alternate, keep the best of both
        every = isoserve_bench(path, level, LADDER, n, distances=n == 1, builds=0, coarsen="all")
        fe_ms = min(fe_ms, fe_again)
        for row in iso["rows"] + every["rows"]:
            row["flying_edges_over_isoserve"] = fe_ms / row["extract_ms_with_minmax"]
        case["threads"][n] = {"flying_edges_ms": fe_ms, "flying_edges_triangles": fe_tri,
                              "build_ms": iso["build_ms"], "rows": iso["rows"], "rows_all": every["rows"]}
        if n == 1:
            for key in ("hierarchy_bytes", "hierarchy_percent", "build_ms", "build_s_per_1e7_voxels",
                        "build_cpu_ms", "build_cpu_s_per_1e7_voxels",
                        "value_range", "voxel_mm", "preview_tolerance"):
                case[key] = iso[key]
    case["ladder"] = case["threads"][1]["rows_all"]
    case["span_space"] = span_space(img, level)
    # Ties: integer levels on integer data; at level + 0.5 both must give the same count.
    fe_half, fe_half_tri = flying_edges(img, level + 0.5, 1)
    iso_half = isoserve_bench(path, level + 0.5, "0", 1, builds=0)
    case["half_level_triangles"] = {"flying_edges": fe_half_tri, "isoserve": iso_half["rows"][0]["polygons"]}
    return case


def faithful(case):
    """The largest ladder tolerance within 0.5 voxel at the 99th percentile, its row."""
    best = case["ladder"][0]
    for row in case["ladder"][1:]:
        d = row["distance_voxels"]
        if d and d["p99"] <= 0.5:
            best = row
    return best


def write_bandwidth():
    """Bytes per second this machine writes to memory already mapped (a 256 MiB buffer,
    best of 5): the physical floor for writing a mesh out."""
    a = np.empty(256 * 1024 * 1024 // 8)
    a.fill(0)
    best = float("inf")
    for _ in range(5):
        t = time.perf_counter()
        a.fill(1.0)
        best = min(best, time.perf_counter() - t)
    return a.nbytes / best


def fit_exponent(xs, ys):
    slope, _ = np.polyfit(np.log(xs), np.log(ys), 1)
    return float(slope)


def scaling():
    out = []
    for file, level, factors in (("CThead_256x256x113_u16be.nhdr", 700, (0.5, 0.79, 1.26, 2.0)),
                                 ("ch2better_301x370x316_u8.nhdr", 30, (0.5, 0.71, 1.0, 1.41))):
        path = os.path.abspath(os.path.join(SHARED, file))
        dims = [int(v) for v in re.search(r"_(\d+)x(\d+)x(\d+)_", file).groups()]
        points = []
        for f in factors:
            size = "x".join(str(max(2, round(d * f))) for d in dims)
            iso = isoserve_bench(path, level, "0,50", 1, resample=size, builds=0, coarsen="all")
            voxels = int(np.prod([int(v) for v in size.split("x")]))
            points.append({"size": size, "voxels": voxels,
                           "tolerance_0": {k: iso["rows"][0][k] for k in ("extract_ms_with_minmax", "cells_visited", "polygons")},
                           "tolerance_50": {k: iso["rows"][1][k] for k in ("extract_ms_with_minmax", "cells_visited", "polygons")}})
        vox = [p["voxels"] for p in points]
        fit = {}
        for tol in ("tolerance_0", "tolerance_50"):
            fit[tol] = {"time_exponent": fit_exponent(vox, [p[tol]["extract_ms_with_minmax"] for p in points]),
                        "cells_exponent": fit_exponent(vox, [p[tol]["cells_visited"] for p in points]),
                        "triangles_exponent": fit_exponent(vox, [p[tol]["polygons"] for p in points])}
        out.append({"file": file, "level": level, "points": points, "fit": fit})
    return out


def plot(scale, png):
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    fig, ax = plt.subplots(1, 2, figsize=(10, 4))
    for s in scale:
        vox = [p["voxels"] for p in s["points"]]
        for tol, style in (("tolerance_0", "o-"), ("tolerance_50", "s--")):
            name = s["file"].split("_")[0]
            ax[0].loglog(vox, [p[tol]["extract_ms_with_minmax"] for p in s["points"]], style,
                         label=f"{name} {tol.replace('_', ' ')} (x^{s['fit'][tol]['time_exponent']:.2f})")
            ax[1].loglog(vox, [p[tol]["cells_visited"] for p in s["points"]], style,
                         label=f"{name} {tol.replace('_', ' ')} (x^{s['fit'][tol]['cells_exponent']:.2f})")
    ax[0].set_xlabel("voxels"); ax[0].set_ylabel("extraction ms, 1 thread")
    ax[1].set_xlabel("voxels"); ax[1].set_ylabel("cells visited")
    for a in ax:
        a.grid(True, which="both", alpha=0.3)
        a.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(png, dpi=110)


def chosen_cases():
    """(path, level, label) of the cases this run measures, and whether they are the
    shared scans (the scaling part needs them)."""
    one = os.environ.get("ISO_BENCH_VOLUME")  # FILE:LEVEL
    if one:
        path, level = one.rsplit(":", 1)
        return [(os.path.abspath(path), float(level), os.path.basename(path))], False
    if not os.path.isdir(SHARED):
        print(f"bench_peer: {SHARED} is absent; measuring Debian's mricron-data brains instead")
        return [(os.path.join(DEBIAN, f), lvl, label) for f, lvl, label in DEBIAN_CASES
                if os.path.exists(os.path.join(DEBIAN, f))], False
    only = os.environ.get("ISO_BENCH_CASES")  # e.g. "CThead skin,aneurism" for a quick look
    return [(os.path.abspath(os.path.join(SHARED, f)), lvl, label) for f, lvl, label in CASES
            if not only or any(o.strip() == label for o in only.split(","))], not only


def mark(ok):
    return "ok" if ok else "OVER"


def print_exact(cases):
    print(f"{'case':18} {'thr':>3} {'FE ms':>7} {'iso ms':>7} {'FE/iso':>6} {'tri FE':>8} {'tri iso':>8} "
          f"{'@L+.5 FE':>8} {'@L+.5 iso':>9} {'cells %':>7} {'SpanSpace first/query ms':>24} {'floor ms':>8}")
    for c in cases:
        for n in THREADS:
            t = c["threads"][n]
            r0 = t["rows"][0]
            cells = (c["dims"][0] - 1) * (c["dims"][1] - 1) * (c["dims"][2] - 1)
            print(f"{c['case']:18} {n:>3} {t['flying_edges_ms']:>7.1f} {r0['extract_ms_with_minmax']:>7.1f} "
                  f"{r0['flying_edges_over_isoserve']:>6.2f} {t['flying_edges_triangles']:>8} "
                  f"{r0['polygons']:>8} {c['half_level_triangles']['flying_edges']:>8} "
                  f"{c['half_level_triangles']['isoserve']:>9} {100 * r0['cells_visited'] / cells:>7.1f} "
                  f"{c['span_space']['first_update_ms']:>12.0f} / {c['span_space']['query_ms']:>9.0f} {c['floor_ms']:>8.2f}")


def print_build(cases):
    print(f"{'case':18} {'voxels':>10} {'build ms 1t':>11} {'s/1e7 vox':>9} {'target':>6} {'CPU ms':>7} "
          f"{'CPU s/1e7':>9} {'tree KB':>8} {'tree %':>6} {'target':>6}")
    for c in cases:
        print(f"{c['case']:18} {c['voxels']:>10} {c['build_ms']:>11.0f} {c['build_s_per_1e7_voxels']:>9.2f} "
              f"{mark(c['build_s_per_1e7_voxels'] <= TARGET_BUILD_S):>6} {c['build_cpu_ms']:>7.0f} "
              f"{c['build_cpu_s_per_1e7_voxels']:>9.2f} {c['hierarchy_bytes'] / 1024:>8.0f} "
              f"{c['hierarchy_percent']:>6.1f} {mark(c['hierarchy_percent'] <= TARGET_HIERARCHY):>6}")


def rung_name(case, row):
    if row["tolerance"] == case["preview_tolerance"] and row["tolerance"] > 0:
        return "prev."
    return f"{100 * (row['share_of_range'] or 0):.0f}%"


def print_speed(cases):
    print(f"{'case':18} {'range':>6} | {'coarse %':>8} {'exact/t 1t':>10} {'2t':>6} {'target':>6} | "
          f"{'coarse %':>8} {'tri %':>6} {'exact/t 1t':>10} {'2t':>6}")
    for c in cases:
        one, two = c["threads"][1], c["threads"][2]
        for k, r in enumerate(one["rows"]):
            if r["tolerance"] == 0:
                continue
            a1, f2, a2 = one["rows_all"][k], two["rows"][k], two["rows_all"][k]
            ok = min(r["exact_over_tolerance_time"], f2["exact_over_tolerance_time"]) >= TARGET_RUNG_SPEED
            print(f"{c['case']:18} {rung_name(c, r):>6} | {100 * r['coarse_share']:>8.1f} "
                  f"{r['exact_over_tolerance_time']:>10.2f} {f2['exact_over_tolerance_time']:>6.2f} {mark(ok):>6} | "
                  f"{100 * a1['coarse_share']:>8.1f} {100 * (a1['share_of_exact_triangles'] or 0):>6.1f} "
                  f"{a1['exact_over_tolerance_time']:>10.2f} {a2['exact_over_tolerance_time']:>6.2f}")


def print_ladder(cases):
    print(f"{'case':18} {'tol':>8} {'range':>6} {'tri':>8} {'tri %':>6} {'ms 1t':>7} {'exact/t':>7} "
          f"{'FE/t':>6} {'mean mm':>8} {'p99 mm':>7} {'max mm':>7} {'mean vx':>8} {'p99 vx':>7} {'max vx':>7}")
    for c in cases:
        for r in c["ladder"]:
            dm = r["distance_mm"] or {"mean": 0, "p99": 0, "max": 0}
            dv = r["distance_voxels"] or {"mean": 0, "p99": 0, "max": 0}
            share = rung_name(c, r)
            print(f"{c['case']:18} {r['tolerance']:>8.4g} {share:>6} {r['polygons']:>8} "
                  f"{100 * (r['share_of_exact_triangles'] or 0):>6.1f} {r['extract_ms_with_minmax']:>7.1f} "
                  f"{r['exact_over_tolerance_time']:>7.2f} {r['flying_edges_over_isoserve']:>6.2f} "
                  f"{dm['mean']:>8.3f} {dm['p99']:>7.3f} {dm['max']:>7.2f} {dv['mean']:>8.3f} {dv['p99']:>7.3f} "
                  f"{dv['max']:>7.2f}")


def print_scaling(scale):
    for s in scale:
        for p in s["points"]:
            print(f"{s['file'].split('_')[0]:10} {p['size']:>12} {p['voxels']:>10} "
                  f"t0 {p['tolerance_0']['extract_ms_with_minmax']:>7.1f} ms {p['tolerance_0']['cells_visited']:>9} cells  "
                  f"t50 {p['tolerance_50']['extract_ms_with_minmax']:>7.1f} ms {p['tolerance_50']['cells_visited']:>9} cells")
        for tol, f in s["fit"].items():
            print(f"  {tol}: time ~ voxels^{f['time_exponent']:.2f}, cells ~ voxels^{f['cells_exponent']:.2f}, "
                  f"triangles ~ voxels^{f['triangles_exponent']:.2f}")


def main():
    tune_malloc()
    bandwidth = write_bandwidth()
    chosen, shared = chosen_cases()
    cases = [run_case(path, lvl, label) for path, lvl, label in chosen]
    for c in cases:  # float32 positions and uint32 indices; vertices ~ triangles / 2
        r0 = c["threads"][1]["rows"][0]
        c["output_bytes"] = r0["polygons"] * 12 + r0["polygons"] // 2 * 12
        c["floor_ms"] = c["output_bytes"] / bandwidth * 1e3
        f = faithful(c)
        c["faithful"] = {"tolerance": f["tolerance"], "extract_ms": f["extract_ms_with_minmax"],
                         "flying_edges_over_isoserve": f["flying_edges_over_isoserve"]}
    print(f"memory write bandwidth {bandwidth / 1e9:.1f} GB/s")
    print("\nthe exact path (tolerance 0) against Flying Edges")
    print_exact(cases)
    print(f"\nthe hierarchy: build on one thread (target <= {TARGET_BUILD_S:g} s per 10^7 voxels), "
          f"size (target <= {TARGET_HIERARCHY:g}% of the volume)")
    print_build(cases)
    print("\nthe ladder against the exact path's time: as extraction answers (--coarsen faster; target every rung "
          f">= {TARGET_RUNG_SPEED:g}x on 1 and 2 threads) | every coarse unit (--coarsen all, the server's)")
    print_speed(cases)
    print("\nthe ladder with every coarse unit, one thread: distances to the exact surface, both ways (mm, and voxels "
          "of the smallest spacing)")
    print_ladder(cases)
    scale = scaling() if shared else []
    print()
    print_scaling(scale)
    out = os.environ.get("ISO_BENCH_OUT", "bench/results/peer.json")
    os.makedirs(os.path.dirname(out) or ".", exist_ok=True)
    json.dump({**provenance(), "repeat": REPEAT,
               "write_bandwidth_bytes_per_s": bandwidth, "ladder": LADDER,
               "vtk": vtk.vtkVersion.GetVTKVersion(), "cases": cases, "scaling": scale},
              open(out, "w"), indent=1)
    png = os.path.join(os.path.dirname(out) or ".", "scaling.png")  # beside the JSON
    if scale:
        plot(scale, png)
    print(f"written {out}" + (f" and {png}" if scale else ""))
    return 0


if __name__ == "__main__":
    sys.exit(main())
