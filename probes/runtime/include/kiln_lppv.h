/* kiln_lppv.h: C99 API for light probe proxy volumes (LPPV): load a .klppv file written by
 * `kiln probes lppv`, sample its L2 spherical harmonics at a point with trilinear filtering, and
 * evaluate irradiance for a surface normal. Same conventions as kiln_runtime.h (whose status
 * codes it uses): an opaque reference-counted handle, verb-object names, a status code from
 * every call. No call throws or aborts.
 *
 * Conventions (see kiln/sh.h, kiln/lppv_volume.h): positions in glTF world space (metres, +Y
 * up). SH arrays are 27 floats, coefficient-major with RGB innermost: sh[3 * i + channel],
 * i = l(l + 1) + m in the real orthonormal basis, holding RADIANCE. Irradiance is E (not
 * E / pi). Outside the volume's outermost samples the value is clamped to the edge.
 *
 * Errors: the message of the last failed kiln_lppv_* call on this thread is returned by
 * kiln_lppv_last_error() (kiln_last_error() covers the kiln_probes_* calls).
 *
 * Thread safety: a loaded kiln_lppv is immutable; every query may run concurrently on the
 * same handle. Queries do not allocate.
 */
#ifndef KILN_LPPV_H
#define KILN_LPPV_H

#include <stddef.h>
#include <stdint.h>

#include "kiln_runtime.h"

#ifdef __cplusplus
extern "C" {
#endif

/* A loaded volume (opaque, reference counted). */
typedef struct kiln_lppv kiln_lppv;

/* Where the grid samples sit (see docs/lppv.md). */
typedef enum kiln_lppv_placement {
  KILN_LPPV_CELL_CENTER = 0, /* sample i at min + (i + 0.5) (max - min) / n */
  KILN_LPPV_CELL_CORNER = 1  /* sample i at min + i (max - min) / (n - 1) */
} kiln_lppv_placement;

/* The grid's box, resolution and placement. Cells are x fastest, then y, then z. */
typedef struct kiln_lppv_info {
  float bounds_min[3];
  float bounds_max[3];
  uint32_t resolution[3];
  kiln_lppv_placement placement;
} kiln_lppv_info;

/* Loads and validates `path`; on success *out holds a handle with one reference. */
kiln_status kiln_lppv_load(const char* path, kiln_lppv** out);
void kiln_lppv_retain(kiln_lppv* volume);
/* Drops one reference; the data is freed with the last. NULL is ignored. */
void kiln_lppv_release(kiln_lppv* volume);

kiln_status kiln_lppv_get_info(const kiln_lppv* volume, kiln_lppv_info* out);

/* Trilinearly filtered radiance SH at position[3] into out_sh[27]; out_validity (may be NULL)
 * gets the blended probe validity in [0, 1]. */
kiln_status kiln_lppv_sample_sh(const kiln_lppv* volume, const float position[3], float out_sh[27],
                                float* out_validity);

/* Irradiance E (RGB) at position[3] for unit normal[3]. */
kiln_status kiln_lppv_irradiance(const kiln_lppv* volume, const float position[3],
                                 const float normal[3], float out_rgb[3]);

/* Batch: `count` points (positions: 3 * count floats) into out_sh (27 * count floats). */
kiln_status kiln_lppv_sample_batch(const kiln_lppv* volume, size_t count, const float* positions,
                                   float* out_sh);

/* Message for the last failed kiln_lppv_* call on this thread ("" when none). Valid until the
 * next kiln_lppv_* call on this thread. */
const char* kiln_lppv_last_error(void);

#ifdef __cplusplus
}
#endif

#endif /* KILN_LPPV_H */
