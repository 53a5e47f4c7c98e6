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

uint64_t mixBits(uint64_t v) {
  v ^= v >> 30;
  v *= 0xbf58476d1ce4e5b9ull;
  v ^= v >> 27;
  v *= 0x94d049bb133111ebull;
  v ^= v >> 31;
  return v;
}

uint64_t hashValues(uint64_t a, uint64_t b) {
  // Chaining through the bijective finaliser; the odd constants keep (0, 0) away from 0.
  uint64_t h = mixBits(a + 0x9e3779b97f4a7c15ull);
  return mixBits(h ^ (b * 0xd1b54a32d192ed03ull + 0x632be59bd9b4e019ull));
}

uint64_t hashValues(uint64_t a, uint64_t b, uint64_t c) { return hashValues(hashValues(a, b), c); }

namespace {

constexpr uint32_t reverseBits(uint32_t x) {
  x = ((x >> 1) & 0x55555555u) | ((x & 0x55555555u) << 1);
  x = ((x >> 2) & 0x33333333u) | ((x & 0x33333333u) << 2);
  x = ((x >> 4) & 0x0f0f0f0fu) | ((x & 0x0f0f0f0fu) << 4);
  x = ((x >> 8) & 0x00ff00ffu) | ((x & 0x00ff00ffu) << 8);
  return (x >> 16) | (x << 16);
}

// A seeded bijection of 32-bit words in which bit k of the result depends only on bits 0..k
// of the input (additions carry upwards; x * even and x * odd only mix lower bits into higher
// ones). Applied to bit-reversed values it permutes each digit conditioned on the more
// significant digits: a nested uniform (Owen) scramble (Laine & Karras 2011; constants from
// Vegdahl 2021, which fix the weak low bits of Burley's original).
uint32_t lkPermutation(uint32_t x, uint32_t seed) {
  x ^= x * 0x3d20adeau;
  x += seed;
  x *= (seed >> 16) | 1u;
  x ^= x * 0x05526c56u;
  x ^= x * 0x53a22864u;
  return x;
}

// Owen scramble of a 32-bit fixed-point value in [0,1) (most significant bit = 1/2).
uint32_t nestedUniformScramble(uint32_t x, uint32_t seed) {
  return reverseBits(lkPermutation(reverseBits(x), seed));
}

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
        reversed[b][k] = reverseBits(x);
      }
  }
};
constexpr SobolTables kSobolDim1;

// reverseBits(Sobol dimension 1 of `index`).
uint32_t sobolDim1Reversed(uint32_t index) {
  return kSobolDim1.reversed[0][index & 0xffu] ^ kSobolDim1.reversed[1][(index >> 8) & 0xffu] ^
         kSobolDim1.reversed[2][(index >> 16) & 0xffu] ^ kSobolDim1.reversed[3][index >> 24];
}

// Top 24 bits to a float in [0,1): exact, and never rounds up to 1.
float toUnitFloat(uint32_t x) { return float(x >> 8) * 0x1p-24f; }

}  // namespace

vec2 sobol2D(uint32_t index, uint64_t seed) {
  // Burley 2020 sec. 4: shuffle the index by an Owen scramble of its own. Bit p of the
  // shuffled index depends only on bits >= p, so the first 2^k indices map onto one aligned
  // block of 2^k Sobol points, which is itself a (0,k,2)-net: every power-of-two prefix stays
  // stratified. The two dimensions then get independent value scrambles.
  // One 64-bit hash gives both value seeds; the seed itself is already a hash.
  uint32_t shuffleSeed = uint32_t(seed);
  uint64_t valueSeeds = mixBits(seed ^ 0x5bd1e9955bd1e995ull);
  uint32_t seed0 = uint32_t(valueSeeds);
  uint32_t seed1 = uint32_t(valueSeeds >> 32);
  uint32_t i = nestedUniformScramble(index, shuffleSeed);
  // nestedUniformScramble(v) = reverseBits(lk(reverseBits(v))): for dimension 0 (v = the
  // radical inverse reverseBits(i)) the inner reversal cancels, and dimension 1's tables are
  // stored reversed, saving three of the seven bit reversals per call.
  uint32_t x = reverseBits(lkPermutation(i, seed0));
  uint32_t y = reverseBits(lkPermutation(sobolDim1Reversed(i), seed1));
  return vec2(toUnitFloat(x), toUnitFloat(y));
}

float SampleStream::get1D() { return get2D().x; }

vec2 SampleStream::get2D() {
  vec2 u = sobol2D(index_, hashValues(key_, dimension_));
  dimension_ += 2;
  return u;
}

vec2 squareToConcentricDisk(vec2 u) {
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

vec3 squareToCosineHemisphere(vec2 u) {
  // Malley's method: project the uniform disk up onto the hemisphere.
  vec2 d = squareToConcentricDisk(u);
  float z = std::sqrt(std::max(0.0f, 1.0f - d.x * d.x - d.y * d.y));
  return vec3(d.x, d.y, z);
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

vec2 squareToTriangle(vec2 u) {
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

size_t Distribution1D::sampleDiscrete(float u, float* pmf, float* remapped) const {
  assert(!weights_.empty());
  double du = std::clamp(double(u), 0.0, std::nextafter(1.0, 0.0));
  // Last i with cdf[i] <= u; since cdf[n] = 1 > u the bin [cdf[i], cdf[i+1]) has width > 0,
  // so zero-weight bins are never returned.
  size_t i = size_t(std::upper_bound(cdf_.begin(), cdf_.end(), du) - cdf_.begin()) - 1;
  i = std::min(i, weights_.size() - 1);
  double lo = cdf_[i], width = cdf_[i + 1] - cdf_[i];
  if (pmf) *pmf = float(width);
  if (remapped) {
    float r = width > 0 ? float((du - lo) / width) : 0.0f;
    *remapped = std::clamp(r, 0.0f, std::nextafter(1.0f, 0.0f));
  }
  return i;
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
