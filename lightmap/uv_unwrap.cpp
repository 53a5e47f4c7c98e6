// uv_unwrap.cpp: lightmap UV generation: welding, chart growing by normal cone, planar
// projection or LSCM per chart, minimum-area orientation and packing by chart shape
// (chart_packer.h).
//
// LSCM: B. Lévy, S. Petitjean, N. Ray, J. Maillot, "Least Squares Conformal Maps for
// Automatic Texture Atlas Generation", SIGGRAPH 2002 (the complex per-triangle energy of
// section 3.3, two pinned vertices, solved here as real least squares through the normal
// equations with a sparse Cholesky factorization). Stretch metric: P. Sander, J. Snyder,
// S. Gortler, H. Hoppe, "Texture Mapping Progressive Meshes", SIGGRAPH 2001.
#include "lightmap/uv_unwrap.h"

#include <Eigen/Sparse>
#include <Eigen/SparseCholesky>
#include <algorithm>
#include <array>
#include <cmath>
#include <deque>
#include <map>
#include <numeric>
#include <string>
#include <unordered_map>

#include "lightmap/atlas.h"
#include "lightmap/chart_packer.h"
#include "lightmap/sealed_surfaces.h"
#include "src/parallel.h"

namespace kiln {

namespace {

using glm::dvec2;
using glm::dvec3;

double cross2(dvec2 a, dvec2 b) { return a.x * b.y - a.y * b.x; }

// Largest ratio between a triangle's texel density and its chart's that LSCM may leave.
constexpr double kMaxAreaDistortion = 2.0;
// Largest ratio between a UV triangle's two singular values (1 = conformal) a chart may
// have; LSCM over a whole chart stays near 1 (1.09 on a sphere), merges may not.
constexpr double kMaxAnisotropy = 1.75;
// A chart that fails (fold, overlap, distortion) is regrown with its cone angle times this:
// gentler than halving, which cut curved meshes (a teapot) into several times the charts
// they need.
constexpr double kRegrowFactor = 0.7;

// The object welded by position: what charts grow over.
struct WeldedMesh {
  std::vector<dvec3> positions;               // per welded vertex
  std::vector<std::array<uint32_t, 3>> tris;  // welded vertex indices, per triangle
  std::vector<dvec3> normals;                 // unit, per triangle (zero when degenerate)
  std::vector<double> areas;                  // world area, per triangle
  std::vector<bool> degenerate;
  std::vector<std::array<int32_t, 3>> neighbours;  // across edge k = (v[k], v[k+1]); -1 none
  // Edge k of triangle t is hard: the object's vertex normals differ across it (a crease the
  // mesh shades as one). Charts do not grow over hard edges, so that bilinear lookups never
  // mix the light of the two sides of a crease.
  std::vector<std::array<bool, 3>> hard;
  // Per triangle, 1 when no light reaches it (sealed_surfaces.h): such triangles and the
  // others never share a chart.
  std::vector<uint8_t> sealed;
};

WeldedMesh weld(const Object& object, const std::vector<uint8_t>* sealed) {
  WeldedMesh m;
  if (sealed && sealed->size() == object.triangles.size())
    m.sealed = *sealed;
  else
    m.sealed.assign(object.triangles.size(), 0);
  // Exact position equality: glTF exporters duplicate vertices bit-for-bit at seams. The
  // comparison treats -0 and +0 as equal; positions were checked to be finite.
  std::map<std::array<float, 3>, uint32_t> ids;
  std::vector<uint32_t> weldedOf(object.positions.size());
  for (size_t i = 0; i < object.positions.size(); ++i) {
    const vec3 p = object.positions[i];
    auto [it, inserted] = ids.emplace(std::array<float, 3>{p.x, p.y, p.z}, 0u);
    if (inserted) {
      it->second = uint32_t(m.positions.size());
      m.positions.push_back(dvec3(p));
    }
    weldedOf[i] = it->second;
  }
  Bounds3 bounds;
  for (const vec3& p : object.positions) bounds.extend(p);
  const double diagonal = bounds.diagonal();

  const size_t triangleCount = object.triangles.size();
  m.tris.resize(triangleCount);
  m.normals.assign(triangleCount, dvec3(0.0));
  m.areas.assign(triangleCount, 0.0);
  m.degenerate.assign(triangleCount, false);
  m.neighbours.assign(triangleCount, {-1, -1, -1});
  m.hard.assign(triangleCount, {false, false, false});
  for (size_t t = 0; t < triangleCount; ++t) {
    const uvec3 tri = object.triangles[t];
    m.tris[t] = {weldedOf[tri.x], weldedOf[tri.y], weldedOf[tri.z]};
    const dvec3 p0 = m.positions[m.tris[t][0]], p1 = m.positions[m.tris[t][1]],
                p2 = m.positions[m.tris[t][2]];
    const dvec3 c = glm::cross(p1 - p0, p2 - p0);
    const double area = 0.5 * glm::length(c);
    const double maxEdge2 = std::max(
        {glm::dot(p1 - p0, p1 - p0), glm::dot(p2 - p1, p2 - p1), glm::dot(p0 - p2, p0 - p2)});
    // Degenerate: collinear within float precision, or negligible against the object.
    const bool degenerate = m.tris[t][0] == m.tris[t][1] || m.tris[t][1] == m.tris[t][2] ||
                            m.tris[t][0] == m.tris[t][2] || area <= 1e-10 * maxEdge2 ||
                            area <= 1e-14 * diagonal * diagonal;
    m.degenerate[t] = degenerate;
    if (!degenerate) {
      m.areas[t] = area;
      m.normals[t] = c / (2.0 * area);
    }
  }

  // Edge adjacency: an edge joins two triangles only when exactly two non-degenerate
  // triangles use it, in opposite directions (consistently oriented manifold edge).
  struct EdgeUse {
    uint64_t key;
    uint32_t triangle;
    uint32_t corner;
  };
  std::vector<EdgeUse> uses;
  uses.reserve(triangleCount * 3);
  for (uint32_t t = 0; t < triangleCount; ++t) {
    if (m.degenerate[t]) continue;
    for (uint32_t k = 0; k < 3; ++k) {
      const uint32_t a = m.tris[t][k], b = m.tris[t][(k + 1) % 3];
      uses.push_back({(uint64_t(std::min(a, b)) << 32) | std::max(a, b), t, k});
    }
  }
  std::sort(uses.begin(), uses.end(), [](const EdgeUse& x, const EdgeUse& y) {
    return x.key != y.key             ? x.key < y.key
           : x.triangle != y.triangle ? x.triangle < y.triangle
                                      : x.corner < y.corner;
  });
  for (size_t i = 0; i < uses.size();) {
    size_t j = i;
    while (j < uses.size() && uses[j].key == uses[i].key) ++j;
    if (j - i == 2) {
      const EdgeUse& x = uses[i];
      const EdgeUse& y = uses[i + 1];
      const bool opposite = m.tris[x.triangle][x.corner] == m.tris[y.triangle][(y.corner + 1) % 3];
      if (opposite && x.triangle != y.triangle) {
        m.neighbours[x.triangle][x.corner] = int32_t(y.triangle);
        m.neighbours[y.triangle][y.corner] = int32_t(x.triangle);
        // Original vertices at the edge's two ends on each side: x's corner k meets y's
        // corner k + 1 and the other way round.
        if (object.normals.size() == object.positions.size()) {
          const uvec3 tx = object.triangles[x.triangle], ty = object.triangles[y.triangle];
          const uint32_t xa = tx[int(x.corner)], xb = tx[int((x.corner + 1) % 3)];
          const uint32_t ya = ty[int((y.corner + 1) % 3)], yb = ty[int(y.corner)];
          // A crease: the normals are split (1 degree: exporters write smooth normals
          // bit-identical on both sides) and the faces meet at more than 20 degrees.
          // Flat-shaded tessellations of smooth shapes split every normal, but their
          // faces meet at small angles and their light is continuous enough for one chart.
          constexpr float kSameNormal = 0.99985f;
          const double kCreaseCos = 0.9397;  // cos 20 degrees
          const bool hard =
              (glm::dot(object.normals[xa], object.normals[ya]) < kSameNormal ||
               glm::dot(object.normals[xb], object.normals[yb]) < kSameNormal) &&
              glm::dot(m.normals[x.triangle], m.normals[y.triangle]) < kCreaseCos;
          m.hard[x.triangle][x.corner] = hard;
          m.hard[y.triangle][y.corner] = hard;
        }
      }
    }
    i = j;
  }
  return m;
}

// Sealed regions (edge-connected sealed triangles) smaller than `minArea` are treated as
// lit: shrinking them would save less than the charts they cut out of their neighbours cost.
void unsealSmallRegions(WeldedMesh& m, double minArea) {
  std::vector<uint8_t> seen(m.tris.size(), 0);
  std::vector<uint32_t> region, stack;
  for (uint32_t seed = 0; seed < m.tris.size(); ++seed) {
    if (!m.sealed[seed] || seen[seed]) continue;
    region.clear();
    stack.assign(1, seed);
    seen[seed] = 1;
    double area = 0.0;
    while (!stack.empty()) {
      const uint32_t t = stack.back();
      stack.pop_back();
      region.push_back(t);
      area += m.areas[t];
      for (int32_t n : m.neighbours[t])
        if (n >= 0 && m.sealed[n] && !seen[n]) {
          seen[n] = 1;
          stack.push_back(uint32_t(n));
        }
    }
    if (area < minArea)
      for (uint32_t t : region) m.sealed[t] = 0;
  }
}

// Grows charts over `subset` (ascending triangle indices). Seeds are taken largest triangle
// first (ties: lowest index), so that big flat regions start charts of their own; a chart
// takes edge neighbours across soft edges, most aligned with the chart's area-weighted mean
// normal first, while a neighbour's normal is within the angle of the current mean. Growing
// by the mean (not the seed's normal) lets a chart cover up to twice the angle of curvature
// symmetrically around its centre; the parameterization's distortion check (below) bounds
// what that costs.
std::vector<std::vector<uint32_t>> growCharts(const WeldedMesh& m,
                                              const std::vector<uint32_t>& subset,
                                              double angleDegrees) {
  const double cosMax = std::cos(angleDegrees * double(kPi) / 180.0);
  // 0 = not in subset, 1 = free, 2 = taken.
  std::vector<uint8_t> state(m.tris.size(), 0);
  for (uint32_t t : subset) state[t] = 1;
  std::vector<uint32_t> seeds = subset;
  std::stable_sort(seeds.begin(), seeds.end(),
                   [&](uint32_t a, uint32_t b) { return m.areas[a] > m.areas[b]; });
  std::vector<std::vector<uint32_t>> charts;
  // (deviation from the mean normal when pushed, triangle): smallest first, ties by index.
  using Candidate = std::pair<double, uint32_t>;
  std::vector<Candidate> heap;
  std::vector<uint32_t> stamp(m.tris.size(), 0);  // chart number + 1 that queued it
  for (uint32_t seed : seeds) {
    if (state[seed] != 1) continue;
    const uint32_t id = uint32_t(charts.size()) + 1;
    dvec3 sum(0.0);
    std::vector<uint32_t> chart;
    heap.clear();
    heap.emplace_back(0.0, seed);
    stamp[seed] = id;
    while (!heap.empty()) {
      std::pop_heap(heap.begin(), heap.end(), std::greater<>());
      const uint32_t t = heap.back().second;
      heap.pop_back();
      if (state[t] != 1) continue;
      const double len = glm::length(sum);
      const dvec3 mean = len > 0.0 ? sum / len : m.normals[t];
      if (glm::dot(m.normals[t], mean) < cosMax) {
        stamp[t] = 0;  // may be reached again once the mean has moved
        continue;
      }
      state[t] = 2;
      chart.push_back(t);
      sum += m.areas[t] * m.normals[t];
      const dvec3 newMean = glm::normalize(sum);
      for (int k = 0; k < 3; ++k) {
        const int32_t n = m.neighbours[t][k];
        if (n < 0 || state[n] != 1 || m.hard[t][k] || stamp[n] == id ||
            m.sealed[n] != m.sealed[t])
          continue;
        stamp[n] = id;
        heap.emplace_back(1.0 - glm::dot(m.normals[n], newMean), uint32_t(n));
        std::push_heap(heap.begin(), heap.end(), std::greater<>());
      }
    }
    std::sort(chart.begin(), chart.end());
    charts.push_back(std::move(chart));
  }
  return charts;
}

// A chart's parameterization: UVs of its welded vertices, in world units.
struct Chart {
  std::vector<uint32_t> triangles;  // ascending
  std::vector<uint32_t> vertices;   // welded indices, ascending
  std::vector<dvec2> uv;            // per entry of `vertices`
  bool planar = false;

