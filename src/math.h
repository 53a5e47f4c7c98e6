// math.h: small geometric helpers on top of GLM shared by the whole core.
//
// Conventions (MISSION.md): glTF world axes (+Y up, right-handed), metres, float geometry,
// double accumulation where sums get long.
#pragma once

#include <glm/glm.hpp>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <limits>

namespace kiln {

using glm::mat3;
using glm::mat4;
using glm::uvec3;
using glm::vec2;
using glm::vec3;
using glm::vec4;

inline constexpr float kPi = 3.14159265358979323846f;
inline constexpr float kInvPi = 0.31830988618379067154f;
inline constexpr float kInfinity = std::numeric_limits<float>::infinity();

// Rec. 709 luminance of linear RGB.
inline float luminance(vec3 c) { return 0.2126f * c.r + 0.7152f * c.g + 0.0722f * c.b; }

inline float maxComponent(vec3 c) { return std::max(c.x, std::max(c.y, c.z)); }

inline bool isFinite(vec3 v) {
  return std::isfinite(v.x) && std::isfinite(v.y) && std::isfinite(v.z);
}

// Axis-aligned bounds; empty when min > max.
struct Bounds3 {
  vec3 min{kInfinity};
  vec3 max{-kInfinity};

  bool empty() const { return min.x > max.x || min.y > max.y || min.z > max.z; }
  void extend(vec3 p) {
    min = glm::min(min, p);
    max = glm::max(max, p);
  }
  void extend(const Bounds3& b) {
    min = glm::min(min, b.min);
    max = glm::max(max, b.max);
  }
  vec3 extent() const { return empty() ? vec3(0.0f) : max - min; }
  vec3 center() const { return 0.5f * (min + max); }
  float diagonal() const { return glm::length(extent()); }
  bool contains(vec3 p) const {
    return p.x >= min.x && p.y >= min.y && p.z >= min.z && p.x <= max.x && p.y <= max.y &&
           p.z <= max.z;
  }
};

// Orthonormal frame around a unit normal n (Duff et al. 2017, "Building an Orthonormal
// Basis, Revisited"): toWorld maps local (x, y, z) with z along n into world space.
struct Frame {
  vec3 t, b, n;

  static Frame fromNormal(vec3 n) {
    float sign = std::copysign(1.0f, n.z);
    float a = -1.0f / (sign + n.z);
    float bb = n.x * n.y * a;
    return Frame{vec3(1.0f + sign * n.x * n.x * a, sign * bb, -sign * n.x),
                 vec3(bb, sign + n.y * n.y * a, -n.y), n};
  }
  vec3 toWorld(vec3 v) const { return v.x * t + v.y * b + v.z * n; }
  vec3 toLocal(vec3 v) const { return vec3(glm::dot(v, t), glm::dot(v, b), glm::dot(v, n)); }
};

// Offsets a ray origin off a surface along its geometric normal, scaled with the magnitude
// of the position so that large coordinates stay robust (cf. Wächter & Binder, Ray Tracing
// Gems ch. 6). `ng` must face the side the new ray leaves from.
inline vec3 offsetRayOrigin(vec3 p, vec3 ng) {
  float scale = 1e-4f + 2e-6f * maxComponent(glm::abs(p));
  return p + scale * ng;
}

// The point of triangle (a, b, c) nearest to p (Ericson, Real-Time Collision Detection 5.1.5:
// Voronoi regions of the vertices, then the edges, else the face).
inline vec3 closestPointOnTriangle(vec3 p, vec3 a, vec3 b, vec3 c) {
  const vec3 ab = b - a, ac = c - a, ap = p - a;
  const float d1 = glm::dot(ab, ap), d2 = glm::dot(ac, ap);
  if (d1 <= 0.0f && d2 <= 0.0f) return a;
  const vec3 bp = p - b;
  const float d3 = glm::dot(ab, bp), d4 = glm::dot(ac, bp);
  if (d3 >= 0.0f && d4 <= d3) return b;
  const float vc = d1 * d4 - d3 * d2;
  if (vc <= 0.0f && d1 >= 0.0f && d3 <= 0.0f) return a + ab * (d1 / (d1 - d3));
  const vec3 cp = p - c;
  const float d5 = glm::dot(ab, cp), d6 = glm::dot(ac, cp);
  if (d6 >= 0.0f && d5 <= d6) return c;
  const float vb = d5 * d2 - d1 * d6;
  if (vb <= 0.0f && d2 >= 0.0f && d6 <= 0.0f) return a + ac * (d2 / (d2 - d6));
  const float va = d3 * d6 - d5 * d4;
  if (va <= 0.0f && d4 - d3 >= 0.0f && d5 - d6 >= 0.0f)
    return b + (c - b) * ((d4 - d3) / ((d4 - d3) + (d5 - d6)));
  const float denom = 1.0f / (va + vb + vc);
  return a + ab * (vb * denom) + ac * (vc * denom);
}

}  // namespace kiln
