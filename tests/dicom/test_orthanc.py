"""DICOM series end to end: from a folder and from an Orthanc server, through `isoserve`.

A phantom CT series (RLE Lossless, written by tests/support/dicom_series.py) is served from
its folder and, uploaded over REST to a real Orthanc (Debian's `Orthanc`, on 127.0.0.1 with
a temporary storage dir, its DICOM port off, remote access and authentication off), from
Orthanc: the two meshes must be byte-identical. An unreachable Orthanc and an unknown series
give 502 problems that name the volume and the cause while the rest of the catalog serves;
the fetched files and the hierarchy are cached and serve again with Orthanc stopped. Also
the CLI on a series folder and `--volumes` with a series subdirectory. Servers are stopped
by PID. Prints PASS/FAIL/SKIP lines; exit status 1 on failure."""

import json
import os
import shutil
import socket
import subprocess
import sys
import tempfile
import time
import urllib.request

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, os.path.join(HERE, "..", "support"))
sys.path.insert(0, os.path.join(HERE, "..", "http"))
from results import Results, Skip  # noqa: E402 - found through the path just set
from test_http import BIN, Server, problem  # noqa: E402 - the daemon driver, shared

LABEL = "dicom" + os.environ.get("ISO_SAN_SUFFIX", "")  # tests/run.sh's asan pass says dicom-san
RESULTS = Results(LABEL)
report, check = RESULTS.report, RESULTS.check
HELPER = os.path.join(HERE, "..", "support", "dicom_series.py")
ORTHANC = shutil.which("Orthanc")
MESH = "/mesh?level=0&format=ply&normals=none"


def free_port():
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


class Orthanc:
    """Debian's Orthanc on 127.0.0.1 with its storage in tmp; stopped by PID."""

    def __init__(self, tmp):
        self.port = free_port()
        self.url = f"http://127.0.0.1:{self.port}"
        storage = os.path.join(tmp, "orthanc-db")
        config = {"Name": "isoserve-test", "StorageDirectory": storage, "IndexDirectory": storage,
                  "HttpPort": self.port, "DicomServerEnabled": False, "DicomPort": free_port(),
                  "RemoteAccessAllowed": False, "AuthenticationEnabled": False, "Plugins": []}
        path = os.path.join(tmp, "orthanc.json")
        with open(path, "w") as f:
            json.dump(config, f)
        self.log = open(os.path.join(tmp, "orthanc.log"), "w")
        self.proc = subprocess.Popen([ORTHANC, path], stdout=self.log, stderr=subprocess.STDOUT)
        deadline = time.time() + 30
        while time.time() < deadline and self.proc.poll() is None:
            try:
                urllib.request.urlopen(self.url + "/system", timeout=1).read()
                return
            except OSError:
                time.sleep(0.1)
        self.stop()
        raise RuntimeError("Orthanc did not start: " + open(os.path.join(tmp, "orthanc.log")).read()[-2000:])

    def upload(self, folder):
        """POST /instances for each file; returns the Orthanc id of their series."""
        series = set()
        for name in sorted(os.listdir(folder)):
            with open(os.path.join(folder, name), "rb") as f:
                req = urllib.request.Request(self.url + "/instances", data=f.read(), method="POST",
                                             headers={"Content-Type": "application/dicom"})
            series.add(json.load(urllib.request.urlopen(req, timeout=30))["ParentSeries"])
        assert len(series) == 1, series
        return series.pop()

    def stop(self):
        if self.proc.poll() is None:
            self.proc.terminate()
        self.proc.wait(timeout=30)
        self.log.close()


def write_catalog(tmp, entries):
    path = os.path.join(tmp, "catalog.json")
    with open(path, "w") as f:
        json.dump({"volumes": entries}, f)
    return path


def mesh(s, vid):
    r = s.get(f"/v1/volumes/{vid}{MESH}")
    assert r.status == 200, (r.status, r.body[:300])
    return r


def orthanc_tests(tmp, series_dir):
    pacs = Orthanc(tmp)
    try:
        sid = pacs.upload(series_dir)
        cache = os.path.join(tmp, "cache")
        catalog = write_catalog(tmp, [
            {"id": "disk", "path": series_dir},
            {"id": "pacs", "orthanc": {"url": pacs.url + "/", "series": sid}},
            # not the uploaded series' id: that one is in the cache once "pacs" is loaded,
            # and a cached series is read without asking any server
            {"id": "down", "orthanc": {"url": f"http://127.0.0.1:{free_port()}", "series": "fedcba98-0001"}},
            {"id": "unknown", "orthanc": {"url": pacs.url, "series": "0123abcd-0000"}}])
        s = Server(["--catalog", catalog, "--cache-dir", cache])
        try:
            served_tests(s, sid, cache)
        finally:
            rc = s.stop()
            report("orthanc_daemon_exits_0", rc == 0, f"exit status {rc}\n{s.log()[-3000:]}")
    finally:
        pacs.stop()
    # Orthanc is gone: the cached series and hierarchy serve the same mesh.
    s = Server(["--catalog", catalog, "--cache-dir", cache])
    try:
        def cached():
            a, b = mesh(s, "disk"), mesh(s, "pacs")
            assert a.body == b.body, "the cached series' mesh differs"
            assert "pacs: " in s.log() and "hierarchy read" in s.log(), s.log()[-2000:]
        check("orthanc_cache_serves_without_server", cached)
    finally:
        s.stop()


