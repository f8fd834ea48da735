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
  mapped from its file again; /v1/status counts the evictions and no chain kept;
- a level never asked, without the suggested levels' builder: the first distance= request
  builds the chain only down to its level (X-Iso-Chain-Source: partial; /chain then says
  "building" with the full chain's first levels, unless completed already), a coarser one is served
  (extended by it, or waiting for the background completer) at the level the full chain's
  JSON picks; the completed chain is written (one more file, /chain ready with every level
  the full build has, measured alike), a restart maps it and serves the first request's
  bytes, and they are the bytes of the same level cut from a chain the background builder
  built whole (that level suggested, in another cache dir);
- while the completer is busy with another volume's chain, a coarser request extends the
  small torus's partial chain itself (X-Iso-Chain-Source: extended) and gets the level the
  completed chain's JSON picks; both chains are then completed and written.
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

    def partial_then_completed():
        fine, coarse = 0.05, 0.3  # mm: torus:48 has 1 mm voxels
        d = Daemon(tmp, "--chain-background", "off")
        try:
            first = d.mesh(0.25, fine)
            assert first.getheader("X-Iso-Chain-Source") == "partial", first.getheader("X-Iso-Chain-Source")
            assert float(first.getheader("X-Iso-Chain-Build-Ms")) > 0
            k_first = int(first.getheader("X-Iso-Chain-Level"))
            early = d.json("/v1/volumes/torus/chain?level=0.25&tolerance=0")  # unless completed already
            second = d.mesh(0.25, coarse)
            assert second.getheader("X-Iso-Chain-Source") in ("extended", "waited", "memory"), \
                second.getheader("X-Iso-Chain-Source")
            deadline = time.time() + 60
            while time.time() < deadline:
                doc = d.json("/v1/volumes/torus/chain?level=0.25&tolerance=0")
                if doc["state"] == "ready":
                    break
                time.sleep(0.1)
            levels = doc["levels"]
            assert doc["state"] == "ready" and len(levels) == 13, doc
            assert all(0 < lv["distance_p99_mm"] <= lv["distance_max_mm"] for lv in levels[1:]), levels
            assert picked(levels, fine) == k_first and picked(levels, coarse) == int(second.getheader("X-Iso-Chain-Level"))
            assert int(second.getheader("X-Iso-Triangles")) == levels[picked(levels, coarse)]["triangles"]
            assert len(files()) == 3, files()
            if early["state"] == "building":  # its levels so far: the full chain's first ones
                assert k_first < len(early["levels"]) < len(levels), early
                assert [lv["triangles"] for lv in early["levels"]] == \
                    [lv["triangles"] for lv in levels[:len(early["levels"])]], early
            else:
                assert early["state"] == "ready" and early["levels"] == levels, early
            status = d.json("/v1/status")["chains"]
            assert status["built"] == 1 and status["completed"] == 1, status
        finally:
            log = d.stop()
        assert "chains: torus level 0.25 completed" in log, log[-800:]
        d = Daemon(tmp, "--chain-background", "off")
        try:
            again = d.mesh(0.25, fine)
            assert again.getheader("X-Iso-Chain-Source") == "file" and again.body == first.body
        finally:
            d.stop()
        # The same level from a chain built whole: 0.25 suggested, in its own cache dir.
        whole = tempfile.mkdtemp(prefix="iso-chains-whole-")
        with open(os.path.join(whole, "catalog.json"), "w") as f:
            json.dump({"volumes": [{"id": "torus", "path": "field:torus:48", "levels": [0.25]}]}, f)
        d = Daemon(whole)
        try:
            deadline = time.time() + 60
            while time.time() < deadline and d.json("/v1/status")["background"]["state"] != "done":
                time.sleep(0.1)
            full = d.mesh(0.25, fine)
            assert full.getheader("X-Iso-Chain-Source") == "memory" and full.body == first.body
            assert d.json("/v1/volumes/torus/chain?level=0.25&tolerance=0")["levels"] == levels
        finally:
            d.stop()
            shutil.rmtree(whole, ignore_errors=True)
        # Partial: the first response came from fewer levels than the whole chain has.
        assert k_first < len(levels) - 1
    RESULTS.check("partial_then_completed", partial_then_completed)

    def extended_while_completer_busy():
        # The completer busy with a larger torus's chain (0.6 s; starved while requests run):
        # a coarser request on the small one extends its partial chain itself.
        busy = tempfile.mkdtemp(prefix="iso-chains-busy-")
        with open(os.path.join(busy, "catalog.json"), "w") as f:
            json.dump({"volumes": [{"id": "torus", "path": "field:torus:48", "levels": [0.5]},
                                   {"id": "big", "path": "field:torus:128", "levels": [0.5]}]}, f)
        d = Daemon(busy, "--chain-background", "off")
        try:
            r = request(d.port, "/v1/volumes/big/mesh?level=0.25&distance=0.05&format=ply&normals=none")
            assert r.status == 200 and r.getheader("X-Iso-Chain-Source") == "partial", r.status
            assert d.mesh(0.25, 0.05).getheader("X-Iso-Chain-Source") == "partial"
            coarse = d.mesh(0.25, 0.3)
            assert coarse.getheader("X-Iso-Chain-Source") == "extended", coarse.getheader("X-Iso-Chain-Source")
            assert float(coarse.getheader("X-Iso-Chain-Build-Ms")) > 0
            deadline = time.time() + 60
            while time.time() < deadline and d.json("/v1/status")["chains"]["completed"] < 2:
                time.sleep(0.1)
            status = d.json("/v1/status")["chains"]
            assert status["completed"] == 2 and status["extended"] >= 3 and status["built"] == 2, status
            levels = d.json("/v1/volumes/torus/chain?level=0.25&tolerance=0")["levels"]
            k = picked(levels, 0.3)
            assert int(coarse.getheader("X-Iso-Chain-Level")) == k and \
                int(coarse.getheader("X-Iso-Triangles")) == levels[k]["triangles"], (coarse.getheader("X-Iso-Chain-Level"), levels)
            assert len(glob.glob(os.path.join(busy, "cache", "*.isochain"))) == 2
        finally:
            d.stop()
            shutil.rmtree(busy, ignore_errors=True)
    RESULTS.check("extended_while_completer_busy", extended_while_completer_busy)
    shutil.rmtree(tmp, ignore_errors=True)
    return 1 if RESULTS.failures else 0


if __name__ == "__main__":
    sys.exit(main())
