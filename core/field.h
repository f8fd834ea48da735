/* field.h: analytic volumes for tests and demos, loaded as "field:NAME", "field:NAME:N" or
 * "field:NAME:WxHxD" (default 64^3).
 *
 * Index space, c = ((W-1)/2, (H-1)/2, (D-1)/2), R = min over axes of (dim-1)/2:
 *   sphere    f32  R - |p - c|: positive inside, level L is the sphere of radius R - L
 *   torus     f32  R/4 - distance to the ring of radius R/2 around c in the xy-plane
 *   ml        f32  Marschner and Lobb's test signal (1994) on [-1,1]^3, values in [0,1],
 *                  alpha 0.25, fM 6; level 0.5 is the usual one
 *   constant  u8   Elber and Malzbender's D1: every sample 1
 *   spike     f32  their D2: every sample 1 but p(0,0,0) = 0
 *   ijk       f32  their D3: p(i,j,k) = i*j*k, which one trilinear represents exactly */
#ifndef ISO_FIELD_H
#define ISO_FIELD_H

#include <stdint.h>

#include "loader.h"
#include "volume.h"

#define ISO_FIELD_PREFIX "field:"
#define ISO_FIELD_DEFAULT_SIZE 64
#define ISO_FIELD_MAX_SIZE 4096

/* "sphere, torus, ml, constant, spike, ijk": the known names, for messages. Never NULL. */
const char *iso_field_names(void);

/* Builds field `name` (a name above, without the prefix) on a dims grid, each dim in
 * 2..ISO_FIELD_MAX_SIZE, unit spacing, zero origin; stats not computed. max_bytes 0 means
 * the default. Returns 0, ISO_E_ARGUMENT (unknown name, listing the known ones, or a bad
 * size), ISO_E_LIMIT or ISO_E_NOMEM. O(samples). */
int iso_field_create(const char *name, const size_t dims[3], uint64_t max_bytes,
                     iso_volume **out, iso_error *err);

/* Parses path "field:NAME[:N|:WxHxD]" and builds the field; opt may be NULL. Safe on
 * untrusted strings. On failure *out is NULL. */
int iso_field_load(const char *path, const iso_load_options *opt, iso_volume **out,
                   iso_error *err);

#endif
