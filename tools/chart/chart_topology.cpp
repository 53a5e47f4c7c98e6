// chart_topology.cpp: chart 4 (TetGen vs CGAL tetrahedralization time) and chart 5 (probe
// lookups per second: kiln's hinted and unhinted walks, CGAL's locate, brute force over all
// tetrahedra), on random probes in a 10 m cube (chart_measure.h, docs/charts.md). CGAL is
// used here, in a tool; kiln_runtime never links it.
#include <CGAL/Delaunay_triangulation_3.h>
#include <CGAL/Exact_predicates_inexact_constructions_kernel.h>
#include <CGAL/Triangulation_vertex_base_with_info_3.h>

#include <algorithm>
#include <array>
#include <chrono>
#include <cmath>
#include <random>

#include "kiln/probe_runtime.h"
#include "probes/tetrahedralize.h"
#include "src/progress.h"
#include "src/sampling.h"
#include "tools/chart/chart_measure.h"

namespace kiln::chart {
namespace {

using Kernel = CGAL::Exact_predicates_inexact_constructions_kernel;
using VertexBase = CGAL::Triangulation_vertex_base_with_info_3<int32_t, Kernel>;
using Tds = CGAL::Triangulation_data_structure_3<VertexBase>;
using CgalDelaunay = CGAL::Delaunay_triangulation_3<Kernel, Tds>;

constexpr float kSide = 10.0f;  // probes fill [0, kSide]^3
constexpr uint64_t kProbeTag = 0x70726f6265ULL;  // "probe"
constexpr uint64_t kQueryTag = 0x7175657279ULL;  // "query"

// n points uniform in [0, kSide]^3, keyed by (seed, tag, n): each size gets its own set.
std::vector<glm::vec3> randomPoints(size_t n, uint64_t seed, uint64_t tag) {
  std::mt19937_64 rng(hashValues(seed, tag, n));
  std::uniform_real_distribution<float> u(0.0f, kSide);
  std::vector<glm::vec3> p(n);
  for (auto& v : p) {
    const float x = u(rng), y = u(rng), z = u(rng);
    v = glm::vec3(x, y, z);
  }
  return p;
}

// A smooth closed Lissajous path through the cube in `steps` steps (an object moving).
std::vector<glm::vec3> pathPoints(size_t steps) {
  std::vector<glm::vec3> p(steps);
  for (size_t i = 0; i < steps; ++i) {
    const float t = 2.0f * kPi * float(i) / float(steps);
    p[i] = glm::vec3(0.5f * kSide) +
           0.4f * kSide * glm::vec3(std::sin(t), std::sin(2.0f * t + 0.5f), std::cos(3.0f * t));
  }
  return p;
}

double secondsSince(std::chrono::steady_clock::time_point t0) {
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
}

std::string sizeList(const std::vector<size_t>& sizes) {
  std::string s;
  for (size_t n : sizes) s += (s.empty() ? "" : ", ") + std::to_string(n);
  return s;
}

// Brute force over all inner tetrahedra: each tetrahedron's inverse edge matrix is
// precomputed (not timed), so a test is one 3x3 product and four sign checks.
struct BruteForce {
  std::vector<glm::dmat3> inverse;
  std::vector<glm::dvec3> origin;

