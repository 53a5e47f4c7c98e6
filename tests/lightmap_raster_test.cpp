// lightmap_raster_test.cpp: conservative texel rasterization: coverage equals UV area, exact
// samples at texel centres, partial texels sampled inside their triangle, supersampling,
// determinism across thread counts.
#include <gtest/gtest.h>

#include <chrono>
#include <cstdio>
#include <filesystem>

#include "lightmap/atlas.h"
#include "lightmap/texel_raster.h"
#include "lightmap/uv_unwrap.h"
#include "src/gltf_loader.h"
#include "tests/test_util.h"

namespace kiln {
namespace {

using glm::dvec2;

double cross2(dvec2 a, dvec2 b) { return a.x * b.y - a.y * b.x; }

// A scene with an unwrapped box (many charts, edges off the texel grid), a quad whose UV1 is
// a diamond (diagonal edges), and a quad that is not lightmapped.
struct Fixture {
  Scene scene;
  AtlasLayout layout;

  explicit Fixture(float resolution) {
    const uint32_t mat = test::addMaterial(scene, test::lambert(vec3(0.5f)));
    const uint32_t box =
        test::addBox(scene, "box", vec3(0.1f, 0, 0), vec3(1.3f, 0.7f, 0.9f), mat, false);
    UnwrapSettings unwrap;
    unwrap.texelsPerUnit = resolution;
    const auto r = generateLightmapUvs(scene.objects[box], unwrap);
    EXPECT_TRUE(r.ok()) << r.error();
    scene.objects[box] = applyUnwrap(scene.objects[box], *r);
    const uint32_t diamond = test::addQuad(scene, "diamond", vec3(0, 2, 0), vec3(1.5f, 2, 0),
                                           vec3(1.5f, 2, -1.5f), vec3(0, 2, -1.5f), mat);
    scene.objects[diamond].uv1 = {{0.5f, 0.0f}, {1.0f, 0.5f}, {0.5f, 1.0f}, {0.0f, 0.5f}};
    const uint32_t dark = test::addQuad(scene, "dark", vec3(0, 3, 0), vec3(1, 3, 0), vec3(1, 3, -1),
                                        vec3(0, 3, -1), mat);
    scene.objects[dark].settings.scaleInLightmap = 0.0f;
    AtlasSettings atlas;
    atlas.resolution = resolution;
    const auto l = packAtlas(scene, atlas);
    EXPECT_TRUE(l.ok()) << l.error();
    layout = *l;
  }

