// gltf_loader.h: glTF 2.0 (.gltf + .bin, .glb) to kiln's Scene, through tinygltf.
//
// Safe for untrusted input: every index, count, offset and value is checked, and the first
// problem becomes an Error naming the file and the glTF element (e.g. "box.gltf:
// accessors[7]: ..."). Problems that can be repaired are repaired and counted in
// Scene::warnings: NaN/Inf positions and zero-area triangles are dropped, missing normals
// generated, a missing texture image replaced by its factor.
#pragma once

#include <atomic>
#include <cstdint>
#include <functional>
#include <optional>
#include <span>
#include <string>
#include <vector>

#include "kiln/result.h"
#include "src/scene.h"

namespace kiln {

struct LoadOptions {
  bool loadTextures = true;  // false: skip image decoding (materials use their factors)
  bool loadSkyMap = true;    // false: leave an equirectangular sky map unloaded
  // Texture decoding can take tens of seconds on a big scene: called after each texture the
  // materials use is decoded, with how many are done and how many there are (the CLI's
  // progress line; the loader itself prints nothing).
  std::function<void(size_t done, size_t total)> textureProgress;
  // Polled before each texture is decoded; when it becomes true loading stops with an Error
  // "cancelled" (Ctrl-C).
  const std::atomic<bool>* cancel = nullptr;
  int scene = -1;            // the glTF scene to load; -1 = the file's default (`scene`, else 0)
};

Result<Scene> loadScene(const std::string& path, const LoadOptions& options = {});

// One accessor component at `p` as a double, for code that reads glTF buffers itself (the
// output glTF writer): `componentType` is glTF's (5120 BYTE ... 5126 FLOAT); normalized
// integers map to [0, 1] or [-1, 1] per glTF 2.0 (signed values clamped to -1). Only for
// accessors loadScene accepted: other component types are a programmer error.
double readGltfComponent(const uint8_t* p, int componentType, bool normalized);

// A glTF URI's percent-encoded bytes (RFC 3986 "%XX") decoded, for file access: the loader
// reads, and the output glTF writer copies, "my%20texture.png" as "my texture.png".
std::string percentDecode(const std::string& uri);

// The triangles a primitive's vertex indices make in glTF `mode` (4 TRIANGLES, 5
// TRIANGLE_STRIP, 6 TRIANGLE_FAN), in the primitive's own numbering and winding; nullopt for
// points and lines.
std::optional<std::vector<uvec3>> gltfTriangles(std::span<const uint32_t> indices, int mode);

}  // namespace kiln
