"""HTTP integration tests of `isoserve serve`: every route and error status, ETag/304, CORS,
the cache, coalescing, a full queue, preloading and hierarchy files, graceful shutdown, and
the bytes decoded back (Debian's draco_decoder, npm's draco3d in node when installed).

Each server is a real process on 127.0.0.1 with port 0 (the kernel picks a free port, which
the server prints), stopped by its PID. Prints PASS/FAIL/SKIP lines; exit status 1 on failure.
Uses Debian's python3 with numpy only."""

import http.client
import gzip
import json
import os
import re
import shutil
import signal
import struct
import subprocess
import sys
import tempfile
import threading
import time

import numpy as np

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "support"))
from results import Results, Skip  # noqa: E402 - found through the path just set

BIN = os.path.abspath(os.environ.get("ISOSERVE_BIN", "build/isoserve"))
LABEL = "http" + os.environ.get("ISO_SAN_SUFFIX", "")  # tests/run.sh's asan pass says http-san
RESULTS = Results(LABEL)
report, check = RESULTS.report, RESULTS.check


# ---------------------------------------------------------------- volumes written here

def write_nrrd(path, data, spacing):
    """An attached raw NRRD of float32 samples (data indexed [z, y, x])."""
    z, y, x = data.shape
    header = ("NRRD0004\ntype: float\ndimension: 3\n"
              f"sizes: {x} {y} {z}\nspacings: {spacing[0]} {spacing[1]} {spacing[2]}\n"
              "endian: little\nencoding: raw\n\n")
    with open(path, "wb") as f:
        f.write(header.encode())
        f.write(data.astype("<f4").tobytes())


def blob_volume():
    """A smooth, lumpy float field (two overlapping blobs) with known samples."""
    z, y, x = np.mgrid[0:30, 0:34, 0:38].astype(np.float64)
    a = np.exp(-((x - 14) ** 2 + (y - 16) ** 2 + (z - 14) ** 2) / 60.0)
    b = np.exp(-((x - 24) ** 2 + (y - 18) ** 2 + (z - 16) ** 2) / 40.0)
    return (100 * (a + 0.8 * b)).astype(np.float32)


def trilinear(data, p):
    """The trilinear interpolant of data ([z,y,x]) at index points p (N x 3, x y z)."""
    nz, ny, nx = data.shape
    q = np.clip(p, 0, [nx - 1.000001, ny - 1.000001, nz - 1.000001])
    i0 = np.floor(q).astype(int)
    t = q - i0
    out = np.zeros(len(p))
    for dz in (0, 1):
        for dy in (0, 1):
            for dx in (0, 1):
                w = ((t[:, 0] if dx else 1 - t[:, 0]) * (t[:, 1] if dy else 1 - t[:, 1])
                     * (t[:, 2] if dz else 1 - t[:, 2]))
                out += w * data[i0[:, 2] + dz, i0[:, 1] + dy, i0[:, 0] + dx]
    return out


# ---------------------------------------------------------------- servers

class Server:
    """A daemon on 127.0.0.1:0; its stderr (access log included) is collected."""

    def __init__(self, args, wait_ready=True):
        self.proc = subprocess.Popen([BIN, "serve", "--listen", "127.0.0.1:0", *args],
                                     stderr=subprocess.PIPE, text=True)
        self.lines = []
        self.port = None
        deadline = time.time() + 30
        while time.time() < deadline:
            line = self.proc.stderr.readline()
            if not line:
                break
            self.lines.append(line)
            m = re.search(r"listening on http://127\.0\.0\.1:(\d+)/", line)
            if m:
                self.port = int(m.group(1))
                break
        if not self.port:
            self.proc.kill()
            raise RuntimeError("server did not start: " + "".join(self.lines))
        self.reader = threading.Thread(target=self._drain, daemon=True)
        self.reader.start()
        if wait_ready:
            self.wait_ready()

    def _drain(self):
        for line in self.proc.stderr:
            self.lines.append(line)

    def wait_ready(self, timeout=120):
        deadline = time.time() + timeout
        while time.time() < deadline:
            if self.get("/healthz").status == 200:
                return
            time.sleep(0.05)
        raise RuntimeError("server not ready")

    def request(self, method, target, headers=None, timeout=60):
        conn = http.client.HTTPConnection("127.0.0.1", self.port, timeout=timeout)
        conn.request(method, target, headers=headers or {})
        r = conn.getresponse()
        r.body = r.read()
        conn.close()
        return r

    def get(self, target, headers=None, timeout=60):
        return self.request("GET", target, headers, timeout)

    def metric(self, name):
        text = self.get("/metrics").body.decode()
        m = re.search(rf"^{re.escape(name)} (\S+)$", text, re.M)
        return float(m.group(1)) if m else None

    def stop(self):
        if self.proc.poll() is None:
            self.proc.send_signal(signal.SIGTERM)
        rc = self.proc.wait(timeout=30)
        self.reader.join(timeout=5)
        return rc

    def log(self):
        return "".join(self.lines)

    def wait_log(self, pattern, timeout=5):
        """The log line is written when a request completes, just after the client has
        its response: poll for it briefly."""
        deadline = time.time() + timeout
        while time.time() < deadline:
            if re.search(pattern, self.log(), re.M):
                return True
            time.sleep(0.02)
        return False


def problem(r):
    assert r.getheader("Content-Type") == "application/problem+json", r.getheader("Content-Type")
    body = json.loads(r.body)
    assert body["status"] == r.status and body["title"] and body["detail"], body
    return body


def draco_decode(body, tmp, name):
    """Decodes Draco bytes with Debian's draco_decoder: (positions N x 3, triangle count)."""
    path = os.path.join(tmp, name + ".drc")
    open(path, "wb").write(body)
    out = os.path.join(tmp, name + "_decoded.ply")
    subprocess.run(["draco_decoder", "-i", path, "-o", out], check=True, capture_output=True)
    head, _, payload = open(out, "rb").read().partition(b"end_header\n")
    nv = int(re.search(rb"element vertex (\d+)", head).group(1))
    nt = int(re.search(rb"element face (\d+)", head).group(1))
    return np.frombuffer(payload[:nv * 12], "<f4").reshape(nv, 3).astype(np.float64), nt


# ---------------------------------------------------------------- the main server's tests

