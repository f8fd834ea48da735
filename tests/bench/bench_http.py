"""HTTP benchmark: mesh requests through a running isoserve, uncached and cached, per request
size. Prints tables and writes bench/results/http.json.

- Uncached, one request at a time (a new level each, so each extracts and encodes): client
  latency, and the server's own split from the X-Iso-* headers: extraction, normals, measure
  (edge census, area, volume), Draco encode; the Draco speed auto chose and the bytes.
- Uncached throughput: wrk, 2 connections, every request a new level.
- Cached: wrk -t2 -c16 (requests/s, p50, p99, and the bytes/s that makes), and 40 cached
  requests one at a time (client latency p50). /healthz under the same wrk is the server's
  per-request ceiling; a large cached body is bounded by bytes over loopback instead.
- Draco speed against bytes for CThead skin: encode time per speed (the server's header),
  bytes, and the browser decoder's time (npm draco3d in node, when installed).

Volumes: the shared CT heads and the aneurism when ../shared/volumes is there, else an
analytic field (so a user's clone can run it too). ISO_BENCH_BASELINE_BIN names a second
binary (an older build) measured the same way in the same run, for side-by-side ratios.
ISO_BENCH_SECONDS sets each wrk run's length (default 6); ISO_BENCH_SPLIT_REPEAT the requests
per cell of the split below (default 9; more on a loaded machine, whose medians move).

First, the server's side of an uncached CThead skin request per codec (Draco; meshopt with
and without gzip accepted), the binaries up at once and asked in turn: extraction,
normals (and their ratio to the extraction), encoding, gzip, their total and its ratio to the
extraction (medians of the per-request ratios). Where the server overlaps steps (meshopt:
the index view beside the normals, gzip beside the encode), each header counts from the end
of the step before, so the total is still the request's time. ISO_BENCH_ONLY=split
runs that alone (bench/results/http_split.json)."""

import http.client
import json
import os
import re
import shutil
import signal
import statistics
import subprocess
import sys
import tempfile
import time

from provenance import provenance  # tests/bench/provenance.py, beside this file  # noqa: E402

BIN = os.path.abspath(os.environ.get("ISOSERVE_BIN", "build/isoserve"))
BASELINE = os.environ.get("ISO_BENCH_BASELINE_BIN")
SHARED = os.environ.get("ISO_SHARED_VOLUMES", "../shared/volumes")
DURATION = os.environ.get("ISO_BENCH_SECONDS", "6")
UNCACHED_REPEAT = 7
SPEEDS = (0, 3, 5, 6, 8, 10)


def volumes_and_cases():
    """The catalog's volumes {id: path} and the cases (label, id, level, tolerances)."""
    ct = os.path.abspath(os.path.join(SHARED, "CThead_256x256x113_u16be.nhdr"))
    if not os.path.exists(ct):
        return {"ml": "field:ml:192"}, [("Marschner-Lobb 192^3", "ml", 0.5, (0,))]
    vols = {"cthead": ct}
    cases = []
    small = os.path.abspath(os.path.join(SHARED, "headsq_quarter_64x64x93_u16le.nhdr"))
    if os.path.exists(small):
        vols["headsq"] = small
        cases.append(("headsq skin (small)", "headsq", 500.5, (0,)))
    sparse = os.path.abspath(os.path.join(SHARED, "aneurism_256x256x256_u8.nhdr"))
    if os.path.exists(sparse):
        vols["aneurism"] = sparse
        cases.append(("aneurism (medium)", "aneurism", 120.5, (0,)))
    # 654 (20% of CThead's value range) is the largest tolerance of bench_peer's ladder within
    # 0.5 voxel at the 99th percentile of surface distance, for skin (p99 0.44) and bone
    # (0.31); 163.6 (5%) was the old ladder's top (docs/performance.md).
    cases += [("CThead skin (large)", "cthead", 700.5, (0, 163.6, 654)),
              ("CThead bone (large)", "cthead", 1500.5, (0, 163.6, 654))]
    return vols, cases


