// cli_common.h: what the `kiln` subcommands share: exit codes, message printing, scene
// loading, and one registration function per subcommand (each in its own *_command.cpp).
//
// A subcommand registers itself on the App with a callback made by commandCallback(); the
// callback's body returns an exit code, and main() returns it. Messages go to stderr as
// "kiln: error: ..." and "kiln: warning: ...".
#pragma once

#include <CLI/CLI.hpp>
#include <functional>
#include <limits>
#include <optional>
#include <string>

#include "src/gltf_loader.h"
#include "src/scene.h"
#include "src/sky.h"

namespace kiln::cli {

// Process exit codes (CONTRIBUTING.md).
inline constexpr int kExitOk = 0;
inline constexpr int kExitBadInput = 1;  // a file could not be loaded, read or written
inline constexpr int kExitBadUsage = 2;  // wrong options or arguments
inline constexpr int kExitInterrupted = 130;  // Ctrl-C / SIGTERM: 128 + SIGINT, as the shell

// Printed by rank 0 only in a distributed bake (the other ranks run the same code and would
// repeat it; a rank's own failure ends the job through finishDistributedJob's MPI_Abort).
void printError(const std::string& message);
void printWarning(const std::string& message);

// --mpi on the commands that bake across ranks (kiln bake, probes bake, probes place).
void addMpiFlag(CLI::App* command, bool* mpi);
// Starts MPI for a distributed bake (src/distributed.h: under mpirun / srun, or --mpi).
// Prints the error and returns kExitBadUsage when that cannot be done, else kExitOk.
int startDistributedBake(bool mpi);
// The end of a `kiln` run: exit code 0 (or a failure every rank learnt of in the same
// exchange) finalizes MPI; any other code on any rank ends every rank of the job with that
// code (MPI_Abort), since the others may be waiting for it.
void finishDistributedJob(int exitCode);

// Wraps a subcommand's body for CLI::App::callback: a non-zero exit code from `body` ends
// parsing with that code (as a CLI::RuntimeError, which CLI11 does not print).
std::function<void()> commandCallback(std::function<int()> body);

// Loads a scene. On failure prints the error and returns kExitBadInput; on success stores the
// scene in *scene, prints its warnings (unless printWarnings is false: callers that report
// warnings themselves) and returns kExitOk.
int loadSceneOrReport(const std::string& path, const LoadOptions& options, Scene* scene,
                      bool printWarnings = true);

// Same, for commands that run long: installs the Ctrl-C handler first, shows texture decoding
// progress on stderr unless `quiet`, stops on Ctrl-C (returns kExitInterrupted, with a
// message) and replaces the scene's sky by `sky` when given (the scene's own sky map is then
// not loaded). `gltfScene` is the glTF scene to load (-1: the file's default; --scene).
int loadSceneForBake(const std::string& path, int gltfScene, bool quiet,
                     const std::optional<Sky>& sky, Scene* scene);

// Prints "interrupted; <what> left untouched" and returns kExitInterrupted.
int reportInterrupted(const std::string& what);

// Output paths checked before any work, so that a bad --out fails at once rather than after
// a long bake. A directory: `path` must be a directory, or not exist with its nearest
// existing ancestor a directory; that directory must accept a new file (a probe file is
// created and removed). A file: `path` must not be a directory and its directory must exist
// and accept a new file. Prints "<option> <path>: ..." and returns kExitBadInput on failure.
int checkOutputDirectory(const std::string& option, const std::string& path);
int checkOutputFile(const std::string& option, const std::string& path);

// "R,G,B": three finite numbers >= 0 separated by commas (spaces around them allowed).
std::optional<vec3> parseNonNegativeRgb(const std::string& text);

// --sky R,G,B | --sky-map FILE [--sky-intensity S]: the environment, overriding the scene's
// extras.kiln.sky.
struct SkyOptions {
  std::optional<std::string> color;
  std::string map;
  std::optional<float> intensity;
};
void addSkyOptions(CLI::App* command, SkyOptions& options);
// The sky the options ask for (nullopt: none given, keep the scene's). Returns an exit code:
// kExitBadUsage for a bad value (naming the option), kExitBadInput for a map that cannot be
// read (naming the file).
int resolveSky(const SkyOptions& options, std::optional<Sky>* sky);

// Subcommand registration.
// Checks a --visibility-resolution value: 0 (whose meaning `zero` names in the message) or an
// integer in [kMinVisibilityResolution, kMaxVisibilityResolution].
CLI::Validator visibilityResolutionValidator(const std::string& zero);
// Checks a finite number in [lo, hi] (in (lo, hi] when loOpen); NaN and infinities fail
// (CLI::Range lets NaN through: every comparison with it is false). The message is "must be
// " + what + ", got '<text>'"; `name` is the validator's description in --help. Every
// floating-point option of kiln is checked with it or the two below, never with CLI::Range,
// CLI::NonNegativeNumber or CLI::PositiveNumber (the last two also let infinities through).
CLI::Validator finiteNumberValidator(double lo, bool loOpen, double hi, const std::string& what,
                                     const std::string& name);
// CLI::NonNegativeNumber and CLI::PositiveNumber without NaN and infinities, for a
// floating-point option: a finite number in [0, hi] or (0, hi]; hi is the largest finite value
// of the option's type (a float's by default: a larger number would read as infinity).
CLI::Validator nonNegativeNumberValidator(double hi = std::numeric_limits<float>::max());
CLI::Validator positiveNumberValidator(double hi = std::numeric_limits<float>::max());

void registerInfoCommand(CLI::App& app);
void registerBakeCommand(CLI::App& app);  // kiln bake (lightmaps)
void registerProbesCommand(CLI::App& app);  // kiln probes bake | query | export
void registerProbesPlaceCommand(CLI::App& probes);  // kiln probes place | compare-placement
void registerRenderCommand(CLI::App& app);  // kiln render (preview renderer, --compare)
void registerChartCommand(CLI::App& app);  // kiln chart (speed vs accuracy charts)

}  // namespace kiln::cli
