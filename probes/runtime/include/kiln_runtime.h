/* kiln_runtime.h: C99 API of kiln's light-probe runtime (what a game links).
 *
 * Load a .kprobe file written by `kiln probes`, find the probes around a point and blend
 * their L2 spherical harmonics, then evaluate irradiance for a surface normal. Modelled on
 * Embree's API: an opaque reference-counted handle, verb-object names, a status code from
 * every call plus a message from kiln_last_error(). No call throws or aborts.
 *
 * Conventions (see src/sh.h): positions in glTF world space (metres, +Y up). SH arrays are 27
 * floats, coefficient-major with RGB innermost: sh[3 * i + channel], i = l(l + 1) + m in the
 * real orthonormal basis, holding RADIANCE. Irradiance is E (not E / pi).
 *
 * Thread safety: a loaded kiln_probes is immutable; every query may run concurrently on the
 * same handle. Queries do not allocate. kiln_last_error() is per thread.
 */
#ifndef KILN_RUNTIME_H
#define KILN_RUNTIME_H

#include <stddef.h>
#include <stdint.h>

#ifdef __cplusplus
extern "C" {
#endif

typedef enum kiln_status {
  KILN_OK = 0,
  KILN_ERROR_INVALID_ARGUMENT = 1, /* a NULL pointer or other misuse */
  KILN_ERROR_IO = 2,               /* the file cannot be opened or read */
  KILN_ERROR_INVALID_FILE = 3,     /* the file is not a valid .kprobe file */
  KILN_ERROR_OUT_OF_MEMORY = 4,
  KILN_ERROR_UNKNOWN = 5
} kiln_status;

/* A loaded probe set (opaque, reference counted). */
typedef struct kiln_probes kiln_probes;

/* Result of a lookup: weights are >= 0 and sum to 1. Unused slots repeat probes[0] with weight
 * 0. Pass `cell` back as the hint of the next lookup for the same object. */
typedef struct kiln_probe_location {
  int32_t cell;
  int32_t probes[4];
  float weights[4];
} kiln_probe_location;

/* Loads `path`; on success *out holds a handle with one reference. */
kiln_status kiln_probes_load(const char* path, kiln_probes** out);
void kiln_probes_retain(kiln_probes* probes);
/* Drops one reference; the data is freed with the last. NULL is ignored. */
void kiln_probes_release(kiln_probes* probes);

/* Number of probes and of cells (cells bound the valid hints: 0 .. cells - 1). */
uint32_t kiln_probes_count(const kiln_probes* probes);
uint32_t kiln_probes_cell_count(const kiln_probes* probes);

/* Finds the cell around position[3]. hint: the cell of the previous lookup or -1. */
kiln_status kiln_probes_locate(const kiln_probes* probes, const float position[3], int32_t hint,
                               kiln_probe_location* out);

/* Blends the located probes' radiance SH into out_sh[27]. */
kiln_status kiln_probes_sample_sh(const kiln_probes* probes, const kiln_probe_location* location,
                                  float out_sh[27]);

/* Blends the located probes' shadowmask occlusion into out_occlusion[4]: channel c is the
 * fraction in [0, 1] of the light kiln_probes_occlusion_lights gives for c that reaches the
 * point unshadowed (baked, soft shadows included), blended with the same weights as the SH.
 * Multiply that light's realtime direct light by it where there is no realtime shadow
 * (Unity's probe occlusion). Unused channels, and files without occlusion, give 1. */
kiln_status kiln_probes_sample_occlusion(const kiln_probes* probes,
                                         const kiln_probe_location* location,
                                         float out_occlusion[4]);

/* The scene light (index into the glTF's KHR_lights_punctual lights) of each shadowmask
 * channel, -1 for an unused channel, into out_lights[4]. */
kiln_status kiln_probes_occlusion_lights(const kiln_probes* probes, int32_t out_lights[4]);

/* Irradiance E (RGB) for unit normal[3] from radiance SH sh[27] (Ramamoorthi-Hanrahan). */
kiln_status kiln_probes_irradiance(const float sh[27], const float normal[3], float out_rgb[3]);

/* Batch lookup of `count` points (positions: 3 * count floats). hints: NULL or count cells,
 * read as hints and overwritten with the cells found. out_locations: count entries or NULL;
 * out_sh: 27 * count floats or NULL. */
kiln_status kiln_probes_sample_batch(const kiln_probes* probes, size_t count,
                                     const float* positions, int32_t* hints,
                                     kiln_probe_location* out_locations, float* out_sh);

/* Message for the last failed call on this thread ("" when none). Valid until the next call. */
const char* kiln_last_error(void);

#ifdef __cplusplus
}
#endif

#endif /* KILN_RUNTIME_H */