def start(binary, catalog):
    proc = subprocess.Popen([binary, "serve", "--catalog", catalog, "--listen", "127.0.0.1:0",
                             "--cache-mb", "1024"], stderr=subprocess.PIPE, text=True)
    port = None
    for line in proc.stderr:
        m = re.search(r"listening on http://127\.0\.0\.1:(\d+)/", line)
        if m:
            port = int(m.group(1))
            break
    if port is None:
        raise SystemExit(f"bench_http: {binary} did not start")
    # Keep reading stderr (the access log) so the daemon never blocks on a full pipe.
    subprocess.Popen(["cat"], stdin=proc.stderr, stdout=subprocess.DEVNULL)
    while True:
        try:
            c = http.client.HTTPConnection("127.0.0.1", port)
            c.request("GET", "/healthz")
            if c.getresponse().status == 200:
                return proc, port
        except OSError:
            pass
        time.sleep(0.1)


def get(conn, target):
    """(response, body, client ms) on a kept-alive connection."""
    t0 = time.perf_counter()
    conn.request("GET", target)
    r = conn.getresponse()
    body = r.read()
    ms = (time.perf_counter() - t0) * 1000
    if r.status != 200:
        raise SystemExit(f"bench_http: {target}: {r.status} {body[:300]!r}")
    return r, body, ms


def header(r, name):
    v = r.getheader(name)
    return None if v is None else float(v)


def median(xs):
    xs = [x for x in xs if x is not None]
    return statistics.median(xs) if xs else None


def wrk(port, target, lua, connections, threads=2):
    """Runs wrk; returns requests/s and latency percentiles in ms."""
    args = ["wrk", "-t", str(threads), "-c", str(connections), "-d", f"{DURATION}s", "--latency",
            f"http://127.0.0.1:{port}{target}"]
    if lua:
        args[1:1] = ["-s", lua]
    out = subprocess.run(args, capture_output=True, text=True, check=True).stdout
    rps = float(re.search(r"Requests/sec:\s+([\d.]+)", out).group(1))

    def ms(tag):
        m = re.search(rf"^\s+{tag}%\s+([\d.]+)(us|ms|s)\s*$", out, re.M)
        value, unit = float(m.group(1)), m.group(2)
        return value / 1000 if unit == "us" else value * 1000 if unit == "s" else value
    non2xx = re.search(r"Non-2xx or 3xx responses: (\d+)", out)
    return {"requests_per_s": rps, "p50_ms": ms("50"), "p90_ms": ms("90"), "p99_ms": ms("99"),
            "non_2xx": int(non2xx.group(1)) if non2xx else 0}


def uncached_one_at_a_time(conn, vid, level, tol, extra=""):
    """UNCACHED_REPEAT requests, each at a level not asked before (same surface within
    1e-3): medians of the client latency and of the server's steps; and the last body."""
    rows, body = [], b""
    for k in range(UNCACHED_REPEAT):
        lvl = level + (k + 1) * 1e-4 + time.time() % 1 * 1e-7
        r, body, ms = get(conn, f"/v1/volumes/{vid}/mesh?level={lvl:.9f}&tolerance={tol}{extra}")
        if r.getheader("X-Iso-Cache") != "miss":
            raise SystemExit(f"bench_http: {vid} {lvl}: expected a cache miss")
        rows.append({"client_ms": ms, "bytes": len(body),
                     "extract_ms": header(r, "X-Iso-Extract-Ms"),
                     "normals_ms": header(r, "X-Iso-Normals-Ms"),
                     "measure_ms": header(r, "X-Iso-Measure-Ms"),
                     "encode_ms": header(r, "X-Iso-Encode-Ms"),
                     "speed": header(r, "X-Iso-Draco-Speed"),
                     "triangles": int(r.getheader("X-Iso-Triangles")),
                     "vertices": int(r.getheader("X-Iso-Vertices"))})
    out = {k: median([row[k] for row in rows]) for k in rows[0]}
    out["client_p90_ms"] = sorted(row["client_ms"] for row in rows)[int(0.9 * (len(rows) - 1))]
    return out, body


