"""Budgets: the tolerance ladder's coarse mesh against the exact mesh simplified with
meshoptimizer, at the same triangle count, by distance to the exact surface.

On sharp CT edges a node's fit error stays above any faithful tolerance until the node
is one cell wide, so the ladder removes few triangles there. For each case and budget N
(50k, 100k, 200k triangles) this measures, in one run:
  ladder      `extract --budget N --no-simplify`: the finest rung of value range / 2^k
              that fits (or the coarsest, over budget, when none does);
  simplified  the exact mesh simplified to the ladder mesh's own triangle count;
  served      `extract --budget N`: what the server serves (the ladder up to the faithful
              tolerance, value range / 32, then the exact mesh simplified to N).
Distances are in voxels (index-space meshes), both ways: from every vertex of the exact
mesh to the candidate surface, and from points sampled every 0.5 voxel over the candidate
(vertices, edges and interiors, vtkPolyDataPointSampler; ISO_SIMPLIFY_SAMPLE_STEP) to the exact surface
(vtkImplicitPolyDataDistance from Debian's python3-vtk9); the symmetric figures pool
both. For served meshes that were simplified, meshoptimizer's own error estimate stands
next to the measured distances. Prints a table, writes bench/results/simplify.json."""

import json
import os
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
CASES = [  # file, level, label
    ("CThead_256x256x113_u16be.nhdr", 700, "CThead skin"),
    ("CThead_256x256x113_u16be.nhdr", 1500, "CThead bone"),
    ("ch2better_301x370x316_u8.nhdr", 30, "ch2better"),
]
BUDGETS = (50_000, 100_000, 200_000)
SAMPLE_STEP = float(os.environ.get("ISO_SIMPLIFY_SAMPLE_STEP", "0.5"))  # voxels between samples on a candidate


def extract(path, level, out, *args):
    """isoserve extract in index space to a PLY; its JSON report and the mesh."""
    p = subprocess.run([BIN, "extract", path, "--level", str(level), "--normals", "none",
                        "--index-space", "--json", "-o", out, *args],
                       check=True, capture_output=True, text=True)
    reader = vtk.vtkPLYReader()
    reader.SetFileName(out)
    reader.Update()
    mesh = vtk.vtkPolyData()
    mesh.DeepCopy(reader.GetOutput())
    return json.loads(p.stdout), mesh


def distance_to(surface):
    f = vtk.vtkImplicitPolyDataDistance()
    f.SetInput(surface)
    return f


def unsigned_distances(field, points):
    out = vtk.vtkDoubleArray()
    field.FunctionValue(points, out)
    return np.abs(numpy_support.vtk_to_numpy(out))


def sample(mesh):
    s = vtk.vtkPolyDataPointSampler()
    s.SetInputData(mesh)
    s.SetDistance(SAMPLE_STEP)
    s.GenerateVertexPointsOn()
    s.GenerateEdgePointsOn()
    s.GenerateInteriorPointsOn()
    s.Update()
    return s.GetOutput().GetPoints().GetData()


def stats(d):
    return {"mean": float(d.mean()), "p99": float(np.percentile(d, 99)), "max": float(d.max())}


def compare(exact, exact_field, candidate):
    """Distances between a candidate mesh and the exact one, in voxels."""
    if candidate.GetNumberOfPolys() == 0:
        return None
    to_exact = unsigned_distances(exact_field, sample(candidate))
    from_exact = unsigned_distances(distance_to(candidate), exact.GetPoints().GetData())
    both = np.concatenate([to_exact, from_exact])
    return {"symmetric": stats(both), "candidate_to_exact": stats(to_exact),
            "exact_to_candidate": stats(from_exact),
            "exact_vertices_beyond_1_voxel": float((from_exact > 1).mean())}