  uint32_t local(uint32_t welded) const {
    return uint32_t(std::lower_bound(vertices.begin(), vertices.end(), welded) - vertices.begin());
  }
};

Chart makeChart(const WeldedMesh& m, std::vector<uint32_t> triangles) {
  Chart c;
  c.triangles = std::move(triangles);
  for (uint32_t t : c.triangles)
    for (uint32_t v : m.tris[t]) c.vertices.push_back(v);
  std::sort(c.vertices.begin(), c.vertices.end());
  c.vertices.erase(std::unique(c.vertices.begin(), c.vertices.end()), c.vertices.end());
  c.uv.assign(c.vertices.size(), dvec2(0.0));
  return c;
}

dvec3 meanNormal(const WeldedMesh& m, const Chart& c) {
  dvec3 n(0.0);
  for (uint32_t t : c.triangles) n += m.areas[t] * m.normals[t];
  const double len = glm::length(n);
  return len > 0.0 ? n / len : m.normals[c.triangles.front()];
}

// Orthogonal projection onto the plane through the origin perpendicular to n: exact (zero
// stretch) for planar charts. Tangent frame of Duff et al. 2017, in double.
void projectChart(const WeldedMesh& m, dvec3 n, Chart& c) {
  const double sign = std::copysign(1.0, n.z);
  const double a = -1.0 / (sign + n.z);
  const double b = n.x * n.y * a;
  const dvec3 t(1.0 + sign * n.x * n.x * a, sign * b, -sign * n.x);
  const dvec3 bt(b, sign + n.y * n.y * a, -n.y);
  for (size_t i = 0; i < c.vertices.size(); ++i) {
    const dvec3 p = m.positions[c.vertices[i]];
    c.uv[i] = dvec2(glm::dot(p, t), glm::dot(p, bt));
  }
}

// Triangle t in its own plane: z0 = 0, z1 on +x, z2 with y > 0 (counter-clockwise).
std::array<dvec2, 3> localTriangle(const WeldedMesh& m, uint32_t t) {
  const dvec3 p0 = m.positions[m.tris[t][0]], p1 = m.positions[m.tris[t][1]],
              p2 = m.positions[m.tris[t][2]];
  const dvec3 e1 = glm::normalize(p1 - p0);
  const dvec3 e2 = glm::cross(m.normals[t], e1);
  return {dvec2(0.0), dvec2(glm::length(p1 - p0), 0.0),
          dvec2(glm::dot(p2 - p0, e1), glm::dot(p2 - p0, e2))};
}

// LSCM (Lévy et al. 2002). For triangle T with local coordinates z_j = x_j + i y_j, the
// conformal energy is |sum_j W_j U_j|^2 / d_T with W_1 = z_3 - z_2, W_2 = z_1 - z_3,
// W_3 = z_2 - z_1, U_j = u_j + i v_j and d_T = twice the area; the identity map has zero
// energy, so the solution keeps the surface's orientation. The energy sums over `triangles`
// (a subset of the chart's); the vertices with pinned[i] set keep c.uv[i], the others are
// solved for. Returns false when the system cannot be solved or a UV triangle of `triangles`
// has non-positive area (a fold).
bool solveLscm(const WeldedMesh& m, const std::vector<uint32_t>& triangles,
               const std::vector<bool>& pinned, Chart& c) {
  const size_t n = c.vertices.size();
  // Unknowns: (u, v) of every vertex that is not pinned.
  std::vector<int32_t> unknown(n, -1);
  int32_t freeCount = 0;
  for (uint32_t i = 0; i < n; ++i)
    if (!pinned[i]) unknown[i] = freeCount++;

  if (freeCount > 0) {
    const size_t rows = 2 * triangles.size();
    std::vector<Eigen::Triplet<double>> entries;
    entries.reserve(rows * 6);
    Eigen::VectorXd rhs = Eigen::VectorXd::Zero(Eigen::Index(rows));
    for (size_t k = 0; k < triangles.size(); ++k) {
      const uint32_t t = triangles[k];
      const std::array<dvec2, 3> z = localTriangle(m, t);
      const double s = 1.0 / std::sqrt(2.0 * m.areas[t]);
      const dvec2 w[3] = {z[2] - z[1], z[0] - z[2], z[1] - z[0]};
      const int re = int(2 * k), im = int(2 * k + 1);
      for (int j = 0; j < 3; ++j) {
        const double a = s * w[j].x, b = s * w[j].y;
        const uint32_t v = c.local(m.tris[t][j]);
        // (a + ib)(u + iv) = (a u - b v) + i (b u + a v)
        if (unknown[v] >= 0) {
          const int col = 2 * unknown[v];
          entries.emplace_back(re, col, a);
          entries.emplace_back(re, col + 1, -b);
          entries.emplace_back(im, col, b);
          entries.emplace_back(im, col + 1, a);
        } else {
          const dvec2 p = c.uv[v];
          rhs[re] -= a * p.x - b * p.y;
          rhs[im] -= b * p.x + a * p.y;
        }
      }
    }
    Eigen::SparseMatrix<double> a(Eigen::Index(rows), 2 * freeCount);
    a.setFromTriplets(entries.begin(), entries.end());
    const Eigen::SparseMatrix<double> normal = a.transpose() * a;
    Eigen::SimplicialLDLT<Eigen::SparseMatrix<double>> solver(normal);
    if (solver.info() != Eigen::Success) return false;
    const Eigen::VectorXd x = solver.solve(a.transpose() * rhs);
    if (solver.info() != Eigen::Success) return false;
    for (uint32_t i = 0; i < n; ++i) {
      if (unknown[i] < 0) continue;
      c.uv[i] = dvec2(x[2 * unknown[i]], x[2 * unknown[i] + 1]);
      if (!std::isfinite(c.uv[i].x) || !std::isfinite(c.uv[i].y)) return false;
    }
  }
  for (uint32_t t : triangles) {
    const dvec2 u0 = c.uv[c.local(m.tris[t][0])], u1 = c.uv[c.local(m.tris[t][1])],
                u2 = c.uv[c.local(m.tris[t][2])];
    if (!(cross2(u1 - u0, u2 - u0) > 0.0)) return false;
  }
  return true;
}

// LSCM of a whole chart: two vertices far apart along the chart's longest bounding-box axis
// are pinned at their 3D distance.
bool lscmChart(const WeldedMesh& m, Chart& c) {
  const size_t n = c.vertices.size();
  if (n < 3) return false;
  dvec3 lo(std::numeric_limits<double>::infinity()), hi(-lo);
  for (uint32_t v : c.vertices) {
    lo = glm::min(lo, m.positions[v]);
    hi = glm::max(hi, m.positions[v]);
  }
  const dvec3 extent = hi - lo;
  const int axis = extent.x >= extent.y && extent.x >= extent.z ? 0 : extent.y >= extent.z ? 1 : 2;
  uint32_t pinA = 0, pinB = 0;
  for (uint32_t i = 0; i < n; ++i) {
    const double x = m.positions[c.vertices[i]][axis];
    if (x < m.positions[c.vertices[pinA]][axis]) pinA = i;
    if (x > m.positions[c.vertices[pinB]][axis]) pinB = i;
  }
  if (pinA == pinB) return false;
  std::vector<bool> pinned(n, false);
  pinned[pinA] = pinned[pinB] = true;
  c.uv[pinA] = dvec2(0.0);
  c.uv[pinB] = dvec2(glm::length(m.positions[c.vertices[pinB]] - m.positions[c.vertices[pinA]]), 0.0);
  return solveLscm(m, c.triangles, pinned, c);
}

// Whether two UV triangles' interiors overlap, by the separating axis theorem: in 2D, two
// convex polygons with disjoint interiors are separated by a line parallel to one of their
// edges. Touching (shared edges or vertices, within `eps`) is not overlapping.
bool trianglesOverlap(const std::array<dvec2, 3>& a, const std::array<dvec2, 3>& b, double eps) {
  for (int pass = 0; pass < 2; ++pass) {
    const std::array<dvec2, 3>& p = pass == 0 ? a : b;
    const std::array<dvec2, 3>& q = pass == 0 ? b : a;
    const double orientation = cross2(p[1] - p[0], p[2] - p[0]) >= 0.0 ? 1.0 : -1.0;
    for (int e = 0; e < 3; ++e) {
      const dvec2 edge = p[(e + 1) % 3] - p[e];
      const double len = glm::length(edge);
      if (len <= 0.0) continue;
      // Signed distances of q's corners to p's edge line, positive on p's inner side.
      double maxInner = -1e300;
      for (int k = 0; k < 3; ++k)
        maxInner = std::max(maxInner, orientation * cross2(edge, q[k] - p[e]) / len);
      if (maxInner <= eps) return false;  // q lies entirely on the outer side of this edge
    }
  }
  return true;
}

// Whether any two triangles of the chart overlap in UV (LSCM is only locally injective: a
// chart's boundary can still run over itself). Sweep over x-sorted bounding boxes. With
// `fresh` (per entry of c.triangles), pairs of two triangles that are not fresh are skipped
// (they were checked before).
bool chartOverlaps(const WeldedMesh& m, const Chart& c, const std::vector<bool>* fresh = nullptr) {
  const size_t n = c.triangles.size();
  std::vector<std::array<dvec2, 3>> uv(n);
  std::vector<dvec2> lo(n), hi(n);
  dvec2 cLo(1e300), cHi(-1e300);
  for (size_t i = 0; i < n; ++i) {
    for (int k = 0; k < 3; ++k) uv[i][k] = c.uv[c.local(m.tris[c.triangles[i]][k])];
    lo[i] = glm::min(uv[i][0], glm::min(uv[i][1], uv[i][2]));
    hi[i] = glm::max(uv[i][0], glm::max(uv[i][1], uv[i][2]));
    cLo = glm::min(cLo, lo[i]);
    cHi = glm::max(cHi, hi[i]);
  }
  const double eps = 1e-9 * std::max(cHi.x - cLo.x, cHi.y - cLo.y);
  std::vector<uint32_t> order(n);
  std::iota(order.begin(), order.end(), 0u);
  std::sort(order.begin(), order.end(),
            [&](uint32_t a, uint32_t b) { return lo[a].x != lo[b].x ? lo[a].x < lo[b].x : a < b; });
  for (size_t i = 0; i < n; ++i)
    for (size_t j = i + 1; j < n && lo[order[j]].x < hi[order[i]].x - eps; ++j) {
      const uint32_t a = order[i], b = order[j];
      if (fresh && !(*fresh)[a] && !(*fresh)[b]) continue;
      if (lo[b].y >= hi[a].y - eps || lo[a].y >= hi[b].y - eps) continue;
      if (trianglesOverlap(uv[a], uv[b], eps)) return true;
    }
  return false;
}

// Smallest cosine between a triangle normal of the chart and the chart's mean normal.
double coneCos(const WeldedMesh& m, const Chart& c, dvec3 mean) {
  double minCos = 1.0;
  for (uint32_t t : c.triangles) minCos = std::min(minCos, glm::dot(m.normals[t], mean));
  return minCos;
}

// Whether the chart's texel density varies by at most kMaxAreaDistortion between triangles
// and its mean (LSCM is conformal but not area-preserving: measured at most 1.13 on
// 45-degree cones, 1.56 on 60-degree ones) and no triangle is stretched more than
// kMaxAnisotropy in one direction than in the other.
bool distortionWithinBound(const WeldedMesh& m, const Chart& c) {
  double uvSum = 0.0, worldSum = 0.0;
  std::vector<double> uvArea(c.triangles.size());
  for (size_t i = 0; i < c.triangles.size(); ++i) {
    const uint32_t t = c.triangles[i];
    const dvec2 u0 = c.uv[c.local(m.tris[t][0])], u1 = c.uv[c.local(m.tris[t][1])],
                u2 = c.uv[c.local(m.tris[t][2])];
    uvArea[i] = 0.5 * cross2(u1 - u0, u2 - u0);
    uvSum += uvArea[i];
    worldSum += m.areas[t];
  }
  for (size_t i = 0; i < c.triangles.size(); ++i) {
    const double ratio = (uvArea[i] / m.areas[c.triangles[i]]) * (worldSum / uvSum);
    if (!(ratio <= kMaxAreaDistortion && ratio >= 1.0 / kMaxAreaDistortion)) return false;
    // Anisotropy s1 / s2 of the map's Jacobian (a merge solved onto a fixed map is less
    // conformal than LSCM over the whole chart).
    const uint32_t t = c.triangles[i];
    const std::array<dvec2, 3> z = localTriangle(m, t);
    const dvec2 u0 = c.uv[c.local(m.tris[t][0])], u1 = c.uv[c.local(m.tris[t][1])],
                u2 = c.uv[c.local(m.tris[t][2])];
    const glm::dmat2 j = glm::dmat2(u1 - u0, u2 - u0) * glm::inverse(glm::dmat2(z[1] - z[0], z[2] - z[0]));
    const double e = j[0][0] * j[0][0] + j[0][1] * j[0][1] + j[1][0] * j[1][0] + j[1][1] * j[1][1];
    const double det = std::abs(glm::determinant(j));
    const double root = std::sqrt(std::max(0.0, e * e - 4.0 * det * det));
    // s1^2 = (e + root) / 2, s2^2 = (e - root) / 2: s1 / s2 <= a  <=>  (e + root) <= a^2 (e - root)
    if (!(e + root <= kMaxAnisotropy * kMaxAnisotropy * (e - root))) return false;
  }
  return true;
}

// Planar projection when the chart is flat, LSCM otherwise. False when the map folds,
// overlaps itself or exceeds the distortion bound.
bool parameterizeChart(const WeldedMesh& m, const UnwrapSettings& settings, Chart& c) {
  const double planarCos = std::cos(double(settings.planarAngleDegrees) * double(kPi) / 180.0);
  const dvec3 n = meanNormal(m, c);
  if (coneCos(m, c, n) >= planarCos) {
    projectChart(m, n, c);
    c.planar = true;
  } else {
    c.planar = false;
    if (!lscmChart(m, c) || !distortionWithinBound(m, c)) return false;
  }
  return !chartOverlaps(m, c);
}

// The union of two edge-adjacent charts, parameterized by keeping `base`'s UVs and solving
// LSCM for `added`'s other vertices, with the shared vertices pinned where `base` has them.
// Much cheaper than solving the union again (a merge costs the added chart's size, not the
// union's), and `base`'s map, already checked, does not move. nullopt when the union folds,
// overlaps or exceeds the distortion bound.
std::optional<Chart> extendChart(const WeldedMesh& m, const UnwrapSettings& settings,
                                 const Chart& base, const Chart& added) {
  std::vector<uint32_t> tris = base.triangles;
  tris.insert(tris.end(), added.triangles.begin(), added.triangles.end());
  std::sort(tris.begin(), tris.end());
  Chart u = makeChart(m, std::move(tris));
  if (base.planar && added.planar) {
    // Two flat charts: planar again when coplanar (a quad split at a crease it no longer has).
    Chart flat = u;
    const double planarCos =
        std::cos(double(settings.planarAngleDegrees) * double(kPi) / 180.0);
    const dvec3 n = meanNormal(m, flat);
    if (coneCos(m, flat, n) >= planarCos) {
      projectChart(m, n, flat);
      flat.planar = true;
      if (!chartOverlaps(m, flat)) return flat;
      return std::nullopt;
    }
  }
  std::vector<bool> pinned(u.vertices.size(), false);
  for (size_t i = 0; i < base.vertices.size(); ++i) {
    const uint32_t local = u.local(base.vertices[i]);
    pinned[local] = true;
    u.uv[local] = base.uv[i];
  }
  if (!solveLscm(m, added.triangles, pinned, u)) return std::nullopt;
  u.planar = false;
  if (!distortionWithinBound(m, u)) return std::nullopt;
  std::vector<bool> fresh(u.triangles.size(), false);
  for (size_t i = 0; i < u.triangles.size(); ++i)
    fresh[i] = !std::binary_search(base.triangles.begin(), base.triangles.end(), u.triangles[i]);
  if (chartOverlaps(m, u, &fresh)) return std::nullopt;
  return u;
}

// Splits a chart's triangles in two halves at the median of their centroids along the
// longest axis of the centroids' bounding box (ties by triangle index).
std::array<std::vector<uint32_t>, 2> bisect(const WeldedMesh& m, std::vector<uint32_t> tris) {
  std::vector<dvec3> centroid(tris.size());
  dvec3 lo(1e300), hi(-1e300);
  for (size_t i = 0; i < tris.size(); ++i) {
    const auto& v = m.tris[tris[i]];
    centroid[i] = (m.positions[v[0]] + m.positions[v[1]] + m.positions[v[2]]) / 3.0;
    lo = glm::min(lo, centroid[i]);
    hi = glm::max(hi, centroid[i]);
  }
  const dvec3 e = hi - lo;
  const int axis = e.x >= e.y && e.x >= e.z ? 0 : e.y >= e.z ? 1 : 2;
  std::vector<uint32_t> order(tris.size());
  std::iota(order.begin(), order.end(), 0u);
  std::sort(order.begin(), order.end(), [&](uint32_t a, uint32_t b) {
    return centroid[a][axis] != centroid[b][axis] ? centroid[a][axis] < centroid[b][axis]
                                                  : tris[a] < tris[b];
  });
  std::array<std::vector<uint32_t>, 2> halves;
  for (size_t i = 0; i < order.size(); ++i)
    halves[i < order.size() / 2 ? 0 : 1].push_back(tris[order[i]]);
  for (auto& h : halves) std::sort(h.begin(), h.end());
  return halves;
}

// Parameterizes `subset` and appends the resulting charts: one per grown chart when it works.
// A chart that fails is regrown with a smaller cone angle when it is curved (LSCM folded it,
// overlapped it or distorted it beyond the bound); a flat one (coplanar overlapping layers,
// which no angle separates) or one still failing at 2 degrees is cut in two halves that are
// regrown on their own, so that only the overlapping spots end up in small charts.
void buildCharts(const WeldedMesh& m, const std::vector<uint32_t>& subset, double angle,
                 const UnwrapSettings& settings, std::vector<Chart>& out) {
  for (std::vector<uint32_t>& group : growCharts(m, subset, angle)) {
    Chart c = makeChart(m, std::move(group));
    if (parameterizeChart(m, settings, c)) {
      out.push_back(std::move(c));
    } else if (!c.planar && angle * kRegrowFactor >= 2.0) {
      buildCharts(m, c.triangles, angle * kRegrowFactor, settings, out);
    } else {
      // A single triangle always parameterizes (projected onto its own plane), so halves of
      // two or more triangles end the recursion.
      for (const std::vector<uint32_t>& half : bisect(m, c.triangles))
        buildCharts(m, half, angle, settings, out);
    }
  }
}

// Growth leaves short charts along the borders of long ones (a 24-sided cylinder gets more
// charts than its arc needs) and small pieces between creases (bevels, thin strips), each of
// which costs a gutter on every side. Merge each chart, smallest world area first, into the
// neighbour it shares the most edges with, when the union parameterizes within the distortion
// bound without a fold or an overlap, and either
//   - the chart is small (under settings.smallChartTexels texels at the expected density):
//     any neighbour, across creases too (a crease inside a few texels does not show), or
//   - every normal of the union is strictly within the cone angle of the union's mean normal
//     and the two share a soft edge (creases stay seams).
// A few passes; deterministic (ties by chart index).
void mergeCharts(const WeldedMesh& m, const UnwrapSettings& settings, std::vector<Chart>& charts) {
  const double cosMax = std::cos(double(settings.maxChartAngleDegrees) * double(kPi) / 180.0);
  const double texelArea = 1.0 / (double(settings.texelsPerUnit) * settings.texelsPerUnit);
  const double smallArea = double(settings.smallChartTexels) * texelArea;
  std::vector<int32_t> chartOf(m.tris.size(), -1);
  std::vector<double> area(charts.size(), 0.0);
  for (uint32_t i = 0; i < charts.size(); ++i)
    for (uint32_t t : charts[i].triangles) {
      chartOf[t] = int32_t(i);
      area[i] += m.areas[t];
    }
  std::vector<bool> alive(charts.size(), true);
  for (int pass = 0; pass < 4; ++pass) {
    std::vector<uint32_t> order;
    for (uint32_t i = 0; i < charts.size(); ++i)
      if (alive[i]) order.push_back(i);
    std::sort(order.begin(), order.end(), [&](uint32_t a, uint32_t b) {
      return area[a] != area[b] ? area[a] < area[b] : a < b;
    });
    bool mergedAny = false;
    for (uint32_t c : order) {
      if (!alive[c]) continue;
      const bool small = area[c] < smallArea;
      std::map<uint32_t, int> shared;  // neighbour chart -> shared edges (soft ones unless small)
      for (uint32_t t : charts[c].triangles)
        for (int k = 0; k < 3; ++k) {
          const int32_t nb = m.neighbours[t][k];
          if (nb >= 0 && chartOf[nb] >= 0 && chartOf[nb] != int32_t(c) && (small || !m.hard[t][k]))
            ++shared[uint32_t(chartOf[nb])];
        }
      std::vector<std::pair<int, uint32_t>> candidates;  // (-shared edges, chart)
      for (auto [chart, count] : shared)
        if (m.sealed[charts[chart].triangles.front()] == m.sealed[charts[c].triangles.front()])
          candidates.emplace_back(-count, chart);
      std::sort(candidates.begin(), candidates.end());
      for (auto [negCount, other] : candidates) {
        if (!small) {
          // Strictly inside the cone: two equal perpendicular faces (a box's) are exactly 45
          // degrees from their mean normal and must stay apart.
          std::vector<uint32_t> tris = charts[other].triangles;
          tris.insert(tris.end(), charts[c].triangles.begin(), charts[c].triangles.end());
          const Chart both = makeChart(m, std::move(tris));
          if (coneCos(m, both, meanNormal(m, both)) < cosMax + 1e-6) continue;
        }
        // The larger chart keeps its map; the smaller one is solved onto it.
        const bool keepOther = area[other] >= area[c];
        std::optional<Chart> merged = keepOther ? extendChart(m, settings, charts[other], charts[c])
                                                : extendChart(m, settings, charts[c], charts[other]);
        if (!merged) continue;
        for (uint32_t t : charts[c].triangles) chartOf[t] = int32_t(other);
        charts[other] = std::move(*merged);
        area[other] += area[c];
        alive[c] = false;
        charts[c] = Chart();
        mergedAny = true;
        break;
      }
    }
    if (!mergedAny) break;
  }
  std::vector<Chart> kept;
  for (uint32_t i = 0; i < charts.size(); ++i)
    if (alive[i]) kept.push_back(std::move(charts[i]));
  charts = std::move(kept);
}

// A point of a chart with extent e turned by 90 degrees counter-clockwise, (x, y) ->
// (e.y - y, x): the turned chart's extent is (e.y, e.x).
dvec2 quarterTurn(dvec2 p, dvec2 e) { return dvec2(e.y - p.y, p.x); }

// Andrew's monotone chain convex hull, counter-clockwise, without collinear points.
std::vector<dvec2> convexHull(std::vector<dvec2> p) {
  std::sort(p.begin(), p.end(),
            [](dvec2 a, dvec2 b) { return a.x != b.x ? a.x < b.x : a.y < b.y; });
  if (p.size() < 3) return p;
  std::vector<dvec2> h(2 * p.size());
  size_t k = 0;
  for (size_t i = 0; i < p.size(); ++i) {
    while (k >= 2 && cross2(h[k - 1] - h[k - 2], p[i] - h[k - 2]) <= 0.0) --k;
    h[k++] = p[i];
  }
  for (size_t i = p.size() - 1, lower = k + 1; i-- > 0;) {
    while (k >= lower && cross2(h[k - 1] - h[k - 2], p[i] - h[k - 2]) <= 0.0) --k;
    h[k++] = p[i];
  }
  h.resize(k - 1);
  return h;
}

// Scales the chart to its world area, rotates it to its minimum-area bounding rectangle
// (an edge of the optimal rectangle lies on a hull edge: Freeman and Shapira 1975) with the
// long side along u, and moves its minimum corner to the origin. Returns the extent.
dvec2 normalizeChart(const WeldedMesh& m, Chart& c) {
  double worldArea = 0.0, uvArea = 0.0;
  for (uint32_t t : c.triangles) {
    worldArea += m.areas[t];
    const dvec2 u0 = c.uv[c.local(m.tris[t][0])], u1 = c.uv[c.local(m.tris[t][1])],
                u2 = c.uv[c.local(m.tris[t][2])];
    uvArea += 0.5 * cross2(u1 - u0, u2 - u0);
  }
  const double scale = uvArea > 0.0 ? std::sqrt(worldArea / uvArea) : 1.0;
  for (dvec2& uv : c.uv) uv *= scale;

  const std::vector<dvec2> hull = convexHull(c.uv);
  dvec2 bestAxis(1.0, 0.0);
  double bestArea = std::numeric_limits<double>::infinity();
  for (size_t i = 0; i < hull.size(); ++i) {
    const dvec2 e = hull[(i + 1) % hull.size()] - hull[i];
    const double len = glm::length(e);
    if (len <= 0.0) continue;
    const dvec2 axis = e / len, perp(-axis.y, axis.x);
    double minU = 1e300, maxU = -1e300, minV = 1e300, maxV = -1e300;
    for (dvec2 p : hull) {
      minU = std::min(minU, glm::dot(p, axis));
      maxU = std::max(maxU, glm::dot(p, axis));
      minV = std::min(minV, glm::dot(p, perp));
      maxV = std::max(maxV, glm::dot(p, perp));
    }
    // Relative tolerance so that near-ties (a square's four edges) keep the first edge.
    const double area = (maxU - minU) * (maxV - minV);
    if (area < bestArea * (1.0 - 1e-9)) {
      bestArea = area;
      bestAxis = axis;
    }
  }
  // A rotation (determinant +1), so orientation is kept.
  dvec2 axis = bestAxis, perp(-bestAxis.y, bestAxis.x);
  dvec2 lo(1e300), hi(-1e300);
  for (dvec2& uv : c.uv) {
    uv = dvec2(glm::dot(uv, axis), glm::dot(uv, perp));
    lo = glm::min(lo, uv);
    hi = glm::max(hi, uv);
  }
  if (hi.y - lo.y > hi.x - lo.x) {  // quarter turn (u, v) -> (v, -u): long side along u
    for (dvec2& uv : c.uv) uv = dvec2(uv.y, -uv.x);
    const dvec2 oldLo = lo, oldHi = hi;
    lo = dvec2(oldLo.y, -oldHi.x);
    hi = dvec2(oldHi.y, -oldLo.x);
  }
  for (dvec2& uv : c.uv) uv -= lo;
  return hi - lo;
}

}  // namespace

Result<UnwrapResult> generateLightmapUvs(const Object& object, const UnwrapSettings& settings,
                                         const std::vector<uint8_t>* sealed) {
  const std::string who = "object '" + object.name + "'";
  if (!(settings.texelsPerUnit > 0.0f) || !std::isfinite(settings.texelsPerUnit))
    return Error{who + ": unwrap texelsPerUnit must be > 0 (got " +
                 std::to_string(settings.texelsPerUnit) + ")"};
  if (settings.gutterTexels < 0) return Error{who + ": unwrap gutterTexels must be >= 0"};
  if (!(settings.maxChartAngleDegrees > 0.0f && settings.maxChartAngleDegrees < 90.0f))
    return Error{who + ": unwrap maxChartAngleDegrees must be in (0, 90)"};
  if (object.triangles.empty()) return Error{who + ": has no triangles to unwrap"};
  for (const vec3& p : object.positions)
    if (!isFinite(p)) return Error{who + ": has a non-finite vertex position"};
  for (size_t t = 0; t < object.triangles.size(); ++t) {
    const uvec3 tri = object.triangles[t];
    if (std::max({tri.x, tri.y, tri.z}) >= object.positions.size())
      return Error{who + ": triangles[" + std::to_string(t) + "] has a vertex index out of range"};
  }

  if (!(settings.sealedTexels > 0.0f) || !std::isfinite(settings.sealedTexels))
    return Error{who + ": unwrap sealedTexels must be > 0"};
  if (sealed && sealed->size() != object.triangles.size())
    return Error{who + ": sealed flags for " + std::to_string(sealed->size()) +
                 " triangles, the object has " + std::to_string(object.triangles.size())};

  WeldedMesh m = weld(object, settings.shrinkSealed ? sealed : nullptr);
  unsealSmallRegions(m, double(settings.smallChartTexels) /
                            (double(settings.texelsPerUnit) * settings.texelsPerUnit));
  std::vector<uint32_t> good, degenerate;
  for (uint32_t t = 0; t < m.tris.size(); ++t) (m.degenerate[t] ? degenerate : good).push_back(t);

  std::vector<Chart> charts;
  buildCharts(m, good, settings.maxChartAngleDegrees, settings, charts);
  mergeCharts(m, settings, charts);

  // Charts in texels at the expected density, packed by their shape (chart_packer.h) with
  // the gutter between their covered texels.
  const double d = settings.texelsPerUnit;
  std::vector<ChartFootprint> footprints(charts.size()), quarters(charts.size());
  std::vector<dvec2> extents(charts.size());
  std::vector<bool> shrunk(charts.size(), false);
  for (size_t i = 0; i < charts.size(); ++i) {
    dvec2 extent = normalizeChart(m, charts[i]);
    // Sealed: at most sealedTexels across (the same scale on both axes: no flip, no fold).
    const double across = std::max(extent.x, extent.y) * d;
    if (m.sealed[charts[i].triangles.front()] && across > settings.sealedTexels) {
      const double scale = settings.sealedTexels / across;
      for (dvec2& uv : charts[i].uv) uv *= scale;
      extent *= scale;
      shrunk[i] = true;
    }
    extents[i] = extent;
    std::vector<std::array<dvec2, 3>> tris;
    tris.reserve(charts[i].triangles.size());
    for (uint32_t t : charts[i].triangles) {
      const Chart& c = charts[i];
      tris.push_back({c.uv[c.local(m.tris[t][0])] * d, c.uv[c.local(m.tris[t][1])] * d,
                      c.uv[c.local(m.tris[t][2])] * d});
    }
    footprints[i] = chartFootprint(tris, extent * d);
    for (auto& tri : tris)
      for (dvec2& p : tri) p = quarterTurn(p, extent * d);
    quarters[i] = chartFootprint(tris, dvec2(extent.y, extent.x) * d);
  }
  const ChartPacking packed = packCharts(footprints, quarters, settings.gutterTexels);
  // A chart's texel position: its corner plus its own texel coordinates, turned by 90
  // and/or 180 degrees as the packer chose (rotations: the orientation is kept).
  auto texelPosition = [&](uint32_t chart, dvec2 uvWorld) {
    dvec2 p = uvWorld * d;
    if (packed.quarter[chart]) p = quarterTurn(p, extents[chart] * d);
    const ChartFootprint& f = packed.quarter[chart] ? quarters[chart] : footprints[chart];
    p += f.offset;  // footprint coordinates (chart_packer.h)
    return dvec2(packed.corners[chart]) +
           (packed.turned[chart] ? dvec2(f.columns, f.rows) - p : p);
  };

  // Texel positions (all > 0: charts sit inside their footprints), then one uniform scale
  // into [0, 1]^2 (the longer extent becomes 1).
  double extent = 0.0;
  for (uint32_t i = 0; i < charts.size(); ++i)
    for (const dvec2& uv : charts[i].uv) {
      const dvec2 p = texelPosition(i, uv);
      extent = std::max({extent, p.x, p.y});
    }
  if (!(extent > 0.0)) extent = 1.0;
  const double uvPerTexel = 1.0 / extent;

  UnwrapResult r;
  r.worldPerUv = extent / d;
  r.triangleChart.assign(m.tris.size(), 0);
  for (uint32_t i = 0; i < charts.size(); ++i)
    for (uint32_t t : charts[i].triangles) r.triangleChart[t] = i;
  for (size_t k = 0; k < degenerate.size(); ++k)
    r.triangleChart[degenerate[k]] = uint32_t(charts.size() + k);

  // New vertices: one per (original vertex, chart), numbered in order of first use.
  std::unordered_map<uint64_t, uint32_t> newIndex;
  r.triangles.resize(m.tris.size());
  for (uint32_t t = 0; t < m.tris.size(); ++t) {
    const uint32_t chart = r.triangleChart[t];
    for (int k = 0; k < 3; ++k) {
      const uint32_t original = object.triangles[t][k];
      const uint64_t key = (uint64_t(chart) << 32) | original;
      auto [it, inserted] = newIndex.emplace(key, uint32_t(r.vertexRemap.size()));
      if (inserted) {
        r.vertexRemap.push_back(original);
        dvec2 uv(0.0);  // degenerate triangles collapse to the origin: no area, no texels
        if (chart < charts.size()) {
          const Chart& c = charts[chart];
          uv = texelPosition(chart, c.uv[c.local(m.tris[t][k])]) * uvPerTexel;
        }
        r.uv1.push_back(vec2(uv));
      }
      r.triangles[t][k] = it->second;
    }
  }

  // Statistics, measured on the float output.
  UnwrapStats& s = r.stats;
  s.chartCount = int(charts.size());
  s.degenerateTriangles = int(degenerate.size());
  for (const Chart& c : charts) s.planarCharts += c.planar ? 1 : 0;
  for (size_t i = 0; i < charts.size(); ++i)
    if (shrunk[i]) {
      ++s.sealedCharts;
      s.sealedTriangles += int(charts[i].triangles.size());
    }
  double sumArea = 0.0, sumStretch = 0.0, uvAreaSum = 0.0;
  dvec2 uvMax(0.0);
  for (const vec2& uv : r.uv1) uvMax = glm::max(uvMax, dvec2(uv));
  for (uint32_t t : good) {
    const std::array<dvec2, 3> z = localTriangle(m, t);
    const dvec2 u0 = dvec2(r.uv1[r.triangles[t][0]]) * r.worldPerUv,
                u1 = dvec2(r.uv1[r.triangles[t][1]]) * r.worldPerUv,
                u2 = dvec2(r.uv1[r.triangles[t][2]]) * r.worldPerUv;
    const double uvArea = 0.5 * cross2(u1 - u0, u2 - u0);
    uvAreaSum += uvArea / (r.worldPerUv * r.worldPerUv);
    if (!(uvArea > 0.0)) {
      ++s.flippedTriangles;
      continue;
    }
    if (shrunk[r.triangleChart[t]]) continue;  // distortion is measured on full-size charts
    // Jacobian J = [u1-u0 u2-u0] [z1-z0 z2-z0]^-1 of the map from the surface to UV.
    const glm::dmat2 q(z[1] - z[0], z[2] - z[0]);
    const glm::dmat2 u(u1 - u0, u2 - u0);
    const glm::dmat2 j = u * glm::inverse(q);
    const double e = j[0][0] * j[0][0] + j[0][1] * j[0][1] + j[1][0] * j[1][0] + j[1][1] * j[1][1];
    const double det = std::abs(glm::determinant(j));
    const double s1 = std::sqrt(0.5 * (e + std::sqrt(std::max(0.0, e * e - 4.0 * det * det))));
    const double s2 = det / s1;
    sumArea += m.areas[t];
    sumStretch += m.areas[t] * 0.5 * (s1 * s1 + s2 * s2);
    s.maxAnisotropy = std::max(s.maxAnisotropy, s1 / s2);
    s.maxAreaDistortion = std::max({s.maxAreaDistortion, det, 1.0 / det});
  }
  s.l2Stretch = sumArea > 0.0 ? std::sqrt(sumStretch / sumArea) : 1.0;
  s.packingEfficiency = uvMax.x * uvMax.y > 0.0 ? uvAreaSum / (uvMax.x * uvMax.y) : 0.0;
  for (size_t i = 0; i < charts.size(); ++i) {
    if (shrunk[i]) continue;
    for (uint32_t t : charts[i].triangles) s.surfaceTexels += m.areas[t] * d * d;
    const ChartFootprint& f = footprints[i];
    for (int c = 0; c < f.columns; ++c)
      s.coveredTexels += std::max(0, f.top[size_t(c)] - f.bottom[size_t(c)]);
  }
  return r;
}

Object applyUnwrap(const Object& object, const UnwrapResult& unwrap) {
  Object o;
  o.name = object.name;
  o.nodeIndex = object.nodeIndex;
  o.meshIndex = object.meshIndex;
  o.settings = object.settings;
  o.triangleMaterial = object.triangleMaterial;
  const size_t n = unwrap.vertexRemap.size();
  o.positions.resize(n);
  if (object.normals.size() == object.positions.size()) o.normals.resize(n);
  if (object.uv0.size() == object.positions.size()) o.uv0.resize(n);
  for (size_t i = 0; i < n; ++i) {
    const uint32_t v = unwrap.vertexRemap[i];
    o.positions[i] = object.positions[v];
    if (!o.normals.empty()) o.normals[i] = object.normals[v];
    if (!o.uv0.empty()) o.uv0[i] = object.uv0[v];
  }
  o.uv1 = unwrap.uv1;
  o.triangles = unwrap.triangles;
  return o;
}

Result<std::vector<std::optional<UnwrapResult>>> generateMissingLightmapUvs(
    Scene& scene, float resolution, const UnwrapSettings& settings) {
  if (!(resolution > 0.0f) || !std::isfinite(resolution))
    return Error{"lightmap resolution must be > 0 texels per unit (got " +
                 std::to_string(resolution) + ")"};
  const size_t n = scene.objects.size();
  std::vector<std::optional<UnwrapResult>> unwraps(n);
  std::vector<std::string> errors(n);
  std::vector<uint8_t> thin(n, 0);
  const double sceneArea = lightmappedArea(scene);
  auto kept = [&](size_t i) { return i < settings.keepCharts.size() && settings.keepCharts[i]; };
  auto needs = [&](size_t i) {
    const Object& o = scene.objects[i];
    return isLightmapped(o) && o.uv1.size() != o.positions.size() &&
           (kept(i) || !tooSmallForLightmap(o, resolution, settings.minObjectTexels, sceneArea));
  };
  // Progress in triangles: objects differ wildly in size, and time grows with triangles.
  size_t triangles = 0;
  for (size_t i = 0; i < n; ++i)
    if (needs(i)) triangles += scene.objects[i].triangles.size();
  Progress progress("UV generation", triangles, "triangles",
                    settings.showProgress && triangles > 0);
  // Sealed triangles, from rays over the static objects (what the bake's tracer holds). A
  // scene without any light (no lights, a black sky, nothing emissive: an AO-only bake, a
  // test scene) has no sealed surfaces to tell apart: everything would be.
  bool anyLight = !scene.lights.empty() || !scene.sky.isBlack();
  for (const Material& material : scene.materials) anyLight |= material.isEmissive();
  std::vector<std::vector<uint8_t>> sealed;
  if (settings.shrinkSealed && anyLight && triangles > 0) {
    auto tracer = Tracer::create(scene, TracerGeometry::BakedGI);
    if (!tracer) return Error{"sealed surfaces: " + tracer.error()};
    SealedSettings ss;
    ss.parallel.cancel = settings.cancel;
    sealed = findSealedTriangles(scene, **tracer, ss);
    if (settings.cancel && settings.cancel->load()) return Error{"cancelled"};
  }
  ParallelOptions options;
  options.grain = 1;  // objects differ wildly in size
  options.cancel = settings.cancel;
  const bool finished = parallelFor(
      n,
      [&](size_t begin, size_t end) {
        for (size_t i = begin; i < end; ++i) {
          const Object& o = scene.objects[i];
          if (!needs(i)) continue;
          if (settings.cancel && settings.cancel->load(std::memory_order_relaxed)) return;
          UnwrapSettings s = settings;
          s.texelsPerUnit = resolution * o.settings.scaleInLightmap;
          Result<UnwrapResult> r = generateLightmapUvs(
              o, s, i < sealed.size() && !sealed[i].empty() ? &sealed[i] : nullptr);
          if (r.ok() && settings.minObjectTexels < 0.0f && !kept(i) &&
              chartsTooThin(r->stats.surfaceTexels, r->stats.coveredTexels) &&
              o.surfaceArea() < kAutoObjectAreaShare * sceneArea)
            thin[i] = 1;  // lit by probes (atlas.h kAutoThinCoverage): no UVs
          else if (r.ok())
            unwraps[i] = std::move(*r);
          else
            errors[i] = r.error();
          progress.advance(o.triangles.size());
        }
      },
      options);
  if (!finished || (settings.cancel && settings.cancel->load())) return Error{"cancelled"};
  progress.finish();
  for (size_t i = 0; i < n; ++i)
    if (!errors[i].empty()) return Error{errors[i]};
  for (size_t i = 0; i < n; ++i) {
    if (unwraps[i]) scene.objects[i] = applyUnwrap(scene.objects[i], *unwraps[i]);
    scene.objects[i].thinCharts = thin[i] != 0;
  }
  return unwraps;
}

}  // namespace kiln
