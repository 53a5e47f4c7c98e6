// probe_scene_test.cpp: probe placement and LPPVs on the shipped scenes (tools/scenes): no
// placed probe ends inside geometry or against a surface; the dark room right behind the
// sunlit wall of two_rooms (and of two_rooms_thin, whose wall is 5 cm) gets no light from the
// sunlit room through the wall, from a uniform grid, placed probes or octree corners, and the
// visibility-weighted blend stays continuous, with a slope bound, across cells spanning the
// wall; an LPPV over a long object reaching from the sun patch into shadow varies along it
// where a single probe lookup cannot.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <map>
#include <string>

#include "kiln/lppv_volume.h"
#include "kiln/probe_runtime.h"
#include "kiln/probe_visibility.h"
#include "probes/lppv.h"
#include "probes/octree_placement.h"
#include "probes/probe_baker.h"
#include "probes/probe_placement.h"
#include "src/gltf_loader.h"
#include "src/sampling.h"
#include "src/tracer.h"
#include "tests/test_util.h"

namespace kiln {
namespace {

struct Loaded {
  Scene scene;
  std::unique_ptr<Tracer> tracer;
};

// The tracer refers to the scene: a Loaded is filled where it stays, never moved.
void loadInto(Loaded& l, const std::string& name) {
  Result<Scene> scene = loadScene(test::scenesDir() + "/" + name);
  EXPECT_TRUE(bool(scene)) << scene.error();
  l.scene = std::move(scene).value();
  Result<std::unique_ptr<Tracer>> tracer = Tracer::create(l.scene);
  EXPECT_TRUE(bool(tracer)) << tracer.error();
  l.tracer = std::move(tracer).value();
}

Loaded load(const std::string& name) {
  Loaded l;
  loadInto(l, name);
  return l;
}

// A small placement run: few candidates' rays and check points, so the test takes seconds.
ProbePlacementSettings quickPlacement(uint32_t budget) {
  ProbePlacementSettings s;
  s.budget = budget;
  s.candidateRays = 256;
  s.checkPoints = 256;
  s.maxDepth = 1;
  s.bake.bounces = 1;
  s.bake.lightSamples = 1;
  return s;
}

float luminance(vec3 c) { return 0.2126f * c.r + 0.7152f * c.g + 0.0722f * c.b; }

// Largest luminance of the irradiance over the six axis normals.
float maxAxisIrradiance(const ShL2Rgb& sh) {
  float m = 0.0f;
  for (int a = 0; a < 3; ++a)
    for (float s : {-1.0f, 1.0f}) {
      vec3 n(0.0f);
      n[a] = s;
      m = std::max(m, luminance(probeIrradiance(sh, n)));
    }
  return m;
}

// A two-room scene of docs/scenes.md: room A x in [0, faceA], the shared wall x in [faceA,
// faceB], room B x in [faceB, faceB + 4]; the sun comes through room A's window onto room A's
// floor and the wall's room-A face (z 1.12..2.09, up to y = 0.87); the doorway is z 2.8..3.8.
struct WallScene {
  const char* file;
  float faceA, faceB;
  float mid() const { return 0.5f * (faceA + faceB); }
  Bounds3 rooms() const { return Bounds3{vec3(0.0f), vec3(faceB + 4.0f, 3.0f, 4.0f)}; }
};
const WallScene kThickWall{"two_rooms.gltf", 4.0f, 4.25f};
const WallScene kThinWall{"two_rooms_thin.gltf", 4.0f, 4.05f};

// The cell, its probes, their weights and visibility of p, for failure messages.
std::string describeLookup(const ProbeSet& set, vec3 p, const ProbeLocation& loc, float mid) {
  char line[256];
  std::snprintf(line, sizeof line, "cell %d%s", loc.cell,
                loc.cell >= set.innerCellCount ? " (outer: p is outside the probes' hull)" : "");
  std::string s = line;
  const ProbeVisibility& vis = set.visibility;
  for (int k = 0; k < 4; ++k) {
    const size_t i = size_t(loc.probes[k]);
    const vec3 x = set.positions[i];
    const float v = vis.empty() ? 1.0f
                                : probeVisibility(vis.probe(int32_t(i)), vis.resolution,
                                                  vis.maxDistance[i], p - x, {});
    std::snprintf(line, sizeof line,
                  "\n    probe %zu (%.2f, %.2f, %.2f) room %c, %.2f m away: barycentric %.3f, "
                  "visibility %.2e, weight %.2e, irradiance %.4f",
                  i, x.x, x.y, x.z, x.x < mid ? 'A' : 'B', glm::length(p - x), loc.barycentric[k],
                  v, loc.weights[k], maxAxisIrradiance(set.sh[i]));
    s += line;
  }
  return s;
}

// Every placed probe on every shipped scene, checked with many more rays than placement's
// own 96 and a different direction set: not inside geometry (share of rays reaching the back
// of a single-sided surface, the probe bake's validity rule) and not against a surface.
TEST(ProbeScenes, NoPlacedProbeInsideGeometryOnTheShippedScenes) {
  for (const char* name : {"cornell_box.gltf", "two_rooms.gltf", "courtyard.gltf"}) {
    const Loaded l = load(name);
    const ProbePlacementSettings s = quickPlacement(40);
    Result<ProbePlacement> placed = placeProbes(l.scene, *l.tracer, s);
    ASSERT_TRUE(bool(placed)) << name << ": " << placed.error();
    ASSERT_GE(placed->probes.size(), 4u) << name;
    for (const PlacedProbe& p : placed->probes) {
      float nearest = kInfinity;
      uint32_t back = 0;
      const uint32_t rays = 4096;
      for (uint32_t i = 0; i < rays; ++i) {
        const vec3 d = squareToUniformSphere(sobol2D(i, 0x5eedULL));
        if (std::optional<Hit> h = l.tracer->intersect(Ray{p.position, d, 0.0f, kInfinity})) {
          nearest = std::min(nearest, h->t);
          // The inside of geometry: back faces of single-sided opaque or cutout surfaces
          // (double-sided leaves and the BLEND awning have no inside).
          const Material& m = l.scene.materialOf(h->object, h->triangle);
          back += h->backFace && !m.doubleSided && m.alphaMode != AlphaMode::Blend ? 1 : 0;
        }
      }
      EXPECT_LE(float(back) / float(rays), 0.25f) << name << " probe at " << p.position.x
                                                  << ", " << p.position.y << ", "
                                                  << p.position.z;
      EXPECT_GE(nearest, 0.9f * s.validity.minSurfaceDistance)
          << name << " probe at " << p.position.x << ", " << p.position.y << ", "
          << p.position.z;
    }
  }
}

// two_rooms: the sun enters room A through the window and lights room A's floor and the
// shared wall's room-A face up to 0.87 m (docs/scenes.md). Points in room B within 0.2-0.3 m
// of the shared wall, right behind that patch, get only the light that comes round through
// the doorway. Probes placed automatically over the rooms (a quick placement: 64-probe
// budget, 256 check points) must give them that, not room A's light: at each point the
// interpolated irradiance is compared with SH baked directly there (the truth) and with the
// truth at the mirror point in room A, in front of the patch. A tetrahedron from a room-A
// probe through the wall pulls the value towards room A's; the bake's visibility maps weight
// such a probe down by its Chebyshev visibility (1e-6 for one a metre behind the wall).
// Known fragility, still true with visibility: a placement that leaves these points below
// its lowest probes (with other check points or another sampling sequence) extrapolates them
// from an outer cell whose hull face joins probes metres apart, across the wall, and a
// room-A probe 4 m away keeps a visibility of 0.03-0.2 through the wall in a 16 x 16 map
// (the depth spread of a texel at that distance): ~0.01 lux, which fails the second bound
// (docs/probe_placement.md, "What is left"; ProbeScenesWall below maps this over 128 points).
TEST(ProbeScenes, DarkRoomBehindTheSunlitWallGetsNoSunThroughIt) {
  const Loaded l = load("two_rooms.gltf");
  ProbePlacementSettings s = quickPlacement(64);
  s.volumes = {kThickWall.rooms()};
  Result<ProbePlacement> placed = placeProbes(l.scene, *l.tracer, s);
  ASSERT_TRUE(bool(placed)) << placed.error();
  const std::vector<vec3> positions = placed->positions();
  ProbeBakeSettings bake;
  bake.rays = 2048;
  Result<ProbeSet> set = bakeProbes(l.scene, *l.tracer, positions, bake);
  ASSERT_TRUE(bool(set)) << set.error();

  std::vector<vec3> behind, mirror;
  for (float d : {0.2f, 0.3f})
    for (float y : {0.3f, 0.6f})
      for (float z : {1.3f, 1.6f, 1.9f}) {
        behind.push_back(vec3(4.25f + d, y, z));
        mirror.push_back(vec3(4.0f - d, y, z));
      }
  ProbeBakeSettings truthBake = bake;
  truthBake.rays = 8192;
  truthBake.seed = 99;
  const std::vector<ShL2Rgb> truthB = bakePointSh(l.scene, *l.tracer, behind, truthBake);
  const std::vector<ShL2Rgb> truthA = bakePointSh(l.scene, *l.tracer, mirror, truthBake);
  ASSERT_EQ(truthB.size(), behind.size());
  for (size_t i = 0; i < behind.size(); ++i) {
    const float eB = maxAxisIrradiance(truthB[i]);
    const float eA = maxAxisIrradiance(truthA[i]);
    const ProbeLocation loc = locateProbe(*set, behind[i]);
    const float e = maxAxisIrradiance(interpolateProbes(*set, loc));
    std::printf("(%.2f, %.2f, %.2f): interpolated %.4f, truth %.4f, room A mirror %.4f lux\n",
                behind[i].x, behind[i].y, behind[i].z, e, eB, eA);
    // The wall really separates light from dark here (room A is hundreds of times brighter:
    // the test has teeth) ...
    EXPECT_GT(eA, 100.0f * eB) << i;
    // ... and no share of room A's light comes through it: a tetrahedron reaching a room-A
    // probe would add a weight (tenths) x eA. What is left is room B's own dim light, which
    // the probes give to within their and the truth's noise at these few-millilux levels.
    EXPECT_LT(e, 0.01f * eA) << i << ": " << describeLookup(*set, behind[i], loc, kThickWall.mid());
    EXPECT_LT(e, 2.0f * eB + 1e-3f)
        << i << ": " << describeLookup(*set, behind[i], loc, kThickWall.mid());
  }
}

// two_rooms, room A: a 2.2 m bar on the floor (y = 0.3, z = 1.3) from x = 1.2 (in the shade) to
// x = 3.4 (in the sun patch). Probes on a 0.5 m lattice, direct light only. An LPPV over the
// bar follows the light along it; one probe lookup at the bar's centre gives every pixel the
// same light. The LPPV equals the probe field at its samples (it is filled from it).
TEST(ProbeScenes, LppvOnALongObjectAcrossLightAndShadowVariesAlongIt) {
  const Loaded l = load("two_rooms.gltf");
  const vec3 sunward = -l.scene.lights.at(0).direction;
  ASSERT_EQ(l.scene.lights.at(0).type, LightType::Directional);
  const vec3 shadeEnd(1.2f, 0.3f, 1.3f), sunEnd(3.4f, 0.3f, 1.3f);
  ASSERT_FALSE(l.tracer->occluded(Ray{sunEnd, sunward, 1e-3f, kInfinity})) << "sun end lit";
  ASSERT_TRUE(l.tracer->occluded(Ray{shadeEnd, sunward, 1e-3f, kInfinity})) << "shade end";

  std::vector<vec3> positions;
  for (float x = 0.25f; x < 4.0f; x += 0.5f)
    for (float y = 0.25f; y < 3.0f; y += 0.5f)
      for (float z = 0.25f; z < 4.0f; z += 0.5f) positions.push_back(vec3(x, y, z));
  ProbeBakeSettings bake;
  bake.rays = 512;
  bake.bounces = 0;
  Result<ProbeSet> set = bakeProbes(l.scene, *l.tracer, positions, bake);
  ASSERT_TRUE(bool(set)) << set.error();

  LppvBuildSettings lb;
  lb.boundsMin = vec3(1.1f, 0.2f, 1.2f);
  lb.boundsMax = vec3(3.5f, 0.4f, 1.4f);
  lb.resolution = glm::ivec3(12, 1, 1);
  Result<LppvBuild> lppv = buildLppvFromProbes(*set, lb);
  ASSERT_TRUE(bool(lppv)) << lppv.error();

  const vec3 up(0.0f, 1.0f, 0.0f);
  const float eSun = luminance(lppvIrradiance(lppv->volume, sunEnd, up));
  const float eShade = luminance(lppvIrradiance(lppv->volume, shadeEnd, up));
  const vec3 centre = 0.5f * (sunEnd + shadeEnd);
  const float eSingle =
      luminance(probeIrradiance(interpolateProbes(*set, locateProbe(*set, centre)), up));
  std::printf("LPPV: sun end %.3f, shade end %.3f; one probe lookup at the centre %.3f lux\n",
              eSun, eShade, eSingle);
  EXPECT_GT(eSun, 3.0f * eShade);           // the bar goes from sun into shade
  EXPECT_GT(eSun, 1.3f * eSingle);          // a single lookup misses the sunlit end ...
  EXPECT_LT(eShade, eSingle / 1.3f);        // ... and brightens the shaded one

  // At a sample position the volume holds the field's interpolation exactly.
  const std::vector<vec3> samples = lppvSamplePositions(lppv->volume);
  for (size_t i = 0; i < samples.size(); ++i) {
    const vec3 field = probeIrradiance(interpolateProbes(*set, locateProbe(*set, samples[i])), up);
    const vec3 volume = lppvIrradiance(lppv->volume, samples[i], up);
    EXPECT_NEAR(luminance(volume), luminance(field), 1e-4f * (1.0f + luminance(field))) << i;
  }
}

// ---- light through the shared wall: two_rooms and two_rooms_thin ----------------------------

enum class Layout { Grid, Placement, Octree };

const char* layoutName(Layout layout) {
  switch (layout) {
    case Layout::Grid:
      return "uniform grid";
    case Layout::Placement:
      return "placement";
    case Layout::Octree:
      return "octree corners";
  }
  return "?";
}

// Probes over the rooms: a 96-probe uniform grid (about 1 m apart), a quick automatic
// placement of at most 64, or Godot-style octree corners at level 3 (1.03 m cells: every
// corner of a cell touching a surface, relocated off the surfaces; 105-106 probes).
std::vector<vec3> layoutPositions(const Loaded& l, const WallScene& w, Layout layout) {
  const std::vector<Bounds3> rooms{w.rooms()};
  switch (layout) {
    case Layout::Grid: {
      Result<std::vector<vec3>> grid = uniformGridPositions(l.scene, *l.tracer, rooms, 96, {});
      EXPECT_TRUE(bool(grid)) << grid.error();
      return grid ? *grid : std::vector<vec3>{};
    }
    case Layout::Placement: {
      ProbePlacementSettings s = quickPlacement(64);
      s.volumes = rooms;
      Result<ProbePlacement> placed = placeProbes(l.scene, *l.tracer, s);
      EXPECT_TRUE(bool(placed)) << placed.error();
      return placed ? placed->positions() : std::vector<vec3>{};
    }
    case Layout::Octree: {
      OctreePlacementSettings s;
      s.volumes = rooms;
      s.level = 3;
      Result<OctreePlacement> octree = octreeCornerPlacement(l.scene, *l.tracer, s);
      EXPECT_TRUE(bool(octree)) << octree.error();
      return octree ? octree->positions : std::vector<vec3>{};
    }
  }
  return {};
}

// Scenes, baked probe sets and points are shared by the tests of one run (each is built on
// first use, so a filtered run builds only what it needs).
const Loaded& loaded(const WallScene& w) {
  static std::map<std::string, Loaded> cache;
  auto [it, fresh] = cache.try_emplace(w.file);
  if (fresh) loadInto(it->second, w.file);
  return it->second;
}

// Probe bakes: the default integrator (16 bounces) and visibility maps (16 x 16), 1024 rays.
const ProbeSet& bakedLayout(const WallScene& w, Layout layout) {
  static std::map<std::pair<std::string, Layout>, ProbeSet> cache;
  const auto key = std::make_pair(std::string(w.file), layout);
  auto it = cache.find(key);
  if (it == cache.end()) {
    const Loaded& l = loaded(w);
    ProbeBakeSettings bake;
    bake.rays = 1024;
    Result<ProbeSet> set = bakeProbes(l.scene, *l.tracer, layoutPositions(l, w, layout), bake);
    EXPECT_TRUE(bool(set)) << set.error();
    it = cache.emplace(key, set ? std::move(set).value() : ProbeSet{}).first;
  }
  return it->second;
}

// 128 random valid points (no surface within 0.1 m) in room B within 0.6 m of the wall's
// room-B face, z <= 2.3 (0.5 m from the doorway), each with its mirror image through the
// wall's mid-plane in room A and the maximum axis irradiance of SH baked at both (the probe
// bake's estimator).
struct BehindTheWall {
  std::vector<vec3> points, mirrors;
  std::vector<float> truth, mirrorTruth;
};

const BehindTheWall& behindTheWall(const WallScene& w) {
  static std::map<std::string, BehindTheWall> cache;
  auto it = cache.find(w.file);
  if (it != cache.end()) return it->second;
  const Loaded& l = loaded(w);
  BehindTheWall b;
  const std::vector<Bounds3> band{
      Bounds3{vec3(w.faceB, 0.0f, 0.0f), vec3(w.faceB + 0.6f, 3.0f, 2.3f)}};
  b.points = randomValidPoints(l.scene, *l.tracer, band, 128, 0x3a11, {});
  EXPECT_EQ(b.points.size(), 128u);
  for (const vec3& p : b.points) {
    b.mirrors.push_back(vec3(2.0f * w.mid() - p.x, p.y, p.z));
    EXPECT_TRUE(isValidProbePoint(l.scene, *l.tracer, b.mirrors.back(), {}))
        << w.file << ": mirror of " << p.x << ", " << p.y << ", " << p.z;
  }
  ProbeBakeSettings truthBake;
  truthBake.rays = 1024;
  truthBake.seed = 99;
  for (const ShL2Rgb& sh : bakePointSh(l.scene, *l.tracer, b.points, truthBake))
    b.truth.push_back(maxAxisIrradiance(sh));
  // Room A's light sets the bound: 2048 rays keep its noise under 10% (5% median).
  truthBake.rays = 2048;
  for (const ShL2Rgb& sh : bakePointSh(l.scene, *l.tracer, b.mirrors, truthBake))
    b.mirrorTruth.push_back(maxAxisIrradiance(sh));
  EXPECT_EQ(b.truth.size(), b.points.size());
  EXPECT_EQ(b.mirrorTruth.size(), b.points.size());
  return cache.emplace(w.file, std::move(b)).first->second;
}

// What the blend at `loc` takes from the probes on room A's side of the wall's mid-plane that
// do not see p (geometry on the segment between them); `seen` counts those that do.
ShL2Rgb lightThroughTheWall(const Tracer& tracer, const ProbeSet& set, vec3 p,
                            const ProbeLocation& loc, float mid, size_t* seen = nullptr) {
  ShL2Rgb sum;
  for (int k = 0; k < 4; ++k) {
    const size_t i = size_t(loc.probes[k]);
    if (!(loc.weights[k] > 0.0f) || set.positions[i].x >= mid) continue;
    const vec3 to = set.positions[i] - p;
    const float length = glm::length(to);
    if (!tracer.occluded(Ray{p, to / length, 0.0f, length})) {
      if (seen) ++*seen;
      continue;
    }
    sum += set.sh[i] * loc.weights[k];
  }
  return sum;
}

struct Ratios {
  std::vector<float> sorted;  // ascending
  size_t over = 0;            // entries above 1
  float quantile(float q) const { return sorted[size_t(q * float(sorted.size() - 1))]; }
  float worst() const { return sorted.back(); }
};

Ratios summarize(std::vector<float> r) {
  Ratios out;
  out.over = size_t(std::count_if(r.begin(), r.end(), [](float x) { return x > 1.0f; }));
  std::sort(r.begin(), r.end());
  out.sorted = std::move(r);
  return out;
}

// Points in room B within 0.6 m of the wall behind room A's sun patch: the blend must not
// bring room A's light through the wall. The bound is the interpolated irradiance <=
// 2 x the truth at the point + 1% of the truth at its mirror point in room A (maximum axis
// irradiance, luminance, in lux). It is applied to the light that leaks: the part of the
// blend that comes from probes in room A that do not see the point (a ray between them hits
// geometry; probes that see it through the doorway are counted apart). Room B's own light,
// from its own probes, is left out of the check: it reaches these points only after several
// bounces through the doorway, a few millilux whose bake is mostly noise (SH baked three
// times at the same points: per-point CV 0.96 at 1024 rays, 0.26 at 16384), so that two such
// estimates differ by more than 2x at some of 128 points with no room-A probe in the blend
// (on two_rooms' grid the whole blend reaches 0.7-2.3x the bound with 8192 truth rays, over
// point and bake seeds, while the part through the wall stays below 0.08x). Room A's light
// is bright (0.2-7 lux at the mirror points; CV 5%, 10% at worst), so the check's margin is
// set by the blend, not by noise: on two_rooms' grid, over six bake, point and truth seeds,
// the worst point is at 0.005-0.075 of the bound.
//
// With plain barycentric blending, cells reaching from room A's probes give these points
// tenths of room A's light (the check fails at most points on the grid); with visibility the
// weight left on a hidden probe in the sun patch (6-7 lux) must be below ~1e-3.
void expectNoLightThroughTheWall(const WallScene& w, Layout layout) {
  const Tracer& tracer = *loaded(w).tracer;
  const ProbeSet& set = bakedLayout(w, layout);
  ASSERT_GT(set.probeCount(), 4) << w.file << " " << layoutName(layout);
  ASSERT_FALSE(set.visibility.empty());
  const BehindTheWall& b = behindTheWall(w);
  ASSERT_EQ(b.truth.size(), b.points.size());
  ASSERT_EQ(b.mirrorTruth.size(), b.points.size());
  ProbeBlendSettings plain;
  plain.visibility = false;
  std::vector<float> ratio, plainRatio, wholeRatio;
  size_t outer = 0, seen = 0;
  for (size_t i = 0; i < b.points.size(); ++i) {
    const vec3 p = b.points[i];
    const float bound = 2.0f * b.truth[i] + 0.01f * b.mirrorTruth[i];
    const ProbeLocation loc = locateProbe(set, p);
    outer += loc.cell >= set.innerCellCount ? 1 : 0;
    const float leak = maxAxisIrradiance(lightThroughTheWall(tracer, set, p, loc, w.mid(), &seen));
    ratio.push_back(leak / bound);
    wholeRatio.push_back(maxAxisIrradiance(interpolateProbes(set, loc)) / bound);
    const ProbeLocation flat = locateProbe(set, p, -1, plain);
    plainRatio.push_back(maxAxisIrradiance(lightThroughTheWall(tracer, set, p, flat, w.mid())) /
                         bound);
    EXPECT_LE(leak, bound) << w.file << ", " << layoutName(layout) << ": at (" << p.x << ", " << p.y
                           << ", " << p.z << ") room A's probes give " << leak
                           << " lux through the wall; truth " << b.truth[i] << ", mirror "
                           << b.mirrorTruth[i] << "; " << describeLookup(set, p, loc, w.mid());
  }
  const Ratios vis = summarize(ratio), flat = summarize(plainRatio);
  const Ratios whole = summarize(wholeRatio);
  std::printf(
      "%s, %s (%d probes; %zu of %zu points outside the hull, %zu room-A probes seeing "
      "a point): light through the wall / bound median %.2g, 90%% %.2g, worst %.3g, "
      "%zu over 1 (whole blend: worst %.3g); plain blend: median %.2g, worst %.3g, %zu "
      "over 1\n",
      w.file, layoutName(layout), set.probeCount(), outer, b.points.size(), seen,
      vis.quantile(0.5f), vis.quantile(0.9f), vis.worst(), vis.over, whole.worst(),
      flat.quantile(0.5f), flat.worst(), flat.over);
  if (layout == Layout::Grid) {
    // The check has teeth: without visibility the grid's cells that span the wall give
    // points behind it many times the bound (measured over six bake and point seeds: 57-70
    // of 128 over it on two_rooms, 85-96 on two_rooms_thin, the worst 320-720x).
    EXPECT_GE(flat.over, b.points.size() / 4) << w.file;
    EXPECT_GT(flat.worst(), 30.0f) << w.file;
  }
}

TEST(ProbeScenesWall, TwoRoomsUniformGridBringsNoLightThroughTheWall) {
  expectNoLightThroughTheWall(kThickWall, Layout::Grid);
}
TEST(ProbeScenesWall, TwoRoomsPlacedProbesBringNoLightThroughTheWall) {
  expectNoLightThroughTheWall(kThickWall, Layout::Placement);
}
TEST(ProbeScenesWall, TwoRoomsOctreeCornersBringNoLightThroughTheWall) {
  expectNoLightThroughTheWall(kThickWall, Layout::Octree);
}
TEST(ProbeScenesWall, ThinWallUniformGridBringsNoLightThroughTheWall) {
  expectNoLightThroughTheWall(kThinWall, Layout::Grid);
}
TEST(ProbeScenesWall, ThinWallPlacedProbesBringNoLightThroughTheWall) {
  expectNoLightThroughTheWall(kThinWall, Layout::Placement);
}
TEST(ProbeScenesWall, ThinWallOctreeCornersBringNoLightThroughTheWall) {
  expectNoLightThroughTheWall(kThinWall, Layout::Octree);
}

// ---- continuity across cells that span the wall --------------------------------------------
//
// With barycentric weights b_k, visibilities v_k, u_k = b_k v_k and U = sum_k u_k, the blend of
// the probes' irradiances E_k (one normal) is E = sum_k (u_k / U) E_k, so
//   dE = sum_k du_k (E_k - E) / U,   |dE| <= (max_k E_k - min_k E_k) sum_k |du_k| / U,
//   |du_k| / U <= (v_k / U) |grad b_k| |dp| + w_k |d ln v_k|          (w_k = u_k / U).
// Barycentric: |grad b_k| is 1 / the cell's height over the face opposite probe k. Visibility
// (kiln/probe_visibility.h): v_k is 1 for d <= mu and floored, both flat; in between
// ln v = 3 ln c, c = s2 / (s2 + e^2), e = d - mu, s2 = max(m2 - mu^2, (minSigma / D)^2), so
//   |d ln c| = |2 e de / (s2 + e^2) - e^2 ds2 / (s2 (s2 + e^2))| <= |de| / s + |ds2| / s2
// (2 e / (s2 + e^2) is largest, 1 / s, at e = s). d changes by at most |dp| / D. mu and m2 are
// bilinear in the map: their gradient in texel units is at most sqrt(2) x the range of the
// footprint's four texels (Dmu, Dm2); texel coordinates move at most R / 2 x 1.618 per radian
// of direction (the octahedral map's largest stretch, (1 + sqrt 5) / 2, the largest singular
// value of its Jacobian, reached on the equator at the x and y axes; the wrapped seams are
// continuous), and the direction from the probe at most |dp| / r radians (r: distance to the
// probe). With G = sqrt(2) x 1.618 x R / (2 r) = 1.145 R / r:
//   |d ln v_k| <= 3 [(1 / D + G Dmu) / s + G (Dm2 + 2 mu Dmu) / s2] |dp|.
// The sum of both terms is the slope bound L(p) (per metre; normalized depths). For a maximum
// over the six axis normals, |d max_a E_a| <= max_a |dE_a|, so the range is the largest over
// the axes. Each 1 mm step's jump must stay below 2 x 1 mm x L x range, with L and the range
// the larger of the step's two ends (x 2: the first-order bound varies within the step; cells
// change at shared faces, where the blend is continuous). And a jump that is no artefact of
// the step shrinks with it: the largest jump at 0.25 mm steps is about 1/4 of that at 1 mm
// (a discontinuity of size J would give J at every step size).

struct SlopeBound {
  float slope = 0.0f;  // L, per metre
  float range = 0.0f;  // lux
};

// L(p) and the probes' irradiance range for p in an inner cell (see above).
SlopeBound blendSlopeBound(const ProbeSet& set, vec3 p) {
  const ProbeLocation loc = locateProbe(set, p);
  SlopeBound out;
  const glm::ivec4 cell = set.cells[size_t(loc.cell)];
  const vec3 x0 = set.positions[size_t(cell[0])];
  // Rows of the inverse edge matrix are the gradients of barycentrics 1..3.
  const glm::mat3 rows = glm::transpose(glm::inverse(
      glm::mat3(set.positions[size_t(cell[1])] - x0, set.positions[size_t(cell[2])] - x0,
                set.positions[size_t(cell[3])] - x0)));
  const vec3 gradB[4] = {-(rows[0] + rows[1] + rows[2]), rows[0], rows[1], rows[2]};
  const ProbeVisibility& vis = set.visibility;
  const ProbeBlendSettings blend;
  float v[4], sum = 0.0f;
  for (int k = 0; k < 4; ++k) {
    const size_t i = size_t(loc.probes[k]);
    v[k] = probeVisibility(vis.probe(int32_t(i)), vis.resolution, vis.maxDistance[i],
                           p - set.positions[i], blend);
    sum += loc.barycentric[k] * v[k];
  }
  for (int k = 0; k < 4; ++k) {
    const size_t i = size_t(loc.probes[k]);
    for (int c = 0; c < 4; ++c)
      if (size_t(cell[c]) == i) out.slope += v[k] / sum * glm::length(gradB[c]);
    const float dMax = vis.maxDistance[i];
    const vec3 offset = p - set.positions[i];
    const float r = glm::length(offset);
    const float d = std::clamp((r - blend.distanceBias) / dMax, 0.0f, 1.0f);
    const OctahedralFootprint f = octahedralFootprint(octahedralEncode(offset / r), vis.resolution);
    const std::span<const uint16_t> m = vis.probe(int32_t(i));
    float mu = 0.0f, m2 = 0.0f, muLo = 1.0f, muHi = 0.0f, m2Lo = 1.0f, m2Hi = 0.0f;
    for (int t = 0; t < 4; ++t) {
      const float a = float(m[2 * size_t(f.texel[t])]) / 65535.0f;
      const float b = float(m[2 * size_t(f.texel[t]) + 1]) / 65535.0f;
      mu += f.weight[t] * a;
      m2 += f.weight[t] * b;
      muLo = std::min(muLo, a), muHi = std::max(muHi, a);
      m2Lo = std::min(m2Lo, b), m2Hi = std::max(m2Hi, b);
    }
    if (d > mu && v[k] > kVisibilityFloor) {
      const float minSigma = blend.minSigma / dMax;
      const float s2 = std::max(m2 - mu * mu, minSigma * minSigma);
      const float g = 1.145f * float(vis.resolution) / r;
      out.slope += loc.weights[k] * 3.0f *
                   ((1.0f / dMax + g * (muHi - muLo)) / std::sqrt(s2) +
                    g * ((m2Hi - m2Lo) + 2.0f * mu * (muHi - muLo)) / s2);
    }
  }
  for (int a = 0; a < 3; ++a)
    for (float sign : {-1.0f, 1.0f}) {
      vec3 n(0.0f);
      n[a] = sign;
      float lo = kInfinity, hi = -kInfinity;
      for (int k = 0; k < 4; ++k) {
        const float e = luminance(probeIrradiance(set.sh[size_t(loc.probes[k])], n));
        lo = std::min(lo, e);
        hi = std::max(hi, e);
      }
      out.range = std::max(out.range, hi - lo);
    }
  return out;
}

struct LineSweep {
  float maxJump = 0.0f;     // largest |E(p + step) - E(p)|
  float worstShare = 0.0f;  // largest jump / (2 step L range)
  float maxSlope = 0.0f;    // largest L met
  size_t outer = 0;         // samples outside the hull (the bound assumes inner cells)
  size_t overBound = 0;     // steps whose jump exceeds the bound
};

LineSweep sweepLine(const ProbeSet& set, vec3 a, vec3 b, float step) {
  LineSweep s;
  const float length = glm::length(b - a);
  const int n = int(length / step);
  float previous = 0.0f;
  SlopeBound previousBound;
  int32_t hint = -1;
  for (int i = 0; i <= n; ++i) {
    const vec3 p = a + (b - a) * (float(i) * step / length);
    const ProbeLocation loc = locateProbe(set, p, hint);
    hint = loc.cell;
    const float e = maxAxisIrradiance(interpolateProbes(set, loc));
    if (loc.cell >= set.innerCellCount) {
      ++s.outer;
      continue;
    }
    const SlopeBound bound = blendSlopeBound(set, p);
    if (i > 0) {
      const float jump = std::fabs(e - previous);
      const float allowed = 2.0f * step * std::max(bound.slope, previousBound.slope) *
                            std::max(bound.range, previousBound.range);
      s.maxJump = std::max(s.maxJump, jump);
      if (allowed > 0.0f) s.worstShare = std::max(s.worstShare, jump / allowed);
      // Float rounding of the blend: a few ulps of the largest probe value.
      s.overBound += jump > allowed + 1e-6f * (1.0f + bound.range) ? 1 : 0;
    }
    s.maxSlope = std::max(s.maxSlope, bound.slope);
    previous = e;
    previousBound = bound;
  }
  return s;
}

// Three lines through cells with probes on both sides of the wall, all in valid space: two
// parallel to the wall 0.2 m into room B (at the sun patch's height behind it, and 1.5 m up),
// where room A's probes are hidden, and one from room B through the doorway into room A,
// where they come into view.
TEST(ProbeScenesWall, BlendIsContinuousWithABoundedSlopeAcrossTheWallsCells) {
  for (const WallScene& w : {kThickWall, kThinWall}) {
    const ProbeSet& set = bakedLayout(w, Layout::Grid);
    ASSERT_FALSE(set.visibility.empty()) << w.file;
    struct Line {
      vec3 a, b;
      const char* name;
    };
    const Line lines[] = {
        {vec3(w.faceB + 0.2f, 0.6f, 0.6f), vec3(w.faceB + 0.2f, 0.6f, 2.4f), "behind the patch"},
        {vec3(w.faceB + 0.2f, 1.5f, 0.6f), vec3(w.faceB + 0.2f, 1.5f, 2.4f), "1.5 m up"},
        {vec3(w.faceB + 0.6f, 1.0f, 3.3f), vec3(w.faceA - 0.6f, 1.0f, 3.3f), "doorway"}};
    for (const Line& line : lines) {
      for (float t = 0.0f; t <= 1.0f; t += 0.05f)
        ASSERT_TRUE(isValidProbePoint(loaded(w).scene, *loaded(w).tracer,
                                      line.a + t * (line.b - line.a), {}))
            << w.file << ", " << line.name << " at " << t;
      const LineSweep mm = sweepLine(set, line.a, line.b, 1e-3f);
      const LineSweep quarter = sweepLine(set, line.a, line.b, 0.25e-3f);
      std::printf(
          "%s, %s: largest jump %.3g lux per 1 mm, %.3g per 0.25 mm (ratio %.3f); "
          "jump / bound at most %.3f; L up to %.1f per m\n",
          w.file, line.name, mm.maxJump, quarter.maxJump, quarter.maxJump / mm.maxJump,
          mm.worstShare, mm.maxSlope);
      EXPECT_EQ(mm.outer + quarter.outer, 0u) << w.file << ", " << line.name;
      EXPECT_EQ(mm.overBound, 0u) << w.file << ", " << line.name;
      EXPECT_EQ(quarter.overBound, 0u) << w.file << ", " << line.name;
      EXPECT_GT(mm.maxJump, 0.0f) << w.file << ", " << line.name;
      EXPECT_LT(quarter.maxJump, 0.3f * mm.maxJump) << w.file << ", " << line.name;
      // The bound is no blanket: a jump of the probes' whole range would break it anywhere
      // on the line (measured: 2 x 1 mm x L <= 0.27).
      EXPECT_LT(2.0f * 1e-3f * mm.maxSlope, 1.0f) << w.file << ", " << line.name;
    }
  }
}

}  // namespace
}  // namespace kiln
