// sampling_test.cpp: the scrambled Sobol sequence, warps, piecewise-constant distributions,
// and parallelFor / Progress.
#include "src/sampling.h"

#include <gtest/gtest.h>

#include <atomic>
#include <cmath>
#include <csignal>
#include <numeric>
#include <set>
#include <vector>

#include "src/parallel.h"
#include "src/progress.h"

namespace kiln {
namespace {

// Every elementary interval [i/2^a, (i+1)/2^a) x [j/2^b, (j+1)/2^b) with a + b = k holds
// exactly one of the 2^k points.
void expectZeroTwoNet(const std::vector<vec2>& points, int k) {
  size_t n = size_t(1) << k;
  ASSERT_EQ(points.size(), n);
  for (int a = 0; a <= k; ++a) {
    int b = k - a;
    std::vector<int> cells(n, 0);
    for (vec2 p : points) {
      // Values are multiples of 2^-24, so these products are exact.
      size_t i = size_t(p.x * float(1u << a)), j = size_t(p.y * float(1u << b));
      ASSERT_LT(i, size_t(1) << a);
      ASSERT_LT(j, size_t(1) << b);
      cells[(j << a) | i]++;
    }
    for (size_t c = 0; c < n; ++c)
      ASSERT_EQ(cells[c], 1) << "k=" << k << " shape 2^-" << a << " x 2^-" << b << " cell " << c;
  }
}

TEST(Sobol, PowerOfTwoPrefixesAreZeroTwoNets) {
  for (uint64_t seed :
       {uint64_t(0), uint64_t(1), uint64_t(42), uint64_t(0xdeadbeefcafe), hashValues(7, 9)}) {
    for (int k : {4, 6, 8}) {
      std::vector<vec2> points;
      for (uint32_t i = 0; i < (1u << k); ++i) points.push_back(sobol2D(i, seed));
      expectZeroTwoNet(points, k);
    }
  }
}

TEST(Sobol, ValuesInUnitSquareAndDeterministic) {
  for (uint32_t i = 0; i < 4096; ++i) {
    vec2 p = sobol2D(i, 1234);
    EXPECT_GE(p.x, 0.0f);
    EXPECT_LT(p.x, 1.0f);
    EXPECT_GE(p.y, 0.0f);
    EXPECT_LT(p.y, 1.0f);
    EXPECT_EQ(p, sobol2D(i, 1234));
  }
  // Large indices too (the whole 32-bit range is valid).
  vec2 p = sobol2D(0xffffffffu, 5);
  EXPECT_LT(p.x, 1.0f);
  EXPECT_LT(p.y, 1.0f);
}

TEST(SampleStream, KeysAndDimensionsGiveDifferentSequences) {
  std::set<std::pair<float, float>> seen;
  for (uint64_t key : {0ull, 1ull, 2ull}) {
    SampleStream s(key, 3);
    for (int d = 0; d < 8; ++d) {
      vec2 u = s.get2D();
      seen.insert({u.x, u.y});
    }
  }
  EXPECT_EQ(seen.size(), 24u);  // no collisions between keys or dimension pairs

  SampleStream a(77, 5), b(77, 5);
  EXPECT_EQ(a.get2D(), b.get2D());
  EXPECT_EQ(a.dimension(), 2u);
  float x = a.get1D();  // consumes one pair, its first component
  EXPECT_EQ(a.dimension(), 4u);
  EXPECT_EQ(x, b.get2D().x);
  a.setDimension(10);
  b.setDimension(10);
  EXPECT_EQ(a.get2D(), b.get2D());
}

TEST(SampleStream, EachDimensionPairIsStratifiedOverSampleIndices) {
  for (uint32_t dim : {0u, 2u, 6u, 20u}) {
    std::vector<vec2> points;
    for (uint32_t i = 0; i < 256; ++i) {
      SampleStream s(0xabcdef, i);
      s.setDimension(dim);
      points.push_back(s.get2D());
    }
    expectZeroTwoNet(points, 8);
  }
}

TEST(Sobol, QmcConvergesFasterThanMonteCarlo) {
  // f(x, y) = cos(x + 2y); its integral over [0,1]^2 is (cos 1 + cos 2 - cos 3 - 1) / 2.
  const double exact = (std::cos(1.0) + std::cos(2.0) - std::cos(3.0) - 1.0) / 2.0;
  auto rmsError = [&](uint32_t n) {
    double sumSq = 0.0;
    for (uint64_t key = 0; key < 64; ++key) {
      double sum = 0.0;
      for (uint32_t i = 0; i < n; ++i) {
        SampleStream s(key, i);
        vec2 u = s.get2D();
        sum += std::cos(double(u.x) + 2.0 * double(u.y));
      }
      double err = sum / n - exact;
      sumSq += err * err;
    }
    return std::sqrt(sumSq / 64.0);
  };
  double e64 = rmsError(64), e1024 = rmsError(1024);
  // Monte Carlo would improve by sqrt(16) = 4; scrambled Sobol does ~N^-1.5 for smooth f.
  EXPECT_GT(e64 / e1024, 8.0) << e64 << " " << e1024;
  EXPECT_LT(e1024, 1e-3);
}

TEST(Warps, CosineHemisphere) {
  const uint32_t n = 4096;
  double sumCos = 0.0;
  for (uint32_t i = 0; i < n; ++i) {
    vec3 d = squareToCosineHemisphere(sobol2D(i, 3));
    ASSERT_GE(d.z, 0.0f);
    ASSERT_NEAR(glm::length(d), 1.0f, 1e-5f);
    sumCos += d.z;
  }
  // E[cos] under pdf cos/pi = (1/pi) * integral of cos^2 over the hemisphere = 2/3.
  EXPECT_NEAR(sumCos / n, 2.0 / 3.0, 1e-3);
  EXPECT_FLOAT_EQ(cosineHemispherePdf(1.0f), kInvPi);
  EXPECT_EQ(cosineHemispherePdf(-0.5f), 0.0f);
}

TEST(Warps, UniformSphere) {
  const uint32_t n = 4096;
  double mx = 0, my = 0, mz = 0, z2 = 0;
  for (uint32_t i = 0; i < n; ++i) {
    vec3 d = squareToUniformSphere(sobol2D(i, 4));
    ASSERT_NEAR(glm::length(d), 1.0f, 1e-5f);
    mx += d.x;
    my += d.y;
    mz += d.z;
    z2 += double(d.z) * d.z;
  }
  EXPECT_NEAR(mx / n, 0.0, 2e-3);
  EXPECT_NEAR(my / n, 0.0, 2e-3);
  EXPECT_NEAR(mz / n, 0.0, 2e-3);
  EXPECT_NEAR(z2 / n, 1.0 / 3.0, 1e-3);
}

TEST(Warps, UniformCone) {
  const float cosMax = std::cos(0.3f);
  const uint32_t n = 4096;
  double sumZ = 0.0;
  for (uint32_t i = 0; i < n; ++i) {
    vec3 d = squareToUniformCone(sobol2D(i, 5), cosMax);
    ASSERT_NEAR(glm::length(d), 1.0f, 1e-5f);
    ASSERT_GE(d.z, cosMax - 1e-6f);
    sumZ += d.z;
  }
  // Uniform in solid angle: cos(theta) uniform on [cosMax, 1].
  EXPECT_NEAR(sumZ / n, (1.0 + cosMax) / 2.0, 1e-5);
}

TEST(Warps, ConcentricDiskAndTriangle) {
  const uint32_t n = 4096;
  double r2 = 0.0, b0 = 0.0, b1 = 0.0;
  for (uint32_t i = 0; i < n; ++i) {
    vec2 u = sobol2D(i, 6);
    vec2 p = squareToConcentricDisk(u);
    ASSERT_LE(glm::length(p), 1.0f + 1e-6f);
    r2 += glm::dot(p, p);
    vec2 b = squareToTriangle(u);
    ASSERT_GE(b.x, 0.0f);
    ASSERT_GE(b.y, 0.0f);
    ASSERT_LE(b.x + b.y, 1.0f + 1e-6f);
    b0 += b.x;
    b1 += b.y;
  }
  EXPECT_NEAR(r2 / n, 0.5, 1e-3);        // uniform disk: E[r^2] = 1/2
  EXPECT_NEAR(b0 / n, 1.0 / 3.0, 1e-3);  // uniform triangle: centroid
  EXPECT_NEAR(b1 / n, 1.0 / 3.0, 1e-3);
}

TEST(Warps, PowerHeuristic) {
  EXPECT_FLOAT_EQ(powerHeuristic(1.0f, 1.0f), 0.5f);
  EXPECT_FLOAT_EQ(powerHeuristic(3.0f, 1.0f), 0.9f);
  EXPECT_EQ(powerHeuristic(0.0f, 0.0f), 0.0f);
}

TEST(Distribution1D, PmfPdfAndHistogram) {
  Distribution1D d({1.0f, 0.0f, 3.0f, 2.0f, -5.0f, 2.0f});
  EXPECT_EQ(d.size(), 6u);
  EXPECT_FLOAT_EQ(d.total(), 8.0f);
  const float expected[6] = {1 / 8.0f, 0, 3 / 8.0f, 2 / 8.0f, 0, 2 / 8.0f};
  double pmfSum = 0.0;
  for (size_t i = 0; i < 6; ++i) {
    EXPECT_FLOAT_EQ(d.pmf(i), expected[i]);
    pmfSum += d.pmf(i);
  }
  EXPECT_NEAR(pmfSum, 1.0, 1e-6);

  const int n = 8192;
  std::vector<int> counts(6, 0);
  for (int i = 0; i < n; ++i) {
    float u = (float(i) + 0.5f) / float(n);
    float pmf, remapped;
    size_t bin = d.sampleDiscrete(u, &pmf, &remapped);
    EXPECT_FLOAT_EQ(pmf, d.pmf(bin));
    EXPECT_GE(remapped, 0.0f);
    EXPECT_LT(remapped, 1.0f);
    counts[bin]++;
    float pdf;
    size_t cbin;
    float x = d.sampleContinuous(u, &pdf, &cbin);
    EXPECT_EQ(cbin, bin);
    EXPECT_EQ(size_t(x * 6.0f), bin);
    EXPECT_FLOAT_EQ(pdf, d.pmf(bin) * 6.0f);
  }
  for (size_t i = 0; i < 6; ++i) {
    double expectedCount = n * double(expected[i]);
    // Stratified u: every bin gets its expected count to within one sample.
    EXPECT_NEAR(counts[i], expectedCount, 1.0) << i;
  }
}

TEST(Distribution1D, AllZeroIsUniformAndSamplesStayBelowOne) {
  Distribution1D d({0.0f, 0.0f, 0.0f, 0.0f});
  EXPECT_EQ(d.total(), 0.0f);
  for (size_t i = 0; i < 4; ++i) EXPECT_FLOAT_EQ(d.pmf(i), 0.25f);
  float pdf;
  size_t bin;
  float x = d.sampleContinuous(0.6f, &pdf, &bin);
  EXPECT_FLOAT_EQ(pdf, 1.0f);
  EXPECT_EQ(bin, 2u);
  EXPECT_NEAR(x, 0.6f, 1e-6f);

  Distribution1D big(std::vector<float>(100000, 1.0f));
  for (float u : {std::nextafter(1.0f, 0.0f), 1.0f, 0.99999f}) {
    float p;
    size_t b;
    float y = big.sampleContinuous(u, &p, &b);
    EXPECT_LT(y, 1.0f);
    EXPECT_EQ(size_t(y * 100000.0f), b);
  }
  // The last bin has zero weight: sampling near 1 still lands in a valid bin.
  Distribution1D tail({1.0f, 1.0f, 0.0f});
  EXPECT_EQ(tail.sampleDiscrete(std::nextafter(1.0f, 0.0f)), 1u);
}

TEST(Distribution2D, PdfIntegratesToOneAndMatchesSamples) {
  const int w = 16, h = 8;
  std::vector<float> weights(w * h);
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x)
      weights[y * w + x] = (x == 3 && y == 2) ? 50.0f : float((x * 7 + y * 3) % 5);
  Distribution2D d(weights, w, h);
  ASSERT_FALSE(d.empty());
  double integral = 0.0, total = 0.0;
  for (float v : weights) total += v;
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x) {
      float p = d.pdf(vec2((x + 0.5f) / w, (y + 0.5f) / h));
      EXPECT_NEAR(p, weights[y * w + x] / total * w * h, 1e-4);
      integral += p / (w * h);
    }
  EXPECT_NEAR(integral, 1.0, 1e-5);

