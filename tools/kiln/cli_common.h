// cli_common.h: what the `kiln` subcommands share: exit codes, message printing, scene
// loading, and one registration function per subcommand (each in its own *_command.cpp).
//
// A subcommand registers itself on the App with a callback made by commandCallback(); the
// callback's body returns an exit code, and main() returns it. Messages go to stderr as
// "kiln: error: ..." and "kiln: warning: ...".
#pragma once

#include <CLI/CLI.hpp>
#include <functional>
#include <string>

#include "src/gltf_loader.h"
#include "src/scene.h"

namespace kiln::cli {

// Process exit codes (CONTRIBUTING.md).
inline constexpr int kExitOk = 0;
inline constexpr int kExitBadInput = 1;  // a file could not be loaded, read or written
inline constexpr int kExitBadUsage = 2;  // wrong options or arguments

void printError(const std::string& message);
void printWarning(const std::string& message);

// Wraps a subcommand's body for CLI::App::callback: a non-zero exit code from `body` ends
// parsing with that code (as a CLI::RuntimeError, which CLI11 does not print).
std::function<void()> commandCallback(std::function<int()> body);

// Loads a scene. On failure prints the error and returns kExitBadInput; on success stores the
// scene in *scene, prints its warnings (unless printWarnings is false: callers that report
// warnings themselves) and returns kExitOk.
int loadSceneOrReport(const std::string& path, const LoadOptions& options, Scene* scene,
                      bool printWarnings = true);

// Subcommand registration.
// Checks a --visibility-resolution value: 0 (whose meaning `zero` names in the message) or an
// integer in [kMinVisibilityResolution, kMaxVisibilityResolution].
CLI::Validator visibilityResolutionValidator(const std::string& zero);

void registerInfoCommand(CLI::App& app);
void registerBakeCommand(CLI::App& app);  // kiln bake (lightmaps)
void registerProbesCommand(CLI::App& app);  // kiln probes bake | query | export
void registerProbesPlaceCommand(CLI::App& probes);  // kiln probes place | compare-placement
void registerRenderCommand(CLI::App& app);  // kiln render (preview renderer, --compare)
void registerChartCommand(CLI::App& app);  // kiln chart (speed vs accuracy charts)

}  // namespace kiln::cli
