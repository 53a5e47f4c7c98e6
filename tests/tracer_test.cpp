// tracer_test.cpp: kiln::Tracer against analytic answers: hit distances and barycentrics,
// faces, alpha cut-outs, coloured transmittance, watertightness and thread safety.
#include "src/tracer.h"

#include <gtest/gtest.h>
#include <tbb/parallel_for.h>

#include <random>
#include <vector>

#include "tests/test_util.h"

namespace kiln {
namespace {

using test::addBox;
using test::addMaterial;
using test::addQuad;
using test::lambert;

// A quad in the plane z = `z` covering [-1, 1]^2, front side facing +Z (CCW seen from +Z).
// Its UVs put u = 0 at x = -1 and u = 1 at x = +1.
uint32_t addFloor(Scene& scene, float z, uint32_t material, float half = 1.0f) {
  return addQuad(scene, "quad", vec3(-half, -half, z), vec3(half, -half, z),
                 vec3(half, half, z), vec3(-half, half, z), material);
}

std::unique_ptr<Tracer> makeTracer(const Scene& scene) {
  auto tracer = Tracer::create(scene);
  EXPECT_TRUE(tracer.ok()) << tracer.error();
  return std::move(tracer).value();
}

Ray down(float x, float y, float z = 5.0f) { return Ray{vec3(x, y, z), vec3(0, 0, -1)}; }

Material blend(vec3 color, float alpha) {
  Material m = lambert(color);
  m.baseColorFactor = vec4(color, alpha);
  m.alphaMode = AlphaMode::Blend;
  return m;
}

vec3 uniformDirection(std::mt19937& rng) {
  std::uniform_real_distribution<float> u(0.0f, 1.0f);
  float z = 1.0f - 2.0f * u(rng);
  float r = std::sqrt(std::max(0.0f, 1.0f - z * z));
  float phi = 2.0f * kPi * u(rng);
  return vec3(r * std::cos(phi), r * std::sin(phi), z);
}

TEST(Tracer, HitsQuadAtAnalyticDistanceAndBarycentrics) {
  Scene scene;
  addFloor(scene, 0.0f, addMaterial(scene, lambert(vec3(0.5f))));
  auto tracer = makeTracer(scene);

  // (0.25, -0.5) lies in triangle 0 (p0 p1 p2): p = p0 + b1 (p1 - p0) + b2 (p2 - p0) with
  // (-1, -1) + b1 (2, 0) + b2 (2, 2) = (0.25, -0.5) -> b2 = 0.25, b1 = 0.375.
  auto hit = tracer->intersect(down(0.25f, -0.5f));
  ASSERT_TRUE(hit);
  EXPECT_EQ(hit->object, 0u);
  EXPECT_EQ(hit->triangle, 0u);
  EXPECT_NEAR(hit->t, 5.0f, 1e-5f);
  EXPECT_NEAR(hit->bary.x, 0.375f, 1e-6f);
  EXPECT_NEAR(hit->bary.y, 0.25f, 1e-6f);
  EXPECT_FLOAT_EQ(hit->geometricNormal.z, 1.0f);
  EXPECT_EQ(hit->geometricNormal.x, 0.0f);
  EXPECT_EQ(hit->geometricNormal.y, 0.0f);
  EXPECT_FALSE(hit->backFace);

  // (-0.5, 0.5) lies in triangle 1 (p0 p2 p3): (-1, -1) + b1 (2, 2) + b2 (0, 2) -> b1 = 0.25,
  // b2 = 0.5.
  hit = tracer->intersect(down(-0.5f, 0.5f));
  ASSERT_TRUE(hit);
  EXPECT_EQ(hit->triangle, 1u);
  EXPECT_NEAR(hit->bary.x, 0.25f, 1e-6f);
  EXPECT_NEAR(hit->bary.y, 0.5f, 1e-6f);
  vec3 p = scene.positionAt(hit->object, hit->triangle, hit->bary);
  EXPECT_NEAR(glm::distance(p, vec3(-0.5f, 0.5f, 0.0f)), 0.0f, 1e-6f);
}

TEST(Tracer, DistanceIsInUnitsOfTheDirectionLength) {
  Scene scene;
  addFloor(scene, 0.0f, addMaterial(scene, lambert(vec3(0.5f))));
  auto tracer = makeTracer(scene);
  auto hit = tracer->intersect(Ray{vec3(0.1f, 0.2f, 5.0f), vec3(0, 0, -4)});
  ASSERT_TRUE(hit);
  EXPECT_NEAR(hit->t, 1.25f, 1e-6f);
}

TEST(Tracer, BackFaceWhenHitFromBehind) {
  Scene scene;
  addFloor(scene, 0.0f, addMaterial(scene, lambert(vec3(0.5f))));
  auto tracer = makeTracer(scene);
  auto hit = tracer->intersect(Ray{vec3(0.3f, 0.2f, -2.0f), vec3(0, 0, 1)});
  ASSERT_TRUE(hit);
  EXPECT_NEAR(hit->t, 2.0f, 1e-6f);
  EXPECT_TRUE(hit->backFace);
  EXPECT_EQ(hit->geometricNormal, vec3(0, 0, 1));  // still the front side
}

TEST(Tracer, GeometricNormalFollowsWinding) {
  Scene scene;
  uint32_t m = addMaterial(scene, lambert(vec3(0.5f)));
  const vec3 p0(-1.3f, -0.7f, 0.2f), p1(1.1f, -0.9f, -0.4f), p2(0.9f, 1.2f, 0.5f);
  const vec3 p3 = p0 + (p2 - p1);
  addQuad(scene, "ccw", p0, p1, p2, p3, m);
  Scene flipped;
  addMaterial(flipped, lambert(vec3(0.5f)));
  addQuad(flipped, "cw", p3, p2, p1, p0, 0);
  const vec3 expected = glm::normalize(glm::cross(p1 - p0, p2 - p0));
  const vec3 target = 0.5f * (p0 + p2) + 0.1f * (p1 - p0);
  const Ray fromFront{target + 3.0f * expected, -expected};

  auto hit = makeTracer(scene)->intersect(fromFront);
  ASSERT_TRUE(hit);
  EXPECT_NEAR(glm::distance(hit->geometricNormal, expected), 0.0f, 1e-6f);
  EXPECT_FALSE(hit->backFace);
  EXPECT_NEAR(hit->t, 3.0f, 1e-5f);

  auto tracerFlipped = makeTracer(flipped);
  hit = tracerFlipped->intersect(fromFront);
  ASSERT_TRUE(hit);
  EXPECT_NEAR(glm::distance(hit->geometricNormal, -expected), 0.0f, 1e-6f);
  EXPECT_TRUE(hit->backFace);
}

TEST(Tracer, ClosestOfStackedQuadsAndRange) {
  Scene scene;
  uint32_t m = addMaterial(scene, lambert(vec3(0.5f)));
  addFloor(scene, 0.0f, m);  // object 0
  addFloor(scene, 1.0f, m);  // object 1
  auto tracer = makeTracer(scene);

  auto hit = tracer->intersect(down(0.1f, 0.1f));
  ASSERT_TRUE(hit);
  EXPECT_EQ(hit->object, 1u);
  EXPECT_NEAR(hit->t, 4.0f, 1e-6f);

  hit = tracer->intersect(Ray{vec3(0.1f, 0.1f, -3.0f), vec3(0, 0, 1)});
  ASSERT_TRUE(hit);
  EXPECT_EQ(hit->object, 0u);
  EXPECT_NEAR(hit->t, 3.0f, 1e-6f);

  Ray r = down(0.1f, 0.1f);
  r.tMin = 4.5f;  // past the upper quad
  hit = tracer->intersect(r);
  ASSERT_TRUE(hit);
  EXPECT_EQ(hit->object, 0u);
  EXPECT_NEAR(hit->t, 5.0f, 1e-6f);
  EXPECT_TRUE(tracer->occluded(r));

  r = down(0.1f, 0.1f);
  r.tMax = 3.9f;  // stops short of both
  EXPECT_FALSE(tracer->intersect(r));
  EXPECT_FALSE(tracer->occluded(r));
  r.tMax = 4.1f;
  hit = tracer->intersect(r);
  ASSERT_TRUE(hit);
  EXPECT_EQ(hit->object, 1u);
  EXPECT_TRUE(tracer->occluded(r));

  r.tMin = 2.0f;  // empty range
  r.tMax = -1.0f;
  EXPECT_FALSE(tracer->intersect(r));
  EXPECT_FALSE(tracer->occluded(r));

  r.tMin = 5.1f;  // beyond both
  r.tMax = kInfinity;
  EXPECT_FALSE(tracer->intersect(r));
  EXPECT_FALSE(tracer->occluded(r));
}

TEST(Tracer, Misses) {
  Scene scene;
  addFloor(scene, 0.0f, addMaterial(scene, lambert(vec3(0.5f))));
  auto tracer = makeTracer(scene);
  EXPECT_FALSE(tracer->intersect(down(1.5f, 0.0f)));             // beside the quad
  EXPECT_FALSE(tracer->intersect(Ray{vec3(0, 0, 5), vec3(0, 0, 1)}));  // pointing away
  EXPECT_FALSE(tracer->intersect(Ray{vec3(0, 0, 5), vec3(1, 0, 0)}));  // parallel
  EXPECT_FALSE(tracer->occluded(down(1.5f, 0.0f)));
  EXPECT_EQ(tracer->transmittance(down(1.5f, 0.0f)), vec3(1.0f));
  EXPECT_FALSE(tracer->hasTranslucentSurfaces());

  addMaterial(scene, blend(vec3(1.0f), 0.5f));  // a BLEND material no triangle uses
  EXPECT_FALSE(makeTracer(scene)->hasTranslucentSurfaces());
}

TEST(Tracer, NearestSurfaceIsExactOnFacesEdgesAndCorners) {
  // A box [0, 1]^3 and a floor quad far below: the nearest point is on a face, an edge or a
  // corner depending on the Voronoi region of the query point, at the analytic distance.
  Scene scene;
  const uint32_t m = addMaterial(scene, lambert(vec3(0.5f)));
  addBox(scene, "box", vec3(0.0f), vec3(1.0f), m, false);
  addFloor(scene, -10.0f, m, 50.0f);
  const auto tracer = makeTracer(scene);
  struct Case {
    vec3 p, nearest;
  };
  for (const Case& c : {Case{vec3(0.5f, 0.5f, 1.3f), vec3(0.5f, 0.5f, 1.0f)},    // face
                        Case{vec3(1.2f, 0.5f, 1.2f), vec3(1.0f, 0.5f, 1.0f)},    // edge
                        Case{vec3(-0.1f, -0.2f, 1.2f), vec3(0.0f, 0.0f, 1.0f)},  // corner
                        Case{vec3(0.5f, 0.5f, 0.4f), vec3(0.5f, 0.5f, 0.0f)}}) { // inside
    const auto n = tracer->nearestSurface(c.p);
    ASSERT_TRUE(n.has_value());
    EXPECT_NEAR(n->distance, glm::length(c.p - c.nearest), 1e-6f);
    EXPECT_NEAR(glm::length(n->point - c.nearest), 0.0f, 1e-6f);
    EXPECT_EQ(n->object, 0u);
  }
  // Far below the box, the floor is nearer; with a radius that reaches neither: nothing.
  const auto floor = tracer->nearestSurface(vec3(3.0f, 3.0f, -9.5f));
  ASSERT_TRUE(floor.has_value());
  EXPECT_EQ(floor->object, 1u);
  EXPECT_NEAR(floor->distance, 0.5f, 1e-6f);
  EXPECT_FALSE(tracer->nearestSurface(vec3(3.0f, 3.0f, 3.0f), 1.0f).has_value());
}

TEST(Tracer, EmptyObjectsKeepObjectIndices) {
  Scene scene;
  uint32_t m = addMaterial(scene, lambert(vec3(0.5f)));
  addFloor(scene, 0.0f, m);
  scene.objects.push_back(Object{});  // object 1: no triangles
  scene.objects.back().name = "empty";
  addFloor(scene, 1.0f, m);  // object 2
  auto tracer = makeTracer(scene);
  auto hit = tracer->intersect(down(0.0f, 0.5f));
  ASSERT_TRUE(hit);
  EXPECT_EQ(hit->object, 2u);
}

TEST(Tracer, RejectsMalformedScenes) {
  Scene scene;
  addFloor(scene, 0.0f, addMaterial(scene, lambert(vec3(0.5f))));
  Scene badIndex = scene;
  badIndex.objects[0].triangles[1].z = 4;  // only 4 vertices
  auto t1 = Tracer::create(badIndex);
  ASSERT_FALSE(t1.ok());
  EXPECT_NE(t1.error().find("triangle 1"), std::string::npos) << t1.error();
  Scene badMaterial = scene;
  badMaterial.objects[0].triangleMaterial[0] = 7;
  EXPECT_FALSE(Tracer::create(badMaterial).ok());
}

// A MASK quad at z = 0 whose texture is transparent (alpha 0) for u < 0.5, i.e. x < 0, and
// opaque for x > 0; an opaque backstop at z = -1.
struct MaskScene {
  Scene scene;
  std::unique_ptr<Tracer> tracer;
  MaskScene() {
    Texture tex;
    tex.name = "half";
    tex.image = Image(2, 1, 4);
    float* left = tex.image.at(0, 0);
    float* right = tex.image.at(1, 0);
    left[0] = left[1] = left[2] = 1.0f;
    left[3] = 0.0f;
    right[0] = right[1] = right[2] = 1.0f;
    right[3] = 1.0f;
    tex.sampler = TextureSampler{Wrap::ClampToEdge, Wrap::ClampToEdge, true};
    scene.textures.push_back(tex);
    Material mask = lambert(vec3(1.0f));
    mask.alphaMode = AlphaMode::Mask;
    mask.alphaCutoff = 0.5f;
    mask.baseColorTexture = 0;
    addFloor(scene, 0.0f, addMaterial(scene, mask));                      // object 0
    addFloor(scene, -1.0f, addMaterial(scene, lambert(vec3(0.5f))), 2.0f);  // object 1
    tracer = makeTracer(scene);
  }
};

TEST(Tracer, MaskCutOutPassesTransparentHalf) {
  MaskScene s;
  // Transparent half: the closest hit is the backstop, and nothing blocks the segment
  // above it.
  for (vec2 xy : {vec2(-0.5f, 0.3f), vec2(-0.9f, -0.7f), vec2(-0.1f, 0.9f)}) {
    auto hit = s.tracer->intersect(down(xy.x, xy.y));
    ASSERT_TRUE(hit);
    EXPECT_EQ(hit->object, 1u);
    EXPECT_NEAR(hit->t, 6.0f, 1e-5f);
    Ray r = down(xy.x, xy.y);
    r.tMax = 5.5f;
    EXPECT_FALSE(s.tracer->occluded(r));
    EXPECT_FALSE(s.tracer->intersect(r));
    EXPECT_EQ(s.tracer->transmittance(r), vec3(1.0f));
  }
  // Opaque half: the mask quad.
  for (vec2 xy : {vec2(0.5f, 0.3f), vec2(0.9f, -0.7f), vec2(0.1f, 0.9f)}) {
    auto hit = s.tracer->intersect(down(xy.x, xy.y));
    ASSERT_TRUE(hit);
    EXPECT_EQ(hit->object, 0u);
    EXPECT_NEAR(hit->t, 5.0f, 1e-5f);
    Ray r = down(xy.x, xy.y);
    r.tMax = 5.5f;
    EXPECT_TRUE(s.tracer->occluded(r));
    EXPECT_EQ(s.tracer->transmittance(r), vec3(0.0f));
  }
  // The same from behind (filters apply to both faces).
  auto hit = s.tracer->intersect(Ray{vec3(-0.5f, 0.0f, -0.5f), vec3(0, 0, 1)});
  EXPECT_FALSE(hit);
  hit = s.tracer->intersect(Ray{vec3(0.5f, 0.0f, -0.5f), vec3(0, 0, 1)});
  ASSERT_TRUE(hit);
  EXPECT_TRUE(hit->backFace);
}

TEST(Tracer, MaskFactorBelowCutoffIsInvisible) {
  Scene scene;
  Material mask = lambert(vec3(1.0f));
  mask.alphaMode = AlphaMode::Mask;
  mask.baseColorFactor.a = 0.3f;
  mask.alphaCutoff = 0.5f;
  addFloor(scene, 0.0f, addMaterial(scene, mask));
  Material kept = mask;
  kept.alphaCutoff = 0.25f;  // 0.3 >= 0.25: kept
  addFloor(scene, -1.0f, addMaterial(scene, kept));
  auto tracer = makeTracer(scene);
  auto hit = tracer->intersect(down(0.2f, 0.2f));
  ASSERT_TRUE(hit);
  EXPECT_EQ(hit->object, 1u);
  Ray r = down(0.2f, 0.2f);
  r.tMax = 5.5f;
  EXPECT_FALSE(tracer->occluded(r));
}

TEST(Tracer, BlendTransmittanceIsTintedByOpacity) {
  Scene scene;
  addFloor(scene, 0.0f, addMaterial(scene, blend(vec3(1.0f, 0.5f, 0.2f), 0.25f)));
  auto tracer = makeTracer(scene);
  EXPECT_TRUE(tracer->hasTranslucentSurfaces());
  Ray r = down(0.3f, -0.4f);
  r.tMax = 10.0f;
  vec3 t = tracer->transmittance(r);
  EXPECT_FLOAT_EQ(t.r, 0.75f * 1.0f);
  EXPECT_FLOAT_EQ(t.g, 0.75f * 0.5f);
  EXPECT_FLOAT_EQ(t.b, 0.75f * 0.2f);
  // BLEND is a surface for the other queries.
  EXPECT_TRUE(tracer->occluded(r));
  EXPECT_TRUE(tracer->intersect(r));
  // Through the shared diagonal edge, where both triangles may report the crossing: still
  // one surface.
  vec3 e = tracer->transmittance(down(0.3f, 0.3f));
  EXPECT_FLOAT_EQ(e.g, 0.375f);
  // A segment that ends before the surface sees nothing.
  r.tMax = 4.9f;
  EXPECT_EQ(tracer->transmittance(r), vec3(1.0f));
}

TEST(Tracer, BlendCrossedAtSharedEdgesCountsOnce) {
  // A tilted BLEND quad; rays aimed at points of its diagonal, where the crossing lies on
  // the edge both triangles share and each may report it at a t a few ulps apart.
  Scene scene;
  const vec3 p0(-1.3f, -0.7f, 0.2f), p1(1.1f, -0.9f, -0.4f), p2(0.9f, 1.2f, 0.5f);
  const vec3 p3 = p0 + (p2 - p1);
  addQuad(scene, "glass", p0, p1, p2, p3,
          addMaterial(scene, blend(vec3(1.0f, 0.5f, 0.2f), 0.25f)));
  auto tracer = makeTracer(scene);
  std::mt19937 rng(5);
  std::uniform_real_distribution<float> u(0.0f, 1.0f);
  int wrong = 0;
  for (int i = 0; i < 20000; ++i) {
    vec3 target = glm::mix(p0, p2, 0.05f + 0.9f * u(rng));
    vec3 o = target + (1.0f + 10.0f * u(rng)) * uniformDirection(rng);
    vec3 t = tracer->transmittance(Ray{o, (target - o) * 2.0f});
    if (t.g != 0.375f) ++wrong;
  }
  EXPECT_EQ(wrong, 0);
}

TEST(Tracer, BlendLayersMultiplyAndOpaqueStops) {
  Scene scene;
  addFloor(scene, 0.0f, addMaterial(scene, blend(vec3(1.0f, 0.5f, 0.2f), 0.25f)));
  addFloor(scene, 1.0f, addMaterial(scene, blend(vec3(0.5f, 1.0f, 1.0f), 0.5f)));
  addFloor(scene, -2.0f, addMaterial(scene, lambert(vec3(0.5f))), 0.5f);  // small, opaque
  auto tracer = makeTracer(scene);

  vec3 t = tracer->transmittance(down(0.8f, 0.8f));  // beside the opaque quad
  EXPECT_FLOAT_EQ(t.r, 0.75f * 1.0f * 0.5f * 0.5f);
  EXPECT_FLOAT_EQ(t.g, 0.75f * 0.5f * 0.5f * 1.0f);
  EXPECT_FLOAT_EQ(t.b, 0.75f * 0.2f * 0.5f * 1.0f);
  // Upwards through both: same product (order does not matter).
  vec3 up = tracer->transmittance(Ray{vec3(0.8f, 0.8f, -5.0f), vec3(0, 0, 1)});
  EXPECT_FLOAT_EQ(up.g, t.g);

  EXPECT_EQ(tracer->transmittance(down(0.1f, 0.1f)), vec3(0.0f));  // opaque behind
  Ray r = down(0.1f, 0.1f);
  r.tMax = 6.0f;  // stops between the lower BLEND quad and the opaque one
  EXPECT_FLOAT_EQ(tracer->transmittance(r).b, 0.75f * 0.2f * 0.5f);
  // Starting below the upper layer.
  r.tMin = 4.5f;
  EXPECT_FLOAT_EQ(tracer->transmittance(r).b, 0.75f * 0.2f);
}

TEST(Tracer, TransmittanceBlockedBehindBlendCostsOneQueryAndCaptureSeesEveryQuery) {
  // The scene above; Tracer::captureRays records each Embree query. A segment that an opaque
  // surface blocks (behind both BLEND layers) takes one any-hit query that passes the BLEND
  // layers, no closest-hit walk; a segment through the two layers alone takes the any-hit
  // query and a walk of three closest hits (two layers, then the miss); a clear segment one.
  Scene scene;
  addFloor(scene, 0.0f, addMaterial(scene, blend(vec3(1.0f, 0.5f, 0.2f), 0.25f)));
  addFloor(scene, 1.0f, addMaterial(scene, blend(vec3(0.5f, 1.0f, 1.0f), 0.5f)));
  addFloor(scene, -2.0f, addMaterial(scene, lambert(vec3(0.5f))), 0.5f);
  auto tracer = makeTracer(scene);
  std::vector<Tracer::CapturedRay> log;
  auto count = [&](bool closestHit) {
    size_t n = 0;
    for (const Tracer::CapturedRay& c : log) n += c.closestHit == closestHit ? 1 : 0;
    return n;
  };
  Tracer::captureRays(&log);
  EXPECT_EQ(tracer->transmittance(down(0.1f, 0.1f)), vec3(0.0f));
  EXPECT_EQ(log.size(), 1u);
  EXPECT_EQ(count(false), 1u);
  EXPECT_EQ(log[0].ray.origin, down(0.1f, 0.1f).origin);
  log.clear();
  EXPECT_GT(tracer->transmittance(down(0.8f, 0.8f)).g, 0.0f);
  EXPECT_EQ(count(false), 1u);
  EXPECT_EQ(count(true), 3u);
  log.clear();
  EXPECT_EQ(tracer->transmittance(Ray{vec3(0.0f, 0.0f, 2.0f), vec3(0, 0, 1)}), vec3(1.0f));
  EXPECT_TRUE(tracer->intersect(down(0.1f, 0.1f)).has_value());
  EXPECT_EQ(count(false), 1u);
  EXPECT_EQ(count(true), 1u);
  Tracer::captureRays(nullptr);
  log.clear();
  (void)tracer->occluded(down(0.1f, 0.1f));
  EXPECT_TRUE(log.empty());
}

TEST(Tracer, OpaqueInFrontOfBlendStops) {
  Scene scene;
  addFloor(scene, 0.0f, addMaterial(scene, blend(vec3(1.0f), 0.1f)));
  addFloor(scene, 1.0f, addMaterial(scene, lambert(vec3(0.5f))));
  auto tracer = makeTracer(scene);
  EXPECT_EQ(tracer->transmittance(down(0.2f, 0.1f)), vec3(0.0f));
}

// Slab test: the entry distance of ray o + t d into [lo, hi], or -1 when it misses.
float slabEntry(vec3 o, vec3 d, vec3 lo, vec3 hi) {
  float t0 = 0.0f, t1 = kInfinity;
  for (int a = 0; a < 3; ++a) {
    float inv = 1.0f / d[a];
    float ta = (lo[a] - o[a]) * inv, tb = (hi[a] - o[a]) * inv;
    t0 = std::max(t0, std::min(ta, tb));
    t1 = std::min(t1, std::max(ta, tb));
  }
  return t0 <= t1 ? t0 : -1.0f;
}

TEST(Tracer, ClosedBoxFromOutside) {
  Scene scene;
  const vec3 lo(0.0f), hi(1.0f);
  addBox(scene, "block", lo, hi, addMaterial(scene, lambert(vec3(0.5f))), false);
  auto tracer = makeTracer(scene);
  std::mt19937 rng(7);
  std::uniform_real_distribution<float> u(0.0f, 1.0f);
  const vec3 c(0.5f);
  int misses = 0, hits = 0;
  for (int i = 0; i < 20000; ++i) {
    vec3 o = c + 5.0f * uniformDirection(rng);
    if (i % 2 == 0) {
      // Aimed past the box: the line's closest approach to the centre exceeds the box's
      // bounding sphere (radius sqrt(3)/2).
      vec3 toC = glm::normalize(c - o);
      vec3 side = glm::normalize(glm::cross(toC, uniformDirection(rng)));
      vec3 d = glm::normalize(toC * 5.0f + side * (1.0f + 2.0f * u(rng)));
      Ray r{o, d};
      EXPECT_FALSE(tracer->intersect(r)) << i;
      EXPECT_FALSE(tracer->occluded(r)) << i;
      ++misses;
    } else {
      // Aimed at a point well inside: hits the outside (front) at the slab distance.
      vec3 target = vec3(0.1f) + 0.8f * vec3(u(rng), u(rng), u(rng));
      vec3 d = glm::normalize(target - o);
      auto hit = tracer->intersect(Ray{o, d});
      ASSERT_TRUE(hit) << i;
      EXPECT_FALSE(hit->backFace);
      EXPECT_NEAR(hit->t, slabEntry(o, d, lo, hi), 1e-4f);
      ++hits;
    }
  }
  EXPECT_EQ(misses + hits, 20000);
}

TEST(Tracer, WatertightFromInsideClosedBox) {
  Scene scene;
  const vec3 lo(-1.0f, -1.0f, -1.0f), hi(1.0f, 2.0f, 3.0f);
  addBox(scene, "room", lo, hi, addMaterial(scene, lambert(vec3(0.5f))), true);
  auto tracer = makeTracer(scene);
  std::mt19937 rng(11);
  std::uniform_real_distribution<float> u(0.0f, 1.0f);
  auto inside = [&] { return lo + (hi - lo) * vec3(u(rng), u(rng), u(rng)); };
  int escaped = 0, backFaces = 0, offSurface = 0;
  const int kRays = 100000;
  for (int i = 0; i < kRays; ++i) {
    vec3 o = inside();
    vec3 d;
    if (i % 4 == 0) {
      d = uniformDirection(rng);
    } else {
      // Straight at an edge or a corner of the box, where the triangles of two or three
      // faces (and each face's diagonal) meet: the cracks a non-watertight test leaks through.
      vec3 target = inside();
      int a = i % 3;
      target[a] = u(rng) < 0.5f ? lo[a] : hi[a];
      int b = (a + 1) % 3;
      target[b] = u(rng) < 0.5f ? lo[b] : hi[b];
      if (i % 4 == 3) target[(a + 2) % 3] = u(rng) < 0.5f ? lo[(a + 2) % 3] : hi[(a + 2) % 3];
      d = target - o;
    }
    auto hit = tracer->intersect(Ray{o, d});
    if (!hit) {
      ++escaped;
      continue;
    }
    if (hit->backFace) ++backFaces;
    vec3 p = o + hit->t * d;
    vec3 dist = glm::min(glm::abs(p - lo), glm::abs(p - hi));
    if (std::min(dist.x, std::min(dist.y, dist.z)) > 1e-4f) ++offSurface;
  }
  EXPECT_EQ(escaped, 0);
  EXPECT_EQ(backFaces, 0);  // the room's faces point inward
  EXPECT_EQ(offSurface, 0);
}

TEST(Tracer, ConcurrentQueriesMatchSerial) {
  MaskScene s;  // cut-out filter in play
  addFloor(s.scene, 0.5f, addMaterial(s.scene, blend(vec3(0.9f, 0.6f, 0.3f), 0.4f)), 0.7f);
  addBox(s.scene, "room", vec3(-3.0f), vec3(3.0f), addMaterial(s.scene, lambert(vec3(0.5f))),
         true);
  s.tracer = makeTracer(s.scene);
  std::mt19937 rng(3);
  std::uniform_real_distribution<float> u(-1.5f, 1.5f);
  const int kRays = 20000;
  std::vector<Ray> rays(kRays);
  for (Ray& r : rays) r = Ray{vec3(u(rng), u(rng), u(rng)), uniformDirection(rng)};
  struct Answer {
    bool hit = false;
    float t = 0.0f;
    uint32_t object = 0, triangle = 0;
    bool occludedShort = false;
    vec3 transmittance{0.0f};
    bool operator==(const Answer&) const = default;
  };
  auto query = [&](const Ray& r) {
    Answer a;
    if (auto h = s.tracer->intersect(r)) {
      a.hit = true;
      a.t = h->t;
      a.object = h->object;
      a.triangle = h->triangle;
    }
    // Short of the room's walls (at least 1.5 away), so that the segment can get through.
    Ray shortRay = r;
    shortRay.tMax = 1.4f;
    a.occludedShort = s.tracer->occluded(shortRay);
    a.transmittance = s.tracer->transmittance(shortRay);
    return a;
  };
  std::vector<Answer> serial(kRays), parallel(kRays);
  for (int i = 0; i < kRays; ++i) serial[i] = query(rays[i]);
  tbb::parallel_for(0, kRays, [&](int i) { parallel[i] = query(rays[i]); });
  int mismatches = 0, partial = 0;
  for (int i = 0; i < kRays; ++i) {
    if (!(serial[i] == parallel[i])) ++mismatches;
    if (serial[i].transmittance.r > 0.0f && serial[i].transmittance.r < 1.0f) ++partial;
  }
  EXPECT_EQ(mismatches, 0);
  EXPECT_GT(partial, 0);  // the BLEND quad was crossed by some rays
}

}  // namespace
}  // namespace kiln
