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

#include "io.h" /* the Segmentation reader's declarations (iso_gdcm_seg_*) */

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
    double padding;          /* PixelPaddingValue (0028,0120) as stored (signed for signed pixels) */
    int has_padding;
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

#ifdef __cplusplus
}
#endif

#endif
