/* nifti.c: NIfTI-1/2 through libnifti2 (see nifti.h). */
#include "nifti.h"

#include <math.h>
#include <nifti2_io.h>
#include <pthread.h>
#include <stdlib.h>
#include <string.h>

/* NIfTI datatype codes and the core's types. */
static int type_of(int datatype, iso_voxel_type *type)
{
    switch (datatype) {
    case DT_UINT8: *type = ISO_U8; return 0;
    case DT_INT8: *type = ISO_I8; return 0;
    case DT_UINT16: *type = ISO_U16; return 0;
    case DT_INT16: *type = ISO_I16; return 0;
    case DT_UINT32: *type = ISO_U32; return 0;
    case DT_INT32: *type = ISO_I32; return 0;
    case DT_FLOAT32: *type = ISO_F32; return 0;
    case DT_FLOAT64: *type = ISO_F64; return 0;
    default: return -1;
    }
}

/* The voxel sizes as stored. Without an sform they are the geometry, and the library
 * quietly takes 1 for a zero size, which would hide a broken header. */
static int stored_pixdim(const char *path, double pixdim[4])
{
    int version = 0;
    void *header = nifti_read_header(path, &version, 1);
    if (!header)
        return -1;
    for (int a = 0; a < 4; a++)
        pixdim[a] = version == 2 ? ((nifti_2_header *)header)->pixdim[a]
                                 : ((nifti_1_header *)header)->pixdim[a];
    free(header);
    return 0;
}

/* Header checks before any sample is read: 3-D, a supported type, a size within limits. */
static int check_header(const char *path, const nifti_image *nim, const iso_load_options *opt,
                        iso_voxel_type *type, size_t dims[3], iso_error *err)
{
    uint64_t bytes;
    if (type_of(nim->datatype, type))
        return iso_error_set(err, ISO_E_UNSUPPORTED, "%s: NIfTI datatype %d (%s) is not a scalar type isoserve reads",
                             path, nim->datatype, nifti_datatype_string(nim->datatype));
    if (nim->ndim < 3 || nim->nx < 2 || nim->ny < 2 || nim->nz < 2)
        return iso_error_set(err, ISO_E_FORMAT, "%s: dims %lldx%lldx%lld: a volume needs at least 2 samples per axis",
                             path, (long long)nim->nx, (long long)nim->ny, (long long)nim->nz);
    for (int d = 4; d <= nim->ndim && d < 8; d++)
        if (nim->dim[d] > 1)
            return iso_error_set(err, ISO_E_UNSUPPORTED, "%s: %lld volumes along dimension %d; isoserve reads one 3-D volume",
                                 path, (long long)nim->dim[d], d);
    double pixdim[4];
    if (nim->sform_code <= 0 && stored_pixdim(path, pixdim) == 0)
        for (int a = 1; a <= 3; a++)
            if (!(pixdim[a] > 0) || !isfinite(pixdim[a]))
                return iso_error_set(err, ISO_E_FORMAT, "%s: voxel size pixdim[%d] = %g is zero, negative or not finite",
                                     path, a, pixdim[a]);
    dims[0] = (size_t)nim->nx, dims[1] = (size_t)nim->ny, dims[2] = (size_t)nim->nz;
    iso_error size_err;
    if (iso_vol_check_size(dims, *type, opt && opt->max_bytes ? opt->max_bytes : ISO_VOL_DEFAULT_MAX_BYTES,
                           &bytes, &size_err))
        return iso_error_set(err, ISO_E_LIMIT, "%s: %s", path, size_err.message);
    return 0;
}

/* scl_slope and scl_inter applied to vol's samples (copied as stored): integers into the
 * narrowest type that holds the values present (volume.h), floats in place. */
