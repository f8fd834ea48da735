"""HTTP benchmark: latency percentiles and throughput with wrk against cached and uncached
mesh requests through a running isoserve, and Draco bytes against the raw float32 positions
(and normals) plus uint32 indices of the same meshes. Prints a table and writes
bench/results/http.json.

Volumes: the shared CT head when ../shared/volumes is there, else the analytic phantoms of
the default collection (so a user's clone can run it too)."""

import http.client
import json
import os
import re
import signal
import subprocess
import sys
import tempfile
import time

BIN = os.path.abspath(os.environ.get("ISOSERVE_BIN", "build/isoserve"))
SHARED = os.environ.get("ISO_SHARED_VOLUMES", "../shared/volumes")
DURATION = os.environ.get("ISO_BENCH_SECONDS", "8")


def start(catalog):
    proc = subprocess.Popen([BIN, "serve", "--catalog", catalog, "--listen", "127.0.0.1:0",
                             "--cache-mb", "512"], stderr=subprocess.PIPE, text=True)
    port = None
    for line in proc.stderr:
        m = re.search(r"listening on http://127\.0\.0\.1:(\d+)/", line)
        if m:
            port = int(m.group(1))
            break
    # Keep reading stderr (the access log) so the daemon never blocks on a full pipe.
    subprocess.Popen(["cat"], stdin=proc.stderr, stdout=subprocess.DEVNULL)
    while True:
        c = http.client.HTTPConnection("127.0.0.1", port)
        c.request("GET", "/healthz")
        if c.getresponse().status == 200:
            return proc, port
        time.sleep(0.1)


def get(port, target):
    c = http.client.HTTPConnection("127.0.0.1", port, timeout=300)
    c.request("GET", target)
    r = c.getresponse()
    body = r.read()
    return r, body


def wrk(port, target, lua, connections):
    """Runs wrk; returns requests/s and latency percentiles in ms."""
    args = ["wrk", "-t", "2", "-c", str(connections), "-d", f"{DURATION}s", "--latency",
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


def main():
    tmp = tempfile.mkdtemp(prefix="isoserve-bench-")
    ct = os.path.abspath(os.path.join(SHARED, "CThead_256x256x113_u16be.nhdr"))
    if os.path.exists(ct):
        cases = [("cthead", ct, 700.5, "CThead skin"), ("cthead", ct, 1500.5, "CThead bone")]
    else:
        cases = [("ml", "field:ml:192", 0.5, "Marschner-Lobb 192^3")]
    catalog = os.path.join(tmp, "catalog.json")
    json.dump({"volumes": [{"id": i, "path": p} for i, p in {(c[0], c[1]) for c in cases}]},
              open(catalog, "w"))
    lua = os.path.join(tmp, "uncached.lua")
    results = []
    proc, port = start(catalog)
    try:
        for vid, _, level, label in cases:
            for tol in (0, 100):
                target = f"/v1/volumes/{vid}/mesh?level={level}&tolerance={tol}"
                r, body = get(port, target)
                if r.status != 200:
                    raise SystemExit(f"bench_http: {target}: {r.status} {body[:300]!r}")
                tri, ver = int(r.getheader("X-Iso-Triangles")), int(r.getheader("X-Iso-Vertices"))
                raw = ver * 12 * 2 + tri * 12  # float32 positions and normals, uint32 indices
                cached = wrk(port, target, None, 16)
                # Uncached: every request a new level, so every one extracts and encodes.
                with open(lua, "w") as f:
                    f.write("local n = 0\nrequest = function()\n  n = n + 1\n"
                            f"  return wrk.format('GET', '/v1/volumes/{vid}/mesh?level=' .. "
                            f"string.format('%.6f', {level} + n * 1e-4 + math.random()) .. "
                            f"'&tolerance={tol}')\nend\n")
                uncached = wrk(port, target, lua, 4)
                results.append({"case": label, "level": level, "tolerance": tol,
                                "triangles": tri, "vertices": ver, "draco_bytes": len(body),
                                "raw_bytes": raw, "draco_share": len(body) / raw,
                                "extract_ms": float(r.getheader("X-Iso-Extract-Ms")),
                                "encode_ms": float(r.getheader("X-Iso-Encode-Ms")),
                                "cached": cached, "uncached": uncached,
                                "cached_over_uncached_throughput":
                                    cached["requests_per_s"] / max(uncached["requests_per_s"], 1e-9)})
    finally:
        proc.send_signal(signal.SIGTERM)
        proc.wait(timeout=60)
    print(f"{'case':22} {'T':>4} {'triangles':>9} {'draco KB':>9} {'raw KB':>8} {'share':>6} "
          f"{'cached r/s':>10} {'p50':>6} {'p99':>6} {'uncached r/s':>12} {'p50':>7} {'p99':>7} {'ratio':>6}")
    for x in results:
        c, u = x["cached"], x["uncached"]
        print(f"{x['case']:22} {x['tolerance']:>4} {x['triangles']:>9} {x['draco_bytes'] / 1024:>9.0f} "
              f"{x['raw_bytes'] / 1024:>8.0f} {x['draco_share']:>6.1%} {c['requests_per_s']:>10.0f} "
              f"{c['p50_ms']:>6.2f} {c['p99_ms']:>6.2f} {u['requests_per_s']:>12.2f} {u['p50_ms']:>7.0f} "
              f"{u['p99_ms']:>7.0f} {x['cached_over_uncached_throughput']:>6.0f}")
    os.makedirs("bench/results", exist_ok=True)
    out = "bench/results/http.json"
    json.dump({"date": time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime()),
               "wrk_seconds": int(DURATION), "results": results}, open(out, "w"), indent=1)
    print(f"written {out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
