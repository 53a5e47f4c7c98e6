// probe_scene_test.cpp: probe placement and LPPVs on the shipped scenes (tools/scenes): no
// placed probe ends inside geometry or against a surface; the dark room right behind the
// sunlit wall of two_rooms gets no sunlight through the wall from the placed probes; an LPPV
// over a long object reaching from the sun patch into shadow varies along it where a single
// probe lookup cannot.
#include <gtest/gtest.h>

#include <algorithm>
#include <cstdio>

#include "kiln/lppv_volume.h"
#include "kiln/probe_runtime.h"
#include "probes/lppv.h"
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

Loaded load(const std::string& name) {
  Loaded l;
  Result<Scene> scene = loadScene(test::scenesDir() + "/" + name);
  EXPECT_TRUE(bool(scene)) << scene.error();
  l.scene = std::move(scene).value();
  Result<std::unique_ptr<Tracer>> tracer = Tracer::create(l.scene);
  EXPECT_TRUE(bool(tracer)) << tracer.error();
  l.tracer = std::move(tracer).value();
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
// the doorway. Probes placed automatically over the rooms must give them that, not room A's
// light: at each point the interpolated irradiance is compared with SH baked directly there
// (the truth) and with the truth at the mirror point in room A, in front of the patch. A
// tetrahedron from a room-A probe through the wall would pull the value towards room A's.
// (The placement is a quick one: 64-probe budget, 256 check points.) Known fragility: with
// 2048 check points, or another sampling sequence, this placement leaves these points below
// its lowest probes, extrapolated from a hull face that spans the wall: ~0.02 lux, which
// fails the second bound (docs/probe_placement.md, "What is left").

TEST(ProbeScenes, DarkRoomBehindTheSunlitWallGetsNoSunThroughIt) {
  const Loaded l = load("two_rooms.gltf");
  ProbePlacementSettings s = quickPlacement(64);
  s.volumes = {Bounds3{vec3(0.0f), vec3(8.25f, 3.0f, 4.0f)}};
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
    const float e = maxAxisIrradiance(interpolateProbes(*set, locateProbe(*set, behind[i])));
    std::printf("(%.2f, %.2f, %.2f): interpolated %.4f, truth %.4f, room A mirror %.4f lux\n",
                behind[i].x, behind[i].y, behind[i].z, e, eB, eA);
    // The wall really separates light from dark here (room A is hundreds of times brighter:
    // the test has teeth) ...
    EXPECT_GT(eA, 100.0f * eB) << i;
    // ... and no share of room A's light comes through it: a tetrahedron reaching a room-A
    // probe would add a weight (tenths) x eA. What is left is room B's own dim light, which
    // the probes give to within their and the truth's noise at these few-millilux levels.
    EXPECT_LT(e, 0.01f * eA) << i;
    EXPECT_LT(e, 2.0f * eB + 1e-3f) << i;
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

}  // namespace
}  // namespace kiln
