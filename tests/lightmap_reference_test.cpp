// lightmap_reference_test.cpp: kiln's Cornell box lightmaps against Blender Cycles' bakes of
// the same scene (../shared/reference/cornell_box, README there), through the comparison the
// kiln_compare_reference tool prints (tools/lightmap_compare/reference_compare.h).
//
// Built twice: lightmap_reference_slow_test (KILN_REFERENCE_SLOW, label "slow") bakes with
// --preset high; lightmap_reference_test (default run, seconds) bakes the cheap
// setting (a bounce cache at 140 texels per metre) against the bounds. Both skip
// without ../shared.
// The metric is the issue's: every reference texel whose 3 x 3 neighbourhood is covered,
// kiln averaged over the reference texel's footprint (reference_compare.h).
//
// Resolution: the reference has 128 texels per UV unit on every object. kiln's atlas gives an
// object resolution x sqrt(world area / UV area) texels per UV unit; the smallest ratio in
// this scene is the tall block's top (0.0266 m^2 over 0.21^2 UV: 0.78), so 200 texels per
// metre gives every object at least 155 texels per UV unit (the floor 530): kiln's texels are
// no larger than the reference's, so their mean over a reference texel is well defined.
// Bounces: kiln's default cap, 64, is the reference's own setting (index.json).
//
// What is left (measured at --preset high --resolution 200 without --coverage-map: overall
// 1.94% RMSE, ratio 1.0018; 0.53% and 0.9998 without the texels next to hidden ones): the
// floor (11.5%) and the ceiling (6.8%) at the edges of the blocks' footprints and of the lamp. kiln's texels
// that a bilinear lookup at a visible point can read hold the light beside the solid (so
// that such lookups do not darken), a lit band at most one kiln texel deep inside each
// hidden region, where Cycles' footprint mean is dark; with the preset's error target, seed
// 0: 1.92%, 1.0016 without --coverage-map. Every other object is within 2.5%
// (3.8% on short_2, the darkest face, under the error target, whose Neyman allocation gives
// dark texels fewer paths).
#include <gtest/gtest.h>

#include <cmath>
#include <iostream>

#include <filesystem>
#include <nlohmann/json.hpp>

#include "src/image.h"
#include "tests/test_util.h"
#include "tools/lightmap_compare/reference_compare.h"

