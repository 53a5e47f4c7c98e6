// lightmap_texels_test.cpp: what a baked texel may hold (lightmap/lightmap_baker.h): never a
// negative value (thin double-sided geometry under sun and sky, with and without the
// denoiser), validity on double-sided geometry (a closed double-sided box on a double-sided
// floor), and ambient occlusion applied to the light map (--ao-amount).
#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>

#include "lightmap/lightmap_baker.h"
#include "tests/test_util.h"

namespace kiln {
namespace {

size_t negativeTexels(const LightmapBakeResult& r, float* lowest = nullptr) {
  size_t count = 0;
  float lo = 0.0f;
  for (const LightmapPageResult& page : r.pages)
    for (size_t t = 0; t < page.light.pixels.size() / 3; ++t) {
      bool negative = false;
      for (int c = 0; c < 3; ++c) {
        const float v = page.light.pixels[3 * t + size_t(c)];
        if (v < 0.0f) negative = true;
        lo = std::min(lo, v);
      }
      count += negative ? 1 : 0;
    }
  if (lowest) *lowest = lo;
  return count;
}

// A closed cylinder (chair leg, pole) of `segments` sides with smooth side normals and no
// lightmap UVs: kiln unwraps it, and the side's charts meet at smooth seams, one side lit by
// the sun and the other dark.
uint32_t addCylinder(Scene& scene, const std::string& name, vec3 base, float radius,
                     float height, int segments, uint32_t material) {
  Object o;
  o.name = name;
  o.nodeIndex = int(scene.objects.size());
  for (int i = 0; i < segments; ++i) {
    const float phi = 2.0f * kPi * float(i) / float(segments);
    const vec3 n(std::cos(phi), 0.0f, -std::sin(phi));
    o.positions.push_back(base + radius * n);
    o.positions.push_back(base + radius * n + vec3(0, height, 0));
    o.normals.push_back(n);
    o.normals.push_back(n);
  }
  for (int i = 0; i < segments; ++i) {
    const uint32_t a = uint32_t(2 * i), b = uint32_t(2 * ((i + 1) % segments));
    o.triangles.push_back({a, b, b + 1});
    o.triangles.push_back({a, b + 1, a + 1});
  }
  // Caps (flat normals: their own vertices).
  for (int cap = 0; cap < 2; ++cap) {
    const uint32_t first = uint32_t(o.positions.size());
    const vec3 n(0.0f, cap ? 1.0f : -1.0f, 0.0f);
    for (int i = 0; i < segments; ++i) {
      o.positions.push_back(o.positions[size_t(2 * i + cap)]);
      o.normals.push_back(n);
    }
    for (int i = 1; i + 1 < segments; ++i) {
      if (cap)
        o.triangles.push_back({first, first + uint32_t(i), first + uint32_t(i + 1)});
      else
        o.triangles.push_back({first, first + uint32_t(i + 1), first + uint32_t(i)});
    }
  }
  o.triangleMaterial.assign(o.triangles.size(), material);
  scene.objects.push_back(std::move(o));
  scene.updateBounds();
  return uint32_t(scene.objects.size() - 1);
}

// A sunlit floor with what produced negative texels on real scenes: thin double-sided
// chair legs (boxes 3 cm wide) and poles (smooth cylinders 2 to 8 cm wide, their
// lightmap UVs generated: seams between a lit and a dark side), a window blind of double-sided slats 2 cm apart, and a thin
// double-sided roof sheet over part of it, under a sun and a blue sky.
Scene thinGeometryScene() {
  Scene scene;
  const uint32_t floor = test::addMaterial(scene, test::lambert(vec3(0.6f)));
  const uint32_t thin = test::addMaterial(scene, test::lambert(vec3(0.8f, 0.7f, 0.5f), vec3(0.0f), true));
  test::addQuad(scene, "floor", vec3(-2, 0, 2), vec3(2, 0, 2), vec3(2, 0, -2), vec3(-2, 0, -2), floor);
  for (int i = 0; i < 4; ++i) {
    const float x = -1.0f + 0.6f * float(i);
    test::addBox(scene, "leg" + std::to_string(i), vec3(x, 0.0f, -0.5f), vec3(x + 0.03f, 0.8f, -0.47f),
                 thin, false);
  }
  for (int i = 0; i < 4; ++i)
    addCylinder(scene, "pole" + std::to_string(i), vec3(-1.0f + 0.6f * float(i), 0.0f, 0.8f),
                0.02f + 0.02f * float(i), 1.0f, 12, thin);
  for (int i = 0; i < 12; ++i) {
    const float y = 0.3f + 0.02f * float(i);
    // Slats tilted 30 degrees, overlapping in projection.
    test::addQuad(scene, "slat" + std::to_string(i), vec3(0.5f, y, 0.5f), vec3(1.5f, y, 0.5f),
                  vec3(1.5f, y + 0.015f, 0.474f), vec3(0.5f, y + 0.015f, 0.474f), thin);
  }
  test::addQuad(scene, "roof", vec3(-1.5f, 1.2f, 1.5f), vec3(0.0f, 1.2f, 1.5f),
                vec3(0.0f, 1.2f, 0.0f), vec3(-1.5f, 1.2f, 0.0f), thin);
  scene.lights.push_back(test::directionalLight(glm::normalize(vec3(0.4f, -1.0f, -0.3f)), 20.0f));
  scene.sky = Sky::constant(vec3(0.3f, 0.45f, 0.8f));
  return scene;
}

LightmapBakeSettings thinSettings(bool denoise) {
  LightmapBakeSettings s;
  s.resolution = 32.0f;
  s.maxSize = 512;
  s.samplesPerTexel = 16;
  s.denoise = denoise;
  return s;
}

TEST(LightmapTexels, ThinDoubleSidedGeometryBakesNoNegativeTexel) {
  const Scene scene = thinGeometryScene();
  for (bool denoise : {true, false}) {
    auto r = bakeLightmaps(scene, thinSettings(denoise));
    ASSERT_TRUE(r.ok()) << r.error();
    float lowest = 0.0f;
    const size_t negative = negativeTexels(*r, &lowest);
    std::printf("denoise %d: %zu texels, %zu invalid, %zu clamped, %zu negative (lowest %g)\n",
                int(denoise), r->stats.texels, r->stats.invalidTexels, r->stats.clampedTexels,
                negative, lowest);
    EXPECT_EQ(negative, 0u);
    // Nothing reached the final guard: every stage keeps values >= 0 by itself.
    EXPECT_EQ(r->stats.clampedTexels, 0u);
  }
}

// A 2 m floor with a closed box 0.2 m wide and 0.1 m high standing on it (its bottom face on the floor), both
// double-sided or both single-sided, under a sun and a sky.
Scene boxOnFloor(bool doubleSided) {
  Scene scene;
  const uint32_t m = test::addMaterial(scene, test::lambert(vec3(0.6f), vec3(0.0f), doubleSided));
  test::addQuad(scene, "floor", vec3(-1, 0, 1), vec3(1, 0, 1), vec3(1, 0, -1), vec3(-1, 0, -1), m);
  test::addBox(scene, "box", vec3(-0.1f, 0.0f, -0.1f), vec3(0.1f, 0.1f, 0.1f), m, false);
  scene.lights.push_back(test::directionalLight(glm::normalize(vec3(0.3f, -1.0f, 0.2f)), 10.0f));
  scene.sky = Sky::constant(vec3(0.4f));
  return scene;
}

struct FloorValidity {
  size_t under = 0, underInvalid = 0;       // floor texels well inside the box's footprint
  size_t outside = 0, outsideValid = 0;     // floor texels well outside it
  size_t outsideZero = 0;                   // of those, baked to exactly 0
};

FloorValidity floorValidity(const Scene& scene, float enclosedTexels = 8.0f) {
  LightmapBakeSettings s;
  s.enclosedTexels = enclosedTexels;
  s.resolution = 32.0f;
  s.maxSize = 256;
  s.samplesPerTexel = 16;
  auto r = bakeLightmaps(scene, s);
  EXPECT_TRUE(r.ok()) << r.error();
  FloorValidity f;
  if (!r.ok()) return f;
  // The floor's texels: its atlas rectangle (uv1 = the unit square).
  const AtlasObject& floor = r->layout.objects[0];
  const LightmapPageResult& page = r->pages[size_t(floor.lightmapIndex)];
  const int w = page.light.width, h = page.light.height;
  const vec4 so = floor.scaleOffset;
  const float texel = 1.0f / 32.0f;
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x) {
      const vec2 uv = ((vec2(float(x), float(y)) + 0.5f) / vec2(float(w), float(h)) -
                       vec2(so.z, so.w)) / vec2(so.x, so.y);
      if (uv.x <= 0.0f || uv.y <= 0.0f || uv.x >= 1.0f || uv.y >= 1.0f) continue;
      // The floor quad maps u to x = -1 + 2u, v to z = 1 - 2v.
      const vec2 p(-1.0f + 2.0f * uv.x, 1.0f - 2.0f * uv.y);
      const float d = std::max(std::abs(p.x), std::abs(p.y));  // box half-size 0.1
      const size_t t = size_t(y) * size_t(w) + size_t(x);
      if (d < 0.1f - 2.0f * texel) {
        ++f.under;
        f.underInvalid += page.valid[t] ? 0 : 1;
      } else if (d > 0.1f + 2.0f * texel && d < 1.0f - 2.0f * texel) {
        ++f.outside;
        f.outsideValid += page.valid[t] ? 1 : 0;
        if (page.valid[t] && page.light.rgb(x, y) == vec3(0.0f)) ++f.outsideZero;
      }
    }
  return f;
}

TEST(LightmapTexels, FloorUnderAClosedDoubleSidedBoxIsInvalid) {
  for (bool doubleSided : {true, false}) {
    const FloorValidity f = floorValidity(boxOnFloor(doubleSided));
    std::printf("%s: under the box %zu of %zu invalid; outside %zu of %zu valid (%zu zero)\n",
                doubleSided ? "double-sided" : "single-sided", f.underInvalid, f.under,
                f.outsideValid, f.outside, f.outsideZero);
    // 0.2 m at 32 texels/m: 6.4 texels across; 2 texels of margin inside the footprint's
    // edge leave the central 2 x 2. Every point inside the box is within 0.25 m (the
    // default 8 texel edges) of its walls: enclosed.
    EXPECT_EQ(f.under, 4u);
    EXPECT_EQ(f.underInvalid, f.under) << "double-sided " << doubleSided;
    EXPECT_GT(f.outside, 3000u);
    EXPECT_EQ(f.outsideValid, f.outside) << "double-sided " << doubleSided;
    EXPECT_EQ(f.outsideZero, 0u);
  }
  // Without the enclosure test (the back-face test alone), the double-sided floor under the
  // box counts as valid: what the issue saw on the gas station.
  const FloorValidity old = floorValidity(boxOnFloor(true), 0.0f);
  EXPECT_EQ(old.under, 4u);
  EXPECT_EQ(old.underInvalid, 0u);
}

// A 4 m plane with a 1 m box on it under a constant sky: AO applied with amount A makes every
// light texel exactly light_without x (1 - A (1 - ao)), with the AO page written alongside.
TEST(LightmapTexels, AmbientOcclusionAppliedByTheDocumentedFactor) {
  Scene scene;
  const uint32_t m = test::addMaterial(scene, test::lambert(vec3(0.5f)));
  test::addQuad(scene, "plane", vec3(-2, 0, 2), vec3(2, 0, 2), vec3(2, 0, -2), vec3(-2, 0, -2), m);
  test::addBox(scene, "box", vec3(-0.5f, 0.0f, -0.5f), vec3(0.5f, 1.0f, 0.5f), m, false);
  scene.sky = Sky::constant(vec3(1.0f));
  LightmapBakeSettings s;
  s.resolution = 8.0f;
  s.maxSize = 256;
  s.samplesPerTexel = 16;
  s.ambientOcclusion = true;
  s.aoMaxDistance = 0.5f;
  s.aoAmount = 0.0f;  // written, not applied
  auto without = bakeLightmaps(scene, s);
  ASSERT_TRUE(without.ok()) << without.error();
  s.aoAmount = 0.7f;
  auto with = bakeLightmaps(scene, s);
  ASSERT_TRUE(with.ok()) << with.error();
  ASSERT_EQ(with->pages.size(), without->pages.size());
  size_t darker = 0, checked = 0;
  for (size_t p = 0; p < with->pages.size(); ++p) {
    const LightmapPageResult& a = without->pages[p];
    const LightmapPageResult& b = with->pages[p];
    ASSERT_EQ(a.ambientOcclusion.pixels, b.ambientOcclusion.pixels);  // same AO page
    for (size_t t = 0; t < a.valid.size(); ++t) {
      const float ao = b.ambientOcclusion.pixels[t];
      const float factor = 1.0f - 0.7f * (1.0f - ao);
      for (int c = 0; c < 3; ++c)
        EXPECT_EQ(b.light.pixels[3 * t + size_t(c)], a.light.pixels[3 * t + size_t(c)] * factor);
      ++checked;
      // Near the box's foot AO rays of 0.5 m hit the box: noticeably darker.
      if (a.valid[t] && ao < 0.8f && b.light.pixels[3 * t] < 0.95f * a.light.pixels[3 * t])
        ++darker;
    }
  }
  std::printf("AO: %zu texels checked, %zu near the box's foot darker by > 5%%\n", checked,
              darker);
  EXPECT_GT(darker, 50u);
}

TEST(LightmapTexels, AoOptionsAreValidated) {
  const std::string scene = test::scenesDir() + "/cornell_box.gltf";
  for (const std::string& args : {std::string("--ao-amount 1.5"), std::string("--ao-amount -0.1"),
                                  std::string("--ao-distance 0"), std::string("--ao-distance -1")}) {
    std::string output;
    const int code = test::runCommand(std::string(test::kilnExe()) + " bake " + args +
                                          " -o " + test::makeTempDir() + "/out " + scene,
                                      &output);
    EXPECT_EQ(code, 2) << args << ": " << output;
    EXPECT_NE(output.find(args.substr(0, args.find(' '))), std::string::npos) << output;
  }
}

}  // namespace
}  // namespace kiln
