// probes_lppv_command.cpp: `kiln probes lppv FILE.kprobe --bounds ... --out PREFIX`, a light
// probe proxy volume (a 3D grid of L2 SH over a box) filled from a .kprobe file's probe field,
// or baked directly at the grid's samples with --scene. Writes PREFIX.klppv (L2, for
// kiln_runtime), PREFIX_L1.exr (Unity-style SHAr/SHAg/SHAb/occlusion) and PREFIX.json. Thin
// over probes/lppv.h; formats in docs/lppv.md.
#include <algorithm>
#include <cmath>
#include <iostream>
#include <limits>
#include <memory>
#include <optional>
#include <sstream>
#include <string>
#include <vector>

#include "kiln/lppv_volume.h"
#include "kiln/probe_set.h"
#include "probes/lppv.h"
#include "probes/probe_baker.h"
#include "src/progress.h"
#include "src/tracer.h"
#include "tools/kiln/cli_common.h"

namespace kiln::cli {

void registerProbesLppvCommand(CLI::App& probes);

namespace {

struct LppvOptions {
  std::string file;
  std::string bounds;
  std::string resolution = "auto";
  bool cellCenter = false;
  bool cellCorner = false;
  std::string out;
  double samplesPerSpacing = 1.0;
  int maxResolution = 32;
  bool unityAxes = false;
  bool half = false;
  std::string blend = "visibility";
  std::string scene;
  int rays = 4096;
  int threads = 0;
  bool quiet = false;
};

// Comma-separated finite numbers, each within a float's range (the bounds are floats: a larger
// number would read as infinity); nullopt when the text is not exactly `count` of them.
std::optional<std::vector<double>> parseNumbers(const std::string& text, size_t count) {
  std::vector<double> values;
  std::stringstream in(text);
  std::string item;
  while (std::getline(in, item, ',')) {
    size_t used = 0;
    double v = 0.0;
    try {
      v = std::stod(item, &used);
    } catch (...) {
      return std::nullopt;
    }
    if (used != item.size() || !(std::fabs(v) <= std::numeric_limits<float>::max()))
      return std::nullopt;
    values.push_back(v);
  }
  if (values.size() != count || (!text.empty() && text.back() == ',')) return std::nullopt;
  return values;
}

std::string fmtVec(glm::vec3 v) {
  std::ostringstream s;
  s << "(" << v.x << ", " << v.y << ", " << v.z << ")";
  return s.str();
}

int runLppv(const LppvOptions& o) {
  LppvBuildSettings settings;
  const std::optional<std::vector<double>> b = parseNumbers(o.bounds, 6);
  if (!b) {
    printError("--bounds: expected minx,miny,minz,maxx,maxy,maxz (6 finite numbers), got '" +
               o.bounds + "'");
    return kExitBadUsage;
  }
  settings.boundsMin = glm::vec3(float((*b)[0]), float((*b)[1]), float((*b)[2]));
  settings.boundsMax = glm::vec3(float((*b)[3]), float((*b)[4]), float((*b)[5]));
  if (o.resolution != "auto") {
    const std::optional<std::vector<double>> r = parseNumbers(o.resolution, 3);
    if (!r || (*r)[0] != std::floor((*r)[0]) || (*r)[1] != std::floor((*r)[1]) ||
        (*r)[2] != std::floor((*r)[2]) || std::fabs((*r)[0]) > 1e9 || std::fabs((*r)[1]) > 1e9 ||
        std::fabs((*r)[2]) > 1e9) {
      printError("--resolution: expected 'auto' or X,Y,Z (3 integers), got '" + o.resolution + "'");
      return kExitBadUsage;
    }
    settings.resolution = glm::ivec3(int((*r)[0]), int((*r)[1]), int((*r)[2]));
  }
  settings.placement = o.cellCorner ? LppvPlacement::kCellCorner : LppvPlacement::kCellCenter;
  settings.autoSettings.samplesPerProbeSpacing = o.samplesPerSpacing;
  settings.autoSettings.maxResolution = o.maxResolution;
  settings.threads = o.threads;
  if (Status st = validateLppvBuildSettings(settings); !st) {
    printError(st.error());
    return kExitBadUsage;
  }

  // Before any work: PREFIX's directory must take the files (PREFIX.klppv is the first).
  if (int code = checkOutputFile("--out", o.out + ".klppv")) return code;
  Result<ProbeSet> set = loadProbeFile(o.file);
  if (!set) {
    printError(set.error());
    return kExitBadInput;
  }
  // The fill blends with locateProbe's default, visibility-weighted when the file has the
  // maps; a set without them blends plainly, so dropping them is exactly --blend plain.
  const bool visibilityUsed = o.blend == "visibility" && !set->visibility.empty();
  if (o.blend == "plain") set->visibility = ProbeVisibility{};
  Result<LppvBuild> built = buildLppvFromProbes(*set, settings);
  if (!built) {
    printError(o.file + ": " + built.error());
    return kExitBadInput;
  }
  LppvVolume& volume = built->volume;

  if (!o.scene.empty()) {
    // Bake the grid's samples directly as probes (one per sample, same order) instead of
    // interpolating the probe field: sharper where the probes are sparse, and costs a bake.
    Scene scene;
    if (int code = loadSceneForBake(o.scene, -1, o.quiet, std::nullopt, &scene)) return code;
    Result<std::unique_ptr<Tracer>> tracer = Tracer::create(scene);
    if (!tracer) {
      printError(scene.path + ": " + tracer.error());
      return kExitBadInput;
    }
    ProbeBakeSettings bake;
    bake.rays = uint32_t(o.rays);
    bake.threads = o.threads;
    bake.sunShadows = false;  // the volume keeps each sample's SH, not the probes' cells
    const std::vector<glm::vec3> positions = lppvSamplePositions(volume);
    Progress progress("lppv", positions.size(), "samples", !o.quiet);
    ProbeBakeReport report;
    Result<ProbeSet> baked =
        bakeProbes(scene, **tracer, positions, bake, &progress, &cancelFlag(), &report);
    if (cancelFlag().load()) return reportInterrupted(o.out + ".*");
    if (!baked) {
      printError(scene.path + ": " + baked.error());
      return kExitBadInput;
    }
    for (const std::string& w : report.warnings) printWarning(w);
    for (size_t i = 0; i < positions.size(); ++i) {
      volume.sh[i] = baked->sh[i];
      volume.validity[i] = std::clamp(baked->validity[i], 0.0f, 1.0f);
    }
  }

  LppvOutputOptions out;
  out.axes = o.unityAxes ? ShAxes::kUnity : ShAxes::kGltf;
  out.halfFloat = o.half;
  out.source = o.file;
  out.autoResolution = built->autoResolution;
  Result<LppvOutputFiles> files = writeLppvOutputs(volume, o.out, out);
  if (!files) {
    printError(files.error());
    return kExitBadInput;
  }
  if (!o.quiet) {
    const glm::ivec3 n = volume.resolution;
    std::cerr << "kiln: LPPV " << n.x << " x " << n.y << " x " << n.z << " samples ("
              << (o.cellCorner ? "cell corners" : "cell centres") << ") over "
              << fmtVec(volume.boundsMin) << " to " << fmtVec(volume.boundsMax);
    if (built->autoResolution) {
      const LppvAutoResolution& a = *built->autoResolution;
      std::cerr << "; auto resolution from " << a.probesInBounds << " probes in the bounds"
                << (a.wholeSetDensity ? " (none: the whole set's density)" : "")
                << ", probe spacing " << a.probeSpacing << " m";
    }
    std::cerr << (o.scene.empty()
                      ? (visibilityUsed ? "; filled from the probe field (visibility blend)"
                                        : "; filled from the probe field (plain blend)")
                      : "; baked directly")
              << "\nkiln: wrote " << files->volume << ", " << files->unityL1 << ", "
              << files->metadata << "\n";
  }
  return kExitOk;
}

}  // namespace

void registerProbesLppvCommand(CLI::App& probes) {
  auto o = std::make_shared<LppvOptions>();
  CLI::App* c = probes.add_subcommand(
      "lppv", "Build a light probe proxy volume (3D grid of SH over a box) from a .kprobe file");
  c->add_option("file", o->file, ".kprobe file whose probe field fills the volume")->required();
  c->add_option("--bounds", o->bounds,
                "minx,miny,minz,maxx,maxy,maxz: the box in world space (metres, glTF axes)")
      ->required();
  c->add_option("--resolution", o->resolution,
                "'auto' (from the probe density in the bounds, see docs/lppv.md) or X,Y,Z "
                "samples per axis")
      ->capture_default_str();
  auto* center = c->add_flag("--cell-center", o->cellCenter,
                             "Samples at the centres of the grid's cells (default; as Unity)");
  auto* corner = c->add_flag("--cell-corner", o->cellCorner,
                             "Samples at the cells' corners: the outermost lie on the box");
  center->excludes(corner);
  corner->excludes(center);
  c->add_option("--out,-o", o->out,
                "Output prefix: writes PREFIX.klppv, PREFIX_L1.exr and PREFIX.json")
      ->required();
  c->add_option("--samples-per-spacing", o->samplesPerSpacing,
                "Auto resolution: grid samples per mean probe spacing")
      ->check(positiveNumberValidator(std::numeric_limits<double>::max()))
      ->capture_default_str();
  c->add_option("--max-resolution", o->maxResolution, "Auto resolution: cap per axis")
      ->check(CLI::Range(1, kLppvMaxAxis))
      ->capture_default_str();
  c->add_flag("--unity-axes", o->unityAxes,
              "Pack the L1 EXR for Unity's axes (x negated, grid mirrored in x)");
  c->add_flag("--half", o->half, "Write the L1 EXR as half floats (default: float)");
  c->add_option("--blend", o->blend,
                "How the probe field is blended at the samples: visibility (weight probes by "
                "their visibility of the sample, when the file has it) or plain (barycentric)")
      ->check(CLI::IsMember({"plain", "visibility"}))
      ->capture_default_str();
  c->add_option("--scene", o->scene,
                "Bake the samples directly from this glTF scene instead of interpolating "
                "the probes (FILE still sets the auto resolution)");
  c->add_option("--rays", o->rays, "With --scene: rays per sample")
      ->check(CLI::Range(1, 1 << 30))
      ->capture_default_str();
  c->add_option("--threads", o->threads, "Worker threads (0 = all cores)")
      ->check(CLI::NonNegativeNumber)
      ->capture_default_str();
  c->add_flag("--quiet,-q", o->quiet, "No summary on stderr");
  c->callback(commandCallback([o]() { return runLppv(*o); }));
}

}  // namespace kiln::cli
