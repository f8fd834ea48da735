"""Segmentations end to end, through `isoserve serve`: a label map, a 3D Slicer .seg.nrrd and
DICOM SEGs (BINARY and FRACTIONAL, written by tests/support/dicom_seg.py with pydicom from
the phantom's label map) from a folder, from a real Orthanc and through DICOMweb.

  - /v1/volumes/{id}/segments: numbers, names, categories, CIELab colours as sRGB, voxels,
    volumes in mL; the label map's and the SEG's agree;
  - /segments/{n}/mesh: the SEG's meshes are the label map's, triangle for triangle (folder,
    BINARY and FRACTIONAL), byte for byte between the folder, Orthanc and DICOMweb; closed
    with cap=true, its enclosed volume the voxels' within 1%;
  - /segments/mesh: one glb scene (Draco and meshopt) the Khronos glTF validator passes with
    no error or warning, three.js's GLTFLoader decodes to every segment's triangles, a node
    per segment named after it with its colour (linear) as material;
  - errors: a bad SEG in the catalog answers 500 with the loader's message; level on a
    segment route, an unknown segment, a volume that is no segmentation.
Orthanc and DICOMweb parts skip without Debian's orthanc (and orthanc-dicomweb). Prints
PASS/FAIL/SKIP lines; exit status 1 on failure."""

import json
import os
import re
import shutil
import struct
import subprocess
import sys
import tempfile

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
ROOT = os.path.abspath(os.path.join(HERE, "..", ".."))
sys.path.insert(0, os.path.join(HERE, "..", "support"))
sys.path.insert(0, os.path.join(HERE, "..", "http"))
sys.path.insert(0, HERE)
from results import Results  # noqa: E402
from test_http import Server, problem  # noqa: E402
from test_orthanc import DICOMWEB_PLUGIN, ORTHANC, Orthanc, write_catalog  # noqa: E402

LABEL = "segmentation" + os.environ.get("ISO_SAN_SUFFIX", "")
RESULTS = Results(LABEL)
report, check = RESULTS.report, RESULTS.check
WRITER = os.path.join(HERE, "..", "support", "dicom_seg.py")
WEB = os.path.join(ROOT, "web")
PLY = "/mesh?format=ply&normals=none"


def write(out, *flags):
    subprocess.run(["/usr/bin/python3", WRITER, "phantom", out, *flags], check=True, capture_output=True)
    return out


def ply(body):
    head, _, payload = body.partition(b"end_header\n")
    nv = int(re.search(rb"element vertex (\d+)", head).group(1))
    nt = int(re.search(rb"element face (\d+)", head).group(1))
    pos = np.frombuffer(payload[:nv * 12], "<f4").reshape(nv, 3)
    faces = np.frombuffer(payload[nv * 12:nv * 12 + nt * 13], np.dtype([("n", "u1"), ("i", "<u4", 3)]))["i"]
    return pos, faces


def triangles(body):
    """Each triangle's corners rounded to 1e-4 mm, rotated to start at the smallest (winding
    kept), sorted: the surface whatever the vertex numbering."""
    pos, faces = ply(body)
    corners = np.round(pos[faces].astype(np.float64), 4)
    out = []
    for t in corners:
        k = min(range(3), key=lambda i: tuple(t[i]))
        out.append(tuple(map(tuple, np.roll(t, -k, axis=0))))
    return sorted(out)


def get_ok(s, path):
    r = s.get(path)
    assert r.status == 200, (path, r.status, r.body[:400])
    return r


def glb_json(body):
    length = struct.unpack_from("<I", body, 12)[0]
    return json.loads(body[20:20 + length])


def srgb_to_linear(c):
    return c / 12.92 if c <= 0.04045 else ((c + 0.055) / 1.055) ** 2.4


