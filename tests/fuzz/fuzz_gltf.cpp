// fuzz_gltf.cpp: libFuzzer harness for the glTF/.glb loader (src/gltf_loader.cpp).
//
// loadScene reads a path (its external buffers and images are resolved next to it), so each
// input is written to a file in a private, otherwise empty directory: "scene.glb" when it starts
// with the GLB magic, "scene.gltf" otherwise. The loader must return a Scene or an Error for
// every input; a crash, a sanitizer report, a leak, a timeout or running out of memory
// (libFuzzer's -rss_limit_mb, -timeout) is a finding. Images are decoded (they are part of
// what a hostile file can abuse); the sky map is loaded too.
#include <unistd.h>

#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <string>

#include "src/gltf_loader.h"

namespace {

std::string& workDir() {
  static std::string dir = [] {
    const char* tmp = std::getenv("TMPDIR");
    std::string pattern = std::string(tmp && *tmp ? tmp : "/tmp") + "/kiln-fuzz-gltf-XXXXXX";
    if (!mkdtemp(pattern.data())) std::abort();
    return pattern;
  }();
  return dir;
}

bool writeFile(const std::string& path, const uint8_t* data, size_t size) {
  std::FILE* f = std::fopen(path.c_str(), "wb");
  if (!f) return false;
  bool ok = std::fwrite(data, 1, size, f) == size;
  return std::fclose(f) == 0 && ok;
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  bool glb = size >= 4 && std::memcmp(data, "glTF", 4) == 0;
  std::string path = workDir() + (glb ? "/scene.glb" : "/scene.gltf");
  if (!writeFile(path, data, size)) std::abort();
  kiln::Result<kiln::Scene> scene = kiln::loadScene(path);
  // Touch the result so that the work cannot be optimized away.
  if (scene) {
    volatile size_t n = scene.value().objects.size() + scene.value().textures.size();
    (void)n;
  } else {
    volatile size_t n = scene.error().size();
    (void)n;
  }
  std::remove(path.c_str());
  return 0;
}
