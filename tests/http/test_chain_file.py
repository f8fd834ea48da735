"""The simplification chain on disk beside the hierarchy files (serve --cache-dir).

One daemon at a time over a catalog of one analytic torus (two iso-levels), restarted
between the steps. Checks:
- the first distance= request at a level builds the chain and writes it as
  CACHE/<id>.<16 hex digits>.isochain (one file per level, nothing outside the cache dir);
- after a restart the same request is answered from that file, mapped (X-Iso-Chain-Source:
  file): no cell visited (nothing extracted), the same bytes and measured distance, no
  rebuild in the log; so is a budget=
  request the chain answers (the file keeps the faithful mesh's triangle count the budget
  is compared with: nothing is extracted to find it again);
- a corrupt file (one byte flipped in the positions, checked before the first cut; or in
  the level records, checked at mapping) or a truncated one is refused (the log says why),
  the chain rebuilt, the same bytes served, and the file rewritten: the next restart reads
  it;
- a stale file (another level's chain under this level's name) is refused the same way;
- a temporary chain file a killed writer left (ID.HASH.isochain.tmp.XXXXXX, unchanged for
  two minutes) is removed at start; one of an id not in the catalog is kept;
- the daemon exits 0 on SIGTERM each time.
Prints PASS/FAIL lines; exit status 1 on failure. Daemons are stopped by their PIDs."""

import glob
import json
import os
import shutil
import struct
import sys
import tempfile
import time

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "support"))
from results import Results  # noqa: E402 - found through the path just set
from client import request  # noqa: E402
import torus_daemon  # noqa: E402

RESULTS = Results("chain_file" + os.environ.get("ISO_SAN_SUFFIX", ""))
LEVELS = (0.0, 0.5)
BUDGET = "budget=300"  # under the faithful mesh's triangles: a chain level answers


class Daemon(torus_daemon.Daemon):
    def __init__(self, tmp):
        # No background builder: the requests build the chains here (test_chains.py has it).
        super().__init__(tmp, "--chain-background", "off")

    def mesh(self, level, ask="distance=0.3"):
        return request(self.port, f"/v1/volumes/torus/mesh?level={level}&{ask}&format=ply&normals=none")


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
                assert r.getheader("X-Iso-Chain-Source") == "file", r.getheader("X-Iso-Chain-Source")
                assert float(r.getheader("X-Iso-Chain-Build-Ms")) == 0
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

    def section(path, i):
        """(offset, bytes) of section i of a chain file: 0 the level records, 1 the positions."""
        with open(path, "rb") as f:
            head = f.read(72 + 24 * (i + 1))
        assert head[:8] == b"ISOCHAIN" and struct.unpack_from("<I", head, 8)[0] == 4
        return struct.unpack_from("<QQ", head, 72 + 24 * i)

    def flip_in(i):
        def flip(files):
            offset, size = section(files[0], i)
            with open(files[0], "r+b") as f:
                f.seek(offset + size // 2)
                b = f.read(1)
                f.seek(offset + size // 2)
                f.write(bytes([b[0] ^ 0x55]))
        return flip

    def truncate(files):
        with open(files[0], "r+b") as f:
            f.truncate(f.seek(0, 2) - 100)

    def swap(files):
        shutil.copyfile(files[0], files[1])

    RESULTS.check("corrupt_positions_refused_and_rebuilt",
                  lambda: refused_and_rebuilt(flip_in(1), "positions' checksum mismatch"))
    RESULTS.check("corrupt_records_refused_and_rebuilt",
                  lambda: refused_and_rebuilt(flip_in(0), "records' checksum mismatch"))
    RESULTS.check("truncated_refused_and_rebuilt", lambda: refused_and_rebuilt(truncate, "cut short"))
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
