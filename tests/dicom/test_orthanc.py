"""DICOM series end to end: from a folder and from an Orthanc server, through `isoserve`.

A phantom CT series (RLE Lossless, written by tests/support/dicom_series.py) is served from
its folder and, uploaded over REST to a real Orthanc (Debian's `Orthanc`, on 127.0.0.1 with
a temporary storage dir, its DICOM port off, remote access and authentication off), from
Orthanc: the two meshes must be byte-identical. An unreachable Orthanc and an unknown series
give 503 problems (with Retry-After) that name the volume and the cause while the rest of
the catalog serves; an archive stopped and started again under load recovers without a
restart (503 meanwhile, attempts backing off);
the fetched files and the hierarchy are cached and serve again with Orthanc stopped. Also
the CLI on a series folder and `--volumes` with a series subdirectory. Servers are stopped
by PID. Prints PASS/FAIL/SKIP lines; exit status 1 on failure."""

import base64
import glob
import json
import os
import re
import threading
import shutil
import subprocess
import sys
import tempfile
import time
import urllib.request

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, os.path.join(HERE, "..", "support"))
sys.path.insert(0, os.path.join(HERE, "..", "http"))
from results import Results, Skip  # noqa: E402 - found through the path just set
from ports import free_port  # noqa: E402
from test_http import BIN, Server, problem  # noqa: E402 - the daemon driver, shared

LABEL = "dicom" + os.environ.get("ISO_SAN_SUFFIX", "")  # tests/run.sh's asan pass says dicom-san
RESULTS = Results(LABEL)
report, check = RESULTS.report, RESULTS.check
HELPER = os.path.join(HERE, "..", "support", "dicom_series.py")
# Debian installs Orthanc in /usr/sbin, which a normal user's PATH often lacks.
ORTHANC = shutil.which("Orthanc") or shutil.which("Orthanc", path="/usr/sbin:/usr/local/sbin")
MESH = "/mesh?level=0&format=ply&normals=none"


class Orthanc:
    """Debian's Orthanc on 127.0.0.1 with its storage in tmp; stopped by PID. port: the
    port of an earlier instance to start again on (its storage is kept)."""

    def __init__(self, tmp, port=None, extra=None, auth=None):
        """extra: more configuration (plugins); auth: (user, password) Orthanc requires."""
        self.port = port or free_port()
        self.url = f"http://127.0.0.1:{self.port}"
        self.headers = {}
        storage = os.path.join(tmp, "orthanc-db")
        config = {"Name": "isoserve-test", "StorageDirectory": storage, "IndexDirectory": storage,
                  "HttpPort": self.port, "DicomServerEnabled": False, "DicomPort": free_port(),
                  "RemoteAccessAllowed": False, "AuthenticationEnabled": False, "Plugins": []}
        if auth:
            config.update(AuthenticationEnabled=True, RegisteredUsers={auth[0]: auth[1]})
            self.headers["Authorization"] = "Basic " + base64.b64encode(f"{auth[0]}:{auth[1]}".encode()).decode()
        config.update(extra or {})
        path = os.path.join(tmp, "orthanc.json")
        with open(path, "w") as f:
            json.dump(config, f)
        self.log = open(os.path.join(tmp, "orthanc.log"), "a")
        self.proc = subprocess.Popen([ORTHANC, path], stdout=self.log, stderr=subprocess.STDOUT)
        deadline = time.time() + 30
        while time.time() < deadline and self.proc.poll() is None:
            try:
                urllib.request.urlopen(urllib.request.Request(self.url + "/system", headers=self.headers),
                                       timeout=1).read()
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
                                             headers={"Content-Type": "application/dicom", **self.headers})
            series.add(json.load(urllib.request.urlopen(req, timeout=30))["ParentSeries"])
        assert len(series) == 1, series
        return series.pop()

    def get_json(self, path):
        req = urllib.request.Request(self.url + path, headers=self.headers)
        return json.load(urllib.request.urlopen(req, timeout=30))

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

    def described_by_instances():
        # The catalog names neither: name and modality come from the instances, and the
        # HU samples are int16 whether read from the folder or fetched from the archive.
        vols = {v["id"]: v for v in json.loads(s.get("/v1/volumes").body)["volumes"]}
        for vid in ("disk", "pacs"):
            v = vols[vid]
            assert (v["modality"], v["name"], v["value_type"], v["value_range"]) == \
                ("CT", "isoserve test series", "int16", [-1000.0, 1000.0]), v
    check("orthanc_volume_described_by_its_instances", described_by_instances)

    def unreachable():
        r = s.get("/v1/volumes/down" + MESH)
        body = problem(r)
        assert r.status == 503 and 1 <= int(r.getheader("Retry-After")) <= 30, (r.status, r.getheader("Retry-After"))
        assert '"down"' in body["detail"] and "connect" in body["detail"].lower(), body["detail"]
    check("orthanc_unreachable_is_503_with_retry_after", unreachable)

    def unknown_series():
        r = s.get("/v1/volumes/unknown")
        body = problem(r)
        assert r.status == 503 and r.getheader("Retry-After"), r.status
        assert '"unknown"' in body["detail"] and "HTTP 404" in body["detail"], body["detail"]
        assert mesh(s, "disk").status == 200  # the rest of the catalog keeps serving
    check("orthanc_unknown_series_is_503", unknown_series)

    def cached_files():
        # one folder per archive (a hash of its URL; "down" made one too): series of two
        # servers never mix, and the fetched series is in its server's folder only
        archives = os.listdir(os.path.join(cache, "orthanc"))
        assert len(archives) == 2 and all(re.fullmatch(r"[0-9a-f]{16}", a) for a in archives), archives
        holding = [a for a in archives if os.path.isdir(os.path.join(cache, "orthanc", a, sid))]
        assert len(holding) == 1, holding
        archives = holding
        folder = os.path.join(cache, "orthanc", archives[0], sid)
        names = os.listdir(folder)
        assert len(names) == 24 and all(n.endswith(".dcm") for n in names), names
        assert os.path.exists(os.path.join(cache, "pacs.isotree"))
        assert not [n for n in os.listdir(os.path.join(cache, "orthanc", archives[0])) if "partial" in n]
    check("orthanc_series_cached_by_id", cached_files)


