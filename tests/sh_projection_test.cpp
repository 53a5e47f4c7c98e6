// sh_projection_test.cpp: SH projection, irradiance, L1, windowing / deringing and Unity
// packing, against identities and closed-form integrals (the deringing fit against the
// projection property and a 2D search), and against brute-force cosine
// integration for the shared HDR environment maps.
#include "src/sh_projection.h"

#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
#include <random>
#include <string>
#include <vector>

#include "src/image.h"
#include "kiln/sh.h"
#include "tests/test_util.h"

namespace kiln {
namespace {

ShL2Rgb randomSh(std::mt19937& rng, float dc = 1.0f) {
  std::uniform_real_distribution<float> u(-1.0f, 1.0f);
  ShL2Rgb sh;
  for (int i = 0; i < kShL2Count; ++i) sh.c[i] = vec3(u(rng), u(rng), u(rng));
  sh.c[0] += vec3(dc);
  return sh;
}

// Exact image from a function of direction sampled at pixel centres.
Image imageOf(int w, int h, const std::function<vec3(vec3)>& f) {
  Image img(w, h, 3);
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x) {
      vec3 v = f(equirectDirection((x + 0.5f) / w, (y + 0.5f) / h));
      float* p = img.at(x, y);
      p[0] = v.x, p[1] = v.y, p[2] = v.z;
    }
  return img;
}

float minComponent(vec3 v) { return std::min(v.x, std::min(v.y, v.z)); }

float denseMinIrradiance(const ShL2Rgb& sh, int n = 20000) {
  float m = kInfinity;
  for (vec3 d : fibonacciSphere(n)) m = std::min(m, minComponent(sh.irradiance(d)));
  return m;
}

TEST(ShProjection, EquirectMappingInvertsSkyConvention) {
  for (vec3 d : fibonacciSphere(300)) {
    // sky.h: u = 0.5 + atan2(x, -z) / (2 pi), v = acos(y) / pi.
    float u = 0.5f + std::atan2(d.x, -d.z) / (2.0f * kPi);
    float v = std::acos(std::clamp(d.y, -1.0f, 1.0f)) / kPi;
    vec3 back = equirectDirection(u, v);
    EXPECT_NEAR(back.x, d.x, 1e-5f);
    EXPECT_NEAR(back.y, d.y, 1e-5f);
    EXPECT_NEAR(back.z, d.z, 1e-5f);
  }
  // Centre looks down -Z, u = 0.75 down +X, row 0 up.
  vec3 c = equirectDirection(0.5f, 0.5f), px = equirectDirection(0.75f, 0.5f);
  EXPECT_NEAR(c.z, -1.0f, 1e-6f);
  EXPECT_NEAR(px.x, 1.0f, 1e-6f);
  EXPECT_NEAR(equirectDirection(0.3f, 0.0f).y, 1.0f, 1e-6f);
  double total = 0.0;
  for (int y = 0; y < 37; ++y) total += 53 * equirectPixelSolidAngle(y, 53, 37);
  EXPECT_NEAR(total, 4.0 * 3.14159265358979323846, 1e-12);
}

TEST(ShProjection, BasisIsOrthonormalByQuadrature) {
  // Project each basis function, sampled on a fine grid, back onto the basis.
  const int w = 512, h = 256;
  for (int j = 0; j < kShL2Count; ++j) {
    Image img = imageOf(w, h, [j](vec3 d) { return vec3(shBasisL2(d)[j]); });
    ShL2Rgb sh = projectEquirect(img);
    for (int i = 0; i < kShL2Count; ++i)
      EXPECT_NEAR(sh.c[i].x, i == j ? 1.0f : 0.0f, 1e-3f) << "i=" << i << " j=" << j;
  }
}

TEST(ShProjection, ConstantEnvironmentIsExact) {
  const vec3 L(0.5f, 1.0f, 2.0f);
  Image img(64, 32, 3);
  for (int y = 0; y < 32; ++y)
    for (int x = 0; x < 64; ++x) {
      float* p = img.at(x, y);
      p[0] = L.x, p[1] = L.y, p[2] = L.z;
    }
  ShL2Rgb sh = projectEquirect(img);
  // c0 = int L Y00 = 4 pi L 0.282095 = 2 sqrt(pi) L (0.282095 ~ 1 / (2 sqrt(pi))).
  const float c0 = 4.0f * kPi * 0.282095f;
  EXPECT_NEAR(c0, 2.0f * std::sqrt(kPi), 1e-5f);  // basis constants have 6 digits
  for (int ch = 0; ch < 3; ++ch) EXPECT_NEAR(sh.c[0][ch], c0 * L[ch], 1e-5f * L[ch]);
  for (int i = 1; i < kShL2Count; ++i)
    for (int ch = 0; ch < 3; ++ch) EXPECT_NEAR(sh.c[i][ch], 0.0f, 1e-6f) << "i=" << i;
  for (vec3 n : fibonacciSphere(200)) {
    vec3 e = sh.irradiance(n);
    for (int ch = 0; ch < 3; ++ch) EXPECT_NEAR(e[ch], kPi * L[ch], 1e-5f * kPi * L[ch]);
  }
  // Unity's constants evaluate to E / pi = L: all in SHA.w.
  UnitySh9 u = packUnitySh9(sh);
  EXPECT_NEAR(u.shAr.w, L.x, 1e-5f);
  EXPECT_NEAR(u.shAg.w, L.y, 1e-5f);
  EXPECT_NEAR(u.shAb.w, L.z, 1e-5f);
}

TEST(ShProjection, UpperHemisphereIrradianceIsExactInL2) {
  // L = 1 for y > 0. Exact E(n) = pi (1 + n_y) / 2. The hemisphere step has only band 0 and
  // odd bands, and A_l = 0 for odd l > 1, so L2 irradiance is exact: c0 = 2 pi Y00,
  // c(1,-1) = pi 0.488603, and E_L2 = pi/2 + (2 pi / 3) pi (3 / (4 pi)) n_y.
  Image img = imageOf(128, 64, [](vec3 d) { return vec3(d.y > 0.0f ? 1.0f : 0.0f); });
  ShL2Rgb sh = projectEquirect(img);
  EXPECT_NEAR(sh.c[0].x, 2.0f * kPi * 0.282095f, 1e-5f);
  EXPECT_NEAR(sh.c[1].x, kPi * 0.488603f, 1e-5f);
  for (int i = 2; i < kShL2Count; ++i) EXPECT_NEAR(sh.c[i].x, 0.0f, 1e-5f) << "i=" << i;
  for (vec3 n : fibonacciSphere(200))
    EXPECT_NEAR(sh.irradiance(n).x, kPi * 0.5f * (1.0f + n.y), 2e-5f);
}

TEST(ShProjection, DirectionalLightMatchesClosedForm) {
  // A directional light of irradiance E0 along s: radiance delta, c_i = E0 Y_i(s). Addition
  // theorem: sum_m Y_lm(s) Y_lm(n) = (2l + 1) / (4 pi) P_l(t), t = n.s, so
  // E_L2(n) = E0 (1/4 + t/2 + 5/32 (3 t^2 - 1)); exact E = E0 max(t, 0).
  const vec3 s = glm::normalize(vec3(0.3f, 0.8f, -0.5f));
  const float e0 = 2.0f;
  ShL2Rgb sh;
  sh.addSample(s, vec3(e0), 1.0f);
  float maxErr = 0.0f;
  for (vec3 n : fibonacciSphere(500)) {
    float t = glm::dot(n, s);
    float expected = e0 * (0.25f + 0.5f * t + 5.0f / 32.0f * (3.0f * t * t - 1.0f));
    EXPECT_NEAR(sh.irradiance(n).x, expected, 2e-5f);
    maxErr = std::max(maxErr, std::abs(sh.irradiance(n).x - e0 * std::max(t, 0.0f)));
  }
  // The L2 error of a clamped cosine: +1/16 E0 at t = 1 and t = -1, and its maximum 3/32 E0
  // at grazing incidence t = 0 (1/4 - 5/32); in between it dips to -1/60 E0 at t = 8/15.
  EXPECT_NEAR(sh.irradiance(s).x, e0 * 17.0f / 16.0f, 1e-5f);
  EXPECT_NEAR(sh.irradiance(-s).x, e0 / 16.0f, 1e-5f);
  EXPECT_LE(maxErr, e0 * 3.0f / 32.0f + 1e-5f);
  EXPECT_GE(maxErr, e0 * 3.0f / 32.0f - 1e-2f);
  // Its minimum: d/dt = 1/2 + 15/16 t = 0 at t = -8/15, value E0 (1/4 - 4/15 + 5/32 (64/75 - 1))
  // = -E0 19/480 = -0.0396 E0.
  std::array<vec3, 3> argmin;
  vec3 m = minIrradiance(sh, &argmin);
  EXPECT_NEAR(m.x, -e0 * 19.0f / 480.0f, 1e-6f);
  EXPECT_NEAR(glm::dot(argmin[0], s), -8.0f / 15.0f, 1e-4f);
}

TEST(ShProjection, ProjectFunctionBySphereSamples) {
  // A band-limited function with known coefficients comes back from 4096 stratified samples.
  std::mt19937 rng(7);
  ShL2Rgb truth = randomSh(rng, 3.0f);
  ShL2Rgb sh = projectFunction([&](vec3 d) { return truth.evaluate(d); }, 4096, 42);
  for (int i = 0; i < kShL2Count; ++i)
    for (int ch = 0; ch < 3; ++ch) EXPECT_NEAR(sh.c[i][ch], truth.c[i][ch], 2e-3f) << i;
  // A constant: c0 = 2 sqrt(pi), and the rest vanishes up to the sampling error.
  ShL2Rgb one = projectFunction([](vec3) { return vec3(1.0f); }, 1024, 3);
  EXPECT_NEAR(one.c[0].x, 2.0f * std::sqrt(kPi), 1e-5f);
}

TEST(ShProjection, AccumulatorMergeEqualsOneSum) {
  std::mt19937 rng(9);
  std::uniform_real_distribution<float> u(-1.0f, 1.0f);
  ShL2Accumulator all, a, b;
  ShL2Rgb direct;
  for (int k = 0; k < 100; ++k) {
    vec3 d = glm::normalize(vec3(u(rng), u(rng), u(rng)) + vec3(0.0f, 0.0f, 1e-3f));
    vec3 l(u(rng) + 1.0f, u(rng) + 1.0f, u(rng) + 1.0f);
    all.add(d, l, 0.01);
    (k % 2 ? a : b).add(d, l, 0.01);
    direct.addSample(d, l, 0.01f);
  }
  a.merge(b);
  ShL2Rgb x = all.result(), y = a.result();
  for (int i = 0; i < kShL2Count; ++i)
    for (int ch = 0; ch < 3; ++ch) {
      EXPECT_NEAR(x.c[i][ch], y.c[i][ch], 1e-6f);
      EXPECT_NEAR(x.c[i][ch], direct.c[i][ch], 1e-5f);
    }
}

TEST(ShProjection, IrradianceShAndL1) {
  std::mt19937 rng(1);
  for (int k = 0; k < 20; ++k) {
    ShL2Rgb sh = randomSh(rng);
    ShL2Rgb e = toIrradianceSh(sh);
    ShL1Rgb l1 = reduceToL1(sh);
    ShL2Rgb band01 = sh;
    for (int i = 4; i < kShL2Count; ++i) band01.c[i] = vec3(0.0f);
    for (int i = 0; i < kShL1Count; ++i) EXPECT_EQ(l1.c[i], sh.c[i]);
    for (vec3 n : fibonacciSphere(100)) {
      vec3 a = e.evaluate(n), b = sh.irradiance(n);
      vec3 la = l1.irradiance(n), lb = band01.irradiance(n);
      vec3 ra = l1.evaluate(n), rb = band01.evaluate(n);
      for (int ch = 0; ch < 3; ++ch) {
        EXPECT_NEAR(a[ch], b[ch], 1e-5f);
        EXPECT_NEAR(la[ch], lb[ch], 1e-5f);
        EXPECT_NEAR(ra[ch], rb[ch], 1e-5f);
      }
    }
  }
}

TEST(ShProjection, UnityPackingEvaluatesToIrradianceOverPi) {
  std::mt19937 rng(2);
  for (int k = 0; k < 20; ++k) {
    ShL2Rgb sh = randomSh(rng);
    UnitySh9 gltf = packUnitySh9(sh, ShAxes::kGltf);
    UnitySh9 unity = packUnitySh9(sh, ShAxes::kUnity);
    EXPECT_EQ(gltf.shC.w, 1.0f);
    for (vec3 n : fibonacciSphere(200)) {
      vec3 expected = sh.irradiance(n) * kInvPi;
      vec3 a = evalUnitySh9(gltf, n);
      vec3 b = evalUnitySh9(unity, vec3(-n.x, n.y, n.z));  // same normal in Unity axes
      for (int ch = 0; ch < 3; ++ch) {
        EXPECT_NEAR(a[ch], expected[ch], 2e-6f);
        EXPECT_NEAR(b[ch], expected[ch], 2e-6f);
      }
    }
  }
}

TEST(ShProjection, WindowFactors) {
  // Hanning width 3: (1 + cos(pi/3)) / 2 = 3/4, (1 + cos(2 pi/3)) / 2 = 1/4.
  auto h = shWindowFactors(ShWindowKind::kHanning, 3.0f);
  EXPECT_FLOAT_EQ(h[0], 1.0f);
  EXPECT_NEAR(h[1], 0.75f, 1e-6f);
  EXPECT_NEAR(h[2], 0.25f, 1e-6f);
  // Lanczos width 3: sinc(pi/3) = (sqrt(3)/2) / (pi/3); sinc^4 is its 4th power.
  const float s1 = (std::sqrt(3.0f) / 2.0f) / (kPi / 3.0f);
  auto l = shWindowFactors(ShWindowKind::kLanczos, 3.0f);
  auto s4 = shWindowFactors(ShWindowKind::kSinc4, 3.0f);
  EXPECT_NEAR(l[1], s1, 1e-6f);
  EXPECT_NEAR(s4[1], s1 * s1 * s1 * s1, 1e-6f);
  // Width <= 2 removes band 2; width <= 1 keeps band 0 only; huge widths change nothing.
  EXPECT_EQ(shWindowFactors(ShWindowKind::kSinc4, 2.0f)[2], 0.0f);
  EXPECT_EQ(shWindowFactors(ShWindowKind::kLanczos, 1.0f)[1], 0.0f);
  for (auto kind : {ShWindowKind::kSinc4, ShWindowKind::kLanczos, ShWindowKind::kHanning}) {
    auto f = shWindowFactors(kind, 1e5f);
    EXPECT_NEAR(f[1], 1.0f, 1e-6f);
    EXPECT_NEAR(f[2], 1.0f, 1e-6f);
  }
  std::mt19937 rng(3);
  ShL2Rgb sh = randomSh(rng);
  ShL2Rgb w = windowSh(sh, {1.0f, 0.5f, 0.25f});
  for (int i = 0; i < kShL2Count; ++i)
    EXPECT_EQ(w.c[i], sh.c[i] * (i == 0 ? 1.0f : i < 4 ? 0.5f : 0.25f));
}

TEST(ShProjection, MinIrradianceMatchesDenseSampling) {
  std::mt19937 rng(4);
  std::vector<ShL2Rgb> cases;
  for (int k = 0; k < 40; ++k) cases.push_back(randomSh(rng, k % 2 ? 2.0f : 0.0f));
  // Hard cases: no linear term (only bands 0 and 2), and a zonal band 2.
  ShL2Rgb zonal;
  zonal.c[0] = vec3(1.0f), zonal.c[6] = vec3(0.7f, -0.7f, 0.0f);
  cases.push_back(zonal);
  ShL2Rgb even = randomSh(rng);
  for (int i = 1; i < 4; ++i) even.c[i] = vec3(0.0f);
  cases.push_back(even);
  for (const ShL2Rgb& sh : cases) {
    std::array<vec3, 3> argmin;
    vec3 m = minIrradiance(sh, &argmin);
    vec3 dense(kInfinity);
    for (vec3 d : fibonacciSphere(40000)) dense = glm::min(dense, sh.irradiance(d));
    for (int ch = 0; ch < 3; ++ch) {
      // Attained at argmin, never above the dense minimum, and not far below it (the dense
      // set's spacing is ~0.018 rad; the values are O(1..10)).
      EXPECT_NEAR(sh.irradiance(argmin[ch])[ch], m[ch], 1e-5f);
      EXPECT_LE(m[ch], dense[ch] + 1e-5f);
      EXPECT_GE(m[ch], dense[ch] - 5e-3f);
    }
  }
}

TEST(ShProjection, DeringingFindsTheWeakestNonNegativeWindow) {
  // A bright small spot (directional light) over a dim ambient: L2 irradiance rings negative
  // on the far side (E0 (1/4 + t/2 + 5/32 (3t^2-1)) bottoms out at -19/480 E0).
  const vec3 s = glm::normalize(vec3(-0.2f, 0.9f, 0.4f));
  ShL2Rgb sh;
  sh.addSample(s, vec3(10.0f, 6.0f, 3.0f), 1.0f);
  sh.c[0] += vec3(0.02f) * (2.0f * std::sqrt(kPi));  // ambient radiance 0.02
  ASSERT_LT(minComponent(minIrradiance(sh)), 0.0f);
  ASSERT_LT(denseMinIrradiance(sh), 0.0f);
  for (auto kind : {ShWindowKind::kSinc4, ShWindowKind::kLanczos, ShWindowKind::kHanning}) {
    WindowDeringResult r = windowDeringSh(sh, kind, 1e-4f);
    ASSERT_TRUE(r.ok);
    EXPECT_TRUE(r.changed);
    EXPECT_GT(r.width, 1.0f);
    EXPECT_LT(r.width, 100.0f);
    EXPECT_GE(minComponent(r.minIrradianceAfter), 0.0f);
    EXPECT_GE(denseMinIrradiance(r.sh), -1e-6f);
    // Mean radiance (band 0) is kept.
    EXPECT_EQ(r.sh.c[0], sh.c[0]);
    // A slightly weaker window (0.03% wider) is negative again: r is the weakest within tol.
    ShL2Rgb weaker = windowSh(sh, kind, r.width * 1.0003f);
    EXPECT_LT(minComponent(minIrradiance(weaker)), 0.0f);
    // The minimum after windowing sits at 0 (within the search tolerance), not far above.
    EXPECT_LT(minComponent(r.minIrradianceAfter), 1e-3f);
    std::printf("dering %d: width %.4f factors (%.4f, %.4f), min %.3g -> %.3g\n", int(kind),
                r.width, r.factors[1], r.factors[2], minComponent(r.minIrradianceBefore),
                minComponent(r.minIrradianceAfter));
  }
  // Already non-negative: returned bit-for-bit unchanged.
  ShL2Rgb fine;
  fine.c[0] = vec3(1.0f);
  fine.c[1] = vec3(0.3f);
  WindowDeringResult r = windowDeringSh(fine);
  EXPECT_FALSE(r.changed);
  for (int i = 0; i < kShL2Count; ++i) EXPECT_EQ(r.sh.c[i], fine.c[i]);
}

// The squared L2 distance over the sphere between the irradiances of two radiance SH, per
// channel: sum_i (A_l (a_i - b_i))^2 (orthonormal basis), the norm deringSh minimises.
vec3 irradianceDistance2(const ShL2Rgb& a, const ShL2Rgb& b) {
  vec3 d(0.0f);
  for (int i = 0; i < kShL2Count; ++i) {
    const vec3 e = (a.c[i] - b.c[i]) * kShCosineLobe[shBand(i)];
    d += e * e;
  }
  return d;
}

// Per channel, <x - raw, y - x> in the irradiance inner product (as above).
vec3 irradianceDot(const ShL2Rgb& raw, const ShL2Rgb& x, const ShL2Rgb& y) {
  glm::dvec3 d(0.0);
  for (int i = 0; i < kShL2Count; ++i) {
    const double a2 = double(kShCosineLobe[shBand(i)]) * kShCosineLobe[shBand(i)];
    d += glm::dvec3(x.c[i] - raw.c[i]) * glm::dvec3(y.c[i] - x.c[i]) * a2;
  }
  return vec3(d);
}

// A bright small spot (a directional light) over a dim ambient: the truncated cosine lobe
// rings negative on the far side (E0 (1/4 + t/2 + 5/32 (3t^2-1)) bottoms out at -19/480 E0).
ShL2Rgb spotOverAmbient(vec3 s, vec3 spot, float ambient) {
  ShL2Rgb sh;
  sh.addSample(s, spot, 1.0f);
  sh.c[0] += vec3(ambient) * (2.0f * std::sqrt(kPi));
  return sh;
}

// deringSh is the projection of the raw irradiance onto the convex set of non-negative L2
// irradiances with the same c0. A point x of a convex set C is the projection of raw onto C
// exactly when <x - raw, y - x> >= 0 for every y in C (the variational inequality of
// projections). Every window of the raw SH with w0 = 1 that is >= 0 is such a y, and so is
// the fit of any other SH with the same c0 moved toward it; the test checks them all, and
// that the result is >= 0 over the sphere, keeps c0 bit-for-bit and sits at the boundary.
TEST(ShProjection, DeringFitIsTheNearestNonNegativeIrradiance) {
  std::vector<ShL2Rgb> cases = {
      spotOverAmbient(glm::normalize(vec3(-0.2f, 0.9f, 0.4f)), vec3(10.0f, 6.0f, 3.0f), 0.02f),
      spotOverAmbient(vec3(1.0f, 0.0f, 0.0f), vec3(1.0f), 0.0f),  // zonal, touches on a circle
  };
  std::mt19937 rng(7);
  while (cases.size() < 200) {
    ShL2Rgb sh = randomSh(rng, 1.0f);
    if (minComponent(minIrradiance(sh)) < 0.0f) cases.push_back(sh);
  }
  int fallbacks = 0;
  for (size_t k = 0; k < cases.size(); ++k) {
    const ShL2Rgb& raw = cases[k];
    ASSERT_LT(minComponent(minIrradiance(raw)), 0.0f) << k;
    const DeringResult r = deringSh(raw);
    ASSERT_TRUE(r.ok) << k;
    EXPECT_TRUE(r.changed) << k;
    fallbacks += r.fallback;
    EXPECT_EQ(r.sh.c[0], raw.c[0]) << k;
    const vec3 minAfter = minIrradiance(r.sh);
    EXPECT_EQ(minAfter, r.minIrradianceAfter) << k;
    EXPECT_GE(denseMinIrradiance(r.sh, 4000), 0.0f) << k;
    // At the boundary: the minimum of every channel that was negative is 0 up to the margin
    // (1e-4 of the mean irradiance, pi Y00 c0), not above it; channels that were >= 0 are
    // untouched.
    for (int c = 0; c < 3; ++c) {
      EXPECT_GE(minAfter[c], 0.0f) << k;
      const float mean = kPi * 0.282095f * raw.c[0][c];
      if (r.minIrradianceBefore[c] < 0.0f) {
        EXPECT_LT(minAfter[c], 2e-4f * mean) << k << " channel " << c;
      } else {
        for (int i = 0; i < kShL2Count; ++i) EXPECT_EQ(r.sh.c[i][c], raw.c[i][c]) << k;
      }
    }
    // The variational inequality against feasible windows of the raw SH (all w0 = 1) and the
    // window the old deringing picked: none is closer, and <x - raw, y - x> >= 0 for each.
    // Tolerance: float coefficients (~1e-6 relative) on O(1) values, and the margin.
    const float tol = 1e-4f * (1.0f + glm::dot(raw.c[0], raw.c[0]));
    std::vector<ShL2Rgb> feasible = {windowDeringSh(raw).sh};
    for (float w1 : {0.0f, 0.25f, 0.5f, 0.75f, 1.0f})
      for (float w2 : {0.0f, 0.25f, 0.5f, 0.75f, 1.0f}) {
        ShL2Rgb y = windowSh(raw, {1.0f, w1, w2});
        if (minComponent(minIrradiance(y)) >= 0.0f) feasible.push_back(y);
      }
    const vec3 dFit = irradianceDistance2(r.sh, raw);
    for (const ShL2Rgb& y : feasible) {
      const vec3 dot = irradianceDot(raw, r.sh, y);
      const vec3 dY = irradianceDistance2(y, raw);
      for (int c = 0; c < 3; ++c) {
        EXPECT_GE(dot[c], -tol) << k << " channel " << c;
        EXPECT_LE(dFit[c], dY[c] + tol) << k << " channel " << c;
      }
    }
  }
  // The cutting planes converge by themselves (the scaling fallback is a guarantee only).
  EXPECT_EQ(fallbacks, 0);
}

// The zonal case, against a 2D search: a directional light of irradiance 1 along s gives
// E(t) = 1/4 + t/2 + 5/32 (3t^2 - 1), t = n.s. The problem is symmetric about s and its
// solution unique, so the fit is zonal too: E(t) = 1/4 + p1 t + p2 (3t^2 - 1) (c0 kept).
// 1, t and 3t^2 - 1 are orthogonal over the sphere with squared norms 4pi, 4pi/3 and
// 16pi/5, so the fit minimises 4pi/3 (p1 - 1/2)^2 + 16pi/5 (p2 - 5/32)^2 subject to
// E(t) >= 0 on [-1, 1]: a grid over (p1, p2) brackets the optimum.
TEST(ShProjection, DeringFitOfADirectionalLightMatchesA2dSearch) {
  constexpr double kPiD = 3.14159265358979323846;
  const vec3 s = glm::normalize(vec3(0.3f, -0.5f, 0.8f));
  const ShL2Rgb raw = spotOverAmbient(s, vec3(1.0f), 0.0f);
  const DeringResult r = deringSh(raw);
  // (p0, p1, p2) of a zonal SH from E at t = -1, 0, 1: E(+-1) = p0 +- p1 + 2 p2, E(0) =
  // p0 - p2.
  const vec3 u = glm::normalize(glm::cross(s, vec3(0, 0, 1)));
  auto zonal = [&](const ShL2Rgb& sh) {
    const double em = sh.irradiance(-s).x, e0 = sh.irradiance(u).x, ep = sh.irradiance(s).x;
    const double p2 = (0.5 * (ep + em) - e0) / 3.0;
    return glm::dvec3(e0 + p2, 0.5 * (ep - em), p2);
  };
  const glm::dvec3 pr = zonal(raw), pf = zonal(r.sh);
  EXPECT_NEAR(pr.x, 0.25, 1e-5);
  EXPECT_NEAR(pr.y, 0.5, 1e-5);
  EXPECT_NEAR(pr.z, 5.0 / 32.0, 1e-5);
  EXPECT_EQ(r.sh.c[0], raw.c[0]);  // c0 kept
  // The fit is zonal, up to the cutting planes' tolerance (the margin, 1e-4 of the mean).
  for (vec3 n : fibonacciSphere(200)) {
    const float t = glm::dot(n, s);
    const double p = pf.x + pf.y * t + pf.z * (3.0 * t * t - 1.0);
    EXPECT_NEAR(r.sh.irradiance(n).x, p, 2e-4) << t;
  }
  auto feasible = [](double p1, double p2) {  // min of 1/4 - p2 + p1 t + 3 p2 t^2 on [-1, 1]
    auto q = [&](double t) { return 0.25 + p1 * t + p2 * (3.0 * t * t - 1.0); };
    double m = std::min(q(-1.0), q(1.0));
    if (p2 > 0.0 && std::abs(p1 / (6.0 * p2)) < 1.0) m = std::min(m, q(-p1 / (6.0 * p2)));
    return m >= 0.0;
  };
  auto dist = [&](double p1, double p2) {
    return 4.0 * kPiD / 3.0 * (p1 - 0.5) * (p1 - 0.5) +
           16.0 * kPiD / 5.0 * (p2 - 5.0 / 32.0) * (p2 - 5.0 / 32.0);
  };
  double best = 1e9, b1 = 0, b2 = 0;
  for (int i = 0; i <= 1000; ++i)
    for (int j = 0; j <= 1000; ++j) {
      const double p1 = 0.5 * i / 1000.0, p2 = 5.0 / 32.0 * j / 1000.0;
      if (dist(p1, p2) < best && feasible(p1, p2)) best = dist(p1, p2), b1 = p1, b2 = p2;
    }
  EXPECT_LE(dist(pf.y, pf.z), best * (1.0 + 1e-3));
  EXPECT_NEAR(pf.y, b1, 2e-3);
  EXPECT_NEAR(pf.z, b2, 2e-3);
  // The window deringing, for comparison, moves further: both bands scaled.
  const glm::dvec3 pw = zonal(windowDeringSh(raw).sh);
  EXPECT_GT(dist(pw.y, pw.z), 10.0 * dist(pf.y, pf.z));
  std::printf(
      "directional light: raw E(t) = 0.25 + 0.5 t + 0.15625 (3t^2-1); fit %.5f t + "
      "%.5f (3t^2-1) (grid %.4f, %.4f); window %.5f t + %.5f (3t^2-1); distance fit "
      "%.4g window %.4g\n",
      pf.y, pf.z, b1, b2, pw.y, pw.z, dist(pf.y, pf.z), dist(pw.y, pw.z));
}

// Only the channels and SH that need it change; the result is a pure function of the input.
TEST(ShProjection, DeringFitLeavesNonNegativeInputAlone) {
  ShL2Rgb fine;
  fine.c[0] = vec3(1.0f);
  fine.c[1] = vec3(0.3f);
  const DeringResult r = deringSh(fine);
  EXPECT_FALSE(r.changed);
  for (int i = 0; i < kShL2Count; ++i) EXPECT_EQ(r.sh.c[i], fine.c[i]);
  // Negative mean radiance: no SH with that c0 is >= 0; band 0 alone is returned, not ok.
  ShL2Rgb negative = fine;
  negative.c[0] = vec3(-1.0f, 1.0f, 1.0f);
  const DeringResult n = deringSh(negative);
  EXPECT_FALSE(n.ok);
  EXPECT_EQ(n.sh.c[0], negative.c[0]);
  for (int i = 1; i < kShL2Count; ++i) EXPECT_EQ(n.sh.c[i].x, 0.0f);
  // Repeatable bit for bit.
  const ShL2Rgb spot = spotOverAmbient(glm::normalize(vec3(1, 2, 3)), vec3(4, 2, 1), 0.01f);
  const DeringResult a = deringSh(spot), b = deringSh(spot);
  for (int i = 0; i < kShL2Count; ++i) EXPECT_EQ(a.sh.c[i], b.sh.c[i]);
}

// Brute-force irradiance of an equirectangular map: sum over pixels of L max(0, n.d) dOmega.
struct PixelSample {
  vec3 d, l;  // direction, radiance x solid angle
};

void checkEnvMap(const std::string& name) {
  if (!test::sharedAvailable()) GTEST_SKIP() << "../shared/scenes not available";
  std::string path = test::sharedDir() + "/scenes/envmaps/" + name + ".hdr";
  Result<Image> img = readHdrImage(path);
  ASSERT_TRUE(img.ok()) << img.error();
  const Image& map = *img;
  ShL2Rgb sh = projectEquirect(map);

  std::vector<PixelSample> px;
  px.reserve(size_t(map.width) * map.height);
  for (int y = 0; y < map.height; ++y) {
    double dOmega = equirectPixelSolidAngle(y, map.width, map.height);
    for (int x = 0; x < map.width; ++x)
      px.push_back({equirectDirection((x + 0.5f) / map.width, (y + 0.5f) / map.height),
                    map.rgb(x, y) * float(dOmega)});
  }
  // Per normal and channel: relative error |E_L2 - E| / E, and the error relative to the
  // channel's largest irradiance over all normals (Ramamoorthi & Hanrahan's figures, ~1%
  // average and < 5% maximum, are of this kind: pointwise relative errors blow up on the dark
  // side of a peaky map, where E is an order of magnitude below its maximum).
  const std::vector<vec3> normals = fibonacciSphere(200);
  std::vector<glm::dvec3> exact, approx;
  glm::dvec3 eMax(0.0);
  for (vec3 n : normals) {
    glm::dvec3 e(0.0);
    for (const PixelSample& p : px) {
      float c = glm::dot(n, p.d);
      if (c > 0.0f) e += glm::dvec3(p.l) * double(c);
    }
    exact.push_back(e);
    approx.push_back(glm::dvec3(sh.irradiance(n)));
    eMax = glm::max(eMax, e);
  }
  double sumRel = 0.0, maxRel = 0.0, sumNorm = 0.0, maxNorm = 0.0;
  int count = 0;
  for (size_t k = 0; k < normals.size(); ++k)
    for (int ch = 0; ch < 3; ++ch) {
      double err = std::abs(approx[k][ch] - exact[k][ch]);
      sumRel += err / exact[k][ch];
      maxRel = std::max(maxRel, err / exact[k][ch]);
      sumNorm += err / eMax[ch];
      maxNorm = std::max(maxNorm, err / eMax[ch]);
      ++count;
    }
  const double avgRel = sumRel / count, avgNorm = sumNorm / count;
  std::printf("%s (%dx%d): L2 irradiance vs brute force, 200 normals x RGB: relative to E avg "
              "%.2f%% max %.2f%%; relative to max E avg %.2f%% max %.2f%%\n",
              name.c_str(), map.width, map.height, 100.0 * avgRel, 100.0 * maxRel,
              100.0 * avgNorm, 100.0 * maxNorm);
  ::testing::Test::RecordProperty(name + "_avg_rel_error", std::to_string(avgRel));
  ::testing::Test::RecordProperty(name + "_max_rel_error", std::to_string(maxRel));
  ::testing::Test::RecordProperty(name + "_avg_error_over_max", std::to_string(avgNorm));
  ::testing::Test::RecordProperty(name + "_max_error_over_max", std::to_string(maxNorm));
  // Measured (256x128 maps): over max E avg 0.9-1.8%, max 2.8-5.8%; relative avg 3-10%.
  EXPECT_LT(avgNorm, 0.025);
  EXPECT_LT(maxNorm, 0.07);
  EXPECT_LT(avgRel, 0.12);

  // Deringing: never negative over a dense sampling; untouched when it already was not.
  DeringResult r = deringSh(sh);
  EXPECT_GE(denseMinIrradiance(r.sh), 0.0f);
  if (!r.changed) {
    EXPECT_GE(minComponent(r.minIrradianceBefore), 0.0f);
    for (int i = 0; i < kShL2Count; ++i) EXPECT_EQ(r.sh.c[i], sh.c[i]);
  }
  std::printf("%s: min irradiance %.4g, deringed %d\n", name.c_str(),
              minComponent(r.minIrradianceBefore), int(r.changed));
}

TEST(ShProjection, EnvMapUffizi) { checkEnvMap("uffizi"); }
TEST(ShProjection, EnvMapGrace) { checkEnvMap("grace"); }
TEST(ShProjection, EnvMapPisa) { checkEnvMap("pisa"); }

}  // namespace
}  // namespace kiln
