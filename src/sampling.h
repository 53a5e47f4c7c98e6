// sampling.h: deterministic random numbers and the warps that turn them into directions.
//
// Every random number in kiln is a pure function of (key, sample index, dimension): the key
// names the thing being estimated (a texel, a probe, a pixel), so results never depend on
// which thread ran what. Samples come from a padded, Owen-scrambled Sobol sequence
// (Burley 2020, "Practical Hash-based Owen Scrambling"): each pair of dimensions is the 2D
// Sobol (0,2)-sequence with its index shuffled and its values scrambled by hashes of
// (key, dimension), so any power-of-two prefix of samples is stratified in every 2D
// projection, and dimensions are decorrelated.
#pragma once

#include <cassert>
#include <cstdint>
#include <vector>

#include "src/math.h"

namespace kiln {

// 64-bit finaliser (splitmix64 / Stafford variant 13): a bijective hash.
inline uint64_t mixBits(uint64_t v) {
  v ^= v >> 30;
  v *= 0xbf58476d1ce4e5b9ull;
  v ^= v >> 27;
  v *= 0x94d049bb133111ebull;
  v ^= v >> 31;
  return v;
}

namespace detail {
// hashValues(a, b) in two halves: the first depends on a only, so a stream that hashes one
// key with many dimensions computes it once (SampleStream).
inline uint64_t hashFirst(uint64_t a) { return mixBits(a + 0x9e3779b97f4a7c15ull); }
inline uint64_t hashSecond(uint64_t first, uint64_t b) {
  return mixBits(first ^ (b * 0xd1b54a32d192ed03ull + 0x632be59bd9b4e019ull));
}
}  // namespace detail

// Hash of several 64-bit values.
inline uint64_t hashValues(uint64_t a, uint64_t b) {
  // Chaining through the bijective finaliser; the odd constants keep (0, 0) away from 0.
  return detail::hashSecond(detail::hashFirst(a), b);
}
inline uint64_t hashValues(uint64_t a, uint64_t b, uint64_t c) {
  return hashValues(hashValues(a, b), c);
}

// The 2D Owen-scrambled Sobol point `index` for scramble seed `seed` (exposed for tests).
vec2 sobol2D(uint32_t index, uint64_t seed);

namespace detail {
// Building blocks of sobol2D, inline because the integrator draws several per path vertex
// (see sampling.cpp for the derivation and references).
inline uint32_t reverseBits(uint32_t x) {
  // Byte swap, then reverse the bits within each byte.
  x = __builtin_bswap32(x);
  x = ((x >> 4) & 0x0f0f0f0fu) | ((x & 0x0f0f0f0fu) << 4);
  x = ((x >> 2) & 0x33333333u) | ((x & 0x33333333u) << 2);
  x = ((x >> 1) & 0x55555555u) | ((x & 0x55555555u) << 1);
  return x;
}
// Laine-Karras style permutation with Vegdahl's constants (sampling.cpp).
inline uint32_t lkPermutation(uint32_t x, uint32_t seed) {
  x ^= x * 0x3d20adeau;
  x += seed;
  x *= (seed >> 16) | 1u;
  x ^= x * 0x05526c56u;
  x ^= x * 0x53a22864u;
  return x;
}
// Top 24 bits to a float in [0,1): exact, and never rounds up to 1.
inline float toUnitFloat(uint32_t x) { return float(x >> 8) * 0x1p-24f; }
// reverseBits(Sobol dimension 1 of `index`) (table-driven, sampling.cpp).
uint32_t sobolDim1Reversed(uint32_t index);
// The Owen-shuffled index of sobol2D.
inline uint32_t sobolShuffledIndex(uint32_t index, uint64_t seed) {
  return reverseBits(lkPermutation(reverseBits(index), uint32_t(seed)));
}
inline uint64_t sobolValueSeeds(uint64_t seed) { return mixBits(seed ^ 0x5bd1e9955bd1e995ull); }
// sobol2D(index, seed).x without the work for .y.
inline float sobol1D(uint32_t index, uint64_t seed) {
  const uint32_t i = sobolShuffledIndex(index, seed);
  return toUnitFloat(reverseBits(lkPermutation(i, uint32_t(sobolValueSeeds(seed)))));
}
inline vec2 sobol2DInline(uint32_t index, uint64_t seed) {
  const uint32_t i = sobolShuffledIndex(index, seed);
  const uint64_t valueSeeds = sobolValueSeeds(seed);
  const uint32_t x = reverseBits(lkPermutation(i, uint32_t(valueSeeds)));
  const uint32_t y = reverseBits(lkPermutation(sobolDim1Reversed(i), uint32_t(valueSeeds >> 32)));
  return vec2(toUnitFloat(x), toUnitFloat(y));
}
}  // namespace detail

// A stream of samples in [0,1) for one sample of one estimate. Successive calls advance the
// dimension: get2D() consumes one dimension pair, get1D() one pair as well (its first
// component), so a 1D and a 2D request never share a pair.
// Dimension pair d of the stream is sobol2D(sampleIndex, hashValues(key, d)).
class SampleStream {
 public:
  SampleStream(uint64_t key, uint32_t sampleIndex)
      : keyHash_(detail::hashFirst(key)), index_(sampleIndex) {}

  float get1D() {
    const float u = detail::sobol1D(index_, detail::hashSecond(keyHash_, dimension_));
    dimension_ += 2;
    return u;
  }
  vec2 get2D() {
    const vec2 u = detail::sobol2DInline(index_, detail::hashSecond(keyHash_, dimension_));
    dimension_ += 2;
    return u;
  }
  // Jumps to a fixed dimension (e.g. the start of bounce k), so that later dimensions do
  // not shift when earlier code changes how many it draws.
  void setDimension(uint32_t dimension) { dimension_ = dimension; }
  uint32_t dimension() const { return dimension_; }

