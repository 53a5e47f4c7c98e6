// cli_common.cpp: the shared pieces of the kiln CLI (see cli_common.h).
#include "tools/kiln/cli_common.h"

#include <charconv>
#include <iostream>

#include "kiln/probe_visibility.h"

namespace kiln::cli {

void printError(const std::string& message) { std::cerr << "kiln: error: " << message << "\n"; }

void printWarning(const std::string& message) { std::cerr << "kiln: warning: " << message << "\n"; }

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
