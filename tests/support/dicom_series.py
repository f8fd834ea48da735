"""dicom_series.py: writes the DICOM files the DICOM and Orthanc tests load, with pydicom.

    dicom_series.py nrrd SRC.nhdr OUTDIR [--rle] [--hu] [--oblique] [--seed N] [--uid UID]
        a series of SRC's slices in OUTDIR: file names and InstanceNumbers shuffled (only
        ImagePositionPatient tells the order); --rle: RLE Lossless (pydicom's own encoder);
        --hu: samples stored as unsigned raw values with RescaleIntercept -1024 (as CT
        scanners do) instead of as they are; --oblique: rows along +y, columns along -z,
        slices along -x (a sagittal stack), else the identity axes. Prints one line per
        slice, "k FILE", in slice order.
    dicom_series.py phantom OUTDIR [--rle] [--bits=16] [--padding]
        the same from a synthetic 40x36x24 CT phantom (a sphere of 1000 HU in -1000 HU
        around a cylinder of 300 HU), stored with --hu: for tests that run without
        ../shared; --bits=16: 16 stored bits although 12 would do (as many scanners write);
        --padding: stored 0 (-1024 HU) outside a circle of radius 17 in every slice, named
        by PixelPaddingValue (0028,0120).
    dicom_series.py ct OUTDIR --bits=B [--signed] [--intercept=I] [--slope=S] [--scale=K] [--offset=O]
        the phantom's values times K plus O (defaults 1, 0) as a series of B stored bits (12
        or 16, in 16 allocated; the bits above B set, as overlays may), signed or unsigned,
        stored = (value - I) / S (defaults 0 and 1, which must give whole numbers that
        fit); Modality CT, SeriesDescription "ct B-bit ...".
    dicom_series.py ct-raw OUT.raw [--scale=K] [--offset=O]
        the ct series' values (float64 little endian, x fastest), to compare with.
    dicom_series.py batch FILE
        each line of FILE as the arguments of one call (one process for many series).
    dicom_series.py phantom-raw OUT.raw
        the phantom's samples (int16 little endian, x fastest), to compare with.
    dicom_series.py enhanced OUT.dcm
        one enhanced multi-frame file (per-frame functional groups, frames stored in a
        shuffled order, a different RescaleIntercept per frame) of a 12x10x8 ramp whose
        sample (i, j, k) is i + 16 j + 256 k - 1000.
    dicom_series.py restack SRC.dcm OUTDIR N
        N copies of a real single-slice file, moved 2.5 mm apart along its slice normal,
        keeping its transfer syntax and (encapsulated) pixel data as they are.
    dicom_series.py pixels SRC.dcm OUT.raw
        the rescaled samples pydicom decodes from an uncompressed file, as float64.
Uses Debian's python3-pydicom and python3-numpy only."""

import gzip
import os
import random
import sys

import numpy as np
import pydicom
from pydicom.dataset import Dataset, FileDataset, FileMetaDataset
from pydicom.encaps import encapsulate
from pydicom.pixel_data_handlers.rle_handler import rle_encode_frame
from pydicom.sequence import Sequence
from pydicom.uid import (CTImageStorage, EnhancedMRImageStorage, ExplicitVRLittleEndian,
                         RLELossless, generate_uid)

ROOT = "1.2.826.0.1.3680043.8.498."  # pydicom's UID root


def read_nrrd(path):
    """The samples of a detached gzip NRRD as written in ../shared/volumes, indexed [z, y, x]."""
    fields = {}
    with open(path) as f:
        for line in f:
            if ":" in line:
                key, value = line.split(":", 1)
                fields[key.strip()] = value.strip()
    types = {"uint16": "u2", "int16": "i2", "uint8": "u1"}
    dtype = (">" if fields.get("endian") == "big" else "<") + types[fields["type"]]
    x, y, z = (int(v) for v in fields["sizes"].split())
    spacing = [float(v) for v in fields["spacings"].split()]
    raw = os.path.join(os.path.dirname(path), fields["data file"])
    data = np.frombuffer(gzip.open(raw).read(), dtype=dtype).reshape(z, y, x)
    return data, spacing


def phantom():
    z, y, x = np.mgrid[0:24, 0:36, 0:40].astype(np.float64)
    data = np.full(z.shape, -1000, dtype=np.int16)
    data[(x - 20) ** 2 + (y - 18) ** 2 + ((z - 12) * 1.5) ** 2 < 14 ** 2] = 1000
    data[((x - 20) ** 2 + (y - 18) ** 2 < 16) & (z > 3) & (z < 20)] = 300
    return data, [0.8, 0.8, 1.25]


AXES = {False: ([1, 0, 0], [0, 1, 0]), True: ([0, 1, 0], [0, 0, -1])}