def run_case(file, level, label, tmp):
    path = os.path.abspath(os.path.join(SHARED, file))
    ply = os.path.join(tmp, "m.ply")
    t = time.perf_counter()
    exact_doc, exact = extract(path, level, os.path.join(tmp, "exact.ply"))
    exact_field = distance_to(exact)
    case = {"case": label, "file": file, "level": level, "exact_triangles": exact_doc["triangles"],
            "budgets": []}
    print(f"  {label}: exact {exact_doc['triangles']} triangles", flush=True)
    for n in BUDGETS:
        ladder_doc, ladder = extract(path, level, ply, "--budget", str(n), "--no-simplify")
        row = {"budget": n,
               "ladder": {"triangles": ladder_doc["triangles"], "tolerance": ladder_doc["tolerance"],
                          "fits": ladder_doc["budget"]["fits"],
                          "extractions": ladder_doc["budget"]["extractions"],
                          "distance": compare(exact, exact_field, ladder)}}
        same_doc, same = extract(path, level, ply, "--simplify", str(ladder_doc["triangles"]))
        row["simplified_to_ladder_count"] = {"triangles": same_doc["triangles"],
                                             "estimate_voxels": same_doc.get("simplify", {}).get("error_voxels", 0.0),
                                             "distance": compare(exact, exact_field, same)}
        served_doc, served = extract(path, level, ply, "--budget", str(n))
        simplify = served_doc.get("simplify")
        row["served"] = {"triangles": served_doc["triangles"], "tolerance": served_doc["tolerance"],
                         "fits": served_doc["budget"]["fits"], "simplified": simplify is not None,
                         "simplify": simplify, "nonmanifold_edges": served_doc["nonmanifold_edges"],
                         "open_edges": served_doc["open_edges"],
                         "boundary_edges": served_doc["boundary_edges"],
                         "boundary_edges_exact": exact_doc["boundary_edges"],
                         "distance": compare(exact, exact_field, served)}
        case["budgets"].append(row)
        print(f"  {label}: budget {n} done ({time.perf_counter() - t:.0f} s)", flush=True)
    return case


def fmt(d):
    if not d:
        return f"{'-':>27}"
    s = d["symmetric"]
    return f"{s['mean']:>7.3f} {s['p99']:>7.3f} {s['max']:>7.2f}  {d['exact_to_candidate']['max']:>6.2f}"


def main():
    if not os.path.isdir(SHARED):
        print(f"bench_simplify: {SHARED} is absent; the budget benchmark needs the shared scans")
        return 0
    only = os.environ.get("ISO_BENCH_CASES")  # e.g. "CThead skin" for a quick look
    chosen = [c for c in CASES if not only or any(o.strip() == c[2] for o in only.split(","))]
    chosen = [c for c in chosen if os.path.exists(os.path.join(SHARED, c[0]))]
    os.makedirs("bench/results", exist_ok=True)
    out = "bench/results/simplify.json"
    cases = []
    with tempfile.TemporaryDirectory(prefix="isoserve-simplify-") as tmp:
        for f, lvl, label in chosen:  # the JSON after every case: a long run keeps what it measured
            cases.append(run_case(f, lvl, label, tmp))
            json.dump({**provenance(), "sample_step_voxels": SAMPLE_STEP, "vtk": vtk.vtkVersion.GetVTKVersion(),
                       "cases": cases}, open(out, "w"), indent=1)
    print("distances in voxels to the exact surface: symmetric mean, p99, max; then the")
    print("largest distance from an exact vertex to the candidate (what the candidate lost)")
    print(f"{'case':12} {'budget':>7} {'mesh':24} {'triangles':>9} {'fits':>4} "
          f"{'mean':>7} {'p99':>7} {'max':>7}  {'lost':>6} {'estimate':>8} {'ms':>7}")
    for c in cases:
        for r in c["budgets"]:
            lad, same, srv = r["ladder"], r["simplified_to_ladder_count"], r["served"]
            print(f"{c['case']:12} {r['budget']:>7} {'ladder t=' + format(lad['tolerance'], 'g'):24} "
                  f"{lad['triangles']:>9} {'yes' if lad['fits'] else 'no':>4} {fmt(lad['distance'])}")
            print(f"{'':12} {'':>7} {'exact simplified, same n':24} {same['triangles']:>9} {'':>4} "
                  f"{fmt(same['distance'])} {same['estimate_voxels']:>8.3f}")
            kind = "served: simplified" if srv["simplified"] else f"served: t={srv['tolerance']:g}"
            est = f"{srv['simplify']['error_voxels']:>8.3f} {srv['simplify']['ms']:>7.0f}" if srv["simplified"] else ""
            print(f"{'':12} {'':>7} {kind:24} {srv['triangles']:>9} {'yes' if srv['fits'] else 'no':>4} "
                  f"{fmt(srv['distance'])} {est}")
    print(f"written {out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
