"""Bounded memory: `serve --max-resident-mb` with more volumes than fit.

50 volumes (analytic fields of 96^3 float32 samples, about 3.6 MB each with their
hierarchies, each with its own level), --cache-dir set and a cap that holds 5 of them.
Every volume is asked for a mesh round-robin twice, then at random from 8 threads at once.
A thread scrapes /metrics and the daemon's VmRSS (/proc/PID/status) all along. Checks:
- every answer is 200, and a volume's mesh (triangles, vertices, body bytes) is the same
  in every round as in the first, after it was evicted and loaded again;
- volumes were evicted (isoserve_volume_evictions_total > 0), and at every scrape the
  resident bytes were at most the cap plus the volumes requests held (one in the rounds
  one at a time, 8 in the concurrent one);
- each hierarchy was built once (the log has one "hierarchy built" line per id and
  isoserve_hierarchies_built_total is 50), and every later load read it back
  (isoserve_hierarchies_read_total = loads - 50);
- the daemon's RSS stayed under the resident bytes + mesh cache (--cache-mb, 0 here: every
  request extracts) + OVERHEAD_MB at every scrape, and in the one-at-a-time rounds under
  cap + one volume + OVERHEAD_MB, below what the 50 volumes' samples alone take. The
  overhead (docs/scaling.md) is the daemon's memory besides volumes: code, libraries,
  thread stacks, the working memory of the extractions running (2 workers here) and the
  bodies being sent. Under ASan, whose shadow and quarantine keep more, it is
  SAN_OVERHEAD_MB;
- the daemon exits 0 on SIGTERM (under ASan: no leak, no error).
Prints PASS/FAIL lines; exit status 1 on failure. The daemon is stopped by its PID."""

import hashlib
import json
import os
import random
import re
import signal
import subprocess
import sys
import tempfile
import threading
import time

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "support"))
from results import Results  # noqa: E402 - found through the path just set
from client import request  # noqa: E402
from ports import free_port  # noqa: E402

ROOT = os.path.abspath(os.path.join(os.path.dirname(__file__), "..", ".."))
BIN = os.path.abspath(os.environ.get("ISOSERVE_BIN", os.path.join(ROOT, "build/isoserve")))
SAN = bool(os.environ.get("ISO_SAN_SUFFIX"))
RESULTS = Results("resident" + os.environ.get("ISO_SAN_SUFFIX", ""))

VOLUMES = 50
SIDE = 96
SAMPLE_BYTES = SIDE ** 3 * 4         # float32
CAP_MB = 19                          # 5 volumes of 3.5 to 3.98 MB fit, 6 do not
HOLDS = 5
THREADS = 8
OVERHEAD_MB = 128
SAN_OVERHEAD_MB = 256
# (field, first level, step): the k-th volume of a field gets first + k * step.
FIELDS = (("sphere", -4.0, 0.9), ("torus", -4.0, 0.4), ("ml", 0.3, 0.04),
          ("spike", 0.3, 0.04), ("ijk", 3000.0, 20000.0))


def metrics(port):
    text = request(port, "/metrics").body.decode()
    return {m.group(1): float(m.group(2))
            for m in re.finditer(r"^(isoserve_[a-z_]+) ([0-9.e+-]+)$", text, re.M)}