  const uint32_t n = 1 << 14;
  std::vector<int> counts(w * h, 0);
  for (uint32_t i = 0; i < n; ++i) {
    float pdf;
    vec2 uv = d.sample(sobol2D(i, 11), &pdf);
    ASSERT_GE(uv.x, 0.0f);
    ASSERT_LT(uv.x, 1.0f);
    ASSERT_GE(uv.y, 0.0f);
    ASSERT_LT(uv.y, 1.0f);
    ASSERT_GT(pdf, 0.0f);
    ASSERT_FLOAT_EQ(pdf, d.pdf(uv));
    counts[int(uv.y * h) * w + int(uv.x * w)]++;
  }
  double chi2 = 0.0;
  int dof = 0;
  for (int c = 0; c < w * h; ++c) {
    double expected = n * weights[c] / total;
    if (expected == 0.0) {
      EXPECT_EQ(counts[c], 0);
      continue;
    }
    chi2 += (counts[c] - expected) * (counts[c] - expected) / expected;
    ++dof;
  }
  // Random sampling would give chi2 ~ dof; stratified samples do far better.
  EXPECT_LT(chi2, double(dof));
}

TEST(Distribution2D, AllZeroIsUniform) {
  Distribution2D d(std::vector<float>(12, 0.0f), 4, 3);
  float pdf;
  vec2 uv = d.sample(vec2(0.3f, 0.7f), &pdf);
  EXPECT_FLOAT_EQ(pdf, 1.0f);
  EXPECT_FLOAT_EQ(d.pdf(uv), 1.0f);
  EXPECT_NEAR(uv.x, 0.3f, 1e-6f);
  EXPECT_NEAR(uv.y, 0.7f, 1e-6f);
}

