// sampling.cpp: hashing, the Owen-scrambled 2D Sobol sequence, warps and piecewise-constant
// distributions.
//
// References: B. Burley, "Practical Hash-based Owen Scrambling", JCGT 9(4), 2020;
// S. Laine and T. Karras, "Stratified Sampling for Stochastic Transparency", EGSR 2011;
// N. Vegdahl, "Building a Better LK Hash", 2021 (the permutation constants);
// P. Shirley and K. Chiu, "A Low Distortion Map Between Disk and Square", 1997;
// E. Heitz, "A Low-Distortion Map Between Triangle and Square", 2019;
// M. Pharr, W. Jakob, G. Humphreys, pbrt-v4, sec. A.1 (piecewise-constant distributions).
#include "src/sampling.h"

#include <algorithm>
#include <cassert>
#include <cmath>

namespace kiln {

namespace {

constexpr uint32_t reverseBitsConstexpr(uint32_t x) {
  x = ((x >> 1) & 0x55555555u) | ((x & 0x55555555u) << 1);
  x = ((x >> 2) & 0x33333333u) | ((x & 0x33333333u) << 2);
  x = ((x >> 4) & 0x0f0f0f0fu) | ((x & 0x0f0f0f0fu) << 4);
  x = ((x >> 8) & 0x00ff00ffu) | ((x & 0x00ff00ffu) << 8);
  return (x >> 16) | (x << 16);
}

// detail::lkPermutation (sampling.h) is a seeded bijection of 32-bit words in which bit k of
// the result depends only on bits 0..k of the input (additions carry upwards; x * even and
// x * odd only mix lower bits into higher ones). Applied to bit-reversed values it permutes each digit conditioned on the more
// significant digits: a nested uniform (Owen) scramble (Laine & Karras 2011; constants from
// Vegdahl 2021, which fix the weak low bits of Burley's original).
// The nested uniform scramble of x is reverseBits(lkPermutation(reverseBits(x), seed)).

// Sobol's second dimension: generator matrix columns v_0 = 1/2, v_j = v_{j-1} ^ (v_{j-1} >> 1)
// (primitive polynomial x + 1), i.e. Pascal's triangle mod 2. Together with the van der
// Corput radical inverse it forms a (0,2)-sequence in base 2.
struct SobolMatrix {
  uint32_t columns[32];
  constexpr SobolMatrix() : columns() {
    uint32_t v = 0x80000000u;
    for (int j = 0; j < 32; ++j) {
      columns[j] = v;
      v ^= v >> 1;
    }
  }
};

// The matrix-vector product over GF(2) is linear in the index's bits, so it splits into the
// XOR of four byte-indexed tables: table[b][k] = product of byte k placed at byte position b.
// This replaces a 32-step loop with unpredictable branches on the integrator's hot path. The
// tables hold the products bit-reversed, the form the Owen scramble consumes.
struct SobolTables {
  uint32_t reversed[4][256];
  constexpr SobolTables() : reversed() {
    constexpr SobolMatrix m;
    for (int b = 0; b < 4; ++b)
      for (uint32_t k = 0; k < 256; ++k) {
        uint32_t x = 0;
        for (int j = 0; j < 8; ++j)
          if (k & (1u << j)) x ^= m.columns[8 * b + j];
        reversed[b][k] = reverseBitsConstexpr(x);
      }
  }
};
constexpr SobolTables kSobolDim1;

}  // namespace

// reverseBits(Sobol dimension 1 of `index`).
uint32_t detail::sobolDim1Reversed(uint32_t index) {
  return kSobolDim1.reversed[0][index & 0xffu] ^ kSobolDim1.reversed[1][(index >> 8) & 0xffu] ^
         kSobolDim1.reversed[2][(index >> 16) & 0xffu] ^ kSobolDim1.reversed[3][index >> 24];
}

vec2 sobol2D(uint32_t index, uint64_t seed) {
  // Burley 2020 sec. 4: shuffle the index by an Owen scramble of its own. Bit p of the
  // shuffled index depends only on bits >= p, so the first 2^k indices map onto one aligned
  // block of 2^k Sobol points, which is itself a (0,k,2)-net: every power-of-two prefix stays
  // stratified. The two dimensions then get independent value scrambles.
  // One 64-bit hash gives both value seeds; the seed itself is already a hash.
  // For dimension 0 (the radical inverse reverseBits(i)) the scramble's inner reversal
  // cancels, and dimension 1's tables are stored reversed, saving three of the seven bit
  // reversals. The arithmetic is detail::sobol2DInline in sampling.h.
  return detail::sobol2DInline(index, seed);
}



vec3 squareToUniformSphere(vec2 u) {
  float z = 1.0f - 2.0f * u.x;
  float r = std::sqrt(std::max(0.0f, 1.0f - z * z));
  float phi = 2.0f * kPi * u.y;
  return vec3(r * std::cos(phi), r * std::sin(phi), z);
}

vec3 squareToUniformCone(vec2 u, float cosThetaMax) {
  // cos(theta) uniform in [cosThetaMax, 1] gives uniform solid angle.
  float cosTheta = (1.0f - u.x) + u.x * cosThetaMax;
  float sinTheta = std::sqrt(std::max(0.0f, 1.0f - cosTheta * cosTheta));
  float phi = 2.0f * kPi * u.y;
  return vec3(sinTheta * std::cos(phi), sinTheta * std::sin(phi), cosTheta);
}


// ---- Distribution1D ----

Distribution1D::Distribution1D(std::vector<float> weights) : weights_(std::move(weights)) {
  assert(!weights_.empty());
  size_t n = weights_.size();
  cdf_.assign(n + 1, 0.0);
  double sum = 0.0;
  for (size_t i = 0; i < n; ++i) {
    float w = weights_[i];
    if (!(w > 0.0f)) w = 0.0f;  // negatives and NaN
    weights_[i] = w;
    sum += double(w);
    cdf_[i + 1] = sum;
  }
  total_ = float(sum);
  if (sum > 0.0) {
    for (size_t i = 1; i <= n; ++i) cdf_[i] /= sum;
  } else {
    // All zero: sample uniformly so callers always get a valid sample and pdf.
    for (size_t i = 1; i <= n; ++i) cdf_[i] = double(i) / double(n);
  }
  cdf_[n] = 1.0;
}


float Distribution1D::sampleContinuous(float u, float* pdf, size_t* bin) const {
  float remapped;
  size_t i = sampleDiscrete(u, nullptr, &remapped);
  size_t n = weights_.size();
  if (bin) *bin = i;
  if (pdf) *pdf = total_ > 0 ? weights_[i] * float(n) / total_ : 1.0f;
  float x = float((double(i) + double(remapped)) / double(n));
  // Keep x inside bin i after float rounding, so pdf lookups by position (x * n) agree.
  while (x > 0.0f && size_t(x * float(n)) > i) x = std::nextafter(x, 0.0f);
  while (size_t(x * float(n)) < i) x = std::nextafter(x, 1.0f);
  return x;
}

// ---- Distribution2D ----

Distribution2D::Distribution2D(const std::vector<float>& weights, int width, int height)
    : width_(width), height_(height) {
  assert(width > 0 && height > 0 && weights.size() == size_t(width) * height);
  rows_.reserve(height);
  std::vector<float> rowTotals(height);
  for (int y = 0; y < height; ++y) {
    rows_.emplace_back(std::vector<float>(weights.begin() + size_t(y) * width,
                                          weights.begin() + size_t(y + 1) * width));
    rowTotals[y] = rows_.back().total();
  }
  marginal_ = Distribution1D(std::move(rowTotals));
}

vec2 Distribution2D::sample(vec2 u, float* pdf) const {
  assert(!empty());
  float pdfV, pdfU;
  size_t row;
  float v = marginal_.sampleContinuous(u.y, &pdfV, &row);
  float x = rows_[row].sampleContinuous(u.x, &pdfU);
  if (pdf) *pdf = pdfU * pdfV;
  return vec2(x, v);
}

float Distribution2D::pdf(vec2 uv) const {
  assert(!empty());
  int x = std::clamp(int(uv.x * float(width_)), 0, width_ - 1);
  int y = std::clamp(int(uv.y * float(height_)), 0, height_ - 1);
  return marginal_.pmf(y) * float(height_) * rows_[y].pmf(x) * float(width_);
}

}  // namespace kiln