def folder_tests(tmp):
    binary, fractional, bad = (write(os.path.join(tmp, n), *f) for n, f in
                               (("binary", ()), ("fractional", ("--fractional",)), ("bad", ("--bad=frames",))))
    catalog = write_catalog(tmp, [
        {"id": "map", "path": os.path.join(binary, "labels.nrrd"), "labels": os.path.join(binary, "labels.txt")},
        {"id": "seg", "path": os.path.join(binary, "ct"), "labels": True},
        {"id": "frac", "path": os.path.join(fractional, "ct"), "labels": True},
        {"id": "ct", "path": os.path.join(binary, "ct")},
        {"id": "bad", "path": os.path.join(bad, "ct"), "labels": True}])
    s = Server(["--catalog", catalog, "--cache-dir", os.path.join(tmp, "cache")])
    try:
        def documents():
            seg = json.loads(get_ok(s, "/v1/volumes/seg/segments").body)
            lab = json.loads(get_ok(s, "/v1/volumes/map/segments").body)
            assert seg["source"] == "dicom-seg" and lab["source"] == "labels", (seg["source"], lab["source"])
            names = [x["name"] for x in seg["segments"]]
            assert names == ["shell", "core", "box"] == [x["name"] for x in lab["segments"]], names
            assert [x["voxels"] for x in seg["segments"]] == [x["voxels"] for x in lab["segments"]] == [6931, 720, 252]
            shell = seg["segments"][0]
            assert shell["color_hex"] == "#fd0d02" and shell["category"] == "Tissue" and shell["type"] == "Bone", shell
            assert abs(shell["volume_ml"] - 6931 * 0.8 * 0.8 * 1.25 / 1000) < 1e-9
            vol = json.loads(get_ok(s, "/v1/volumes/seg").body)
            assert vol["segments"] == 3 and vol["segmentation"] == "dicom-seg"
            ct = json.loads(get_ok(s, "/v1/volumes/ct").body)
            assert "segments" not in ct and ct["dims"] == [40, 36, 24], ct["dims"]
        check("segments_documents_agree", documents)

        def same_meshes():
            for n in (1, 2, 3):
                for cap in ("false", "true"):
                    q = f"/segments/{n}{PLY}&cap={cap}"
                    a, b, c = (get_ok(s, f"/v1/volumes/{v}{q}") for v in ("map", "seg", "frac"))
                    ta = triangles(a.body)
                    assert len(ta) > 100 and ta == triangles(b.body) == triangles(c.body), (n, cap)
                    assert a.getheader("X-Iso-Triangles") == b.getheader("X-Iso-Triangles")
        check("seg_binary_and_fractional_meshes_equal_the_label_maps", same_meshes)

        def closed():
            r = get_ok(s, "/v1/volumes/seg/segments/1/mesh?cap=true&measures=true")
            assert r.getheader("X-Iso-Closed") == "true", r.getheader("X-Iso-Closed")
            want = 6931 * 0.8 * 0.8 * 1.25
            got = float(r.getheader("X-Iso-Volume-Mm3"))
            assert abs(got - want) < 0.01 * want, (got, want)
            r = get_ok(s, "/v1/volumes/seg/segments/1/mesh?cap=true&measures=true&smoothing=1")
            assert r.getheader("X-Iso-Closed") == "true"
            r = get_ok(s, "/v1/volumes/seg/segments/1/mesh?distance=0.3&format=ply")
            assert int(r.getheader("X-Iso-Chain-Level")) >= 1 and float(r.getheader("X-Iso-Distance-Mm")) <= 0.3
        check("segment_mesh_closed_volume_smoothing_distance", closed)

        def scene():
            for fmt in ("glb", "glb-meshopt"):
                r = get_ok(s, f"/v1/volumes/seg/segments/mesh?format={fmt}")
                assert r.getheader("Content-Type") == "model/gltf-binary"
                total = sum(int(get_ok(s, f"/v1/volumes/seg/segments/{n}{PLY}").getheader("X-Iso-Triangles"))
                            for n in (1, 2, 3))
                assert int(r.getheader("X-Iso-Triangles")) == total, (r.getheader("X-Iso-Triangles"), total)
                path = os.path.join(tmp, f"scene-{fmt}.glb")
                open(path, "wb").write(r.body)
                v = subprocess.run(["node", os.path.join(ROOT, "tests/http/gltf_validate.mjs"), WEB, path],
                                   capture_output=True, text=True)
                errors, warnings = v.stdout.split()[:2]
                assert v.returncode == 0 and errors == "0" and warnings == "0", (v.stdout, v.stderr[-800:])
                out = subprocess.run(["node", os.path.join(ROOT, "tests/http/gltf_load.mjs"), path, WEB],
                                     capture_output=True, text=True)
                assert out.returncode == 0, out.stderr[-500:]
                tri = int(out.stdout.split()[0])
                assert tri == total, (tri, total)
                doc = glb_json(r.body)
                assert [n["name"] for n in doc["nodes"]] == ["shell", "core", "box"], doc["nodes"]
                assert [n["extras"]["segment"] for n in doc["nodes"]] == [1, 2, 3]
                color = doc["materials"][0]["pbrMetallicRoughness"]["baseColorFactor"]
                want = [srgb_to_linear(c / 255) for c in (0xfd, 0x0d, 0x02)]
                assert all(abs(a - b) < 0.01 for a, b in zip(color, want)), (color, want)
        check("segments_scene_validates_and_decodes", scene)

        def errors():
            r = s.get("/v1/volumes/bad/segments")
            body = problem(r)
            assert r.status == 500 and "missing frames" in body["detail"], (r.status, body["detail"])
            r = s.get("/v1/volumes/seg/segments/1/mesh?level=3")
            assert r.status == 400 and problem(r)["parameter"] == "level"
            r = s.get("/v1/volumes/seg/segments/7/mesh")
            assert r.status == 404 and "no segment 7" in problem(r)["detail"]
            r = s.get("/v1/volumes/ct/segments")
            assert r.status == 404 and "not a segmentation" in problem(r)["detail"]
            r = s.get("/v1/volumes/seg/segments/mesh?format=draco")
            assert r.status == 400 and problem(r)["parameter"] == "format"
            r = s.get("/v1/volumes/seg/segments/01/mesh")
            assert r.status == 404
        check("segment_routes_refuse_precisely", errors)

        def cached():
            etag = get_ok(s, "/v1/volumes/seg/segments").getheader("ETag")
            assert s.get("/v1/volumes/seg/segments", {"If-None-Match": etag}).status == 304
            r = get_ok(s, f"/v1/volumes/seg/segments/2{PLY}")
            assert r.getheader("X-Iso-Cache") == "hit"
        check("segments_cacheable", cached)
    finally:
        rc = s.stop()
        report("segmentation_daemon_exits_0", rc == 0, f"exit status {rc}\n{s.log()[-3000:]}")
    return binary


