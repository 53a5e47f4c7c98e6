// predicates.h: robust orientation test for the probe tetrahedralization and lookup.
//
// The walk through the tetrahedra (probe_runtime.h) decides which face to cross from the sign
// of orientation determinants; a wrong sign from round-off can send it round in circles on
// nearly degenerate cells. Following Shewchuk ("Adaptive Precision Floating-Point Arithmetic
// and Fast Robust Geometric Predicates", 1997), the determinant is first evaluated in double
// precision with a forward error bound; only when the result is within that bound is it
// recomputed exactly with floating-point expansions. Inputs are floats, so every triple
// product of coordinates is exactly a two-term expansion (one exact double product followed
// by an FMA-based two-product), which keeps the exact path short.
#pragma once

#include <cmath>

#include <glm/glm.hpp>

namespace kiln {

// The same determinant computed only by the exact expansion path (for tests, and the
// rare queries the filter below cannot settle).
double orient3dExact(glm::vec3 a, glm::vec3 b, glm::vec3 c, glm::vec3 d) noexcept;

// orient3d(a, b, c, d) = det[b - a; c - a; d - a] = dot(cross(b - a, c - a), d - a): six times
// the signed volume of the tetrahedron abcd; positive when d lies on the side of the plane abc
// that cross(b - a, c - a) points to. The SIGN is exact (0 only for exactly coplanar points);
// the magnitude is accurate to double precision. Thread-safe, no allocation. Inline: the
// double evaluation and its error bound settle almost every call. Like every floating-point
// filter it relies on IEEE arithmetic: do not compile it with -ffast-math.
inline double orient3d(glm::vec3 a, glm::vec3 b, glm::vec3 c, glm::vec3 d) noexcept {
  const double bax = double(b.x) - a.x, bay = double(b.y) - a.y, baz = double(b.z) - a.z;
  const double cax = double(c.x) - a.x, cay = double(c.y) - a.y, caz = double(c.z) - a.z;
  const double dax = double(d.x) - a.x, day = double(d.y) - a.y, daz = double(d.z) - a.z;
  const double m0 = cay * daz - caz * day;
  const double m1 = caz * dax - cax * daz;
  const double m2 = cax * day - cay * dax;
  const double det = bax * m0 + bay * m1 + baz * m2;
  const double permanent = std::fabs(bax) * (std::fabs(cay * daz) + std::fabs(caz * day)) +
                           std::fabs(bay) * (std::fabs(caz * dax) + std::fabs(cax * daz)) +
                           std::fabs(baz) * (std::fabs(cax * day) + std::fabs(cay * dax));
  // Shewchuk's bound for exact differences is about 7.8e-16 x permanent; float differences
  // in double may round once more each (relative 1.1e-16), so 1e-14 is a safe margin.
  const double bound = 1e-14 * permanent;
  if (det > bound || -det > bound) return det;
  if (!std::isfinite(det)) return det;
  const double exact = orient3dExact(a, b, c, d);
  if (exact == 0.0) return 0.0;
  // Keep the double magnitude when it agrees in sign (it is the better estimate).
  if ((exact > 0.0) == (det > 0.0) && det != 0.0) return det;
  return exact;
}

}  // namespace kiln
