/* dicomweb.h: DICOM series from any DICOMweb archive (Orthanc with its DICOMweb plugin,
 * dcm4chee, the cloud archives) as a volume source of the catalog.
 *
 * QIDO-RS finds series: GET {url}/series?{query} (Accept: application/dicom+json), e.g.
 * `ModalitiesInStudy=CT` or `StudyInstanceUID=...&Modality=CT`. WADO-RS fetches one:
 * GET {url}/studies/{study}/series/{series} (Accept: multipart/related;
 * type="application/dicom"; transfer-syntax=*), one part per instance, in whatever transfer
 * syntax the archive stores (GDCM reads them); the parts become the files of a series
 * folder, cached as fetch.h says under {cache_dir}/dicomweb/{archive}/{series}/.
 * Credentials (optional) come from a file: "bearer TOKEN" or "basic USER:PASSWORD". */
#ifndef SRV_DICOMWEB_H
#define SRV_DICOMWEB_H

#include <stddef.h>

#include "io/io.h"
#include "segment/segment.h"
#include "volume/volume.h"

#define SRV_UID_MAX 64

/* 1 if uid is a DICOM UID: [0-9.]{1,64}. */
int srv_dicomweb_uid_valid(const char *uid);

/* One series a QIDO-RS query found. */
typedef struct srv_dicomweb_series {
    char study[SRV_UID_MAX + 1], series[SRV_UID_MAX + 1];
    char modality[17], description[65];
} srv_dicomweb_series;

/* The series matching query (a QIDO-RS query string without the "?", "" for all) at url:
 * *out (malloc'd, caller frees) holds *count of them. Results without valid UIDs are
 * skipped. 0, or an ISO_E_* code with err saying why (*upstream: the archive failed). */
int srv_dicomweb_find(const char *url, const char *query, const char *credentials,
                      srv_dicomweb_series **out, size_t *count, iso_error *err, int *upstream);

/* Loads the series (study may be "" or NULL: a QIDO-RS lookup finds it) from the cache dir
 * when it holds it, else through WADO-RS. Progress on the terminal through opt->progress. */
int srv_dicomweb_load(const char *url, const char *study, const char *series, const char *credentials,
                      const char *cache_dir, const iso_load_options *opt, iso_volume **out,
                      iso_error *err, int *upstream);

/* srv_dicomweb_load for a DICOM SEG series: the SEG, then (found by QIDO-RS) the series it
 * references, fetched into one folder and loaded as a segmentation (segment.h). */
int srv_dicomweb_load_segmentation(const char *url, const char *study, const char *series, const char *credentials,
                                   const char *cache_dir, const iso_load_options *opt, iso_segmentation **out,
                                   iso_error *err, int *upstream);

#endif
