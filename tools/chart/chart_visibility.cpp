// chart_visibility.cpp: chart 6, light leaking through walls against the size of the
// per-probe visibility maps (kiln/probe_visibility.h), on two_rooms and two_rooms_thin
// (chart_measure.h, docs/charts.md). Two measures: the issue's leak bound (the light that
// room A's hidden probes put into room B, against 2 x the truth + 1% of the room-A mirror
// point, as tests/probe_scene_test.cpp's ProbeScenesWall checks it) and probe_placement.h's
// field error, as chart 2.
#include <algorithm>
#include <chrono>
#include <memory>

#include "kiln/probe_runtime.h"
#include "kiln/probe_visibility.h"
#include "probes/octree_placement.h"
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

// A two-room scene of docs/scenes.md: room A x in [0, faceA] (the sunlit one), the shared
// wall x in [faceA, faceB] with its doorway at z 2.8..3.8, room B x in [faceB, faceB + 4].
struct WallScene {
  const char* file;
  const char* label;
  float faceA, faceB;
  float mid() const { return 0.5f * (faceA + faceB); }
  Bounds3 rooms() const { return Bounds3{vec3(0.0f), vec3(faceB + 4.0f, 3.0f, 4.0f)}; }
  // Room B within 0.6 m of the wall, z <= 2.3 (0.5 m or more from the doorway): any light
  // from room A's probes that do not see the point is a leak.
  Bounds3 band() const { return Bounds3{vec3(faceB, 0.0f, 0.0f), vec3(faceB + 0.6f, 3.0f, 2.3f)}; }
};

struct ProbeLayout {
  std::string name;
  std::vector<vec3> positions;
  uint32_t rays = 0;  // per probe
};

}  // namespace

