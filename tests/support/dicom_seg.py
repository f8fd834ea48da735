"""dicom_seg.py: DICOM Segmentation objects (SEG) for the tests, written with pydicom from
label maps made here, beside the CT series they segment.

    dicom_seg.py phantom OUTDIR [--fractional | --labelmap] [--overlap] [--bad=KIND]
        OUTDIR/ct/: dicom_series.py's phantom CT (40x36x24, 0.8 x 0.8 x 1.25 mm, origin
        (10, -20, 30)); OUTDIR/ct/seg.dcm: a SEG of its label map, derived from that series
        (Referenced Series Sequence), frames only on the slices a segment touches, in a
        shuffled order; OUTDIR/labels.nrrd: the same label map as a NRRD on the same grid
        (0 background, 1 shell, 2 core, 3 box), OUTDIR/labels.txt its names (ITK-SNAP).
        BINARY by default (1 bit per pixel, packed across frames); --fractional: 8-bit
        frames of 0 and 255 (Maximum Fractional Value 255), whose 0.5 surface is the
        label map's; --labelmap: a LABELMAP SEG (pixel = segment number); --overlap: a
        fourth segment overlapping the core (BINARY: another layer).
        --bad=frames      NumberOfFrames larger than the pixel data holds
        --bad=segment     a frame refers to segment 9, which is not in the Segment Sequence
        --bad=position    a frame half a slice off the CT's slices
        --bad=spacing     Pixel Spacing other than the CT's
        --bad=overlap     a LABELMAP SEG whose two frames on one slice give one voxel two segments
    dicom_seg.py variants OUTDIR
        every one of those in OUTDIR/NAME (binary, fractional, labelmap, overlap, and
        bad-frames, bad-segment, bad-position, bad-spacing, bad-overlap), in one process.
Uses Debian's python3-pydicom and python3-numpy only."""

import os
import random
import sys

import numpy as np
from pydicom.dataset import Dataset, FileDataset, FileMetaDataset
from pydicom.sequence import Sequence
from pydicom.uid import ExplicitVRLittleEndian, generate_uid

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import dicom_series  # noqa: E402

SEG_STORAGE = "1.2.840.10008.5.1.4.1.1.66.4"
LABELMAP_STORAGE = "1.2.840.10008.5.1.4.1.1.66.7"
ORIGIN = (10.0, -20.0, 30.0)
# name, category, type, CIELab (scaled to 0..65535: L* 0..100, a* b* -128..127)
SEGMENTS = [("shell", "Tissue", "Bone", (34885, 53151, 50000)),
            ("core", "Tissue", "Bone marrow", (49151, 26000, 40000)),
            ("box", "Physical object", "Marker", (20000, 32896, 10000)),
            ("overlap", "Tissue", "Lesion", (40000, 40000, 40000))]


def label_map(data):
    """The phantom's labels: 1 the sphere's shell, 2 the cylinder, 3 a box apart."""
    labels = np.zeros(data.shape, np.uint8)
    labels[data == 1000] = 1
    labels[data == 300] = 2
    labels[3:9, 2:8, 2:9] = 3
    return labels


def write_nrrd(labels, spacing, path):
    nz, ny, nx = labels.shape
    header = ("NRRD0004\ntype: uint8\ndimension: 3\nsizes: %d %d %d\nspace: left-posterior-superior\n"
              "space directions: (%r,0,0) (0,%r,0) (0,0,%r)\nspace origin: (%r,%r,%r)\nencoding: raw\n\n"
              % (nx, ny, nz, spacing[0], spacing[1], spacing[2], *ORIGIN))
    with open(path, "wb") as f:
        f.write(header.encode())
        f.write(labels.tobytes())


def write_descriptions(path):
    with open(path, "w") as f:
        f.write("# ITK-SnAP Label Description File\n")
        f.write('    0     0    0    0        0  0  0    "Clear Label"\n')
        for v, (name, _, _, _) in enumerate(SEGMENTS[:3], start=1):
            f.write('%5d   200  100   50        1  1  1    "%s"\n' % (v, name))