def base_dataset(sop_class, uid, rows, columns):
    meta = FileMetaDataset()
    meta.MediaStorageSOPClassUID = sop_class
    meta.MediaStorageSOPInstanceUID = generate_uid(ROOT)
    meta.TransferSyntaxUID = ExplicitVRLittleEndian
    ds = FileDataset(None, {}, file_meta=meta, preamble=b"\0" * 128)
    ds.SOPClassUID = sop_class
    ds.SOPInstanceUID = meta.MediaStorageSOPInstanceUID
    ds.StudyInstanceUID = ROOT + "1"
    ds.SeriesInstanceUID = uid
    ds.PatientName = "Test^Isoserve"
    ds.PatientID = "isoserve-test"
    ds.Rows, ds.Columns = rows, columns
    ds.SamplesPerPixel = 1
    ds.PhotometricInterpretation = "MONOCHROME2"
    ds.BitsAllocated, ds.BitsStored, ds.HighBit = 16, 16, 15
    return ds


def set_pixels(ds, frames, rle):
    """frames: a list of 2-D arrays, already of the stored dtype (little endian)."""
    if rle:
        ds.file_meta.TransferSyntaxUID = RLELossless
        ds.PixelData = encapsulate([rle_encode_frame(f) for f in frames])
        ds["PixelData"].is_undefined_length = True
    else:
        ds.PixelData = b"".join(f.astype(f.dtype.newbyteorder("<")).tobytes() for f in frames)
    ds.is_little_endian, ds.is_implicit_VR = True, False


def write_series(data, spacing, out, rle=False, hu=False, oblique=False, seed=1, uid=None, bits=None,
                 stored=None, description="isoserve test series", padding=None):
    """One file per slice of data ([z, y, x]); prints "k FILE" per slice in slice order.
    stored: (bits, signed, intercept, slope) to write data's values through a rescale."""
    os.makedirs(out, exist_ok=True)
    uid = uid or generate_uid(ROOT)
    rng = random.Random(seed)
    nz = data.shape[0]
    numbers = list(range(1, nz + 1))
    rng.shuffle(numbers)
    row, col = AXES[oblique]
    normal = np.cross(row, col)
    for k in range(nz):
        ds = base_dataset(CTImageStorage, uid, data.shape[1], data.shape[2])
        ds.Modality = "CT"
        ds.SeriesDescription = description
        ds.InstanceNumber = numbers[k]
        ds.ImageOrientationPatient = [float(v) for v in row + col]
        ds.ImagePositionPatient = [float(v) for v in (np.array([10.0, -20.0, 30.0]) + k * spacing[2] * normal)]
        ds.PixelSpacing = [spacing[1], spacing[0]]
        ds.SliceThickness = spacing[2]
        slice_ = data[k]
        if stored:
            nbits, signed, intercept, slope = stored
            raw = (slice_.astype(np.float64) - intercept) / slope
            lo, hi = (-(1 << (nbits - 1)), (1 << (nbits - 1)) - 1) if signed else (0, (1 << nbits) - 1)
            assert (raw == np.round(raw)).all() and raw.min() >= lo and raw.max() <= hi, (raw.min(), raw.max())
            ds.PixelRepresentation = int(signed)
            ds.BitsStored, ds.HighBit = nbits, nbits - 1
            ds.RescaleIntercept, ds.RescaleSlope = intercept, slope
            # bits above BitsStored hold garbage, as overlays may: a reader must mask them
            slice_ = (raw.astype(np.int64) & ((1 << nbits) - 1) | (0xa000 if nbits == 12 else 0)).astype("<u2")
            if signed:
                slice_ = slice_.view("<i2")
        elif hu:  # 12 stored bits when they hold the values, as most CT scanners write
            ds.PixelRepresentation = 0
            ds.RescaleIntercept, ds.RescaleSlope = -1024, 1
            if int(data.max()) + 1024 < 4096 and bits != 16:
                ds.BitsStored, ds.HighBit = 12, 11
            slice_ = (slice_.astype(np.int32) + 1024).astype("<u2")
            if padding is not None:
                ds.PixelPaddingValue = padding
        else:
            ds.PixelRepresentation = 1 if slice_.dtype.kind == "i" else 0
            slice_ = slice_.astype("<i2" if slice_.dtype.kind == "i" else "<u2")
        set_pixels(ds, [slice_], rle)
        name = "%08x.dcm" % rng.getrandbits(32)
        ds.save_as(os.path.join(out, name), write_like_original=False)
        print(k, name)


def frame_group(position, intercept):
    group = Dataset()
    pos = Dataset()
    pos.ImagePositionPatient = position
    group.PlanePositionSequence = Sequence([pos])
    vt = Dataset()
    vt.RescaleIntercept, vt.RescaleSlope, vt.RescaleType = intercept, 1, "US"
    group.PixelValueTransformationSequence = Sequence([vt])
    return group


