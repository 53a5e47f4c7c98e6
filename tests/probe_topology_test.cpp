// probe_topology_test.cpp: buildProbeTopology: TetGen and CGAL agree, cells are positively
// oriented and linked symmetrically, the hull is closed by outer cells, and every degenerate
// probe set (Cupisz 2012 assumes none) gets a working fallback and a warning.
#include <gtest/gtest.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <limits>
#include <map>
#include <random>
#include <set>

#include "kiln/predicates.h"
#include "kiln/probe_runtime.h"
#include "probes/tetrahedralize.h"

namespace kiln {
namespace {

std::vector<glm::vec3> randomPoints(int n, uint32_t seed, float scale = 1.0f) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<float> u(-scale, scale);
  std::vector<glm::vec3> p(static_cast<size_t>(n));
  for (auto& v : p) v = glm::vec3(u(rng), u(rng), u(rng));
  return p;
}

ProbeSet build(std::span<const glm::vec3> pts, DelaunayBackend backend,
               std::vector<std::string>* warnings = nullptr) {
  ProbeTopologySettings s;
  s.backend = backend;
  Result<ProbeSet> r = buildProbeTopology(pts, s, warnings);
  EXPECT_TRUE(r.ok()) << r.error();
  return r.ok() ? std::move(r).value() : ProbeSet{};
}

bool anyContains(const std::vector<std::string>& w, const std::string& text) {
  return std::any_of(w.begin(), w.end(),
                     [&](const std::string& s) { return s.find(text) != std::string::npos; });
}

std::set<std::array<int32_t, 4>> sortedTets(const ProbeSet& s) {
  std::set<std::array<int32_t, 4>> r;
  for (int32_t c = 0; c < s.innerCellCount; ++c) {
    std::array<int32_t, 4> t{s.cells[c][0], s.cells[c][1], s.cells[c][2], s.cells[c][3]};
    std::sort(t.begin(), t.end());
    r.insert(t);
  }
  return r;
}

// Structural checks shared by both backends (dimension 3).
void checkTopology(const ProbeSet& s) {
  ASSERT_EQ(s.dimension, 3);
  ASSERT_TRUE(validateProbeSet(s, "test").ok());
  for (int32_t c = 0; c < s.innerCellCount; ++c) {
    const glm::ivec4 t = s.cells[c];
    EXPECT_GT(orient3d(s.positions[t[0]], s.positions[t[1]], s.positions[t[2]],
                       s.positions[t[3]]),
              0.0)
        << "cell " << c;
    for (int k = 0; k < 4; ++k) {
      const int32_t n = s.neighbours[c][k];
      ASSERT_GE(n, 0) << "every tetrahedron face has a cell beyond it (tet or outer)";
      // The neighbour shares exactly the face opposite vertex k.
      std::set<int32_t> face, other;
      for (int j = 0; j < 4; ++j) {
        if (j != k) face.insert(t[j]);
        if (s.cells[n][j] >= 0) other.insert(s.cells[n][j]);
      }
      for (int32_t v : face) EXPECT_TRUE(other.count(v)) << "cell " << c << " face " << k;
      const glm::ivec4 back = s.neighbours[n];
      EXPECT_TRUE(back[0] == c || back[1] == c || back[2] == c || back[3] == c);
    }
  }
  for (int32_t c = s.innerCellCount; c < s.cellCount(); ++c) {
    const glm::ivec4 t = s.cells[c];
    EXPECT_EQ(t[3], -1);
    const int32_t tet = s.neighbours[c][3];
    ASSERT_GE(tet, 0);
    ASSERT_LT(tet, s.innerCellCount);
    // Outward winding: the tetrahedron's other vertex is behind the hull triangle.
    int32_t apex = -1;
    for (int j = 0; j < 4; ++j) {
      const int32_t v = s.cells[tet][j];
      if (v != t[0] && v != t[1] && v != t[2]) apex = v;
    }
    ASSERT_GE(apex, 0);
    const glm::vec3 a = s.positions[t[0]], b = s.positions[t[1]], cc = s.positions[t[2]];
    EXPECT_LT(orient3d(a, b, cc, s.positions[apex]), 0.0);
    const glm::vec3 fn = glm::normalize(glm::cross(b - a, cc - a));
    for (int k = 0; k < 3; ++k) {
      const glm::vec3 n = s.outerCells[size_t(c - s.innerCellCount)].normals[k];
      EXPECT_NEAR(glm::length(n), 1.0f, 1e-5f);
      EXPECT_GT(glm::dot(n, fn), 0.0f) << "hull vertex normal points out of the hull";
      EXPECT_GE(s.neighbours[c][k], s.innerCellCount) << "outer cells link to outer cells";
    }
  }
}

// Barycentric weights reproduce linear functions: sum w_k x_k == p inside the hull.
glm::dvec3 blendPositions(const ProbeSet& s, const ProbeLocation& loc) {
  glm::dvec3 r(0.0);
  for (int k = 0; k < 4; ++k) r += double(loc.weights[k]) * glm::dvec3(s.positions[loc.probes[k]]);
  return r;
}

void expectSaneWeights(const ProbeLocation& loc) {
  ASSERT_GE(loc.cell, 0);
  float sum = 0.0f;
  for (float w : loc.weights) {
    EXPECT_TRUE(std::isfinite(w));
    EXPECT_GE(w, -1e-6f);
    sum += w;
  }
  EXPECT_NEAR(sum, 1.0f, 1e-5f);
}

TEST(ProbeTopology, TetGenAndCgalGiveTheSameTetrahedra) {
  for (uint32_t seed : {1u, 2u, 3u}) {
    const auto pts = randomPoints(300, seed);
    const ProbeSet a = build(pts, DelaunayBackend::TetGen);
    const ProbeSet b = build(pts, DelaunayBackend::Cgal);
    EXPECT_EQ(sortedTets(a), sortedTets(b));
    // Canonical order: the whole topology is identical, not just the set of cells.
    ASSERT_EQ(a.cells.size(), b.cells.size());
    EXPECT_TRUE(a.cells == b.cells);
    EXPECT_TRUE(a.neighbours == b.neighbours);
    EXPECT_EQ(a.innerCellCount, b.innerCellCount);
  }
}

TEST(ProbeTopology, CellsArePositiveAndLinkedBothWays) {
  const auto pts = randomPoints(500, 7);
  for (DelaunayBackend backend : {DelaunayBackend::TetGen, DelaunayBackend::Cgal}) {
    const ProbeSet s = build(pts, backend);
    checkTopology(s);
    // Euler: a closed triangulated sphere has F = 2V - 4 hull triangles.
    std::set<int32_t> hullVerts;
    for (int32_t c = s.innerCellCount; c < s.cellCount(); ++c) {
      for (int k = 0; k < 3; ++k) hullVerts.insert(s.cells[c][k]);
    }
    EXPECT_EQ(s.cellCount() - s.innerCellCount, 2 * int(hullVerts.size()) - 4);
  }
}

TEST(ProbeTopology, SeedGridOfTheBuildPassEqualsARebuild) {
  // The build offers each cell to the seed grid in its pass over the cells; the grid must be
  // the one buildProbeSeedGrid makes from the finished cells (random and grid probes).
  std::vector<glm::vec3> grid;
  for (int z = 0; z < 6; ++z)
    for (int y = 0; y < 5; ++y)
      for (int x = 0; x < 7; ++x) grid.emplace_back(x, 0.5f * y, 2.0f * z);
  for (const auto& pts : {randomPoints(3000, 11), grid}) {
    for (DelaunayBackend backend : {DelaunayBackend::TetGen, DelaunayBackend::Cgal}) {
      const ProbeSet s = build(pts, backend);
      ProbeSet rebuilt = s;
      buildProbeSeedGrid(rebuilt, ProbeTopologySettings{}.cellsPerSeed);
      EXPECT_EQ(s.grid.size, rebuilt.grid.size);
      EXPECT_EQ(s.grid.min, rebuilt.grid.min);
      EXPECT_EQ(s.grid.max, rebuilt.grid.max);
      EXPECT_EQ(s.grid.seeds, rebuilt.grid.seeds);
      EXPECT_GT(s.grid.seeds.size(), 100u);
    }
  }
}

// The seed grid as the build made it before it filled the grid without a sweep over every
// cell (docs/probes.md "Speed"): each grid cell's seed the inner cell whose centroid, in the
// grid's float arithmetic, is nearest its centre (the earlier one on a tie), and every empty
// grid cell the seed of the neighbour from which a breadth-first sweep (filled cells first, in
// index order; neighbours at -x, +x, -y, +y, -z, +z) reaches it first.
// `deep` counts the grid cells two or more steps from a filled one, `deepest` the most steps.
std::vector<int32_t> sweptSeeds(const ProbeSet& s, size_t& deep, int& deepest) {
  const ProbeSeedGrid& g = s.grid;
  const glm::ivec3 n = g.size;
  glm::vec3 scale(0.0f);
  for (int a = 0; a < 3; ++a) scale[a] = g.max[a] > g.min[a] ? float(n[a]) / (g.max[a] - g.min[a]) : 0.0f;
  const size_t count = size_t(n.x) * size_t(n.y) * size_t(n.z);
  std::vector<int32_t> seeds(count, -1);
  std::vector<float> best(count, std::numeric_limits<float>::infinity());
  for (int32_t c = 0; c < s.innerCellCount; ++c) {
    const glm::ivec4 t = s.cells[size_t(c)];
    const glm::vec3 sum = ((s.positions[size_t(t[0])] + s.positions[size_t(t[1])]) +
                           s.positions[size_t(t[2])]) + s.positions[size_t(t[3])];
    const glm::vec3 f = (sum * 0.25f - g.min) * scale;
    const glm::ivec3 q = glm::clamp(glm::ivec3(f), glm::ivec3(0), n - 1);
    const glm::vec3 d = f - (glm::vec3(q) + 0.5f);
    const float d2 = glm::dot(d, d);
    const size_t i = size_t(q.x) + size_t(n.x) * (size_t(q.y) + size_t(n.y) * size_t(q.z));
    if (d2 < best[i]) {
      best[i] = d2;
      seeds[i] = c;
    }
  }
  std::vector<glm::ivec3> queue;
  std::vector<int> steps(count, 0);
  for (int z = 0; z < n.z; ++z)
    for (int y = 0; y < n.y; ++y)
      for (int x = 0; x < n.x; ++x)
        if (seeds[size_t(x) + size_t(n.x) * (size_t(y) + size_t(n.y) * size_t(z))] >= 0)
          queue.emplace_back(x, y, z);
  auto index = [&](glm::ivec3 q) {
    return size_t(q.x) + size_t(n.x) * (size_t(q.y) + size_t(n.y) * size_t(q.z));
  };
  for (size_t head = 0; head < queue.size(); ++head) {
    const glm::ivec3 q = queue[head];
    for (int a = 0; a < 3; ++a) {
      for (int side = -1; side <= 1; side += 2) {
        glm::ivec3 r = q;
        r[a] += side;
        if (r[a] < 0 || r[a] >= n[a]) continue;
        if (seeds[index(r)] < 0) {
          seeds[index(r)] = seeds[index(q)];
          steps[index(r)] = steps[index(q)] + 1;
          deep += steps[index(r)] >= 2 ? 1 : 0;
          deepest = std::max(deepest, steps[index(r)]);
          queue.push_back(r);
        }
      }
    }
  }
  return seeds;
}

TEST(ProbeTopology, SeedGridIsTheBreadthFirstSweepsGrid) {
  // Sets whose grids have empty cells far from any filled one (the sweep's deeper levels):
  // clusters in corners of their bounds, a sparse set, a dense one, a thin line, a sphere; the
  // build's own grid (one cell per seed) and buildProbeSeedGrid's with other targets.
  std::vector<glm::vec3> corners = randomPoints(400, 21, 0.1f);
  for (const glm::vec3& p : randomPoints(400, 22, 0.1f)) corners.push_back(p + glm::vec3(3.0f, 2.0f, 1.0f));
  for (const glm::vec3& p : randomPoints(60, 23, 0.05f)) corners.push_back(p + glm::vec3(3.0f, 0.0f, 0.0f));
  std::vector<glm::vec3> line = randomPoints(300, 24, 0.02f);
  for (size_t i = 0; i < line.size(); ++i) line[i].x += 0.01f * float(i);
  // Points on a sphere: the grid's corners outside it are empty, bordered by a curved front.
  std::vector<glm::vec3> sphere = randomPoints(2000, 27);
  for (glm::vec3& p : sphere) p = glm::normalize(p);
  size_t deep = 0;
  int deepest = 0;
  for (const auto& pts : {corners, randomPoints(40, 25), randomPoints(5000, 26), line, sphere}) {
    for (DelaunayBackend backend : {DelaunayBackend::TetGen, DelaunayBackend::Cgal}) {
      ProbeSet s = build(pts, backend);
      ASSERT_EQ(s.dimension, 3);
      EXPECT_EQ(s.grid.seeds, sweptSeeds(s, deep, deepest));
      for (int target : {4, 16}) {
        buildProbeSeedGrid(s, target);
        EXPECT_EQ(s.grid.seeds, sweptSeeds(s, deep, deepest)) << target;
      }
    }
  }
  // The sets above reach the sweep's deeper levels (where the fast fill hands over to it).
  EXPECT_GT(deep, 1000u);
  EXPECT_GE(deepest, 4);
}

TEST(ProbeTopology, GridProbesAreCosphericalButValid) {
  // Regular grids are the common case for probes and maximally degenerate for Delaunay.
  std::vector<glm::vec3> pts;
  for (int z = 0; z < 4; ++z)
    for (int y = 0; y < 4; ++y)
      for (int x = 0; x < 4; ++x) pts.emplace_back(x, y, z);
  for (DelaunayBackend backend : {DelaunayBackend::TetGen, DelaunayBackend::Cgal}) {
    const ProbeSet s = build(pts, backend);
    checkTopology(s);
    double volume = 0.0;
    for (int32_t c = 0; c < s.innerCellCount; ++c) {
      const glm::ivec4 t = s.cells[c];
      volume += orient3d(s.positions[t[0]], s.positions[t[1]], s.positions[t[2]],
                         s.positions[t[3]]) / 6.0;
    }
    EXPECT_NEAR(volume, 27.0, 1e-12);  // the tetrahedra tile the 3x3x3 cube
  }
}

TEST(ProbeTopology, NoProbesIsAnError) {
  std::vector<glm::vec3> none;
  Result<ProbeSet> r = buildProbeTopology(none);
  ASSERT_FALSE(r.ok());
  EXPECT_NE(r.error().find("no probes"), std::string::npos);
}

TEST(ProbeTopology, NonFinitePositionIsAnError) {
  std::vector<glm::vec3> pts = randomPoints(10, 3);
  pts[4].y = std::nanf("");
  Result<ProbeSet> r = buildProbeTopology(pts);
  ASSERT_FALSE(r.ok());
  EXPECT_NE(r.error().find("positions[4]"), std::string::npos) << r.error();
}

TEST(ProbeTopology, SingleProbeIsConstant) {
  std::vector<glm::vec3> pts = {glm::vec3(1, 2, 3)};
  std::vector<std::string> w;
  const ProbeSet s = build(pts, DelaunayBackend::TetGen, &w);
  EXPECT_EQ(s.dimension, 0);
  EXPECT_TRUE(anyContains(w, "fewer than 4 probes"));
  EXPECT_TRUE(anyContains(w, "single distinct probe"));
  for (glm::vec3 p : {glm::vec3(0), glm::vec3(1e6f, -1e6f, 5)}) {
    const ProbeLocation loc = locateProbe(s, p);
    expectSaneWeights(loc);
    EXPECT_EQ(loc.probes[0], 0);
    EXPECT_EQ(loc.weights[0], 1.0f);
  }
}

TEST(ProbeTopology, AllDuplicatesCollapseToOneProbe) {
  std::vector<glm::vec3> pts(5, glm::vec3(4, 5, 6));
  std::vector<std::string> w;
  const ProbeSet s = build(pts, DelaunayBackend::Cgal, &w);
  EXPECT_EQ(s.dimension, 0);
  EXPECT_EQ(s.probeCount(), 5);  // merged probes keep their slots
  EXPECT_TRUE(anyContains(w, "4 duplicate probe positions merged"));
  expectSaneWeights(locateProbe(s, glm::vec3(0)));
}

TEST(ProbeTopology, TwoProbesInterpolateAlongTheirLine) {
  std::vector<glm::vec3> pts = {glm::vec3(0, 0, 0), glm::vec3(2, 0, 0)};
  std::vector<std::string> w;
  const ProbeSet s = build(pts, DelaunayBackend::TetGen, &w);
  EXPECT_EQ(s.dimension, 1);
  EXPECT_TRUE(anyContains(w, "colinear"));
  ProbeLocation loc = locateProbe(s, glm::vec3(0.5f, 3.0f, -1.0f));
  expectSaneWeights(loc);
  EXPECT_NEAR(blendPositions(s, loc).x, 0.5, 1e-6);
  loc = locateProbe(s, glm::vec3(-10, 0, 0));  // clamped at the ends
  expectSaneWeights(loc);
  EXPECT_NEAR(blendPositions(s, loc).x, 0.0, 1e-6);
}

TEST(ProbeTopology, ColinearProbesUseSegments) {
  std::vector<glm::vec3> pts;
  const glm::vec3 dir = glm::normalize(glm::vec3(1, 2, 3));
  for (int i : {5, 0, 3, 9, 1, 7}) pts.push_back(float(i) * dir + glm::vec3(1, 1, 1));
  std::vector<std::string> w;
  const ProbeSet s = build(pts, DelaunayBackend::TetGen, &w);
  EXPECT_EQ(s.dimension, 1);
  EXPECT_TRUE(anyContains(w, "colinear probes: all 6"));
  EXPECT_EQ(s.cellCount(), 5);
  std::mt19937 rng(5);
  std::uniform_real_distribution<float> u(0.0f, 9.0f);
  for (int i = 0; i < 200; ++i) {
    const float t = u(rng);
    const glm::vec3 p = t * dir + glm::vec3(1, 1, 1);
    const ProbeLocation loc = locateProbe(s, p);
    expectSaneWeights(loc);
    EXPECT_NEAR(glm::length(blendPositions(s, loc) - glm::dvec3(p)), 0.0, 1e-4);
  }
}

TEST(ProbeTopology, CoplanarProbesUseA2DTriangulation) {
  // A tilted 5x5 grid: every point lies in one plane (within float rounding).
  std::vector<glm::vec3> pts;
  const glm::vec3 u = glm::normalize(glm::vec3(1, 0, 1)), v(0, 1, 0);
  for (int y = 0; y < 5; ++y)
    for (int x = 0; x < 5; ++x) pts.push_back(float(x) * u + float(y) * v);
  for (DelaunayBackend backend : {DelaunayBackend::TetGen, DelaunayBackend::Cgal}) {
    std::vector<std::string> w;
    const ProbeSet s = build(pts, backend, &w);
    EXPECT_EQ(s.dimension, 2);
    EXPECT_TRUE(anyContains(w, "coplanar probes: all 25"));
    // The triangles tile the 4x4 square (float rounding of the tilted grid may add slivers
    // along its border, so the count is not fixed at 32).
    double area = 0.0;
    for (int32_t c = 0; c < s.innerCellCount; ++c) {
      const glm::dvec3 a(s.positions[s.cells[c][0]]), b(s.positions[s.cells[c][1]]),
          d(s.positions[s.cells[c][2]]);
      area += 0.5 * glm::length(glm::cross(b - a, d - a));
    }
    EXPECT_NEAR(area, 16.0, 1e-5);
    EXPECT_GE(s.cellCount() - s.innerCellCount, 4);  // hull edges
    const glm::vec3 n = glm::cross(u, v);
    std::mt19937 rng(9);
    std::uniform_real_distribution<float> r(0.0f, 4.0f), off(-2.0f, 2.0f);
    int bruteForce = 0;
    for (int i = 0; i < 500; ++i) {
      const glm::vec3 inPlane = r(rng) * u + r(rng) * v;
      const ProbeLocation loc = locateProbe(s, inPlane + off(rng) * n);
      expectSaneWeights(loc);
      bruteForce += loc.bruteForce;
      // Constant along the normal, linear in the plane.
      EXPECT_NEAR(glm::length(blendPositions(s, loc) - glm::dvec3(inPlane)), 0.0, 1e-4);
    }
    EXPECT_EQ(bruteForce, 0);
    // Outside the hull: the nearest hull point (continuous, bounded).
    const ProbeLocation out = locateProbe(s, -3.0f * u + 2.0f * v);
    expectSaneWeights(out);
    EXPECT_NEAR(glm::length(blendPositions(s, out) - glm::dvec3(2.0f * v)), 0.0, 1e-4);
  }
}

TEST(ProbeTopology, ThreeProbesMakeOneTriangle) {
  std::vector<glm::vec3> pts = {glm::vec3(0, 0, 0), glm::vec3(1, 0, 0), glm::vec3(0, 0, 1)};
  std::vector<std::string> w;
  const ProbeSet s = build(pts, DelaunayBackend::TetGen, &w);
  EXPECT_EQ(s.dimension, 2);
  EXPECT_TRUE(anyContains(w, "fewer than 4 probes (3)"));
  const ProbeLocation loc = locateProbe(s, glm::vec3(0.25f, 7.0f, 0.25f));
  expectSaneWeights(loc);
  EXPECT_NEAR(glm::length(blendPositions(s, loc) - glm::dvec3(0.25, 0.0, 0.25)), 0.0, 1e-6);
}

TEST(ProbeTopology, NearDuplicatesAreMerged) {
  std::vector<glm::vec3> pts = randomPoints(50, 11);
  pts.push_back(pts[3] + glm::vec3(1e-7f, 0, 0));   // near-duplicate
  pts.push_back(pts[8]);                            // exact duplicate
  std::vector<std::string> w;
  for (DelaunayBackend backend : {DelaunayBackend::TetGen, DelaunayBackend::Cgal}) {
    w.clear();
    const ProbeSet s = build(pts, backend, &w);
    checkTopology(s);
    EXPECT_TRUE(anyContains(w, "1 near-duplicate probes (within"));
    EXPECT_TRUE(anyContains(w, "merged (e.g. positions[50] into positions[3])"));
    EXPECT_TRUE(anyContains(w, "1 duplicate probe positions merged (e.g. positions[51] into "
                               "positions[8])"));
    for (const glm::ivec4& c : s.cells) {
      for (int k = 0; k < 4; ++k) {
        EXPECT_NE(c[k], 50);
        EXPECT_NE(c[k], 51);
      }
    }
  }
}

TEST(ProbeTopology, HugeCoordinatesStillWork) {
  std::vector<glm::vec3> pts = randomPoints(100, 13, 50.0f);
  for (auto& p : pts) p += glm::vec3(1e6f, -2e6f, 1e6f);
  for (DelaunayBackend backend : {DelaunayBackend::TetGen, DelaunayBackend::Cgal}) {
    std::vector<std::string> w;
    const ProbeSet s = build(pts, backend, &w);
    checkTopology(s);
    EXPECT_TRUE(anyContains(w, "large coordinates"));
    std::mt19937 rng(1);
    std::uniform_int_distribution<int> pick(0, s.innerCellCount - 1);
    for (int i = 0; i < 200; ++i) {
      const glm::ivec4 t = s.cells[pick(rng)];
      const glm::vec3 p = 0.25f * (s.positions[t[0]] + s.positions[t[1]] + s.positions[t[2]] +
                                   s.positions[t[3]]);
      const ProbeLocation loc = locateProbe(s, p);
      expectSaneWeights(loc);
      EXPECT_FALSE(loc.bruteForce);
      EXPECT_LT(glm::length(blendPositions(s, loc) - glm::dvec3(p)), 0.2);  // float spacing
    }
  }
}

TEST(ProbeTopology, NearlyCoplanarSetsStayThreeDimensional) {
  std::vector<glm::vec3> pts = randomPoints(40, 17);
  for (auto& p : pts) p.y *= 1e-3f;  // thin slab: 3D, many slivers
  for (DelaunayBackend backend : {DelaunayBackend::TetGen, DelaunayBackend::Cgal}) {
    const ProbeSet s = build(pts, backend);
    checkTopology(s);
    std::mt19937 rng(2);
    std::uniform_real_distribution<float> u(-2.0f, 2.0f);
    for (int i = 0; i < 500; ++i) expectSaneWeights(locateProbe(s, glm::vec3(u(rng), u(rng), u(rng))));
  }
}

}  // namespace
}  // namespace kiln
