"""The simplification chain (distance=) against one meshopt_simplify, side by side.

For each case, in one run on the same exact surface (world mm):
  single   `extract --simplify T/4 --threads 1`: one single-threaded meshopt_simplify of
           the exact mesh to 25% of its triangles, its time without the measure that
           follows it, and that measure (p99 both ways and max, mm);
  chain    `extract --distance 1e30`: the whole chain (levels of 70.7% .. 1.6%, 1/sqrt(2)
           apart, each simplified from the one before and measured against the exact
           surface; a smaller distance builds only down to the first level beyond it),
           its build time split into simplification and measurement, its 25% level's triangles and
           measured p99 (beside the single call's, at its count);
  answer   `extract --distance D` with D = half the smallest spacing: the level chosen,
           its share of the exact triangles and its measured distance;
  pinch    the chain's worst level: its pinches (edges of 3+ triangles and vertices of
           2+ fans) per 10,000 edges (the target is under 1).
Ratios are chain time / single time, measured in the same run. With ISO_BENCH_LEVELS=1,
each chain level is also compared with one meshopt_simplify of the exact mesh to that
level's triangle count (`extract --simplify N`, measured at one voxel's spacing where the
chain measures at three: the p99s, drawn by area, compare; the maxima less so): triangles,
p99 and max of both, and the single call's pinches (edges of 3+ triangles). Under each row, the
chain's levels: p99 and max (mm) and simplification ms. With ISOSERVE_BIN_BASE set, each
case runs with that build first, then with ISOSERVE_BIN, side by side, and a line gives
each level's p99 and max of the second over the first's, minus 1, in per cent. Prints a
table, writes bench/results/chain.json. Needs ../shared/volumes (prints SKIP otherwise)."""

import json
import os
import subprocess
import sys

from provenance import provenance  # tests/bench/provenance.py, beside this file  # noqa: E402

BIN = os.path.abspath(os.environ.get("ISOSERVE_BIN", "build/isoserve"))
BASE = os.environ.get("ISOSERVE_BIN_BASE")  # a second build to compare with, run first
SHARED = os.environ.get("ISO_SHARED_VOLUMES", "../shared/volumes")
CASES = [  # file, level, label, smallest spacing (mm)
    ("CThead_256x256x113_u16be.nhdr", 700.5, "CThead skin", 1.0),
    ("CThead_256x256x113_u16be.nhdr", 1500.5, "CThead bone", 1.0),
    ("cranium_256x256x108_i16le.nhdr", 250, "cranium bone", 0.957),
    ("ch2better_301x370x316_u8.nhdr", 30, "ch2better", 0.5),
    ("bunny_512x512x361_i16le.nhdr", 1700, "bunny 512x512x361", 0.338),
]


USE = {"bin": BIN}  # the build extract() runs (main sets it per pass)


def extract(path, level, *args):
    p = subprocess.run([USE["bin"], "extract", path, "--level", str(level), "--normals", "none", "--json", *args],
                       check=True, capture_output=True, text=True)
    return json.loads(p.stdout)


def print_levels(row, tag):
    """A build for a distance measures only its answer's maximum: the others print "-"."""
    levels = row["chain_levels"][1:]
    print(f"  {tag or 'levels':<6} p99 " + " ".join(f"{b['p99']:.4f}" for b in levels) +
          " | max " + " ".join("-" if b["max"] is None else f"{b['max']:.3f}" for b in levels) +
          " | simplify ms " + " ".join(f"{b['simplify_ms']:.0f}" for b in levels), flush=True)


def print_change(base, new):
    def change(key):
        return " ".join(f"{100 * (n[key] / b[key] - 1):+.1f}" if b[key] else "0"
                        for b, n in zip(base["chain_levels"][1:], new["chain_levels"][1:]))
    print(f"  new/base-1 % p99 {change('p99')} | max {change('max')}", flush=True)


def compare_levels(path, level, built):
    """Each chain level beside one meshopt_simplify to its triangle count (ISO_BENCH_LEVELS)."""
    rows = []
    for k, b in enumerate(built[1:], 1):
        single = extract(path, level, "--threads", "1", "--simplify", str(b["triangles"]))
        d = single["simplify"]["distance"]
        rows.append({"level": k, "chain_triangles": b["triangles"], "single_triangles": single["triangles"],
                     "chain_p99": b["p99"], "single_p99": d["p99"], "chain_max": b["max"], "single_max": d["max"],
                     "single_nonmanifold_edges": single["nonmanifold_edges"]})
        print(f"    level {k}: {b['triangles']:>7} tris p99 {b['p99']:.4f} max {'-' if b['max'] is None else format(b['max'], '.3f')} | single "
              f"{single['triangles']:>7} tris p99 {d['p99']:.4f} max {d['max']:.3f} pinch edges "
              f"{single['nonmanifold_edges']} | p99 chain/single {b['p99'] / d['p99'] if d['p99'] else float('nan'):.3f}",
              flush=True)
    return rows