def archive_tests(tmp, binary):
    """The BINARY SEG and its CT uploaded to Orthanc (with the DICOMweb plugin): served
    from Orthanc's REST API and through DICOMweb, byte for byte the folder's meshes."""
    if not ORTHANC:
        print(f"SKIP {LABEL}.orthanc: Debian's orthanc is not installed (scripts/setup.sh installs it)")
        return
    plugins = {"Plugins": [DICOMWEB_PLUGIN], "DicomWeb": {"Enable": True, "Root": "/dicom-web/"}} if DICOMWEB_PLUGIN else None
    atmp = os.path.join(tmp, "archive")
    os.mkdir(atmp)
    pacs = Orthanc(atmp, extra=plugins)
    try:
        ct = os.path.join(binary, "ct")
        seg_only, ct_only = os.path.join(atmp, "seg-only"), os.path.join(atmp, "ct-only")
        os.mkdir(seg_only)
        os.mkdir(ct_only)
        for name in os.listdir(ct):
            shutil.copy(os.path.join(ct, name), seg_only if name == "seg.dcm" else ct_only)
        pacs.upload(ct_only)
        seg_id = pacs.upload(seg_only)
        seg_uid = pacs.get_json(f"/series/{seg_id}")["MainDicomTags"]["SeriesInstanceUID"]
        entries = [{"id": "disk", "path": ct, "labels": True},
                   {"id": "pacs", "labels": True, "orthanc": {"url": pacs.url, "series": seg_id}}]
        if DICOMWEB_PLUGIN:
            entries.append({"id": "web", "labels": True, "dicomweb": {"url": pacs.url + "/dicom-web/", "series": seg_uid}})
        catalog = write_catalog(atmp, entries)
        s = Server(["--catalog", catalog, "--cache-dir", os.path.join(atmp, "cache")])
        try:
            def same():
                for v in [e["id"] for e in entries[1:]]:
                    assert get_ok(s, f"/v1/volumes/{v}/segments").body.replace(v.encode(), b"disk") == \
                        get_ok(s, "/v1/volumes/disk/segments").body, v
                    for n in (1, 2, 3):
                        a, b = (get_ok(s, f"/v1/volumes/{x}/segments/{n}{PLY}") for x in ("disk", v))
                        assert a.body == b.body and int(a.getheader("X-Iso-Triangles")) > 100, (v, n)
                    a, b = (get_ok(s, f"/v1/volumes/{x}/segments/mesh?format=glb-meshopt") for x in ("disk", v))
                    assert a.body == b.body, v
            check("orthanc_and_dicomweb_segs_equal_the_folders", same)
            if not DICOMWEB_PLUGIN:
                print(f"SKIP {LABEL}.dicomweb: Debian's orthanc-dicomweb is not installed")
        finally:
            rc = s.stop()
            report("archive_daemon_exits_0", rc == 0, f"exit status {rc}\n{s.log()[-3000:]}")
    finally:
        pacs.stop()