def cached(conn, port, vid, level, tol):
    target = f"/v1/volumes/{vid}/mesh?level={level}&tolerance={tol}"
    r, body, _ = get(conn, target)
    one = [get(conn, target)[2] for _ in range(40)]
    w = wrk(port, target, None, 16)
    w["one_at_a_time_p50_ms"] = median(one)
    w["bytes"] = len(body)
    w["bytes_per_s"] = w["requests_per_s"] * len(body)
    return w


def uncached_throughput(port, tmp, vid, level, tol):
    lua = os.path.join(tmp, "uncached.lua")
    with open(lua, "w") as f:
        f.write("local n = 0\nrequest = function()\n  n = n + 1\n"
                f"  return wrk.format('GET', '/v1/volumes/{vid}/mesh?level=' .. "
                f"string.format('%.9f', {level} + n * 1e-5 + math.random() * 1e-6) .. "
                f"'&tolerance={tol}')\nend\n")
    return wrk(port, f"/v1/volumes/{vid}/mesh?level={level}", lua, 2)


def node_decode_ms(tmp, body):
    """The browser's decoder (draco3d's wasm in node) on body: best of 3 ms, or None."""
    module = os.path.abspath("web/node_modules/draco3d")
    if not os.path.isdir(module) or not shutil.which("node"):
        return None
    path = os.path.join(tmp, "speed.drc")
    open(path, "wb").write(body)
    script = r"""
const draco3d = require(process.argv[1]);
const bytes = new Int8Array(require('fs').readFileSync(process.argv[2]));
draco3d.createDecoderModule({}).then((m) => {
  let best = 1e9;
  for (let r = 0; r < 3; r++) {
    const t0 = performance.now();
    const dec = new m.Decoder(), mesh = new m.Mesh();
    if (!dec.DecodeArrayToMesh(bytes, bytes.length, mesh).ok()) process.exit(1);
    const n = mesh.num_points() * 3, p = m._malloc(n * 4);
    for (const t of [m.POSITION, m.NORMAL]) {
      const id = dec.GetAttributeId(mesh, t);
      if (id >= 0) dec.GetAttributeDataArrayForAllPoints(mesh, dec.GetAttribute(mesh, id), m.DT_FLOAT32, n * 4, p);
    }
    m._free(p);
    const q = m._malloc(mesh.num_faces() * 12);
    dec.GetTrianglesUInt32Array(mesh, mesh.num_faces() * 12, q);
    m._free(q);
    m.destroy(mesh); m.destroy(dec);
    best = Math.min(best, performance.now() - t0);
  }
  console.log(best.toFixed(2));
});"""
    out = subprocess.run(["node", "-e", script, module, path], capture_output=True, text=True, timeout=120)
    return float(out.stdout) if out.returncode == 0 else None


def speeds(conn, tmp, vid, level):
    """Bytes and times per Draco speed (the server's own encode time, median)."""
    rows = []
    for sp in SPEEDS:
        u, body = uncached_one_at_a_time(conn, vid, level + 0.01 * (sp + 1), 0, f"&speed={sp}")
        rows.append({"speed": sp, "bytes": u["bytes"], "encode_ms": u["encode_ms"],
                     "client_ms": u["client_ms"], "triangles": u["triangles"],
                     "browser_decode_ms": node_decode_ms(tmp, body)})
    return rows


SPLIT_KINDS = (("draco", "", None), ("glb-meshopt, gzip accepted", "&format=glb-meshopt", "gzip"),
               ("glb-meshopt, identity", "&format=glb-meshopt", None))
SPLIT_REPEAT = int(os.environ.get("ISO_BENCH_SPLIT_REPEAT", "9"))


