// sh.h: real spherical harmonics up to order 2 (9 coefficients), RGB.
//
// Basis (MISSION.md "Conventions"): the real orthonormal SH basis, coefficient index
// i = l(l+1) + m, in glTF world axes, for a unit direction (x, y, z):
//   i=0 Y00  = 0.282095
//   i=1 Y1-1 = 0.488603 y     i=2 Y10 = 0.488603 z     i=3 Y11 = 0.488603 x
//   i=4 Y2-2 = 1.092548 xy    i=5 Y2-1 = 1.092548 yz   i=6 Y20 = 0.315392 (3z^2 - 1)
//   i=7 Y21  = 1.092548 xz    i=8 Y22 = 0.546274 (x^2 - y^2)
// An ShL2Rgb holds the projection of RADIANCE L(w) onto this basis:
//   c_i = integral over the sphere of L(w) Y_i(w) dw   (no pre-scaling, no convolution).
// Irradiance for a normal n is the convolution with the clamped cosine (Ramamoorthi and
// Hanrahan 2001): E(n) = sum_i A_l(i) c_i Y_i(n), A0 = pi, A1 = 2 pi / 3, A2 = pi / 4.
//
// This header is the part a game needs (evaluation and irradiance): it depends only on GLM,
// so kiln_runtime uses it without linking the bake-time core. Projection, windowing and
// packing live in sh_projection.h.
#pragma once

#include <array>

#include <glm/glm.hpp>

namespace kiln {

inline constexpr int kShL2Count = 9;
inline constexpr int kShL1Count = 4;

// The 9 basis functions at unit direction d.
inline std::array<float, kShL2Count> shBasisL2(glm::vec3 d) {
  const float x = d.x, y = d.y, z = d.z;
  return {0.282095f,
          0.488603f * y,
          0.488603f * z,
          0.488603f * x,
          1.092548f * x * y,
          1.092548f * y * z,
          0.315392f * (3.0f * z * z - 1.0f),
          1.092548f * x * z,
          0.546274f * (x * x - y * y)};
}

// Band of coefficient i (0, 1 or 2).
inline constexpr int shBand(int i) { return i == 0 ? 0 : (i < 4 ? 1 : 2); }

// Ramamoorthi-Hanrahan clamped-cosine convolution factors A_l.
inline constexpr float kShCosineLobe[3] = {3.14159265358979f, 2.09439510239320f,
                                           0.785398163397448f};

// L2 spherical harmonics of RGB radiance (see the header comment for the convention).
struct ShL2Rgb {
  std::array<glm::vec3, kShL2Count> c{};

  ShL2Rgb& operator+=(const ShL2Rgb& o) {
    for (int i = 0; i < kShL2Count; ++i) c[i] += o.c[i];
    return *this;
  }
  ShL2Rgb& operator*=(float s) {
    for (auto& v : c) v *= s;
    return *this;
  }
  friend ShL2Rgb operator+(ShL2Rgb a, const ShL2Rgb& b) { return a += b; }
  friend ShL2Rgb operator*(ShL2Rgb a, float s) { return a *= s; }
  friend ShL2Rgb operator*(float s, ShL2Rgb a) { return a *= s; }

  // Adds a sample: radiance `value` from direction d with quadrature weight `weight`
  // (e.g. 4 pi / N for N uniform sphere samples).
  void addSample(glm::vec3 d, glm::vec3 value, float weight) {
    auto y = shBasisL2(d);
    for (int i = 0; i < kShL2Count; ++i) c[i] += value * (y[i] * weight);
  }
  // Reconstructed radiance in direction d.
  glm::vec3 evaluate(glm::vec3 d) const {
    auto y = shBasisL2(d);
    glm::vec3 r(0.0f);
    for (int i = 0; i < kShL2Count; ++i) r += c[i] * y[i];
    return r;
  }
  // Irradiance E (not E / pi) on a surface with unit normal n.
  glm::vec3 irradiance(glm::vec3 n) const {
    auto y = shBasisL2(n);
    glm::vec3 r(0.0f);
    for (int i = 0; i < kShL2Count; ++i) r += c[i] * (kShCosineLobe[shBand(i)] * y[i]);
    return r;
  }
};

// L1 spherical harmonics of RGB radiance: bands 0-1 of ShL2Rgb (coefficients 0-3, same basis
// and convention). Cheaper (4 instead of 9 coefficients) and blurrier: L1 irradiance keeps
// A0 and A1 only, E(n) = A0 c0 Y00 + A1 sum_{i=1..3} c_i Y_i(n).
struct ShL1Rgb {
  std::array<glm::vec3, kShL1Count> c{};

  // Reconstructed radiance in direction d.
  glm::vec3 evaluate(glm::vec3 d) const {
    return c[0] * 0.282095f + (c[1] * d.y + c[2] * d.z + c[3] * d.x) * 0.488603f;
  }
  // Irradiance E (not E / pi) on a surface with unit normal n.
  glm::vec3 irradiance(glm::vec3 n) const {
    return c[0] * (kShCosineLobe[0] * 0.282095f) +
           (c[1] * n.y + c[2] * n.z + c[3] * n.x) * (kShCosineLobe[1] * 0.488603f);
  }
};

}  // namespace kiln
