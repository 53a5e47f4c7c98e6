// probe_visibility.cpp: octahedral mapping and the Chebyshev visibility test (see
// probe_visibility.h).
#include "kiln/probe_visibility.h"

#include <algorithm>
#include <cmath>

namespace kiln {
namespace {

// sign() with sign(0) = +1, so that directions on the map's axes encode one way only.
inline float signNotZero(float x) { return x >= 0.0f ? 1.0f : -1.0f; }

// Texel (i, j) of the R x R map with the octahedral wrap applied to indices one beyond an
// edge (the only ones a bilinear footprint reaches): crossing the right or left edge mirrors
// j, crossing the top or bottom edge mirrors i, a corner maps to the opposite corner.
inline int32_t wrapTexel(int32_t i, int32_t j, int32_t r) {
  if (i < 0) {
    i = 0;
    j = r - 1 - j;
  } else if (i >= r) {
    i = r - 1;
    j = r - 1 - j;
  }
  if (j < 0) {
    j = 0;
    i = r - 1 - i;
  } else if (j >= r) {
    j = r - 1;
    i = r - 1 - i;
  }
  return j * r + i;
}

constexpr float kUnorm16 = 1.0f / 65535.0f;

}  // namespace

glm::vec2 octahedralEncode(glm::vec3 d) noexcept {
  const float l1 = std::fabs(d.x) + std::fabs(d.y) + std::fabs(d.z);
  if (!(l1 > 0.0f)) return glm::vec2(0.0f);
  glm::vec2 p(d.x / l1, d.y / l1);
  if (d.z < 0.0f) {
    p = glm::vec2((1.0f - std::fabs(p.y)) * signNotZero(p.x),
                  (1.0f - std::fabs(p.x)) * signNotZero(p.y));
  }
  return p;
}

glm::vec3 octahedralDecode(glm::vec2 uv) noexcept {
  glm::vec3 v(uv.x, uv.y, 1.0f - std::fabs(uv.x) - std::fabs(uv.y));
  if (v.z < 0.0f) {
    const float x = v.x;
    v.x = (1.0f - std::fabs(v.y)) * signNotZero(x);
    v.y = (1.0f - std::fabs(x)) * signNotZero(v.y);
  }
  return glm::normalize(v);
}

OctahedralFootprint octahedralFootprint(glm::vec2 uv, int32_t r) noexcept {
  // Continuous texel coordinates: texel i's centre is at i + 0.5.
  const float x = std::clamp((uv.x + 1.0f) * 0.5f * float(r), 0.0f, float(r)) - 0.5f;
  const float y = std::clamp((uv.y + 1.0f) * 0.5f * float(r), 0.0f, float(r)) - 0.5f;
  const float fx = std::floor(x), fy = std::floor(y);
  const int32_t i = int32_t(fx), j = int32_t(fy);
  const float tx = x - fx, ty = y - fy;
  OctahedralFootprint f;
  f.texel[0] = wrapTexel(i, j, r);
  f.texel[1] = wrapTexel(i + 1, j, r);
  f.texel[2] = wrapTexel(i, j + 1, r);
  f.texel[3] = wrapTexel(i + 1, j + 1, r);
  f.weight[0] = (1.0f - tx) * (1.0f - ty);
  f.weight[1] = tx * (1.0f - ty);
  f.weight[2] = (1.0f - tx) * ty;
  f.weight[3] = tx * ty;
  return f;
}

float probeVisibility(std::span<const uint16_t> moments, int32_t r, float maxDistance,
                      glm::vec3 offset, const ProbeBlendSettings& s) noexcept {
  const float length = std::sqrt(glm::dot(offset, offset));
  if (!(length > 0.0f) || !(maxDistance > 0.0f) || r <= 0) return 1.0f;
  const float d = std::clamp((length - s.distanceBias) / maxDistance, 0.0f, 1.0f);
  const OctahedralFootprint f = octahedralFootprint(octahedralEncode(offset / length), r);
  float mean = 0.0f, meanSquare = 0.0f;
  for (int k = 0; k < 4; ++k) {
    const size_t t = 2 * size_t(f.texel[k]);
    mean += f.weight[k] * float(moments[t]);
    meanSquare += f.weight[k] * float(moments[t + 1]);
  }
  mean *= kUnorm16;
  meanSquare *= kUnorm16;
  if (d <= mean) return 1.0f;
  const float minSigma = s.minSigma / maxDistance;
  const float variance = std::max(meanSquare - mean * mean, minSigma * minSigma);
  const float excess = d - mean;
  const float chebyshev = variance / (variance + excess * excess);
  return std::max(chebyshev * chebyshev * chebyshev, kVisibilityFloor);
}

}  // namespace kiln
