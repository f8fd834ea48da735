"""Segmentations: every segment of a label map at once against VTK's vtkDiscreteFlyingEdges3D
over the same labels, side by side in one run, on one thread and on two; each segment's
triangle count against vtkFlyingEdges3D on that segment's indicator at 0.5; and a single
segment's time against the cells it visits (its boundary bricks), not the volume.

Cases:
  bunny   a label map made from ../shared's CT bunny (512x512x361): thresholds into five
          value bands, each band cut into its connected components (vtkImageConnectivityFilter),
          the largest 100 of at least 1,000 voxels numbered 1..100 (about a 512^2 CT with
          as many organs); made once into build/bench/ and reused;
  aal     Debian's mricron-data AAL atlas (181x217x181, 116 regions): runs without ../shared.
Both sides extract without normals; VTK keeps its per-triangle label scalars (how its
output tells the segments apart), isoserve makes a mesh per segment. Times are the best of
REPEAT runs. Prints a table, writes bench/results/segments.json with the commit."""

import gzip
import json
import os
import subprocess
import sys
import time

import numpy as np
import vtkmodules.all as vtk
from vtkmodules.util import numpy_support

BIN = os.path.abspath(os.environ.get("ISOSERVE_BIN", "build/isoserve"))
SHARED = os.environ.get("ISO_SHARED_VOLUMES", "../shared/volumes")
AAL = "/usr/share/mricron/templates/aal.nii.gz"
REPEAT = int(os.environ.get("ISO_SEGMENTS_REPEAT", "5"))
BANDS = (150, 700, 1300, 1900, 2150, 4096)


def bunny_labels(out):
    """The bunny's label map as a raw NRRD (uint8, the bunny's geometry)."""
    if os.path.exists(out):
        return out
    src = os.path.join(SHARED, "bunny_512x512x361_i16le.raw.gz")
    data = np.frombuffer(gzip.open(src).read(), "<i2").reshape(361, 512, 512)
    regions = []  # (size, band, region id, label image)
    for b in range(len(BANDS) - 1):
        mask = ((data >= BANDS[b]) & (data < BANDS[b + 1])).astype(np.uint8)
        image = vtk.vtkImageData()
        image.SetDimensions(512, 512, 361)
        image.GetPointData().SetScalars(numpy_support.numpy_to_vtk(mask.ravel(), deep=1))
        f = vtk.vtkImageConnectivityFilter()
        f.SetInputData(image)
        f.SetScalarRange(1, 1)
        f.SetExtractionModeToAllRegions()
        f.SetLabelModeToSizeRank()
        f.SetLabelScalarTypeToInt()
        f.Update()
        sizes = numpy_support.vtk_to_numpy(f.GetExtractedRegionSizes())
        ids = numpy_support.vtk_to_numpy(f.GetOutput().GetPointData().GetScalars()).reshape(data.shape)
        regions += [(int(sizes[r]), b, r + 1, ids) for r in range(len(sizes)) if sizes[r] >= 1000]
    regions.sort(key=lambda r: -r[0])
    labels = np.zeros(data.shape, np.uint8)
    for n, (_, b, r, ids) in enumerate(regions[:100], start=1):
        labels[ids == r] = n
    os.makedirs(os.path.dirname(out), exist_ok=True)
    with open(out + ".tmp", "wb") as f:
        f.write(b"NRRD0004\ntype: uint8\ndimension: 3\nsizes: 512 512 361\nspace: left-posterior-superior\n"
                b"space directions: (0.337891,0,0) (0,0.337891,0) (0,0,0.5)\nspace origin: (0,0,0)\n"
                b"encoding: raw\n\n")
        f.write(labels.tobytes())
    os.replace(out + ".tmp", out)
    return out


def vtk_image(path):
    """The label map as VTK image data (index space: both sides count the same triangles).
    NIfTI through vtkNIFTIImageReader; this bench's own raw uint8 NRRD read here."""
    image = vtk.vtkImageData()
    if path.endswith(".nii.gz"):
        r = vtk.vtkNIFTIImageReader()
        r.SetFileName(path)
        r.Update()
        image.DeepCopy(r.GetOutput())
    else:
        raw = open(path, "rb").read()
        head = raw[:raw.index(b"\n\n")].decode()
        nx, ny, nz = (int(v) for v in head.split("sizes:")[1].split("\n")[0].split())
        image.SetDimensions(nx, ny, nz)
        labels = np.frombuffer(raw[-nx * ny * nz:], np.uint8)
        image.GetPointData().SetScalars(numpy_support.numpy_to_vtk(labels, deep=1))
    image.SetSpacing(1, 1, 1)
    image.SetOrigin(0, 0, 0)
    return image


def vtk_discrete(image, labels, threads):
    vtk.vtkSMPTools.Initialize(threads)
    best, triangles = None, 0
    for _ in range(REPEAT):
        f = vtk.vtkDiscreteFlyingEdges3D()
        f.SetInputData(image)
        for i, v in enumerate(labels):
            f.SetValue(i, v)
        f.ComputeNormalsOff()
        f.ComputeGradientsOff()
        t = time.perf_counter()
        f.Update()
        ms = (time.perf_counter() - t) * 1e3
        best = ms if best is None else min(best, ms)
        triangles = f.GetOutput().GetNumberOfCells()
    return best, triangles


