// dicom_gdcm.cc: the GDCM shim behind dicom_gdcm.h. Reads one file's header fields (plain
// tags and the enhanced multi-frame functional groups) and decodes its pixels; reads a
// Segmentation object (its segments, frames and pixel data) through GDCM's dataset API. Every entry
// point catches everything: GDCM throws on some malformed input, and C must never see it.
#include "dicom_gdcm.h"

#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <mutex>
#include <string>

#include <gdcmImage.h>
#include <gdcmImageReader.h>
#include <gdcmReader.h>
#include <gdcmSequenceOfItems.h>
#include <gdcmStringFilter.h>
#include <gdcmTrace.h>

namespace {

const gdcm::Tag kPixelData(0x7fe0, 0x0010);
const gdcm::Tag kSharedGroups(0x5200, 0x9229), kPerFrameGroups(0x5200, 0x9230);
const gdcm::Tag kPixelMeasures(0x0028, 0x9110), kPlanePosition(0x0020, 0x9113);
const gdcm::Tag kPlaneOrientation(0x0020, 0x9116), kValueTransform(0x0028, 0x9145);
const gdcm::Tag kPixelSpacing(0x0028, 0x0030), kPosition(0x0020, 0x0032);
const gdcm::Tag kOrientation(0x0020, 0x0037), kIntercept(0x0028, 0x1052), kSlope(0x0028, 0x1053);

void say(char *why, size_t size, const char *text)
{
    if (why && size)
        std::snprintf(why, size, "%s", text);
}

// GDCM's own warnings go to stderr; our messages say what failed, once. Its switches are
// process globals: set once, so that loads on different threads never write them together.
std::once_flag quiet_once;

void quiet()
{
    std::call_once(quiet_once, [] {
        gdcm::Trace::SetWarning(false);
        gdcm::Trace::SetError(false);
        gdcm::Trace::SetDebug(false);
    });
}

// A DICOM Part 10 file starts with 128 bytes of preamble and "DICM": anything else in a
// series folder (a README, a thumbnail) is not ours and is skipped without parsing.
bool has_magic(const char *path)
{
    FILE *f = std::fopen(path, "rb");
    if (!f)
        return false;
    char buf[132];
    bool ok = std::fread(buf, 1, sizeof buf, f) == sizeof buf && !std::memcmp(buf + 128, "DICM", 4);
    std::fclose(f);
    return ok;
}

// Up to n backslash-separated decimals; returns how many parsed (junk stops the count).
int decimals(const std::string &text, double *out, int n)
{
    const char *s = text.c_str();
    int count = 0;
    while (*s && count < n) {
        char *end;
        double v = std::strtod(s, &end);
        if (end == s)
            return count;
        out[count++] = v;
        s = end;
        while (*s == ' ')
            s++;
        if (*s == '\\')
            s++;
        else
            break;
    }
    return count;
}

struct Fields {
    const gdcm::StringFilter &sf;

