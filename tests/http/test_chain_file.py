"""The simplification chain on disk beside the hierarchy files (serve --cache-dir).

One daemon at a time over a catalog of one analytic torus (two iso-levels), restarted
between the steps. Checks:
- the first distance= request at a level builds the chain and writes it as
  CACHE/<id>.<16 hex digits>.isochain (one file per level, nothing outside the cache dir);
- after a restart the same request is answered from that file: no cell visited (nothing
  extracted), the same bytes and measured distance, no rebuild in the log; so is a budget=
  request the chain answers (the file keeps the faithful mesh's triangle count the budget
  is compared with: nothing is extracted to find it again);
- a corrupt file (one payload byte flipped) is refused (the log says why), the chain
  rebuilt, the same bytes served, and the file rewritten: the next restart reads it;
- a stale file (another level's chain under this level's name) is refused the same way;
- a temporary chain file a killed writer left (ID.HASH.isochain.tmp.XXXXXX, unchanged for
  two minutes) is removed at start; one of an id not in the catalog is kept;
- the daemon exits 0 on SIGTERM each time.
Prints PASS/FAIL lines; exit status 1 on failure. Daemons are stopped by their PIDs."""

import glob
import json
import os
import shutil
import signal
import subprocess
import sys
import tempfile
import time

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "support"))
from results import Results  # noqa: E402 - found through the path just set
from client import request  # noqa: E402
from ports import free_port  # noqa: E402

ROOT = os.path.abspath(os.path.join(os.path.dirname(__file__), "..", ".."))
BIN = os.path.abspath(os.environ.get("ISOSERVE_BIN", os.path.join(ROOT, "build/isoserve")))
RESULTS = Results("chain_file" + os.environ.get("ISO_SAN_SUFFIX", ""))
LEVELS = (0.0, 0.5)
BUDGET = "budget=300"  # under the faithful mesh's triangles: a chain level answers


class Daemon:
    def __init__(self, tmp):
        self.tmp, self.port = tmp, free_port()
        self.log_path = os.path.join(tmp, "serve.log")
        with open(self.log_path, "w") as log:
            self.proc = subprocess.Popen([BIN, "serve", "--catalog", os.path.join(tmp, "catalog.json"),
                                          "--listen", f"127.0.0.1:{self.port}",
                                          "--cache-dir", os.path.join(tmp, "cache"), "--threads", "2"],
                                         stdout=log, stderr=subprocess.STDOUT, cwd=ROOT)
        deadline = time.time() + 60
        while time.time() < deadline:
            try:
                if request(self.port, "/healthz", timeout=5).status == 200:
                    return
            except OSError:
                pass
            time.sleep(0.1)
        raise AssertionError("the daemon did not start")

    def mesh(self, level, ask="distance=0.3"):
        return request(self.port, f"/v1/volumes/torus/mesh?level={level}&{ask}&format=ply&normals=none")

    def stop(self):
        self.proc.send_signal(signal.SIGTERM)
        rc = self.proc.wait(timeout=60)
        with open(self.log_path) as f:
            log = f.read()
        assert rc == 0, f"exit {rc}: {log[-500:]}"
        return log


def facts(r):
    assert r.status == 200, (r.status, r.body[:200])
    return (r.body, r.getheader("X-Iso-Chain-Level"), r.getheader("X-Iso-Distance-Mm"))


def main():
    tmp = tempfile.mkdtemp(prefix="iso-chain-file-")
    with open(os.path.join(tmp, "catalog.json"), "w") as f:
        json.dump({"volumes": [{"id": "torus", "path": "field:torus:48", "levels": list(LEVELS)}]}, f)
    cache = os.path.join(tmp, "cache")
    first = {}

    def built_and_written():
        d = Daemon(tmp)
        try:
            for level in LEVELS:
                r = d.mesh(level)
                first[level] = facts(r)
                assert int(r.getheader("X-Iso-Cells-Visited")) > 0  # extracted: no chain yet
                r = d.mesh(level, BUDGET)
                first[(level, BUDGET)] = facts(r)
                assert r.getheader("X-Iso-Budget-Source") == "chain", r.getheader("X-Iso-Budget-Source")
        finally:
            d.stop()
        files = sorted(glob.glob(os.path.join(cache, "torus.*.isochain")))
        assert len(files) == 2 and all(len(os.path.basename(p).split(".")[1]) == 16 for p in files), files
        outside = [p for p in glob.glob(os.path.join(tmp, "**", "*.isochain*"), recursive=True)
                   if os.path.dirname(p) != cache]
        assert not outside, outside
    RESULTS.check("built_and_written", built_and_written)

    def read_after_restart():
        d = Daemon(tmp)
        try:
            for level in LEVELS:
                r = d.mesh(level)
                assert facts(r) == first[level], level
                assert int(r.getheader("X-Iso-Cells-Visited")) == 0, r.getheader("X-Iso-Cells-Visited")
                r = d.mesh(level, BUDGET)
                assert facts(r) == first[(level, BUDGET)], level
                assert int(r.getheader("X-Iso-Cells-Visited")) == 0, ("budget", r.getheader("X-Iso-Cells-Visited"))
        finally:
            log = d.stop()
        assert "rebuilding the chain" not in log, log[-500:]
    RESULTS.check("read_after_restart", read_after_restart)

    def refused_and_rebuilt(damage, why):
        files = sorted(glob.glob(os.path.join(cache, "torus.*.isochain")))
        damage(files)
        d = Daemon(tmp)
        try:
            for level in LEVELS:
                assert facts(d.mesh(level)) == first[level], level
        finally:
            log = d.stop()
        assert "rebuilding the chain" in log and why in log, log[-800:]
        d = Daemon(tmp)  # rewritten: read back without complaint
        try:
            for level in LEVELS:
                r = d.mesh(level)
                assert facts(r) == first[level] and int(r.getheader("X-Iso-Cells-Visited")) == 0
        finally:
            log = d.stop()
        assert "rebuilding the chain" not in log, log[-500:]

    def flip(files):
        with open(files[0], "r+b") as f:
            size = f.seek(0, 2)
            f.seek(size // 2)
            b = f.read(1)
            f.seek(size // 2)
            f.write(bytes([b[0] ^ 0x55]))

    def swap(files):
        shutil.copyfile(files[0], files[1])

    RESULTS.check("corrupt_refused_and_rebuilt", lambda: refused_and_rebuilt(flip, "checksum"))
    RESULTS.check("stale_refused_and_rebuilt", lambda: refused_and_rebuilt(swap, "another surface"))
    def stale_temporaries_removed():
        mine = os.path.join(cache, "torus.0123456789abcdef.isochain.tmp.a1B2c3")
        other = os.path.join(cache, "other.0123456789abcdef.isochain.tmp.a1B2c3")
        for p in (mine, other):
            with open(p, "wb") as f:
                f.write(b"half a chain")
            old = time.time() - 120
            os.utime(p, (old, old))
        d = Daemon(tmp)
        log = d.stop()
        assert not os.path.exists(mine) and "removed, a stale temporary file" in log, log[-500:]
        assert os.path.exists(other)
    RESULTS.check("stale_temporaries_removed", stale_temporaries_removed)
    shutil.rmtree(tmp, ignore_errors=True)
    return 1 if RESULTS.failures else 0


if __name__ == "__main__":
    sys.exit(main())
