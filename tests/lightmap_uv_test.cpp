// lightmap_uv_test.cpp: lightmap UV generation: charts, zero stretch on planar charts,
// bounded stretch on curved ones, no overlaps, determinism.
#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
#include <map>

#include "lightmap/atlas.h"
#include "lightmap/sealed_surfaces.h"
#include "lightmap/texel_raster.h"
#include "lightmap/uv_unwrap.h"
#include "src/tracer.h"
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

// Whether a UV triangle (texel units) and the texel square [x, x+1] x [y, y+1] overlap with
// positive area (separating axis test over the square's axes and the triangle's edges).
bool triangleTouchesTexel(const std::array<dvec2, 3>& t, int x, int y) {
  const double lx = std::min({t[0].x, t[1].x, t[2].x}), hx = std::max({t[0].x, t[1].x, t[2].x});
  const double ly = std::min({t[0].y, t[1].y, t[2].y}), hy = std::max({t[0].y, t[1].y, t[2].y});
  if (hx <= x || lx >= x + 1 || hy <= y || ly >= y + 1) return false;
  const dvec2 box[4] = {dvec2(x, y), dvec2(x + 1, y), dvec2(x + 1, y + 1), dvec2(x, y + 1)};
  const double o = cross2(t[1] - t[0], t[2] - t[0]) >= 0 ? 1.0 : -1.0;
  for (int e = 0; e < 3; ++e) {
    bool outside = true;
    for (const dvec2& p : box)
      if (o * cross2(t[(e + 1) % 3] - t[e], p - t[e]) > 1e-9) outside = false;
    if (outside) return false;
  }
  return true;
}

