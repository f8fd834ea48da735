"""The chains' registry, the background builder and GET /v1/volumes/{id}/chain.

One daemon at a time over a catalog of one analytic torus (two suggested levels),
restarted between the steps. Checks:
- after preloading, the background builder makes the chain of each suggested level and
  writes it to the cache dir (two files); /v1/status says so (built 2 of 2, done);
- /chain of a suggested level: state ready, level 0 first with the exact triangle count,
  fewer triangles at each level, p99 <= max; a distance= request at level 1's own p99 gets
  the level the same rule picks from that JSON, from memory, nothing extracted;
- /chain of a level never asked: state none, no levels, and nothing is built by asking
  (no new file, built count unchanged); unknown volume 404 "no volume ..."; a missing level,
  a negative tolerance or an unknown parameter 400;
- after a restart without the builder, a distance= request maps the file
  (X-Iso-Chain-Source: file, build 0 ms, nothing extracted); a budget= request then builds
  the surface's grid once, and the registry weighs it;
- --chain-mb 0 keeps nothing once used: two levels asked, then the first again, which is
  mapped from its file again; /v1/status counts the evictions and no chain kept.
Prints PASS/FAIL lines; exit status 1 on failure. Daemons are stopped by their PIDs."""

import glob
import json
import os
import shutil
import sys
import tempfile
import time

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "support"))
from results import Results  # noqa: E402 - found through the path just set
from client import request  # noqa: E402
import torus_daemon  # noqa: E402

RESULTS = Results("chains" + os.environ.get("ISO_SAN_SUFFIX", ""))
LEVELS = (0.0, 0.5)


class Daemon(torus_daemon.Daemon):
    def __init__(self, tmp, *extra):
        super().__init__(tmp, "--cache-mb", "0", *extra)

    def json(self, target, status=200):
        r = request(self.port, target)
        assert r.status == status, (target, r.status, r.body[:300])
        return json.loads(r.body)

    def mesh(self, level, distance):
        r = request(self.port, f"/v1/volumes/torus/mesh?level={level}&distance={distance}&format=ply&normals=none")
        assert r.status == 200, (r.status, r.body[:200])
        return r


def picked(levels, distance):
    """The level a distance= request gets: fewest triangles within that p99 (mesh.h)."""
    best = 0
    for k, lv in enumerate(levels):
        if k and lv["distance_p99_mm"] <= distance and lv["triangles"] < levels[best]["triangles"]:
            best = k
    return best