report_numbers = {}


DICOMWEB_PLUGIN = (glob.glob("/usr/lib/orthanc/libOrthancDicomWeb.so*") or [None])[0]


def dicomweb_tests(tmp, series_dir):
    """The same series through DICOMweb: Orthanc with Debian's orthanc-dicomweb plugin,
    basic authentication required, credentials from a file. One entry names the series by
    its UID alone (QIDO-RS finds its study), one is a QIDO-RS query that expands to the
    series; WADO-RS fetches it as multipart/related. Both meshes equal the folder's."""
    if not DICOMWEB_PLUGIN:
        print(f"SKIP {LABEL}.dicomweb: Debian's orthanc-dicomweb is not installed (apt-get install orthanc-dicomweb)")
        return
    tmp = os.path.join(tmp, "dicomweb")
    os.mkdir(tmp)
    pacs = Orthanc(tmp, extra={"Plugins": [DICOMWEB_PLUGIN], "DicomWeb": {"Enable": True, "Root": "/dicom-web/"}},
                   auth=("isoserve", "s3cret-pass"))
    try:
        sid = pacs.upload(series_dir)
        uid = pacs.get_json(f"/series/{sid}")["MainDicomTags"]["SeriesInstanceUID"]
        cred = os.path.join(tmp, "pacs.cred")
        with open(cred, "w") as f:
            f.write("basic isoserve:s3cret-pass\n")
        wrong = os.path.join(tmp, "wrong.cred")
        with open(wrong, "w") as f:
            f.write("basic isoserve:not-it\n")
        web = pacs.url + "/dicom-web/"
        cache = os.path.join(tmp, "cache")
        catalog = write_catalog(tmp, [
            {"id": "disk", "path": series_dir},
            {"id": "web", "dicomweb": {"url": web, "series": uid, "credentials": "pacs.cred"}},
            {"id": "ct", "name": "CT", "dicomweb": {"url": web, "query": "Modality=CT", "credentials": cred}},
            # another spelling of the archive: a cache key of its own, so the series is asked for
            {"id": "denied", "dicomweb": {"url": web.replace("127.0.0.1", "localhost"), "series": uid,
                                          "credentials": wrong}},
            {"id": "bad", "dicomweb": {"url": web, "series": "not-a-uid"}}])
        s = Server(["--catalog", catalog, "--cache-dir", cache])
        try:
            def denied():
                r = s.get("/v1/volumes/denied" + MESH)
                body = problem(r)
                assert r.status == 503 and r.getheader("Retry-After"), r.status
                assert "HTTP 401" in body["detail"] and "not-it" not in body["detail"], body["detail"]
            check("dicomweb_wrong_credentials_is_503", denied)

            def same_mesh():
                a, b = mesh(s, "disk"), mesh(s, "web")
                assert a.body == b.body and int(a.getheader("X-Iso-Triangles")) > 1000, (len(a.body), len(b.body))
                assert "dicomweb " in s.log() and "/studies/" in s.log(), s.log()[-2000:]
            check("dicomweb_mesh_equals_folder_mesh", same_mesh)

            def described_by_instances():
                v = json.loads(s.get("/v1/volumes/web").body)
                assert (v["modality"], v["name"], v["value_type"]) == ("CT", "isoserve test series", "int16"), v
            check("dicomweb_volume_described_by_its_instances", described_by_instances)

            def query():
                vols = {v["id"]: v for v in json.loads(s.get("/v1/volumes").body)["volumes"]}
                found = [i for i in vols if i.startswith("ct-")]
                assert len(found) == 1 and re.fullmatch(r"ct-[0-9a-f]{8}", found[0]), sorted(vols)
                assert vols[found[0]]["modality"] == "CT" and vols[found[0]]["name"].startswith("CT: ")
                assert mesh(s, found[0]).body == mesh(s, "disk").body
                assert "bad" not in vols and '"bad"' in s.log()
            check("dicomweb_qido_query_expands_to_its_series", query)


            def cached():
                folders = glob.glob(os.path.join(cache, "dicomweb", "*", uid))
                assert len(folders) == 1, folders
                names = sorted(os.listdir(folders[0]))
                assert len(names) == 24 and all(n.endswith(".dcm") for n in names), names
            check("dicomweb_series_cached_by_archive_and_uid", cached)
        finally:
            rc = s.stop()
            report("dicomweb_daemon_exits_0", rc == 0, f"exit status {rc}\n{s.log()[-3000:]}")
    finally:
        pacs.stop()


