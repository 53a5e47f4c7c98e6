// probe_reference_test.cpp: probes baked by kiln against an independent renderer (Blender
// Cycles, ../shared/reference/cornell_box/probes.json; see ../shared/reference/README.md).
//
// The reference gives, at 20 points of the Cornell box, the irradiance E (not E/pi) for the
// six axis normals twice: `irradiance_axis`, exact (integrated from 360-degree panoramas),
// and `irradiance_axis_from_sh`, what the L2 projection of the same panorama gives. kiln
// stores L2 radiance SH, so the like-for-like comparison is kiln's L2 irradiance against
// irradiance_axis_from_sh; the exact value is reported as well (its gap is SH truncation,
// which no baker can remove).
//
// Error measure (stated, since some axis irradiances are near zero and the L2 reconstruction
// even goes negative there): per point and axis, |Lum(kiln) - Lum(ref)| / Lum(ref mean),
// with Lum = Rec. 709 luminance and "ref mean" the mean of the point's six reference axis
// irradiances. The error of an L2 reconstruction is a sum over all nine coefficients, so it
// scales with the point's overall light level, not with the one axis value; dividing by a
// near-zero axis value would measure nothing. The per-axis relative error (own value) is
// printed too. Per-channel checks use the same denominator per channel.
//
// Deringing is judged against the EXACT values (compareDeringing): the default bake (raw
// projection + the bake's deringing fit) against Cycles' own unwindowed L2, the floor of the
// representation.
//
// ProbeReference.CornellBox bakes KILN_PROBE_REF_RAYS rays per probe (default 262144, ~8 s
// of one core) and KILN_PROBE_REF_BOUNCES bounces (default 16). It skips with a message when
// ../shared is absent. ProbeReference.ReaderNamesTheFaultyField checks the reader of the
// reference files on made-up ones.
#include <gtest/gtest.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <memory>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "probes/probe_baker.h"
#include "src/gltf_loader.h"
#include "src/sh_projection.h"
#include "src/tracer.h"
#include "tests/test_util.h"
#include "tools/chart/chart_table.h"
#include "tools/chart/probe_reference.h"

