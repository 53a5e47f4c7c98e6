// probe_runtime.cpp: point location in the probe tetrahedralization and SH blending.
//
// Inside the hull: a visibility walk (Cupisz, GDC 2012; Devillers, Pion and Teillaud, "Walking
// in a triangulation", 2002) that leaves each tetrahedron across the face with the most
// negative barycentric coordinate. Signs come from the filtered exact orient3d
// (predicates.h), so on a Delaunay tetrahedralization the walk terminates; a step cap and a
// scan of all cells make it terminate on any input. Outside the hull: Cupisz's outer cells,
// solving a cubic for the offset t at which the hull triangle swept along its vertex normals
// passes through the point.
#include "kiln/probe_runtime.h"

#include <algorithm>
#include <cmath>
#include <cstddef>
#include <cstring>
#include <limits>

#if defined(__SSE2__)
#include <immintrin.h>
#endif

#include "kiln/predicates.h"
#include "prefetch.h"

namespace kiln {
namespace {

using glm::dvec3;
using runtime_detail::prefetch;

// Outer-cell barycentrics this far below zero still count as inside (then clamped); keeps
// neighbouring outer cells from both rejecting a point on their shared swept edge.
constexpr double kOuterTolerance = 1e-7;

dvec3 d3(glm::vec3 v) { return dvec3(v); }

// Writes n weights (clamped to >= 0, normalised) and pads unused slots.
void finish(ProbeLocation& loc, int32_t cell, const int32_t* probes, const double* w, int n) {
  loc.cell = cell;
  double sum = 0.0;
  double c[4] = {0, 0, 0, 0};
  for (int k = 0; k < n; ++k) {
    c[k] = std::isfinite(w[k]) ? std::max(w[k], 0.0) : 0.0;
    sum += c[k];
  }
  if (!(sum > 0.0) || !std::isfinite(sum)) {
    // Degenerate cell (should not happen on validated data): fall back to its first probe.
    for (int k = 0; k < n; ++k) c[k] = 0.0;
    c[0] = 1.0;
    sum = 1.0;
  }
  for (int k = 0; k < 4; ++k) {
    loc.probes[k] = k < n ? probes[k] : probes[0];
    loc.weights[k] = k < n ? float(c[k] / sum) : 0.0f;
  }
  loc.barycentric = loc.weights;
}

// ---- dimension 3 -------------------------------------------------------------------------

// Signed sub-volumes of p against tetrahedron `cell` (b[k]: vertex k replaced by p). Returns
// the face to leave by (most negative, exact sign) or -1 when p is inside or on the boundary.
int evalTet(const ProbeSet& s, int32_t cell, glm::vec3 p, double b[4]) {
  const glm::ivec4 t = s.cells[cell];
  const glm::vec3 v0 = s.positions[t[0]], v1 = s.positions[t[1]], v2 = s.positions[t[2]],
                  v3 = s.positions[t[3]];
  b[0] = orient3d(p, v1, v2, v3);
  b[1] = orient3d(v0, p, v2, v3);
  b[2] = orient3d(v0, v1, p, v3);
  b[3] = orient3d(v0, v1, v2, p);
  int exit = -1;
  double most = 0.0;
  for (int k = 0; k < 4; ++k) {
    if (b[k] < most) {
      most = b[k];
      exit = k;
    }
  }
  return exit;
}

double horner(const double c[4], double t) { return ((c[0] * t + c[1]) * t + c[2]) * t + c[3]; }
double hornerDerivative(const double c[4], double t) {
  return (3.0 * c[0] * t + 2.0 * c[1]) * t + c[2];
}
int sgn(double x) { return (x > 0.0) - (x < 0.0); }

// Root of the polynomial in [lo, hi] where it changes sign: bisection safeguarded Newton.
double refineRoot(const double c[4], double lo, double hi) {
  const int slo = sgn(horner(c, lo));
  double t = 0.5 * (lo + hi);
  for (int i = 0; i < 200; ++i) {
    const double ft = horner(c, t);
    if (ft == 0.0) return t;
    if (sgn(ft) == slo) {
      lo = t;
    } else {
      hi = t;
    }
    const double df = hornerDerivative(c, t);
    double next = df != 0.0 ? t - ft / df : 0.5 * (lo + hi);
    if (!(next > lo && next < hi)) next = 0.5 * (lo + hi);
    if (std::fabs(next - t) <= 1e-15 * std::max(1.0, std::fabs(t)) || hi - lo <= 0.0) {
      return next;
    }
    t = next;
  }
  return t;
}

// Non-negative real roots of c[0] t^3 + c[1] t^2 + c[2] t + c[3], increasing, found by
// splitting [0, inf) at the critical points into monotone pieces; works unchanged when the
// leading coefficients vanish (flat hull regions give a linear equation). `scale` is a
// typical length, the first step when searching for a bracket towards infinity.
int nonNegativeRoots(const double c[4], double scale, double roots[3]) {
  double crit[2];
  int nc = 0;
  const double qa = 3.0 * c[0], qb = 2.0 * c[1], qc = c[2];
  if (qa == 0.0) {
    if (qb != 0.0) crit[nc++] = -qc / qb;
  } else {
    const double disc = qb * qb - 4.0 * qa * qc;
    if (disc >= 0.0) {
      const double q = -0.5 * (qb + std::copysign(std::sqrt(disc), qb));
      crit[nc++] = q / qa;
      if (q != 0.0) crit[nc++] = qc / q;
    }
  }
  if (nc == 2 && crit[0] > crit[1]) std::swap(crit[0], crit[1]);
  double breaks[4];
  int nb = 0;
  breaks[nb++] = 0.0;
  for (int i = 0; i < nc; ++i) {
    if (std::isfinite(crit[i]) && crit[i] > breaks[nb - 1]) breaks[nb++] = crit[i];
  }
  const double inf = std::numeric_limits<double>::infinity();
  breaks[nb++] = inf;
  int signInf = sgn(c[0]);
  for (int i = 1; i < 4 && signInf == 0; ++i) signInf = sgn(c[i]);

  int n = 0;
  for (int i = 0; i + 1 < nb && n < 3; ++i) {
    const double lo = breaks[i];
    double hi = breaks[i + 1];
    const double flo = horner(c, lo);
    if (flo == 0.0) {
      if (n == 0 || roots[n - 1] != lo) roots[n++] = lo;
      continue;
    }
    int shi = hi == inf ? signInf : sgn(horner(c, hi));
    if (shi == 0 || shi == sgn(flo)) continue;
    if (hi == inf) {
      double step = scale > 0.0 ? scale : 1.0;
      hi = lo + step;
      int iter = 0;
      while (sgn(horner(c, hi)) == sgn(flo) && iter++ < 2100 && std::isfinite(hi)) {
        step *= 2.0;
        hi = lo + step;
      }
      if (!std::isfinite(hi) || sgn(horner(c, hi)) == sgn(flo)) continue;
    }
    roots[n++] = refineRoot(c, lo, hi);
  }
  return n;
}

// Barycentrics of p with respect to triangle abc (p assumed in its plane, else projected).
void triangleBarycentrics(dvec3 a, dvec3 b, dvec3 c, dvec3 p, double w[3]) {
  const dvec3 n = glm::cross(b - a, c - a);
  const double den = glm::dot(n, n);
  if (!(den > 0.0)) {
    w[0] = 1.0;
    w[1] = w[2] = 0.0;
    return;
  }
  w[0] = glm::dot(glm::cross(b - p, c - p), n) / den;
  w[1] = glm::dot(glm::cross(c - p, a - p), n) / den;
  w[2] = glm::dot(glm::cross(a - p, b - p), n) / den;
}

struct OuterEval {
  int exit = -1;  // -1: inside; 3: back into the hull; 0..2: across a swept edge
  double w[3] = {0, 0, 0};
};

OuterEval evalOuter(const ProbeSet& s, int32_t cell, glm::vec3 p) {
  OuterEval e;
  const glm::ivec4 t = s.cells[cell];
  const glm::vec3 A = s.positions[t[0]], B = s.positions[t[1]], C = s.positions[t[2]];
  const double side = orient3d(A, B, C, p);
  if (side < 0.0) {
    e.exit = 3;
    e.w[0] = side;  // only used as a (poor) score by the scan
    return e;
  }
  const OuterCell& oc = s.outerCells[size_t(cell - s.innerCellCount)];
  const dvec3 q = d3(p) - d3(A);
  double coef[4];
  for (int i = 0; i < 4; ++i) {
    coef[i] = glm::dot(dvec3(oc.cubic[i]), q) + double(oc.cubic[i].w);
  }
  double roots[3];
  int nr;
  if (side == 0.0 || coef[3] <= 0.0) {
    roots[0] = 0.0;  // on the hull plane (or round-off says so): the triangle itself
    nr = 1;
  } else {
    const double scale = std::sqrt(std::sqrt(glm::dot(dvec3(oc.cubic[3]), dvec3(oc.cubic[3]))));
    nr = nonNegativeRoots(coef, scale, roots);
    if (nr == 0) {
      roots[0] = 0.0;  // degenerate normals: project onto the hull triangle
      nr = 1;
    }
  }
  const dvec3 nA(oc.normals[0]), nB(oc.normals[1]), nC(oc.normals[2]);
  double first[3] = {0, 0, 0};
  for (int r = 0; r < nr; ++r) {
    const double tr = roots[r];
    double w[3];
    triangleBarycentrics(d3(A) + tr * nA, d3(B) + tr * nB, d3(C) + tr * nC, d3(p), w);
    if (r == 0) std::copy(w, w + 3, first);
    if (w[0] >= -kOuterTolerance && w[1] >= -kOuterTolerance && w[2] >= -kOuterTolerance) {
      std::copy(w, w + 3, e.w);
      e.exit = -1;
      return e;
    }
  }
  std::copy(first, first + 3, e.w);
  e.exit = int(std::min_element(first, first + 3) - first);
  return e;
}

// The index into grid.seeds of the grid cell around p (the nearest one outside the grid), or
// kNoSeed when the set has no grid.
constexpr size_t kNoSeed = ~size_t(0);
size_t seedSlot(const ProbeSet& s, glm::vec3 p) {
  const ProbeSeedGrid& g = s.grid;
  if (g.size.x <= 0 || g.seeds.empty()) return kNoSeed;
  glm::ivec3 idx;
  for (int a = 0; a < 3; ++a) {
    const float ext = g.max[a] - g.min[a];
    float f = ext > 0.0f ? (p[a] - g.min[a]) / ext * float(g.size[a]) : 0.0f;
    if (!(f >= 0.0f)) f = 0.0f;  // also catches NaN
    idx[a] = std::min(int(std::min(f, 1e9f)), g.size[a] - 1);
  }
  return size_t(idx.x) + size_t(g.size.x) * (size_t(idx.y) + size_t(g.size.y) * idx.z);
}

int32_t seedAt(const ProbeSet& s, size_t slot) {
  return slot == kNoSeed ? 0 : s.grid.seeds[slot];
}

int32_t seedCell(const ProbeSet& s, glm::vec3 p) { return seedAt(s, seedSlot(s, p)); }

void setTet(const ProbeSet& s, ProbeLocation& loc, int32_t cell, const double b[4]) {
  const glm::ivec4 t = s.cells[cell];
  const int32_t probes[4] = {t[0], t[1], t[2], t[3]};
  finish(loc, cell, probes, b, 4);
}

void setOuter(const ProbeSet& s, ProbeLocation& loc, int32_t cell, const double w[3]) {
  const glm::ivec4 t = s.cells[cell];
  const int32_t probes[3] = {t[0], t[1], t[2]};
  finish(loc, cell, probes, w, 3);
}

void scan3(const ProbeSet& s, glm::vec3 p, ProbeLocation& loc) {
  loc.bruteForce = true;
  double bestScore = -std::numeric_limits<double>::infinity();
  int32_t bestCell = -1;
  double bestW[4] = {1, 0, 0, 0};
  for (int32_t c = 0; c < s.innerCellCount; ++c) {
    double b[4];
    if (evalTet(s, c, p, b) < 0) {
      setTet(s, loc, c, b);
      return;
    }
    const double total = b[0] + b[1] + b[2] + b[3];
    if (!(total > 0.0)) continue;
    const double score = std::min(std::min(b[0], b[1]), std::min(b[2], b[3])) / total;
    if (score > bestScore) {
      bestScore = score;
      bestCell = c;
      std::copy(b, b + 4, bestW);
    }
  }
  for (int32_t c = s.innerCellCount; c < s.cellCount(); ++c) {
    const OuterEval e = evalOuter(s, c, p);
    if (e.exit < 0) {
      setOuter(s, loc, c, e.w);
      return;
    }
    if (e.exit == 3) continue;
    const double score = std::min(std::min(e.w[0], e.w[1]), e.w[2]);
    if (score > bestScore) {
      bestScore = score;
      bestCell = c;
      std::copy(e.w, e.w + 3, bestW);
    }
  }
  if (bestCell < 0) bestCell = 0;
  if (bestCell < s.innerCellCount) {
    setTet(s, loc, bestCell, bestW);
  } else {
    setOuter(s, loc, bestCell, bestW);
  }
}

// ---- dimension 3: the float fast path ----------------------------------------------------
//
// A step computes p's barycentric coordinates in float from the cell's record (ProbeWalkCell):
// l_k = c_k + g_k . q with q = p - origin, g_k lane k's gradient and c = (1, 0, 0, 0). It
// trusts a sign only beyond an error bound; when no bound settles the step (p within about
// 1e-6 relative of a face, or a sliver) the step is made with the exact predicates instead
// (evalTet). The error of l_k (u = 2^-24, float rounding): walkRecord makes each gradient
// entry accurate to 1.07 u relative; q rounds once (u relative per component); the 3-term dot
// product rounds within 3 u x sum_j |g_kj q_j|, with or without FMA; lane 0's addition of 1
// rounds within u |l_0| <= u (1 + S_0) (1 + 6 u). So, with S_k = sum_j |g_kj| |q_j|,
//   |l_k - lambda_k| <= 5.1 u S_k for k = 1, 2, 3, and 6.2 u S_0 + 1.01 u for k = 0.
// Two bounds rest on this.
//  - The record's `inside` settles the common case, a point inside its cell, with one compare:
//    every l_k > inside proves every lambda_k > 0. Proof: q = sum_m lambda_m e_m (e_m = v_m -
//    v0), so S_k <= Lambda T_k with T_k = sum_j |g_kj| D_j, D_j = sum_m |e_mj| and Lambda =
//    max_m |lambda_m|. Every l_k > 0 gives lambda_k > -err_k, and as the lambdas sum to 1,
//    Lambda <= 1 + sum_k err_k. walkRecord sets `inside` only where u sum_k T_k <= 2^-10 (else
//    infinity), which gives Lambda < 1.007 and err_k < 6.3 u T_k + 1.01 u; inside = 8 u max_k
//    T_k + 4 u + kTiny exceeds that, so l_k > inside implies lambda_k > 0.
//  - Otherwise the bound is computed from q: e_k = kFastError S_k + kTiny (+ 2 u in lane 0,
//    which also covers its kTiny). kFastError = 8 u covers 5.1 u (6.2 u in lane 0) with the
//    rounding of S itself; kTiny covers products that underflow. A step then decides:
//    - inside: every l_k > e_k, so every exact coordinate is positive: the exact walk stops
//      here too;
//    - exit: the smallest l_k is below -e_k and below every other l_j by more than both error
//      bounds, so it is the exact walk's most negative coordinate and the same face is left
//      (the exact walk ranks its double determinants, accurate to about 1e-15 of their
//      permanent: far inside that margin);
//    - otherwise (and for NaN): evalTet, the exact walk's own step.
// The fast walk thus visits the exact walk's cells and stops in the exact walk's cell; its
// weights are the float coordinates (within e_k of the exact ones).
constexpr float kUnitRoundoff = 5.9604645e-8f;  // 2^-24
constexpr float kFastError = 8.0f * kUnitRoundoff;
constexpr float kLaneZeroError = 2.0f * kUnitRoundoff;  // l_0's final addition of 1
constexpr float kTiny = 1.2e-38f;

// The decision from the coordinates l and their error bounds e (see above).
inline int fastDecision(const float l[4], const float e[4]) {
  if (l[0] > e[0] && l[1] > e[1] && l[2] > e[2] && l[3] > e[3]) return -1;
  int k = 0;
  for (int j = 1; j < 4; ++j) {
    if (l[j] < l[k]) k = j;
  }
  if (!(l[k] < -e[k])) return -2;
  const float upper = l[k] + e[k];
  for (int j = 0; j < 4; ++j) {
    if (j != k && !(l[j] - e[j] > upper)) return -2;
  }
  return k;
}

#if defined(__SSE2__)
// The four coordinates (and q, and the bounds) side by side in one SSE register: lane k is
// l_k. The record is 64-byte aligned (ProbeWalkCell), so every load is aligned.
using Lanes = __m128;

inline Lanes pointLanes(glm::vec3 p) { return _mm_setr_ps(p.x, p.y, p.z, 0.0f); }
inline glm::vec3 toPoint(Lanes p) {
  alignas(16) float a[4];
  _mm_store_ps(a, p);
  return {a[0], a[1], a[2]};
}

inline Lanes fastQ(const ProbeWalkCell& w, Lanes p) {
  return _mm_sub_ps(p, _mm_load_ps(&w.origin.x));
}

// l_k = (x[k] q.x + y[k] q.y) + z[k] q.z, then l_0 + 1.
inline Lanes fastCoordinates(const ProbeWalkCell& w, Lanes q) {
  const __m128 qx = _mm_shuffle_ps(q, q, _MM_SHUFFLE(0, 0, 0, 0)),
               qy = _mm_shuffle_ps(q, q, _MM_SHUFFLE(1, 1, 1, 1)),
               qz = _mm_shuffle_ps(q, q, _MM_SHUFFLE(2, 2, 2, 2));
  const __m128 l = _mm_add_ps(
      _mm_add_ps(_mm_mul_ps(_mm_load_ps(w.x.data()), qx), _mm_mul_ps(_mm_load_ps(w.y.data()), qy)),
      _mm_mul_ps(_mm_load_ps(w.z.data()), qz));
  return _mm_add_ss(l, _mm_set_ss(1.0f));
}

// Every l_k > w.inside (false for NaN).
inline bool fastInside(const ProbeWalkCell& w, Lanes l) {
  return _mm_movemask_ps(_mm_cmpgt_ps(l, _mm_set1_ps(w.inside))) == 0xF;
}

// The step's decision from bounds computed from q, for when w.inside does not settle it:
// -1 (inside), 0..3 (the face to leave by) or -2 (undecided).
inline int boundedDecision(const ProbeWalkCell& w, Lanes q, Lanes l) {
  const __m128 sign = _mm_set1_ps(-0.0f);
  const __m128 a = _mm_andnot_ps(sign, q);
  const __m128 ax = _mm_shuffle_ps(a, a, _MM_SHUFFLE(0, 0, 0, 0)),
               ay = _mm_shuffle_ps(a, a, _MM_SHUFFLE(1, 1, 1, 1)),
               az = _mm_shuffle_ps(a, a, _MM_SHUFFLE(2, 2, 2, 2));
  const __m128 s =
      _mm_add_ps(_mm_add_ps(_mm_mul_ps(_mm_andnot_ps(sign, _mm_load_ps(w.x.data())), ax),
                            _mm_mul_ps(_mm_andnot_ps(sign, _mm_load_ps(w.y.data())), ay)),
                 _mm_mul_ps(_mm_andnot_ps(sign, _mm_load_ps(w.z.data())), az));
  const __m128 e = _mm_add_ps(_mm_mul_ps(_mm_set1_ps(kFastError), s),
                              _mm_setr_ps(kLaneZeroError, kTiny, kTiny, kTiny));
  if (_mm_movemask_ps(_mm_cmpgt_ps(l, e)) == 0xF) return -1;
  float lf[4], ef[4];
  _mm_storeu_ps(lf, l);
  _mm_storeu_ps(ef, e);
  return fastDecision(lf, ef);
}

// The weights from coordinates that passed an inside test: l_1..l_3, and l_0 replaced by
// max(((1 - l_1) - l_2) - l_3, 0), which makes the four sum to 1 within three roundings
// (lane 0's own value is within its error bound of lambda_0 but sums with the others only to
// within theirs, up to 1e-5 in a thin cell); the clamp keeps a weight that rounding took
// below 0 (lambda_0 is positive) at 0.
inline std::array<float, 4> fastWeights(Lanes l) {
  const __m128 l0 = _mm_sub_ss(
      _mm_sub_ss(_mm_sub_ss(_mm_set_ss(1.0f), _mm_shuffle_ps(l, l, _MM_SHUFFLE(1, 1, 1, 1))),
                 _mm_shuffle_ps(l, l, _MM_SHUFFLE(2, 2, 2, 2))),
      _mm_shuffle_ps(l, l, _MM_SHUFFLE(3, 3, 3, 3)));
  std::array<float, 4> a;
  _mm_storeu_ps(a.data(), _mm_move_ss(l, _mm_max_ss(l0, _mm_setzero_ps())));
  return a;
}
#else
// The same lanes one by one, each with the SSE form's operations in its order.
using Lanes = std::array<float, 4>;

inline Lanes pointLanes(glm::vec3 p) { return {p.x, p.y, p.z, 0.0f}; }
inline glm::vec3 toPoint(Lanes p) { return {p[0], p[1], p[2]}; }

inline Lanes fastQ(const ProbeWalkCell& w, Lanes p) {
  return {p[0] - w.origin.x, p[1] - w.origin.y, p[2] - w.origin.z, 0.0f};
}

inline Lanes fastCoordinates(const ProbeWalkCell& w, Lanes q) {
  Lanes l;
  for (size_t k = 0; k < 4; ++k) l[k] = (w.x[k] * q[0] + w.y[k] * q[1]) + w.z[k] * q[2];
  l[0] += 1.0f;
  return l;
}

inline bool fastInside(const ProbeWalkCell& w, Lanes l) {
  return l[0] > w.inside && l[1] > w.inside && l[2] > w.inside && l[3] > w.inside;
}

inline int boundedDecision(const ProbeWalkCell& w, Lanes q, Lanes l) {
  const float ax = std::fabs(q[0]), ay = std::fabs(q[1]), az = std::fabs(q[2]);
  float e[4];
  for (size_t k = 0; k < 4; ++k) {
    const float s = (std::fabs(w.x[k]) * ax + std::fabs(w.y[k]) * ay) + std::fabs(w.z[k]) * az;
    e[k] = kFastError * s + (k == 0 ? kLaneZeroError : kTiny);
  }
  return fastDecision(l.data(), e);
}

inline std::array<float, 4> fastWeights(Lanes l) {
  return {std::max(((1.0f - l[1]) - l[2]) - l[3], 0.0f), l[1], l[2], l[3]};
}
#endif

// Returns -1 (inside, l = the coordinates), 0..3 (the face to leave by) or -2 (undecided).
inline int fastStep(const ProbeWalkCell& w, glm::vec3 p, Lanes& l) {
  const Lanes q = fastQ(w, pointLanes(p));
  l = fastCoordinates(w, q);
  if (fastInside(w, l)) return -1;
  return boundedDecision(w, q, l);
}

// The location a fast step that ended inside gives (every l_k finite and positive). The
// weights need no normalising: they sum to 1 within three roundings (fastWeights), as close as
// dividing by their sum would make them.
// Each array is copied whole (the compiler otherwise rebuilds the probes from scalars).
inline ProbeLocation fastLocation(const ProbeSet& s, int32_t cell, Lanes l, uint16_t steps) {
  ProbeLocation loc{cell, {}, {}, {}, steps, false};
  std::memcpy(loc.probes.data(), &s.cells[size_t(cell)], sizeof(loc.probes));
  loc.barycentric = fastWeights(l);
  loc.weights = loc.barycentric;
  return loc;
}

// The walk: with `walk` (the set's records) each step tries fastStep first; without, every
// step is exact (locateProbeExact).
// `firstStep`: cells already visited on the way to `cell` (counted in loc.steps and the cap).
void locate3(const ProbeSet& s, glm::vec3 p, int32_t cell, ProbeLocation& loc,
             const ProbeWalkCell* walk, int firstStep = 0) {
  for (int step = firstStep; step < kMaxWalkSteps; ++step) {
    loc.steps = uint16_t(std::min(step + 1, 65535));
    if (cell < s.innerCellCount) {
      int exit = -2;
      if (walk) {
        // The neighbours' line is read only after the step's decision: ask for it now, so
        // that a miss there overlaps the record's.
        prefetch(&s.neighbours[size_t(cell)]);
        Lanes l;
        exit = fastStep(walk[cell], p, l);
        if (exit == -1) {
          loc = fastLocation(s, cell, l, loc.steps);
          return;
        }
      }
      if (exit == -2) {
        double b[4];
        exit = evalTet(s, cell, p, b);
        if (exit < 0) {
          setTet(s, loc, cell, b);
          return;
        }
      }
      cell = s.neighbours[cell][exit];
    } else {
      const OuterEval e = evalOuter(s, cell, p);
      if (e.exit < 0) {
        setOuter(s, loc, cell, e.w);
        return;
      }
      cell = s.neighbours[cell][e.exit];
    }
    if (cell < 0) break;
  }
  scan3(s, p, loc);
}

// ---- dimension 3: interleaved walks (the batch forms) --------------------------------------
//
// A walk through a large set misses the cache at nearly every step (the grid's seed, then each
// record and its neighbours: a 100k-probe set's records fill 42 MB), and a single walk cannot
// overlap those misses, since each step's address comes from the step before. The batch forms
// advance up to kInterleavedWalks points' walks in turn instead: each walk's next lines are
// prefetched when its step is decided and read a round later, by which time the other walks'
// steps have hidden most of their latency. Only fast steps between inner cells are taken here; any other step
// (near a face, an outer cell, the hull) finishes that point with locate3 from the cell its
// walk has reached, which is the same walk's continuation. So each point gets locateProbe's
// cell, weights and steps (steps may differ only on a walk that reaches the step cap).
constexpr int kInterleavedWalks = 8;

struct InterleavedWalk {
  glm::vec3 p{0.0f};
  size_t index = 0;     // into the points
  size_t seed = 0;      // grid slot still to be read (cell < 0)
  int32_t cell = -1;    // the cell whose record the next round reads; -1: read the seed first
  uint16_t visited = 0; // cells left behind so far
};

// Calls emit(i, location) once for each point i, in no particular order. `hints`: null, or
// one hint per point (read before that point's walk starts).
template <typename Emit>
void locateInterleaved(const ProbeSet& s, std::span<const glm::vec3> points,
                       const int32_t* hints, const ProbeBlendSettings& blend, Emit&& emit) {
  const ProbeWalkCell* walk = s.walk.data();
  const int32_t inner = s.innerCellCount;
  size_t nextPoint = 0;
  // A step reads the record, then the neighbours (to leave) or the cell's probes (to stop).
  auto fetch = [&](int32_t cell) {
    if (cell < inner) prefetch(&walk[cell]);
    prefetch(&s.neighbours[size_t(cell)]);
    prefetch(&s.cells[size_t(cell)]);
  };
  auto start = [&](InterleavedWalk& w) {
    if (nextPoint >= points.size()) return false;
    w.index = nextPoint++;
    w.p = points[w.index];
    w.visited = 0;
    const int32_t hint = hints ? hints[w.index] : -1;
    if (hint >= 0 && hint < s.cellCount()) {
      w.cell = hint;
      fetch(hint);
    } else {
      w.cell = -1;
      w.seed = seedSlot(s, w.p);
      if (w.seed != kNoSeed) prefetch(&s.grid.seeds[w.seed]);
    }
    return true;
  };
  InterleavedWalk walks[kInterleavedWalks];
  bool live[kInterleavedWalks];
  int active = 0;
  for (int k = 0; k < kInterleavedWalks; ++k) active += (live[k] = start(walks[k])) ? 1 : 0;
  while (active > 0) {
    for (int k = 0; k < kInterleavedWalks; ++k) {
      if (!live[k]) continue;
      InterleavedWalk& w = walks[k];
      if (w.cell < 0) {
        w.cell = seedAt(s, w.seed);
        fetch(w.cell);
        continue;
      }
      ProbeLocation loc;
      bool found = false;
      if (w.cell < inner && w.visited < kMaxWalkSteps) {
        Lanes l;
        const int exit = fastStep(walk[w.cell], w.p, l);
        if (exit == -1) {
          loc = fastLocation(s, w.cell, l, uint16_t(w.visited + 1));
          found = true;
        } else if (exit >= 0) {
          const int32_t next = s.neighbours[size_t(w.cell)][exit];
          if (next >= 0 && next < inner) {
            w.cell = next;
            ++w.visited;
            fetch(next);
            continue;
          }
        }
      }
      if (!found) {
        locate3(s, w.p, w.cell, loc, walk);
        loc.steps = uint16_t(std::min(int(loc.steps) + int(w.visited), 65535));
      }
      weightByVisibility(s, w.p, loc, blend);
      emit(w.index, loc);
      if (!(live[k] = start(w))) --active;
    }
  }
}

// The batch forms' lookups: interleaved where the set has walk records, else one by one.
template <typename Emit>
void locateMany(const ProbeSet& s, std::span<const glm::vec3> points, const int32_t* hints,
                const ProbeBlendSettings& blend, Emit&& emit) {
  if (s.dimension == 3 && s.innerCellCount > 0 && s.walk.size() == size_t(s.innerCellCount) &&
      s.cells.size() >= size_t(s.innerCellCount)) {
    locateInterleaved(s, points, hints, blend, emit);
    return;
  }
  for (size_t i = 0; i < points.size(); ++i) {
    emit(i, locateProbe(s, points[i], hints ? hints[i] : -1, blend));
  }
}

// ---- dimension 2 -------------------------------------------------------------------------

// The plane's normal, stored by the bake in every hull edge (OuterCell::normals[0]); any one
// triangle's normal would do in exact arithmetic, but a sliver's is noise.
dvec3 planeNormal(const ProbeSet& s) {
  if (!s.outerCells.empty()) {
    const dvec3 n(s.outerCells[0].normals[0]);
    if (glm::dot(n, n) > 0.5) return n;
  }
  const glm::ivec4 t = s.cells[0];
  const dvec3 a = d3(s.positions[t[0]]);
  return glm::cross(d3(s.positions[t[1]]) - a, d3(s.positions[t[2]]) - a);
}

// Signed areas (times |n|) of p against triangle `cell` projected along n.
int evalTriangle(const ProbeSet& s, int32_t cell, dvec3 p, dvec3 n, double b[3]) {
  const glm::ivec4 t = s.cells[cell];
  const dvec3 v0 = d3(s.positions[t[0]]), v1 = d3(s.positions[t[1]]), v2 = d3(s.positions[t[2]]);
  b[0] = glm::dot(glm::cross(v1 - p, v2 - p), n);
  b[1] = glm::dot(glm::cross(v2 - p, v0 - p), n);
  b[2] = glm::dot(glm::cross(v0 - p, v1 - p), n);
  const double tol = -1e-12 * (std::fabs(b[0]) + std::fabs(b[1]) + std::fabs(b[2]));
  int exit = -1;
  double most = tol;
  for (int k = 0; k < 3; ++k) {
    if (b[k] < most) {
      most = b[k];
      exit = k;
    }
  }
  return exit;
}

// Outside a planar hull: the nearest point of the hull boundary (continuous; documented
// fallback for coplanar probe sets).
void nearestHullEdge(const ProbeSet& s, dvec3 p, ProbeLocation& loc) {
  double best = std::numeric_limits<double>::infinity();
  int32_t bestCell = -1;
  double bestS = 0.0;
  for (int32_t c = s.innerCellCount; c < s.cellCount(); ++c) {
    const glm::ivec4 t = s.cells[c];
    const dvec3 a = d3(s.positions[t[0]]), b = d3(s.positions[t[1]]);
    const dvec3 ab = b - a;
    const double len2 = glm::dot(ab, ab);
    const double u = len2 > 0.0 ? std::clamp(glm::dot(p - a, ab) / len2, 0.0, 1.0) : 0.0;
    const dvec3 d = a + u * ab - p;
    const double dist2 = glm::dot(d, d);
    if (dist2 < best) {
      best = dist2;
      bestCell = c;
      bestS = u;
    }
  }
  if (bestCell < 0) {
    const int32_t probes[1] = {s.cells[0][0]};
    const double w[1] = {1.0};
    finish(loc, 0, probes, w, 1);
    return;
  }
  const glm::ivec4 t = s.cells[bestCell];
  const int32_t probes[2] = {t[0], t[1]};
  const double w[2] = {1.0 - bestS, bestS};
  finish(loc, bestCell, probes, w, 2);
}

void setTriangle(const ProbeSet& s, ProbeLocation& loc, int32_t cell, const double b[3]) {
  const glm::ivec4 t = s.cells[cell];
  const int32_t probes[3] = {t[0], t[1], t[2]};
  finish(loc, cell, probes, b, 3);
}

void locate2(const ProbeSet& s, glm::vec3 pf, int32_t cell, ProbeLocation& loc) {
  const dvec3 n = planeNormal(s);
  const dvec3 p = d3(pf);
  if (cell >= s.innerCellCount) cell = s.neighbours[cell][2] >= 0 ? s.neighbours[cell][2] : 0;
  for (int step = 0; step < kMaxWalkSteps; ++step) {
    loc.steps = uint16_t(std::min(step + 1, 65535));
    double b[3];
    const int exit = evalTriangle(s, cell, p, n, b);
    if (exit < 0) {
      setTriangle(s, loc, cell, b);
      return;
    }
    const int32_t next = s.neighbours[cell][exit];
    if (next < 0 || next >= s.innerCellCount) {
      nearestHullEdge(s, p, loc);  // crossed a hull edge: p is outside the convex hull
      return;
    }
    cell = next;
  }
  loc.bruteForce = true;
  for (int32_t c = 0; c < s.innerCellCount; ++c) {
    double b[3];
    if (evalTriangle(s, c, p, n, b) < 0) {
      setTriangle(s, loc, c, b);
      return;
    }
  }
  nearestHullEdge(s, p, loc);
}

// ---- dimensions 1 and 0 ------------------------------------------------------------------

void locate1(const ProbeSet& s, glm::vec3 pf, ProbeLocation& loc) {
  const int32_t n = s.innerCellCount;
  const dvec3 origin = d3(s.positions[s.cells[0][0]]);
  const dvec3 dir = d3(s.positions[s.cells[n - 1][1]]) - origin;
  const double len2 = glm::dot(dir, dir);
  auto param = [&](dvec3 x) { return len2 > 0.0 ? glm::dot(x - origin, dir) / len2 : 0.0; };
  const double sp = param(d3(pf));
  // Last segment whose start is at or before sp (segments are ordered along the line).
  int32_t lo = 0, hi = n - 1;
  while (lo < hi) {
    const int32_t mid = (lo + hi + 1) / 2;
    if (param(d3(s.positions[s.cells[mid][0]])) <= sp) {
      lo = mid;
    } else {
      hi = mid - 1;
    }
  }
  const glm::ivec4 t = s.cells[lo];
  const double s0 = param(d3(s.positions[t[0]])), s1 = param(d3(s.positions[t[1]]));
  const double u = s1 > s0 ? std::clamp((sp - s0) / (s1 - s0), 0.0, 1.0) : 0.0;
  const int32_t probes[2] = {t[0], t[1]};
  const double w[2] = {1.0 - u, u};
  finish(loc, lo, probes, w, 2);
  loc.steps = 1;
}

// The cell around p from `hint` (the exact walk, or the fast one when `fast` and the set has
// its walk records) and the weights.
ProbeLocation locate(const ProbeSet& s, glm::vec3 p, int32_t hint,
                     const ProbeBlendSettings& blend, bool fast) noexcept {
  ProbeLocation loc;
  if (s.cells.empty() || s.innerCellCount <= 0) return loc;
  switch (s.dimension) {
    case 3:
    case 2: {
      if (hint < 0 || hint >= s.cellCount()) hint = seedCell(s, p);
      if (hint < 0 || hint >= s.cellCount()) hint = 0;
      if (s.dimension == 2) {
        locate2(s, p, hint, loc);
      } else {
        const bool useWalk = fast && s.walk.size() == size_t(s.innerCellCount);
        locate3(s, p, hint, loc, useWalk ? s.walk.data() : nullptr);
      }
      break;
    }
    case 1:
      locate1(s, p, loc);
      break;
    default: {
      const int32_t probes[1] = {s.cells[0][0]};
      const double w[1] = {1.0};
      finish(loc, 0, probes, w, 1);
      loc.steps = 1;
    }
  }
  weightByVisibility(s, p, loc, blend);
  return loc;
}

// A cell's walk record (gradients and `inside`); false when the float map cannot be made
// accurate to 1.07 u per entry. The edges are float differences, exact in double unless the
// coordinates' exponents differ by more than 29 (checked); each gradient is a cross product of
// two edges over the determinant: the cross products accurate to 2^-49 relative, the
// determinant to u / 16 (checked with its error bound: a sliver fails), then one rounding to
// float (u).
bool walkRecord(const glm::vec3 v[4], ProbeWalkCell& w) {
  // b - a in double, false unless exact (two-sum error zero).
  auto difference = [](glm::vec3 b, glm::vec3 a, dvec3& d) {
    for (int i = 0; i < 3; ++i) {
      const double x = double(b[i]), y = double(a[i]);
      d[i] = x - y;
      const double bv = d[i] - x, av = d[i] - bv;
      if ((x - av) + (-y - bv) != 0.0) return false;
    }
    return true;
  };
  // The edges from v0 (lanes 1..3 are the rows of their matrix's inverse) and two edges of
  // the face opposite v0 (lane 0).
  dvec3 e[3], f[2];
  for (int j = 0; j < 3; ++j) {
    if (!difference(v[j + 1], v[0], e[j])) return false;
  }
  if (!difference(v[2], v[1], f[0]) || !difference(v[3], v[1], f[1])) return false;
  // a b - c d and a bound on its error: plain double (within 2^-53 (|a b| + |c d|)) unless it
  // cancels below 1/8 of that, where Kahan's FMA algorithm (1.5 ulp) takes over. Either way
  // each component is accurate to 2^-49 relative.
  struct Value {
    double v, error;
  };
  auto diff = [](double a, double b, double c, double d) {
    const double ab = a * b, cd = c * d, plain = ab - cd;
    const double size = std::fabs(ab) + std::fabs(cd);
    if (std::fabs(plain) >= 0.125 * size) return Value{plain, 0x1p-52 * size};
    const double kahan = std::fma(a, b, -cd) + std::fma(-c, d, cd);
    return Value{kahan, 0x1p-51 * std::fabs(kahan)};
  };
  auto cross = [&](dvec3 a, dvec3 b, dvec3& error) {
    const Value x = diff(a.y, b.z, a.z, b.y), y = diff(a.z, b.x, a.x, b.z),
                z = diff(a.x, b.y, a.y, b.x);
    error = dvec3(x.error, y.error, z.error);
    return dvec3(x.v, y.v, z.v);
  };
  // c[k + 1] = e[k + 1] x e[k + 2]: det times row k of the inverse; c[0] = f[0] x f[1] =
  // c[1] + c[2] + c[3], so -c[0] / det is the gradient of l_0 = 1 - l_1 - l_2 - l_3.
  dvec3 c[4], error[4];
  c[0] = cross(f[0], f[1], error[0]);
  for (int k = 0; k < 3; ++k) c[k + 1] = cross(e[(k + 1) % 3], e[(k + 2) % 3], error[k + 1]);
  // det = e_0 . c_1 within the components' errors plus the dot product's rounding (3 ulp of
  // sum |e_0j c_1j|); the gradients need it to u / 16 = 2^-28 relative, else the cell is a
  // sliver left to the exact path.
  const double det = glm::dot(e[0], c[1]);
  const double detError =
      glm::dot(glm::abs(e[0]), error[1]) + 0x1p-51 * glm::dot(glm::abs(e[0]), glm::abs(c[1]));
  if (!(det > 0.0) || !(detError <= 0x1p-28 * det)) return false;
  // Multiplying by 1 / det adds two double roundings (2^-52 relative) to the entries' error:
  // nothing beside the float rounding.
  const double inverse = 1.0 / det;
  const dvec3 extent = glm::abs(e[0]) + glm::abs(e[1]) + glm::abs(e[2]);  // D_j
  double sumT = 0.0, maxT = 0.0;
  for (int k = 0; k < 4; ++k) {
    const dvec3 g = (k == 0 ? -inverse : inverse) * c[k];
    for (int a = 0; a < 3; ++a) {
      const float x = float(g[a]);
      if (x != 0.0f && !std::isnormal(x)) return false;
      (a == 0 ? w.x : a == 1 ? w.y : w.z)[size_t(k)] = x;
    }
    const double t = glm::dot(glm::abs(g), extent);  // T_k
    sumT += t;
    maxT = std::max(maxT, t);
  }
  // `inside` (see "the float fast path"), rounded up to float; infinite where u sum T_k >
  // 2^-10, which the proof needs (only extreme slivers: T_k grows like the cell's aspect).
  w.inside = std::numeric_limits<float>::infinity();
  if (sumT * double(kUnitRoundoff) <= 0x1p-10) {
    const double bound = 8.0 * double(kUnitRoundoff) * maxT * (1.0 + 0x1p-20) +
                         4.0 * double(kUnitRoundoff) + double(kTiny);
    float inside = float(bound);
    if (double(inside) < bound) inside = std::nextafter(inside, w.inside);
    w.inside = inside;
  }
  return true;
}

// locateProbe past its one-compare case: the hint's step with bounds computed from q, then
// the walk on from the hint's neighbour (the hint counted as the first step), or from the
// start. Out of line, so that the common case keeps a small frame.
[[gnu::noinline]] ProbeLocation locateFromHint(const ProbeSet& s, Lanes point, int32_t hint,
                                               Lanes q, Lanes l,
                                               const ProbeBlendSettings& blend) noexcept {
  const glm::vec3 p = toPoint(point);
  const ProbeWalkCell& w = s.walk[size_t(hint)];
  const int exit = fastInside(w, l) ? -1 : boundedDecision(w, q, l);
  if (exit == -2 || (exit >= 0 && s.neighbours[size_t(hint)][exit] < 0)) {
    return locate(s, p, hint, blend, true);
  }
  ProbeLocation loc;
  if (exit == -1) {
    loc = fastLocation(s, hint, l, 1);
  } else {
    locate3(s, p, s.neighbours[size_t(hint)][exit], loc, s.walk.data(), 1);
  }
  weightByVisibility(s, p, loc, blend);
  return loc;
}

// walkRecord for four cells side by side (one cell per lane of an AVX2 register, with FMA for
// Kahan's form): the same operations in the same order, and FMA rounds as std::fma does, so
// every lane's record is walkRecord's bit for bit. Compiled for AVX2 + FMA and called only on
// CPUs that have them (makeProbeWalkCells asks); floating-point contraction is off in it, so
// that the compiler fuses no product into an add that walkRecord rounds separately. A lane that
// walkRecord would fail (an inexact edge, a failed determinant test, a gradient entry that
// rounds to a subnormal or overflows) is reported in the returned mask and left to walkRecord.
#if defined(__GNUC__) && !defined(__clang__) && defined(__x86_64__)
#define KILN_WALK_RECORDS4 1
#pragma GCC push_options
#pragma GCC target("avx2,fma")
#pragma GCC optimize("fp-contract=off")
#pragma GCC diagnostic push
using V4d = double __attribute__((vector_size(32)));
using V4l = int64_t __attribute__((vector_size(32)));
using V4f = float __attribute__((vector_size(16)));
using V4i = int32_t __attribute__((vector_size(16)));

struct V3 {
  V4d x, y, z;
};

inline V4d vabs(V4d a) { return V4d(V4l(a) & (V4l{} + INT64_MAX)); }

// Lanes whose b - a (floats widened) is inexact in double, as walkRecord's `difference`.
inline V3 vdifference(const V3& b, const V3& a, V4l& bad) {
  auto one = [&](V4d x, V4d y) {
    const V4d d = x - y;
    const V4d bv = d - x, av = d - bv;
    bad |= ((x - av) + (-y - bv)) != 0.0;
    return d;
  };
  return {one(b.x, a.x), one(b.y, a.y), one(b.z, a.z)};
}

// walkRecord's a b - c d and its error bound: plain, or Kahan's FMA form where it cancels.
inline V4d vdiff(V4d a, V4d b, V4d c, V4d d, V4d& error) {
  const V4d ab = a * b, cd = c * d, plain = ab - cd;
  const V4d size = vabs(ab) + vabs(cd);
  const V4l isPlain = vabs(plain) >= 0.125 * size;
  const V4d kahan = V4d(_mm256_fmadd_pd(__m256d(a), __m256d(b), __m256d(-cd))) +
                    V4d(_mm256_fmadd_pd(__m256d(-c), __m256d(d), __m256d(cd)));
  error = isPlain ? 0x1p-52 * size : 0x1p-51 * vabs(kahan);
  return isPlain ? plain : kahan;
}

inline V3 vcross(const V3& a, const V3& b, V3& error) {
  return {vdiff(a.y, b.z, a.z, b.y, error.x), vdiff(a.z, b.x, a.x, b.z, error.y),
          vdiff(a.x, b.y, a.y, b.x, error.z)};
}

inline V4d vdot(const V3& a, const V3& b) { return (a.x * b.x + a.y * b.y) + a.z * b.z; }
inline V3 vabs(const V3& a) { return {vabs(a.x), vabs(a.y), vabs(a.z)}; }

// Float bits of x that walkRecord rejects: neither zero nor normal.
inline V4i notNormal(V4f x) {
  const V4i bits = V4i(x), exponent = bits & 0x7f800000;
  return ((bits & 0x7fffffff) != 0) & ((exponent == 0) | (exponent == 0x7f800000));
}

// Records for cells[0..3] into out[0..3]; returns a mask of the lanes left to walkRecord.
// The positions go into lanes, and the records out of them, by 4 x 4 transposes in SSE
// registers: filling a vector lane by lane went through the stack, four narrow stores and one
// wide load per vector, a failed store forward each (only data movement: the values are the
// same bits).
inline __m128 loadPosition(const glm::vec3& p) {  // (x, y, z, 0), reading only the vec3
  const __m128 xy = _mm_castpd_ps(_mm_load_sd(reinterpret_cast<const double*>(&p.x)));
  return _mm_movelh_ps(xy, _mm_load_ss(&p.z));
}

unsigned walkRecords4(const glm::vec3* positions, const glm::ivec4* cells, ProbeWalkCell* out) {
  V3 v[4];
  __m128 origin[3];  // vertex 0's coordinates as floats, lane l = cell l
  for (int j = 0; j < 4; ++j) {
    __m128 r0 = loadPosition(positions[size_t(cells[0][j])]);
    __m128 r1 = loadPosition(positions[size_t(cells[1][j])]);
    __m128 r2 = loadPosition(positions[size_t(cells[2][j])]);
    __m128 r3 = loadPosition(positions[size_t(cells[3][j])]);
    _MM_TRANSPOSE4_PS(r0, r1, r2, r3);  // r0 = the four x, r1 the y, r2 the z
    v[j].x = V4d(_mm256_cvtps_pd(r0));
    v[j].y = V4d(_mm256_cvtps_pd(r1));
    v[j].z = V4d(_mm256_cvtps_pd(r2));
    if (j == 0) {
      origin[0] = r0;
      origin[1] = r1;
      origin[2] = r2;
    }
  }
  V4l bad{};
  V3 e[3], f[2];
  for (int j = 0; j < 3; ++j) e[j] = vdifference(v[j + 1], v[0], bad);
  f[0] = vdifference(v[2], v[1], bad);
  f[1] = vdifference(v[3], v[1], bad);
  V3 c[4], error[4];
  c[0] = vcross(f[0], f[1], error[0]);
  for (int k = 0; k < 3; ++k) c[k + 1] = vcross(e[(k + 1) % 3], e[(k + 2) % 3], error[k + 1]);
  const V4d det = vdot(e[0], c[1]);
  const V3 absE0 = vabs(e[0]);
  const V4d detError = vdot(absE0, error[1]) + 0x1p-51 * vdot(absE0, vabs(c[1]));
  bad |= ~((det > 0.0) & (detError <= 0x1p-28 * det));
  const V4d inverse = 1.0 / det;
  const V3 extent = {(vabs(e[0].x) + vabs(e[1].x)) + vabs(e[2].x),
                     (vabs(e[0].y) + vabs(e[1].y)) + vabs(e[2].y),
                     (vabs(e[0].z) + vabs(e[1].z)) + vabs(e[2].z)};
  V4d sumT{}, maxT{};
  V4f g[4][3];
  V4i badFloat{};
  for (int k = 0; k < 4; ++k) {
    const V4d scale = k == 0 ? -inverse : inverse;
    const V3 gk = {scale * c[k].x, scale * c[k].y, scale * c[k].z};
    g[k][0] = __builtin_convertvector(gk.x, V4f);
    g[k][1] = __builtin_convertvector(gk.y, V4f);
    g[k][2] = __builtin_convertvector(gk.z, V4f);
    for (int a = 0; a < 3; ++a) badFloat |= notNormal(g[k][a]);
    const V4d t = vdot(vabs(gk), extent);
    sumT += t;
    maxT = maxT < t ? t : maxT;
  }
  const V4d bound = 8.0 * double(kUnitRoundoff) * maxT * (1.0 + 0x1p-20) +
                    4.0 * double(kUnitRoundoff) + double(kTiny);
  V4f inside = __builtin_convertvector(bound, V4f);
  // Rounded up: the next float above where the rounding went down (bound > 0, finite).
  inside = V4f(V4i(inside) - V4i(__builtin_convertvector(__builtin_convertvector(inside, V4d) <
                                                             bound, V4i)));
  const V4i tight = __builtin_convertvector(sumT * double(kUnitRoundoff) <= 0x1p-10, V4i);
  inside = tight ? inside : V4f{} + std::numeric_limits<float>::infinity();
  // Every lane's record is written; the caller overwrites the ones in the returned mask.
  static_assert(offsetof(ProbeWalkCell, y) == 16 && offsetof(ProbeWalkCell, z) == 32 &&
                offsetof(ProbeWalkCell, origin) == 48 && offsetof(ProbeWalkCell, inside) == 60);
  for (int a = 0; a < 3; ++a) {  // row l of the transpose = lane l's x (y, z) of l_0..l_3
    __m128 r0 = __m128(g[0][a]), r1 = __m128(g[1][a]), r2 = __m128(g[2][a]),
           r3 = __m128(g[3][a]);
    _MM_TRANSPOSE4_PS(r0, r1, r2, r3);
    auto row = [&](int l) {
      return a == 0 ? out[l].x.data() : a == 1 ? out[l].y.data() : out[l].z.data();
    };
    _mm_storeu_ps(row(0), r0);
    _mm_storeu_ps(row(1), r1);
    _mm_storeu_ps(row(2), r2);
    _mm_storeu_ps(row(3), r3);
  }
  {
    __m128 r0 = origin[0], r1 = origin[1], r2 = origin[2], r3 = __m128(inside);
    _MM_TRANSPOSE4_PS(r0, r1, r2, r3);  // row l = (origin of cell l, its inside)
    _mm_storeu_ps(&out[0].origin.x, r0);
    _mm_storeu_ps(&out[1].origin.x, r1);
    _mm_storeu_ps(&out[2].origin.x, r2);
    _mm_storeu_ps(&out[3].origin.x, r3);
  }
  unsigned left = 0;
  for (int l = 0; l < 4; ++l) {
    if (bad[l] != 0 || badFloat[l] != 0) left |= 1u << l;
  }
  return left;
}

#pragma GCC diagnostic pop
#pragma GCC pop_options
#endif

}  // namespace

void makeProbeWalkCell(const std::array<glm::vec3, 4>& v, ProbeWalkCell& w) {
  w.origin = v[0];
  if (!walkRecord(v.data(), w)) {
    const float nan = std::numeric_limits<float>::quiet_NaN();
    w.x.fill(nan);
    w.y.fill(nan);
    w.z.fill(nan);
    w.inside = std::numeric_limits<float>::infinity();
  }
}

void makeProbeWalkCells(std::span<const glm::vec3> positions, std::span<const glm::ivec4> cells,
                        ProbeWalkCell* out) {
  const size_t n = cells.size();
  size_t c = 0;
#ifdef KILN_WALK_RECORDS4
  const bool simd = __builtin_cpu_supports("avx2") && __builtin_cpu_supports("fma");
  for (; simd && c + 4 <= n; c += 4) {
    const unsigned left = walkRecords4(positions.data(), cells.data() + c, out + c);
    for (int l = 0; l < 4; ++l) {
      if (!(left >> l & 1)) continue;
      const glm::ivec4 t = cells[c + size_t(l)];
      makeProbeWalkCell({positions[size_t(t[0])], positions[size_t(t[1])],
                         positions[size_t(t[2])], positions[size_t(t[3])]},
                        out[c + size_t(l)]);
    }
  }
#endif
  for (; c < n; ++c) {
    const glm::ivec4 t = cells[c];
    makeProbeWalkCell({positions[size_t(t[0])], positions[size_t(t[1])],
                       positions[size_t(t[2])], positions[size_t(t[3])]},
                      out[c]);
  }
}

void prepareProbeLookup(ProbeSet& s) {
  s.walk.clear();
  if (s.dimension != 3 || s.innerCellCount <= 0 || s.cells.size() < size_t(s.innerCellCount)) {
    return;
  }
  s.walk.resize(size_t(s.innerCellCount));
  makeProbeWalkCells(s.positions, std::span(s.cells).first(size_t(s.innerCellCount)),
                     s.walk.data());
}

ProbeLocation locateProbe(const ProbeSet& s, glm::vec3 p, int32_t hint,
                          const ProbeBlendSettings& blend) noexcept {
  // The common case first: a hint whose cell still holds p (an object that stayed in its
  // cell since the last lookup) computes the four coordinates, settles the step with one
  // compare against the record's `inside` and returns them as the weights, built in the
  // caller's result. Anything else (a visibility-weighted blend, a point near a face or
  // beyond it) goes on in locateFromHint.
  if (uint32_t(hint) < uint32_t(s.innerCellCount) && s.dimension == 3 &&
      s.walk.size() == size_t(s.innerCellCount)) {
    const ProbeWalkCell& w = s.walk[size_t(hint)];
    const Lanes point = pointLanes(p);
    const Lanes q = fastQ(w, point);
    const Lanes l = fastCoordinates(w, q);
    if (fastInside(w, l) && !(blend.visibility && !s.visibility.empty())) {
      return fastLocation(s, hint, l, 1);
    }
    return locateFromHint(s, point, hint, q, l, blend);
  }
  return locate(s, p, hint, blend, true);
}

ProbeLocation locateProbeExact(const ProbeSet& s, glm::vec3 p, int32_t hint,
                               const ProbeBlendSettings& blend) noexcept {
  return locate(s, p, hint, blend, false);
}

void weightByVisibility(const ProbeSet& s, glm::vec3 p, ProbeLocation& loc,
                        const ProbeBlendSettings& blend) noexcept {
  loc.weights = loc.barycentric;
  const ProbeVisibility& vis = s.visibility;
  if (!blend.visibility || vis.empty() || loc.cell < 0) return;
  // The biased point: off the surface along its normal (when the caller gives one).
  const glm::vec3 q = p + blend.normal * blend.normalBias;
  if (!(std::isfinite(q.x) && std::isfinite(q.y) && std::isfinite(q.z))) return;
  // Each weight as its own value (not an array the compiler packs through memory for the
  // division: four scalar stores read back as one vector stall the store forwarding).
  auto weight = [&](int k) {
    const float b = loc.barycentric[size_t(k)];
    if (b == 0.0f) return 0.0f;
    const int32_t i = loc.probes[size_t(k)];
    return b * probeVisibility(vis.probe(i), vis.resolution, vis.maxDistance[size_t(i)],
                               q - s.positions[size_t(i)], blend);
  };
  const float w0 = weight(0), w1 = weight(1), w2 = weight(2), w3 = weight(3);
  const float sum = ((w0 + w1) + w2) + w3;
  // Every v >= kVisibilityFloor > 0 and the barycentric weights sum to 1, so sum > 0.
  if (!(sum > 0.0f)) return;
  const float inverse = visibleWeightScale(sum, blend.minVisibleWeight);
  loc.weights = {w0 * inverse, w1 * inverse, w2 * inverse, w3 * inverse};
  loc.visibilityWeighted = true;
}

ShL2Rgb interpolateProbes(const ProbeSet& s, const ProbeLocation& loc) noexcept {
  ShL2Rgb r;
  if (loc.cell < 0) return r;
  for (int k = 0; k < 4; ++k) {
    const float w = loc.weights[k];
    if (w == 0.0f) continue;
    const ShL2Rgb& src = s.sh[size_t(loc.probes[k])];
    for (int i = 0; i < kShL2Count; ++i) r.c[i] += w * src.c[i];
  }
  // The sun layer (kiln/probe_set.h): the light's share as the cell's ramp gives it at the
  // point, in place of the weights' mix of the probes' shares.
  if (loc.visibilityWeighted && !s.sun.empty() && !s.isOuter(loc.cell) &&
      size_t(loc.cell) < s.sun.ramps.size()) {
    const glm::vec4 a = s.sun.ramps[size_t(loc.cell)];
    if (!std::isnan(a.x)) {
      const float ramp = loc.barycentric[0] * a.x + loc.barycentric[1] * a.y +
                         loc.barycentric[2] * a.z + loc.barycentric[3] * a.w;
      // The ramp is geometry-blind: across a wall it would light a closed room. So it only
      // chooses within the shares of the probes that see the point (visibility weight at
      // least kSeen of the barycentric one).
      constexpr float kSeen = 0.1f;
      float mixed = 0.0f, lo = 1.0f, hi = 0.0f;
      for (int k = 0; k < 4; ++k) {
        const float v = s.sun.visibility[size_t(loc.probes[k])];
        mixed += loc.weights[k] * v;
        if (loc.weights[k] > 0.0f && loc.weights[k] >= kSeen * loc.barycentric[k]) {
          lo = std::min(lo, v);
          hi = std::max(hi, v);
        }
      }
      // (A location from the C API is untrusted: a non-finite ramp value changes nothing.)
      const float d = lo <= hi && std::isfinite(ramp) ? std::clamp(ramp, lo, hi) - mixed : 0.0f;
      for (int i = 0; i < kShL2Count; ++i) r.c[i] += d * s.sun.sh.c[i];
    }
  }
  return r;
}

glm::vec4 interpolateOcclusion(const ProbeSet& s, const ProbeLocation& loc) noexcept {
  if (loc.cell < 0 || s.occlusion.empty()) return glm::vec4(1.0f);
  glm::vec4 r(0.0f);
  float sum = 0.0f;
  for (int k = 0; k < 4; ++k) {
    const float w = loc.weights[k];
    if (w == 0.0f) continue;
    r += w * s.occlusion[size_t(loc.probes[k])];
    sum += w;
  }
  // Weights sum to 1 only up to rounding: dividing by their float sum (accumulated in the same
  // order) keeps a field that is 1 everywhere exactly 1, so fully lit objects stay unshadowed.
  if (sum > 0.0f) r /= sum;
  return glm::clamp(r, glm::vec4(0.0f), glm::vec4(1.0f));
}

glm::vec4 sampleOcclusion(const ProbeSet& s, glm::vec3 p, int32_t hint,
                          const ProbeBlendSettings& blend) noexcept {
  return interpolateOcclusion(s, locateProbe(s, p, hint, blend));
}

ShL2Rgb sampleProbes(const ProbeSet& s, glm::vec3 p, int32_t hint,
                     const ProbeBlendSettings& blend) noexcept {
  return interpolateProbes(s, locateProbe(s, p, hint, blend));
}

void locateProbes(const ProbeSet& s, std::span<const glm::vec3> points,
                  std::span<int32_t> hints, std::span<ProbeLocation> out,
                  const ProbeBlendSettings& blend) noexcept {
  const bool useHints = hints.size() == points.size();
  const size_t n = std::min(points.size(), out.size());
  locateMany(s, points.first(n), useHints ? hints.data() : nullptr, blend,
             [&](size_t i, const ProbeLocation& loc) {
               out[i] = loc;
               if (useHints) hints[i] = loc.cell;
             });
}

void sampleProbes(const ProbeSet& s, std::span<const glm::vec3> points, std::span<int32_t> hints,
                  std::span<ShL2Rgb> out, const ProbeBlendSettings& blend) noexcept {
  const size_t n = std::min(points.size(), out.size());
  sampleProbes(s, points.first(n),
               hints.size() == points.size() ? hints.first(n) : std::span<int32_t>{},
               out.first(n), {}, blend);
}

void sampleProbes(const ProbeSet& s, std::span<const glm::vec3> points, std::span<int32_t> hints,
                  std::span<ShL2Rgb> sh, std::span<glm::vec4> occlusion,
                  const ProbeBlendSettings& blend) noexcept {
  const bool useHints = hints.size() == points.size();
  const bool wantSh = sh.size() == points.size();
  const bool wantOcclusion = occlusion.size() == points.size();
  locateMany(s, points, useHints ? hints.data() : nullptr, blend,
             [&](size_t i, const ProbeLocation& loc) {
               if (useHints) hints[i] = loc.cell;
               if (wantSh) sh[i] = interpolateProbes(s, loc);
               if (wantOcclusion) occlusion[i] = interpolateOcclusion(s, loc);
             });
}

}  // namespace kiln
