/* orthanc.h: a DICOM series on an Orthanc server (its REST API, through libcurl) as a
 * volume source of the catalog.
 *
 * GET {url}/series/{id} lists the instances, GET {url}/instances/{iid}/file fetches each
 * one's DICOM file; the files then load as a DICOM series directory (core/io/io.h). With a
 * cache dir the files stay in {cache_dir}/orthanc/{archive}/{id}/ (written under a
 * temporary name, renamed when complete; {archive} is a hash of the server's base URL, so
 * two archives holding the same series never share files), and later loads read them
 * without asking the server. Without a cache dir they go to a temporary directory
 * that is removed after loading. */
#ifndef SRV_ORTHANC_H
#define SRV_ORTHANC_H

#include "io/io.h"
#include "segment/segment.h"
#include "volume/volume.h"

/* 1 if url is http:// or https:// followed by a host (no spaces, quotes or control bytes). */
int srv_orthanc_url_valid(const char *url);
/* 1 if id looks like an Orthanc id: [0-9a-f-]{1,64} (it is used in URLs and file names). */
int srv_orthanc_id_valid(const char *id);

/* Loads the series (from the cache dir when it holds it). On failure *upstream is 1 when
 * the server was unreachable or answered an error (the caller's 503, retried later), 0 when the files
 * came but did not make a volume. Progress on the terminal through opt->progress. */
int srv_orthanc_load(const char *url, const char *series, const char *cache_dir,
                     const iso_load_options *opt, iso_volume **out, iso_error *err, int *upstream);

/* srv_orthanc_load for a DICOM SEG series: the SEG, then the series of its study it
 * references, fetched into one folder and loaded as a segmentation (segment.h). */
int srv_orthanc_load_segmentation(const char *url, const char *series, const char *cache_dir,
                                  const iso_load_options *opt, iso_segmentation **out, iso_error *err, int *upstream);

#endif
