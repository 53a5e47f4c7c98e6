// probes_command.cpp: `kiln probes bake | query | export`, the light-probe SH bake and the
// tools to look inside a .kprobe file. Thin over probes/probe_baker.h (bake) and kiln_runtime
// (query, export). Usage and formats: docs/probes.md.
#include <algorithm>
#include <charconv>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <iostream>
#include <memory>
#include <nlohmann/json.hpp>
#include <span>
#include <sstream>

#include "kiln/probe_runtime.h"
#include "kiln/probe_set.h"
#include "probes/probe_baker.h"
#include "src/distributed.h"
#include "src/progress.h"
#include "src/sh_projection.h"
#include "src/text_file.h"
#include "src/tracer.h"
#include "tools/kiln/cli_common.h"

namespace kiln::cli {
namespace {

using Json = nlohmann::json;

// A float as the double with the shortest decimal form that reads back as the same float, so
// JSON shows 0.3 rather than 0.30000001192092896.
double shortest(float v) {
  if (!std::isfinite(v)) return double(v);
  char buf[32];
  const auto r = std::to_chars(buf, buf + sizeof buf, v);
  return std::strtod(std::string(buf, r.ptr).c_str(), nullptr);
}

Json vecJson(glm::vec3 v) { return Json::array({shortest(v.x), shortest(v.y), shortest(v.z)}); }

Json vec4Json(glm::vec4 v) {
  return Json::array({shortest(v.x), shortest(v.y), shortest(v.z), shortest(v.w)});
}

Json shJson(const ShL2Rgb& sh) {
  Json j = Json::array();
  for (const glm::vec3& c : sh.c) j.push_back(vecJson(c));
  return j;
}

// ---- bake ----------------------------------------------------------------------------------

struct BakeOptions {
  std::string scene;
  int gltfScene = -1;  // --scene
  std::string positions;
  std::string out;
  int rays = 16384;
  uint64_t seed = 0;
  std::string backend = "cgal";
  int bounces = -1;          // -1 = the scene's extras.kiln.bounces, else kDefaultProbeBounces
  std::string lightingMode;  // empty = the scene's extras.kiln.lightingMode, else baked-indirect
  int threads = 0;
  bool noDering = false;
  bool noSceneProbes = false;
  int visibilityResolution = kDefaultVisibilityResolution;  // 0 = none
  float visibilityMaxDistance = 0.0f;                       // 0 = per probe (auto)
  float footprint = ProbeBakeSettings{}.footprint;          // 0 = a point bake
  float footprintMaxRadius = ProbeBakeSettings{}.footprintMaxRadius;
  bool footprintEverywhere = ProbeBakeSettings{}.footprintEverywhere;
  bool noSunShadows = false;
  bool quiet = false;
  bool mpi = false;
  SkyOptions sky;
};

int runBake(const BakeOptions& options) {
  // A distributed bake (docs/distributed.md): probes split across ranks, rank 0 writes.
  if (int code = startDistributedBake(options.mpi)) return code;
  BakeOptions o = options;
  o.quiet = o.quiet || !distributedRoot();
  // Before any work: a bad --out or sky fails now, not after the bake.
  if (distributedRoot())
    if (int code = checkOutputFile("--out", o.out)) return code;
  std::optional<Sky> sky;
  if (int code = resolveSky(o.sky, &sky)) return code;
  Scene scene;
  if (int code = loadSceneForBake(o.scene, o.gltfScene, o.quiet, sky, &scene)) return code;

  std::vector<vec3> positions;
  if (!o.positions.empty()) {
    Result<std::vector<vec3>> loaded = loadProbePositions(o.positions);
    if (!loaded) {
      printError(loaded.error());
      return kExitBadInput;
    }
    positions = std::move(loaded).value();
  }
  const size_t fromFile = positions.size();
  if (!o.noSceneProbes) {
    const std::vector<vec3> groups = sceneProbePositions(scene);
    positions.insert(positions.end(), groups.begin(), groups.end());
  }
  if (positions.empty()) {
    printError(scene.path +
               ": no probe positions (the scene has no probe groups, extras.kiln.probes; "
               "give --positions FILE)");
    return kExitBadInput;
  }

  Result<std::unique_ptr<Tracer>> tracer = Tracer::create(scene);
  if (!tracer) {
    printError(scene.path + ": " + tracer.error());
    return kExitBadInput;
  }
  if (cancelFlag().load()) return reportInterrupted(o.out);

  ProbeBakeSettings settings;
  settings.rays = uint32_t(o.rays);
  settings.seed = o.seed;
  settings.topology.backend = o.backend == "cgal" ? DelaunayBackend::Cgal : DelaunayBackend::TetGen;
  if (o.bounces >= 0) settings.bounces = o.bounces;
  settings.threads = o.threads;
  settings.dering = !o.noDering;
  settings.visibilityResolution = o.visibilityResolution;
  settings.visibilityMaxDistance = o.visibilityMaxDistance;
  settings.footprint = o.footprint;
  settings.footprintMaxRadius = o.footprintMaxRadius;
  settings.footprintEverywhere = o.footprintEverywhere;
  settings.sunShadows = !o.noSunShadows;
  if (!o.lightingMode.empty()) {
    Result<LightingMode> mode = parseLightingMode(o.lightingMode);
    if (!mode) {
      printError(mode.error());
      return kExitBadUsage;
    }
    settings.lightingMode = *mode;
  }

  if (!o.quiet) {
    std::cerr << "kiln: baking " << positions.size() << " probes (" << fromFile
              << " from the positions file, " << positions.size() - fromFile
              << " from the scene's probe groups), " << o.rays << " rays each\n";
  }
  Progress progress("probes", positions.size(), "probes", !o.quiet);
  ProbeBakeReport report;
  const auto start = std::chrono::steady_clock::now();
  Result<ProbeSet> set =
      bakeProbes(scene, **tracer, positions, settings, &progress, &cancelFlag(), &report);
  if (cancelFlag().load()) return reportInterrupted(o.out);
  if (!set) {
    printError(scene.path + ": " + set.error());
    return kExitBadInput;
  }
  if (!distributedRoot()) return kExitOk;  // rank 0 writes
  for (const std::string& w : report.warnings) printWarning(w);
  if (Status s = writeProbeFile(*set, o.out); !s) {
    printError(s.error());
    return kExitBadInput;
  }
  if (!o.quiet) {
    const double seconds =
        std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
    std::cerr << "kiln: wrote " << o.out << ": " << set->probeCount() << " probes, "
              << set->cellCount() << " cells (dimension " << set->dimension << "), "
              << report.invalidProbes.size() << " invalid, " << report.deringedProbes
              << " deringed, " << report.footprintProbes << " over a footprint, "
              << report.integrator.maxBounces << " bounces, " << report.rays
              << " rays in " << seconds << " s\n";
    std::cerr << "kiln: lighting mode " << lightingModeName(report.lightModes.mode);
    for (int c = 0; c < kProbeOcclusionChannels; ++c) {
      const int32_t l = set->occlusionLights[size_t(c)];
      if (l >= 0) {
        std::cerr << ", occlusion channel " << c << " = light '" << scene.lights[l].name << "'";
      }
    }
    std::cerr << "\n";
    if (set->sun.empty()) {
      std::cerr << "kiln: sun layer none ("
                << (o.noSunShadows ? "--no-sun-shadows" : "no baked directional light") << ")\n";
    } else {
      std::cerr << "kiln: sun layer: light '" << scene.lights[size_t(set->sun.light)].name
                << "', a shadow ramp in " << report.sunRampCells << " of " << set->innerCellCount
                << " cells\n";
    }
    const ProbeVisibility& vis = set->visibility;
    if (vis.empty()) {
      std::cerr << "kiln: visibility none (plain barycentric blending)\n";
    } else {
      float lo = kInfinity, hi = 0.0f;
      for (float d : vis.maxDistance) lo = std::min(lo, d), hi = std::max(hi, d);
      std::cerr << "kiln: visibility " << vis.resolution << " x " << vis.resolution
                << " depth map per probe ({mu, sigma, far} per texel), "
                << visibilityBytesPerProbe(vis.resolution) << " bytes per probe, max distance "
                << lo << " to " << hi << " m"
                << (o.visibilityMaxDistance > 0.0f
                        ? " (--visibility-max-distance)"
                        : " (to the farthest corner of the scene and probes)")
                << "\n";
    }
  }
  return kExitOk;
}

// ---- query ---------------------------------------------------------------------------------

struct QueryOptions {
  std::string file;
  std::vector<double> coords;  // x y z [nx ny nz]
  std::string blend = "visibility";
  bool json = false;
};

int runQuery(const QueryOptions& o) {
  if (o.coords.size() != 3 && o.coords.size() != 6) {
    printError("probes query: expected X Y Z or X Y Z NX NY NZ (" +
               std::to_string(o.coords.size()) + " numbers given)");
    return kExitBadUsage;
  }
  const glm::vec3 p(o.coords[0], o.coords[1], o.coords[2]);
  glm::vec3 n(0.0f, 1.0f, 0.0f);  // up (glTF +Y) when no normal is given
  if (o.coords.size() == 6) n = glm::vec3(o.coords[3], o.coords[4], o.coords[5]);
  const float len = glm::length(n);
  if (!std::isfinite(p.x + p.y + p.z) || !(len > 0.0f) || !std::isfinite(len)) {
    printError("probes query: the point must be finite and the normal finite and non-zero");
    return kExitBadUsage;
  }
  n /= len;
  Result<ProbeSet> set = loadProbeFile(o.file);
  if (!set) {
    printError(set.error());
    return kExitBadInput;
  }
  // The point is blended as an object's centre (no surface normal, so no normal bias): the
  // query's normal only chooses the direction the irradiance is evaluated for.
  ProbeBlendSettings blend;
  blend.visibility = o.blend == "visibility";
  const ProbeLocation loc = locateProbe(*set, p, -1, blend);
  // What the weights are: visibility-weighted only when asked for and the file has the maps.
  const bool visibilityUsed = blend.visibility && !set->visibility.empty();
  const std::string blendName = visibilityUsed ? "visibility" : "plain";
  const ShL2Rgb sh = interpolateProbes(*set, loc);
  const glm::vec3 e = probeIrradiance(sh, n);
  const glm::vec4 occlusion = interpolateOcclusion(*set, loc);
  const bool outer = loc.cell >= 0 && set->isOuter(loc.cell);
  if (o.json) {
    Json j;
    j["point"] = vecJson(p);
    j["normal"] = vecJson(n);
    j["tet"] = loc.cell;
    j["outer"] = outer;
    j["probes"] = loc.probes;
    j["weights"] = Json::array();
    for (float w : loc.weights) j["weights"].push_back(shortest(w));
    j["barycentric"] = Json::array();
    for (float w : loc.barycentric) j["barycentric"].push_back(shortest(w));
    j["blend"] = blendName;
    j["sh"] = shJson(sh);
    j["irradiance"] = vecJson(e);
    j["occlusion"] = vec4Json(occlusion);
    j["occlusionLights"] = set->occlusionLights;
    std::cout << j.dump(2) << "\n";
    return kExitOk;
  }
  std::printf("point (%g, %g, %g)\n", p.x, p.y, p.z);
  std::printf("tet %d (%s)\n", loc.cell, outer ? "outer cell, extrapolated" : "inside the hull");
  std::printf("probes %d %d %d %d\n", loc.probes[0], loc.probes[1], loc.probes[2], loc.probes[3]);
  std::printf("barycentric %.6g %.6g %.6g %.6g\n", loc.barycentric[0], loc.barycentric[1],
              loc.barycentric[2], loc.barycentric[3]);
  std::printf("weights %.6g %.6g %.6g %.6g (blend %s%s)\n", loc.weights[0], loc.weights[1],
              loc.weights[2], loc.weights[3], blendName.c_str(),
              visibilityUsed            ? ""
              : set->visibility.empty() ? ": the file has no visibility"
                                        : ": --blend plain");
  std::printf("sh (radiance, W/(m^2 sr), r g b per coefficient):\n");
  static const char* kNames[kShL2Count] = {"Y00",  "Y1-1", "Y10", "Y11", "Y2-2",
                                           "Y2-1", "Y20",  "Y21", "Y22"};
  for (int i = 0; i < kShL2Count; ++i)
    std::printf("  %-4s %.6g %.6g %.6g\n", kNames[i], sh.c[i].x, sh.c[i].y, sh.c[i].z);
  std::printf("irradiance E (not E/pi) for normal (%g, %g, %g): %.6g %.6g %.6g\n", n.x, n.y, n.z,
              e.x, e.y, e.z);
  const std::array<int32_t, 4>& lights = set->occlusionLights;
  std::printf(
      "occlusion (shadowmask channels 0-3, lights %d %d %d %d; -1 unused): %.6g %.6g "
      "%.6g %.6g\n",
      lights[0], lights[1], lights[2], lights[3], occlusion.x, occlusion.y, occlusion.z,
      occlusion.w);
  return kExitOk;
}

// ---- export --------------------------------------------------------------------------------

struct ExportOptions {
  std::string file;
  std::string out;
  bool json = false;
  bool moments = false;
  bool unity = false;
  std::string axes = "unity";  // with --unity: "unity" or "gltf"
};

Json exportJson(const ProbeSet& s, bool withMoments) {
  Json j;
  j["version"] = kProbeFileVersion;
  j["dimension"] = s.dimension;
  j["probeCount"] = s.probeCount();
  j["cellCount"] = s.cellCount();
  j["innerCellCount"] = s.innerCellCount;
  j["shConvention"] =
      "radiance SH, real orthonormal basis Y00 Y1-1 Y10 Y11 Y2-2 Y2-1 Y20 Y21 Y22 in glTF world "
      "axes; irradiance E(n) = sum A_l c_i Y_i(n), A = pi, 2pi/3, pi/4";
  j["occlusionConvention"] =
      "per probe, shadowmask channels 0-3: fraction of the light occlusionLights[c] (scene light "
      "index, -1 unused) that reaches the probe unshadowed, in [0, 1]";
  j["occlusionLights"] = s.occlusionLights;
  Json positions = Json::array(), validity = Json::array(), sh = Json::array(),
       occlusion = Json::array();
  for (int32_t i = 0; i < s.probeCount(); ++i) {
    positions.push_back(vecJson(s.positions[i]));
    validity.push_back(shortest(s.validity[i]));
    sh.push_back(shJson(s.sh[i]));
    occlusion.push_back(vec4Json(s.occlusion.empty() ? glm::vec4(1.0f) : s.occlusion[i]));
  }
  j["positions"] = std::move(positions);
  j["validity"] = std::move(validity);
  j["sh"] = std::move(sh);
  j["occlusion"] = std::move(occlusion);
  const ProbeVisibility& vis = s.visibility;
  j["visibilityResolution"] = vis.resolution;
  j["visibilityConvention"] =
      "per probe, an octahedral map (visibilityResolution^2 texels, +z at the centre, texel "
      "(i, j) at index j * R + i) of the first-hit distances s = min(t, D) / D of the probe's "
      "bake rays (a miss counts as D = visibilityMaxDistance, metres), fitted per texel by a "
      "plane in the map's coordinates; visibilityMoments (with --visibility-moments) lists per "
      "texel [mu, sigma, far]: the plane at the texel centre, the RMS residual of the fit and "
      "the largest s of the texel's rays, all as fractions of D; resolution 0 = no visibility "
      "(plain blending)";
  Json maxDistance = Json::array();
  for (float d : vis.maxDistance) maxDistance.push_back(shortest(d));
  j["visibilityMaxDistance"] = std::move(maxDistance);
  if (withMoments && !vis.empty()) {
    Json moments = Json::array();
    for (int32_t i = 0; i < s.probeCount(); ++i) {
      const std::span<const uint16_t> m = vis.probe(i);
      Json texels = Json::array();
      for (size_t t = 0; t + kVisibilityValuesPerTexel <= m.size();
           t += kVisibilityValuesPerTexel) {
        Json texel = Json::array();
        for (size_t k = 0; k < kVisibilityValuesPerTexel; ++k)
          texel.push_back(shortest(float(m[t + k]) / 65535.0f));
        texels.push_back(std::move(texel));
      }
      moments.push_back(std::move(texels));
    }
    j["visibilityMoments"] = std::move(moments);
  }
  Json cells = Json::array();
  for (const glm::ivec4& c : s.cells) cells.push_back({c[0], c[1], c[2], c[3]});
  j["cells"] = std::move(cells);
  const ProbeSunLayer& sun = s.sun;
  j["sunConvention"] =
      "the sun layer (kiln/probe_set.h ProbeSunLayer): sunLight is the baked directional light "
      "(scene light index, -1 = no layer) whose direct light sunSh holds at a fully lit point "
      "(radiance SH as sh); sunVisibility per probe the share of it that reaches the probe, "
      "in [0, 1]; sunRamps per inner cell the ramp's values at the cell's 4 vertices, or null "
      "for no ramp (sunRampCount ramps, 0 or innerCellCount; sunRampsFitted not null)";
  j["sunLight"] = sun.light;
  if (!sun.empty()) {
    j["sunSh"] = shJson(sun.sh);
    Json visibility = Json::array(), ramps = Json::array();
    for (float v : sun.visibility) visibility.push_back(shortest(v));
    int32_t fitted = 0;
    for (const glm::vec4& a : sun.ramps) {
      fitted += std::isnan(a.x) ? 0 : 1;
      ramps.push_back(std::isnan(a.x) ? Json(nullptr) : vec4Json(a));
    }
    j["sunVisibility"] = std::move(visibility);
    j["sunRampCount"] = sun.ramps.size();
    j["sunRampsFitted"] = fitted;
    j["sunRamps"] = std::move(ramps);
  }
  return j;
}

// `export --unity`: per probe Unity's SH9 shader constants (packUnitySh9, src/sh_projection.h),
// the 7 float4 that UnityCG.cginc's ShadeSH9 reads as unity_SHAr .. unity_SHC, with the probe
// positions, in Unity's world axes (a glTF point or direction (x, y, z) is Unity's (-x, y, z),
// as glTFast and UnityGLTF import it) or, with --axes gltf, in kiln's own.
Json exportUnityJson(const ProbeSet& s, ShAxes axes) {
  const bool unity = axes == ShAxes::kUnity;
  Json j;
  j["format"] = "kiln unity sh9";
  j["version"] = 1;
  j["axes"] = unity ? "unity" : "gltf";
  j["axesConvention"] =
      unity ? "Unity world axes (left-handed, +Y up, +Z forward): a glTF point or direction "
              "(x, y, z) is Unity's (-x, y, z), the X negation of glTFast and UnityGLTF"
            : "glTF world axes (right-handed, +Y up), as in the .kprobe file";
  j["shConvention"] =
      "per probe the 7 float4 shader constants of Unity's SH9 lighting (unity_SHAr, unity_SHAg, "
      "unity_SHAb, unity_SHBr, unity_SHBg, unity_SHBb, unity_SHC; UnityCG.cginc ShadeSH9): for "
      "a unit world-space normal n, x1.c = dot(SHAc, (n, 1)), x2.c = dot(SHBc, n.xyzz * n.yzzx), "
      "x3 = SHC.rgb * (n.x^2 - n.y^2), and x1 + x2 + x3 = E(n) / pi, the outgoing radiance of a "
      "white Lambertian surface (linear colour; E in lux)";
  j["probeCount"] = s.probeCount();
  const float sx = unity ? -1.0f : 1.0f;
  Json positions = Json::array(), sh9 = Json::array();
  for (int32_t i = 0; i < s.probeCount(); ++i) {
    const vec3 p = s.positions[i];
    positions.push_back(vecJson(vec3(sx * p.x, p.y, p.z)));
    const UnitySh9 u = packUnitySh9(s.sh[i], axes);
    sh9.push_back({{"SHAr", vec4Json(u.shAr)},
                   {"SHAg", vec4Json(u.shAg)},
                   {"SHAb", vec4Json(u.shAb)},
                   {"SHBr", vec4Json(u.shBr)},
                   {"SHBg", vec4Json(u.shBg)},
                   {"SHBb", vec4Json(u.shBb)},
                   {"SHC", vec4Json(u.shC)}});
  }
  j["positions"] = std::move(positions);
  j["sh9"] = std::move(sh9);
  return j;
}

int runExport(const ExportOptions& o) {
  Result<ProbeSet> set = loadProbeFile(o.file);
  if (!set) {
    printError(set.error());
    return kExitBadInput;
  }
  if (!o.unity && o.axes != "unity") {
    printError("probes export: --axes applies to --unity only");
    return kExitBadUsage;
  }
  if (o.unity && o.moments) {
    printError("probes export: --visibility-moments and --unity do not go together");
    return kExitBadUsage;
  }
  const Json json = o.unity
                        ? exportUnityJson(*set, o.axes == "gltf" ? ShAxes::kGltf : ShAxes::kUnity)
                        : exportJson(*set, o.moments);
  const std::string text = json.dump(2) + "\n";
  if (o.out.empty()) {
    std::cout << text;
    return kExitOk;
  }
  if (Status s = writeTextFileAtomically(o.out, text); !s) {
    printError(s.error());
    return kExitBadInput;
  }
  return kExitOk;
}

}  // namespace

// `kiln probes lppv` (probes_lppv_command.cpp) registers on the "probes" command made here.
void registerProbesLppvCommand(CLI::App& probes);

void registerProbesCommand(CLI::App& app) {
  // Other probe subcommands (place, lppv) may register on the same "probes" command.
  CLI::App* probes = nullptr;
  try {
    probes = app.get_subcommand("probes");
  } catch (const CLI::OptionNotFound&) {
    probes = app.add_subcommand("probes", "Light probes: bake, query and export .kprobe files");
    probes->require_subcommand(1);
  }

  auto bake = std::make_shared<BakeOptions>();
  CLI::App* b = probes->add_subcommand(
      "bake", "Bake L2 radiance SH light probes at given positions into a .kprobe file");
  b->add_option("scene", bake->scene, "glTF 2.0 file (.gltf or .glb)")->required();
  b->add_option("--scene", bake->gltfScene, "glTF scene to load, numbered from 0 (default: the file's 'scene', else 0)")
      ->check(CLI::NonNegativeNumber);
  b->add_option("--positions", bake->positions,
                "JSON file {\"positions\": [[x, y, z], ...]} (world space, metres); the scene's "
                "probe groups (extras.kiln.probes) are added unless --no-scene-probes");
  b->add_option("--out,-o", bake->out, "Output .kprobe file (written atomically)")->required();
  b->add_option("--rays", bake->rays, "Rays per probe (a power of two is best)")
      ->check(CLI::Range(1, 1 << 30))
      ->capture_default_str();
  b->add_option("--seed", bake->seed, "Seed of every random number")->capture_default_str();
  b->add_option("--backend", bake->backend,
                "Tetrahedralization backend: cgal (CGAL's Delaunay) or tetgen (AGPLv3)")
      ->check(CLI::IsMember({"cgal", "tetgen"}))
      ->capture_default_str();
  b->add_option("--bounces", bake->bounces,
                "Indirect bounces (default: the scene's extras.kiln.bounces, else " +
                    std::to_string(kDefaultProbeBounces) + ")")
      ->check(CLI::Range(0, 1024));
  b->add_option("--lighting-mode", bake->lightingMode,
                "Mixed lighting mode: which lights the probes bake and whether they store "
                "shadowmask occlusion (default: the scene's extras.kiln.lightingMode, else "
                "baked-indirect)")
      ->check(CLI::IsMember({"baked-indirect", "shadowmask", "subtractive"}));
  b->add_option("--threads", bake->threads, "Worker threads (0 = all cores)")
      ->check(CLI::NonNegativeNumber)
      ->capture_default_str();
  b->add_flag("--no-dering", bake->noDering,
              "Keep the raw SH even where its irradiance goes negative");
  b->add_flag("--no-scene-probes", bake->noSceneProbes,
              "Ignore the scene's probe groups (use only --positions)");
  b->add_option("--visibility-resolution", bake->visibilityResolution,
                "Side of each probe's octahedral visibility map for leak-free blending (" +
                    std::to_string(kMinVisibilityResolution) + " to " +
                    std::to_string(kMaxVisibilityResolution) + "; 0 = none: plain blending)")
      ->check(visibilityResolutionValidator("no visibility"))
      ->capture_default_str();
  b->add_option("--visibility-max-distance", bake->visibilityMaxDistance,
                "Metres the visibility depths are clamped to (0 = per probe, the distance to "
                "the farthest corner of the scene and the probes)")
      ->check(finiteNumberValidator(0.0, false, 1e9, "a finite number of metres >= 0 (0 = auto)",
                                    "METRES >= 0"))
      ->capture_default_str();
  b->add_option("--footprint", bake->footprint,
                "Bake each probe as the mean over a ball of this fraction of the distance to "
                "its nearest probe (at most --footprint-max-radius): a prefilter against light "
                "and shade finer than the probes, for probes in a sheet of light or shade under "
                "18 cm thick (a blind's stripes; see --footprint-everywhere) (0 to 0.5; 0 = at "
                "the probe's point)")
      ->check(finiteNumberValidator(0.0, false, double(kMaxProbeFootprint),
                                    "a number from 0 to 0.5 (a fraction of the distance to the "
                                    "nearest probe; 0 = a point bake)",
                                    "0..0.5"))
      ->capture_default_str();
  b->add_option("--footprint-max-radius", bake->footprintMaxRadius,
                "Largest footprint radius, metres")
      ->check(finiteNumberValidator(0.0, true, 1e6, "a finite number of metres > 0", "METRES > 0"))
      ->capture_default_str();
  b->add_flag("--no-sun-shadows", bake->noSunShadows,
              "No sun layer: objects lit by the probes get the brightest baked directional "
              "light's shadow edges blended across each tetrahedron instead of sharp (see "
              "docs/probes.md, \"Sun shadows\")");
  b->add_flag("--footprint-everywhere", bake->footprintEverywhere,
              "Bake every probe over its footprint, not only those in thin sheets of light or "
              "shade (smoother, but less accurate where light varies no faster than the probes)");
  addSkyOptions(b, bake->sky);
  b->add_flag("--quiet,-q", bake->quiet, "No progress or summary on stderr");
  addMpiFlag(b, &bake->mpi);
  b->callback(commandCallback([bake]() { return runBake(*bake); }));

  auto query = std::make_shared<QueryOptions>();
  CLI::App* q = probes->add_subcommand(
      "query", "Locate a point in a .kprobe file: cell, probes, weights, SH and irradiance");
  q->add_option("file", query->file, ".kprobe file")->required();
  q->add_option("coords", query->coords, "X Y Z [NX NY NZ]: point and optional normal (+Y)")
      ->required()
      ->expected(3, 6);
  q->add_option("--blend", query->blend,
                "visibility: weight the probes by their visibility of the point (when the file "
                "has it); plain: barycentric weights alone")
      ->check(CLI::IsMember({"plain", "visibility"}))
      ->capture_default_str();
  q->add_flag("--json", query->json,
              "Print JSON with keys tet, probes, weights (the blend's), barycentric, blend, sh "
              "(9 x [r, g, b]), irradiance");
  q->callback(commandCallback([query]() { return runQuery(*query); }));

  auto exp = std::make_shared<ExportOptions>();
  CLI::App* e = probes->add_subcommand(
      "export", "Print a .kprobe file as JSON, for people or (--unity) for Unity's SH9 shading");
  e->add_option("file", exp->file, ".kprobe file")->required();
  e->add_flag("--json", exp->json, "JSON output (the only format; accepted for clarity)");
  e->add_option("--out,-o", exp->out, "Write to this file instead of stdout");
  e->add_flag("--visibility-moments", exp->moments,
              "Also list every probe's visibility map (visibilityMoments: per probe R^2 "
              "texels of [mu, sigma, far]; large)");
  e->add_flag("--unity", exp->unity,
              "Instead: per probe Unity's SH9 shader constants (SHAr SHAg SHAb SHBr SHBg SHBb "
              "SHC, evaluating to E/pi as ShadeSH9 does) and positions");
  e->add_option("--axes", exp->axes,
                "With --unity: the axes of positions and SH: unity (a glTF (x, y, z) is Unity's "
                "(-x, y, z), as glTFast and UnityGLTF import) or gltf")
      ->check(CLI::IsMember({"unity", "gltf"}))
      ->capture_default_str();
  e->callback(commandCallback([exp]() { return runExport(*exp); }));

  registerProbesLppvCommand(*probes);
  registerProbesPlaceCommand(*probes);
}

}  // namespace kiln::cli
