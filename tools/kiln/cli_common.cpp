// cli_common.cpp: the shared pieces of the kiln CLI (see cli_common.h).
#include "tools/kiln/cli_common.h"

#include <iostream>

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

}  // namespace kiln::cli
