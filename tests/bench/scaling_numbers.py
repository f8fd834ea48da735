"""The measurements behind docs/scaling.md: per volume, the hierarchy's bytes per voxel and
build time, and the Draco mesh bytes and extraction time of one view at a few tolerances.

    /usr/bin/python3 tests/bench/scaling_numbers.py [--shared ../shared/volumes] > table.md

Uses build/isoserve (`build`, `extract --json -o X.drc`). Volumes: the default collection
(mricron-data, analytic fields) and, when the directory exists, the shared real scans.
Prints two Markdown tables."""

import argparse
import json
import os
import re
import subprocess
import tempfile

ROOT = os.path.abspath(os.path.join(os.path.dirname(__file__), "..", ".."))
BIN = os.path.join(ROOT, "build/isoserve")
MRICRON = "/usr/share/mricron/templates"

# (label, path or field, level) - levels from docs and the shared volumes' README.
DEFAULT = [("ch2bet (MR, 1 mm)", f"{MRICRON}/ch2bet.nii.gz", 30),
           ("ch2 (MR head, 1 mm)", f"{MRICRON}/ch2.nii.gz", 60),
           ("ch2better (MR, 0.5 mm)", f"{MRICRON}/ch2better.nii.gz", 30),
           ("torus field 128^3 (f32)", "field:torus:128", 0),
           ("Marschner-Lobb 128^3 (f32)", "field:ml:128", 0.5)]
SHARED = [("CThead (CT, u16)", "CThead_256x256x113_u16be.nhdr", 700.5),
          ("cranium (CT, i16 HU)", "cranium_256x256x108_i16le.nhdr", -300),
          ("engine (industrial CT, u8)", "engine_256x256x128_u8.nhdr", 80),
          ("bonsai (CT, u8, noisy)", "bonsai_256x256x256_u8.nhdr", 40),
          ("aneurism (angiography, u8)", "aneurism_256x256x256_u8.nhdr", 100)]
TOLERANCES = (0, 5, 20)


def run(args):
    p = subprocess.run([BIN, *args], capture_output=True, text=True, check=True)
    return p.stdout + p.stderr


def measure(path, level, tmp):
    info = json.loads(run(["info", path, "--json"]))
    tree = os.path.join(tmp, "h.isotree")
    out = run(["build", path, "-o", tree])
    m = re.search(r"(\d+) nodes, (\d+) bytes .* built in ([\d.]+) ms", out)
    voxels = info["dims"][0] * info["dims"][1] * info["dims"][2]
    row = {"dims": "x".join(map(str, info["dims"])), "type": info["value_type"], "voxels": voxels,
           "volume_bytes": info["bytes"], "tree_bytes": int(m.group(2)),
           "file_bytes": os.path.getsize(tree), "build_ms": float(m.group(3)), "meshes": []}
    for t in TOLERANCES:
        drc = os.path.join(tmp, "m.drc")
        r = json.loads(run(["extract", path, "--level", str(level), "--tolerance", str(t),
                            "--hierarchy", tree, "--normals", "none", "-o", drc, "--json"]))
        row["meshes"].append((t, r["triangles"], os.path.getsize(drc), r["extract_ms"]))
    return row


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--shared", default=os.path.join(ROOT, "..", "shared", "volumes"))
    args = ap.parse_args()
    volumes = [(n, p, lv) for n, p, lv in DEFAULT if p.startswith("field:") or os.path.exists(p)]
    volumes += [(n, os.path.join(args.shared, p), lv) for n, p, lv in SHARED
                if os.path.exists(os.path.join(args.shared, p))]
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        for name, path, level in volumes:
            rows.append((name, level, measure(path, level, tmp)))
    print("| volume | dims | type | voxels | volume bytes | hierarchy bytes | bytes/voxel | "
          "share of volume | build ms |")
    print("|---|---|---|---:|---:|---:|---:|---:|---:|")
    for name, _, r in rows:
        print(f"| {name} | {r['dims']} | {r['type']} | {r['voxels']:,} | {r['volume_bytes']:,} | "
              f"{r['tree_bytes']:,} | {r['tree_bytes'] / r['voxels']:.4f} | "
              f"{100.0 * r['tree_bytes'] / r['volume_bytes']:.1f}% | {r['build_ms']:.0f} |")
    print()
    print("| volume | level | " + " | ".join(f"t={t}: triangles, Draco bytes, ms" for t in TOLERANCES) + " |")
    print("|---|---:|" + "---|" * len(TOLERANCES))
    for name, level, r in rows:
        cells = [f"{tri:,}, {size:,}, {ms:.0f}" for _, tri, size, ms in r["meshes"]]
        print(f"| {name} | {level} | " + " | ".join(cells) + " |")


if __name__ == "__main__":
    main()
