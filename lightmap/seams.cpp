// seams.cpp: seam detection by welding vertices on a hash grid, and least-squares seam
// stitching solved with CGLS (conjugate gradients on the normal equations, Hestenes and
// Stiefel 1952) on Iwanicki's (2013) formulation; seamoptimizer.h solves the same system
// per seam with a dense Cholesky factorisation, CGLS keeps it sparse for long seams.
#include "lightmap/seams.h"

#include <algorithm>
#include <array>
#include <cassert>
#include <cmath>
#include <numeric>
#include <unordered_map>

namespace kiln {

namespace {

// Union-find whose root is always the smallest index: components, and so the canonical
// vertex of each 3D point, do not depend on the order of the unions.
struct MinUnionFind {
  std::vector<uint32_t> parent;
  explicit MinUnionFind(size_t n) : parent(n) { std::iota(parent.begin(), parent.end(), 0u); }
  uint32_t find(uint32_t a) {
    while (parent[a] != a) {
      parent[a] = parent[parent[a]];
      a = parent[a];
    }
    return a;
  }
  void unite(uint32_t a, uint32_t b) {
    a = find(a);
    b = find(b);
    if (a == b) return;
    if (a < b) std::swap(a, b);
    parent[a] = b;
  }
};

struct CellHash {
  size_t operator()(const std::array<int64_t, 3>& k) const {
    uint64_t h = 1469598103934665603ull;
    for (int64_t v : k) h = (h ^ uint64_t(v)) * 1099511628211ull;
    return size_t(h);
  }
};

// Canonical vertex per vertex: vertices within `tol` per axis (chained) share one.
std::vector<uint32_t> weldByPosition(const std::vector<vec3>& positions, float tol) {
  MinUnionFind uf(positions.size());
  const double cell = std::max(double(tol), 1e-12);
  std::unordered_map<std::array<int64_t, 3>, std::vector<uint32_t>, CellHash> grid;
  auto key = [&](vec3 p) {
    return std::array<int64_t, 3>{int64_t(std::floor(p.x / cell)), int64_t(std::floor(p.y / cell)),
                                  int64_t(std::floor(p.z / cell))};
  };
  for (uint32_t v = 0; v < positions.size(); ++v) grid[key(positions[v])].push_back(v);
  for (uint32_t v = 0; v < positions.size(); ++v) {
    const auto k = key(positions[v]);
    for (int dz = -1; dz <= 1; ++dz)
      for (int dy = -1; dy <= 1; ++dy)
        for (int dx = -1; dx <= 1; ++dx) {
          const auto it = grid.find({k[0] + dx, k[1] + dy, k[2] + dz});
          if (it == grid.end()) continue;
          for (uint32_t u : it->second) {
            if (u >= v) continue;
            const vec3 d = glm::abs(positions[u] - positions[v]);
            if (d.x <= tol && d.y <= tol && d.z <= tol) uf.unite(u, v);
          }
        }
  }
  std::vector<uint32_t> canon(positions.size());
  for (uint32_t v = 0; v < positions.size(); ++v) canon[v] = uf.find(v);
  return canon;
}

struct HalfEdge {
  uint32_t lo, hi;  // canonical endpoints, lo < hi
  uint32_t triangle;
  uint32_t vLo, vHi;  // the triangle's own vertices at lo and hi
  int edge;           // 0..2 within the triangle
};

// The bilinear footprint of point p: up to 4 (texel index, weight) with weight > 0.
int footprint(int w, int h, vec2 p, std::array<std::pair<size_t, double>, 4>& out) {
  const double fx = double(p.x) - 0.5, fy = double(p.y) - 0.5;
  const double x0 = std::floor(fx), y0 = std::floor(fy);
  const double tx = fx - x0, ty = fy - y0;
  int n = 0;
  for (int j = 0; j < 2; ++j)
    for (int i = 0; i < 2; ++i) {
      const double wgt = (i ? tx : 1.0 - tx) * (j ? ty : 1.0 - ty);
      if (wgt <= 0.0) continue;
      const int x = std::clamp(int(x0) + i, 0, w - 1), y = std::clamp(int(y0) + j, 0, h - 1);
      const size_t idx = size_t(y) * w + x;
      bool merged = false;
      for (int k = 0; k < n; ++k)
        if (out[size_t(k)].first == idx) {
          out[size_t(k)].second += wgt;  // clamped at the border: same texel twice
          merged = true;
        }
      if (!merged) out[size_t(n++)] = {idx, wgt};
    }
  return n;
}

}  // namespace

std::vector<SeamEdge> findSeams(const Object& object, vec4 scaleOffset, int pageWidth,
                                int pageHeight, const SeamSettings& settings) {
  std::vector<SeamEdge> seams;
  if (object.uv1.size() != object.positions.size() || object.triangles.empty()) return seams;
  const std::vector<uint32_t> canon = weldByPosition(object.positions, settings.weldTolerance);

  std::vector<HalfEdge> edges;
  edges.reserve(object.triangles.size() * 3);
  for (uint32_t t = 0; t < object.triangles.size(); ++t) {
    const uvec3 tri = object.triangles[t];
    for (int e = 0; e < 3; ++e) {
      uint32_t va = tri[e], vb = tri[(e + 1) % 3];
      if (canon[va] == canon[vb]) continue;  // degenerate in 3D
      if (canon[va] > canon[vb]) std::swap(va, vb);
      edges.push_back({canon[va], canon[vb], t, va, vb, e});
    }
  }
  std::sort(edges.begin(), edges.end(), [](const HalfEdge& a, const HalfEdge& b) {
    if (a.lo != b.lo) return a.lo < b.lo;
    if (a.hi != b.hi) return a.hi < b.hi;
    if (a.triangle != b.triangle) return a.triangle < b.triangle;
    return a.edge < b.edge;
  });

  const vec2 scale(scaleOffset.x, scaleOffset.y), offset(scaleOffset.z, scaleOffset.w);
  const vec2 page = vec2(float(pageWidth), float(pageHeight));
  auto texelPoint = [&](uint32_t v) { return (object.uv1[v] * scale + offset) * page; };
  const bool haveNormals = object.normals.size() == object.positions.size();

  for (size_t i = 0; i < edges.size();) {
    size_t j = i + 1;
    while (j < edges.size() && edges[j].lo == edges[i].lo && edges[j].hi == edges[i].hi) ++j;
    if (j - i == 2 && edges[i].triangle != edges[i + 1].triangle) {
      const HalfEdge& a = edges[i];
      const HalfEdge& b = edges[i + 1];
      const vec2 a0 = texelPoint(a.vLo), a1 = texelPoint(a.vHi);
      const vec2 b0 = texelPoint(b.vLo), b1 = texelPoint(b.vHi);
      const bool split = glm::length(a0 - b0) > settings.uvTolerance ||
                         glm::length(a1 - b1) > settings.uvTolerance;
      bool smooth = true;
      if (haveNormals && settings.minNormalCos > -1.0f) {
        smooth = glm::dot(object.normals[a.vLo], object.normals[b.vLo]) >= settings.minNormalCos &&
                 glm::dot(object.normals[a.vHi], object.normals[b.vHi]) >= settings.minNormalCos;
      }
      if (split && smooth) seams.push_back({a0, a1, b0, b1, a.triangle, b.triangle});
    }
    i = j;
  }
  std::stable_sort(seams.begin(), seams.end(), [](const SeamEdge& x, const SeamEdge& y) {
    return x.triangleA != y.triangleA ? x.triangleA < y.triangleA : x.triangleB < y.triangleB;
  });
  return seams;
}

void sampleBilinear(const Image& image, vec2 p, float* out) {
  std::array<std::pair<size_t, double>, 4> fp;
  const int n = footprint(image.width, image.height, p, fp);
  for (int ch = 0; ch < image.channels; ++ch) {
    double v = 0.0;
    for (int k = 0; k < n; ++k)
      v += fp[size_t(k)].second * image.pixels[fp[size_t(k)].first * image.channels + ch];
    out[ch] = float(v);
  }
}

StitchStats stitchSeams(Image& image, const std::vector<uint8_t>& mask,
                        const std::vector<SeamEdge>& seams, const StitchSettings& settings) {
  const int w = image.width, h = image.height, c = image.channels;
  assert(mask.size() == size_t(w) * size_t(h));
  StitchStats stats;

  // Rows of M: one per matching pair, +bilinear weights on side A, - on side B, as
  // (texel index, weight) entries in CSR form.
  std::vector<size_t> rowStart{0};
  std::vector<std::pair<size_t, double>> entries;
  for (const SeamEdge& s : seams) {
    const float length = std::max(glm::length(s.a1 - s.a0), glm::length(s.b1 - s.b0));
    const int count = std::max(1, int(std::ceil(length * settings.samplesPerTexel)));
    for (int k = 0; k < count; ++k) {
      const float t = (float(k) + 0.5f) / float(count);
      std::array<std::pair<size_t, double>, 4> fa, fb;
      const int na = footprint(w, h, glm::mix(s.a0, s.a1, t), fa);
      const int nb = footprint(w, h, glm::mix(s.b0, s.b1, t), fb);
      bool usable = true;
      for (int q = 0; q < na; ++q) usable &= mask[fa[size_t(q)].first] != 0;
      for (int q = 0; q < nb; ++q) usable &= mask[fb[size_t(q)].first] != 0;
      if (!usable) continue;
      for (int q = 0; q < na; ++q) entries.push_back(fa[size_t(q)]);
      for (int q = 0; q < nb; ++q) entries.push_back({fb[size_t(q)].first, -fb[size_t(q)].second});
      rowStart.push_back(entries.size());
    }
  }
  const size_t rows = rowStart.size() - 1;
  stats.samples = rows;
  if (rows == 0) return stats;

  // Variables: the texels read by any lookup, in texel order.
  std::vector<size_t> texels;
  texels.reserve(entries.size());
  for (const auto& e : entries) texels.push_back(e.first);
  std::sort(texels.begin(), texels.end());
  texels.erase(std::unique(texels.begin(), texels.end()), texels.end());
  stats.texels = texels.size();
  std::vector<uint32_t> var(entries.size());
  for (size_t e = 0; e < entries.size(); ++e)
    var[e] =
        uint32_t(std::lower_bound(texels.begin(), texels.end(), entries[e].first) - texels.begin());
  const size_t nv = texels.size();

  auto applyM = [&](const std::vector<double>& x, std::vector<double>& y) {
    y.assign(rows, 0.0);
    for (size_t r = 0; r < rows; ++r)
      for (size_t e = rowStart[r]; e < rowStart[r + 1]; ++e) y[r] += entries[e].second * x[var[e]];
  };
  auto applyMt = [&](const std::vector<double>& y, std::vector<double>& x) {
    x.assign(nv, 0.0);
    for (size_t r = 0; r < rows; ++r)
      for (size_t e = rowStart[r]; e < rowStart[r + 1]; ++e) x[var[e]] += entries[e].second * y[r];
  };
  auto dot = [](const std::vector<double>& a, const std::vector<double>& b) {
    double s = 0.0;
    for (size_t i = 0; i < a.size(); ++i) s += a[i] * b[i];
    return s;
  };

  const double sqrtLambda = std::sqrt(std::max(0.0, double(settings.regularization)));
  double before = 0.0, after = 0.0;
  std::vector<double> original(nv), x(nv), delta(nv), rM, rR(nv), s, p, qM, qR(nv), m0;
  std::vector<uint8_t> fixedAtZero(nv);
  for (int ch = 0; ch < c; ++ch) {
    for (size_t v = 0; v < nv; ++v) original[v] = image.pixels[texels[v] * c + ch];
    x = original;
    applyM(x, m0);
    before += dot(m0, m0);
    // Free variables: all, or (nonNegative) those not yet pinned at 0. Each round solves
    //   min |M (x + delta)|^2 + lambda |x + delta - original|^2 over the free variables
    // with CGLS (A = [M; sqrt(lambda) I] restricted to the free columns, b = [-M x;
    // -sqrt(lambda) (x - original)], from delta = 0). The unconstrained least-squares
    // solution overshoots: a dark texel whose bilinear lookup is pulled towards a much
    // brighter other side, or a texel shared by lookups pulled different ways, can go below
    // 0 (breakfast room: 212 texels, down to -0.59). A texel held at 0 is the nearest
    // value a light map can hold, so those are pinned at 0 and the others solved again
    // (an active-set pass; each round pins at least one more texel, so it ends).
    std::fill(fixedAtZero.begin(), fixedAtZero.end(), 0);
    if (settings.nonNegative)
      for (size_t v = 0; v < nv; ++v)
        if (x[v] < 0.0) {
          x[v] = 0.0;  // a negative input is outside what the map may hold
          fixedAtZero[v] = 1;
        }
    for (size_t round = 0; round <= nv; ++round) {
      applyM(x, m0);
      std::fill(delta.begin(), delta.end(), 0.0);
      rM.resize(rows);
      for (size_t r = 0; r < rows; ++r) rM[r] = -m0[r];
      for (size_t v = 0; v < nv; ++v) rR[v] = -sqrtLambda * (x[v] - original[v]);
      auto gradient = [&]() {
        applyMt(rM, s);
        for (size_t v = 0; v < nv; ++v) s[v] = fixedAtZero[v] ? 0.0 : s[v] + sqrtLambda * rR[v];
      };
      gradient();
      p = s;
      double gamma = dot(s, s);
      const double gamma0 = gamma;
      for (int it = 0; it < settings.iterations && gamma > 1e-30 && gamma > 1e-24 * gamma0;
           ++it) {
        applyM(p, qM);
        for (size_t v = 0; v < nv; ++v) qR[v] = sqrtLambda * p[v];
        const double qq = dot(qM, qM) + dot(qR, qR);
        if (qq <= 0.0) break;
        const double alpha = gamma / qq;
        for (size_t v = 0; v < nv; ++v) delta[v] += alpha * p[v];
        for (size_t r = 0; r < rows; ++r) rM[r] -= alpha * qM[r];
        for (size_t v = 0; v < nv; ++v) rR[v] -= alpha * qR[v];
        gradient();
        const double gammaNew = dot(s, s);
        const double beta = gammaNew / gamma;
        for (size_t v = 0; v < nv; ++v) p[v] = s[v] + beta * p[v];
        gamma = gammaNew;
      }
      bool pinned = false;
      for (size_t v = 0; v < nv; ++v) {
        x[v] += delta[v];
        if (settings.nonNegative && x[v] < 0.0) {
          x[v] = 0.0;
          fixedAtZero[v] = 1;
          pinned = true;
        }
      }
      if (!pinned) break;
    }
    for (size_t v = 0; v < nv; ++v) image.pixels[texels[v] * c + ch] = float(x[v]);
    applyM(x, m0);
    after += dot(m0, m0);
  }
  stats.rmsBefore = std::sqrt(before / double(rows * size_t(c)));
  stats.rmsAfter = std::sqrt(after / double(rows * size_t(c)));
  return stats;
}

}  // namespace kiln
