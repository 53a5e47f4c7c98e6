// chart_placement.cpp: chart 2, probe count vs interpolation error on two_rooms for kiln's
// automatic placement, a uniform grid and Godot-style octree corners (chart_measure.h,
// docs/charts.md). The error measure is probe_placement.h's (the one `kiln probes
// compare-placement` reports).
#include <chrono>
#include <memory>

#include "probes/octree_placement.h"
#include "probes/placement_evaluation.h"
#include "probes/probe_baker.h"
#include "probes/probe_placement.h"
#include "src/gltf_loader.h"
#include "src/progress.h"
#include "src/sampling.h"
#include "tools/chart/chart_measure.h"

namespace kiln::chart {
namespace {

constexpr uint64_t kEvalTag = 0x6576616cULL;  // "eval", as compare-placement

double secondsSince(std::chrono::steady_clock::time_point t0) {
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
}

}  // namespace

Result<ChartTable> probePlacementChart(const ChartOptions& o) {
  const std::string path = o.scenesDir + "/two_rooms.gltf";
  Result<Scene> loaded = loadScene(path);
  if (!loaded) return Error{loaded.error()};
  const Scene& scene = *loaded;
  Result<std::unique_ptr<Tracer>> tracerResult = Tracer::create(scene);
  if (!tracerResult) return Error{path + ": " + tracerResult.error()};
  const Tracer& tracer = **tracerResult;

  // The two rooms' interior as the placement volume (docs/probe_placement.md: what a user
  // gives; the static bounds add a sunlit shell outside the building).
  const std::vector<Bounds3> volumes = {Bounds3{vec3(0.0f), vec3(8.25f, 3.0f, 4.0f)}};
  const std::vector<uint32_t> counts =
      o.quick ? std::vector<uint32_t>{16, 32} : std::vector<uint32_t>{32, 64, 128, 256};
  const std::vector<int> levels = o.quick ? std::vector<int>{2, 3} : std::vector<int>{3, 4, 5};
  const uint32_t pointCount = o.quick ? 150 : 1000;
  const uint32_t evalRays = o.quick ? 256 : 2048;

  ProbePlacementSettings place;
  place.volumes = volumes;
  place.budget = counts.back();
  place.candidateRays = o.quick ? 256 : 1024;
  place.checkPoints = o.quick ? 256 : 2048;
  place.seed = o.seed;
  place.threads = o.threads;
  place.bake.threads = o.threads;
  for (size_t i = 0; i + 1 < counts.size(); ++i) place.snapshotCounts.push_back(counts[i]);

  const size_t steps = 2 + counts.size() * 2 + levels.size() * 2 + counts.size();
  Progress progress("chart placement", steps, "steps", o.progress);

  // Evaluation points and their truth: random valid points (a seed apart from placement's
  // check points), SH baked directly there with the probe bake's estimator: the harness
  // compare-placement uses (placement_evaluation.h).
  const uint64_t evalSeed = hashValues(o.seed, kEvalTag);
  ProbeBakeSettings bake;
  bake.rays = evalRays;
  bake.seed = evalSeed;
  bake.threads = o.threads;
  bake.dering = false;  // the truth is not deringed either: compare like with like
  bake.fillInvalid = false;
  Result<TruthPoints> truth = bakeTruthPoints(scene, tracer, volumes, pointCount, evalSeed,
                                              place.validity, bake, nullptr, o.cancel);
  if (o.cancel && o.cancel->load()) return Error{"cancelled"};
  if (!truth) return Error{path + ": evaluation points: " + truth.error()};
  progress.advance();
  bake.seed = o.seed;
  const PlacementEvaluation evaluation(scene, tracer, *truth, bake);

  ChartTable t;
  t.name = "probe_placement";
  t.title = "Probes: count vs interpolation error (two_rooms)";
  t.columns = {"method", "probes", "mean_error", "p95_error", "max_error", "place_seconds",
               "setting"};
  auto evaluate = [&](const std::string& method, const std::vector<vec3>& positions,
                      double seconds, const std::string& setting) -> Status {
    Result<ProbeSetError> measured = evaluation.measure(positions, o.cancel);
    progress.advance();
    if (!measured) return Error{path + ": " + method + " (" + setting + "): " + measured.error()};
    const FieldError& e = measured->visibility;
    t.addRow({method, std::to_string(positions.size()), num(e.mean), num(e.p95), num(e.max),
              num(seconds), setting});
    return Status::success();
  };

  // Uniform grid at each count.
  for (uint32_t n : counts) {
    const auto t0 = std::chrono::steady_clock::now();
    Result<std::vector<vec3>> grid =
        uniformGridPositions(scene, tracer, volumes, n, place.validity, o.threads);
    progress.advance();
    if (!grid) return Error{path + ": uniform grid of " + std::to_string(n) + ": " + grid.error()};
    if (Status s = evaluate("uniform grid", *grid, secondsSince(t0), "count " + std::to_string(n));
        !s)
      return Error{s.error()};
  }

  // Automatic placement: one run to the largest count; the smaller counts are the best sets
  // recorded while it grew (ProbePlacementSettings::snapshotCounts).
  {
    const auto t0 = std::chrono::steady_clock::now();
    Result<ProbePlacement> placed = placeProbes(scene, tracer, place, o.cancel);
    const double seconds = secondsSince(t0);
    progress.advance();
    if (!placed) return Error{path + ": automatic placement: " + placed.error()};
    for (size_t s = 0; s < placed->snapshots.size(); ++s)
      if (Status st = evaluate("automatic", placed->snapshots[s], 0.0,
                               "grown to " + std::to_string(placed->snapshotCounts[s]));
          !st)
        return Error{st.error()};
    if (Status st = evaluate("automatic", placed->positions(), seconds,
                             "budget " + std::to_string(place.budget));
        !st)
      return Error{st.error()};
  }

  // Godot-style octree corners at each level.
  for (int level : levels) {
    OctreePlacementSettings os;
    os.volumes = volumes;
    os.level = level;
    os.validity = place.validity;
    os.threads = o.threads;
    const auto t0 = std::chrono::steady_clock::now();
    Result<OctreePlacement> oct = octreeCornerPlacement(scene, tracer, os);
    progress.advance();
    if (!oct) return Error{path + ": " + oct.error()};
    if (Status s = evaluate("octree corners", oct->positions, secondsSince(t0),
                            "level " + std::to_string(level) + ", cell " +
                                num(oct->cellSize) + " m");
        !s)
      return Error{s.error()};
  }
  progress.finish();

  t.notes = commonNotes(o, o.threads);
  t.notes.push_back("chart 2: probe count vs interpolation error");
  t.notes.push_back("scene: " + path + ", placement volume 0,0,0,8.25,3,4 (the two rooms)");
  t.notes.push_back(
      "error: probe_placement.h relativeIrradianceError (RMS over the 6 axis normals of the "
      "luminance error of E, over max(RMS of the true E, 5% of the mean)) at " +
      std::to_string(truth->points.size()) +
      " random valid points (seed hash(seed, 'eval')); truth = SH baked at each point, probes "
      "baked with bakeProbes, both " + std::to_string(evalRays) + " rays, no deringing");
  t.notes.push_back("methods: automatic = placeProbes (budget " + std::to_string(place.budget) +
                    ", " + std::to_string(place.candidateRays) + " candidate rays, " +
                    std::to_string(place.checkPoints) +
                    " check points; smaller counts are the snapshots of the same run's growth); "
                    "uniform grid = uniformGridPositions (relocated lattice, exact count); "
                    "octree corners = octreeCornerPlacement (Godot LightmapGI: corners of the "
                    "finest octree cells touching static triangles, relocated)");
  t.notes.push_back("baseline: uniform grid and octree corners (what Unity's grid and Godot's "
                    "LightmapGI place); place_seconds = wall time of the placement alone "
                    "(0 for growth snapshots)");

  t.plot =
      "set logscale x 2\n"
      "set logscale y\n"
      "set xlabel 'probes'\n"
      "set ylabel 'mean relative irradiance error'\n"
      "set key top right\n"
      "plot @CSV@ using 'probes':(strcol('method') eq 'automatic' ? column('mean_error') : NaN) "
      "with linespoints lw 2 pt 7 title 'automatic (kiln)', \\\n"
      "  '' using 'probes':(strcol('method') eq 'uniform grid' ? column('mean_error') : NaN) "
      "with linespoints lw 2 pt 5 title 'uniform grid', \\\n"
      "  '' using 'probes':(strcol('method') eq 'octree corners' ? column('mean_error') : NaN) "
      "with linespoints lw 2 pt 9 title 'octree corners (Godot-style)'\n";
  return t;
}

}  // namespace kiln::chart
