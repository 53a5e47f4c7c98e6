// probes_place_command.cpp: `kiln probes place` (automatic probe placement, writes the JSON
// that `kiln probes bake --positions` reads) and `kiln probes compare-placement` (the
// rerunnable comparison of automatic placement against a uniform grid and Godot-style octree
// corners, each evaluated with and without visibility-weighted blending). Thin over
// probes/probe_placement.h and probes/octree_placement.h. Usage, algorithm and measurements:
// docs/probe_placement.md.
#include <chrono>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <functional>
#include <iomanip>
#include <iostream>
#include <memory>
#include <optional>
#include <nlohmann/json.hpp>
#include <sstream>

#include "probes/octree_placement.h"
#include "probes/placement_evaluation.h"
#include "probes/probe_baker.h"
#include "probes/probe_placement.h"
#include "src/distributed.h"
#include "src/progress.h"
#include "src/tracer.h"
#include "tools/kiln/cli_common.h"
#include "src/text_file.h"

namespace kiln::cli {
namespace {

using Json = nlohmann::json;

Json vecJson(vec3 v) { return Json::array({v.x, v.y, v.z}); }

// "minx,miny,minz,maxx,maxy,maxz" -> Bounds3 (finite floats, min < max).
std::optional<Bounds3> parseVolume(const std::string& text) {
  std::stringstream ss(text);
  std::string item;
  std::vector<float> v;
  while (std::getline(ss, item, ',')) {
    try {
      size_t used = 0;
      v.push_back(std::stof(item, &used));
      if (used != item.size()) return std::nullopt;
    } catch (...) {
      return std::nullopt;
    }
  }
  if (v.size() != 6) return std::nullopt;
  Bounds3 b;
  b.min = vec3(v[0], v[1], v[2]);
  b.max = vec3(v[3], v[4], v[5]);
  if (!isFinite(b.min) || !isFinite(b.max) || !(b.min.x < b.max.x && b.min.y < b.max.y &&
                                                b.min.z < b.max.z))
    return std::nullopt;
  return b;
}

struct CommonOptions {
  std::string scene;
  std::vector<std::string> volumes;
  float minDistance = 0.1f;
  int rays = 1024;         // cheap bake rays
  int checkPoints = 2048;  // training check points
  float spacing = 0.0f;
  int depth = 2;
  float leakWeight = 1.0f;
  float floorHeight = 0.4f;
  bool holdOut = false;
  bool symmetricPicks = false;
  bool noSceneProbes = false;
  int visibilityResolution = kDefaultVisibilityResolution;  // 0 = score the plain blend
  uint64_t seed = 0;
  int threads = 0;
  bool quiet = false;
  bool mpi = false;
  SkyOptions sky;
};

// Fills the placement settings shared by both subcommands; returns an exit code.
int makeSettings(const CommonOptions& o, ProbePlacementSettings* s) {
  for (size_t i = 0; i < o.volumes.size(); ++i) {
    std::optional<Bounds3> b = parseVolume(o.volumes[i]);
    if (!b) {
      printError("--volume " + o.volumes[i] +
                 ": expected minx,miny,minz,maxx,maxy,maxz (6 finite numbers) with min < max");
      return kExitBadUsage;
    }
    s->volumes.push_back(*b);
  }
  s->validity.minSurfaceDistance = o.minDistance;
  s->candidateRays = uint32_t(o.rays);
  s->checkPoints = uint32_t(o.checkPoints);
  s->spacing = o.spacing;
  s->maxDepth = o.depth;
  s->leakWeight = o.leakWeight;
  s->floorHeight = o.floorHeight;
  s->holdOut = o.holdOut;
  s->symmetricPicks = o.symmetricPicks;
  s->bake.visibilityResolution = o.visibilityResolution;
  s->seed = o.seed;
  s->threads = o.threads;
  s->bake.threads = o.threads;
  s->showProgress = !o.quiet;
  return kExitOk;
}

void addCommonOptions(CLI::App* c, CommonOptions* o) {
  c->add_option("scene", o->scene, "glTF 2.0 file (.gltf or .glb)")->required();
  c->add_option("--volume", o->volumes,
                "minx,miny,minz,maxx,maxy,maxz (repeatable); default: the static objects' bounds");
  c->add_option("--min-distance", o->minDistance, "Closest a probe may be to a surface (m)")
      ->check(positiveNumberValidator())
      ->capture_default_str();
  c->add_option("--rays", o->rays, "Rays per cheap bake (candidates and check points)")
      ->check(CLI::Range(1, 1 << 20))
      ->capture_default_str();
  c->add_option("--check-points", o->checkPoints, "Training check points")
      ->check(CLI::Range(1, 1 << 20))
      ->capture_default_str();
  c->add_option("--spacing", o->spacing, "Base octree spacing in m (0 = from the budget)")
      ->check(nonNegativeNumberValidator());
  c->add_option("--depth", o->depth, "Octree levels below the base spacing")
      ->check(CLI::Range(0, 6))
      ->capture_default_str();
  c->add_option("--leak-weight", o->leakWeight,
                "Weight of the leak estimate (cells spanning walls) in a set's score (0 = off)")
      ->check(nonNegativeNumberValidator())
      ->capture_default_str();
  c->add_option("--visibility-resolution", o->visibilityResolution,
                "Side of the visibility maps the cheap bakes record, so that sets are scored "
                "with the visibility-weighted blend (as kiln probes bake; 0 = plain blend, for "
                "probes baked without visibility)")
      ->check(visibilityResolutionValidator("plain blend"))
      ->capture_default_str();
  c->add_option("--floor-height", o->floorHeight,
                "Height (m) of the first layer of candidates above walkable surfaces, with "
                "sparser layers above it (0 = octree corners only)")
      ->check(finiteNumberValidator(0.0, false, 100.0, "a number of metres from 0 to 100",
                                    "0..100"))
      ->capture_default_str();
  c->add_flag("--hold-out", o->holdOut,
              "Growth picks from half of the check points and the other half scores the sets "
              "(by default the same check points do both)");
  c->add_flag("--symmetric-picks", o->symmetricPicks,
              "Each growth round also builds a batch from the check points ranked by the "
              "error relative to the brighter of truth and estimate, and keeps the batch "
              "that scores lower (better in open sunlit space, worse where objects stand)");
  c->add_flag("--no-scene-probes", o->noSceneProbes,
              "Ignore the scene's probe groups (extras.kiln.probes); by default they are fixed "
              "probes that placement builds around");
  c->add_option("--seed", o->seed, "Seed of every random number")->capture_default_str();
  c->add_option("--threads", o->threads, "Worker threads (0 = all cores)")
      ->check(CLI::NonNegativeNumber);
  addSkyOptions(c, o->sky);
  c->add_flag("--quiet,-q", o->quiet, "No progress or summary on stderr");
}

struct LoadedScene {
  Scene scene;
  std::unique_ptr<Tracer> tracer;
};

// Loads the scene (with the --sky override; Ctrl-C installed) and builds its tracer.
int loadTraced(const CommonOptions& o, LoadedScene* out) {
  std::optional<Sky> sky;
  if (int code = resolveSky(o.sky, &sky)) return code;
  if (int code = loadSceneForBake(o.scene, -1, o.quiet, sky, &out->scene)) return code;
  const std::string& path = o.scene;
  Result<std::unique_ptr<Tracer>> tracer = Tracer::create(out->scene);
  if (!tracer) {
    printError(path + ": " + tracer.error());
    return kExitBadInput;
  }
  out->tracer = std::move(tracer).value();
  return kExitOk;
}

// The scene's probe groups as fixed probes, unless --no-scene-probes.
void addSceneProbes(const CommonOptions& o, const Scene& scene, ProbePlacementSettings* s) {
  if (!o.noSceneProbes) s->fixedProbes = sceneProbePositions(scene);
}

// ---- place ---------------------------------------------------------------------------------

struct PlaceOptions {
  CommonOptions common;
  std::string out;
  int budget = 256;
  float targetError = 0.0f;
  bool noPrune = false;
};

int runPlace(const PlaceOptions& options) {
  // A distributed placement (docs/distributed.md): the cheap bakes split across ranks, every
  // rank places from all of them; rank 0 writes.
  if (int code = startDistributedBake(options.common.mpi)) return code;
  PlaceOptions o = options;
  o.common.quiet = o.common.quiet || !distributedRoot();
  ProbePlacementSettings settings;
  if (int code = makeSettings(o.common, &settings)) return code;
  settings.budget = uint32_t(o.budget);
  settings.targetError = o.targetError;
  settings.prune = !o.noPrune;
  // Before any work: a bad --out fails now, not after the placement.
  if (distributedRoot())
    if (int code = checkOutputFile("--out", o.out)) return code;
  LoadedScene ls;
  if (int code = loadTraced(o.common, &ls)) return code;
  addSceneProbes(o.common, ls.scene, &settings);
  Result<ProbePlacement> placed = placeProbes(ls.scene, *ls.tracer, settings, &cancelFlag());
  if (cancelFlag().load()) return reportInterrupted(o.out);
  if (!placed) {
    printError(o.common.scene + ": " + placed.error());
    return kExitBadInput;
  }
  if (!distributedRoot()) return kExitOk;  // rank 0 writes
  // "positions" leaves the scene's own probes out: `kiln probes bake` adds them itself
  // (unless --no-scene-probes); "fixedPositions" lists them.
  Json positions = Json::array(), fixedPositions = Json::array(), probes = Json::array();
  for (const PlacedProbe& p : placed->probes) {
    (p.fixed ? fixedPositions : positions).push_back(vecJson(p.position));
    if (p.fixed) continue;
    Json note = {{"position", vecJson(p.position)}, {"moved", p.moved}};
    if (p.moved) {
      note["candidate"] = vecJson(p.candidate);
      note["why"] = p.why;
    }
    probes.push_back(note);
  }
  Json doc = {{"positions", positions},
              {"fixedPositions", fixedPositions},
              {"probes", probes},
              {"report",
               {{"probeCount", placed->probes.size()},
                {"budget", settings.budget},
                {"belowBudget", placed->belowBudget},
                {"fixedProbes", placed->fixedProbes},
                {"candidates", placed->candidates},
                {"candidatesMoved", placed->candidatesMoved},
                {"candidatesDropped", placed->candidatesDropped},
                {"candidatesUnreachable", placed->candidatesUnreachable},
                {"candidatesAboveFloors", placed->candidatesAboveFloors},
                {"reachableCells", placed->reachableCells},
                {"gridCells", placed->gridCells},
                {"checkPoints", placed->checkPoints},
                {"checkPointsAboveFloors", placed->checkPointsAboveFloors},
                {"visibilityResolution", settings.bake.visibilityResolution},
                {"spawned", placed->spawned},
                {"initialError", placed->initialError},
                {"estimatedError", placed->estimatedError},
                {"estimatedError95", placed->estimatedError95},
                {"estimatedLeak", placed->estimatedLeak},
                {"leakRejected", placed->leakRejected},
                {"rounds", placed->rounds},
                {"pruned", placed->pruned},
                {"seconds", placed->seconds}}}};
  if (Status s = writeTextFileAtomically(o.out, doc.dump(1) + "\n"); !s) {
    printError(s.error());
    return kExitBadInput;
  }
  // Far below the budget is worth a warning even with --quiet: the user asked for more.
  if (!placed->belowBudget.empty())
    std::cerr << "kiln: warning: " << o.common.scene << ": placed " << placed->belowBudget
              << "\n";
  if (!o.common.quiet) {
    std::cerr << "kiln: wrote " << o.out << ": " << placed->probes.size() << " probes ("
              << placed->fixedProbes << " fixed from the scene's probe groups) from "
              << placed->candidates << " valid candidates (" << placed->candidatesAboveFloors
              << " above walkable surfaces; " << placed->candidatesMoved
              << " moved out of or away from geometry, " << placed->candidatesDropped
              << " dropped, " << placed->candidatesUnreachable << " in sealed space; "
              << placed->spawned
              << " probes added at check points); estimated score (mean relative irradiance "
              << "error + leak estimate, "
              << (settings.bake.visibilityResolution > 0 ? "visibility-weighted" : "plain")
              << " blend) " << std::setprecision(3) << placed->estimatedError
              << " (leak " << placed->estimatedLeak << ", 95th percentile of the error "
              << placed->estimatedError95 << ", from " << placed->initialError << ") at "
              << placed->checkPoints << " check points; " << placed->rounds << " rounds, "
              << placed->pruned << " pruned, " << placed->leakRejected
              << " picks dropped for leaks; " << std::setprecision(3) << placed->seconds
              << " s\n";
  }
  return kExitOk;
}

// ---- compare-placement -----------------------------------------------------------------------

struct CompareOptions {
  CommonOptions common;
  int count = 256;
  int points = 1000;
  int evalRays = 4096;
  int objectPoints = 0;  // points where objects stand, for the sphere measure (0 = off)
  std::optional<uint64_t> evalSeed;  // default: derived from --seed
  bool exactSun = false;  // also measure every set with the exact sun share (a bound)
  std::string csv, pointsCsv;
};

struct Row {
  std::string method;
  size_t count = 0;
  FieldError error;       // visibility-weighted blend (the runtime's default)
  FieldError plain;       // plain barycentric blend of the same probes
  float nearWall = 0.0f;  // mean over points within 0.5 m of a surface (visibility)
  float nearWallPlain = 0.0f;
  CellCrossing crossing;
  std::optional<SphereError> spheres;  // at the object points (--object-points)
  std::optional<FieldError> exactSun;  // the sun layer replaced by exact shares (--exact-sun)
  double seconds = 0.0;
};

// The fewest probes of an automatic row whose mean (as `mean` reads it off a row) is at most
// the grid's; 0 = none.
size_t countToMatch(const std::vector<Row>& rows, const Row& grid,
                    const std::function<float(const Row&)>& mean) {
  size_t needed = 0;
  for (const Row& r : rows)
    if (r.method.rfind("automatic", 0) == 0 && mean(r) <= mean(grid) &&
        (needed == 0 || r.count < needed))
      needed = r.count;
  return needed;
}

int runCompare(const CompareOptions& o) {
  ProbePlacementSettings settings;
  if (int code = makeSettings(o.common, &settings)) return code;
  settings.budget = uint32_t(o.count);
  // Snapshots at these fractions of the count resolve the count automatic needs.
  for (const auto& [num, den] : {std::pair{1, 8}, {1, 6}, {1, 5}, {1, 4}, {1, 3}, {1, 2},
                                 {2, 3}, {3, 4}, {7, 8}}) {
    const int n = o.count * num / den;
    if (n >= 4) settings.snapshotCounts.push_back(uint32_t(n));
  }
  for (const auto& [option, file] : {std::pair{"--csv", o.csv}, {"--points-csv", o.pointsCsv}})
    if (!file.empty())
      if (int code = checkOutputFile(option, file)) return code;
  LoadedScene ls;
  if (int code = loadTraced(o.common, &ls)) return code;
  const Scene& scene = ls.scene;
  const Tracer& tracer = *ls.tracer;
  addSceneProbes(o.common, scene, &settings);
  const std::vector<Bounds3> volumes = placementVolumes(scene, settings.volumes);
  // Evaluation points only where objects can go: not in sealed cavities.
  ReachableSpaceSettings reachableSettings;
  reachableSettings.seeds = settings.fixedProbes;
  reachableSettings.threads = o.common.threads;
  const ReachableSpace reachable =
      ReachableSpace::build(scene, tracer, volumes, reachableSettings, &cancelFlag());
  if (cancelFlag().load()) return reportInterrupted("outputs");
  PointSampling sampling;
  sampling.reachable = &reachable;

  // Evaluation points and their ground truth: a different seed from placement's check points.
  const uint64_t evalSeed =
      hashValues(o.evalSeed ? *o.evalSeed : o.common.seed, 0x6576616cULL);  // "eval"
  ProbeBakeSettings bake;
  bake.rays = uint32_t(o.evalRays);
  bake.seed = evalSeed;
  bake.threads = o.common.threads;
  bake.dering = false;  // the truth is not deringed either: compare like with like
  bake.fillInvalid = false;
  Result<TruthPoints> truth = [&] {
    Progress progress("truth", uint32_t(o.points), "points", !o.common.quiet);
    Result<TruthPoints> t = bakeTruthPoints(scene, tracer, volumes, uint32_t(o.points), evalSeed,
                                            settings.validity, bake, &progress, &cancelFlag(),
                                            sampling);
    progress.finish();
    return t;
  }();
  if (cancelFlag().load()) return reportInterrupted("outputs");
  if (!truth) {
    printError(o.common.scene + ": evaluation points: " + truth.error());
    return kExitBadInput;
  }
  const std::vector<vec3>& points = truth->points;
  // Where objects stand (0.3-2 m above walkable surfaces): spheres lit by each method's probes
  // against SH baked at their centres.
  std::optional<TruthPoints> objectTruth;
  if (o.objectPoints > 0) {
    PointSampling objects = sampling;
    objects.objectShare = 1.0f;
    const uint64_t objectSeed = hashValues(evalSeed, 0x6f626aULL);  // "obj"
    ProbeBakeSettings objectBake = bake;
    objectBake.seed = objectSeed;
    Progress progress("object points", uint32_t(o.objectPoints), "points", !o.common.quiet);
    Result<TruthPoints> t =
        bakeTruthPoints(scene, tracer, volumes, uint32_t(o.objectPoints), objectSeed,
                        settings.validity, objectBake, &progress, &cancelFlag(), objects);
    progress.finish();
    if (cancelFlag().load()) return reportInterrupted("outputs");
    if (!t) {
      printError(o.common.scene + ": object points: " + t.error());
      return kExitBadInput;
    }
    objectTruth = std::move(*t);
  }

  // Every method's probes are baked once, with visibility maps as `kiln probes bake` makes
  // them (per-probe maxDistance to the scene's farthest corner), and measured with both blends.
  ProbeBakeSettings probeBake = bake;
  probeBake.seed = o.common.seed;
  probeBake.visibilityResolution = o.common.visibilityResolution > 0
                                       ? o.common.visibilityResolution
                                       : kDefaultVisibilityResolution;
  const PlacementEvaluation evaluation(scene, tracer, *truth, probeBake);
  // The measure's noise: a second bake of the points with another seed against the truth.
  // Probes have the same noise (same rays), so no method can score much below this (a blend
  // of four probes averages theirs down to between 1/sqrt(2) and 1 times it).
  Result<FieldError> noise = [&] {
    Progress progress("noise", points.size(), "points", !o.common.quiet);
    Result<FieldError> n = evaluation.noise(bake, hashValues(evalSeed, 0x6e6f697365ULL),  // "noise"
                                            &progress, &cancelFlag());
    progress.finish();
    return n;
  }();
  if (!noise || cancelFlag().load()) return reportInterrupted("outputs");
  std::vector<float> exactShares;
  if (o.exactSun) {
    exactShares = evaluation.sunShares(&cancelFlag());
    if (cancelFlag().load()) return reportInterrupted("outputs");
    if (exactShares.empty())
      printWarning(o.common.scene + ": --exact-sun: the probes bake no directional light with "
                   "shadows, so there is no sun layer to replace");
  }
  auto evaluate = [&](const std::string& method, const std::vector<vec3>& positions,
                      double seconds) -> std::optional<Row> {
    Result<ProbeSet> set = evaluation.bake(positions, &cancelFlag());
    if (!set) {
      printError(method + ": " + set.error());
      return std::nullopt;
    }
    ProbeSetError e = evaluation.measure(*set);
    Row row;
    if (objectTruth) row.spheres = sphereError(*set, *objectTruth, o.common.threads);
    row.method = method;
    row.count = positions.size();
    row.error = std::move(e.visibility);
    row.plain = std::move(e.plain);
    row.nearWall = e.nearWall;
    row.nearWallPlain = e.nearWallPlain;
    row.crossing = e.crossing;
    row.seconds = seconds;
    if (!exactShares.empty())
      row.exactSun = evaluation.measureWithExactSunShares(*set, exactShares);
    return row;
  };

  std::vector<Row> rows;
  {
    Row r;
    r.method = "noise (rebake)";
    r.error = r.plain = *noise;
    r.nearWall = r.nearWallPlain = evaluation.nearWallMean(noise->perPoint);
    if (!exactShares.empty()) r.exactSun = *noise;
    rows.push_back(std::move(r));
  }
  // A baseline at the same count: placed (timed), baked and measured.
  auto baseline = [&](const std::string& method,
                      const std::function<Result<std::vector<vec3>>()>& place)
      -> std::optional<Row> {
    const auto t0 = std::chrono::steady_clock::now();
    Result<std::vector<vec3>> positions = place();
    if (!positions) {
      printError(o.common.scene + ": " + positions.error());
      return std::nullopt;
    }
    const double seconds =
        std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    return evaluate(method, *positions, seconds);
  };
  std::optional<Row> gridRow = baseline("uniform grid", [&] {
    return uniformGridPositions(scene, tracer, volumes, uint32_t(o.count), settings.validity,
                                o.common.threads);
  });
  if (cancelFlag().load()) return reportInterrupted("outputs");
  if (!gridRow) return kExitBadInput;
  rows.push_back(*gridRow);

  // Godot-style baseline: corners of the finest octree cells that touch a static triangle,
  // the cell size searched for the count.
  OctreePlacementSettings octree;
  octree.volumes = volumes;
  octree.validity = settings.validity;
  octree.threads = o.common.threads;
  std::optional<Row> octreeRow = baseline("octree corners", [&] {
    return octreeCornerPositions(scene, tracer, octree, uint32_t(o.count));
  });
  if (cancelFlag().load()) return reportInterrupted("outputs");
  if (!octreeRow) return kExitBadInput;
  rows.push_back(*octreeRow);

  Result<ProbePlacement> placed = placeProbes(scene, tracer, settings, &cancelFlag());
  if (cancelFlag().load()) return reportInterrupted("outputs");
  if (!placed) {
    printError(o.common.scene + ": " + placed.error());
    return kExitBadInput;
  }
  for (size_t s = 0; s < placed->snapshots.size(); ++s) {
    // A requested count that growth stepped over gives the same best set as the one before
    // it: measured once.
    if (s > 0 && placed->snapshots[s] == placed->snapshots[s - 1]) continue;
    std::optional<Row> r = evaluate("automatic (grown)", placed->snapshots[s], 0.0);
    if (cancelFlag().load()) return reportInterrupted("outputs");
    if (!r) return kExitBadInput;
    rows.push_back(*r);
  }
  std::optional<Row> autoRow = evaluate("automatic", placed->positions(), placed->seconds);
  if (cancelFlag().load()) return reportInterrupted("outputs");
  if (!autoRow) return kExitBadInput;
  rows.push_back(*autoRow);

  std::ostringstream table;
  table << "scene: " << o.common.scene << ", " << points.size()
        << " random valid points, truth and probes baked with " << o.evalRays
        << " rays; automatic placement scored with "
        << (settings.bake.visibilityResolution > 0
                ? "the visibility-weighted blend (" +
                      std::to_string(settings.bake.visibilityResolution) + " x " +
                      std::to_string(settings.bake.visibilityResolution) + " maps)"
                : std::string("the plain blend (--visibility-resolution 0)"))
        << "\n";
  table << std::left << std::setw(27) << "" << std::setw(41) << "  with visibility (runtime default)"
        << std::setw(41) << "  plain blend" << "\n";
  table << std::left << std::setw(20) << "method" << std::right << std::setw(7) << "probes";
  for (int k = 0; k < 2; ++k)
    table << std::setw(10) << "mean" << std::setw(10) << "p95" << std::setw(10) << "max"
          << std::setw(11) << "near-wall";
  table << std::setw(14) << "crossing-tets" << std::setw(10) << "seconds";
  if (objectTruth) table << std::setw(11) << "sphere-med" << std::setw(11) << "sphere-x";
  if (!exactShares.empty()) table << std::setw(11) << "exact-sun";
  table << "\n";
  std::ostringstream csv;
  csv << "scene,method,probes,mean,p95,max,near_wall_mean,plain_mean,plain_p95,plain_max,"
         "plain_near_wall_mean,crossing_cells,inner_cells,seconds,sphere_median,"
         "sphere_worst_ratio,exact_sun_mean\n";
  for (const Row& r : rows) {
    table << std::left << std::setw(20) << r.method << std::right << std::setw(7) << r.count
          << std::fixed << std::setprecision(4);
    for (const auto& [e, near] : {std::pair{&r.error, r.nearWall}, {&r.plain, r.nearWallPlain}})
      table << std::setw(10) << e->mean << std::setw(10) << e->p95 << std::setw(10) << e->max
            << std::setw(11) << near;
    table << std::setw(8) << r.crossing.crossingCells << "/" << std::setw(5) << std::left
          << r.crossing.innerCells << std::right << std::setprecision(1) << std::setw(10)
          << r.seconds;
    // A ratio past a million is a sphere left (all but) black against lit truth, or lit
    // against black truth: its digits say nothing more, so the table prints ">1e6".
    if (r.spheres) {
      table << std::setprecision(4) << std::setw(11) << r.spheres->median << std::setw(11);
      if (r.spheres->worstRatio > 1e6f) table << ">1e6";
      else table << r.spheres->worstRatio;
    }
    if (r.exactSun) table << std::setprecision(4) << std::setw(11) << r.exactSun->mean;
    table << "\n";
    csv << std::filesystem::path(o.common.scene).filename().string() << "," << r.method << ","
        << r.count << "," << r.error.mean << "," << r.error.p95 << "," << r.error.max << ","
        << r.nearWall << "," << r.plain.mean << "," << r.plain.p95 << "," << r.plain.max << ","
        << r.nearWallPlain << "," << r.crossing.crossingCells << "," << r.crossing.innerCells
        << "," << r.seconds << ",";
    if (r.spheres) csv << r.spheres->median << "," << r.spheres->worstRatio;
    else csv << ",";
    csv << ",";
    if (r.exactSun) csv << r.exactSun->mean;
    csv << "\n";
  }
  // The fewest automatic probes that reach the grid's error at its count, per blend (and with
  // exact sun shares, when measured).
  std::vector<std::pair<std::string, std::function<float(const Row&)>>> measures = {
      {"visibility-weighted: ", [](const Row& r) { return r.error.mean; }},
      {"plain: ", [](const Row& r) { return r.plain.mean; }}};
  if (!exactShares.empty())
    measures.push_back({"visibility-weighted, exact sun shares: ",
                        [](const Row& r) { return r.exactSun ? r.exactSun->mean : kInfinity; }});
  for (const auto& [label, mean] : measures) {
    const size_t needed = countToMatch(rows, *gridRow, mean);
    const float gridMean = mean(*gridRow);
    table << label;
    if (needed) {
      table << "automatic placement reaches the grid's mean error (" << std::setprecision(4)
            << gridMean << " at " << gridRow->count << " probes) with " << needed
            << " probes (" << std::setprecision(2) << double(needed) / double(gridRow->count)
            << " of the grid's count)\n";
    } else {
      table << "no automatic probe set reached the grid's mean error (" << std::setprecision(4)
            << gridMean << ")\n";
    }
  }
  std::cout << table.str();
  if (!o.pointsCsv.empty()) {
    std::ostringstream pc;
    pc << "x,y,z,near_wall,truth_rms";
    for (const Row& r : rows) pc << "," << r.method << " " << r.count;
    for (const Row& r : rows) pc << "," << r.method << " " << r.count << " plain";
    for (const Row& r : rows)
      if (r.exactSun) pc << "," << r.method << " " << r.count << " exact sun";
    pc << "\n";
    pc << std::setprecision(6);
    for (size_t i = 0; i < points.size(); ++i) {
      pc << points[i].x << "," << points[i].y << "," << points[i].z << ","
         << int(evaluation.nearWall()[i]) << "," << irradianceRms(truth->sh[i]);
      for (const Row& r : rows) pc << "," << r.error.perPoint[i];
      for (const Row& r : rows) pc << "," << r.plain.perPoint[i];
      for (const Row& r : rows)
        if (r.exactSun) pc << "," << r.exactSun->perPoint[i];
      pc << "\n";
    }
    if (Status s = writeTextFileAtomically(o.pointsCsv, pc.str()); !s) {
      printError(s.error());
      return kExitBadInput;
    }
  }
  if (!o.csv.empty()) {
    if (Status s = writeTextFileAtomically(o.csv, csv.str()); !s) {
      printError(s.error());
      return kExitBadInput;
    }
  }
  return kExitOk;
}

}  // namespace

void registerProbesPlaceCommand(CLI::App& probes) {
  auto place = std::make_shared<PlaceOptions>();
  CLI::App* p = probes.add_subcommand(
      "place", "Place probes automatically (error-driven) and write positions JSON for bake");
  addCommonOptions(p, &place->common);
  addMpiFlag(p, &place->common.mpi);
  p->add_option("--out,-o", place->out,
                "Output JSON {\"positions\": [...], \"probes\": [notes], \"report\": {...}}")
      ->required();
  p->add_option("--budget", place->budget, "Most probes to place")
      ->check(CLI::Range(4, 1 << 20))
      ->capture_default_str();
  p->add_option("--target-error", place->targetError,
                "Stop at this score: mean relative check error + leak estimate (0 = off)")
      ->check(nonNegativeNumberValidator());
  p->add_flag("--no-prune", place->noPrune, "Do not remove probes that add nothing");
  p->callback(commandCallback([place]() { return runPlace(*place); }));

  auto compare = std::make_shared<CompareOptions>();
  CLI::App* c = probes.add_subcommand(
      "compare-placement",
      "Automatic placement against a uniform grid and Godot-style octree corners: "
      "interpolated irradiance error at random valid points, with the visibility-weighted "
      "blend (the runtime's default) and the plain blend of the same probes, at equal counts "
      "and the count automatic needs to match the grid");
  addCommonOptions(c, &compare->common);
  c->add_option("--count", compare->count,
                "Probe count of the grid and the octree corners (and the automatic budget)")
      ->check(CLI::Range(4, 1 << 20))
      ->capture_default_str();
  c->add_option("--points", compare->points, "Random valid evaluation points")
      ->check(CLI::Range(1, 1 << 20))
      ->capture_default_str();
  c->add_option("--eval-rays", compare->evalRays,
                "Rays per probe and per evaluation point (the probes also record visibility "
                "maps, at --visibility-resolution, or at " +
                    std::to_string(kDefaultVisibilityResolution) + " when that is 0)")
      ->check(CLI::Range(1, 1 << 24))
      ->capture_default_str();
  c->add_option("--object-points", compare->objectPoints,
                "Also light spheres at this many points where objects stand (0.3-2 m above "
                "walkable surfaces) with each method's probes, against SH baked at their "
                "centres: median relative error and worst ratio of mean irradiance (0 = off)")
      ->check(CLI::Range(0, 1 << 20))
      ->capture_default_str();
  c->add_flag("--exact-sun", compare->exactSun,
             "Also measure every set with its sun layer's ramps replaced by the exact share of "
             "the light at each point (a bound on what a better layer could give, not a "
             "method; column exact-sun)");
  c->add_option("--eval-seed", compare->evalSeed,
                "Seed of the evaluation points and their truth (default: --seed)");
  c->add_option("--csv", compare->csv,
                "Also write the table as CSV (mean, p95, max, near_wall_mean with visibility; "
                "plain_* without; sphere_* with --object-points, exact_sun_mean with "
                "--exact-sun)");
  c->add_option("--points-csv", compare->pointsCsv,
                "Also write every evaluation point's error per method as CSV (a column per "
                "method with visibility, then one per method with the plain blend, then with "
                "--exact-sun one per method with exact sun shares)");
  c->callback(commandCallback([compare]() { return runCompare(*compare); }));
}

}  // namespace kiln::cli
