"""seeds.py OUT_DIR ISOSERVE_BIN: writes small seed inputs for each fuzz target into
OUT_DIR/<target>/ (made at fuzz time, never committed): valid NRRD (raw, gzip, detached
header), NIfTI-1 and MetaImage volumes of 4x4x4 to 6x5x4 samples, queries, a hierarchy file
and a Draco mesh made by the isoserve binary. When Debian's mricron-data or ../shared is
there, the first 4 KiB of a real header of each format joins the seeds (libFuzzer mutates
from a real file's bytes, and the short read makes the loader report truncation)."""

import glob
import gzip
import os
import struct
import subprocess
import sys

out, binary = sys.argv[1], sys.argv[2]


def put(target, name, data):
    d = os.path.join(out, target)
    os.makedirs(d, exist_ok=True)
    with open(os.path.join(d, name), "wb") as f:
        f.write(data)


samples = bytes((i * 37) % 256 for i in range(6 * 5 * 4))
floats = struct.pack("<120f", *[float(i % 11) for i in range(120)])
put("nrrd", "raw.nrrd", b"NRRD0004\ntype: uchar\ndimension: 3\nsizes: 6 5 4\nencoding: raw\n\n" + samples)
put("nrrd", "gzip.nrrd", b"NRRD0005\ntype: float\ndimension: 3\nsizes: 6 5 4\nendian: little\n"
    b"encoding: gzip\nspace: left-posterior-superior\nspace directions: (1,0,0) (0,2,0) (0,0,3)\n"
    b"space origin: (1,2,3)\n\n" + gzip.compress(floats))
put("nrrd", "skip.nrrd", b"NRRD0004\ntype: short\ndimension: 3\nsizes: 4 4 4\nendian: big\n"
    b"encoding: raw\nbyte skip: -1\nspacings: 1 1 2\n\n" + bytes(128))
put("metaimage", "local.mha", b"ObjectType = Image\nNDims = 3\nDimSize = 6 5 4\nElementSpacing = 1 1 2\n"
    b"Offset = 0 0 0\nTransformMatrix = 1 0 0 0 1 0 0 0 1\nElementType = MET_UCHAR\nElementDataFile = LOCAL\n" + samples)
put("metaimage", "zlib.mha", b"NDims = 3\nDimSize = 6 5 4\nElementType = MET_FLOAT\nCompressedData = True\n"
    b"ElementByteOrderMSB = False\nElementDataFile = LOCAL\n" + __import__("zlib").compress(floats))
header = bytearray(352)
struct.pack_into("<i", header, 0, 348)
struct.pack_into("<8h", header, 40, 3, 6, 5, 4, 1, 1, 1, 1)
struct.pack_into("<hh", header, 70, 16, 32)           # float32
struct.pack_into("<8f", header, 76, 1, 1, 1, 2, 1, 1, 1, 1)
struct.pack_into("<f", header, 108, 352)              # vox_offset
struct.pack_into("<ff", header, 112, 1, 0)            # scl_slope, scl_inter
struct.pack_into("<hh", header, 252, 1, 1)            # qform, sform codes
struct.pack_into("<12f", header, 280, 1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 2, 0)
header[344:348] = b"n+1\0"
put("nifti", "float.nii", bytes(header) + floats)
for q in (b"level=700", b"level=0.5&tolerance=2&normals=none&format=glb&qp=12&qn=8&budget=5000&cap=true",
          b"level=-1e300&tolerance=1e30&format=stl", b"level=1&format=ply&normals=trilinear"):
    put("query", f"q{len(q)}", q)
# Files of the real binary: a hierarchy of the 12^3 sphere fuzz_tree checks against, a mesh.
subprocess.run([binary, "build", "field:sphere:12", "-o", os.path.join(out, "sphere.isotree")],
               check=True, stdout=subprocess.DEVNULL)
put("tree", "sphere.isotree", open(os.path.join(out, "sphere.isotree"), "rb").read())
subprocess.run([binary, "extract", "field:sphere:12", "--level", "4", "-o", os.path.join(out, "sphere.drc")],
               check=True, stdout=subprocess.DEVNULL)
put("draco", "sphere.drc", open(os.path.join(out, "sphere.drc"), "rb").read())
# Real headers, cut to 4 KiB.
real = {"nifti": glob.glob("/usr/share/mricron/templates/*.nii.gz")[:0] + glob.glob("../shared/volumes/**/*.nii", recursive=True)[:2],
        "nrrd": glob.glob("../shared/volumes/**/*.nhdr", recursive=True)[:2] + glob.glob("../shared/volumes/**/*.nrrd", recursive=True)[:2],
        "metaimage": glob.glob("../shared/volumes/**/*.mha", recursive=True)[:2] + glob.glob("../shared/volumes/**/*.mhd", recursive=True)[:2]}
for target, paths in real.items():
    for p in paths:
        put(target, "real-" + os.path.basename(p), open(p, "rb").read(4096))