def split_one(port, vid, level, extra, encoding):
    """One uncached request's server steps from its X-Iso-* headers; total is their sum
    (extraction, normals, encoding and gzip when made), ratio that over the extraction."""
    conn = http.client.HTTPConnection("127.0.0.1", port, timeout=600)
    headers = {"Accept-Encoding": encoding} if encoding else {}
    conn.request("GET", f"/v1/volumes/{vid}/mesh?level={level:.9f}&tolerance=0{extra}", headers=headers)
    r = conn.getresponse()
    body = r.read()
    conn.close()
    if r.status != 200 or r.getheader("X-Iso-Cache") != "miss":
        raise SystemExit(f"bench_http: split {vid} {level}: {r.status} {r.getheader('X-Iso-Cache')}")
    row = {k: header(r, f"X-Iso-{h}-Ms") or 0.0 for k, h in
           (("extract_ms", "Extract"), ("normals_ms", "Normals"), ("encode_ms", "Encode"), ("gzip_ms", "Gzip"))}
    row["total_ms"] = sum(row.values())
    row["ratio"] = row["total_ms"] / row["extract_ms"]
    row["normals_ratio"] = row["normals_ms"] / row["extract_ms"]
    row["bytes"] = len(body)
    return row


def split(binaries, catalog, vid, level):
    """The server's side of an uncached request per codec (SPLIT_KINDS), every binary up at
    once and asked in turn, the kinds and binaries alternating: medians per cell."""
    servers = [start(b, catalog) for b in binaries]
    cells = {(b, kind[0]): [] for b in binaries for kind in SPLIT_KINDS}
    try:
        n = 0
        for k in range(SPLIT_REPEAT):
            kinds = SPLIT_KINDS if k % 2 == 0 else SPLIT_KINDS[::-1]
            for kind in kinds:
                order = list(zip(binaries, servers))
                for b, (_, port) in (order if k % 2 == 0 else order[::-1]):
                    n += 1
                    lvl = level + n * 1e-4 + time.time() % 1 * 1e-7
                    cells[(b, kind[0])].append(split_one(port, vid, lvl, kind[1], kind[2]))
    finally:
        for proc, _ in servers:
            proc.send_signal(signal.SIGTERM)
            proc.wait(timeout=60)
    out = []
    for (b, kind), rows in cells.items():
        out.append({"binary": b, "kind": kind, **{k: median([r[k] for r in rows]) for k in rows[0]}})
    return out


def print_split(rows):
    print(f"\nuncached CThead skin, tolerance 0, server steps (X-Iso-* headers), median of {SPLIT_REPEAT}, load {os.getloadavg()[0]:.1f}")
    print("| binary | request | extract | normals | normals / extract | encode | gzip | total | total / extract | MB |")
    print("|---|---|---:|---:|---:|---:|---:|---:|---:|---:|")
    for r in rows:
        print(f"| {os.path.relpath(r['binary'])} | {r['kind']} | {r['extract_ms']:.1f} | {r['normals_ms']:.1f} | "
              f"{r['normals_ratio']:.2f} | "
              f"{r['encode_ms']:.1f} | {r['gzip_ms']:.1f} | {r['total_ms']:.1f} | {r['ratio']:.1f} | {r['bytes'] / 1e6:.2f} |")


def run(binary, tmp, catalog, cases, with_speeds):
    proc, port = start(binary, catalog)
    results, speed_rows = [], []
    try:
        conn = http.client.HTTPConnection("127.0.0.1", port, timeout=600)
        ceiling = wrk(port, "/healthz", None, 16)
        for label, vid, level, tolerances in cases:
            for tol in tolerances:
                print(f"  {os.path.basename(binary)}: {label}, tolerance {tol}", file=sys.stderr)
                results.append({"case": label, "volume": vid, "level": level, "tolerance": tol,
                                "uncached": uncached_one_at_a_time(conn, vid, level, tol)[0],
                                "uncached_wrk": uncached_throughput(port, tmp, vid, level, tol),
                                "cached": cached(conn, port, vid, level, tol)})
        if with_speeds:  # on CThead skin, or the field
            skin = [c for c in cases if c[0].startswith("CThead skin")] or cases
            speed_rows = speeds(conn, tmp, skin[0][1], skin[0][2])
    finally:
        proc.send_signal(signal.SIGTERM)
        proc.wait(timeout=60)
    return {"binary": binary, "healthz": ceiling, "results": results, "speeds": speed_rows}


