/* dicom_gdcm.h: the C face of the GDCM shim (dicom_gdcm.cc), the one place that speaks C++.
 *
 * It reads what one DICOM file says about its frames (the header, without decoding
 * pixels) and decodes its pixel data whatever the transfer syntax (raw little or big
 * endian, RLE, JPEG lossless, JPEG-LS, JPEG 2000). Every GDCM call runs inside try/catch:
 * a hostile file yields an error message, never an exception through C. Sorting frames
 * into a volume is dicom.c's job; nothing here knows about volumes. */
#ifndef ISO_DICOM_GDCM_H
#define ISO_DICOM_GDCM_H

#include <stddef.h>
#include <stdint.h>

#ifdef __cplusplus
extern "C" {
#endif

/* One frame's place and value map (single-frame files have one). */
typedef struct iso_gdcm_frame {
    double position[3];      /* ImagePositionPatient (LPS mm) of the frame's first pixel */
    int has_position;
    double slope, intercept; /* RescaleSlope/Intercept (DoseGridScaling for RT dose): 1, 0 if absent */
} iso_gdcm_frame;

typedef struct iso_gdcm_header {
    char series_uid[80];     /* SeriesInstanceUID, "" if absent */
    char sop_class[80];      /* SOPClassUID, "" if absent */
    char transfer_syntax[80];
    char modality[17];       /* Modality (0008,0060), "" if absent */
    char series_description[65]; /* SeriesDescription (0008,103E), "" if absent */
    unsigned rows, columns, frames;
    unsigned bits_allocated, bits_stored, pixel_signed, samples_per_pixel;
    double pixel_spacing[2]; /* PixelSpacing: between rows, between columns; 0 if absent */
    double orientation[6];   /* ImageOrientationPatient: row direction, column direction */
    int has_orientation;
    double *grid_offsets;    /* RT dose GridFrameOffsetVector (frames values) or NULL */
    iso_gdcm_frame *frame;   /* frames entries, malloc'd */
} iso_gdcm_header;

enum { ISO_GDCM_OK = 0, ISO_GDCM_NOT_DICOM = 1, ISO_GDCM_BAD = -1 };

/* Reads the header of `path` (stops before the pixel data). Returns ISO_GDCM_OK,
 * ISO_GDCM_NOT_DICOM (no DICOM preamble/meta: not ours, skipped quietly by callers) or
 * ISO_GDCM_BAD with why filled. On success free h with iso_gdcm_header_free. max_frames
 * caps NumberOfFrames before anything is allocated for them. */
int iso_gdcm_read_header(const char *path, unsigned max_frames, iso_gdcm_header *h, char *why,
                         size_t why_size);
void iso_gdcm_header_free(iso_gdcm_header *h);

/* Decodes every frame of `path` into dst: exactly `bytes` bytes (columns x rows x frames x
 * bits_allocated/8, host byte order), or fails with why when the decoded image has another
 * size or layout than `expect` says. 0 or -1. */
int iso_gdcm_read_pixels(const char *path, const iso_gdcm_header *expect, void *dst, size_t bytes,
                         char *why, size_t why_size);

/* DICOM Segmentation objects (PS3.3 A.51, C.8.20): what a SEG says (its segments, its
 * type, its frames' places and segments, the shared plane geometry, the series it was
 * derived from) and its pixel data as stored, read with GDCM's dataset API. Placing the
 * frames on a grid is core/segment/dicom_seg.c's job. */

/* Segmentation Storage, and Label Map Segmentation Storage (2024). */
#define ISO_GDCM_SEG_SOP_CLASS "1.2.840.10008.5.1.4.1.1.66.4"
#define ISO_GDCM_SEG_LABELMAP_SOP_CLASS "1.2.840.10008.5.1.4.1.1.66.7"

typedef struct iso_gdcm_seg_segment {
    unsigned number;          /* Segment Number (0062,0004) */
    char label[128];          /* Segment Label (0062,0005) */
    char category[128];       /* Segmented Property Category (0062,0003) > Code Meaning */
    char type[128];           /* Segmented Property Type (0062,000F) > Code Meaning */
    uint16_t lab[3];          /* Recommended Display CIELab Value (0062,000D) */
    int has_lab;
} iso_gdcm_seg_segment;

typedef struct iso_gdcm_seg_frame {
    double position[3];       /* Plane Position (0020,9113) > Image Position (Patient) */
    int has_position;
    unsigned segment;         /* Segment Identification (0062,000A) > Referenced Segment Number; 0 if absent */
} iso_gdcm_seg_frame;

typedef struct iso_gdcm_seg {
    char sop_class[80], series_uid[80];
    char referenced_series[80];   /* Referenced Series Sequence (0008,1115) > SeriesInstanceUID */
    char type[16];                /* Segmentation Type (0062,0001): BINARY, FRACTIONAL, LABELMAP */
    unsigned rows, columns, frames, bits_allocated;
    double max_fraction;          /* Maximum Fractional Value (0062,000E) */
    double pixel_spacing[2];      /* shared Pixel Measures: between rows, between columns */
    double orientation[6];        /* shared Plane Orientation (0020,9116) */
    int has_orientation;
    unsigned per_frame_items;     /* items in Per-frame Functional Groups (5200,9230) */
    iso_gdcm_seg_segment *segments; /* segment_count, malloc'd */
    unsigned segment_count;
    iso_gdcm_seg_frame *frame;   /* frames entries, malloc'd */
    unsigned char *pixels;        /* the Pixel Data as stored (1-bit packed, or 8/16-bit), malloc'd */
    size_t pixel_bytes;
} iso_gdcm_seg;

/* Reads SOP Class and Series UIDs only (the header up to them): 0, 1 when path is no
 * DICOM file, -1 with why. */
int iso_gdcm_seg_probe(const char *path, char *sop_class, size_t sop_size, char *series_uid, size_t series_size,
                        char *why, size_t why_size);
/* Reads the whole object, pixel data included (uncompressed or deflated; an encapsulated
 * one is decoded by GDCM). max_frames caps NumberOfFrames. 0, or -1 with why. On success
 * free with iso_gdcm_seg_free. */
int iso_gdcm_seg_read(const char *path, unsigned max_frames, iso_gdcm_seg *out, char *why, size_t why_size);
void iso_gdcm_seg_free(iso_gdcm_seg *seg);

#ifdef __cplusplus
}
#endif

#endif
