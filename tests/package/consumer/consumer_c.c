/* consumer_c.c: a C99 game's use of an installed kiln_runtime (tests/package). It writes a
 * two-probe .kprobe file byte by byte from the documented format (probe_set.h: version 1, the
 * probes on a line), loads it through the C API, blends the probes at a point and checks the
 * irradiance against the closed form, and checks that headers and library carry the
 * project's version. Built with find_package(kiln), with add_subdirectory and with
 * pkg-config flags; C99, -Wpedantic -Werror, so the C headers must stay C99-clean.
 * Usage: consumer_c <writable directory>. Returns 0 when every check passes. */
#include <math.h>
#include <stdio.h>
#include <string.h>

#include <kiln_lppv.h> /* also includes kiln_runtime.h, which includes kiln/version.h */

#ifndef KILN_EXPECTED_VERSION
#error "KILN_EXPECTED_VERSION (the kiln project's version) must be defined by the build"
#endif

static int failures = 0;
#define CHECK(cond)                                                              \
  do {                                                                           \
    if (!(cond)) {                                                               \
      fprintf(stderr, "%s:%d: CHECK failed: %s\n", __FILE__, __LINE__, #cond);   \
      ++failures;                                                                \
    }                                                                            \
  } while (0)

static unsigned char bytes[512];
static size_t used = 0;

static void putU32(uint32_t v) {
  int i;
  for (i = 0; i < 4; ++i) bytes[used++] = (unsigned char)(v >> (8 * i));
}
static void putF32(float f) {
  uint32_t v;
  memcpy(&v, &f, 4);
  putU32(v);
}

/* A constant radiance L has SH c0 = L x 4 pi x Y00 = L sqrt(4 pi) and nothing else. */
static const double kPi = 3.14159265358979323846;
static const float kRadiance[2][3] = {{1.0f, 2.0f, 3.0f}, {3.0f, 2.0f, 1.0f}};

/* Version 1 file: probes at x = 0 and x = 2 (dimension 1, one segment cell), each lit by a
 * constant radiance kRadiance[probe]; checksum FNV-1a 64 of header [0, 64) + payload. */
static size_t buildFile(void) {
  int i, k;
  uint64_t sum = 14695981039346656037ULL;
  memcpy(bytes, "KPRB", 4);
  used = 4;
  putU32(1); /* version */
  putU32(1); /* dimension: colinear */
  putU32(2); /* probeCount */
  putU32(1); /* cellCount */
  putU32(1); /* innerCellCount */
  for (i = 0; i < 3; ++i) putU32(0); /* no seed grid */
  for (i = 0; i < 6; ++i) putF32(0.0f);
  putU32(0);  /* reserved */
  used += 8;  /* checksum, below */
  putF32(0.0f); putF32(0.0f); putF32(0.0f);
  putF32(2.0f); putF32(0.0f); putF32(0.0f);
  for (i = 0; i < 2; ++i)
    for (k = 0; k < 27; ++k) putF32(k < 3 ? (float)(kRadiance[i][k] * sqrt(4.0 * kPi)) : 0.0f);
  putF32(1.0f); putF32(1.0f);                                /* validity */
  putU32(0); putU32(1); putU32((uint32_t)-1); putU32((uint32_t)-1); /* the cell */
  for (i = 0; i < 4; ++i) putU32((uint32_t)-1);              /* no neighbours */
  for (i = 0; i < 64; ++i) sum = (sum ^ bytes[i]) * 1099511628211ULL;
  for (i = 72; i < (int)used; ++i) sum = (sum ^ bytes[i]) * 1099511628211ULL;
  for (i = 0; i < 8; ++i) bytes[64 + i] = (unsigned char)(sum >> (8 * i));
  return used;
}

static int near(double a, double b, double relative) { return fabs(a - b) <= relative * fabs(b); }

int main(int argc, char** argv) {
  char path[1024], version[64];
  FILE* f;
  size_t n;
  kiln_probes* probes = NULL;
  kiln_probe_location loc;
  float sh[27], rgb[3];
  const float point[3] = {0.5f, 0.0f, 0.0f};
  const float normals[3][3] = {{0.0f, 1.0f, 0.0f}, {-1.0f, 0.0f, 0.0f}, {0.6f, 0.0f, 0.8f}};
  int c, k;

  if (argc != 2) {
    fprintf(stderr, "usage: %s <writable directory>\n", argv[0]);
    return 2;
  }

  /* Headers and library: the project's version, spelled alike. */
  CHECK(strcmp(KILN_VERSION_STRING, KILN_EXPECTED_VERSION) == 0);
  snprintf(version, sizeof version, "%d.%d.%d", KILN_VERSION_MAJOR, KILN_VERSION_MINOR,
           KILN_VERSION_PATCH);
  CHECK(strcmp(version, KILN_VERSION_STRING) == 0);
  CHECK(KILN_VERSION == KILN_VERSION_MAJOR * 10000 + KILN_VERSION_MINOR * 100 + KILN_VERSION_PATCH);
  CHECK(strcmp(kiln_runtime_version(), KILN_VERSION_STRING) == 0);

  snprintf(path, sizeof path, "%s/consumer_c.kprobe", argv[1]);
  n = buildFile();
  f = fopen(path, "wb");
  if (!f || fwrite(bytes, 1, n, f) != n) {
    fprintf(stderr, "cannot write %s\n", path);
    return 1;
  }
  fclose(f);

  if (kiln_probes_load(path, &probes) != KILN_OK) {
    fprintf(stderr, "kiln_probes_load: %s\n", kiln_last_error());
    return 1;
  }
  CHECK(kiln_probes_count(probes) == 2);
  CHECK(kiln_probes_cell_count(probes) == 1);
  CHECK(kiln_probes_has_visibility(probes) == 0);

  /* x = 0.5 on the segment: barycentric weights 0.75 (probe 0) and 0.25 (probe 1). */
  CHECK(kiln_probes_locate(probes, point, -1, &loc) == KILN_OK);
  CHECK(loc.cell == 0 && loc.probes[0] == 0 && loc.probes[1] == 1);
  CHECK(near(loc.weights[0], 0.75, 1e-6) && near(loc.weights[1], 0.25, 1e-6));
  CHECK(kiln_probes_sample_sh(probes, &loc, sh) == KILN_OK);

  /* The blend of two constant radiances is the constant 0.75 L0 + 0.25 L1 = (1.5, 2, 2.5), and
   * a constant radiance L gives irradiance E = pi L on every surface (Ramamoorthi-Hanrahan:
   * E = A0 c0 Y00 with A0 = pi; kiln's Y00 = 0.282095 differs from 1 / (2 sqrt(pi)) by 7e-7). */
  for (k = 0; k < 3; ++k) {
    CHECK(kiln_probes_irradiance(sh, normals[k], rgb) == KILN_OK);
    for (c = 0; c < 3; ++c) {
      const double radiance = 0.75 * kRadiance[0][c] + 0.25 * kRadiance[1][c];
      CHECK(near(rgb[c], kPi * radiance, 1e-5));
      CHECK(near(rgb[c], kPi * sh[c] * 0.282095, 1e-6));
    }
  }
  /* A bad argument is a status and a message, not a crash. */
  CHECK(kiln_probes_locate(probes, NULL, -1, &loc) == KILN_ERROR_INVALID_ARGUMENT);
  CHECK(kiln_last_error()[0] != '\0');
  kiln_probes_release(probes);
  remove(path);

  if (failures == 0) printf("consumer_c %s: ok\n", kiln_runtime_version());
  return failures == 0 ? 0 : 1;
}
