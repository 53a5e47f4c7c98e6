// probe_bench.cpp: light-probe lookups per second and tetrahedralization time.
//
// Lookups (kiln::locateProbe, Cupisz's walk) on N random probes in a 10 m cube:
//   - Hinted: an object moving along a smooth closed path, each lookup starting from the
//     previous one's cell (the per-object cache of Cupisz 2012);
//   - Unhinted: uniformly random points, each walk starting from the seed grid, one call per
//     point, and (UnhintedBatch) the same points through the batch form, which interleaves
//     several walks;
//   - CGAL: Delaunay_triangulation_3::locate on the same random points (no hint) and on the
//     path (hinted with the previous cell), CGAL's own triangulation of the same probes (the
//     same Delaunay cells for points in general position). The two hinted loops do the same
//     walk from the same hints (the previous query's cell); kiln's also computes the four
//     barycentric weights and fills a ProbeLocation (probes, weights, steps), where CGAL's
//     returns only the cell: the comparison favours CGAL;
//   - BruteForce: a scan of every tetrahedron (barycentric test), the baseline a lookup
//     structure must beat, on fewer probes;
//   - BlendHinted: the hinted path's lookup plus the SH blend (locateProbe + interpolateProbes),
//     on the same random probes given synthetic visibility maps at the bake's default
//     resolution (kDefaultVisibilityResolution; {mu, sigma, far} per texel), with visibility
//     weighting (visibility:1) and without (visibility:0, the plain barycentric blend of the same
//     set): the two rows of one probe count give the cost of leak-free blending as a ratio (the aim
//     is at most 2x). bytes_per_probe is the .kprobe size (serializeProbeSet) over the probe
//     count, with the visibility block (visibility:1) and without it (0); hidden_share is the
//     share of the blend's probe tests that find the point (partly) hidden (v < 1).
// BM_BlendHinted/visibility:2: the visibility-weighted blend on the same set with a sun layer
// (a ramp in every inner cell).
// Tetrahedralization: buildProbeTopology (Delaunay + outer cells + seed grid) with TetGen and
// with CGAL for 1k, 10k and 100k random probes; BM_CgalDelaunay, a bare CGAL Delaunay of the
// same points; BM_TetrahedralizeOverCgalDelaunay, the two in each iteration and their ratio.
// Each benchmark reports items_per_second (lookups, or probes tetrahedralized).
#include <CGAL/Delaunay_triangulation_3.h>
#include <CGAL/Exact_predicates_inexact_constructions_kernel.h>
#include <benchmark/benchmark.h>

#include <algorithm>
#include <cmath>
#include <ctime>
#include <map>
#include <memory>
#include <random>
#include <vector>

#include "kiln/probe_runtime.h"
#include "probes/probe_baker.h"
#include "probes/tetrahedralize.h"
#include "probes/visibility_bake.h"

