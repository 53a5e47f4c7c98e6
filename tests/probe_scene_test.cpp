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
#include <tuple>
#include <vector>

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

const std::vector<vec3>& probePositions(const WallScene& w, Layout layout) {
  static std::map<std::pair<std::string, Layout>, std::vector<vec3>> cache;
  const auto key = std::make_pair(std::string(w.file), layout);
  auto it = cache.find(key);
  if (it == cache.end()) it = cache.emplace(key, layoutPositions(loaded(w), w, layout)).first;
  return it->second;
}

// Probe bakes: the default integrator (16 bounces) and visibility maps (the default 24 x 24),
// 1024 rays unless told.
const ProbeSet& bakedLayout(const WallScene& w, Layout layout, uint32_t rays = 1024,
                            DelaunayBackend backend = ProbeTopologySettings{}.backend) {
  static std::map<std::tuple<std::string, Layout, uint32_t, DelaunayBackend>, ProbeSet> cache;
  const auto key = std::make_tuple(std::string(w.file), layout, rays, backend);
  auto it = cache.find(key);
  if (it == cache.end()) {
    const Loaded& l = loaded(w);
    ProbeBakeSettings bake;
    bake.rays = rays;
    bake.topology.backend = backend;
    Result<ProbeSet> set = bakeProbes(l.scene, *l.tracer, probePositions(w, layout), bake);
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
// (the whole blend's worst point is at 1.2-5x the bound on the grid and the octree corners,
// over six bake and six point seeds, while the part through the wall stays below 1e-12x).
// Room A's light is bright (0.2-7 lux at the mirror points; CV 5%, 10% at worst), so the
// check's margin is set by the blend, not by noise. Measured with the 24 x 24 maps over six
// bake seeds x six point seeds (these points and five other sets, truth seeds with them), the
// worst point's share of the bound: grid 1.5e-17 (two_rooms) and 3.3e-15 (two_rooms_thin);
// placement 1.1e-3 and 0.22; octree corners 1.2e-13, and on two_rooms_thin 2.2e-4 for all
// point sets but one, at which it is 7.5-26x in every bake (a room-B corner by the end wall,
// (4.19, 2.89, 0.13), outside the hull: its three probes are all hidden from it, 4 m away
// along the wall, and the relative floor gives the two in room A 44% of the weight). Other
// placement seeds (1-7) put such points in all-hidden cells too, and on two_rooms_thin let
// room-A probes see through the 5 cm wall where a texel spans a room corner (visibility
// 0.2-0.4): those placements fail here, up to 42x.
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
    const float leak = maxAxisIrradiance(lightThroughWall(tracer, set, p, loc, w.mid(), &seen));
    ratio.push_back(leak / bound);
    wholeRatio.push_back(maxAxisIrradiance(interpolateProbes(set, loc)) / bound);
    const ProbeLocation flat = locateProbe(set, p, -1, plain);
    plainRatio.push_back(maxAxisIrradiance(lightThroughWall(tracer, set, p, flat, w.mid())) /
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

// two_rooms: the sun enters room A through the window and lights room A's floor and the
// shared wall's room-A face up to 0.87 m (docs/scenes.md). Twelve points in room B, 0.2-0.3 m
// behind the wall right behind that patch, get only the light that comes round through the
// doorway: 0.002-0.005 lux (SH baked there, 4 x 16384 rays; per-point CV 0.13-0.69 even so),
// against 1.1-7.9 lux at their mirror points in front of the patch. The probes are the quick
// placement of ProbeScenesWall (64-probe budget), baked with 2048 rays. At each point:
//  - No light through the wall: the part of the blend that comes from room-A probes hidden
//    from the point (as in ProbeScenesWall; none sees these points) stays below the issue's
//    bound, 2 x the truth + 1% of the mirror's truth. Measured over placement seeds 0-5 x six
//    bakes: below 4e-16 of it (weights on room-A probes 1e-17 or less).
//  - The whole blend is room B's own light: at most kRoomBNoise x the brightest truth among
//    the point and its cell's room-B probes (SH baked at those probes' positions, 16384 rays).
//    A blend of room B's light field holds no more than its brightest sample; what the probes
//    add on top is their bake noise.
// The old second bound, 2 x the point's truth + 1e-3 lux (with 1% of the mirror's truth as
// the first), took the blend to reproduce the truth at the point to within noise, so it
// counted room B's own interpolation error as light through the wall: the points' cells have
// room-B probes by the doorway, 1.3-1.9 m away, where room B's light is 4-13x theirs
// ((4.73, 0.11, 3.06): 0.021-0.026 lux), so the blend, from room B's probes alone (room A's
// weights below 1e-20), gives 0.002-0.021 lux here: up to 5.6x the truth, 0.017 lux above it,
// over six bakes (20x and 0.042 lux with placement seeds 1-2); at (4.55, 0.6, 1.9) it gave
// 0.014 lux, over both old bounds (0.012).
// This placement's cells here reach room A only at a dim probe in its far corner (1.48, 0.11,
// 0.11; 0.08 lux), so the plain blend (no visibility) takes 0.011-0.033 lux through the wall:
// above the points' own light at all twelve, but within the first bound, and within the
// second at all but two. The check that the plain blend fails is ProbeScenesWall's (92 of 128
// points over the bound there); here it only shows that the cells do span the wall.
TEST(ProbeScenes, DarkRoomBehindTheSunlitWallGetsNoSunThroughIt) {
  // Room B's probes at 2048 rays: probe / truth at the same place up to 2.6 over eight bakes
  // (SD 0.0007-0.008 lux), and the truths at 16384 rays vary by 2-4x between seeds at these
  // light levels. Measured blend / brightest room-B truth: at most 2.1 over six bakes x
  // two truth seeds, 2.25 with placement seeds 0-5.
  constexpr float kRoomBNoise = 4.0f;
  const WallScene& w = kThickWall;
  const Loaded& l = loaded(w);
  const ProbeSet& set = bakedLayout(w, Layout::Placement, 2048);
  ASSERT_GT(set.probeCount(), 4);
  ASSERT_FALSE(set.visibility.empty());
  std::vector<vec3> behind, mirror;
  for (float d : {0.2f, 0.3f})
    for (float y : {0.3f, 0.6f})
      for (float z : {1.3f, 1.6f, 1.9f}) {
        behind.push_back(vec3(w.faceB + d, y, z));
        mirror.push_back(vec3(w.faceA - d, y, z));
      }
  // The points and their cells' room-B probes (with a barycentric share) get SH baked with
  // 16384 rays: room B's light there is mostly noise at fewer (per-point CV 0.13-0.69 even at
  // 16384, over four seeds).
  std::vector<ProbeLocation> locs;
  std::vector<vec3> dim = behind;
  for (const vec3& p : behind) {
    locs.push_back(locateProbe(set, p));
    for (int k = 0; k < 4; ++k) {
      const vec3 x = set.positions[size_t(locs.back().probes[k])];
      if (x.x > w.mid() && locs.back().barycentric[k] > 0.0f &&
          std::find(dim.begin() + ptrdiff_t(behind.size()), dim.end(), x) == dim.end())
        dim.push_back(x);
    }
  }
  ProbeBakeSettings truthBake;
  truthBake.rays = 16384;
  truthBake.seed = 99;
  std::vector<float> truthDim;
  for (const ShL2Rgb& sh : bakePointSh(l.scene, *l.tracer, dim, truthBake))
    truthDim.push_back(maxAxisIrradiance(sh));
  // Room A's light is bright: 2048 rays keep its noise under 10%.
  truthBake.rays = 2048;
  std::vector<float> truthA;
  for (const ShL2Rgb& sh : bakePointSh(l.scene, *l.tracer, mirror, truthBake))
    truthA.push_back(maxAxisIrradiance(sh));
  ASSERT_EQ(truthDim.size(), dim.size());
  ASSERT_EQ(truthA.size(), mirror.size());
  ProbeBlendSettings plain;
  plain.visibility = false;
  float worstLeak = 0.0f, worstBlend = 0.0f, plainLeak = 0.0f;
  size_t plainOverTruth = 0;
  for (size_t i = 0; i < behind.size(); ++i) {
    const vec3 p = behind[i];
    const ProbeLocation& loc = locs[i];
    const float eB = truthDim[i], eA = truthA[i];
    float roomB = eB;
    for (int k = 0; k < 4; ++k) {
      const auto at = std::find(dim.begin() + ptrdiff_t(behind.size()), dim.end(),
                                set.positions[size_t(loc.probes[k])]);
      if (at != dim.end()) roomB = std::max(roomB, truthDim[size_t(at - dim.begin())]);
    }
    const float e = maxAxisIrradiance(interpolateProbes(set, loc));
    const float leak = maxAxisIrradiance(lightThroughWall(*l.tracer, set, p, loc, w.mid()));
    const ProbeLocation flat = locateProbe(set, p, -1, plain);
    const float ePlain = maxAxisIrradiance(interpolateProbes(set, flat));
    const float leakPlain =
        maxAxisIrradiance(lightThroughWall(*l.tracer, set, p, flat, w.mid()));
    worstLeak = std::max(worstLeak, leak / (2.0f * eB + 0.01f * eA));
    worstBlend = std::max(worstBlend, e / (kRoomBNoise * roomB));
    plainLeak = std::max(plainLeak, leakPlain / eA);
    plainOverTruth += leakPlain > eB ? 1 : 0;
    std::printf(
        "(%.2f, %.2f, %.2f): interpolated %.4f lux (through the wall %.2g), truth %.4f, room B "
        "at most %.4f, room A mirror %.3f; plain blend %.4f (through the wall %.4f)\n",
        p.x, p.y, p.z, e, leak, eB, roomB, eA, ePlain, leakPlain);
    // The wall really separates light from dark here (the test has teeth) ...
    EXPECT_GT(eA, 100.0f * eB) << i;
    // ... no light comes through it ...
    EXPECT_LE(leak, 2.0f * eB + 0.01f * eA) << i << ": " << describeLookup(set, p, loc, w.mid());
    // ... and the blend holds room B's own light.
    EXPECT_LE(e, kRoomBNoise * roomB) << i << ": " << describeLookup(set, p, loc, w.mid());
  }
  std::printf(
      "worst: through the wall / bound %.2g, blend / room B bound %.3f; plain blend "
      "through the wall up to %.2g of room A's light, above the truth at %zu points\n",
      worstLeak, worstBlend, plainLeak, plainOverTruth);
  // The cells span the wall: without visibility, room A's light through it exceeds the points'
  // own (measured: at 11-12 of the 12 points, over placement seeds 0-5).
  EXPECT_GE(plainOverTruth, behind.size() / 2);
}

// ---- continuity across cells that span the wall --------------------------------------------
//
// With barycentric weights b_k, visibilities v_k, u_k = b_k v_k, U = sum_k u_k and w_k = u_k / U,
// the blend of the probes' irradiances E_k (one normal) is E = sum_k w_k E_k, so
//   dE = sum_k du_k (E_k - E) / U,   |dE| <= (max_k E_k - min_k E_k) sum_k |du_k| / U.
// Visibility (kiln/probe_visibility.h): v_k = max(c_k a_k, floor), with c_k = 1 for d <= mu and
// C^3 beyond, C = s2 / (s2 + e^2), e = d - mu, s = max(sigma, minSigma / D), s2 = s^2, and the
// reach a_k = clamp(1 - (d - far) / w, 1e-12, 1), w = minSigma / D; mu, sigma and far are
// each bilinear in the map. Where v_k is floored it is flat; elsewhere dv_k = a_k dc_k + c_k da_k
// and
//   |du_k| / U <= (v_k / U) |grad b_k| |dp| + w_k |d ln c_k| + (b_k c_k / U) |da_k|.
// Barycentric: |grad b_k| is 1 / the cell's height over the face opposite probe k.
// Chebyshev: |d ln C| = |ds2 e^2 / (s2 (s2 + e^2)) - 2 e de / (s2 + e^2)| <= |ds2| / s2 + |de| / s
// (2 e / (s2 + e^2) is largest, 1 / s, at e = s), |ds2| / s2 = 2 |ds| / s, and ln c = 3 ln C.
// d changes by at most |dp| / D. A bilinear value's gradient in texel units is at most
// sqrt(2) x the range of the footprint's four texels (Dmu, Dsigma, Dfar; while s sits on its
// minimum it is flat, so Dsigma over-counts there); texel coordinates move at most R / 2 x 1.618 per radian of
// direction (the octahedral map's largest stretch, (1 + sqrt 5) / 2, the largest singular
// value of its Jacobian, reached on the equator at the x and y axes; the wrapped seams are
// continuous), and the direction from the probe at most |dp| / r radians (r: distance to the
// probe). With G = sqrt(2) x 1.618 x R / (2 r) = 1.145 R / r:
//   |d ln c_k| <= 3 [(1 / D + G Dmu) / s + 2 G Dsigma / s] |dp|   (0 for d <= mu).
// Reach: flat at both clamps, and on the ramp between them |da_k| <= (|dd| + |dfar|) / w <=
// (1 + D G Dfar) |dp| / minSigma. That ramp is steep, and the bound carries its slope 1 / w in
// full: 1 / minSigma is 50 per metre from the distance alone, and where far jumps between
// neighbouring texels (a silhouette: a doorway's edge with the room behind it, metres deeper)
// D G Dfar multiplies it by tens to hundreds, so a point crossing the edge of what a probe
// sees goes from seen to hidden within millimetres; that is the cut-off doing its job. The
// term is written (b_k c_k / U) |da_k|, which is w_k |d ln a_k| without the division by a_k:
// d ln a_k is unbounded as a_k falls to 1e-12, but probe k's share of U falls with a_k as
// fast, so the term is large only where a probe that the Chebyshev test lets through (c_k
// near 1) carries weight at the edge of its reach. (In a cell whose probes are all hidden, U
// itself is tiny and so the bound is huge: the blend there is continuous but can swing between
// probes within far less than a millimetre. The lines below stay where some probe of every
// cell sees the point.)
// The sum of all terms is the slope bound L(p) (per metre). For a maximum over the six axis
// normals, |d max_a E_a| <= max_a |dE_a|, so the range is the largest over the axes. Each
// step's jump must stay below 2 x step x L x range, with L and the range the larger of the
// step's two ends (x 2: the first-order bound varies within the step; cells change at shared
// faces, where the blend is continuous). And a jump that is no artefact of the step shrinks
// with it: the largest jump at 0.25 mm steps is about 1/4 of that at 1 mm (a discontinuity of
// size J would give J at every step size).

struct SlopeBound {
  float slope = 0.0f;       // L, per metre
  float range = 0.0f;       // lux
  float visibility = 0.0f;  // largest |v_k (recomputed here) - probeVisibility| (a self-check)
  float ramp = 0.0f;        // the reach ramps' part of L
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
  constexpr float kUnorm = 1.0f / 65535.0f;
  constexpr size_t kValues = kVisibilityValuesPerTexel;
  // The factors of v_k, from the map as probeVisibility reads it.
  struct Factors {
    float c = 1.0f, reach = 1.0f, v = 1.0f;
    bool onRamp = false, floored = false;
    float lnC = 0.0f, reachSlope = 0.0f;  // |d ln c| and |d reach| per metre
  } f[4];
  float sum = 0.0f;
  for (int k = 0; k < 4; ++k) {
    const size_t i = size_t(loc.probes[k]);
    const float dMax = vis.maxDistance[i];
    const vec3 offset = p - set.positions[i];
    const float r = glm::length(offset);
    const float d = std::clamp((r - blend.distanceBias) / dMax, 0.0f, 1.0f);
    const OctahedralFootprint fp =
        octahedralFootprint(octahedralEncode(offset / r), vis.resolution);
    const std::span<const uint16_t> m = vis.probe(int32_t(i));
    float mu = 0.0f, sigma = 0.0f, far = 0.0f;
    float muLo = 1.0f, muHi = 0.0f, sLo = 1.0f, sHi = 0.0f, farLo = 1.0f, farHi = 0.0f;
    for (int t = 0; t < 4; ++t) {
      const uint16_t* texel = &m[kValues * size_t(fp.texel[t])];
      const float a = float(texel[0]) * kUnorm, b = float(texel[1]) * kUnorm;
      const float z = float(texel[2]) * kUnorm;
      mu += fp.weight[t] * a, sigma += fp.weight[t] * b, far += fp.weight[t] * z;
      muLo = std::min(muLo, a), muHi = std::max(muHi, a);
      sLo = std::min(sLo, b), sHi = std::max(sHi, b);
      farLo = std::min(farLo, z), farHi = std::max(farHi, z);
    }
    const float w = blend.minSigma / dMax;
    const float g = 1.145f * float(vis.resolution) / r;
    const float sd = std::max(sigma, w);
    const float s2 = sd * sd;
    const float ramp = 1.0f - (d - far) / w;
    f[k].reach = std::clamp(ramp, 1e-12f, 1.0f);
    f[k].onRamp = ramp > 1e-12f && ramp < 1.0f;
    f[k].reachSlope = (1.0f + dMax * g * (farHi - farLo)) / blend.minSigma;
    if (d > mu) {
      const float e = d - mu;
      const float chebyshev = s2 / (s2 + e * e);
      f[k].c = chebyshev * chebyshev * chebyshev;
      f[k].lnC =
          3.0f * ((1.0f / dMax + g * (muHi - muLo)) / sd + 2.0f * g * (sHi - sLo) / sd);
    }
    f[k].v = std::max(f[k].c * f[k].reach, kVisibilityFloor);
    f[k].floored = f[k].c * f[k].reach <= kVisibilityFloor;
    const float runtime = probeVisibility(m, vis.resolution, dMax, offset, blend);
    out.visibility = std::max(out.visibility, std::fabs(f[k].v - runtime));
    sum += loc.barycentric[k] * f[k].v;
  }
  for (int k = 0; k < 4; ++k) {
    const size_t i = size_t(loc.probes[k]);
    for (int c = 0; c < 4; ++c)
      if (size_t(cell[c]) == i) out.slope += f[k].v / sum * glm::length(gradB[c]);
    if (f[k].floored) continue;
    out.slope += loc.weights[k] * f[k].lnC;
    if (f[k].onRamp) {
      const float term = loc.barycentric[k] * f[k].c / sum * f[k].reachSlope;
      out.slope += term;
      out.ramp += term;
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
  float ramp = 0.0f;        // largest part of L from reach ramps
  float visibility = 0.0f;  // largest SlopeBound::visibility
  size_t outer = 0;         // samples outside the hull (the bound assumes inner cells)
  size_t overBound = 0;     // steps whose jump exceeds the bound
  size_t samples = 0;       // samples inside the hull
  size_t blanket = 0;       // of those, where 2 step L >= 1 (the bound allows any jump)
};

LineSweep sweepLine(const ProbeSet& set, vec3 a, vec3 b, float step) {
  LineSweep s;
  const float length = glm::length(b - a);
  const int n = int(length / step);
  float previous = 0.0f;
  SlopeBound previousBound;
  bool havePrevious = false;
  int32_t hint = -1;
  for (int i = 0; i <= n; ++i) {
    const vec3 p = a + (b - a) * (float(i) * step / length);
    const ProbeLocation loc = locateProbe(set, p, hint);
    hint = loc.cell;
    const float e = maxAxisIrradiance(interpolateProbes(set, loc));
    if (loc.cell >= set.innerCellCount) {
      ++s.outer;
      havePrevious = false;
      continue;
    }
    const SlopeBound bound = blendSlopeBound(set, p);
    if (havePrevious) {
      const float jump = std::fabs(e - previous);
      const float allowed = 2.0f * step * std::max(bound.slope, previousBound.slope) *
                            std::max(bound.range, previousBound.range);
      s.maxJump = std::max(s.maxJump, jump);
      if (allowed > 0.0f) s.worstShare = std::max(s.worstShare, jump / allowed);
      // Float rounding of the blend: a few ulps of the largest probe value.
      s.overBound += jump > allowed + 1e-6f * (1.0f + bound.range) ? 1 : 0;
    }
    ++s.samples;
    s.blanket += 2.0f * step * bound.slope >= 1.0f ? 1 : 0;
    s.maxSlope = std::max(s.maxSlope, bound.slope);
    s.ramp = std::max(s.ramp, bound.ramp);
    s.visibility = std::max(s.visibility, bound.visibility);
    previous = e;
    previousBound = bound;
    havePrevious = true;
  }
  return s;
}

// Lines through cells with probes on both sides of the wall, all in valid space and inside
// the grid's hull: two parallel to the wall 0.2 m into room B (at the sun patch's height
// behind it, and 1.5 m up), where room A's probes are hidden; one from room B through the
// doorway into room A, where they come into view; and two in room B near the doorway's
// edges as room A's probes see them (0.3 m from the wall 0.2 m above the doorway's top, along
// z past its side; and up its middle past the lintel). On those, points pass out of room-A
// probes' reach (with TetGen's cells on the first, with CGAL's on the second: which probes
// the line's cells hold depends on how the backend splits the grid's cospherical cubes, both
// valid Delaunay tetrahedralizations). Each backend's set is swept: the continuity bound holds
// for any valid Delaunay, not one backend's tie-breaking.
// Measured over six bakes: every jump within 0.23 of its bound; the 0.25 mm / 1 mm ratio of the
// largest jumps 0.250-0.281 (above 1/4 where L varies within a millimetre, on the ramps).
TEST(ProbeScenesWall, BlendIsContinuousWithABoundedSlopeAcrossTheWallsCells) {
  for (const DelaunayBackend backend : {DelaunayBackend::TetGen, DelaunayBackend::Cgal})
  for (const WallScene& w : {kThickWall, kThinWall}) {
    const char* backendName = backend == DelaunayBackend::TetGen ? "tetgen" : "cgal";
    const ProbeSet& set = bakedLayout(w, Layout::Grid, 1024, backend);
    ASSERT_FALSE(set.visibility.empty()) << w.file;
    struct Line {
      vec3 a, b;
      const char* name;
    };
    const Line lines[] = {
        {vec3(w.faceB + 0.2f, 0.6f, 0.6f), vec3(w.faceB + 0.2f, 0.6f, 2.4f), "behind the patch"},
        {vec3(w.faceB + 0.2f, 1.5f, 0.6f), vec3(w.faceB + 0.2f, 1.5f, 2.4f), "1.5 m up"},
        {vec3(w.faceB + 0.6f, 1.0f, 3.3f), vec3(w.faceA - 0.6f, 1.0f, 3.3f), "doorway"},
        {vec3(w.faceB + 0.3f, 2.3f, 2.0f), vec3(w.faceB + 0.3f, 2.3f, 3.45f), "over the doorway"},
        {vec3(w.faceB + 0.2f, 0.55f, 3.3f), vec3(w.faceB + 0.2f, 2.45f, 3.3f),
         "up past the lintel"}};
    float rampOnAnyLine = 0.0f;
    for (const Line& line : lines) {
      for (float t = 0.0f; t <= 1.0f; t += 0.05f)
        ASSERT_TRUE(isValidProbePoint(loaded(w).scene, *loaded(w).tracer,
                                      line.a + t * (line.b - line.a), {}))
            << w.file << ", " << line.name << " at " << t;
      const LineSweep mm = sweepLine(set, line.a, line.b, 1e-3f);
      const LineSweep quarter = sweepLine(set, line.a, line.b, 0.25e-3f);
      const double blanketShare = double(mm.blanket) / double(std::max<size_t>(mm.samples, 1));
      std::printf(
          "%s, %s, %s: largest jump %.3g lux per 1 mm, %.3g per 0.25 mm (ratio %.3f); jump / "
          "bound at most %.3f (0.25 mm: %.3f); L up to %.1f per m, reach ramps' part up to "
          "%.1f; 2 x 1 mm x L >= 1 on %.4f of the line\n",
          backendName, w.file, line.name, mm.maxJump, quarter.maxJump,
          quarter.maxJump / mm.maxJump, mm.worstShare, quarter.worstShare, mm.maxSlope, mm.ramp,
          blanketShare);
      const std::string what = std::string(backendName) + ", " + w.file + ", " + line.name;
      EXPECT_EQ(mm.outer + quarter.outer, 0u) << what;
      // The bound's own v is the runtime's (up to float rounding through the ramp's 1 / w).
      EXPECT_LE(std::max(mm.visibility, quarter.visibility), 1e-3f) << what;
      EXPECT_EQ(mm.overBound, 0u) << what;
      EXPECT_EQ(quarter.overBound, 0u) << what;
      EXPECT_GT(mm.maxJump, 0.0f) << what;
      EXPECT_LT(quarter.maxJump, 0.35f * mm.maxJump) << what;
      // The bound is no blanket: a jump of the probes' whole range would break it on all but
      // a sliver of the line. Not "anywhere": L peaks where a cell's probe sees a depth edge
      // (the lintel) with a small spread, and whether the line's cells hold such a probe
      // depends on how the backend splits the grid's cospherical cubes (TetGen: L <= 390 per
      // m, 2 x 1 mm x L < 1 everywhere; CGAL: L up to 1460 per m, 2 x 1 mm x L >= 1 on 0.0026 of
      // one line, the thin wall's lintel).
      EXPECT_LT(blanketShare, 0.01) << what;
      rampOnAnyLine = std::max(rampOnAnyLine, mm.ramp);
    }
    // Near the doorway's edges points pass out of room-A probes' reach: some line crosses a
    // reach ramp (which line depends on the split of the grid's cubes as well).
    EXPECT_GT(rampOnAnyLine, 0.0f) << backendName << ", " << w.file << ": no reach ramp";
  }
}

}  // namespace
}  // namespace kiln
