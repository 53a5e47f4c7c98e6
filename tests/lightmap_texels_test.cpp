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

}  // namespace
}  // namespace kiln
