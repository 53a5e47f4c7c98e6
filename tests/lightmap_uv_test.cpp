// lightmap_uv_test.cpp: lightmap UV generation: charts, zero stretch on planar charts,
// bounded stretch on curved ones, no overlaps, determinism.
#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
#include <map>

#include "lightmap/atlas.h"
#include "lightmap/uv_unwrap.h"
#include "tests/test_util.h"

namespace kiln {
namespace {

using glm::dvec2;

double cross2(dvec2 a, dvec2 b) { return a.x * b.y - a.y * b.x; }

// Area of the intersection of two triangles (convex clipping, Sutherland-Hodgman).
double overlapArea(std::array<dvec2, 3> a, std::array<dvec2, 3> b) {
  if (cross2(a[1] - a[0], a[2] - a[0]) < 0) std::swap(a[1], a[2]);
  if (cross2(b[1] - b[0], b[2] - b[0]) < 0) std::swap(b[1], b[2]);
  std::vector<dvec2> poly(a.begin(), a.end());
  for (int e = 0; e < 3 && !poly.empty(); ++e) {
    const dvec2 p = b[e], q = b[(e + 1) % 3];
    std::vector<dvec2> out;
    for (size_t i = 0; i < poly.size(); ++i) {
      const dvec2 s = poly[i], t = poly[(i + 1) % poly.size()];
      const double ds = cross2(q - p, s - p), dt = cross2(q - p, t - p);
      if (ds >= 0) out.push_back(s);
      if ((ds >= 0) != (dt >= 0)) out.push_back(s + (t - s) * (ds / (ds - dt)));
    }
    poly = out;
  }
  double area = 0;
  for (size_t i = 0; i < poly.size(); ++i) area += cross2(poly[i], poly[(i + 1) % poly.size()]);
  return 0.5 * area;
}

std::array<dvec2, 3> uvTriangle(const UnwrapResult& r, size_t t) {
  return {dvec2(r.uv1[r.triangles[t][0]]), dvec2(r.uv1[r.triangles[t][1]]),
          dvec2(r.uv1[r.triangles[t][2]])};
}

// Largest overlap area between any two UV triangles (brute force; meshes are small).
double maxOverlap(const UnwrapResult& r) {
  double worst = 0;
  for (size_t i = 0; i < r.triangles.size(); ++i)
    for (size_t j = i + 1; j < r.triangles.size(); ++j)
      worst = std::max(worst, overlapArea(uvTriangle(r, i), uvTriangle(r, j)));
  return worst;
}

// A UV sphere (latitude-longitude), one object, vertices shared except at the seam column as
// a glTF exporter writes it.
Object makeSphere(int stacks, int slices, float radius) {
  Object o;
  o.name = "sphere";
  for (int i = 0; i <= stacks; ++i) {
    const float theta = kPi * float(i) / float(stacks);
    for (int j = 0; j <= slices; ++j) {
      const float phi = 2.0f * kPi * float(j) / float(slices);
      const vec3 n(std::sin(theta) * std::cos(phi), std::cos(theta),
                   std::sin(theta) * std::sin(phi));
      o.positions.push_back(radius * n);
      o.normals.push_back(n);
    }
  }
  auto idx = [&](int i, int j) { return uint32_t(i * (slices + 1) + j); };
  for (int i = 0; i < stacks; ++i)
    for (int j = 0; j < slices; ++j) {
      // Counter-clockwise seen from outside.
      if (i > 0) o.triangles.push_back(uvec3(idx(i, j), idx(i, j + 1), idx(i + 1, j)));
      if (i < stacks - 1)
        o.triangles.push_back(uvec3(idx(i, j + 1), idx(i + 1, j + 1), idx(i + 1, j)));
    }
  o.triangleMaterial.assign(o.triangles.size(), 0);
  return o;
}

// An open cylinder (side only) of radius r and height h around +Y.
Object makeCylinder(int slices, int rings, float r, float h) {
  Object o;
  o.name = "cylinder";
  for (int i = 0; i <= rings; ++i)
    for (int j = 0; j <= slices; ++j) {
      const float phi = 2.0f * kPi * float(j % slices) / float(slices);
      o.positions.push_back(
          vec3(r * std::cos(phi), h * float(i) / float(rings), r * std::sin(phi)));
      o.normals.push_back(vec3(std::cos(phi), 0, std::sin(phi)));
    }
  auto idx = [&](int i, int j) { return uint32_t(i * (slices + 1) + j); };
  for (int i = 0; i < rings; ++i)
    for (int j = 0; j < slices; ++j) {
      o.triangles.push_back(uvec3(idx(i, j), idx(i + 1, j), idx(i, j + 1)));
      o.triangles.push_back(uvec3(idx(i, j + 1), idx(i + 1, j), idx(i + 1, j + 1)));
    }
  o.triangleMaterial.assign(o.triangles.size(), 0);
  return o;
}

TEST(LightmapUv, BoxGivesSixPlanarChartsWithZeroStretch) {
  Scene scene;
  const uint32_t mat = test::addMaterial(scene, test::lambert(vec3(0.5f)));
  const uint32_t id = test::addBox(scene, "box", vec3(0), vec3(2, 1, 0.5f), mat, false);
  const Object& box = scene.objects[id];
  UnwrapSettings settings;
  settings.texelsPerUnit = 16.0f;
  const Result<UnwrapResult> r = generateLightmapUvs(box, settings);
  ASSERT_TRUE(r.ok()) << r.error();
  EXPECT_EQ(r->stats.chartCount, 6);
  EXPECT_EQ(r->stats.planarCharts, 6);
  EXPECT_EQ(r->stats.flippedTriangles, 0);
  EXPECT_EQ(r->triangles.size(), box.triangles.size());
  // Each face keeps its 4 vertices (the box already splits them per face).
  EXPECT_EQ(r->vertexRemap.size(), 24u);
  // Zero stretch: every UV edge is its world edge divided by worldPerUv.
  for (size_t t = 0; t < r->triangles.size(); ++t)
    for (int k = 0; k < 3; ++k) {
      const uint32_t a = r->triangles[t][k], b = r->triangles[t][(k + 1) % 3];
      const double world =
          glm::length(box.positions[r->vertexRemap[a]] - box.positions[r->vertexRemap[b]]);
      const double uv = glm::length(dvec2(r->uv1[a]) - dvec2(r->uv1[b])) * r->worldPerUv;
      EXPECT_NEAR(uv, world, 1e-5 * world) << "triangle " << t << " edge " << k;
    }
  EXPECT_NEAR(r->stats.l2Stretch, 1.0, 1e-5);
  EXPECT_NEAR(r->stats.maxAnisotropy, 1.0, 1e-5);
  EXPECT_EQ(maxOverlap(*r), 0.0);
  // Everything inside the unit square, the longer extent exactly 1.
  vec2 hi(0.0f);
  for (vec2 uv : r->uv1) {
    EXPECT_GE(uv.x, 0.0f);
    EXPECT_GE(uv.y, 0.0f);
    hi = glm::max(hi, uv);
  }
  EXPECT_FLOAT_EQ(std::max(hi.x, hi.y), 1.0f);
  // Total UV area x worldPerUv^2 == world area (2*(2*1 + 2*0.5 + 1*0.5) = 7).
  double uvArea = 0;
  for (size_t t = 0; t < r->triangles.size(); ++t) {
    const auto tri = uvTriangle(*r, t);
    uvArea += 0.5 * cross2(tri[1] - tri[0], tri[2] - tri[0]);
  }
  EXPECT_NEAR(uvArea * r->worldPerUv * r->worldPerUv, 7.0, 1e-4);
  // Gutter: charts at least gutterTexels apart at the expected density. Charts are
  // axis-aligned rectangles here, so compare their UV bounding boxes.
  std::map<uint32_t, std::pair<dvec2, dvec2>> boxes;
  for (size_t t = 0; t < r->triangles.size(); ++t)
    for (int k = 0; k < 3; ++k) {
      const dvec2 uv(r->uv1[r->triangles[t][k]]);
      auto [it, fresh] = boxes.emplace(r->triangleChart[t], std::make_pair(uv, uv));
      it->second.first = glm::min(it->second.first, uv);
      it->second.second = glm::max(it->second.second, uv);
    }
  ASSERT_EQ(boxes.size(), 6u);
  const double texel = 1.0 / (settings.texelsPerUnit * r->worldPerUv);  // in UV
  for (auto& [ci, a] : boxes)
    for (auto& [cj, b] : boxes) {
      if (ci >= cj) continue;
      const double gapU = std::max(b.first.x - a.second.x, a.first.x - b.second.x);
      const double gapV = std::max(b.first.y - a.second.y, a.first.y - b.second.y);
      EXPECT_GE(std::max(gapU, gapV), settings.gutterTexels * texel * (1 - 1e-5));
    }
  std::printf("box: %d charts, packing efficiency %.3f\n", r->stats.chartCount,
              r->stats.packingEfficiency);
}

TEST(LightmapUv, WeldsSplitVerticesAndSplitsAtChartSeams) {
  // The sphere's vertices are shared within rows; the unwrap splits them only at chart
  // borders, and every new vertex maps back to an original at the same position.
  const Object sphere = makeSphere(12, 24, 1.0f);
  const Result<UnwrapResult> r = generateLightmapUvs(sphere, UnwrapSettings{});
  ASSERT_TRUE(r.ok()) << r.error();
  EXPECT_GT(r->vertexRemap.size(), sphere.positions.size() - 13);  // seam column removed
  for (size_t t = 0; t < r->triangles.size(); ++t)
    for (int k = 0; k < 3; ++k)
      EXPECT_EQ(r->vertexRemap[r->triangles[t][k]], sphere.triangles[t][k]);
  const Object rebuilt = applyUnwrap(sphere, *r);
  EXPECT_EQ(rebuilt.positions.size(), rebuilt.uv1.size());
  EXPECT_EQ(rebuilt.normals.size(), rebuilt.uv1.size());
  EXPECT_NEAR(rebuilt.surfaceArea(), sphere.surfaceArea(), 1e-5);
}

TEST(LightmapUv, SphereHasNoFlipsNoOverlapsAndBoundedStretch) {
  const Object sphere = makeSphere(16, 32, 1.0f);
  const Result<UnwrapResult> r = generateLightmapUvs(sphere, UnwrapSettings{});
  ASSERT_TRUE(r.ok()) << r.error();
  EXPECT_EQ(r->stats.flippedTriangles, 0);
  EXPECT_EQ(r->stats.degenerateTriangles, 0);
  EXPECT_LT(maxOverlap(*r), 1e-12);
  // 60-degree cones around each chart's mean normal: a chart spans up to about 120 degrees
  // of arc, so a sphere needs at least 4 charts (a cube's 6 at 90 degrees) and few more.
  EXPECT_GE(r->stats.chartCount, 4);
  EXPECT_LE(r->stats.chartCount, 12);
  EXPECT_LT(r->stats.l2Stretch, 1.1);
  EXPECT_LT(r->stats.maxAnisotropy, 1.5);
  EXPECT_LT(r->stats.maxAreaDistortion, 2.0);
  std::printf(
      "sphere 16x32: %d charts (%d planar), L2 stretch %.4f, max anisotropy %.3f, "
      "max area distortion %.3f, packing efficiency %.3f\n",
      r->stats.chartCount, r->stats.planarCharts, r->stats.l2Stretch, r->stats.maxAnisotropy,
      r->stats.maxAreaDistortion, r->stats.packingEfficiency);
}

TEST(LightmapUv, CylinderIsDevelopableSoLscmIsNearIsometric) {
  const Object cylinder = makeCylinder(24, 4, 0.5f, 2.0f);
  const Result<UnwrapResult> r = generateLightmapUvs(cylinder, UnwrapSettings{});
  ASSERT_TRUE(r.ok()) << r.error();
  EXPECT_EQ(r->stats.flippedTriangles, 0);
  EXPECT_LT(maxOverlap(*r), 1e-12);
  // Charts of at most 120 degrees of arc (mean normal +-60 degrees): 3 for 24 slices, a
  // fourth at most when growth leaves a short one that cannot merge.
  EXPECT_GE(r->stats.chartCount, 3);
  EXPECT_LE(r->stats.chartCount, 4);
  // A cylinder's facets unfold exactly: LSCM finds the isometry up to float error.
  EXPECT_NEAR(r->stats.l2Stretch, 1.0, 1e-3);
  EXPECT_LT(r->stats.maxAnisotropy, 1.01);
  std::printf("cylinder 24x4: %d charts, L2 stretch %.5f, max anisotropy %.4f, packing %.3f\n",
              r->stats.chartCount, r->stats.l2Stretch, r->stats.maxAnisotropy,
              r->stats.packingEfficiency);
}

TEST(LightmapUv, DeterministicAndRejectsBadInput) {
  const Object sphere = makeSphere(8, 16, 2.0f);
  const auto a = generateLightmapUvs(sphere, UnwrapSettings{});
  const auto b = generateLightmapUvs(sphere, UnwrapSettings{});
  ASSERT_TRUE(a.ok() && b.ok());
  EXPECT_EQ(a->triangles, b->triangles);
  EXPECT_EQ(a->vertexRemap, b->vertexRemap);
  ASSERT_EQ(a->uv1.size(), b->uv1.size());
  for (size_t i = 0; i < a->uv1.size(); ++i) EXPECT_EQ(a->uv1[i], b->uv1[i]);

  Object empty;
  empty.name = "Empty";
  const auto e = generateLightmapUvs(empty, UnwrapSettings{});
  ASSERT_FALSE(e.ok());
  EXPECT_NE(e.error().find("Empty"), std::string::npos);
  UnwrapSettings bad;
  bad.texelsPerUnit = 0.0f;
  const auto f = generateLightmapUvs(sphere, bad);
  ASSERT_FALSE(f.ok());
  EXPECT_NE(f.error().find("texelsPerUnit"), std::string::npos);
}

TEST(LightmapUv, DegenerateTrianglesCollapseWithoutBreakingCharts) {
  Scene scene;
  test::addQuad(scene, "quad", vec3(0, 0, 0), vec3(1, 0, 0), vec3(1, 0, -1), vec3(0, 0, -1), 0);
  Object quad = scene.objects[0];
  // A zero-area triangle on the quad's edge.
  quad.positions.push_back(vec3(0.5f, 0, 0));
  quad.triangles.push_back(uvec3(0, 1, 4));
  quad.triangleMaterial.push_back(0);
  const auto r = generateLightmapUvs(quad, UnwrapSettings{});
  ASSERT_TRUE(r.ok()) << r.error();
  EXPECT_EQ(r->stats.chartCount, 1);
  EXPECT_EQ(r->stats.degenerateTriangles, 1);
  EXPECT_EQ(r->stats.flippedTriangles, 0);
}

TEST(LightmapUv, SceneUnwrapFillsOnlyMissingLightmapUvs) {
  Scene scene;
  const uint32_t mat = test::addMaterial(scene, test::lambert(vec3(0.5f)));
  const uint32_t given = test::addBox(scene, "given", vec3(0), vec3(1), mat, false);
  const uint32_t missing = test::addBox(scene, "missing", vec3(2, 0, 0), vec3(3, 2, 1), mat, false);
  const uint32_t dark = test::addBox(scene, "dark", vec3(4, 0, 0), vec3(5, 1, 1), mat, false);
  scene.objects[missing].uv1.clear();
  scene.objects[dark].uv1.clear();
  scene.objects[dark].settings.scaleInLightmap = 0.0f;
  scene.objects[missing].settings.scaleInLightmap = 2.0f;
  const std::vector<vec2> givenUv = scene.objects[given].uv1;
  UnwrapSettings settings;
  settings.gutterTexels = 3;
  const auto r = generateMissingLightmapUvs(scene, 8.0f, settings);
  ASSERT_TRUE(r.ok()) << r.error();
  ASSERT_EQ(r->size(), 3u);
  EXPECT_FALSE((*r)[given].has_value());
  EXPECT_FALSE((*r)[dark].has_value());
  ASSERT_TRUE((*r)[missing].has_value());
  EXPECT_EQ((*r)[missing]->stats.chartCount, 6);
  EXPECT_EQ(scene.objects[given].uv1, givenUv);
  EXPECT_TRUE(scene.objects[dark].uv1.empty());
  const Object& m = scene.objects[missing];
  EXPECT_EQ(m.uv1.size(), m.positions.size());
  EXPECT_EQ(m.normals.size(), m.positions.size());
  EXPECT_EQ(m.triangleMaterial.size(), m.triangles.size());
  // The same object unwrapped alone at 8 x 2 texels per unit gives the same UVs.
  Scene again;
  test::addMaterial(again, test::lambert(vec3(0.5f)));
  test::addBox(again, "missing", vec3(2, 0, 0), vec3(3, 2, 1), 0, false);
  UnwrapSettings alone = settings;
  alone.texelsPerUnit = 16.0f;
  const auto single = generateLightmapUvs(again.objects[0], alone);
  ASSERT_TRUE(single.ok());
  EXPECT_EQ(single->uv1, m.uv1);
}

}  // namespace
}  // namespace kiln
