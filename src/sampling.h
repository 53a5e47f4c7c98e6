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

#include <cstdint>
#include <vector>

#include "src/math.h"

namespace kiln {

// 64-bit finaliser (splitmix64 / Stafford variant 13): a bijective hash.
uint64_t mixBits(uint64_t v);
// Hash of several 64-bit values.
uint64_t hashValues(uint64_t a, uint64_t b);
uint64_t hashValues(uint64_t a, uint64_t b, uint64_t c);

// A stream of samples in [0,1) for one sample of one estimate. Successive calls advance the
// dimension: get2D() consumes one dimension pair, get1D() one pair as well (its first
// component), so a 1D and a 2D request never share a pair.
class SampleStream {
 public:
  SampleStream(uint64_t key, uint32_t sampleIndex) : key_(key), index_(sampleIndex) {}

  float get1D();
  vec2 get2D();
  // Jumps to a fixed dimension (e.g. the start of bounce k), so that later dimensions do
  // not shift when earlier code changes how many it draws.
  void setDimension(uint32_t dimension) { dimension_ = dimension; }
  uint32_t dimension() const { return dimension_; }

 private:
  uint64_t key_;
  uint32_t index_;
  uint32_t dimension_ = 0;
};

// The 2D Owen-scrambled Sobol point `index` for scramble seed `seed` (exposed for tests).
vec2 sobol2D(uint32_t index, uint64_t seed);

// Warps from [0,1)^2. Directions are in the local frame with z up unless noted.
vec3 squareToCosineHemisphere(vec2 u);  // pdf = cos(theta) / pi
inline float cosineHemispherePdf(float cosTheta) { return cosTheta > 0 ? cosTheta * kInvPi : 0; }
vec3 squareToUniformSphere(vec2 u);  // pdf = 1 / (4 pi)
vec3 squareToUniformCone(vec2 u, float cosThetaMax);  // pdf = 1 / (2 pi (1 - cosThetaMax))
vec2 squareToConcentricDisk(vec2 u);  // unit disk, uniform
vec2 squareToTriangle(vec2 u);  // barycentrics (b1, b2) uniform over a triangle

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