Result<ChartTable> probeVisibilityChart(const ChartOptions& o) {
  const std::vector<WallScene> scenes = {{"two_rooms.gltf", "two_rooms", 4.0f, 4.25f},
                                         {"two_rooms_thin.gltf", "two_rooms_thin", 4.0f, 4.05f}};
  const std::vector<int32_t> resolutions =
      o.quick ? std::vector<int32_t>{0, 24, 32} : std::vector<int32_t>{0, 8, 12, 16, 20, 24, 32};
  const uint32_t wallPoints = o.quick ? 100 : 300;
  const uint32_t roomPoints = o.quick ? 100 : 500;
  const uint32_t truthRays = o.quick ? 512 : 2048;
  const uint32_t probeRays = o.quick ? 2048 : 16384;  // 16384: the CLI bake's default
  // The octree corners again with the rays of placement's bakes and the wall tests
  // (tests/probe_scene_test.cpp): fewer rays per texel reach past a silhouette.
  constexpr uint32_t fewRays = 1024;
  const uint32_t gridCount = 64;
  const int octreeLevel = 3;  // 1.03 m cells over two_rooms (Godot's subdiv 8)
  const ProbeValiditySettings validity;

  ChartTable t;
  t.name = "probe_visibility";
  t.title = "Probe visibility: light through the wall vs map size (two_rooms, two_rooms_thin)";
  t.width = 1100;
  t.height = 500;
  t.columns = {"scene",
               "probe_set",
               "probes",
               "probe_rays",
               "resolution",
               "visibility_bytes_per_probe",
               "file_bytes_per_probe",
               "near_wall_points",
               "near_wall_over_bound",
               "near_wall_worst_leak_ratio",
               "near_wall_mean_error",
               "near_wall_p95_error",
               "overall_mean_error",
               "overall_p95_error",
               "bake_seconds"};
  Progress progress("chart visibility", scenes.size() * (1 + 3 * resolutions.size()), "steps",
                    o.progress);
  std::vector<std::string> layoutNotes;
  uint64_t sceneKey = 0;
  for (const WallScene& w : scenes) {
    ++sceneKey;
    const std::string path = o.scenesDir + "/" + w.file;
    Result<Scene> loaded = loadScene(path);
    if (!loaded) return Error{loaded.error()};
    const Scene& scene = *loaded;
    Result<std::unique_ptr<Tracer>> tracerResult = Tracer::create(scene);
    if (!tracerResult) return Error{path + ": " + tracerResult.error()};
    const Tracer& tracer = **tracerResult;
    const std::vector<Bounds3> rooms{w.rooms()};

    // Probe sets whose cells span the wall: the scene's probe groups (3 x 2 x 3 per room,
    // what `kiln probes bake` bakes), a uniform grid over both rooms, and Godot-style octree
    // corners (probes on every surface, next to the wall: the silhouette case, where one
    // texel holds the wall's edge and what lies beyond it).
    std::vector<ProbeLayout> layouts;
    layouts.push_back({"scene probes", sceneProbePositions(scene), probeRays});
    if (layouts[0].positions.empty()) return Error{path + ": no probe groups"};
    {
      Result<std::vector<vec3>> grid =
          uniformGridPositions(scene, tracer, rooms, gridCount, validity, o.threads);
      if (!grid)
        return Error{path + ": uniform grid of " + std::to_string(gridCount) + ": " + grid.error()};
      layouts.push_back({"uniform grid", std::move(grid).value(), probeRays});
    }
    {
      OctreePlacementSettings s;
      s.volumes = rooms;
      s.level = octreeLevel;
      s.threads = o.threads;
      Result<OctreePlacement> octree = octreeCornerPlacement(scene, tracer, s);
      if (!octree) return Error{path + ": octree corners: " + octree.error()};
      layouts.push_back({"octree corners", octree->positions, probeRays});
      layouts.push_back({"octree corners at " + std::to_string(fewRays) + " rays",
                         std::move(octree->positions), fewRays});
    }
    layoutNotes.push_back(std::string(w.label) + ": " +
                          std::to_string(layouts[0].positions.size()) + " scene probes, " +
                          std::to_string(layouts[1].positions.size()) + " grid, " +
                          std::to_string(layouts[2].positions.size()) + " octree corners");

    // Evaluation points and their truth, SH baked at each point (no deringing, as the probes):
    // near-wall points whose mirror through the wall's mid-plane (in room A, in front of the
    // sun patch) is valid too, and points over both rooms.
    std::vector<vec3> wall, mirrors;
    for (const vec3& p :
         randomValidPoints(scene, tracer, std::vector<Bounds3>{w.band()}, wallPoints,
                           hashValues(o.seed, kWallTag, sceneKey), validity, o.threads)) {
      const vec3 m(2.0f * w.mid() - p.x, p.y, p.z);
      if (!isValidProbePoint(scene, tracer, m, validity)) continue;
      wall.push_back(p);
      mirrors.push_back(m);
    }
    const std::vector<vec3> room =
        randomValidPoints(scene, tracer, rooms, roomPoints, hashValues(o.seed, kRoomsTag, sceneKey),
                          validity, o.threads);
    if (wall.empty() || room.empty()) return Error{path + ": no valid evaluation points"};
    ProbeBakeSettings truthBake;
    truthBake.rays = truthRays;
    truthBake.seed = hashValues(o.seed, kWallTag, kRoomsTag);
    truthBake.threads = o.threads;
    truthBake.dering = false;
    truthBake.fillInvalid = false;
    truthBake.visibilityResolution = 0;
    std::vector<vec3> all = wall;
    all.insert(all.end(), mirrors.begin(), mirrors.end());
    all.insert(all.end(), room.begin(), room.end());
    const std::vector<ShL2Rgb> truth =
        bakePointSh(scene, tracer, all, truthBake, nullptr, o.cancel);
    if (truth.empty() || (o.cancel && o.cancel->load())) return Error{"cancelled"};
    const std::span<const ShL2Rgb> wallTruth(truth.data(), wall.size());
    const std::span<const ShL2Rgb> mirrorTruth(truth.data() + wall.size(), wall.size());
    const std::span<const ShL2Rgb> roomTruth(truth.data() + 2 * wall.size(), room.size());
    // The issue's bound per near-wall point: 2 x its truth + 1% of its mirror's (lux).
    std::vector<float> bound(wall.size());
    for (size_t i = 0; i < wall.size(); ++i)
      bound[i] = 2.0f * maxAxisIrradiance(wallTruth[i]) + 0.01f * maxAxisIrradiance(mirrorTruth[i]);
    progress.advance();
    // One floor for the field error, from the rooms' points (5% of the scene's typical light):
    // near the wall room B is so dark that a floor of its own would turn its noise into error.
    double meanRms = 0.0;
    for (const ShL2Rgb& sh : roomTruth) meanRms += irradianceRms(sh);
    const float floor = float(kErrorFloorFraction * meanRms / double(room.size()));

    for (const ProbeLayout& layout : layouts) {
      for (int32_t r : resolutions) {
        if (o.cancel && o.cancel->load()) return Error{"cancelled"};
        ProbeBakeSettings bake;
        bake.rays = layout.rays;
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
        size_t over = 0;
        float worst = 0.0f;
        for (size_t i = 0; i < wall.size(); ++i) {
          const ProbeLocation loc = locateProbe(*set, wall[i]);
          const float ratio =
              maxAxisIrradiance(lightThroughWall(tracer, *set, wall[i], loc, w.mid())) /
              bound[i];
          over += ratio > 1.0f ? 1 : 0;
          worst = std::max(worst, ratio);
        }
        const double probes = double(set->probeCount());
        t.addRow({w.label, layout.name, std::to_string(set->probeCount()),
                  std::to_string(layout.rays), std::to_string(r),
                  std::to_string(visibilityBytesPerProbe(r)),
                  num(double(serializeProbeSet(*set).size()) / probes), std::to_string(wall.size()),
                  std::to_string(over), num(worst), num(near.mean), num(near.p95),
                  num(overall.mean), num(overall.p95), num(seconds)});
      }
    }
  }
  progress.finish();

  t.notes = commonNotes(o, o.threads);
  t.notes.push_back("chart 6: light leaking through a wall vs the visibility map's resolution");
  std::string sets;
  for (const std::string& n : layoutNotes) sets += (sets.empty() ? "" : "; ") + n;
  t.notes.push_back(
      "scenes: two_rooms.gltf (0.25 m shared wall x 4-4.25) and two_rooms_thin.gltf (5 cm wall "
      "x 4-4.05) in " +
      o.scenesDir + "; probe sets per scene: its probe groups, uniformGridPositions (" +
      std::to_string(gridCount) + ") and octreeCornerPlacement level " +
      std::to_string(octreeLevel) + " over both rooms (" + sets +
      "); each baked with bakeProbes at visibility resolution " + list(resolutions) +
      " (0 = none: plain barycentric blending), " + std::to_string(probeRays) +
      " rays per probe (probe_rays), the octree corners also with " + std::to_string(fewRays) +
      " (placement's bakes and the wall tests'), no deringing, seed as above (the SH are the "
      "same at every resolution)");
  t.notes.push_back(
      "near wall: random valid points in room B within 0.6 m of the shared wall, z <= 2.3 "
      "(0.5 m or more from the doorway), kept when their mirror through the wall's mid-plane "
      "(room A, in front of the sun patch) is valid; " +
      std::to_string(wallPoints) +
      " drawn, near_wall_points kept; truth = SH baked at the "
      "points and mirrors (" +
      std::to_string(truthRays) + " rays, no deringing)");
  t.notes.push_back(
      "leak: light through the wall = maximum axis irradiance (luminance, lux) of the part of "
      "the runtime's blend (locateProbe) that comes from probes on room A's side of the "
      "mid-plane that do not see the point; bound = 2 x the point's truth + 1% of its "
      "mirror's (the issue's, as tests/probe_scene_test.cpp ProbeScenesWall); "
      "near_wall_over_bound = points whose leak exceeds it, near_wall_worst_leak_ratio = the "
      "largest leak / bound");
  t.notes.push_back(
      "error: probe_placement.h relativeIrradianceError of the whole blend against the truth, "
      "floor 5% of the mean true RMS over the rooms' points; overall = " +
      std::to_string(roomPoints) + " random valid points over both rooms");
  t.notes.push_back(
      "bytes: visibility_bytes_per_probe = 4 (maxDistance) + R^2 x 3 x 2 (unorm16 mu, sigma, "
      "far); file_bytes_per_probe = serializeProbeSet size / probes (SH, cells, seed grid and "
      "visibility)");
  t.notes.push_back(
      "baseline: resolution 0 (no visibility: the plain tetrahedral blend of Cupisz 2012, which "
      "leaks)");

  // Resolution 0 (no maps, 0 bytes) is drawn at x = 128, labelled "none"; each tic gives the
  // bytes and the map side. Left: the worst leak against the bound (1 = the bound, dotted;
  // ratios below 1e-9, down to 0, are drawn at the bottom edge). Right: the field error over
  // both rooms. Colour: the probe set; solid: two_rooms, dashed: two_rooms_thin.
  std::string tics = "\"none\" 128";
  for (int32_t r : resolutions)
    if (r > 0)
      tics += ", \"" + std::to_string(visibilityBytesPerProbe(r)) + "\\nR " + std::to_string(r) +
              "\" " + std::to_string(visibilityBytesPerProbe(r));
  struct Series {
    const char* scene;
    const char* set;
    const char* colour;
    const char* point;
  };
  const Series series[] = {{"two_rooms", "scene probes", "#9400d3", "7"},
                           {"two_rooms", "uniform grid", "#009e73", "5"},
                           {"two_rooms", "octree corners", "#0072b2", "9"},
                           {"two_rooms", "octree corners at 1024 rays", "#e69f00", "11"},
                           {"two_rooms_thin", "scene probes", "#9400d3", "6"},
                           {"two_rooms_thin", "uniform grid", "#009e73", "4"},
                           {"two_rooms_thin", "octree corners", "#0072b2", "8"},
                           {"two_rooms_thin", "octree corners at 1024 rays", "#e69f00", "10"}};
  static_assert(fewRays == 1024, "the series names above spell it");
  auto plotLines = [&](const std::string& y) {
    std::string s;
    for (size_t k = 0; k < std::size(series); ++k) {
      const Series& c = series[k];
      s += std::string(k ? ", \\\n  ''" : "plot @CSV@") + " using (strcol('scene') eq '" + c.scene +
           "' && strcol('probe_set') eq '" + c.set +
           "' ? x(column('resolution'), column('visibility_bytes_per_probe')) : NaN):(" + y +
           ") with linespoints lw 2 pt " + c.point + " lc rgb '" + c.colour + "'" +
           (std::string(c.scene) == "two_rooms" ? "" : " dt 2") + " title '" + c.scene + ", " +
           c.set + "'";
    }
    return s;
  };
  t.plot =
      "max(a, b) = a > b ? a : b\n"
      "x(r, b) = r > 0 ? b : 128\n"
      "set multiplot layout 1,2 title '" +
      t.title +
      "' noenhanced\n"
      "unset title\n"
      "set logscale x 2\n"
      "set logscale y\n"
      "set xrange [100:8000]\n"
      "set xtics (" +
      tics +
      ")\n"
      "set xlabel 'visibility bytes per probe (4 + 6 R^2; R x R map)' offset 0,-1\n"
      "set bmargin 5\n"
      "set ylabel 'worst near-wall light through the wall / bound (2 truth + 1% mirror)'\n"
      "set yrange [1e-9:1e4]\n"
      "set format y '10^{%T}'\n"
      "set arrow 1 from graph 0, first 1 to graph 1, first 1 nohead dt 3 lw 2 lc 'red'\n"
      "set key bottom left font ',8'\n" +
      plotLines("max(column('near_wall_worst_leak_ratio'), 1e-9)") +
      "\n"
      "unset arrow 1\n"
      "set ylabel 'mean relative irradiance error, both rooms'\n"
      "set yrange [0.1:10]\n"
      "set format y '%g'\n"
      "set key top right font ',8'\n" +
      plotLines("column('overall_mean_error')") +
      "\n"
      "unset multiplot\n";
  return t;
}

}  // namespace kiln::chart