def volumes_dir_tests(tmp, binary):
    """A .seg.nrrd in a --volumes folder is a segmentation without configuration."""
    folder = os.path.join(tmp, "volumes")
    os.mkdir(folder)
    labels = np.fromfile(os.path.join(binary, "labels.nrrd"), np.uint8)[-40 * 36 * 24:]
    head = ("NRRD0004\ntype: uint8\ndimension: 3\nsizes: 40 36 24\nspace: left-posterior-superior\n"
            "space directions: (0.8,0,0) (0,0.8,0) (0,0,1.25)\nspace origin: (10,-20,30)\nencoding: raw\n"
            "Segment0_ID:=Segment_1\nSegment0_Name:=shell\nSegment0_Color:=0.9 0.5 0.4\nSegment0_LabelValue:=1\n"
            "Segment0_Layer:=0\nSegment1_Name:=core\nSegment1_LabelValue:=2\nSegment1_Layer:=0\n\n")
    with open(os.path.join(folder, "phantom.seg.nrrd"), "wb") as f:
        f.write(head.encode() + labels.tobytes())
    s = Server(["--volumes", folder])
    try:
        def seg_nrrd():
            doc = json.loads(get_ok(s, "/v1/volumes/phantom.seg/segments").body)
            assert doc["source"] == "seg.nrrd" and [x["name"] for x in doc["segments"]] == ["shell", "core"], doc
            assert doc["segments"][0]["color_hex"] == "#e68066" and doc["segments"][0]["voxels"] == 6931
            assert int(get_ok(s, f"/v1/volumes/phantom.seg/segments/2{PLY}").getheader("X-Iso-Triangles")) > 100
        check("seg_nrrd_in_volumes_dir", seg_nrrd)
    finally:
        s.stop()


def main():
    if subprocess.run(["/usr/bin/python3", "-c", "import pydicom, numpy"], capture_output=True).returncode:
        print(f"SKIP {LABEL}.all: needs Debian's python3-pydicom and python3-numpy")
        return 0
    tmp = tempfile.mkdtemp(prefix="isoserve-seg-")
    try:
        binary = folder_tests(tmp)
        archive_tests(tmp, binary)
        volumes_dir_tests(tmp, binary)
    finally:
        shutil.rmtree(tmp, ignore_errors=True)
    return 1 if RESULTS.failures else 0


if __name__ == "__main__":
    sys.exit(main())