    std::string text(const gdcm::DataSet &ds, const gdcm::Tag &t) const
    {
        if (!ds.FindDataElement(t))
            return "";
        const gdcm::DataElement &de = ds.GetDataElement(t);
        return de.IsEmpty() ? "" : sf.ToString(de);
    }
    int numbers(const gdcm::DataSet &ds, const gdcm::Tag &t, double *out, int n) const
    {
        std::string s = text(ds, t);
        return s.empty() ? 0 : decimals(s, out, n);
    }
    unsigned whole(const gdcm::DataSet &ds, const gdcm::Tag &t) const
    {
        double v = 0;
        return numbers(ds, t, &v, 1) == 1 && v >= 0 && v < 4294967295.0 ? (unsigned)v : 0;
    }
};

// The first item of sequence `seq` in ds, handed to fn while the sequence is alive (GDCM
// may parse an implicit sequence on demand into a fresh object).
template <typename Fn> void first_item(const gdcm::DataSet &ds, const gdcm::Tag &seq, Fn fn)
{
    if (!ds.FindDataElement(seq))
        return;
    gdcm::SmartPointer<gdcm::SequenceOfItems> sq = ds.GetDataElement(seq).GetValueAsSQ();
    if (sq && sq->GetNumberOfItems() >= 1)
        fn(sq->GetItem(1).GetNestedDataSet());
}

// The macros of one functional group item (shared or per frame): what it says overrides.
void read_group(const Fields &f, const gdcm::DataSet &group, iso_gdcm_header *h, iso_gdcm_frame *frame)
{
    first_item(group, kPixelMeasures, [&](const gdcm::DataSet &m) {
        f.numbers(m, kPixelSpacing, h->pixel_spacing, 2);
    });
    first_item(group, kPlaneOrientation, [&](const gdcm::DataSet &m) {
        if (f.numbers(m, kOrientation, h->orientation, 6) == 6)
            h->has_orientation = 1;
    });
    first_item(group, kPlanePosition, [&](const gdcm::DataSet &m) {
        if (frame && f.numbers(m, kPosition, frame->position, 3) == 3)
            frame->has_position = 1;
    });
    first_item(group, kValueTransform, [&](const gdcm::DataSet &m) {
        if (frame) {
            f.numbers(m, kSlope, &frame->slope, 1);
            f.numbers(m, kIntercept, &frame->intercept, 1);
        }
    });
}

// Enhanced multi-frame files: the shared group, then each frame's own.
void read_functional_groups(const Fields &f, const gdcm::DataSet &ds, iso_gdcm_header *h)
{
    first_item(ds, kSharedGroups, [&](const gdcm::DataSet &g) {
        for (unsigned i = 0; i < h->frames; i++)
            read_group(f, g, h, &h->frame[i]);
    });
    if (!ds.FindDataElement(kPerFrameGroups))
        return;
    gdcm::SmartPointer<gdcm::SequenceOfItems> sq = ds.GetDataElement(kPerFrameGroups).GetValueAsSQ();
    if (!sq)
        return;
    for (unsigned i = 0; i < h->frames && i < sq->GetNumberOfItems(); i++)
        read_group(f, sq->GetItem(i + 1).GetNestedDataSet(), h, &h->frame[i]);
}

// The classic single-frame tags (and RT dose's frame offsets and dose scaling).
void read_plain(const Fields &f, const gdcm::DataSet &ds, iso_gdcm_header *h)
{
    f.numbers(ds, kPixelSpacing, h->pixel_spacing, 2);
    if (f.numbers(ds, kOrientation, h->orientation, 6) == 6)
        h->has_orientation = 1;
    // Padding is US or SS as the pixels are; a reader that took SS bits as US gives
    // 65536 + v, folded back here for signed pixels.
    if (f.numbers(ds, gdcm::Tag(0x0028, 0x0120), &h->padding, 1) == 1 && std::isfinite(h->padding)) {
        double half = std::ldexp(1.0, h->bits_allocated ? (int)h->bits_allocated - 1 : 15);
        if (h->pixel_signed && h->padding >= half)
            h->padding -= 2 * half;
        h->has_padding = 1;
    }
    double position[3], slope = 1, intercept = 0;
    int has_position = f.numbers(ds, kPosition, position, 3) == 3;
    if (!f.numbers(ds, kSlope, &slope, 1))
        f.numbers(ds, gdcm::Tag(0x3004, 0x000e), &slope, 1); // DoseGridScaling
    f.numbers(ds, kIntercept, &intercept, 1);
    for (unsigned i = 0; i < h->frames; i++) {
        h->frame[i].slope = slope;
        h->frame[i].intercept = intercept;
        h->frame[i].has_position = has_position;
        std::memcpy(h->frame[i].position, position, sizeof position);
    }
    std::string offsets = f.text(ds, gdcm::Tag(0x3004, 0x000c)); // GridFrameOffsetVector
    if (offsets.empty() || h->frames < 1)
        return;
    h->grid_offsets = static_cast<double *>(std::calloc(h->frames, sizeof(double)));
    if (h->grid_offsets && decimals(offsets, h->grid_offsets, (int)h->frames) != (int)h->frames) {
        std::free(h->grid_offsets);
        h->grid_offsets = nullptr;
    }
}

void read_copy(const Fields &f, const gdcm::DataSet &ds, const gdcm::Tag &t, char *out, size_t size)
{
    std::string s = f.text(ds, t);
    while (!s.empty() && (s.back() == ' ' || s.back() == '\0'))
        s.pop_back();
    std::snprintf(out, size, "%s", s.c_str());
}

int read_header(const char *path, unsigned max_frames, iso_gdcm_header *h, char *why, size_t why_size)
{
    gdcm::Reader reader;
    reader.SetFileName(path);
    if (!reader.ReadUpToTag(kPixelData)) {
        say(why, why_size, "GDCM cannot parse the DICOM header (truncated or malformed)");
        return ISO_GDCM_BAD;
    }
    gdcm::StringFilter sf;
    sf.SetFile(reader.GetFile());
    Fields f{sf};
    const gdcm::DataSet &ds = reader.GetFile().GetDataSet();
    h->rows = f.whole(ds, gdcm::Tag(0x0028, 0x0010));
    h->columns = f.whole(ds, gdcm::Tag(0x0028, 0x0011));
    if (!h->rows || !h->columns)
        return ISO_GDCM_NOT_DICOM; // no image (a DICOMDIR, a report): not a slice
    h->bits_allocated = f.whole(ds, gdcm::Tag(0x0028, 0x0100));
    h->bits_stored = f.whole(ds, gdcm::Tag(0x0028, 0x0101));
    h->pixel_signed = f.whole(ds, gdcm::Tag(0x0028, 0x0103));
    h->samples_per_pixel = f.whole(ds, gdcm::Tag(0x0028, 0x0002));
    if (!h->samples_per_pixel)
        h->samples_per_pixel = 1;
    unsigned frames = f.whole(ds, gdcm::Tag(0x0028, 0x0008));
    h->frames = frames ? frames : 1;
    if (h->frames > max_frames) {
        std::snprintf(why, why_size, "NumberOfFrames %u exceeds the limit of %u", h->frames, max_frames);
        return ISO_GDCM_BAD;
    }
    read_copy(f, ds, gdcm::Tag(0x0020, 0x000e), h->series_uid, sizeof h->series_uid);
    read_copy(f, ds, gdcm::Tag(0x0008, 0x0060), h->modality, sizeof h->modality);
    read_copy(f, ds, gdcm::Tag(0x0008, 0x103e), h->series_description, sizeof h->series_description);
    read_copy(f, ds, gdcm::Tag(0x0008, 0x0016), h->sop_class, sizeof h->sop_class);
    std::snprintf(h->transfer_syntax, sizeof h->transfer_syntax, "%s",
                  reader.GetFile().GetHeader().GetDataSetTransferSyntax().GetString());
    h->frame = static_cast<iso_gdcm_frame *>(std::calloc(h->frames, sizeof *h->frame));
    if (!h->frame) {
        say(why, why_size, "out of memory");
        return ISO_GDCM_BAD;
    }
    read_plain(f, ds, h);
    read_functional_groups(f, ds, h);
    return ISO_GDCM_OK;
}

} // namespace

