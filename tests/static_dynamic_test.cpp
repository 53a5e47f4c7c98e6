// static_dynamic_test.cpp: Unity's static/dynamic rule and Beast's two shadow switches.
//   - a dynamic object (extras.kiln.static false) casts, bounces and emits nothing into baked
//     data: the lightmaps and probes of a scene with it are bit-identical to those of the same
//     scene without it (the baking Tracer holds the same triangles, the atlas the same
//     rectangles, and every random number is keyed by texel or probe and sample, never by
//     what else the scene holds); probe placement puts the same probes;
//   - castShadows false: the object stops no punctual light's shadow ray, yet is lightmapped,
//     bounces light and blocks the sky;
//   - bakedShadows false on a light: its baked light ignores occlusion;
//   - the loader reads both switches, warns about unknown keys and root extras.kiln, and
//     loads kiln's own output glTF without a warning.
#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
#include <filesystem>
#include <nlohmann/json.hpp>

#include "lightmap/lightmap_baker.h"
#include "probes/probe_baker.h"
#include "probes/probe_placement.h"
#include "src/gltf_loader.h"
#include "src/integrator.h"
#include "src/tracer.h"
#include "tests/test_util.h"

namespace kiln {
namespace {

namespace fs = std::filesystem;
using Json = nlohmann::json;

vec3 texel(const Image& image, size_t i) {
  return vec3(image.pixels[3 * i], image.pixels[3 * i + 1], image.pixels[3 * i + 2]);
}

// A 4 m x 4 m ground (y = 0, facing +y, x and z in [-2, 2]), grey.
Scene groundScene() {
  Scene scene;
  const uint32_t m = test::addMaterial(scene, test::lambert(vec3(0.6f)));
  test::addQuad(scene, "ground", vec3(-2, 0, 2), vec3(2, 0, 2), vec3(2, 0, -2), vec3(-2, 0, -2), m);
  return scene;
}

LightmapBakeSettings smallSettings() {
  LightmapBakeSettings s;
  s.resolution = 8.0f;
  s.maxSize = 64;
  s.samplesPerTexel = 32;
  s.bounces = 3;
  return s;
}

// Whether two bakes hold the same pages bit for bit (light, validity, positions).
void expectSamePages(const LightmapBakeResult& a, const LightmapBakeResult& b) {
  ASSERT_EQ(a.pages.size(), b.pages.size());
  for (size_t p = 0; p < a.pages.size(); ++p) {
    const LightmapPageResult& x = a.pages[p];
    const LightmapPageResult& y = b.pages[p];
    ASSERT_EQ(x.light.width, y.light.width);
    ASSERT_EQ(x.light.height, y.light.height);
    EXPECT_EQ(x.valid, y.valid) << "page " << p;
    EXPECT_EQ(x.light.pixels, y.light.pixels) << "page " << p;
    EXPECT_EQ(x.position.pixels, y.position.pixels) << "page " << p;
  }
}

// Relative RMS difference of two bakes' light over the texels valid in both.
double relativeRms(const LightmapBakeResult& a, const LightmapBakeResult& b) {
  double d2 = 0.0, v2 = 0.0;
  for (size_t p = 0; p < a.pages.size(); ++p)
    for (size_t i = 0; i < a.pages[p].valid.size(); ++i) {
      if (!a.pages[p].valid[i] || !b.pages[p].valid[i]) continue;
      const vec3 d = texel(a.pages[p].light, i) - texel(b.pages[p].light, i);
      const vec3 v = texel(b.pages[p].light, i);
      d2 += glm::dot(d, d);
      v2 += glm::dot(v, v);
    }
  return v2 > 0.0 ? std::sqrt(d2 / v2) : 0.0;
}

// The sunlit ground with a 0.5 m box standing on it, orange and emissive, inserted BEFORE the
// ground (so the ground's object index differs from the scene without it: what matters is
// the set of triangles the tracer holds, not indices).
Scene groundWithBox(bool isStatic) {
  Scene scene = groundScene();
  Material orange = test::lambert(vec3(0.8f, 0.45f, 0.1f), vec3(2.0f, 1.0f, 0.5f));
  const uint32_t m = test::addMaterial(scene, orange);
  test::addBox(scene, "box", vec3(-0.25f, 0.0f, -0.25f), vec3(0.25f, 0.5f, 0.25f), m, false);
  std::rotate(scene.objects.begin(), scene.objects.end() - 1, scene.objects.end());
  scene.objects[0].settings.isStatic = isStatic;
  // Static, it would take a lightmap rectangle and move the ground's; lightmapped or not does
  // not change what it casts, so the control keeps the atlas equal.
  if (isStatic) scene.objects[0].settings.scaleInLightmap = 0.0f;
  scene.updateBounds();
  return scene;
}

void addSunAndSky(Scene& scene) {
  scene.lights.push_back(test::directionalLight(vec3(0.4f, -1.0f, 0.3f), 5.0f));
  scene.lights.back().shadowAngle = 2.0f;  // soft: the shadow rays use random numbers too
  scene.lights.back().shadowSamples = 4;
  scene.sky = Sky::constant(vec3(0.3f, 0.4f, 0.6f));
}

// The three scenes the dynamic-box tests compare, under the same sun and sky: the ground
// alone, the ground with the dynamic box, and (the control) with the box static.
struct SunlitBoxScenes {
  Scene without, dynamic, control;
};
SunlitBoxScenes sunlitBoxScenes() {
  SunlitBoxScenes s{groundScene(), groundWithBox(false), groundWithBox(true)};
  for (Scene* scene : {&s.without, &s.dynamic, &s.control}) addSunAndSky(*scene);
  return s;
}

TEST(StaticDynamic, DynamicBoxLeavesTheGroundLightmapBitIdentical) {
  const auto [without, dynamic, control] = sunlitBoxScenes();

  const LightmapBakeSettings s = smallSettings();
  auto a = bakeLightmaps(without, s);
  auto b = bakeLightmaps(dynamic, s);
  auto c = bakeLightmaps(control, s);
  ASSERT_TRUE(a.ok()) << a.error();
  ASSERT_TRUE(b.ok()) << b.error();
  ASSERT_TRUE(c.ok()) << c.error();
  // The dynamic box has no lightmap.
  EXPECT_EQ(b->layout.objects[0].lightmapIndex, -1);
  EXPECT_GE(b->layout.objects[1].lightmapIndex, 0);
  expectSamePages(*b, *a);
  // The control: the same box, static, shadows, blocks the sky and glows onto the ground.
  const double change = relativeRms(*c, *a);
  std::printf("static box changes the ground by %.1f%% (relative RMS)\n", 100.0 * change);
  EXPECT_GT(change, 0.02);
}

TEST(StaticDynamic, DynamicEmitterLightsNothing) {
  // Only light in the scene: an emissive ceiling panel. Dynamic, the ground stays exactly 0.
  for (bool isStatic : {false, true}) {
    Scene scene = groundScene();
    const uint32_t m = test::addMaterial(scene, test::lambert(vec3(0.5f), vec3(10.0f), true));
    const uint32_t panel = test::addQuad(scene, "panel", vec3(-1, 1, -1), vec3(1, 1, -1),
                                         vec3(1, 1, 1), vec3(-1, 1, 1), m);
    scene.objects[panel].settings.isStatic = isStatic;
    scene.objects[panel].settings.scaleInLightmap = 0.0f;
    auto r = bakeLightmaps(scene, smallSettings());
    ASSERT_TRUE(r.ok()) << r.error();
    double sum = 0.0, maximum = 0.0;
    for (const LightmapPageResult& page : r->pages)
      for (size_t i = 0; i < page.valid.size(); ++i)
        if (page.valid[i]) {
          sum += maxComponent(texel(page.light, i));
          maximum = std::max(maximum, double(maxComponent(texel(page.light, i))));
        }
    if (isStatic)
      EXPECT_GT(sum, 0.0);
    else
      EXPECT_EQ(maximum, 0.0);
  }
}

// Probes around (and one inside) the box: SH, validity and visibility maps are identical
// with the dynamic box and without it.
TEST(StaticDynamic, DynamicBoxLeavesProbesBitIdentical) {
  const auto [without, dynamic, control] = sunlitBoxScenes();
  const std::vector<vec3> positions = {vec3(0.0f, 0.25f, 0.0f),  // inside the box
                                       vec3(0.6f, 0.3f, 0.0f),  vec3(-0.6f, 0.3f, 0.1f),
                                       vec3(0.0f, 0.3f, 0.6f),  vec3(0.1f, 0.3f, -0.6f),
                                       vec3(0.0f, 1.2f, 0.0f),  vec3(0.3f, 0.9f, 0.3f)};
  ProbeBakeSettings settings;
  settings.rays = 1024;
  settings.bounces = 2;
  settings.lightSamples = 4;
  settings.visibilityResolution = 8;
  settings.fillInvalid = false;
  auto bake = [&](const Scene& scene) {
    auto tracer = Tracer::create(scene);
    EXPECT_TRUE(tracer.ok());
    auto set = bakeProbes(scene, **tracer, positions, settings);
    EXPECT_TRUE(set.ok()) << set.error();
    return std::move(set).value();
  };
  const ProbeSet a = bake(without), b = bake(dynamic), c = bake(control);
  ASSERT_EQ(a.sh.size(), positions.size());
  ASSERT_EQ(b.sh.size(), positions.size());
  for (size_t i = 0; i < positions.size(); ++i)
    for (int k = 0; k < kShL2Count; ++k) {
      EXPECT_EQ(a.sh[i].c[size_t(k)], b.sh[i].c[size_t(k)])
          << "probe " << i << " coefficient " << k;
    }
  EXPECT_EQ(a.validity, b.validity);
  EXPECT_EQ(a.visibility.maxDistance, b.visibility.maxDistance);
  EXPECT_EQ(a.visibility.moments, b.visibility.moments);
  // The control: the static box makes the probe inside it invalid and changes its neighbours.
  EXPECT_EQ(a.validity[0], 1.0f);
  EXPECT_LT(c.validity[0], 0.5f);
  EXPECT_NE(a.sh[1].c[0], c.sh[1].c[0]);
}

// Automatic placement (candidates, relocation out of geometry, the cheap bakes that score
// sets) puts the same probes with the dynamic box and without it; a static box changes them.
TEST(StaticDynamic, DynamicBoxLeavesProbePlacementIdentical) {
  ProbePlacementSettings s;
  s.volumes = {Bounds3{vec3(-1.5f, 0.05f, -1.5f), vec3(1.5f, 1.5f, 1.5f)}};
  s.budget = 24;
  s.candidateRays = 128;
  s.checkPoints = 64;
  s.maxDepth = 1;
  s.bake.bounces = 1;
  s.bake.lightSamples = 1;
  s.bake.visibilityResolution = 8;
  auto place = [&](const Scene& scene) {
    auto tracer = Tracer::create(scene);
    EXPECT_TRUE(tracer.ok());
    auto placed = placeProbes(scene, **tracer, s);
    EXPECT_TRUE(placed.ok()) << placed.error();
    std::vector<vec3> positions;
    for (const PlacedProbe& p : placed->probes) positions.push_back(p.position);
    return positions;
  };
  const auto [without, dynamic, control] = sunlitBoxScenes();
  const std::vector<vec3> a = place(without), b = place(dynamic), c = place(control);
  ASSERT_GE(a.size(), 4u);
  EXPECT_EQ(a, b);
  EXPECT_NE(a, c);
}

// The project's two_rooms scene has a dynamic box in room B: its lightmaps equal those of the
// scene with the box removed.
TEST(StaticDynamic, TwoRoomsDynamicBoxChangesNoTexel) {
  Result<Scene> loaded = loadScene(test::scenesDir() + "/two_rooms.gltf");
  ASSERT_TRUE(loaded.ok()) << loaded.error();
  Scene with = std::move(loaded).value();
  auto box = std::find_if(with.objects.begin(), with.objects.end(),
                          [](const Object& o) { return o.name == "dynamic_box"; });
  ASSERT_NE(box, with.objects.end());
  ASSERT_FALSE(box->settings.isStatic);
  Scene without = with;
  without.objects.erase(without.objects.begin() + (box - with.objects.begin()));
  without.updateBounds();
  LightmapBakeSettings s;
  s.resolution = 4.0f;
  s.maxSize = 128;
  s.samplesPerTexel = 16;
  s.bounces = 3;
  auto a = bakeLightmaps(with, s);
  auto b = bakeLightmaps(without, s);
  ASSERT_TRUE(a.ok()) << a.error();
  ASSERT_TRUE(b.ok()) << b.error();
  expectSamePages(*a, *b);
}

// The tracer: a bake's holds static objects only, the renderer's every object; shadow rays of
// punctual lights pass castShadows-false objects, other rays do not.
TEST(StaticDynamic, TracerGeometryAndShadowRays) {
  Scene scene = groundScene();
  const uint32_t m = test::addMaterial(scene, test::lambert(vec3(0.5f)));
  const uint32_t dyn =
      test::addBox(scene, "dynamic", vec3(-1.5f, 1, -0.5f), vec3(-0.5f, 2, 0.5f), m, false);
  const uint32_t ghost =
      test::addBox(scene, "ghost", vec3(0.5f, 1, -0.5f), vec3(1.5f, 2, 0.5f), m, false);
  scene.objects[dyn].settings.isStatic = false;
  scene.objects[ghost].settings.castShadows = false;
  auto baked = Tracer::create(scene);
  auto all = Tracer::create(scene, TracerGeometry::All);
  ASSERT_TRUE(baked.ok() && all.ok());
  EXPECT_TRUE((*baked)->contains(0));
  EXPECT_FALSE((*baked)->contains(dyn));
  EXPECT_TRUE((*baked)->contains(ghost));
  EXPECT_TRUE((*all)->contains(dyn));
  const Ray up{vec3(-1.0f, 0.1f, 0.0f), vec3(0, 1, 0)};
  EXPECT_FALSE((*baked)->occluded(up));
  EXPECT_FALSE((*baked)->intersect(up).has_value());
  EXPECT_TRUE((*all)->occluded(up));
  ASSERT_TRUE((*all)->intersect(up).has_value());
  EXPECT_EQ((*all)->intersect(up)->object, dyn);
  const Ray upGhost{vec3(1.0f, 0.1f, 0.0f), vec3(0, 1, 0)};
  for (const auto* t : {baked->get(), all->get()}) {
    EXPECT_TRUE(t->occluded(upGhost));
    EXPECT_TRUE(t->occluded(upGhost, RayKind::Any));
    EXPECT_FALSE(t->occluded(upGhost, RayKind::LightShadow));
    EXPECT_EQ(t->transmittance(upGhost, RayKind::LightShadow), vec3(1.0f));
    EXPECT_EQ(t->transmittance(upGhost), vec3(0.0f));
    ASSERT_TRUE(t->intersect(upGhost).has_value());
    EXPECT_EQ(t->intersect(upGhost)->object, ghost);
  }
  // With a BLEND surface in the scene the transmittance walk runs, and must agree.
  Material glass = test::lambert(vec3(0.5f, 0.5f, 1.0f));
  glass.alphaMode = AlphaMode::Blend;
  glass.baseColorFactor.a = 0.5f;
  const uint32_t g = test::addMaterial(scene, glass);
  test::addQuad(scene, "glass", vec3(-2, 3, 2), vec3(2, 3, 2), vec3(2, 3, -2), vec3(-2, 3, -2), g);
  auto blend = Tracer::create(scene);
  ASSERT_TRUE(blend.ok());
  ASSERT_TRUE((*blend)->hasTranslucentSurfaces());
  const vec3 through = (*blend)->transmittance(upGhost, RayKind::LightShadow);
  EXPECT_NEAR(through.x, 0.25f, 1e-6f);  // (1 - 0.5) x 0.5
  EXPECT_NEAR(through.z, 0.5f, 1e-6f);
  EXPECT_EQ((*blend)->transmittance(upGhost), vec3(0.0f));
  // BLEND surfaces of dynamic objects do not count.
  scene.objects.back().settings.isStatic = false;
  auto noBlend = Tracer::create(scene);
  ASSERT_TRUE(noBlend.ok());
  EXPECT_FALSE((*noBlend)->hasTranslucentSurfaces());
}

// A sun at theta from the zenith over the ground; a 1 m box floats 0.5 m above it. Texel
// values E / pi. The sun has soft shadows (each texel averages several shadow rays) but no
// ray is blocked when nothing casts, so an unshadowed texel is exactly lux cos(theta) / pi
// (up to float rounding and the denoiser's weights summing to 1: 1e-5 relative, as
// LightmapBake.DirectionalLightCosineLaw); no indirect light (bounces 0, no sky).
struct FloatingBox {
  Scene scene;
  float lux = 6.0f;
  float theta = glm::radians(30.0f);
  uint32_t box = 0;

