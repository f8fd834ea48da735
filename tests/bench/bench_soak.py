"""bench_soak.py [SECONDS] [--label L]: a soak of one `isoserve serve` on 127.0.0.1 (loopback
only; bounded by SECONDS, default 300, and by 200,000 requests). Four client threads mix
cached requests (a few fixed meshes, asked again and again) with uncached ones (a level
never asked before) across three volumes, with a small --queue so that some 503s happen on
purpose. Reports requests, statuses, p50/p99 latency, RSS and open file descriptors of the
server before and after (/proc/PID), and fails (exit 1) on any status other than 200, 304
or a deliberate 503, on an fd leak, or on a server that does not exit 0. Writes
bench/results/soak.json when run by `make bench`. Uses $ISOSERVE_BIN (default build/isoserve)."""

import http.client
import json
import os
import random
import sys
import tempfile
import threading
import time

from provenance import provenance  # tests/bench/provenance.py, beside this file  # noqa: E402

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "http"))
import test_http  # noqa: E402 - its Server class: a daemon on 127.0.0.1:0 stopped by PID

MAX_REQUESTS = 200000
VOLUMES = {"sphere": ("field:sphere:48", 4.0), "torus": ("field:torus:48", 1.0), "ml": ("field:ml:64", 0.5)}


def rss_kb(pid):
    for line in open(f"/proc/{pid}/status"):
        if line.startswith("VmRSS:"):
            return int(line.split()[1])
    return -1


def fds(pid):
    return len(os.listdir(f"/proc/{pid}/fd"))


def client(port, until, seed, out, lock, counter):
    rng = random.Random(seed)
    conn = http.client.HTTPConnection("127.0.0.1", port, timeout=60)
    while time.time() < until:
        with lock:
            if counter[0] >= MAX_REQUESTS:
                return
            counter[0] += 1
        vid = rng.choice(sorted(VOLUMES))
        base = VOLUMES[vid][1]
        if rng.random() < 0.7:   # cached: one of a few fixed meshes
            q = f"level={base}&tolerance={rng.choice([0.05, 0.1, 0.2])}&normals=none"
        else:                    # uncached: a level not asked before
            q = f"level={base + rng.uniform(-0.05, 0.05):.9f}&tolerance=0.1&normals=none"
        t0 = time.time()
        try:
            conn.request("GET", f"/v1/volumes/{vid}/mesh?{q}")
            r = conn.getresponse()
            r.read()
            status = r.status
            if r.getheader("Connection") == "close":
                conn.close()
        except (OSError, http.client.HTTPException):
            status = -1
            conn.close()
        out.append((status, time.time() - t0))


def soak(seconds, label="soak"):
    tmp = tempfile.mkdtemp(prefix="isoserve-soak-")
    cat = os.path.join(tmp, "catalog.json")
    json.dump({"volumes": [{"id": k, "path": v[0], "levels": [v[1]]} for k, v in VOLUMES.items()]}, open(cat, "w"))
    s = test_http.Server(["--catalog", cat, "--threads", "2", "--queue", "2", "--cache-mb", "32"])
    pid = s.proc.pid
    # Warm up one of each so that "before" counts the steady state, not start-up.
    for vid, (_, level) in VOLUMES.items():
        s.get(f"/v1/volumes/{vid}/mesh?level={level}&tolerance=0.1&normals=none")
    before = {"rss_kb": rss_kb(pid), "fds": fds(pid)}
    results, lock, counter = [], threading.Lock(), [0]
    until = time.time() + seconds
    threads = [threading.Thread(target=client, args=(s.port, until, i, results, lock, counter)) for i in range(4)]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    time.sleep(0.5)  # connections closing
    after = {"rss_kb": rss_kb(pid), "fds": fds(pid)}
    rc = s.stop()
    lat = sorted(d for st, d in results if st == 200)
    statuses = {}
    for st, _ in results:
        statuses[st] = statuses.get(st, 0) + 1
    pct = lambda p: lat[min(len(lat) - 1, int(p * len(lat)))] * 1000 if lat else float("nan")  # noqa: E731
    report = {"seconds": seconds, "requests": len(results), "statuses": statuses,
              "p50_ms": round(pct(0.50), 2), "p99_ms": round(pct(0.99), 2),
              "rss_kb_before": before["rss_kb"], "rss_kb_after": after["rss_kb"],
              "fds_before": before["fds"], "fds_after": after["fds"], "exit_status": rc}
    print(f"INFO {label}: " + json.dumps(report), flush=True)
    bad = {k: v for k, v in statuses.items() if k not in (200, 304, 503)}
    problems = []
    if bad:
        problems.append(f"unexpected statuses {bad}")
    if after["fds"] > before["fds"] + 2:
        problems.append(f"fds {before['fds']} -> {after['fds']}")
    if rc != 0:
        problems.append(f"server exit status {rc}")
    if statuses.get(200, 0) < 10:
        problems.append("fewer than 10 answers")
    return report, problems


def main():
    seconds = float(sys.argv[1]) if len(sys.argv) > 1 else 300
    report, problems = soak(seconds)
    if os.path.isdir("bench"):
        os.makedirs("bench/results", exist_ok=True)
        json.dump({**provenance(), **report}, open("bench/results/soak.json", "w"), indent=1)
    print("soak: " + ("ok" if not problems else "; ".join(problems)))
    return 1 if problems else 0


if __name__ == "__main__":
    sys.exit(main())