extern "C" int iso_gdcm_read_header(const char *path, unsigned max_frames, iso_gdcm_header *h,
                                    char *why, size_t why_size)
{
    std::memset(h, 0, sizeof *h);
    quiet();
    if (!has_magic(path))
        return ISO_GDCM_NOT_DICOM;
    int rc;
    try {
        rc = read_header(path, max_frames, h, why, why_size);
    } catch (const std::exception &e) {
        std::snprintf(why, why_size, "GDCM: %s", e.what());
        rc = ISO_GDCM_BAD;
    } catch (...) {
        say(why, why_size, "GDCM failed on the header");
        rc = ISO_GDCM_BAD;
    }
    if (rc != ISO_GDCM_OK)
        iso_gdcm_header_free(h);
    return rc;
}

extern "C" void iso_gdcm_header_free(iso_gdcm_header *h)
{
    std::free(h->frame);
    std::free(h->grid_offsets);
    h->frame = nullptr;
    h->grid_offsets = nullptr;
}

namespace {

// GDCM 3.0's raw codec swaps big-endian pixels in 16-bit words whatever BitsAllocated
// says: a 32-bit sample comes out with its two halves in the wrong order (checked against
// pydicom's rtdose_expb.dcm, which holds rtdose.dcm's samples).
void swap_halves(unsigned char *p, size_t bytes)
{
    for (size_t i = 0; i + 4 <= bytes; i += 4) {
        unsigned char a = p[i], b = p[i + 1];
        p[i] = p[i + 2];
        p[i + 1] = p[i + 3];
        p[i + 2] = a;
        p[i + 3] = b;
    }
}

int read_pixels(const char *path, const iso_gdcm_header *expect, void *dst, size_t bytes, char *why,
                size_t why_size)
{
    gdcm::ImageReader reader;
    reader.SetFileName(path);
    if (!reader.Read()) {
        say(why, why_size, "GDCM cannot read the image (unsupported or corrupt pixel data)");
        return -1;
    }
    const gdcm::Image &img = reader.GetImage();
    unsigned frames = img.GetNumberOfDimensions() >= 3 ? img.GetDimension(2) : 1;
    const gdcm::PixelFormat &pf = img.GetPixelFormat();
    if (img.GetDimension(0) != expect->columns || img.GetDimension(1) != expect->rows ||
        frames != expect->frames || pf.GetBitsAllocated() != expect->bits_allocated ||
        pf.GetSamplesPerPixel() != expect->samples_per_pixel) {
        std::snprintf(why, why_size, "the image is %ux%ux%u of %u bits, the header said %ux%ux%u of %u bits",
                      img.GetDimension(0), img.GetDimension(1), frames, (unsigned)pf.GetBitsAllocated(),
                      expect->columns, expect->rows, expect->frames, expect->bits_allocated);
        return -1;
    }
    if (img.GetBufferLength() != bytes) {
        std::snprintf(why, why_size, "the pixel data decodes to %lu bytes, not %zu", img.GetBufferLength(), bytes);
        return -1;
    }
    if (!img.GetBuffer(static_cast<char *>(dst))) {
        std::snprintf(why, why_size, "GDCM cannot decode the pixel data (%s)", expect->transfer_syntax);
        return -1;
    }
    if (expect->bits_allocated == 32 &&
        reader.GetFile().GetHeader().GetDataSetTransferSyntax() == gdcm::TransferSyntax::ExplicitVRBigEndian)
        swap_halves(static_cast<unsigned char *>(dst), bytes);
    return 0;
}

} // namespace