  FloatingBox() {
    scene = groundScene();
    const uint32_t m = test::addMaterial(scene, test::lambert(vec3(0.7f)));
    box = test::addBox(scene, "box", vec3(-0.5f, 0.5f, -0.5f), vec3(0.5f, 1.5f, 0.5f), m, false);
    // addBox gives every face the unit square as UV1; generated lightmap UVs give each face
    // its own texels.
    scene.objects[box].uv1.clear();
    Light sun = test::directionalLight(vec3(std::sin(theta), -std::cos(theta), 0.0f), lux);
    sun.shadowAngle = 1.0f;
    sun.shadowSamples = 4;
    scene.lights.push_back(sun);
  }
  float expected() const { return lux * std::cos(theta) * kInvPi; }
  // The ground texels inside the box's shadow, away from its edges by 0.1 m (the penumbra
  // of a 1 degree sun is 1.5 m x tan(1 deg) = 0.03 m wide at most): the union of the box's
  // horizontal slices at height h in [0.5, 1.5] moved along the sun by h tan(theta), i.e.
  // x in [-0.5 + 0.5 tan, 0.5 + 1.5 tan], |z| < 0.5.
  bool inShadow(vec3 p) const {
    const float t = std::tan(theta);
    return p.y < 0.01f && std::abs(p.z) < 0.4f && p.x > -0.4f + 0.5f * t && p.x < 0.4f + 1.5f * t;
  }
};

LightmapBakeSettings directOnly() {
  LightmapBakeSettings s = smallSettings();
  s.bounces = 0;
  s.samplesPerTexel = 16;
  return s;
}

// Statistics of the ground's shadow texels and of the box's top face.
struct ShadowStats {
  size_t shadowTexels = 0;
  double maxShadowError = 0.0;  // max |v - expected| / expected over the shadow texels
  double meanShadow = 0.0;
  size_t topTexels = 0;
  double maxTopError = 0.0;
};

ShadowStats measure(const LightmapBakeResult& r, const FloatingBox& f) {
  ShadowStats st;
  for (const LightmapPageResult& page : r.pages)
    for (size_t i = 0; i < page.valid.size(); ++i) {
      if (!page.valid[i]) continue;
      const vec3 p(page.position.pixels[3 * i], page.position.pixels[3 * i + 1],
                   page.position.pixels[3 * i + 2]);
      const float v = texel(page.light, i).x;
      if (f.inShadow(p)) {
        ++st.shadowTexels;
        st.meanShadow += v;
        st.maxShadowError =
            std::max(st.maxShadowError, double(std::abs(v - f.expected())) / f.expected());
      } else if (p.y > 1.49f && std::abs(p.x) < 0.4f && std::abs(p.z) < 0.4f) {
        ++st.topTexels;
        st.maxTopError =
            std::max(st.maxTopError, double(std::abs(v - f.expected())) / f.expected());
      }
    }
  if (st.shadowTexels) st.meanShadow /= double(st.shadowTexels);
  return st;
}

TEST(StaticDynamic, CastShadowsOffLetsTheSunThroughAndKeepsTheLightmap) {
  FloatingBox f;
  auto casting = bakeLightmaps(f.scene, directOnly());
  ASSERT_TRUE(casting.ok()) << casting.error();
  f.scene.objects[f.box].settings.castShadows = false;
  auto ghost = bakeLightmaps(f.scene, directOnly());
  ASSERT_TRUE(ghost.ok()) << ghost.error();

  const ShadowStats on = measure(*casting, f), off = measure(*ghost, f);
  std::printf(
      "castShadows on: %zu shadow texels, mean %.4g; off: mean %.6g (expected %.6g), "
      "max error %.2e\n",
      on.shadowTexels, on.meanShadow, off.meanShadow, f.expected(), off.maxShadowError);
  ASSERT_GT(on.shadowTexels, 20u);
  EXPECT_EQ(on.shadowTexels, off.shadowTexels);
  EXPECT_EQ(on.meanShadow, 0.0);  // the control: fully in the umbra, no indirect light
  EXPECT_LT(off.maxShadowError, 1e-5);
  // Still lightmapped, and its own top face lit as any other surface.
  EXPECT_GE(ghost->layout.objects[f.box].lightmapIndex, 0);
  ASSERT_GT(off.topTexels, 20u);
  EXPECT_LT(off.maxTopError, 1e-5);
}

TEST(StaticDynamic, CastShadowsOffStillBouncesAndBlocksTheSky) {
  // With one bounce and a sky, the ground under a castShadows-false box gets the full sun
  // (direct, noiseless) plus sky light reduced by the box (it still blocks the sky's rays)
  // plus light bounced off the box's sunlit sides. Compare against the same scene without
  // the box: the difference must be far outside the noise measured between two seeds.
  FloatingBox f;
  f.scene.objects[f.box].settings.castShadows = false;
  f.scene.sky = Sky::constant(vec3(0.5f));
  LightmapBakeSettings s = directOnly();
  s.bounces = 1;
  s.samplesPerTexel = 64;
  s.denoise = false;
  auto ghost = bakeLightmaps(f.scene, s);
  Scene open = f.scene;
  open.objects[f.box].settings.isStatic = false;  // out of the bake: as if absent
  auto none = bakeLightmaps(open, s);
  s.seed = 1;
  auto noneOtherSeed = bakeLightmaps(open, s);
  ASSERT_TRUE(ghost.ok() && none.ok() && noneOtherSeed.ok());
  // Mean over the ground texels of the shadow region (selected by position: the layouts
  // differ, the box being lightmapped in one only).
  // Mean red light over the valid texels whose position `where` selects (-1 when none).
  auto meanWhere = [](const LightmapBakeResult& r, auto where) {
    double sum = 0.0;
    size_t n = 0;
    for (const LightmapPageResult& page : r.pages)
      for (size_t i = 0; i < page.valid.size(); ++i) {
        const vec3 p(page.position.pixels[3 * i], page.position.pixels[3 * i + 1],
                     page.position.pixels[3 * i + 2]);
        if (page.valid[i] && where(p)) {
          sum += texel(page.light, i).x;
          ++n;
        }
      }
    return n ? sum / double(n) : -1.0;
  };
  auto meanUnder = [&](const LightmapBakeResult& r) {
    return meanWhere(r, [&](vec3 p) { return f.inShadow(p); });
  };
  const double g = meanUnder(*ghost), o = meanUnder(*none), o2 = meanUnder(*noneOtherSeed);
  const double noise = std::abs(o - o2);
  std::printf(
      "under the box: castShadows off %.5f, no box %.5f (other seed %.5f), sun alone %.5f\n", g, o,
      o2, f.expected());
  // Sun alone is a floor for all of them (direct is exact, the rest >= 0).
  EXPECT_GT(g, f.expected());
  EXPECT_GT(o, f.expected());
  // The box takes sky light away (a box 0.5 m above, 1 m wide, hides a large part of the
  // hemisphere) more than it bounces back: the texels under it are darker than with no box.
  EXPECT_GT(std::abs(g - o), 20.0 * noise + 1e-4);
  EXPECT_LT(g, o);

  // Without the sky, the only light on the ground beside the box's sunlit -x face (the sun
  // comes from -x), beyond the exact sun, is what that face bounces down: it still bounces.
  // Without the box that excess is exactly 0 (a plane sees nothing of itself).
  f.scene.sky = Sky::constant(vec3(0.0f));
  open.sky = Sky::constant(vec3(0.0f));
  s.seed = 0;
  auto ghostNoSky = bakeLightmaps(f.scene, s);
  auto noneNoSky = bakeLightmaps(open, s);
  ASSERT_TRUE(ghostNoSky.ok() && noneNoSky.ok());
  auto meanBeside = [&](const LightmapBakeResult& r) {
    return meanWhere(r, [](vec3 p) {
      return p.y < 0.01f && p.x > -1.2f && p.x < -0.6f && std::abs(p.z) < 0.4f;
    });
  };
  const double bounced = meanBeside(*ghostNoSky) - f.expected();
  std::printf("no sky, beside the box: castShadows off %.5f, no box %.5f: bounced %.5f\n",
              meanBeside(*ghostNoSky), meanBeside(*noneNoSky), bounced);
  EXPECT_NEAR(meanBeside(*noneNoSky), f.expected(), 1e-5 * f.expected());
  EXPECT_GT(bounced, 0.01 * f.expected());
}

TEST(StaticDynamic, BakedShadowsOffIgnoresOcclusion) {
  FloatingBox f;
  f.scene.lights[0].bakedShadows = false;
  auto r = bakeLightmaps(f.scene, directOnly());
  ASSERT_TRUE(r.ok()) << r.error();
  const ShadowStats st = measure(*r, f);
  std::printf("bakedShadows off: %zu shadow texels, max error %.2e\n", st.shadowTexels,
              st.maxShadowError);
  ASSERT_GT(st.shadowTexels, 20u);
  EXPECT_LT(st.maxShadowError, 1e-5);

  // A point light in the integrator, at a point under the box: E = I cos / d^2 exactly with
  // bakedShadows false, 0 with it on; realtime lights and the preview's run-time evaluation
  // keep their shadows.
  Scene scene = f.scene;
  scene.lights.clear();
  scene.lights.push_back(test::pointLight(vec3(0.2f, 3.0f, 0.1f), 9.0f));
  const vec3 p(0.0f, 0.0f, 0.0f), n(0, 1, 0);
  const vec3 d = scene.lights[0].position - p;
  const float expected = 9.0f * (d.y / glm::length(d)) / glm::dot(d, d);
  auto tracer = Tracer::create(scene);
  ASSERT_TRUE(tracer.ok());
  IntegratorSettings is;
  is.maxBounces = 0;
  {
    const Integrator shadowed(scene, **tracer, is);
    EXPECT_EQ(shadowed.irradiance(p, n, 7, 0, 4).direct.x, 0.0f);
  }
  scene.lights[0].bakedShadows = false;
  {
    const Integrator open(scene, **tracer, is);
    EXPECT_NEAR(open.irradiance(p, n, 7, 0, 4).direct.x, expected, 1e-6f * expected);
    EXPECT_EQ(open.lightVisibility(p, n, 0, 7, 0), vec3(1.0f));  // shadowmask / probe occlusion
    IntegratorSettings runtime = is;
    runtime.honourBakedShadows = false;
    const Integrator preview(scene, **tracer, runtime);
    EXPECT_EQ(preview.lightVisibility(p, n, 0, 7, 0), vec3(0.0f));
  }
  scene.lights[0].mode = LightMode::Realtime;
  {
    const Integrator realtime(scene, **tracer, is);
    EXPECT_EQ(realtime.lightVisibility(p, n, 0, 7, 0), vec3(0.0f));
  }
}

// ---- loader -------------------------------------------------------------------------------

// two_rooms.gltf copied into `dir` (with its .bin), its JSON edited by `edit`.
template <typename Edit>
std::string editedTwoRooms(const std::string& dir, Edit edit) {
  const std::string src = test::scenesDir() + "/two_rooms";
  fs::copy_file(src + ".bin", dir + "/two_rooms.bin", fs::copy_options::overwrite_existing);
  Json doc = Json::parse(test::readTextFile(src + ".gltf"));
  edit(doc);
  const std::string path = dir + "/two_rooms.gltf";
  test::writeTextFile(path, doc.dump(1));
  return path;
}

bool hasWarning(const Scene& s, const std::string& text) {
  for (const std::string& w : s.warnings)
    if (w.find(text) != std::string::npos) return true;
  return false;
}

int nodeNamed(const Json& doc, const std::string& name) {
  for (size_t i = 0; i < doc["nodes"].size(); ++i)
    if (doc["nodes"][i].value("name", "") == name) return int(i);
  return -1;
}

TEST(StaticDynamic, LoaderReadsTheSwitchesAndNamesUnknownKeys) {
  const std::string dir = test::makeTempDir("kiln_static_dynamic");
  const std::string path = editedTwoRooms(dir, [](Json& doc) {
    Json& table = doc["nodes"][size_t(nodeNamed(doc, "table_A"))];
    table["extras"]["kiln"] = {{"castShadows", false}, {"castShadow", true}};
    Json& light = doc["extensions"]["KHR_lights_punctual"]["lights"][0];
    light["extras"]["kiln"]["bakedShadows"] = false;
    light["extras"]["kiln"]["bakedShadow"] = 1;
    doc["scenes"][0]["extras"]["kiln"]["bounce"] = 2;
  });
  Result<Scene> s = loadScene(path);
  ASSERT_TRUE(s.ok()) << s.error();
  const Object* table = nullptr;
  for (const Object& o : s->objects)
    if (o.name == "table_A") table = &o;
  ASSERT_NE(table, nullptr);
  EXPECT_FALSE(table->settings.castShadows);
  for (const Object& o : s->objects)
    if (&o != table) {
      EXPECT_TRUE(o.settings.castShadows) << o.name;
    }
  ASSERT_EQ(s->lights.size(), 1u);
  EXPECT_FALSE(s->lights[0].bakedShadows);
  const std::string t = std::to_string(nodeNamed(Json::parse(test::readTextFile(path)), "table_A"));
  for (const std::string& w : s->warnings) std::printf("warning: %s\n", w.c_str());
  EXPECT_TRUE(
      hasWarning(*s, path + ": nodes[" + t + "].extras.kiln: unknown key 'castShadow' ignored"));
  EXPECT_TRUE(hasWarning(*s, path + ": extensions.KHR_lights_punctual.lights[0].extras.kiln: "
                                    "unknown key 'bakedShadow' ignored"));
  EXPECT_TRUE(hasWarning(*s, path + ": scenes[0].extras.kiln: unknown key 'bounce' ignored"));
  EXPECT_EQ(s->warnings.size(), 3u);

  // Wrong types are errors naming the key.
  const std::string bad = editedTwoRooms(dir, [](Json& doc) {
    doc["nodes"][0]["extras"]["kiln"] = {{"castShadows", "no"}};
  });
  Result<Scene> e = loadScene(bad);
  ASSERT_FALSE(e.ok());
  EXPECT_NE(e.error().find("nodes[0].extras.kiln.castShadows: must be true or false"),
            std::string::npos)
      << e.error();
  const std::string badLight = editedTwoRooms(dir, [](Json& doc) {
    doc["extensions"]["KHR_lights_punctual"]["lights"][0]["extras"]["kiln"]["bakedShadows"] = 0;
  });
  e = loadScene(badLight);
  ASSERT_FALSE(e.ok());
  EXPECT_NE(e.error().find("lights[0].extras.kiln.bakedShadows: must be true or false"),
            std::string::npos)
      << e.error();
  fs::remove_all(dir);
}

TEST(StaticDynamic, RootExtrasKilnIsReportedAsIgnored) {
  const std::string dir = test::makeTempDir("kiln_static_dynamic");
  const std::string path = editedTwoRooms(dir, [](Json& doc) {
    doc["extras"]["kiln"] = {{"bounces", 5}, {"sky", {{"color", {1, 1, 1}}}}};
  });
  Result<Scene> s = loadScene(path);
  ASSERT_TRUE(s.ok()) << s.error();
  ASSERT_EQ(s->warnings.size(), 1u);
  EXPECT_EQ(s->warnings[0], path +
                                ": extras.kiln: root extras.kiln is ignored ('bounces', "
                                "'sky'); put scene settings in scenes[0].extras.kiln");
  EXPECT_EQ(s->settings.bounces, std::optional<int>(3));  // the scene's, untouched

  // The key kiln bake writes there itself is no setting: no warning.
  const std::string own = editedTwoRooms(dir, [](Json& doc) {
    doc["extras"]["kiln"] = {{"lightmaps", Json::array()}};
  });
  s = loadScene(own);
  ASSERT_TRUE(s.ok()) << s.error();
  EXPECT_TRUE(s->warnings.empty());
  fs::remove_all(dir);
}

// kiln bake's output glTF carries extras.kiln it writes itself (root lightmaps, node
// lightmap, light baked/mode): loading it warns about nothing.
TEST(StaticDynamic, OwnOutputGltfLoadsWithoutWarnings) {
  const std::string dir = test::makeTempDir("kiln_static_dynamic");
  std::string output;
  const std::string cmd = std::string(test::kilnExe()) + " bake " + test::scenesDir() +
                          "/two_rooms.gltf --out " + dir +
                          "/out --preset preview --resolution 2 "
                          "--lighting-mode shadowmask 2>&1";
  ASSERT_EQ(test::runCommand(cmd, &output), 0) << output;
  std::string gltf;
  for (const auto& entry : fs::recursive_directory_iterator(dir + "/out"))
    if (entry.path().extension() == ".gltf") gltf = entry.path().string();
  ASSERT_FALSE(gltf.empty()) << output;
  const Json doc = Json::parse(test::readTextFile(gltf));
  ASSERT_TRUE(doc["extras"]["kiln"].contains("lightmaps"));
  Result<Scene> s = loadScene(gltf);
  ASSERT_TRUE(s.ok()) << s.error();
  for (const std::string& w : s->warnings) ADD_FAILURE() << w;
  fs::remove_all(dir);
}

}  // namespace
}  // namespace kiln
