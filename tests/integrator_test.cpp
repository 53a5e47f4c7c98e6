// integrator_test.cpp: the path tracer against closed forms (Lambert's cosine law, inverse
// square, glTF spot falloff, furnace series, a view factor), its splitting into direct and
// indirect light, its convergence rate and its determinism across thread counts.
//
// Noisy estimates are checked against 5 standard errors estimated from the samples
// themselves (each sample evaluated alone, so the spread is measured, not assumed); with
// scrambled Sobol samples the true error is smaller, so this bound is conservative.
#include "src/integrator.h"

#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <memory>
#include <vector>

#include "src/parallel.h"
#include "src/sampling.h"
#include "src/tracer.h"
#include "tests/test_util.h"

namespace kiln {
namespace {

using test::addBox;
using test::addMaterial;
using test::addQuad;
using test::lambert;

constexpr double kPiD = 3.14159265358979323846;

// A scene together with its tracer.
struct World {
  Scene scene;
  std::unique_ptr<Tracer> tracer;

  void build() {
    auto created = Tracer::create(scene);
    ASSERT_TRUE(created.ok()) << created.error();
    tracer = std::move(created).value();
  }
};

// A horizontal square at height y, half-size h, facing up (+Y).
uint32_t addFloor(Scene& scene, float h, uint32_t material, float y = 0.0f,
                  const std::string& name = "floor") {
  return addQuad(scene, name, vec3(-h, y, h), vec3(h, y, h), vec3(h, y, -h), vec3(-h, y, -h),
                 material);
}

// The quad x in [x0, x1], z in [z0, z1] at height y, facing up.
uint32_t addHorizontal(Scene& scene, float x0, float x1, float z0, float z1, float y,
                       uint32_t material, const std::string& name = "quad") {
  return addQuad(scene, name, vec3(x0, y, z1), vec3(x1, y, z1), vec3(x1, y, z0), vec3(x0, y, z0),
                 material);
}

struct MeanError {
  glm::dvec3 mean{0.0};
  glm::dvec3 stdError{0.0};
};

// Mean and standard error of the mean of n per-sample values f(i).
template <typename F>
MeanError sampleMean(uint32_t n, F f) {
  glm::dvec3 sum(0.0), sum2(0.0);
  for (uint32_t i = 0; i < n; ++i) {
    glm::dvec3 v(f(i));
    sum += v;
    sum2 += v * v;
  }
  MeanError r;
  r.mean = sum / double(n);
  glm::dvec3 var = glm::max(sum2 / double(n) - r.mean * r.mean, glm::dvec3(0.0));
  r.stdError = glm::sqrt(var * double(n) / double(n - 1) / double(n));
  return r;
}

// Checks every channel of `m` against `expected` within 5 standard errors (plus a float
// rounding floor), and that the test is sharp: the standard error is below `maxRelError`.
void expectWithinErrors(const MeanError& m, glm::dvec3 expected, double maxRelError,
                        const std::string& what) {
  if (std::getenv("KILN_TEST_VERBOSE"))
    std::printf("%s: mean %.6g expected %.6g rel.err %.2e (%.2f stderr, stderr/exp %.2e)\n",
                what.c_str(), m.mean.x, expected.x, (m.mean.x - expected.x) / expected.x,
                (m.mean.x - expected.x) / std::max(m.stdError.x, 1e-30), m.stdError.x / expected.x);
  for (int c = 0; c < 3; ++c) {
    double tol = 5.0 * m.stdError[c] + 1e-5 * std::abs(expected[c]);
    EXPECT_NEAR(m.mean[c], expected[c], tol)
        << what << " channel " << c << " (stderr " << m.stdError[c] << ")";
    EXPECT_LE(m.stdError[c], maxRelError * std::abs(expected[c]) + 1e-9) << what;
  }
}

void expectRelNear(vec3 value, glm::dvec3 expected, double rel, const std::string& what) {
  for (int c = 0; c < 3; ++c)
    EXPECT_NEAR(value[c], expected[c], rel * std::abs(expected[c]) + 1e-7)
        << what << " channel " << c;
}

IntegratorSettings bounces(int n) {
  IntegratorSettings s;
  s.maxBounces = n;
  return s;
}

// ---------------------------------------------------------------------------------------
// Punctual lights: exact (no noise: hard shadows are one deterministic ray).

TEST(IntegratorTest, DirectionalLightFollowsLambertsCosineLaw) {
  for (float albedo : {0.0f, 0.7f}) {
    World w;
    uint32_t m = addMaterial(w.scene, lambert(vec3(albedo)));
    addFloor(w.scene, 1000.0f, m);  // large: nothing but the floor
    w.scene.lights.push_back(test::directionalLight(vec3(0, -1, 0), 1.0f));
    w.build();
    for (float degrees : {0.0f, 30.0f, 60.0f, 85.0f}) {
      const float theta = glm::radians(degrees);
      w.scene.lights[0] =
          test::directionalLight(vec3(std::sin(theta), -std::cos(theta), 0.3f * std::sin(theta)),
                                 7.5f, vec3(1.0f, 0.5f, 0.25f));
      const vec3 toLight = -w.scene.lights[0].direction;
      const double cosTheta = toLight.y;
      for (int maxBounces : {0, 8}) {
        Integrator integrator(w.scene, *w.tracer, bounces(maxBounces));
        for (vec3 p : {vec3(0.0f), vec3(3.5f, 0.0f, -12.25f)}) {
          LightingEstimate e = integrator.irradiance(p, vec3(0, 1, 0), 17, 0, 8);
          expectRelNear(e.direct, 7.5 * cosTheta * glm::dvec3(1.0, 0.5, 0.25), 1e-4,
                        "directional " + std::to_string(degrees));
          // A lone floor (black sky): nothing ever bounces back.
          EXPECT_EQ(e.indirect, vec3(0.0f));
        }
      }
    }
  }
}

TEST(IntegratorTest, PointLightFollowsInverseSquareLaw) {
  World w;
  uint32_t m = addMaterial(w.scene, lambert(vec3(0.0f)));
  addFloor(w.scene, 100.0f, m);
  const vec3 lightPos(0.5f, 2.0f, -0.25f);
  w.scene.lights.push_back(test::pointLight(lightPos, 50.0f, vec3(1.0f, 0.8f, 0.6f)));
  w.build();
  Integrator integrator(w.scene, *w.tracer, bounces(2));
  for (vec3 p : {vec3(0.5f, 0.0f, -0.25f), vec3(1.5f, 0.0f, -0.25f), vec3(-2.0f, 0.0f, 1.5f),
                 vec3(6.0f, 0.0f, 3.0f)}) {
    glm::dvec3 d = glm::dvec3(lightPos) - glm::dvec3(p);
    double r2 = glm::dot(d, d);
    double cosTheta = d.y / std::sqrt(r2);
    LightingEstimate e = integrator.irradiance(p, vec3(0, 1, 0), 3, 0, 4);
    expectRelNear(e.direct, 50.0 * cosTheta / r2 * glm::dvec3(1.0, 0.8, 0.6), 1e-4, "point");
    EXPECT_EQ(e.indirect, vec3(0.0f));
  }
}

TEST(IntegratorTest, SpotLightConeFalloffAndRangeWindow) {
  World w;
  uint32_t m = addMaterial(w.scene, lambert(vec3(0.0f)));
  addFloor(w.scene, 100.0f, m);
  Light spot = test::pointLight(vec3(0, 3, 0), 40.0f);
  spot.type = LightType::Spot;
  spot.direction = vec3(0, -1, 0);
  spot.innerConeAngle = 0.3f;
  spot.outerConeAngle = 0.6f;
  spot.range = 4.0f;
  w.scene.lights.push_back(spot);
  w.build();
  Integrator integrator(w.scene, *w.tracer, bounces(0));
  const double cosInner = std::cos(0.3), cosOuter = std::cos(0.6);
  int inside = 0, partial = 0, outside = 0;
  for (float x : {0.0f, 0.5f, 0.85f, 1.2f, 1.5f, 1.8f, 2.5f, 5.0f}) {
    const vec3 p(x, 0.0f, 0.0f);
    const double d2 = 9.0 + double(x) * x, d = std::sqrt(d2);
    const double cosAngle = 3.0 / d;  // angle from the spot axis = angle from the normal
    double t = std::clamp((cosAngle - cosOuter) / (cosInner - cosOuter), 0.0, 1.0);
    double window = std::pow(std::clamp(1.0 - std::pow(d / 4.0, 4.0), 0.0, 1.0), 2.0);
    double expected = 40.0 * cosAngle / d2 * t * t * window;
    (t >= 1.0 ? inside : t > 0.0 ? partial : outside)++;
    LightingEstimate e = integrator.irradiance(p, vec3(0, 1, 0), 5, 0, 2);
    expectRelNear(e.direct, glm::dvec3(expected), 1e-4, "spot x=" + std::to_string(x));
  }
  // The points cover the inner cone, the falloff band and the outside.
  EXPECT_GE(inside, 2);
  EXPECT_GE(partial, 2);
  EXPECT_GE(outside, 2);
}

// ---------------------------------------------------------------------------------------
// Sky and emitters (Monte Carlo, MIS).

TEST(IntegratorTest, ConstantSkyOverPlaneGivesPiL) {
  const vec3 sky(0.5f, 1.0f, 2.0f);
  World w;
  uint32_t m = addMaterial(w.scene, lambert(vec3(0.5f)));
  addFloor(w.scene, 10.0f, m);
  w.scene.sky = Sky::constant(sky);
  w.build();
  for (int maxBounces : {0, 5}) {
    Integrator integrator(w.scene, *w.tracer, bounces(maxBounces));
    MeanError direct = sampleMean(8192, [&](uint32_t i) {
      LightingEstimate e = integrator.irradiance(vec3(1, 0, 2), vec3(0, 1, 0), 11, i, 1);
      EXPECT_EQ(e.indirect, vec3(0.0f));  // the plane never sees itself
      return e.direct;
    });
    expectWithinErrors(direct, kPiD * glm::dvec3(sky), 0.004, "sky");
    // The whole batch in one call is the same mean.
    LightingEstimate all = integrator.irradiance(vec3(1, 0, 2), vec3(0, 1, 0), 11, 0, 8192);
    expectRelNear(all.direct, direct.mean, 1e-4, "batched sky");
  }
}

TEST(IntegratorTest, MapSkyOverPlaneGivesPiLOfUpperHemisphere) {
  // An equirectangular map: radiance (1, 2, 3) above the horizon and a few rows below it
  // (so bilinear filtering never mixes the ground into the upper hemisphere), a brighter
  // (10, 5, 1) ground further down; a bright patch up high for the importance sampler.
  const vec3 skyColor(1.0f, 2.0f, 3.0f), ground(10.0f, 5.0f, 1.0f);
  Image map(64, 32, 3);
  for (int y = 0; y < 32; ++y)
    for (int x = 0; x < 64; ++x) {
      vec3 c = y < 19 ? skyColor : ground;
      float* px = map.at(x, y);
      px[0] = c.r, px[1] = c.g, px[2] = c.b;
    }
  World w;
  uint32_t m = addMaterial(w.scene, lambert(vec3(0.5f)));
  addFloor(w.scene, 10.0f, m);
  w.scene.sky = Sky::fromImage(map, 0.5f);
  w.build();
  Integrator integrator(w.scene, *w.tracer, bounces(2));
  MeanError direct = sampleMean(8192, [&](uint32_t i) {
    return integrator.irradiance(vec3(0.0f), vec3(0, 1, 0), 13, i, 1).direct;
  });
  expectWithinErrors(direct, kPiD * 0.5 * glm::dvec3(skyColor), 0.005, "map sky");
}

// A closed box of inward faces, each of albedo a and emission Le: the radiance everywhere
// is the geometric series Le (1 + a + a^2 + ...), so irradiance = pi Le (1 - a^(k+1)) / (1 - a)
// with k bounces ("white furnace").
double furnace(double le, double a, int k) {
  return kPiD * le * (1.0 - std::pow(a, k + 1)) / (1.0 - a);
}

World furnaceWorld(float albedo, float emission) {
  World w;
  uint32_t m = addMaterial(w.scene, lambert(vec3(albedo), vec3(emission)));
  addBox(w.scene, "box", vec3(-1.0f), vec3(1.0f), m, /*inward=*/true);
  return w;
}

TEST(IntegratorTest, WhiteFurnaceUnlimitedBounces) {
  for (float albedo : {0.5f, 0.8f}) {
    World w = furnaceWorld(albedo, 1.5f);
    w.build();
    IntegratorSettings s = bounces(64);
    Integrator integrator(w.scene, *w.tracer, s);
    struct Point {
      vec3 p, n;
    };
    for (Point pt :
         {Point{vec3(0, -1, 0), vec3(0, 1, 0)}, Point{vec3(1, 0.3f, -0.6f), vec3(-1, 0, 0)},
          Point{vec3(0.9f, 0.95f, 1.0f), vec3(0, 0, -1)}}) {
      // The series' variance grows with a: a = 0.8 needs 4x the samples of a = 0.5.
      MeanError m = sampleMean(albedo > 0.6f ? 65536 : 16384, [&](uint32_t i) {
        return integrator.irradiance(pt.p, pt.n, 23, i, 1).total();
      });
      expectWithinErrors(m, glm::dvec3(furnace(1.5, albedo, 64)), 0.005,
                         "furnace a=" + std::to_string(albedo));
    }
  }
}

TEST(IntegratorTest, WhiteFurnacePartialSums) {
  World w = furnaceWorld(0.5f, 1.0f);
  w.build();
  for (int k : {0, 1, 2, 3}) {
    Integrator integrator(w.scene, *w.tracer, bounces(k));
    MeanError total = sampleMean(16384, [&](uint32_t i) {
      return integrator.irradiance(vec3(0.2f, 1.0f, 0.1f), vec3(0, -1, 0), 29, i, 1).total();
    });
    expectWithinErrors(total, glm::dvec3(furnace(1.0, 0.5, k)), 0.004,
                       "furnace k=" + std::to_string(k));
    // Direct is the emission seen straight away: pi Le.
    MeanError direct = sampleMean(8192, [&](uint32_t i) {
      return integrator.irradiance(vec3(0.2f, 1.0f, 0.1f), vec3(0, -1, 0), 29, i, 1).direct;
    });
    expectWithinErrors(direct, glm::dvec3(kPiD), 0.004, "furnace direct");
  }
}

TEST(IntegratorTest, AlbedoBoostRaisesAlbedo) {
  // pow(0.25, 1/2) = 0.5.
  World w = furnaceWorld(0.25f, 1.0f);
  w.build();
  IntegratorSettings s = bounces(64);
  s.albedoBoost = 2.0f;
  Integrator integrator(w.scene, *w.tracer, s);
  MeanError m = sampleMean(16384, [&](uint32_t i) {
    return integrator.irradiance(vec3(0, -1, 0), vec3(0, 1, 0), 31, i, 1).total();
  });
  expectWithinErrors(m, glm::dvec3(furnace(1.0, 0.5, 64)), 0.004, "boosted furnace");
}

// Hottel's view factor between perpendicular rectangles sharing an edge of length l, with
// other sides w (receiver) and h (emitter) (Howell's catalogue, C-14), with W = w/l, H = h/l.
double perpendicularViewFactor(double W, double H) {
  double W2 = W * W, H2 = H * H, R2 = W2 + H2, R = std::sqrt(R2);
  double a = (1 + W2) * (1 + H2) / (1 + R2);
  double b = std::pow(W2 * (1 + R2) / ((1 + W2) * R2), W2);
  double c = std::pow(H2 * (1 + R2) / ((1 + H2) * R2), H2);
  return (W * std::atan(1 / W) + H * std::atan(1 / H) - R * std::atan(1 / R) +
          0.25 * std::log(a * b * c)) /
         (kPiD * W);
}

TEST(IntegratorTest, ViewFactorOfPerpendicularSquares) {
  const double F = perpendicularViewFactor(1.0, 1.0);
  ASSERT_NEAR(F, 0.200044, 1e-6);
  const float L = 2.0f;
  for (bool doubleSided : {false, true}) {
    World w;
    // Emitter: x, y in [0, 1] at z = 0 facing +Z, towards the receiver x, z in [0, 1], y = 0.
    uint32_t m = addMaterial(w.scene, lambert(vec3(0.0f), vec3(L), doubleSided));
    addQuad(w.scene, "emitter", vec3(0, 0, 0), vec3(1, 0, 0), vec3(1, 1, 0), vec3(0, 1, 0), m);
    w.build();
    Integrator integrator(w.scene, *w.tracer, bounces(0));
    // Receiver average: G x G strata, two independent uniform points in each, N samples per
    // point. The error of a stratified mean is estimated from the pairs' differences:
    // Var(mean) = sum_h (x_h1 - x_h2)^2 / (4 H^2).
    constexpr int G = 16, N = 32;
    double sum = 0.0, var = 0.0;
    uint64_t key = 0;
    for (int gy = 0; gy < G; ++gy)
      for (int gx = 0; gx < G; ++gx) {
        double e[2];
        for (int j = 0; j < 2; ++j) {
          uint64_t h = mixBits(hashValues(uint64_t(gy * G + gx), j, 99));
          float ux = float(h >> 40) * 0x1p-24f, uz = float((h >> 16) & 0xffffff) * 0x1p-24f;
          vec3 p((gx + ux) / G, 0.0f, (gy + uz) / G);
          e[j] = integrator.irradiance(p, vec3(0, 1, 0), key++, 0, N).direct.x;
        }
        sum += e[0] + e[1];
        var += (e[0] - e[1]) * (e[0] - e[1]) / 4.0;
      }
    const double H = double(G) * G;
    const double mean = sum / (2.0 * H), stdError = std::sqrt(var) / H;
    const double expected = kPiD * L * F;
    if (std::getenv("KILN_TEST_VERBOSE"))
      std::printf("view factor: mean %.6g expected %.6g rel.err %.2e (%.2f stderr)\n", mean,
                  expected, (mean - expected) / expected, (mean - expected) / stdError);
    EXPECT_NEAR(mean, expected, 5.0 * stdError + 1e-5 * expected) << "stderr " << stdError;
    EXPECT_LT(stdError, 0.005 * expected);
  }
  // Seen from behind, a single-sided emitter gives nothing.
  World w;
  uint32_t m = addMaterial(w.scene, lambert(vec3(0.0f), vec3(L)));
  addQuad(w.scene, "emitter", vec3(0, 1, 0), vec3(1, 1, 0), vec3(1, 0, 0), vec3(0, 0, 0), m);
  w.build();
  Integrator integrator(w.scene, *w.tracer, bounces(3));
  EXPECT_EQ(integrator.irradiance(vec3(0.5f, 0, 0.5f), vec3(0, 1, 0), 1, 0, 256).total(),
            vec3(0.0f));
}

// RMS error over many keys of estimates with N, 4N and 16N samples.
template <typename F>
void expectErrorHalves(int keys, double expected, F estimate, const std::string& what) {
  double rms[3];
  const uint32_t counts[3] = {4, 16, 64};
  for (int c = 0; c < 3; ++c) {
    double sum2 = 0.0;
    for (int key = 0; key < keys; ++key) {
      double e = estimate(uint64_t(1000 + key), counts[c]);
      sum2 += (e - expected) * (e - expected);
    }
    rms[c] = std::sqrt(sum2 / keys);
  }
  if (std::getenv("KILN_TEST_VERBOSE"))
    std::printf("%s convergence: rms %.4g %.4g %.4g ratios %.3f %.3f\n", what.c_str(), rms[0],
                rms[1], rms[2], rms[1] / rms[0], rms[2] / rms[1]);
  // Monte Carlo halves the error per 4x samples (a ratio of 0.5; scrambled Sobol points do
  // better on smooth integrands). The RMS over K keys is itself known to about
  // 1/sqrt(2K) (1.6% for K = 2048), so 0.55 leaves room for that noise only.
  EXPECT_LE(rms[1] / rms[0], 0.55) << what;
  EXPECT_LE(rms[2] / rms[1], 0.55) << what;
}

TEST(IntegratorTest, ErrorHalvesWhenSamplesQuadruple) {
  {
    World w = furnaceWorld(0.5f, 1.0f);
    w.build();
    Integrator integrator(w.scene, *w.tracer, bounces(64));
    expectErrorHalves(
        2048, furnace(1.0, 0.5, 64),
        [&](uint64_t key, uint32_t n) {
          return integrator.irradiance(vec3(0.3f, -1, 0.2f), vec3(0, 1, 0), key, 0, n).total().x;
        },
        "furnace");
  }
  {
    // The view-factor setup at one receiver point (emitter NEE + cosine sampling, MIS),
    // against a reference from 2^20 samples (error ~1e-4, far below the RMS measured here).
    World w;
    uint32_t m = addMaterial(w.scene, lambert(vec3(0.0f), vec3(1.0f)));
    addQuad(w.scene, "emitter", vec3(0, 0, 0), vec3(1, 0, 0), vec3(1, 1, 0), vec3(0, 1, 0), m);
    w.build();
    Integrator integrator(w.scene, *w.tracer, bounces(0));
    const vec3 p(0.5f, 0.0f, 0.5f);
    const double reference = integrator.irradiance(p, vec3(0, 1, 0), 1, 0, 1 << 20).direct.x;
    expectErrorHalves(
        2048, reference,
        [&](uint64_t key, uint32_t n) {
          return integrator.irradiance(p, vec3(0, 1, 0), key, 0, n).direct.x;
        },
        "view factor");
  }
}

// ---------------------------------------------------------------------------------------
// Shadows.

// Visibility = E / unoccluded E on the floor at (x, 0, 0) under a light, with an opaque
// occluder over x < 0 at height 1.
struct ShadowScene {
  World w;
  explicit ShadowScene(const Light& light) {
    uint32_t black = addMaterial(w.scene, lambert(vec3(0.0f)));
    addFloor(w.scene, 20.0f, black);
    addHorizontal(w.scene, -20.0f, 0.0f, -20.0f, 20.0f, 1.0f, black, "occluder");
    w.scene.lights.push_back(light);
    w.build();
  }
  double visibility(float x, uint32_t samples) const {
    Integrator integrator(w.scene, *w.tracer, bounces(0));
    const vec3 p(x, 0.0f, 0.0f);
    const Light& l = w.scene.lights[0];
    double unoccluded = l.irradianceAt(p).x * l.directionTo(p).y;
    return integrator.irradiance(p, vec3(0, 1, 0), 77, 0, samples).direct.x / unoccluded;
  }
};

TEST(IntegratorTest, SoftShadowsFromPointLightRadius) {
  Light light = test::pointLight(vec3(0, 2, 0), 10.0f);
  {
    ShadowScene hard(light);
    EXPECT_EQ(hard.visibility(-0.2f, 4), 0.0);
    EXPECT_NEAR(hard.visibility(0.2f, 4), 1.0, 1e-5);
  }
  light.shadowRadius = 0.5f;
  light.shadowSamples = 16;
  ShadowScene soft(light);
  // At x = 0 the occluder's edge halves the (horizontal) disk exactly. 64 x 16 rays: a
  // binomial standard error of at most 0.5 / 32.
  const double v0 = soft.visibility(0.0f, 64);
  EXPECT_NEAR(v0, 0.5, 5.0 * 0.5 / 32.0);
  const double vMinus = soft.visibility(-0.2f, 64), vPlus = soft.visibility(0.2f, 64);
  EXPECT_GT(vMinus, 0.05);
  EXPECT_LT(vMinus, v0);
  EXPECT_GT(vPlus, v0);
  EXPECT_LT(vPlus, 0.95);
  // Outside the penumbra (half-width 0.5 on the floor) it is hard again.
  EXPECT_EQ(soft.visibility(-0.6f, 16), 0.0);
  EXPECT_NEAR(soft.visibility(0.6f, 16), 1.0, 1e-5);
}

TEST(IntegratorTest, SoftShadowsFromDirectionalLightAngle) {
  Light light = test::directionalLight(vec3(0, -1, 0), 3.0f);
  {
    ShadowScene hard(light);
    EXPECT_EQ(hard.visibility(-0.03f, 4), 0.0);
    EXPECT_NEAR(hard.visibility(0.03f, 4), 1.0, 1e-5);
  }
  light.shadowAngle = 10.0f;  // penumbra half-width tan(5 deg) = 0.087 at height 1
  light.shadowSamples = 16;
  ShadowScene soft(light);
  EXPECT_NEAR(soft.visibility(0.0f, 64), 0.5, 5.0 * 0.5 / 32.0);
  const double vMinus = soft.visibility(-0.03f, 64), vPlus = soft.visibility(0.03f, 64);
  EXPECT_GT(vMinus, 0.0);
  EXPECT_LT(vMinus, 0.5);
  EXPECT_GT(vPlus, 0.5);
  EXPECT_LT(vPlus, 1.0);
  EXPECT_EQ(soft.visibility(-0.1f, 16), 0.0);
  EXPECT_NEAR(soft.visibility(0.1f, 16), 1.0, 1e-5);
}

TEST(IntegratorTest, BlendOccluderTransmitsOneMinusAlphaTimesBaseColor) {
  for (vec3 base : {vec3(1.0f), vec3(1.0f, 0.5f, 0.25f)}) {
    World w;
    uint32_t black = addMaterial(w.scene, lambert(vec3(0.0f)));
    Material glass = lambert(base);
    glass.alphaMode = AlphaMode::Blend;
    glass.baseColorFactor.a = 0.3f;
    uint32_t g = addMaterial(w.scene, glass);
    addFloor(w.scene, 20.0f, black);
    addFloor(w.scene, 5.0f, g, 1.0f, "glass");
    w.scene.lights.push_back(test::pointLight(vec3(0, 2, 0), 8.0f));
    w.scene.sky = Sky::constant(vec3(1.0f));
    w.build();
    ASSERT_TRUE(w.tracer->hasTranslucentSurfaces());
    IntegratorSettings s = bounces(0);
    s.includeSky = false;
    Integrator integrator(w.scene, *w.tracer, s);
    LightingEstimate e = integrator.irradiance(vec3(0.5f, 0, 0), vec3(0, 1, 0), 1, 0, 4);
    const double unoccluded = 8.0 * 2.0 / std::pow(4.25, 1.5);
    expectRelNear(e.direct, 0.7 * unoccluded * glm::dvec3(base), 1e-4, "blend shadow");

    // A path through the glass towards the sky passes with probability 0.7, tinted.
    Integrator withSky(w.scene, *w.tracer, bounces(0));
    MeanError m = sampleMean(2048, [&](uint32_t i) {
      return withSky.incomingRadiance(vec3(0, 0.5f, 0), vec3(0, 1, 0), 3, i).direct;
    });
    expectWithinErrors(m, 0.7 * glm::dvec3(base), 0.02, "blend path");
  }
}

TEST(IntegratorTest, FullyTransparentMaskLetsAllLightThrough) {
  World w;
  uint32_t black = addMaterial(w.scene, lambert(vec3(0.0f)));
  Texture clear;
  clear.name = "clear";
  clear.image = Image(2, 2, 4);
  for (size_t i = 0; i < clear.image.pixels.size(); i += 4)
    clear.image.pixels[i] = clear.image.pixels[i + 1] = clear.image.pixels[i + 2] = 1.0f;
  clear.average = vec4(1, 1, 1, 0);
  w.scene.textures.push_back(clear);
  Material leaves = lambert(vec3(1.0f));
  leaves.alphaMode = AlphaMode::Mask;
  leaves.baseColorTexture = 0;
  uint32_t cut = addMaterial(w.scene, leaves);
  addFloor(w.scene, 20.0f, black);
  addFloor(w.scene, 5.0f, cut, 1.0f, "leaves");
  w.scene.lights.push_back(test::pointLight(vec3(0, 2, 0), 8.0f));
  w.build();
  Integrator integrator(w.scene, *w.tracer, bounces(3));
  LightingEstimate e = integrator.irradiance(vec3(0.0f), vec3(0, 1, 0), 1, 0, 16);
  expectRelNear(e.direct, glm::dvec3(2.0), 1e-4, "mask");
  EXPECT_EQ(e.indirect, vec3(0.0f));  // the cut-out reflects nothing either
}

// ---------------------------------------------------------------------------------------
// Direct / indirect splitting and per-light controls.

struct SplitScene {
  World w;
  SplitScene() {
    uint32_t grey = addMaterial(w.scene, lambert(vec3(0.5f)));
    addFloor(w.scene, 10.0f, grey);
    // A wall at x = 2 facing -X, lit by both lights, bouncing light onto the floor.
    addQuad(w.scene, "wall", vec3(2, 0, -5), vec3(2, 0, 5), vec3(2, 5, 5), vec3(2, 5, -5), grey);
    w.scene.lights.push_back(test::pointLight(vec3(0, 2, 0), 10.0f));
    Light mixed = test::pointLight(vec3(1, 1, 1), 20.0f);
    mixed.mode = LightMode::Mixed;
    w.scene.lights.push_back(mixed);
    w.build();
  }
  LightingEstimate estimate(const IntegratorSettings& s) const {
    Integrator integrator(w.scene, *w.tracer, s);
    return integrator.irradiance(vec3(0.0f), vec3(0, 1, 0), 7, 0, 64);
  }
};

TEST(IntegratorTest, SplittingRespectsLightSelection) {
  SplitScene sc;
  const double directA = 10.0 / 4.0, directB = 20.0 / (3.0 * std::sqrt(3.0));
  LightingEstimate all = sc.estimate(bounces(3));
  expectRelNear(all.direct, glm::dvec3(directA + directB), 1e-4, "both direct");
  EXPECT_GT(all.indirect.x, 0.0f);

  IntegratorSettings noB = bounces(3);
  noB.directLights = {true, false};
  LightingEstimate e = sc.estimate(noB);
  expectRelNear(e.direct, glm::dvec3(directA), 1e-4, "mixed light excluded from direct");
  EXPECT_EQ(e.indirect, all.indirect);  // its bounced light stays, sample for sample

  // A realtime light is excluded by default.
  SplitScene rt;
  rt.w.scene.lights[1].mode = LightMode::Realtime;
  LightingEstimate r = rt.estimate(bounces(3));
  expectRelNear(r.direct, glm::dvec3(directA), 1e-4, "realtime excluded");

  // bounceIntensity 0 removes exactly what excluding the light from indirectLights does.
  IntegratorSettings indirectA = bounces(3);
  indirectA.indirectLights = {true, false};
  LightingEstimate onlyA = sc.estimate(indirectA);
  sc.w.scene.lights[1].bounceIntensity = 0.0f;
  LightingEstimate zeroB = sc.estimate(bounces(3));
  expectRelNear(zeroB.indirect, glm::dvec3(onlyA.indirect), 1e-6, "bounceIntensity 0");
  expectRelNear(zeroB.direct, glm::dvec3(all.direct), 1e-6, "direct untouched");
  EXPECT_LT(zeroB.indirect.x, 0.9f * all.indirect.x);
  // Scaling every light's bounce intensity scales indirect light exactly (no sky, no
  // emitters here), and direct not at all.
  sc.w.scene.lights[0].bounceIntensity = 2.0f;
  sc.w.scene.lights[1].bounceIntensity = 2.0f;
  LightingEstimate twice = sc.estimate(bounces(3));
  expectRelNear(twice.indirect, 2.0 * glm::dvec3(all.indirect), 1e-6, "bounceIntensity 2");
  expectRelNear(twice.direct, glm::dvec3(all.direct), 1e-6, "direct untouched");
}

TEST(IntegratorTest, IndirectIntensityScalesIndirectExactly) {
  SplitScene sc;
  sc.w.scene.sky = Sky::constant(vec3(0.3f));  // sky and punctual light both bounce
  LightingEstimate base = sc.estimate(bounces(4));
  IntegratorSettings s = bounces(4);
  s.indirectIntensity = 0.37f;
  LightingEstimate scaled = sc.estimate(s);
  expectRelNear(scaled.direct, glm::dvec3(base.direct), 1e-6, "direct");
  expectRelNear(scaled.indirect, 0.37 * glm::dvec3(base.indirect), 1e-6, "indirect");
  EXPECT_GT(base.indirect.x, 0.0f);
}

TEST(IntegratorTest, SkyAndEmissiveSwitches) {
  World w;
  uint32_t grey = addMaterial(w.scene, lambert(vec3(0.5f)));
  uint32_t glow = addMaterial(w.scene, lambert(vec3(0.0f), vec3(3.0f)));
  addFloor(w.scene, 10.0f, grey);
  addQuad(w.scene, "lamp", vec3(-1, 2, -1), vec3(1, 2, -1), vec3(1, 2, 1), vec3(-1, 2, 1),
          glow);  // faces down
  w.scene.sky = Sky::constant(vec3(1.0f));
  w.build();
  auto run = [&](bool sky, bool emissive) {
    IntegratorSettings s = bounces(2);
    s.includeSky = sky;
    s.includeEmissive = emissive;
    Integrator integrator(w.scene, *w.tracer, s);
    return integrator.irradiance(vec3(3, 0, 0), vec3(0, 1, 0), 9, 0, 256).total();
  };
  EXPECT_EQ(run(false, false), vec3(0.0f));
  vec3 skyOnly = run(true, false), lampOnly = run(false, true), both = run(true, true);
  EXPECT_GT(skyOnly.x, 0.0f);
  EXPECT_GT(lampOnly.x, 0.0f);
  // Same estimators combined: the sum within the noise of 256 samples (a few percent).
  EXPECT_NEAR(both.x, skyOnly.x + lampOnly.x, 0.05 * both.x);
}

// ---------------------------------------------------------------------------------------
// incomingRadiance and punctualLights.

TEST(IntegratorTest, IncomingRadianceFromSkyAndEmitter) {
  World w;
  uint32_t grey = addMaterial(w.scene, lambert(vec3(0.5f)));
  uint32_t glow = addMaterial(w.scene, lambert(vec3(0.2f), vec3(1, 2, 3)));
  addFloor(w.scene, 10.0f, grey);
  addQuad(w.scene, "panel", vec3(5, 0, -1), vec3(5, 0, 1), vec3(5, 2, 1), vec3(5, 2, -1),
          glow);  // faces -X
  w.scene.sky = Sky::constant(vec3(0.2f, 0.4f, 0.6f));
  w.build();
  Integrator integrator(w.scene, *w.tracer, bounces(0));
  LightingEstimate up = integrator.incomingRadiance(vec3(0, 1, 0), vec3(0.1f, 1, 0), 1, 0);
  EXPECT_EQ(up.direct, vec3(0.2f, 0.4f, 0.6f));
  EXPECT_EQ(up.indirect, vec3(0.0f));
  LightingEstimate panel = integrator.incomingRadiance(vec3(0, 1, 0), vec3(1, 0, 0), 1, 0);
  EXPECT_EQ(panel.direct, vec3(1, 2, 3));  // seen from the probe: counted fully
  EXPECT_EQ(panel.indirect, vec3(0.0f));   // no bounces allowed
  LightingEstimate back = integrator.incomingRadiance(vec3(6, 1, 0), vec3(-1, 0, 0), 1, 0);
  EXPECT_EQ(back.total(), vec3(0.0f));  // the single-sided panel's back
}

TEST(IntegratorTest, IncomingRadianceFromLitLambertWall) {
  World w;
  uint32_t wallMat = addMaterial(w.scene, lambert(vec3(0.6f, 0.4f, 0.2f)));
  addQuad(w.scene, "wall", vec3(-10, -10, -1), vec3(10, -10, -1), vec3(10, 10, -1),
          vec3(-10, 10, -1), wallMat);  // faces +Z
  w.scene.lights.push_back(test::directionalLight(vec3(0, 0, -1), 3.0f));
  w.build();
  for (int k : {0, 1, 4}) {
    Integrator integrator(w.scene, *w.tracer, bounces(k));
    for (vec3 dir : {vec3(0, 0, -1), vec3(0.3f, 0.2f, -1.0f)}) {
      LightingEstimate e = integrator.incomingRadiance(vec3(0.0f), dir, 5, 0);
      EXPECT_EQ(e.direct, vec3(0.0f));
      glm::dvec3 expected = k == 0 ? glm::dvec3(0.0) : 3.0 / kPiD * glm::dvec3(0.6, 0.4, 0.2);
      expectRelNear(e.indirect, expected, 1e-4, "wall k=" + std::to_string(k));
    }
  }
}

TEST(IntegratorTest, PunctualLightsReportVisibleIrradiance) {
  Light a = test::pointLight(vec3(0, 2, 0), 10.0f);
  ShadowScene sc(a);
  sc.w.scene.lights.push_back(test::directionalLight(vec3(0, -1, 0), 2.0f));
  Light rt = test::pointLight(vec3(0, 3, 0), 1.0f);
  rt.mode = LightMode::Realtime;
  sc.w.scene.lights.push_back(rt);
  Integrator integrator(sc.w.scene, *sc.w.tracer);
  std::vector<DeltaLight> lit, shadowed;
  integrator.punctualLights(vec3(0.5f, 0.5f, 0), 1, 0, lit);
  integrator.punctualLights(vec3(-0.5f, 0.5f, 0), 1, 0, shadowed);
  ASSERT_EQ(lit.size(), 2u);  // the realtime light is not selected
  EXPECT_EQ(lit[0].light, 0u);
  expectRelNear(lit[0].irradiance, glm::dvec3(10.0 / 2.5), 1e-4, "point");
  expectRelNear(lit[0].direction, glm::dvec3(-0.5, 1.5, 0) / std::sqrt(2.5), 1e-5, "dir");
  expectRelNear(lit[1].irradiance, glm::dvec3(2.0), 1e-6, "sun");
  EXPECT_EQ(shadowed[0].irradiance, vec3(0.0f));
  EXPECT_EQ(shadowed[1].irradiance, vec3(0.0f));
  EXPECT_EQ(integrator.lightVisibility(vec3(-0.5f, 0, 0), vec3(0, 1, 0), 0, 1, 0), vec3(0.0f));
  EXPECT_EQ(integrator.lightVisibility(vec3(0.5f, 0, 0), vec3(0, 1, 0), 1, 1, 0), vec3(1.0f));
}

// ---------------------------------------------------------------------------------------
// Determinism.

TEST(IntegratorTest, BitIdenticalAcrossThreadCounts) {
  World w;
  uint32_t grey = addMaterial(w.scene, lambert(vec3(0.6f)));
  uint32_t glow = addMaterial(w.scene, lambert(vec3(0.1f), vec3(4.0f), true));
  Material glass = lambert(vec3(0.8f, 0.3f, 0.3f));
  glass.alphaMode = AlphaMode::Blend;
  glass.baseColorFactor.a = 0.5f;
  uint32_t g = addMaterial(w.scene, glass);
  addBox(w.scene, "room", vec3(-4, 0, -4), vec3(4, 3, 4), grey, true);
  addBox(w.scene, "block", vec3(-1, 0, -1), vec3(0, 1, 0), grey, false);
  addQuad(w.scene, "lamp", vec3(1, 2.5f, 1), vec3(2, 2.5f, 1), vec3(2, 2.5f, 2), vec3(1, 2.5f, 2),
          glow);
  addFloor(w.scene, 1.0f, g, 1.5f, "glass");
  Light soft = test::pointLight(vec3(-2, 2.5f, 2), 15.0f);
  soft.shadowRadius = 0.3f;
  soft.shadowSamples = 4;
  w.scene.lights.push_back(soft);
  w.scene.sky = Sky::constant(vec3(0.5f));
  w.build();
  Integrator integrator(w.scene, *w.tracer, bounces(6));
  constexpr size_t kCount = 200;
  auto run = [&](int threads) {
    std::vector<LightingEstimate> out(kCount);
    ParallelOptions options;
    options.threads = threads;
    options.grain = 3;
    parallelFor(
        kCount,
        [&](size_t begin, size_t end) {
          for (size_t i = begin; i < end; ++i) {
            vec3 p(-3.5f + 7.0f * float(i % 20) / 19.0f, 0.0f, -3.5f + 7.0f * float(i / 20) / 9.0f);
            out[i] = integrator.irradiance(p, vec3(0, 1, 0), i, 0, 16);
          }
        },
        options);
    return out;
  };
  std::vector<LightingEstimate> one = run(1), two = run(2);
  ASSERT_EQ(std::memcmp(one.data(), two.data(), kCount * sizeof(LightingEstimate)), 0);
  double total = 0.0;
  for (const auto& e : one) total += e.total().x;
  EXPECT_GT(total, 0.0);
}

}  // namespace
}  // namespace kiln