extern "C" int iso_gdcm_read_pixels(const char *path, const iso_gdcm_header *expect, void *dst,
                                    size_t bytes, char *why, size_t why_size)
{
    quiet();
    try {
        return read_pixels(path, expect, dst, bytes, why, why_size);
    } catch (const std::exception &e) {
        std::snprintf(why, why_size, "GDCM: %s", e.what());
    } catch (...) {
        say(why, why_size, "GDCM failed decoding the pixel data");
    }
    return -1;
}

namespace {

// DICOM Segmentation objects (dicom_gdcm.h's iso_gdcm_seg_*).
const gdcm::Tag kSopClass(0x0008, 0x0016), kSeriesUid(0x0020, 0x000e);
const gdcm::Tag kReferencedSeries(0x0008, 0x1115), kSegmentationType(0x0062, 0x0001);
const gdcm::Tag kSegmentSequence(0x0062, 0x0002), kSegmentNumber(0x0062, 0x0004), kSegmentLabel(0x0062, 0x0005);
const gdcm::Tag kCategory(0x0062, 0x0003), kType(0x0062, 0x000f), kCodeMeaning(0x0008, 0x0104);
const gdcm::Tag kLab(0x0062, 0x000d), kMaxFraction(0x0062, 0x000e);
const gdcm::Tag kSegmentIdentification(0x0062, 0x000a), kReferencedSegment(0x0062, 0x000b);

// The Segment Sequence.
bool read_segments(const Fields &f, const gdcm::DataSet &ds, iso_gdcm_seg *out, char *why, size_t why_size)
{
    if (!ds.FindDataElement(kSegmentSequence)) {
        say(why, why_size, "no Segment Sequence (0062,0002)");
        return false;
    }
    gdcm::SmartPointer<gdcm::SequenceOfItems> sq = ds.GetDataElement(kSegmentSequence).GetValueAsSQ();
    unsigned n = sq ? (unsigned)sq->GetNumberOfItems() : 0;
    if (n == 0 || n > 65535) {
        std::snprintf(why, why_size, "the Segment Sequence (0062,0002) has %u items", n);
        return false;
    }
    out->segments = static_cast<iso_gdcm_seg_segment *>(std::calloc(n, sizeof *out->segments));
    if (!out->segments) {
        say(why, why_size, "out of memory");
        return false;
    }
    out->segment_count = n;
    for (unsigned i = 0; i < n; i++) {
        const gdcm::DataSet &item = sq->GetItem(i + 1).GetNestedDataSet();
        iso_gdcm_seg_segment *s = &out->segments[i];
        s->number = f.whole(item, kSegmentNumber);
        read_copy(f, item, kSegmentLabel, s->label, sizeof s->label);
        first_item(item, kCategory, [&](const gdcm::DataSet &c) { read_copy(f, c, kCodeMeaning, s->category, sizeof s->category); });
        first_item(item, kType, [&](const gdcm::DataSet &c) { read_copy(f, c, kCodeMeaning, s->type, sizeof s->type); });
        double lab[3];
        if (f.numbers(item, kLab, lab, 3) == 3 && lab[0] >= 0 && lab[0] <= 65535 && lab[1] >= 0 && lab[1] <= 65535 &&
            lab[2] >= 0 && lab[2] <= 65535) {
            for (int c = 0; c < 3; c++)
                s->lab[c] = (uint16_t)lab[c];
            s->has_lab = 1;
        }
    }
    return true;
}

// The shared and per-frame functional groups.
void read_groups(const Fields &f, const gdcm::DataSet &ds, iso_gdcm_seg *out)
{
    first_item(ds, kSharedGroups, [&](const gdcm::DataSet &g) {
        first_item(g, kPixelMeasures, [&](const gdcm::DataSet &m) { f.numbers(m, kPixelSpacing, out->pixel_spacing, 2); });
        first_item(g, kPlaneOrientation, [&](const gdcm::DataSet &m) {
            out->has_orientation = f.numbers(m, kOrientation, out->orientation, 6) == 6;
        });
    });
    if (!ds.FindDataElement(kPerFrameGroups))
        return;
    gdcm::SmartPointer<gdcm::SequenceOfItems> sq = ds.GetDataElement(kPerFrameGroups).GetValueAsSQ();
    if (!sq)
        return;
    out->per_frame_items = (unsigned)sq->GetNumberOfItems();
    for (unsigned i = 0; i < out->frames && i < out->per_frame_items; i++) {
        const gdcm::DataSet &g = sq->GetItem(i + 1).GetNestedDataSet();
        iso_gdcm_seg_frame *fr = &out->frame[i];
        first_item(g, kPlanePosition, [&](const gdcm::DataSet &m) {
            fr->has_position = f.numbers(m, kPosition, fr->position, 3) == 3;
        });
        first_item(g, kSegmentIdentification, [&](const gdcm::DataSet &m) { fr->segment = f.whole(m, kReferencedSegment); });
        // A frame may say its own plane geometry (not shared): the first one found counts.
        if (!out->has_orientation)
            first_item(g, kPlaneOrientation, [&](const gdcm::DataSet &m) {
                out->has_orientation = f.numbers(m, kOrientation, out->orientation, 6) == 6;
            });
        if (!out->pixel_spacing[0])
            first_item(g, kPixelMeasures, [&](const gdcm::DataSet &m) { f.numbers(m, kPixelSpacing, out->pixel_spacing, 2); });
    }
}

// The pixel data: native bytes as stored, or GDCM's decode of encapsulated ones.
bool read_pixel_data(const char *path, const gdcm::DataSet &ds, iso_gdcm_seg *out, char *why, size_t why_size)
{
    if (!ds.FindDataElement(kPixelData)) {
        say(why, why_size, "no Pixel Data (7FE0,0010)");
        return false;
    }
    const gdcm::DataElement &de = ds.GetDataElement(kPixelData);
    const gdcm::ByteValue *bv = de.GetByteValue();
    if (bv) {
        out->pixel_bytes = bv->GetLength();
        out->pixels = static_cast<unsigned char *>(std::malloc(out->pixel_bytes ? out->pixel_bytes : 1));
        if (!out->pixels) {
            say(why, why_size, "out of memory for the pixel data");
            return false;
        }
        std::memcpy(out->pixels, bv->GetPointer(), out->pixel_bytes);
        return true;
    }
    gdcm::ImageReader reader;
    reader.SetFileName(path);
    if (!reader.Read()) {
        say(why, why_size, "GDCM cannot decode the encapsulated pixel data");
        return false;
    }
    const gdcm::Image &img = reader.GetImage();
    out->pixel_bytes = img.GetBufferLength();
    out->pixels = static_cast<unsigned char *>(std::malloc(out->pixel_bytes ? out->pixel_bytes : 1));
    if (!out->pixels || !img.GetBuffer(reinterpret_cast<char *>(out->pixels))) {
        say(why, why_size, "GDCM cannot decode the encapsulated pixel data");
        return false;
    }
    return true;
}

bool read_all(const char *path, unsigned max_frames, iso_gdcm_seg *out, char *why, size_t why_size)
{
    gdcm::Reader reader;
    reader.SetFileName(path);
    if (!reader.Read()) {
        say(why, why_size, "GDCM cannot parse the file (truncated or malformed)");
        return false;
    }
    gdcm::StringFilter sf;
    sf.SetFile(reader.GetFile());
    Fields f{sf};
    const gdcm::DataSet &ds = reader.GetFile().GetDataSet();
    read_copy(f, ds, kSopClass, out->sop_class, sizeof out->sop_class);
    read_copy(f, ds, kSeriesUid, out->series_uid, sizeof out->series_uid);
    read_copy(f, ds, kSegmentationType, out->type, sizeof out->type);
    first_item(ds, kReferencedSeries, [&](const gdcm::DataSet &r) {
        read_copy(f, r, kSeriesUid, out->referenced_series, sizeof out->referenced_series);
    });
    out->rows = f.whole(ds, gdcm::Tag(0x0028, 0x0010));
    out->columns = f.whole(ds, gdcm::Tag(0x0028, 0x0011));
    out->bits_allocated = f.whole(ds, gdcm::Tag(0x0028, 0x0100));
    unsigned frames = f.whole(ds, gdcm::Tag(0x0028, 0x0008));
    out->frames = frames ? frames : 1;
    out->max_fraction = 0;
    f.numbers(ds, kMaxFraction, &out->max_fraction, 1);
    if (out->frames > max_frames) {
        std::snprintf(why, why_size, "NumberOfFrames %u exceeds the limit of %u", out->frames, max_frames);
        return false;
    }
    out->frame = static_cast<iso_gdcm_seg_frame *>(std::calloc(out->frames, sizeof *out->frame));
    if (!out->frame) {
        say(why, why_size, "out of memory");
        return false;
    }
    if (std::strcmp(out->type, "LABELMAP") && !read_segments(f, ds, out, why, why_size))
        return false;
    if (!std::strcmp(out->type, "LABELMAP") && ds.FindDataElement(kSegmentSequence) &&
        !read_segments(f, ds, out, why, why_size))
        return false;
    read_groups(f, ds, out);
    return read_pixel_data(path, ds, out, why, why_size);
}

} // namespace