namespace kiln {
namespace {

using Kernel = CGAL::Exact_predicates_inexact_constructions_kernel;
using CgalDelaunay = CGAL::Delaunay_triangulation_3<Kernel>;

constexpr float kSide = 10.0f;        // probes fill [0, kSide]^3
constexpr int kQueryCount = 1 << 14;  // lookups per benchmark iteration

std::vector<glm::vec3> randomPoints(size_t n, uint32_t seed, float lo = 0.0f, float hi = kSide) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<float> u(lo, hi);
  std::vector<glm::vec3> p(n);
  for (auto& v : p) v = glm::vec3(u(rng), u(rng), u(rng));
  return p;
}

// A smooth closed Lissajous path through the cube, kQueryCount steps (~3 mm each).
std::vector<glm::vec3> pathPoints() {
  std::vector<glm::vec3> p(kQueryCount);
  for (int i = 0; i < kQueryCount; ++i) {
    const float t = 2.0f * 3.14159265f * float(i) / float(kQueryCount);
    p[i] = glm::vec3(0.5f * kSide) +
           0.4f * kSide * glm::vec3(std::sin(t), std::sin(2.0f * t + 0.5f), std::cos(3.0f * t));
  }
  return p;
}

struct Fixture {
  ProbeSet set;
  std::unique_ptr<CgalDelaunay> cgal;
};

// One ProbeSet (TetGen) and one CGAL triangulation per probe count, built on first use.
const Fixture& fixture(int probes) {
  static std::map<int, std::unique_ptr<Fixture>> cache;
  auto& slot = cache[probes];
  if (!slot) {
    slot = std::make_unique<Fixture>();
    const std::vector<glm::vec3> positions = randomPoints(size_t(probes), 1);
    slot->set = buildProbeTopology(positions).value();
    slot->cgal = std::make_unique<CgalDelaunay>();
    std::vector<Kernel::Point_3> pts;
    for (const auto& p : positions) pts.emplace_back(p.x, p.y, p.z);
    slot->cgal->insert(pts.begin(), pts.end());
  }
  return *slot;
}

void BM_LocateHinted(benchmark::State& state) {
  const Fixture& f = fixture(int(state.range(0)));
  const std::vector<glm::vec3> path = pathPoints();
  int32_t hint = -1;
  size_t steps = 0;
  for (auto _ : state) {
    for (const glm::vec3& p : path) {
      const ProbeLocation loc = locateProbe(f.set, p, hint);
      hint = loc.cell;
      steps += loc.steps;
      benchmark::DoNotOptimize(loc);
    }
  }
  state.SetItemsProcessed(int64_t(state.iterations()) * kQueryCount);
  state.counters["cells_per_lookup"] =
      double(steps) / double(int64_t(state.iterations()) * kQueryCount);
}

void BM_LocateUnhinted(benchmark::State& state) {
  const Fixture& f = fixture(int(state.range(0)));
  const std::vector<glm::vec3> points = randomPoints(kQueryCount, 2);
  size_t steps = 0;
  for (auto _ : state) {
    for (const glm::vec3& p : points) {
      const ProbeLocation loc = locateProbe(f.set, p, -1);
      steps += loc.steps;
      benchmark::DoNotOptimize(loc);
    }
  }
  state.SetItemsProcessed(int64_t(state.iterations()) * kQueryCount);
  state.counters["cells_per_lookup"] =
      double(steps) / double(int64_t(state.iterations()) * kQueryCount);
}

// The same random points as BM_LocateUnhinted through the batch form (locateProbes, no
// hints), which interleaves several walks so that their cache misses overlap: the figure for
// a caller that looks up many objects at once (a frame's dynamic objects).
void BM_LocateUnhintedBatch(benchmark::State& state) {
  const Fixture& f = fixture(int(state.range(0)));
  const std::vector<glm::vec3> points = randomPoints(kQueryCount, 2);
  std::vector<ProbeLocation> out(points.size());
  size_t steps = 0;
  for (auto _ : state) {
    locateProbes(f.set, points, {}, out);
    for (const ProbeLocation& loc : out) steps += loc.steps;
    benchmark::DoNotOptimize(out.data());
  }
  state.SetItemsProcessed(int64_t(state.iterations()) * kQueryCount);
  state.counters["cells_per_lookup"] =
      double(steps) / double(int64_t(state.iterations()) * kQueryCount);
}

void BM_CgalLocateRandom(benchmark::State& state) {
  const Fixture& f = fixture(int(state.range(0)));
  std::vector<Kernel::Point_3> points;
  for (const auto& p : randomPoints(kQueryCount, 2)) points.emplace_back(p.x, p.y, p.z);
  for (auto _ : state) {
    for (const auto& p : points) benchmark::DoNotOptimize(f.cgal->locate(p));
  }
  state.SetItemsProcessed(int64_t(state.iterations()) * kQueryCount);
}

void BM_CgalLocateHinted(benchmark::State& state) {
  const Fixture& f = fixture(int(state.range(0)));
  std::vector<Kernel::Point_3> points;
  for (const auto& p : pathPoints()) points.emplace_back(p.x, p.y, p.z);
  CgalDelaunay::Cell_handle hint;
  for (auto _ : state) {
    for (const auto& p : points) {
      hint = f.cgal->locate(p, hint);
      benchmark::DoNotOptimize(hint);
    }
  }
  state.SetItemsProcessed(int64_t(state.iterations()) * kQueryCount);
}

// Scans every tetrahedron for the one whose barycentric coordinates are all >= 0.
int32_t bruteForceLocate(const ProbeSet& s, glm::vec3 p) {
  const glm::dvec3 q(p);
  for (int32_t c = 0; c < s.innerCellCount; ++c) {
    const glm::dvec3 a(s.positions[s.cells[c][0]]), b(s.positions[s.cells[c][1]]),
        d(s.positions[s.cells[c][2]]), e(s.positions[s.cells[c][3]]);
    const glm::dmat3 m(b - a, d - a, e - a);
    const double det = glm::determinant(m);
    if (det == 0.0) continue;
    const glm::dvec3 l = glm::inverse(m) * (q - a);
    if (l.x >= 0 && l.y >= 0 && l.z >= 0 && l.x + l.y + l.z <= 1) return c;
  }
  return -1;
}

void BM_LocateBruteForce(benchmark::State& state) {
  const Fixture& f = fixture(int(state.range(0)));
  const std::vector<glm::vec3> points = randomPoints(1024, 2, 1.0f, kSide - 1.0f);
  for (auto _ : state) {
    for (const glm::vec3& p : points) benchmark::DoNotOptimize(bruteForceLocate(f.set, p));
  }
  state.SetItemsProcessed(int64_t(state.iterations()) * int64_t(points.size()));
}

// The random probe set of `fixture` (same positions, no CGAL) with a synthetic visibility map
// per probe, the file size per probe with and without the maps, and the share of the blend's
// probe tests along the path that find the point (partly) hidden.
struct VisibilityFixture {
  ProbeSet set;
  double bytesPerProbe = 0.0, plainBytesPerProbe = 0.0;
  double hiddenShare = 0.0;
};

constexpr int32_t kBenchVisibilityResolution = kDefaultVisibilityResolution;

// Every texel {mu, sigma, far} as a bake of a cluttered scene would give it: a surface at a
// depth uniform in [0.5, 1.5] probe spacings (spacing = side / cbrt(probes): about the
// distance to the cell's other probes), a spread of 0.1 spacing and the farthest ray 3
// spreads beyond the surface, each as a fraction of the probe's D (to the farthest corner of
// the probes' bounds, as a bake sets it) and clamped to [0, 1]. Random probes in empty space
// would see nothing (mu = far = 1: every test passes at once, the cheapest case); with these
// maps about half of the tests fall beyond mu, into the Chebyshev branch a wall between probes
// takes, and some beyond far, so both branches and the reach ramp are timed and the branch
// is not predictable.
void addSyntheticVisibility(ProbeSet& set, int32_t resolution, uint32_t seed) {
  ProbeVisibility& v = set.visibility;
  v.resolution = resolution;
  v.maxDistance = visibilityMaxDistances(set.positions, Bounds3{});
  v.moments.resize(size_t(set.probeCount()) * v.valuesPerProbe());
  const float spacing = kSide / std::cbrt(float(set.probeCount()));
  std::mt19937 rng(seed);
  std::uniform_real_distribution<float> depth(0.5f * spacing, 1.5f * spacing);
  const float sigma = 0.1f * spacing;
  auto unorm = [](float x) { return uint16_t(std::lround(std::clamp(x, 0.0f, 1.0f) * 65535.0f)); };
  for (int32_t i = 0; i < set.probeCount(); ++i) {
    const float inverseD = 1.0f / v.maxDistance[size_t(i)];
    uint16_t* texel = v.moments.data() + size_t(i) * v.valuesPerProbe();
    for (size_t t = 0; t < v.valuesPerProbe(); t += kVisibilityValuesPerTexel) {
      const float mu = depth(rng);
      texel[t] = unorm(mu * inverseD);
      texel[t + 1] = unorm(sigma * inverseD);
      texel[t + 2] = unorm((mu + 3.0f * sigma) * inverseD);
    }
  }
}

const VisibilityFixture& visibilityFixture(int probes) {
  static std::map<int, std::unique_ptr<VisibilityFixture>> cache;
  auto& slot = cache[probes];
  if (!slot) {
    slot = std::make_unique<VisibilityFixture>();
    ProbeSet& set = slot->set;
    set = buildProbeTopology(randomPoints(size_t(probes), 1)).value();
    const double n = double(set.probeCount());
    slot->plainBytesPerProbe = double(serializeProbeSet(set).size()) / n;
    addSyntheticVisibility(set, kBenchVisibilityResolution, 4);
    slot->bytesPerProbe = double(serializeProbeSet(set).size()) / n;
    size_t tests = 0, hidden = 0;
    int32_t hint = -1;
    for (const glm::vec3& p : pathPoints()) {
      const ProbeLocation loc = locateProbe(set, p, hint);
      hint = loc.cell;
      for (int k = 0; k < 4; ++k) {
        if (loc.probes[k] < 0 || !(loc.barycentric[k] > 0.0f)) continue;
        const size_t i = size_t(loc.probes[k]);
        ++tests;
        hidden += probeVisibility(set.visibility.probe(int32_t(i)), set.visibility.resolution,
                                  set.visibility.maxDistance[i], p - set.positions[i], {}) < 1.0f;
      }
    }
    slot->hiddenShare = tests > 0 ? double(hidden) / double(tests) : 0.0;
  }
  return *slot;
}

// The visibility fixture's set with a sun layer whose every inner cell has a ramp (the worst
// case: a bake gives ramps only to cells a shadow edge crosses), random shares and ramps.
const ProbeSet& sunFixture(int probes) {
  static std::map<int, std::unique_ptr<ProbeSet>> cache;
  auto& slot = cache[probes];
  if (!slot) {
    slot = std::make_unique<ProbeSet>(visibilityFixture(probes).set);
    ProbeSet& s = *slot;
    std::mt19937 rng(5);
    std::uniform_real_distribution<float> share(0.0f, 1.0f), ramp(-20.0f, 20.0f);
    s.sun.light = 0;
    s.sun.sh.addSample(glm::normalize(glm::vec3(0.3f, 1.0f, -0.2f)), glm::vec3(3.0f), 1.0f);
    for (int32_t i = 0; i < s.probeCount(); ++i) s.sun.visibility.push_back(share(rng));
    for (int32_t c = 0; c < s.innerCellCount; ++c)
      s.sun.ramps.push_back(glm::vec4(ramp(rng), ramp(rng), ramp(rng), ramp(rng)));
  }
  return *slot;
}

// range(1): 0 plain blend, 1 visibility-weighted, 2 visibility-weighted with a sun layer
// (a ramp in every cell).
void BM_BlendHinted(benchmark::State& state) {
  const VisibilityFixture& f = visibilityFixture(int(state.range(0)));
  const ProbeSet& set = state.range(1) == 2 ? sunFixture(int(state.range(0))) : f.set;
  ProbeBlendSettings blend;
  blend.visibility = state.range(1) != 0;
  const std::vector<glm::vec3> path = pathPoints();
  int32_t hint = -1;
  for (auto _ : state) {
    for (const glm::vec3& p : path) {
      const ProbeLocation loc = locateProbe(set, p, hint, blend);
      hint = loc.cell;
      const ShL2Rgb sh = interpolateProbes(set, loc);
      benchmark::DoNotOptimize(sh);
    }
  }
  state.SetItemsProcessed(int64_t(state.iterations()) * kQueryCount);
  state.counters["bytes_per_probe"] = blend.visibility ? f.bytesPerProbe : f.plainBytesPerProbe;
  state.counters["hidden_share"] = blend.visibility ? f.hiddenShare : 0.0;
}

void BM_Tetrahedralize(benchmark::State& state) {
  const std::vector<glm::vec3> positions = randomPoints(size_t(state.range(1)), 3);
  ProbeTopologySettings settings;
  settings.backend = state.range(0) == 0 ? DelaunayBackend::TetGen : DelaunayBackend::Cgal;
  state.SetLabel(state.range(0) == 0 ? "tetgen" : "cgal");
  for (auto _ : state) {
    Result<ProbeSet> set = buildProbeTopology(positions, settings);
    if (!set) {
      state.SkipWithError(set.error().c_str());
      return;
    }
    benchmark::DoNotOptimize(set->cells.data());
  }
  state.SetItemsProcessed(int64_t(state.iterations()) * state.range(1));
}

// The bare Delaunay the topology build is measured against: CGAL's range insert of the same
// points (converted from the floats), nothing else.
void BM_CgalDelaunay(benchmark::State& state) {
  const std::vector<glm::vec3> positions = randomPoints(size_t(state.range(0)), 3);
  for (auto _ : state) {
    std::vector<Kernel::Point_3> pts;
    pts.reserve(positions.size());
    for (const auto& p : positions) pts.emplace_back(p.x, p.y, p.z);
    CgalDelaunay dt(pts.begin(), pts.end());
    benchmark::DoNotOptimize(dt.number_of_cells());
  }
  state.SetItemsProcessed(int64_t(state.iterations()) * state.range(0));
}

// The ratio issue 16 asks about, measured like with like: in each iteration the bare CGAL
// Delaunay of BM_CgalDelaunay and the whole topology build of BM_Tetrahedralize (CGAL backend:
// cells, links, outer cells, seed grid, walk records, validation) on the same points, one
// after the other on this thread, each timed by the thread's CPU clock (so other processes on
// a loaded machine count as little as they can). Counters: cgal_ms, build_ms and ratio =
// build_ms / cgal_ms, summed over the iterations; with --benchmark_repetitions the medians.
double threadCpuMs() {
  timespec t;
  clock_gettime(CLOCK_THREAD_CPUTIME_ID, &t);
  return double(t.tv_sec) * 1e3 + double(t.tv_nsec) * 1e-6;
}

void BM_TetrahedralizeOverCgalDelaunay(benchmark::State& state) {
  const std::vector<glm::vec3> positions = randomPoints(size_t(state.range(0)), 3);
  ProbeTopologySettings settings;
  settings.backend = DelaunayBackend::Cgal;
  double cgal = 0.0, build = 0.0;
  for (auto _ : state) {
    const double t0 = threadCpuMs();
    {
      std::vector<Kernel::Point_3> pts;
      pts.reserve(positions.size());
      for (const auto& p : positions) pts.emplace_back(p.x, p.y, p.z);
      CgalDelaunay dt(pts.begin(), pts.end());
      benchmark::DoNotOptimize(dt.number_of_cells());
    }
    const double t1 = threadCpuMs();
    {
      Result<ProbeSet> set = buildProbeTopology(positions, settings);
      if (!set) {
        state.SkipWithError(set.error().c_str());
        return;
      }
      benchmark::DoNotOptimize(set->cells.data());
    }
    const double t2 = threadCpuMs();
    cgal += t1 - t0;
    build += t2 - t1;
  }
  state.counters["cgal_ms"] = cgal / double(state.iterations());
  state.counters["build_ms"] = build / double(state.iterations());
  state.counters["ratio"] = build / cgal;
}

BENCHMARK(BM_LocateHinted)->Arg(1000)->Arg(10000)->Arg(100000);
BENCHMARK(BM_LocateUnhinted)->Arg(1000)->Arg(10000)->Arg(100000);
BENCHMARK(BM_LocateUnhintedBatch)->Arg(1000)->Arg(10000)->Arg(100000);
BENCHMARK(BM_CgalLocateHinted)->Arg(1000)->Arg(10000)->Arg(100000);
BENCHMARK(BM_CgalLocateRandom)->Arg(1000)->Arg(10000)->Arg(100000);
BENCHMARK(BM_LocateBruteForce)->Arg(1000);
BENCHMARK(BM_BlendHinted)
    ->ArgNames({"probes", "visibility"})
    ->Args({1000, 0})
    ->Args({1000, 1})
    ->Args({10000, 0})
    ->Args({10000, 1})
    ->Args({100000, 0})
    ->Args({100000, 1})
    ->Args({1000, 2})
    ->Args({100000, 2});
BENCHMARK(BM_CgalDelaunay)->ArgName("probes")->Arg(1000)->Arg(10000)->Unit(benchmark::kMillisecond);
BENCHMARK(BM_CgalDelaunay)->ArgName("probes")->Arg(100000)->Iterations(1)->Unit(
    benchmark::kMillisecond);
BENCHMARK(BM_Tetrahedralize)
    ->ArgNames({"backend", "probes"})
    ->Args({0, 1000})
    ->Args({1, 1000})
    ->Args({0, 10000})
    ->Args({1, 10000})
    ->Unit(benchmark::kMillisecond);
BENCHMARK(BM_TetrahedralizeOverCgalDelaunay)
    ->ArgName("probes")
    ->Arg(100000)
    ->Iterations(1)
    ->Unit(benchmark::kMillisecond);
BENCHMARK(BM_Tetrahedralize)
    ->ArgNames({"backend", "probes"})
    ->Args({0, 100000})
    ->Args({1, 100000})
    ->Iterations(1)
    ->Unit(benchmark::kMillisecond);

}  // namespace
}  // namespace kiln
