// lppv_test.cpp: light probe proxy volumes: sample positions for both placements, the fill
// from the probe field and trilinear sampling (both exact for a field linear in position,
// which tetrahedral and trilinear interpolation reproduce), the automatic resolution rule,
// Unity's L1 packing (E_L1 / pi) and its EXR atlas, the .klppv file (round trip, every
// truncation, NaN and header damage rejected with the field named), the C API and the CLI.
#include "probes/lppv.h"

#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
#include <filesystem>
#include <nlohmann/json.hpp>
#include <random>

#include "kiln/lppv_volume.h"
#include "kiln/probe_runtime.h"
#include "kiln_lppv.h"
#include "probes/tetrahedralize.h"
#include "src/image.h"
#include "src/sh_projection.h"
#include "tests/test_util.h"

namespace kiln {
namespace {

// A radiance SH field linear in position: c_i(p) = a_i + B_i p per channel, evaluated in
// double for reference values.
struct LinearField {
  std::array<glm::dvec3, kShL2Count> a;
  std::array<glm::dmat3, kShL2Count> b;  // column `axis` = d c_i / d p[axis] for RGB

  explicit LinearField(uint32_t seed) {
    std::mt19937 rng(seed);
    std::uniform_real_distribution<double> u(-1.0, 1.0);
    for (int i = 0; i < kShL2Count; ++i) {
      a[i] = glm::dvec3(u(rng), u(rng), u(rng)) + (i == 0 ? 3.0 : 0.0);
      for (int c = 0; c < 3; ++c) b[i][c] = glm::dvec3(u(rng), u(rng), u(rng)) * 0.5;
    }
  }
  ShL2Rgb at(glm::dvec3 p) const {
    ShL2Rgb s;
    for (int i = 0; i < kShL2Count; ++i) s.c[i] = glm::vec3(a[i] + b[i] * p);
    return s;
  }
  // Validity linear in position too, within (0, 1) over [-1, 1]^3.
  static double validity(glm::dvec3 p) { return 0.55 + 0.1 * p.x - 0.15 * p.y + 0.2 * p.z; }
};

// Probes at the corners of [-1, 1]^3 and at random interior points, holding the field.
ProbeSet linearProbeSet(const LinearField& field, int interior = 40, uint32_t seed = 7) {
  std::vector<glm::vec3> p;
  for (int i = 0; i < 8; ++i) p.emplace_back(i & 1 ? 1 : -1, i & 2 ? 1 : -1, i & 4 ? 1 : -1);
  std::mt19937 rng(seed);
  std::uniform_real_distribution<float> u(-0.9f, 0.9f);
  for (int i = 0; i < interior; ++i) p.emplace_back(u(rng), u(rng), u(rng));
  Result<ProbeSet> r = buildProbeTopology(p);
  EXPECT_TRUE(r.ok()) << r.error();
  ProbeSet set = r.ok() ? std::move(r).value() : ProbeSet{};
  for (size_t i = 0; i < set.positions.size(); ++i) {
    set.sh[i] = field.at(glm::dvec3(set.positions[i]));
    set.validity[i] = float(LinearField::validity(glm::dvec3(set.positions[i])));
  }
  return set;
}

// Rounding bound for values of size ~4 through float barycentrics and blends.
constexpr float kTol = 2e-5f;

void expectShNear(const ShL2Rgb& got, const ShL2Rgb& want, float tol, const std::string& what) {
  for (int i = 0; i < kShL2Count; ++i) {
    for (int c = 0; c < 3; ++c) {
      ASSERT_NEAR(got.c[i][c], want.c[i][c], tol) << what << " coefficient " << i << " ch " << c;
    }
  }
}

bool bitEqual(const ShL2Rgb& a, const ShL2Rgb& b) {
  return std::memcmp(&a, &b, sizeof(ShL2Rgb)) == 0;
}

LppvBuildSettings boxSettings(LppvPlacement placement, glm::ivec3 resolution) {
  LppvBuildSettings s;
  s.boundsMin = glm::vec3(-0.8f, -0.7f, -0.9f);
  s.boundsMax = glm::vec3(0.9f, 0.6f, 0.75f);
  s.resolution = resolution;
  s.placement = placement;
  return s;
}

// ---- sample positions --------------------------------------------------------------------

TEST(LppvGrid, CellCenterAndCellCornerPositionsAreExact) {
  const glm::vec3 lo(-1.0f, 0.0f, 2.0f), hi(3.0f, 2.0f, 5.0f);
  const LppvVolume c = makeLppvVolume(lo, hi, glm::ivec3(4, 2, 3), LppvPlacement::kCellCenter);
  // Centre: min + (i + 0.5) (max - min) / n.
  EXPECT_EQ(c.samplePosition(0, 0, 0), glm::vec3(-0.5f, 0.5f, 2.5f));
  EXPECT_EQ(c.samplePosition(3, 1, 2), glm::vec3(2.5f, 1.5f, 4.5f));
  EXPECT_EQ(c.samplePosition(1, 0, 1), glm::vec3(0.5f, 0.5f, 3.5f));
  // Corner: min + i (max - min) / (n - 1): the outermost samples lie on the box.
  const LppvVolume k = makeLppvVolume(lo, hi, glm::ivec3(5, 3, 4), LppvPlacement::kCellCorner);
  EXPECT_EQ(k.samplePosition(0, 0, 0), lo);
  EXPECT_EQ(k.samplePosition(4, 2, 3), hi);
  EXPECT_EQ(k.samplePosition(1, 1, 1), glm::vec3(0.0f, 1.0f, 3.0f));
  // An axis with one corner sample puts it at the centre.
  const LppvVolume one = makeLppvVolume(lo, hi, glm::ivec3(1, 2, 1), LppvPlacement::kCellCorner);
  EXPECT_EQ(one.samplePosition(0, 1, 0), glm::vec3(1.0f, 2.0f, 3.5f));
  // Sampling exactly at a sample gives that sample alone.
  for (const LppvVolume* v : {&c, &k}) {
    for (int z = 0; z < v->resolution.z; ++z) {
      for (int y = 0; y < v->resolution.y; ++y) {
        for (int x = 0; x < v->resolution.x; ++x) {
          const LppvTrilinear t = locateLppv(*v, v->samplePosition(x, y, z));
          float w = 0.0f;
          for (int j = 0; j < 8; ++j) {
            if (t.cells[j] == v->cellIndex(x, y, z)) w += t.weights[j];
          }
          EXPECT_NEAR(w, 1.0f, 1e-6f) << x << " " << y << " " << z;
        }
      }
    }
  }
  const std::vector<glm::vec3> pos = lppvSamplePositions(k);
  ASSERT_EQ(pos.size(), k.cellCount());
  EXPECT_EQ(pos[k.cellIndex(2, 1, 3)], k.samplePosition(2, 1, 3));
}

// ---- fill and sampling -------------------------------------------------------------------

TEST(LppvFill, ReproducesALinearFieldAtEveryGridPoint) {
  const LinearField field(1);
  const ProbeSet set = linearProbeSet(field);
  for (LppvPlacement placement : {LppvPlacement::kCellCenter, LppvPlacement::kCellCorner}) {
    Result<LppvBuild> b = buildLppvFromProbes(set, boxSettings(placement, glm::ivec3(5, 4, 6)));
    ASSERT_TRUE(b.ok()) << b.error();
    const LppvVolume& v = b->volume;
    ASSERT_TRUE(validateLppvVolume(v, "built").ok());
    for (int z = 0; z < 6; ++z) {
      for (int y = 0; y < 4; ++y) {
        for (int x = 0; x < 5; ++x) {
          const glm::dvec3 p(v.samplePosition(x, y, z));
          expectShNear(v.sh[v.cellIndex(x, y, z)], field.at(p), kTol, "grid point");
          ASSERT_NEAR(v.validity[v.cellIndex(x, y, z)], LinearField::validity(p), 1e-5);
        }
      }
    }
  }
}

TEST(LppvSample, TrilinearReproducesALinearFieldBetweenGridPoints) {
  const LinearField field(2);
  const ProbeSet set = linearProbeSet(field);
  for (LppvPlacement placement : {LppvPlacement::kCellCenter, LppvPlacement::kCellCorner}) {
    Result<LppvBuild> b = buildLppvFromProbes(set, boxSettings(placement, glm::ivec3(3, 5, 4)));
    ASSERT_TRUE(b.ok()) << b.error();
    const LppvVolume& v = b->volume;
    // Points between the outermost samples (where trilinear interpolation is not clamped).
    const glm::vec3 lo = v.samplePosition(0, 0, 0);
    const glm::vec3 hi = v.samplePosition(2, 4, 3);
    std::mt19937 rng(3);
    std::uniform_real_distribution<float> u(0.0f, 1.0f);
    for (int i = 0; i < 2000; ++i) {
      const glm::vec3 p = lo + glm::vec3(u(rng), u(rng), u(rng)) * (hi - lo);
      expectShNear(sampleLppv(v, p), field.at(glm::dvec3(p)), kTol, "between samples");
      ASSERT_NEAR(sampleLppvValidity(v, p), LinearField::validity(glm::dvec3(p)), 1e-5);
      const LppvTrilinear t = locateLppv(v, p);
      float sum = 0.0f;
      for (float w : t.weights) {
        ASSERT_GE(w, 0.0f);
        sum += w;
      }
      ASSERT_NEAR(sum, 1.0f, 1e-6f);
    }
  }
}

TEST(LppvSample, ClampsToTheEdgeOutsideTheOutermostSamples) {
  const LinearField field(4);
  const ProbeSet set = linearProbeSet(field);
  Result<LppvBuild> b =
      buildLppvFromProbes(set, boxSettings(LppvPlacement::kCellCenter, glm::ivec3(4, 3, 2)));
  ASSERT_TRUE(b.ok()) << b.error();
  const LppvVolume& v = b->volume;
  const ShL2Rgb& first = v.sh[v.cellIndex(0, 0, 0)];
  const ShL2Rgb& last = v.sh[v.cellIndex(3, 2, 1)];
  // The box's min corner lies outside the first sample: held at the first sample's value.
  EXPECT_TRUE(bitEqual(sampleLppv(v, v.boundsMin), first));
  EXPECT_TRUE(bitEqual(sampleLppv(v, glm::vec3(-1e30f)), first));
  EXPECT_TRUE(bitEqual(sampleLppv(v, glm::vec3(1e30f)), last));
  EXPECT_TRUE(bitEqual(sampleLppv(v, glm::vec3(INFINITY)), last));
  EXPECT_TRUE(bitEqual(sampleLppv(v, glm::vec3(NAN)), first));
  // Along one axis only: x beyond the last sample, y and z at samples.
  const glm::vec3 p(100.0f, v.samplePosition(0, 1, 1).y, v.samplePosition(0, 1, 1).z);
  expectShNear(sampleLppv(v, p), v.sh[v.cellIndex(3, 1, 1)], 1e-6f, "clamped x");
}

TEST(LppvSample, BatchAndIrradianceMatchSingleQueries) {
  const LinearField field(5);
  const ProbeSet set = linearProbeSet(field);
  Result<LppvBuild> b =
      buildLppvFromProbes(set, boxSettings(LppvPlacement::kCellCorner, glm::ivec3(4, 4, 4)));
  ASSERT_TRUE(b.ok()) << b.error();
  std::vector<glm::vec3> pts;
  std::mt19937 rng(6);
  std::uniform_real_distribution<float> u(-1.2f, 1.2f);
  for (int i = 0; i < 100; ++i) pts.emplace_back(u(rng), u(rng), u(rng));
  std::vector<ShL2Rgb> out(pts.size());
  sampleLppv(b->volume, pts, out);
  for (size_t i = 0; i < pts.size(); ++i) {
    const ShL2Rgb one = sampleLppv(b->volume, pts[i]);
    ASSERT_TRUE(bitEqual(out[i], one));
    const glm::vec3 n = glm::normalize(glm::vec3(u(rng), u(rng), u(rng)) + 0.01f);
    EXPECT_EQ(lppvIrradiance(b->volume, pts[i], n), probeIrradiance(one, n));
  }
}

TEST(LppvFill, IsIdenticalAtAnyThreadCountAndWhenRefilledAtRunTime) {
  const LinearField field(8);
  const ProbeSet set = linearProbeSet(field, 200, 9);
  LppvBuildSettings s = boxSettings(LppvPlacement::kCellCenter, glm::ivec3(16, 12, 10));
  s.threads = 1;
  Result<LppvBuild> one = buildLppvFromProbes(set, s);
  s.threads = 4;
  Result<LppvBuild> four = buildLppvFromProbes(set, s);
  ASSERT_TRUE(one.ok() && four.ok());
  EXPECT_EQ(serializeLppvVolume(one->volume), serializeLppvVolume(four->volume));
  // A run-time refill after moving the volume equals a fresh build at the new place.
  LppvVolume moved = one->volume;
  moved.boundsMin += glm::vec3(0.05f, -0.1f, 0.2f);
  moved.boundsMax += glm::vec3(0.05f, -0.1f, 0.2f);
  fillLppvFromProbes(set, moved);
  s.boundsMin = moved.boundsMin;
  s.boundsMax = moved.boundsMax;
  Result<LppvBuild> fresh = buildLppvFromProbes(set, s);
  ASSERT_TRUE(fresh.ok());
  EXPECT_EQ(serializeLppvVolume(moved), serializeLppvVolume(fresh->volume));
}

TEST(LppvFill, BadSettingsAreNamed) {
  const ProbeSet set = linearProbeSet(LinearField(10));
  LppvBuildSettings s = boxSettings(LppvPlacement::kCellCenter, glm::ivec3(2, 2, 2));
  s.boundsMax.y = s.boundsMin.y;
  EXPECT_NE(buildLppvFromProbes(set, s).error().find("bounds: max.y"), std::string::npos);
  s = boxSettings(LppvPlacement::kCellCenter, glm::ivec3(2, 0, 2));
  EXPECT_NE(buildLppvFromProbes(set, s).error().find("resolution.y"), std::string::npos);
  s = boxSettings(LppvPlacement::kCellCenter, glm::ivec3(1024, 1024, 1024));
  EXPECT_NE(buildLppvFromProbes(set, s).error().find("resolution:"), std::string::npos);
  s = boxSettings(LppvPlacement::kCellCenter, glm::ivec3(2, 2, 2));
  s.boundsMin.z = NAN;
  EXPECT_NE(buildLppvFromProbes(set, s).error().find("bounds: not finite"), std::string::npos);
}

// ---- automatic resolution ----------------------------------------------------------------

// Probes on the integer lattice [0, 4]^3 (125 probes, spacing 1).
ProbeSet latticeSet() {
  std::vector<glm::vec3> p;
  for (int z = 0; z <= 4; ++z)
    for (int y = 0; y <= 4; ++y)
      for (int x = 0; x <= 4; ++x) p.emplace_back(x, y, z);
  Result<ProbeSet> r = buildProbeTopology(p);
  EXPECT_TRUE(r.ok()) << r.error();
  return r.ok() ? std::move(r).value() : ProbeSet{};
}

TEST(LppvAutoResolution, FollowsTheDocumentedDensityRule) {
  const ProbeSet set = latticeSet();
  const LppvPlacement center = LppvPlacement::kCellCenter, corner = LppvPlacement::kCellCorner;
  // Bounds [0.5, 2.5]^3 hold the 8 probes {1, 2}^3: s = cbrt(8 / 8) = 1, k = 2 per axis.
  LppvAutoResolution r = autoLppvResolution(set, glm::vec3(0.5f), glm::vec3(2.5f), center);
  EXPECT_EQ(r.probesInBounds, 8);
  EXPECT_DOUBLE_EQ(r.probeSpacing, 1.0);
  EXPECT_FALSE(r.wholeSetDensity);
  EXPECT_EQ(r.resolution, glm::ivec3(2));
  EXPECT_EQ(autoLppvResolution(set, glm::vec3(0.5f), glm::vec3(2.5f), corner).resolution,
            glm::ivec3(3));
  LppvAutoSettings twice;
  twice.samplesPerProbeSpacing = 2.0;
  EXPECT_EQ(autoLppvResolution(set, glm::vec3(0.5f), glm::vec3(2.5f), center, twice).resolution,
            glm::ivec3(4));
  // Closed bounds [0, 4] x [0, 2] x [0, 1]: 5 x 3 x 2 = 30 probes, V = 8, s = cbrt(8 / 30).
  r = autoLppvResolution(set, glm::vec3(0.0f), glm::vec3(4.0f, 2.0f, 1.0f), center);
  EXPECT_EQ(r.probesInBounds, 30);
  const double s = std::cbrt(8.0 / 30.0);
  EXPECT_NEAR(r.probeSpacing, s, 1e-12);
  EXPECT_EQ(r.resolution,
            glm::ivec3(int(std::ceil(4.0 / s)), int(std::ceil(2.0 / s)), int(std::ceil(1.0 / s))));
  EXPECT_EQ(r.resolution, glm::ivec3(7, 4, 2));
  // The cap.
  LppvAutoSettings capped;
  capped.maxResolution = 5;
  EXPECT_EQ(autoLppvResolution(set, glm::vec3(0.0f), glm::vec3(4.0f, 2.0f, 1.0f), center, capped)
                .resolution,
            glm::ivec3(5, 4, 2));
  // No probe inside: the whole set's density, (4^3 / 125)^(1/3) = 0.8: a 2 m box gets
  // ceil(2.5) = 3 per axis.
  r = autoLppvResolution(set, glm::vec3(10.0f), glm::vec3(12.0f), center);
  EXPECT_TRUE(r.wholeSetDensity);
  EXPECT_EQ(r.probesInBounds, 0);
  EXPECT_NEAR(r.probeSpacing, 0.8, 1e-12);
  EXPECT_EQ(r.resolution, glm::ivec3(3));
  // The build uses the rule and reports it.
  LppvBuildSettings bs;
  bs.boundsMin = glm::vec3(0.5f);
  bs.boundsMax = glm::vec3(2.5f);
  Result<LppvBuild> b = buildLppvFromProbes(set, bs);
  ASSERT_TRUE(b.ok()) << b.error();
  ASSERT_TRUE(b->autoResolution.has_value());
  EXPECT_EQ(b->volume.resolution, glm::ivec3(2));
}

TEST(LppvAutoResolution, FlatProbeLayoutsUseTheirArea) {
  // 5 x 5 probes on the plane y = 1, spacing 1: no probe in the box, d = 2 spanned axes,
  // s = sqrt(16 / 25) = 0.8.
  std::vector<glm::vec3> p;
  for (int z = 0; z <= 4; ++z)
    for (int x = 0; x <= 4; ++x) p.emplace_back(x, 1, z);
  Result<ProbeSet> set = buildProbeTopology(p);
  ASSERT_TRUE(set.ok()) << set.error();
  const LppvAutoResolution r = autoLppvResolution(
      *set, glm::vec3(0.0f, 2.0f, 0.0f), glm::vec3(4.0f, 3.6f, 1.6f), LppvPlacement::kCellCenter);
  EXPECT_TRUE(r.wholeSetDensity);
  EXPECT_NEAR(r.probeSpacing, 0.8, 1e-12);
  EXPECT_EQ(r.resolution, glm::ivec3(5, 2, 2));
}

// ---- Unity L1 packing --------------------------------------------------------------------

TEST(LppvUnityL1, EvaluatesToTheL1IrradianceOverPi) {
  std::mt19937 rng(11);
  std::uniform_real_distribution<float> u(-1.0f, 1.0f);
  std::normal_distribution<float> g;
  for (int t = 0; t < 50; ++t) {
    ShL2Rgb sh;
    for (auto& c : sh.c) c = glm::vec3(u(rng), u(rng), u(rng));
    const ShL1Rgb l1 = reduceToL1(sh);
    const UnityShL1 gltf = packUnityShL1(sh, ShAxes::kGltf);
    const UnityShL1 unity = packUnityShL1(sh, ShAxes::kUnity);
    // The constant term is exactly c0 Y00 (A0 / pi = 1; band 2 is not folded in).
    EXPECT_FLOAT_EQ(gltf.shAr.w, 0.282095f * sh.c[0].x);
    for (int k = 0; k < 20; ++k) {
      const glm::vec3 n = glm::normalize(glm::vec3(g(rng), g(rng), g(rng)));
      const glm::vec3 want = l1.irradiance(n) / 3.14159265358979f;
      const glm::vec3 got = evalUnityShL1(gltf, n);
      const glm::vec3 gotUnity = evalUnityShL1(unity, glm::vec3(-n.x, n.y, n.z));
      for (int c = 0; c < 3; ++c) {
        ASSERT_NEAR(got[c], want[c], 1e-6f);
        ASSERT_NEAR(gotUnity[c], want[c], 1e-6f);
      }
    }
  }
}

TEST(LppvUnityL1, ImageIsTheDocumentedAtlas) {
  LppvVolume v = makeLppvVolume(glm::vec3(0.0f), glm::vec3(3.0f, 2.0f, 4.0f), glm::ivec3(3, 2, 4),
                                LppvPlacement::kCellCenter);
  std::mt19937 rng(12);
  std::uniform_real_distribution<float> u(-1.0f, 1.0f);
  for (ShL2Rgb& s : v.sh)
    for (auto& c : s.c) c = glm::vec3(u(rng), u(rng), u(rng));
  for (ShAxes axes : {ShAxes::kGltf, ShAxes::kUnity}) {
    const Image img = lppvUnityL1Image(v, axes);
    ASSERT_EQ(img.width, 12);
    ASSERT_EQ(img.height, 8);
    ASSERT_EQ(img.channels, 4);
    for (int z = 0; z < 4; ++z) {
      for (int y = 0; y < 2; ++y) {
        for (int i = 0; i < 3; ++i) {
          const int x = axes == ShAxes::kUnity ? 2 - i : i;
          const UnityShL1 p = packUnityShL1(v.sh[v.cellIndex(x, y, z)], axes);
          const glm::vec4 want[4] = {p.shAr, p.shAg, p.shAb, glm::vec4(1.0f)};
          for (int b = 0; b < 4; ++b) {
            const float* px = img.at(b * 3 + i, z * 2 + y);
            EXPECT_EQ(glm::vec4(px[0], px[1], px[2], px[3]), want[b])
                << "block " << b << " sample " << x << " " << y << " " << z;
          }
        }
      }
    }
  }
}

// ---- files -------------------------------------------------------------------------------

LppvVolume smallVolume() {
  const ProbeSet set = linearProbeSet(LinearField(13), 10, 14);
  Result<LppvBuild> b =
      buildLppvFromProbes(set, boxSettings(LppvPlacement::kCellCorner, glm::ivec3(2, 2, 1)));
  EXPECT_TRUE(b.ok()) << b.error();
  return b.ok() ? std::move(b).value().volume : LppvVolume{};
}

std::string parseError(const std::vector<uint8_t>& bytes) {
  Result<LppvVolume> r = parseLppvVolume(bytes, "bad.klppv");
  return r.ok() ? std::string("(accepted)") : r.error();
}

TEST(LppvFile, RoundTripThroughAllOutputsIsExact) {
  const LinearField field(15);
  const ProbeSet set = linearProbeSet(field);
  LppvBuildSettings s = boxSettings(LppvPlacement::kCellCenter, glm::ivec3(5, 3, 4));
  s.resolution.reset();
  Result<LppvBuild> b = buildLppvFromProbes(set, s);
  ASSERT_TRUE(b.ok()) << b.error();
  const std::string dir = test::makeTempDir("kiln_lppv");
  LppvOutputOptions options;
  options.source = "field.kprobe";
  options.autoResolution = b->autoResolution;
  options.axes = ShAxes::kUnity;
  Result<LppvOutputFiles> files = writeLppvOutputs(b->volume, dir + "/vol", options);
  ASSERT_TRUE(files.ok()) << files.error();
  for (const std::string& f : {files->volume, files->unityL1, files->metadata}) {
    EXPECT_TRUE(std::filesystem::exists(f)) << f;
    EXPECT_FALSE(std::filesystem::exists(f + ".tmp")) << f;
  }
  // .klppv: bit-exact.
  Result<LppvVolume> loaded = loadLppvFile(files->volume);
  ASSERT_TRUE(loaded.ok()) << loaded.error();
  EXPECT_EQ(serializeLppvVolume(*loaded), serializeLppvVolume(b->volume));
  EXPECT_EQ(std::filesystem::file_size(files->volume), 64 + 128 * b->volume.cellCount());
  // EXR: full float, so exact.
  Result<Image> exr = readHdrImage(files->unityL1);
  ASSERT_TRUE(exr.ok()) << exr.error();
  const Image want = lppvUnityL1Image(b->volume, ShAxes::kUnity);
  ASSERT_EQ(exr->width, want.width);
  ASSERT_EQ(exr->height, want.height);
  ASSERT_EQ(exr->channels, 4);
  EXPECT_EQ(exr->pixels, want.pixels);
  // JSON.
  const nlohmann::json j = nlohmann::json::parse(test::readTextFile(files->metadata));
  const glm::ivec3 n = b->volume.resolution;
  EXPECT_EQ(j["resolution"], nlohmann::json::array({n.x, n.y, n.z}));
  EXPECT_EQ(j["placement"], "cellCenter");
  EXPECT_EQ(j["files"]["l2"], "vol.klppv");
  EXPECT_EQ(j["files"]["unityL1"], "vol_L1.exr");
  EXPECT_EQ(j["unityL1"]["width"], 4 * n.x);
  EXPECT_EQ(j["unityL1"]["height"], n.y * n.z);
  EXPECT_EQ(j["unityL1"]["axes"], "unity");
  EXPECT_FLOAT_EQ(j["unityL1"]["bounds"]["min"][0].get<float>(), -s.boundsMax.x);
  EXPECT_FLOAT_EQ(j["bounds"]["max"][2].get<float>(), s.boundsMax.z);
  EXPECT_EQ(j["source"]["resolutionMode"], "auto");
  EXPECT_EQ(j["source"]["probes"], "field.kprobe");
  std::filesystem::remove_all(dir);
}

TEST(LppvFile, EveryTruncationIsRejected) {
  const std::vector<uint8_t> bytes = serializeLppvVolume(smallVolume());
  ASSERT_EQ(bytes.size(), 64u + 4u * 128u);
  ASSERT_TRUE(parseLppvVolume(bytes, "ok").ok());
  for (size_t n = 0; n < bytes.size(); ++n) {
    const std::vector<uint8_t> cut(bytes.begin(), bytes.begin() + long(n));
    const std::string e = parseError(cut);
    ASSERT_EQ(e.rfind("bad.klppv: ", 0), 0u) << n << ": " << e;
    ASSERT_NE(e.find("truncated"), std::string::npos) << n << ": " << e;
  }
  std::vector<uint8_t> longer = bytes;
  longer.push_back(0);
  EXPECT_NE(parseError(longer).find("trailing data"), std::string::npos);
  // Through the file reader, which names the path.
  const std::string dir = test::makeTempDir("kiln_lppv");
  const std::string path = dir + "/cut.klppv";
  for (size_t n : {size_t(0), size_t(4), size_t(63), size_t(64), bytes.size() - 1}) {
    std::FILE* f = std::fopen(path.c_str(), "wb");
    std::fwrite(bytes.data(), 1, n, f);
    std::fclose(f);
    Result<LppvVolume> r = loadLppvFile(path);
    ASSERT_FALSE(r.ok());
    EXPECT_EQ(r.error().rfind(path + ": ", 0), 0u) << r.error();
  }
  EXPECT_NE(loadLppvFile(dir + "/missing.klppv").error().find("cannot open"), std::string::npos);
  std::filesystem::remove_all(dir);
}

TEST(LppvFile, BadValuesAndHeadersAreNamed) {
  const LppvVolume good = smallVolume();
  auto withVolume = [&](auto change) {
    LppvVolume v = good;
    change(v);
    return parseError(serializeLppvVolume(v));  // checksum is valid: the values are judged
  };
  EXPECT_NE(withVolume([](LppvVolume& v) { v.sh[3].c[5].y = NAN; }).find("sh[3][5]: not finite"),
            std::string::npos);
  EXPECT_NE(withVolume([](LppvVolume& v) { v.sh[0].c[0].x = INFINITY; }).find("sh[0][0]"),
            std::string::npos);
  EXPECT_NE(withVolume([](LppvVolume& v) { v.validity[2] = NAN; }).find("validity[2]"),
            std::string::npos);
  EXPECT_NE(withVolume([](LppvVolume& v) { v.validity[1] = 1.5f; }).find("validity[1]"),
            std::string::npos);
  EXPECT_NE(withVolume([](LppvVolume& v) { v.boundsMin.x = NAN; }).find("bounds: not finite"),
            std::string::npos);
  EXPECT_NE(withVolume([](LppvVolume& v) { v.boundsMax.y = v.boundsMin.y; }).find("bounds.y"),
            std::string::npos);

  const std::vector<uint8_t> bytes = serializeLppvVolume(good);
  auto patched = [&](size_t at, uint32_t value) {
    std::vector<uint8_t> b = bytes;
    std::memcpy(b.data() + at, &value, 4);
    return parseError(b);
  };
  EXPECT_NE(patched(0, 0x4b505242).find("magic"), std::string::npos);
  EXPECT_NE(patched(4, 3).find("version"), std::string::npos);
  EXPECT_NE(patched(8, 0).find("resolution.x"), std::string::npos);
  EXPECT_NE(patched(12, 5000).find("resolution.y"), std::string::npos);
  EXPECT_NE(patched(20, 7).find("placement"), std::string::npos);
  EXPECT_NE(patched(48, 1).find("reserved"), std::string::npos);
  // Resolution that would need more data than the file holds: caught before allocating.
  EXPECT_NE(patched(16, 1000).find("truncated"), std::string::npos);
  // A flipped payload bit.
  std::vector<uint8_t> flipped = bytes;
  flipped[100] ^= 0x10;
  EXPECT_NE(parseError(flipped).find("checksum"), std::string::npos);
}

// ---- C API -------------------------------------------------------------------------------

TEST(LppvCApi, LoadsSamplesAndReportsErrors) {
  const LinearField field(16);
  const ProbeSet set = linearProbeSet(field);
  Result<LppvBuild> b =
      buildLppvFromProbes(set, boxSettings(LppvPlacement::kCellCorner, glm::ivec3(4, 3, 5)));
  ASSERT_TRUE(b.ok()) << b.error();
  const std::string dir = test::makeTempDir("kiln_lppv");
  const std::string path = dir + "/c.klppv";
  ASSERT_TRUE(writeLppvFile(b->volume, path).ok());

  kiln_lppv* h = nullptr;
  ASSERT_EQ(kiln_lppv_load(path.c_str(), &h), KILN_OK) << kiln_lppv_last_error();
  EXPECT_STREQ(kiln_lppv_last_error(), "");
  kiln_lppv_info info;
  ASSERT_EQ(kiln_lppv_get_info(h, &info), KILN_OK);
  EXPECT_EQ(info.resolution[0], 4u);
  EXPECT_EQ(info.resolution[2], 5u);
  EXPECT_EQ(info.placement, KILN_LPPV_CELL_CORNER);
  EXPECT_EQ(info.bounds_min[1], b->volume.boundsMin.y);

  const float p[3] = {0.1f, -0.2f, 0.3f};
  const float n[3] = {0.0f, 1.0f, 0.0f};
  float sh[27], validity = -1.0f, rgb[3];
  ASSERT_EQ(kiln_lppv_sample_sh(h, p, sh, &validity), KILN_OK);
  const ShL2Rgb want = sampleLppv(b->volume, glm::vec3(p[0], p[1], p[2]));
  for (int i = 0; i < 9; ++i)
    for (int c = 0; c < 3; ++c) EXPECT_EQ(sh[3 * i + c], want.c[i][c]);
  EXPECT_EQ(validity, sampleLppvValidity(b->volume, glm::vec3(p[0], p[1], p[2])));
  ASSERT_EQ(kiln_lppv_irradiance(h, p, n, rgb), KILN_OK);
  const glm::vec3 e = probeIrradiance(want, glm::vec3(0, 1, 0));
  EXPECT_EQ(glm::vec3(rgb[0], rgb[1], rgb[2]), e);
  const float pts[6] = {0.1f, -0.2f, 0.3f, 5.0f, 5.0f, 5.0f};
  float batch[54];
  ASSERT_EQ(kiln_lppv_sample_batch(h, 2, pts, batch), KILN_OK);
  EXPECT_EQ(std::memcmp(batch, sh, sizeof(sh)), 0);

  kiln_lppv_retain(h);
  kiln_lppv_release(h);
  kiln_lppv_release(h);
  kiln_lppv_release(nullptr);

  kiln_lppv* bad = nullptr;
  EXPECT_EQ(kiln_lppv_load((dir + "/missing.klppv").c_str(), &bad), KILN_ERROR_IO);
  EXPECT_EQ(bad, nullptr);
  test::writeTextFile(dir + "/junk.klppv", "KLPVjunk");
  EXPECT_EQ(kiln_lppv_load((dir + "/junk.klppv").c_str(), &bad), KILN_ERROR_INVALID_FILE);
  EXPECT_NE(std::string(kiln_lppv_last_error()).find("junk.klppv: header: truncated"),
            std::string::npos)
      << kiln_lppv_last_error();
  EXPECT_EQ(kiln_lppv_load(nullptr, &bad), KILN_ERROR_INVALID_ARGUMENT);
  EXPECT_EQ(kiln_lppv_sample_sh(nullptr, p, sh, nullptr), KILN_ERROR_INVALID_ARGUMENT);
  EXPECT_EQ(kiln_lppv_sample_batch(nullptr, 1, pts, batch), KILN_ERROR_INVALID_ARGUMENT);
  std::filesystem::remove_all(dir);
}

// ---- CLI ---------------------------------------------------------------------------------

TEST(LppvCli, WritesTheThreeOutputs) {
  std::string out;
  if (!std::filesystem::exists(test::kilnExe()) ||
      test::runCommand(std::string(test::kilnExe()) + " probes lppv --help", &out) != 0 ||
      out.find("--bounds") == std::string::npos) {
    GTEST_SKIP() << "kiln has no 'probes lppv' subcommand in this build";
  }
  const LinearField field(17);
  const ProbeSet set = linearProbeSet(field);
  const std::string dir = test::makeTempDir("kiln_lppv");
  ASSERT_TRUE(writeProbeFile(set, dir + "/p.kprobe").ok());
  const std::string kiln = test::kilnExe();
  int code = test::runCommand(kiln + " probes lppv " + dir + "/p.kprobe --bounds " +
                                  "-0.5,-0.5,-0.5,0.5,0.5,0.5 --resolution 3,4,5 --cell-corner " +
                                  "--out " + dir + "/v",
                              &out);
  ASSERT_EQ(code, 0) << out;
  Result<LppvVolume> v = loadLppvFile(dir + "/v.klppv");
  ASSERT_TRUE(v.ok()) << v.error();
  EXPECT_EQ(v->resolution, glm::ivec3(3, 4, 5));
  EXPECT_EQ(v->placement, LppvPlacement::kCellCorner);
  expectShNear(v->sh[v->cellIndex(2, 3, 4)], field.at(glm::dvec3(0.5)), kTol, "corner sample");
  EXPECT_TRUE(std::filesystem::exists(dir + "/v_L1.exr"));
  EXPECT_TRUE(std::filesystem::exists(dir + "/v.json"));
  // Usage errors: exit code 2; bad input: 1.
  EXPECT_EQ(
      test::runCommand(
          kiln + " probes lppv " + dir + "/p.kprobe --bounds 1,2,3 --out " + dir + "/w", &out),
      2)
      << out;
  EXPECT_EQ(test::runCommand(kiln + " probes lppv " + dir + "/p.kprobe --bounds 0,0,0,1,1,1 " +
                                 "--resolution 0,2,2 --out " + dir + "/w",
                             &out),
            2)
      << out;
  EXPECT_EQ(test::runCommand(kiln + " probes lppv " + dir + "/missing.kprobe --bounds " +
                                 "0,0,0,1,1,1 --out " + dir + "/w",
                             &out),
            1)
      << out;
  EXPECT_NE(out.find("missing.kprobe"), std::string::npos) << out;
  std::filesystem::remove_all(dir);
}

// --blend on two_rooms' 36 scene probes: a small volume in dark room B, 0.1-0.6 m from the
// wall whose other side room A's sun lights. Filled plainly it takes room A's light through
// the cells that span the wall (the query of docs/probes.md at (4.45, 0.3, 1.5), inside this
// box, gives ~1.7 lux plainly and ~0.003 with visibility); filled with the default
// visibility-weighted blend it keeps room B's own light.
TEST(LppvCli, VisibilityBlendKeepsTheLightOfTheFarRoomOut) {
  const std::string scene = test::scenesDir() + "/two_rooms.gltf";
  if (!std::filesystem::exists(scene)) GTEST_SKIP() << scene << " not generated";
  const std::string dir = test::makeTempDir("kiln_lppv_blend");
  const std::string kiln = test::kilnExe();
  std::string out;
  ASSERT_EQ(test::runCommand(kiln + " probes bake " + scene + " --out " + dir +
                                 "/p.kprobe --rays 2048 --threads 2 --quiet",
                             &out),
            0)
      << out;
  const std::string lppv = kiln + " probes lppv " + dir + "/p.kprobe --bounds " +
                           "4.35,0.2,0.5,4.85,1.2,2.0 --resolution 2,2,3 --out " + dir;
  ASSERT_EQ(test::runCommand(lppv + "/vis", &out), 0) << out;
  EXPECT_NE(out.find("filled from the probe field (visibility blend)"), std::string::npos) << out;
  ASSERT_EQ(test::runCommand(lppv + "/plain --blend plain", &out), 0) << out;
  EXPECT_NE(out.find("filled from the probe field (plain blend)"), std::string::npos) << out;
  Result<LppvVolume> vis = loadLppvFile(dir + "/vis.klppv");
  Result<LppvVolume> plain = loadLppvFile(dir + "/plain.klppv");
  ASSERT_TRUE(vis.ok()) << vis.error();
  ASSERT_TRUE(plain.ok()) << plain.error();
  ASSERT_EQ(vis->sh.size(), plain->sh.size());
  // Mean luminance of band 0 (2 sqrt(pi) x the mean radiance) over the samples.
  auto meanC0 = [](const LppvVolume& v) {
    double sum = 0.0;
    for (const ShL2Rgb& sh : v.sh)
      sum += 0.2126 * sh.c[0].x + 0.7152 * sh.c[0].y + 0.0722 * sh.c[0].z;
    return sum / double(v.sh.size());
  };
  // Measured: plain 0.65, visibility 0.0017 (370x); a factor 10 leaves room for any CPU's noise.
  EXPECT_GT(meanC0(*plain), 10.0 * meanC0(*vis));
  EXPECT_GT(meanC0(*vis), 0.0);
  EXPECT_EQ(test::runCommand(lppv + "/bad --blend linear", &out), 2) << out;
  EXPECT_NE(out.find("--blend"), std::string::npos) << out;
  std::filesystem::remove_all(dir);
}

}  // namespace
}  // namespace kiln