def main():
    tmp = tempfile.mkdtemp(prefix="iso-chains-")
    with open(os.path.join(tmp, "catalog.json"), "w") as f:
        json.dump({"volumes": [{"id": "torus", "path": "field:torus:48", "levels": list(LEVELS)}]}, f)
    cache = os.path.join(tmp, "cache")
    files = lambda: sorted(glob.glob(os.path.join(cache, "torus.*.isochain")))  # noqa: E731
    seen = {}

    def background_builds():
        d = Daemon(tmp)
        try:
            deadline = time.time() + 120
            while time.time() < deadline:
                status = d.json("/v1/status")
                if status["background"]["state"] == "done":
                    break
                time.sleep(0.2)
            bg = status["background"]
            assert bg["state"] == "done" and bg["planned"] == 2 and bg["built"] == 2 and bg["failed"] == 0, status
            assert status["chains"]["built"] == 2 and status["chains"]["ready"] == 2, status
            assert len(files()) == 2, files()
            doc = d.json("/v1/volumes/torus/chain?level=0.5&tolerance=0")
            levels = doc["levels"]
            assert doc["state"] == "ready" and len(levels) >= 3, doc
            assert levels[0]["triangles"] == doc["exact_triangles"] and levels[0]["distance_p99_mm"] == 0, doc
            assert all(b["triangles"] < a["triangles"] for a, b in zip(levels, levels[1:])), levels
            assert all(0 < lv["distance_p99_mm"] <= lv["distance_max_mm"] for lv in levels[1:]), levels
            ask = levels[1]["distance_p99_mm"]
            r = d.mesh(0.5, ask)
            k = picked(levels, ask)
            assert int(r.getheader("X-Iso-Chain-Level")) == k and int(r.getheader("X-Iso-Triangles")) == \
                levels[k]["triangles"], (r.getheader("X-Iso-Chain-Level"), k, levels)
            assert r.getheader("X-Iso-Chain-Source") == "memory" and int(r.getheader("X-Iso-Cells-Visited")) == 0
            seen["levels"] = levels
        finally:
            log = d.stop()
        assert "chains: 2/2 torus level 0.5 built" in log, log[-800:]
    RESULTS.check("background_builds_suggested_levels", background_builds)

    def chain_route_never_builds():
        d = Daemon(tmp, "--chain-background", "off")
        try:
            doc = d.json("/v1/volumes/torus/chain?level=0.25&tolerance=0")
            assert doc["state"] == "none" and doc["levels"] == [] and doc["exact_triangles"] is None, doc
            assert d.json("/v1/status")["chains"]["built"] == 0
            assert len(files()) == 2, files()
            missing = d.json("/v1/volumes/nope/chain?level=1", 404)
            assert missing["detail"].startswith("no volume"), missing
            for bad in ("tolerance=0", "level=0.5&tolerance=-1", "level=0.5&distance=1"):
                d.json(f"/v1/volumes/torus/chain?{bad}", 400)
            doc = d.json("/v1/volumes/torus/chain?level=0.5&tolerance=0")  # mapped from its file
            assert doc["state"] == "ready" and doc["levels"] == seen["levels"], doc
        finally:
            d.stop()
    RESULTS.check("chain_route_never_builds", chain_route_never_builds)

    def restart_maps_the_file():
        d = Daemon(tmp, "--chain-background", "off")
        try:
            r = d.mesh(0.0, 0.3)
            assert r.getheader("X-Iso-Chain-Source") == "file", r.getheader("X-Iso-Chain-Source")
            assert float(r.getheader("X-Iso-Chain-Build-Ms")) == 0 and int(r.getheader("X-Iso-Cells-Visited")) == 0
            assert float(r.getheader("X-Iso-Chain-Load-Ms")) >= 0 and float(r.getheader("X-Iso-Chain-Cut-Ms")) > 0
            # A budget measures against the surface: its grid is built once, weighed with the chain.
            before = d.json("/v1/status")["chains"]["bytes"]
            r = request(d.port, "/v1/volumes/torus/mesh?level=0.0&budget=300&format=ply&normals=none")
            assert r.status == 200 and r.getheader("X-Iso-Budget-Source") == "chain", r.status
            assert int(r.getheader("X-Iso-Cells-Visited")) == 0 and r.getheader("X-Iso-Chain-Source") == "memory"
            after = d.json("/v1/status")["chains"]["bytes"]
            assert after > before, (before, after)
        finally:
            log = d.stop()
        assert "built" not in log and "rebuilding" not in log, log[-500:]
    RESULTS.check("restart_maps_the_file", restart_maps_the_file)

    def limit_evicts():
        d = Daemon(tmp, "--chain-background", "off", "--chain-mb", "0")
        try:
            sources = [d.mesh(level, 0.3).getheader("X-Iso-Chain-Source") for level in (0.0, 0.5, 0.0)]
            assert sources == ["file", "file", "file"], sources
            chains = d.json("/v1/status")["chains"]
            assert chains["evictions"] == 3 and chains["ready"] == 0 and chains["bytes"] == 0, chains
            assert chains["mapped"] == 3 and chains["limit_bytes"] == 0, chains
        finally:
            d.stop()
    RESULTS.check("limit_evicts", limit_evicts)
    shutil.rmtree(tmp, ignore_errors=True)
    return 1 if RESULTS.failures else 0


if __name__ == "__main__":
    sys.exit(main())