namespace kiln {
namespace {

using chart::ProbeReferencePoint;
constexpr const auto& kAxisNames = chart::kReferenceAxisNames;
const auto& kAxes = chart::kReferenceAxes;

double lum(glm::dvec3 c) { return 0.2126 * c.x + 0.7152 * c.y + 0.0722 * c.z; }

struct Comparison {
  double maxErrFromSh = 0;  // over points and axes, luminance, relative to the point's mean
  double maxErrExact = 0;
  double maxChannelErrFromSh = 0;
  // compareDeringing: [Cycles' L2, kiln raw, kiln window, kiln default] against exact.
  double median[4] = {};
  double p90[4] = {};
  int deringed = 0;
};

// Deringing against the EXACT irradiance (the measure): per point and axis, the
// relative error |E - E_exact| / E_exact of the RGB mean of E, over the 120 point-axes; its
// median and 90th percentile for Cycles' own unwindowed L2 (the representation's floor),
// kiln's raw bake, the old window (windowDeringSh) and the bake's default deringing
// (deringProbeSh, what bakeProbes applies). The relative error of near-zero dark axes is what
// the p90 measures: there raw L2 goes negative and deringing decides the value.
void compareDeringing(const std::vector<ProbeReferencePoint>& ref, const ProbeSet& raw,
                      Comparison& out) {
  std::vector<ShL2Rgb> fitted(raw.sh.begin(), raw.sh.end());
  out.deringed = deringProbeSh(fitted);
  auto mean = [](glm::dvec3 v) { return (v.x + v.y + v.z) / 3.0; };
  std::vector<double> err[4];  // Cycles L2, raw, window, default
  for (size_t p = 0; p < ref.size(); ++p) {
    const ShL2Rgb window = windowDeringSh(raw.sh[p]).sh;
    for (int a = 0; a < 6; ++a) {
      const double exact = mean(ref[p].exact[a]);
      const double value[4] = {mean(ref[p].fromSh[a]),
                               mean(glm::dvec3(raw.sh[p].irradiance(kAxes[a]))),
                               mean(glm::dvec3(window.irradiance(kAxes[a]))),
                               mean(glm::dvec3(fitted[p].irradiance(kAxes[a])))};
      for (int k = 0; k < 4; ++k) err[k].push_back(std::abs(value[k] - exact) / exact);
      if (fitted[p].c[1] != raw.sh[p].c[1] || fitted[p].c[4] != raw.sh[p].c[4])
        std::printf(
            "deringed point %zu %s: exact %.4f, Cycles L2 %.4f, raw %.4f, window %.4f, "
            "fit %.4f\n",
            p, kAxisNames[a], exact, value[0], value[1], value[2], value[3]);
    }
  }
  const char* names[4] = {"Cycles' L2", "kiln raw", "kiln window", "kiln default (fit)"};
  std::printf(
      "error vs exact irradiance (RGB mean, per point and axis), %d of %zu probes "
      "deringed:\n",
      out.deringed, ref.size());
  for (int k = 0; k < 4; ++k) {
    out.median[k] = chart::quantile(err[k], 0.5);
    out.p90[k] = chart::quantile(err[k], 0.9);
    std::printf("  %-19s median %.2f%%  p90 %.2f%%\n", names[k], 100 * out.median[k],
                100 * out.p90[k]);
  }
}

// Bakes the reference points, prints the per-point table and stores the worst errors.
void compareCornellBox(uint32_t rays, int bounces, Comparison* result) {
  Comparison& out = *result;
  const std::string scenePath = test::sharedDir() + "/scenes/cornell_box/cornell_box.gltf";
  const std::string refPath = test::sharedDir() + "/reference/cornell_box/probes.json";
  if (!std::filesystem::exists(scenePath) || !std::filesystem::exists(refPath)) {
    GTEST_SKIP() << "../shared (Cornell box scene and Cycles probe reference) not available";
  }
  Result<Scene> scene = loadScene(scenePath);
  EXPECT_TRUE(scene.ok()) << scene.error();
  if (!scene.ok()) return;
  auto tracer = Tracer::create(*scene);
  EXPECT_TRUE(tracer.ok()) << tracer.error();
  if (!tracer.ok()) return;
  Result<std::vector<ProbeReferencePoint>> loaded = chart::loadProbeReference(refPath);
  ASSERT_TRUE(loaded.ok()) << loaded.error();
  const std::vector<ProbeReferencePoint>& ref = *loaded;
  EXPECT_EQ(ref.size(), 20u);
  std::vector<vec3> positions;
  for (const ProbeReferencePoint& r : ref) positions.push_back(r.position);

  ProbeBakeSettings settings;
  settings.rays = rays;
  settings.bounces = bounces;
  settings.dering = false;  // the reference's from-SH values are not windowed either
  // The estimator against Cycles' SH at the same points: a point bake (footprint 0). The
  // deringing measure below is of the default bake (its footprint included).
  settings.footprint = 0.0f;
  ProbeBakeReport report;
  Result<ProbeSet> set =
      bakeProbes(*scene, **tracer, positions, settings, nullptr, nullptr, &report);
  EXPECT_TRUE(set.ok()) << set.error();
  if (!set.ok()) return;
  EXPECT_TRUE(report.invalidProbes.empty());

  std::printf(
      "Cornell box probes vs Cycles: %u rays/probe, %d bounces. Luminance of E (not "
      "E/pi) per axis; err = |kiln - ref| / ref mean over the 6 axes (own = / ref axis)\n",
      rays, bounces);
  std::printf("%5s %5s %9s %9s %9s %8s %8s %8s\n", "point", "axis", "kiln", "cyclesSH", "cycles",
              "errSH", "errExact", "ownSH");
  for (size_t p = 0; p < ref.size(); ++p) {
    const ProbeReferencePoint& r = ref[p];
    glm::dvec3 meanSh(0.0), meanExact(0.0);
    for (int a = 0; a < 6; ++a) meanSh += r.fromSh[a] / 6.0, meanExact += r.exact[a] / 6.0;
    double worstSh = 0, worstExact = 0, truncation = 0;
    for (int a = 0; a < 6; ++a) {
      const glm::dvec3 k(set->sh[p].irradiance(kAxes[a]));
      const double errSh = std::abs(lum(k) - lum(r.fromSh[a])) / lum(meanSh);
      const double errExact = std::abs(lum(k) - lum(r.exact[a])) / lum(meanExact);
      const double own = std::abs(lum(k) - lum(r.fromSh[a])) / std::abs(lum(r.fromSh[a]));
      for (int c = 0; c < 3; ++c) {
        out.maxChannelErrFromSh =
            std::max(out.maxChannelErrFromSh, std::abs(k[c] - r.fromSh[a][c]) / meanSh[c]);
      }
      truncation =
          std::max(truncation, std::abs(lum(r.fromSh[a]) - lum(r.exact[a])) / lum(meanExact));
      worstSh = std::max(worstSh, errSh);
      worstExact = std::max(worstExact, errExact);
      std::printf("%5zu %5s %9.4f %9.4f %9.4f %7.2f%% %7.2f%% %7.1f%%\n", p, kAxisNames[a], lum(k),
                  lum(r.fromSh[a]), lum(r.exact[a]), 100 * errSh, 100 * errExact, 100 * own);
    }
    std::printf(
        "point %zu worst: %.2f%% vs from-SH, %.2f%% vs exact (Cycles' own L2 vs exact: "
        "%.2f%%)\n",
        p, 100 * worstSh, 100 * worstExact, 100 * truncation);
    out.maxErrFromSh = std::max(out.maxErrFromSh, worstSh);
    out.maxErrExact = std::max(out.maxErrExact, worstExact);
  }
  std::printf("point bake (footprint 0):\n");
  Comparison point;
  compareDeringing(ref, *set, point);
  ProbeBakeSettings withFootprint = settings;
  withFootprint.footprint = ProbeBakeSettings{}.footprint;
  withFootprint.footprintMaxRadius = ProbeBakeSettings{}.footprintMaxRadius;
  withFootprint.footprintEverywhere = ProbeBakeSettings{}.footprintEverywhere;
  std::printf("the default bake (footprint %.2f in thin light sheets, radius at most %.3f m):\n",
              withFootprint.footprint, withFootprint.footprintMaxRadius);
  Result<ProbeSet> footprintSet = bakeProbes(*scene, **tracer, positions, withFootprint);
  EXPECT_TRUE(footprintSet.ok()) << footprintSet.error();
  if (!footprintSet.ok()) return;
  compareDeringing(ref, *footprintSet, out);
  std::printf("worst over all points: %.2f%% vs from-SH (per channel %.2f%%), %.2f%% vs exact\n",
              100 * out.maxErrFromSh, 100 * out.maxChannelErrFromSh, 100 * out.maxErrExact);
}

// Overrides for exploring convergence: KILN_PROBE_REF_RAYS, KILN_PROBE_REF_BOUNCES.
uint32_t envValue(const char* name, uint32_t fallback) {
  const char* v = std::getenv(name);
  return v ? uint32_t(std::strtoul(v, nullptr, 10)) : fallback;
}

TEST(ProbeReference, CornellBox) {
  Comparison c;
  compareCornellBox(envValue("KILN_PROBE_REF_RAYS", 262144),
                    int(envValue("KILN_PROBE_REF_BOUNCES", 16)), &c);
  if (testing::Test::IsSkipped()) return;
  EXPECT_LT(c.maxErrFromSh, 0.03);
  EXPECT_LT(c.maxChannelErrFromSh, 0.03);
  // Issue 13: the default (deringed) bake within 1.1x of the representation's floor at the
  // median and no worse at p90. Measured at 262144 rays: median 4.91% against Cycles' 4.82%
  // (window: 6.16%), p90 22.0% against 25.0% (window: 25.6%) with point bakes. The default
  // bake is the same here: the box has no thin sheet of light, so no probe is baked over a
  // footprint. (Over a footprint at every probe, radii of at most 9.5 / 14 / 19 mm gave
  // 4.71% / 5.15% / 5.27-5.29%, 2-9 cm 5.85%, beyond the bound: the box is 0.55 m wide and
  // its light changes within centimetres of the lamp.) The estimator bounds above are of the
  // point bake.
  EXPECT_GT(c.deringed, 0);  // the measure must include deringed probes to mean anything
  EXPECT_LE(c.median[3], 1.1 * c.median[0]);
  EXPECT_LE(c.p90[3], c.p90[0]);
}

// The reader (tools/chart/probe_reference.h) on a minimal valid file and on broken ones: the
// message names the file and the field.
TEST(ProbeReference, ReaderNamesTheFaultyField) {
  const std::string dir = test::makeTempDir("kiln_probe_reference");
  auto write = [&](const std::string& name, const nlohmann::json& doc) {
    test::writeTextFile(dir + "/" + name, doc.dump());
    return dir + "/" + name;
  };
  nlohmann::json axes;
  for (const char* a : kAxisNames) axes[a] = {1.0, 2.0, 3.0};
  nlohmann::json probe = {{"position", {0.5, 1.0, -0.5}},
                          {"irradiance_axis", axes},
                          {"irradiance_axis_from_sh", axes},
                          {"sh_radiance", nlohmann::json::array()}};
  for (int i = 0; i < kShL2Count; ++i) probe["sh_radiance"].push_back({0.1 * i, 0.0, 1.0});
  const nlohmann::json header = {
      {"order", {"Y00", "Y1-1", "Y10", "Y11", "Y2-2", "Y2-1", "Y20", "Y21", "Y22"}}};
  const nlohmann::json good = {{"header", header}, {"probes", {probe}}};

  auto ok = chart::loadProbeReference(write("good.json", good));
  ASSERT_TRUE(ok.ok()) << ok.error();
  ASSERT_EQ(ok->size(), 1u);
  EXPECT_EQ((*ok)[0].position, vec3(0.5f, 1.0f, -0.5f));
  EXPECT_EQ((*ok)[0].exact[5], glm::dvec3(1.0, 2.0, 3.0));
  EXPECT_EQ((*ok)[0].sh.c[8], vec3(0.8f, 0.0f, 1.0f));

  auto expectError = [&](const std::string& name, const nlohmann::json& doc,
                         const std::string& field) {
    auto r = chart::loadProbeReference(write(name, doc));
    ASSERT_FALSE(r.ok()) << name;
    EXPECT_NE(r.error().find(name), std::string::npos) << r.error();
    EXPECT_NE(r.error().find(field), std::string::npos) << r.error();
  };
  nlohmann::json bad = good;
  bad["header"]["order"][1] = "Y11";
  expectError("order.json", bad, "header.order");
  bad = good;
  bad["probes"][0]["irradiance_axis"].erase("-z");
  expectError("axis.json", bad, "probes[0].irradiance_axis.-z");
  bad = good;
  bad["probes"][0]["sh_radiance"].erase(8);
  expectError("sh.json", bad, "probes[0].sh_radiance");
  bad = good;
  bad["probes"][0]["position"] = {1.0, "two", 3.0};
  expectError("position.json", bad, "probes[0].position");
  expectError("array.json", nlohmann::json::array({1, 2}), "header.order");
  test::writeTextFile(dir + "/broken.json", "{\"header\": ");
  auto broken = chart::loadProbeReference(dir + "/broken.json");
  ASSERT_FALSE(broken.ok());
  EXPECT_NE(broken.error().find("broken.json"), std::string::npos) << broken.error();
  std::filesystem::remove_all(dir);
}

}  // namespace
}  // namespace kiln
