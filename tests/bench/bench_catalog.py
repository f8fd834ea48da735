"""The catalog at archive scale, for docs/scaling.md: a replica of a 64-way sharded
deployment whose catalog names 100,000 studies (tiny analytic fields, so that preloading
its share costs seconds), measured over HTTP on loopback:

- the time from start to ready (reading the catalog, preloading shard 0);
- a lookup that misses (GET /v1/volumes/{unknown id}: 404) and one that hits a preloaded
  volume (GET /v1/volumes/{id}), median of many;
- the whole catalog (GET /v1/volumes) against one page of 100 (?limit=100&after=ID), bytes
  and median time.

    /usr/bin/python3 tests/bench/bench_catalog.py [--bin build/isoserve] [--before OLD_BIN]
        [--entries 100000]

With --before, the same requests against another build in the same run (old builds
ignore limit and after, so their "page" is the whole catalog): the table then gives
both and their ratio. Prints a Markdown table; writes bench/results/catalog.json."""

import argparse
import http.client
import json
import os
import statistics
import subprocess
import sys
import tempfile
import time

from provenance import provenance  # tests/bench/provenance.py, beside this file  # noqa: E402

ROOT = os.path.abspath(os.path.join(os.path.dirname(__file__), "..", ".."))
sys.path.insert(0, os.path.join(ROOT, "tests", "support"))
from ports import free_port  # noqa: E402 - found through the path just set

SHARDS = 64


def get(port, path):
    c = http.client.HTTPConnection("127.0.0.1", port, timeout=120)
    start = time.perf_counter()
    c.request("GET", path)
    r = c.getresponse()
    body = r.read()
    ms = (time.perf_counter() - start) * 1000
    c.close()
    return r.status, len(body), ms, r


def median_ms(port, path, n, status):
    times = []
    for _ in range(n):
        got, _, ms, _ = get(port, path)
        if got != status:
            sys.exit(f"GET {path}: {got}, expected {status}")
        times.append(ms)
    return statistics.median(times)


def serve(binary, catalog, tmp, label):
    port = free_port()
    peers = [f"127.0.0.1:{port}"] + [f"127.0.0.1:{free_port()}" for _ in range(SHARDS - 1)]
    log = open(os.path.join(tmp, f"{label}.log"), "w")
    p = subprocess.Popen([binary, "serve", "--catalog", catalog, "--listen", f"127.0.0.1:{port}",
                          "--shard", f"0/{SHARDS}", "--shard-peers", ",".join(peers)],
                         stdout=log, stderr=subprocess.STDOUT)
    start = time.time()
    while time.time() < start + 600:
        try:
            if get(port, "/healthz")[0] == 200:
                return p, port, time.time() - start
        except OSError:
            pass
        time.sleep(0.2)
    p.kill()
    sys.exit(f"{label} did not become ready; see {log.name}")


def measure(binary, catalog, ids, tmp, label):
    print(f"{label}: reading the catalog, preloading shard 0 ...", file=sys.stderr)
    p, port, ready_s = serve(binary, catalog, tmp, label)
    try:
        loaded = None
        for i in ids:  # a volume of shard 0, preloaded there
            status, _, _, r = get(port, f"/v1/volumes/{i}")
            if status == 200 and r.getheader("X-Iso-Load") == "preloaded":
                loaded = i
                break
        out = {"ready_s": ready_s, "miss_ms": median_ms(port, "/v1/volumes/no-such-study", 200, 404),
               "hit_ms": median_ms(port, f"/v1/volumes/{loaded}", 200, 200)}
        _, out["all_bytes"], _, _ = get(port, "/v1/volumes")
        out["all_ms"] = median_ms(port, "/v1/volumes", 5, 200)
        page = f"/v1/volumes?limit=100&after={ids[len(ids) // 2]}"
        _, out["page_bytes"], _, _ = get(port, page)
        out["page_ms"] = median_ms(port, page, 50, 200)
        return out
    finally:
        p.terminate()
        p.wait(timeout=60)


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--bin", default=os.path.join(ROOT, "build/isoserve"))
    ap.add_argument("--before")
    ap.add_argument("--entries", type=int, default=100000)
    a = ap.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        ids = [f"study-{i:06d}" for i in range(a.entries)]
        catalog = os.path.join(tmp, "catalog.json")
        with open(catalog, "w") as f:
            json.dump({"volumes": [{"id": i, "path": "field:sphere:4", "levels": [0.5]} for i in ids]}, f)
        runs = [("this build", a.bin)] + ([("before", a.before)] if a.before else [])
        results = {label: measure(b, catalog, ids, tmp, label.replace(" ", "-")) for label, b in runs}
    rows = [("start to ready (catalog read, shard preloaded), s", "ready_s"), ("lookup that misses (404), median ms", "miss_ms"), ("lookup that hits, median ms", "hit_ms"),
            ("whole catalog, bytes", "all_bytes"), ("whole catalog, median ms", "all_ms"),
            ("a page of 100, bytes", "page_bytes"), ("a page of 100, median ms", "page_ms")]
    head = "| %d entries, shard 0/%d | " % (a.entries, SHARDS) + " | ".join(label for label, _ in runs)
    print(head + (" | before / this |" if a.before else " |"))
    print("|---" * (len(runs) + 1 + bool(a.before)) + "|")
    for text, key in rows:
        cells = [f"{results[label][key]:,.3f}" if key.endswith(("ms", "_s")) else f"{results[label][key]:,}"
                 for label, _ in runs]
        ratio = f" | {results['before'][key] / max(results['this build'][key], 1e-9):,.1f}x" if a.before else ""
        print(f"| {text} | " + " | ".join(cells) + ratio + " |")
    os.makedirs(os.path.join(ROOT, "bench/results"), exist_ok=True)
    with open(os.path.join(ROOT, "bench/results/catalog.json"), "w") as f:
        json.dump({**provenance(), "entries": a.entries, "shards": SHARDS, "results": results}, f, indent=1)
    mine = results["this build"]
    print(f"\nwhole catalog / one page: {mine['all_ms'] / mine['page_ms']:,.0f}x the time, "
          f"{mine['all_bytes'] / mine['page_bytes']:,.0f}x the bytes")


if __name__ == "__main__":
    main()
