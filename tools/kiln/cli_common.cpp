// cli_common.cpp: the shared pieces of the kiln CLI (see cli_common.h).
#include "tools/kiln/cli_common.h"

#include <fcntl.h>
#include <unistd.h>

#include <cerrno>
#include <charconv>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <iostream>
#include <limits>
#include <memory>

#include "kiln/probe_visibility.h"
#include "src/distributed.h"
#include "src/progress.h"

namespace kiln::cli {

void printError(const std::string& message) {
  if (distributedRoot()) std::cerr << "kiln: error: " << message << "\n";
}

void printWarning(const std::string& message) {
  if (distributedRoot()) std::cerr << "kiln: warning: " << message << "\n";
}

void addMpiFlag(CLI::App* command, bool* mpi) {
  command->add_flag("--mpi", *mpi,
                    "Distributed bake over MPI (automatic under mpirun or srun): ranks split "
                    "the work, rank 0 writes the outputs, byte-identical to one process "
                    "(docs/distributed.md)");
}

int startDistributedBake(bool mpi) {
  if (Status s = startDistributed(mpi); !s) {
    printError(s.error());
    return kExitBadUsage;
  }
  return kExitOk;
}

void finishDistributedJob(int exitCode) {
  if (exitCode == kExitOk || !distributedActive() || distributedFailureAgreed()) {
    stopDistributed();
    return;
  }
  std::cerr.flush();
  distributedAbort("", exitCode);  // the message was printed already
}

std::function<void()> commandCallback(std::function<int()> body) {
  return [body = std::move(body)]() {
    int code = body();
    if (code != kExitOk) throw CLI::RuntimeError(code);
  };
}

int loadSceneOrReport(const std::string& path, const LoadOptions& options, Scene* scene,
                      bool printWarnings) {
  Result<Scene> loaded = loadScene(path, options);
  if (!loaded) {
    printError(loaded.error());
    return kExitBadInput;
  }
  *scene = std::move(loaded).value();
  if (printWarnings)
    for (const std::string& w : scene->warnings) printWarning(w);
  return kExitOk;
}

int loadSceneForBake(const std::string& path, int gltfScene, bool quiet,
                     const std::optional<Sky>& sky, Scene* scene) {
  installInterruptHandler();
  LoadOptions options;
  options.scene = gltfScene;
  options.loadSkyMap = !sky;  // replaced anyway: do not read the scene's map
  options.cancel = &cancelFlag();
  std::unique_ptr<Progress> progress;  // made at the first texture, when the total is known
  if (!quiet)
    options.textureProgress = [&progress](size_t done, size_t total) {
      if (!progress) progress = std::make_unique<Progress>("texture decoding", total, "textures");
      progress->advance(done - progress->done());
      if (done >= total) progress->finish();
    };
  Result<Scene> loaded = loadScene(path, options);
  if (progress) progress->finish();
  if (cancelFlag().load()) return reportInterrupted("outputs");
  if (!loaded) {
    printError(loaded.error());
    return kExitBadInput;
  }
  *scene = std::move(loaded).value();
  if (sky) scene->sky = *sky;
  for (const std::string& w : scene->warnings) printWarning(w);
  return kExitOk;
}

int reportInterrupted(const std::string& what) {
  printError("interrupted; " + what + " left untouched");
  return kExitInterrupted;
}

namespace {

namespace fs = std::filesystem;

// Whether a new file can be created in the existing directory `dir`: creates and removes a
// uniquely named probe file (permission bits alone say nothing for root, and nothing about
// read-only file systems). Returns an empty string or the reason.
std::string probeWritable(const fs::path& dir) {
  std::string probe = (dir / ".kiln-write-check-XXXXXX").string();
  int fd = ::mkstemp(probe.data());
  if (fd < 0) return std::string("cannot create files in ") + dir.string() + ": " + std::strerror(errno);
  ::close(fd);
  ::unlink(probe.c_str());
  return "";
}

// Prints "OPTION PATH: why" and returns kExitBadInput.
int failOutput(const std::string& option, const std::string& path, const std::string& why) {
  printError(option + " " + path + ": " + why);
  return kExitBadInput;
}

// `path` made absolute; an empty string in `why` unless it is empty or cannot be.
fs::path absoluteOutput(const std::string& path, std::string& why) {
  if (path.empty()) {
    why = "empty path";
    return {};
  }
  std::error_code ec;
  fs::path p = fs::absolute(fs::path(path), ec);
  if (ec) why = ec.message();
  return p;
}

}  // namespace

int checkOutputDirectory(const std::string& option, const std::string& path) {
  auto fail = [&](const std::string& why) { return failOutput(option, path, why); };
  std::string why;
  const fs::path p = absoluteOutput(path, why);
  if (!why.empty()) return fail(why);
  std::error_code ec;
  // The nearest existing ancestor (or the path itself) must be a directory: mkdir fails
  // under a regular file.
  fs::path existing = p;
  while (!fs::exists(existing, ec)) {
    if (ec && ec != std::errc::no_such_file_or_directory) return fail(ec.message());
    if (!existing.has_parent_path() || existing.parent_path() == existing) break;
    existing = existing.parent_path();
  }
  if (!fs::is_directory(existing, ec))
    return fail(existing == p ? "exists and is not a directory"
                              : existing.string() + " is not a directory, so the directory "
                                                    "cannot be created");
  const std::string notWritable = probeWritable(existing);
  if (!notWritable.empty()) return fail(notWritable);
  return kExitOk;
}

int checkOutputFile(const std::string& option, const std::string& path) {
  auto fail = [&](const std::string& why) { return failOutput(option, path, why); };
  std::string why;
  const fs::path p = absoluteOutput(path, why);
  if (!why.empty()) return fail(why);
  std::error_code ec;
  if (fs::is_directory(p, ec)) return fail("is a directory");
  const fs::path dir = p.parent_path();
  if (!fs::exists(dir, ec)) return fail("directory " + dir.string() + " does not exist");
  if (!fs::is_directory(dir, ec)) return fail(dir.string() + " is not a directory");
  const std::string notWritable = probeWritable(dir);
  if (!notWritable.empty()) return fail(notWritable);
  return kExitOk;
}

std::optional<vec3> parseNonNegativeRgb(const std::string& text) {
  vec3 colour(0.0f);
  size_t start = 0;
  for (int c = 0; c < 3; ++c) {
    const size_t comma = text.find(',', start);
    if ((c < 2) != (comma != std::string::npos)) return std::nullopt;  // not exactly 3 parts
    std::string part =
        text.substr(start, comma == std::string::npos ? std::string::npos : comma - start);
    start = comma + 1;
    const size_t first = part.find_first_not_of(" \t"), last = part.find_last_not_of(" \t");
    if (first == std::string::npos) return std::nullopt;
    part = part.substr(first, last - first + 1);
    char* end = nullptr;
    const double v = std::strtod(part.c_str(), &end);
    if (end != part.c_str() + part.size() || !std::isfinite(v) || v < 0.0 ||
        v > double(std::numeric_limits<float>::max()))
      return std::nullopt;
    colour[c] = float(v) + 0.0f;  // "-0" reads as +0
  }
  return colour;
}

void addSkyOptions(CLI::App* command, SkyOptions& options) {
  CLI::Option* color = command->add_option(
      "--sky", options.color,
      "Constant sky radiance R,G,B (finite, >= 0), replacing the scene's extras.kiln.sky");
  CLI::Option* map = command->add_option(
      "--sky-map", options.map,
      "Equirectangular sky map (.hdr or .exr), replacing the scene's extras.kiln.sky");
  map->excludes(color);
  command->add_option("--sky-intensity", options.intensity,
                      "Scale of --sky or --sky-map (default 1)")
      ->check(nonNegativeNumberValidator());
}

int resolveSky(const SkyOptions& o, std::optional<Sky>* sky) {
  if (o.intensity && !o.color && o.map.empty()) {
    printError("--sky-intensity needs --sky or --sky-map");
    return kExitBadUsage;
  }
  const float intensity = o.intensity.value_or(1.0f);
  if (o.color) {
    std::optional<vec3> c = parseNonNegativeRgb(*o.color);
    if (!c) {
      printError("--sky '" + *o.color +
                 "': expected three finite numbers >= 0 separated by commas, R,G,B radiance "
                 "(e.g. 1,1,1)");
      return kExitBadUsage;
    }
    *sky = Sky::constant(*c * intensity);
  } else if (!o.map.empty()) {
    Result<Sky> loaded = Sky::fromFile(o.map, intensity);
    if (!loaded) {
      printError("--sky-map " + o.map + ": " + loaded.error());
      return kExitBadInput;
    }
    *sky = std::move(loaded).value();
  }
  return kExitOk;
}

CLI::Validator finiteNumberValidator(double lo, bool loOpen, double hi, const std::string& what,
                                     const std::string& name) {
  return CLI::Validator(
      [lo, loOpen, hi, what](std::string& text) -> std::string {
        char* end = nullptr;
        const double v = std::strtod(text.c_str(), &end);
        const bool inRange = (loOpen ? v > lo : v >= lo) && v <= hi;
        if (end != text.c_str() && *end == '\0' && std::isfinite(v) && inRange) return "";
        return "must be " + what + ", got '" + text + "'";
      },
      name);
}

CLI::Validator nonNegativeNumberValidator(double hi) {
  return finiteNumberValidator(0.0, false, hi, "a finite number >= 0", "NUMBER >= 0");
}

CLI::Validator positiveNumberValidator(double hi) {
  return finiteNumberValidator(0.0, true, hi, "a finite number > 0", "NUMBER > 0");
}

CLI::Validator visibilityResolutionValidator(const std::string& zero) {
  const std::string range =
      std::to_string(kMinVisibilityResolution) + " to " + std::to_string(kMaxVisibilityResolution);
  return CLI::Validator(
      [zero, range](std::string& text) -> std::string {
        int v = -1;
        const auto r = std::from_chars(text.data(), text.data() + text.size(), v);
        const bool number = r.ec == std::errc() && r.ptr == text.data() + text.size();
        if (number && isVisibilityResolution(v)) return "";
        return "must be 0 (" + zero + ") or an integer from " + range + ", got '" + text + "'";
      },
      "0 or " + std::to_string(kMinVisibilityResolution) + ".." +
          std::to_string(kMaxVisibilityResolution));
}

}  // namespace kiln::cli
