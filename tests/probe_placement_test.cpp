// probe_placement_test.cpp: automatic probe placement (probes/probe_placement.h): validity
// and relocation checked with independent rays, refinement monotonicity, the budget, the
// uniform-grid baseline's exact count, determinism across thread counts, and the CLI.
#include "probes/probe_placement.h"

#include <gtest/gtest.h>

#include <cmath>
#include <iostream>
#include <nlohmann/json.hpp>
#include <numeric>
#include <sstream>

#include "probes/object_space.h"
#include "probes/placement_evaluation.h"
#include "src/gltf_loader.h"
#include "src/sampling.h"
#include "tests/test_util.h"

namespace kiln {
namespace {

struct Traced {
  Scene scene;
  std::unique_ptr<Tracer> tracer;
};

Traced traced(Scene s) {
  Traced t;
  t.scene = std::move(s);
  Result<std::unique_ptr<Tracer>> tr = Tracer::create(t.scene);
  EXPECT_TRUE(bool(tr));
  t.tracer = std::move(tr).value();
  return t;
}

// The generated atrium (tools/make_scenes.py, docs/scenes.md) and the sealed cavities inside
// its outer walls (AT_CAVITIES there).
Traced atrium() {
  Result<Scene> s = loadScene(test::scenesDir() + "/atrium.gltf");
  EXPECT_TRUE(bool(s)) << s.error();
  return traced(std::move(s).value());
}
const std::array<Bounds3, 4> kAtriumCavities = {
    Bounds3{vec3(-4.5f, 0.5f, 5.3f), vec3(4.5f, 7.5f, 5.9f)},
    Bounds3{vec3(-4.5f, 0.5f, -5.9f), vec3(4.5f, 7.5f, -5.3f)},
    Bounds3{vec3(5.3f, 0.5f, -4.5f), vec3(5.9f, 9.0f, 4.5f)},
    Bounds3{vec3(-5.9f, 0.5f, -4.5f), vec3(-5.3f, 9.0f, 4.5f)}};
[[maybe_unused]] bool inAtriumCavity(vec3 p) {
  for (const Bounds3& b : kAtriumCavities)
    if (b.contains(p)) return true;
  return false;
}

#ifndef KILN_PLACEMENT_SLOW
using test::addBox;
using test::addMaterial;
using test::lambert;

// Two rooms (x in [0, 2] and [2.2, 4.2]) separated by a 0.2 m solid wall, in a closed box; a
// point light in the left room only, so the wall separates light from dark. A solid block
// stands on the floor of the left room.
Scene twoCells() {
  Scene scene;
  const uint32_t white = addMaterial(scene, lambert(vec3(0.7f)));
  addBox(scene, "shell", vec3(0.0f), vec3(4.2f, 2.0f, 2.0f), white, /*inward=*/true);
  addBox(scene, "wall", vec3(2.0f, -0.1f, -0.1f), vec3(2.2f, 2.1f, 2.1f), white, false);
  addBox(scene, "block", vec3(0.6f, -0.05f, 0.6f), vec3(1.2f, 0.6f, 1.4f), white, false);
  scene.lights.push_back(test::pointLight(vec3(1.0f, 1.6f, 1.0f), 5.0f));
  scene.updateBounds();
  return scene;
}

// Nearest hit distance and back-face share from p with many rays (independent of the
// placement's own 96-ray estimate: different count and key).
std::pair<float, float> denseProbe(const Traced& t, vec3 p) {
  float nearest = kInfinity;
  int back = 0;
  const uint32_t n = 2048;
  for (uint32_t s = 0; s < n; ++s) {
    const vec3 d = squareToUniformSphere(sobol2D(s, 12345));
    if (std::optional<Hit> h = t.tracer->intersect(Ray{p, d, 0.0f, kInfinity})) {
      nearest = std::min(nearest, h->t);
      back += h->backFace ? 1 : 0;
    }
  }
  return {nearest, float(back) / float(n)};
}

ProbePlacementSettings smallSettings() {
  ProbePlacementSettings s;
  s.budget = 40;
  s.candidateRays = 128;
  s.checkPoints = 96;
  s.maxDepth = 1;
  s.bake.bounces = 1;
  s.bake.lightSamples = 1;
  return s;
}

TEST(ProbePlacement, CandidateInsideSolidBlockIsMovedOutOrDropped) {
  const Traced t = traced(twoCells());
  ProbeValiditySettings v;
  // The block's centre and a point 3 cm inside its top face.
  for (vec3 p : {vec3(0.9f, 0.3f, 1.0f), vec3(0.9f, 0.57f, 1.0f)}) {
    EXPECT_FALSE(isValidProbePoint(t.scene, *t.tracer, p, v));
    const RelocatedPoint r = relocateProbePoint(t.scene, *t.tracer, p, v);
    if (!r.valid) continue;  // dropped is allowed
    EXPECT_TRUE(r.moved);
    EXPECT_FALSE(r.why.empty());
    const auto [nearest, back] = denseProbe(t, r.position);
    EXPECT_LE(back, 0.25f) << r.why;
    EXPECT_GE(nearest, 0.95f * v.minSurfaceDistance) << r.why;
  }
  // Inside the wall between the rooms: out on one side.
  const RelocatedPoint w = relocateProbePoint(t.scene, *t.tracer, vec3(2.05f, 1.0f, 1.0f), v);
  ASSERT_TRUE(w.valid);
  EXPECT_TRUE(w.position.x < 2.0f - 0.09f || w.position.x > 2.2f + 0.09f);
}

TEST(ProbePlacement, DistanceToACornerIsExact) {
  // 5 cm off the block's top corner (1.2, 0.6, 1.4) along each axis: 8.66 cm from it, under
  // the 10 cm minimum. Few rays come that close (the corner is a point; rays towards the top
  // and side faces meet them farther out), so a ray estimate passes the point; the exact
  // nearest-surface distance does not, and relocation moves it to 1.1 x the minimum.
  const Traced t = traced(twoCells());
  ProbeValiditySettings v;
  const vec3 p(1.25f, 0.65f, 1.45f);
  const PointProbe pp = probePoint(t.scene, *t.tracer, p, v.rays);
  EXPECT_NEAR(pp.nearestDistance, std::sqrt(3.0f) * 0.05f, 1e-5f);
  EXPECT_NEAR(glm::length(pp.nearestNormal - glm::normalize(vec3(1.0f))), 0.0f, 1e-5f);
  EXPECT_FALSE(isValidProbePoint(t.scene, *t.tracer, p, v));
  const RelocatedPoint r = relocateProbePoint(t.scene, *t.tracer, p, v);
  ASSERT_TRUE(r.valid) << r.why;
  EXPECT_TRUE(r.moved);
  EXPECT_NEAR(glm::length(r.position - vec3(1.2f, 0.6f, 1.4f)), 1.1f * v.minSurfaceDistance, 1e-5f)
      << r.why;
}

TEST(ProbePlacement, NoFinalProbeInsideGeometryOrNearASurface) {
  const Traced t = traced(twoCells());
  const ProbePlacementSettings s = smallSettings();
  Result<ProbePlacement> placed = placeProbes(t.scene, *t.tracer, s);
  ASSERT_TRUE(bool(placed)) << placed.error();
  ASSERT_GE(placed->probes.size(), 4u);
  EXPECT_LE(placed->probes.size(), s.budget);
  EXPECT_GT(placed->candidatesMoved, 0u);  // the wall and the block hold lattice corners
  int left = 0, right = 0;
  for (const PlacedProbe& p : placed->probes) {
    const auto [nearest, back] = denseProbe(t, p.position);
    EXPECT_LE(back, 0.25f);
    EXPECT_GE(nearest, 0.95f * s.validity.minSurfaceDistance);
    EXPECT_TRUE(t.scene.bounds.contains(p.position));
    left += p.position.x < 2.0f;
    right += p.position.x > 2.2f;
    if (p.moved) {
      EXPECT_FALSE(p.why.empty());
    }
  }
  // Probes on both sides of the wall.
  EXPECT_GT(left, 0);
  EXPECT_GT(right, 0);
}

// With either pick ranking (symmetricPicks: two batches per round, the lower score kept).
TEST(ProbePlacement, RefinementNeverRaisesItsCheckError) {
  const Traced t = traced(twoCells());
  for (bool symmetric : {false, true}) {
    ProbePlacementSettings s = smallSettings();
    s.symmetricPicks = symmetric;
    Result<ProbePlacement> placed = placeProbes(t.scene, *t.tracer, s);
    ASSERT_TRUE(bool(placed)) << placed.error();
    ASSERT_FALSE(placed->errorHistory.empty());
    for (size_t i = 1; i < placed->errorHistory.size(); ++i)
      EXPECT_LE(placed->errorHistory[i], placed->errorHistory[i - 1]) << symmetric;
    EXPECT_LE(placed->estimatedError, placed->initialError) << symmetric;
    EXPECT_FLOAT_EQ(placed->estimatedError, placed->errorHistory.back()) << symmetric;
  }
}

TEST(ProbePlacement, BudgetAndTargetAreRespected) {
  const Traced t = traced(twoCells());
  for (uint32_t budget : {6u, 17u}) {
    ProbePlacementSettings s = smallSettings();
    s.budget = budget;
    Result<ProbePlacement> placed = placeProbes(t.scene, *t.tracer, s);
    ASSERT_TRUE(bool(placed)) << placed.error();
    EXPECT_LE(placed->probes.size(), budget);
  }
  ProbePlacementSettings s = smallSettings();
  s.targetError = 1e9f;  // met by the start set: no growth
  Result<ProbePlacement> placed = placeProbes(t.scene, *t.tracer, s);
  ASSERT_TRUE(bool(placed));
  EXPECT_EQ(placed->rounds, 0u);
  ProbePlacementSettings bad = smallSettings();
  bad.budget = 3;
  EXPECT_FALSE(bool(placeProbes(t.scene, *t.tracer, bad)));
}

TEST(ProbePlacement, UniformGridHasExactlyTheRequestedCount) {
  const Traced t = traced(twoCells());
  const std::vector<Bounds3> volumes = placementVolumes(t.scene, {});
  ProbeValiditySettings v;
  for (uint32_t count : {4u, 27u, 50u, 101u}) {
    Result<std::vector<vec3>> grid = uniformGridPositions(t.scene, *t.tracer, volumes, count, v);
    ASSERT_TRUE(bool(grid)) << grid.error();
    EXPECT_EQ(grid->size(), count);
    for (const vec3& p : *grid) EXPECT_TRUE(isValidProbePoint(t.scene, *t.tracer, p, v));
  }
  EXPECT_FALSE(bool(uniformGridPositions(t.scene, *t.tracer, volumes, 3, v)));
}

TEST(ProbePlacement, DeterministicAcrossThreadCounts) {
  const Traced t = traced(twoCells());
  for (bool symmetric : {false, true}) {
    ProbePlacementSettings a = smallSettings();
    a.threads = 1;
    a.bake.threads = 1;
    a.symmetricPicks = symmetric;
    ProbePlacementSettings b = a;
    b.threads = 2;
    b.bake.threads = 2;
    Result<ProbePlacement> pa = placeProbes(t.scene, *t.tracer, a);
    Result<ProbePlacement> pb = placeProbes(t.scene, *t.tracer, b);
    ASSERT_TRUE(bool(pa) && bool(pb));
    ASSERT_EQ(pa->probes.size(), pb->probes.size());
    for (size_t i = 0; i < pa->probes.size(); ++i)
      EXPECT_EQ(pa->probes[i].position, pb->probes[i].position) << symmetric;
    EXPECT_EQ(pa->estimatedError, pb->estimatedError) << symmetric;
  }
  const std::vector<Bounds3> volumes = placementVolumes(t.scene, {});
  EXPECT_EQ(randomValidPoints(t.scene, *t.tracer, volumes, 50, 7, {}, 1),
            randomValidPoints(t.scene, *t.tracer, volumes, 50, 7, {}, 3));
}

TEST(ProbePlacement, RandomValidPointsAreValid) {
  const Traced t = traced(twoCells());
  const std::vector<Bounds3> volumes = placementVolumes(t.scene, {});
  ProbeValiditySettings v;
  const std::vector<vec3> pts = randomValidPoints(t.scene, *t.tracer, volumes, 100, 1, v);
  EXPECT_EQ(pts.size(), 100u);
  for (const vec3& p : pts) {
    const auto [nearest, back] = denseProbe(t, p);
    EXPECT_LE(back, 0.25f);
    EXPECT_GE(nearest, 0.95f * v.minSurfaceDistance);
  }
}

// The error measures' test light: grey, L00 of 1 and an L1 term of 0.5 along z (c[2]).
ShL2Rgb greyWithLightAlongZ() {
  ShL2Rgb a;
  a.c[0] = vec3(1.0f);
  a.c[2] = vec3(0.5f);
  return a;
}

TEST(ProbePlacement, ErrorMeasureIsZeroForItselfAndScaleInvariant) {
  const ShL2Rgb a = greyWithLightAlongZ();
  EXPECT_EQ(relativeIrradianceError(a, a, 0.0f), 0.0f);
  EXPECT_NEAR(relativeIrradianceError(a, a * 1.1f, 0.0f), 0.1f, 1e-5f);
  EXPECT_NEAR(relativeIrradianceError(a * 3.0f, a * 3.3f, 0.0f), 0.1f, 1e-5f);
}

// Growth's pick measure: relative to the brighter of truth and estimate, so a shaded point
// lit 3x too bright and a sunlit point lit 3x too dark rank alike (the relative error gives 2
// and 2/3: greedy picks went to the first kind, and sunlit open air stayed lit by shaded
// probes, docs/probe_placement.md "Symmetric picks").
TEST(ProbePlacement, PickErrorIsSymmetricInTruthAndEstimate) {
  const ShL2Rgb a = greyWithLightAlongZ();
  EXPECT_EQ(symmetricIrradianceError(a, a, 0.0f), 0.0f);
  EXPECT_NEAR(symmetricIrradianceError(a, a * 3.0f, 0.0f), 2.0f / 3.0f, 1e-5f);
  EXPECT_NEAR(symmetricIrradianceError(a * 3.0f, a, 0.0f), 2.0f / 3.0f, 1e-5f);
  EXPECT_NEAR(relativeIrradianceError(a, a * 3.0f, 0.0f), 2.0f, 1e-5f);
  EXPECT_NEAR(relativeIrradianceError(a * 3.0f, a, 0.0f), 2.0f / 3.0f, 1e-5f);
  // Below the floor both measures divide by it.
  const float floor = 100.0f * irradianceRms(a);
  EXPECT_NEAR(symmetricIrradianceError(a, a * 3.0f, floor),
              relativeIrradianceError(a, a * 3.0f, floor), 1e-6f);
}

// Growth's ranking of the check points where objects stand (objectRatioPicks): the ratio of
// the mean irradiance (L00) either way up, as the sphere measure's worst ratio counts it, so
// a sunlit point lit 3x too dark ranks with a shaded one lit 3x too bright (2 both), where
// the relative error gives 2/3 and 2; the floor keeps near-black points from ranking first.
TEST(ProbePlacement, MeanIrradianceRatioErrorCountsBothWaysAlike) {
  const ShL2Rgb a = greyWithLightAlongZ();
  EXPECT_EQ(meanIrradianceRatioError(a, a, 0.0f), 0.0f);
  EXPECT_NEAR(meanIrradianceRatioError(a, a * 3.0f, 0.0f), 2.0f, 1e-5f);
  EXPECT_NEAR(meanIrradianceRatioError(a * 3.0f, a, 0.0f), 2.0f, 1e-5f);
  // Only L00 counts: the directional terms do not move it.
  ShL2Rgb b = a;
  b.c[2] = vec3(-0.5f);
  EXPECT_EQ(meanIrradianceRatioError(a, b, 0.0f), 0.0f);
  // A black truth: the floor bounds the ratio (estimate 1 over a floor of 0.25: 3).
  EXPECT_NEAR(meanIrradianceRatioError(a * 0.0f, a, 0.25f), 3.0f, 1e-5f);
  EXPECT_TRUE(std::isfinite(meanIrradianceRatioError(a * 0.0f, a, 0.0f)));
}

TEST(ProbePlacement, CellsCrossingAWallAreCounted) {
  const Traced t = traced(twoCells());
  // One tetrahedron on each side, and one spanning the wall.
  const std::vector<vec3> left = {vec3(0.3f, 1.0f, 0.3f), vec3(1.7f, 1.0f, 0.3f),
                                  vec3(1.0f, 1.0f, 1.7f), vec3(1.0f, 1.8f, 1.0f)};
  Result<ProbeSet> set = buildProbeTopology(left);
  ASSERT_TRUE(bool(set));
  EXPECT_EQ(countCellsCrossingGeometry(*t.tracer, *set).crossingCells, 0u);
  const std::vector<vec3> span = {vec3(1.5f, 1.0f, 0.3f), vec3(2.7f, 1.0f, 0.3f),
                                  vec3(1.5f, 1.0f, 1.7f), vec3(1.5f, 1.8f, 1.0f)};
  set = buildProbeTopology(span);
  ASSERT_TRUE(bool(set));
  EXPECT_EQ(countCellsCrossingGeometry(*t.tracer, *set).crossingCells, 1u);
}

TEST(ProbePlacement, LeakEstimateSeesOnlyCellsSpanningAWallWithDifferentLight) {
  const Traced t = traced(twoCells());
  ShL2Rgb bright, dark;
  bright.c[0] = vec3(2.0f);
  dark.c[0] = vec3(0.01f);
  const float floor = 0.05f;
  // All in the left room: no blocked edge, no leak whatever the light.
  const std::array<vec3, 4> left = {vec3(0.3f, 1.0f, 0.3f), vec3(1.7f, 1.0f, 0.3f),
                                    vec3(1.0f, 1.0f, 1.7f), vec3(1.0f, 1.8f, 1.0f)};
  EXPECT_EQ(cellLeakVolumeError(*t.tracer, left, {&bright, &dark, &dark, &bright}, floor), 0.0f);
  // Spanning the wall: a leak when the sides differ, none when all four probes agree.
  const std::array<vec3, 4> span = {vec3(1.5f, 1.0f, 0.3f), vec3(2.7f, 1.0f, 0.3f),
                                    vec3(1.5f, 1.0f, 1.7f), vec3(1.5f, 1.8f, 1.0f)};
  EXPECT_EQ(cellLeakVolumeError(*t.tracer, span, {&bright, &bright, &bright, &bright}, floor),
            0.0f);
  const float leak =
      cellLeakVolumeError(*t.tracer, span, {&bright, &dark, &bright, &bright}, floor);
  EXPECT_GT(leak, 0.0f);
  // At most the cell's volume x the largest relative error a point can see (all-bright blend
  // against the dark probe alone).
  const float volume = glm::length(glm::dot(span[1] - span[0],
                                            glm::cross(span[2] - span[0], span[3] - span[0]))) /
                       6.0f;
  EXPECT_LE(leak, volume * relativeIrradianceError(dark, bright, floor));
}

TEST(ProbePlacement, LeakEstimateScoresTheVisibilityWeightedBlend) {
  // The cell spanning the wall of the previous test, three probes in the bright left room and
  // one in the dark right one, with visibility maps baked at the four probes as placement
  // bakes its candidates (bakePointSh). Plain blending carries the bright probes' light past
  // the wall; the maps hide them from the points behind it, and the dark probe from the
  // points in the left room, so the runtime's blend is what each point sees and the estimate
  // all but vanishes.
  const Traced t = traced(twoCells());
  const std::array<vec3, 4> span = {vec3(1.5f, 1.0f, 0.3f), vec3(2.7f, 1.0f, 0.3f),
                                    vec3(1.5f, 1.0f, 1.7f), vec3(1.5f, 1.8f, 1.0f)};
  ProbeBakeSettings b;
  b.rays = 1024;
  b.bounces = 1;
  b.lightSamples = 1;
  b.visibilityMaxDistance = 2.0f;  // the cell's longest edge is 1.84 m
  ProbeVisibility vis;
  const std::vector<ShL2Rgb> baked = bakePointSh(t.scene, *t.tracer, span, b, nullptr, nullptr,
                                                 &vis);
  ASSERT_EQ(baked.size(), 4u);
  ASSERT_EQ(vis.resolution, kDefaultVisibilityResolution);
  ASSERT_EQ(vis.maxDistance, std::vector<float>(4, 2.0f));
  ASSERT_EQ(vis.moments.size(), 4 * vis.valuesPerProbe());
  CellProbeMaps maps;
  maps.resolution = vis.resolution;
  for (int v = 0; v < 4; ++v) {
    maps.moments[size_t(v)] = vis.probe(v);
    maps.maxDistance[size_t(v)] = vis.maxDistance[size_t(v)];
  }
  ShL2Rgb bright, dark;
  bright.c[0] = vec3(2.0f);
  dark.c[0] = vec3(0.01f);
  const std::array<const ShL2Rgb*, 4> sh = {&bright, &dark, &bright, &bright};
  const float floor = 0.05f;
  const float plain = cellLeakVolumeError(*t.tracer, span, sh, floor);
  const float weighted = cellLeakVolumeError(*t.tracer, span, sh, floor, maps);
  EXPECT_GT(plain, 0.0f);
  // Measured 0.26 plain and 0.0004-0.0007 with maps over four bake seeds (what remains is
  // the maps' blur at points next to the wall): a margin of about 4x.
  EXPECT_LT(weighted, 0.01f * plain) << "plain " << plain << ", with maps " << weighted;
  // Without visibility (resolution 0) bakePointSh leaves the maps empty.
  b.visibilityResolution = 0;
  bakePointSh(t.scene, *t.tracer, span, b, nullptr, nullptr, &vis);
  EXPECT_TRUE(vis.empty());
  EXPECT_TRUE(vis.moments.empty());
}

TEST(ProbePlacement, PlacementWithoutVisibilityStillWorks) {
  // visibilityResolution 0: candidates get no maps and sets are scored with the plain blend
  // (for probes baked without visibility); placement keeps its guarantees.
  const Traced t = traced(twoCells());
  ProbePlacementSettings s = smallSettings();
  s.bake.visibilityResolution = 0;
  Result<ProbePlacement> placed = placeProbes(t.scene, *t.tracer, s);
  ASSERT_TRUE(bool(placed)) << placed.error();
  EXPECT_GE(placed->probes.size(), 4u);
  EXPECT_LE(placed->probes.size(), s.budget);
  EXPECT_LE(placed->estimatedError, placed->initialError);
  for (size_t i = 1; i < placed->errorHistory.size(); ++i)
    EXPECT_LE(placed->errorHistory[i], placed->errorHistory[i - 1]);
  s.bake.visibilityResolution = 3;  // below kMinVisibilityResolution
  Result<ProbePlacement> bad = placeProbes(t.scene, *t.tracer, s);
  ASSERT_FALSE(bool(bad));
  EXPECT_NE(bad.error().find("visibilityResolution"), std::string::npos) << bad.error();
}

TEST(ProbePlacement, CliWritesPositionsThatBakeReads) {
  const std::string dir = test::makeTempDir("kiln_place");
  const std::string scene = test::scenesDir() + "/two_rooms.gltf";
  std::string out;
  const std::string cmd = std::string(test::kilnExe()) + " probes place " + scene +
                          " --volume 0,0,0,8.25,3,4 --budget 24 --rays 64 --check-points 64"
                          " --depth 1 --no-scene-probes -q --out " + dir + "/pos.json";
  ASSERT_EQ(test::runCommand(cmd, &out), 0) << out;
  const nlohmann::json doc = nlohmann::json::parse(test::readTextFile(dir + "/pos.json"));
  ASSERT_TRUE(doc.contains("positions"));
  EXPECT_LE(doc["positions"].size(), 24u);
  EXPECT_EQ(doc["probes"].size(), doc["positions"].size());
  EXPECT_TRUE(doc["report"].contains("estimatedError"));
  Result<std::vector<vec3>> parsed = loadProbePositions(dir + "/pos.json");
  ASSERT_TRUE(bool(parsed)) << parsed.error();
  EXPECT_EQ(parsed->size(), doc["positions"].size());
  EXPECT_EQ(test::runCommand(std::string(test::kilnExe()) + " probes bake " + scene +
                                 " --positions " + dir + "/pos.json --no-scene-probes --rays 64"
                                 " -q --out " + dir + "/p.kprobe",
                             &out),
            0)
      << out;
  // Bad usage.
  EXPECT_EQ(test::runCommand(std::string(test::kilnExe()) + " probes place " + scene +
                                 " --volume 1,2,3 --out " + dir + "/x.json",
                             &out),
            2);
}

TEST(ProbePlacement, FloodFillFindsTheAtriumsSealedCavities) {
  const Traced t = atrium();
  const std::vector<Bounds3> volumes = placementVolumes(t.scene, {});
  const ReachableSpace space = ReachableSpace::build(t.scene, *t.tracer, volumes, {});
  ASSERT_TRUE(space.enabled());
  EXPECT_GT(space.seedCells(), 0u);
  // The cavities' centres and points near their walls: sealed.
  for (const Bounds3& b : kAtriumCavities) {
    EXPECT_FALSE(space.reachable(b.center())) << b.center().x << " " << b.center().z;
    EXPECT_FALSE(space.reachable(b.min + vec3(0.12f))) << b.min.x << " " << b.min.z;
  }
  // The court, both galleries on both floors, under the roof and above it: reachable.
  for (vec3 p : {vec3(0.0f, 1.0f, 0.0f), vec3(0.0f, 1.0f, 4.0f), vec3(2.0f, 0.4f, -4.7f),
                 vec3(0.0f, 5.3f, -4.0f), vec3(-4.8f, 7.8f, 4.8f), vec3(0.0f, 9.0f, 4.0f)})
    EXPECT_TRUE(space.reachable(p)) << p.x << " " << p.y << " " << p.z;
  // Random points: valid points fall in the cavities (about 10% of the volume; a ray test
  // alone takes them for open space), reachable ones never.
  const std::vector<vec3> valid = randomPlacementPoints(t.scene, *t.tracer, volumes, 400, 3,
                                                        {}, PointSampling{});
  const size_t sealed = size_t(std::count_if(valid.begin(), valid.end(), inAtriumCavity));
  EXPECT_GT(sealed, 10u);
  PointSampling reachable;
  reachable.reachable = &space;
  const std::vector<vec3> open = randomPlacementPoints(t.scene, *t.tracer, volumes, 400, 3, {},
                                                       reachable);
  EXPECT_EQ(open.size(), 400u);
  EXPECT_EQ(std::count_if(open.begin(), open.end(), inAtriumCavity), 0);
}

TEST(ProbePlacement, NoProbeInTheAtriumsSealedCavities) {
  const Traced t = atrium();
  ProbePlacementSettings s = smallSettings();
  s.budget = 48;
  s.fixedProbes = sceneProbePositions(t.scene);  // as the CLI does
  Result<ProbePlacement> placed = placeProbes(t.scene, *t.tracer, s);
  ASSERT_TRUE(bool(placed)) << placed.error();
  // Octree corners inside the walls are relocated through the nearest back face, often into
  // a cavity: the flood fill drops them.
  EXPECT_GT(placed->candidatesUnreachable, 0u);
  EXPECT_GT(placed->candidatesAboveFloors, 0u);
  EXPECT_EQ(placed->fixedProbes, 8u);
  size_t fixed = 0;
  for (const PlacedProbe& p : placed->probes) {
    EXPECT_FALSE(inAtriumCavity(p.position)) << p.position.x << " " << p.position.y << " "
                                             << p.position.z << " " << p.why;
    fixed += p.fixed;
  }
  EXPECT_EQ(fixed, 8u);
}

TEST(ProbePlacement, FloorsAndPointsAboveThem) {
  const Traced t = traced(twoCells());
  // Open floor at (1.5, 0.3): the shell's floor (y = 0) under its ceiling (y = 2), seen from
  // above through the ceiling's back face.
  std::vector<Floor> floors = floorsBelow(t.scene, *t.tracer, 1.5f, 0.3f, 2.5f, -1.0f);
  ASSERT_EQ(floors.size(), 1u);
  EXPECT_NEAR(floors[0].point.y, 0.0f, 1e-5f);
  EXPECT_NEAR(floors[0].clearance, 2.0f, 1e-4f);
  // Over the block: its top (y = 0.6, 1.4 m under the ceiling) first.
  floors = floorsBelow(t.scene, *t.tracer, 0.9f, 1.0f, 2.5f, -1.0f);
  ASSERT_GE(floors.size(), 1u);
  EXPECT_NEAR(floors[0].point.y, 0.6f, 1e-5f);
  EXPECT_NEAR(floors[0].clearance, 1.4f, 1e-4f);
  // Layers at 0.4 and 1.2 m over the open floor (2.4 m is above the 2 m ceiling), 0.4 and
  // 1.2 m over the block's top (1.0 and 1.8; 1.8 is within 0.2 m headroom of the ceiling: no).
  const std::vector<Bounds3> volumes = placementVolumes(t.scene, {});
  const std::vector<vec3> points = pointsAboveFloors(t.scene, *t.tracer, volumes, 0.3f, 0.4f, 0.2f);
  size_t at04 = 0, at12 = 0, onBlock = 0;
  for (const vec3& p : points) {
    at04 += std::abs(p.y - 0.4f) < 1e-4f;
    at12 += std::abs(p.y - 1.2f) < 1e-4f;
    onBlock += std::abs(p.y - 1.0f) < 1e-4f;
    EXPECT_TRUE(std::abs(p.y - 0.4f) < 1e-4f || std::abs(p.y - 1.2f) < 1e-4f ||
                std::abs(p.y - 1.0f) < 1e-4f)
        << p.y;
  }
  EXPECT_GT(at04, 50u);
  EXPECT_EQ(at04, at12);  // every column over the floor gets both layers
  EXPECT_GT(onBlock, 0u);
  // Object points: 0.3-2 m above a floor (here at most 1.9: 0.1 m under the ceiling).
  for (uint32_t i = 0; i < 64; ++i) {
    SampleStream stream(99, i);
    const vec2 a = stream.get2D(), b = stream.get2D();
    const std::optional<vec3> p = objectPoint(t.scene, *t.tracer, volumes, a, b.x, b.y, 0.3f, 2.0f);
    if (!p) continue;
    const std::vector<Floor> below = floorsBelow(t.scene, *t.tracer, p->x, p->z, p->y, -1.0f);
    ASSERT_FALSE(below.empty());
    EXPECT_GE(p->y - below[0].point.y, 0.3f - 1e-4f);
    EXPECT_LE(p->y - below[0].point.y, 1.9f + 1e-4f);
  }
}

TEST(ProbePlacement, FixedProbesAreKeptAndCounted) {
  const Traced t = traced(twoCells());
  ProbePlacementSettings s = smallSettings();
  s.budget = 20;
  s.fixedProbes = {vec3(0.5f, 1.5f, 0.5f), vec3(1.5f, 1.0f, 1.7f), vec3(3.0f, 1.0f, 1.0f)};
  Result<ProbePlacement> placed = placeProbes(t.scene, *t.tracer, s);
  ASSERT_TRUE(bool(placed)) << placed.error();
  EXPECT_LE(placed->probes.size(), s.budget);
  std::vector<vec3> fixed;
  for (const PlacedProbe& p : placed->probes)
    if (p.fixed) fixed.push_back(p.position);
  ASSERT_EQ(fixed.size(), 3u);
  for (const vec3& f : s.fixedProbes)
    EXPECT_NE(std::find(fixed.begin(), fixed.end(), f), fixed.end());  // exactly where given
  s.budget = 3;
  EXPECT_FALSE(bool(placeProbes(t.scene, *t.tracer, s)));
}

TEST(ProbePlacement, BelowTheBudgetSaysWhy) {
  const Traced t = traced(twoCells());
  ProbePlacementSettings s = smallSettings();
  s.targetError = 1e9f;  // met by the start set
  Result<ProbePlacement> placed = placeProbes(t.scene, *t.tracer, s);
  ASSERT_TRUE(bool(placed));
  ASSERT_LT(placed->probes.size() * 10, size_t(s.budget) * 9);
  EXPECT_NE(placed->belowBudget.find("target error"), std::string::npos) << placed->belowBudget;
  s = smallSettings();
  placed = placeProbes(t.scene, *t.tracer, s);
  ASSERT_TRUE(bool(placed));
  // Either the budget is used or the report says why not.
  EXPECT_TRUE(placed->probes.size() * 10 >= size_t(s.budget) * 9 || !placed->belowBudget.empty());
  EXPECT_EQ(placed->belowBudget.empty(), placed->probes.size() * 10 >= size_t(s.budget) * 9);
}

// Held-out check points (ProbePlacementSettings::holdOut): growth picks only from the
// even-numbered check points, the odd-numbered ones score the sets. With candidateReach 0
// every pick spawns a probe at its own check point, so the placed probes that stand on check
// points stand on even-numbered ones only (without the hold-out: on both).
TEST(ProbePlacement, GrowthPicksOnlyFromTheCheckPointsThatDoNotScore) {
  const Traced t = traced(twoCells());
  ProbePlacementSettings s = smallSettings();
  s.reachableOnly = false;
  s.floorHeight = 0.0f;  // check points uniform over the volume: randomValidPoints
  s.candidateReach = 0.0f;
  s.prune = false;
  const std::vector<Bounds3> volumes = placementVolumes(t.scene, {});
  const std::vector<vec3> checks =
      randomPlacementPoints(t.scene, *t.tracer, volumes, s.checkPoints,
                            placementCheckPointSeed(s.seed), s.validity, PointSampling{});
  for (bool holdOut : {true, false}) {
    s.holdOut = holdOut;
    Result<ProbePlacement> placed = placeProbes(t.scene, *t.tracer, s);
    ASSERT_TRUE(bool(placed)) << placed.error();
    ASSERT_EQ(checks.size(), placed->checkPoints);
    size_t onPick = 0, onScoring = 0;
    for (const PlacedProbe& p : placed->probes)
      for (size_t i = 0; i < checks.size(); ++i)
        if (p.position == checks[i]) ++(i % 2 == 0 ? onPick : onScoring);
    EXPECT_GT(onPick, 0u) << "hold-out " << holdOut;
    if (holdOut) {
      EXPECT_EQ(onScoring, 0u);
    } else {
      EXPECT_GT(onScoring, 0u);
    }
  }
}

#else
// The comparison on the shipped scenes with their default volumes (docs/probe_placement.md):
// at equal probe counts (the automatic run's budget is the grid's count) the automatic
// placement's mean interpolated irradiance error at 1000 random valid points is lower than a
// uniform grid's, for two evaluation seeds. Minutes; labelled slow.
struct CsvRow {
  std::string method;
  size_t count = 0;
  double mean = 0.0;
};
std::vector<CsvRow> csvRows(const std::string& csv) {
  std::vector<CsvRow> rows;
  std::istringstream in(csv);
  std::string line;
  std::getline(in, line);  // header
  while (std::getline(in, line)) {
    std::vector<std::string> f;
    std::istringstream ls(line);
    std::string x;
    while (std::getline(ls, x, ',')) f.push_back(x);
    if (f.size() >= 4) rows.push_back(CsvRow{f[1], std::stoul(f[2]), std::stod(f[3])});
  }
  return rows;
}

// Spheres where objects stand (0.3-2 m above walkable surfaces), lit by the probes placement
// chose (default settings, the scene's probe groups fixed), against SH baked at the spheres'
// centres (docs/probe_placement.md, "Where objects go"). Returns the measure; checks the
// placement's own guarantees.
SphereError spheresWhereObjectsStand(const Traced& t, uint32_t budget, uint64_t seed = 0,
                                     float footprint = ProbeBakeSettings{}.footprint) {
  ProbePlacementSettings s;
  s.budget = budget;
  s.seed = seed;
  s.fixedProbes = sceneProbePositions(t.scene);
  Result<ProbePlacement> placed = placeProbes(t.scene, *t.tracer, s);
  EXPECT_TRUE(bool(placed)) << placed.error();
  if (!placed) return {};
  // The budget is used, or the report says why not.
  EXPECT_TRUE(placed->probes.size() * 10 >= size_t(budget) * 9 || !placed->belowBudget.empty());
  ProbeBakeSettings bake;  // the probe bake's defaults (deringing, visibility maps), fewer rays
  bake.rays = 2048;
  // (footprint, everywhere) pairs: the default's first.
  std::vector<std::pair<float, bool>> footprints = {{footprint, bake.footprintEverywhere}};
  // For measuring (docs/probe_placement.md, round 8): KILN_SPHERE_FOOTPRINTS="0 0.25 0.5*"
  // also bakes the placed set with those footprints (a trailing * : at every probe, not only
  // in thin light sheets) and prints their spheres; the bounds apply to `footprint`'s.
  if (const char* env = std::getenv("KILN_SPHERE_FOOTPRINTS")) {
    std::istringstream in(env);
    for (std::string f; in >> f;)
      footprints.emplace_back(std::stof(f), !f.empty() && f.back() == '*');
  }
  std::vector<ProbeSet> sets;
  for (const auto& [f, everywhere] : footprints) {
    bake.footprint = f;
    bake.footprintEverywhere = everywhere;
    Result<ProbeSet> set = bakeProbes(t.scene, *t.tracer, placed->positions(), bake);
    EXPECT_TRUE(bool(set)) << set.error();
    if (!set) return {};
    sets.push_back(std::move(set).value());
  }
  const std::vector<Bounds3> volumes = placementVolumes(t.scene, {});
  ReachableSpaceSettings rs;
  rs.seeds = s.fixedProbes;
  const ReachableSpace space = ReachableSpace::build(t.scene, *t.tracer, volumes, rs);
  PointSampling objects;
  objects.reachable = &space;
  objects.objectShare = 1.0f;
  ProbeBakeSettings truthBake = bake;
  truthBake.footprint = 0.0f;  // the reference: SH baked at the spheres' centres
  truthBake.rays = 4096;
  truthBake.seed = 77;  // apart from the probes' and placement's seeds
  Result<TruthPoints> truth = bakeTruthPoints(t.scene, *t.tracer, volumes, 60, 77, s.validity,
                                              truthBake, nullptr, nullptr, objects);
  EXPECT_TRUE(bool(truth)) << truth.error();
  if (!truth) return {};
  SphereError first;
  for (size_t fi = 0; fi < sets.size(); ++fi) {
    const SphereError e = sphereError(sets[fi], *truth);
    if (fi == 0) first = e;
    std::cout << "footprint " << footprints[fi].first
              << (footprints[fi].second ? " everywhere" : " in thin light sheets")
              << " (radius at most "
              << bake.footprintMaxRadius << " m): ";
    size_t beyond = 0;
    for (float r : e.ratio) beyond += (r > 0.0f ? std::max(r, 1.0f / r) : kInfinity) > 2.0f;
    std::cout << "beyond 2x " << beyond << "; ";
    std::vector<size_t> order(e.points);
    std::iota(order.begin(), order.end(), size_t(0));
    std::sort(order.begin(), order.end(), [&](size_t a, size_t b) {
      return std::max(e.ratio[a], 1.0f / e.ratio[a]) > std::max(e.ratio[b], 1.0f / e.ratio[b]);
    });
    std::ostringstream worst;
    for (size_t k = 0; k < std::min<size_t>(5, order.size()); ++k) {
      const size_t i = order[k];
      worst << "(" << truth->points[i].x << ", " << truth->points[i].y << ", "
            << truth->points[i].z << "): ratio " << e.ratio[i] << ", error " << e.perPoint[i]
            << "; ";
    }
    std::cout << t.scene.path << ", placement seed " << seed << ": " << placed->probes.size()
              << " probes, " << e.points
              << " spheres: median " << e.median << ", mean " << e.mean << ", worst ratio "
              << e.worstRatio << "; worst: " << worst.str() << "\n";
  }
  return first;
}

// Issue 13's bounds (median within 15%, worst within 2x) at placement seeds 0-4, each a
// different draw of check points and cheap bakes: a user's result should not depend on the
// seed. Spheres beside the sun's shadow edges (the south roof's across the court, the north
// gallery floor's and the piers' under the arcades) lie in bands where the four probes on
// both sides of the edge blend lit (L00 about 3) and shaded (about 0.9) light; 256 probes
// cannot hug every edge, and 1024 did not help either (docs/probe_placement.md, rounds 7 and
// 9). The sun layer (docs/probes.md, "Sun shadows"; the default since round 9) replaces the
// blend's share of the sun by a ramp across the shadow's plane in the cells it fits.
// Measured with it (CGAL's cells, footprint in thin sheets, least-squares ramps where no plane
// passes): medians 0.071, 0.076, 0.089, 0.100, 0.105 (mean 0.088), worst ratios 1.87, 1.44,
// 1.55, 1.76, 1.87, none of the 300 spheres beyond 2x (plane ramps alone: seed 0 2.14, 1
// beyond); without the layer: medians 0.091, 0.124, 0.135, 0.111, 0.123 (mean 0.117), worst
// 2.14, 1.87, 2.63, 2.62, 2.13, 5 beyond 2x. Over 600 object points per seed (seeds 0-2)
// 1.8% of the bright ones are still beyond 2x (3.1% without), so the bounds leave room for
// another draw (another machine's Embree bits move placement as a seed does): every seed's
// median within the 0.15 (the seeds' spread is about 0.015) and worst within 3x, the
// five medians' mean within 0.12 (its spread is about 0.007), at most 10 of the 300 spheres
// beyond 2x (1.8% of 300 is 5.4; a count's spread is about its square root).
TEST(ProbePlacementSlow, SpheresWhereObjectsStandInTheAtriumAtFivePlacementSeeds) {
  const Traced t = atrium();
  double medianSum = 0.0;
  size_t beyond2x = 0, spheres = 0;
  for (uint64_t seed = 0; seed < 5; ++seed) {
    const SphereError e = spheresWhereObjectsStand(t, 256, seed);
    EXPECT_GE(e.points, 30u) << "seed " << seed;
    EXPECT_LE(e.median, 0.15f) << "seed " << seed;
    EXPECT_LE(e.worstRatio, 3.0f) << "seed " << seed;
    medianSum += e.median;
    spheres += e.points;
    for (float r : e.ratio) beyond2x += (r > 0.0f ? std::max(r, 1.0f / r) : kInfinity) > 2.0f;
  }
  std::cout << "atrium, seeds 0-4: mean median " << medianSum / 5.0 << ", " << beyond2x << " of "
            << spheres << " spheres beyond 2x\n";
  EXPECT_LE(medianSum / 5.0, 0.12);
  EXPECT_LE(beyond2x, 10u);
}

// At placement seeds 0 and 1. Measured with the default bake (probes in thin sheets of light
// baked over a footprint, round 8; docs/probe_placement.md, "Probes baked over a footprint"):
// 256 and 232 probes, medians 0.094 and 0.086, worst ratios 1.93 and 1.74 (seeds 2 and 3, not
// run here: 0.095 / 2.43 and 0.102 / 1.87); the same sets point-baked (footprint 0, as before
// round 8): medians 0.086 and 0.084, worst 2.94 and 3.41 (seeds 2, 3: 2.88, 3.08).
TEST(ProbePlacementSlow, SpheresWhereObjectsStandInTheBreakfastRoom) {
  if (!test::sharedAvailable()) GTEST_SKIP() << "../shared absent: no breakfast room";
  Result<Scene> s = loadScene(test::sharedDir() + "/scenes/breakfast_room/BreakfastRoom.gltf");
  ASSERT_TRUE(bool(s)) << s.error();
  const Traced t = traced(std::move(s).value());
  for (uint64_t seed : {0u, 1u}) {
    const SphereError e = spheresWhereObjectsStand(t, 256, seed);
    EXPECT_GE(e.points, 30u) << "seed " << seed;
    EXPECT_LE(e.median, 0.15f) << "seed " << seed;
    // The 2x at three placement seeds of four (1.74-1.93; 2.43 at seed 2). The
    // window's blind stripes the sunbeam into lit sheets about 3 cm thick between shaded ones
    // 4.7 cm thick (L00 3.0 against 0.9), which probes 0.587 m apart cannot resolve:
    // point-baked, a probe there is lit or shaded at random and the sphere at (1.56, 1.08,
    // -0.58), on a lit sheet, was 3.4x too dark between four shaded probes. Baked over a
    // footprint the beam's probes carry its mean, and the best a smooth field can do is
    // 1.7-1.9x off at points on and beside the sheets; where the sphere's tetrahedron reaches
    // probes outside the beam (seed 2) it stays darker. 2.5x leaves room for another draw
    // (another machine's Embree bits move placement as a seed does) without letting the
    // point-baked 2.9-3.4x back.
    EXPECT_LE(e.worstRatio, 2.5f) << "seed " << seed;
  }
}

TEST(ProbePlacementSlow, AutomaticBeatsUniformGridOnShippedScenes) {
  const std::string dir = test::makeTempDir("kiln_place_slow");
  for (const std::string scene : {"two_rooms.gltf", "courtyard.gltf"}) {
    for (int evalSeed : {0, 1}) {
      std::string out;
      const std::string cmd = std::string(test::kilnExe()) + " probes compare-placement " +
                              test::scenesDir() + "/" + scene +
                              " --count 256 --points 1000 --eval-rays 2048 --eval-seed " +
                              std::to_string(evalSeed) + " -q --csv " + dir + "/c.csv";
      ASSERT_EQ(test::runCommand(cmd, &out), 0) << out;
      const std::vector<CsvRow> rows = csvRows(test::readTextFile(dir + "/c.csv"));
      const CsvRow* grid = nullptr;
      const CsvRow* automatic = nullptr;
      size_t fewestMatching = 0;  // fewest automatic probes with the grid's error or less
      for (const CsvRow& r : rows) {
        if (r.method == "uniform grid") grid = &r;
        if (r.method == "automatic") automatic = &r;
      }
      ASSERT_TRUE(grid && automatic) << out;
      for (const CsvRow& r : rows)
        if (r.method.rfind("automatic", 0) == 0 && r.mean <= grid->mean &&
            (fewestMatching == 0 || r.count < fewestMatching))
          fewestMatching = r.count;
      EXPECT_EQ(grid->count, 256u);
      EXPECT_LE(automatic->count, 256u);
      EXPECT_LT(automatic->mean, grid->mean) << scene << " eval seed " << evalSeed << "\n"
                                              << out;
      // Some automatic set (the final one at least) matches the grid with no more probes.
      EXPECT_GT(fewestMatching, 0u) << out;
      EXPECT_LE(fewestMatching, automatic->count) << out;
    }
  }
}

#endif

}  // namespace
}  // namespace kiln
