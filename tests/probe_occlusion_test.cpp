// probe_occlusion_test.cpp: mixed lighting in the probe bake (probes/probe_baker.h) and probe
// occlusion end to end: which lights reach the SH under each lighting mode (against the
// analytic delta of a directional light), the shadowmask occlusion of probes in full light,
// hard shadow and penumbra (against Integrator::lightVisibility and the half-disc symmetry),
// its interpolation, the .kprobe v2 file (round trip, v1 compatibility, bad files), the C API,
// and the LPPV occlusion block filled from the probes.
#include <gtest/gtest.h>

#include <cmath>
#include <cstring>
#include <filesystem>
#include <memory>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "kiln/lppv_volume.h"
#include "kiln/probe_runtime.h"
#include "kiln_runtime.h"
#include "probes/lppv.h"
#include "probes/probe_baker.h"
#include "src/sh_projection.h"
#include "tests/test_util.h"

namespace kiln {
namespace {

using test::addBox;
using test::addMaterial;
using test::lambert;

struct World {
  Scene scene;
  std::unique_ptr<Tracer> tracer;

  void build() {
    scene.updateBounds();
    auto created = Tracer::create(scene);
    ASSERT_TRUE(created.ok()) << created.error();
    tracer = std::move(created).value();
  }
  ProbeSample bakeOne(vec3 p, ProbeBakeSettings s) const {
    Integrator integrator(scene, *tracer, probeIntegratorSettings(scene, s));
    return bakeProbe(integrator, p, 7, 64, s.lightSamples);
  }
};

Light mixedSun(float lux, vec3 travel = vec3(0, -1, 0)) {
  Light l = test::directionalLight(travel, lux);
  l.mode = LightMode::Mixed;
  return l;
}

ProbeBakeSettings withMode(LightingMode mode) {
  ProbeBakeSettings s;
  s.lightingMode = mode;
  return s;
}

// ---- which lights reach the SH --------------------------------------------------------------

// No geometry, black sky: a light's only contribution is its direct delta, c_i = E Y_i(s).
// A mixed light is absent under baked-indirect and shadowmask (its direct light is real
// time) and present under subtractive; a realtime light is absent and a baked light present
// in every mode.
TEST(ProbeLightModes, MixedDirectLightPerLightingMode) {
  const vec3 travel = glm::normalize(vec3(0.3f, -1.0f, 0.2f));
  const auto y = shBasisL2(-travel);
  for (LightMode lightMode : {LightMode::Mixed, LightMode::Realtime, LightMode::Baked}) {
    World w;
    Light l = test::directionalLight(travel, 2.0f);
    l.mode = lightMode;
    w.scene.lights.push_back(l);
    w.build();
    for (LightingMode mode :
         {LightingMode::BakedIndirect, LightingMode::Shadowmask, LightingMode::Subtractive}) {
      const ShL2Rgb sh = w.bakeOne(vec3(0.0f), withMode(mode)).sh;
      const bool present = lightMode == LightMode::Baked ||
                           (lightMode == LightMode::Mixed && mode == LightingMode::Subtractive);
      for (int i = 0; i < kShL2Count; ++i) {
        EXPECT_NEAR(sh.c[i].x, present ? 2.0f * y[i] : 0.0f, 1e-6f)
            << lightingModeName(mode) << " light mode " << int(lightMode) << " c" << i;
      }
    }
  }
}

// Without a mode in the settings the scene's extras.kiln.lightingMode decides, else
// baked-indirect.
TEST(ProbeLightModes, ModeFromTheScene) {
  World w;
  w.scene.lights.push_back(mixedSun(2.0f));
  w.build();
  EXPECT_EQ(probeLightingMode(w.scene, {}), LightingMode::BakedIndirect);
  EXPECT_EQ(w.bakeOne(vec3(0.0f), {}).sh.c[0].x, 0.0f);
  w.scene.settings.lightingMode = "subtractive";
  EXPECT_EQ(probeLightingMode(w.scene, {}), LightingMode::Subtractive);
  EXPECT_NEAR(w.bakeOne(vec3(0.0f), {}).sh.c[0].x, 2.0f * 0.282095f, 1e-6f);
  EXPECT_EQ(probeLightingMode(w.scene, withMode(LightingMode::Shadowmask)),
            LightingMode::Shadowmask);
}

// Five overlapping mixed lights under shadowmask: four get channels (indirect only, occlusion
// stored), the fifth falls back to baked (its direct light in the SH) with a warning.
TEST(ProbeLightModes, ShadowmaskFallbackIsBakedAndWarned) {
  World w;
  for (int i = 0; i < 5; ++i) {
    Light l = mixedSun(float(5 - i));  // decreasing intensity: light 4 is coloured last
    l.name = "sun" + std::to_string(i);
    w.scene.lights.push_back(l);
  }
  w.build();
  ProbeBakeReport report;
  ProbeBakeSettings s = withMode(LightingMode::Shadowmask);
  s.rays = 16;
  std::vector<vec3> positions = {vec3(0, 0, 0), vec3(1, 0, 0), vec3(0, 1, 0), vec3(0, 0, 1)};
  auto set = bakeProbes(w.scene, *w.tracer, positions, s, nullptr, nullptr, &report);
  ASSERT_TRUE(set.ok()) << set.error();
  EXPECT_EQ(set->occlusionLights, (std::array<int32_t, 4>{0, 1, 2, 3}));
  bool warned = false;
  for (const std::string& m : report.warnings) warned |= m.find("'sun4'") != std::string::npos;
  EXPECT_TRUE(warned);
  // Only light 4 (1 lux, straight down) is in the SH: c0 = 1 x Y00. Deringing keeps c0.
  EXPECT_NEAR(set->sh[0].c[0].x, 0.282095f, 1e-6f);
  for (const glm::vec4& o : set->occlusion) EXPECT_EQ(o, glm::vec4(1.0f));  // nothing occludes
}

// ---- occlusion ------------------------------------------------------------------------------

// A mixed sun straight down and a slab over x < 0 at height 3: probes at x = +4 are in full
// light, at x = -4 in hard shadow, at x = 0 directly under the slab's edge.
struct SlabWorld : World {
  explicit SlabWorld(float shadowAngle) {
    Light sun = mixedSun(3.0f);
    sun.name = "sun";
    sun.shadowAngle = shadowAngle;
    sun.shadowSamples = 4;
    scene.lights.push_back(sun);
    Light fill = test::pointLight(vec3(20, 5, 0), 10.0f);  // realtime: never baked
    fill.mode = LightMode::Realtime;
    scene.lights.push_back(fill);
    const uint32_t m = addMaterial(scene, lambert(vec3(0.5f)));
    addBox(scene, "slab", vec3(-30, 3, -30), vec3(0, 3.2f, 30), m, false);
    scene.settings.lightingMode = "shadowmask";
    build();
  }
};

std::vector<vec3> slabProbes() {
  return {vec3(4, 1, 0),  vec3(5, 1, 1),  vec3(4, 2, 1),  vec3(5, 2, 0),   // lit
          vec3(-4, 1, 0), vec3(-5, 1, 1), vec3(-4, 2, 1), vec3(-5, 2, 0),  // shadow
          vec3(0, 1, 0)};                                                  // under the edge
}

TEST(ProbeOcclusion, FullLightHardShadowAndUnusedChannels) {
  SlabWorld w(0.0f);
  ProbeBakeSettings s;
  s.rays = 32;
  ProbeBakeReport report;
  auto set = bakeProbes(w.scene, *w.tracer, slabProbes(), s, nullptr, nullptr, &report);
  ASSERT_TRUE(set.ok()) << set.error();
  EXPECT_EQ(report.lightModes.mode, LightingMode::Shadowmask);
  EXPECT_EQ(set->occlusionLights, (std::array<int32_t, 4>{0, -1, -1, -1}));  // realtime: none
  ASSERT_EQ(set->occlusion.size(), 9u);
  for (int i = 0; i < 8; ++i) {
    EXPECT_EQ(set->occlusion[i].x, i < 4 ? 1.0f : 0.0f) << i;
    EXPECT_EQ(glm::vec3(set->occlusion[i].y, set->occlusion[i].z, set->occlusion[i].w),
              glm::vec3(1.0f))
        << i;
  }
  // The mixed sun's direct light is not in the SH (shadowmask: indirect only), and neither is
  // the realtime light: a lit probe facing the sun gets nothing like its 3 lux (the slab's
  // lit top reflects upwards, away from every probe).
  EXPECT_LT(set->sh[0].irradiance(vec3(0, 1, 0)).x, 0.01f);
  // Under baked-indirect there is no channel and nothing is occluded.
  s.lightingMode = LightingMode::BakedIndirect;
  auto plain = bakeProbes(w.scene, *w.tracer, slabProbes(), s);
  ASSERT_TRUE(plain.ok());
  EXPECT_EQ(plain->occlusionLights, (std::array<int32_t, 4>{-1, -1, -1, -1}));
  for (const glm::vec4& o : plain->occlusion) EXPECT_EQ(o, glm::vec4(1.0f));
}

// Soft shadow (a 20 degree sun): the probe under the edge sees half the sun's disc by
// symmetry, and its occlusion is exactly the mean of lightVisibility over the keyed samples.
TEST(ProbeOcclusion, PenumbraMatchesLightVisibility) {
  SlabWorld w(20.0f);
  ProbeBakeSettings s;
  s.rays = 32;
  s.seed = 11;
  auto set = bakeProbes(w.scene, *w.tracer, slabProbes(), s);
  ASSERT_TRUE(set.ok()) << set.error();
  const float o = set->occlusion[8].x;
  EXPECT_GT(o, 0.3f);
  EXPECT_LT(o, 0.7f);
  EXPECT_NEAR(o, 0.5f, 0.08f);  // 64 evaluations x 4 rays
  // Deep in the shadow and in full light the soft shadow changes nothing: 20 degrees at 2 m
  // blurs the edge over ~0.7 m.
  EXPECT_EQ(set->occlusion[0].x, 1.0f);
  EXPECT_EQ(set->occlusion[4].x, 0.0f);

  // The definition, computed directly: bakeProbes keys probe i with hashValues(seed, i).
  const Integrator integrator(w.scene, *w.tracer, probeIntegratorSettings(w.scene, s));
  const uint64_t key = hashValues(s.seed, 8);
  EXPECT_EQ(probeLightOcclusion(integrator, vec3(0, 1, 0), 0, key, s.occlusionSamples), o);
  // And an independent estimate from lightVisibility with its own key and many samples.
  double sum = 0.0;
  const int n = 1024;
  for (int j = 0; j < n; ++j)
    sum += integrator.lightVisibility(vec3(0, 1, 0), vec3(0.0f), 0, 0xabcdefull, uint32_t(j)).x;
  EXPECT_NEAR(o, sum / n, 0.06);
  // Keyed per probe: bit-identical at any thread count.
  s.threads = 1;
  auto one = bakeProbes(w.scene, *w.tracer, slabProbes(), s);
  s.threads = 3;
  auto three = bakeProbes(w.scene, *w.tracer, slabProbes(), s);
  ASSERT_TRUE(one.ok() && three.ok());
  EXPECT_EQ(serializeProbeSet(*one), serializeProbeSet(*three));
  EXPECT_EQ(one->occlusion[8].x, o);
  // A probe a little into the lit side is lit more.
  EXPECT_GT(probeLightOcclusion(integrator, vec3(0.2f, 1, 0), 0, key, 256), o);
}

// ---- interpolation --------------------------------------------------------------------------

ProbeSet cubeSetWithOcclusion() {
  std::vector<vec3> p;
  for (int i = 0; i < 8; ++i) p.push_back(vec3(i & 1, (i >> 1) & 1, (i >> 2) & 1));
  Result<ProbeSet> r = buildProbeTopology(p, {});
  EXPECT_TRUE(r.ok()) << r.error();
  ProbeSet s = r.ok() ? std::move(r).value() : ProbeSet{};
  s.sh.assign(p.size(), ShL2Rgb{});
  s.validity.assign(p.size(), 1.0f);
  s.occlusion.resize(p.size());
  for (size_t i = 0; i < p.size(); ++i) {
    const float t = float(i) / 7.0f;
    s.occlusion[i] = glm::vec4(t, 1.0f - t, (i & 1) ? 1.0f : 0.0f, 1.0f);
  }
  s.occlusionLights = {0, 2, 1, -1};
  return s;
}

TEST(ProbeOcclusion, InterpolationAtProbesAndBetween) {
  const ProbeSet s = cubeSetWithOcclusion();
  for (int32_t i = 0; i < s.probeCount(); ++i) {
    const ProbeLocation loc = locateProbe(s, s.positions[i]);
    EXPECT_EQ(interpolateOcclusion(s, loc), s.occlusion[i]) << i;
    EXPECT_EQ(sampleOcclusion(s, s.positions[i]), s.occlusion[i]) << i;
  }
  // Weights blend it, like the SH.
  const vec3 p(0.3f, 0.6f, 0.45f);
  const ProbeLocation loc = locateProbe(s, p);
  glm::vec4 want(0.0f);
  for (int k = 0; k < 4; ++k) want += loc.weights[k] * s.occlusion[loc.probes[k]];
  const glm::vec4 got = interpolateOcclusion(s, loc);
  for (int c = 0; c < 4; ++c) EXPECT_NEAR(got[c], want[c], 1e-6f);
  EXPECT_EQ(got.w, 1.0f);
  // Outside the hull the outer cells extrapolate, still within [0, 1].
  const glm::vec4 far = sampleOcclusion(s, vec3(5, -3, 2));
  for (int c = 0; c < 4; ++c) {
    EXPECT_GE(far[c], 0.0f);
    EXPECT_LE(far[c], 1.0f);
  }
  // Batch = single, with and without SH.
  const std::vector<vec3> pts = {p, vec3(0.9f, 0.1f, 0.5f), vec3(2, 2, 2)};
  std::vector<int32_t> hints(pts.size(), -1);
  std::vector<glm::vec4> occ(pts.size());
  std::vector<ShL2Rgb> sh(pts.size());
  sampleProbes(s, pts, hints, sh, occ);
  for (size_t i = 0; i < pts.size(); ++i) {
    EXPECT_EQ(occ[i], sampleOcclusion(s, pts[i])) << i;
    EXPECT_GE(hints[i], 0);
  }
  sampleProbes(s, pts, {}, {}, occ);
  EXPECT_EQ(occ[2], sampleOcclusion(s, pts[2]));
  // No occlusion at all: 1.
  ProbeSet none = s;
  none.occlusion.clear();
  EXPECT_EQ(sampleOcclusion(none, p), glm::vec4(1.0f));
}

// ---- .kprobe version 2 ----------------------------------------------------------------------

std::string parseError(const std::vector<uint8_t>& bytes) {
  Result<ProbeSet> r = parseProbeSet(bytes, "bad.kprobe");
  return r.ok() ? std::string("accepted") : r.error();
}

TEST(ProbeOcclusionFile, Version2RoundTripAndVersion1StillLoads) {
  const ProbeSet s = cubeSetWithOcclusion();
  const std::vector<uint8_t> v2 = serializeProbeSet(s, 2);
  uint32_t version = 0;
  std::memcpy(&version, v2.data() + 4, 4);
  EXPECT_EQ(version, 2u);
  Result<ProbeSet> r = parseProbeSet(v2, "v2");
  ASSERT_TRUE(r.ok()) << r.error();
  EXPECT_EQ(r->occlusion, s.occlusion);
  EXPECT_EQ(r->occlusionLights, s.occlusionLights);
  EXPECT_EQ(serializeProbeSet(*r, 2), v2);

  // Version 1: the same without the block; it loads with occlusion 1 and no channel lights.
  const std::vector<uint8_t> v1 = serializeProbeSet(s, 1);
  EXPECT_EQ(v1.size(), v2.size() - 16 - 16 * s.positions.size());
  Result<ProbeSet> old = parseProbeSet(v1, "v1");
  ASSERT_TRUE(old.ok()) << old.error();
  ASSERT_EQ(old->occlusion.size(), s.positions.size());
  for (const glm::vec4& o : old->occlusion) EXPECT_EQ(o, glm::vec4(1.0f));
  EXPECT_EQ(old->occlusionLights, (std::array<int32_t, 4>{-1, -1, -1, -1}));
  EXPECT_EQ(old->positions, s.positions);
  EXPECT_EQ(serializeProbeSet(*old, 1), v1);
  // Through the file reader too.
  const std::string dir = test::makeTempDir("kiln_occl");
  std::FILE* f = std::fopen((dir + "/old.kprobe").c_str(), "wb");
  std::fwrite(v1.data(), 1, v1.size(), f);
  std::fclose(f);
  Result<ProbeSet> loaded = loadProbeFile(dir + "/old.kprobe");
  ASSERT_TRUE(loaded.ok()) << loaded.error();
  EXPECT_EQ(sampleOcclusion(*loaded, vec3(0.5f)), glm::vec4(1.0f));
  std::filesystem::remove_all(dir);
}

TEST(ProbeOcclusionFile, BadVersion2FilesAreRejected) {
  const ProbeSet good = cubeSetWithOcclusion();
  const std::vector<uint8_t> bytes = serializeProbeSet(good);
  for (size_t n = 0; n < bytes.size(); ++n) {
    const std::vector<uint8_t> cut(bytes.begin(), bytes.begin() + long(n));
    const std::string e = parseError(cut);
    ASSERT_NE(e, "accepted") << n;
    ASSERT_EQ(e.rfind("bad.kprobe: ", 0), 0u) << n << ": " << e;
  }
  auto withSet = [&](auto change) {
    ProbeSet s = good;
    change(s);
    return parseError(serializeProbeSet(s));  // valid checksum: the values are judged
  };
  EXPECT_NE(withSet([](ProbeSet& s) { s.occlusion[1][2] = NAN; }).find("occlusion[1][2]"),
            std::string::npos);
  EXPECT_NE(withSet([](ProbeSet& s) { s.occlusion[3].x = 1.5f; }).find("occlusion[3][0]"),
            std::string::npos);
  EXPECT_NE(withSet([](ProbeSet& s) { s.occlusion[0].w = -0.25f; }).find("not in [0, 1]"),
            std::string::npos);
  EXPECT_NE(withSet([](ProbeSet& s) { s.occlusion[5].y = INFINITY; }).find("occlusion[5][1]"),
            std::string::npos);
  EXPECT_NE(withSet([](ProbeSet& s) { s.occlusionLights[2] = -7; }).find("occlusionLights[2]"),
            std::string::npos);
  // A version 1 header on a version 2 payload (and the reverse) does not fit the size.
  std::vector<uint8_t> b = bytes;
  const uint32_t one = 1;
  std::memcpy(b.data() + 4, &one, 4);
  EXPECT_NE(parseError(b).find("trailing data"), std::string::npos);
  std::vector<uint8_t> b1 = serializeProbeSet(good, 1);
  const uint32_t two = 2;
  std::memcpy(b1.data() + 4, &two, 4);
  EXPECT_NE(parseError(b1).find("truncated"), std::string::npos);
  // Validation of in-memory sets: a wrong-sized occlusion is named.
  ProbeSet wrong = good;
  wrong.occlusion.pop_back();
  EXPECT_NE(validateProbeSet(wrong, "mem").error().find("occlusion: size"), std::string::npos);
}

// ---- C API ----------------------------------------------------------------------------------

TEST(ProbeOcclusionCApi, SamplesOcclusionAndChannelLights) {
  const ProbeSet s = cubeSetWithOcclusion();
  const std::string dir = test::makeTempDir("kiln_occl_c");
  const std::string path = dir + "/c.kprobe";
  ASSERT_TRUE(writeProbeFile(s, path).ok());
  kiln_probes* probes = nullptr;
  ASSERT_EQ(kiln_probes_load(path.c_str(), &probes), KILN_OK) << kiln_last_error();
  const float pos[3] = {0.3f, 0.6f, 0.45f};
  kiln_probe_location loc;
  ASSERT_EQ(kiln_probes_locate(probes, pos, -1, &loc), KILN_OK);
  float occ[4] = {};
  ASSERT_EQ(kiln_probes_sample_occlusion(probes, &loc, occ), KILN_OK);
  const glm::vec4 want = sampleOcclusion(s, vec3(pos[0], pos[1], pos[2]));
  for (int c = 0; c < 4; ++c) EXPECT_EQ(occ[c], want[c]) << c;
  int32_t lights[4] = {};
  ASSERT_EQ(kiln_probes_occlusion_lights(probes, lights), KILN_OK);
  for (int c = 0; c < 4; ++c) EXPECT_EQ(lights[c], s.occlusionLights[c]);
  EXPECT_EQ(kiln_probes_sample_occlusion(probes, nullptr, occ), KILN_ERROR_INVALID_ARGUMENT);
  EXPECT_EQ(kiln_probes_occlusion_lights(nullptr, lights), KILN_ERROR_INVALID_ARGUMENT);
  loc.probes[1] = 1000;
  EXPECT_EQ(kiln_probes_sample_occlusion(probes, &loc, occ), KILN_ERROR_INVALID_ARGUMENT);
  EXPECT_NE(std::string(kiln_last_error()).find("out of range"), std::string::npos);
  kiln_probes_release(probes);
  std::filesystem::remove_all(dir);
}

// ---- LPPV -----------------------------------------------------------------------------------

TEST(ProbeOcclusionLppv, OcclusionBlockFilledFromTheProbes) {
  const ProbeSet s = cubeSetWithOcclusion();
  LppvBuildSettings bs;
  bs.boundsMin = vec3(-0.2f);
  bs.boundsMax = vec3(1.3f, 1.1f, 1.2f);
  bs.resolution = glm::ivec3(3, 4, 2);
  bs.threads = 2;
  Result<LppvBuild> b = buildLppvFromProbes(s, bs);
  ASSERT_TRUE(b.ok()) << b.error();
  const LppvVolume& v = b->volume;
  ASSERT_EQ(v.occlusion.size(), v.cellCount());
  for (int z = 0; z < 2; ++z)
    for (int y = 0; y < 4; ++y)
      for (int x = 0; x < 3; ++x) {
        const glm::vec4 want = sampleOcclusion(s, v.samplePosition(x, y, z));
        const glm::vec4 got = v.occlusion[v.cellIndex(x, y, z)];
        for (int c = 0; c < 4; ++c) EXPECT_NEAR(got[c], want[c], 1e-6f) << x << y << z;
        EXPECT_EQ(sampleLppvOcclusion(v, v.samplePosition(x, y, z)), got);
      }
  // Unity L1 atlas: block 3 holds it (and glTF axes are not mirrored).
  const Image image = lppvUnityL1Image(v);
  const int nx = 3, ny = 4;
  for (int z = 0; z < 2; ++z)
    for (int y = 0; y < ny; ++y)
      for (int x = 0; x < nx; ++x) {
        const float* px = image.at(3 * nx + x, z * ny + y);
        for (int c = 0; c < 4; ++c) EXPECT_EQ(px[c], v.occlusion[v.cellIndex(x, y, z)][c]);
      }
  // .klppv v2 round trip, and v1 files still load (occlusion 1).
  Result<LppvVolume> r = parseLppvVolume(serializeLppvVolume(v), "v2");
  ASSERT_TRUE(r.ok()) << r.error();
  EXPECT_EQ(r->occlusion, v.occlusion);
  const std::vector<uint8_t> v1 = serializeLppvVolume(v, 1);
  EXPECT_EQ(v1.size(), 64 + 112 * v.cellCount());
  Result<LppvVolume> old = parseLppvVolume(v1, "v1");
  ASSERT_TRUE(old.ok()) << old.error();
  for (const glm::vec4& o : old->occlusion) EXPECT_EQ(o, glm::vec4(1.0f));
  EXPECT_EQ(old->sh.size(), v.sh.size());
  // A NaN occlusion in a v2 file is named.
  LppvVolume bad = v;
  bad.occlusion[5].z = NAN;
  Result<LppvVolume> rb = parseLppvVolume(serializeLppvVolume(bad), "bad.klppv");
  ASSERT_FALSE(rb.ok());
  EXPECT_NE(rb.error().find("occlusion[5][2]"), std::string::npos) << rb.error();
}

// ---- the CLI ---------------------------------------------------------------------------------

// `kiln probes bake` takes the lighting mode from the scene or --lighting-mode; query and export
// show the occlusion. (Skips when the kiln executable has not been built.)
TEST(ProbeOcclusionCli, LightingModeAndOcclusionOutput) {
  if (!std::filesystem::exists(test::kilnExe())) GTEST_SKIP() << "kiln not built";
  using Json = nlohmann::json;
  const std::string dir = test::makeTempDir("kiln_occl_cli");
  const Json doc = {
      {"asset", {{"version", "2.0"}}},
      {"extensionsUsed", {"KHR_lights_punctual"}},
      {"extensions",
       {{"KHR_lights_punctual",
         {{"lights",
           {{{"type", "directional"},
             {"name", "sun"},
             {"intensity", 2},
             {"extras", {{"kiln", {{"mode", "mixed"}}}}}}}}}}}},
      {"nodes",
       {{{"name", "sun"}, {"extensions", {{"KHR_lights_punctual", {{"light", 0}}}}}},
        {{"name", "probes"},
         {"extras", {{"kiln", {{"probes", {{0, 0, 0}, {1, 0, 0}, {0, 1, 0}, {0, 0, 1}}}}}}}}}},
      {"scenes", {{{"nodes", {0, 1}}, {"extras", {{"kiln", {{"lightingMode", "shadowmask"}}}}}}}},
      {"scene", 0}};
  test::writeTextFile(dir + "/s.gltf", doc.dump());
  const std::string kiln = std::string(test::kilnExe()) + " probes ";
  std::string log;
  ASSERT_EQ(
      test::runCommand(kiln + "bake " + dir + "/s.gltf --out " + dir + "/a.kprobe --rays 16", &log),
      0)
      << log;
  EXPECT_NE(log.find("lighting mode shadowmask, occlusion channel 0 = light 'sun'"),
            std::string::npos)
      << log;
  ASSERT_EQ(test::runCommand(kiln + "query " + dir + "/a.kprobe 0.2 0.2 0.2 --json", &log), 0)
      << log;
  Json q = Json::parse(log);
  EXPECT_EQ(q["occlusion"], Json::array({1, 1, 1, 1}));
  EXPECT_EQ(q["occlusionLights"], Json::array({0, -1, -1, -1}));
  EXPECT_EQ(q["sh"][0][0].get<double>(), 0.0);  // mixed: direct light is real time
  ASSERT_EQ(test::runCommand(kiln + "query " + dir + "/a.kprobe 0.2 0.2 0.2", &log), 0) << log;
  EXPECT_NE(log.find("occlusion (shadowmask channels 0-3, lights 0 -1 -1 -1"), std::string::npos)
      << log;
  ASSERT_EQ(test::runCommand(kiln + "export " + dir + "/a.kprobe", &log), 0) << log;
  Json x = Json::parse(log);
  EXPECT_EQ(x["version"], kProbeFileVersion);
  EXPECT_EQ(x["occlusion"].size(), 4u);
  EXPECT_EQ(x["occlusionLights"], Json::array({0, -1, -1, -1}));

  // --lighting-mode overrides the scene: subtractive bakes the mixed sun fully, no channels.
  ASSERT_EQ(test::runCommand(kiln + "bake " + dir + "/s.gltf --out " + dir +
                                 "/b.kprobe --rays 16 --quiet --lighting-mode subtractive",
                             &log),
            0)
      << log;
  Result<ProbeSet> b = loadProbeFile(dir + "/b.kprobe");
  ASSERT_TRUE(b.ok()) << b.error();
  EXPECT_EQ(b->occlusionLights, (std::array<int32_t, 4>{-1, -1, -1, -1}));
  EXPECT_NEAR(b->sh[0].c[0].x, 2.0f * 0.282095f, 1e-5f);
  EXPECT_EQ(
      test::runCommand(
          kiln + "bake " + dir + "/s.gltf --out " + dir + "/c.kprobe --lighting-mode mixed", &log),
      2)
      << log;
  std::filesystem::remove_all(dir);
}

}  // namespace
}  // namespace kiln