// ---- parallelFor ----

TEST(ParallelFor, VisitsEveryIndexExactlyOnce) {
  for (size_t count : {size_t(0), size_t(1), size_t(7), size_t(1000), size_t(100003)}) {
    for (size_t grain : {size_t(1), size_t(16), size_t(1000)}) {
      for (int threads : {0, 1, 2}) {
        std::vector<std::atomic<int>> visits(count);
        Progress progress("test", count, "items", false);
        ParallelOptions options;
        options.threads = threads;
        options.grain = grain;
        options.progress = &progress;
        bool ok = parallelFor(
            count,
            [&](size_t begin, size_t end) {
              ASSERT_LE(begin, end);
              ASSERT_LE(end, count);
              for (size_t i = begin; i < end; ++i) visits[i].fetch_add(1);
            },
            options);
        EXPECT_TRUE(ok);
        EXPECT_EQ(progress.done(), count);
        for (size_t i = 0; i < count; ++i)
          ASSERT_EQ(visits[i].load(), 1) << count << " " << grain << " " << threads << " " << i;
      }
    }
  }
}

TEST(ParallelFor, ResultsDoNotDependOnThreadCount) {
  const size_t count = 20000;
  auto run = [&](int threads) {
    std::vector<float> out(count);
    ParallelOptions options;
    options.threads = threads;
    options.grain = 37;
    EXPECT_TRUE(parallelFor(
        count,
        [&](size_t begin, size_t end) {
          for (size_t i = begin; i < end; ++i) {
            SampleStream s(i, 0);
            float sum = 0.0f;
            for (int k = 0; k < 8; ++k) sum += s.get1D();
            out[i] = sum;
          }
        },
        options));
    return out;
  };
  EXPECT_EQ(run(1), run(2));
  EXPECT_EQ(run(1), run(0));
}