static int rescale(const char *path, const nifti_image *nim, iso_volume *vol, uint64_t max_bytes, iso_error *err)
{
    if (iso_vol_type_is_float(vol->type)) {
        size_t n = iso_vol_count(vol);
        for (size_t at = 0; at < n; at++)
            iso_vol_set(vol, at % vol->dims[0], at / vol->dims[0] % vol->dims[1], at / (vol->dims[0] * vol->dims[1]),
                        nim->scl_slope * iso_vol_sample(vol, at) + nim->scl_inter);
        return 0;
    }
    double *slope = malloc(2 * vol->dims[2] * sizeof *slope);
    if (!slope)
        return iso_error_set(err, ISO_E_NOMEM, "%s: out of memory", path);
    double *intercept = slope + vol->dims[2];
    for (size_t k = 0; k < vol->dims[2]; k++)
        slope[k] = nim->scl_slope, intercept[k] = nim->scl_inter;
    iso_error why = {0};
    int rc = iso_vol_rescale(vol, slope, intercept, max_bytes, &why);
    if (rc)
        rc = iso_error_set(err, rc, "%s: %s", path, why.message);
    free(slope);
    return rc;
}

/* The sform if set, else the qform; RAS to LPS by negating the x and y rows. */
static int set_geometry(const char *path, const nifti_image *nim, iso_volume *vol, iso_error *err)
{
    const nifti_dmat44 *m = nim->sform_code > 0 ? &nim->sto_xyz : &nim->qto_xyz;
    double affine[3][4];
    for (int r = 0; r < 3; r++)
        for (int c = 0; c < 4; c++)
            affine[r][c] = (r < 2 ? -1.0 : 1.0) * m->m[r][c];
    char what[600];
    snprintf(what, sizeof what, "%s (%s)", path, nim->sform_code > 0 ? "sform" : "qform");
    int rc = iso_vol_set_affine(vol, affine, what, err);
    /* Code 0 on both is NIfTI's "unknown": the qform is then the voxel sizes alone. */
    if (!rc)
        vol->oriented = nim->sform_code > 0 || nim->qform_code > 0;
    return rc;
}

/* libnifti keeps its options (the debug level, set here, among them) in one global that
 * nifti_image_read and nifti_image_load read and write: loads of different files on
 * different threads (collection.c loads on demand without its lock) take turns. */
static pthread_mutex_t nifti_lock = PTHREAD_MUTEX_INITIALIZER;

static int load_locked(const char *path, const iso_load_options *opt, iso_volume **out,
                       iso_error *err);

int iso_nifti_load(const char *path, const iso_load_options *opt, iso_volume **out,
                   iso_error *err)
{
    pthread_mutex_lock(&nifti_lock);
    int rc = load_locked(path, opt, out, err);
    pthread_mutex_unlock(&nifti_lock);
    return rc;
}

static int load_locked(const char *path, const iso_load_options *opt, iso_volume **out,
                       iso_error *err)
{
    *out = NULL;
    nifti_set_debug_level(0); /* our messages say what failed; the library's would repeat it */
    nifti_image *nim = nifti_image_read(path, 0);
    if (!nim)
        return iso_error_set(err, ISO_E_FORMAT, "%s: not a readable NIfTI-1/2 file (bad header, or cannot open)", path);
    iso_voxel_type source = ISO_U8, type;
    size_t dims[3];
    int rc = check_header(path, nim, opt, &source, dims, err);
    int rescaled = nim->scl_slope != 0 && isfinite(nim->scl_slope) && isfinite(nim->scl_inter) &&
                   (nim->scl_slope != 1 || nim->scl_inter != 0);
    type = source;
    if (!rc && nifti_image_load(nim) != 0)
        rc = iso_error_set(err, ISO_E_TRUNCATED, "%s: the samples cannot be read (file shorter than its header says?)", path);
    iso_volume *vol = NULL;
    if (!rc) {
        vol = iso_vol_create(dims, type, opt ? opt->max_bytes : 0, err);
        rc = vol ? 0 : ISO_E_NOMEM;
    }
    if (!rc)
        rc = set_geometry(path, nim, vol, err);
    if (!rc)
        memcpy(vol->data, nim->data, iso_vol_count(vol) * iso_vol_type_size(source));
    if (!rc && rescaled)
        rc = rescale(path, nim, vol, opt ? opt->max_bytes : 0, err);
    nifti_image_free(nim);
    if (rc) {
        iso_vol_destroy(vol);
        return rc;
    }
    *out = vol;
    return 0;
}
