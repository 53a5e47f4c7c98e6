// predicates.cpp: filtered exact orient3d (Shewchuk 1997, "Adaptive Precision Floating-Point
// Arithmetic and Fast Robust Geometric Predicates"): a double evaluation with an error bound,
// then an exact sum of floating-point expansion terms when the bound does not settle the sign.
// The filter is inline in predicates.h; this file holds the exact path.
#include "kiln/predicates.h"

#include <cmath>

namespace kiln {
namespace {

// Knuth's two-sum: x + y == a + b exactly, with x = fl(a + b).
inline void twoSum(double a, double b, double& x, double& y) {
  x = a + b;
  double bv = x - a;
  double av = x - bv;
  double br = b - bv;
  double ar = a - av;
  y = ar + br;
}

// A nonoverlapping expansion in increasing magnitude order (Shewchuk's GROW-EXPANSION with
// zero elimination); its sign is the sign of its last (largest) component.
struct Expansion {
  double e[64];
  int n = 0;
  void add(double b) {
    double q = b;
    int m = 0;
    for (int i = 0; i < n; ++i) {
      double h;
      twoSum(q, e[i], q, h);
      if (h != 0.0) e[m++] = h;
    }
    if (q != 0.0) e[m++] = q;
    n = m;
  }
  // a * b * c for float inputs, exactly: a * b fits in 48 bits, so only the last product
  // rounds, and its error is recovered with an FMA.
  void addProduct(double a, double b, double c, bool negate) {
    double ab = a * b;
    double hi = ab * c;
    double lo = std::fma(ab, c, -hi);
    if (negate) {
      hi = -hi;
      lo = -lo;
    }
    add(lo);
    add(hi);
  }
  double estimate() const { return n == 0 ? 0.0 : e[n - 1]; }
};

// det[r0; r1; r2] added to `x` with sign s, as its six exact triple products.
void addDet3(Expansion& x, glm::vec3 r0, glm::vec3 r1, glm::vec3 r2, bool negate) {
  auto add = [&](float a, float b, float c, bool neg) {
    x.addProduct(a, b, c, neg != negate);
  };
  add(r0.x, r1.y, r2.z, false);
  add(r0.x, r1.z, r2.y, true);
  add(r0.y, r1.x, r2.z, true);
  add(r0.y, r1.z, r2.x, false);
  add(r0.z, r1.x, r2.y, false);
  add(r0.z, r1.y, r2.x, true);
}

}  // namespace

double orient3dExact(glm::vec3 a, glm::vec3 b, glm::vec3 c, glm::vec3 d) noexcept {
  // Multilinearity: det[b-a; c-a; d-a] = det(b,c,d) - det(a,c,d) + det(a,b,d) - det(a,b,c).
  Expansion x;
  addDet3(x, b, c, d, false);
  addDet3(x, a, c, d, true);
  addDet3(x, a, b, d, false);
  addDet3(x, a, b, c, true);
  return x.estimate();
}

}  // namespace kiln