  explicit BruteForce(const ProbeSet& s) {
    inverse.resize(size_t(s.innerCellCount));
    origin.resize(size_t(s.innerCellCount));
    for (int32_t c = 0; c < s.innerCellCount; ++c) {
      const glm::dvec3 a(s.positions[size_t(s.cells[size_t(c)][0])]);
      const glm::dmat3 m(glm::dvec3(s.positions[size_t(s.cells[size_t(c)][1])]) - a,
                         glm::dvec3(s.positions[size_t(s.cells[size_t(c)][2])]) - a,
                         glm::dvec3(s.positions[size_t(s.cells[size_t(c)][3])]) - a);
      origin[size_t(c)] = a;
      inverse[size_t(c)] = glm::inverse(m);
    }
  }
  // The first inner cell whose barycentric coordinates are all >= 0, or -1 (outside the hull).
  int32_t locate(glm::vec3 p) const {
    const glm::dvec3 q(p);
    for (size_t c = 0; c < inverse.size(); ++c) {
      const glm::dvec3 l = inverse[c] * (q - origin[c]);
      if (l.x >= 0.0 && l.y >= 0.0 && l.z >= 0.0 && l.x + l.y + l.z <= 1.0) return int32_t(c);
    }
    return -1;
  }
};

std::array<int32_t, 4> sortedProbes(const ProbeSet& s, int32_t cell) {
  std::array<int32_t, 4> v{-1, -1, -1, -1};
  if (cell < 0 || cell >= s.innerCellCount) return v;
  for (int k = 0; k < 4; ++k) v[size_t(k)] = s.cells[size_t(cell)][k];
  std::sort(v.begin(), v.end());
  return v;
}

std::array<int32_t, 4> sortedProbes(const CgalDelaunay& dt, CgalDelaunay::Cell_handle c) {
  std::array<int32_t, 4> v{-1, -1, -1, -1};
  if (dt.is_infinite(c)) return v;
  for (int k = 0; k < 4; ++k) v[size_t(k)] = c->vertex(k)->info();
  std::sort(v.begin(), v.end());
  return v;
}

}  // namespace

Result<ChartTable> tetrahedralizationChart(const ChartOptions& o) {
  const std::vector<size_t> sizes = o.quick ? std::vector<size_t>{1000, 3000}
                                            : std::vector<size_t>{1000, 3000, 10000, 30000,
                                                                  100000};
  const std::array<DelaunayBackend, 2> backends = {DelaunayBackend::TetGen,
                                                   DelaunayBackend::Cgal};
  auto repeatsFor = [&](size_t n) { return o.quick ? 3 : (n <= 10000 ? 5 : 3); };
  size_t steps = 0;
  for (size_t n : sizes) steps += size_t(repeatsFor(n)) * backends.size();
  Progress progress("chart tetrahedralization", steps, "runs", o.progress);

  ChartTable t;
  t.name = "tetrahedralization";
  t.title = "Tetrahedralization time: TetGen vs CGAL (random probes)";
  t.columns = {"probes", "backend", "median_seconds", "min_seconds", "max_seconds",
               "probes_per_second", "inner_cells", "repeats"};
  // Rows grouped by backend (gnuplot draws each backend's rows as one line).
  std::array<std::vector<std::vector<std::string>>, 2> rowsByBackend;
  for (size_t n : sizes) {
    const std::vector<glm::vec3> positions = randomPoints(n, o.seed, kProbeTag);
    std::array<std::vector<double>, 2> seconds;
    std::array<int32_t, 2> cells{0, 0};
    // Repeats interleaved: TetGen, CGAL, TetGen, CGAL, ...
    for (int r = 0; r < repeatsFor(n); ++r)
      for (size_t b = 0; b < backends.size(); ++b) {
        if (o.cancel && o.cancel->load()) return Error{"cancelled"};
        ProbeTopologySettings settings;
        settings.backend = backends[b];
        const auto t0 = std::chrono::steady_clock::now();
        Result<ProbeSet> set = buildProbeTopology(positions, settings);
        seconds[b].push_back(secondsSince(t0));
        progress.advance();
        if (!set)
          return Error{std::string(b == 0 ? "TetGen" : "CGAL") + " on " + std::to_string(n) +
                       " probes: " + set.error()};
        cells[b] = set->innerCellCount;
      }
    for (size_t b = 0; b < backends.size(); ++b) {
      const double med = median(seconds[b]);
      rowsByBackend[b].push_back({std::to_string(n), b == 0 ? "TetGen" : "CGAL", num(med),
                num(*std::min_element(seconds[b].begin(), seconds[b].end())),
                num(*std::max_element(seconds[b].begin(), seconds[b].end())),
                num(double(n) / med), std::to_string(cells[b]), std::to_string(seconds[b].size())});
    }
  }
  progress.finish();
  for (const auto& rows : rowsByBackend)
    for (const auto& row : rows) t.addRow(row);

  t.notes = commonNotes(o, 1);
  t.notes.push_back("chart 4: TetGen vs CGAL tetrahedralization time");
  t.notes.push_back("input: " + sizeList(sizes) +
                    " probes uniform in a 10 m cube (std::mt19937_64 keyed by seed and size)");
  t.notes.push_back("measured: buildProbeTopology (probes/tetrahedralize.h) with backend TetGen "
                    "(tetrahedralize 'Qz') or CGAL (Delaunay_triangulation_3, exact predicates, "
                    "inexact constructions): the Delaunay step plus kiln's shared work (merge "
                    "check, canonical cell order, neighbours, outer cells, seed grid), one thread");
  t.notes.push_back("timing: median of 5 runs (3 at >10k probes; 3 with --quick), TetGen and CGAL "
                    "runs interleaved; baseline: TetGen, kiln's default backend; inner_cells of "
                    "the two must agree (the Delaunay tetrahedralization of points in general "
                    "position is unique)");
  t.plot =
      "set logscale xy\n"
      "set xlabel 'probes'\n"
      "set ylabel 'seconds (median)'\n"
      "set key top left\n"
      "plot @CSV@ using 'probes':(strcol('backend') eq 'TetGen' ? column('median_seconds') : "
      "NaN) with linespoints lw 2 pt 7 title 'TetGen', \\\n"
      "  '' using 'probes':(strcol('backend') eq 'CGAL' ? column('median_seconds') : NaN) with "
      "linespoints lw 2 pt 5 title 'CGAL'\n";
  return t;
}

Result<ChartTable> probeLookupChart(const ChartOptions& o) {
  const std::vector<size_t> sizes =
      o.quick ? std::vector<size_t>{1000, 3000} : std::vector<size_t>{1000, 10000, 100000};
  const size_t queryCount = o.quick ? 4096 : 16384;
  const int repeats = o.quick ? 3 : 5;
  const std::vector<glm::vec3> path = pathPoints(queryCount);
  const std::vector<glm::vec3> random = randomPoints(queryCount, o.seed, kQueryTag);
  double meanStep = 0.0;
  for (size_t i = 1; i < path.size(); ++i) meanStep += glm::distance(path[i - 1], path[i]);
  meanStep /= double(path.size() - 1);
  Progress progress("chart lookup", sizes.size() * size_t(repeats + 1), "steps", o.progress);

  ChartTable t;
  t.name = "probe_lookup";
  t.title = "Probe lookup throughput (random probes in a 10 m cube, one thread)";
  t.columns = {"probes", "method", "lookups_per_second", "ns_per_lookup", "queries", "repeats",
               "cells_per_lookup", "checked", "agree_brute_force"};
  volatile int64_t sink = 0;  // keeps the timed loops from being optimized away
  for (size_t n : sizes) {
    if (o.cancel && o.cancel->load()) return Error{"cancelled"};
    const std::vector<glm::vec3> positions = randomPoints(n, o.seed, kProbeTag);
    Result<ProbeSet> built = buildProbeTopology(positions);
    if (!built) return Error{"TetGen on " + std::to_string(n) + " probes: " + built.error()};
    const ProbeSet& set = *built;
    CgalDelaunay dt;
    {
      std::vector<std::pair<Kernel::Point_3, int32_t>> pts;
      for (size_t i = 0; i < positions.size(); ++i)
        pts.emplace_back(Kernel::Point_3(positions[i].x, positions[i].y, positions[i].z),
                         int32_t(i));
      dt.insert(pts.begin(), pts.end());
    }
    std::vector<Kernel::Point_3> cgalRandom, cgalPath;
    for (const glm::vec3& p : random) cgalRandom.emplace_back(p.x, p.y, p.z);
    for (const glm::vec3& p : path) cgalPath.emplace_back(p.x, p.y, p.z);
    const BruteForce brute(set);
    // Brute force costs queries x cells: fewer queries on larger sets (~2.6e8 tests per run).
    const size_t bruteCount =
        std::clamp<size_t>(size_t(2.6e8 / double(std::max<int32_t>(set.innerCellCount, 1))),
                           16, 1024);
    progress.advance();

    // Correctness first (not timed): at bruteCount random points and bruteCount path points,
    // every method must find the tetrahedron brute force finds (the same four probes for
    // CGAL; "outside the hull" for an outer cell / CGAL's infinite cell / -1).
    std::array<size_t, 5> agree{};
    {
      std::vector<int32_t> hintedCells(path.size());
      int32_t hint = -1;
      for (size_t i = 0; i < path.size(); ++i) hint = hintedCells[i] = locateProbe(set, path[i], hint).cell;
      std::vector<CgalDelaunay::Cell_handle> cgalHinted(path.size());
      CgalDelaunay::Cell_handle ch;
      for (size_t i = 0; i < path.size(); ++i) ch = cgalHinted[i] = dt.locate(cgalPath[i], ch);
      for (size_t k = 0; k < bruteCount; ++k) {
        const size_t ip = k * path.size() / bruteCount;
        const std::array<int32_t, 4> truthPath = sortedProbes(set, brute.locate(path[ip]));
        const std::array<int32_t, 4> truthRandom = sortedProbes(set, brute.locate(random[k]));
        agree[0] += sortedProbes(set, hintedCells[ip]) == truthPath;
        agree[1] += sortedProbes(set, locateProbe(set, random[k], -1).cell) == truthRandom;
        agree[2] += sortedProbes(dt, dt.locate(cgalRandom[k])) == truthRandom;
        agree[3] += sortedProbes(dt, cgalHinted[ip]) == truthPath;
        agree[4] += 1;  // brute force is the reference
      }
    }

    // Timing: each repeat runs every method once, in the same order; medians over repeats.
    std::array<std::vector<double>, 5> seconds;
    std::array<double, 2> steps{0.0, 0.0};
    for (int r = 0; r < repeats; ++r) {
      if (o.cancel && o.cancel->load()) return Error{"cancelled"};
      int64_t acc = 0;
      size_t walkSteps = 0;
      auto t0 = std::chrono::steady_clock::now();
      int32_t hint = -1;
      for (const glm::vec3& p : path) {
        const ProbeLocation loc = locateProbe(set, p, hint);
        hint = loc.cell;
        walkSteps += loc.steps;
      }
      seconds[0].push_back(secondsSince(t0));
      acc += hint;
      steps[0] = double(walkSteps) / double(path.size());

      walkSteps = 0;
      t0 = std::chrono::steady_clock::now();
      for (const glm::vec3& p : random) {
        const ProbeLocation loc = locateProbe(set, p, -1);
        acc += loc.cell;
        walkSteps += loc.steps;
      }
      seconds[1].push_back(secondsSince(t0));
      steps[1] = double(walkSteps) / double(random.size());

      t0 = std::chrono::steady_clock::now();
      for (const auto& p : cgalRandom) acc += dt.is_infinite(dt.locate(p)) ? 1 : 0;
      seconds[2].push_back(secondsSince(t0));

      t0 = std::chrono::steady_clock::now();
      CgalDelaunay::Cell_handle ch;
      for (const auto& p : cgalPath) {
        ch = dt.locate(p, ch);
        acc += dt.is_infinite(ch) ? 1 : 0;
      }
      seconds[3].push_back(secondsSince(t0));

      t0 = std::chrono::steady_clock::now();
      for (size_t k = 0; k < bruteCount; ++k) acc += brute.locate(random[k]);
      seconds[4].push_back(secondsSince(t0));
      sink = sink + acc;
      progress.advance();
    }
    const std::array<const char*, 5> names = {"hinted walk (path)", "unhinted walk (random)",
                                              "CGAL locate (random)", "CGAL locate hinted (path)",
                                              "brute force (random)"};
    const std::array<size_t, 5> queries = {path.size(), random.size(), random.size(), path.size(),
                                           bruteCount};
    for (size_t m = 0; m < names.size(); ++m) {
      const double med = median(seconds[m]);
      t.addRow({std::to_string(n), names[m], num(double(queries[m]) / med),
                num(1e9 * med / double(queries[m])), std::to_string(queries[m]),
                std::to_string(repeats), m < 2 ? num(steps[m]) : "",
                std::to_string(bruteCount), std::to_string(agree[m])});
    }
  }
  progress.finish();

  t.notes = commonNotes(o, 1);
  t.notes.push_back("chart 5: probe lookup throughput");
  t.notes.push_back("probes: " + sizeList(sizes) +
                    " uniform in a 10 m cube (same sets as chart 4), TetGen topology "
                    "(buildProbeTopology); CGAL: its own Delaunay_triangulation_3 of the same "
                    "points");
  t.notes.push_back("queries: 'path' = " + std::to_string(queryCount) +
                    " steps of a closed Lissajous path (an object moving, " +
                    num(1000.0 * meanStep) + " mm per step on average), each lookup hinted with the previous one's cell (Cupisz "
                    "2012); 'random' = " + std::to_string(queryCount) +
                    " uniform points in the cube, no hint (kiln starts from its seed grid)");
  t.notes.push_back("brute force: scan of every inner tetrahedron (barycentric test with "
                    "precomputed inverse edge matrices, precomputation not timed) on the first "
                    "'queries' random points; baseline of the chart");
  t.notes.push_back("timing: one thread; median of " + std::to_string(repeats) +
                    " repeats, each repeat running all five methods in turn; cells_per_lookup = "
                    "cells the walk visited");
  t.notes.push_back("check: at 'checked' random points and as many path points (not timed), "
                    "agree_brute_force = lookups that found the same tetrahedron (same four "
                    "probes) as brute force, or outside the hull for both");
  t.plot =
      "set logscale y\n"
      "set style data histograms\n"
      "set style histogram clustered gap 1\n"
      "set style fill solid 0.8 border -1\n"
      "set ylabel 'lookups per second (one thread)'\n"
      "set format y '10^{%L}'\n"
      "set xlabel 'probes'\n"
      "set key top right\n"
      "set yrange [*:*]\n";
  // Clustered bars: one cluster per probe count, one bar per method (rows are method-major
  // within a count, so each method's rows are every 5th line).
  t.plot += "plot ";
  const std::array<const char*, 5> titles = {"hinted walk (path)", "unhinted walk (random)",
                                             "CGAL locate (random)", "CGAL locate hinted (path)",
                                             "brute force"};
  for (size_t m = 0; m < titles.size(); ++m) {
    t.plot += std::string(m ? ", \\\n  " : "") + "@CSV@ every 5::" + std::to_string(m) +
              " using 'lookups_per_second'" + (m == 0 ? ":xtic(1)" : "") + " title '" +
              titles[m] + "'";
  }
  t.plot += "\n";
  return t;
}

}  // namespace kiln::chart
