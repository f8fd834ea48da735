/* load.c: a segmentation from any source (segment.h): a .seg.nrrd, a DICOM SEG, else any
 * volume the loaders read, as a label map. */
#include "segment.h"

int iso_seg_load(const char *path, const char *descriptions, const iso_load_options *opt,
                 iso_segmentation **out, iso_error *err)
{
    *out = NULL;
    if (iso_seg_nrrd_recognises(path))
        return iso_seg_nrrd_load(path, opt, out, err);
    if (iso_seg_dicom_recognises(path))
        return iso_seg_dicom_load(path, opt, out, err);
    iso_volume *vol;
    int rc = iso_load(path, opt, &vol, err);
    if (rc)
        return rc;
    return iso_seg_from_labels(vol, descriptions, out, err);
}