TEST(ParallelFor, CancelStopsEarly) {
  for (int threads : {1, 2}) {
    std::atomic<bool> cancel{false};
    std::atomic<size_t> processed{0};
    const size_t count = 1000000;
    ParallelOptions options;
    options.threads = threads;
    options.grain = 10;
    options.cancel = &cancel;
    bool ok = parallelFor(
        count,
        [&](size_t begin, size_t end) {
          processed += end - begin;
          if (processed.load() >= 100) cancel.store(true);
        },
        options);
    EXPECT_FALSE(ok);
    EXPECT_LT(processed.load(), count / 10);
  }
  // Already cancelled: nothing runs.
  std::atomic<bool> cancel{true};
  ParallelOptions options;
  options.cancel = &cancel;
  bool ran = false;
  EXPECT_FALSE(parallelFor(
      100, [&](size_t, size_t) { ran = true; }, options));
  EXPECT_FALSE(ran);
}

TEST(Progress, CountsAndFinishesOnce) {
  Progress p("quiet", 10, "things", false);
  p.advance(3);
  p.advance();
  EXPECT_EQ(p.done(), 4u);
  p.finish();
  p.finish();
  EXPECT_EQ(p.done(), 4u);
  EXPECT_FALSE(cancelFlag().load());
}

TEST(InterruptDeathTest, FirstSignalSetsFlagSecondKills) {
  // Runs in a forked child, so the parent's flag and handlers stay untouched.
  EXPECT_EXIT(
      {
        installInterruptHandler();
        std::raise(SIGINT);
        if (!cancelFlag().load()) std::_Exit(3);
        std::raise(SIGINT);
        std::_Exit(4);
      },
      testing::KilledBySignal(SIGINT), "interrupted");
}

}  // namespace
}  // namespace kiln
