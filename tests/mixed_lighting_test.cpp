// mixed_lighting_test.cpp: directional lightmaps and mixed lighting (docs/mixed_lighting.md):
//   1. directional decode: a tilted normal gets the Lambert irradiance within 5%, the
//      geometric normal gives the non-directional value back;
//   2. Baked Indirect lightmap + the mixed light's analytic direct light = the fully baked
//      lightmap; realtime lights bake nothing;
//   3. shadowmask channels end to end: five overlapping mixed spots use four channels and the
//      fifth is baked and warned about; two far-apart mixed lights share a channel;
//   4. shadowmask values: 1 in light, 0 in hard shadow, the visible fraction of a soft light's
//      cone in its penumbra (computed directly by quadrature);
//   5. the subtractive decode on a known configuration (baked, and in closed form).
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdio>

#include "lightmap/directional.h"
#include "lightmap/lightmap_baker.h"
#include "tests/test_util.h"

namespace kiln {
namespace {

// A 2 m x 2 m floor, x in [0, 2], z in [-2, 0], y = 0, facing +y.
Scene floorScene() {
  Scene scene;
  const uint32_t m = test::addMaterial(scene, test::lambert(vec3(0.5f)));
  test::addQuad(scene, "floor", vec3(0, 0, 0), vec3(2, 0, 0), vec3(2, 0, -2), vec3(0, 0, -2), m);
  return scene;
}

LightmapBakeSettings exactSettings() {
  LightmapBakeSettings s;
  s.resolution = 8.0f;
  s.maxSize = 256;
  s.samplesPerTexel = 16;
  s.denoise = false;  // identities below hold texel by texel
  s.stitchSeams = false;
  return s;
}

vec3 rgb(const Image& image, size_t i) {
  const float* p = &image.pixels[size_t(image.channels) * i];
  return vec3(p[0], p[1], p[2]);
}
vec4 rgba(const Image& image, size_t i) {
  const float* p = &image.pixels[4 * i];
  return vec4(p[0], p[1], p[2], p[3]);
}

template <typename F>
void forValidTexels(const LightmapBakeResult& r, F f) {
  for (const LightmapPageResult& page : r.pages)
    for (size_t i = 0; i < page.valid.size(); ++i)
      if (page.valid[i]) f(page, i, rgb(page.position, i));
}

Light mixed(Light l, const std::string& name) {
  l.mode = LightMode::Mixed;
  l.name = name;
  return l;
}

Light spotLight(vec3 position, float candela, float range) {
  Light l;
  l.type = LightType::Spot;
  l.position = position;
  l.direction = vec3(0, -1, 0);
  l.intensity = candela;
  l.range = range;
  l.outerConeAngle = glm::radians(70.0f);
  return l;
}

// 1. One directional light at 20 degrees from the floor's normal. Half-Lambert is exact only
// for the geometric normal; for a normal tilted by 10 degrees its error is bounded by
// |(1 + cos t) / (1 + cos t0) - cos t / cos t0| / (cos t / cos t0) <= 4.4% here.
TEST(MixedLighting, Check1DirectionalDecodeMatchesLambert) {
  Scene scene = floorScene();
  const float theta = glm::radians(20.0f), lux = 3.0f;
  const vec3 travel(std::sin(theta), -std::cos(theta), 0.0f);
  scene.lights.push_back(test::directionalLight(travel, lux));
  LightmapBakeSettings s = exactSettings();
  s.directional = true;
  auto r = bakeLightmaps(scene, s);
  ASSERT_TRUE(r.ok()) << r.error();
  const vec3 toLight = -travel, n0(0, 1, 0);
  const float tilt = glm::radians(10.0f);
  const vec3 normals[] = {
      vec3(std::sin(tilt), std::cos(tilt), 0.0f),   // towards the light
      vec3(-std::sin(tilt), std::cos(tilt), 0.0f),  // away from it
      vec3(0.0f, std::cos(tilt), std::sin(tilt)),   // sideways
  };
  double worstDirectional = 0.0, worstFlat = 0.0, worstIdentity = 0.0;
  size_t count = 0;
  forValidTexels(*r, [&](const LightmapPageResult& page, size_t i, vec3) {
    ASSERT_FALSE(page.direction.empty());
    const vec3 light = rgb(page.light, i);
    const vec4 dir = rgba(page.direction, i);
    // A single delta light: D is its direction, directionality 1.
    EXPECT_NEAR(glm::length(2.0f * vec3(dir) - 1.0f), 1.0f, 1e-4f);
    EXPECT_GT(glm::dot(2.0f * vec3(dir) - 1.0f, toLight), 0.9999f);
    const vec3 flat = decodeDirectionalLightmap(light, dir, n0);
    worstIdentity = std::max(worstIdentity, double(std::abs(flat.x - light.x) / light.x));
    for (const vec3& n : normals) {
      const float expected = lux * glm::dot(n, toLight) * kInvPi;
      const vec3 v = decodeDirectionalLightmap(light, dir, n);
      worstDirectional = std::max(worstDirectional, double(std::abs(v.x - expected) / expected));
      worstFlat = std::max(worstFlat, double(std::abs(light.x - expected) / expected));
    }
    ++count;
  });
  std::printf("check 1: %zu texels; tilted normal: directional error %.2f%%, non-directional "
              "%.2f%%; geometric normal: %.2e\n",
              count, 100.0 * worstDirectional, 100.0 * worstFlat, worstIdentity);
  EXPECT_EQ(count, 256u);
  EXPECT_LT(worstDirectional, 0.05);
  EXPECT_LT(worstDirectional, worstFlat);  // the direction map is worth having
  EXPECT_LT(worstIdentity, 1e-5);
}

// 1b. With bounced light and a sky the direction is no longer a single delta (directionality
// < 1), and the geometric normal still decodes to the lightmap value exactly.
TEST(MixedLighting, Check1DirectionalGeometricNormalWithBounce) {
  Scene scene = floorScene();
  const uint32_t m = test::addMaterial(scene, test::lambert(vec3(0.8f)));
  test::addQuad(scene, "wall", vec3(2, 0, -2), vec3(2, 0, 0), vec3(2, 2, 0), vec3(2, 2, -2), m);
  scene.lights.push_back(test::directionalLight(vec3(0.6f, -0.8f, 0.0f), 3.0f));
  scene.sky = Sky::constant(vec3(0.1f, 0.15f, 0.3f));
  LightmapBakeSettings s = exactSettings();
  s.directional = true;
  s.denoise = true;
  s.stitchSeams = true;
  auto r = bakeLightmaps(scene, s);
  ASSERT_TRUE(r.ok()) << r.error();
  double worst = 0.0, minDirectionality = 1.0;
  forValidTexels(*r, [&](const LightmapPageResult& page, size_t i, vec3 p) {
    if (p.y > 1e-3f) return;  // floor texels: normal +y
    const vec3 light = rgb(page.light, i);
    const vec4 dir = rgba(page.direction, i);
    const vec3 v = decodeDirectionalLightmap(light, dir, vec3(0, 1, 0));
    worst = std::max(worst, double(glm::length(v - light) / glm::length(light)));
    minDirectionality = std::min(minDirectionality, double(glm::length(2.0f * vec3(dir) - 1.0f)));
  });
  std::printf("check 1b: geometric normal error %.2e, min directionality %.3f\n", worst,
              minDirectionality);
  EXPECT_LT(worst, 1e-5);
  EXPECT_LT(minDirectionality, 0.95);
  EXPECT_GT(minDirectionality, 0.2);
}

// A floor and a wall at x = 2 facing -x, lit by a directional light travelling +x and down:
// nothing is shadowed, the wall bounces light onto the floor.
Scene bounceScene(LightMode mode) {
  Scene scene = floorScene();
  const uint32_t m = test::addMaterial(scene, test::lambert(vec3(0.8f)));
  test::addQuad(scene, "wall", vec3(2, 0, -2), vec3(2, 0, 0), vec3(2, 2, 0), vec3(2, 2, -2), m);
  Light sun = test::directionalLight(glm::normalize(vec3(0.64f, -0.77f, 0.0f)), 4.0f);
  sun.mode = mode;
  sun.name = "sun";
  scene.lights.push_back(sun);
  return scene;
}

// 2. Baked Indirect: lightmap + analytic direct (E cos / pi, unshadowed) = fully baked.
TEST(MixedLighting, Check2BakedIndirectPlusDirectEqualsBaked) {
  LightmapBakeSettings s = exactSettings();
  s.bounces = 2;
  s.samplesPerTexel = 64;
  auto full = bakeLightmaps(bounceScene(LightMode::Baked), s);
  const Scene mixedScene = bounceScene(LightMode::Mixed);
  auto indirect = bakeLightmaps(mixedScene, s);
  LightmapBakeSettings other = s;
  other.seed = 17;  // independent noise
  auto indirectOther = bakeLightmaps(mixedScene, other);
  auto realtime = bakeLightmaps(bounceScene(LightMode::Realtime), s);
  ASSERT_TRUE(full.ok() && indirect.ok() && indirectOther.ok() && realtime.ok());
  ASSERT_EQ(indirect->lightModes.bakeDirect, std::vector<bool>{false});
  ASSERT_EQ(indirect->lightModes.bakeIndirect, std::vector<bool>{true});
  ASSERT_EQ(full->pages.size(), indirect->pages.size());

  const Light& sun = mixedScene.lights[0];
  double worstSame = 0.0, sumFull = 0.0, sumOther = 0.0, sumIndirect = 0.0, sumDirect = 0.0;
  for (size_t p = 0; p < full->pages.size(); ++p) {
    const LightmapPageResult& a = full->pages[p];
    const LightmapPageResult& b = indirect->pages[p];
    const LightmapPageResult& c = indirectOther->pages[p];
    for (size_t i = 0; i < a.valid.size(); ++i) {
      if (!a.valid[i]) continue;
      const vec3 x = rgb(a.position, i);
      const vec3 n = x.y < 1e-3f ? vec3(0, 1, 0) : vec3(-1, 0, 0);  // floor or wall
      const float direct =
          luminance(sun.irradianceAt(x)) * glm::dot(n, sun.directionTo(x)) * kInvPi;
      const float f = rgb(a.light, i).x;
      worstSame = std::max(worstSame, double(std::abs(rgb(b.light, i).x + direct - f) / f));
      sumFull += f;
      sumOther += rgb(c.light, i).x + direct;
      sumIndirect += rgb(b.light, i).x;
      sumDirect += direct;
    }
  }
  double realtimeMax = 0.0;
  for (const auto& page : realtime->pages)
    for (float v : page.light.pixels) realtimeMax = std::max(realtimeMax, double(v));
  std::printf("check 2: same seed max relative difference %.2e; other seed mean %.4f vs %.4f "
              "(indirect share %.1f%%); realtime max %.1e\n",
              worstSame, sumOther, sumFull, 100.0 * sumIndirect / sumFull, realtimeMax);
  EXPECT_LT(worstSame, 1e-5);  // same paths: the indirect light is the same estimate
  EXPECT_NEAR(sumOther / sumFull, 1.0, 0.01);  // independent noise averages out
  EXPECT_GT(sumIndirect, 0.05 * sumDirect);    // there is indirect light to keep
  EXPECT_EQ(realtimeMax, 0.0);                 // realtime lights never enter lightmaps
}

// 3a. Five mutually overlapping mixed spotlights under Shadowmask.
TEST(MixedLighting, Check3FiveOverlappingSpotsFourChannels) {
  Scene scene = floorScene();
  const vec3 offsets[] = {vec3(0), vec3(0.3f, 0, 0), vec3(-0.3f, 0, 0), vec3(0, 0, 0.3f),
                          vec3(0, 0, -0.3f)};
  for (int k = 0; k < 5; ++k)
    scene.lights.push_back(mixed(spotLight(vec3(1, 1.5f, -1) + offsets[k], 10.0f - float(k), 4.0f),
                                 "spot" + std::to_string(k)));
  LightmapBakeSettings s = exactSettings();
  s.lightingMode = LightingMode::Shadowmask;
  s.bounces = 0;
  auto r = bakeLightmaps(scene, s);
  ASSERT_TRUE(r.ok()) << r.error();
  std::vector<int> channels = r->lightModes.shadowmaskChannel;
  ASSERT_EQ(channels.size(), 5u);
  EXPECT_EQ(channels[4], -1);  // the weakest is coloured last
  std::vector<int> used(channels.begin(), channels.begin() + 4);
  std::sort(used.begin(), used.end());
  EXPECT_EQ(used, (std::vector<int>{0, 1, 2, 3}));
  EXPECT_EQ(r->lightModes.bakeDirect, (std::vector<bool>{false, false, false, false, true}));
  bool warned = false;
  for (const std::string& w : r->warnings) warned |= w.find("'spot4'") != std::string::npos;
  EXPECT_TRUE(warned);
  // The lightmap holds exactly the fifth light's direct light; the four channels are 1
  // (nothing casts shadows).
  const Light& fifth = scene.lights[4];
  double worst = 0.0, minMask = 1.0;
  forValidTexels(*r, [&](const LightmapPageResult& page, size_t i, vec3 x) {
    const float expected =
        luminance(fifth.irradianceAt(x)) * glm::dot(vec3(0, 1, 0), fifth.directionTo(x)) * kInvPi;
    worst = std::max(worst, double(std::abs(rgb(page.light, i).x - expected)) /
                                std::max(1e-6, double(expected)));
    for (int c = 0; c < 4; ++c)
      minMask = std::min(minMask, double(page.shadowmask.pixels[4 * i + size_t(c)]));
  });
  std::printf("check 3a: channels %d %d %d %d %d, fifth light's lightmap error %.2e\n",
              channels[0], channels[1], channels[2], channels[3], channels[4], worst);
  EXPECT_LT(worst, 1e-4);
  EXPECT_EQ(minMask, 1.0);
}

// A 20 m x 2 m strip (x in [0, 20]) with two mixed point lights of range 2 at x = 1 and
// x = 19, and a small blocker under the second one.
Scene farApartScene() {
  Scene scene;
  const uint32_t m = test::addMaterial(scene, test::lambert(vec3(0.5f)));
  const uint32_t block = test::addMaterial(scene, test::lambert(vec3(0.5f), vec3(0.0f), true));
  test::addQuad(scene, "strip", vec3(0, 0, 0), vec3(20, 0, 0), vec3(20, 0, -2), vec3(0, 0, -2), m);
  const uint32_t b = test::addQuad(scene, "blocker", vec3(18.7f, 0.5f, -0.7f),
                                   vec3(19.3f, 0.5f, -0.7f), vec3(19.3f, 0.5f, -1.3f),
                                   vec3(18.7f, 0.5f, -1.3f), block);
  scene.objects[b].settings.scaleInLightmap = 0.0f;
  Light a = test::pointLight(vec3(1, 1, -1), 5.0f);
  a.range = 2.0f;
  Light c = test::pointLight(vec3(19, 1, -1), 5.0f);
  c.range = 2.0f;
  scene.lights.push_back(mixed(a, "near"));
  scene.lights.push_back(mixed(c, "far"));
  return scene;
}

// 3b. Two far-apart mixed lights share channel 0, each texel's channel 0 holds the shadow of
// the light that reaches it.
TEST(MixedLighting, Check3FarApartLightsShareAChannel) {
  const Scene scene = farApartScene();
  LightmapBakeSettings s = exactSettings();
  s.resolution = 4.0f;
  s.lightingMode = LightingMode::Shadowmask;
  s.bounces = 0;
  auto r = bakeLightmaps(scene, s);
  ASSERT_TRUE(r.ok()) << r.error();
  EXPECT_EQ(r->lightModes.shadowmaskChannel, (std::vector<int>{0, 0}));
  EXPECT_TRUE(r->lightModes.warnings.empty());
  size_t shadowed = 0, lit = 0;
  forValidTexels(*r, [&](const LightmapPageResult& page, size_t i, vec3 x) {
    const vec4 m = rgba(page.shadowmask, i);
    for (int c = 1; c < 4; ++c) EXPECT_EQ(m[c], 1.0f);  // unused channels
    // Under the blocker (its shadow from a light 0.5 m above it spans twice its size).
    if (std::abs(x.x - 19.0f) < 0.5f && std::abs(x.z + 1.0f) < 0.5f) {
      EXPECT_EQ(m.x, 0.0f) << x.x << " " << x.z;
      ++shadowed;
    } else if (std::abs(x.x - 19.0f) > 0.75f || std::abs(x.z + 1.0f) > 0.75f) {
      EXPECT_EQ(m.x, 1.0f) << x.x << " " << x.z;
      ++lit;
    }
    EXPECT_EQ(rgb(page.light, i), vec3(0.0f));  // mixed: no direct, nothing to bounce off
  });
  std::printf("check 3b: shared channel 0, %zu texels shadowed by 'far', %zu lit\n", shadowed,
              lit);
  EXPECT_GT(shadowed, 4u);
  EXPECT_GT(lit, 100u);
}

// The fraction of directions uniform over the cone of half-angle `halfAngle` around +y with
// dx / dy >= t: the visible share of a soft directional light straight overhead at a point
// x = edge - t h beside the straight edge of a half-plane blocker at height h. Quadrature on
// a fine grid in (cos theta, phi), independent of the integrator.
struct ConeFraction {
  std::vector<float> ratios;  // sorted dx / dy of the grid directions
  explicit ConeFraction(float halfAngle) {
    const int nu = 600, nphi = 600;
    const float cosMax = std::cos(halfAngle);
    for (int i = 0; i < nu; ++i) {
      const float c = 1.0f - (1.0f - cosMax) * (float(i) + 0.5f) / float(nu);
      const float sn = std::sqrt(std::max(0.0f, 1.0f - c * c));
      for (int j = 0; j < nphi; ++j) {
        const float phi = 2.0f * kPi * (float(j) + 0.5f) / float(nphi);
        ratios.push_back(sn * std::cos(phi) / c);
      }
    }
    std::sort(ratios.begin(), ratios.end());
  }
  float visible(float t) const {
    const auto it = std::lower_bound(ratios.begin(), ratios.end(), t);
    return float(ratios.end() - it) / float(ratios.size());
  }
};

// 4. Shadowmask values against the visible fraction computed directly.
TEST(MixedLighting, Check4ShadowmaskVisibleFraction) {
  Scene scene = floorScene();
  const uint32_t block = test::addMaterial(scene, test::lambert(vec3(0.5f), vec3(0.0f), true));
  const float h = 0.5f, edge = 1.0f;
  // A half-plane at height h covering x < edge (wide enough to be infinite for the floor).
  const uint32_t b = test::addQuad(scene, "blocker", vec3(-4, h, 3), vec3(edge, h, 3),
                                   vec3(edge, h, -5), vec3(-4, h, -5), block);
  scene.objects[b].settings.scaleInLightmap = 0.0f;
  Light sun = test::directionalLight(vec3(0, -1, 0), 3.0f);
  sun.shadowAngle = 30.0f;  // full cone angle, degrees
  sun.shadowSamples = 4;
  const vec3 lamp(1.6f, 2.0f, -1.0f);
  scene.lights.push_back(mixed(sun, "sun"));                          // channel 0
  scene.lights.push_back(mixed(test::pointLight(lamp, 4.0f), "lamp"));  // channel 1, hard
  LightmapBakeSettings s = exactSettings();
  s.resolution = 32.0f;
  s.samplesPerTexel = 64;
  s.bounces = 1;
  s.lightingMode = LightingMode::Shadowmask;
  auto r = bakeLightmaps(scene, s);
  ASSERT_TRUE(r.ok()) << r.error();
  ASSERT_EQ(r->lightModes.shadowmaskChannel, (std::vector<int>{0, 1}));
  const ConeFraction cone(glm::radians(15.0f));
  double worstSoft = 0.0;
  size_t full = 0, umbra = 0, penumbra = 0, hardChecked = 0, hardWrong = 0;
  forValidTexels(*r, [&](const LightmapPageResult& page, size_t i, vec3 x) {
    const vec4 m = rgba(page.shadowmask, i);
    const float expected = cone.visible((edge - x.x) / h);
    worstSoft = std::max(worstSoft, double(std::abs(m.x - expected)));
    if (expected == 1.0f) {
      EXPECT_EQ(m.x, 1.0f);
      ++full;
    } else if (expected == 0.0f) {
      EXPECT_EQ(m.x, 0.0f);
      ++umbra;
    } else if (m.x > 0.05f && m.x < 0.95f) {
      ++penumbra;
    }
    // Hard point light: blocked when the segment crosses y = h at x < edge.
    const float cross = x.x + (h / lamp.y) * (lamp.x - x.x);
    if (std::abs(cross - edge) > 1e-3f) {
      ++hardChecked;
      hardWrong += m.y != (cross < edge ? 0.0f : 1.0f);
    }
    EXPECT_EQ(m.z, 1.0f);
    EXPECT_EQ(m.w, 1.0f);
  });
  std::printf("check 4: soft light: %zu texels in full light, %zu in umbra, %zu in penumbra, "
              "max |mask - visible fraction| %.4f; hard light: %zu of %zu texels wrong\n",
              full, umbra, penumbra, worstSoft, hardWrong, hardChecked);
  EXPECT_GT(full, 100u);
  EXPECT_GT(umbra, 100u);
  EXPECT_GT(penumbra, 100u);
  EXPECT_LT(worstSoft, 0.03);
  EXPECT_EQ(hardWrong, 0u);
  EXPECT_GT(hardChecked, 4000u);
}

// 5. Subtractive: floor under a hard-shadowing blocker, a mixed sun straight down and a
// constant sky, no bounces. Known values: lit texels hold sun + sky, shadowed texels the sky
// only.
TEST(MixedLighting, Check5SubtractiveFormula) {
  Scene scene = floorScene();
  const uint32_t block = test::addMaterial(scene, test::lambert(vec3(0.5f), vec3(0.0f), true));
  const uint32_t b = test::addQuad(scene, "blocker", vec3(-4, 0.5f, 3), vec3(1, 0.5f, 3),
                                   vec3(1, 0.5f, -5), vec3(-4, 0.5f, -5), block);
  scene.objects[b].settings.scaleInLightmap = 0.0f;
  const float lux = 3.0f;
  scene.lights.push_back(mixed(test::directionalLight(vec3(0, -1, 0), lux), "sun"));
  scene.sky = Sky::constant(vec3(0.2f));
  LightmapBakeSettings s = exactSettings();
  s.bounces = 0;
  s.lightingMode = LightingMode::Subtractive;
  auto sub = bakeLightmaps(scene, s);
  s.lightingMode = LightingMode::BakedIndirect;
  auto ind = bakeLightmaps(scene, s);
  ASSERT_TRUE(sub.ok() && ind.ok());
  EXPECT_EQ(sub->lightModes.bakeDirect, std::vector<bool>{true});  // mixed baked fully
  const vec3 n(0, 1, 0), toLight(0, 1, 0), lightColor(lux * kInvPi);  // lightmap units
  const vec3 darkShadow(0.02f), brightShadow(0.5f);
  size_t lit = 0, shadowed = 0;
  double worst = 0.0;
  for (size_t p = 0; p < sub->pages.size(); ++p) {
    const LightmapPageResult& a = sub->pages[p];
    for (size_t i = 0; i < a.valid.size(); ++i) {
      if (!a.valid[i]) continue;
      const vec3 x = rgb(a.position, i);
      const vec3 lm = rgb(a.light, i), skyOnly = rgb(ind->pages[p].light, i);
      const bool inLight = x.x > 1.02f;
      // Baked: sun x visibility + sky.
      const vec3 expectedLm = skyOnly + (inLight ? lightColor : vec3(0.0f));
      worst = std::max(worst, double(glm::length(lm - expectedLm)));
      // Realtime attenuation 1 (no dynamic shadow): the lightmap unchanged.
      EXPECT_EQ(subtractiveLightmap(lm, n, toLight, 1.0f, lightColor, darkShadow), lm);
      const vec3 dark = subtractiveLightmap(lm, n, toLight, 0.0f, lightColor, darkShadow);
      const vec3 bright = subtractiveLightmap(lm, n, toLight, 0.0f, lightColor, brightShadow);
      if (inLight) {
        // A dynamic object's shadow removes the sun: the texel as if baked in shadow.
        worst = std::max(worst, double(glm::length(dark - skyOnly)));
        // ... but never darker than the shadow colour.
        worst = std::max(worst, double(glm::length(bright - glm::max(skyOnly, brightShadow))));
        ++lit;
      } else {
        // Already in baked shadow: min with the lightmap keeps it (no double shadow) when the
        // shadow colour is above it; a darker shadow colour is the known over-darkening,
        // clamped at the shadow colour.
        worst = std::max(worst, double(glm::length(bright - lm)));
        worst = std::max(worst, double(glm::length(dark - glm::min(lm, darkShadow))));
        ++shadowed;
      }
    }
  }
  std::printf("check 5: %zu lit and %zu shadowed texels, max error %.2e\n", lit, shadowed, worst);
  EXPECT_GT(lit, 50u);
  EXPECT_GT(shadowed, 50u);
  EXPECT_LT(worst, 1e-5);
}

// 5b. The subtractive decode in closed form, every branch: the estimate subtracted, the clamp
// to the shadow colour, the shadow strength blend and the min with the lightmap.
TEST(MixedLighting, Check5SubtractiveHandComputed) {
  const vec3 lm(1.0f, 0.8f, 0.6f), shadowColor(0.3f);
  const vec3 n(0, 1, 0), toLight(0.6f, 0.8f, 0.0f);  // dot(n, l) = 0.8
  const vec3 lightColor(0.5f);                       // estimate = 0.8 x 0.5 = 0.4 in shadow
  auto near = [](vec3 a, vec3 b) { return glm::length(a - b) < 1e-6f; };
  // Full shadow: (1, 0.8, 0.6) - 0.4 = (0.6, 0.4, 0.2), clamped to 0.3 in blue.
  EXPECT_PRED2(near, subtractiveLightmap(lm, n, toLight, 0.0f, lightColor, shadowColor),
               vec3(0.6f, 0.4f, 0.3f));
  // Half attenuation: estimate 0.2.
  EXPECT_PRED2(near, subtractiveLightmap(lm, n, toLight, 0.5f, lightColor, shadowColor),
               vec3(0.8f, 0.6f, 0.4f));
  // Shadow strength 0.5 (shadowStrength' = 0.5): halfway back to the lightmap.
  EXPECT_PRED2(near, subtractiveLightmap(lm, n, toLight, 0.0f, lightColor, shadowColor, 0.5f),
               vec3(0.8f, 0.6f, 0.45f));
  // A shadow colour above the lightmap never brightens it.
  EXPECT_PRED2(near, subtractiveLightmap(lm, n, toLight, 0.0f, lightColor, vec3(0.9f)),
               vec3(0.9f, 0.8f, 0.6f));
  // A surface facing away from the light: nothing to subtract.
  EXPECT_PRED2(near, subtractiveLightmap(lm, -n, toLight, 0.0f, lightColor, shadowColor), lm);
  // Shadowmask: the light's channel, 1 without one.
  const vec4 mask(0.25f, 0.5f, 0.75f, 1.0f);
  EXPECT_EQ(shadowmaskVisibility(mask, 2), 0.75f);
  EXPECT_EQ(shadowmaskVisibility(mask, -1), 1.0f);
}

// The shadowmask and direction maps are keyed like the light: bit-identical at any thread
// count.
TEST(MixedLighting, MapsDeterministicAcrossThreadCounts) {
  Scene scene = floorScene();
  const uint32_t m = test::addMaterial(scene, test::lambert(vec3(0.8f)));
  test::addQuad(scene, "wall", vec3(2, 0, -2), vec3(2, 0, 0), vec3(2, 2, 0), vec3(2, 2, -2), m);
  Light sun = test::directionalLight(glm::normalize(vec3(-0.5f, -0.8f, 0.2f)), 3.0f);
  sun.shadowAngle = 10.0f;
  sun.shadowSamples = 2;
  scene.lights.push_back(mixed(sun, "sun"));
  scene.sky = Sky::constant(vec3(0.1f));
  LightmapBakeSettings s = exactSettings();
  s.lightingMode = LightingMode::Shadowmask;
  s.directional = true;
  s.threads = 1;
  auto one = bakeLightmaps(scene, s);
  s.threads = 0;
  auto all = bakeLightmaps(scene, s);
  ASSERT_TRUE(one.ok() && all.ok());
  ASSERT_EQ(one->pages.size(), all->pages.size());
  for (size_t p = 0; p < one->pages.size(); ++p) {
    EXPECT_EQ(one->pages[p].light.pixels, all->pages[p].light.pixels);
    EXPECT_EQ(one->pages[p].shadowmask.pixels, all->pages[p].shadowmask.pixels);
    EXPECT_EQ(one->pages[p].direction.pixels, all->pages[p].direction.pixels);
    EXPECT_FALSE(one->pages[p].shadowmask.empty());
  }
}

}  // namespace
}  // namespace kiln
