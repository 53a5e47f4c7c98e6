/* runtime_c_api_test.c: the C API (kiln_runtime.h) compiled as C99 and linked against
 * kiln_runtime alone. It writes a tiny .kprobe file byte by byte from the documented format
 * (version 1, two probes on a line: a dimension-1 set), then loads and queries it, and checks
 * that bad files and bad arguments come back as status codes with messages.
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

/* Two probes at x = 0 and x = 2; probe 0 has L00 = (1, 2, 3), probe 1 has L00 = (3, 2, 1). */
static size_t buildFile(void) {
  int i, k;
  uint64_t sum;
  used = 0;
  memcpy(buffer, "KPRB", 4);
  used = 4;
  putU32(1);            /* version */
  putU32(1);            /* dimension: colinear */
  putU32(2);            /* probeCount */
  putU32(1);            /* cellCount */
  putU32(1);            /* innerCellCount */
  for (i = 0; i < 3; ++i) putU32(0); /* no seed grid */
  for (i = 0; i < 6; ++i) putF32(0.0f);
  putU32(0);            /* reserved */
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

  snprintf(path, sizeof(path), "%s/runtime_c_api_test.kprobe", argc > 1 ? argv[1] : ".");
  n = buildFile();
  writeFile(path, buffer, n);

  /* Load and query. */
  CHECK(kiln_probes_load(path, &probes) == KILN_OK);
  CHECK(probes != NULL);
  if (!probes) return 1;
  CHECK(kiln_probes_count(probes) == 2);
  CHECK(kiln_probes_cell_count(probes) == 1);
  CHECK(kiln_probes_locate(probes, mid, -1, &loc) == KILN_OK);
  CHECK(loc.cell == 0);
  CHECK(loc.probes[0] == 0 && loc.probes[1] == 1);
  CHECK(fabsf(loc.weights[0] - 0.75f) < 1e-6f && fabsf(loc.weights[1] - 0.25f) < 1e-6f);
  CHECK(loc.weights[2] == 0.0f && loc.weights[3] == 0.0f);
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
  n = buildFile();
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

  if (failures) fprintf(stderr, "%d checks failed\n", failures);
  return failures ? 1 : 0;
}