 private:
  uint64_t keyHash_;  // detail::hashFirst(key)
  uint32_t index_;
  uint32_t dimension_ = 0;
};

// Warps from [0,1)^2. Directions are in the local frame with z up unless noted.
inline vec3 squareToCosineHemisphere(vec2 u);  // pdf = cos(theta) / pi
inline float cosineHemispherePdf(float cosTheta) { return cosTheta > 0 ? cosTheta * kInvPi : 0; }
vec3 squareToUniformSphere(vec2 u);  // pdf = 1 / (4 pi)
vec3 squareToUniformCone(vec2 u, float cosThetaMax);  // pdf = 1 / (2 pi (1 - cosThetaMax))
inline vec2 squareToConcentricDisk(vec2 u);  // unit disk, uniform
inline vec2 squareToTriangle(vec2 u);  // barycentrics (b1, b2) uniform over a triangle

// Power heuristic with beta = 2 (Veach 1997) for one sample from each of two strategies.
inline float powerHeuristic(float pdfA, float pdfB) {
  float a = pdfA * pdfA, b = pdfB * pdfB;
  return a + b > 0 ? a / (a + b) : 0.0f;
}

// Piecewise-constant 1D distribution over [0, 1) with n bins.
class Distribution1D {
 public:
  Distribution1D() = default;
  explicit Distribution1D(std::vector<float> weights);  // negative weights are clamped to 0

  size_t size() const { return weights_.size(); }
  float total() const { return total_; }  // sum of weights
  // Picks a bin with probability weight / total; `remapped` returns u rescaled to [0,1)
  // within the bin. Returns the bin index.
  // Inline (below), as the integrator picks an emitter at every path vertex.
  size_t sampleDiscrete(float u, float* pmf = nullptr, float* remapped = nullptr) const;
  // All-zero weights sample uniformly, so the pmf is then 1 / size().
  float pmf(size_t bin) const {
    return total_ > 0 ? weights_[bin] / total_ : 1.0f / float(weights_.size());
  }
  // Continuous sample in [0,1) with density pdf (relative to [0,1)).
  float sampleContinuous(float u, float* pdf, size_t* bin = nullptr) const;

 private:
  std::vector<float> weights_;
  std::vector<double> cdf_;  // size n + 1
  float total_ = 0.0f;
};

inline size_t Distribution1D::sampleDiscrete(float u, float* pmf, float* remapped) const {
  assert(!weights_.empty());
  const size_t n = weights_.size();
  const double du = std::clamp(double(u), 0.0, 0x1.fffffffffffffp-1);  // [0, 1)
  // Last i with cdf[i] <= u; since cdf[n] = 1 > u the bin [cdf[i], cdf[i+1]) has width > 0,
  // so zero-weight bins are never returned. A linear scan for the few emitters of small
  // scenes, a binary search otherwise; both find the same bin.
  size_t i;
  if (n <= 16) {
    i = 0;
    while (i + 1 < n && cdf_[i + 1] <= du) ++i;
  } else {
    i = size_t(std::upper_bound(cdf_.begin(), cdf_.end(), du) - cdf_.begin()) - 1;
    i = std::min(i, n - 1);
  }
  const double lo = cdf_[i], width = cdf_[i + 1] - cdf_[i];
  if (pmf) *pmf = float(width);
  if (remapped) {
    const float r = width > 0 ? float((du - lo) / width) : 0.0f;
    *remapped = std::clamp(r, 0.0f, 0x1.fffffep-1f);
  }
  return i;
}

inline vec2 squareToConcentricDisk(vec2 u) {
  // Shirley & Chiu 1997, in the single-branch form (pbrt-v4 SampleUniformDiskConcentric).
  vec2 p = 2.0f * u - vec2(1.0f);
  if (p.x == 0.0f && p.y == 0.0f) return vec2(0.0f);
  float r, theta;
  if (std::abs(p.x) > std::abs(p.y)) {
    r = p.x;
    theta = 0.25f * kPi * (p.y / p.x);
  } else {
    r = p.y;
    theta = 0.5f * kPi - 0.25f * kPi * (p.x / p.y);
  }
  return r * vec2(std::cos(theta), std::sin(theta));
}

inline vec3 squareToCosineHemisphere(vec2 u) {
  // Malley's method: project the uniform disk up onto the hemisphere.
  vec2 d = squareToConcentricDisk(u);
  float z = std::sqrt(std::max(0.0f, 1.0f - d.x * d.x - d.y * d.y));
  return vec3(d.x, d.y, z);
}

inline vec2 squareToTriangle(vec2 u) {
  // Heitz 2019: fold the square onto the triangle without a square root, so stratification
  // of u carries over with little distortion.
  float b0, b1;
  if (u.y > u.x) {
    b0 = 0.5f * u.x;
    b1 = u.y - b0;
  } else {
    b1 = 0.5f * u.y;
    b0 = u.x - b1;
  }
  return vec2(b0, b1);
}

// Piecewise-constant 2D distribution over [0,1)^2 (rows = v, columns = u).
class Distribution2D {
 public:
  Distribution2D() = default;
  Distribution2D(const std::vector<float>& weights, int width, int height);

  // Returns (u, v) with density pdf over [0,1)^2.
  vec2 sample(vec2 u, float* pdf) const;
  float pdf(vec2 uv) const;
  bool empty() const { return rows_.empty(); }

 private:
  int width_ = 0, height_ = 0;
  std::vector<Distribution1D> rows_;
  Distribution1D marginal_;
};

}  // namespace kiln
