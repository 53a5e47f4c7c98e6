// bake_command.cpp: `kiln bake SCENE --out DIR`, the lightmap bake. Thin over
// lightmap/lightmap_baker.h (the bake) and lightmap/lightmap_writer.h (the files). Settings
// come from the defaults, then the quality preset (--preset, else the scene's
// extras.kiln.quality), then the scene's extras.kiln, then the command line: the command line
// wins. Outputs and their formats: docs/lightmap_outputs.md.
#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <iostream>
#include <limits>
#include <memory>
#include <nlohmann/json.hpp>
#include <optional>
#include <sstream>

#include "lightmap/atlas.h"
#include "lightmap/lightmap_baker.h"
#include "lightmap/lightmap_writer.h"
#include "lightmap/manifest.h"
#include "src/distributed.h"
#include "src/progress.h"
#include "src/text_file.h"
#include "tools/kiln/cli_common.h"

#ifndef KILN_VERSION
#define KILN_VERSION "0.1.0"
#endif

namespace kiln::cli {
namespace {

using Json = nlohmann::json;

struct BakeOptions {
  std::string scene;
  int gltfScene = -1;  // --scene
  std::string out;
  std::string preset;
  std::optional<int> samples;
  std::optional<float> errorTarget;
  std::optional<int> bounceCache;
  bool adaptive = false;
  bool coverageMap = false;
  bool footprintGrid = false;    // --footprint-grid: the default, accepted
  bool noFootprintGrid = false;  // --no-footprint-grid
  std::optional<float> resolution;
  std::optional<int> maxSize;
  std::optional<int> padding;
  std::optional<std::string> minObjectTexels;  // "auto" or a texel count
  std::optional<int> bounces;
  std::optional<uint64_t> seed;
  int threads = 0;
  bool noDenoise = false;
  bool ao = false;
  std::optional<float> aoAmount;    // --ao-amount: bakes AO and applies it to the light map
  std::optional<float> aoDistance;  // --ao-distance: AO ray length, world units
  std::string ldr;
  std::string lockAtlas;
  std::string lightingMode;
  std::optional<std::string> shadowColor;  // "R,G,B", parsed by parseShadowColor
  bool directional = false;
  bool atlasUv = false;
  bool glb = false;
  bool quiet = false;
  bool mpi = false;
  SkyOptions sky;
};

std::string humanCount(double n) {
  char buf[32];
  if (n >= 1e9)
    std::snprintf(buf, sizeof buf, "%.2fG", n / 1e9);
  else if (n >= 1e6)
    std::snprintf(buf, sizeof buf, "%.2fM", n / 1e6);
  else if (n >= 1e3)
    std::snprintf(buf, sizeof buf, "%.1fk", n / 1e3);
  else
    std::snprintf(buf, sizeof buf, "%.0f", n);
  return buf;
}

// The scene's extras.kiln settings that the lightmap bake uses. Returns an exit code.
int applySceneSettings(const Scene& scene, LightmapBakeSettings& b) {
  const SceneSettings& s = scene.settings;
  if (s.lightingMode) {
    Result<LightingMode> mode = parseLightingMode(*s.lightingMode);
    if (!mode) {
      printError(scene.path + ": extras.kiln.lightingMode: " + mode.error());
      return kExitBadInput;
    }
    b.lightingMode = *mode;
  }
  if (s.directionalMode) {
    b.directional = *s.directionalMode != "non-directional";
    if (*s.directionalMode == "sh")
      printWarning(scene.path + ": extras.kiln.directionalMode \"sh\": L1 SH lightmaps are not "
                   "baked yet; baking \"directional\" instead");
  }
  if (s.lightmapResolution) b.resolution = *s.lightmapResolution;
  if (s.lightmapPadding) b.padding = *s.lightmapPadding;
  if (s.lightmapMaxSize) b.maxSize = *s.lightmapMaxSize;
  if (s.bounces) b.bounces = *s.bounces;
  if (s.albedoBoost) b.albedoBoost = *s.albedoBoost;
  if (s.indirectIntensity) b.indirectIntensity = *s.indirectIntensity;
  if (s.ambientOcclusion) b.ambientOcclusion = *s.ambientOcclusion;
  if (s.aoMaxDistance) b.aoMaxDistance = *s.aoMaxDistance;
  if (s.aoAmount) b.aoAmount = *s.aoAmount;
  if (s.shadowColor) b.shadowColor = *s.shadowColor;
  return kExitOk;
}

// --lock-atlas: the earlier bake's layout for this scene. The atlas settings come from that
// manifest (a different resolution would generate different UVs), so the command line may
// not contradict them. Returns an exit code.
int lockAtlas(const BakeOptions& o, LightmapBakeSettings& settings) {
  Result<Manifest> read = readManifestFile(o.lockAtlas, ManifestUse::kAtlas);
  if (!read) {
    printError("--lock-atlas: " + read.error());
    return kExitBadInput;
  }
  const Manifest& manifest = *read;
  const ManifestSettingsFields& s = manifest.settingsFields;
  auto take = [&](const char* key, const char* option, const auto& given, const auto& locked,
                  auto& field) -> bool {
    if (!locked) return true;
    if (given && *given != *locked) {
      std::ostringstream msg;
      msg << option << " " << *given << " contradicts --lock-atlas " << o.lockAtlas << " ("
          << key << " " << *locked << "); leave it out to use the locked atlas";
      printError(msg.str());
      return false;
    }
    field = *locked;
    return true;
  };
  if (!take("resolution", "--resolution", o.resolution, s.resolution, settings.resolution) ||
      !take("padding", "--padding", o.padding, s.padding, settings.padding) ||
      !take("maxSize", "--max-size", o.maxSize, s.maxSize, settings.maxSize))
    return kExitBadUsage;
  // bakeLightmaps generates the UVs and recovers the manifest's texel rectangles from them.
  settings.lockedAtlas = LightmapBakeSettings::LockedAtlas{std::move(read).value(), o.lockAtlas};
  return kExitOk;
}

int runBake(const BakeOptions& options) {
  const auto start = std::chrono::steady_clock::now();
  // A distributed bake (docs/distributed.md): every rank bakes its share; rank 0 alone
  // prints, post-processes and writes.
  if (int code = startDistributedBake(options.mpi)) return code;
  BakeOptions o = options;
  o.quiet = o.quiet || !distributedRoot();
  std::optional<vec3> shadowColor;
  if (o.shadowColor) {
    shadowColor = parseNonNegativeRgb(*o.shadowColor);
    if (!shadowColor) {
      printError("--shadow-color '" + *o.shadowColor +
                 "': expected three finite numbers >= 0 separated by commas, R,G,B in "
                 "lightmap units (e.g. 0.42,0.478,0.627)");
      return kExitBadUsage;
    }
  }
  // Before any work: a bad --out or sky fails now, not after the bake.
  if (distributedRoot())
    if (int code = checkOutputDirectory("--out", o.out)) return code;
  std::optional<Sky> sky;
  if (int code = resolveSky(o.sky, &sky)) return code;
  Scene scene;
  if (int code = loadSceneForBake(o.scene, o.gltfScene, o.quiet, sky, &scene)) return code;

  LightmapBakeSettings settings;
  std::string preset = o.preset;
  if (preset.empty() && scene.settings.quality) preset = *scene.settings.quality;
  if (!preset.empty()) {
    if (Status s = applyLightmapPreset(preset, settings); !s) {
      // --preset is checked by CLI11, so a bad name here came from the scene.
      printError(scene.path + ": extras.kiln.quality: " + s.error());
      return kExitBadInput;
    }
  }
  if (int code = applySceneSettings(scene, settings)) return code;
  if (!o.lightingMode.empty()) settings.lightingMode = *parseLightingMode(o.lightingMode);
  if (shadowColor) settings.shadowColor = *shadowColor;
  if (o.directional) settings.directional = true;
  // --samples alone is a fixed count per texel; with --error-target it is the cap.
  if (o.samples) {
    settings.samplesPerTexel = *o.samples;
    settings.errorTarget = 0.0f;
  }
  if (o.errorTarget) settings.errorTarget = *o.errorTarget;
  if (o.bounceCache) settings.bounceCacheSamples = *o.bounceCache;
  if (o.adaptive) settings.adaptiveSamples = true;
  if (o.coverageMap) settings.coverageMap = true;
  if (o.noFootprintGrid) settings.footprintGrid = false;
  if (o.resolution) settings.resolution = *o.resolution;
  if (o.maxSize) settings.maxSize = *o.maxSize;
  if (o.padding) settings.padding = *o.padding;
  if (o.minObjectTexels)
    settings.minObjectTexels =
        *o.minObjectTexels == "auto" ? -1.0f : std::strtof(o.minObjectTexels->c_str(), nullptr);
  if (o.bounces) settings.bounces = *o.bounces;
  if (o.seed) settings.seed = *o.seed;
  settings.threads = o.threads;
  if (o.noDenoise) settings.denoise = false;
  if (o.ao) settings.ambientOcclusion = true;
  if (o.aoAmount) {
    settings.ambientOcclusion = true;
    settings.aoAmount = *o.aoAmount;
  }
  if (o.aoDistance) settings.aoMaxDistance = *o.aoDistance;

  LightmapOutputSettings output;
  output.outDir = o.out;
  output.preset = preset;
  output.kilnVersion = KILN_VERSION;
  output.lockAtlas = o.lockAtlas;
  if (o.ldr == "rgbm") output.ldr = LdrEncoding::Rgbm;
  if (o.ldr == "dldr") output.ldr = LdrEncoding::Dldr;
  output.atlasUv = o.atlasUv;
  output.glb = o.glb;

  if (!o.lockAtlas.empty())
    if (int code = lockAtlas(o, settings)) return code;

  // Settings that cannot work together (each alone is range-checked by CLI11 or the loader).
  if (settings.adaptiveSamples &&
      (settings.bounceCacheSamples == 0 || settings.errorTarget > 0.0f)) {
    printError(std::string("--adaptive allocates paths by the bounce cache's first pass: it "
                           "needs --bounce-cache N (N >= 1)") +
               (settings.errorTarget > 0.0f
                    ? o.errorTarget ? " and no --error-target"
                                    : " and --samples N (the mean paths per texel: a preset "
                                      "sets an error target, which allocates by its own rule)"
                    : ""));
    return kExitBadUsage;
  }
  if (settings.maxSize < 1 + 2 * settings.padding) {
    printError("--max-size " + std::to_string(settings.maxSize) + " cannot hold one texel with " +
               "--padding " + std::to_string(settings.padding) +
               " on each side (needs --max-size >= 1 + 2 x padding = " +
               std::to_string(1 + 2 * settings.padding) + ")");
    return kExitBadUsage;
  }

  if (!o.quiet)
    std::cerr << "kiln: baking " << scene.path << ": " << settings.resolution
              << " texels/unit, "
              << (settings.errorTarget > 0.0f
                      ? "error target " + std::to_string(settings.errorTarget) + " (at most " +
                            std::to_string(settings.samplesPerTexel) + " samples/texel), "
                      : std::to_string(settings.samplesPerTexel) + " samples/texel, ")
              << settings.bounces << " bounces" << (preset.empty() ? "" : ", preset " + preset)
              << "\n";
  Result<LightmapBakeResult> baked = bakeLightmaps(scene, settings, !o.quiet, &cancelFlag());
  if (cancelFlag().load()) return reportInterrupted(o.out);
  if (!baked) {
    printError(scene.path + ": " + baked.error());
    return kExitBadInput;
  }
  if (!distributedRoot()) return kExitOk;  // rank 0 has every texel and writes
  const LightmapBakeResult& result = *baked;
  std::vector<std::string> writeWarnings;
  if (Status s = writeLightmapOutputs(o.scene, result, settings, output, &writeWarnings); !s) {
    printError(s.error());
    return kExitBadInput;
  }
  for (const std::string& w : result.warnings) printWarning(w);
  for (const std::string& w : writeWarnings) printWarning(w);
  if (!o.quiet) {
    const double seconds =
        std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
    size_t pageTexels = 0;
    for (const AtlasPage& p : result.layout.pages) pageTexels += size_t(p.width) * p.height;
    const LightmapBakeStats& st = result.stats;
    std::ostringstream line;
    line.setf(std::ios::fixed);
    line.precision(2);
    int charts = 0;
    for (const auto& u : result.unwraps) charts += u ? u->stats.chartCount : 0;
    line << "kiln: wrote " << o.out << ": " << result.layout.pages.size() << " lightmap page(s) ("
         << pageTexels << " texels, "
         << (pageTexels > 0 ? 100.0 * double(st.texels) / double(pageTexels) : 0.0)
         << "% baked), " << st.texels << " baked texels (" << st.invalidTexels << " invalid), "
         << charts << " charts in generated UVs, " << st.minSamples << "/" << st.meanSamples
         << "/" << st.maxSamples << " paths per texel (min/mean/max), "
         << humanCount(double(st.rays)) << " rays in " << st.seconds << " s ("
         << humanCount(st.seconds > 0 ? double(st.rays) / st.seconds : 0.0)
         << " rays/s); total " << seconds << " s";
    if (distributedActive())
      line << "; " << distributedSize() << " ranks, "
           << humanCount(double(distributedBytesReceived())) << "B gathered";
    line << "\n";
    std::cerr << line.str();
  }
  return kExitOk;
}

}  // namespace

void registerBakeCommand(CLI::App& app) {
  auto o = std::make_shared<BakeOptions>();
  CLI::App* b = app.add_subcommand(
      "bake", "Bake lightmaps: OpenEXR pages, manifest.json and a glTF that references them");
  b->add_option("scene", o->scene, "glTF 2.0 file (.gltf or .glb)")->required();
  b->add_option("--scene", o->gltfScene, "glTF scene to load, numbered from 0 (default: the file's 'scene', else 0)")
      ->check(CLI::NonNegativeNumber);
  b->add_option("--out,-o", o->out, "Output directory (created; files replaced atomically)")
      ->required();
  b->add_option("--preset", o->preset,
                "Quality preset (default: the scene's extras.kiln.quality, else none)")
      ->check(CLI::IsMember({"preview", "low", "medium", "high", "production"}));
  b->add_option("--samples", o->samples,
                "Paths per texel, the same for every texel (replaces the preset's error "
                "target); with --error-target, the cap")
      ->check(CLI::Range(1, 1 << 24));
  b->add_option("--error-target", o->errorTarget,
                "Error target: the relative RMS error of the texels to aim at; a pilot pass on "
                "its own random numbers measures each texel's spread, and texels get paths in "
                "proportion to it (at least the preset's minimum, 32 without one, at most "
                "--samples); unbiased; 0 = off")
      ->check(finiteNumberValidator(0.0, false, 1.0, "a number from 0 to 1 (0 = off)", "0..1"));
  b->add_option("--bounce-cache", o->bounceCache,
                "Final gather: a first pass of this many paths per texel, whose light the "
                "bake's paths read at their first hit instead of tracing on; 0 = off")
      ->check(CLI::Range(0, 1 << 24));
  b->add_flag("--adaptive", o->adaptive,
              "With --bounce-cache: the same paths in total, given to texels in proportion to "
              "the spread the first pass measured (--samples on average, up to 8x)");
  auto* grid = b->add_flag("--footprint-grid", o->footprintGrid,
                           "Texels next to geometry average the visible part of their "
                           "footprint, 4 x 4 points (the default)");
  b->add_flag("--no-footprint-grid", o->noFootprintGrid,
              "Texels next to geometry bake at their main sample point (or supersampling "
              "points) alone, as kiln did before the footprint grid")
      ->excludes(grid);
  b->add_flag("--coverage-map", o->coverageMap,
              "Also write lightmap-<i>_coverage.exr: the visible share of each texel's "
              "footprint (for comparisons with renderers that bake hidden points black)");
  b->add_option("--resolution", o->resolution,
                "Texels per world unit, before each object's scaleInLightmap")
      ->check(finiteNumberValidator(1e-6, false, 1e5, "a number from 1e-6 to 1e5",
                                    "1e-6..1e5"));
  b->add_option("--max-size", o->maxSize, "Largest lightmap page side, texels (default 1024)")
      ->check(CLI::Range(1, 16384));
  b->add_option("--min-object-texels", o->minObjectTexels,
                "Objects whose surface would get fewer lightmap texels are lit by probes "
                "instead (their own probe light in the manifest and output glTF), listed in a "
                "warning and the manifest (default \"auto\": objects without TEXCOORD_1 under "
                "5 x --resolution texels and 1% of the lightmapped area, or under 1% whose "
                "generated charts are too thin: surface under 25% of the texels they touch; "
                "0 = never)")
      ->check([](const std::string& v) -> std::string {
        if (v == "auto") return "";
        char* end = nullptr;
        const float n = std::strtof(v.c_str(), &end);
        if (end == v.c_str() || *end != '\0' || !(n >= 0.0f && n <= 1e9f))
          return "expected \"auto\" or a number in [0, 1e9], got \"" + v +
                 "\"";
        return "";
      });
  b->add_option("--padding", o->padding, "Empty texels around every object (default 2)")
      ->check(CLI::Range(0, 256));
  b->add_option("--bounces", o->bounces, "Bounce cap (default 64; Russian roulette)")
      ->check(CLI::Range(0, 1024));
  b->add_option("--seed", o->seed, "Seed of every random number (default 0)");
  b->add_option("--threads", o->threads, "Worker threads (0 = all cores; output is the same)")
      ->check(CLI::Range(0, 4096))
      ->capture_default_str();
  b->add_flag("--no-denoise", o->noDenoise, "Skip the edge-aware denoiser");
  b->add_flag("--ao", o->ao, "Also bake ambient occlusion (lightmap-<i>_ao.exr)");
  b->add_option("--ao-amount", o->aoAmount,
                "Bake AO and apply it to the light map: light x (1 - A (1 - ao)), A in [0, 1] "
                "(default: the scene's extras.kiln.aoAmount, else 0 = not applied)")
      ->check(finiteNumberValidator(0.0, false, 1.0, "a number from 0 to 1", "0..1"));
  b->add_option("--ao-distance", o->aoDistance,
                "AO ray length in world units, > 0 (default: extras.kiln.aoMaxDistance, else 1)")
      ->check(finiteNumberValidator(1e-6, false, 1e9, "a number of world units from 1e-6 to 1e9",
                                    "1e-6..1e9"));
  b->add_option("--ldr", o->ldr,
                "8-bit PNG pages, the output glTF's lightmap textures: dldr (default) or rgbm "
                "(decode: docs)")
      ->check(CLI::IsMember({"rgbm", "dldr"}));
  b->add_flag("--atlas-uv", o->atlasUv,
              "Write atlas UVs into the output glTF's TEXCOORD_1 (identity scale/offset)");
  b->add_flag("--glb", o->glb, "Write one self-contained <scene>.glb instead of .gltf + files");
  b->add_option("--lock-atlas", o->lockAtlas,
                "Reuse the atlas of an earlier bake's manifest.json (same scene)");
  b->add_option("--lighting-mode", o->lightingMode,
                "Mixed lights: baked-indirect, shadowmask or subtractive (docs/mixed_lighting.md)")
      ->check(CLI::IsMember({"baked-indirect", "shadowmask", "subtractive"}));
  b->add_option("--shadow-color", o->shadowColor,
                "Subtractive: realtime shadow colour R,G,B in lightmap units, recorded in the "
                "manifest (default 0.42,0.478,0.627)");
  b->add_flag("--directional", o->directional,
              "Also bake the dominant light direction (lightmap-<i>_direction.exr)");
  addSkyOptions(b, o->sky);
  b->add_flag("--quiet,-q", o->quiet, "No progress or summary on stderr");
  addMpiFlag(b, &o->mpi);
  b->callback(commandCallback([o]() { return runBake(*o); }));
}

}  // namespace kiln::cli