def outage_tests(tmp, series_dir):
    """The archive stops and starts again under load: requests for its volume answer 503
    with Retry-After while it is down, the first after its backoff asks it again, and once
    it is back the volume serves (the same mesh as the folder's) without a restart; the
    folder's volume answers 200 throughout; no other status appears."""
    pacs = Orthanc(tmp)
    sid = pacs.upload(series_dir)
    port = pacs.port
    pacs.stop()
    catalog = write_catalog(tmp, [{"id": "disk", "path": series_dir},
                                  {"id": "flaky", "orthanc": {"url": f"http://127.0.0.1:{port}", "series": sid}}])
    s = Server(["--catalog", catalog])  # no cache dir: every attempt asks the archive
    seen, lock, stop = [], threading.Lock(), threading.Event()

    def load(vid):
        while not stop.is_set():
            r = s.get(f"/v1/volumes/{vid}{MESH}")
            with lock:
                seen.append((time.time(), vid, r.status, r.getheader("Retry-After"), r.body if r.status == 200 else b""))
            time.sleep(0.05)
    threads = [threading.Thread(target=load, args=(v,)) for v in ("disk", "flaky", "flaky", "disk")]
    pacs = None
    try:
        for t in threads:
            t.start()
        time.sleep(3)  # the archive is down: three attempts (0, 1, 3 s)
        restarted = time.time()
        pacs = Orthanc(tmp, port)
        deadline = time.time() + 40
        while time.time() < deadline and not any(v == "flaky" and st == 200 for _, v, st, _, _ in list(seen)):
            time.sleep(0.2)
        time.sleep(1)
    finally:
        stop.set()
        for t in threads:
            t.join(timeout=120)
        rc = s.stop()
        if pacs:
            pacs.stop()
    log = s.log()

    def statuses():
        bad = [(v, st) for _, v, st, _, _ in seen if st not in (200, 503) or (st == 503 and v != "flaky")]
        assert not bad, bad[:5]
        down = [ra for t, v, st, ra, _ in seen if st == 503]
        assert down and all(ra and 1 <= int(ra) <= 30 for ra in down), down[:5]
    check("outage_only_the_archives_volume_is_503_with_retry_after", statuses)

    def recovered():
        flaky = [(t, st, body) for t, v, st, _, body in seen if v == "flaky"]
        first = next(i for i, (_, st, _) in enumerate(flaky) if st == 200)
        assert all(st == 200 for _, st, _ in flaky[first:]), "a 200 was followed by a failure"
        disk = next(body for _, v, st, _, body in seen if v == "disk" and st == 200)
        assert flaky[first][2] == disk, "the recovered volume's mesh differs from the folder's"
        print(f"INFO {LABEL}.outage: {sum(st == 503 for _, st, _ in flaky)} answers 503 while down, "
              f"recovered {flaky[first][0] - restarted:.1f} s after the archive came back")
    check("outage_recovers_without_restart", recovered)

    def backoff():
        asked = log.count('"flaky": asking its source again')
        down = sum(1 for _, v, st, _, _ in seen if v == "flaky" and st == 503)
        # many requests, few attempts: one per backoff (1, 2, 4, ... s) while down
        assert 1 <= asked <= 8 and down > 3 * asked, (asked, down)
        assert rc == 0, f"exit status {rc}"
    check("outage_attempts_back_off", backoff)



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
        # 16 stored bits and intercept -1024, as most scanners write CT: int16 all the same
        r = subprocess.run(["/usr/bin/python3", HELPER, "phantom", series_dir, "--rle", "--bits=16"],
                           capture_output=True, text=True)
        if r.returncode != 0:
            print(f"SKIP {LABEL}.all: cannot write a series with pydicom: {r.stderr.strip()[-300:]}")
            return 0
        if ORTHANC:
            orthanc_tests(tmp, series_dir)
            dicomweb_tests(tmp, series_dir)
            outage_tests(tmp, series_dir)
        else:
            print(f"SKIP {LABEL}.orthanc: Debian's orthanc is not installed (scripts/setup.sh installs it)")
        cli_tests(tmp, series_dir)
    finally:
        shutil.rmtree(tmp, ignore_errors=True)
    return 1 if RESULTS.failures else 0


if __name__ == "__main__":
    sys.exit(main())