def fmt(x, spec):
    return "-" if x is None else format(x, spec)


def print_run(run_result):
    print(f"\n{run_result['binary']}: /healthz ceiling {run_result['healthz']['requests_per_s']:.0f} requests/s")
    print(f"{'case':22} {'T':>6} {'triangles':>9} {'KB':>6} {'sp':>3} | {'uncached':>8} {'p90':>6} "
          f"{'extract':>7} {'normals':>7} {'measure':>7} {'encode':>7} {'r/s':>5} | {'cached r/s':>10} "
          f"{'p50':>5} {'p99':>6} {'GB/s':>5} {'1-by-1':>6}")
    for x in run_result["results"]:
        u, w, c = x["uncached"], x["uncached_wrk"], x["cached"]
        print(f"{x['case']:22} {x['tolerance']:>6} {u['triangles']:>9} {c['bytes'] / 1024:>6.0f} "
              f"{fmt(u['speed'], '>3.0f')} | {u['client_ms']:>8.1f} {u['client_p90_ms']:>6.1f} "
              f"{fmt(u['extract_ms'], '>7.1f')} {fmt(u['normals_ms'], '>7.1f')} {fmt(u['measure_ms'], '>7.1f')} "
              f"{fmt(u['encode_ms'], '>7.1f')} {w['requests_per_s']:>5.1f} | {c['requests_per_s']:>10.0f} "
              f"{c['p50_ms']:>5.2f} {c['p99_ms']:>6.2f} {c['bytes_per_s'] / 1e9:>5.2f} "
              f"{c['one_at_a_time_p50_ms']:>6.2f}")
    if run_result["speeds"]:
        print(f"{'speed':>5} {'KB':>7} {'encode ms':>9} {'request ms':>10} {'browser decode ms':>17}")
        for s in run_result["speeds"]:
            print(f"{s['speed']:>5} {s['bytes'] / 1024:>7.0f} {fmt(s['encode_ms'], '>9.1f')} "
                  f"{s['client_ms']:>10.1f} {fmt(s['browser_decode_ms'], '>17.1f')}")


def main():
    tmp = tempfile.mkdtemp(prefix="isoserve-bench-")
    vols, cases = volumes_and_cases()
    catalog = os.path.join(tmp, "catalog.json")
    json.dump({"volumes": [{"id": i, "path": p} for i, p in vols.items()]}, open(catalog, "w"))
    skin = [c for c in cases if c[0].startswith("CThead skin")] or cases
    split_rows = split([BIN] + ([os.path.abspath(BASELINE)] if BASELINE else []), catalog, skin[0][1], skin[0][2])
    print_split(split_rows)
    if os.environ.get("ISO_BENCH_ONLY") == "split":
        os.makedirs("bench/results", exist_ok=True)
        json.dump({**provenance(), "split": split_rows}, open("bench/results/http_split.json", "w"), indent=1)
        return 0
    runs = [run(BIN, tmp, catalog, cases, True)]
    if BASELINE:
        runs.append(run(os.path.abspath(BASELINE), tmp, catalog, cases, False))
    for r in runs:
        print_run(r)
    if BASELINE:
        print("\nratios, this build over the baseline, same run (uncached: baseline ms / ms; cached: r/s over r/s)")
        for a, b in zip(runs[0]["results"], runs[1]["results"]):
            print(f"{a['case']:22} {a['tolerance']:>6}  uncached {b['uncached']['client_ms'] / a['uncached']['client_ms']:>5.2f}x"
                  f"  cached {a['cached']['requests_per_s'] / b['cached']['requests_per_s']:>5.2f}x"
                  f"  bytes {a['cached']['bytes'] / b['cached']['bytes']:>5.2f}x")
    os.makedirs("bench/results", exist_ok=True)
    out = "bench/results/http.json"
    json.dump({**provenance(), "wrk_seconds": int(DURATION), "split": split_rows, "runs": runs}, open(out, "w"), indent=1)
    shutil.rmtree(tmp, ignore_errors=True)
    print(f"written {out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
