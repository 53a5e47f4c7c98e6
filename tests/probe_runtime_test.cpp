// probe_runtime_test.cpp: the probe lookup (Cupisz 2012): robust orientation, barycentric
// weights, hinted walks, outer-cell extrapolation, batch and threads, and the .kprobe file
// (round trip, and rejection of every kind of bad file without crashing), and the file's sun
// layer block (version 4).
#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <bit>
#include <limits>
#include <map>
#include <random>
#include <thread>

#include "kiln/predicates.h"
#include "kiln/probe_runtime.h"
#include "kiln/probe_set.h"
#include "kiln_runtime.h"
#include "probes/tetrahedralize.h"

namespace kiln {
namespace {

// Probes filling the cube [-1, 1]^3: its 8 corners (so the hull is the cube) and random
// interior points.
std::vector<glm::vec3> cubeProbes(int interior, uint32_t seed) {
  std::vector<glm::vec3> p;
  for (int i = 0; i < 8; ++i) p.emplace_back(i & 1 ? 1 : -1, i & 2 ? 1 : -1, i & 4 ? 1 : -1);
  std::mt19937 rng(seed);
  std::uniform_real_distribution<float> u(-0.95f, 0.95f);
  for (int i = 0; i < interior; ++i) p.emplace_back(u(rng), u(rng), u(rng));
  return p;
}

std::vector<glm::vec3> ballProbes(int n, uint32_t seed) {
  std::mt19937 rng(seed);
  std::normal_distribution<float> g;
  std::uniform_real_distribution<float> u(0.0f, 1.0f);
  std::vector<glm::vec3> p;
  for (int i = 0; i < n; ++i) {
    glm::vec3 d = glm::normalize(glm::vec3(g(rng), g(rng), g(rng)));
    p.push_back(d * (0.3f + 0.7f * std::cbrt(u(rng))));
  }
  return p;
}

ProbeSet build(std::span<const glm::vec3> pts, DelaunayBackend backend) {
  ProbeTopologySettings s;
  s.backend = backend;
  Result<ProbeSet> r = buildProbeTopology(pts, s);
  EXPECT_TRUE(r.ok()) << r.error();
  ProbeSet set = r.ok() ? std::move(r).value() : ProbeSet{};
  // Distinct SH per probe so blends are recognisable.
  std::mt19937 rng(42);
  std::uniform_real_distribution<float> u(-1.0f, 1.0f);
  for (ShL2Rgb& sh : set.sh)
    for (auto& c : sh.c) c = glm::vec3(u(rng), u(rng), u(rng));
  return set;
}

std::map<int32_t, double> weightMap(const ProbeLocation& loc) {
  std::map<int32_t, double> m;
  for (int k = 0; k < 4; ++k) m[loc.probes[k]] += loc.weights[k];
  return m;
}

double weightDistance(const ProbeLocation& a, const ProbeLocation& b) {
  auto ma = weightMap(a), mb = weightMap(b);
  double d = 0.0;
  for (auto& [k, w] : ma) d = std::max(d, std::fabs(w - (mb.count(k) ? mb[k] : 0.0)));
  for (auto& [k, w] : mb) d = std::max(d, std::fabs(w - (ma.count(k) ? ma[k] : 0.0)));
  return d;
}

void expectSaneWeights(const ProbeLocation& loc) {
  ASSERT_GE(loc.cell, 0);
  double sum = 0.0;
  for (float w : loc.weights) {
    ASSERT_TRUE(std::isfinite(w));
    EXPECT_GE(w, -1e-6f);
    sum += w;
  }
  EXPECT_NEAR(sum, 1.0, 1e-6);
}

glm::dvec3 blendPositions(const ProbeSet& s, const ProbeLocation& loc) {
  glm::dvec3 r(0.0);
  for (int k = 0; k < 4; ++k) r += double(loc.weights[k]) * glm::dvec3(s.positions[loc.probes[k]]);
  return r;
}

// ---- predicates -------------------------------------------------------------------------

TEST(Predicates, ExactOnCoplanarPointsThatDoubleGetsWrong) {
  // Points on the plane z = x + y with coordinates whose double evaluation rounds.
  std::mt19937 rng(3);
  std::uniform_real_distribution<float> u(-1000.0f, 1000.0f);
  int zeros = 0;
  for (int i = 0; i < 1000; ++i) {
    glm::vec3 q[4];
    for (auto& v : q) {
      // x and y multiples of 1/64 keep x + y exact in float: the points are exactly coplanar.
      v.x = std::round(u(rng) * 64.0f) / 64.0f;
      v.y = std::round(u(rng) * 64.0f) / 64.0f;
      v.z = v.x + v.y;
    }
    zeros += orient3d(q[0], q[1], q[2], q[3]) == 0.0;
    EXPECT_EQ(orient3dExact(q[0], q[1], q[2], q[3]), 0.0);
  }
  EXPECT_EQ(zeros, 1000);
}

TEST(Predicates, SignMatchesExactNearDegeneracy) {
  std::mt19937 rng(4);
  std::uniform_real_distribution<float> u(-1.0f, 1.0f);
  for (int i = 0; i < 2000; ++i) {
    const glm::vec3 a(u(rng), u(rng), u(rng)), b(u(rng), u(rng), u(rng)), c(u(rng), u(rng),
                                                                           u(rng));
    // d very close to the plane abc.
    const float s = u(rng), t = u(rng);
    glm::vec3 d = a + s * (b - a) + t * (c - a);
    d.z = std::nextafter(d.z, i % 2 ? 10.0f : -10.0f);
    const double fast = orient3d(a, b, c, d), exact = orient3dExact(a, b, c, d);
    EXPECT_EQ((fast > 0) - (fast < 0), (exact > 0) - (exact < 0));
  }
  EXPECT_GT(orient3d(glm::vec3(0), glm::vec3(1, 0, 0), glm::vec3(0, 1, 0), glm::vec3(0, 0, 1)),
            0.0);
  EXPECT_DOUBLE_EQ(
      orient3d(glm::vec3(0), glm::vec3(1, 0, 0), glm::vec3(0, 1, 0), glm::vec3(0, 0, 1)), 1.0);
}

// ---- lookup -----------------------------------------------------------------------------

TEST(ProbeLookup, WeightsAreBarycentricInsideTheHull) {
  const auto pts = cubeProbes(300, 1);
  for (DelaunayBackend backend : {DelaunayBackend::TetGen, DelaunayBackend::Cgal}) {
    const ProbeSet s = build(pts, backend);
    std::mt19937 rng(2);
    std::uniform_real_distribution<float> u(-1.0f, 1.0f);
    for (int i = 0; i < 2000; ++i) {
      const glm::vec3 p(u(rng), u(rng), u(rng));
      const ProbeLocation loc = locateProbe(s, p);
      expectSaneWeights(loc);
      EXPECT_LT(loc.cell, s.innerCellCount);
      EXPECT_LT(glm::length(blendPositions(s, loc) - glm::dvec3(p)), 1e-5);
    }
  }
}

TEST(ProbeLookup, AtAProbeItReturnsThatProbesSh) {
  const auto pts = ballProbes(200, 5);
  const ProbeSet s = build(pts, DelaunayBackend::TetGen);
  for (int32_t i = 0; i < s.probeCount(); ++i) {
    const ShL2Rgb sh = sampleProbes(s, s.positions[i]);
    for (int k = 0; k < kShL2Count; ++k) {
      for (int ch = 0; ch < 3; ++ch) {
        EXPECT_NEAR(sh.c[k][ch], s.sh[i].c[k][ch], 1e-6f) << "probe " << i;
      }
    }
  }
}

TEST(ProbeLookup, HundredThousandPointsInsideNeedNoScan) {
  const auto pts = cubeProbes(1000, 6);
  for (DelaunayBackend backend : {DelaunayBackend::TetGen, DelaunayBackend::Cgal}) {
    const ProbeSet s = build(pts, backend);
    std::mt19937 rng(7);
    std::uniform_real_distribution<float> u(-1.0f, 1.0f);
    int located = 0, scans = 0;
    double steps = 0.0;
    for (int i = 0; i < 100000; ++i) {
      const ProbeLocation loc = locateProbe(s, glm::vec3(u(rng), u(rng), u(rng)));
      located += loc.cell >= 0 && loc.cell < s.innerCellCount;
      scans += loc.bruteForce;
      steps += loc.steps;
    }
    EXPECT_EQ(located, 100000);
    EXPECT_EQ(scans, 0);
    EXPECT_LT(steps / 100000.0, 20.0) << "the seed grid starts walks near their cell";
  }
}

TEST(ProbeLookup, HintedWalkFindsTheSameCellsAsUnhinted) {
  const auto pts = ballProbes(800, 8);
  const ProbeSet s = build(pts, DelaunayBackend::Cgal);
  std::mt19937 rng(9);
  std::normal_distribution<float> g(0.0f, 0.01f);
  glm::vec3 p(0.0f);
  int32_t hint = -1;
  double hintedSteps = 0.0;
  for (int i = 0; i < 20000; ++i) {
    p = glm::clamp(p + glm::vec3(g(rng), g(rng), g(rng)), glm::vec3(-1.5f), glm::vec3(1.5f));
    const ProbeLocation hinted = locateProbe(s, p, hint);
    const ProbeLocation fresh = locateProbe(s, p);
    ASSERT_EQ(hinted.cell, fresh.cell) << "step " << i;
    EXPECT_LT(weightDistance(hinted, fresh), 1e-6);
    EXPECT_FALSE(hinted.bruteForce);
    hint = hinted.cell;
    hintedSteps += hinted.steps;
  }
  EXPECT_LT(hintedSteps / 20000.0, 3.0) << "last frame's cell is at most a step or two away";
}

TEST(ProbeLookup, ExtrapolationIsContinuousAcrossTheHull) {
  const auto pts = ballProbes(300, 10);
  for (DelaunayBackend backend : {DelaunayBackend::TetGen, DelaunayBackend::Cgal}) {
    const ProbeSet s = build(pts, backend);
    std::mt19937 rng(11);
    std::uniform_real_distribution<float> u(0.05f, 0.9f);
    const float eps = 1e-4f;
    for (int32_t c = s.innerCellCount; c < s.cellCount(); ++c) {
      const glm::ivec4 t = s.cells[c];
      const glm::vec3 a = s.positions[t[0]], b = s.positions[t[1]], cc = s.positions[t[2]];
      float x = u(rng), y = u(rng);
      if (x + y > 0.95f) {
        x *= 0.5f;
        y *= 0.5f;
      }
      const glm::vec3 q = a + x * (b - a) + y * (cc - a);
      const glm::vec3 n = glm::normalize(glm::cross(b - a, cc - a));
      const ProbeLocation in = locateProbe(s, q - eps * n), out = locateProbe(s, q + eps * n);
      expectSaneWeights(in);
      expectSaneWeights(out);
      EXPECT_LT(in.cell, s.innerCellCount);
      EXPECT_EQ(out.cell, c) << "just outside a hull triangle is its outer cell";
      // Continuity: the gap shrinks with the distance (linearly: thin tetrahedra near the hull
      // have steep but finite gradients), rather than staying at a jump.
      const double gap = weightDistance(in, out);
      const ProbeLocation in10 = locateProbe(s, q - 0.1f * eps * n),
                          out10 = locateProbe(s, q + 0.1f * eps * n);
      const double gap10 = weightDistance(in10, out10);
      EXPECT_LT(gap, 0.5) << "hull triangle " << c;
      EXPECT_LT(gap10, 0.3 * gap + 2e-6) << "hull triangle " << c;
    }
  }
}

TEST(ProbeLookup, ExtrapolationIsContinuousOutside) {
  const auto pts = ballProbes(200, 12);
  const ProbeSet s = build(pts, DelaunayBackend::TetGen);
  std::mt19937 rng(13);
  std::normal_distribution<float> g;
  std::uniform_real_distribution<float> r(1.0f, 4.0f);
  double worst = 0.0;
  int outer = 0;
  for (int i = 0; i < 20000; ++i) {
    const glm::vec3 d = glm::normalize(glm::vec3(g(rng), g(rng), g(rng)));
    const glm::vec3 p = d * r(rng);
    const glm::vec3 step = 1e-5f * glm::normalize(glm::vec3(g(rng), g(rng), g(rng)));
    const ProbeLocation a = locateProbe(s, p), b = locateProbe(s, p + step);
    expectSaneWeights(a);
    expectSaneWeights(b);
    EXPECT_FALSE(a.bruteForce);
    outer += a.cell >= s.innerCellCount;
    worst = std::max(worst, weightDistance(a, b));
  }
  EXPECT_GT(outer, 15000);
  EXPECT_LT(worst, 1e-2) << "weights move by O(step) between points 1e-5 apart";
}

TEST(ProbeLookup, FarAwayPointsGetFiniteWeights) {
  const auto pts = ballProbes(100, 14);
  const ProbeSet s = build(pts, DelaunayBackend::TetGen);
  std::mt19937 rng(15);
  std::normal_distribution<float> g;
  for (int i = 0; i < 2000; ++i) {
    const glm::vec3 p = 1e6f * glm::normalize(glm::vec3(g(rng), g(rng), g(rng)));
    const ProbeLocation loc = locateProbe(s, p);
    expectSaneWeights(loc);
    EXPECT_GE(loc.cell, s.innerCellCount);
    const ShL2Rgb sh = interpolateProbes(s, loc);
    for (auto& c : sh.c) EXPECT_TRUE(std::isfinite(c.x) && std::isfinite(c.y));
  }
}

TEST(ProbeLookup, BadHintsAreIgnored) {
  const ProbeSet s = build(cubeProbes(50, 16), DelaunayBackend::TetGen);
  const glm::vec3 p(0.1f, 0.2f, 0.3f);
  const ProbeLocation ref = locateProbe(s, p);
  for (int32_t hint : {-5, -1, s.cellCount(), 1 << 30, s.cellCount() - 1, 0}) {
    const ProbeLocation loc = locateProbe(s, p, hint);
    EXPECT_EQ(loc.cell, ref.cell);
  }
  // NaN input does not hang or crash; it still returns some cell with sane weights.
  expectSaneWeights(locateProbe(s, glm::vec3(std::nanf(""), 0.0f, 0.0f)));
}

TEST(ProbeLookup, BatchMatchesSingleQueriesAndUpdatesHints) {
  const ProbeSet s = build(ballProbes(300, 17), DelaunayBackend::TetGen);
  std::mt19937 rng(18);
  std::uniform_real_distribution<float> u(-2.0f, 2.0f);
  std::vector<glm::vec3> points(500);
  for (auto& p : points) p = glm::vec3(u(rng), u(rng), u(rng));
  std::vector<int32_t> hints(points.size(), -1);
  std::vector<ProbeLocation> locs(points.size());
  locateProbes(s, points, hints, locs);
  std::vector<ShL2Rgb> sh(points.size());
  sampleProbes(s, points, hints, sh);
  for (size_t i = 0; i < points.size(); ++i) {
    const ProbeLocation ref = locateProbe(s, points[i]);
    EXPECT_EQ(locs[i].cell, ref.cell);
    EXPECT_EQ(hints[i], ref.cell);
    const ShL2Rgb one = interpolateProbes(s, ref);
    for (int k = 0; k < kShL2Count; ++k) EXPECT_EQ(sh[i].c[k], one.c[k]);
  }
}

// The batch forms interleave several walks (probe_runtime.cpp); each point must still get
// exactly the single lookup's result. Points inside and outside the hull, probe positions and
// edge midpoints (undecided fast steps), without hints, with good hints and with stale ones
// (any cell, outer cells included), on a grid (cospherical: exact steps) and random probes.
TEST(ProbeLookup, InterleavedBatchGivesTheSingleLookupsResults) {
  std::vector<glm::vec3> grid;
  for (int z = 0; z < 12; ++z)
    for (int y = 0; y < 12; ++y)
      for (int x = 0; x < 12; ++x) grid.push_back(glm::vec3(x, y, z) * (2.0f / 11.0f) - 1.0f);
  for (const ProbeSet& s : {build(cubeProbes(4000, 61), DelaunayBackend::Cgal),
                            build(grid, DelaunayBackend::Cgal)}) {
    std::mt19937 rng(62);
    std::uniform_real_distribution<float> u(-1.5f, 1.5f);
    std::uniform_int_distribution<int32_t> anyCell(0, s.cellCount() - 1);
    std::uniform_int_distribution<int32_t> anyProbe(0, s.probeCount() - 1);
    std::vector<glm::vec3> points(20000);
    std::vector<int32_t> hints(points.size());
    for (size_t i = 0; i < points.size(); ++i) {
      points[i] = glm::vec3(u(rng), u(rng), u(rng));
      if (i % 7 == 3) points[i] = s.positions[size_t(anyProbe(rng))];
      if (i % 7 == 5) {
        const glm::ivec4 t = s.cells[size_t(anyCell(rng) % s.innerCellCount)];
        points[i] = 0.5f * (s.positions[size_t(t[0])] + s.positions[size_t(t[1])]);
      }
      hints[i] = i % 3 == 0 ? -1 : i % 3 == 1 ? anyCell(rng) : locateProbe(s, points[i]).cell;
    }
    for (bool withHints : {false, true}) {
      std::vector<int32_t> h = hints;
      std::vector<ProbeLocation> batch(points.size());
      locateProbes(s, points, withHints ? std::span<int32_t>(h) : std::span<int32_t>{}, batch);
      std::vector<ShL2Rgb> sh(points.size());
      std::vector<glm::vec4> occlusion(points.size());
      std::vector<int32_t> h2 = hints;
      sampleProbes(s, points, withHints ? std::span<int32_t>(h2) : std::span<int32_t>{}, sh,
                   occlusion);
      int outside = 0, walked = 0;
      for (size_t i = 0; i < points.size(); ++i) {
        const ProbeLocation one = locateProbe(s, points[i], withHints ? hints[i] : -1);
        const ProbeLocation& b = batch[i];
        ASSERT_EQ(b.cell, one.cell) << i;
        ASSERT_EQ(b.probes, one.probes) << i;
        ASSERT_EQ(b.weights, one.weights) << i;
        ASSERT_EQ(b.barycentric, one.barycentric) << i;
        ASSERT_EQ(b.steps, one.steps) << i;
        ASSERT_EQ(b.bruteForce, one.bruteForce) << i;
        if (withHints) {
          ASSERT_EQ(h[i], one.cell);
          ASSERT_EQ(h2[i], one.cell);
        }
        const ShL2Rgb ref = interpolateProbes(s, one);
        for (int k = 0; k < kShL2Count; ++k) ASSERT_EQ(sh[i].c[k], ref.c[k]) << i;
        ASSERT_EQ(occlusion[i], interpolateOcclusion(s, one)) << i;
        outside += one.cell >= s.innerCellCount;
        walked += one.steps > 2;
      }
      // The cases the interleaving hands over to the single walk occur, and so do long walks.
      EXPECT_GT(outside, int(points.size()) / 10);
      EXPECT_GT(walked, int(points.size()) / 10);
    }
  }
}

TEST(ProbeLookup, ManyThreadsGetTheSameAnswers) {
  const ProbeSet s = build(ballProbes(500, 19), DelaunayBackend::Cgal);
  std::mt19937 rng(20);
  std::uniform_real_distribution<float> u(-2.0f, 2.0f);
  std::vector<glm::vec3> points(4000);
  for (auto& p : points) p = glm::vec3(u(rng), u(rng), u(rng));
  std::vector<int32_t> expected(points.size());
  for (size_t i = 0; i < points.size(); ++i) expected[i] = locateProbe(s, points[i]).cell;
  std::vector<int> mismatches(4, 0);
  std::vector<std::thread> threads;
  for (int t = 0; t < 4; ++t) {
    threads.emplace_back([&, t] {
      int32_t hint = -1;
      for (size_t i = 0; i < points.size(); ++i) {
        const ProbeLocation loc = locateProbe(s, points[i], hint);
        hint = loc.cell;
        mismatches[t] += loc.cell != expected[i];
      }
    });
  }
  for (auto& th : threads) th.join();
  for (int m : mismatches) EXPECT_EQ(m, 0);
}

// The fast walk (float barycentrics, exact predicates near faces) against the exact walk
// from the same start, on 1M points inside and outside the hull: the same cell every time,
// and weights that differ by no more than the float error bound of the fast path (8 u S_k,
// S_k = sum_j |g_kj| |p_j - origin_j| with g_k = ProbeWalkCell::gradient(k) for k = 1..3,
// and l_0 held to the sum of the others' bounds, which covers its own since S_0 <= S_1 + S_2
// + S_3; see probe_runtime.cpp). The queries mix jumps (no hint), small moves (hinted),
// probe positions exactly (three coordinates exactly 0, computed with rounding: only the
// exact predicates can decide) and float midpoints of a cell's edges (within rounding of
// two faces). Two sets: random probes in a cube, and a rotated grid (cospherical).
void expectFastMatchesExact(const ProbeSet& s, int count, uint32_t seed) {
  ASSERT_EQ(s.walk.size(), size_t(s.innerCellCount));
  std::mt19937 rng(seed);
  std::uniform_real_distribution<float> u(-1.6f, 1.6f);
  std::normal_distribution<float> g(0.0f, 0.02f);
  std::uniform_int_distribution<int32_t> probe(0, s.probeCount() - 1);
  constexpr double kU = 5.9604645e-8;
  glm::vec3 p(0.0f);
  int32_t hint = -1;
  int outside = 0, mismatches = 0;
  double worstExcess = 0.0;
  for (int i = 0; i < count; ++i) {
    switch (i % 16) {
      case 0:
        p = glm::vec3(u(rng), u(rng), u(rng));
        hint = -1;
        break;
      case 5:
        p = s.positions[size_t(probe(rng))];
        break;
      case 10:
        if (hint >= 0 && hint < s.innerCellCount) {
          const glm::ivec4 t = s.cells[size_t(hint)];
          p = 0.5f * (s.positions[size_t(t[i % 4])] + s.positions[size_t(t[(i / 16) % 4])]);
        }
        break;
      default:
        p += glm::vec3(g(rng), g(rng), g(rng));
    }
    const ProbeLocation fast = locateProbe(s, p, hint);
    const ProbeLocation exact = locateProbeExact(s, p, hint);
    if (fast.cell != exact.cell) {
      if (++mismatches <= 5) {
        ADD_FAILURE() << "query " << i << " (" << p.x << ", " << p.y << ", " << p.z
                      << "): fast cell " << fast.cell << ", exact cell " << exact.cell;
      }
      continue;
    }
    hint = fast.cell;
    outside += fast.cell >= s.innerCellCount;
    ASSERT_EQ(fast.probes, exact.probes);
    double bound[4] = {0, 0, 0, 0};
    if (fast.cell < s.innerCellCount) {
      const ProbeWalkCell& w = s.walk[size_t(fast.cell)];
      const glm::dvec3 q = glm::abs(glm::dvec3(p) - glm::dvec3(w.origin));
      for (int k = 0; k < 3; ++k) {
        const double sk = glm::dot(glm::abs(glm::dvec3(w.gradient(k + 1))), q);
        bound[k + 1] = 8.0 * kU * sk + 4.0 * kU;
        bound[0] += bound[k + 1];
      }
      bound[0] += 8.0 * kU;
    }
    for (int k = 0; k < 4; ++k) {
      // Both normalise by their sum (1 within a few u) and round to float.
      const double tolerance = bound[k] + 4.0 * kU;
      const double d = std::fabs(double(fast.weights[k]) - double(exact.weights[k]));
      worstExcess = std::max(worstExcess, d / tolerance);
    }
  }
  EXPECT_EQ(mismatches, 0);
  EXPECT_LE(worstExcess, 1.0) << "largest weight difference over its float error bound";
  EXPECT_GT(outside, count / 20) << "the queries reach outer cells too";
}

TEST(ProbeLookup, FastWalkFindsTheExactWalksCellOnAMillionPoints) {
  expectFastMatchesExact(build(cubeProbes(2000, 30), DelaunayBackend::Cgal), 600000, 31);
  const glm::mat3 rotation = glm::mat3(glm::normalize(glm::vec3(1, 2, 2)),
                                       glm::normalize(glm::vec3(-2, 2, -1)),
                                       glm::normalize(glm::vec3(2, 1, -2)));
  std::vector<glm::vec3> grid;
  for (int z = 0; z < 9; ++z)
    for (int y = 0; y < 9; ++y)
      for (int x = 0; x < 9; ++x) grid.push_back(rotation * (glm::vec3(x, y, z) * 0.25f - 1.0f));
  expectFastMatchesExact(build(grid, DelaunayBackend::Cgal), 400000, 32);
}

// makeProbeWalkCells computes four records at a time in SIMD lanes where the CPU allows; each
// must equal makeProbeWalkCell's for the same corners, bit for bit, whatever branch the
// single-cell code takes: random tetrahedra (about 4 in 10 have a cross-product component that
// cancels and takes Kahan's FMA form), slivers (determinant test fails), corners whose
// exponents differ by more than 29 (inexact edges), huge cells (gradients below the normal
// floats), exactly flat cells, and a count that is not a multiple of four (the tail).
TEST(ProbeLookup, WalkRecordsInLanesEqualTheSingleCellOnes) {
  std::mt19937 rng(77);
  std::uniform_real_distribution<float> u(-1.0f, 1.0f);
  std::vector<glm::vec3> positions;
  std::vector<glm::ivec4> cells;
  auto add = [&](std::array<glm::vec3, 4> v) {
    if (orient3d(v[0], v[1], v[2], v[3]) < 0.0) std::swap(v[2], v[3]);
    const int32_t first = int32_t(positions.size());
    positions.insert(positions.end(), v.begin(), v.end());
    cells.emplace_back(first, first + 1, first + 2, first + 3);
  };
  auto point = [&]() { return glm::vec3(u(rng), u(rng), u(rng)); };
  for (int i = 0; i < 4001; ++i) {
    const int kind = i % 8;
    std::array<glm::vec3, 4> v{point(), point(), point(), point()};
    if (kind == 5) v[3] = 0.5f * (v[0] + v[1]) + 1e-6f * point();        // sliver
    if (kind == 6) v[i / 8 % 4] = std::ldexp(1.0f, -40) * point();      // tiny exponents
    if (kind == 7 && i % 16 == 7) for (auto& x : v) x *= 1e38f;          // huge cell
    if (kind == 7 && i % 16 == 15) v[3] = v[0] + (v[1] - v[0]) * 0.25f;  // flat or nearly
    add(v);
  }
  // Shared corners too (cells of a real set), in an order that puts each kind in every lane.
  const ProbeSet set = build(cubeProbes(500, 78), DelaunayBackend::Cgal);
  const int32_t offset = int32_t(positions.size());
  positions.insert(positions.end(), set.positions.begin(), set.positions.end());
  for (int32_t c = 0; c < set.innerCellCount; ++c) cells.push_back(set.cells[size_t(c)] + offset);
  std::shuffle(cells.begin(), cells.end(), rng);
  cells.pop_back();
  ASSERT_NE(cells.size() % 4, 0u);

  std::vector<ProbeWalkCell> lanes(cells.size()), single(cells.size());
  makeProbeWalkCells(positions, cells, lanes.data());
  int failed = 0, bounded = 0;
  for (size_t c = 0; c < cells.size(); ++c) {
    const glm::ivec4 t = cells[c];
    makeProbeWalkCell({positions[size_t(t[0])], positions[size_t(t[1])], positions[size_t(t[2])],
                       positions[size_t(t[3])]},
                      single[c]);
    failed += std::isnan(single[c].x[0]);
    bounded += std::isfinite(single[c].inside);
    EXPECT_EQ(std::memcmp(&lanes[c], &single[c], sizeof(ProbeWalkCell)), 0) << "cell " << c;
  }
  // Both outcomes occur: records that failed (NaN gradients) and ones with a finite bound.
  EXPECT_GT(failed, 300);
  EXPECT_GT(bounded, 3000);
}

TEST(ProbeLookup, IrradianceOfAConstantEnvironmentIsPiTimesRadiance) {
  // Constant radiance L: c0 = L * sqrt(4 pi) / ... projection gives c0 = L * 4 pi * Y00.
  ShL2Rgb sh;
  sh.c[0] = glm::vec3(1.0f) * (4.0f * 3.14159265f * 0.282095f);
  const glm::vec3 e = probeIrradiance(sh, glm::vec3(0, 1, 0));
  EXPECT_NEAR(e.x, 3.14159265f, 1e-3f);  // E = pi L for constant radiance L = 1
}

// ---- .kprobe file -----------------------------------------------------------------------

std::string tempPath(const std::string& name) {
  return (std::filesystem::temp_directory_path() / ("kiln_" + name)).string();
}

TEST(ProbeFile, RoundTripIsExact) {
  const ProbeSet s = build(ballProbes(100, 21), DelaunayBackend::TetGen);
  const std::string path = tempPath("roundtrip.kprobe");
  ASSERT_TRUE(writeProbeFile(s, path).ok());
  EXPECT_FALSE(std::filesystem::exists(path + ".tmp"));
  Result<ProbeSet> r = loadProbeFile(path);
  ASSERT_TRUE(r.ok()) << r.error();
  EXPECT_EQ(serializeProbeSet(*r), serializeProbeSet(s));
  EXPECT_EQ(r->dimension, 3);
  std::mt19937 rng(22);
  std::uniform_real_distribution<float> u(-3.0f, 3.0f);
  for (int i = 0; i < 200; ++i) {
    const glm::vec3 p(u(rng), u(rng), u(rng));
    EXPECT_EQ(locateProbe(s, p).cell, locateProbe(*r, p).cell);
  }
  std::filesystem::remove(path);
}

// A small valid set (dimension 3: 5 probes, 2 tetrahedra, 6 outer cells).
ProbeSet smallSet() {
  std::vector<glm::vec3> pts = {glm::vec3(0, 0, 0), glm::vec3(1, 0, 0), glm::vec3(0, 1, 0),
                                glm::vec3(0, 0, 1), glm::vec3(0.9f, 0.9f, 0.9f)};
  return build(pts, DelaunayBackend::TetGen);
}

// smallSet() with a visibility block (version 3): 4 x 4 maps of varied valid texels
// {mu, sigma <= 1/2, far >= mu}.
ProbeSet smallSetWithVisibility() {
  ProbeSet s = smallSet();
  s.visibility.resolution = kMinVisibilityResolution;
  s.visibility.maxDistance.assign(size_t(s.probeCount()), 1.5f);
  s.visibility.moments.resize(size_t(s.probeCount()) * s.visibility.valuesPerProbe());
  for (size_t t = 0; t < s.visibility.moments.size(); t += kVisibilityValuesPerTexel) {
    const uint16_t mu = uint16_t(1000 + 97 * t);
    s.visibility.moments[t] = mu;
    s.visibility.moments[t + 1] = uint16_t(50 + 31 * t);
    s.visibility.moments[t + 2] = uint16_t(std::min(65535.0, mu * 1.5 + 10.0));
  }
  return s;
}

std::string parseError(const std::vector<uint8_t>& bytes) {
  Result<ProbeSet> r = parseProbeSet(bytes, "bad.kprobe");
  return r.ok() ? std::string("(accepted)") : r.error();
}

TEST(ProbeFile, EveryTruncationIsRejected) {
  const std::vector<uint8_t> bytes = serializeProbeSet(smallSet());
  ASSERT_TRUE(parseProbeSet(bytes, "ok").ok());
  for (const std::vector<uint8_t>& file : {bytes, serializeProbeSet(smallSetWithVisibility())}) {
    ASSERT_TRUE(parseProbeSet(file, "ok").ok());
    for (size_t n = 0; n < file.size(); ++n) {
      const std::vector<uint8_t> cut(file.begin(), file.begin() + long(n));
      const std::string e = parseError(cut);
      ASSERT_EQ(e.rfind("bad.kprobe: ", 0), 0u) << n << ": " << e;
      EXPECT_TRUE(e.find("truncated") != std::string::npos) << n << ": " << e;
    }
  }
  // And through the file reader, at a few offsets.
  const std::string path = tempPath("truncated.kprobe");
  for (size_t n : {size_t(0), size_t(3), size_t(71), size_t(72), bytes.size() / 2,
                   bytes.size() - 1}) {
    std::FILE* f = std::fopen(path.c_str(), "wb");
    std::fwrite(bytes.data(), 1, n, f);
    std::fclose(f);
    Result<ProbeSet> r = loadProbeFile(path);
    ASSERT_FALSE(r.ok());
    EXPECT_EQ(r.error().rfind(path + ": ", 0), 0u) << r.error();
  }
  std::filesystem::remove(path);
}

TEST(ProbeFile, HeaderDamageIsNamed) {
  const std::vector<uint8_t> good = serializeProbeSet(smallSet());
  auto patched = [&](size_t at, uint32_t value) {
    std::vector<uint8_t> b = good;
    std::memcpy(b.data() + at, &value, 4);
    return parseError(b);
  };
  std::vector<uint8_t> b = good;
  b[0] = 'X';
  EXPECT_NE(parseError(b).find("magic"), std::string::npos);
  EXPECT_NE(patched(4, 5).find("version: file version 5"), std::string::npos);
  EXPECT_NE(patched(8, 7).find("dimension"), std::string::npos);
  // Huge counts in a small file: rejected from the header, before any allocation.
  EXPECT_NE(patched(12, 1u << 25).find("size: file has"), std::string::npos);
  EXPECT_NE(patched(12, 0xFFFFFFFFu).find("probeCount"), std::string::npos);
  EXPECT_NE(patched(16, 0xFFFFFFFFu).find("cellCount"), std::string::npos);
  EXPECT_NE(patched(20, 1000).find("innerCellCount"), std::string::npos);
  EXPECT_NE(patched(24, 5000).find("gridSize[0]"), std::string::npos);
  b = good;
  b.push_back(0);
  EXPECT_NE(parseError(b).find("trailing data"), std::string::npos);
  b = good;
  b[good.size() - 5] ^= 0x40;  // payload bit flip
  EXPECT_NE(parseError(b).find("checksum"), std::string::npos);
}

TEST(ProbeFile, BadContentIsNamed) {
  const ProbeSet good = smallSet();
  {
    ProbeSet s = good;
    s.cells[1][2] = 99;
    EXPECT_NE(parseError(serializeProbeSet(s))
                  .find("cells[1][2]: probe index 99 out of range (probeCount 5)"),
              std::string::npos)
        << parseError(serializeProbeSet(s));
  }
  {
    ProbeSet s = good;
    s.sh[2].c[4].g = std::nanf("");
    EXPECT_NE(parseError(serializeProbeSet(s)).find("sh[2][4]: not finite"), std::string::npos);
  }
  {
    ProbeSet s = good;
    s.positions[3].x = std::numeric_limits<float>::infinity();
    EXPECT_NE(parseError(serializeProbeSet(s)).find("positions[3]"), std::string::npos);
  }
  {
    ProbeSet s = good;
    // Point cell 0 at a cell that does not link back.
    int32_t other = -1;
    for (int32_t c = 1; c < s.cellCount() && other < 0; ++c) {
      const glm::ivec4 n = s.neighbours[c];
      if (n[0] != 0 && n[1] != 0 && n[2] != 0 && n[3] != 0) other = c;
    }
    ASSERT_GE(other, 0);
    s.neighbours[0][0] = other;
    const std::string e = parseError(serializeProbeSet(s));
    EXPECT_NE(e.find("neighbours[0][0]"), std::string::npos) << e;
    EXPECT_NE(e.find("asymmetric"), std::string::npos) << e;
  }
  {
    ProbeSet s = good;
    s.neighbours[2][1] = 1000;
    EXPECT_NE(parseError(serializeProbeSet(s)).find("neighbours[2][1]: cell index 1000"),
              std::string::npos);
  }
  {
    ProbeSet s = good;
    s.grid.seeds[0] = -3;
    EXPECT_NE(parseError(serializeProbeSet(s)).find("seeds[0]"), std::string::npos);
  }
  {
    ProbeSet s = good;
    s.outerCells[0].cubic[2].w = std::nanf("");
    EXPECT_NE(parseError(serializeProbeSet(s)).find("outerCells[0].cubic"), std::string::npos);
  }
  {
    ProbeSet s = good;
    s.cells[s.innerCellCount][3] = 2;  // outer cells have -1 in slot 3
    EXPECT_NE(parseError(serializeProbeSet(s)).find("unused slot must be -1"),
              std::string::npos);
  }
}

// validateProbeSet's slot pass (four slots at a time where SSE2 is there) at the edges of every
// range: each of these single-slot corruptions of a valid 3D set, in an inner cell near the
// start, in the middle and at the end, and in an outer cell, is rejected and named.
TEST(ProbeFile, EverySlotCorruptionAtTheRangeEdgesIsRejected) {
  const ProbeSet good = build(cubeProbes(200, 91), DelaunayBackend::Cgal);
  ASSERT_TRUE(validateProbeSet(good, "good").ok());
  const int32_t np = good.probeCount(), nc = good.cellCount();
  const int32_t inner = good.innerCellCount;
  const std::vector<int32_t> probeValues = {np, np + 1, -1, -2, INT32_MIN, INT32_MAX};
  const std::vector<int32_t> linkValues = {nc, nc + 1, -2, INT32_MIN, INT32_MAX};
  int rejected = 0, tried = 0;
  for (int32_t c : {0, 5, inner / 2, inner - 1, inner, nc - 1}) {
    const int used = c < inner ? 4 : 3;
    for (int k = 0; k < 4; ++k) {
      for (int32_t value : k < used ? probeValues : std::vector<int32_t>{0, np - 1, np}) {
        ProbeSet s = good;
        s.cells[size_t(c)][k] = value;
        const Status st = validateProbeSet(s, "bad");
        ++tried;
        rejected += !st.ok();
        EXPECT_FALSE(st.ok()) << "cells[" << c << "][" << k << "] = " << value;
        if (!st.ok()) {
          EXPECT_NE(st.error().find("cells[" + std::to_string(c) + "][" + std::to_string(k) + "]"),
                    std::string::npos)
              << st.error();
        }
      }
      for (int32_t value : linkValues) {
        ProbeSet s = good;
        s.neighbours[size_t(c)][k] = value;
        const Status st = validateProbeSet(s, "bad");
        ++tried;
        rejected += !st.ok();
        EXPECT_FALSE(st.ok()) << "neighbours[" << c << "][" << k << "] = " << value;
      }
      // A link to a cell in range that does not link back.
      ProbeSet s = good;
      const int32_t other = (c + nc / 3) % nc;
      const glm::ivec4 back = s.neighbours[size_t(other)];
      if (back[0] != c && back[1] != c && back[2] != c && back[3] != c) {
        s.neighbours[size_t(c)][k] = other;
        const Status st = validateProbeSet(s, "bad");
        ++tried;
        rejected += !st.ok();
        EXPECT_NE(st.ok() ? std::string() : st.error(), std::string()) << "asymmetric link";
      }
    }
  }
  EXPECT_EQ(rejected, tried);
  EXPECT_GT(tried, 200);
}

TEST(ProbeFile, RandomCorruptionNeverCrashes) {
  std::mt19937 rng(23);
  for (const ProbeSet& set : {smallSet(), smallSetWithVisibility()}) {
    const std::vector<uint8_t> good = serializeProbeSet(set);
    for (int i = 0; i < 3000; ++i) {
      std::vector<uint8_t> b = good;
      const int flips = 1 + int(rng() % 4);
      for (int f = 0; f < flips; ++f) b[rng() % b.size()] ^= uint8_t(1u << (rng() % 8));
      (void)parseProbeSet(b, "fuzz");  // must return, accepted or not
    }
  }
  EXPECT_FALSE(loadProbeFile(tempPath("does_not_exist.kprobe")).ok());
}

// ---- .kprobe version 4: the sun layer ------------------------------------------------------

// A NaN with a payload: the file keeps the bits of a "no ramp" as they were written.
float payloadNan() { return std::bit_cast<float>(0x7fc01234u); }

// smallSet() with a sun layer: light 2 (any index >= 0; the runtime does not know the scene's
// count), a lobe, a share per probe across [0, 1], and both kinds of ramp.
ProbeSet smallSetWithSun() {
  ProbeSet s = smallSet();
  s.sun.light = 2;
  s.sun.sh.addSample(glm::normalize(glm::vec3(0.3f, 1.0f, -0.2f)), glm::vec3(3.0f, 2.5f, 2.0f),
                     1.0f);
  s.sun.visibility = {0.0f, 0.25f, 1.0f, 0.6f, 0.125f};
  EXPECT_EQ(s.sun.visibility.size(), size_t(s.probeCount()));
  s.sun.ramps.assign(size_t(s.innerCellCount), glm::vec4(payloadNan()));
  s.sun.ramps[0] = glm::vec4(-0.25f, 1.5f, 0.5f, 0.75f);
  return s;
}

// Recomputes a .kprobe image's checksum after its bytes were patched, so that the reader
// judges the patched field and not the checksum.
void reseal(std::vector<uint8_t>& b) {
  const uint64_t sum = binaryFileChecksum(b, kProbeFileChecksumOffset, kProbeFileHeaderSize);
  std::memcpy(b.data() + kProbeFileChecksumOffset, &sum, 8);
}

bool allFinite(const ShL2Rgb& sh) {
  for (const glm::vec3& c : sh.c)
    if (!std::isfinite(c.x) || !std::isfinite(c.y) || !std::isfinite(c.z)) return false;
  return true;
}

template <typename T>
bool sameBits(const std::vector<T>& a, const std::vector<T>& b) {
  return a.size() == b.size() && (a.empty() || std::memcmp(a.data(), b.data(), sizeof(T) * a.size()) == 0);
}

TEST(ProbeSunFile, Version4RoundTripIsBitExact) {
  const ProbeSet s = smallSetWithSun();
  ASSERT_TRUE(validateProbeSet(s, "sun").ok()) << validateProbeSet(s, "sun").error();
  ProbeSet plain = s;
  plain.sun = ProbeSunLayer{};
  const std::vector<uint8_t> bytes = serializeProbeSet(s);
  uint32_t version = 0;
  std::memcpy(&version, bytes.data() + 4, 4);
  EXPECT_EQ(version, 4u);
  // The block after the version 3 payload: sunLight, the lobe, a share per probe, the ramp
  // count and the ramps; without a layer, sunLight -1 alone.
  const size_t v3 = serializeProbeSet(s, 3).size();
  const size_t np = size_t(s.probeCount()), inner = size_t(s.innerCellCount);
  EXPECT_EQ(bytes.size(), v3 + 4 + 108 + 4 * np + 4 + 16 * inner);
  EXPECT_EQ(serializeProbeSet(plain).size(), v3 + 4);
  int32_t light = 0;
  std::memcpy(&light, bytes.data() + v3, 4);
  EXPECT_EQ(light, 2);
  const std::string path = tempPath("sun.kprobe");
  ASSERT_TRUE(writeProbeFile(s, path).ok());
  for (const Result<ProbeSet>& r : {parseProbeSet(bytes, "v4"), loadProbeFile(path)}) {
    ASSERT_TRUE(r.ok()) << r.error();
    EXPECT_EQ(r->sun.light, 2);
    EXPECT_EQ(std::memcmp(&r->sun.sh, &s.sun.sh, sizeof(ShL2Rgb)), 0);
    EXPECT_TRUE(sameBits(r->sun.visibility, s.sun.visibility));
    EXPECT_TRUE(sameBits(r->sun.ramps, s.sun.ramps));  // the NaN payloads too
    EXPECT_EQ(std::bit_cast<uint32_t>(r->sun.ramps[1].z), 0x7fc01234u);
    EXPECT_EQ(serializeProbeSet(*r), bytes);
    // The loaded layer blends as the original does, bit for bit, inside and outside the hull.
    std::mt19937 rng(31);
    std::uniform_real_distribution<float> u(-0.5f, 1.5f);
    for (int i = 0; i < 200; ++i) {
      const glm::vec3 p(u(rng), u(rng), u(rng));
      const ShL2Rgb a = interpolateProbes(s, locateProbe(s, p));
      const ShL2Rgb b = interpolateProbes(*r, locateProbe(*r, p));
      EXPECT_EQ(std::memcmp(&a, &b, sizeof(ShL2Rgb)), 0) << i;
    }
  }
  std::filesystem::remove(path);
  // A layer without ramps (dimension 3 too: the bake may fit none) round-trips likewise.
  ProbeSet noRamps = s;
  noRamps.sun.ramps.clear();
  const std::vector<uint8_t> b2 = serializeProbeSet(noRamps);
  EXPECT_EQ(b2.size(), v3 + 4 + 108 + 4 * np + 4);
  const Result<ProbeSet> r2 = parseProbeSet(b2, "v4");
  ASSERT_TRUE(r2.ok()) << r2.error();
  EXPECT_EQ(r2->sun.light, 2);
  EXPECT_TRUE(sameBits(r2->sun.visibility, s.sun.visibility));
  EXPECT_TRUE(r2->sun.ramps.empty());
}

// Written as version 3 (what older readers take), the layer is left out, as version 2 leaves
// out the visibility; the new reader gives such a file no layer and the plain blend.
TEST(ProbeSunFile, Version3FileHasNoSunLayer) {
  const ProbeSet s = smallSetWithSun();
  ProbeSet plain = s;
  plain.sun = ProbeSunLayer{};
  const std::vector<uint8_t> v3 = serializeProbeSet(s, 3);
  uint32_t version = 0;
  std::memcpy(&version, v3.data() + 4, 4);
  EXPECT_EQ(version, 3u);
  EXPECT_EQ(v3, serializeProbeSet(plain, 3));
  EXPECT_EQ(v3.size() + 4, serializeProbeSet(plain).size());
  const Result<ProbeSet> r = parseProbeSet(v3, "v3");
  ASSERT_TRUE(r.ok()) << r.error();
  EXPECT_TRUE(r->sun.empty());
  EXPECT_EQ(r->sun.light, -1);
  EXPECT_TRUE(r->sun.visibility.empty() && r->sun.ramps.empty());
  EXPECT_EQ(serializeProbeSet(*r, 3), v3);
  EXPECT_EQ(serializeProbeSet(*r), serializeProbeSet(plain));
  int differ = 0;
  std::mt19937 rng(32);
  std::uniform_real_distribution<float> u(0.0f, 0.9f);
  for (int i = 0; i < 200; ++i) {
    const glm::vec3 p(u(rng), u(rng), u(rng));
    const ShL2Rgb a = interpolateProbes(*r, locateProbe(*r, p));
    const ShL2Rgb b = interpolateProbes(plain, locateProbe(plain, p));
    EXPECT_EQ(std::memcmp(&a, &b, sizeof(ShL2Rgb)), 0) << i;
    // The layer applies to visibility-weighted blends only (these sets have no maps, so the
    // flag stands in for one whose probes all see the point); the plain blend ignores it.
    ProbeLocation seen = locateProbe(s, p);
    const ShL2Rgb plainBlend = interpolateProbes(s, seen);
    EXPECT_EQ(std::memcmp(&a, &plainBlend, sizeof(ShL2Rgb)), 0) << i;
    seen.visibilityWeighted = true;
    const ShL2Rgb c = interpolateProbes(s, seen);
    differ += std::memcmp(&a, &c, sizeof(ShL2Rgb)) != 0;
  }
  EXPECT_GT(differ, 10) << "the layer does change the blend where it has a ramp";
}

// Each of validateProbeSet's rules for the layer, in memory and (where the format can carry
// the fault) through a file whose checksum is valid: rejected, and the message names the field.
TEST(ProbeSunFile, EveryLayerRuleIsCheckedAndNamed) {
  const ProbeSet good = smallSetWithSun();
  auto check = [&](auto change, const std::string& field, bool viaFile = true) {
    ProbeSet s = good;
    change(s);
    const Status st = validateProbeSet(s, "mem");
    EXPECT_FALSE(st.ok()) << field;
    if (!st.ok()) {
      EXPECT_EQ(st.error().rfind("mem: " + field, 0), 0u) << st.error();
    }
    if (viaFile) {
      const std::string e = parseError(serializeProbeSet(s));
      EXPECT_EQ(e.rfind("bad.kprobe: ", 0), 0u) << e;
      EXPECT_NE(e.find(field), std::string::npos) << field << ": " << e;
    }
  };
  for (float bad : {-0.01f, 1.01f, std::nanf(""), std::numeric_limits<float>::infinity()}) {
    check([&](ProbeSet& s) { s.sun.visibility[3] = bad; }, "sun.visibility[3]: not in [0, 1]");
  }
  check([](ProbeSet& s) { s.sun.visibility[0] = -0.0f, s.sun.visibility[4] = 2.0f; },
        "sun.visibility[4]: not in [0, 1]");
  // Sizes (a file cannot hold these: its counts fix them; the reader names the size).
  check([](ProbeSet& s) { s.sun.visibility.pop_back(); },
        "sun.visibility: size differs from positions", false);
  check([](ProbeSet& s) { s.sun.ramps.push_back(glm::vec4(0.5f)); },
        "sun.ramps: size differs from innerCellCount", false);
  check([](ProbeSet& s) { s.sun.ramps.pop_back(); }, "sun.ramps: size differs from innerCellCount",
        false);
  check([](ProbeSet& s) { s.sun.sh.c[4].g = std::nanf(""); }, "sun.sh[4]: not finite");
  check([](ProbeSet& s) { s.sun.sh.c[0].r = -std::numeric_limits<float>::infinity(); },
        "sun.sh[0]: not finite");
  // Ramps: four finite values, or x NaN and the rest NaN too; an infinity is neither.
  check([](ProbeSet& s) { s.sun.ramps[1].y = 0.5f; }, "sun.ramps[1]: x is NaN (no ramp)");
  check([](ProbeSet& s) { s.sun.ramps[1].w = 0.0f; }, "sun.ramps[1]: x is NaN (no ramp)");
  check([](ProbeSet& s) { s.sun.ramps[0].w = std::nanf(""); }, "sun.ramps[0]: not finite");
  check([](ProbeSet& s) { s.sun.ramps[0].x = std::numeric_limits<float>::infinity(); },
        "sun.ramps[0]: not finite");
  check([](ProbeSet& s) { s.sun.ramps[1] = glm::vec4(std::numeric_limits<float>::infinity()); },
        "sun.ramps[1]: not finite");
  // No layer: no data. (The writer writes only sunLight then, so this is in memory alone.)
  check([](ProbeSet& s) { s.sun.light = -1, s.sun.ramps.clear(); },
        "sun.visibility: data without a light", false);
  check([](ProbeSet& s) { s.sun.light = -1, s.sun.visibility.clear(); },
        "sun.ramps: data without a light", false);
  check([](ProbeSet& s) { s.sun.light = -2; }, "sun.light: -2 is not a light or -1", false);
  EXPECT_NE(parseError(serializeProbeSet([&] {
              ProbeSet s = good;
              s.sun.light = -2;
              return s;
            }())).find("sunLight: -2 is not a light or -1"),
            std::string::npos);
  // Ramps are for tetrahedra: a planar set (dimension 2) may have a layer but no ramps.
  ProbeSet flat = build(std::vector<glm::vec3>{glm::vec3(0, 0, 0), glm::vec3(1, 0, 0),
                                               glm::vec3(0, 0, 1), glm::vec3(1, 0, 1.2f)},
                        DelaunayBackend::TetGen);
  ASSERT_EQ(flat.dimension, 2);
  flat.sun.light = 0;
  flat.sun.visibility.assign(size_t(flat.probeCount()), 0.5f);
  EXPECT_TRUE(validateProbeSet(flat, "flat").ok());
  EXPECT_TRUE(parseProbeSet(serializeProbeSet(flat), "flat").ok());
  flat.sun.ramps.assign(size_t(flat.innerCellCount), glm::vec4(0.5f));
  EXPECT_NE(validateProbeSet(flat, "flat").error().find("sun.ramps: ramps in dimension 2"),
            std::string::npos);
  EXPECT_NE(parseError(serializeProbeSet(flat)).find("sunRampCount: " +
                                                    std::to_string(flat.innerCellCount) +
                                                    " ramps in dimension 2"),
            std::string::npos)
      << parseError(serializeProbeSet(flat));
  // What is allowed: any light index >= 0, shares at 0 and 1 exactly, no ramps, all NaN ramps.
  ProbeSet ok = good;
  ok.sun.light = 1 << 30;
  ok.sun.visibility = {0.0f, 1.0f, 0.0f, 1.0f, -0.0f};
  EXPECT_TRUE(parseProbeSet(serializeProbeSet(ok), "ok").ok());
  ok.sun.ramps.assign(ok.sun.ramps.size(), glm::vec4(std::nanf("")));
  EXPECT_TRUE(parseProbeSet(serializeProbeSet(ok), "ok").ok());
}

// Truncated and hostile sun blocks: every cut is named as truncated; a sunLight or rampCount
// that asks for more than the file holds gets a message naming it, decided from the counts
// against the file's size before anything is read (the header's counts bound the file: the
// reader never allocates beyond it); bit flips in the block never crash, and what is accepted
// blends to finite values.
TEST(ProbeSunFile, TruncatedAndHostileSunBlocksAreNamed) {
  const ProbeSet s = smallSetWithSun();
  const std::vector<uint8_t> good = serializeProbeSet(s);
  const size_t block = serializeProbeSet(s, 3).size();  // offset of sunLight
  const size_t rampCountAt = block + 4 + 108 + 4 * size_t(s.probeCount());
  for (size_t n = block - 8; n < good.size(); ++n) {
    const std::vector<uint8_t> cut(good.begin(), good.begin() + long(n));
    const std::string e = parseError(cut);
    ASSERT_EQ(e.rfind("bad.kprobe: size: file has " + std::to_string(n), 0), 0u) << n << ": " << e;
    EXPECT_NE(e.find("truncated"), std::string::npos) << n << ": " << e;
  }
  auto patched = [&](size_t at, uint32_t value, std::vector<uint8_t> b) {
    std::memcpy(b.data() + at, &value, 4);
    reseal(b);
    return b;
  };
  // rampCount neither 0 nor innerCellCount, up to 2^32 - 1.
  for (uint32_t count : {1u, uint32_t(s.innerCellCount) + 1, 1u << 28, 0xFFFFFFFFu}) {
    const std::string e = parseError(patched(rampCountAt, count, good));
    EXPECT_NE(e.find("sunRampCount: " + std::to_string(count) + " is neither 0 nor "
                     "innerCellCount (" + std::to_string(s.innerCellCount) + ")"),
              std::string::npos)
        << e;
  }
  // rampCount 0 with the ramps still there: trailing data.
  EXPECT_NE(parseError(patched(rampCountAt, 0, good)).find("trailing data"), std::string::npos);
  // A light on a file that ends after sunLight -1, up to INT32_MAX: truncated, not read.
  ProbeSet plain = s;
  plain.sun = ProbeSunLayer{};
  for (uint32_t light : {0u, 7u, 0x7FFFFFFFu}) {
    const std::string e = parseError(patched(block, light, serializeProbeSet(plain)));
    EXPECT_NE(e.find("sunLight " + std::to_string(light) + " needs at least"), std::string::npos)
        << e;
    EXPECT_NE(e.find("truncated"), std::string::npos) << e;
  }
  EXPECT_NE(parseError(patched(block, 0x80000000u, good)).find("sunLight: -2147483648"),
            std::string::npos);
  // sunLight -1 on a full layer: trailing data.
  EXPECT_NE(parseError(patched(block, 0xFFFFFFFFu, good)).find("trailing data"),
            std::string::npos);
  // Huge counts in the header of a version 4 file are refused from the header (the file's
  // size cannot match them), through the file reader too, and so is a file longer than the
  // largest sun block its counts allow.
  const std::vector<uint8_t> hugeProbes = patched(12, 1u << 25, good);
  EXPECT_NE(parseError(hugeProbes).find("size: file has"), std::string::npos);
  std::vector<uint8_t> longer = good;
  longer.resize(good.size() + 64, 0);
  EXPECT_NE(parseError(longer).find("trailing data"), std::string::npos) << parseError(longer);
  const std::string path = tempPath("hostile_sun.kprobe");
  for (const std::vector<uint8_t>& b :
       {hugeProbes, longer, patched(rampCountAt, 0xFFFFFFFFu, good)}) {
    std::FILE* f = std::fopen(path.c_str(), "wb");
    std::fwrite(b.data(), 1, b.size(), f);
    std::fclose(f);
    const Result<ProbeSet> r = loadProbeFile(path);
    ASSERT_FALSE(r.ok());
    EXPECT_EQ(r.error().rfind(path + ": ", 0), 0u) << r.error();
  }
  std::filesystem::remove(path);
  // Bit flips in the block with the checksum resealed: caught, or harmless to the blend.
  std::mt19937 rng(33);
  int accepted = 0;
  for (int i = 0; i < 3000; ++i) {
    std::vector<uint8_t> b = good;
    const int flips = 1 + int(rng() % 3);
    for (int f = 0; f < flips; ++f) b[block + rng() % (good.size() - block)] ^= uint8_t(1u << (rng() % 8));
    reseal(b);
    const Result<ProbeSet> r = parseProbeSet(b, "fuzz");
    if (!r.ok()) continue;
    ++accepted;
    for (const glm::vec3 p : {glm::vec3(0.2f, 0.2f, 0.2f), glm::vec3(0.6f, 0.5f, 0.55f),
                              glm::vec3(3.0f, -1.0f, 0.5f)}) {
      const ShL2Rgb sh = interpolateProbes(*r, locateProbe(*r, p));
      ASSERT_TRUE(allFinite(sh)) << i;
    }
  }
  EXPECT_GT(accepted, 100);  // flips in the values that stay valid
}

}  // namespace
// The C batch (kiln_probes_sample_batch_blend) takes its cells from the interleaved C++
// batch a chunk at a time and weights each point with its own normal: against single C
// lookups with the same normals, on a file with visibility maps (so the normals matter), over
// several chunks, with and without hints.
TEST(ProbeCApi, BatchWithNormalsGivesTheSingleLookupsResults) {
  ProbeSet s = build(cubeProbes(1500, 71), DelaunayBackend::Cgal);
  s.visibility.resolution = kMinVisibilityResolution;
  s.visibility.maxDistance.assign(size_t(s.probeCount()), 1.0f);
  s.visibility.moments.resize(size_t(s.probeCount()) * s.visibility.valuesPerProbe());
  std::mt19937 rng(72);
  std::uniform_int_distribution<int> depth(2000, 40000);
  for (size_t t = 0; t < s.visibility.moments.size(); t += kVisibilityValuesPerTexel) {
    const int mu = depth(rng);
    s.visibility.moments[t] = uint16_t(mu);
    s.visibility.moments[t + 1] = uint16_t(mu / 20);
    s.visibility.moments[t + 2] = uint16_t(std::min(65535, mu + mu / 4));
  }
  // A sun layer, so that the single lookups' kiln_probes_sample_sh must carry the location's
  // barycentric coordinates and visibility flag from C to apply it as the batch does.
  s.sun.light = 0;
  s.sun.sh.addSample(glm::normalize(glm::vec3(0.3f, 1.0f, -0.2f)), glm::vec3(3.0f), 1.0f);
  std::uniform_real_distribution<float> share(0.0f, 1.0f), rampValue(-2.0f, 3.0f);
  for (int32_t i = 0; i < s.probeCount(); ++i) s.sun.visibility.push_back(share(rng));
  for (int32_t c = 0; c < s.innerCellCount; ++c)
    s.sun.ramps.push_back(c % 2 ? glm::vec4(std::numeric_limits<float>::quiet_NaN())
                                : glm::vec4(rampValue(rng), rampValue(rng), rampValue(rng),
                                            rampValue(rng)));
  ASSERT_TRUE(validateProbeSet(s, "c_batch").ok()) << validateProbeSet(s, "c_batch").error();
  const std::string path = tempPath("c_batch.kprobe");
  ASSERT_TRUE(writeProbeFile(s, path).ok());
  kiln_probes* probes = nullptr;
  ASSERT_EQ(kiln_probes_load(path.c_str(), &probes), KILN_OK) << kiln_last_error();
  std::filesystem::remove(path);
  std::uniform_real_distribution<float> u(-1.3f, 1.3f);
  std::normal_distribution<float> g;
  const size_t n = 300;  // several chunks and a partial one
  std::vector<float> positions(3 * n), normals(3 * n);
  std::vector<int32_t> hints(n);
  for (size_t i = 0; i < n; ++i) {
    const glm::vec3 d = glm::normalize(glm::vec3(g(rng), g(rng), g(rng)));
    for (int a = 0; a < 3; ++a) {
      positions[3 * i + size_t(a)] = u(rng);
      normals[3 * i + size_t(a)] = d[a];
    }
    hints[i] = i % 2 ? int32_t(i * 37 % size_t(s.cellCount())) : -1;
  }
  kiln_probe_blend blend;
  ASSERT_EQ(kiln_probe_blend_defaults(&blend), KILN_OK);
  int hidden = 0, weighted = 0, layered = 0;
  for (bool withHints : {false, true}) {
    std::vector<int32_t> h = hints;
    std::vector<kiln_probe_location> batch(n);
    std::vector<float> sh(27 * n);
    ASSERT_EQ(kiln_probes_sample_batch_blend(probes, n, positions.data(), normals.data(), &blend,
                                             withHints ? h.data() : nullptr, batch.data(),
                                             sh.data()),
              KILN_OK)
        << kiln_last_error();
    for (size_t i = 0; i < n; ++i) {
      kiln_probe_blend one = blend;
      std::memcpy(one.normal, &normals[3 * i], sizeof(one.normal));
      kiln_probe_location loc;
      ASSERT_EQ(kiln_probes_locate_blend(probes, &positions[3 * i], withHints ? hints[i] : -1,
                                         &one, &loc),
                KILN_OK);
      float ref[27];
      ASSERT_EQ(kiln_probes_sample_sh(probes, &loc, ref), KILN_OK);
      ASSERT_EQ(batch[i].cell, loc.cell) << i;
      if (withHints) {
        ASSERT_EQ(h[i], loc.cell) << i;
      }
      for (int k = 0; k < 4; ++k) {
        ASSERT_EQ(batch[i].probes[k], loc.probes[k]) << i;
        ASSERT_EQ(batch[i].weights[k], loc.weights[k]) << i;
        ASSERT_EQ(batch[i].barycentric[k], loc.barycentric[k]) << i;
        hidden += loc.weights[k] != loc.barycentric[k];
      }
      for (int k = 0; k < 27; ++k) ASSERT_EQ(sh[27 * i + size_t(k)], ref[k]) << i;
      ASSERT_EQ(batch[i].visibility_weighted, loc.visibility_weighted) << i;
      weighted += loc.visibility_weighted != 0;
      // The same location with the flag cleared: the plain blend's SH, no layer.
      kiln_probe_location plain = loc;
      plain.visibility_weighted = 0;
      float noLayer[27];
      ASSERT_EQ(kiln_probes_sample_sh(probes, &plain, noLayer), KILN_OK);
      layered += std::memcmp(noLayer, ref, sizeof(ref)) != 0;
    }
  }
  EXPECT_GT(hidden, int(n) / 4) << "the visibility weighting changes weights";
  EXPECT_GT(weighted, int(n)) << "inside the hull every location is visibility-weighted";
  EXPECT_GT(layered, int(n) / 4) << "the sun layer changes the blend in cells with a ramp";
  kiln_probes_release(probes);
}

}  // namespace kiln