def main_tests(s, tmp, blob):
    def volumes():
        r = s.get("/v1/volumes")
        assert r.status == 200 and r.getheader("Content-Type") == "application/json"
        vols = {v["id"]: v for v in json.loads(r.body)["volumes"]}
        assert set(vols) == {"blob", "torus", "ml"}, sorted(vols)
        b = vols["blob"]
        assert b["dims"] == [38, 34, 30] and b["value_type"] == "float32", b
        assert b["spacing"] == [0.75, 1.0, 1.25], b["spacing"]
        assert abs(b["value_range"][1] - float(blob.max())) < 1e-3, b["value_range"]
        assert vols["torus"]["suggested_levels"] == [0.0], vols["torus"]["suggested_levels"]
        assert len(b["suggested_levels"]) == 2 and b["value_range"][0] < b["suggested_levels"][0] < b["suggested_levels"][1] < b["value_range"][1]
        assert len(b["index_to_world"]) == 16 and b["index_to_world"][0] == 0.75
    check("volumes_list", volumes)

    def volumes_paged():
        whole = [v["id"] for v in json.loads(s.get("/v1/volumes").body)["volumes"]]
        walked, target = [], "/v1/volumes?limit=2"
        while target:
            r = s.get(target)
            assert r.status == 200 and r.getheader("X-Iso-Total") == "3", (r.status, r.getheader("X-Iso-Total"))
            page = [v["id"] for v in json.loads(r.body)["volumes"]]
            assert 1 <= len(page) <= 2, page
            walked += page
            link = r.getheader("Link")
            target = re.fullmatch(r'<(/v1/volumes\?limit=2&after=[A-Za-z0-9._-]+)>; rel="next"', link).group(1) if link else None
        assert walked == whole, (walked, whole)
        r = s.get(f"/v1/volumes?after={whole[-1]}")
        assert r.status == 200 and json.loads(r.body)["volumes"] == [] and r.getheader("Link") is None
        for bad in ("limit=0", "limit=10001", "limit=2x", "after=nosuch", "after=..%2F"):
            r = s.get(f"/v1/volumes?{bad}")
            assert r.status == 400 and problem(r)["status"] == 400, (bad, r.status)
    check("volumes_paged_with_limit_and_after", volumes_paged)

    def one_volume():
        r = s.get("/v1/volumes/blob")
        v = json.loads(r.body)
        h = v["histogram"]
        assert r.status == 200 and len(h["counts"]) == 256 and sum(h["counts"]) == blob.size
        top = int(np.floor((blob.max() - h["min"]) / (h["max"] - h["min"]) * 256))
        assert h["counts"][255] >= 1 and top >= 255
        # 12 bytes per kd-tree node plus, per brick of 8^3 cells, its float min and max and
        # its 17 one-byte level codes, and the codes' 256-value scale (core/hierarchy/tree.h).
        bricks = int(np.prod([-(-(d - 1) // 8) for d in v["dims"]]))
        assert v["hierarchy"]["nodes"] >= 1 and \
            v["hierarchy"]["bytes"] == 12 * v["hierarchy"]["nodes"] + 25 * bricks + 256 * 8, \
            (v["hierarchy"], bricks)
        assert v["hierarchy"]["share_of_volume"] < 0.1, v["hierarchy"]
        assert v["preview_tolerance"] == (v["value_range"][1] - v["value_range"][0]) / 2, v["preview_tolerance"]
    check("volume_document", one_volume)

    # The mesh, uncompressed (PLY) and in Draco: counts agree with the headers, Draco's
    # positions sit within half a quantization step of the exact ones, and the error bound
    # holds at the exact vertices against the samples this test wrote.
    level, tol = 40.0, 2.0
    state = {}

    def mesh_ply():
        r = s.get(f"/v1/volumes/blob/mesh?level={level}&tolerance={tol}&format=ply&normals=none")
        assert r.status == 200 and r.getheader("Content-Type") == "application/x-ply"
        head, _, payload = r.body.partition(b"end_header\n")
        nv = int(re.search(rb"element vertex (\d+)", head).group(1))
        nt = int(re.search(rb"element face (\d+)", head).group(1))
        assert nv == int(r.getheader("X-Iso-Vertices")) and nt == int(r.getheader("X-Iso-Triangles"))
        assert nt > 500 and len(payload) == nv * 12 + nt * 13
        pos = np.frombuffer(payload[:nv * 12], "<f4").reshape(nv, 3).astype(np.float64)
        bound = float(r.getheader("X-Iso-Error-Bound"))
        assert 0 <= bound <= tol and float(r.getheader("X-Iso-Tolerance")) == tol
        for h in ("X-Iso-Cells-Visited", "X-Iso-Extract-Ms", "X-Iso-Encode-Ms"):
            assert float(r.getheader(h)) >= 0, h
        for h in ("X-Iso-Measure-Ms", "X-Iso-Area-Mm2", "X-Iso-Closed", "X-Iso-Volume-Mm3"):
            assert r.getheader(h) is None, f"{h} without measures=true"
        index = pos / np.array([0.75, 1.0, 1.25])  # origin 0, identity directions
        err = np.abs(trilinear(blob.astype(np.float64), index) - level)
        assert err.max() <= bound + 1e-3, f"max |f - L| {err.max()} > bound {bound}"
        faces = np.frombuffer(payload[nv * 12:], np.dtype([("n", "u1"), ("v", "<u4", 3)]))
        assert (faces["n"] == 3).all() and (faces["v"] < nv).all()
        state["pos"], state["bound"], state["nt"] = pos, bound, nt
        state["corners"] = pos[faces["v"]]  # (nt, 3, 3): each triangle's corners
    check("mesh_ply_bound_holds", mesh_ply)


    def mesh_draco():
        r = s.get(f"/v1/volumes/blob/mesh?level={level}&tolerance={tol}&normals=none&qp=12")
        assert r.status == 200 and r.getheader("Content-Type") == "application/x-draco"
        dec, nt = draco_decode(r.body, tmp, "blob")
        nv = len(dec)
        assert nv == int(r.getheader("X-Iso-Vertices")), (nv, r.getheader("X-Iso-Vertices"))
        assert nt == int(r.getheader("X-Iso-Triangles")) == state["nt"]
        exact = state["pos"]
        extent = (exact.max(0) - exact.min(0)).max()
        half_step = extent / (2 ** 12 - 1) / 2
        # Nearest exact vertex of each decoded one, bucketed on a coarse grid.
        cell = 4 * half_step + 1e-9
        keys = {}
        for i, p in enumerate(np.floor(exact / cell).astype(int)):
            keys.setdefault(tuple(p), []).append(i)
        worst = 0.0
        for p in dec:
            k = np.floor(p / cell).astype(int)
            cand = [j for dx in (-1, 0, 1) for dy in (-1, 0, 1) for dz in (-1, 0, 1)
                    for j in keys.get((k[0] + dx, k[1] + dy, k[2] + dz), [])]
            assert cand, f"decoded vertex {p} has no exact vertex near it"
            worst = max(worst, np.abs(exact[cand] - p).max(axis=1).min())
        assert worst <= half_step * 1.01 + 1e-6, f"moved {worst} > half step {half_step}"
        state["drc"] = os.path.join(tmp, "blob.drc")
    check("mesh_draco_decodes_within_half_step", mesh_draco)

    def draco3d_node():
        node_dir = "web/node_modules/draco3d"
        if not os.path.isdir(node_dir) or not shutil.which("node") or "drc" not in state:
            raise Skip("web/node_modules/draco3d not installed (make web)")
        script = r"""
const draco3d = require(process.argv[1]);
const fs = require('fs');
draco3d.createDecoderModule({}).then(m => {
  const buf = fs.readFileSync(process.argv[2]);
  const dec = new m.Decoder(), mesh = new m.Mesh();
  const st = dec.DecodeArrayToMesh(new Int8Array(buf), buf.length, mesh);
  if (!st.ok()) { console.log('error ' + st.error_msg()); process.exit(1); }
  console.log(mesh.num_points() + ' ' + mesh.num_faces());
});"""
        out = subprocess.run(["node", "-e", script, os.path.abspath(node_dir), state["drc"]],
                             capture_output=True, text=True, timeout=60)
        assert out.returncode == 0, out.stdout + out.stderr
        nv, nt = map(int, out.stdout.split())
        assert nt == state["nt"], (nt, state["nt"])
        assert nv == len(state["pos"]), (nv, len(state["pos"]))
    check("mesh_draco3d_node", draco3d_node)

    # Draco's speed: auto (8 for this small mesh), or named; each its own cached body and
    # ETag, each decoding to the mesh; 10 keeps the PLY's vertex order. The steps' times.
    def draco_speeds():
        base = f"/v1/volumes/blob/mesh?level={level}&tolerance={tol}&normals=none"
        etags = set()
        for asked, used in (("", "8"), ("&speed=auto", "8"), ("&speed=0", "0"), ("&speed=10", "10")):
            r = s.get(base + asked)
            assert r.status == 200 and r.getheader("X-Iso-Draco-Speed") == used, (asked, r.getheader("X-Iso-Draco-Speed"))
            for h in ("X-Iso-Extract-Ms", "X-Iso-Normals-Ms", "X-Iso-Encode-Ms"):
                assert float(r.getheader(h)) >= 0, h
            dec, nt = draco_decode(r.body, tmp, "speed" + used)
            assert nt == state["nt"] and len(dec) == len(state["pos"]), (asked, nt, len(dec))
            etags.add(r.getheader("ETag"))
        assert len(etags) == 3, etags  # "" and "auto" are one request
        extent = (state["pos"].max(0) - state["pos"].min(0)).max()
        assert np.abs(dec - state["pos"]).max() <= extent / (2 ** 14 - 1) / 2 * 1.01  # in order
        r = s.get(base + "&speed=3&format=ply")
        assert r.status == 200 and r.getheader("X-Iso-Draco-Speed") is None
        for bad in ("11", "fast", "-1"):
            r = s.get(base + "&speed=" + bad)
            assert r.status == 400 and problem(r)["parameter"] == "speed", (bad, r.body)
    check("mesh_draco_speeds", draco_speeds)

    def mesh_glb():
        r = s.get(f"/v1/volumes/blob/mesh?level={level}&tolerance={tol}&format=glb")
        b = r.body
        assert r.status == 200 and r.getheader("Content-Type") == "model/gltf-binary"
        magic, version, length = struct.unpack_from("<III", b, 0)
        assert magic == 0x46546C67 and version == 2 and length == len(b)
        jlen, jtype = struct.unpack_from("<II", b, 12)
        assert jtype == 0x4E4F534A
        doc = json.loads(b[20:20 + jlen])
        blen, btype = struct.unpack_from("<II", b, 20 + jlen)
        assert btype == 0x004E4942 and 28 + jlen + blen == len(b)
        assert "KHR_draco_mesh_compression" in doc["extensionsRequired"]
        prim = doc["meshes"][0]["primitives"][0]
        ext = prim["extensions"]["KHR_draco_mesh_compression"]
        view = doc["bufferViews"][ext["bufferView"]]
        assert view["byteOffset"] + view["byteLength"] <= blen
        assert "NORMAL" in prim["attributes"], prim["attributes"]
        assert doc["accessors"][prim["indices"]]["count"] == 3 * int(r.getheader("X-Iso-Triangles"))
        state["glb"] = os.path.join(tmp, "blob.glb")
        open(state["glb"], "wb").write(b)
        state["glb_counts"] = (int(r.getheader("X-Iso-Triangles")), int(r.getheader("X-Iso-Vertices")))
    check("mesh_glb_structure", mesh_glb)

    def glb_three():
        if not os.path.isdir("web/node_modules/three") or "glb" not in state:
            raise Skip("web/node_modules/three not installed (make node-deps)")
        out = subprocess.run(["node", "tests/http/gltf_load.mjs", state["glb"], os.path.abspath("web")],
                             capture_output=True, text=True, timeout=60)
        assert out.returncode == 0, out.stdout + out.stderr
        tri, ver, normals, *_ = out.stdout.split()
        assert (int(tri), int(ver)) == state["glb_counts"], (out.stdout, state["glb_counts"])
        assert normals == "true", out.stdout
    check("mesh_glb_loads_in_three_gltfloader", glb_three)

    # format=glb-plain, for tools without Draco or meshopt: no extension used or required,
    # the Khronos validator finds nothing to report, and the buffers hold the PLY's own
    # floats and indices, bit for bit; three's GLTFLoader reads the same counts.
    def glb_plain():
        if not os.path.isdir("web/node_modules/gltf-validator"):
            raise Skip("web/node_modules/gltf-validator not installed (make node-deps)")
        r = s.get(f"/v1/volumes/blob/mesh?level={level}&tolerance={tol}&format=glb-plain&normals=trilinear")
        ply = s.get(f"/v1/volumes/blob/mesh?level={level}&tolerance={tol}&format=ply&normals=trilinear")
        assert r.status == 200 and r.getheader("Content-Type") == "model/gltf-binary", r.status
        assert 'filename="blob-' in r.getheader("Content-Disposition")
        b = r.body
        jlen = struct.unpack_from("<I", b, 12)[0]
        doc = json.loads(b[20:20 + jlen])
        assert "extensionsUsed" not in doc and "extensionsRequired" not in doc, doc
        path = os.path.join(tmp, "blob.plain.glb")
        open(path, "wb").write(b)
        out = subprocess.run(["node", "tests/http/gltf_validate.mjs", os.path.abspath("web"), path],
                             capture_output=True, text=True, timeout=60)
        assert out.returncode == 0 and out.stdout.split("\n")[0] == "0 0 -" and not out.stderr, out.stdout + out.stderr
        head, _, payload = ply.body.partition(b"end_header\n")
        nv = int(re.search(rb"element vertex (\d+)", head).group(1))
        nt = int(re.search(rb"element face (\d+)", head).group(1))
        vertices = np.frombuffer(payload[:24 * nv], "<f4").reshape(nv, 6)
        faces = np.frombuffer(payload[24 * nv:], np.dtype([("n", "u1"), ("i", "<u4", 3)]))["i"]
        binary = b[28 + jlen:]
        views = doc["bufferViews"]
        got_pos = np.frombuffer(binary[views[0]["byteOffset"]:][:12 * nv], "<f4").reshape(nv, 3)
        got_nrm = np.frombuffer(binary[views[1]["byteOffset"]:][:12 * nv], "<f4").reshape(nv, 3)
        got_idx = np.frombuffer(binary[views[2]["byteOffset"]:][:12 * nt], "<u4").reshape(nt, 3)
        assert np.array_equal(got_pos, vertices[:, :3]), "positions differ from the PLY's"
        assert np.array_equal(got_nrm, vertices[:, 3:]), "normals differ from the PLY's"
        assert np.array_equal(got_idx, faces), "indices differ from the PLY's"
        bounds = np.float32([doc["accessors"][0]["min"], doc["accessors"][0]["max"]])
        assert np.array_equal(bounds, [vertices[:, :3].min(0), vertices[:, :3].max(0)]), doc["accessors"][0]
        loaded = subprocess.run(["node", "tests/http/gltf_load.mjs", path, os.path.abspath("web")],
                                capture_output=True, text=True, timeout=60)
        tri, ver, normals, *_ = loaded.stdout.split()
        assert (int(tri), int(ver), normals) == (nt, nv, "true"), loaded.stdout + loaded.stderr
    check("mesh_glb_plain_validates_and_is_the_ply", glb_plain)

    # format=glb-meshopt: three's GLTFLoader with its MeshoptDecoder gets exactly the
    # mesh's triangles and vertices, and the PLY's bounding box within half a qp step; its
    # vertices are numbered by first use, so the two are compared corner by corner: each
    # triangle, in order, is the PLY's (a rotation of it) within half a qp step.
    # Its gzip form goes to a client that accepts gzip: the same bytes inflated, its own
    # ETag, and either ETag answers 304. The gzip form is made only when a client accepts
    # it (none before), then cached beside the body (the cache's bytes grow by its size).
    def glb_meshopt():
        if not os.path.isdir("web/node_modules/three"):
            raise Skip("web/node_modules/three not installed (make node-deps)")
        url = f"/v1/volumes/blob/mesh?level={level}&tolerance={tol}&format=glb-meshopt"
        r = s.get(url)
        assert r.status == 200 and r.getheader("Content-Type") == "model/gltf-binary", r.status
        assert r.getheader("Content-Encoding") is None and r.getheader("Vary") == "Accept-Encoding"
        assert r.getheader("X-Iso-Gzip-Ms") is None, "gzip made for a client that did not accept it"
        cached_bytes = s.metric("isoserve_mesh_cache_bytes")
        assert r.getheader("X-Iso-Draco-Speed") is None
        assert 'filename="blob-' in r.getheader("Content-Disposition") and ".glb\"" in r.getheader("Content-Disposition")
        path = os.path.join(tmp, "blob.meshopt.glb")
        open(path, "wb").write(r.body)
        corners_path = os.path.join(tmp, "blob.meshopt.corners")
        out = subprocess.run(["node", "tests/http/gltf_load.mjs", path, os.path.abspath("web"), corners_path],
                             capture_output=True, text=True, timeout=60)
        assert out.returncode == 0, out.stdout + out.stderr
        tri, ver, normals, *box = out.stdout.split()
        got = np.fromfile(corners_path, "<f4").astype(np.float64).reshape(-1, 3, 3)
        want_corners = state["corners"]
        assert got.shape == want_corners.shape, (got.shape, want_corners.shape)
        extent = (state["pos"].max(0) - state["pos"].min(0)).max()
        off = np.min([np.abs(np.roll(got, r, axis=1) - want_corners).max(axis=(1, 2)) for r in range(3)], axis=0)
        assert off.max() <= extent / (2 ** 14 - 1) / 2 * 1.01 + 1e-5, (off.max(), int(off.argmax()))
        assert (int(tri), int(ver)) == (int(r.getheader("X-Iso-Triangles")), int(r.getheader("X-Iso-Vertices")))
        assert (int(tri), int(ver)) == (state["nt"], len(state["pos"])), (tri, ver)
        assert normals == "true"
        box = np.array([float(x) for x in box]).reshape(2, 3)
        want = np.array([state["pos"].min(0), state["pos"].max(0)])
        half = (want[1] - want[0]).max() / (2 ** 14 - 1) / 2
        assert np.abs(box - want).max() <= half * 1.01 + 1e-5, (box, want)
        g = s.get(url, {"Accept-Encoding": "br, gzip;q=0.8"})
        assert g.status == 200 and g.getheader("Content-Encoding") == "gzip", g.getheader("Content-Encoding")
        assert g.getheader("Vary") == "Accept-Encoding" and g.getheader("X-Iso-Cache") == "hit"
        assert gzip.decompress(g.body) == r.body and len(g.body) <= 0.95 * len(r.body), (len(g.body), len(r.body))
        assert g.getheader("ETag") != r.getheader("ETag") and float(g.getheader("X-Iso-Gzip-Ms")) >= 0
        grew = s.metric("isoserve_mesh_cache_bytes") - cached_bytes
        assert grew == len(g.body), (grew, len(g.body))
        again = s.get(url, {"Accept-Encoding": "gzip"})
        assert again.body == g.body and s.metric("isoserve_mesh_cache_bytes") - cached_bytes == grew
        refused = s.get(url, {"Accept-Encoding": "gzip;q=0, identity"})
        assert refused.getheader("Content-Encoding") is None and refused.body == r.body
        assert refused.getheader("Vary") == "Accept-Encoding"
        for etag in (r.getheader("ETag"), g.getheader("ETag")):
            assert s.get(url, {"If-None-Match": etag}).status == 304, etag
        # A first request that accepts gzip gets the gzip form made with the body (beside
        # its encode); a later one without gzip gets the body it inflates to, from the cache.
        url2 = f"/v1/volumes/blob/mesh?level={level + 1e-3}&tolerance={tol}&format=glb-meshopt"
        before = s.metric("isoserve_mesh_cache_bytes")
        first = s.get(url2, {"Accept-Encoding": "gzip"})
        assert first.status == 200 and first.getheader("Content-Encoding") == "gzip", first.getheader("Content-Encoding")
        assert first.getheader("X-Iso-Cache") == "miss" and float(first.getheader("X-Iso-Gzip-Ms")) >= 0
        plain = s.get(url2)
        assert plain.getheader("X-Iso-Cache") == "hit" and plain.getheader("Content-Encoding") is None
        assert gzip.decompress(first.body) == plain.body and len(first.body) <= 0.95 * len(plain.body)
        grew = s.metric("isoserve_mesh_cache_bytes") - before
        assert grew == len(first.body) + len(plain.body), (grew, len(first.body), len(plain.body))
        # Draco is entropy coded already: never gzipped.
        d = s.get(f"/v1/volumes/blob/mesh?level={level}&tolerance={tol}&format=glb", {"Accept-Encoding": "gzip"})
        assert d.getheader("Content-Encoding") is None and d.getheader("Vary") is None
    check("mesh_glb_meshopt_gzip", glb_meshopt)

    def etag_and_cache():
        t = f"/v1/volumes/blob/mesh?level={level}&tolerance=3"
        a = s.get(t)
        b = s.get(f"/v1/volumes/blob/mesh?tolerance=3.0&level={level}&normals=tricubic&format=draco")
        assert a.status == b.status == 200
        etag = a.getheader("ETag")
        assert etag and etag.startswith('"') and etag == b.getheader("ETag"), (etag, b.getheader("ETag"))
        assert a.getheader("X-Iso-Cache") == "miss" and b.getheader("X-Iso-Cache") == "hit"
        assert a.body == b.body
        assert a.getheader("Cache-Control") == "public, max-age=31536000, immutable"
        c = s.get(t, {"If-None-Match": etag})
        assert c.status == 304 and c.body == b"" and c.getheader("ETag") == etag
        d = s.get(t, {"If-None-Match": f'"other", W/{etag}'})
        assert d.status == 304
        e = s.get(f"/v1/volumes/blob/mesh?level={level}&tolerance=4", {"If-None-Match": etag})
        assert e.status == 200 and e.getheader("ETag") != etag
    check("etag_304_and_cache", etag_and_cache)

    def cors():
        r = s.get(f"/v1/volumes/blob/mesh?level={level}&tolerance=3", {"Origin": "http://example.org"})
        assert r.getheader("Access-Control-Allow-Origin") == "*"
        exposed = r.getheader("Access-Control-Expose-Headers")
        for h in ("X-Iso-Triangles", "X-Iso-Error-Bound", "X-Iso-Tolerance", "ETag", "X-Iso-Simplified",
                  "X-Iso-Simplify-Error-Mm", "X-Iso-Simplify-Error-Voxels"):
            assert h in exposed, exposed
        p = s.request("OPTIONS", "/v1/volumes/blob/mesh", {"Origin": "http://example.org",
                                                          "Access-Control-Request-Method": "GET"})
        assert p.status == 204 and "GET" in p.getheader("Access-Control-Allow-Methods")
    check("cors_headers", cors)

    # budget=: the ladder up to the faithful tolerance (value range / 32) when it fits there;
    # below that, the exact mesh simplified by meshoptimizer, its error estimate in mm and
    # in voxels of the smallest spacing (0.75 mm here). The exact mesh has 3,004 triangles.
    def ply_mesh(r):
        head, _, payload = r.body.partition(b"end_header\n")
        nv = int(re.search(rb"element vertex (\d+)", head).group(1))
        nt = int(re.search(rb"element face (\d+)", head).group(1))
        assert len(payload) == nv * 12 + nt * 13
        pos = np.frombuffer(payload[:nv * 12], "<f4").reshape(nv, 3)
        faces = np.frombuffer(payload[nv * 12:], np.dtype([("n", "u1"), ("i", "<u4", 3)]))["i"]
        return pos, faces

    def assert_closed(faces):
        """Every directed edge used once, and its reverse once: closed and consistently oriented."""
        edges = {}
        for a, b, c in faces:
            for e in ((a, b), (b, c), (c, a)):
                edges[e] = edges.get(e, 0) + 1
        assert all(n == 1 and edges.get((b, a)) == 1 for (a, b), n in edges.items())

    def assert_exact_or_moved(pos, exact_pos, offset):
        """Every vertex one of exact_pos, or when offset is not 0, within |offset| of one
        (and further than float rounding from all: it moved)."""
        if offset == 0:
            assert {p.tobytes() for p in pos} <= {p.tobytes() for p in exact_pos}
            return
        e = exact_pos.astype(np.float64)
        nearest = np.array([np.linalg.norm(e - p, axis=1).min() for p in pos.astype(np.float64)])
        assert nearest.max() <= abs(offset) + 1e-4, (nearest.max(), offset)

    def count_pinches(faces):
        """Edges, edges of 3+ triangles, and vertices whose triangles make 2+ fans (joined
        through corners other than the vertex): the X-Iso-Edges / Pinch-* headers' counts."""
        uses, around = {}, {}
        for t in faces:
            t = [int(x) for x in t]
            for k in range(3):
                a, b = t[k], t[(k + 1) % 3]
                uses[(min(a, b), max(a, b))] = uses.get((min(a, b), max(a, b)), 0) + 1
                around.setdefault(a, []).append([x for x in t if x != a])
        pinch_vertices = 0
        for v, links in around.items():
            parent = list(range(len(links)))
            def root(i):
                while parent[i] != i:
                    i = parent[i]
                return i
            for i in range(len(links)):
                for j in range(i + 1, len(links)):
                    if set(links[i]) & set(links[j]):
                        parent[root(i)] = root(j)
            pinch_vertices += len({root(i) for i in range(len(links))}) > 1
        return len(uses), sum(n > 2 for n in uses.values()), pinch_vertices

    # When the faithful tolerance's mesh fits too, the answer is whichever of it and the
    # chain's finest level that fits is closer to the exact surface, by measurement: the
    # header says which, its distance and the other's.
    def budget_faithful():
        r = s.get(f"/v1/volumes/blob/mesh?level={level}&budget=3000&format=ply&normals=none")
        nt = int(r.getheader("X-Iso-Triangles"))
        assert r.status == 200 and 0 < nt <= 3000, nt
        assert r.getheader("X-Iso-Budget-Fits") == "true"
        source, p99 = r.getheader("X-Iso-Budget-Source"), float(r.getheader("X-Iso-Distance-Mm"))
        other = float(r.getheader("X-Iso-Budget-Other-Distance-Mm"))
        assert 0 < p99 <= other, (source, p99, other)
        t = float(r.getheader("X-Iso-Tolerance"))
        if source == "tolerance":
            assert 0 < t <= (float(blob.max()) - float(blob.min())) / 32, t
            assert r.getheader("X-Iso-Simplified") == "false" and r.getheader("X-Iso-Chain-Level") is None
        else:
            assert source == "chain" and t == 0 and int(r.getheader("X-Iso-Chain-Level")) == 1, source
        print(f"budget_source: {source}, {nt} triangles at p99 {p99:.4f} mm, the other at {other:.4f} mm",
              flush=True)
    check("budget_faithful_tolerance", budget_faithful)

    # X-Iso-Cells-Visited counts every extraction the request ran: a budget the faithful
    # ladder's mesh fits is compared with the chain's level by extracting that mesh, so a
    # request whose chain is cached still visits cells, whichever mesh answers (only one
    # the chain answers alone, under the faithful mesh's triangles, visits none:
    # tests/http/test_chain_file.py).
    def budget_cells_visited():
        q = "/v1/volumes/torus/mesh?level=0&budget=2000&normals=none&format="
        first, again = s.get(q + "ply"), s.get(q + "stl")  # the second finds the chain cached
        for r in (first, again):
            assert r.status == 200 and r.getheader("X-Iso-Budget-Fits") == "true", r.status
            assert float(r.getheader("X-Iso-Budget-Other-Distance-Mm")) > 0  # the ladder's, measured
            assert int(r.getheader("X-Iso-Cells-Visited")) > 0, (r.getheader("X-Iso-Budget-Source"),
                                                                  r.getheader("X-Iso-Cells-Visited"))
    check("budget_cells_visited", budget_cells_visited)

    def budget_simplified():
        exact = s.get(f"/v1/volumes/blob/mesh?level={level}&format=ply&normals=none&measures=true")
        assert int(exact.getheader("X-Iso-Triangles")) == 3004
        r = s.get(f"/v1/volumes/blob/mesh?level={level}&budget=400&format=ply&normals=none&measures=true")
        nt = int(r.getheader("X-Iso-Triangles"))
        assert r.status == 200 and 340 < nt <= 3004 >> 3, nt
        assert r.getheader("X-Iso-Budget-Fits") == "true" and r.getheader("X-Iso-Simplified") == "true"
        assert float(r.getheader("X-Iso-Tolerance")) == 0
        # From the chain: its finest level within the budget (level 6: 3004 / 2^3 = 375; its
        # levels are 1/sqrt(2) apart), the measured distance beside.
        assert int(r.getheader("X-Iso-Chain-Level")) == 6 and float(r.getheader("X-Iso-Distance-Mm")) > 0
        mm = float(r.getheader("X-Iso-Simplify-Error-Mm"))
        voxels = float(r.getheader("X-Iso-Simplify-Error-Voxels"))
        assert 0 < mm < 2 and abs(voxels - mm / 0.75) <= 1e-5 * voxels, (mm, voxels)
        pos, faces = ply_mesh(r)
        assert len(faces) == nt and len(pos) == int(r.getheader("X-Iso-Vertices"))
        # Every vertex is one of the exact mesh's, or (a level moved to keep the enclosed
        # volume) one moved by the offset along its normal, and the error bound then covers
        # its value error.
        exact_pos, _ = ply_mesh(exact)
        assert_exact_or_moved(pos, exact_pos, float(r.getheader("X-Iso-Vertex-Offset-Mm")))
        bound = float(r.getheader("X-Iso-Error-Bound"))
        index = pos.astype(np.float64) / np.array([0.75, 1.0, 1.25])
        assert np.abs(trilinear(blob.astype(np.float64), index) - level).max() <= bound + 1e-3
        # Still closed: every edge once each way. The enclosed volume: 400 triangles' chords
        # cut 2.5% off the exact mesh's (measured), which the offset along the normals gives
        # back: within 0.5%.
        assert_closed(faces)
        v, v0 = float(r.getheader("X-Iso-Volume-Mm3")), float(exact.getheader("X-Iso-Volume-Mm3"))
        assert abs(v - v0) <= 0.005 * v0, (v, v0)
    check("budget_simplified_with_error", budget_simplified)

    # distance=: the coarsest level of the surface's simplification chain whose measured
    # distance (p99 both ways) is within D mm; the chain is built by the first request at a
    # (level, tolerance, cap) and answers the next ones without extracting (0 cells).
    def point_triangles(p, tri):
        """Distance from each point of p (n x 3) to the nearest of triangles tri (m x 3 x 3),
        by projection onto each plane when the foot falls inside, else the nearest side."""
        a, b, c = tri[:, 0], tri[:, 1], tri[:, 2]
        n = np.cross(b - a, c - a)
        nn = np.einsum("ij,ij->i", n, n)
        best = np.full(len(p), np.inf)
        for i in range(0, len(p), 256):
            q = p[i:i + 256, None, :]
            h = np.einsum("pmj,mj->pm", q - a, n) / nn
            foot = q - h[..., None] * n
            inside = np.ones(h.shape, bool)
            for u, v in ((a, b), (b, c), (c, a)):
                inside &= np.einsum("pmj,mj->pm", np.cross(v - u, foot - u), n) >= 0
            d = np.where(inside, np.abs(h) * np.sqrt(nn), np.inf)
            for u, v in ((a, b), (b, c), (c, a)):
                e = v - u
                t = np.clip(np.einsum("pmj,mj->pm", q - u, e) / np.einsum("ij,ij->i", e, e), 0, 1)
                d = np.minimum(d, np.linalg.norm(q - (u + t[..., None] * e), axis=2))
            best[i:i + 256] = d.min(axis=1)
        return best

    def chain_target(triangles, k):
        """Level k's triangle target (iso_mesh_chain_target): levels 1/sqrt(2) apart."""
        half = triangles >> (k // 2)
        return int(half * 0.7071067811865476) if k % 2 else half

    def distance_from_chain():
        exact = s.get(f"/v1/volumes/blob/mesh?level={level}&format=ply&normals=none&measures=true")
        zero = s.get(f"/v1/volumes/blob/mesh?level={level}&distance=0&format=ply&normals=none")
        assert zero.status == 200 and zero.body == exact.body, zero.status
        assert zero.getheader("X-Iso-Chain-Level") == "0" and float(zero.getheader("X-Iso-Distance-Mm")) == 0
        assert int(zero.getheader("X-Iso-Exact-Triangles")) == 3004
        r = s.get(f"/v1/volumes/blob/mesh?level={level}&distance=0.3&format=ply&normals=none&measures=true")
        assert r.status == 200 and int(r.getheader("X-Iso-Cells-Visited")) == 0  # from the chain
        k, nt = int(r.getheader("X-Iso-Chain-Level")), int(r.getheader("X-Iso-Triangles"))
        p99, top = float(r.getheader("X-Iso-Distance-Mm")), float(r.getheader("X-Iso-Distance-Max-Mm"))
        assert k >= 1 and nt <= chain_target(3004, k) and 0 < p99 <= 0.3 and p99 <= top, (k, nt, p99, top)
        assert abs(float(r.getheader("X-Iso-Distance-Voxels")) - p99 / 0.75) <= 1e-5 * p99
        pos, faces = ply_mesh(r)
        exact_pos, exact_faces = ply_mesh(exact)
        assert_exact_or_moved(pos, exact_pos, float(r.getheader("X-Iso-Vertex-Offset-Mm")))
        # The header's maximum against an independent measure: the exact vertices' distances
        # to the mesh served (samples the server measures too, so at most its maximum) and
        # the served triangles' centroids' to the exact surface.
        served = pos.astype(np.float64)[faces]
        from_exact = point_triangles(exact_pos.astype(np.float64), served)
        to_exact = point_triangles(served.mean(axis=1), exact_pos.astype(np.float64)[exact_faces])
        assert from_exact.max() <= top + 1e-4 and to_exact.max() <= top + 1e-4, (from_exact.max(), top)
        assert max(from_exact.max(), to_exact.max()) >= 0.5 * top, (from_exact.max(), top)
        assert np.quantile(from_exact, 0.9) <= p99 + 1e-4, (np.quantile(from_exact, 0.9), p99)
        assert_closed(faces)
        counted = count_pinches(faces)
        assert counted == tuple(int(r.getheader(h)) for h in ("X-Iso-Edges", "X-Iso-Pinch-Edges",
                                                             "X-Iso-Pinch-Vertices")), counted
        assert counted[1] == counted[2] == 0, counted
        v, v0 = float(r.getheader("X-Iso-Volume-Mm3")), float(exact.getheader("X-Iso-Volume-Mm3"))
        print(f"distance_volume: chain level {k}: {nt} of 3004 triangles, p99 {p99:.4f} mm, "
               f"max {top:.4f} mm, enclosed volume {100 * (v - v0) / v0:+.3f}%", flush=True)
        assert abs(v - v0) <= 0.005 * v0, (v, v0)
        coarse = s.get(f"/v1/volumes/blob/mesh?level={level}&distance=100&format=ply&normals=none")
        assert int(coarse.getheader("X-Iso-Chain-Level")) == 12, coarse.getheader("X-Iso-Chain-Level")
        assert int(coarse.getheader("X-Iso-Triangles")) <= chain_target(3004, 12) == 3004 >> 6
        both = s.get(f"/v1/volumes/blob/mesh?level={level}&distance=1&budget=100")
        assert both.status == 400 and b"distance" in both.body, (both.status, both.body[:200])
        bad = s.get(f"/v1/volumes/blob/mesh?level={level}&distance=-1")
        assert bad.status == 400 and b"distance" in bad.body, (bad.status, bad.body[:200])
    check("distance_from_chain", distance_from_chain)

    # min_component=: closed components enclosing less (mm3) go before anything else, counted
    # in X-Iso-Components-Removed with the largest one's bounding-box diagonal; the blob is
    # one closed component of about 3004 triangles.
    def min_component_removed():
        exact = s.get(f"/v1/volumes/blob/mesh?level={level}&format=ply&normals=none")
        assert exact.getheader("X-Iso-Components-Removed") is None
        kept = s.get(f"/v1/volumes/blob/mesh?level={level}&distance=0.3&min_component=1&format=ply&normals=none")
        assert kept.status == 200 and kept.getheader("X-Iso-Components-Removed") == "0", kept.status
        assert float(kept.getheader("X-Iso-Removed-Largest-Mm")) == 0
        gone = s.get(f"/v1/volumes/blob/mesh?level={level}&distance=0.3&min_component=1e12&format=ply&normals=none")
        assert gone.status == 200 and gone.getheader("X-Iso-Components-Removed") == "1", gone.status
        assert int(gone.getheader("X-Iso-Triangles")) == 0
        pos, _ = ply_mesh(exact)
        diagonal = float(np.linalg.norm(pos.max(axis=0).astype(np.float64) - pos.min(axis=0)))
        largest = float(gone.getheader("X-Iso-Removed-Largest-Mm"))
        assert abs(largest - diagonal) <= 1e-5 * diagonal, (largest, diagonal)
        exact_gone = s.get(f"/v1/volumes/blob/mesh?level={level}&min_component=1e12&format=ply&normals=none")
        assert exact_gone.status == 200 and exact_gone.getheader("X-Iso-Components-Removed") == "1"
        bad = s.get(f"/v1/volumes/blob/mesh?level={level}&min_component=-1")
        assert bad.status == 400 and b"min_component" in bad.body, (bad.status, bad.body[:200])
    check("min_component_removed", min_component_removed)

    # measures=true: the same bytes, another cache entry, and the area and closedness of
    # exactly those triangles in the headers.
    def measures_on_request():
        plain = s.get(f"/v1/volumes/blob/mesh?level={level}&tolerance={tol}&format=ply&normals=none")
        r = s.get(f"/v1/volumes/blob/mesh?level={level}&tolerance={tol}&format=ply&normals=none&measures=true")
        assert r.status == 200 and r.body == plain.body and r.getheader("ETag") != plain.getheader("ETag")
        assert r.getheader("X-Iso-Cache") == "miss" and float(r.getheader("X-Iso-Measure-Ms")) >= 0
        pos, faces = ply_mesh(r)
        p = pos.astype(np.float64)[faces]
        area = 0.5 * np.linalg.norm(np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0]), axis=1).sum()
        header = float(r.getheader("X-Iso-Area-Mm2"))
        assert abs(area - header) <= 1e-5 * area, (area, header)
        assert r.getheader("X-Iso-Closed") == "true"
        enclosed = abs(np.einsum("ij,ij->i", p[:, 0], np.cross(p[:, 1], p[:, 2])).sum() / 6)
        assert abs(enclosed - float(r.getheader("X-Iso-Volume-Mm3"))) <= 1e-4 * enclosed
        bad = s.get(f"/v1/volumes/blob/mesh?level={level}&measures=yes")
        assert bad.status == 400 and b"measures" in bad.body, bad.status
    check("mesh_measures_on_request", measures_on_request)

    # cap=true&format=stl: a printable file. Its triangles weld into a closed surface (every
    # edge twice, in opposite directions) whose enclosed volume is the header's.
    def capped_stl():
        r = s.get(f"/v1/volumes/blob/mesh?level={level}&tolerance={tol}&cap=true&format=stl&normals=none&measures=true")
        assert r.status == 200 and r.getheader("Content-Type") == "model/stl", r.status
        assert not r.body.startswith(b"solid")
        nt = struct.unpack_from("<I", r.body, 80)[0]
        assert nt == int(r.getheader("X-Iso-Triangles")) and len(r.body) == 84 + 50 * nt
        rec = np.frombuffer(r.body[84:], dtype=np.dtype([("n", "<f4", 3), ("v", "<f4", (3, 3)), ("a", "<u2")]))
        corners = rec["v"].reshape(-1, 3)
        _, ids = np.unique(corners, axis=0, return_inverse=True)
        tri = ids.reshape(-1, 3)
        directed = {(int(a), int(b)) for t in tri for a, b in ((t[0], t[1]), (t[1], t[2]), (t[2], t[0]))}
        assert len(directed) == 3 * nt, "an edge is used twice in one direction"
        assert all((b, a) in directed for a, b in directed), "an edge has no opposite twin: open"
        v = rec["v"].astype(np.float64)
        enclosed = abs(np.einsum("ij,ij->i", v[:, 0], np.cross(v[:, 1], v[:, 2])).sum() / 6)
        header = float(r.getheader("X-Iso-Volume-Mm3"))
        assert abs(enclosed - header) <= 1e-4 * header, (enclosed, header)
        plain = s.get(f"/v1/volumes/blob/mesh?level={level}&tolerance={tol}&format=stl&normals=none")
        assert plain.status == 200 and plain.getheader("ETag") != r.getheader("ETag")
    check("mesh_cap_stl_closed", capped_stl)

    def empty_mesh():
        r = s.get("/v1/volumes/blob/mesh?level=1e6")
        assert r.status == 200 and r.getheader("X-Iso-Triangles") == "0" and len(r.body) > 0
    check("empty_mesh_is_200", empty_mesh)

    def errors():
        cases = [
            ("/v1/volumes/blob/mesh", 400, "level", "required"),
            ("/v1/volumes/blob/mesh?level=abc", 400, "level", "not a number"),
            ("/v1/volumes/blob/mesh?level=nan", 400, "level", "finite"),
            ("/v1/volumes/blob/mesh?level=1&tolerance=inf", 400, "tolerance", "finite"),
            ("/v1/volumes/blob/mesh?level=1&tolerance=-2", 400, "tolerance", "from 0"),
            ("/v1/volumes/blob/mesh?level=1&qp=30", 400, "qp", "from 8 to 24"),
            ("/v1/volumes/blob/mesh?level=1&normals=flat", 400, "normals", "tricubic"),
            ("/v1/volumes/blob/mesh?level=1&format=obj", 400, "format", "stl"),
            ("/v1/volumes/blob/mesh?level=1&cap=yes", 400, "cap", "true or false"),
            ("/v1/volumes/blob/mesh?level=1&level=2", 400, "level", "more than once"),
            ("/v1/volumes/blob/mesh?level=1&colour=red", 400, None, "unknown parameter"),
            ("/v1/volumes/nope/mesh?level=1", 404, None, "nope"),
            ("/v1/volumes/nope", 404, None, "nope"),
            ("/v1/volumes/blob/other", 404, None, "no such resource"),
            ("/v1/elsewhere", 404, None, "no such resource"),
            ("/v1/volumes/..%2F..%2Fetc%2Fpasswd/mesh?level=1", 404, None, "not a valid id"),
            ("/v1/volumes/bl%20ob/mesh?level=1", 404, None, "not a valid id"),
            ("/v1/volumes/blob/mesh?level=1&" + "x" * 5000, 414, None, "bytes"),
        ]
        for target, status, param, words in cases:
            r = s.get(target)
            assert r.status == status, f"{target[:80]}: {r.status} {r.body[:200]}"
            body = problem(r)
            assert body.get("parameter") == param, f"{target[:60]}: {body}"
            assert words in body["detail"], f"{target[:60]}: {body['detail']}"
        r = s.request("POST", "/v1/volumes")
        assert r.status == 405 and "GET" in r.getheader("Allow") and problem(r)
        r = s.request("DELETE", "/v1/volumes/blob")
        assert r.status == 405 and problem(r)
    check("error_statuses_and_problems", errors)

    def metrics_and_log():
        text = s.get("/metrics").body.decode()
        for needle in ('isoserve_http_requests_total{route="mesh",status="200"}',
                       'isoserve_http_requests_total{route="mesh",status="400"}',
                       'isoserve_http_request_duration_seconds_bucket{route="mesh",le="+Inf"}',
                       "isoserve_mesh_cache_hits_total", "isoserve_mesh_cache_misses_total",
                       "isoserve_http_response_bytes_total", "isoserve_extractions_in_flight 0",
                       "isoserve_extraction_queue_length 0", "isoserve_hierarchy_bytes"):
            assert needle in text, f"{needle} not in /metrics"
        assert s.metric("isoserve_mesh_cache_hits_total") >= 1, "no cache hit counted"
        assert s.wait_log(r"^\S+Z GET /v1/volumes/blob/mesh 200 \d+ [\d.]+ms$"), s.log()[-500:]
        assert s.wait_log(r"^\S+Z POST /v1/volumes 405 \d+ [\d.]+ms$"), "no 405 log line"
    check("metrics_and_access_log", metrics_and_log)

    def static_files():
        r = s.get("/")
        assert r.status == 200 and b"isoserve test page" in r.body, r.status
        assert r.getheader("Content-Type").startswith("text/html")
        for bad in ("/../../etc/passwd", "/.secret", "/missing.js", "/%2e%2e/%2e%2e/etc/passwd"):
            r = s.get(bad)
            assert r.status == 404, (bad, r.status)
    check("static_files_and_traversal", static_files)

    def coalescing():
        # ml:160 at tolerance 0 with tricubic normals takes long enough for 8 requests to meet.
        before_x = s.metric("isoserve_extractions_total")
        before_c = s.metric("isoserve_coalesced_requests_total")
        before_h = s.metric("isoserve_mesh_cache_hits_total")
        results = []

        def fetch():
            r = s.get("/v1/volumes/ml/mesh?level=0.5&tolerance=0")
            results.append((r.status, r.getheader("ETag"), len(r.body)))
        threads = [threading.Thread(target=fetch) for _ in range(8)]
        for t in threads:
            t.start()
        for t in threads:
            t.join()
        assert len(results) == 8 and all(r[0] == 200 for r in results), results
        assert len({r[1:] for r in results}) == 1, results
        dx = s.metric("isoserve_extractions_total") - before_x
        dc = s.metric("isoserve_coalesced_requests_total") - before_c
        dh = s.metric("isoserve_mesh_cache_hits_total") - before_h
        assert dx == 1 and dc + dh == 7 and dc >= 1, f"extractions +{dx}, coalesced +{dc}, hits +{dh}"
    check("coalescing_one_extraction", coalescing)


# ---------------------------------------------------------------- other servers

def queue_full(tmp, catalog):
    s = Server(["--catalog", catalog, "--threads", "1", "--queue", "1", "--web-root", tmp])
    try:
        statuses = {}

        def fetch(level):
            r = s.get(f"/v1/volumes/ml/mesh?level={level}&tolerance=0")
            statuses[level] = (r.status, r.getheader("Retry-After"), r)
        levels = [0.3, 0.4, 0.45, 0.55, 0.6, 0.7]
        threads = [threading.Thread(target=fetch, args=(lv,)) for lv in levels]
        for t in threads:
            t.start()
            time.sleep(0.02)
        for t in threads:
            t.join()
        codes = sorted(v[0] for v in statuses.values())
        assert codes.count(503) >= 1 and codes.count(200) >= 2, codes
        for st, retry, r in statuses.values():
            if st == 503:
                assert retry == "1" and "queue is full" in problem(r)["detail"]
        assert s.metric("isoserve_rejected_requests_total") == codes.count(503)
        assert 'route="mesh",status="503"' in s.get("/metrics").body.decode()
    finally:
        s.stop()


def graceful_shutdown(tmp, catalog):
    s = Server(["--catalog", catalog, "--threads", "1", "--web-root", tmp])
    result = {}

    def fetch():
        result["r"] = s.get("/v1/volumes/ml/mesh?level=0.52&tolerance=0")
    t = threading.Thread(target=fetch)
    t.start()
    deadline = time.time() + 10
    while time.time() < deadline and s.metric("isoserve_extractions_in_flight") != 1:
        time.sleep(0.005)
    s.proc.send_signal(signal.SIGTERM)
    t.join(timeout=60)
    rc = s.proc.wait(timeout=30)
    assert rc == 0, f"exit status {rc}"
    r = result.get("r")
    assert r is not None and r.status == 200 and len(r.body) > 1000, r and r.status
    assert int(r.getheader("X-Iso-Triangles")) > 1000
    try:
        http.client.HTTPConnection("127.0.0.1", s.port, timeout=2).request("GET", "/healthz")
        raise AssertionError("still accepting after shutdown")
    except OSError:
        pass
    assert re.search(r"finishing \d+ requests in flight", s.log()) and "stopped" in s.log(), s.log()[-400:]


def preload_and_cache_dir(tmp):
    cache = os.path.join(tmp, "hier")
    cat = os.path.join(tmp, "big.json")
    json.dump({"volumes": [{"id": "big", "path": "field:ml:224"},
                           {"id": "gone", "path": "missing.nrrd"},
                           {"id": "bad id!", "path": "field:sphere:8"},
                           {"id": "small", "path": "field:sphere:24", "levels": [2]}]},
              open(cat, "w"))
    s = Server(["--catalog", cat, "--cache-dir", cache, "--web-root", tmp], wait_ready=False)
    try:
        first = s.get("/healthz")
        early = s.get("/v1/volumes")
        s.wait_ready()
        assert first.status == 503 and first.getheader("Retry-After") and json.loads(first.body)["status"] == "loading", first.status
        assert early.status == 503 and problem(early)
        ids = [v["id"] for v in json.loads(s.get("/v1/volumes").body)["volumes"]]
        assert ids == ["big", "small"], ids
        assert "missing.nrrd" in s.log() and "bad id!" in s.log()
        v = json.loads(s.get("/v1/volumes/big").body)
        assert v["hierarchy"]["from_file"] is False
    finally:
        assert s.stop() == 0
    files = sorted(f for f in os.listdir(cache) if ".isochain" not in f)  # the background's chains aside
    assert files == ["big.isotree", "small.isotree"], files
    s = Server(["--catalog", cat, "--cache-dir", cache, "--web-root", tmp])
    try:
        assert json.loads(s.get("/v1/volumes/big").body)["hierarchy"]["from_file"] is True
        assert "big: 224x224x224 f32, hierarchy read" in s.log(), s.log()
    finally:
        s.stop()
    # A damaged file is refused, rebuilt and rewritten; the volume is still served.
    path = os.path.join(cache, "small.isotree")
    data = bytearray(open(path, "rb").read())
    data[80] ^= 0xFF
    open(path, "wb").write(data)
    s = Server(["--catalog", cat, "--cache-dir", cache, "--web-root", tmp])
    try:
        assert "small" in s.log() and "rebuilding" in s.log(), s.log()
        assert json.loads(s.get("/v1/volumes/small").body)["hierarchy"]["from_file"] is False
        assert s.get("/v1/volumes/small/mesh?level=2").status == 200
    finally:
        s.stop()
    assert open(path, "rb").read() != bytes(data)


def orientation_and_padding(tmp):
    """A CT-like scan (air -1000, tissue 40, bone 1200) whose corners outside the
    reconstruction circle hold -2000 on every slice, with spacings only: its orientation is
    "none" and its suggested levels skip the padding; the same file with a catalog
    "orientation" is "catalog" with that map; a header with a space is "file"; a bad code is
    refused by name."""
    z, y, x = np.mgrid[0:16, 0:40, 0:40].astype(np.float64)
    r2 = (x - 19.5) ** 2 + (y - 19.5) ** 2
    data = np.full(z.shape, -1000.0)
    data[r2 + 4 * (z - 8) ** 2 < 14 ** 2] = 40
    data[r2 + 4 * (z - 8) ** 2 < 8 ** 2] = 1200
    data[r2 > 19 ** 2] = -2000
    write_nrrd(os.path.join(tmp, "scan.nrrd"), data, (0.5, 0.5, 2))
    with open(os.path.join(tmp, "spaced.nrrd"), "wb") as f:
        f.write(b"NRRD0004\ntype: float\ndimension: 3\nsizes: 40 40 16\nspace: left-posterior-superior\n"
                b"space directions: (0.5,0,0) (0,0.5,0) (0,0,2)\nendian: little\nencoding: raw\n\n")
        f.write(data.astype("<f4").tobytes())
    cat = os.path.join(tmp, "oriented.json")
    json.dump({"volumes": [{"id": "scan", "path": "scan.nrrd"},
                           {"id": "scan-lpi", "path": "scan.nrrd", "orientation": "LPI"},
                           {"id": "spaced", "path": "spaced.nrrd"},
                           {"id": "bad", "path": "scan.nrrd", "orientation": "LPX"}]}, open(cat, "w"))
    s = Server(["--catalog", cat, "--web-root", tmp])
    try:
        vols = {v["id"]: v for v in json.loads(s.get("/v1/volumes").body)["volumes"]}
        assert sorted(vols) == ["scan", "scan-lpi", "spaced"], sorted(vols)
        assert 'volume "bad": "orientation" must be three letters' in s.log(), s.log()
        assert [vols[v]["orientation"] for v in ("scan", "scan-lpi", "spaced")] == ["none", "catalog", "file"]
        assert vols["scan"]["index_to_world"][:12] == [0.5, 0, 0, 0, 0, 0.5, 0, 0, 0, 0, 2, 0]
        assert vols["scan-lpi"]["index_to_world"][:12] == [0.5, 0, 0, 0, 0, 0.5, 0, 0, 0, 0, -2, 0]
        levels = vols["scan"]["suggested_levels"]
        assert len(levels) == 2 and -1000 < levels[0] < 40 < levels[1] < 1200, levels
        doc = json.loads(s.get("/v1/volumes/scan").body)
        assert doc["padding"] == -2000 and doc["orientation"] == "none", doc.get("padding")
        # The flipped map keeps the surface's winding: the same enclosed volume, closed.
        heads = [s.request("HEAD", f"/v1/volumes/{v}/mesh?level={levels[1]}&format=ply&measures=true")
                 for v in ("scan", "scan-lpi")]
        assert [h.getheader("X-Iso-Closed") for h in heads] == ["true", "true"]
        assert heads[0].getheader("X-Iso-Volume-Mm3") == heads[1].getheader("X-Iso-Volume-Mm3")
    finally:
        s.stop()


def volumes_dir(tmp, blob):
    d = os.path.join(tmp, "dir")
    os.mkdir(d)
    write_nrrd(os.path.join(d, "blob.nrrd"), blob, (1, 1, 1))
    with open(os.path.join(d, "detached.nhdr"), "w") as f:
        f.write("NRRD0004\ntype: uint8\ndimension: 3\nsizes: 4 4 4\nencoding: raw\ndata file: detached.raw\n")
    open(os.path.join(d, "detached.raw"), "wb").write(bytes(range(64)))
    open(os.path.join(d, "broken.nrrd"), "wb").write(b"NRRD0004\ntype: float\n")
    open(os.path.join(d, ".hidden.nrrd"), "wb").write(b"")
    open(os.path.join(d, "notes.txt"), "w").write("not a volume")
    open(os.path.join(d, "side.raw"), "wb").write(bytes(range(27)))
    json.dump({"dims": [3, 3, 3], "type": "uint8"}, open(os.path.join(d, "side.raw.json"), "w"))
    s = Server(["--volumes", d, "--web-root", tmp])
    try:
        listed = json.loads(s.get("/v1/volumes").body)["volumes"]
        ids = [v["id"] for v in listed]
        assert ids == ["blob", "detached", "side"], ids
        assert "broken.nrrd" in s.log() and "skipped" in s.log()
    finally:
        s.stop()
    # `isoserve info --json` gives each volume's entry as /v1/volumes does, field for field.
    for entry, name in zip(listed, ["blob.nrrd", "detached.nhdr", "side.raw"]):
        info = json.loads(subprocess.run([BIN, "info", os.path.join(d, name), "--json"], check=True,
                                         capture_output=True, text=True).stdout)
        assert {k: info.get(k) for k in entry} == entry, (entry, info)
        assert len(entry) >= 11 and entry["suggested_levels"], entry


def cors_origins(tmp, catalog):
    s = Server(["--catalog", catalog, "--cors-origin", "https://viewer.example", "--web-root", tmp])
    try:
        r = s.get("/v1/volumes", {"Origin": "https://viewer.example"})
        assert r.getheader("Access-Control-Allow-Origin") == "https://viewer.example"
        assert "Origin" in r.getheader("Vary")
        r = s.get("/v1/volumes", {"Origin": "https://evil.example"})
        assert r.getheader("Access-Control-Allow-Origin") is None
    finally:
        s.stop()


def default_collection(tmp):
    """No catalog: Debian's mricron-data templates (NIfTI) and the phantoms."""
    if LABEL != "http":
        raise Skip("the default collection preloads 60 M voxels; checked in the normal build only")
    s = Server(["--web-root", tmp])
    try:
        vols = {v["id"]: v for v in json.loads(s.get("/v1/volumes").body)["volumes"]}
        want = {"marschner-lobb", "torus", "sphere"}
        if os.path.exists("/usr/share/mricron/templates/ch2bet.nii.gz"):
            want |= {"ch2bet", "ch2", "ch2better"}
        assert set(vols) == want, sorted(vols)
        if "ch2bet" in vols:
            v = vols["ch2bet"]
            assert v["dims"] == [181, 217, 181] and v["value_type"] == "uint8", v
            assert v["suggested_levels"] == [30.0, 90.0] and v["modality"] == "MR"
            assert v["index_to_world"][:4] == [-1.0, 0.0, 0.0, 90.0], v["index_to_world"]
            r = s.get("/v1/volumes/ch2bet/mesh?level=30&tolerance=5&normals=none")
            assert r.status == 200 and int(r.getheader("X-Iso-Triangles")) > 10000
    finally:
        assert s.stop() == 0


def bad_options():
    for args, words in ((["--listen", "nowhere"], "HOST:PORT"),
                        (["--threads", "0"], "--threads"),
                        (["--catalog", "/nonexistent.json"], "nonexistent.json"),
                        (["--catalog", "a", "--volumes", "b"], "not both"),
                        (["--bogus", "1"], "--bogus")):
        p = subprocess.run([BIN, "serve", *args], capture_output=True, text=True, timeout=30)
        assert p.returncode == 1 and words in p.stderr, (args, p.returncode, p.stderr)


def main():
    if not os.access(BIN, os.X_OK):
        print(f"FAIL {LABEL}.binary: {BIN} missing (run make)")
        return 1
    tmp = tempfile.mkdtemp(prefix="isoserve-http-")
    try:
        blob = blob_volume()
        write_nrrd(os.path.join(tmp, "blob.nrrd"), blob, (0.75, 1.0, 1.25))
        open(os.path.join(tmp, "index.html"), "w").write("<!doctype html><title>isoserve test page</title>")
        catalog = os.path.join(tmp, "catalog.json")
        json.dump({"volumes": [
            {"id": "blob", "path": "blob.nrrd", "name": "Two blobs", "modality": "phantom"},
            {"id": "torus", "path": "field:torus:64", "levels": [0]},
            {"id": "ml", "path": "field:ml:160", "levels": [0.5]}]}, open(catalog, "w"))
        s = Server(["--catalog", catalog, "--web-root", tmp, "--threads", "2"])
        try:
            main_tests(s, tmp, blob)
        finally:
            rc = s.stop()
            report("sigterm_exits_0", rc == 0, f"exit status {rc}")
        check("queue_full_503", lambda: queue_full(tmp, catalog))
        check("graceful_shutdown_finishes_request", lambda: graceful_shutdown(tmp, catalog))
        check("preload_healthz_and_cache_dir", lambda: preload_and_cache_dir(tmp))
        check("volumes_dir_ids", lambda: volumes_dir(tmp, blob))
        check("orientation_and_padding", lambda: orientation_and_padding(tmp))
        check("cors_configured_origins", lambda: cors_origins(tmp, catalog))
        check("default_collection", lambda: default_collection(tmp))
        check("bad_options", bad_options)
    finally:
        shutil.rmtree(tmp, ignore_errors=True)
    return 1 if RESULTS.failures else 0


if __name__ == "__main__":
    sys.exit(main())
