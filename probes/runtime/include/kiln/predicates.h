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

#include <glm/glm.hpp>

namespace kiln {

// orient3d(a, b, c, d) = det[b - a; c - a; d - a] = dot(cross(b - a, c - a), d - a): six times
// the signed volume of the tetrahedron abcd; positive when d lies on the side of the plane abc
// that cross(b - a, c - a) points to. The SIGN is exact (0 only for exactly coplanar points);
// the magnitude is accurate to double precision. Thread-safe, no allocation.
double orient3d(glm::vec3 a, glm::vec3 b, glm::vec3 c, glm::vec3 d) noexcept;

// The same determinant computed only by the exact expansion path (for tests).
double orient3dExact(glm::vec3 a, glm::vec3 b, glm::vec3 c, glm::vec3 d) noexcept;

}  // namespace kiln
