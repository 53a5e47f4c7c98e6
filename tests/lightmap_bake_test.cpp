// lightmap_bake_test.cpp: the lightmap bake pipeline (lightmap/lightmap_baker.h): analytic
// texel values (cosine law, constant sky, inverse square, ambient occlusion under a plane),
// 1/sqrt(samples) convergence, no sun leaking through the two-room scene's shared wall,
// invalid texels inside geometry (dark beyond bilinear reach), determinism across
// thread counts, cancellation, presets and setting errors.
#include <gtest/gtest.h>

#include <array>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <string>
#include <thread>

#include "lightmap/lightmap_baker.h"
#include "lightmap/seams.h"
#include "src/gltf_loader.h"
#include "tests/test_util.h"
#include "tools/lightmap_compare/reference_compare.h"

namespace kiln {
namespace {

// The index of the scene's object called `name`, or -1.
int objectNamed(const Scene& scene, const std::string& name) {
  for (size_t o = 0; o < scene.objects.size(); ++o)
    if (scene.objects[o].name == name) return int(o);
  return -1;
}

// A 2 m x 2 m quad in the plane y = 0 facing +y (uv1 = its unit square).
Scene quadScene() {
  Scene scene;
  const uint32_t m = test::addMaterial(scene, test::lambert(vec3(0.5f)));
  test::addQuad(scene, "quad", vec3(0, 0, 0), vec3(2, 0, 0), vec3(2, 0, -2), vec3(0, 0, -2), m);
  return scene;
}

LightmapBakeSettings smallSettings() {
  LightmapBakeSettings s;
  s.resolution = 8.0f;
  s.maxSize = 64;
  s.samplesPerTexel = 16;
  return s;
}

vec3 texel(const Image& image, size_t i) {
  return vec3(image.pixels[3 * i], image.pixels[3 * i + 1], image.pixels[3 * i + 2]);
}

// Runs `f(page, texel index)` over every valid texel of every page.
template <typename F>
void forValidTexels(const LightmapBakeResult& r, F f) {
  for (const LightmapPageResult& page : r.pages)
    for (size_t i = 0; i < page.valid.size(); ++i)
      if (page.valid[i]) f(page, i);
}

TEST(LightmapBake, DirectionalLightCosineLaw) {
  Scene scene = quadScene();
  const float theta = glm::radians(35.0f), lux = 7.0f;
  scene.lights.push_back(
      test::directionalLight(vec3(std::sin(theta), -std::cos(theta), 0.0f), lux));
  LightmapBakeSettings s = smallSettings();
  s.bounces = 0;
  auto r = bakeLightmaps(scene, s);
  ASSERT_TRUE(r.ok()) << r.error();
  const float expected = lux * std::cos(theta) * kInvPi;
  size_t count = 0;
  forValidTexels(*r, [&](const LightmapPageResult& page, size_t i) {
    const vec3 v = texel(page.light, i);
    for (int c = 0; c < 3; ++c) EXPECT_NEAR(v[c], expected, 1e-5f * expected);
    ++count;
  });
  EXPECT_EQ(count, 16u * 16u);  // 2 m at 8 texels/m, all fully covered
  EXPECT_EQ(r->stats.texels, 256u);
  EXPECT_EQ(r->stats.invalidTexels, 0u);
}

TEST(LightmapBake, ConstantSkyGivesItsRadiance) {
  Scene scene = quadScene();
  const vec3 sky(0.3f, 0.6f, 1.2f);
  scene.sky = Sky::constant(sky);
  LightmapBakeSettings s = smallSettings();
  s.bounces = 0;
  s.samplesPerTexel = 64;
  // E = pi L over the open hemisphere, so E / pi = L; MIS of sky and cosine sampling of a
  // constant sky is nearly noise-free at 64 paths: measured, the raw texels' relative RMS
  // deviation is 0.71% (largest 2.3%), the denoised ones' 0.18% (largest 0.52%). Bounds at
  // about twice those (other CPUs trace other hits), and the denoiser must cut the RMS by 3x
  // or more on this flat, uniformly lit quad (measured 4.0x). The denoiser keeps the share
  // of the filter's change that maximises the lower bound of SURE's gain (postprocess.h),
  // here most but not all of it. Before that rule it kept the whole change (0.08%, largest
  // 0.31%), the rule that raised single Cornell bakes' error by up to 1.15%
  // (DenoisingNeverRaisesTheErrorOfOneBake).
  double rawRms = 0.0;
  for (bool denoise : {false, true}) {
    s.denoise = denoise;
    auto r = bakeLightmaps(scene, s);
    ASSERT_TRUE(r.ok()) << r.error();
    double ss = 0.0, worst = 0.0;
    size_t n = 0;
    forValidTexels(*r, [&](const LightmapPageResult& page, size_t i) {
      const vec3 v = texel(page.light, i);
      for (int c = 0; c < 3; ++c) {
        const double d = std::abs(double(v[c]) / sky[c] - 1.0);
        ss += d * d;
        worst = std::max(worst, d);
        ++n;
      }
    });
    const double rms = std::sqrt(ss / double(n));
    std::printf("denoise %d: relative RMS deviation %.5f, largest %.5f\n", int(denoise), rms,
                worst);
    EXPECT_EQ(n, 3u * 16u * 16u);
    if (!denoise) {
      rawRms = rms;
      EXPECT_LT(rms, 0.015);
      EXPECT_LT(worst, 0.04);
    } else {
      EXPECT_LT(rms, rawRms / 3.0);
      EXPECT_LT(worst, 0.01);
    }
  }
}

TEST(LightmapBake, PointLightInverseSquareAtSamplePoints) {
  Scene scene = quadScene();
  const vec3 light(0.7f, 1.0f, -1.2f);
  const float candela = 5.0f;
  scene.lights.push_back(test::pointLight(light, candela));
  LightmapBakeSettings s = smallSettings();
  s.bounces = 0;
  s.denoise = false;  // the gradient must come through untouched
  s.stitchSeams = false;
  auto r = bakeLightmaps(scene, s);
  ASSERT_TRUE(r.ok()) << r.error();
  double maxRel = 0.0;
  forValidTexels(*r, [&](const LightmapPageResult& page, size_t i) {
    const vec3 p(page.position.pixels[3 * i], page.position.pixels[3 * i + 1],
                 page.position.pixels[3 * i + 2]);
    const vec3 d = light - p;
    const float r2 = glm::dot(d, d);
    const float expected = candela * (d.y / std::sqrt(r2)) / r2 * kInvPi;
    const float v = texel(page.light, i).x;
    maxRel = std::max(maxRel, double(std::abs(v - expected) / expected));
  });
  std::printf("point light: max relative error %.2e\n", maxRel);
  EXPECT_LT(maxRel, 1e-5);
}

TEST(LightmapBake, AmbientOcclusionUnderAPlane) {
  // A ceiling at height h over the quad, extending past it by more than the AO distance D:
  // for it an infinite plane. A cosine-weighted ray hits it within D when cos > h / D, which
  // has probability 1 - (h / D)^2.
  Scene scene = quadScene();
  const uint32_t m = test::addMaterial(scene, test::lambert(vec3(0.5f)));
  const float h = 0.5f, D = 1.0f;
  const uint32_t ceiling = test::addQuad(scene, "ceiling", vec3(-2, h, 2), vec3(-2, h, -4),
                                         vec3(4, h, -4), vec3(4, h, 2), m);
  scene.objects[ceiling].settings.scaleInLightmap = 0.0f;
  LightmapBakeSettings s = smallSettings();
  s.bounces = 0;
  s.samplesPerTexel = 256;
  s.denoise = false;
  s.ambientOcclusion = true;
  s.aoMaxDistance = D;
  s.aoAmount = 0.8f;
  auto r = bakeLightmaps(scene, s);
  ASSERT_TRUE(r.ok()) << r.error();
  // The AO page holds the open fraction itself; aoAmount only scales the light map
  // (lightmap_texels_test).
  const float expected = (h / D) * (h / D);
  double sum = 0.0;
  size_t n = 0;
  forValidTexels(*r, [&](const LightmapPageResult& page, size_t i) {
    EXPECT_NEAR(page.ambientOcclusion.pixels[i], expected, 0.03f);
    sum += page.ambientOcclusion.pixels[i];
    ++n;
  });
  ASSERT_GT(n, 0u);
  EXPECT_NEAR(sum / double(n), expected, 2e-3);
}

// RMS difference over texels valid in both (first three channels).
double rmsDifference(const LightmapBakeResult& a, const LightmapBakeResult& b) {
  double sum = 0.0;
  size_t n = 0;
  for (size_t p = 0; p < a.pages.size(); ++p)
    for (size_t i = 0; i < a.pages[p].valid.size(); ++i) {
      if (!a.pages[p].valid[i] || !b.pages[p].valid[i]) continue;
      const vec3 d = texel(a.pages[p].light, i) - texel(b.pages[p].light, i);
      sum += glm::dot(glm::dvec3(d), glm::dvec3(d)) / 3.0;
      ++n;
    }
  return n ? std::sqrt(sum / double(n)) : 0.0;
}

Scene loadShipped(const std::string& name) {
  auto scene = loadScene(test::scenesDir() + "/" + name);
  EXPECT_TRUE(scene.ok()) << scene.error();
  return scene.ok() ? std::move(scene).value() : Scene{};
}

TEST(LightmapBake, ErrorFallsAsOneOverSqrtSamples) {
  // The Cornell box (emissive ceiling light, 3 bounces) at a low resolution, denoiser off:
  // RMS error against a bake with 64x the largest sample count.
  const Scene scene = loadShipped("cornell_box.gltf");
  ASSERT_FALSE(scene.objects.empty());
  LightmapBakeSettings s;
  s.resolution = 14.0f;
  s.maxSize = 256;
  s.bounces = 3;
  s.denoise = false;
  s.stitchSeams = false;
  const int base = 8;
  s.samplesPerTexel = base * 16 * 64;
  auto reference = bakeLightmaps(scene, s);
  ASSERT_TRUE(reference.ok()) << reference.error();
  std::printf("convergence: %zu texels, reference %d samples/texel\n", reference->stats.texels,
              s.samplesPerTexel);
  double previous = 0.0;
  for (int n = base; n <= base * 16; n *= 4) {
    s.samplesPerTexel = n;
    auto r = bakeLightmaps(scene, s);
    ASSERT_TRUE(r.ok()) << r.error();
    const double e = rmsDifference(*r, *reference);
    std::printf("  %5d samples: RMS error %.5f", n, e);
    if (previous > 0.0)
      std::printf("  ratio to %d samples %.3f (1/sqrt(4) = 0.5)", n / 4, e / previous);
    std::printf("\n");
    ASSERT_GT(e, 0.0);
    if (previous > 0.0) {
      EXPECT_LE(e / previous, 0.6);
    }
    previous = e;
  }
}

// Relative RMSE over RGB, sqrt(sum |k - r|^2 / sum |r|^2), of `bake` against `reference`
// over the texels of the reference's visible footprint (coverage > 0): kiln_compare_bakes'
// measure of a bake against a --coverage-map reference, through the same function.
double visibleRelativeRmse(const LightmapBakeResult& bake, const LightmapBakeResult& reference) {
  ReferenceErrorSums sums;
  for (size_t p = 0; p < reference.pages.size(); ++p)
    addBakeDifference(bake.pages[p].light, reference.pages[p].light,
                      &reference.pages[p].coverage, sums);
  return sums.relativeRmse();
}

TEST(LightmapBake, DenoisingNeverRaisesTheErrorOfOneBake) {
  // The per-bake check: `kiln bake tools/scenes/cornell_box.gltf --resolution 14
  // --max-size 256 --bounces 3 --samples 64 --seed S` with and without the denoiser, each
  // against a 16384-path bake of another seed, over the 435 visible texels. The seeds are
  // the three on which the denoiser's old keep-or-raw object test raised the error most
  // (visible texels, denoised / raw: seed 51 1.0115, 29 1.0090, 25 1.0062), and the two on
  // which the share rule alone still did (1003 1.0157, 1172 1.0177: the ceiling's blurred
  // peak). With the trend candidate (lightmap/postprocess.cpp, ObjectTrend) 0.9584, 0.9406,
  // 0.9473, 0.9796, 0.9557, and 0 of 512 seeds above 1 (docs/charts.md).
  // The reference's own noise (1/256 of a 64-path bake's variance) moves a ratio by about
  // 0.1% (measured against a second reference of another seed: at most 0.0011); the bound
  // allows twice that.
  const Scene scene = loadShipped("cornell_box.gltf");
  ASSERT_FALSE(scene.objects.empty());
  LightmapBakeSettings s;
  s.resolution = 14.0f;
  s.maxSize = 256;
  s.bounces = 3;
  s.samplesPerTexel = 16384;
  s.seed = 99999;
  s.coverageMap = true;
  auto reference = bakeLightmaps(scene, s);
  ASSERT_TRUE(reference.ok()) << reference.error();
  s.samplesPerTexel = 64;
  s.coverageMap = false;
  for (uint64_t seed : {51u, 29u, 25u, 1003u, 1172u}) {
    s.seed = seed;
    s.denoise = false;
    auto raw = bakeLightmaps(scene, s);
    s.denoise = true;
    auto denoised = bakeLightmaps(scene, s);
    ASSERT_TRUE(raw.ok() && denoised.ok());
    const double r = visibleRelativeRmse(*raw, *reference);
    const double d = visibleRelativeRmse(*denoised, *reference);
    std::printf("seed %d: relative RMSE raw %.5f, denoised %.5f, ratio %.4f\n", int(seed), r, d,
                d / r);
    EXPECT_LE(d / r, 1.002) << seed;
  }
}

// A closed 1 m room whose six walls (single-sided, facing in) all emit Le = 1 and reflect
// with albedo 0.5: the radiance leaving every wall is Le / (1 - albedo) = 2 (the geometric
// series of bounces), so every texel's E / pi is 2 exactly. With the bounce cache, a path
// reads the first pass's value at its first hit: Le + albedo x cache = 1 + 0.5 x 2 = 2, the
// same limit. One wall has no lightmap (scaleInLightmap 0), so paths that hit it go on as
// without a cache. Denoiser off: the mean over the texels must reach 2 within its noise, and
// each texel within its own (measured: full paths 64 spp, mean 1.9954, worst texel 19% off,
// in a corner; cache 64 + 16 spp, mean 2.0026, worst 12%).
Scene furnaceRoom() {
  Scene scene;
  const uint32_t m = test::addMaterial(scene, test::lambert(vec3(0.5f), vec3(1.0f)));
  const vec3 c[8] = {{0, 0, 0}, {1, 0, 0}, {0, 1, 0}, {1, 1, 0},
                     {0, 0, 1}, {1, 0, 1}, {0, 1, 1}, {1, 1, 1}};
  // Counter-clockwise seen from inside the room.
  test::addQuad(scene, "floor", c[0], c[4], c[5], c[1], m);
  test::addQuad(scene, "ceiling", c[2], c[3], c[7], c[6], m);
  test::addQuad(scene, "left", c[0], c[2], c[6], c[4], m);
  test::addQuad(scene, "right", c[1], c[5], c[7], c[3], m);
  test::addQuad(scene, "back", c[0], c[1], c[3], c[2], m);
  const uint32_t front = test::addQuad(scene, "front", c[4], c[6], c[7], c[5], m);
  scene.objects[front].settings.scaleInLightmap = 0.0f;
  return scene;
}

// The furnace room's bake settings: 12 texels per unit, denoiser off.
LightmapBakeSettings furnaceSettings() {
  LightmapBakeSettings s;
  s.resolution = 12.0f;
  s.maxSize = 256;
  s.denoise = false;
  return s;
}

TEST(LightmapBake, FurnaceRoomGivesLeOverOneMinusAlbedoWithAndWithoutBounceCache) {
  const Scene scene = furnaceRoom();
  LightmapBakeSettings s = furnaceSettings();
  s.samplesPerTexel = 64;
  for (int cache : {0, 16}) {
    s.bounceCacheSamples = cache;
    auto r = bakeLightmaps(scene, s);
    ASSERT_TRUE(r.ok()) << r.error();
    double sum = 0.0, worst = 0.0;
    size_t n = 0;
    forValidTexels(*r, [&](const LightmapPageResult& page, size_t i) {
      const vec3 v = texel(page.light, i);
      for (int ch = 0; ch < 3; ++ch) worst = std::max(worst, std::abs(double(v[ch]) - 2.0) / 2.0);
      sum += luminance(v);
      ++n;
    });
    ASSERT_GT(n, 600u);  // 5 walls x 12 x 12 texels
    const double mean = sum / double(n);
    std::printf("furnace, bounce cache %d: %zu texels, mean %.4f, worst texel %.2f%% off, %.2f M rays\n",
                cache, n, mean, 100.0 * worst, double(r->stats.rays) / 1e6);
    EXPECT_NEAR(mean, 2.0, 0.01);
    EXPECT_LE(worst, 0.3);
  }
}

// The error target in the furnace room above (E / pi = 2 at every texel, exactly): a pilot
// pass on its own random numbers measures each texel's spread, and the texels take paths in
// proportion to it, the fewest in total whose predicted relative RMS error over the texels
// is at most the target. With the denoiser off, the RMS over the texels of (v - 2) / 2
// must be at most 1.15 x the target (the pilot's estimate of the spread, 8 paths at each of
// 9 texels, is good to ~10%; measured at 0.03: 0.0213 with full paths, whose Sobol
// sequence beats the 1 / n the prediction assumes, 0.0286 with the bounce cache) and above a
// third of it (the cap, 4096 paths everywhere, would give a fifth). The mean over 720 texels
// has the noise of target / sqrt(720) ~ 0.1%: it must be within 0.5% of 2 (measured 1.9994
// and 2.0017; counts read from the texel's own paths, the earlier stopping rule, darkened by
// stopping where those happened to agree). The denoiser's variance (each texel's batch
// means, now over unequal counts) must stand for the squared error within a factor 2
// (measured 0.96 and 1.01). The counts follow where the light is hard to sample (the
// corners): min < max. And the result is bit-identical at 1 and 2 threads.
void expectSameLightAndPaths(const LightmapBakeResult& a, const LightmapBakeResult& b);

TEST(LightmapBake, ErrorTargetMetAndUnbiasedInTheFurnaceRoom) {
  const Scene scene = furnaceRoom();
  LightmapBakeSettings s = furnaceSettings();
  s.samplesPerTexel = 4096;
  s.minSamples = 8;
  s.errorTarget = 0.03f;
  for (int cache : {0, 16}) {
    s.bounceCacheSamples = cache;
    s.threads = 2;
    auto r = bakeLightmaps(scene, s);
    ASSERT_TRUE(r.ok()) << r.error();
    double sum = 0.0, sumSq = 0.0, variance = 0.0;
    size_t n = 0;
    forValidTexels(*r, [&](const LightmapPageResult& page, size_t i) {
      const double v = luminance(texel(page.light, i));
      sum += v;
      sumSq += (v - 2.0) * (v - 2.0) / 4.0;
      variance += page.variance[i] / 4.0;
      ++n;
    });
    ASSERT_GT(n, 600u);
    const double mean = sum / double(n), rms = std::sqrt(sumSq / double(n));
    std::printf("furnace, error target %.3f, bounce cache %d: mean %.4f, relative RMS error "
                "%.4f, denoiser's variance / squared error %.3f, paths per texel %u / %.1f / "
                "%u, %.2f M rays\n",
                s.errorTarget, cache, mean, rms, variance / sumSq, r->stats.minSamples,
                r->stats.meanSamples, r->stats.maxSamples, double(r->stats.rays) / 1e6);
    // The denoiser's variance (each texel's own batch means, now over unequal counts) against
    // the squared error it stands for.
    EXPECT_GT(variance / sumSq, 0.5);
    EXPECT_LT(variance / sumSq, 2.0);
    EXPECT_LE(rms, 1.15 * s.errorTarget);
    EXPECT_GE(rms, s.errorTarget / 3.0);
    EXPECT_NEAR(mean, 2.0, 0.01);
    EXPECT_LT(r->stats.minSamples, r->stats.maxSamples);
    EXPECT_LT(r->stats.maxSamples, 4096u);
    s.threads = 1;
    auto one = bakeLightmaps(scene, s);
    ASSERT_TRUE(one.ok()) << one.error();
    expectSameLightAndPaths(*r, *one);
  }
}

// The bounce cache changes how the indirect light is estimated, hardly what it converges to:
// on the Cornell box (64 bounces, denoiser off) its mean over the texels agrees with full
// paths, while tracing far fewer rays. Its bias comes from reading the first pass's texels
// bilinearly (a texel's mean stands for the light at every point of it) and falls with the
// texel size: cached / full = 1.0076 at 14 texels per unit, 1.0035 at 28, 1.0022 at 56
// (256 + 16 against 1024 paths); against Cycles at 140 texels per unit the mean ratio is
// 1.0000 (docs/lightmap_outputs.md).
TEST(LightmapBake, BounceCacheKeepsTheMeanOfFullPaths) {
  const Scene scene = loadShipped("cornell_box.gltf");
  ASSERT_FALSE(scene.objects.empty());
  LightmapBakeSettings s;
  s.resolution = 28.0f;
  s.maxSize = 256;
  s.samplesPerTexel = 256;
  s.denoise = false;
  auto full = bakeLightmaps(scene, s);
  ASSERT_TRUE(full.ok()) << full.error();
  s.samplesPerTexel = 64;
  s.bounceCacheSamples = 8;
  auto cached = bakeLightmaps(scene, s);
  ASSERT_TRUE(cached.ok()) << cached.error();
  auto sumLuminance = [](const LightmapBakeResult& r) {
    double sum = 0.0;
    forValidTexels(r, [&](const LightmapPageResult& page, size_t i) {
      sum += luminance(texel(page.light, i));
    });
    return sum;
  };
  const double sumFull = sumLuminance(*full), sumCached = sumLuminance(*cached);
  std::printf("cornell at 28 texels/unit: mean ratio cached / full %.4f; rays %.2f M vs %.2f M\n",
              sumCached / sumFull, double(cached->stats.rays) / 1e6,
              double(full->stats.rays) / 1e6);
  EXPECT_NEAR(sumCached / sumFull, 1.0, 0.007);
  EXPECT_LT(cached->stats.rays * 6, full->stats.rays);
}

TEST(LightmapBake, TwoRoomsNoSunLeaksThroughTheSharedWall) {
  // Direct light only (bounces 0, no sky): the sun enters room A (x in [0, 4]) through its
  // window; room B (x in [4.25, 8.25]) sees no sun, so every texel there must be exactly 0,
  // in particular the floor along the shared wall (x = 4 to 4.25), whose slab runs on under
  // the wall into room A, and the wall's room-B face. That holds for the bake's light
  // exactly (denoiser off). The denoiser mixes texels by a Gaussian in their luminance
  // difference over its standard error, which is never exactly 0: a footprint-grid texel
  // where the sun's shadow edge crosses it (16 paths over 16 points: its batch means differ)
  // has a variance, and about e^-35 (1e-15) of its light reaches room B's texels two
  // texels away, page neighbours across the wall. That is no light through the wall, and
  // it is below half precision: the written page holds 0 (every value below 2^-25 rounds
  // to 0 in a half float).
  Scene scene = loadShipped("two_rooms.gltf");
  ASSERT_FALSE(scene.objects.empty());
  scene.sky = Sky();
  ASSERT_EQ(scene.lights.size(), 1u);
  const Light sun = scene.lights[0];
  for (bool denoise : {false, true}) {
    SCOPED_TRACE(denoise ? "denoised" : "not denoised");
    const float bound = denoise ? 2.9e-8f : 0.0f;
    LightmapBakeSettings s;
    s.resolution = 8.0f;
    s.maxSize = 1024;
    s.bounces = 0;
    s.samplesPerTexel = 16;
    s.denoise = denoise;
    auto r = bakeLightmaps(scene, s);
    ASSERT_TRUE(r.ok()) << r.error();
    const Scene& baked = r->scene;
    const int floorIndex = objectNamed(baked, "floor");
    const int wallIndex = objectNamed(baked, "wall_shared");
    ASSERT_GE(floorIndex, 0);
    ASSERT_GE(wallIndex, 0);
    const float sunlit = sun.intensity * sun.color.r * -sun.direction.y * kInvPi;

    size_t nearWall = 0, wallFace = 0, roomB = 0, patch = 0;
    float maxNearWall = 0.0f, maxWallFace = 0.0f, maxRoomB = 0.0f, maxA = 0.0f;
    for (size_t o : {size_t(floorIndex), size_t(wallIndex)}) {
      const AtlasObject& ao = r->layout.objects[o];
      ASSERT_GE(ao.lightmapIndex, 0);
      const LightmapPageResult& page = r->pages[size_t(ao.lightmapIndex)];
      const int w = page.light.width;
      for (int y = ao.texelMin.y; y < ao.texelMin.y + ao.texelSize.y; ++y)
        for (int x = ao.texelMin.x; x < ao.texelMin.x + ao.texelSize.x; ++x) {
          const size_t i = size_t(y) * w + x;
          if (!page.valid[i]) continue;
          const vec3 p(page.position.pixels[3 * i], page.position.pixels[3 * i + 1],
                       page.position.pixels[3 * i + 2]);
          const float v = maxComponent(texel(page.light, i));
          const bool inRoomZ = p.z > 0.05f && p.z < 3.95f;
          if (int(o) == floorIndex && std::abs(p.y) < 1e-3f && inRoomZ) {
            if (p.x > 4.25f - 1e-3f && p.x < 8.2f) {
              roomB++;
              maxRoomB = std::max(maxRoomB, v);
              if (p.x < 4.25f + 0.3f) {
                nearWall++;
                maxNearWall = std::max(maxNearWall, v);
              }
            }
            // No valid floor sample point may stay inside the wall (the doorway, z in
            // [2.8, 3.8], is open floor).
            const bool doorway = p.z > 2.8f - 1e-3f && p.z < 3.8f + 1e-3f;
            EXPECT_FALSE(!doorway && p.x > 4.0f + 1e-3f && p.x < 4.25f - 1e-3f)
                << p.x << " " << p.z;
            if (p.x > 0.05f && p.x < 3.95f) {
              maxA = std::max(maxA, v);
              if (std::abs(texel(page.light, i).r - sunlit) < 1e-3f * sunlit) patch++;
            }
          }
          if (int(o) == wallIndex && std::abs(p.x - 4.25f) < 1e-3f && inRoomZ && p.y > 0.0f) {
            wallFace++;
            maxWallFace = std::max(maxWallFace, v);
          }
        }
    }
    std::printf(
        "two rooms: sunlit E cos/pi = %.4f, max room A floor %.4f (%zu texels at it);\n"
        "  room B floor max %.3g over %zu texels, within 0.3 m of the wall %.3g over %zu,"
        " shared wall's B face %.3g over %zu\n",
        sunlit, maxA, patch, maxRoomB, roomB, maxNearWall, nearWall, maxWallFace, wallFace);
    EXPECT_GT(nearWall, 50u);
    EXPECT_GT(wallFace, 100u);
    EXPECT_LE(maxRoomB, bound);
    EXPECT_LE(maxNearWall, bound);
    EXPECT_LE(maxWallFace, bound);
    EXPECT_NEAR(maxA, sunlit, 1e-3f * sunlit);
    EXPECT_GT(patch, 20u);
  }
}



TEST(LightmapBake, FloorTexelsUnderOverlappingWallsTakeNoLightFromOutside) {
  // two_rooms and two_rooms_thin at 10 texels per metre: the outer walls are 0.25 m thick
  // (2.5 texels) and overlap one another and the shared wall at their ends, and the floor
  // slab runs on under them to a sunlit overhang outside. A floor texel whose main sample
  // lies inside a wall, away from its faces (push-out moved it to neither), sees no light;
  // it holds 0, or, filled because a neighbour has a point on the visible room floor, a
  // mean of valid neighbours no brighter than the room floor beside that wall. The sunlit
  // outside (E / pi about 3) must never reach it: near a wall that meets this one, another
  // wall's front face stands inside it, some of a footprint grid's points there see it and
  // count as valid (dark), and that made the texel a fill seed although its own point is
  // inside, so its neighbour under the wall took the mean of the outside and the room
  // (1.1-1.4 against at most 0.2 beside the wall in the room).
  for (const char* name : {"two_rooms.gltf", "two_rooms_thin.gltf"}) {
    SCOPED_TRACE(name);
    const Scene scene = loadShipped(name);
    ASSERT_FALSE(scene.objects.empty());
    LightmapBakeSettings s;
    s.resolution = 10.0f;
    s.samplesPerTexel = 16;
    s.denoise = false;
    auto r = bakeLightmaps(scene, s);
    ASSERT_TRUE(r.ok()) << r.error();
    const int floorIndex = objectNamed(r->scene, "floor");
    ASSERT_GE(floorIndex, 0);
    const float shared = std::string(name) == "two_rooms.gltf" ? 0.25f : 0.05f;
    const float xEnd = 8.0f + shared, t = 0.25f, e = 1e-3f;
    const AtlasObject& ao = r->layout.objects[size_t(floorIndex)];
    ASSERT_GE(ao.lightmapIndex, 0);
    const LightmapPageResult& page = r->pages[size_t(ao.lightmapIndex)];
    const int w = page.light.width;
    // Per outer wall (south, north, west, east): texels inside it (main sample more than
    // e from both faces; not within half a texel of the rooms' corners, where the floor's
    // visible notch outside the wall ends may be a legitimate seed), and the room floor
    // within 0.3 m of its inner face.
    std::array<float, 4> under{}, strip{};
    std::array<size_t, 4> underCount{}, stripCount{};
    for (int y = ao.texelMin.y; y < ao.texelMin.y + ao.texelSize.y; ++y)
      for (int x = ao.texelMin.x; x < ao.texelMin.x + ao.texelSize.x; ++x) {
        const size_t i = size_t(y) * w + x;
        if (page.samples[i] == 0) continue;  // padding
        const vec3 p(page.position.pixels[3 * i], page.position.pixels[3 * i + 1],
                     page.position.pixels[3 * i + 2]);
        if (std::abs(p.y) > e) continue;  // the slab's top only
        const float v = maxComponent(texel(page.light, i));
        const bool alongX = p.x > 0.05f && p.x < xEnd - 0.05f;
        const bool alongZ = p.z > 0.05f && p.z < 4.0f - 0.05f;
        const std::array<bool, 4> inWall = {alongX && p.z > -t + e && p.z < -e,
                                            alongX && p.z > 4.0f + e && p.z < 4.0f + t - e,
                                            alongZ && p.x > -t + e && p.x < -e,
                                            alongZ && p.x > xEnd + e && p.x < xEnd + t - e};
        const bool inRoom = p.z >= 0.0f && p.z <= 4.0f &&
                            ((p.x >= 0.0f && p.x <= 4.0f) || (p.x >= 4.0f + shared && p.x <= xEnd));
        const std::array<bool, 4> inStrip = {inRoom && p.z < 0.3f, inRoom && p.z > 3.7f,
                                             inRoom && p.x < 0.3f, inRoom && p.x > xEnd - 0.3f};
        for (size_t k = 0; k < 4; ++k) {
          if (inWall[k]) {
            ++underCount[k];
            under[k] = std::max(under[k], v);
          }
          if (inStrip[k]) {
            ++stripCount[k];
            strip[k] = std::max(strip[k], v);
          }
        }
      }
    const char* sides[4] = {"south", "north", "west", "east"};
    for (size_t k = 0; k < 4; ++k) {
      std::printf("%s %s wall: %zu floor texels inside it, max %.4f; room floor within 0.3 m: "
                  "max %.4f over %zu\n",
                  name, sides[k], underCount[k], under[k], strip[k], stripCount[k]);
      EXPECT_GT(stripCount[k], 100u) << sides[k];
      EXPECT_LE(under[k], strip[k]) << sides[k];
    }
    // Where texel centres fall inside a wall depends on the grid's alignment: measured 80-82
    // under the south wall, 39 under the west one, 0-2 under the north and east ones.
    EXPECT_GT(underCount[0] + underCount[2], 100u);
  }
}

TEST(LightmapBake, ThinWallTexelsTakeTheSideOfTheirMainSample) {
  // two_rooms_thin: the shared wall is 5 cm thick (x in [4, 4.05]), 0.4 of a texel at 8
  // texels per metre, and the floor slab runs on under it, so the floor texels along it
  // straddle both rooms and get a footprint grid. A point light 0.25 m from the wall lights
  // room A's floor beside it; direct light only, no sky, no sun: room B's floor (x > 4.05)
  // sees nothing from it away from the doorway (z in [2.8, 3.8], and a ray from the light at
  // z = 1.2 through it only goes on to z > 2.8). A room-B texel's grid points on room A's
  // side are hidden from its main sample by the wall, so every one of them is exactly 0
  // (mixing in the lit side's grid points gave them room A's light); the room-A texels along
  // the wall hold room A's light, not a mix with the dark wall or room B.
  Scene scene = loadShipped("two_rooms_thin.gltf");
  ASSERT_FALSE(scene.objects.empty());
  scene.sky = Sky();
  const vec3 lamp(3.75f, 0.6f, 1.2f);
  const float candela = 2.0f;
  scene.lights = {test::pointLight(lamp, candela)};
  LightmapBakeSettings s;
  ASSERT_TRUE(s.footprintGrid);  // the default
  s.resolution = 8.0f;
  s.bounces = 0;
  s.samplesPerTexel = 16;
  auto r = bakeLightmaps(scene, s);
  ASSERT_TRUE(r.ok()) << r.error();
  const int floorIndex = objectNamed(r->scene, "floor");
  ASSERT_GE(floorIndex, 0);
  const AtlasObject& ao = r->layout.objects[size_t(floorIndex)];
  ASSERT_GE(ao.lightmapIndex, 0);
  const LightmapPageResult& page = r->pages[size_t(ao.lightmapIndex)];
  const int w = page.light.width;
  size_t roomB = 0, roomA = 0;
  float maxB = 0.0f, minRatioA = 1e9f;
  for (int y = ao.texelMin.y; y < ao.texelMin.y + ao.texelSize.y; ++y)
    for (int x = ao.texelMin.x; x < ao.texelMin.x + ao.texelSize.x; ++x) {
      const size_t i = size_t(y) * w + x;
      if (!page.valid[i]) continue;
      const vec3 p(page.position.pixels[3 * i], page.position.pixels[3 * i + 1],
                   page.position.pixels[3 * i + 2]);
      if (std::abs(p.y) > 1e-3f || p.z < 0.05f || p.z > 2.7f) continue;
      const float v = maxComponent(texel(page.light, i));
      if (p.x > 4.05f - 1e-3f && p.x < 4.05f + 0.3f) {
        ++roomB;
        maxB = std::max(maxB, v);
      }
      if (p.x > 4.0f - 0.125f && p.x < 4.0f + 1e-3f) {
        // Within a texel of the wall on room A's side: E / pi = I h / (pi r^3) at the main
        // sample; the texel holds the mean over its visible part (up to a texel from it,
        // where E differs by less than 40%): a dark halo would be near 0 or half of it.
        ++roomA;
        const vec3 d = lamp - p;
        const float r2 = glm::dot(d, d);
        const float e = candela * d.y / (r2 * std::sqrt(r2)) * kInvPi;
        minRatioA = std::min(minRatioA, texel(page.light, i).r / e);
      }
    }
  std::printf("thin wall: room B floor within 0.3 m of the wall max %.3g over %zu texels; "
              "room A texels along it: min value / E(main sample) %.3f over %zu\n",
              maxB, roomB, minRatioA, roomA);
  EXPECT_GT(roomB, 40u);
  EXPECT_EQ(maxB, 0.0f);
  EXPECT_GT(roomA, 15u);
  EXPECT_GT(minRatioA, 0.6f);
}

// The quad (x in [0, 2], 8 texels per metre) running into a solid block whose face is at
// x = faceX (the block encloses the quad beyond it; it gets no lightmap), under a constant
// sky, no bounces. Calls f(column k, valid, value) for every texel of the quad, k = texel
// column along x (centres at (k + 0.5) / 8 m); returns the bake's invalid-texel count.
template <typename F>
size_t bakeQuadIntoBlock(float faceX, int supersampling, F f) {
  Scene scene = quadScene();
  const uint32_t m = test::addMaterial(scene, test::lambert(vec3(0.5f)));
  const uint32_t block =
      test::addBox(scene, "block", vec3(faceX, -0.5f, -2.5f), vec3(3.0f, 0.5f, 0.5f), m, false);
  scene.objects[block].settings.scaleInLightmap = 0.0f;
  scene.sky = Sky::constant(vec3(1.0f));
  LightmapBakeSettings s = smallSettings();
  s.supersampling = supersampling;
  s.bounces = 0;
  auto r = bakeLightmaps(scene, s);
  EXPECT_TRUE(r.ok()) << r.error();
  if (!r.ok()) return 0;
  const AtlasObject& ao = r->layout.objects[0];
  const LightmapPageResult& page = r->pages[size_t(ao.lightmapIndex)];
  for (int y = ao.texelMin.y; y < ao.texelMin.y + ao.texelSize.y; ++y)
    for (int x = ao.texelMin.x; x < ao.texelMin.x + ao.texelSize.x; ++x) {
      const size_t i = size_t(y) * page.light.width + x;
      f(x - ao.texelMin.x, page.valid[i] != 0, texel(page.light, i));
    }
  return r->stats.invalidTexels;
}

TEST(LightmapBake, TexelsInsideGeometryAreInvalidAndDarkBeyondBilinearReach) {
  // The block encloses the quad's half x > 1: texels more than a texel inside see only the
  // block's back faces. k = 8 (centre 1/16 m inside) lies within the push-out reach: moved
  // out past the block's face, valid, lit. k >= 9 is invalid, and more than a texel from any
  // visible point of the quad (x <= 1), so no bilinear lookup reads it: it keeps its
  // physical irradiance, exactly 0 (the sky's shadow rays and every path end on the block),
  // as an independent renderer bakes it, instead of light filled in from its neighbours.
  // (Invalid texels next to a visible centre are filled: lightmap_post_test's LightmapFill.)
  // k = 8's whole footprint is under the block, so its footprint grid has no visible point
  // and it bakes at its main sample, pushed out to the face: E / pi = f(0) = 1/2 (half the
  // sky hidden by a long wall; f(s) in HiddenEdgeTexelHoldsTheVisibleFootprintAverage), the
  // light a bilinear lookup at the visible edge needs. The pipeline's denoiser blends it
  // with k = 7, whose footprint mean is 0.5615: the mean over the 16 rows lies between the
  // two, up to 3 standard errors of that mean (raw 16-path texels here: 0.498 +- 0.030 per
  // texel, i.e. 0.0076 over 16 rows; denoised 0.540).
  size_t inside = 0, pushed = 0;
  double footSum = 0.0;
  const size_t invalid = bakeQuadIntoBlock(1.0f, 1, [&](int k, bool valid, vec3 v) {
    if (k >= 9) {
      ++inside;
      EXPECT_FALSE(valid) << k;
      EXPECT_EQ(v, vec3(0.0f)) << "enclosed: dark, not filled (column " << k << ")";
    } else if (k == 8) {
      ++pushed;
      EXPECT_TRUE(valid);
      // At the block's foot the block hides less than half the sky (E / pi in (0.5, 1) L),
      // not the darkness a point inside it would see.
      EXPECT_GT(v.x, 0.45f);
      EXPECT_LT(v.x, 1.0f);
      footSum += v.x;
    } else {
      EXPECT_TRUE(valid) << k;
    }
  });
  EXPECT_EQ(inside, 7u * 16u);
  EXPECT_EQ(pushed, 1u * 16u);
  EXPECT_EQ(invalid, inside);
  const double footMean = footSum / 16.0;
  std::printf("block foot (k = 8, footprint wholly hidden): mean %.4f over 16 rows\n", footMean);
  EXPECT_GT(footMean, 0.5 - 3.0 * 0.0076);
  EXPECT_LT(footMean, 0.5615 + 3.0 * 0.0076);
}

TEST(LightmapBake, SupersampledTexelsPushedOutOnlyInPartDoNotSpreadTheFill) {
  // As above with 2 x 2 supersample points (at +-1/4 texel) and the block's face at
  // x = 1.05 m. Column k = 8 (centre 1.0625) straddles the face: its points at x = 1.03125 lie
  // on the visible quad. Column 9 (centre 1.1875, 1.1 texels inside) is out of the push-out's
  // one-texel reach, but its points at x = 1.15625 (0.85 texels inside) are not: they are
  // moved out, so the texel is valid and lit, and a bilinear lookup at the visible points
  // just left of the face reads it. Column 10 (centre 2.1 texels inside, its nearest points
  // 1.85) is invalid, and no visible point is within a texel of it: exactly 0. The fill's
  // seeds are the texels with a point on the visible surface; counting column 9 as one (its
  // centre was not moved, but only because push-out could not reach it) lit column 10 too,
  // a band two texels deep inside every solid standing on a supersampled surface.
  size_t dark = 0;
  bakeQuadIntoBlock(1.05f, 2, [&](int k, bool valid, vec3 v) {
    if (k >= 10) {
      ++dark;
      EXPECT_FALSE(valid) << k;
      EXPECT_EQ(v, vec3(0.0f)) << "beyond bilinear reach: dark (column " << k << ")";
    } else {
      EXPECT_TRUE(valid) << k;
      if (k >= 8) {
        EXPECT_GT(v.x, 0.45f) << k;
      }
    }
  });
  EXPECT_EQ(dark, 6u * 16u);
}

// The quad running into the block (face at x = faceX, 1.05 m unless given) under a constant
// sky L = 1, no bounces, with `settings` on top of smallSettings(). Returns the bake.
Result<LightmapBakeResult> bakeBlockFoot(LightmapBakeSettings s, int bounces = 0,
                                         float faceX = 1.05f) {
  Scene scene = quadScene();
  const uint32_t m = test::addMaterial(scene, test::lambert(vec3(0.5f)));
  const uint32_t block =
      test::addBox(scene, "block", vec3(faceX, -0.5f, -2.5f), vec3(3.0f, 0.5f, 0.5f), m, false);
  scene.objects[block].settings.scaleInLightmap = 0.0f;
  scene.sky = Sky::constant(vec3(1.0f));
  s.bounces = bounces;
  return bakeLightmaps(scene, s);
}

// Mean paths per texel of the quad's columns 0..8 (the block's face is in column 8).
std::vector<double> meanPathsByColumn(const LightmapBakeResult& r) {
  const AtlasObject& ao = r.layout.objects[0];
  const LightmapPageResult& page = r.pages[size_t(ao.lightmapIndex)];
  std::vector<double> perColumn(9, 0.0);
  for (int y = ao.texelMin.y; y < ao.texelMin.y + ao.texelSize.y; ++y)
    for (int k = 0; k <= 8; ++k) {
      const size_t i = size_t(y) * page.light.width + ao.texelMin.x + k;
      perColumn[size_t(k)] += page.samples[i] / double(ao.texelSize.y);
    }
  return perColumn;
}

// Two bakes of the same settings at different thread counts: the same light, paths and rays.
void expectSameLightAndPaths(const LightmapBakeResult& a, const LightmapBakeResult& b) {
  ASSERT_EQ(a.pages.size(), b.pages.size());
  for (size_t p = 0; p < a.pages.size(); ++p) {
    EXPECT_EQ(a.pages[p].light.pixels, b.pages[p].light.pixels);
    EXPECT_EQ(a.pages[p].samples, b.pages[p].samples);
  }
  EXPECT_EQ(a.stats.rays, b.stats.rays);
}

TEST(LightmapBake, HiddenEdgeTexelHoldsTheVisibleFootprintAverage) {
  // Column k = 8 of the quad covers x in [1, 1.125]; the block (0.5 m above the quad) hides
  // x > 1.05. A point at distance s from the block's face sees the sky except the face:
  // E / pi = (1 + s / sqrt(s^2 + H^2)) / 2 with H = 0.5 m (a long wall: the block spans
  // 3 m along z, the quad 2 m), so its mean over the visible part s in [0, 0.05] is
  // 1/2 + (sqrt(0.05^2 + H^2) - H) / (2 x 0.05) = 0.52494. The texel's 4 x 4 footprint grid
  // has two of its four columns of points (x = 1.0156, 1.0469) on the visible part: it must
  // hold their mean, 0.5187 (s = 0.0344, 0.0031), never a mix with the dark inside of the
  // block (0.26 with the hidden points counted as 0), and its coverage is 8 / 16.
  LightmapBakeSettings s = smallSettings();
  s.samplesPerTexel = 1024;
  s.coverageMap = true;
  s.footprintGrid = true;
  auto r = bakeBlockFoot(s);
  ASSERT_TRUE(r.ok()) << r.error();
  const AtlasObject& ao = r->layout.objects[0];
  const LightmapPageResult& page = r->pages[size_t(ao.lightmapIndex)];
  auto f = [](double x) { return 0.5 * (1.0 + x / std::sqrt(x * x + 0.25)); };
  const double gridMean = 0.5 * (f(1.05 - 1.015625) + f(1.05 - 1.046875));
  const double continuous = 0.5 + (std::sqrt(0.05 * 0.05 + 0.25) - 0.5) / (2.0 * 0.05);
  int rows = 0;
  // The rows away from the quad's z ends (where the block's finite length shows).
  for (int y = ao.texelMin.y + 4; y < ao.texelMin.y + ao.texelSize.y - 4; ++y) {
    const size_t i = size_t(y) * page.light.width + ao.texelMin.x + 8;
    ASSERT_TRUE(page.valid[i]);
    const float v = page.light.pixels[3 * i];
    EXPECT_NEAR(v, gridMean, 0.01 * gridMean) << "row " << y;
    EXPECT_NEAR(v, continuous, 0.02 * continuous) << "row " << y;
    // value x coverage = the mean over all 16 points (hidden ones 0): 8 / 16 up to the
    // points' own noise.
    EXPECT_NEAR(page.coverage.pixels[i], 0.5f, 0.01f) << "row " << y;
    ++rows;
  }
  EXPECT_EQ(rows, 8);
}

TEST(LightmapBake, NoDarkHaloAtABlocksFoot) {
  // What a renderer reads at a visible point beside a solid standing on the surface: a
  // bilinear lookup in the finished page (denoised, filled, dilated) at x = face - 1/4 texel
  // (3.1 cm in front of the block's face) and one texel further out, against the light
  // there, E / pi = f(s) = (1 + s / sqrt(s^2 + H^2)) / 2 (H = 0.5 m, s = distance to the face;
  // see HiddenEdgeTexelHoldsTheVisibleFootprintAverage). The lookup mixes the texel beside
  // the face with the one straddling it or lying under the block; f is nearly linear over a
  // texel, so the lookup of footprint means is within a few percent of f(s) (the texel under
  // the block holds the light at the face, f(0) = 0.5, a little above the linear
  // continuation: +2.4% to +4.1% from the texels' exact grid means at these four faces).
  // A halo, the straddling or the hidden texel counted dark, takes the lookup 30% or more
  // below f(s). Faces on a texel edge (1.0), inside texels at 1/4, 2/5 and 2/3 of a texel.
  LightmapBakeSettings s = smallSettings();
  s.samplesPerTexel = 1024;
  auto f = [](double x) { return 0.5 * (1.0 + x / std::sqrt(x * x + 0.25)); };
  for (float face : {1.0f, 1.03f, 1.05f, 1.08f}) {
    auto r = bakeBlockFoot(s, 0, face);
    ASSERT_TRUE(r.ok()) << r.error();
    const AtlasObject& ao = r->layout.objects[0];
    const LightmapPageResult& page = r->pages[size_t(ao.lightmapIndex)];
    for (double texels : {0.25, 1.25}) {
      const double dist = texels / 8.0, physical = f(dist);
      double sum = 0.0;
      int rows = 0;
      // The rows away from the quad's z ends; lookups at row centres (x interpolation only).
      for (int y = ao.texelMin.y + 4; y < ao.texelMin.y + ao.texelSize.y - 4; ++y) {
        const vec2 at(float(ao.texelMin.x + (face - dist) * 8.0), float(y) + 0.5f);
        float v[3];
        sampleBilinear(page.light, at, v);
        EXPECT_GT(v[0], 0.95 * physical) << "face " << face << " row " << y;
        EXPECT_LT(v[0], 1.09 * physical) << "face " << face << " row " << y;
        sum += v[0];
        ++rows;
      }
      const double mean = sum / rows;
      std::printf("face %.2f: lookup %.2f texel out %.4f, E/pi there %.4f (%+.1f%%)\n", face,
                  texels, mean, physical, 100.0 * (mean / physical - 1.0));
      EXPECT_GT(mean, 0.98 * physical) << "face " << face << " at " << texels << " texel";
      EXPECT_LT(mean, 1.06 * physical) << "face " << face << " at " << texels << " texel";
      EXPECT_EQ(rows, 8);
    }
  }
}

TEST(LightmapBake, ErrorTargetSpendsPathsWherePathsDisagree) {
  // Under a constant sky the paths of a texel disagree only through what hides the sky: far
  // from the block (column 0, 1 m from its face) it hides a small share, at its foot
  // (column 8) up to half, so the pilot pass measures a larger spread there and the error
  // target gives those texels more paths (in proportion to the spread: measured 731 against
  // 387). The counts come from the pilot's own random numbers in texel order: bit-identical
  // at 1 and 2 threads.
  LightmapBakeSettings s = smallSettings();
  s.samplesPerTexel = 4096;
  s.minSamples = 16;
  s.errorTarget = 0.02f;
  s.threads = 1;
  auto a = bakeBlockFoot(s);
  s.threads = 2;
  auto b = bakeBlockFoot(s);
  ASSERT_TRUE(a.ok()) << a.error();
  ASSERT_TRUE(b.ok()) << b.error();
  const std::vector<double> perColumn = meanPathsByColumn(*a);
  std::printf("mean paths per texel by column (block face in column 8):");
  for (double c : perColumn) std::printf(" %.0f", c);
  std::printf("\n");
  EXPECT_GT(perColumn[8], 1.5 * perColumn[0]);
  EXPECT_LT(a->stats.minSamples, a->stats.maxSamples);
  EXPECT_LT(a->stats.meanSamples, 0.5 * 4096.0);
  expectSameLightAndPaths(*a, *b);
}

// Neyman allocation from the bounce cache's first pass (settings.adaptiveSamples): the same
// block foot under a constant sky (2 bounces, so that there is a cache), where paths
// disagree most at the foot (column 8) and least 1 m from it (column 0); the texels under
// the block (invalid) take the least. The mean over the texels stays samplesPerTexel (the
// counts are scaled to it; rounding moves it by < 1), the foot gets more than the far side,
// no texel leaves [samplesPerTexel / 2, 8 x samplesPerTexel], and the result is
// bit-identical at 1 and 2 threads.
TEST(LightmapBake, AdaptiveAllocationFromTheBounceCacheKeepsTheMeanCount) {
  LightmapBakeSettings s = smallSettings();
  s.samplesPerTexel = 64;
  s.bounceCacheSamples = 16;
  s.adaptiveSamples = true;
  s.threads = 1;
  auto a = bakeBlockFoot(s, 2);
  s.threads = 2;
  auto b = bakeBlockFoot(s, 2);
  ASSERT_TRUE(a.ok()) << a.error();
  ASSERT_TRUE(b.ok()) << b.error();
  const std::vector<double> perColumn = meanPathsByColumn(*a);
  std::printf("adaptive allocation, mean paths per texel by column (block face in column 8):");
  for (double c : perColumn) std::printf(" %.0f", c);
  std::printf("; mean %.2f, min %u, max %u\n", a->stats.meanSamples, a->stats.minSamples,
              a->stats.maxSamples);
  EXPECT_GT(perColumn[8], 1.25 * perColumn[0]);  // measured 101 against 70
  EXPECT_NEAR(a->stats.meanSamples, 64.0, 1.0);
  EXPECT_GE(a->stats.minSamples, 32u);
  EXPECT_LE(a->stats.maxSamples, 512u);
  EXPECT_LT(a->stats.minSamples, a->stats.maxSamples);
  expectSameLightAndPaths(*a, *b);
}

TEST(LightmapBake, BitIdenticalAtAnyThreadCount) {
  const Scene scene = loadShipped("cornell_box.gltf");
  ASSERT_FALSE(scene.objects.empty());
  LightmapBakeSettings s;
  s.resolution = 16.0f;
  s.maxSize = 256;
  s.samplesPerTexel = 16;
  s.supersampling = 2;
  s.ambientOcclusion = true;
  s.aoMaxDistance = 0.1f;
  s.threads = 1;
  auto a = bakeLightmaps(scene, s);
  s.threads = 2;
  auto b = bakeLightmaps(scene, s);
  ASSERT_TRUE(a.ok()) << a.error();
  ASSERT_TRUE(b.ok()) << b.error();
  ASSERT_EQ(a->pages.size(), b->pages.size());
  for (size_t p = 0; p < a->pages.size(); ++p) {
    EXPECT_EQ(a->pages[p].light.pixels, b->pages[p].light.pixels);
    EXPECT_EQ(a->pages[p].ambientOcclusion.pixels, b->pages[p].ambientOcclusion.pixels);
    EXPECT_EQ(a->pages[p].valid, b->pages[p].valid);
  }
  EXPECT_EQ(a->stats.rays, b->stats.rays);
}

TEST(LightmapBake, CancelledFlagStopsTheBake) {
  const Scene scene = loadShipped("cornell_box.gltf");
  std::atomic<bool> cancel{true};
  LightmapBakeSettings s;
  s.samplesPerTexel = 4096;
  auto r = bakeLightmaps(scene, s, false, &cancel);
  ASSERT_FALSE(r.ok());
  EXPECT_EQ(r.error(), "cancelled");
}

TEST(LightmapBake, CancelDuringTheLightStageStopsQuickly) {
  // A bake of minutes (two rooms at 4096 samples per texel), cancelled after 0.2 s.
  const Scene scene = loadShipped("two_rooms.gltf");
  std::atomic<bool> cancel{false};
  LightmapBakeSettings s;
  s.resolution = 8.0f;
  s.samplesPerTexel = 4096;
  std::thread canceller([&] {
    std::this_thread::sleep_for(std::chrono::milliseconds(200));
    cancel = true;
  });
  const auto start = std::chrono::steady_clock::now();
  auto r = bakeLightmaps(scene, s, false, &cancel);
  const double seconds =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  canceller.join();
  ASSERT_FALSE(r.ok());
  EXPECT_EQ(r.error(), "cancelled");
  std::printf("cancelled after %.2f s\n", seconds);
  EXPECT_LT(seconds, 5.0);
}

TEST(LightmapBake, PresetsAndSettingErrors) {
  // Error targets with a cap: each step halves the target and quadruples the cap.
  struct Expect {
    const char* name;
    float target;
    int cap, supersampling;
  };
  for (const Expect& e : {Expect{"preview", 0.12f, 64, 1}, Expect{"low", 0.06f, 256, 1},
                          Expect{"medium", 0.03f, 1024, 1}, Expect{"high", 0.015f, 4096, 2},
                          Expect{"production", 0.0075f, 16384, 2}}) {
    LightmapBakeSettings s;
    ASSERT_TRUE(applyLightmapPreset(e.name, s).ok()) << e.name;
    EXPECT_EQ(s.errorTarget, e.target) << e.name;
    EXPECT_EQ(s.samplesPerTexel, e.cap) << e.name;
    EXPECT_EQ(s.supersampling, e.supersampling) << e.name;
    EXPECT_LE(s.minSamples, s.samplesPerTexel) << e.name;
    EXPECT_GE(s.minSamples, s.supersampling * s.supersampling) << e.name;
  }
  LightmapBakeSettings s;
  const Status unknown = applyLightmapPreset("ultra", s);
  ASSERT_FALSE(unknown.ok());
  EXPECT_NE(unknown.error().find("production"), std::string::npos) << unknown.error();

  const Scene scene = quadScene();
  auto expectError = [&](LightmapBakeSettings bad, const std::string& word) {
    auto r = bakeLightmaps(scene, bad);
    ASSERT_FALSE(r.ok()) << word;
    EXPECT_NE(r.error().find(word), std::string::npos) << r.error();
  };
  LightmapBakeSettings bad = smallSettings();
  bad.maxSize = 4;  // padding 2 on both sides leaves no texel
  expectError(bad, "maxSize");
  bad = smallSettings();
  bad.samplesPerTexel = 2;
  bad.supersampling = 2;
  expectError(bad, "samplesPerTexel");
  bad = smallSettings();
  bad.backfaceTolerance = 1.5f;
  expectError(bad, "backfaceTolerance");
  bad = smallSettings();
  bad.resolution = 0.0f;
  expectError(bad, "resolution");
}

}  // namespace
}  // namespace kiln
