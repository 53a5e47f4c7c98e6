// render_command.cpp: `kiln render`, the preview renderer (tools/render/preview_renderer.h):
//   kiln render SCENE --lightmaps DIR [--probes FILE.kprobe [--probe-blend plain|visibility]]
//       [--camera NAME | --look-from X,Y,Z --look-at X,Y,Z --fov DEG] [--size W,H] [--spheres FILE]
//       [--exposure EV] [--mode preview|reference] [--samples N] [--linear FILE.exr]
//       --out image.png
//   kiln render --compare A.png B.png --out DIR_or_PREFIX [--diff-scale S]
// Exit codes: 0 ok, 1 bad input (a file that cannot be read or does not fit the scene), 2 bad
// usage, 130 interrupted (nothing written). Usage and formulas: docs/render.md.
#include <chrono>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <iostream>
#include <memory>
#include <optional>
#include <sstream>

#include "kiln/probe_set.h"
#include "src/progress.h"
#include "tools/kiln/cli_common.h"
#include "tools/render/preview_renderer.h"

namespace kiln::cli {
namespace {

namespace fs = std::filesystem;

struct RenderOptions {
  std::string scene;
  int gltfScene = -1;  // --scene
  std::string lightmaps;
  std::string probes;
  std::string probeBlend = "visibility";
  std::string camera;
  std::string lookFrom, lookAt;
  std::optional<float> fov;
  std::string size;
  std::string spheres;
  float exposure = 0.0f;
  std::string mode = "preview";
  uint32_t samples = 64;
  uint64_t seed = 0;
  int threads = 0;
  std::string out;
  std::string linear;
  std::vector<std::string> compare;
  float diffScale = 4.0f;
  bool quiet = false;
  SkyOptions sky;
};

// "X,Y,Z" -> three finite numbers.
bool parseVec3(const std::string& text, vec3& out) {
  std::istringstream in(text);
  char c1 = 0, c2 = 0;
  if (!(in >> out.x >> c1 >> out.y >> c2 >> out.z) || c1 != ',' || c2 != ',') return false;
  in >> std::ws;
  return in.eof() && isFinite(out);
}

// "W,H" -> two integers in [1, 16384].
bool parseSize(const std::string& text, int& w, int& h) {
  std::istringstream in(text);
  char c = 0;
  long long a = 0, b = 0;
  if (!(in >> a >> c >> b) || c != ',') return false;
  in >> std::ws;
  if (!in.eof() || a < 1 || b < 1 || a > 16384 || b > 16384) return false;
  w = int(a);
  h = int(b);
  return true;
}

int runCompare(const RenderOptions& o) {
  if (!o.scene.empty()) {
    printError("--compare takes no SCENE (got " + o.scene + ")");
    return kExitBadUsage;
  }
  Result<Image> a = readImageFile(o.compare[0]);
  if (!a) {
    printError(a.error());
    return kExitBadInput;
  }
  Result<Image> b = readImageFile(o.compare[1]);
  if (!b) {
    printError(b.error());
    return kExitBadInput;
  }
  Result<ImageComparison> c = compareImages(*a, *b, o.diffScale);
  if (!c) {
    printError(o.compare[0] + " vs " + o.compare[1] + ": " + c.error());
    return kExitBadInput;
  }
  // --out: a directory (existing, or ending in '/') gets compare.png and compare_diff.png;
  // anything else is a prefix (a trailing .png is dropped).
  std::string sideBySide, difference;
  std::error_code ec;
  if (fs::is_directory(o.out, ec) || (!o.out.empty() && o.out.back() == '/')) {
    fs::create_directories(o.out, ec);
    sideBySide = (fs::path(o.out) / "compare.png").string();
    difference = (fs::path(o.out) / "compare_diff.png").string();
  } else {
    std::string prefix = o.out;
    if (prefix.size() > 4 && prefix.substr(prefix.size() - 4) == ".png")
      prefix.resize(prefix.size() - 4);
    sideBySide = prefix + ".png";
    difference = prefix + "_diff.png";
  }
  for (auto [path, image] : {std::pair{sideBySide, &c->sideBySide},
                             std::pair{difference, &c->difference}})
    if (Status s = writePng(path, *image); !s) {
      printError(s.error());
      return kExitBadInput;
    }
  std::printf("compared %s (A) with %s (B), %d x %d\n", o.compare[0].c_str(), o.compare[1].c_str(),
              a->width, a->height);
  std::printf("mean A %.6f, mean B %.6f\n", c->meanA, c->meanB);
  std::printf("mean absolute difference %.6f\n", c->meanAbsoluteDifference);
  std::printf("relative mean difference %.6f (%.2f%%: sum |A - B| / sum B)\n",
              c->relativeMeanDifference, 100.0 * c->relativeMeanDifference);
  std::printf("wrote %s (A | B | |A - B| x %g) and %s\n", sideBySide.c_str(), o.diffScale,
              difference.c_str());
  return kExitOk;
}

int runRender(const RenderOptions& o) {
  const auto start = std::chrono::steady_clock::now();
  if (o.scene.empty()) {
    printError("render: SCENE is required (or --compare A B)");
    return kExitBadUsage;
  }
  const bool reference = o.mode == "reference";
  if (!reference && o.lightmaps.empty()) {
    printError("--lightmaps DIR is required in preview mode (the --out directory of kiln bake)");
    return kExitBadUsage;
  }
  if (!o.camera.empty() && (!o.lookFrom.empty() || !o.lookAt.empty())) {
    printError("--camera cannot be combined with --look-from/--look-at");
    return kExitBadUsage;
  }
  if (o.lookFrom.empty() != o.lookAt.empty()) {
    printError("--look-from and --look-at go together");
    return kExitBadUsage;
  }
  CameraRequest request;
  request.name = o.camera;
  if (!o.lookFrom.empty()) {
    vec3 from, at;
    if (!parseVec3(o.lookFrom, from)) {
      printError("--look-from " + o.lookFrom + ": expected X,Y,Z (three finite numbers)");
      return kExitBadUsage;
    }
    if (!parseVec3(o.lookAt, at)) {
      printError("--look-at " + o.lookAt + ": expected X,Y,Z (three finite numbers)");
      return kExitBadUsage;
    }
    if (glm::length(at - from) <= 0.0f) {
      printError("--look-at must differ from --look-from");
      return kExitBadUsage;
    }
    request.lookFrom = from;
    request.lookAt = at;
  }
  if (o.fov) request.fovDegrees = *o.fov;
  int width = 0, height = 0;
  if (!o.size.empty() && !parseSize(o.size, width, height)) {
    printError("--size " + o.size + ": expected W,H (integers 1..16384)");
    return kExitBadUsage;
  }

  // Before any work: a bad --out or sky fails now, not after the render.
  if (int code = checkOutputFile("--out", o.out)) return code;
  if (!o.linear.empty())
    if (int code = checkOutputFile("--linear", o.linear)) return code;
  std::optional<Sky> sky;
  if (int code = resolveSky(o.sky, &sky)) return code;
  Scene scene;
  if (int code = loadSceneForBake(o.scene, o.gltfScene, o.quiet, sky, &scene)) return code;

  std::optional<LightmapSet> lightmaps;
  if (!o.lightmaps.empty()) {
    Result<LightmapSet> loaded = loadLightmapSet(o.lightmaps, scene);
    if (!loaded) {
      printError(loaded.error());
      return kExitBadInput;
    }
    lightmaps = std::move(loaded).value();
  }
  std::optional<ProbeSet> probes;
  if (!o.probes.empty()) {
    Result<ProbeSet> loaded = loadProbeFile(o.probes);
    if (!loaded) {
      printError(loaded.error());
      return kExitBadInput;
    }
    probes = std::move(loaded).value();
    // Probe-lit objects take one lookup (or an LPPV fill) with locateProbe's default blend,
    // visibility-weighted when the file has the maps; without them it is the plain blend.
    if (o.probeBlend == "plain") probes->visibility = ProbeVisibility{};
  }
  RenderInputs inputs;
  inputs.scene = &scene;
  inputs.lightmaps = lightmaps ? &*lightmaps : nullptr;
  inputs.probes = probes ? &*probes : nullptr;
  if (!o.spheres.empty()) {
    Result<std::vector<RenderSphere>> spheres = loadSpheres(o.spheres);
    if (!spheres) {
      printError(spheres.error());
      return kExitBadInput;
    }
    inputs.spheres = std::move(spheres).value();
  }
  if (!reference && !inputs.spheres.empty() && !probes) {
    printError("--spheres needs --probes FILE.kprobe in preview mode (the spheres are probe-lit)");
    return kExitBadUsage;
  }
  Result<RenderCamera> camera = resolveCamera(scene, request);
  if (!camera) {
    printError(camera.error());
    return kExitBadInput;
  }
  if (o.size.empty()) {
    // 480 wide; the height from the glTF camera's aspect ratio when it has one, else 4:3.
    const Camera* used = nullptr;
    if (!o.camera.empty()) {
      for (const Camera& c : scene.cameras)
        if (c.name == o.camera) used = &c;
    } else if (o.lookFrom.empty() && !scene.cameras.empty()) {
      used = &scene.cameras.front();
    }
    width = 480;
    height = used && used->aspectRatio > 0.0f
                 ? std::max(1, int(std::lround(480.0f / used->aspectRatio)))
                 : 360;
    height = std::min(height, 16384);
  }

  RenderSettings settings;
  settings.width = width;
  settings.height = height;
  settings.mode = reference ? RenderMode::Reference : RenderMode::Preview;
  settings.samples = o.samples;
  settings.seed = o.seed;
  settings.threads = o.threads;
  settings.showProgress = !o.quiet;
  settings.cancel = &cancelFlag();
  if (!o.quiet)
    std::cerr << "kiln: rendering " << scene.path << " (" << o.mode << ", " << width << " x "
              << height << (reference ? ", " + std::to_string(o.samples) + " paths/pixel" : "")
              << ")\n";
  Result<RenderResult> rendered = renderImage(inputs, *camera, settings);
  if (cancelFlag().load()) {
    printError("interrupted; nothing written");
    return kExitInterrupted;
  }
  if (!rendered) {
    printError(scene.path + ": " + rendered.error());
    return kExitBadInput;
  }
  for (const std::string& w : rendered->warnings) printWarning(w);
  if (!o.linear.empty())
    if (Status s = writeExr(o.linear, rendered->radiance, true); !s) {
      printError(s.error());
      return kExitBadInput;
    }
  if (Status s = writePng(o.out, toneMap(rendered->radiance, o.exposure)); !s) {
    printError(s.error());
    return kExitBadInput;
  }
  if (!o.quiet) {
    const double seconds =
        std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
    char line[256];
    std::snprintf(line, sizeof line, "kiln: wrote %s (%d x %d, exposure %+.2f EV) in %.2f s\n",
                  o.out.c_str(), width, height, double(o.exposure), seconds);
    std::cerr << line;
  }
  return kExitOk;
}

}  // namespace

void registerRenderCommand(CLI::App& app) {
  auto o = std::make_shared<RenderOptions>();
  CLI::App* r = app.add_subcommand(
      "render",
      "Render a PNG of the scene shaded from its lightmaps and probes (preview), or path traced "
      "(reference); or compare two images (--compare A B)");
  r->add_option("scene", o->scene, "glTF 2.0 file (.gltf or .glb)");
  r->add_option("--scene", o->gltfScene, "glTF scene to load, numbered from 0 (default: the file's 'scene', else 0)")
      ->check(CLI::NonNegativeNumber);
  r->add_option("--lightmaps", o->lightmaps,
                "Directory written by kiln bake (manifest.json + EXR pages)");
  r->add_option("--probes", o->probes, ".kprobe file (kiln probes bake) for dynamic objects");
  r->add_option("--probe-blend", o->probeBlend,
                "Probe lighting: visibility (probes weighted by their visibility of the object, "
                "when the .kprobe has it) or plain (barycentric weights alone)")
      ->check(CLI::IsMember({"plain", "visibility"}))
      ->capture_default_str();
  r->add_option("--camera", o->camera, "A glTF camera by name (default: the first camera)");
  r->add_option("--look-from", o->lookFrom, "Camera position X,Y,Z (with --look-at)");
  r->add_option("--look-at", o->lookAt, "Point the camera looks at X,Y,Z");
  r->add_option("--fov", o->fov, "Vertical field of view, degrees (default 50)")
      ->check(finiteNumberValidator(0.01, false, 179.0, "a number of degrees from 0.01 to 179",
                                    "0.01..179"));
  r->add_option("--size", o->size,
                "Image size W,H (default 480 wide, height from the camera's aspect or 4:3)");
  r->add_option("--spheres", o->spheres,
                "JSON {\"spheres\": [{\"center\": [x,y,z], \"radius\": r, \"albedo\": [r,g,b], "
                "\"lppv\": false}]}: dynamic probe-lit spheres");
  r->add_option("--exposure", o->exposure, "Exposure in EV (x 2^EV before the tone map)")
      ->check(finiteNumberValidator(-32.0, false, 32.0, "a number of EV from -32 to 32", "-32..32"))
      ->capture_default_str();
  r->add_option("--mode", o->mode, "preview (baked data) or reference (path traced)")
      ->check(CLI::IsMember({"preview", "reference"}))
      ->capture_default_str();
  r->add_option("--samples", o->samples, "Reference mode: paths per pixel")
      ->check(CLI::Range(1, 1 << 20))
      ->capture_default_str();
  r->add_option("--seed", o->seed, "Seed of every random number")->capture_default_str();
  r->add_option("--threads", o->threads, "Worker threads (0 = all cores; output is the same)")
      ->check(CLI::Range(0, 4096))
      ->capture_default_str();
  r->add_option("--out,-o", o->out,
                "Output PNG (render), or output directory / prefix (--compare)")
      ->required();
  r->add_option("--linear", o->linear, "Also write the linear radiance as an OpenEXR (FLOAT)");
  r->add_option("--compare", o->compare,
                "Compare two images (PNG or EXR) of one size: writes A | B | difference and the "
                "difference; prints the mean absolute and relative mean difference")
      ->expected(2);
  r->add_option("--diff-scale", o->diffScale, "--compare: difference image = |A - B| x this")
      ->check(finiteNumberValidator(1e-3, false, 1e6, "a number from 1e-3 to 1e6", "1e-3..1e6"))
      ->capture_default_str();
  addSkyOptions(r, o->sky);
  r->add_flag("--quiet,-q", o->quiet, "No progress or summary on stderr");
  r->callback(commandCallback([o]() { return o->compare.empty() ? runRender(*o) : runCompare(*o); }));
}

}  // namespace kiln::cli
