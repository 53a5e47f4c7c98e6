// sh_projection.cpp: SH projection, irradiance conversion, windowing / deringing and Unity
// packing (see sh_projection.h for the conventions of each function).
#include "src/sh_projection.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <utility>
#include <vector>

#include "src/sampling.h"

namespace kiln {

namespace {

constexpr double kPiD = 3.14159265358979323846;

// Polynomial constants of the basis, exactly those of shBasisL2 (sh.h), so that expanded
// polynomials agree with ShL2Rgb::irradiance to float rounding.
constexpr double kY00 = 0.282095;
constexpr double kY1 = 0.488603;
constexpr double kY2xy = 1.092548;  // Y2-2 = k xy, Y2-1 = k yz, Y21 = k xz
constexpr double kY20 = 0.315392;   // Y20 = k (3 z^2 - 1)
constexpr double kY22 = 0.546274;   // Y22 = k (x^2 - y^2)

// Double-precision A_l (Ramamoorthi & Hanrahan 2001).
constexpr double kA[3] = {kPiD, 2.0 * kPiD / 3.0, kPiD / 4.0};

// One channel of an L2 irradiance as the quadratic q(n) = n^T M n + b.n + c.
struct Quadratic {
  double m[3][3];
  double b[3];
  double c;

  double eval(const double n[3]) const {
    double r = c;
    for (int i = 0; i < 3; ++i) {
      r += b[i] * n[i];
      for (int j = 0; j < 3; ++j) r += m[i][j] * n[i] * n[j];
    }
    return r;
  }
};

// Expands E(n) = sum_i e_i Y_i(n), e the irradiance coefficients (A_l c_i), into monomials;
// axes (x, y, z) = 0, 1, 2.
Quadratic quadraticOf(const double e[kShL2Count]) {
  Quadratic q{};
  const double a8 = kY22 * e[8];
  const double a6 = kY20 * e[6];
  const double hxy = 0.5 * kY2xy * e[4];
  const double hyz = 0.5 * kY2xy * e[5];
  const double hxz = 0.5 * kY2xy * e[7];
  q.m[0][0] = a8;
  q.m[1][1] = -a8;
  q.m[2][2] = 3.0 * a6;
  q.m[0][1] = q.m[1][0] = hxy;
  q.m[1][2] = q.m[2][1] = hyz;
  q.m[0][2] = q.m[2][0] = hxz;
  q.b[0] = kY1 * e[3];
  q.b[1] = kY1 * e[1];
  q.b[2] = kY1 * e[2];
  q.c = kY00 * e[0] - a6;
  return q;
}

// The irradiance coefficients e_i = A_l c_i of channel `ch`, in double.
std::array<double, kShL2Count> irradianceCoefficients(const ShL2Rgb& sh, int ch) {
  std::array<double, kShL2Count> e;
  for (int i = 0; i < kShL2Count; ++i) e[i] = kA[shBand(i)] * double(sh.c[i][ch]);
  return e;
}

Quadratic irradianceQuadratic(const ShL2Rgb& sh, int ch) {
  return quadraticOf(irradianceCoefficients(sh, ch).data());
}

// The basis (sh.h's order and constants) in double.
std::array<double, kShL2Count> basisL2(const double n[3]) {
  const double x = n[0], y = n[1], z = n[2];
  return {kY00,
          kY1 * y,
          kY1 * z,
          kY1 * x,
          kY2xy * x * y,
          kY2xy * y * z,
          kY20 * (3.0 * z * z - 1.0),
          kY2xy * x * z,
          kY22 * (x * x - y * y)};
}

// Eigen-decomposition of a symmetric 3x3 matrix by cyclic Jacobi rotations (Golub & Van
// Loan, sec. 8.5): a = V diag(w) V^T, eigenvalues ascending, V's columns the eigenvectors.
void symmetricEigen3(const double a_in[3][3], double w[3], double v[3][3]) {
  double a[3][3];
  for (int i = 0; i < 3; ++i)
    for (int j = 0; j < 3; ++j) {
      a[i][j] = a_in[i][j];
      v[i][j] = i == j ? 1.0 : 0.0;
    }
  for (int sweep = 0; sweep < 50; ++sweep) {
    double off = std::abs(a[0][1]) + std::abs(a[0][2]) + std::abs(a[1][2]);
    double diag = std::abs(a[0][0]) + std::abs(a[1][1]) + std::abs(a[2][2]);
    if (off <= 1e-300 || off <= 1e-17 * diag) break;
    for (int p = 0; p < 2; ++p) {
      for (int r = p + 1; r < 3; ++r) {
        if (a[p][r] == 0.0) continue;
        // Rotation angle that zeroes a[p][r]: t = tan(theta), the smaller root.
        double theta = (a[r][r] - a[p][p]) / (2.0 * a[p][r]);
        double t = std::copysign(1.0, theta) / (std::abs(theta) + std::sqrt(theta * theta + 1.0));
        double cs = 1.0 / std::sqrt(t * t + 1.0), sn = t * cs;
        for (int k = 0; k < 3; ++k) {  // a <- a J
          double akp = a[k][p], akr = a[k][r];
          a[k][p] = cs * akp - sn * akr;
          a[k][r] = sn * akp + cs * akr;
        }
        for (int k = 0; k < 3; ++k) {  // a <- J^T a
          double apk = a[p][k], ark = a[r][k];
          a[p][k] = cs * apk - sn * ark;
          a[r][k] = sn * apk + cs * ark;
        }
        for (int k = 0; k < 3; ++k) {  // v <- v J
          double vkp = v[k][p], vkr = v[k][r];
          v[k][p] = cs * vkp - sn * vkr;
          v[k][r] = sn * vkp + cs * vkr;
        }
      }
    }
  }
  for (int i = 0; i < 3; ++i) w[i] = a[i][i];
  // Sort ascending (selection sort, swapping eigenvector columns along).
  for (int i = 0; i < 2; ++i) {
    int k = i;
    for (int j = i + 1; j < 3; ++j)
      if (w[j] < w[k]) k = j;
    if (k != i) {
      std::swap(w[i], w[k]);
      for (int r = 0; r < 3; ++r) std::swap(v[r][i], v[r][k]);
    }
  }
}

// Minimum of q over the unit sphere (trust-region subproblem; see minIrradiance in the
// header). Every candidate is a point of the sphere, so the result is an attained value.
double minOnSphere(const Quadratic& q, double argmin[3]) {
  double w[3], v[3][3];
  symmetricEigen3(q.m, w, v);
  // Linear term in eigen coordinates, halved: q = sum w_i m_i^2 + 2 g.m + c.
  double g[3];
  for (int i = 0; i < 3; ++i) g[i] = 0.5 * (v[0][i] * q.b[0] + v[1][i] * q.b[1] + v[2][i] * q.b[2]);
  const double gNorm = std::sqrt(g[0] * g[0] + g[1] * g[1] + g[2] * g[2]);

  double best = std::numeric_limits<double>::infinity();
  auto consider = [&](const double m[3]) {
    double len = std::sqrt(m[0] * m[0] + m[1] * m[1] + m[2] * m[2]);
    if (!(len > 0.0) || !std::isfinite(len)) return;
    double n[3];
    for (int r = 0; r < 3; ++r) n[r] = (v[r][0] * m[0] + v[r][1] * m[1] + v[r][2] * m[2]) / len;
    double value = q.eval(n);
    if (value < best) {
      best = value;
      for (int r = 0; r < 3; ++r) argmin[r] = n[r];
    }
  };

  // The smallest eigenvector, both ways (the answer when the linear term vanishes).
  const double e0p[3] = {1.0, 0.0, 0.0}, e0m[3] = {-1.0, 0.0, 0.0};
  consider(e0p);
  consider(e0m);
  if (gNorm == 0.0) return best;

  // Easy case: the stationarity condition (M - lambda I) n = -b/2, i.e. m_i = -g_i / (w_i -
  // lambda), with |m| = 1 and lambda < w_0. phi(lambda) = sum g_i^2 / (w_i - lambda)^2 - 1
  // increases on (-inf, w_0); phi(w_0 - |g|) <= 0, so bisect in [w_0 - |g|, w_0].
  auto phi = [&](double lambda) {
    double s = -1.0;
    for (int i = 0; i < 3; ++i) {
      double d = w[i] - lambda;
      s += g[i] * g[i] / (d * d);
    }
    return s;
  };
  double lo = w[0] - gNorm, hi = w[0];
  for (int it = 0; it < 200; ++it) {
    double mid = 0.5 * (lo + hi);
    if (mid <= lo || mid >= hi) break;
    if (phi(mid) < 0.0) lo = mid; else hi = mid;
  }
  for (double lambda : {lo, hi}) {
    if (lambda >= w[0]) continue;
    double m[3];
    for (int i = 0; i < 3; ++i) m[i] = -g[i] / (w[i] - lambda);
    consider(m);
  }

  // Hard case: g has (almost) no component along the eigenvectors of w_0, lambda = w_0 and
  // the minimiser is the pseudo-inverse solution plus a multiple of those eigenvectors.
  const double scale = std::max({std::abs(w[0]), std::abs(w[2]), gNorm});
  double m[3] = {0.0, 0.0, 0.0};
  double r2 = 0.0;
  bool degenerate[3];
  for (int i = 0; i < 3; ++i) {
    degenerate[i] = w[i] - w[0] <= 1e-12 * scale;
    if (!degenerate[i]) {
      m[i] = -g[i] / (w[i] - w[0]);
      r2 += m[i] * m[i];
    }
  }
  if (r2 < 1.0) {
    double t = std::sqrt(1.0 - r2);
    for (int i = 0; i < 3; ++i) {
      if (!degenerate[i]) continue;
      for (double sign : {1.0, -1.0}) {
        double mm[3] = {m[0], m[1], m[2]};
        mm[i] = sign * t;
        consider(mm);
      }
    }
  }
  return best;
}

// ---- Deringing fit: a least-distance program solved by NNLS ------------------------------------

// Rows of the fit's NNLS matrix: the 8 coefficients of bands 1-2 and the constraint bound.
constexpr int kFitRows = kShL2Count;
using FitColumn = std::array<double, kFitRows>;

// Least squares min |sum_{j in passive} a[j] s_j - b| by Householder QR of the (at most
// kFitRows) passive columns. Returns false when they are numerically dependent.
bool passiveLeastSquares(const std::vector<FitColumn>& a, const std::vector<int>& passive,
                         const FitColumn& b, std::vector<double>& s) {
  const int k = int(passive.size());
  if (k > kFitRows) return false;
  double m[kFitRows][kFitRows];  // m[row][col]
  double r[kFitRows];
  double diag[kFitRows];
  for (int i = 0; i < kFitRows; ++i) {
    r[i] = b[size_t(i)];
    for (int j = 0; j < k; ++j) m[i][j] = a[size_t(passive[size_t(j)])][size_t(i)];
  }
  for (int j = 0; j < k; ++j) {
    double norm2 = 0.0, colScale = 0.0;
    for (int i = 0; i < kFitRows; ++i) colScale = std::max(colScale, std::abs(m[i][j]));
    for (int i = j; i < kFitRows; ++i) norm2 += m[i][j] * m[i][j];
    const double norm = std::sqrt(norm2);
    if (!(norm > 1e-12 * std::max(colScale, 1e-300))) return false;
    const double alpha = m[j][j] > 0.0 ? -norm : norm;
    // Householder vector v = x - alpha e_j (stored in column j, rows j..), |v|^2 = 2 norm^2 -
    // 2 alpha x_j.
    m[j][j] -= alpha;
    const double v2 = 2.0 * (norm2 - alpha * (m[j][j] + alpha));
    diag[j] = alpha;
    if (!(v2 > 0.0)) continue;  // already e_j-aligned
    for (int c = j + 1; c < k; ++c) {
      double d = 0.0;
      for (int i = j; i < kFitRows; ++i) d += m[i][j] * m[i][c];
      const double f = 2.0 * d / v2;
      for (int i = j; i < kFitRows; ++i) m[i][c] -= f * m[i][j];
    }
    double d = 0.0;
    for (int i = j; i < kFitRows; ++i) d += m[i][j] * r[i];
    const double f = 2.0 * d / v2;
    for (int i = j; i < kFitRows; ++i) r[i] -= f * m[i][j];
  }
  s.assign(size_t(k), 0.0);
  for (int j = k - 1; j >= 0; --j) {
    double v = r[j];
    for (int c = j + 1; c < k; ++c) v -= m[j][c] * s[size_t(c)];
    s[size_t(j)] = v / diag[j];
  }
  return true;
}

// Non-negative least squares min |A v - b|, v >= 0, with A's columns `a` (Lawson & Hanson
// 1974, ch. 23, algorithm NNLS). Returns v. Deterministic (ties go to the lowest index).
std::vector<double> nnls(const std::vector<FitColumn>& a, const FitColumn& b) {
  const size_t m = a.size();
  std::vector<double> v(m, 0.0), s;
  std::vector<char> passiveFlag(m, 0), rejected(m, 0);
  std::vector<int> passive;
  FitColumn residual = b;
  auto updateResidual = [&] {
    residual = b;
    for (size_t j = 0; j < m; ++j)
      if (v[j] != 0.0)
        for (int i = 0; i < kFitRows; ++i) residual[size_t(i)] -= a[j][size_t(i)] * v[j];
  };
  constexpr double kTolerance = 1e-12;  // the caller scales A and b to O(1)
  for (size_t outer = 0; outer < 3 * m + 30; ++outer) {
    // The most promising column: the largest gradient component w_j = a_j . residual.
    int t = -1;
    double best = kTolerance;
    for (size_t j = 0; j < m; ++j) {
      if (passiveFlag[j] || rejected[j]) continue;
      double w = 0.0;
      for (int i = 0; i < kFitRows; ++i) w += a[j][size_t(i)] * residual[size_t(i)];
      if (w > best) best = w, t = int(j);
    }
    if (t < 0) break;
    passive.push_back(t);
    passiveFlag[size_t(t)] = 1;
    bool accepted = false;
    for (int inner = 0; inner < 3 * kFitRows && !passive.empty(); ++inner) {
      if (!passiveLeastSquares(a, passive, b, s)) break;
      bool positive = true;
      for (double x : s) positive = positive && x > 0.0;
      if (positive) {
        for (size_t p = 0; p < passive.size(); ++p) v[size_t(passive[p])] = s[p];
        accepted = true;
        break;
      }
      // Step from v toward s as far as v stays >= 0, and drop the columns that reach 0 (the
      // one that limits the step always).
      double alpha = 1.0;
      size_t limiting = 0;
      for (size_t p = 0; p < passive.size(); ++p) {
        if (s[p] > 0.0) continue;
        const double vp = v[size_t(passive[p])];
        const double ap = vp - s[p] > 0.0 ? vp / (vp - s[p]) : 0.0;
        if (ap < alpha) alpha = ap, limiting = p;
      }
      std::vector<int> kept;
      for (size_t p = 0; p < passive.size(); ++p) {
        double& vp = v[size_t(passive[p])];
        vp += alpha * (s[p] - vp);
        if (p != limiting && vp > 0.0) {
          kept.push_back(passive[p]);
        } else {
          vp = 0.0;
          passiveFlag[size_t(passive[p])] = 0;
        }
      }
      passive = std::move(kept);
    }
    if (!accepted || !passiveFlag[size_t(t)]) {
      // The new column did not stay (dependent on the others, or rounding made its
      // coefficient <= 0): drop it for good, so that the loop terminates. v stays >= 0.
      if (passiveFlag[size_t(t)]) {
        passiveFlag[size_t(t)] = 0;
        v[size_t(t)] = 0.0;
        passive.erase(std::find(passive.begin(), passive.end(), t));
      }
      rejected[size_t(t)] = 1;
    }
    updateResidual();
  }
  return v;
}

// The deringing fit of one channel, in units of the channel's mean irradiance (so that
// every number is O(1)): z = e_1..8 / mean, where E(n) / mean = 1 + sum_{i>=1} z_i Y_i(n).
// Minimises sum_i (z_i - raw_i)^2 subject to E(n) / mean >= margin for every normal, by
// cutting planes (see deringSh in the header). Returns the fitted z (index 0 unused).
std::array<double, kShL2Count> fitNonNegative(const std::array<double, kShL2Count>& raw,
                                              double margin) {
  constexpr int kSeedNormals = 256;
  constexpr int kMaxCuts = 32;
  static const std::vector<vec3> seeds = fibonacciSphere(kSeedNormals);
  // In u = z - raw the program is a least-distance one, min |u| s.t. G u >= h, with G_k =
  // Y_1..8(n_k) and h_k = margin - E_raw(n_k) / mean. Lawson & Hanson's LDP: NNLS on the
  // columns (G_k, h_k) against b = (0, ..., 0, 1); with r = A v - b, u = -r_1..8 / r_9.
  std::vector<FitColumn> columns;
  auto addConstraint = [&](const double n[3]) {
    const auto y = basisL2(n);
    FitColumn col;
    double eRaw = 1.0;
    for (int i = 1; i < kShL2Count; ++i) {
      col[size_t(i - 1)] = y[size_t(i)];
      eRaw += raw[size_t(i)] * y[size_t(i)];
    }
    col[kFitRows - 1] = margin - eRaw;
    columns.push_back(col);
  };
  for (const vec3& d : seeds) {
    const double n[3] = {d.x, d.y, d.z};
    addConstraint(n);
  }
  FitColumn b{};
  b[kFitRows - 1] = 1.0;

  std::array<double, kShL2Count> z = raw;
  for (int cut = 0; cut <= kMaxCuts; ++cut) {
    const std::vector<double> v = nnls(columns, b);
    FitColumn r{};
    for (size_t j = 0; j < columns.size(); ++j)
      for (int i = 0; i < kFitRows; ++i) r[size_t(i)] += columns[j][size_t(i)] * v[j];
    for (int i = 0; i < kFitRows; ++i) r[size_t(i)] -= b[size_t(i)];
    // r_9 = h.v - 1 < 0 whenever the program is feasible (z = 0, the mean alone, always is).
    if (!(r[kFitRows - 1] < 0.0)) break;
    for (int i = 1; i < kShL2Count; ++i)
      z[size_t(i)] = raw[size_t(i)] - r[size_t(i - 1)] / r[kFitRows - 1];
    // The exact minimum of the fit over the sphere: done when it is >= 0 (the margin is what
    // the cuts may still miss by), else it becomes a new constraint.
    double e[kShL2Count];
    e[0] = 1.0 / kY00;
    for (int i = 1; i < kShL2Count; ++i) e[i] = z[size_t(i)];
    double n[3] = {0.0, 1.0, 0.0};
    if (minOnSphere(quadraticOf(e), n) >= 0.0) break;
    addConstraint(n);
  }
  return z;
}

}  // namespace

// ---------------------------------------------------------------------------------------------

void ShL2Accumulator::add(vec3 d, vec3 radiance, double weight) {
  auto y = shBasisL2(d);
  for (int i = 0; i < kShL2Count; ++i) {
    double yw = double(y[i]) * weight;
    for (int ch = 0; ch < 3; ++ch) sum_[i][ch] += double(radiance[ch]) * yw;
  }
}

void ShL2Accumulator::addIntegrals(vec3 radiance,
                                   const std::array<double, kShL2Count>& basisIntegrals) {
  for (int i = 0; i < kShL2Count; ++i)
    for (int ch = 0; ch < 3; ++ch) sum_[i][ch] += double(radiance[ch]) * basisIntegrals[i];
}

void ShL2Accumulator::merge(const ShL2Accumulator& other) {
  for (int i = 0; i < kShL2Count; ++i)
    for (int ch = 0; ch < 3; ++ch) sum_[i][ch] += other.sum_[i][ch];
}

ShL2Rgb ShL2Accumulator::result() const {
  ShL2Rgb sh;
  for (int i = 0; i < kShL2Count; ++i)
    sh.c[i] = vec3(float(sum_[i][0]), float(sum_[i][1]), float(sum_[i][2]));
  return sh;
}

vec3 equirectDirection(float u, float v) {
  const double theta = kPiD * double(v), phi = 2.0 * kPiD * (double(u) - 0.5);
  const double st = std::sin(theta);
  return vec3(float(st * std::sin(phi)), float(std::cos(theta)), float(-st * std::cos(phi)));
}

double equirectPixelSolidAngle(int y, int width, int height) {
  const double theta0 = kPiD * y / height, theta1 = kPiD * (y + 1) / height;
  return (2.0 * kPiD / width) * (std::cos(theta0) - std::cos(theta1));
}

ShL2Rgb projectEquirect(const Image& map, float scale) {
  // The map is taken as piecewise constant over its pixels and the basis is integrated over
  // each pixel in closed form. With x = sin(t) sin(p), y = cos(t), z = -sin(t) cos(p) and
  // dw = sin(t) dt dp, every basis polynomial separates into a theta factor (a row integral
  // T) and a phi factor (a column integral P), e.g. int x dw = Ts Ps with
  // Ts = int sin^2(t) dt and Ps = int sin(p) dp. T0 P0 is the pixel's exact solid angle.
  ShL2Accumulator acc;
  if (map.empty()) return acc.result();
  const int w = map.width, h = map.height;
  struct Col { double p0, ps, pc, pss, pcc, psc; };
  std::vector<Col> cols(w);
  for (int x = 0; x < w; ++x) {
    const double a = 2.0 * kPiD * (double(x) / w - 0.5), b = 2.0 * kPiD * (double(x + 1) / w - 0.5);
    Col& c = cols[x];
    c.p0 = b - a;
    c.ps = std::cos(a) - std::cos(b);
    c.pc = std::sin(b) - std::sin(a);
    c.pss = 0.5 * c.p0 - 0.25 * (std::sin(2.0 * b) - std::sin(2.0 * a));
    c.pcc = c.p0 - c.pss;
    c.psc = 0.5 * (std::sin(b) * std::sin(b) - std::sin(a) * std::sin(a));
  }
  std::array<double, kShL2Count> yInt;
  for (int y = 0; y < h; ++y) {
    const double t0 = kPiD * y / h, t1 = kPiD * (y + 1) / h;
    const double c0 = std::cos(t0), c1 = std::cos(t1), s0 = std::sin(t0), s1 = std::sin(t1);
    const double tT0 = c0 - c1;                                                 // int s
    const double tC = 0.5 * (s1 * s1 - s0 * s0);                                // int c s
    const double tS = 0.5 * (t1 - t0) - 0.25 * (std::sin(2 * t1) - std::sin(2 * t0));  // s^2
    const double tCC = (c0 * c0 * c0 - c1 * c1 * c1) / 3.0;                     // int c^2 s
    const double tSC = (s1 * s1 * s1 - s0 * s0 * s0) / 3.0;                     // int s^2 c
    const double tSS = tT0 - tCC;                                               // int s^3
    for (int x = 0; x < w; ++x) {
      const Col& c = cols[x];
      yInt[0] = kY00 * tT0 * c.p0;
      yInt[1] = kY1 * tC * c.p0;
      yInt[2] = -kY1 * tS * c.pc;
      yInt[3] = kY1 * tS * c.ps;
      yInt[4] = kY2xy * tSC * c.ps;
      yInt[5] = -kY2xy * tSC * c.pc;
      yInt[6] = kY20 * (3.0 * tSS * c.pcc - tT0 * c.p0);
      yInt[7] = -kY2xy * tSS * c.psc;
      yInt[8] = kY22 * (tSS * c.pss - tCC * c.p0);
      acc.addIntegrals(map.rgb(x, y) * scale, yInt);
    }
  }
  return acc.result();
}

ShL2Rgb projectFunction(const std::function<vec3(vec3)>& radiance, uint32_t sampleCount,
                        uint64_t seed) {
  ShL2Accumulator acc;
  if (sampleCount == 0) return acc.result();
  const double weight = 4.0 * kPiD / sampleCount;
  for (uint32_t i = 0; i < sampleCount; ++i) {
    SampleStream stream(seed, i);
    const vec3 d = squareToUniformSphere(stream.get2D());
    acc.add(d, radiance(d), weight);
  }
  return acc.result();
}

// ---------------------------------------------------------------------------------------------

ShL2Rgb toIrradianceSh(const ShL2Rgb& radiance) {
  ShL2Rgb e = radiance;
  for (int i = 0; i < kShL2Count; ++i) e.c[i] *= kShCosineLobe[shBand(i)];
  return e;
}

ShL1Rgb reduceToL1(const ShL2Rgb& sh) {
  ShL1Rgb l1;
  for (int i = 0; i < kShL1Count; ++i) l1.c[i] = sh.c[i];
  return l1;
}

// ---------------------------------------------------------------------------------------------

std::array<float, 3> shWindowFactors(ShWindowKind kind, float width) {
  std::array<float, 3> f{1.0f, 0.0f, 0.0f};
  for (int l = 1; l < 3; ++l) {
    if (!(double(l) < double(width))) continue;  // also 0 for NaN widths
    const double x = kPiD * l / width;
    const double sinc = std::sin(x) / x;
    double w = 1.0;
    switch (kind) {
      case ShWindowKind::kSinc4: w = sinc * sinc * sinc * sinc; break;
      case ShWindowKind::kLanczos: w = sinc; break;
      case ShWindowKind::kHanning: w = 0.5 * (1.0 + std::cos(x)); break;
    }
    f[l] = float(w);
  }
  return f;
}

ShL2Rgb windowSh(const ShL2Rgb& sh, const std::array<float, 3>& factors) {
  ShL2Rgb out = sh;
  for (int i = 0; i < kShL2Count; ++i) out.c[i] *= factors[shBand(i)];
  return out;
}

vec3 minIrradiance(const ShL2Rgb& sh, std::array<vec3, 3>* argmin) {
  vec3 result;
  for (int ch = 0; ch < 3; ++ch) {
    double n[3] = {0.0, 1.0, 0.0};
    result[ch] = float(minOnSphere(irradianceQuadratic(sh, ch), n));
    if (argmin) (*argmin)[ch] = vec3(float(n[0]), float(n[1]), float(n[2]));
  }
  return result;
}

std::vector<vec3> fibonacciSphere(int n) {
  std::vector<vec3> out;
  out.reserve(size_t(std::max(n, 0)));
  const double golden = kPiD * (3.0 - std::sqrt(5.0));
  for (int i = 0; i < n; ++i) {
    const double z = 1.0 - (2.0 * i + 1.0) / n;
    const double r = std::sqrt(std::max(0.0, 1.0 - z * z));
    const double phi = golden * i;
    out.push_back(vec3(float(r * std::cos(phi)), float(r * std::sin(phi)), float(z)));
  }
  return out;
}

namespace {
float minOf(vec3 v) { return std::min(v.x, std::min(v.y, v.z)); }
}  // namespace

DeringResult deringSh(const ShL2Rgb& sh) {
  DeringResult r;
  r.sh = sh;
  r.minIrradianceBefore = minIrradiance(sh);
  r.minIrradianceAfter = r.minIrradianceBefore;
  if (minOf(r.minIrradianceBefore) >= 0.0f) return r;  // already fine: untouched
  r.changed = true;

  // The target minimum, relative to the mean irradiance: far below any accuracy that
  // matters, far above float rounding of the coefficients.
  constexpr double kMargin = 1e-4;
  for (int ch = 0; ch < 3; ++ch) {
    if (r.minIrradianceBefore[ch] >= 0.0f) continue;  // this channel is fine as it is
    const std::array<double, kShL2Count> e = irradianceCoefficients(sh, ch);
    const double mean = kY00 * e[0];  // the irradiance of band 0 alone, pi Y00 c0
    if (!(mean > 0.0)) {
      // A negative mean radiance: nothing with the same c0 is >= 0. Keep band 0 alone.
      r.ok = false;
      for (int i = 1; i < kShL2Count; ++i) r.sh.c[i][ch] = 0.0f;
      continue;
    }
    std::array<double, kShL2Count> raw;
    for (int i = 0; i < kShL2Count; ++i) raw[size_t(i)] = e[size_t(i)] / mean;
    const std::array<double, kShL2Count> z = fitNonNegative(raw, kMargin);
    for (int i = 1; i < kShL2Count; ++i) r.sh.c[i][ch] = float(z[size_t(i)] * mean / kA[shBand(i)]);
  }
  // The guarantee: should the cuts have stopped short, or float rounding of the coefficients
  // have dipped below 0, scale bands 1-2 of that channel toward the mean. E_t = m0 + t (E -
  // m0) with m0 = pi Y00 c0 has minimum m0 + t (min E - m0), which t = m0 / (m0 - min E)
  // brings to 0; shrink t a little until the exact minimum of the float SH is >= 0.
  r.minIrradianceAfter = minIrradiance(r.sh);
  for (int ch = 0; ch < 3; ++ch) {
    const double m0 = kA[0] * kY00 * double(r.sh.c[0][ch]);
    for (int attempt = 0; attempt < 8 && r.minIrradianceAfter[ch] < 0.0f && m0 > 0.0; ++attempt) {
      const double t = m0 / (m0 - double(r.minIrradianceAfter[ch])) * (1.0 - 1e-5 * (1 << attempt));
      for (int i = 1; i < kShL2Count; ++i) r.sh.c[i][ch] = float(double(r.sh.c[i][ch]) * t);
      r.minIrradianceAfter = minIrradiance(r.sh);
      r.fallback = true;
    }
  }
  return r;
}

WindowDeringResult windowDeringSh(const ShL2Rgb& sh, ShWindowKind kind, float relTolerance) {
  WindowDeringResult r;
  r.sh = sh;
  r.width = kInfinity;
  r.minIrradianceBefore = minIrradiance(sh);
  r.minIrradianceAfter = r.minIrradianceBefore;
  if (minOf(r.minIrradianceBefore) >= 0.0f) return r;  // already fine: untouched

  r.changed = true;
  auto minAt = [&](float width) { return minOf(minIrradiance(windowSh(sh, kind, width))); };
  // Width 1 keeps band 0 only, whose irradiance pi Y00 c0 is constant: feasible unless the
  // mean radiance itself is negative, which no window can fix.
  float lo = 1.0f;
  if (minAt(lo) < 0.0f) {
    r.ok = false;
    r.width = lo;
    r.factors = shWindowFactors(kind, lo);
    r.sh = windowSh(sh, r.factors);
    r.minIrradianceAfter = minIrradiance(r.sh);
    return r;
  }
  // An infeasible upper bound: start where cmgen does (4 x bands + 1) and widen while the
  // window is still weak enough to stay non-negative.
  float hi = 13.0f;
  while (minAt(hi) >= 0.0f && hi < 1e6f) {
    lo = hi;
    hi *= 2.0f;
  }
  if (minAt(hi) >= 0.0f) {
    lo = hi;  // only tiny (rounding-level) negatives: the weakest tried window will do
  } else {
    while (hi - lo > relTolerance * lo) {
      const float mid = 0.5f * (lo + hi);
      if (mid <= lo || mid >= hi) break;
      if (minAt(mid) >= 0.0f) lo = mid; else hi = mid;
    }
  }
  r.width = lo;
  r.factors = shWindowFactors(kind, lo);
  r.sh = windowSh(sh, r.factors);
  r.minIrradianceAfter = minIrradiance(r.sh);
  return r;
}

// ---------------------------------------------------------------------------------------------

UnitySh9 packUnitySh9(const ShL2Rgb& radiance, ShAxes axes) {
  // E(n) / pi = sum_i (A_l / pi) c_i Y_i(n); A_l / pi = 1, 2/3, 1/4.
  const double k0 = kA[0] / kPiD, k1 = kA[1] / kPiD, k2 = kA[2] / kPiD;
  const double sx = axes == ShAxes::kUnity ? -1.0 : 1.0;  // Unity x = -glTF x
  vec4 a[3], b[3];
  vec4 cc(0.0f, 0.0f, 0.0f, 1.0f);
  for (int ch = 0; ch < 3; ++ch) {
    double s[kShL2Count];
    for (int i = 0; i < kShL2Count; ++i) s[i] = radiance.c[i][ch];
    a[ch] = vec4(float(sx * k1 * kY1 * s[3]), float(k1 * kY1 * s[1]), float(k1 * kY1 * s[2]),
                 float(k0 * kY00 * s[0] - k2 * kY20 * s[6]));
    b[ch] = vec4(float(sx * k2 * kY2xy * s[4]), float(k2 * kY2xy * s[5]),
                 float(3.0 * k2 * kY20 * s[6]), float(sx * k2 * kY2xy * s[7]));
    cc[ch] = float(k2 * kY22 * s[8]);
  }
  return UnitySh9{a[0], a[1], a[2], b[0], b[1], b[2], cc};
}

vec3 evalUnitySh9(const UnitySh9& p, vec3 n) {
  const vec4 n1(n, 1.0f);
  vec3 res(glm::dot(p.shAr, n1), glm::dot(p.shAg, n1), glm::dot(p.shAb, n1));
  const vec4 vB = vec4(n.x, n.y, n.z, n.z) * vec4(n.y, n.z, n.z, n.x);
  res += vec3(glm::dot(p.shBr, vB), glm::dot(p.shBg, vB), glm::dot(p.shBb, vB));
  res += vec3(p.shC) * (n.x * n.x - n.y * n.y);
  return res;
}

}  // namespace kiln