def served_tests(s, sid, cache):
    def same_mesh():
        a, b = mesh(s, "disk"), mesh(s, "pacs")
        tris = int(a.getheader("X-Iso-Triangles"))
        assert tris > 1000, tris
        assert a.body == b.body, f"{len(a.body)} vs {len(b.body)} bytes"
        assert b.getheader("X-Iso-Triangles") == a.getheader("X-Iso-Triangles")
        report_numbers["triangles"] = tris
    check("orthanc_mesh_equals_folder_mesh", same_mesh)

    def unreachable():
        r = s.get("/v1/volumes/down" + MESH)
        body = problem(r)
        assert r.status == 502, r.status
        assert '"down"' in body["detail"] and "connect" in body["detail"].lower(), body["detail"]
    check("orthanc_unreachable_is_502", unreachable)

    def unknown_series():
        r = s.get("/v1/volumes/unknown")
        body = problem(r)
        assert r.status == 502, r.status
        assert '"unknown"' in body["detail"] and "HTTP 404" in body["detail"], body["detail"]
        assert mesh(s, "disk").status == 200  # the rest of the catalog keeps serving
    check("orthanc_unknown_series_is_502", unknown_series)

    def cached_files():
        folder = os.path.join(cache, "orthanc", sid)
        names = os.listdir(folder)
        assert len(names) == 24 and all(n.endswith(".dcm") for n in names), names
        assert os.path.exists(os.path.join(cache, "pacs.isotree"))
        assert not [n for n in os.listdir(os.path.join(cache, "orthanc")) if "partial" in n]
    check("orthanc_series_cached_by_id", cached_files)


report_numbers = {}


def cli_tests(tmp, series_dir):
    def extract_folder():
        out = os.path.join(tmp, "cli.ply")
        r = subprocess.run([BIN, "extract", series_dir, "--level", "0", "-o", out, "--normals", "none"],
                           capture_output=True, text=True)
        assert r.returncode == 0, r.stderr
        head = open(out, "rb").read(400).split(b"end_header")[0].decode()
        faces = int([line for line in head.splitlines() if line.startswith("element face")][0].split()[2])
        assert faces == report_numbers.get("triangles", faces) and faces > 1000, faces
    check("cli_extract_series_folder", extract_folder)

    def wrong_uid():
        r = subprocess.run([BIN, "info", series_dir + "#1.2.3"], capture_output=True, text=True)
        assert r.returncode == 1 and "no series 1.2.3" in r.stderr and "24 files" in r.stderr, r.stderr
    check("cli_names_the_missing_series", wrong_uid)

    def volumes_dir():
        vols = os.path.join(tmp, "vols")
        os.makedirs(vols)
        shutil.copytree(series_dir, os.path.join(vols, "phantom"))
        os.makedirs(os.path.join(vols, "not-a-series"))
        s = Server(["--volumes", vols])
        try:
            ids = [v["id"] for v in json.loads(s.get("/v1/volumes").body)["volumes"]]
            assert ids == ["phantom"], ids
        finally:
            s.stop()
    check("volumes_dir_takes_series_subdirectory", volumes_dir)


def main():
    tmp = tempfile.mkdtemp(prefix="isoserve-dicom-")
    try:
        series_dir = os.path.join(tmp, "phantom")
        r = subprocess.run(["/usr/bin/python3", HELPER, "phantom", series_dir, "--rle"],
                           capture_output=True, text=True)
        if r.returncode != 0:
            print(f"SKIP {LABEL}.all: cannot write a series with pydicom: {r.stderr.strip()[-300:]}")
            return 0
        if ORTHANC:
            orthanc_tests(tmp, series_dir)
        else:
            print(f"SKIP {LABEL}.orthanc: Debian's orthanc is not installed (scripts/setup.sh installs it)")
        cli_tests(tmp, series_dir)
    finally:
        shutil.rmtree(tmp, ignore_errors=True)
    return 1 if RESULTS.failures else 0


if __name__ == "__main__":
    sys.exit(main())