def main():
    if not os.path.isdir(SHARED):
        print(f"SKIP bench_chain: {SHARED} is absent")
        return 0
    only = os.environ.get("ISO_BENCH_CASES")  # e.g. "CThead skin,ch2better"
    rows = []
    head = (f"{'case':<20} {'exact':>8} {'single ms':>9} {'p99 mm':>7} {'chain ms':>9} {'simpl.':>7} "
            f"{'meas.':>7} {'ratio':>6} {'s.ratio':>7} {'25% tris':>8} {'25% p99':>7} {'D mm':>5} {'level':>5} {'share':>6} "
            f"{'p99':>6} {'max':>6} {'vol %':>6} {'pinch':>6}")
    print(head)
    for name, level, label, spacing in CASES:
        if only and label not in only.split(","):
            continue
        pair = []
        for binary, tag in ([(os.path.abspath(BASE), "base"), (BIN, "new")] if BASE else [(BIN, "")]):
            USE["bin"] = binary
            path = os.path.join(SHARED, name)
            exact = extract(path, level, "--threads", "1")
            quarter = max(1, exact["triangles"] // 4)
            single = extract(path, level, "--threads", "1", "--simplify", str(quarter))
            s = single["simplify"]
            single_ms = s["ms"] - s["distance"]["ms"]
            chain = extract(path, level, "--distance", "1e30")["chain"]
            built = chain["built"]
            # the 25% level: 2 of a halving chain's (a base build's), 4 of one 1/sqrt(2) apart
            quarter_level = min(range(1, len(built)), key=lambda k: abs(built[k]["triangles"] - quarter))
            simplify_ms = sum(b["simplify_ms"] for b in built)
            measure_ms = sum(b["measure_ms"] for b in built)
            d = 0.5 * spacing
            answer = extract(path, level, "--distance", str(d), "--cap")
            k = answer["chain"]["level"]
            vol = None
            capped_exact = extract(path, level, "--cap")
            if answer["closed"] and capped_exact["closed"]:
                vol = 100 * (answer["enclosed_volume_mm3"] - capped_exact["enclosed_volume_mm3"]) / capped_exact["enclosed_volume_mm3"]
            row = {"case": label, "level": level, "exact_triangles": exact["triangles"],
                   "single_ms": single_ms, "single_p99_mm": s["distance"]["p99"], "single_max_mm": s["distance"]["max"],
                   "single_triangles": single["triangles"], "chain_ms": chain["build_ms"],
                   "chain_simplify_ms": simplify_ms, "chain_measure_ms": measure_ms,
                   "ratio": chain["build_ms"] / single_ms, "simplify_ratio": simplify_ms / single_ms,
                   "chain_levels": built, "quarter_p99_mm": built[quarter_level]["p99"], "quarter_triangles": built[quarter_level]["triangles"],
                   "distance_mm": d, "answer_level": k, "answer_triangles": answer["triangles"],
                   "answer_share": answer["triangles"] / answer["chain"]["exact_triangles"], "answer_p99_mm": answer["distance"]["p99"],
                   "answer_max_mm": answer["distance"]["max"], "answer_nonmanifold_edges": answer["nonmanifold_edges"],
                   "answer_edges_closed": answer["closed"], "answer_volume_change_percent": vol}
            row["pinches_per_10k_edges"] = max(1e4 * (b["nonmanifold_edges"] + b["pinch_vertices"]) / b["edges"]
                                               for b in built if b["edges"])
            row["folds_dropped"] = sum(b["folds_dropped"] for b in built)
            row["measure_share"] = measure_ms / chain["build_ms"]
            row["build"] = tag
            rows.append(row)
            pair.append(row)
            print(f"{(label + ' ' + tag).strip():<20} {exact['triangles']:>8} {single_ms:>9.0f} {s['distance']['p99']:>7.3f} "
                  f"{chain['build_ms']:>9.0f} {simplify_ms:>7.0f} {measure_ms:>7.0f} {row['ratio']:>6.2f} "
                  f"{row['simplify_ratio']:>7.2f} {built[quarter_level]['triangles']:>8} {built[quarter_level]['p99']:>7.3f} {d:>5.2f} {k:>5} "
                  f"{100 * row['answer_share']:>5.1f}% {answer['distance']['p99']:>6.3f} {answer['distance']['max']:>6.2f} "
                  f"{'' if vol is None else f'{vol:+.2f}':>6} {row['pinches_per_10k_edges']:>6.2f}", flush=True)
            print_levels(row, tag)
            if os.environ.get("ISO_BENCH_LEVELS") and binary == BIN:
                row["levels_vs_single"] = compare_levels(path, level, built)
        if len(pair) == 2:
            print_change(pair[0], pair[1])
    os.makedirs("bench/results", exist_ok=True)
    with open("bench/results/chain.json", "w") as f:
        json.dump({**provenance(), "rows": rows}, f, indent=1)
    return 0


if __name__ == "__main__":
    sys.exit(main())
