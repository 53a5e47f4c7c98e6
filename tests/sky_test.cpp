// sky_test.cpp: the sky's map convention, rotation, and importance sampling (unbiased
// estimates of the sphere integral, pdf consistency).
#include "src/sky.h"

#include <gtest/gtest.h>

#include <filesystem>

#include "src/sampling.h"
#include "tests/test_util.h"

namespace kiln {
namespace {

constexpr double kTwoPiSq = 2.0 * 3.14159265358979323846 * 3.14159265358979323846;

// Direction at map coordinates (u, v) per sky.h.
vec3 uvDir(double u, double v) {
  double theta = 3.14159265358979323846 * v, phi = 2 * 3.14159265358979323846 * (u - 0.5);
  return vec3(float(std::sin(theta) * std::sin(phi)), float(std::cos(theta)),
              float(-std::sin(theta) * std::cos(phi)));
}

// Integral of f(direction) over the sphere by a dense midpoint rule in (u, v).
template <typename F>
glm::dvec3 sphereIntegral(F f, int nu = 1024, int nv = 512) {
  glm::dvec3 sum(0.0);
  for (int j = 0; j < nv; ++j) {
    double v = (j + 0.5) / nv;
    double weight = kTwoPiSq * std::sin(3.14159265358979323846 * v) / (double(nu) * nv);
    for (int i = 0; i < nu; ++i) sum += glm::dvec3(f(uvDir((i + 0.5) / nu, v))) * weight;
  }
  return sum;
}

// Sum over pixels of radiance x the pixel's solid angle.
glm::dvec3 pixelSum(const Image& map, float intensity = 1.0f) {
  glm::dvec3 sum(0.0);
  for (int y = 0; y < map.height; ++y) {
    double t0 = 3.14159265358979323846 * y / map.height;
    double t1 = 3.14159265358979323846 * (y + 1) / map.height;
    double solidAngle = 2 * 3.14159265358979323846 / map.width * (std::cos(t0) - std::cos(t1));
    for (int x = 0; x < map.width; ++x) sum += glm::dvec3(map.rgb(x, y)) * solidAngle;
  }
  return sum * double(intensity);
}

glm::dvec3 importanceEstimate(const Sky& sky, uint32_t n, uint64_t seed = 1) {
  glm::dvec3 sum(0.0);
  for (uint32_t i = 0; i < n; ++i) {
    Sky::Sample s = sky.sample(sobol2D(i, seed));
    if (s.pdf > 0) sum += glm::dvec3(s.radiance) / double(s.pdf);
  }
  return sum / double(n);
}

// A dim blue-grey map with a bright, smooth-edged patch centred at (u0, v0).
Image patchMap(int w, int h, float u0, float v0) {
  Image map(w, h, 3);
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x) {
      float du = (x + 0.5f) / w - u0, dv = (y + 0.5f) / h - v0;
      float r2 = (du * du + dv * dv) / (0.05f * 0.05f);
      float bright = 50.0f * std::exp(-r2);
      float* p = map.at(x, y);
      p[0] = 0.05f + bright;
      p[1] = 0.1f + 0.8f * bright;
      p[2] = 0.2f + 0.5f * bright;
    }
  return map;
}

TEST(Sky, ConstantSky) {
  Sky black;
  EXPECT_TRUE(black.isBlack());
  Sky sky = Sky::constant(vec3(0.5f, 1.0f, 2.0f));
  EXPECT_FALSE(sky.isBlack());
  EXPECT_FALSE(sky.hasMap());
  for (vec3 d : {vec3(0, 1, 0), vec3(1, 0, 0), glm::normalize(vec3(1, -2, 3))}) {
    EXPECT_EQ(sky.radiance(d), vec3(0.5f, 1.0f, 2.0f));
    EXPECT_FLOAT_EQ(sky.pdf(d), 1.0f / (4.0f * kPi));
  }
  glm::dvec3 e = importanceEstimate(sky, 256);
  EXPECT_NEAR(e.x, 0.5 * 4 * kPi, 1e-4);
  EXPECT_NEAR(e.z, 2.0 * 4 * kPi, 1e-4);
  Sky::Sample s = sky.sample(vec2(0.3f, 0.6f));
  EXPECT_NEAR(glm::length(s.direction), 1.0f, 1e-6f);
  EXPECT_FLOAT_EQ(s.pdf, 1.0f / (4.0f * kPi));
}

TEST(Sky, MapConvention) {
  const int w = 64, h = 32;
  // Bright around u = 0.75 on the horizon: that is +X.
  Sky sky = Sky::fromImage(patchMap(w, h, 0.75f, 0.5f));
  float east = luminance(sky.radiance(vec3(1, 0, 0)));
  for (vec3 d : {vec3(-1, 0, 0), vec3(0, 0, 1), vec3(0, 0, -1), vec3(0, 1, 0), vec3(0, -1, 0)})
    EXPECT_GT(east, 10.0f * luminance(sky.radiance(d))) << d.x << " " << d.y << " " << d.z;

  // The image centre looks down -Z; row 0 is straight up.
  Image marks(w, h, 3);
  for (int x = 0; x < w; ++x) marks.at(x, 0)[1] = 1.0f;  // top row green
  marks.at(w / 2, h / 2)[0] = marks.at(w / 2 - 1, h / 2)[0] = 1.0f;
  marks.at(w / 2, h / 2 - 1)[0] = marks.at(w / 2 - 1, h / 2 - 1)[0] = 1.0f;
  Sky m = Sky::fromImage(marks);
  EXPECT_NEAR(m.radiance(vec3(0, 0, -1)).r, 1.0f, 1e-5f);
  EXPECT_NEAR(m.radiance(vec3(0, 0, 1)).r, 0.0f, 1e-5f);
  EXPECT_NEAR(m.radiance(vec3(0, 1, 0)).g, 1.0f, 1e-5f);
  EXPECT_NEAR(m.radiance(vec3(0, -1, 0)).g, 0.0f, 1e-5f);
}

TEST(Sky, RotationIsCounterClockwiseSeenFromAbove) {
  Image map = patchMap(64, 32, 0.75f, 0.5f);  // bright towards +X
  Sky sky = Sky::fromImage(map, 2.0f, 90.0f);
  EXPECT_FLOAT_EQ(sky.rotationDegrees(), 90.0f);
  // Seen from +Y looking down, counter-clockwise takes +X to -Z.
  vec3 brightest(0.0f);
  float best = -1.0f;
  for (vec3 d : {vec3(1, 0, 0), vec3(-1, 0, 0), vec3(0, 0, 1), vec3(0, 0, -1)}) {
    float l = luminance(sky.radiance(d));
    if (l > best) best = l, brightest = d;
  }
  EXPECT_EQ(brightest, vec3(0, 0, -1));
  // Intensity scales the radiance; rotating back recovers the unrotated map.
  Sky plain = Sky::fromImage(map);
  vec3 a = sky.radiance(vec3(0, 0, -1)), b = plain.radiance(vec3(1, 0, 0));
  EXPECT_NEAR(a.r, 2.0f * b.r, 1e-3f * b.r);
  // Samples of the rotated sky also concentrate around -Z.
  glm::dvec3 mean(0.0);
  for (uint32_t i = 0; i < 1024; ++i) mean += glm::dvec3(sky.sample(sobol2D(i, 3)).direction);
  mean /= 1024.0;
  EXPECT_LT(mean.z, -0.5);
  EXPECT_NEAR(mean.x, 0.0, 0.1);
}

TEST(Sky, PdfMatchesSamplesAndIntegratesToOne) {
  Sky sky = Sky::fromImage(patchMap(64, 32, 0.3f, 0.2f), 1.0f, 33.0f);
  for (uint32_t i = 0; i < 4096; ++i) {
    Sky::Sample s = sky.sample(sobol2D(i, 7));
    ASSERT_GT(s.pdf, 0.0f);
    EXPECT_NEAR(glm::length(s.direction), 1.0f, 1e-5f);
    EXPECT_NEAR(sky.pdf(s.direction), s.pdf, 2e-3f * s.pdf) << i;
    vec3 r = sky.radiance(s.direction);
    EXPECT_EQ(r, s.radiance);
  }
  glm::dvec3 total = sphereIntegral([&](vec3 d) { return vec3(sky.pdf(d)); });
  EXPECT_NEAR(total.x, 1.0, 2e-3);
}

TEST(Sky, ImportanceSamplingIsUnbiased) {
  Image map = patchMap(64, 32, 0.6f, 0.4f);
  Sky sky = Sky::fromImage(map, 1.5f, -20.0f);
  // Truth: the dense integral of the (bilinear) radiance; it also agrees with the sum over
  // pixels x solid angles up to the interpolation's smoothing.
  glm::dvec3 truth = sphereIntegral([&](vec3 d) { return sky.radiance(d); });
  glm::dvec3 pixels = pixelSum(map, 1.5f);
  for (int c = 0; c < 3; ++c) EXPECT_NEAR(truth[c], pixels[c], 0.01 * pixels[c]) << c;
  glm::dvec3 estimate = importanceEstimate(sky, 4096);
  for (int c = 0; c < 3; ++c) EXPECT_NEAR(estimate[c], truth[c], 0.005 * truth[c]) << c;

  // A map with isolated single bright pixels next to black ones: bilinear lookup spreads
  // each into its neighbours, which must still be sampled.
  Image sparse(32, 16, 3);
  sparse.at(5, 7)[0] = 100.0f;
  sparse.at(20, 3)[2] = 40.0f;
  Sky s2 = Sky::fromImage(sparse);
  glm::dvec3 t2 = sphereIntegral([&](vec3 d) { return s2.radiance(d); }, 2048, 1024);
  glm::dvec3 e2 = importanceEstimate(s2, 1 << 14);
  EXPECT_NEAR(e2.x, t2.x, 0.01 * t2.x);
  EXPECT_NEAR(e2.z, t2.z, 0.01 * t2.z);
  EXPECT_EQ(e2.y, 0.0);
}

TEST(Sky, BlackMapSamplesUniformly) {
  Sky sky = Sky::fromImage(Image(8, 4, 3));
  EXPECT_TRUE(sky.hasMap());
  Sky::Sample s = sky.sample(vec2(0.4f, 0.5f));
  EXPECT_EQ(s.radiance, vec3(0.0f));
  EXPECT_GT(s.pdf, 0.0f);
  EXPECT_NEAR(sky.pdf(s.direction), s.pdf, 1e-4f * s.pdf);
}

TEST(Sky, FromFile) {
  std::string dir = test::makeTempDir("kiln_sky");
  auto missing = Sky::fromFile(dir + "/no_such_sky.hdr");
  ASSERT_FALSE(missing.ok());
  EXPECT_NE(missing.error().find("no_such_sky.hdr"), std::string::npos) << missing.error();

  Image map = patchMap(32, 16, 0.75f, 0.5f);
  ASSERT_TRUE(writeExr(dir + "/sky.exr", map, true).ok());
  auto sky = Sky::fromFile(dir + "/sky.exr", 3.0f, 0.0f);
  ASSERT_TRUE(sky.ok()) << sky.error();
  EXPECT_TRUE(sky->hasMap());
  EXPECT_EQ(sky->path(), dir + "/sky.exr");
  EXPECT_FLOAT_EQ(sky->intensity(), 3.0f);
  Sky direct = Sky::fromImage(map);
  vec3 a = sky->radiance(vec3(1, 0, 0)), b = direct.radiance(vec3(1, 0, 0));
  EXPECT_NEAR(a.g, 3.0f * b.g, 1e-4f * a.g);
}

TEST(Sky, SharedUffiziIntegral) {
  if (!test::sharedAvailable()) GTEST_SKIP() << "../shared not present";
  std::string path = test::sharedDir() + "/scenes/envmaps/uffizi.hdr";
  if (!std::filesystem::exists(path)) GTEST_SKIP() << path << " not present";
  auto sky = Sky::fromFile(path);
  ASSERT_TRUE(sky.ok()) << sky.error();
  auto map = readHdrImage(path);
  ASSERT_TRUE(map.ok());
  glm::dvec3 pixels = pixelSum(*map);
  glm::dvec3 estimate = importanceEstimate(*sky, 4096);
  for (int c = 0; c < 3; ++c) EXPECT_NEAR(estimate[c], pixels[c], 0.01 * pixels[c]) << c;
}

}  // namespace
}  // namespace kiln