def catalog(path):
    entries = []
    for i in range(VOLUMES):
        name, first, step = FIELDS[i % len(FIELDS)]
        entries.append({"id": f"v{i:02d}", "path": f"field:{name}:{SIDE}",
                        "levels": [first + (i // len(FIELDS)) * step]})
    with open(path, "w") as f:
        json.dump({"volumes": entries}, f)
    return {e["id"]: e["levels"][0] for e in entries}


class Sampler(threading.Thread):
    """Scrapes /metrics and VmRSS until stopped; keeps the largest values per phase."""

    def __init__(self, port, pid):
        super().__init__(daemon=True)
        self.port, self.pid = port, pid
        self.phase = "rounds"
        self.peak = {}
        self.halt = threading.Event()

    def sample(self):
        m = metrics(self.port)
        with open(f"/proc/{self.pid}/status") as f:
            rss = int(re.search(r"VmRSS:\s+(\d+) kB", f.read()).group(1)) * 1024
        p = self.peak.setdefault(self.phase, {"resident": 0, "rss": 0, "other": 0, "samples": 0})
        p["resident"] = max(p["resident"], m["isoserve_resident_bytes"])
        p["rss"] = max(p["rss"], rss)
        p["other"] = max(p["other"], rss - m["isoserve_resident_bytes"])
        p["samples"] += 1

    def run(self):
        while not self.halt.is_set():
            try:
                self.sample()
            except (OSError, KeyError, AttributeError):
                pass
            time.sleep(0.05)


def mesh(port, vid, level):
    r = request(port, f"/v1/volumes/{vid}/mesh?level={level}&format=glb")
    return r.status, (r.getheader("X-Iso-Triangles"), r.getheader("X-Iso-Vertices"),
                      hashlib.sha256(r.body).hexdigest()), r.body[:200]


def main():
    tmp = tempfile.mkdtemp(prefix="iso-resident-")
    levels = catalog(os.path.join(tmp, "catalog.json"))
    port = free_port()
    env = dict(os.environ)
    if SAN:  # a small quarantine: freed volumes leave the process instead of waiting there
        env["ASAN_OPTIONS"] = env.get("ASAN_OPTIONS", "") + ":quarantine_size_mb=16"
    log_path = os.path.join(tmp, "serve.log")
    log = open(log_path, "w")
    proc = subprocess.Popen([BIN, "serve", "--catalog", os.path.join(tmp, "catalog.json"),
                             "--listen", f"127.0.0.1:{port}", "--cache-dir", os.path.join(tmp, "cache"),
                             "--max-resident-mb", str(CAP_MB), "--cache-mb", "0", "--threads", "2",
                             "--queue", "64"],
                            stdout=log, stderr=subprocess.STDOUT, env=env, cwd=ROOT)
    cap = CAP_MB << 20
    try:
        deadline = time.time() + 120
        while time.time() < deadline:
            try:
                if request(port, "/healthz", timeout=5).status == 200:
                    break
            except OSError:
                pass
            time.sleep(0.1)
        sampler = Sampler(port, proc.pid)
        sampler.start()

        first, bad = {}, []
        for round_no in (1, 2):
            for vid in sorted(levels):
                status, facts, head = mesh(port, vid, levels[vid])
                if status != 200:
                    bad.append(f"round {round_no} {vid}: {status} {head!r}")
                elif vid not in first:
                    first[vid] = facts
                elif facts != first[vid]:
                    bad.append(f"round {round_no} {vid}: {facts} != {first[vid]}")
        sampler.phase = "concurrent"
        rng = random.Random(27)
        picks = [rng.choice(sorted(levels)) for _ in range(6 * THREADS)]
        lock = threading.Lock()

        def worker(share):
            for vid in share:
                status, facts, head = mesh(port, vid, levels[vid])
                with lock:
                    if status != 200:
                        bad.append(f"concurrent {vid}: {status} {head!r}")
                    elif facts != first.get(vid):
                        bad.append(f"concurrent {vid}: {facts} != {first.get(vid)}")

        threads = [threading.Thread(target=worker, args=(picks[t::THREADS],)) for t in range(THREADS)]
        for t in threads:
            t.start()
        for t in threads:
            t.join()
        sampler.halt.set()
        sampler.join()
        sampler.sample()
        m = metrics(port)

        RESULTS.report("every_answer_200_same_mesh", not bad and len(first) == VOLUMES,
                       f"{len(bad)} wrong: {bad[:3]}; {len(first)} of {VOLUMES} answered")
        loads = m["isoserve_hierarchies_built_total"] + m["isoserve_hierarchies_read_total"]
        print(f"INFO resident{os.environ.get('ISO_SAN_SUFFIX', '')}: {int(loads)} loads, "
              f"{int(m['isoserve_volume_evictions_total'])} evictions, peaks {sampler.peak}",
              flush=True)
        RESULTS.report("evicted", m["isoserve_volume_evictions_total"] >= VOLUMES and
                       m["isoserve_volume_evictions_total"] == loads - m["isoserve_volumes_loaded"],
                       f"evictions {m['isoserve_volume_evictions_total']}, loads {loads}, "
                       f"loaded now {m['isoserve_volumes_loaded']}")
        RESULTS.report("limit_reported", m["isoserve_resident_limit_bytes"] == cap,
                       f"isoserve_resident_limit_bytes {m['isoserve_resident_limit_bytes']} != {cap}")
        volume_max = SAMPLE_BYTES * 1.125  # samples and a hierarchy (about 2.5 % of them)
        rounds, concurrent = sampler.peak.get("rounds", {}), sampler.peak.get("concurrent", {})
        RESULTS.report("resident_bounded",
                       rounds.get("samples", 0) > 10 and concurrent.get("samples", 0) > 0 and
                       rounds["resident"] <= cap + volume_max and
                       concurrent["resident"] <= cap + THREADS * volume_max and
                       m["isoserve_resident_bytes"] <= cap,
                       f"peaks {sampler.peak}, now {m['isoserve_resident_bytes']}, cap {cap}")
        with open(log_path) as f:
            text = f.read()
        built = re.findall(r"\] (v\d\d): .* hierarchy built in", text)
        read = re.findall(r"\] (v\d\d): .* hierarchy read in", text)
        RESULTS.report("built_once",
                       sorted(built) == sorted(levels) and
                       m["isoserve_hierarchies_built_total"] == VOLUMES and
                       len(read) == m["isoserve_hierarchies_read_total"] == loads - VOLUMES and
                       len(read) >= VOLUMES - HOLDS - 1,
                       f"built {len(built)} ({len(set(built))} ids), read {len(read)}, metrics "
                       f"built {m['isoserve_hierarchies_built_total']} read "
                       f"{m['isoserve_hierarchies_read_total']}")
        overhead = (SAN_OVERHEAD_MB if SAN else OVERHEAD_MB) << 20
        peak_rss = max(p["rss"] for p in sampler.peak.values())
        peak_other = max(p["other"] for p in sampler.peak.values())
        everything = VOLUMES * SAMPLE_BYTES  # what the samples alone would take without the cap
        RESULTS.report("rss_bounded",
                       peak_other <= overhead and rounds["rss"] <= cap + volume_max + overhead and
                       (SAN or peak_rss < everything),
                       f"VmRSS peak {peak_rss >> 20} MB (rounds {rounds['rss'] / 2**20:.0f} MB), "
                       f"beyond the resident volumes {peak_other / 2**20:.0f} MB, stated overhead "
                       f"{overhead >> 20} MB; all {VOLUMES} volumes {everything >> 20} MB")
    finally:
        if proc.poll() is None:
            os.kill(proc.pid, signal.SIGTERM)
        try:
            rc = proc.wait(timeout=60)
        except subprocess.TimeoutExpired:
            os.kill(proc.pid, signal.SIGKILL)
            rc = proc.wait(timeout=10)
        log.close()
    with open(log_path) as f:
        tail = f.read()[-1500:]
    RESULTS.report("clean_exit", rc == 0, f"exit status {rc}: {tail}")
    if not RESULTS.failures:
        subprocess.run(["rm", "-rf", tmp], check=False)
    else:
        print(f"INFO resident: kept {tmp}", flush=True)


main()
sys.exit(1 if RESULTS.failures else 0)