// Rasterizes every chart into texels at the unwrap's density (conservatively: every texel a
// triangle touches) and checks the packing's identities: no texel touched by two charts, at
// least `gutter` empty texels between two charts (Chebyshev distance > gutter), every UV in
// [0, 1]. Returns the number of touched texels.
size_t expectChartsApart(const UnwrapResult& r, float texelsPerUnit, int gutter) {
  const double s = texelsPerUnit * r.worldPerUv;  // texels per UV unit
  const int n = int(std::ceil(s)) + 1;
  std::vector<int64_t> owner(size_t(n) * size_t(n), -1);
  size_t shared = 0, touched = 0;
  for (vec2 uv : r.uv1) {
    EXPECT_TRUE(uv.x >= 0.0f && uv.x <= 1.0f && uv.y >= 0.0f && uv.y <= 1.0f);
  }
  for (size_t t = 0; t < r.triangles.size(); ++t) {
    std::array<dvec2, 3> p = uvTriangle(r, t);
    for (dvec2& q : p) q *= s;
    if (cross2(p[1] - p[0], p[2] - p[0]) == 0.0) continue;  // degenerate: no texels
    const int x0 = int(std::floor(std::min({p[0].x, p[1].x, p[2].x})));
    const int x1 = int(std::ceil(std::max({p[0].x, p[1].x, p[2].x})));
    const int y0 = int(std::floor(std::min({p[0].y, p[1].y, p[2].y})));
    const int y1 = int(std::ceil(std::max({p[0].y, p[1].y, p[2].y})));
    for (int y = std::max(0, y0); y < std::min(n, y1); ++y)
      for (int x = std::max(0, x0); x < std::min(n, x1); ++x) {
        if (!triangleTouchesTexel(p, x, y)) continue;
        int64_t& o = owner[size_t(y) * size_t(n) + size_t(x)];
        if (o >= 0 && o != int64_t(r.triangleChart[t])) ++shared;
        if (o < 0) ++touched;
        o = r.triangleChart[t];
      }
  }
  EXPECT_EQ(shared, 0u);
  size_t tooClose = 0;
  for (int y = 0; y < n; ++y)
    for (int x = 0; x < n; ++x) {
      const int64_t a = owner[size_t(y) * size_t(n) + size_t(x)];
      if (a < 0) continue;
      for (int dy = -gutter; dy <= gutter; ++dy)
        for (int dx = -gutter; dx <= gutter; ++dx) {
          const int xx = x + dx, yy = y + dy;
          if (xx < 0 || yy < 0 || xx >= n || yy >= n) continue;
          const int64_t b = owner[size_t(yy) * size_t(n) + size_t(xx)];
          if (b >= 0 && b != a) ++tooClose;
        }
    }
  EXPECT_EQ(tooClose, 0u);
  return touched;
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

TEST(LightmapUv, DenseSphereGivesFewChartsWithinTheStretchBoundAndApart) {
  // 10,080 triangles: a chart spans up to about 120 degrees of arc, so a sphere needs about
  // 6 to 10; far from one chart per few triangles.
  const Object sphere = makeSphere(72, 72, 1.0f);
  ASSERT_GT(sphere.triangles.size(), 10000u);
  UnwrapSettings settings;
  settings.texelsPerUnit = 32.0f;
  const Result<UnwrapResult> r = generateLightmapUvs(sphere, settings);
  ASSERT_TRUE(r.ok()) << r.error();
  EXPECT_LE(r->stats.chartCount, 20);
  EXPECT_EQ(r->stats.flippedTriangles, 0);
  // The distortion bound every chart is held to (kMaxAreaDistortion = 2 between a
  // triangle's density and its chart's mean).
  EXPECT_LT(r->stats.maxAreaDistortion, 4.0);
  EXPECT_LT(r->stats.l2Stretch, 1.1);
  const size_t texels = expectChartsApart(*r, settings.texelsPerUnit, settings.gutterTexels);
  // The sphere's 4 pi = 12.57 m^2 at 32^2 texels per m^2: 12,868 texels, plus the texels its
  // chart borders touch; more than 300 per chart.
  EXPECT_GT(double(texels) / r->stats.chartCount, 300.0);
  std::printf("sphere 72x72 (%zu triangles): %d charts, %zu texels (%.0f per chart), L2 %.4f, "
              "max area distortion %.3f\n",
              sphere.triangles.size(), r->stats.chartCount, texels,
              double(texels) / r->stats.chartCount, r->stats.l2Stretch,
              r->stats.maxAreaDistortion);
}

TEST(LightmapUv, CreasesAreSeamsButSmallPiecesMerge) {
  // A box with split normals: every edge is a crease, so six charts as before; the
  // rasterized charts keep the gutter.
  Scene scene;
  const uint32_t mat = test::addMaterial(scene, test::lambert(vec3(0.5f)));
  test::addBox(scene, "box", vec3(0), vec3(2, 1, 0.5f), mat, false);
  UnwrapSettings settings;
  settings.texelsPerUnit = 20.0f;
  auto r = generateLightmapUvs(scene.objects[0], settings);
  ASSERT_TRUE(r.ok()) << r.error();
  EXPECT_EQ(r->stats.chartCount, 6);
  expectChartsApart(*r, settings.texelsPerUnit, settings.gutterTexels);
  // At 2 texels per unit the 0.5-unit faces hold 1 x 2 texels: under smallChartTexels, they
  // merge into their neighbours across the creases (fewer than six charts), still apart.
  settings.texelsPerUnit = 2.0f;
  r = generateLightmapUvs(scene.objects[0], settings);
  ASSERT_TRUE(r.ok()) << r.error();
  EXPECT_LT(r->stats.chartCount, 6);
  EXPECT_EQ(r->stats.flippedTriangles, 0);
  EXPECT_LT(maxOverlap(*r), 1e-12);
  expectChartsApart(*r, settings.texelsPerUnit, settings.gutterTexels);
}

TEST(LightmapUv, SealedFacesGetAtMostATexel) {
  // A solid box resting on a floor under the sun, black sky: no light reaches the box's
  // bottom face (its rays go down into the void, the sun is behind it), everything else is
  // lit. The bottom gets a chart of its own, shrunk to at most one texel across.
  Scene scene;
  const uint32_t mat = test::addMaterial(scene, test::lambert(vec3(0.5f)));
  test::addQuad(scene, "floor", vec3(-3, 0, 3), vec3(3, 0, 3), vec3(3, 0, -3), vec3(-3, 0, -3),
                mat);
  const uint32_t box = test::addBox(scene, "box", vec3(-1, 0, -1), vec3(1, 1, 1), mat, false);
  scene.lights.push_back(test::directionalLight(glm::normalize(vec3(0.3f, -1, 0.2f)), 5.0f));
  scene.objects[box].uv1.clear();
  scene.objects[0].uv1.clear();
  auto tracer = Tracer::create(scene);
  ASSERT_TRUE(tracer.ok()) << tracer.error();
  const auto sealed = findSealedTriangles(scene, **tracer);
  ASSERT_EQ(sealed.size(), 2u);
  size_t sealedCount = 0;
  for (size_t t = 0; t < sealed[box].size(); ++t) {
    const bool bottom = scene.objects[box].faceNormal(uint32_t(t)).y < -0.5f;
    EXPECT_EQ(sealed[box][t], bottom ? 1 : 0) << "triangle " << t;
    sealedCount += sealed[box][t];
  }
  EXPECT_EQ(sealedCount, 2u);
  for (uint8_t f : sealed[0]) EXPECT_EQ(f, 0);

  // Texels the box's faces get, with and without shrinking, through the atlas and raster.
  auto boxTexels = [&](bool shrink, size_t& bottomTexels) {
    Scene copy = scene;
    UnwrapSettings settings;
    settings.shrinkSealed = shrink;
    const auto uvs = generateMissingLightmapUvs(copy, 16.0f, settings);
    EXPECT_TRUE(uvs.ok());
    EXPECT_EQ((*uvs)[box]->stats.sealedCharts, shrink ? 1 : 0);
    AtlasSettings as;
    as.resolution = 16.0f;
    for (const auto& u : *uvs) as.worldPerUv.push_back(u ? u->worldPerUv : 0.0);
    const auto layout = packAtlas(copy, as);
    EXPECT_TRUE(layout.ok());
    const auto pages = rasterizeAtlas(copy, *layout, RasterSettings{});
    EXPECT_TRUE(pages.ok());
    size_t all = 0;
    bottomTexels = 0;
    for (const RasterPage& p : *pages)
      for (const TexelSample& t : p.texels) {
        if (t.object != int32_t(box)) continue;
        ++all;
        if (copy.objects[box].faceNormal(t.sample.triangle).y < -0.5f) ++bottomTexels;
      }
    return all;
  };
  size_t bottomBefore = 0, bottomAfter = 0;
  const size_t before = boxTexels(false, bottomBefore);
  const size_t after = boxTexels(true, bottomAfter);
  // 2 x 2 units at 16 texels per unit: 32 x 32 texels and the chart border; then a chart one
  // texel across, which the conservative rasterizer (texel_raster.h) gives at most 3 x 3.
  EXPECT_GE(bottomBefore, 1024u);
  EXPECT_LE(bottomAfter, 9u);
  // The other five faces keep their texels (within what packing changes at chart borders).
  EXPECT_NEAR(double(after - bottomAfter), double(before - bottomBefore),
              0.05 * double(before - bottomBefore));
  std::printf("box on floor: sealed bottom %zu of %zu texels without shrinking, %zu of %zu "
              "with\n",
              bottomBefore, before, bottomAfter, after);
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