def write_enhanced(out):
    nx, ny, nz = 12, 10, 8
    k, j, i = np.mgrid[0:nz, 0:ny, 0:nx]
    value = i + 16 * j + 256 * k - 1000
    order = list(range(nz))
    random.Random(7).shuffle(order)
    ds = base_dataset(EnhancedMRImageStorage, generate_uid(ROOT), ny, nx)
    ds.Modality = "MR"
    ds.PixelRepresentation = 0
    ds.NumberOfFrames = nz
    shared = Dataset()
    measures = Dataset()
    measures.PixelSpacing, measures.SliceThickness = [0.5, 0.25], 3
    shared.PixelMeasuresSequence = Sequence([measures])
    orient = Dataset()
    orient.ImageOrientationPatient = [1, 0, 0, 0, 1, 0]
    shared.PlaneOrientationSequence = Sequence([orient])
    ds.SharedFunctionalGroupsSequence = Sequence([shared])
    # frame f holds slice order[f], with intercept -2000 + 10 k: stored = value - intercept
    ds.PerFrameFunctionalGroupsSequence = Sequence(
        [frame_group([1.0, 2.0, 3.0 + 3 * order[f]], -2000 + 10 * order[f]) for f in range(nz)])
    frames = [(value[order[f]] - (-2000 + 10 * order[f])).astype("<u2") for f in range(nz)]
    set_pixels(ds, frames, False)
    ds.save_as(out, write_like_original=False)


def restack(src, out, n):
    os.makedirs(out, exist_ok=True)
    for k in range(n):
        ds = pydicom.dcmread(src)
        iop = [float(v) for v in ds.ImageOrientationPatient]
        normal = np.cross(iop[:3], iop[3:])
        ds.ImagePositionPatient = [float(v) for v in np.array([float(v) for v in ds.ImagePositionPatient]) + 2.5 * k * normal]
        ds.SOPInstanceUID = generate_uid(ROOT)
        ds.file_meta.MediaStorageSOPInstanceUID = ds.SOPInstanceUID
        ds.save_as(os.path.join(out, "slice%d.dcm" % k))


def pixels(src, out):
    ds = pydicom.dcmread(src)
    a = ds.pixel_array.astype(np.float64)
    a = a * float(ds.get("RescaleSlope", ds.get("DoseGridScaling", 1))) + float(ds.get("RescaleIntercept", 0))
    a.astype("<f8").tofile(out)


def main(argv):
    flags = {a for a in argv if a.startswith("--")}
    args = [a for a in argv if not a.startswith("--")]
    seed = next((int(a.split("=")[1]) for a in flags if a.startswith("--seed=")), 1)
    uid = next((a.split("=", 1)[1] for a in flags if a.startswith("--uid=")), None)
    kind = args[0]

    def number(name, default):
        return next((float(a.split("=", 1)[1]) for a in flags if a.startswith(f"--{name}=")), default)

    if kind == "nrrd":
        data, spacing = read_nrrd(args[1])
        write_series(data, spacing, args[2], "--rle" in flags, "--hu" in flags, "--oblique" in flags, seed, uid)
    elif kind == "phantom":
        data, spacing = phantom()
        padding = None
        if "--padding" in flags:
            y, x = np.mgrid[0:data.shape[1], 0:data.shape[2]]
            data[:, (x - 20) ** 2 + (y - 18) ** 2 > 17 ** 2] = -1024
            padding = 0
        write_series(data, spacing, args[1], "--rle" in flags, True, False, seed, uid, bits=number("bits", None),
                     padding=padding)
    elif kind == "ct":
        data, spacing = phantom()
        offset, nbits, signed = number("offset", 0), int(number("bits", 16)), "--signed" in flags
        intercept, slope = number("intercept", 0), number("slope", 1)
        description = "ct %d-bit %s, intercept %g, slope %g" % (nbits, "signed" if signed else "unsigned",
                                                                intercept, slope)
        write_series(data * number("scale", 1) + offset, spacing, args[1], False, False, False, seed, uid,
                     stored=(nbits, signed, intercept, slope), description=description)
    elif kind == "ct-raw":
        (phantom()[0] * number("scale", 1) + number("offset", 0)).astype("<f8").tofile(args[1])
    elif kind == "phantom-raw":
        phantom()[0].astype("<i2").tofile(args[1])
    elif kind == "enhanced":
        write_enhanced(args[1])
    elif kind == "restack":
        restack(args[1], args[2], int(args[3]))
    elif kind == "batch":
        for line in open(args[1]):
            if line.split():
                main(line.split())
    elif kind == "pixels":
        pixels(args[1], args[2])
    else:
        sys.exit(__doc__)


if __name__ == "__main__":
    main(sys.argv[1:])
