// lightmap_writer.h: kiln bake's output files: OpenEXR pages, manifest.json, the output glTF.
//
// Files (MISSION.md "Output"): DIR/lightmap-<i>_light.exr (half RGB, E / pi, glTF
// orientation), DIR/lightmap-<i>_ao.exr when baked, 8-bit PNGs (RGBM or dLDR, ldr_encoding.h;
// always with the output glTF, whose MX_lightmap textures they are), DIR/manifest.json
// ({"version": 1, "lightmaps": [...], "objects": [...], "settings": {...}}) and
// DIR/<scene>.gltf (or .glb) with the lightmaps and generated TEXCOORD_1, self-contained
// (gltf_writer.h). Every file is written to a temporary name first and all are renamed only when
// all were written, so a failed or cancelled bake leaves earlier outputs intact.
#pragma once

#include <nlohmann/json_fwd.hpp>
#include <string>
#include <vector>

#include "lightmap/lightmap_baker.h"
#include "kiln/result.h"

namespace kiln {

enum class LdrEncoding { None, Rgbm, Dldr };

struct LightmapOutputSettings {
  std::string outDir;
  // The LDR pages' encoding. None: none without the output glTF, dLDR with it (the glTF's
  // lightmap textures are the LDR pages).
  LdrEncoding ldr = LdrEncoding::None;
  // Recorded in the manifest's "settings" (not used otherwise).
  std::string preset;       // quality preset applied, empty when none
  std::string kilnVersion;  // e.g. "0.1.0"
  std::string lockAtlas;    // the --lock-atlas manifest, empty when the atlas was packed
  bool writeGltf = true;    // false: no output glTF (the manifest alone places the lightmaps)
  bool atlasUv = false;     // the output glTF's TEXCOORD_1 = atlas UV (identity scale/offset)
  bool glb = false;         // one self-contained <scene>.glb instead of .gltf + files
};

// File names inside the output directory.
std::string lightmapFileName(int page, const char* kind);  // "lightmap-<page>_<kind>.exr"
inline constexpr const char* kManifestFileName = "manifest.json";

// The manifest's "settings" object for `settings` and `output`.
nlohmann::json lightmapSettingsJson(const LightmapBakeSettings& settings,
                                    const LightmapOutputSettings& output);

// Writes the outputs of `result`, baked from the glTF file `scenePath` with `settings`
// (recorded in the manifest). `warnings`, when given, receives the warnings the writing added
// to the manifest's (those of result.warnings excluded).
Status writeLightmapOutputs(const std::string& scenePath, const LightmapBakeResult& result,
                            const LightmapBakeSettings& settings,
                            const LightmapOutputSettings& output,
                            std::vector<std::string>* warnings = nullptr);

}  // namespace kiln
