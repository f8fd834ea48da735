"""Latency of distance= requests through the server (2 threads), beside the uncached exact
request at the same level in the same run, all in the viewer's format (glb-meshopt, tricubic
normals).

One catalog of the shared scans present (CThead skin, the bunny, ch2better), each with its
level as the one suggested level; a fresh cache dir. Server time is the access log's, per
request. Three daemons in turn over that cache dir:
  first    (--chain-background off) the exact mesh (uncached), then the first
           distance=0.5 voxel at that level: it builds the chain down to that level while
           the user waits (targets: CThead skin 1.0 s, the bunny 4 s); the background
           completes and writes it (waited for: completed_after_s);
  restart  (background on; the chains are on disk) the first distance=0.5 voxel, mapped
           from its file, then the same request again from the mesh cache (target: within
           50 ms of it); then distance=1 voxel (a level of the ready chain, a new URL)
           beside the exact mesh (uncached since the restart): target distance <= exact;
  full     (--cache-mb 48) the mesh cache filled with other meshes of the bunny (exact at
           other tolerances) until it evicts, then distance=1.5 voxel on the bunny and
           ch2better (new URLs; target <= 100 ms).
Prints a table, writes bench/results/chain_latency.json. Needs ../shared/volumes (prints
SKIP for the cases whose scan is absent)."""

import http.client
import json
import os
import re
import shutil
import subprocess
import sys
import tempfile
import threading
import time

from provenance import provenance  # tests/bench/provenance.py, beside this file  # noqa: E402

BIN = os.path.abspath(os.environ.get("ISOSERVE_BIN", "build/isoserve"))
SHARED = os.environ.get("ISO_SHARED_VOLUMES", "../shared/volumes")
CASES = [  # id, file, level, smallest spacing (mm), first distance= target (ms) or None
    ("skin", "CThead_256x256x113_u16be.nhdr", 700.5, 1.0, 1000),
    ("bunny", "bunny_512x512x361_i16le.nhdr", 1700, 0.338, 4000),
    ("ch2better", "ch2better_301x370x316_u8.nhdr", 30, 0.5, None),
]
LOG_LINE = re.compile(r" GET (\S+) (\d+) (\d+) ([\d.]+)ms$")


class Daemon:
    """A daemon whose access log is read on a thread: ms() is the server time of the
    request just answered."""

    def __init__(self, catalog, cache, *extra):
        self.proc = subprocess.Popen([BIN, "serve", "--catalog", catalog, "--listen", "127.0.0.1:0",
                                      "--threads", "2", "--cache-dir", cache, *extra],
                                     stderr=subprocess.PIPE, text=True)
        self.lines, self.port, self.cond = [], None, threading.Condition()
        threading.Thread(target=self.read, daemon=True).start()
        with self.cond:
            self.cond.wait_for(lambda: self.port is not None or self.proc.poll() is not None, timeout=600)
        if self.port is None:
            raise SystemExit("bench_chain_latency: the daemon did not start")
        while True:
            try:
                if self.get("/healthz", log=False)[0].status == 200:
                    break
            except OSError:
                pass
            time.sleep(0.2)

    def read(self):
        for line in self.proc.stderr:
            with self.cond:
                m = re.search(r"listening on http://127\.0\.0\.1:(\d+)/", line)
                if m:
                    self.port = int(m.group(1))
                self.lines.append(line.rstrip("\n"))
                self.cond.notify_all()

    def get(self, target, log=True):
        """(response, body, server ms)."""
        with self.cond:
            seen = len(self.lines)
        c = http.client.HTTPConnection("127.0.0.1", self.port, timeout=600)
        c.request("GET", target)
        r = c.getresponse()
        body = r.read()
        c.close()
        if not log:
            return r, body, None
        if r.status != 200:
            raise SystemExit(f"bench_chain_latency: {target}: {r.status} {body[:300]!r}")
        path = target.split("?")[0]
        with self.cond:
            self.cond.wait_for(lambda: any(LOG_LINE.search(x) and f" GET {path} " in x for x in self.lines[seen:]),
                               timeout=30)
            ms = [float(LOG_LINE.search(x).group(4)) for x in self.lines[seen:]
                  if LOG_LINE.search(x) and f" GET {path} " in x]
        return r, body, ms[-1] if ms else None

    def json(self, target):
        return json.loads(self.get(target, log=False)[1])

    def wait_background(self):
        deadline = time.time() + 1800
        while time.time() < deadline:
            if self.json("/v1/status")["background"]["state"] in ("done", "off"):
                return
            time.sleep(0.5)

    def stop(self):
        self.proc.terminate()
        self.proc.wait(timeout=1800)


def mesh(vid, level, extra):
    return f"/v1/volumes/{vid}/mesh?level={level}&{extra}"


def chain_facts(r):
    h = r.getheader
    return {"source": h("X-Iso-Chain-Source"), "level": h("X-Iso-Chain-Level"), "triangles": int(h("X-Iso-Triangles")),
            "load_ms": float(h("X-Iso-Chain-Load-Ms") or 0), "cut_ms": float(h("X-Iso-Chain-Cut-Ms") or 0),
            "build_ms": float(h("X-Iso-Chain-Build-Ms") or 0)}