def vtk_indicator_triangles(image, label):
    """vtkFlyingEdges3D on the label's 0/1 indicator at 0.5, and its time."""
    a = numpy_support.vtk_to_numpy(image.GetPointData().GetScalars())
    ind = vtk.vtkImageData()
    ind.SetDimensions(image.GetDimensions())
    ind.GetPointData().SetScalars(numpy_support.numpy_to_vtk((a == label).astype(np.uint8), deep=1))
    f = vtk.vtkFlyingEdges3D()
    f.SetInputData(ind)
    f.SetValue(0, 0.5)
    f.ComputeNormalsOff()
    f.ComputeGradientsOff()
    f.ComputeScalarsOff()
    t = time.perf_counter()
    f.Update()
    return f.GetOutput().GetNumberOfCells(), (time.perf_counter() - t) * 1e3


def isoserve(path, threads):
    p = subprocess.run([BIN, "segments", path, "--json", "--repeat", str(REPEAT), "--threads", str(threads)],
                       check=True, capture_output=True, text=True)
    return json.loads(p.stdout)


def run_case(name, path):
    ours = {t: isoserve(path, t) for t in (1, 2)}
    labels = [s["number"] for s in ours[1]["segments"]]
    image = vtk_image(path)
    theirs = {t: vtk_discrete(image, labels, t) for t in (1, 2)}
    vtk.vtkSMPTools.Initialize(1)
    mismatches, per_segment, fe_ms = [], [], []
    for s in ours[1]["segments"]:
        tris, ms = vtk_indicator_triangles(image, s["number"])
        fe_ms.append(ms)
        if tris != s["triangles"]:
            mismatches.append((s["number"], s["triangles"], tris))
        per_segment.append({"number": s["number"], "voxels": s["voxels"], "triangles": s["triangles"],
                            "vtk_triangles": tris, "cells_visited": s["cells_visited"], "ms": s["extract_ms"],
                            "vtk_indicator_ms": ms})
    cells = np.array([s["cells_visited"] for s in per_segment], float)
    ms = np.array([s["ms"] for s in per_segment], float)
    ns_per_cell = ms * 1e6 / np.maximum(cells, 1)
    result = {
        "case": name, "file": path, "dims": ours[1]["dims"], "segments": len(labels),
        "voxels": ours[1]["voxels"], "repeat": REPEAT,
        "isoserve_ms": {str(t): ours[t]["extract_ms"] for t in (1, 2)},
        "vtk_discrete_ms": {str(t): theirs[t][0] for t in (1, 2)},
        "ratio": {str(t): ours[t]["extract_ms"] / theirs[t][0] for t in (1, 2)},
        "triangles": ours[1]["triangles"], "vtk_discrete_triangles": theirs[1][1],
        "segments_with_other_triangle_counts": mismatches,
        "cells_visited_share": float(cells.sum()) / ours[1]["voxels"],
        "ns_per_cell_visited": {"min": float(ns_per_cell.min()), "median": float(np.median(ns_per_cell)),
                                "max": float(ns_per_cell.max())},
        "ms_cells_correlation": float(np.corrcoef(cells, ms)[0, 1]) if len(ms) > 2 else None,
        "vtk_indicator_ms_median": float(np.median(fe_ms)),
        "per_segment": per_segment,
    }
    return result


def commit():
    p = subprocess.run(["git", "rev-parse", "--short", "HEAD"], capture_output=True, text=True)
    return p.stdout.strip() or None


def main():
    cases = []
    if os.path.exists(os.path.join(SHARED, "bunny_512x512x361_i16le.raw.gz")):
        cases.append(("bunny", bunny_labels(os.path.abspath("build/bench/bunny_labels.nrrd"))))
    else:
        print(f"SKIP bunny: {SHARED} is absent (a user's clone); the AAL atlas runs alone")
    if os.path.exists(AAL):
        cases.append(("aal", AAL))
    else:
        print(f"SKIP aal: {AAL} is absent (apt-get install mricron-data)")
    results = []
    print(f"{'case':6} {'segs':>4} {'threads':>7} {'isoserve ms':>11} {'VTK discrete ms':>15} {'ratio':>6} "
          f"{'triangles':>10} {'FE3D counts differ':>18} {'cells visited':>13} {'ns/cell':>8}")
    for name, path in cases:
        r = run_case(name, path)
        results.append(r)
        for t in ("1", "2"):
            print(f"{name:6} {r['segments']:4d} {t:>7} {r['isoserve_ms'][t]:11.1f} {r['vtk_discrete_ms'][t]:15.1f} "
                  f"{r['ratio'][t]:6.3f} {r['triangles']:10d} {len(r['segments_with_other_triangle_counts']):18d} "
                  f"{r['cells_visited_share']:12.1%} {r['ns_per_cell_visited']['median']:8.2f}")
        print(f"       one segment: {r['ns_per_cell_visited']['min']:.2f}..{r['ns_per_cell_visited']['max']:.2f} ns per "
              f"cell visited (correlation of time and cells {r['ms_cells_correlation']:.3f}); vtkFlyingEdges3D on one "
              f"indicator {r['vtk_indicator_ms_median']:.1f} ms (median)")
    os.makedirs("bench/results", exist_ok=True)
    with open("bench/results/segments.json", "w") as f:
        json.dump({"commit": commit(), "date": time.strftime("%Y-%m-%d"), "cases": results}, f, indent=1)
    return 0


if __name__ == "__main__":
    sys.exit(main())
