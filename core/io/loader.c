/* loader.c: the table of volume loaders behind iso_load (io.h). */
#include "io.h"

#include <assert.h>
#include <string.h>
#include <strings.h>

#include "metaimage.h"
#include "nifti.h"
#include "nrrd.h"
#include "sidecar.h"

typedef struct loader {
    const char *name;
    int (*recognises)(const char *path); /* by name only (the raw sidecar: by its file) */
    int (*load)(const char *path, const iso_load_options *opt, iso_volume **out,
                iso_error *err);
} loader;

static int has_suffix(const char *path, const char *suffix)
{
    size_t n = strlen(path), m = strlen(suffix);
    return n > m && strcasecmp(path + n - m, suffix) == 0;
}

static int is_field(const char *path)
{
    return strncmp(path, ISO_FIELD_PREFIX, sizeof ISO_FIELD_PREFIX - 1) == 0;
}

/* A detached header's data file (.raw, .raw.gz) is not matched: it is no volume alone. */
static int is_nrrd(const char *path)
{
    return has_suffix(path, ".nrrd") || has_suffix(path, ".nhdr");
}

static int is_nifti(const char *path)
{
    return has_suffix(path, ".nii") || has_suffix(path, ".nii.gz");
}

static int is_metaimage(const char *path)
{
    return has_suffix(path, ".mhd") || has_suffix(path, ".mha");
}

/* Tried in order, the first that recognises a path loads it. Prefixes such as "field:"
 * come first so that they win over any suffix; then a file with a NAME.json sidecar,
 * whatever its suffix; DICOM (a directory, "DIR#UID" or .dcm) comes last. */
static const loader loaders[] = {
    {"field", is_field, iso_field_load},
    {"raw", iso_sidecar_recognises, iso_sidecar_load},
    {"nrrd", is_nrrd, iso_nrrd_load},
    {"nifti", is_nifti, iso_nifti_load},
    {"metaimage", is_metaimage, iso_metaimage_load},
    {"dicom", iso_dicom_recognises, iso_dicom_load},
};

#define LOADER_COUNT (sizeof loaders / sizeof loaders[0])

static const loader *find_loader(const char *path)
{
    for (size_t l = 0; l < LOADER_COUNT; l++)
        if (loaders[l].recognises(path))
            return &loaders[l];
    return NULL;
}

int iso_load(const char *path, const iso_load_options *opt, iso_volume **out, iso_error *err)
{
    const loader *l;
    int rc;
    assert(path && out);
    *out = NULL;
    l = find_loader(path);
    if (!l)
        return iso_error_set(err, ISO_E_UNSUPPORTED,
                             "%s: not a volume format isoserve reads (.nrrd, .nhdr, .nii, .nii.gz, .mhd, .mha, a DICOM series directory, .dcm, field:NAME, raw samples with a NAME.json sidecar)",
                             path);
    rc = l->load(path, opt, out, err);
    if (rc != ISO_OK) {
        assert(*out == NULL);
        return rc;
    }
    iso_vol_update_stats(*out);
    return ISO_OK;
}

int iso_load_recognises(const char *path)
{
    assert(path);
    return find_loader(path) != NULL;
}
