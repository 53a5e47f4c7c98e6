// lightmap_atlas_test.cpp: atlas packing: the texel density rule, padding, pages,
// determinism, errors, and the manifest round trip used by --lock-atlas.
#include <gtest/gtest.h>

#include <nlohmann/json.hpp>

#include "lightmap/atlas.h"
#include "lightmap/texel_raster.h"
#include "lightmap/uv_unwrap.h"
#include "tests/test_util.h"

namespace kiln {
namespace {

// A horizontal w x d quad at height y (UV1 = unit square).
uint32_t addFloor(Scene& scene, const std::string& name, float w, float d, float y = 0.0f) {
  return test::addQuad(scene, name, vec3(0, y, 0), vec3(w, y, 0), vec3(w, y, -d), vec3(0, y, -d),
                       0);
}

// Many quads of assorted sizes (deterministic).
Scene assortedScene(int count) {
  Scene scene;
  test::addMaterial(scene, test::lambert(vec3(0.5f)));
  for (int i = 0; i < count; ++i) {
    const float w = 0.3f + 0.17f * float((i * 7) % 11), d = 0.2f + 0.23f * float((i * 5) % 7);
    addFloor(scene, "quad" + std::to_string(i), w, d, float(i));
  }
  return scene;
}

// Checks the layout's geometry: rectangles inside their pages with `padding` to the border,
// and at least `padding` texels between any two objects of a page.
void expectValidLayout(const Scene& scene, const AtlasLayout& layout, int padding, int maxSize) {
  ASSERT_EQ(layout.objects.size(), scene.objects.size());
  for (const AtlasPage& page : layout.pages) {
    EXPECT_LE(page.width, maxSize);
    EXPECT_LE(page.height, maxSize);
  }
  for (size_t i = 0; i < layout.objects.size(); ++i) {
    const AtlasObject& a = layout.objects[i];
    if (a.lightmapIndex < 0) continue;
    ASSERT_LT(a.lightmapIndex, int(layout.pages.size()));
    const AtlasPage page = layout.pages[size_t(a.lightmapIndex)];
    EXPECT_GE(a.texelMin.x, padding);
    EXPECT_GE(a.texelMin.y, padding);
    EXPECT_LE(a.texelMin.x + a.texelSize.x, page.width - padding);
    EXPECT_LE(a.texelMin.y + a.texelSize.y, page.height - padding);
    for (size_t j = i + 1; j < layout.objects.size(); ++j) {
      const AtlasObject& b = layout.objects[j];
      if (b.lightmapIndex != a.lightmapIndex) continue;
      const int gapX = std::max(b.texelMin.x - (a.texelMin.x + a.texelSize.x),
                                a.texelMin.x - (b.texelMin.x + b.texelSize.x));
      const int gapY = std::max(b.texelMin.y - (a.texelMin.y + a.texelSize.y),
                                a.texelMin.y - (b.texelMin.y + b.texelSize.y));
      EXPECT_GE(std::max(gapX, gapY), padding) << "objects " << i << " and " << j;
    }
    // scaleOffset maps the UV1 bounding rectangle exactly onto the texel rectangle.
    const auto [lo, hi] = uv1Bounds(scene.objects[i]);
    const vec2 s(a.scaleOffset.x, a.scaleOffset.y), o(a.scaleOffset.z, a.scaleOffset.w);
    const vec2 dims(float(page.width), float(page.height));
    const vec2 p0 = (lo * s + o) * dims, p1 = (hi * s + o) * dims;
    EXPECT_NEAR(p0.x, float(a.texelMin.x), 1e-3f);
    EXPECT_NEAR(p0.y, float(a.texelMin.y), 1e-3f);
    EXPECT_NEAR(p1.x, float(a.texelMin.x + a.texelSize.x), 1e-3f);
    EXPECT_NEAR(p1.y, float(a.texelMin.y + a.texelSize.y), 1e-3f);
  }
}

TEST(LightmapAtlas, TexelCountFollowsResolutionTimesScaleSquaredTimesArea) {
  Scene scene;
  test::addMaterial(scene, test::lambert(vec3(0.5f)));
  addFloor(scene, "two", 2.0f, 2.0f);         // area 4, UV area 1: 20 x 20 at 10 texels/unit
  addFloor(scene, "long", 3.0f, 1.0f, 1.0f);  // area 3: k = 10 sqrt(3) = 17.32 -> 18 x 18
  const uint32_t doubled = addFloor(scene, "doubled", 2.0f, 2.0f, 2.0f);
  scene.objects[doubled].settings.scaleInLightmap = 2.0f;
  AtlasSettings settings;
  settings.resolution = 10.0f;
  const auto layout = packAtlas(scene, settings);
  ASSERT_TRUE(layout.ok()) << layout.error();
  EXPECT_EQ(layout->objects[0].texelSize, glm::ivec2(20, 20));
  EXPECT_EQ(layout->objects[1].texelSize, glm::ivec2(18, 18));
  // scaleInLightmap 2 doubles the density: four times the texels.
  EXPECT_EQ(layout->objects[2].texelSize, glm::ivec2(40, 40));
  EXPECT_EQ(layout->objects[2].texelSize.x * layout->objects[2].texelSize.y,
            4 * layout->objects[0].texelSize.x * layout->objects[0].texelSize.y);
  EXPECT_FLOAT_EQ(layout->objects[0].texelsPerUnit, 10.0f);
  EXPECT_FLOAT_EQ(layout->objects[2].texelsPerUnit, 20.0f);
  ASSERT_EQ(layout->pages.size(), 1u);
  // Items of w + padding (42 x 42, 22 x 22, 20 x 20) in a bin of page - padding: the
  // smallest page puts the 42 alone in a row of width 44 - 2 and the 22 and the 20 on top
  // (42 + 22 = 64, + 2 padding = 66, aligned to 68); side by side would need 86 x 44.
  EXPECT_EQ(layout->pages[0].width, 44);
  EXPECT_EQ(layout->pages[0].height, 68);
  expectValidLayout(scene, *layout, settings.padding, settings.maxSize);
}

TEST(LightmapAtlas, NotLightmappedObjectsGetNoPage) {
  Scene scene;
  test::addMaterial(scene, test::lambert(vec3(0.5f)));
  addFloor(scene, "lit", 1, 1);
  const uint32_t zero = addFloor(scene, "scale0", 1, 1, 1);
  scene.objects[zero].settings.scaleInLightmap = 0.0f;
  const uint32_t dyn = addFloor(scene, "dynamic", 1, 1, 2);
  scene.objects[dyn].settings.isStatic = false;
  const uint32_t probe = addFloor(scene, "probeLit", 1, 1, 3);
  scene.objects[probe].settings.receiveGI = ReceiveGI::Probes;
  scene.objects[probe].uv1.clear();  // not needed when not lightmapped
  const auto layout = packAtlas(scene, AtlasSettings{});
  ASSERT_TRUE(layout.ok()) << layout.error();
  EXPECT_EQ(layout->objects[0].lightmapIndex, 0);
  EXPECT_EQ(layout->objects[zero].lightmapIndex, -1);
  EXPECT_EQ(layout->objects[dyn].lightmapIndex, -1);
  EXPECT_EQ(layout->objects[probe].lightmapIndex, -1);
}

TEST(LightmapAtlas, ObjectsTooSmallForALightmapAreProbeLit) {
  // At 10 texels per unit a 1 x 1 quad gets 100 texels, a 0.3 x 0.3 quad 9 and a 0.3 x 0.3
  // quad with scaleInLightmap 2 gets 36: with minObjectTexels 16, only the second is lit by
  // probes, needs no UVs and gets no page.
  Scene scene;
  test::addMaterial(scene, test::lambert(vec3(0.5f)));
  addFloor(scene, "big", 1.0f, 1.0f);
  const uint32_t tiny = addFloor(scene, "tiny", 0.3f, 0.3f, 1.0f);
  const uint32_t scaled = addFloor(scene, "scaled", 0.3f, 0.3f, 2.0f);
  scene.objects[scaled].settings.scaleInLightmap = 2.0f;
  scene.objects[tiny].uv1.clear();
  EXPECT_NEAR(lightmapTexels(scene.objects[tiny], 10.0f), 9.0, 1e-4);
  EXPECT_NEAR(lightmapTexels(scene.objects[scaled], 10.0f), 36.0, 1e-4);
  AtlasSettings settings;
  settings.resolution = 10.0f;
  settings.minObjectTexels = 16.0f;
  const auto layout = packAtlas(scene, settings);
  ASSERT_TRUE(layout.ok()) << layout.error();
  EXPECT_EQ(layout->objects[tiny].lightmapIndex, -1);
  EXPECT_TRUE(layout->objects[tiny].probeLit);
  EXPECT_EQ(layout->objects[0].lightmapIndex, 0);
  EXPECT_EQ(layout->objects[scaled].lightmapIndex, 0);
  EXPECT_FALSE(layout->objects[scaled].probeLit);
  ASSERT_EQ(layout->warnings.size(), 1u);
  EXPECT_NE(layout->warnings[0].find("'tiny'"), std::string::npos) << layout->warnings[0];
  expectValidLayout(scene, *layout, settings.padding, settings.maxSize);
  // Through the manifest and back, as --lock-atlas reads it: still probe-lit.
  const auto back = atlasFromManifest(atlasToJson(*layout, scene), scene);
  ASSERT_TRUE(back.ok()) << back.error();
  EXPECT_TRUE(back->objects[tiny].probeLit);
  EXPECT_EQ(back->objects[tiny].lightmapIndex, -1);
  settings.locked = *back;
  EXPECT_TRUE(packAtlas(scene, settings).ok());
  // Off (0, the default): every object gets a page, and the one without UVs is an error.
  settings.locked.reset();
  settings.minObjectTexels = 0.0f;
  const auto all = packAtlas(scene, settings);
  ASSERT_FALSE(all.ok());
  EXPECT_NE(all.error().find("'tiny'"), std::string::npos) << all.error();
}

// A flat L of five 1 x 1 squares (arms 1 wide and 3 long, a 3 x 3 bounding box) at height
// y, one object.
uint32_t addL(Scene& scene, const std::string& name, float y) {
  const uint32_t first = uint32_t(scene.objects.size());
  for (const vec2 c : {vec2(0, 0), vec2(1, 0), vec2(2, 0), vec2(0, 1), vec2(0, 2)})
    test::addQuad(scene, name, vec3(c.x, y, c.y), vec3(c.x, y, c.y + 1),
                  vec3(c.x + 1, y, c.y + 1), vec3(c.x + 1, y, c.y), 0);
  Object& l = scene.objects[first];
  for (uint32_t k = first + 1; k < first + 5; ++k) {
    const Object& q = scene.objects[k];
    const uint32_t base = uint32_t(l.positions.size());
    l.positions.insert(l.positions.end(), q.positions.begin(), q.positions.end());
    l.normals.insert(l.normals.end(), q.normals.begin(), q.normals.end());
    l.uv0.insert(l.uv0.end(), q.uv0.begin(), q.uv0.end());
    for (const uvec3& t : q.triangles) l.triangles.push_back(t + uvec3(base));
    l.triangleMaterial.insert(l.triangleMaterial.end(), q.triangleMaterial.begin(),
                              q.triangleMaterial.end());
  }
  l.uv1.clear();  // generated below
  scene.objects.resize(first + 1);
  return first;
}

TEST(LightmapAtlas, ChartsPackedIntoThePageBeatTheirObjectsRectangles) {
  // Eight L-shaped floors with generated UVs at 20 texels per unit: each L covers 5/9 of its
  // 60 x 60 rectangle, so no packing of their rectangles fills more than 56% of a page.
  // Packed chart by chart, an L's arm goes into the corner of an L turned by 180 degrees
  // (two make a 3 x 4 rectangle less two squares, 83% full, less the gutters).
  Scene scene;
  test::addMaterial(scene, test::lambert(vec3(0.5f)));
  for (int i = 0; i < 8; ++i) addL(scene, std::string("L") + std::to_string(i), float(i));
  AtlasSettings settings;
  settings.resolution = 20.0f;
  std::vector<std::optional<UnwrapResult>> unwraps(scene.objects.size());
  for (size_t i = 0; i < scene.objects.size(); ++i) {
    UnwrapSettings u;
    u.texelsPerUnit = settings.resolution;
    u.gutterTexels = settings.padding;
    const Result<UnwrapResult> r = generateLightmapUvs(scene.objects[i], u);
    ASSERT_TRUE(r.ok()) << r.error();
    ASSERT_EQ(r->stats.chartCount, 1);
    scene.objects[i] = applyUnwrap(scene.objects[i], *r);
    unwraps[i] = *r;
    settings.worldPerUv.push_back(r->worldPerUv);
  }
  const Scene local = scene;  // object UVs, as generateMissingLightmapUvs leaves them
  const auto unwrapped = unwraps;
  Result<AtlasLayout> layout = packAtlas(scene, settings);
  ASSERT_TRUE(layout.ok()) << layout.error();
  ASSERT_EQ(layout->pages.size(), 1u);
  const AtlasPage rectangles = layout->pages[0];
  ASSERT_TRUE(packChartsIntoPages(scene, *layout, settings, unwraps).ok());
  const AtlasPage page = layout->pages[0];
  EXPECT_LT(page.width * page.height, rectangles.width * rectangles.height);
  for (size_t i = 0; i < scene.objects.size(); ++i) {
    EXPECT_EQ(layout->objects[i].scaleOffset, vec4(1, 1, 0, 0));
    EXPECT_EQ(unwraps[i]->uv1, scene.objects[i].uv1);
  }

  // Every texel of the page rasterized: each L's, at least `padding` empty texels between
  // two Ls and to the page's border.
  const auto raster = rasterizeAtlas(scene, *layout, RasterSettings{});
  ASSERT_TRUE(raster.ok()) << raster.error();
  const RasterPage& texels = (*raster)[0];
  std::vector<size_t> count(scene.objects.size(), 0);
  const int p = settings.padding;
  for (int y = 0; y < texels.height; ++y)
    for (int x = 0; x < texels.width; ++x) {
      const int o = texels.at(x, y).object;
      if (o < 0) continue;
      ++count[size_t(o)];
      EXPECT_TRUE(x >= p && y >= p && x < texels.width - p && y < texels.height - p);
      for (int dy = -p; dy <= p; ++dy)
        for (int dx = -p; dx <= p; ++dx) {
          const int nx = x + dx, ny = y + dy;
          if (nx < 0 || ny < 0 || nx >= texels.width || ny >= texels.height) continue;
          const int other = texels.at(nx, ny).object;
          EXPECT_TRUE(other < 0 || other == o) << x << "," << y << " next to " << nx << "," << ny;
        }
    }
  size_t total = 0;
  for (size_t c : count) {
    // 5 m^2 at 400 texels per m^2, plus at most the texels its 12 m of border touch.
    EXPECT_GE(c, 2000u);
    EXPECT_LE(c, 2000u + 2 * 12 * 20 + 8);
    total += c;
  }
  const double fill = double(total) / (double(page.width) * page.height);
  EXPECT_GT(fill, 0.65);  // rectangles: at most 5/9
  std::printf("8 Ls: rectangles %d x %d, charts %d x %d, fill %.1f%%\n", rectangles.width,
              rectangles.height, page.width, page.height, 100.0 * fill);

  // --lock-atlas: the same page packed again from the objects' own UVs gives the same UVs; a
  // page size that no longer holds the charts is an error.
  AtlasSettings lock = settings;
  lock.locked = *layout;
  Scene again = local;
  auto againUnwraps = unwrapped;
  AtlasLayout locked = *layout;
  ASSERT_TRUE(packChartsIntoPages(again, locked, lock, againUnwraps).ok());
  for (size_t i = 0; i < scene.objects.size(); ++i)
    EXPECT_EQ(again.objects[i].uv1, scene.objects[i].uv1);
  again = local;
  againUnwraps = unwrapped;
  locked = *layout;
  locked.pages[0].width -= 4;
  lock.locked = locked;
  const Status mismatch = packChartsIntoPages(again, locked, lock, againUnwraps);
  ASSERT_FALSE(mismatch.ok());
  EXPECT_NE(mismatch.error().find("no longer pack"), std::string::npos) << mismatch.error();
}

TEST(LightmapAtlas, SmallPropsWithoutLightmapUvsAreProbeLitUnderTheAutomaticRule) {
  // At 10 texels per unit the automatic rule (minObjectTexels < 0, `--min-object-texels auto`) takes objects without TEXCOORD_1 under 50 texels
  // (0.5 m^2) that hold under 1% of the lightmapped area. A 10 x 10 floor (100 m^2) with a
  // 0.5 x 0.5 prop (25 texels, 0.25%): the prop goes to probes without UVs of its own, not
  // with them, nor at 20 texels per unit (100 texels > 5 x 20) or with minObjectTexels 0.
  constexpr float kAuto = -1.0f;
  Scene scene;
  test::addMaterial(scene, test::lambert(vec3(0.5f)));
  addFloor(scene, "floor", 10.0f, 10.0f);
  const uint32_t prop = addFloor(scene, "prop", 0.5f, 0.5f, 1.0f);
  const uint32_t authored = addFloor(scene, "authored", 0.5f, 0.5f, 2.0f);
  scene.objects[prop].uv1.clear();
  const double area = lightmappedArea(scene);
  EXPECT_NEAR(area, 100.5, 1e-4);
  EXPECT_TRUE(tooSmallForLightmap(scene.objects[prop], 10.0f, kAuto, area));
  EXPECT_FALSE(tooSmallForLightmap(scene.objects[authored], 10.0f, kAuto, area));
  EXPECT_FALSE(tooSmallForLightmap(scene.objects[prop], 20.0f, kAuto, area));
  EXPECT_FALSE(tooSmallForLightmap(scene.objects[prop], 10.0f, 0.0f, area));
  AtlasSettings automatic;
  automatic.minObjectTexels = kAuto;
  const auto layout = packAtlas(scene, automatic);
  // The automatic rule is the default; with 0 every object gets a lightmap: the prop, without
  // UVs, is an error here (the baker generates them first).
  EXPECT_EQ(AtlasSettings{}.minObjectTexels, kAuto);
  AtlasSettings every;
  every.minObjectTexels = 0.0f;
  const auto all = packAtlas(scene, every);
  ASSERT_FALSE(all.ok());
  EXPECT_NE(all.error().find("'prop'"), std::string::npos) << all.error();
  ASSERT_TRUE(layout.ok()) << layout.error();
  EXPECT_TRUE(layout->objects[prop].probeLit);
  EXPECT_EQ(layout->objects[authored].lightmapIndex, 0);
  ASSERT_EQ(layout->warnings.size(), 1u);
  EXPECT_NE(layout->warnings[0].find("'prop'"), std::string::npos) << layout->warnings[0];
  // A scene modelled small (four 0.5 x 0.5 walls, 25% of the surface each) keeps them all.
  Scene small;
  test::addMaterial(small, test::lambert(vec3(0.5f)));
  for (int i = 0; i < 4; ++i) addFloor(small, "wall" + std::to_string(i), 0.5f, 0.5f, float(i));
  for (const Object& o : small.objects)
    EXPECT_FALSE(tooSmallForLightmap(o, 10.0f, kAuto, lightmappedArea(small)));
}

// One object of n x n cubes of side `side`, 2.5 sides apart (a bead curtain, a chain: a prop
// of many pieces each smaller than a texel), with flat faces and no lightmap UVs.
uint32_t addBeads(Scene& scene, const std::string& name, int n, float side) {
  Scene scratch;
  Object beads;
  beads.name = name;
  beads.nodeIndex = int(scene.objects.size());
  for (int i = 0; i < n * n; ++i) {
    const vec3 lo(2.5f * side * float(i % n), 1.0f + 2.5f * side * float(i / n), 0.0f);
    const Object cube = scratch.objects[test::addBox(scratch, "bead", lo, lo + vec3(side), 0,
                                                     false)];
    const uint32_t first = uint32_t(beads.positions.size());
    beads.positions.insert(beads.positions.end(), cube.positions.begin(), cube.positions.end());
    beads.normals.insert(beads.normals.end(), cube.normals.begin(), cube.normals.end());
    for (const uvec3& t : cube.triangles) beads.triangles.push_back(t + uvec3(first));
  }
  beads.triangleMaterial.assign(beads.triangles.size(), 0);
  scene.objects.push_back(std::move(beads));
  scene.updateBounds();
  return uint32_t(scene.objects.size() - 1);
}

TEST(LightmapAtlas, PropsWithChartsThinnerThanATexelAreProbeLitUnderTheAutomaticRule) {
  // At 20 texels per unit, 30 x 30 beads of 8 mm (0.35 m^2: 138 texels, over the 100 of the
  // small-prop rule; 0.3% of the scene) hold 0.154 texels each, and every chart touches at
  // least one texel: their surface fills at most 15% of the texels their charts touch, under
  // kAutoThinCoverage (25%). A 0.24 m box of about the same area (0.35 m^2) has 4.8-texel
  // faces: each face touches at most 6 x 6 texels, filled to at least 23 / 36 = 64%.
  constexpr float kResolution = 20.0f;
  Scene scene;
  test::addMaterial(scene, test::lambert(vec3(0.5f)));
  addFloor(scene, "floor", 10.0f, 10.0f);
  const uint32_t beads = addBeads(scene, "beads", 30, 0.008f);
  const uint32_t box = test::addBox(scene, "box", vec3(2, 0, -2), vec3(2.24f, 0.24f, -1.76f), 0,
                                    false);
  scene.objects[box].uv1.clear();
  const double area = lightmappedArea(scene);
  EXPECT_FALSE(tooSmallForLightmap(scene.objects[beads], kResolution, -1.0f, area));

  UnwrapSettings u;
  u.texelsPerUnit = kResolution;
  const Result<UnwrapResult> thin = generateLightmapUvs(scene.objects[beads], u);
  ASSERT_TRUE(thin.ok()) << thin.error();
  // Surface texels: 900 beads x 6 faces x (0.008 x 20)^2.
  EXPECT_NEAR(thin->stats.surfaceTexels, 900 * 6 * 0.16 * 0.16, 0.01);
  EXPECT_GE(thin->stats.coveredTexels, double(thin->stats.chartCount));
  EXPECT_GE(thin->stats.chartCount, 900);  // beads share no edge: a chart at least each
  EXPECT_LT(thin->stats.surfaceTexels, 0.16 * thin->stats.coveredTexels);
  EXPECT_TRUE(chartsTooThin(thin->stats.surfaceTexels, thin->stats.coveredTexels));
  const Result<UnwrapResult> broad = generateLightmapUvs(scene.objects[box], u);
  ASSERT_TRUE(broad.ok()) << broad.error();
  EXPECT_NEAR(broad->stats.surfaceTexels, 6 * 4.8 * 4.8, 0.01);
  EXPECT_GT(broad->stats.surfaceTexels, 0.6 * broad->stats.coveredTexels);
  EXPECT_FALSE(chartsTooThin(broad->stats.surfaceTexels, broad->stats.coveredTexels));
  std::printf("surface / touched texels: beads %.1f / %.0f (%d charts), box %.1f / %.0f\n",
              thin->stats.surfaceTexels, thin->stats.coveredTexels, thin->stats.chartCount,
              broad->stats.surfaceTexels, broad->stats.coveredTexels);

  // The bake's path: the beads keep no UVs, are marked and go to probes with their own
  // warning; the box gets a lightmap.
  Scene automatic = scene;
  UnwrapSettings bake;
  bake.gutterTexels = 2;
  auto unwraps = generateMissingLightmapUvs(automatic, kResolution, bake);
  ASSERT_TRUE(unwraps.ok()) << unwraps.error();
  EXPECT_FALSE((*unwraps)[beads].has_value());
  EXPECT_TRUE(automatic.objects[beads].thinCharts);
  EXPECT_TRUE(automatic.objects[beads].uv1.empty());
  ASSERT_TRUE((*unwraps)[box].has_value());
  EXPECT_FALSE(automatic.objects[box].thinCharts);
  AtlasSettings settings;
  settings.resolution = kResolution;
  for (const auto& w : *unwraps) settings.worldPerUv.push_back(w ? w->worldPerUv : 0.0);
  const auto layout = packAtlas(automatic, settings);
  ASSERT_TRUE(layout.ok()) << layout.error();
  EXPECT_TRUE(layout->objects[beads].probeLit);
  EXPECT_EQ(layout->objects[beads].lightmapIndex, -1);
  EXPECT_EQ(layout->objects[box].lightmapIndex, 0);
  ASSERT_EQ(layout->warnings.size(), 1u);
  EXPECT_NE(layout->warnings[0].find("too thin"), std::string::npos) << layout->warnings[0];
  EXPECT_NE(layout->warnings[0].find("'beads'"), std::string::npos) << layout->warnings[0];

  // --min-object-texels 0 (every object a lightmap) and N > 0 do not apply the rule.
  for (float minTexels : {0.0f, 50.0f}) {
    Scene every = scene;
    UnwrapSettings all = bake;
    all.minObjectTexels = minTexels;
    auto allUnwraps = generateMissingLightmapUvs(every, kResolution, all);
    ASSERT_TRUE(allUnwraps.ok()) << allUnwraps.error();
    EXPECT_TRUE((*allUnwraps)[beads].has_value()) << minTexels;
    EXPECT_FALSE(every.objects[beads].thinCharts);
    AtlasSettings s = settings;
    s.minObjectTexels = minTexels;
    s.worldPerUv.clear();
    for (const auto& w : *allUnwraps) s.worldPerUv.push_back(w ? w->worldPerUv : 0.0);
    const auto l = packAtlas(every, s);
    ASSERT_TRUE(l.ok()) << l.error();
    EXPECT_EQ(l->objects[beads].lightmapIndex, 0) << minTexels;
    // --lock-atlas with that manifest on a default bake, whose beads are thin: an error
    // that says why, not "no lightmap UVs".
    const nlohmann::json manifest = nlohmann::json::parse(atlasToJson(*l, every).dump());
    const auto locked = atlasFromManifest(manifest, automatic);
    ASSERT_FALSE(locked.ok());
    EXPECT_NE(locked.error().find("too thin"), std::string::npos) << locked.error();
    EXPECT_NE(locked.error().find("'beads'"), std::string::npos) << locked.error();
    // The bake's path under --lock-atlas: what the manifest gives a page keeps its charts
    // (keepCharts), so the same manifest locks, with the beads on their page.
    Scene relocked = scene;
    UnwrapSettings keep = bake;
    keep.keepCharts.assign(scene.objects.size(), 0);
    keep.keepCharts[beads] = 1;
    auto keptUnwraps = generateMissingLightmapUvs(relocked, kResolution, keep);
    ASSERT_TRUE(keptUnwraps.ok()) << keptUnwraps.error();
    EXPECT_TRUE((*keptUnwraps)[beads].has_value());
    EXPECT_FALSE(relocked.objects[beads].thinCharts);
    const auto relock = atlasFromManifest(manifest, relocked);
    ASSERT_TRUE(relock.ok()) << relock.error();
    EXPECT_EQ(relock->objects[beads].lightmapIndex, 0) << minTexels;
    EXPECT_FALSE(relock->objects[beads].probeLit);
  }

  // A scene of nothing but beads keeps them (they hold all of its lightmapped surface).
  Scene alone;
  test::addMaterial(alone, test::lambert(vec3(0.5f)));
  addBeads(alone, "beads", 30, 0.008f);
  auto aloneUnwraps = generateMissingLightmapUvs(alone, kResolution, bake);
  ASSERT_TRUE(aloneUnwraps.ok()) << aloneUnwraps.error();
  EXPECT_TRUE((*aloneUnwraps)[0].has_value());
  EXPECT_FALSE(alone.objects[0].thinCharts);
}

TEST(LightmapAtlas, ManyObjectsPackWithoutOverlapAndDeterministically) {
  const Scene scene = assortedScene(60);
  AtlasSettings settings;
  settings.resolution = 16.0f;
  settings.padding = 3;
  const auto a = packAtlas(scene, settings);
  const auto b = packAtlas(scene, settings);
  ASSERT_TRUE(a.ok() && b.ok());
  expectValidLayout(scene, *a, settings.padding, settings.maxSize);
  ASSERT_EQ(a->pages.size(), 1u);
  long used = 0;
  for (size_t i = 0; i < a->objects.size(); ++i) {
    EXPECT_EQ(a->objects[i].texelMin, b->objects[i].texelMin);
    EXPECT_EQ(a->objects[i].scaleOffset, b->objects[i].scaleOffset);
    used += long(a->objects[i].texelSize.x) * a->objects[i].texelSize.y;
  }
  const double efficiency = double(used) / (double(a->pages[0].width) * a->pages[0].height);
  std::printf("60 quads: page %d x %d, %.1f%% of texels inside object rectangles\n",
              a->pages[0].width, a->pages[0].height, 100.0 * efficiency);
}

TEST(LightmapAtlas, EqualSquaresWithoutPaddingFillTheirPageExactly) {
  // Unit quads at 8 texels per unit, no padding: 8 x 8 texels each. 16 fill 32 x 32 exactly
  // (power-of-two pages did too); 12 fill 32 x 24 exactly, where the power-of-two candidates
  // gave 32 x 32 (75% filled).
  for (const int count : {16, 12}) {
    Scene scene;
    test::addMaterial(scene, test::lambert(vec3(0.5f)));
    for (int i = 0; i < count; ++i) addFloor(scene, "quad" + std::to_string(i), 1.0f, 1.0f, float(i));
    AtlasSettings settings;
    settings.resolution = 8.0f;
    settings.padding = 0;
    const auto layout = packAtlas(scene, settings);
    ASSERT_TRUE(layout.ok()) << layout.error();
    ASSERT_EQ(layout->pages.size(), 1u);
    EXPECT_EQ(layout->pages[0].width * layout->pages[0].height, count * 64) << count;
    expectValidLayout(scene, *layout, settings.padding, settings.maxSize);
  }
}

TEST(LightmapAtlas, SmallMaxSizeGivesSeveralPages) {
  const Scene scene = assortedScene(40);
  AtlasSettings settings;
  settings.resolution = 16.0f;
  settings.maxSize = 64;
  const auto layout = packAtlas(scene, settings);
  ASSERT_TRUE(layout.ok()) << layout.error();
  EXPECT_GT(layout->pages.size(), 1u);
  for (const AtlasPage& p : layout->pages) {
    EXPECT_TRUE(p.width % 4 == 0 || p.width == settings.maxSize) << p.width;  // 4 x 4 blocks
    EXPECT_TRUE(p.height % 4 == 0 || p.height == settings.maxSize) << p.height;
  }
  expectValidLayout(scene, *layout, settings.padding, settings.maxSize);
  for (const AtlasObject& o : layout->objects) EXPECT_GE(o.lightmapIndex, 0);
  std::printf("40 quads at maxSize 64: %zu pages\n", layout->pages.size());
}

TEST(LightmapAtlas, OversizedObjectIsScaledDownWithAWarning) {
  Scene scene;
  test::addMaterial(scene, test::lambert(vec3(0.5f)));
  addFloor(scene, "Huge", 100.0f, 50.0f);
  AtlasSettings settings;
  settings.maxSize = 128;
  settings.padding = 2;
  const auto layout = packAtlas(scene, settings);
  ASSERT_TRUE(layout.ok()) << layout.error();
  EXPECT_EQ(layout->objects[0].texelSize, glm::ivec2(124, 124));
  ASSERT_EQ(layout->warnings.size(), 1u);
  EXPECT_NE(layout->warnings[0].find("Huge"), std::string::npos);
  expectValidLayout(scene, *layout, settings.padding, settings.maxSize);
}

TEST(LightmapAtlas, ImpossibleSettingsAreClearErrors) {
  Scene scene;
  test::addMaterial(scene, test::lambert(vec3(0.5f)));
  addFloor(scene, "floor", 1, 1);
  AtlasSettings settings;
  settings.padding = 4;
  settings.maxSize = 8;  // < 1 + 2 x 4
  const auto r = packAtlas(scene, settings);
  ASSERT_FALSE(r.ok());
  EXPECT_NE(r.error().find("maxSize 8"), std::string::npos) << r.error();
  EXPECT_NE(r.error().find("padding 4"), std::string::npos) << r.error();
  settings.maxSize = 9;  // exactly one texel fits
  const auto ok = packAtlas(scene, settings);
  ASSERT_TRUE(ok.ok()) << ok.error();
  EXPECT_EQ(ok->objects[0].texelSize, glm::ivec2(1, 1));

  scene.objects[0].uv1.clear();
  const auto noUv = packAtlas(scene, AtlasSettings{});
  ASSERT_FALSE(noUv.ok());
  EXPECT_NE(noUv.error().find("'floor'"), std::string::npos) << noUv.error();
}

TEST(LightmapAtlas, LockedLayoutRoundTripsThroughTheManifest) {
  Scene scene = assortedScene(12);
  scene.objects[3].settings.scaleInLightmap = 0.0f;
  AtlasSettings settings;
  settings.maxSize = 128;
  settings.resolution = 20.0f;
  const auto layout = packAtlas(scene, settings);
  ASSERT_TRUE(layout.ok()) << layout.error();
  // Through text, as a manifest file would go.
  const nlohmann::json manifest = nlohmann::json::parse(atlasToJson(*layout, scene).dump());
  const auto back = atlasFromManifest(manifest, scene);
  ASSERT_TRUE(back.ok()) << back.error();
  ASSERT_EQ(back->pages.size(), layout->pages.size());
  for (size_t p = 0; p < layout->pages.size(); ++p) {
    EXPECT_EQ(back->pages[p].width, layout->pages[p].width);
    EXPECT_EQ(back->pages[p].height, layout->pages[p].height);
  }
  for (size_t i = 0; i < scene.objects.size(); ++i) {
    EXPECT_EQ(back->objects[i].lightmapIndex, layout->objects[i].lightmapIndex);
    EXPECT_EQ(back->objects[i].scaleOffset, layout->objects[i].scaleOffset);
    if (layout->objects[i].lightmapIndex < 0) continue;
    EXPECT_EQ(back->objects[i].texelMin, layout->objects[i].texelMin);
    EXPECT_EQ(back->objects[i].texelSize, layout->objects[i].texelSize);
  }
  // packAtlas with the lock returns it, whatever the other settings say.
  AtlasSettings locked;
  locked.resolution = 1.0f;
  locked.locked = *back;
  const auto again = packAtlas(scene, locked);
  ASSERT_TRUE(again.ok()) << again.error();
  EXPECT_EQ(again->objects[5].scaleOffset, layout->objects[5].scaleOffset);

  // Mismatches are named.
  Scene renamed = scene;
  renamed.objects[2].name = "renamed";
  const auto r1 = atlasFromManifest(manifest, renamed);
  ASSERT_FALSE(r1.ok());
  EXPECT_NE(r1.error().find("'quad2' in the manifest but 'renamed'"), std::string::npos)
      << r1.error();
  Scene nowLit = scene;
  nowLit.objects[3].settings.scaleInLightmap = 1.0f;
  const auto r2 = atlasFromManifest(manifest, nowLit);
  ASSERT_FALSE(r2.ok());
  EXPECT_NE(r2.error().find("'quad3'"), std::string::npos) << r2.error();
  Scene nowDark = scene;
  nowDark.objects[4].settings.scaleInLightmap = 0.0f;
  const auto r3 = atlasFromManifest(manifest, nowDark);
  ASSERT_FALSE(r3.ok());
  EXPECT_NE(r3.error().find("'quad4'"), std::string::npos) << r3.error();
  const auto r4 = packAtlas(nowDark, locked);
  ASSERT_FALSE(r4.ok());
  EXPECT_NE(r4.error().find("'quad4'"), std::string::npos) << r4.error();
}

}  // namespace
}  // namespace kiln
