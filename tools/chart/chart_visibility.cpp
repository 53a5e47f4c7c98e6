// chart_visibility.cpp: chart 6, light leaking through walls against the size of the
// per-probe visibility maps (kiln/probe_visibility.h), on two_rooms (chart_measure.h,
// docs/charts.md). The error measure is probe_placement.h's, as chart 2.
#include <chrono>
#include <memory>

#include "kiln/probe_visibility.h"
#include "probes/probe_baker.h"
#include "probes/probe_placement.h"
#include "src/gltf_loader.h"
#include "src/progress.h"
#include "src/sampling.h"
#include "tools/chart/chart_measure.h"

namespace kiln::chart {
namespace {

constexpr uint64_t kWallTag = 0x77616c6cULL;   // "wall"
constexpr uint64_t kRoomsTag = 0x726f6f6dULL;  // "room"

double secondsSince(std::chrono::steady_clock::time_point t0) {
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
}

std::string list(const std::vector<int32_t>& v) {
  std::string s;
  for (int32_t x : v) s += (s.empty() ? "" : ", ") + std::to_string(x);
  return s;
}

}  // namespace

Result<ChartTable> probeVisibilityChart(const ChartOptions& o) {
  const std::string path = o.scenesDir + "/two_rooms.gltf";
  Result<Scene> loaded = loadScene(path);
  if (!loaded) return Error{loaded.error()};
  const Scene& scene = *loaded;
  Result<std::unique_ptr<Tracer>> tracerResult = Tracer::create(scene);
  if (!tracerResult) return Error{path + ": " + tracerResult.error()};
  const Tracer& tracer = **tracerResult;

  // two_rooms: room A (x 0-4, the sunlit one) and room B (x 4.25-8.25) share the wall
  // x 4-4.25, whose doorway spans z 2.8-3.8. "Near the wall": room B within 0.6 m of it,
  // 0.4 m or more from the doorway, where light blended from room A's probes is a leak.
  const Bounds3 rooms{vec3(0.0f), vec3(8.25f, 3.0f, 4.0f)};
  const Bounds3 nearWall{vec3(4.25f, 0.0f, 0.0f), vec3(4.85f, 3.0f, 2.4f)};
  const std::vector<int32_t> resolutions =
      o.quick ? std::vector<int32_t>{0, 8, 16}
              : std::vector<int32_t>{0, 4, 6, 8, 10, 12, 16, 24, 32};
  const uint32_t wallPoints = o.quick ? 100 : 300;
  const uint32_t roomPoints = o.quick ? 100 : 500;
  const uint32_t truthRays = o.quick ? 512 : 2048;
  const uint32_t probeRays = o.quick ? 2048 : 16384;  // 16384: the CLI bake's default
  const uint32_t gridCount = o.quick ? 32 : 64;
  const ProbeValiditySettings validity;

  // Two probe sets whose cells span the wall: the scene's probe groups (3 x 2 x 3 per room,
  // what `kiln probes bake two_rooms.gltf` bakes) and a coarse uniform grid over both rooms.
  struct ProbeLayout {
    std::string name;
    std::vector<vec3> positions;
  };
  std::vector<ProbeLayout> layouts;
  layouts.push_back({"scene probes", sceneProbePositions(scene)});
  if (layouts[0].positions.empty()) return Error{path + ": no probe groups"};
  {
    Result<std::vector<vec3>> grid = uniformGridPositions(
        scene, tracer, std::vector<Bounds3>{rooms}, gridCount, validity, o.threads);
    if (!grid)
      return Error{path + ": uniform grid of " + std::to_string(gridCount) + ": " + grid.error()};
    layouts.push_back({"uniform grid", std::move(grid).value()});
  }

  Progress progress("chart visibility", 1 + layouts.size() * resolutions.size(), "steps",
                    o.progress);
  // Evaluation points and their truth, SH baked at each point (no deringing, as the probes).
  const std::vector<vec3> wall =
      randomValidPoints(scene, tracer, std::vector<Bounds3>{nearWall}, wallPoints,
                        hashValues(o.seed, kWallTag), validity, o.threads);
  const std::vector<vec3> room =
      randomValidPoints(scene, tracer, std::vector<Bounds3>{rooms}, roomPoints,
                        hashValues(o.seed, kRoomsTag), validity, o.threads);
  if (wall.empty() || room.empty()) return Error{path + ": no valid evaluation points"};
  ProbeBakeSettings truthBake;
  truthBake.rays = truthRays;
  truthBake.seed = hashValues(o.seed, kWallTag, kRoomsTag);
  truthBake.threads = o.threads;
  truthBake.dering = false;
  truthBake.fillInvalid = false;
  truthBake.visibilityResolution = 0;
  std::vector<vec3> all = wall;
  all.insert(all.end(), room.begin(), room.end());
  const std::vector<ShL2Rgb> truth = bakePointSh(scene, tracer, all, truthBake, nullptr, o.cancel);
  if (truth.empty() || (o.cancel && o.cancel->load())) return Error{"cancelled"};
  const std::span<const ShL2Rgb> wallTruth(truth.data(), wall.size());
  const std::span<const ShL2Rgb> roomTruth(truth.data() + wall.size(), room.size());
  progress.advance();
  // One floor for both sets, from the rooms' points (5% of the scene's typical light): near
  // the wall room B is so dark that a floor of its own would turn its noise into error.
  double meanRms = 0.0;
  for (const ShL2Rgb& sh : roomTruth) meanRms += irradianceRms(sh);
  const float floor = float(kErrorFloorFraction * meanRms / double(room.size()));

  ChartTable t;
  t.name = "probe_visibility";
  t.title = "Probe visibility: leak error vs map size (two_rooms)";
  t.columns = {"probe_set",
               "probes",
               "resolution",
               "visibility_bytes_per_probe",
               "file_bytes_per_probe",
               "near_wall_mean_error",
               "near_wall_p95_error",
               "near_wall_leaking",
               "overall_mean_error",
               "overall_p95_error",
               "bake_seconds"};
  for (const ProbeLayout& layout : layouts) {
    for (int32_t r : resolutions) {
      if (o.cancel && o.cancel->load()) return Error{"cancelled"};
      ProbeBakeSettings bake;
      bake.rays = probeRays;
      bake.seed = o.seed;
      bake.threads = o.threads;
      bake.dering = false;  // compare like with like (the truth is not deringed)
      bake.visibilityResolution = r;
      const auto t0 = std::chrono::steady_clock::now();
      Result<ProbeSet> set = bakeProbes(scene, tracer, layout.positions, bake, nullptr, o.cancel);
      const double seconds = secondsSince(t0);
      progress.advance();
      if (!set)
        return Error{path + ": " + layout.name + ", resolution " + std::to_string(r) + ": " +
                     set.error()};
      const FieldError near = measureFieldError(*set, wall, wallTruth, floor, o.threads);
      const FieldError overall = measureFieldError(*set, room, roomTruth, floor, o.threads);
      // Points whose error exceeds the floor-relative 1: light off by more than 5% of the
      // scene's typical irradiance, in a room that has ~1/1000 of it.
      size_t leaking = 0;
      for (float e : near.perPoint) leaking += e > 1.0f ? 1 : 0;
      const double probes = double(set->probeCount());
      const size_t visibilityBytes =
          r > 0 ? sizeof(float) + 2 * sizeof(uint16_t) * size_t(r) * size_t(r) : 0;
      t.addRow({layout.name, std::to_string(set->probeCount()), std::to_string(r),
                std::to_string(visibilityBytes),
                num(double(serializeProbeSet(*set).size()) / probes), num(near.mean), num(near.p95),
                std::to_string(leaking), num(overall.mean), num(overall.p95), num(seconds)});
    }
  }
  progress.finish();

  t.notes = commonNotes(o, o.threads);
  t.notes.push_back("chart 6: light leaking through a wall vs the visibility map's resolution");
  t.notes.push_back(
      "scene: " + path + "; probe sets: the scene's probe groups (" +
      std::to_string(layouts[0].positions.size()) +
      " probes) and uniformGridPositions over "
      "0,0,0,8.25,3,4 (" +
      std::to_string(layouts[1].positions.size()) +
      " probes); each baked with bakeProbes at visibility resolution " + list(resolutions) +
      " (0 = none: plain barycentric blending), " + std::to_string(probeRays) +
      " rays per probe, no deringing, seed as above (the SH are the same at every resolution)");
  t.notes.push_back(
      "error: probe_placement.h relativeIrradianceError of the runtime's blend (locateProbe, "
      "visibility-weighted when the set has maps) against SH baked at each point (" +
      std::to_string(truthRays) +
      " rays, no deringing), floor 5% of the mean true RMS over the rooms' points; near wall = " +
      std::to_string(wall.size()) +
      " random valid points in room B within 0.6 m of the wall it shares with sunlit room A, "
      "0.4 m or more from the doorway (box 4.25,0,0,4.85,3,2.4); overall = " +
      std::to_string(room.size()) +
      " random valid points over both rooms; near_wall_leaking = near-wall points with error "
      "> 1 (off by more than the floor)");
  t.notes.push_back(
      "bytes: visibility_bytes_per_probe = 4 (maxDistance) + R^2 x 2 x 2 "
      "(unorm16 moments); file_bytes_per_probe = serializeProbeSet size / probes "
      "(SH, cells, seed grid and visibility)");
  t.notes.push_back(
      "baseline: resolution 0 (no visibility: the plain tetrahedral blend of "
      "Cupisz 2012, which leaks)");

  // Resolution 0 (no maps, 0 bytes) is drawn at x = 16, labelled "none"; the map sides are
  // written along the bottom.
  std::string tics = "'none' 16";
  for (int32_t r : resolutions)
    if (r > 0) tics += ", '" + std::to_string(4 + 4 * r * r) + "' " + std::to_string(4 + 4 * r * r);
  t.plot =
      "set logscale x 2\n"
      "set logscale y\n"
      "set xlabel 'visibility bytes per probe (4 + 4 R^2; R x R map, R written above the axis)'\n"
      "set ylabel 'mean relative irradiance error'\n"
      "set key top right\n"
      "set xrange [12:6000]\n"
      "set yrange [0.05:200]\n"
      "set xtics (" +
      tics +
      ")\n"
      "x(r, b) = r > 0 ? b : 16\n"
      "plot @CSV@ using (strcol('probe_set') eq 'scene probes' ? "
      "x(column('resolution'), column('visibility_bytes_per_probe')) : NaN):"
      "'near_wall_mean_error' with linespoints lw 2 pt 7 title 'near wall, scene probes', \\\n"
      "  '' using (strcol('probe_set') eq 'uniform grid' ? "
      "x(column('resolution'), column('visibility_bytes_per_probe')) : NaN):"
      "'near_wall_mean_error' with linespoints lw 2 pt 5 title 'near wall, uniform grid', \\\n"
      "  '' using (strcol('probe_set') eq 'scene probes' ? "
      "x(column('resolution'), column('visibility_bytes_per_probe')) : NaN):"
      "'overall_mean_error' with linespoints lw 2 dt 2 pt 6 title 'overall, scene probes', \\\n"
      "  '' using (strcol('probe_set') eq 'uniform grid' ? "
      "x(column('resolution'), column('visibility_bytes_per_probe')) : NaN):"
      "'overall_mean_error' with linespoints lw 2 dt 2 pt 4 title 'overall, uniform grid', \\\n"
      "  '' using (strcol('probe_set') eq 'scene probes' ? "
      "x(column('resolution'), column('visibility_bytes_per_probe')) : NaN):(0.07):"
      "(column('resolution') > 0 ? sprintf('R=%d', column('resolution')) : 'plain') with labels "
      "notitle\n";
  return t;
}

}  // namespace kiln::chart
