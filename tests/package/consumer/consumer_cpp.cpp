// consumer_cpp.cpp: a C++ game's use of an installed kiln_runtime (tests/package). It builds
// a probe set with the C++ API (two probes on a line, each lit by a constant radiance),
// validates it, writes and reads it back as a .kprobe file, blends it at a point with the C++
// lookup and with the C API, and checks the irradiance against the closed form. The consumer
// sets no C++ standard: kiln::runtime must bring C++20 (its headers use <span>).
// Usage: consumer_cpp <writable directory>. Returns 0 when every check passes.
#include <cmath>
#include <cstdio>
#include <cstring>
#include <numbers>
#include <string>

#include <kiln/lppv_volume.h>
#include <kiln/predicates.h>
#include <kiln/probe_runtime.h>
#include <kiln/probe_set.h>
#include <kiln/result.h>
#include <kiln/sh.h>
#include <kiln/version.h>
#include <kiln_lppv.h>
#include <kiln_runtime.h>

static_assert(__cplusplus >= 202002L, "kiln::runtime should have brought C++20");

#ifndef KILN_EXPECTED_VERSION
#error "KILN_EXPECTED_VERSION (the kiln project's version) must be defined by the build"
#endif

namespace {

int failures = 0;

void check(bool ok, const char* what, int line) {
  if (!ok) {
    std::fprintf(stderr, "consumer_cpp.cpp:%d: CHECK failed: %s\n", line, what);
    ++failures;
  }
}
#define CHECK(cond) check((cond), #cond, __LINE__)

bool near(double a, double b, double relative) { return std::fabs(a - b) <= relative * std::fabs(b); }

constexpr double kPi = std::numbers::pi;

}  // namespace

int main(int argc, char** argv) {
  if (argc != 2) {
    std::fprintf(stderr, "usage: %s <writable directory>\n", argv[0]);
    return 2;
  }
  CHECK(std::string(KILN_VERSION_STRING) == KILN_EXPECTED_VERSION);
  CHECK(std::string(kiln_runtime_version()) == KILN_VERSION_STRING);

  // Two probes at x = 0 and x = 2 joined by one segment cell (ProbeSet, dimension 1); a
  // constant radiance L has SH c0 = L sqrt(4 pi) and nothing else.
  const glm::vec3 radiance[2] = {{1.0f, 2.0f, 3.0f}, {3.0f, 2.0f, 1.0f}};
  kiln::ProbeSet set;
  set.dimension = 1;
  set.positions = {{0.0f, 0.0f, 0.0f}, {2.0f, 0.0f, 0.0f}};
  set.sh.resize(2);
  for (int i = 0; i < 2; ++i) set.sh[i].c[0] = radiance[i] * float(std::sqrt(4.0 * kPi));
  set.validity = {1.0f, 1.0f};
  set.cells = {{0, 1, -1, -1}};
  set.neighbours = {{-1, -1, -1, -1}};
  set.innerCellCount = 1;
  const kiln::Status valid = kiln::validateProbeSet(set, "consumer");
  CHECK(valid.ok());
  if (!valid) std::fprintf(stderr, "%s\n", valid.error().c_str());

  const std::string path = std::string(argv[1]) + "/consumer_cpp.kprobe";
  const kiln::Status written = kiln::writeProbeFile(set, path);
  if (!written) {
    std::fprintf(stderr, "%s\n", written.error().c_str());
    return 1;
  }
  kiln::Result<kiln::ProbeSet> loaded = kiln::loadProbeFile(path);
  if (!loaded) {
    std::fprintf(stderr, "%s\n", loaded.error().c_str());
    return 1;
  }
  CHECK(loaded->probeCount() == 2 && loaded->cellCount() == 1);

  // x = 0.5: weights 0.75 and 0.25, so the blend is the constant radiance (1.5, 2, 2.5), and a
  // constant radiance L gives E = pi L for every normal (kiln/sh.h: E = A0 c0 Y00, A0 = pi).
  const glm::vec3 point(0.5f, 0.0f, 0.0f);
  const kiln::ProbeLocation location = kiln::locateProbe(*loaded, point);
  CHECK(location.cell == 0);
  CHECK(near(location.weights[0], 0.75, 1e-6) && near(location.weights[1], 0.25, 1e-6));
  const kiln::ShL2Rgb sh = kiln::interpolateProbes(*loaded, location);
  const glm::vec3 expected = 0.75f * radiance[0] + 0.25f * radiance[1];
  const glm::vec3 normals[3] = {{0.0f, 1.0f, 0.0f}, {-1.0f, 0.0f, 0.0f}, {0.6f, 0.0f, 0.8f}};
  for (const glm::vec3& n : normals) {
    const glm::vec3 e = kiln::probeIrradiance(sh, n);
    for (int c = 0; c < 3; ++c) {
      CHECK(near(e[c], kPi * expected[c], 1e-5));
      CHECK(near(e[c], kPi * sh.c[0][c] * 0.282095, 1e-6));
    }
  }

  // The same file through the C API gives the same numbers.
  kiln_probes* probes = nullptr;
  CHECK(kiln_probes_load(path.c_str(), &probes) == KILN_OK);
  if (probes) {
    const float p[3] = {point.x, point.y, point.z}, up[3] = {0.0f, 1.0f, 0.0f};
    kiln_probe_location loc;
    float csh[27], rgb[3];
    CHECK(kiln_probes_locate(probes, p, -1, &loc) == KILN_OK);
    CHECK(kiln_probes_sample_sh(probes, &loc, csh) == KILN_OK);
    CHECK(kiln_probes_irradiance(csh, up, rgb) == KILN_OK);
    const glm::vec3 e = kiln::probeIrradiance(sh, glm::vec3(0.0f, 1.0f, 0.0f));
    for (int c = 0; c < 3; ++c) CHECK(near(rgb[c], e[c], 1e-6));
    kiln_probes_release(probes);
  }
  std::remove(path.c_str());

  if (failures == 0) std::printf("consumer_cpp %s: ok\n", kiln_runtime_version());
  return failures == 0 ? 0 : 1;
}