extern "C" int iso_gdcm_seg_probe(const char *path, char *sop_class, size_t sop_size, char *series_uid,
                                   size_t series_size, char *why, size_t why_size)
{
    sop_class[0] = series_uid[0] = '\0';
    if (!has_magic(path))
        return 1;
    quiet();
    try {
        gdcm::Reader reader;
        reader.SetFileName(path);
        if (!reader.ReadUpToTag(gdcm::Tag(0x0020, 0x000f))) {
            say(why, why_size, "GDCM cannot parse the DICOM header (truncated or malformed)");
            return -1;
        }
        gdcm::StringFilter sf;
        sf.SetFile(reader.GetFile());
        Fields f{sf};
        const gdcm::DataSet &ds = reader.GetFile().GetDataSet();
        read_copy(f, ds, kSopClass, sop_class, sop_size);
        read_copy(f, ds, kSeriesUid, series_uid, series_size);
        return 0;
    } catch (const std::exception &e) {
        std::snprintf(why, why_size, "GDCM: %s", e.what());
    } catch (...) {
        say(why, why_size, "GDCM failed on the header");
    }
    return -1;
}

extern "C" int iso_gdcm_seg_read(const char *path, unsigned max_frames, iso_gdcm_seg *out, char *why,
                                  size_t why_size)
{
    std::memset(out, 0, sizeof *out);
    quiet();
    bool ok = false;
    try {
        ok = read_all(path, max_frames, out, why, why_size);
    } catch (const std::exception &e) {
        std::snprintf(why, why_size, "GDCM: %s", e.what());
    } catch (...) {
        say(why, why_size, "GDCM failed reading the segmentation");
    }
    if (!ok)
        iso_gdcm_seg_free(out);
    return ok ? 0 : -1;
}

extern "C" void iso_gdcm_seg_free(iso_gdcm_seg *seg)
{
    std::free(seg->segments);
    std::free(seg->frame);
    std::free(seg->pixels);
    seg->segments = nullptr;
    seg->frame = nullptr;
    seg->pixels = nullptr;
}