def code(meaning):
    c = Dataset()
    c.CodeValue, c.CodingSchemeDesignator, c.CodeMeaning = "T-D0050", "SRT", meaning
    return Sequence([c])


def segment_item(number, name, category, kind, lab):
    s = Dataset()
    s.SegmentNumber = number
    s.SegmentLabel = name
    s.SegmentAlgorithmType = "AUTOMATIC"
    s.SegmentAlgorithmName = "isoserve tests"
    s.SegmentedPropertyCategoryCodeSequence = code(category)
    s.SegmentedPropertyTypeCodeSequence = code(kind)
    s.RecommendedDisplayCIELabValue = list(lab)
    return s


def frame_item(position, segment):
    g = Dataset()
    p = Dataset()
    p.ImagePositionPatient = [float(v) for v in position]
    g.PlanePositionSequence = Sequence([p])
    if segment is not None:
        s = Dataset()
        s.ReferencedSegmentNumber = segment
        g.SegmentIdentificationSequence = Sequence([s])
    return g


def write_seg(masks, spacing, ct_uid, out, kind, bad):
    """masks: {segment number: bool array [z, y, x]}; one frame per (segment, slice it
    touches), in a shuffled order."""
    nz, ny, nx = next(iter(masks.values())).shape
    frames = [(n, k) for n in sorted(masks) for k in range(nz) if masks[n][k].any()]
    if kind == "LABELMAP":  # one frame per slice holding any segment: pixel = its number
        frames = [(None, k) for k in range(nz) if any(masks[n][k].any() for n in masks)]
    random.Random(5).shuffle(frames)
    meta = FileMetaDataset()
    meta.MediaStorageSOPClassUID = LABELMAP_STORAGE if kind == "LABELMAP" else SEG_STORAGE
    meta.MediaStorageSOPInstanceUID = generate_uid(dicom_series.ROOT)
    meta.TransferSyntaxUID = ExplicitVRLittleEndian
    ds = FileDataset(None, {}, file_meta=meta, preamble=b"\0" * 128)
    ds.SOPClassUID, ds.SOPInstanceUID = meta.MediaStorageSOPClassUID, meta.MediaStorageSOPInstanceUID
    ds.StudyInstanceUID = dicom_series.ROOT + "1"
    ds.SeriesInstanceUID = generate_uid(dicom_series.ROOT)
    ds.Modality = "SEG"
    ds.PatientName, ds.PatientID = "Test^Isoserve", "isoserve-test"
    ds.SeriesDescription = "phantom segmentation"
    ds.ContentLabel = "PHANTOM"
    ds.SegmentationType = kind
    ref = Dataset()
    ref.SeriesInstanceUID = ct_uid
    ds.ReferencedSeriesSequence = Sequence([ref])
    ds.Rows, ds.Columns = ny, nx
    ds.SamplesPerPixel, ds.PhotometricInterpretation, ds.PixelRepresentation = 1, "MONOCHROME2", 0
    if kind == "BINARY":
        ds.BitsAllocated, ds.BitsStored, ds.HighBit = 1, 1, 0
    else:
        ds.BitsAllocated, ds.BitsStored, ds.HighBit = 8, 8, 7
    if kind == "FRACTIONAL":
        ds.SegmentationFractionalType, ds.MaximumFractionalValue = "PROBABILITY", 255
    ds.SegmentSequence = Sequence([segment_item(n, *SEGMENTS[n - 1]) for n in sorted(masks)])
    shared = Dataset()
    measures = Dataset()
    measures.PixelSpacing = [spacing[1], spacing[0]] if bad != "spacing" else [spacing[1] * 2, spacing[0] * 2]
    measures.SliceThickness = spacing[2]
    shared.PixelMeasuresSequence = Sequence([measures])
    orient = Dataset()
    orient.ImageOrientationPatient = [1.0, 0.0, 0.0, 0.0, 1.0, 0.0]
    shared.PlaneOrientationSequence = Sequence([orient])
    ds.SharedFunctionalGroupsSequence = Sequence([shared])
    items, pixels = [], []
    for i, (n, k) in enumerate(frames):
        z = ORIGIN[2] + k * spacing[2] + (spacing[2] / 2 if bad == "position" and i == 0 else 0)
        segment = 9 if bad == "segment" and i == 0 else n
        items.append(frame_item((ORIGIN[0], ORIGIN[1], z), segment))
        if kind == "LABELMAP":
            plane = np.zeros((ny, nx), np.uint8)
            for m in sorted(masks):
                plane[masks[m][k]] = m
            pixels.append(plane)
        else:
            pixels.append(masks[n][k].astype(np.uint8) * (255 if kind == "FRACTIONAL" else 1))
    if bad == "overlap":  # a second frame on a slice, claiming a voxel for another segment
        k = frames[0][1]
        plane = np.zeros((ny, nx), np.uint8)
        plane[pixels[0] > 0] = 1 if pixels[0].max() != 1 else 2
        items.append(frame_item((ORIGIN[0], ORIGIN[1], ORIGIN[2] + k * spacing[2]), None))
        pixels.append(plane)
    ds.PerFrameFunctionalGroupsSequence = Sequence(items)
    ds.NumberOfFrames = len(pixels) + (3 if bad == "frames" else 0)
    stack = np.stack(pixels)
    ds.PixelData = (np.packbits(stack.ravel(), bitorder="little").tobytes() if kind == "BINARY"
                    else stack.tobytes())
    ds.is_little_endian, ds.is_implicit_VR = True, False
    ds.save_as(out, write_like_original=False)


