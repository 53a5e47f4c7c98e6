/* runtime_c_api_test.c: the C API (kiln_runtime.h) compiled as C99 and linked against
 * kiln_runtime alone. It writes tiny .kprobe files byte by byte from the documented format
 * (two probes on a line: a dimension-1 set; version 1, and version 3 with per-probe
 * visibility maps of {mu, sigma, far} u16 per texel), then loads and queries them, and checks that bad files and bad arguments come
 * back as status codes with messages naming the field.
 * Usage: runtime_c_api_test <writable directory>. Returns 0 on success. */
#include <math.h>
#include <stdio.h>
#include <string.h>

#include "kiln_runtime.h"

static int failures = 0;
#define CHECK(cond)                                                   \
  do {                                                                \
    if (!(cond)) {                                                    \
      fprintf(stderr, "%s:%d: CHECK failed: %s\n", __FILE__, __LINE__, #cond); \
      ++failures;                                                     \
    }                                                                 \
  } while (0)

static unsigned char buffer[4096];
static size_t used = 0;

static void putU32(uint32_t v) {
  int i;
  for (i = 0; i < 4; ++i) buffer[used++] = (unsigned char)(v >> (8 * i));
}
static void putI32(int32_t v) { putU32((uint32_t)v); }
static void putF32(float f) {
  uint32_t v;
  memcpy(&v, &f, 4);
  putU32(v);
}

static uint64_t fnv1a(const unsigned char* p, size_t n, uint64_t h) {
  size_t i;
  for (i = 0; i < n; ++i) {
    h ^= p[i];
    h *= 1099511628211ULL;
  }
  return h;
}

/* What buildFile writes: version 1 (no occlusion, no visibility) or version 3 with the
 * occlusion block (nothing occluded) and, when resolution > 0, visibility maps of
 * {mu, sigma, far} per texel: probe 0 sees nothing (every ray reached maxDistance: {1, 0, 1}),
 * probe 1 sits inside a sphere kWall metres in radius (every ray stops there: mu = far =
 * kWall / maxDistance, no spread). resolution is written to the header as given; the maps
 * are written only when the buffer can hold them, so an impossible resolution makes a file
 * whose header is wrong. */
typedef struct FileSpec {
  uint32_t version;
  uint32_t resolution;
  float maxDistance[2];
  int spreadTexel; /* >= 0: probe 1's texel whose sigma is `spread` instead of 0 */
  uint16_t spread;
} FileSpec;

static const float kWall = 0.3f;     /* metres from probe 1 to its wall */
static const float kDistance = 2.0f; /* maxDistance of a good file */

static FileSpec plainSpec(void) {
  FileSpec f;
  f.version = 1;
  f.resolution = 0;
  f.maxDistance[0] = f.maxDistance[1] = kDistance;
  f.spreadTexel = -1;
  f.spread = 0;
  return f;
}

static FileSpec visibilitySpec(void) {
  FileSpec f = plainSpec();
  f.version = 3;
  f.resolution = 4;
  return f;
}

/* unorm16 of v in [0, 1], rounded to nearest (as the bake stores it). */
static uint16_t unorm16(double v) { return (uint16_t)(v * 65535.0 + 0.5); }
static void putU16(uint16_t v) {
  buffer[used++] = (unsigned char)v;
  buffer[used++] = (unsigned char)(v >> 8);
}

/* Probe 1's stored mu and far: kWall / maxDistance as unorm16. */
static uint16_t wallDepth(void) { return unorm16(kWall / kDistance); }

/* Two probes at x = 0 and x = 2; probe 0 has L00 = (1, 2, 3), probe 1 has L00 = (3, 2, 1). */
static size_t buildFile(const FileSpec* spec) {
  int i, k;
  uint32_t t, texels;
  uint64_t sum;
  used = 0;
  memcpy(buffer, "KPRB", 4);
  used = 4;
  putU32(spec->version);
  putU32(1);            /* dimension: colinear */
  putU32(2);            /* probeCount */
  putU32(1);            /* cellCount */
  putU32(1);            /* innerCellCount */
  for (i = 0; i < 3; ++i) putU32(0); /* no seed grid */
  for (i = 0; i < 6; ++i) putF32(0.0f);
  putU32(spec->resolution); /* visibilityResolution (version 3), reserved = 0 before */
  used += 8;            /* checksum, filled below */
  putF32(0.0f); putF32(0.0f); putF32(0.0f);  /* positions */
  putF32(2.0f); putF32(0.0f); putF32(0.0f);
  for (i = 0; i < 2; ++i) {                  /* sh[probe][9][3] */
    for (k = 0; k < 27; ++k) {
      float v = 0.0f;
      if (k < 3) v = i == 0 ? (float)(k + 1) : (float)(3 - k);
      putF32(v);
    }
  }
  putF32(1.0f); putF32(1.0f);                /* validity */
  putI32(0); putI32(1); putI32(-1); putI32(-1);  /* cells */
  putI32(-1); putI32(-1); putI32(-1); putI32(-1); /* neighbours */
  if (spec->version >= 2) {
    for (i = 0; i < 4; ++i) putI32(-1);      /* occlusionLights: no channel used */
    for (i = 0; i < 8; ++i) putF32(1.0f);    /* occlusion[probe][4] */
  }
  texels = spec->resolution <= 64 ? spec->resolution * spec->resolution : 0;
  if (spec->version >= 3 && texels > 0 && used + 8 + 2 * texels * 3 * 2 <= sizeof(buffer)) {
    const uint16_t depth = wallDepth();
    putF32(spec->maxDistance[0]);
    putF32(spec->maxDistance[1]);
    for (t = 0; t < texels; ++t) { /* probe 0: open in every direction */
      putU16(65535);
      putU16(0);
      putU16(65535);
    }
    for (t = 0; t < texels; ++t) { /* probe 1: a wall at kWall, no spread */
      putU16(depth);
      putU16((int)t == spec->spreadTexel ? spec->spread : 0);
      putU16(depth);
    }
  }
  sum = fnv1a(buffer, 64, 14695981039346656037ULL);
  sum = fnv1a(buffer + 72, used - 72, sum);
  for (i = 0; i < 8; ++i) buffer[64 + i] = (unsigned char)(sum >> (8 * i));
  return used;
}

static void writeFile(const char* path, const unsigned char* bytes, size_t n) {
  FILE* f = fopen(path, "wb");
  CHECK(f != NULL);
  if (f) {
    fwrite(bytes, 1, n, f);
    fclose(f);
  }
}

/* Loads `path` after writing the first n bytes of the file `spec` describes; returns the
 * status, and checks that a failure leaves no handle. */
static kiln_status loadSpec(const char* path, const FileSpec* spec, size_t cut) {
  kiln_probes* probes = NULL;
  kiln_status st;
  const size_t n = buildFile(spec);
  writeFile(path, buffer, n - cut);
  st = kiln_probes_load(path, &probes);
  if (st != KILN_OK) CHECK(probes == NULL);
  kiln_probes_release(probes);
  return st;
}

/* Probe 1's visibility of a point `distance` metres from it (kiln/probe_visibility.h), for a
 * blend's distance bias and min_sigma: d = (distance - distance_bias) / D against its stored
 * mu = far = m (no stored spread, so sigma is at its floor w = min_sigma / D); 1 up to m,
 * then the Chebyshev bound cubed times the reach factor clamp(1 - (d - far) / w, 1e-12, 1). */
static double wallVisibility(double distance, double distanceBias, double minSigma) {
  const double w = minSigma / kDistance, m = wallDepth() / 65535.0;
  const double d = (distance - distanceBias) / kDistance;
  double c, reach = 1.0 - (d - m) / w;
  if (reach > 1.0) reach = 1.0;
  if (reach < 1e-12) reach = 1e-12;
  if (d <= m) return reach;
  c = w * w / (w * w + (d - m) * (d - m));
  return c * c * c * reach;
}

/* With the default blend (distance_bias = min_sigma = 0.02). */
static double hiddenVisibility(double distance) { return wallVisibility(distance, 0.02, 0.02); }

/* The blend's weight of probe 1 at x, when probe 1's visibility there is v (probe 0 sees
 * everything): barycentric weights (2 - x) / 2 and x / 2, probe 1's scaled by v, renormalized. */
static double blendedWeight1(double x, double v) {
  const double b0 = (2.0 - x) / 2.0, b1 = x / 2.0;
  return b1 * v / (b0 + b1 * v);
}

static int within(double a, double b, double tolerance) { return fabs(a - b) <= tolerance; }

static void testVisibility(const char* path) {
  kiln_probes* probes = NULL;
  kiln_probe_location loc, plain, single[2];
  kiln_probe_blend blend, bad;
  FileSpec spec = visibilitySpec();
  /* x = 1.5 is 0.5 m from probe 1, beyond its wall at 0.3 m; x = 1.8 is 0.2 m from it, in
   * front of the wall. */
  const float behind[3] = {1.5f, 0.0f, 0.0f}, before[3] = {1.8f, 0.0f, 0.0f};
  const float pastEnd[3] = {2.5f, 0.0f, 0.0f};
  const float positions[6] = {1.5f, 0.0f, 0.0f, 1.8f, 0.0f, 0.0f};
  float normals[6] = {0.0f, 0.0f, 0.0f, -1.0f, 0.0f, 0.0f};
  int32_t hints[2] = {-1, -1};
  kiln_probe_location batch[2];
  float sh[27], batchSh[54];
  double expected;
  int k;

  /* Defaults match kiln::ProbeBlendSettings. */
  CHECK(kiln_probe_blend_defaults(&blend) == KILN_OK);
  CHECK(blend.visibility == 1);
  CHECK(blend.normal[0] == 0.0f && blend.normal[1] == 0.0f && blend.normal[2] == 0.0f);
  CHECK(blend.normal_bias == 0.05f && blend.distance_bias == 0.02f && blend.min_sigma == 0.02f);
  CHECK(kiln_probe_blend_defaults(NULL) == KILN_ERROR_INVALID_ARGUMENT);

  /* A version 3 file with visibility loads and says so. */
  writeFile(path, buffer, buildFile(&spec));
  CHECK(kiln_probes_load(path, &probes) == KILN_OK);
  if (!probes) {
    fprintf(stderr, "%s\n", kiln_last_error());
    ++failures;
    return;
  }
  CHECK(kiln_probes_has_visibility(probes) == 1);
  CHECK(kiln_probes_visibility_resolution(probes) == 4);
  CHECK(kiln_probes_has_visibility(NULL) == 0 && kiln_probes_visibility_resolution(NULL) == 0);

  /* Behind probe 1's wall: the plain blend leaks probe 1 in with its barycentric 0.75; the
   * visibility blend gives it its visibility's weight. 0.5 m from probe 1 is past far + w
   * (0.3 + 0.02 + 0.02 m), so v = (1e-4 / (1e-4 + 0.09^2))^3 x 1e-12 = 1.8e-18 and the weight
   * 0.75 v / 0.25 = 5.4e-18. (Probe 0, 1.5 m away with nothing within D, has v = 1.) */
  blend.visibility = 0;
  CHECK(kiln_probes_locate_blend(probes, behind, -1, &blend, &plain) == KILN_OK);
  CHECK(within(plain.weights[0], 0.25, 1e-6) && within(plain.weights[1], 0.75, 1e-6));
  for (k = 0; k < 4; ++k) CHECK(plain.barycentric[k] == plain.weights[k]);
  CHECK(kiln_probes_locate_blend(probes, behind, -1, NULL, &loc) == KILN_OK);
  expected = blendedWeight1(1.5, hiddenVisibility(0.5));
  CHECK(expected > 5e-18 && expected < 6e-18);
  CHECK(within(loc.weights[1], expected, 1e-4 * expected));
  CHECK(within(loc.weights[0] + loc.weights[1], 1.0, 1e-6));
  CHECK(loc.cell == plain.cell);
  for (k = 0; k < 4; ++k) CHECK(loc.barycentric[k] == plain.barycentric[k]);
  /* The SH is probe 0's, not the 1:3 mix. */
  CHECK(kiln_probes_sample_sh(probes, &loc, sh) == KILN_OK);
  CHECK(within(sh[0], 1.0, 1e-4) && within(sh[2], 3.0, 1e-4));
  /* kiln_probes_locate uses the default blend: the same answer. */
  CHECK(kiln_probes_locate(probes, behind, -1, &single[0]) == KILN_OK);
  CHECK(memcmp(&single[0], &loc, sizeof(loc)) == 0);
  /* Past the end of the line (x = 2.5) probe 1 has all the barycentric weight and is hidden
   * (0.5 m away, behind its wall): its visible weight 1.8e-18 is below the blend's 1% floor
   * (kiln::ProbeBlendSettings::minVisibleWeight), so the blend fades out, weight v / 0.01,
   * instead of renormalizing onto the hidden probe: the SH is ~0, not probe 1's. */
  CHECK(kiln_probes_locate(probes, pastEnd, -1, &single[0]) == KILN_OK);
  CHECK(single[0].barycentric[0] == 0.0f && single[0].barycentric[1] == 1.0f);
  expected = hiddenVisibility(0.5) / 0.01;
  CHECK(single[0].weights[0] == 0.0f);
  CHECK(within(single[0].weights[1], expected, 1e-4 * expected));
  CHECK(kiln_probes_sample_sh(probes, &single[0], sh) == KILN_OK);
  CHECK(fabs(sh[0]) < 1e-15 && fabs(sh[2]) < 1e-15);

  /* The blend's min_sigma and distance_bias reach the test. min_sigma 0.2 m (w = 0.1) puts
   * the point inside the reach factor's ramp, (d - far) / w = 0.9, with sigma at 0.1:
   * v = (0.01 / (0.01 + 0.09^2))^3 x 0.1 = 0.0169. (Float rounding of d and far, ~1e-7, over
   * w stays below 1e-5 of v.) A distance bias of 0.25 m puts d at 0.125 < mu: seen, the
   * barycentric blend. */
  CHECK(kiln_probe_blend_defaults(&blend) == KILN_OK);
  blend.min_sigma = 0.2f;
  CHECK(kiln_probes_locate_blend(probes, behind, -1, &blend, &loc) == KILN_OK);
  expected = blendedWeight1(1.5, wallVisibility(0.5, 0.02, 0.2));
  CHECK(expected > 0.045 && expected < 0.05);
  CHECK(within(loc.weights[1], expected, 1e-4 * expected));
  CHECK(within(loc.weights[0] + loc.weights[1], 1.0, 1e-6));
  CHECK(kiln_probe_blend_defaults(&blend) == KILN_OK);
  blend.distance_bias = 0.25f;
  CHECK(kiln_probes_locate_blend(probes, behind, -1, &blend, &loc) == KILN_OK);
  CHECK(within(loc.weights[0], 0.25, 1e-6) && within(loc.weights[1], 0.75, 1e-6));

  /* In front of the wall probe 1 sees the point: the barycentric blend (0.1, 0.9). A surface
   * normal facing probe 0 moves the tested point 0.3 m back, behind the wall. */
  CHECK(kiln_probe_blend_defaults(&blend) == KILN_OK);
  CHECK(kiln_probes_locate_blend(probes, before, -1, &blend, &loc) == KILN_OK);
  CHECK(within(loc.weights[0], 0.1, 1e-6) && within(loc.weights[1], 0.9, 1e-6));
  blend.normal[0] = -1.0f;
  blend.normal_bias = 0.3f;
  CHECK(kiln_probes_locate_blend(probes, before, -1, &blend, &single[1]) == KILN_OK);
  expected = blendedWeight1(1.8, hiddenVisibility(0.5));
  CHECK(within(single[1].weights[1], expected, 1e-4 * expected));

  /* Batch with one normal per point: the same as single lookups, bit for bit. */
  blend.normal[0] = 0.0f;
  CHECK(kiln_probes_locate_blend(probes, behind, -1, &blend, &single[0]) == KILN_OK);
  CHECK(kiln_probes_sample_batch_blend(probes, 2, positions, normals, &blend, hints, batch,
                                       batchSh) == KILN_OK);
  CHECK(memcmp(&batch[0], &single[0], sizeof(loc)) == 0);
  CHECK(memcmp(&batch[1], &single[1], sizeof(loc)) == 0);
  CHECK(hints[0] == 0 && hints[1] == 0);
  CHECK(within(batchSh[0], 1.0, 1e-4) && within(batchSh[27], 1.0, 1e-4));
  /* Without normals every point uses blend.normal (zero here): x = 1.8 is seen again. */
  CHECK(kiln_probes_sample_batch_blend(probes, 2, positions, NULL, &blend, NULL, batch, NULL) ==
        KILN_OK);
  CHECK(within(batch[1].weights[1], 0.9, 1e-6));

  /* Bad blends: an error naming the field, and the output left alone. */
  memset(&loc, 0x7f, sizeof(loc));
  single[0] = loc;
  kiln_probe_blend_defaults(&blend);
  bad = blend;
  bad.normal[1] = NAN;
  CHECK(kiln_probes_locate_blend(probes, behind, -1, &bad, &loc) == KILN_ERROR_INVALID_ARGUMENT);
  CHECK(strstr(kiln_last_error(), "kiln_probes_locate_blend") != NULL);
  CHECK(strstr(kiln_last_error(), "blend.normal") != NULL);
  CHECK(memcmp(&loc, &single[0], sizeof(loc)) == 0);
  bad = blend;
  bad.normal_bias = -0.01f;
  CHECK(kiln_probes_locate_blend(probes, behind, -1, &bad, &loc) == KILN_ERROR_INVALID_ARGUMENT);
  CHECK(strstr(kiln_last_error(), "blend.normal_bias") != NULL);
  bad = blend;
  bad.distance_bias = INFINITY;
  CHECK(kiln_probes_locate_blend(probes, behind, -1, &bad, &loc) == KILN_ERROR_INVALID_ARGUMENT);
  CHECK(strstr(kiln_last_error(), "blend.distance_bias") != NULL);
  bad = blend;
  bad.min_sigma = 0.0f;
  CHECK(kiln_probes_locate_blend(probes, behind, -1, &bad, &loc) == KILN_ERROR_INVALID_ARGUMENT);
  CHECK(strstr(kiln_last_error(), "blend.min_sigma") != NULL);
  bad.min_sigma = NAN;
  CHECK(kiln_probes_sample_batch_blend(probes, 2, positions, NULL, &bad, NULL, batch, NULL) ==
        KILN_ERROR_INVALID_ARGUMENT);
  CHECK(strstr(kiln_last_error(), "kiln_probes_sample_batch_blend: blend.min_sigma") != NULL);
  /* A non-finite per-point normal: named by index, nothing written. */
  normals[4] = NAN;
  hints[0] = hints[1] = -1;
  CHECK(kiln_probes_sample_batch_blend(probes, 2, positions, normals, &blend, hints, batch, NULL) ==
        KILN_ERROR_INVALID_ARGUMENT);
  CHECK(strstr(kiln_last_error(), "normals[1]") != NULL);
  CHECK(hints[0] == -1 && hints[1] == -1);
  /* A good call clears the message. */
  CHECK(kiln_probes_locate_blend(probes, behind, -1, &blend, &loc) == KILN_OK);
  CHECK(kiln_last_error()[0] == '\0');
  kiln_probes_release(probes);

  /* Bad visibility blocks: rejected on load, the message naming the field. */
  CHECK(loadSpec(path, &spec, 10) == KILN_ERROR_INVALID_FILE);
  CHECK(strstr(kiln_last_error(), "size") != NULL);
  CHECK(strstr(kiln_last_error(), "truncated") != NULL);
  spec.maxDistance[1] = NAN;
  CHECK(loadSpec(path, &spec, 0) == KILN_ERROR_INVALID_FILE);
  CHECK(strstr(kiln_last_error(), "visibilityMaxDistance[1]") != NULL);
  spec.maxDistance[1] = kDistance;
  spec.maxDistance[0] = 0.0f;
  CHECK(loadSpec(path, &spec, 0) == KILN_ERROR_INVALID_FILE);
  CHECK(strstr(kiln_last_error(), "visibilityMaxDistance[0]") != NULL);
  spec.maxDistance[0] = kDistance;
  spec.resolution = 3;
  CHECK(loadSpec(path, &spec, 0) == KILN_ERROR_INVALID_FILE);
  CHECK(strstr(kiln_last_error(), "visibilityResolution") != NULL);
  spec.resolution = 65;
  CHECK(loadSpec(path, &spec, 0) == KILN_ERROR_INVALID_FILE);
  CHECK(strstr(kiln_last_error(), "visibilityResolution") != NULL);
  spec.resolution = 100000;
  CHECK(loadSpec(path, &spec, 0) == KILN_ERROR_INVALID_FILE);
  CHECK(strstr(kiln_last_error(), "visibilityResolution") != NULL);
  spec.resolution = 4;
  /* A spread above half the distance range (sigma > 32768) is named; 32768 loads. */
  spec.spreadTexel = 5;
  spec.spread = 32769;
  CHECK(loadSpec(path, &spec, 0) == KILN_ERROR_INVALID_FILE);
  CHECK(strstr(kiln_last_error(), "visibilityMoments[1][5]") != NULL);
  spec.spread = 32768;
  CHECK(loadSpec(path, &spec, 0) == KILN_OK);
  spec.spreadTexel = -1;
  /* A resolution the format allows but whose maps the file lacks: truncated. */
  spec.resolution = 64;
  CHECK(loadSpec(path, &spec, 0) == KILN_ERROR_INVALID_FILE);
  CHECK(strstr(kiln_last_error(), "truncated") != NULL);
  spec.resolution = 4;
  /* A version 1 file may not use the word that holds the resolution. */
  spec = plainSpec();
  spec.resolution = 4;
  CHECK(loadSpec(path, &spec, 0) == KILN_ERROR_INVALID_FILE);
  CHECK(strstr(kiln_last_error(), "reserved") != NULL);
  remove(path);
}

int main(int argc, char** argv) {
  char path[1024];
  kiln_probes* probes = NULL;
  kiln_probe_location loc;
  float sh[27], rgb[3];
  float occlusion[4];
  int32_t lights[4];
  const float mid[3] = {0.5f, 5.0f, -3.0f};
  const float up[3] = {0.0f, 1.0f, 0.0f};
  float positions[9] = {0.5f, 0.0f, 0.0f, -4.0f, 0.0f, 0.0f, 1.0f, 1.0f, 1.0f};
  int32_t hints[3] = {-1, -1, -1};
  kiln_probe_location locs[3];
  float shs[81];
  size_t n;
  FileSpec spec;

  snprintf(path, sizeof(path), "%s/runtime_c_api_test.kprobe", argc > 1 ? argv[1] : ".");
  spec = plainSpec();
  n = buildFile(&spec);
  writeFile(path, buffer, n);

  /* Load and query. */
  CHECK(kiln_probes_load(path, &probes) == KILN_OK);
  CHECK(probes != NULL);
  if (!probes) return 1;
  CHECK(kiln_probes_count(probes) == 2);
  CHECK(kiln_probes_cell_count(probes) == 1);
  CHECK(kiln_probes_has_visibility(probes) == 0);
  CHECK(kiln_probes_visibility_resolution(probes) == 0);
  CHECK(kiln_probes_locate(probes, mid, -1, &loc) == KILN_OK);
  CHECK(loc.cell == 0);
  CHECK(loc.probes[0] == 0 && loc.probes[1] == 1);
  CHECK(fabsf(loc.weights[0] - 0.75f) < 1e-6f && fabsf(loc.weights[1] - 0.25f) < 1e-6f);
  CHECK(loc.weights[2] == 0.0f && loc.weights[3] == 0.0f);
  CHECK(memcmp(loc.barycentric, loc.weights, sizeof(loc.weights)) == 0);
  CHECK(kiln_probes_sample_sh(probes, &loc, sh) == KILN_OK);
  CHECK(fabsf(sh[0] - 1.5f) < 1e-6f && fabsf(sh[1] - 2.0f) < 1e-6f && fabsf(sh[2] - 2.5f) < 1e-6f);
  CHECK(sh[3] == 0.0f && sh[26] == 0.0f);
  /* Only L00 is set: E = pi * Y00 * c00 for any normal. */
  CHECK(kiln_probes_irradiance(sh, up, rgb) == KILN_OK);
  CHECK(fabsf(rgb[0] - 3.14159265f * 0.282095f * 1.5f) < 1e-4f);
  CHECK(fabsf(rgb[2] - 3.14159265f * 0.282095f * 2.5f) < 1e-4f);
  /* A version 1 file has no probe occlusion: 1 in every channel, no channel lights. */
  CHECK(kiln_probes_sample_occlusion(probes, &loc, occlusion) == KILN_OK);
  CHECK(occlusion[0] == 1.0f && occlusion[1] == 1.0f && occlusion[2] == 1.0f &&
        occlusion[3] == 1.0f);
  CHECK(kiln_probes_occlusion_lights(probes, lights) == KILN_OK);
  CHECK(lights[0] == -1 && lights[1] == -1 && lights[2] == -1 && lights[3] == -1);

  /* Batch: locations, SH and hints together; beyond the ends the line clamps. */
  CHECK(kiln_probes_sample_batch(probes, 3, positions, hints, locs, shs) == KILN_OK);
  CHECK(hints[0] == 0 && hints[1] == 0 && hints[2] == 0);
  CHECK(fabsf(shs[0] - 1.5f) < 1e-6f);
  CHECK(fabsf(shs[27] - 1.0f) < 1e-6f);    /* x = -4 clamps to probe 0 */
  CHECK(fabsf(shs[54] - 2.0f) < 1e-6f);    /* x = 1: halfway */
  CHECK(fabsf(locs[1].weights[0] - 1.0f) < 1e-6f);

  /* Misuse is reported, not crashed on. */
  CHECK(kiln_probes_locate(probes, NULL, -1, &loc) == KILN_ERROR_INVALID_ARGUMENT);
  CHECK(strstr(kiln_last_error(), "kiln_probes_locate") != NULL);
  loc.probes[1] = 7;
  CHECK(kiln_probes_sample_sh(probes, &loc, sh) == KILN_ERROR_INVALID_ARGUMENT);
  kiln_probes_retain(probes);
  kiln_probes_release(probes);
  kiln_probes_release(probes);
  kiln_probes_release(NULL);

  /* Bad files: flipped magic, a truncated file, a corrupted payload, a missing file. */
  buffer[0] = 'X';
  writeFile(path, buffer, n);
  probes = NULL;
  CHECK(kiln_probes_load(path, &probes) == KILN_ERROR_INVALID_FILE);
  CHECK(probes == NULL);
  CHECK(strstr(kiln_last_error(), "magic") != NULL);
  n = buildFile(&spec);
  writeFile(path, buffer, n - 10);
  CHECK(kiln_probes_load(path, &probes) == KILN_ERROR_INVALID_FILE);
  CHECK(strstr(kiln_last_error(), "truncated") != NULL);
  buffer[100] ^= 1;
  writeFile(path, buffer, n);
  CHECK(kiln_probes_load(path, &probes) == KILN_ERROR_INVALID_FILE);
  CHECK(strstr(kiln_last_error(), "checksum") != NULL);
  remove(path);
  CHECK(kiln_probes_load(path, &probes) == KILN_ERROR_IO);
  CHECK(kiln_probes_load(NULL, &probes) == KILN_ERROR_INVALID_ARGUMENT);

  testVisibility(path);

  if (failures) fprintf(stderr, "%d checks failed\n", failures);
  return failures ? 1 : 0;
}