  // The object's triangle t in page texel coordinates.
  std::array<dvec2, 3> texelTriangle(uint32_t object, uint32_t t) const {
    const Object& o = scene.objects[object];
    const AtlasObject& a = layout.objects[object];
    const AtlasPage& p = layout.pages[size_t(a.lightmapIndex)];
    std::array<dvec2, 3> r;
    for (int k = 0; k < 3; ++k) {
      const vec2 uv = o.uv1[o.triangles[t][k]];
      r[k] = (dvec2(uv) * dvec2(a.scaleOffset.x, a.scaleOffset.y) +
              dvec2(a.scaleOffset.z, a.scaleOffset.w)) *
             dvec2(p.width, p.height);
    }
    return r;
  }
};

dvec2 bary(const std::array<dvec2, 3>& t, dvec2 q) {
  const double d = cross2(t[1] - t[0], t[2] - t[0]);
  return dvec2(cross2(q - t[0], t[2] - t[0]), cross2(t[1] - t[0], q - t[0])) / d;
}

bool insideTol(dvec2 b, double tol) { return b.x >= -tol && b.y >= -tol && 1 - b.x - b.y >= -tol; }

TEST(LightmapRaster, CoverageSumsToUvAreaInTexels) {
  const Fixture f(24.0f);
  const auto pages = rasterizeAtlas(f.scene, f.layout, RasterSettings{});
  ASSERT_TRUE(pages.ok()) << pages.error();
  for (uint32_t oi = 0; oi < f.scene.objects.size(); ++oi) {
    double expected = 0.0;
    const AtlasObject& a = f.layout.objects[oi];
    double covered = 0.0;
    int texels = 0;
    for (const RasterPage& page : *pages)
      for (int y = 0; y < page.height; ++y)
        for (int x = 0; x < page.width; ++x)
          if (page.at(x, y).object == int(oi)) {
            covered += page.at(x, y).coverage;
            ++texels;
            // Within the object's texel rectangle: padding keeps objects apart.
            EXPECT_GE(x, a.texelMin.x);
            EXPECT_LT(x, a.texelMin.x + a.texelSize.x);
            EXPECT_GE(y, a.texelMin.y);
            EXPECT_LT(y, a.texelMin.y + a.texelSize.y);
          }
    if (a.lightmapIndex < 0) {
      EXPECT_EQ(texels, 0);
      continue;
    }
    for (uint32_t t = 0; t < f.scene.objects[oi].triangles.size(); ++t) {
      const auto tri = f.texelTriangle(oi, t);
      expected += 0.5 * std::abs(cross2(tri[1] - tri[0], tri[2] - tri[0]));
    }
    EXPECT_NEAR(covered, expected, 1e-5 * expected) << f.scene.objects[oi].name;
    // The density rule: texel area == (resolution x scale)^2 x world area, within rounding of
    // the rectangle to whole texels.
    const double world = f.scene.objects[oi].surfaceArea();
    EXPECT_NEAR(expected / (24.0 * 24.0 * world), 1.0, 0.1) << f.scene.objects[oi].name;
    std::printf("%s: %d texels touched, coverage sum %.4f, UV area %.4f texels\n",
                f.scene.objects[oi].name.c_str(), texels, covered, expected);
  }
}

TEST(LightmapRaster, CentresAndPartialTexelsGetExactPointsOnTheirTriangles) {
  const Fixture f(20.0f);
  const auto pages = rasterizeAtlas(f.scene, f.layout, RasterSettings{});
  ASSERT_TRUE(pages.ok()) << pages.error();
  int centres = 0, partial = 0;
  for (uint32_t oi = 0; oi < f.scene.objects.size(); ++oi) {
    const AtlasObject& a = f.layout.objects[oi];
    if (a.lightmapIndex < 0) continue;
    const RasterPage& page = (*pages)[size_t(a.lightmapIndex)];
    const Object& o = f.scene.objects[oi];
    for (uint32_t t = 0; t < o.triangles.size(); ++t) {
      const auto tri = f.texelTriangle(oi, t);
      const dvec2 lo = glm::min(tri[0], glm::min(tri[1], tri[2]));
      const dvec2 hi = glm::max(tri[0], glm::max(tri[1], tri[2]));
      for (int y = int(lo.y); y < int(std::ceil(hi.y)); ++y)
        for (int x = int(lo.x); x < int(std::ceil(hi.x)); ++x) {
          const dvec2 c(x + 0.5, y + 0.5);
          const dvec2 b = bary(tri, c);
          if (b.x <= 1e-9 || b.y <= 1e-9 || 1 - b.x - b.y <= 1e-9) continue;  // strictly inside
          const TexelSample& s = page.at(x, y);
          ASSERT_EQ(s.object, int(oi));
          EXPECT_EQ(s.sample.triangle, t);
          EXPECT_EQ(s.sample.point, vec2(c));
          EXPECT_NEAR(s.sample.bary.x, b.x, 1e-6);
          EXPECT_NEAR(s.sample.bary.y, b.y, 1e-6);
          // The world position is the barycentric interpolation of the triangle's corners.
          const vec3 p = float(1 - b.x - b.y) * o.positions[o.triangles[t].x] +
                         float(b.x) * o.positions[o.triangles[t].y] +
                         float(b.y) * o.positions[o.triangles[t].z];
          EXPECT_LT(glm::length(s.sample.position - p), 1e-5f);
          EXPECT_NEAR(glm::length(s.sample.normal), 1.0f, 1e-5f);
          ++centres;
        }
    }
  }
  // Every valid texel: the sample is on its triangle; partial texels (centre outside every
  // triangle) sample the centroid, which is inside both the texel and the triangle.
  for (const RasterPage& page : *pages)
    for (int y = 0; y < page.height; ++y)
      for (int x = 0; x < page.width; ++x) {
        const TexelSample& s = page.at(x, y);
        if (!s.valid()) continue;
        EXPECT_GT(s.coverage, 0.0f);
        EXPECT_LE(s.coverage, 1.0f);
        const auto tri = f.texelTriangle(uint32_t(s.object), s.sample.triangle);
        const dvec2 q(s.sample.point);
        EXPECT_TRUE(insideTol(bary(tri, q), 1e-6)) << x << "," << y;
        EXPECT_GE(q.x, x);
        EXPECT_LE(q.x, x + 1);
        EXPECT_GE(q.y, y);
        EXPECT_LE(q.y, y + 1);
        const dvec2 b = bary(tri, q);
        EXPECT_NEAR(s.sample.bary.x, b.x, 1e-5);
        EXPECT_NEAR(s.sample.bary.y, b.y, 1e-5);
        if (q != dvec2(x + 0.5, y + 0.5)) ++partial;
      }
  EXPECT_GT(centres, 100);
  EXPECT_GT(partial, 10);
  std::printf("%d interior centres checked, %d partial texels sampled at centroids\n", centres,
              partial);
}

TEST(LightmapRaster, ConservativeEveryOverlappedTexelIsCovered) {
  const Fixture f(16.0f);
  const auto pages = rasterizeAtlas(f.scene, f.layout, RasterSettings{});
  ASSERT_TRUE(pages.ok()) << pages.error();
  // A texel overlapped by a triangle by more than a sliver of area (corner checks: a texel
  // corner strictly inside the triangle) must be covered.
  for (uint32_t oi = 0; oi < f.scene.objects.size(); ++oi) {
    const AtlasObject& a = f.layout.objects[oi];
    if (a.lightmapIndex < 0) continue;
    const RasterPage& page = (*pages)[size_t(a.lightmapIndex)];
    for (uint32_t t = 0; t < f.scene.objects[oi].triangles.size(); ++t) {
      const auto tri = f.texelTriangle(oi, t);
      // Texels at each corner (a point just inside the triangle: vertices often sit exactly
      // on texel edges), and the four texels around any grid corner inside the triangle.
      const dvec2 centroid = (tri[0] + tri[1] + tri[2]) / 3.0;
      for (int k = 0; k < 3; ++k) {
        const dvec2 q = tri[k] + 1e-4 * (centroid - tri[k]);
        const int x = int(std::floor(q.x)), y = int(std::floor(q.y));
        if (x < page.width && y < page.height) {
          EXPECT_EQ(page.at(x, y).object, int(oi));
        }
      }
      const dvec2 lo = glm::min(tri[0], glm::min(tri[1], tri[2]));
      const dvec2 hi = glm::max(tri[0], glm::max(tri[1], tri[2]));
      for (int y = int(lo.y); y <= int(hi.y); ++y)
        for (int x = int(lo.x); x <= int(hi.x); ++x) {
          const dvec2 b = bary(tri, dvec2(x, y));
          if (b.x <= 1e-9 || b.y <= 1e-9 || 1 - b.x - b.y <= 1e-9) continue;
          for (int dy = -1; dy <= 0; ++dy)
            for (int dx = -1; dx <= 0; ++dx) EXPECT_EQ(page.at(x + dx, y + dy).object, int(oi));
        }
    }
  }
}

TEST(LightmapRaster, SupersamplesLieInsideTheirTrianglesAndTexels) {
  const Fixture f(12.0f);
  RasterSettings settings;
  settings.supersampling = 3;
  const auto pages = rasterizeAtlas(f.scene, f.layout, settings);
  ASSERT_TRUE(pages.ok()) << pages.error();
  size_t total = 0;
  double coverage = 0.0;
  for (const RasterPage& page : *pages)
    for (int y = 0; y < page.height; ++y)
      for (int x = 0; x < page.width; ++x) {
        const TexelSample& s = page.at(x, y);
        if (!s.valid()) continue;
        coverage += s.coverage;
        if (s.coverage == 1.0f) {
          EXPECT_EQ(s.subsampleCount, 9u);
        }
        EXPECT_LE(s.subsampleCount, 9u);
        for (uint32_t i = 0; i < s.subsampleCount; ++i) {
          const TexelPoint& p = page.subsamples[s.firstSubsample + i];
          const auto tri = f.texelTriangle(uint32_t(s.object), p.triangle);
          EXPECT_TRUE(insideTol(bary(tri, dvec2(p.point)), 1e-5));  // point stored as float
          EXPECT_GT(p.point.x, float(x));
          EXPECT_LT(p.point.x, float(x + 1));
          EXPECT_GT(p.point.y, float(y));
          EXPECT_LT(p.point.y, float(y + 1));
          // Stratified grid positions.
          const float fx = (p.point.x - float(x)) * 3.0f - 0.5f,
                      fy = (p.point.y - float(y)) * 3.0f - 0.5f;
          EXPECT_NEAR(fx, std::round(fx), 1e-4f);
          EXPECT_NEAR(fy, std::round(fy), 1e-4f);
        }
        total += s.subsampleCount;
      }
  // The grid estimates the covered area.
  EXPECT_NEAR(double(total) / 9.0, coverage, 0.05 * coverage);
}

TEST(LightmapRaster, DeterministicAcrossThreadCounts) {
  const Fixture f(20.0f);
  RasterSettings one, many;
  one.supersampling = many.supersampling = 2;
  one.parallel.threads = 1;
  many.parallel.threads = 0;
  many.parallel.grain = 1;
  const auto a = rasterizeAtlas(f.scene, f.layout, one);
  const auto b = rasterizeAtlas(f.scene, f.layout, many);
  ASSERT_TRUE(a.ok() && b.ok());
  ASSERT_EQ(a->size(), b->size());
  for (size_t p = 0; p < a->size(); ++p) {
    const RasterPage &pa = (*a)[p], &pb = (*b)[p];
    ASSERT_EQ(pa.texels.size(), pb.texels.size());
    ASSERT_EQ(pa.subsamples.size(), pb.subsamples.size());
    for (size_t i = 0; i < pa.texels.size(); ++i) {
      EXPECT_EQ(pa.texels[i].object, pb.texels[i].object);
      EXPECT_EQ(pa.texels[i].sample.position, pb.texels[i].sample.position);
      EXPECT_EQ(pa.texels[i].coverage, pb.texels[i].coverage);
      EXPECT_EQ(pa.texels[i].firstSubsample, pb.texels[i].firstSubsample);
    }
    for (size_t i = 0; i < pa.subsamples.size(); ++i)
      EXPECT_EQ(pa.subsamples[i].position, pb.subsamples[i].position);
  }
  RasterSettings bad;
  bad.supersampling = 0;
  EXPECT_FALSE(rasterizeAtlas(f.scene, f.layout, bad).ok());
}

// The whole geometry pipeline on real scenes: every lightmapped object's UVs regenerated,
// packed and rasterized; no folds, no overlapping UV triangles, exact coverage.
void checkScene(const std::string& path, float resolution) {
  LoadOptions options;
  options.loadTextures = false;
  auto loaded = loadScene(path, options);
  ASSERT_TRUE(loaded.ok()) << loaded.error();
  Scene scene = std::move(*loaded);
  const auto start = std::chrono::steady_clock::now();
  int charts = 0, triangles = 0;
  double worstL2 = 1.0, worstAnisotropy = 1.0, worstArea = 1.0;
  for (Object& o : scene.objects) {
    if (!isLightmapped(o)) continue;
    UnwrapSettings unwrap;
    unwrap.texelsPerUnit = resolution * o.settings.scaleInLightmap;
    const auto r = generateLightmapUvs(o, unwrap);
    ASSERT_TRUE(r.ok()) << r.error();
    EXPECT_EQ(r->stats.flippedTriangles, 0) << o.name;
    charts += r->stats.chartCount;
    triangles += int(o.triangles.size());
    worstL2 = std::max(worstL2, r->stats.l2Stretch);
    worstAnisotropy = std::max(worstAnisotropy, r->stats.maxAnisotropy);
    worstArea = std::max(worstArea, r->stats.maxAreaDistortion);
    EXPECT_LT(r->stats.maxAnisotropy, 2.0) << o.name;
    EXPECT_LE(r->stats.maxAreaDistortion, 2.0 + 1e-3) << o.name;
    o = applyUnwrap(o, *r);
    // No two UV triangles overlap (bounding-box sweep, then exact clipping).
    std::vector<std::array<dvec2, 3>> uv(o.triangles.size());
    std::vector<uint32_t> order(o.triangles.size());
    for (uint32_t t = 0; t < o.triangles.size(); ++t) {
      for (int k = 0; k < 3; ++k) uv[t][k] = dvec2(o.uv1[o.triangles[t][k]]);
      order[t] = t;
    }
    auto lo = [&](uint32_t t) { return glm::min(uv[t][0], glm::min(uv[t][1], uv[t][2])); };
    auto hi = [&](uint32_t t) { return glm::max(uv[t][0], glm::max(uv[t][1], uv[t][2])); };
    std::sort(order.begin(), order.end(),
              [&](uint32_t a, uint32_t b) { return lo(a).x < lo(b).x; });
    int overlaps = 0;
    for (size_t i = 0; i < order.size(); ++i)
      for (size_t j = i + 1; j < order.size() && lo(order[j]).x < hi(order[i]).x; ++j) {
        const uint32_t a = order[i], b = order[j];
        if (lo(b).y >= hi(a).y || lo(a).y >= hi(b).y) continue;
        // Strict interior test: a corner of one strictly inside the other, or crossing edges.
        auto strictlyInside = [&](const std::array<dvec2, 3>& t, dvec2 q) {
          const dvec2 bb = bary(t, q);
          return bb.x > 1e-6 && bb.y > 1e-6 && 1 - bb.x - bb.y > 1e-6;
        };
        for (int k = 0; k < 3; ++k)
          if (strictlyInside(uv[a], uv[b][k]) || strictlyInside(uv[b], uv[a][k])) ++overlaps;
      }
    EXPECT_EQ(overlaps, 0) << o.name;
  }
  AtlasSettings atlas;
  atlas.resolution = resolution;
  const auto layout = packAtlas(scene, atlas);
  ASSERT_TRUE(layout.ok()) << layout.error();
  const auto pages = rasterizeAtlas(scene, *layout, RasterSettings{});
  ASSERT_TRUE(pages.ok()) << pages.error();
  const double ms =
      std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - start).count();
  long valid = 0, total = 0;
  for (const RasterPage& page : *pages) {
    total += long(page.width) * page.height;
    for (const TexelSample& s : page.texels) valid += s.valid() ? 1 : 0;
  }
  std::printf(
      "%s @ %.0f texels/unit: %d triangles, %d charts, worst L2 stretch %.4f, worst "
      "anisotropy %.3f, worst area distortion %.3f; %zu page(s), first %d x %d, %.1f%% of texels "
      "used; %.1f ms\n",
      std::filesystem::path(path).filename().c_str(), resolution, triangles, charts, worstL2,
      worstAnisotropy, worstArea, pages->size(), (*pages)[0].width, (*pages)[0].height,
      100.0 * double(valid) / double(total), ms);
}

TEST(LightmapPipeline, ProjectScenesUnwrapPackAndRasterize) {
  for (const char* name : {"cornell_box.gltf", "two_rooms.gltf", "courtyard.gltf"})
    checkScene(test::scenesDir() + "/" + name, 8.0f);
}

TEST(LightmapPipeline, SharedCornellBoxFromBlender) {
  const std::string path =
      test::sharedDir() + "/scenes/cornell_vinc3r/cornellBox-2.80-Eevee-gltf.gltf";
  if (!std::filesystem::exists(path)) GTEST_SKIP() << "../shared is absent: " << path;
  checkScene(path, 16.0f);
}

}  // namespace
}  // namespace kiln