def first_phase(d, cases):
    rows = []
    for vid, _, level, spacing, target in cases:
        ex, _, ex_ms = d.get(mesh(vid, level, "format=glb-meshopt"))
        r, _, ms = d.get(mesh(vid, level, f"distance={0.5 * spacing:.6g}&format=glb-meshopt"))
        answered = time.time()
        # The rest of the chain is made in the background: waited for, so that the next
        # case starts on an idle server and the restart finds the file.
        while d.json(f"/v1/volumes/{vid}/chain?level={level}")["state"] != "ready":
            time.sleep(0.1)
        rows.append({"case": vid, "what": "first distance=0.5 voxel", "ms": ms, "exact_ms": ex_ms,
                     "exact_triangles": int(ex.getheader("X-Iso-Triangles")), "target_ms": target,
                     "ok": None if target is None else ms <= target,
                     "completed_after_s": round(time.time() - answered, 2), **chain_facts(r)})
    return rows


def restart_phase(d, cases):
    rows = []
    for vid, _, level, spacing, _ in cases:
        url = mesh(vid, level, f"distance={0.5 * spacing:.6g}&format=glb-meshopt")
        r, _, ms = d.get(url)
        _, _, cached_ms = d.get(url)
        rows.append({"case": vid, "what": "after a restart, first distance=0.5 voxel", "ms": ms,
                     "cached_ms": cached_ms, "target": "<= cached + 50 ms", "ok": ms <= cached_ms + 50,
                     **chain_facts(r)})
        r, _, ms = d.get(mesh(vid, level, f"distance={1.0 * spacing:.6g}&format=glb-meshopt"))
        ex, _, ex_ms = d.get(mesh(vid, level, "format=glb-meshopt"))
        rows.append({"case": vid, "what": "distance=1 voxel, chain ready", "ms": ms, "exact_ms": ex_ms,
                     "exact_triangles": int(ex.getheader("X-Iso-Triangles")), "target": "<= exact",
                     "ok": ms <= ex_ms, **chain_facts(r)})
    return rows


def full_cache_phase(d, cases):
    rows = []
    fill = next((c for c in cases if c[0] == "bunny"), cases[0])
    evictions, filled = 0, 0
    for tol in (2, 5, 10, 20, 40, 80, 160, 320, 640, 1280):
        d.get(mesh(fill[0], fill[2], f"tolerance={tol}&format=glb-plain&normals=none"))
        filled += 1
        text = d.get("/metrics", log=False)[1].decode()
        m = re.search(r"^isoserve_mesh_cache_evictions_total (\S+)$", text, re.M)
        evictions = float(m.group(1)) if m else 0
        if evictions > 0:
            break
    for vid, _, level, spacing, _ in cases:
        if vid not in ("bunny", "ch2better"):
            continue
        r, _, ms = d.get(mesh(vid, level, f"distance={1.5 * spacing:.6g}&format=glb-meshopt"))
        rows.append({"case": vid, "what": "later distance=1.5 voxel, mesh cache full", "ms": ms,
                     "cache_fill_requests": filled, "cache_evictions": evictions, "target": "<= 100 ms",
                     "ok": ms <= 100, **chain_facts(r)})
    return rows


def fmt(x, spec):
    return "-" if x is None else format(x, spec)


def main():
    cases = [c for c in CASES if os.path.exists(os.path.join(SHARED, c[1]))]
    for c in CASES:
        if c not in cases:
            print(f"SKIP {c[0]}: {os.path.join(SHARED, c[1])} absent")
    if not cases:
        return 0
    tmp = tempfile.mkdtemp(prefix="iso-bench-chains-")
    catalog, cache = os.path.join(tmp, "catalog.json"), os.path.join(tmp, "cache")
    os.makedirs(cache)
    with open(catalog, "w") as f:
        json.dump({"volumes": [{"id": v, "path": os.path.abspath(os.path.join(SHARED, p)), "levels": [lv]}
                               for v, p, lv, _, _ in cases]}, f)
    rows = []
    try:
        d = Daemon(catalog, cache, "--chain-background", "off")
        try:
            rows += first_phase(d, cases)
        finally:
            d.stop()
        d = Daemon(catalog, cache, "--cache-mb", "48")
        try:
            d.wait_background()
            rows += restart_phase(d, cases)
            rows += full_cache_phase(d, cases)
        finally:
            d.stop()
    finally:
        shutil.rmtree(tmp, ignore_errors=True)
    print(f"{'case':<10} {'request':<44} {'server ms':>9} {'beside':>14} {'chain':>8} {'load':>6} {'cut':>6} "
          f"{'build':>7} {'triangles':>9}  target")
    for x in rows:
        beside = (f"exact {x['exact_ms']:.0f}" if "exact_ms" in x else
                  f"cached {x['cached_ms']:.1f}" if "cached_ms" in x else f"evict {x.get('cache_evictions', 0):.0f}")
        target = x.get("target") or (f"<= {x['target_ms']} ms" if x.get("target_ms") else "")
        ok = "" if x["ok"] is None else ("ok" if x["ok"] else "MISSED")
        print(f"{x['case']:<10} {x['what']:<44} {fmt(x['ms'], '9.1f')} {beside:>14} {x['source'] or '-':>8} "
              f"{x['load_ms']:6.1f} {x['cut_ms']:6.1f} {x['build_ms']:7.0f} {x['triangles']:>9}  {target} {ok}")
    os.makedirs("bench/results", exist_ok=True)
    with open("bench/results/chain_latency.json", "w") as f:
        json.dump({**provenance(), "threads": 2, "rows": rows}, f, indent=1)
    print("wrote bench/results/chain_latency.json")
    return 0


if __name__ == "__main__":
    sys.exit(main())