VARIANTS = {"binary": [], "fractional": ["--fractional"], "labelmap": ["--labelmap"], "overlap": ["--overlap"],
            "bad-frames": ["--bad=frames"], "bad-segment": ["--bad=segment"], "bad-position": ["--bad=position"],
            "bad-spacing": ["--bad=spacing"], "bad-overlap": ["--bad=overlap"]}


def main(argv):
    flags = [a for a in argv if a.startswith("--")]
    args = [a for a in argv if not a.startswith("--")]
    if len(args) == 2 and args[0] == "variants":
        for name, variant in VARIANTS.items():
            phantom(os.path.join(args[1], name), variant)
        return
    if len(args) != 2 or args[0] != "phantom":
        sys.exit(__doc__)
    phantom(args[1], flags)


def phantom(out, flags):
    bad = next((a.split("=", 1)[1] for a in flags if a.startswith("--bad=")), None)
    kind = "FRACTIONAL" if "--fractional" in flags else "LABELMAP" if "--labelmap" in flags or bad == "overlap" else "BINARY"
    data, spacing = dicom_series.phantom()
    ct_uid = generate_uid(dicom_series.ROOT)
    ct = os.path.join(out, "ct")
    with open(os.devnull, "w") as quiet:
        stdout, sys.stdout = sys.stdout, quiet
        try:
            dicom_series.write_series(data, spacing, ct, rle=False, hu=True, uid=ct_uid)
        finally:
            sys.stdout = stdout
    labels = label_map(data)
    write_nrrd(labels, spacing, os.path.join(out, "labels.nrrd"))
    write_descriptions(os.path.join(out, "labels.txt"))
    masks = {n: labels == n for n in (1, 2, 3)}
    if "--overlap" in flags:
        masks[4] = np.zeros(labels.shape, bool)
        masks[4][8:16, 14:22, 16:24] = True  # straddles the core (2) and the shell (1)
    write_seg(masks, spacing, ct_uid, os.path.join(ct, "seg.dcm"), kind, bad)


if __name__ == "__main__":
    main(sys.argv[1:])
