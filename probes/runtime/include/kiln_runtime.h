/* kiln_runtime.h: C99 API of kiln's light-probe runtime (what a game links).
 *
 * Load a .kprobe file written by `kiln probes`, find the probes around a point and blend
 * their L2 spherical harmonics, then evaluate irradiance for a surface normal. Modelled on
 * Embree's API: an opaque reference-counted handle, verb-object names, a status code from
 * every call plus a message from kiln_last_error(). No call throws or aborts.
 *
 * Conventions (see kiln/sh.h): positions in glTF world space (metres, +Y up). SH arrays are 27
 * floats, coefficient-major with RGB innermost: sh[3 * i + channel], i = l(l + 1) + m in the
 * real orthonormal basis, holding RADIANCE. Irradiance is E (not E / pi).
 *
 * Leak-free blending: files baked with per-probe visibility (version 3, the default of
 * `kiln probes bake`) let a lookup weight each probe of the cell by whether it can see the
 * point (a Chebyshev test on the depths its bake rays reached), so light does not pass
 * through a wall between probes on both sides of it. kiln_probes_locate and
 * kiln_probes_sample_batch use the default kiln_probe_blend, which is visibility-weighted when
 * the file has visibility and plain barycentric otherwise; kiln_probes_locate_blend and
 * kiln_probes_sample_batch_blend choose (and take the surface normal, which keeps a surface
 * point from being shadowed by the wall it lies on).
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

/* Result of a lookup: weights are >= 0 and sum to 1 (less only where the cell's probes see the
 * point with under 1% of its barycentric weight: the blend fades out there rather than take
 * the light of probes that cannot see it). Unused slots repeat probes[0] with weight 0. Pass
 * `cell` back as the hint of the next lookup for the same object.
 * `weights` are the blend's: with visibility, barycentric[k] x probe k's visibility of the
 * point, renormalized; without, equal to `barycentric`. `barycentric` are the cell's own
 * weights of the point (>= 0, sum 1; the same whatever the blend), e.g. to see how much
 * visibility changed. The sample_* calls read `weights` only. */
typedef struct kiln_probe_location {
  int32_t cell;
  int32_t probes[4];
  float weights[4];
  float barycentric[4];
} kiln_probe_location;

/* How a lookup blends the probes of the cell around a point. Start from
 * kiln_probe_blend_defaults() and change what you need; lengths in metres. */
typedef struct kiln_probe_blend {
  /* Nonzero: weight the probes by their visibility of the point when the file has visibility
   * (kiln_probes_has_visibility); 0: the plain barycentric blend. Default 1. */
  int visibility;
  /* Unit surface normal at the point, or 0 0 0 for an object's centre (default). Used as
   * given: the point is moved by normal_bias x normal before the visibility test. */
  float normal[3];
  /* Distance the point is moved along `normal` (>= 0; default 0.05). */
  float normal_bias;
  /* Distance subtracted from the probe-to-point distance (>= 0; default 0.02), so a point on
   * a surface the probe sees is not hidden by that surface's own depth. */
  float distance_bias;
  /* Smallest standard deviation of a probe's depths (> 0; default 0.02): larger values soften
   * the cut-off behind a wall. */
  float min_sigma;
} kiln_probe_blend;

/* Fills *blend with the defaults (the blend kiln_probes_locate uses). */
kiln_status kiln_probe_blend_defaults(kiln_probe_blend* blend);

/* Loads `path`; on success *out holds a handle with one reference. */
kiln_status kiln_probes_load(const char* path, kiln_probes** out);
void kiln_probes_retain(kiln_probes* probes);
/* Drops one reference; the data is freed with the last. NULL is ignored. */
void kiln_probes_release(kiln_probes* probes);

/* Number of probes and of cells (cells bound the valid hints: 0 .. cells - 1). */
uint32_t kiln_probes_count(const kiln_probes* probes);
uint32_t kiln_probes_cell_count(const kiln_probes* probes);

/* 1 when the file holds per-probe visibility (leak-free blending is possible), else 0; and the
 * side of each probe's octahedral visibility map (0 without visibility). */
int kiln_probes_has_visibility(const kiln_probes* probes);
uint32_t kiln_probes_visibility_resolution(const kiln_probes* probes);

/* Finds the cell around position[3] and its weights with the default blend (visibility-
 * weighted when the file has visibility). hint: the cell of the previous lookup or -1. */
kiln_status kiln_probes_locate(const kiln_probes* probes, const float position[3], int32_t hint,
                               kiln_probe_location* out);

/* The same with a chosen blend (NULL = the defaults). The cell does not depend on the blend,
 * only the weights do. A blend with a non-finite field, a negative bias or min_sigma <= 0 gives
 * KILN_ERROR_INVALID_ARGUMENT and a message naming the field; *out is then left unchanged. */
kiln_status kiln_probes_locate_blend(const kiln_probes* probes, const float position[3],
                                     int32_t hint, const kiln_probe_blend* blend,
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

/* Batch lookup of `count` points (positions: 3 * count floats) with the default blend. hints:
 * NULL or count cells, read as hints and overwritten with the cells found. out_locations:
 * count entries or NULL; out_sh: 27 * count floats or NULL. */
kiln_status kiln_probes_sample_batch(const kiln_probes* probes, size_t count,
                                     const float* positions, int32_t* hints,
                                     kiln_probe_location* out_locations, float* out_sh);

/* The same with a chosen blend (NULL = the defaults) and, optionally, one normal per point:
 * normals NULL uses blend->normal for every point, else 3 * count floats replacing it (zero for
 * object centres). Arguments are checked before anything is written: a bad blend or a
 * non-finite normal gives KILN_ERROR_INVALID_ARGUMENT naming the field ("normals[i]"). */
kiln_status kiln_probes_sample_batch_blend(const kiln_probes* probes, size_t count,
                                           const float* positions, const float* normals,
                                           const kiln_probe_blend* blend, int32_t* hints,
                                           kiln_probe_location* out_locations, float* out_sh);

/* Message for the last failed call on this thread ("" when none). Valid until the next call. */
const char* kiln_last_error(void);

#ifdef __cplusplus
}
#endif

#endif /* KILN_RUNTIME_H */
