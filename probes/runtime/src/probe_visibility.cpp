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
// The reach factor of a point beyond every ray of its texels: tiny, not 0, so that v stays
// above 0 and, with minVisibleWeight 0 (full renormalization), a cell whose probes are all
// hidden still weights them by how hidden each is.
constexpr float kHiddenReach = 1e-12f;

// octahedralFootprint, inline so that probeVisibility (four calls per lookup) keeps the texels
// in registers.
inline OctahedralFootprint footprint(glm::vec2 uv, int32_t r) {
  // Continuous texel coordinates: texel i's centre is at i + 0.5. Clamped so that NaN goes
  // to 0 (std::clamp passes it through to the int conversion below: undefined, and texel
  // indices far outside the map), so a NaN coordinate reads the map's first column or row;
  // std::max(0, v) is that (and one maxss; std::fmax is a library call here).
  const float fr = float(r);
  const float x = std::min(std::max(0.0f, (uv.x + 1.0f) * 0.5f * fr), fr) - 0.5f;
  const float y = std::min(std::max(0.0f, (uv.y + 1.0f) * 0.5f * fr), fr) - 0.5f;
  // floor(x) for x >= -0.5 (as here): truncation, or -1 below 0 (std::floor is a library call
  // or a long SSE2 sequence without SSE4.1's roundss).
  const int32_t i = x < 0.0f ? -1 : int32_t(x), j = y < 0.0f ? -1 : int32_t(y);
  const float tx = x - float(i), ty = y - float(j);
  OctahedralFootprint f;
  if (i >= 0 && j >= 0 && i + 1 < r && j + 1 < r) {
    // Inside the map (all but a half-texel border): no wrapping.
    f.texel[0] = j * r + i;
    f.texel[1] = f.texel[0] + 1;
    f.texel[2] = f.texel[0] + r;
    f.texel[3] = f.texel[2] + 1;
  } else {
    f.texel[0] = wrapTexel(i, j, r);
    f.texel[1] = wrapTexel(i + 1, j, r);
    f.texel[2] = wrapTexel(i, j + 1, r);
    f.texel[3] = wrapTexel(i + 1, j + 1, r);
  }
  f.weight[0] = (1.0f - tx) * (1.0f - ty);
  f.weight[1] = tx * (1.0f - ty);
  f.weight[2] = (1.0f - tx) * ty;
  f.weight[3] = tx * ty;
  return f;
}

}  // namespace

glm::vec2 octahedralEncode(glm::vec3 d) noexcept {
  const float l1 = std::fabs(d.x) + std::fabs(d.y) + std::fabs(d.z);
  if (!(l1 > 0.0f)) return glm::vec2(0.0f);
  const float inv = 1.0f / l1;  // one division for both coordinates
  glm::vec2 p(d.x * inv, d.y * inv);
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
  return footprint(uv, r);
}

float probeVisibility(std::span<const uint16_t> moments, int32_t r, float maxDistance,
                      glm::vec3 offset, const ProbeBlendSettings& s) noexcept {
  const float length = std::sqrt(glm::dot(offset, offset));
  if (!(length > 0.0f) || !(maxDistance > 0.0f) || r <= 0) return 1.0f;
  const float inverseD = 1.0f / maxDistance;
  const float d = std::clamp((length - s.distanceBias) * inverseD, 0.0f, 1.0f);
  // The octahedral map is scale-invariant (it divides by the L1 norm), so the offset goes in
  // as it is: normalizing it first would put a division on the lookup's critical path for a
  // change in the last bit.
  const OctahedralFootprint f = footprint(octahedralEncode(offset), r);
  // Depth, spread and far are interpolated separately: a tilted wall's depth changes by a lot
  // between neighbouring texels, and the spread of those texel values (what interpolating the
  // second moment would add) is no uncertainty about where the wall is along this direction.
  // The spread is interpolated as sigma, not sigma^2, so that a texel at a silhouette (wall
  // and window in one texel: a large sigma) does not widen its neighbours' test by its
  // weight x sigma^2 where its weight is small.
  float mean = 0.0f, sigma = 0.0f, far = 0.0f;
  for (int k = 0; k < 4; ++k) {
    const uint16_t* texel = &moments[3 * size_t(f.texel[k])];
    mean += f.weight[k] * float(texel[0]);
    sigma += f.weight[k] * float(texel[1]);
    far += f.weight[k] * float(texel[2]);
  }
  mean *= kUnorm16;
  far *= kUnorm16;
  // A zero minSigma (allowed from C++) would make the far ramp a 0/0 at d = far.
  const float minSigma = std::max(s.minSigma, 1e-6f) * inverseD;
  // Beyond the farthest any of the texels' rays went, every ray stopped short of the point:
  // hidden, whatever a wide (e.g. two-surface) distribution lets Chebyshev's bound say. The
  // cut is a ramp minSigma wide, so v stays continuous in d.
  const float reach = std::clamp(1.0f - (d - far) / minSigma, kHiddenReach, 1.0f);
  if (d <= mean) return std::max(reach, kVisibilityFloor);
  sigma = std::max(sigma * kUnorm16, minSigma);
  const float variance = sigma * sigma;
  const float excess = d - mean;
  const float chebyshev = variance / (variance + excess * excess);
  return std::max(chebyshev * chebyshev * chebyshev * reach, kVisibilityFloor);
}

}  // namespace kiln
