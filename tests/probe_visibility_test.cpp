// probe_visibility_test.cpp: per-probe visibility (kiln/probe_visibility.h): the octahedral
// map, the Chebyshev weight and the visibility-weighted blend, maps baked from a scene, and the
// .kprobe version 3 block.
#include "kiln/probe_visibility.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <limits>
#include <memory>
#include <random>
#include <span>
#include <thread>
#include <vector>

#include "kiln/probe_runtime.h"
#include "kiln/probe_set.h"
#include "probes/probe_baker.h"
#include "probes/tetrahedralize.h"
#include "tests/test_util.h"

namespace kiln {
namespace {

// ---- helpers ----------------------------------------------------------------------------

uint16_t unorm16(double v) { return uint16_t(std::lround(std::clamp(v, 0.0, 1.0) * 65535.0)); }

// A map whose every texel holds mean `mean` (unorm16) and mean square `meanSquare`.
std::vector<uint16_t> constantMap(int32_t r, uint16_t mean, uint16_t meanSquare) {
  std::vector<uint16_t> m(2 * size_t(r) * size_t(r));
  for (size_t t = 0; t < m.size(); t += 2) {
    m[t] = mean;
    m[t + 1] = meanSquare;
  }
  return m;
}

// The map of a probe with a wall `wall` metres away in every direction (no spread: the mean
// square is the squared stored mean, to unorm16 rounding), for maxDistance d.
std::vector<uint16_t> wallMap(int32_t r, float wall, float d) {
  const uint16_t mean = unorm16(wall / d);
  const double m = mean / 65535.0;
  return constantMap(r, mean, unorm16(m * m));
}

// The map of a probe that sees nothing within maxDistance.
std::vector<uint16_t> openMap(int32_t r) { return constantMap(r, 65535, 65535); }

// The visibility probeVisibility must give for a map of mean `m`, mean square `m2` (both as
// fractions of D), for a point `length` metres from the probe: the file comment's formula in
// double.
double chebyshev(double m, double m2, double d, double length, const ProbeBlendSettings& s) {
  if (!(length > 0.0)) return 1.0;
  const double x = std::clamp((length - s.distanceBias) / d, 0.0, 1.0);
  if (x <= m) return 1.0;
  const double sigma = s.minSigma / d;
  const double variance = std::max(m2 - m * m, sigma * sigma);
  const double c = variance / (variance + (x - m) * (x - m));
  return std::max(c * c * c, double(kVisibilityFloor));
}

glm::vec2 texelCentre(int32_t i, int32_t j, int32_t r) {
  return glm::vec2((float(i) + 0.5f) * 2.0f / float(r) - 1.0f,
                   (float(j) + 0.5f) * 2.0f / float(r) - 1.0f);
}

// A point of the octahedral map's plane beyond [-1, 1]^2 folded back onto the map the way the
// footprint wraps texels: across u = +-1 the point mirrors v, across v = +-1 it mirrors u.
glm::vec2 wrapUv(glm::vec2 uv) {
  if (uv.x > 1.0f || uv.x < -1.0f) uv = glm::vec2((uv.x > 0.0f ? 2.0f : -2.0f) - uv.x, -uv.y);
  if (uv.y > 1.0f || uv.y < -1.0f) uv = glm::vec2(-uv.x, (uv.y > 0.0f ? 2.0f : -2.0f) - uv.y);
  return uv;
}

// Directions whose rays can reach texel (i, j)'s moments: the bilinear footprint gives a ray
// weight in every texel whose centre is less than one texel from the ray's point of the map,
// i.e. the square of side 4 / R around the centre, wrapped across the map's edges. Sampled on
// a grid.
std::vector<glm::vec3> footprintDirections(int32_t i, int32_t j, int32_t r) {
  const glm::vec2 c = texelCentre(i, j, r);
  const float h = 2.0f / float(r);
  std::vector<glm::vec3> out;
  for (int a = -16; a <= 16; ++a) {
    for (int b = -16; b <= 16; ++b)
      out.push_back(octahedralDecode(wrapUv(c + h * glm::vec2(a, b) / 16.0f)));
  }
  return out;
}

// Recomputes a .kprobe image's checksum after its bytes were patched, as serializeProbeSet
// computes it, so the reader reports the patched field and not "checksum".
void reseal(std::vector<uint8_t>& b) {
  uint64_t sum = fnv1a64(std::span<const uint8_t>(b.data(), 64));
  sum = fnv1a64(
      std::span<const uint8_t>(b.data() + kProbeFileHeaderSize, b.size() - kProbeFileHeaderSize),
      sum);
  std::memcpy(b.data() + 64, &sum, 8);
}

std::string parseError(const std::vector<uint8_t>& bytes) {
  Result<ProbeSet> r = parseProbeSet(bytes, "bad.kprobe");
  return r.ok() ? std::string("(accepted)") : r.error();
}

// ---- octahedral map ---------------------------------------------------------------------

// Encoding then decoding a unit direction gives it back (the map is a bijection of the sphere).
TEST(Octahedral, RoundTripsEveryDirection) {
  std::mt19937 rng(7);
  std::normal_distribution<float> n;
  for (int i = 0; i < 10000; ++i) {
    const glm::vec3 d = glm::normalize(glm::vec3(n(rng), n(rng), n(rng)));
    const glm::vec2 uv = octahedralEncode(d);
    EXPECT_LE(std::fabs(uv.x), 1.0f);
    EXPECT_LE(std::fabs(uv.y), 1.0f);
    const glm::vec3 back = octahedralDecode(uv);
    EXPECT_NEAR(glm::dot(back, d), 1.0f, 1e-5f) << i;
  }
}

// Bilinear weights are >= 0 and sum to 1 and every texel is in the map, anywhere on it:
// random points, the edges and the corners, for even and odd sides.
TEST(Octahedral, FootprintWeightsSumToOneAndTexelsAreInTheMap) {
  std::mt19937 rng(8);
  std::uniform_real_distribution<float> u(-1.0f, 1.0f);
  for (int32_t r : {kMinVisibilityResolution, 5, 16, kMaxVisibilityResolution}) {
    std::vector<glm::vec2> points;
    for (int i = 0; i < 2000; ++i) points.emplace_back(u(rng), u(rng));
    for (float t : {-1.0f, -0.5f, 0.0f, 0.3f, 1.0f}) {
      points.emplace_back(t, 1.0f);
      points.emplace_back(t, -1.0f);
      points.emplace_back(1.0f, t);
      points.emplace_back(-1.0f, t);
    }
    // Not on the map at all (callers pass encoded unit vectors, but the function is public):
    // still four texels of the map, not an out-of-range read.
    const float nan = std::nanf(""), inf = std::numeric_limits<float>::infinity();
    for (const glm::vec2 odd : {glm::vec2(nan, 0.2f), glm::vec2(0.2f, nan), glm::vec2(nan, nan),
                                glm::vec2(inf, -inf), glm::vec2(3.0f, -7.0f)})
      points.push_back(odd);
    for (const glm::vec2 uv : points) {
      const OctahedralFootprint f = octahedralFootprint(uv, r);
      float sum = 0.0f;
      for (int k = 0; k < 4; ++k) {
        EXPECT_GE(f.weight[k], 0.0f);
        EXPECT_GE(f.texel[k], 0);
        EXPECT_LT(f.texel[k], r * r);
        sum += f.weight[k];
      }
      EXPECT_NEAR(sum, 1.0f, 1e-6f) << uv.x << " " << uv.y;
    }
  }
}

// A smooth function of direction stored at the texel centres and sampled with the footprint
// is continuous across every seam of the map: the points (1 - e, t) and (1 - e, -t) lie on
// either side of the fold u = 1 (they decode to directions 2e apart in y), likewise for the
// other three edges, and the four corners (+-(1 - e), +-(1 - e)) all surround -z. Their
// samples differ by at most the map's slope times their distance, so by O(e): the bound is
// the largest difference between any two texels divided by a texel's width (2 / R), times
// the distance 2e between the points in the unfolded map. Without the wrap the two sides read
// texels half the map apart and differ by O(1).
TEST(Octahedral, SampledFunctionIsContinuousAcrossSeams) {
  for (int32_t r : {5, 16}) {
    auto f = [](glm::vec3 d) { return 0.3f + 0.5f * d.x - 0.2f * d.y + 0.7f * d.z + d.x * d.z; };
    std::vector<float> map(size_t(r) * size_t(r));
    float lo = 1e9f, hi = -1e9f;
    for (int32_t j = 0; j < r; ++j) {
      for (int32_t i = 0; i < r; ++i) {
        map[size_t(j * r + i)] = f(octahedralDecode(texelCentre(i, j, r)));
        lo = std::min(lo, map[size_t(j * r + i)]);
        hi = std::max(hi, map[size_t(j * r + i)]);
      }
    }
    auto sample = [&](glm::vec2 uv) {
      const OctahedralFootprint fp = octahedralFootprint(uv, r);
      float v = 0.0f;
      for (int k = 0; k < 4; ++k) v += fp.weight[k] * map[size_t(fp.texel[k])];
      return v;
    };
    const float slope = (hi - lo) / (2.0f / float(r));
    for (float e : {1e-2f, 1e-3f, 1e-4f}) {
      const float bound = slope * 2.0f * e * 1.01f + 1e-6f;
      for (float t : {0.05f, 0.3f, 0.55f, 0.8f, 0.97f}) {
        const std::pair<glm::vec2, glm::vec2> sides[] = {
            {{1.0f - e, t}, {1.0f - e, -t}},
            {{-1.0f + e, t}, {-1.0f + e, -t}},
            {{t, 1.0f - e}, {-t, 1.0f - e}},
            {{t, -1.0f + e}, {-t, -1.0f + e}},
        };
        for (const auto& [a, b] : sides) {
          // The two points are the same direction to O(e): a seam, not two far-apart places.
          EXPECT_LT(glm::length(octahedralDecode(a) - octahedralDecode(b)), 4.0f * e);
          EXPECT_LE(std::fabs(sample(a) - sample(b)), bound)
              << "R " << r << " e " << e << " at (" << a.x << ", " << a.y << ")";
        }
      }
      const glm::vec2 corners[] = {{1.0f - e, 1.0f - e},
                                   {-1.0f + e, 1.0f - e},
                                   {1.0f - e, -1.0f + e},
                                   {-1.0f + e, -1.0f + e}};
      for (const glm::vec2 a : corners) {
        for (const glm::vec2 b : corners) {
          EXPECT_LE(std::fabs(sample(a) - sample(b)), 1.5f * bound) << "R " << r << " e " << e;
        }
      }
    }
  }
}

// ---- the Chebyshev weight ---------------------------------------------------------------

// A map whose every texel says "a wall at distance m D": the point is visible (1) up to
// m D + distanceBias, and beyond it gets the exact Chebyshev value with sigma at its floor
// minSigma / D, cubed; non-increasing in distance; never below kVisibilityFloor; 1 at the probe.
TEST(ProbeVisibility, ConstantMapGivesTheChebyshevValue) {
  const int32_t r = 8;
  const float d = 2.0f;
  const ProbeBlendSettings s;
  const std::vector<uint16_t> map = wallMap(r, 0.3f, d);
  const double m = map[0] / 65535.0, m2 = map[1] / 65535.0;
  // The stored mean square is m^2 to unorm16 rounding, far below the variance floor.
  ASSERT_LT(std::fabs(m2 - m * m), 0.5 / 65535.0 + 1e-12);
  ASSERT_LT(0.5 / 65535.0, (s.minSigma / d) * (s.minSigma / d) / 10.0);
  const double edge = m * d + s.distanceBias;  // ~0.32 m
  std::mt19937 rng(9);
  std::normal_distribution<float> g;
  for (int i = 0; i < 200; ++i) {
    const glm::vec3 dir = glm::normalize(glm::vec3(g(rng), g(rng), g(rng)));
    float previous = 1.0f;
    for (int k = 0; k <= 300; ++k) {
      const double length = 0.01 * k;  // 0 to 3 m, through the edge and past D
      const float v = probeVisibility(map, r, d, dir * float(length), s);
      if (length < edge * (1.0 - 1e-4)) {
        EXPECT_EQ(v, 1.0f) << length;
      } else if (length > edge * (1.0 + 1e-4)) {
        const double expected = chebyshev(m, m2, d, length, s);
        EXPECT_NEAR(v, expected, 1e-4 * expected) << length;
      }
      EXPECT_LE(v, previous) << "non-increasing in distance, at " << length;
      EXPECT_GE(v, kVisibilityFloor);
      previous = v;
    }
    // Far beyond the wall the bound is ~3e-12: the floor.
    EXPECT_EQ(probeVisibility(map, r, d, dir * 100.0f, s), kVisibilityFloor);
  }
  EXPECT_EQ(probeVisibility(map, r, d, glm::vec3(0.0f), s), 1.0f);
  // 5 cm past the edge, one direction: (1e-4 / (1e-4 + 0.025^2))^3 = 2.6e-3.
  EXPECT_NEAR(probeVisibility(map, r, d, glm::vec3(0.0f, 0.0f, float(edge + 0.05)), s),
              std::pow(1e-4 / (1e-4 + 0.025 * 0.025), 3.0), 1e-5);
}

// Spread in the stored depths (a texel seeing a slanted surface) widens the test: the
// variance is the stored one when it exceeds the floor.
TEST(ProbeVisibility, StoredVarianceAboveTheFloorIsUsed) {
  const int32_t r = 4;
  const float d = 1.0f;
  const ProbeBlendSettings s;
  const uint16_t mean = unorm16(0.4);
  const double m = mean / 65535.0;
  const uint16_t meanSquare = unorm16(m * m + 0.01);  // sigma = 0.1 >> minSigma / D = 0.02
  const std::vector<uint16_t> map = constantMap(r, mean, meanSquare);
  for (double length : {0.45, 0.5, 0.6, 0.8, 1.0}) {
    const double expected = chebyshev(m, meanSquare / 65535.0, d, length, s);
    EXPECT_NEAR(probeVisibility(map, r, d, glm::vec3(0.0f, float(length), 0.0f), s), expected,
                1e-4 * expected)
        << length;
  }
  // At 0.6 m: x - m = 0.18, (0.01 / (0.01 + 0.0324))^3 = 0.0131 (1.8e-6 with sigma at its floor).
  EXPECT_NEAR(probeVisibility(map, r, d, glm::vec3(0.0f, 0.6f, 0.0f), s), 0.0131, 2e-4);
}

// ---- the blend --------------------------------------------------------------------------

constexpr float kMaxDistance = 2.0f;
constexpr int32_t kResolution = 8;
constexpr float kWall = 0.3f;

// Nine probes: the corners of [-1, 1]^3 and one near the centre (probe 8), whose map says a
// wall is kWall metres away in every direction; the corners see nothing. Distinct SH per probe.
ProbeSet hiddenCentreSet() {
  std::vector<glm::vec3> pts;
  for (int i = 0; i < 8; ++i) pts.emplace_back(i & 1 ? 1 : -1, i & 2 ? 1 : -1, i & 4 ? 1 : -1);
  pts.emplace_back(0.1f, 0.05f, -0.05f);
  Result<ProbeSet> r = buildProbeTopology(pts);
  EXPECT_TRUE(r.ok()) << r.error();
  ProbeSet s = r.ok() ? std::move(r).value() : ProbeSet{};
  std::mt19937 rng(10);
  std::uniform_real_distribution<float> u(-1.0f, 1.0f);
  for (ShL2Rgb& sh : s.sh)
    for (auto& c : sh.c) c = glm::vec3(u(rng), u(rng), u(rng));
  s.visibility.resolution = kResolution;
  s.visibility.maxDistance.assign(pts.size(), kMaxDistance);
  for (size_t i = 0; i < pts.size(); ++i) {
    const std::vector<uint16_t> m =
        i == 8 ? wallMap(kResolution, kWall, kMaxDistance) : openMap(kResolution);
    s.visibility.moments.insert(s.visibility.moments.end(), m.begin(), m.end());
  }
  EXPECT_TRUE(validateProbeSet(s, "hiddenCentreSet").ok());
  return s;
}

std::vector<glm::vec3> pointsInCube(int n, uint32_t seed) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<float> u(-0.98f, 0.98f);
  std::vector<glm::vec3> p(static_cast<size_t>(n));
  for (auto& v : p) v = glm::vec3(u(rng), u(rng), u(rng));
  return p;
}

ProbeBlendSettings plainBlend() {
  ProbeBlendSettings b;
  b.visibility = false;
  return b;
}

// With visibility the weights are the barycentric ones times each probe's visibility,
// renormalized: here the corners see everything (v = 1) and probe 8 has the Chebyshev value of
// its wall, so weight k = b_k v_k / sum_j b_j v_j in closed form. Without visibility (the
// setting, or a set that has none) the weights are exactly the barycentric ones.
TEST(ProbeBlend, WeightsAreBarycentricTimesVisibilityRenormalized) {
  const ProbeSet s = hiddenCentreSet();
  ProbeSet none = s;
  none.visibility = ProbeVisibility{};
  const std::vector<uint16_t> wall = wallMap(kResolution, kWall, kMaxDistance);
  const double m = wall[0] / 65535.0, m2 = wall[1] / 65535.0;
  const ProbeBlendSettings blend;
  int hidden = 0, seen = 0;
  for (const glm::vec3 p : pointsInCube(3000, 11)) {
    const ProbeLocation plain = locateProbe(s, p, -1, plainBlend());
    const ProbeLocation noData = locateProbe(none, p);
    const ProbeLocation loc = locateProbe(s, p, -1, blend);
    ASSERT_EQ(loc.cell, plain.cell);
    ASSERT_EQ(noData.cell, plain.cell);
    EXPECT_EQ(plain.weights, plain.barycentric);
    EXPECT_EQ(noData.weights, plain.weights);
    EXPECT_EQ(loc.barycentric, plain.weights);
    EXPECT_EQ(loc.probes, plain.probes);

    double v[4], sum = 0.0, weightSum = 0.0, b8 = 0.0, distance8 = 0.0;
    for (int k = 0; k < 4; ++k) {
      const bool centre = loc.probes[k] == 8;
      v[k] = 1.0;
      if (centre && loc.barycentric[k] != 0.0f) {
        distance8 = glm::length(p - s.positions[8]);
        v[k] = chebyshev(m, m2, kMaxDistance, distance8, blend);
        b8 += loc.barycentric[k];
      }
      sum += loc.barycentric[k] * v[k];
    }
    for (int k = 0; k < 4; ++k) {
      const double expected = loc.barycentric[k] * v[k] / sum;
      EXPECT_GE(loc.weights[k], 0.0f);
      EXPECT_NEAR(loc.weights[k], expected, 1e-6 + 1e-4 * expected) << k;
      weightSum += loc.weights[k];
    }
    EXPECT_NEAR(weightSum, 1.0, 1e-6);
    if (b8 > 0.0 && distance8 >= 0.5 && b8 <= 0.9) {
      // Beyond the wall (v8 <= 1.8e-6 at 0.5 m) probe 8 drops out: weight <= 0.9 v8 / 0.1.
      ++hidden;
      for (int k = 0; k < 4; ++k) {
        if (loc.probes[k] == 8) {
          EXPECT_LT(loc.weights[k], 2e-5f) << distance8;
        }
      }
    }
    if (b8 > 0.0 && distance8 < 0.3f) {
      // In front of it every probe sees the point: the barycentric blend.
      ++seen;
      for (int k = 0; k < 4; ++k) EXPECT_NEAR(loc.weights[k], loc.barycentric[k], 1e-6f);
    }
  }
  EXPECT_GT(hidden, 500);
  EXPECT_GT(seen, 5);
}

// When no probe of the cell sees the point, every v is at the floor and the blend is the
// barycentric one (to float rounding of b * floor / sum).
TEST(ProbeBlend, AllHiddenGivesTheBarycentricWeights) {
  ProbeSet s = hiddenCentreSet();
  // Every probe behind a wall 0.1 m away: beyond 0.45 m, (1e-4 / (1e-4 + 0.165^2))^3 = 5e-8.
  s.visibility.moments.clear();
  for (int32_t i = 0; i < s.probeCount(); ++i) {
    const std::vector<uint16_t> m = wallMap(kResolution, 0.1f, kMaxDistance);
    s.visibility.moments.insert(s.visibility.moments.end(), m.begin(), m.end());
  }
  int tested = 0;
  for (const glm::vec3 p : pointsInCube(2000, 12)) {
    const ProbeLocation loc = locateProbe(s, p);
    float nearest = 1e9f;
    for (int k = 0; k < 4; ++k)
      if (loc.barycentric[k] != 0.0f)
        nearest = std::min(nearest, glm::length(p - s.positions[size_t(loc.probes[k])]));
    if (nearest < 0.45f) continue;
    ++tested;
    for (int k = 0; k < 4; ++k) EXPECT_NEAR(loc.weights[k], loc.barycentric[k], 1e-6f);
  }
  EXPECT_GT(tested, 300);
}

// The blend is continuous in the point (the cut-off behind the wall is steep, ~1/minSigma, but
// finite): points 1e-5 m apart get weights within 1e-2 of each other.
TEST(ProbeBlend, WeightsAreContinuous) {
  const ProbeSet s = hiddenCentreSet();
  std::mt19937 rng(13);
  std::normal_distribution<float> g;
  double worst = 0.0;
  for (const glm::vec3 p : pointsInCube(3000, 14)) {
    const glm::vec3 step = 1e-5f * glm::normalize(glm::vec3(g(rng), g(rng), g(rng)));
    const ProbeLocation a = locateProbe(s, p), b = locateProbe(s, p + step);
    double wa[9] = {}, wb[9] = {};
    for (int k = 0; k < 4; ++k) {
      wa[a.probes[k]] += a.weights[k];
      wb[b.probes[k]] += b.weights[k];
    }
    for (int i = 0; i < 9; ++i) worst = std::max(worst, std::fabs(wa[i] - wb[i]));
  }
  EXPECT_LT(worst, 1e-2);
}

// Batch forms with a blend match single lookups; lookups from several threads at once give the
// same bits as one thread.
TEST(ProbeBlend, BatchAndThreadsGiveTheSameAnswers) {
  const ProbeSet s = hiddenCentreSet();
  const std::vector<glm::vec3> points = pointsInCube(2000, 15);
  ProbeBlendSettings blend;
  blend.normal = glm::normalize(glm::vec3(0.3f, -1.0f, 0.2f));
  std::vector<ProbeLocation> expected(points.size());
  for (size_t i = 0; i < points.size(); ++i) expected[i] = locateProbe(s, points[i], -1, blend);
  std::vector<ProbeLocation> batch(points.size());
  std::vector<int32_t> hints(points.size(), -1);
  locateProbes(s, points, hints, batch, blend);
  auto same = [](const ProbeLocation& a, const ProbeLocation& b) {
    return a.cell == b.cell && a.probes == b.probes &&
           std::memcmp(a.weights.data(), b.weights.data(), sizeof(a.weights)) == 0 &&
           std::memcmp(a.barycentric.data(), b.barycentric.data(), sizeof(a.weights)) == 0;
  };
  for (size_t i = 0; i < points.size(); ++i) {
    EXPECT_TRUE(same(batch[i], expected[i])) << i;
    EXPECT_EQ(hints[i], expected[i].cell);
  }
  std::vector<int> mismatches(4, 0);
  std::vector<std::thread> threads;
  for (int t = 0; t < 4; ++t) {
    threads.emplace_back([&, t] {
      int32_t hint = -1;
      for (size_t i = 0; i < points.size(); ++i) {
        const ProbeLocation loc = locateProbe(s, points[i], hint, blend);
        hint = loc.cell;
        mismatches[size_t(t)] += !same(loc, expected[i]);
      }
    });
  }
  for (auto& th : threads) th.join();
  for (int m : mismatches) EXPECT_EQ(m, 0);
}

// ---- maps baked from a scene ------------------------------------------------------------

// A probe h = 0.4 m in front of a large wall (a 100 m double-sided quad perpendicular to the
// centre direction c of one texel T), and three more probes 1 m from it on the far side, along
// an orthonormal basis whose vectors each make the same angle with -c: probe 0's edges are all
// 1 m long and the others' longest is sqrt(2) m, so those are the maxDistances D. Every ray
// that reaches T's moments points within T's footprint, where the wall is between h / D and
// h / (D cos theta_max) away (theta_max: the footprint's largest angle from c), so T's mean lies
// there; texels whose footprint stays below the wall's angle (every hit farther than D) hold
// exactly 1.
TEST(VisibilityBake, MapsHoldTheWallsDistance) {
  const int32_t r = 16;
  const int32_t ti = 9, tj = 6;
  const glm::vec3 c = octahedralDecode(texelCentre(ti, tj, r));
  const float h = 0.4f;
  // An orthonormal basis {a, b, n} with c = -(a + b + n) / sqrt(3).
  glm::vec3 e0 = glm::normalize(
      glm::cross(c, std::fabs(c.x) < 0.9f ? glm::vec3(1, 0, 0) : glm::vec3(0, 1, 0)));
  glm::vec3 e1 = glm::cross(c, e0);
  const glm::vec3 p0(0.2f, 1.0f, -0.3f);
  std::vector<vec3> positions = {p0};
  for (int k = 0; k < 3; ++k) {
    const float phi = 2.0f * 3.14159265f * float(k) / 3.0f;
    // Unit vectors at angle acos(-1/sqrt 3) from c, 120 degrees apart around it: orthonormal.
    const glm::vec3 a =
        -c / std::sqrt(3.0f) + std::sqrt(2.0f / 3.0f) * (std::cos(phi) * e0 + std::sin(phi) * e1);
    positions.push_back(p0 + a);
  }
  Scene scene;
  const uint32_t mat = test::addMaterial(scene, test::lambert(vec3(0.5f), vec3(0.0f), true));
  const glm::vec3 centre = p0 + h * c;
  test::addQuad(scene, "wall", centre - 50.0f * e0 - 50.0f * e1, centre + 50.0f * e0 - 50.0f * e1,
                centre + 50.0f * e0 + 50.0f * e1, centre - 50.0f * e0 + 50.0f * e1, mat);
  scene.updateBounds();
  auto tracer = Tracer::create(scene);
  ASSERT_TRUE(tracer.ok()) << tracer.error();
  ProbeBakeSettings settings;
  settings.rays = 4096;
  settings.bounces = 1;
  settings.visibilityResolution = r;
  settings.threads = 2;
  Result<ProbeSet> set = bakeProbes(scene, **tracer, positions, settings);
  ASSERT_TRUE(set.ok()) << set.error();
  const ProbeVisibility& vis = set->visibility;
  ASSERT_EQ(vis.resolution, r);
  ASSERT_EQ(vis.maxDistance.size(), 4u);
  EXPECT_NEAR(vis.maxDistance[0], 1.0f, 1e-5f);
  for (int k = 1; k < 4; ++k) EXPECT_NEAR(vis.maxDistance[size_t(k)], std::sqrt(2.0f), 1e-5f);
  const float d = vis.maxDistance[0];
  const std::span<const uint16_t> map = vis.probe(0);

  float cosMax = 1.0f;
  for (const glm::vec3 dir : footprintDirections(ti, tj, r))
    cosMax = std::min(cosMax, glm::dot(dir, c));
  ASSERT_GT(cosMax, 0.85f) << "T is an interior texel: its footprint is a narrow cone";
  const double lo = h / d, hi = h / (d * cosMax), q = 1.0 / 65535.0;
  const size_t t = 2 * size_t(tj * r + ti);
  EXPECT_GE(map[t] / 65535.0, lo - q);
  EXPECT_LE(map[t] / 65535.0, hi + q);
  EXPECT_GE(map[t + 1] / 65535.0, lo * lo - q);
  EXPECT_LE(map[t + 1] / 65535.0, hi * hi + q);

  // Every texel: its rays hit the wall's plane at h / cos(angle to c) when the cosine is > 0,
  // so its mean lies between the distances of its footprint's largest and smallest cosines
  // (clamped to D; a ray that misses counts as D). Texels whose footprint's largest cosine
  // is below h / D see nothing within D: exactly 1.
  int far = 0;
  for (int32_t j = 0; j < r; ++j) {
    for (int32_t i = 0; i < r; ++i) {
      float cosBest = -1.0f, cosWorst = 1.0f;
      for (const glm::vec3 dir : footprintDirections(i, j, r)) {
        cosBest = std::max(cosBest, glm::dot(dir, c));
        cosWorst = std::min(cosWorst, glm::dot(dir, c));
      }
      auto along = [&](float cosine) {
        return cosine > 0.0f ? std::min(1.0, h / (d * double(cosine))) : 1.0;
      };
      const size_t k = 2 * size_t(j * r + i);
      EXPECT_GE(map[k] / 65535.0, along(cosBest) - q) << i << " " << j;
      EXPECT_LE(map[k] / 65535.0, along(cosWorst) + q) << i << " " << j;
      if (cosBest < h / d) {
        ++far;
        EXPECT_EQ(map[k], 65535) << i << " " << j;
        EXPECT_EQ(map[k + 1], 65535) << i << " " << j;
      }
    }
  }
  EXPECT_GT(far, r * r / 3);
}

// ---- .kprobe version 3 ------------------------------------------------------------------

// A valid set with varied maps: random depth distributions per texel.
ProbeSet setWithVariedMaps() {
  ProbeSet s = hiddenCentreSet();
  std::mt19937 rng(16);
  std::uniform_real_distribution<double> u(0.0, 1.0);
  for (size_t t = 0; t < s.visibility.moments.size(); t += 2) {
    const double m = u(rng), spread = u(rng) * m * (1.0 - m);
    s.visibility.moments[t] = unorm16(m);
    s.visibility.moments[t + 1] = unorm16(m * m + spread);
  }
  for (size_t i = 0; i < s.visibility.maxDistance.size(); ++i)
    s.visibility.maxDistance[i] = 1.0f + 0.25f * float(i);
  return s;
}

uint32_t wordAt(const std::vector<uint8_t>& b, size_t at) {
  uint32_t v;
  std::memcpy(&v, b.data() + at, 4);
  return v;
}

TEST(ProbeVisibilityFile, Version3RoundTripsExactly) {
  const ProbeSet s = setWithVariedMaps();
  const std::vector<uint8_t> bytes = serializeProbeSet(s);
  EXPECT_EQ(wordAt(bytes, 4), 3u);
  EXPECT_EQ(wordAt(bytes, 60), uint32_t(kResolution));
  // The block's size: maxDistance and R^2 x 2 moments per probe, after the version 2 payload.
  EXPECT_EQ(bytes.size(), serializeProbeSet(s, 2).size() +
                              size_t(s.probeCount()) * (4 + kResolution * kResolution * 4));
  Result<ProbeSet> r = parseProbeSet(bytes, "v3");
  ASSERT_TRUE(r.ok()) << r.error();
  EXPECT_EQ(r->visibility.resolution, s.visibility.resolution);
  EXPECT_EQ(r->visibility.maxDistance, s.visibility.maxDistance);
  EXPECT_EQ(r->visibility.moments, s.visibility.moments);
  EXPECT_EQ(serializeProbeSet(*r), bytes);
  for (const glm::vec3 p : pointsInCube(200, 17)) {
    const ProbeLocation a = locateProbe(s, p), b = locateProbe(*r, p);
    EXPECT_EQ(a.cell, b.cell);
    EXPECT_EQ(a.weights, b.weights);
  }
}

// The same set written as version 2 loads without visibility and blends like the plain blend.
TEST(ProbeVisibilityFile, Version2HasNoVisibilityAndBlendsPlain) {
  const ProbeSet s = hiddenCentreSet();
  const std::vector<uint8_t> v2 = serializeProbeSet(s, 2);
  EXPECT_EQ(wordAt(v2, 4), 2u);
  EXPECT_EQ(wordAt(v2, 60), 0u);
  Result<ProbeSet> r = parseProbeSet(v2, "v2");
  ASSERT_TRUE(r.ok()) << r.error();
  EXPECT_TRUE(r->visibility.empty());
  EXPECT_TRUE(r->visibility.maxDistance.empty() && r->visibility.moments.empty());
  int differ = 0;
  for (const glm::vec3 p : pointsInCube(500, 18)) {
    const ProbeLocation loaded = locateProbe(*r, p);
    const ProbeLocation plain = locateProbe(s, p, -1, plainBlend());
    EXPECT_EQ(loaded.cell, plain.cell);
    EXPECT_EQ(loaded.weights, plain.weights);
    EXPECT_EQ(loaded.weights, loaded.barycentric);
    differ += locateProbe(s, p).weights != plain.weights;
  }
  EXPECT_GT(differ, 100) << "the version 3 set does blend differently";
}

TEST(ProbeVisibilityFile, TruncatedBlockIsNamed) {
  const std::vector<uint8_t> good = serializeProbeSet(hiddenCentreSet());
  const size_t v2Size = serializeProbeSet(hiddenCentreSet(), 2).size();
  // Cut at the start of the block, inside the maxDistances, inside the moments, one byte short.
  for (size_t n : {v2Size, v2Size + 6, v2Size + 40, good.size() - 1}) {
    std::vector<uint8_t> b(good.begin(), good.begin() + long(n));
    const std::string e = parseError(b);
    EXPECT_NE(e.find("size: file has " + std::to_string(n)), std::string::npos) << e;
    EXPECT_NE(e.find("truncated"), std::string::npos) << e;
  }
}

TEST(ProbeVisibilityFile, BadMaxDistanceIsNamed) {
  for (float bad : {std::nanf(""), 0.0f, -1.0f, std::numeric_limits<float>::infinity()}) {
    ProbeSet s = hiddenCentreSet();
    s.visibility.maxDistance[3] = bad;
    const std::string e = parseError(serializeProbeSet(s));
    EXPECT_NE(e.find("visibilityMaxDistance[3]"), std::string::npos) << bad << ": " << e;
  }
}

TEST(ProbeVisibilityFile, ImpossibleResolutionIsNamed) {
  const std::vector<uint8_t> good = serializeProbeSet(hiddenCentreSet());
  for (uint32_t resolution : {1u, 3u, 65u, 100000u, 0xFFFFFFFFu}) {
    std::vector<uint8_t> b = good;
    std::memcpy(b.data() + 60, &resolution, 4);
    reseal(b);
    const std::string e = parseError(b);
    EXPECT_NE(e.find("visibilityResolution: " + std::to_string(resolution) + " out of range"),
              std::string::npos)
        << e;
  }
  // Resolution 0 with the block still there: the block is trailing data.
  std::vector<uint8_t> b = good;
  std::memset(b.data() + 60, 0, 4);
  reseal(b);
  EXPECT_NE(parseError(b).find("trailing data"), std::string::npos) << parseError(b);
  // Version 2 files may not use the word.
  b = serializeProbeSet(hiddenCentreSet(), 2);
  const uint32_t four = 4;
  std::memcpy(b.data() + 60, &four, 4);
  reseal(b);
  EXPECT_NE(parseError(b).find("reserved: must be 0"), std::string::npos) << parseError(b);
}

// A mean square below the squared mean is no distribution; unorm16 rounding of both can put it
// up to ~3 steps below, which is accepted (the reader allows 4 / 65535).
TEST(ProbeVisibilityFile, ImpossibleMomentsAreNamed) {
  const ProbeSet good = hiddenCentreSet();
  const size_t texels = size_t(kResolution * kResolution);
  const size_t probe = 5, texel = 17, at = 2 * (probe * texels + texel);
  {
    ProbeSet s = good;
    s.visibility.moments[at] = 40000;
    s.visibility.moments[at + 1] = 20000;  // 0.305 < 0.6104^2 = 0.3725
    const std::string e = parseError(serializeProbeSet(s));
    EXPECT_NE(e.find("visibilityMoments[5][17]"), std::string::npos) << e;
  }
  // mean 32768 / 65535: mean^2 x 65535 = 16384.25; 16381 is within 4 steps, 16380 is not.
  ProbeSet s = good;
  s.visibility.moments[at] = 32768;
  s.visibility.moments[at + 1] = 16381;
  EXPECT_TRUE(parseProbeSet(serializeProbeSet(s), "ok").ok());
  s.visibility.moments[at + 1] = 16380;
  EXPECT_NE(parseError(serializeProbeSet(s)).find("visibilityMoments[5][17]"), std::string::npos);
}

// Bit flips in the visibility block or its header word, with the checksum recomputed so that
// the validation itself is reached: the reader never crashes, and whatever it accepts gives
// lookups with finite weights >= 0 summing to 1.
TEST(ProbeVisibilityFile, CorruptionPastTheChecksumIsCaughtOrHarmless) {
  const ProbeSet s = setWithVariedMaps();
  const std::vector<uint8_t> good = serializeProbeSet(s);
  const size_t block = serializeProbeSet(s, 2).size();
  const std::vector<glm::vec3> points = pointsInCube(20, 19);
  std::mt19937 rng(20);
  int accepted = 0;
  for (int i = 0; i < 2000; ++i) {
    std::vector<uint8_t> b = good;
    const int flips = 1 + int(rng() % 3);
    for (int f = 0; f < flips; ++f) {
      const size_t at = rng() % 8 == 0 ? 60 + rng() % 4 : block + rng() % (good.size() - block);
      b[at] ^= uint8_t(1u << (rng() % 8));
    }
    reseal(b);
    Result<ProbeSet> r = parseProbeSet(b, "fuzz");
    if (!r.ok()) continue;
    ++accepted;
    for (const glm::vec3 p : points) {
      const ProbeLocation loc = locateProbe(*r, p);
      float sum = 0.0f;
      for (float w : loc.weights) {
        ASSERT_TRUE(std::isfinite(w) && w >= 0.0f) << i;
        sum += w;
      }
      ASSERT_NEAR(sum, 1.0f, 1e-5f) << i;
    }
  }
  // Most flips in the moments leave a valid distribution (a different depth), so the
  // acceptance path is exercised too.
  EXPECT_GT(accepted, 200);
}

}  // namespace
}  // namespace kiln
