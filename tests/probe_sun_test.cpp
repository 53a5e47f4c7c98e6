// The sun layer (kiln/probe_set.h, ProbeSunLayer; probes/sun_shadows.h): ramps fitted to a
// shadow whose boundary is known in closed form, and the blend that uses them.
//
// The scene: a ground quad at y = 0 and a roof slab over x <= 0 (y in [3, 3.2]), under a
// directional light travelling along t = (a, -b, c) (b > 0, a > 0: from the roof's side).
// A point p below the roof sees the light unless its ray towards the light, -t, enters the
// roof (through its underside or its end face x = 0): the ray reaches y = 3.2 at
// x = p.x - a (3.2 - p.y) / b, so p is in shadow exactly when p.x < a (3.2 - p.y) / b. The
// boundary is the plane through the roof's top edge {x = 0, y = 3.2} that contains t.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <memory>
#include <random>
#include <vector>

#include "kiln/probe_runtime.h"
#include "probes/placement_evaluation.h"
#include "probes/probe_baker.h"
#include "probes/probe_placement.h"
#include "probes/sun_shadows.h"
#include "src/sh_projection.h"
#include "tests/test_util.h"

namespace kiln {
namespace {

using glm::vec3;
using glm::vec4;

const vec3 kTravel = glm::normalize(vec3(1.0f, -1.5f, 0.3f));
constexpr float kSunLux = 4.0f;

// Signed distance of p from the shadow boundary, positive on the lit side.
float litSide(vec3 p) {
  // The plane contains the edge's direction (0, 0, 1) and the travel direction t: its normal
  // is their cross product, oriented so that +x (away from the roof) is lit.
  vec3 n = glm::normalize(glm::cross(vec3(0, 0, 1), kTravel));
  if (n.x < 0.0f) n = -n;
  return glm::dot(n, p - vec3(0.0f, 3.2f, 0.0f));
}

struct SunWorld {
  Scene scene;
  std::unique_ptr<Tracer> tracer;
  explicit SunWorld(float slatGap = 0.0f) {
    const uint32_t grey = test::addMaterial(scene, test::lambert(vec3(0.5f)));
    test::addQuad(scene, "ground", vec3(-30, 0, 30), vec3(30, 0, 30), vec3(30, 0, -30),
                  vec3(-30, 0, -30), grey);
    if (slatGap > 0.0f) {
      // A roof of thin slats (2 cm) along z, each slatGap wide with slatGap between: stripes
      // of light and shade about slatGap wide each, which no single plane bounds.
      for (int k = 0; k < 40; ++k) {
        const float x1 = -2.0f * slatGap * float(k);
        test::addBox(scene, "slat" + std::to_string(k), vec3(x1 - slatGap, 3.0f, -30.0f),
                     vec3(x1, 3.02f, 30.0f), grey, false);
      }
    } else {
      test::addBox(scene, "roof", vec3(-30.0f, 3.0f, -30.0f), vec3(0.0f, 3.2f, 30.0f), grey,
                   false);
    }
    scene.lights.push_back(test::directionalLight(kTravel, kSunLux));
    scene.updateBounds();
    tracer = std::move(Tracer::create(scene)).value();
  }
  Integrator integrator() const {
    return Integrator(scene, *tracer, probeIntegratorSettings(scene, ProbeBakeSettings{}));
  }
};

// A regular tetrahedron of edge `edge` centred at c, positively oriented.
std::array<vec3, 4> tetrahedron(vec3 c, float edge) {
  const float h = edge / (2.0f * std::sqrt(2.0f));
  std::array<vec3, 4> t = {c + h * vec3(1, 1, 1), c + h * vec3(1, -1, -1),
                           c + h * vec3(-1, 1, -1), c + h * vec3(-1, -1, 1)};
  const float o = glm::dot(glm::cross(t[1] - t[0], t[2] - t[0]), t[3] - t[0]);
  if (o < 0.0f) std::swap(t[2], t[3]);
  return t;
}

std::array<float, 4> sharesOf(const Integrator& in, const std::array<vec3, 4>& t) {
  std::array<float, 4> s{};
  for (int k = 0; k < 4; ++k) s[size_t(k)] = sunShare(in, 0, t[size_t(k)], uint64_t(k));
  return s;
}

// The ramp is the analytic step: its zero crossing (value 1/2) lies on the boundary plane
// and its gradient is the plane's normal, perpendicular to the light; clamped, it is the
// light's share (0 or 1) at every point more than its width from the plane.
TEST(ProbeSun, RampFollowsTheShadowPlaneOfAStraightEdge) {
  const SunWorld w;
  const Integrator in = w.integrator();
  const vec3 centre(kTravel.x / -kTravel.y * 1.7f, 1.5f, 0.0f);
  ASSERT_NEAR(litSide(centre), 0.0f, 1e-5f);  // on the boundary
  const std::array<vec3, 4> t = tetrahedron(centre + vec3(0.05f, 0.0f, 0.0f), 1.2f);
  const vec4 a = fitSunRamp(in, 0, t, sharesOf(in, t), 11);
  ASSERT_FALSE(std::isnan(a.x)) << "a straight edge's shadow through the cell gets a ramp";
  // The ramp's gradient g from its four values: solve [t_k - t_0] g = a_k - a_0.
  const glm::mat3 m = glm::transpose(glm::mat3(t[1] - t[0], t[2] - t[0], t[3] - t[0]));
  const vec3 g = glm::inverse(m) * vec3(a[1] - a[0], a[2] - a[0], a[3] - a[0]);
  vec3 n = glm::normalize(glm::cross(vec3(0, 0, 1), kTravel));
  if (n.x < 0.0f) n = -n;
  EXPECT_NEAR(glm::dot(glm::normalize(g), kTravel), 0.0f, 2e-3f);  // contains the light
  EXPECT_GT(glm::dot(glm::normalize(g), n), 0.99999f);  // the plane's normal, within 0.26 deg
  const float width = 1.0f / glm::length(g);  // from value 0 to 1
  EXPECT_LE(width, 0.0105f) << "a hard shadow gets the narrowest ramp";
  // The half-value surface passes through the plane at the cell's centre within 1 mm.
  const vec3 mid = 0.25f * (t[0] + t[1] + t[2] + t[3]);
  const float atMid = a[0] + glm::dot(g, mid - t[0]);
  EXPECT_NEAR((0.5f - atMid) / glm::length(g), -litSide(mid), 1e-3f);
  // Every point more than 2 cm from the plane: the clamped ramp is the share, exactly.
  std::mt19937 rng(5);
  std::uniform_real_distribution<float> u(0.0f, 1.0f);
  int checked = 0;
  for (int i = 0; i < 2000; ++i) {
    float b[4], sum = 0.0f;
    for (float& x : b) sum += (x = -std::log(1.0f - u(rng)));
    vec3 p(0.0f);
    float r = 0.0f;
    for (int k = 0; k < 4; ++k) {
      p += b[k] / sum * t[size_t(k)];
      r += b[k] / sum * a[k];
    }
    if (std::abs(litSide(p)) < 0.02f) continue;
    ++checked;
    const float expected = litSide(p) > 0.0f ? 1.0f : 0.0f;
    EXPECT_EQ(std::clamp(r, 0.0f, 1.0f), expected) << p.x << " " << p.y << " " << p.z;
    EXPECT_EQ(sunShare(in, 0, p, uint64_t(i)), expected);  // the tracer agrees
  }
  EXPECT_GT(checked, 1800);
}

// No ramp where the plain blend is exact (a cell in full sun) or where no plane bounds the
// shade (stripes under slats, 3 per cell).
TEST(ProbeSun, NoRampInFullSunOrUnderStripes) {
  const SunWorld open;
  const Integrator in = open.integrator();
  const std::array<vec3, 4> lit = tetrahedron(vec3(10.0f, 1.5f, 0.0f), 1.2f);
  EXPECT_TRUE(std::isnan(fitSunRamp(in, 0, lit, sharesOf(in, lit), 3).x));
  const SunWorld slats(0.15f);
  const Integrator striped = slats.integrator();
  int ramps = 0;
  for (int i = 0; i < 8; ++i) {
    const std::array<vec3, 4> t = tetrahedron(vec3(-4.0f + 0.37f * float(i), 1.5f, 0.0f), 1.2f);
    const std::array<float, 4> s = sharesOf(striped, t);
    ramps += std::isnan(fitSunRamp(striped, 0, t, s, uint64_t(i)).x) ? 0 : 1;
  }
  EXPECT_EQ(ramps, 0);
}

// Two of a cell's probes stand in small pockets of shade (columns under two small slabs, the
// sun overhead) while the cell around them is lit: no one plane bounds that shade, and the
// plain blend darkens the whole cell by those probes' weights. The cell gets the linear share
// that fits its interior (here the constant 1): lit at every point outside the pockets.
TEST(ProbeSun, ProbesInPocketsOfShadeDoNotDarkenTheirCell) {
  Scene scene;
  const uint32_t grey = test::addMaterial(scene, test::lambert(vec3(0.5f)));
  test::addQuad(scene, "ground", vec3(-30, 0, 30), vec3(30, 0, 30), vec3(30, 0, -30),
                vec3(-30, 0, -30), grey);
  const std::array<vec3, 4> t = tetrahedron(vec3(0.0f, 1.5f, 0.0f), 1.2f);
  // The pockets: columns over the two lower vertices, whose edge (level) projects along the
  // light onto a diagonal through the middle of the cell's shadow: a plane along the light
  // that cut both pockets off would cut the cell in two.
  std::array<int, 4> byHeight = {0, 1, 2, 3};
  std::sort(byHeight.begin(), byHeight.end(),
            [&](int a, int b) { return t[size_t(a)].y < t[size_t(b)].y; });
  const std::array<int, 2> pockets = {byHeight[0], byHeight[1]};
  ASSERT_NEAR(t[size_t(pockets[0])].y, t[size_t(pockets[1])].y, 1e-5f);
  constexpr float kPocket = 0.08f;  // half the side of each square column of shade
  for (int k : pockets) {
    const vec3 v = t[size_t(k)];
    test::addBox(scene, "slab" + std::to_string(k), vec3(v.x - kPocket, 3.0f, v.z - kPocket),
                 vec3(v.x + kPocket, 3.05f, v.z + kPocket), grey, false);
  }
  scene.lights.push_back(test::directionalLight(vec3(0.0f, -1.0f, 0.0f), kSunLux));
  scene.updateBounds();
  const std::unique_ptr<Tracer> tracer = std::move(Tracer::create(scene)).value();
  const Integrator in(scene, *tracer, probeIntegratorSettings(scene, ProbeBakeSettings{}));
  const std::array<float, 4> shares = sharesOf(in, t);
  for (int k = 0; k < 4; ++k)
    ASSERT_EQ(shares[size_t(k)], k == pockets[0] || k == pockets[1] ? 0.0f : 1.0f) << k;
  const vec4 a = fitSunRamp(in, 0, t, shares, 21);
  ASSERT_FALSE(std::isnan(a.x)) << "the cell gets a ramp";
  auto inPocket = [&](vec3 p) {
    for (int k : pockets)
      if (std::abs(p.x - t[size_t(k)].x) < kPocket + 0.02f &&
          std::abs(p.z - t[size_t(k)].z) < kPocket + 0.02f)
        return true;
    return false;
  };
  std::mt19937 rng(9);
  std::uniform_real_distribution<float> u(0.0f, 1.0f);
  int checked = 0;
  double plainError = 0.0;
  for (int i = 0; i < 2000; ++i) {
    float b[4], sum = 0.0f;
    for (float& x : b) sum += (x = -std::log(1.0f - u(rng)));
    vec3 p(0.0f);
    float r = 0.0f, plain = 0.0f;
    for (int k = 0; k < 4; ++k) {
      p += b[k] / sum * t[size_t(k)];
      r += b[k] / sum * a[k];
      plain += b[k] / sum * shares[size_t(k)];
    }
    if (inPocket(p)) continue;
    ++checked;
    EXPECT_EQ(sunShare(in, 0, p, uint64_t(i)), 1.0f);  // lit, as the tracer says
    EXPECT_GE(std::clamp(r, 0.0f, 1.0f), 0.97f) << p.x << " " << p.y << " " << p.z;
    plainError += 1.0 - plain;
  }
  EXPECT_GT(checked, 1900);
  EXPECT_GT(plainError / checked, 0.4) << "the plain blend darkens the cell";
}

// Through the bake and the blend: points beside the edge, where a cell's probes on both sides
// mix lit and shaded light, get the light as SH baked at the point has it (its L00 within
// the indirect light's interpolation error), where the plain blend (no layer) is off by
// much more; every blended result keeps irradiance >= 0.
TEST(ProbeSun, BlendMatchesTheCentreBakeBesideTheEdge) {
  const SunWorld w;
  std::vector<vec3> grid;
  for (int x = -3; x <= 3; ++x)
    for (int y = 0; y <= 2; ++y)
      for (int z = -1; z <= 1; ++z) grid.push_back(vec3(0.9f * float(x) + 1.3f, 0.3f + 1.1f * float(y), 1.0f * float(z)));
  ProbeBakeSettings bake;  // with visibility maps: the layer applies to the visibility blend
  bake.rays = 1024;
  ProbeBakeReport report;
  Result<ProbeSet> set = bakeProbes(w.scene, *w.tracer, grid, bake, nullptr, nullptr, &report);
  ASSERT_TRUE(bool(set)) << set.error();
  ASSERT_EQ(set->sun.light, 0);
  EXPECT_GT(report.sunRampCells, 0);
  bake.sunShadows = false;
  Result<ProbeSet> plain = bakeProbes(w.scene, *w.tracer, grid, bake);
  ASSERT_TRUE(bool(plain)) << plain.error();
  EXPECT_TRUE(plain->sun.empty());
  // The same light in the probes either way (band 0 is kept by deringing).
  for (size_t i = 0; i < grid.size(); ++i)
    EXPECT_NEAR(luminance(set->sh[i].c[0]), luminance(plain->sh[i].c[0]),
                1e-5f * luminance(plain->sh[i].c[0]))
        << i;
  const Integrator in = w.integrator();
  std::mt19937 rng(9);
  std::uniform_real_distribution<float> ux(-1.0f, 3.5f), uy(0.4f, 2.4f), uz(-0.8f, 0.8f);
  float worstLayer = 0.0f, worstPlain = 0.0f;
  int points = 0;
  for (int i = 0; i < 400 && points < 40; ++i) {
    const vec3 p(ux(rng), uy(rng), uz(rng));
    const float d = litSide(p);
    if (std::abs(d) < 0.05f || std::abs(d) > 0.5f) continue;  // beside the edge
    ++points;
    const ProbeSample truth = bakeProbe(in, p, 1000 + uint64_t(i), 1024, 1);
    const float t = luminance(truth.sh.c[0]);
    const ShL2Rgb layer = sampleProbes(*set, p);
    const ShL2Rgb blend = sampleProbes(*plain, p);
    auto off = [&](const ShL2Rgb& e) {
      const float r = luminance(e.c[0]) / t;
      return std::max(r, 1.0f / r);
    };
    worstLayer = std::max(worstLayer, off(layer));
    worstPlain = std::max(worstPlain, off(blend));
    const vec3 minE = minIrradiance(layer);
    EXPECT_GE(std::min({minE.x, minE.y, minE.z}), -1e-4f * kSunLux) << p.x << " " << p.y;
  }
  ASSERT_GE(points, 30);
  std::cout << "beside the edge: worst L00 ratio " << worstLayer << " with the layer, "
            << worstPlain << " plain\n";
  EXPECT_LT(worstLayer, 1.3f);
  EXPECT_GT(worstPlain, 2.0f);
}

// compare-placement --exact-sun (PlacementEvaluation::measureWithExactSunShares): the bound a
// perfect layer would give. Under slats 15 cm apart the light falls in stripes no ramp fits
// (NoRampInFullSunOrUnderStripes) and no probe 0.8 m from the next resolves, so the layer's
// blend gives every point about the stripes' mean; with each point's exact share in its
// place, only the bounced light is left to interpolate. Where a point and all four of its
// probes are in full sun, the exact share is the probes' share and nothing changes.
// Measured: 57 points under the slats, mean error 0.74 with the layer and 0.027 with exact
// shares; 45 points in full sun.
TEST(ProbeSun, ExactSharesBoundWhatALayerCouldGive) {
  const SunWorld slats(0.15f);
  std::vector<vec3> grid;
  for (int x = 0; x <= 9; ++x)
    for (int y = 0; y <= 2; ++y)
      for (int z = -1; z <= 1; ++z)
        grid.push_back(vec3(-4.0f + 0.8f * float(x), 0.4f + 1.0f * float(y), 0.8f * float(z)));
  ProbeBakeSettings bake;  // visibility maps: the layer applies to the visibility blend
  bake.rays = 1024;
  TruthPoints truth;
  std::mt19937 rng(5);
  std::uniform_real_distribution<float> ux(-3.5f, 3.0f), uy(0.5f, 2.3f), uz(-0.7f, 0.7f);
  for (int i = 0; i < 200; ++i) truth.points.push_back(vec3(ux(rng), uy(rng), uz(rng)));
  ProbeBakeSettings truthBake = bake;
  truthBake.seed = 99;
  truth.sh = bakePointSh(slats.scene, *slats.tracer, truth.points, truthBake);
  ASSERT_EQ(truth.sh.size(), truth.points.size());
  truth.floor = 0.02f * kSunLux;
  const PlacementEvaluation evaluation(slats.scene, *slats.tracer, truth, bake);
  Result<ProbeSet> set = evaluation.bake(grid);
  ASSERT_TRUE(bool(set)) << set.error();
  ASSERT_EQ(set->sun.light, 0);
  const std::vector<float> shares = evaluation.sunShares();
  ASSERT_EQ(shares.size(), truth.points.size());
  const FieldError layer = evaluation.measure(*set).visibility;
  const FieldError exact = evaluation.measureWithExactSunShares(*set, shares);
  double striped = 0.0, stripedExact = 0.0;
  int stripedPoints = 0, litPoints = 0;
  for (size_t i = 0; i < truth.points.size(); ++i) {
    const ProbeLocation loc = locateProbe(*set, truth.points[i]);
    ASSERT_GE(loc.cell, 0);
    bool allLit = shares[i] == 1.0f;
    bool mixed = false;
    for (int k = 0; k < 4; ++k) {
      const float v = set->sun.visibility[size_t(loc.probes[k])];
      allLit = allLit && v == 1.0f;
      mixed = mixed || (v > 0.1f && v < 0.9f);
    }
    if (allLit) {
      ++litPoints;
      // (The weights sum to 1 up to float rounding, so the share added is 1 - (1 +- eps).)
      EXPECT_NEAR(exact.perPoint[i], layer.perPoint[i], 1e-5f) << i;
    } else if (mixed && truth.points[i].x < -1.0f) {
      ++stripedPoints;
      striped += layer.perPoint[i];
      stripedExact += exact.perPoint[i];
    }
  }
  ASSERT_GE(litPoints, 20);
  ASSERT_GE(stripedPoints, 40);
  striped /= stripedPoints;
  stripedExact /= stripedPoints;
  std::cout << stripedPoints << " points under the slats: mean error " << striped
            << " with the layer, " << stripedExact << " with exact shares; " << litPoints
            << " in full sun\n";
  EXPECT_GT(striped, 0.5);
  EXPECT_LT(stripedExact, 0.2);
}

// Ramps are a function of the cell and the seed alone: the same bits on 1 and 2 threads.
TEST(ProbeSun, RampsDoNotDependOnTheThreadCount) {
  const SunWorld w;
  std::vector<vec3> grid;
  for (int x = 0; x < 5; ++x)
    for (int y = 0; y < 3; ++y)
      for (int z = 0; z < 3; ++z) grid.push_back(vec3(-1.0f + 0.8f * float(x), 0.5f + 0.9f * float(y), 0.7f * float(z)));
  ProbeBakeSettings bake;
  bake.rays = 64;
  bake.visibilityResolution = 0;
  bake.threads = 1;
  Result<ProbeSet> one = bakeProbes(w.scene, *w.tracer, grid, bake);
  bake.threads = 2;
  Result<ProbeSet> two = bakeProbes(w.scene, *w.tracer, grid, bake);
  ASSERT_TRUE(bool(one) && bool(two));
  ASSERT_EQ(one->sun.ramps.size(), two->sun.ramps.size());
  ASSERT_FALSE(one->sun.ramps.empty());
  EXPECT_EQ(std::memcmp(one->sun.ramps.data(), two->sun.ramps.data(),
                        one->sun.ramps.size() * sizeof(vec4)),
            0);
  EXPECT_EQ(one->sun.visibility, two->sun.visibility);
}

}  // namespace
}  // namespace kiln