namespace kiln {
namespace {

#ifdef KILN_REFERENCE_SLOW
// With the footprint grid (the default) a texel straddling a hidden edge holds the mean over
// its visible part; --coverage-map gives the comparison that part's share, so both sides
// are the mean over the whole footprint with hidden points dark. Without it the comparison
// spreads the visible mean over the whole texel: 1.94% and 1.0018 (seed 0; 1.93% and
// 1.0017 with --no-footprint-grid).
constexpr const char* kBakeArgs = "--preset high --resolution 200 --coverage-map";
// The targets: RMSE <= 2% and |ratio - 1| <= 1% over all texels (measured 0.89%, 0.9998;
// 0.82%, 0.9997 with the denoiser's trend candidate, 2026-12-03;
// the bake is deterministic, so the margin is not eaten by noise). Away from hidden
// texels kiln is within the reference's own noise: 0.58% against a bound of 1%.
constexpr double kRmseBound = 0.02;
constexpr double kRatioBound = 0.01;
constexpr double kVisibleRmseBound = 0.01;
constexpr double kVisibleRatioBound = 0.01;
#else
// The cost target: a final gather over a bounce cache (8 full paths per texel, then
// 256 paths per texel that end at their first hit), the footprint grid at hidden edges, no
// denoiser, 140 texels per metre: 19 M rays, 4.1 CPU s on the 2-core build machine, a
// tenth of the 49 CPU s Cycles needs for 1%. Measured 0.91% and 0.9999 over all texels,
// 0.69% and 0.9999 away from hidden ones (seed 0; 0.90% and 1.0000 with the first grid). The
// bounds are the (1% RMSE, 0.3% bias) over all texels; Embree's kernels differ
// between machines, and a re-seeded bake moved the RMSE by less than 0.05%.
constexpr const char* kBakeArgs =
    "--samples 256 --bounce-cache 8 --resolution 140 --no-denoise --coverage-map";
constexpr double kRmseBound = 0.01;
constexpr double kRatioBound = 0.003;
constexpr double kVisibleRmseBound = 0.01;
constexpr double kVisibleRatioBound = 0.003;
#endif

// The comparison itself, without a bake: a "bake" whose page i is object i's reference image
// with scaleOffset (1, 1, 0, 0) (atlas UV = UV1, texel centres on the reference's) must give
// RMSE 0 and ratio 1; the same pages flipped upside down must not.
TEST(LightmapReference, ComparisonOfTheReferenceWithItself) {
  if (!test::sharedAvailable())
    GTEST_SKIP() << "../shared is absent: no Cycles reference to compare with";
  const std::string reference = test::sharedDir() + "/reference/cornell_box";
  const nlohmann::json index =
      nlohmann::json::parse(test::readTextFile(reference + "/index.json"));
  for (bool flip : {false, true}) {
    const std::string out = test::makeTempDir("lightmap_reference_self");
    nlohmann::json manifest = {{"version", 1}, {"lightmaps", nlohmann::json::array()},
                               {"objects", nlohmann::json::array()}};
    int page = 0;
    for (const auto& o : index["objects"]) {
      Result<Image> img = readHdrImage(reference + "/" + o["file"].get<std::string>());
      ASSERT_TRUE(img.ok()) << img.error();
      Image pageImage = *img;
      if (flip)
        for (int y = 0; y < img->height; ++y)
          for (int x = 0; x < img->width; ++x)
            for (int c = 0; c < img->channels; ++c)
              pageImage.at(x, y)[c] = img->at(x, img->height - 1 - y)[c];
      const std::string file = "lightmap-" + std::to_string(page) + "_light.exr";
      ASSERT_TRUE(writeExr(out + "/" + file, pageImage, /*fullFloat=*/true).ok());
      manifest["lightmaps"].push_back({{"index", page},
                                       {"width", img->width},
                                       {"height", img->height},
                                       {"files", {{"light", file}}}});
      manifest["objects"].push_back({{"node", o["node"]},
                                     {"nodeIndex", o["nodeIndex"]},
                                     {"lightmapIndex", page},
                                     {"scaleOffset", {1.0, 1.0, 0.0, 0.0}}});
      ++page;
    }
    test::writeTextFile(out + "/manifest.json", manifest.dump());
    Result<ReferenceComparison> c = compareWithReference(reference, out);
    ASSERT_TRUE(c.ok()) << c.error();
    if (!flip) {
      EXPECT_EQ(c->overall.relativeRmse(), 0.0);
      EXPECT_NEAR(c->overall.meanRatio(), 1.0, 1e-12);
    } else {
      EXPECT_GT(c->overall.relativeRmse(), 0.1);  // orientation matters
    }
  }
}

TEST(LightmapReference, CornellBoxAgainstCycles) {
  if (!test::sharedAvailable())
    GTEST_SKIP() << "../shared is absent: no Cycles reference to compare with";
  const std::string scene = test::sharedDir() + "/scenes/cornell_box/cornell_box.gltf";
  const std::string reference = test::sharedDir() + "/reference/cornell_box";
  const std::string out = test::makeTempDir("lightmap_reference");
  std::string log;
  const std::string command = std::string(test::kilnExe()) + " bake " + scene + " --out " + out +
                              " " + kBakeArgs + " -q";
  ASSERT_EQ(test::runCommand(command, &log), 0) << command << "\n" << log;
  Result<ReferenceComparison> c = compareWithReference(reference, out);
  ASSERT_TRUE(c.ok()) << c.error();
  std::cout << "kiln bake ... " << kBakeArgs << " vs Cycles:\n" << formatReferenceTable(*c);
  EXPECT_EQ(c->objects.size(), 16u);
  EXPECT_GT(c->overall.texels, 16u * 400u);  // ~24 x 24 interior texels per object
  // The metric: every compared texel, hidden regions included (kiln bakes texels
  // beyond bilinear reach of visible points dark, as Cycles does).
  EXPECT_LE(c->overall.relativeRmse(), kRmseBound);
  EXPECT_LE(std::abs(c->overall.meanRatio() - 1.0), kRatioBound);
  // Away from hidden texels (228 of 9216 next to one), where light is smooth on the scale of
  // a texel, kiln and Cycles agree within their noise.
  EXPECT_GT(c->overallVisible.texels, c->overall.texels * 95 / 100);
  EXPECT_LE(c->overallVisible.relativeRmse(), kVisibleRmseBound);
  EXPECT_LE(std::abs(c->overallVisible.meanRatio() - 1.0), kVisibleRatioBound);
}

}  // namespace
}  // namespace kiln
