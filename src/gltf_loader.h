// gltf_loader.h: glTF 2.0 (.gltf + .bin, .glb) to kiln's Scene, through tinygltf.
//
// Safe for untrusted input: every index, count, offset and value is checked, and the first
// problem becomes an Error naming the file and the glTF element (e.g. "box.gltf:
// accessors[7]: ..."). Problems that can be repaired are repaired and counted in
// Scene::warnings: NaN/Inf positions and zero-area triangles are dropped, missing normals
// generated, a missing texture image replaced by its factor.
#pragma once

#include <string>

#include "src/result.h"
#include "src/scene.h"

namespace kiln {

struct LoadOptions {
  bool loadTextures = true;  // false: skip image decoding (materials use their factors)
  bool loadSkyMap = true;    // false: leave an equirectangular sky map unloaded
};

Result<Scene> loadScene(const std::string& path, const LoadOptions& options = {});

}  // namespace kiln
