// gltf_writer.h: the output glTF of `kiln bake`: the input document, edited, that references
// the lightmaps and carries generated lightmap UVs (docs/lightmap_outputs.md).
//
// Edits, and nothing else (unknown extensions and extras are kept as they are):
//   - root extras.kiln.lightmaps = the manifest's "lightmaps" array (index, size, files);
//   - one glTF image per lightmap page (its LDR PNG, image/png), one texture per page and one
//     sampler (LINEAR, no mipmaps, CLAMP_TO_EDGE);
//   - every lightmapped node: the node-level extension MX_lightmap = {"lightMapTexture":
//     {"index", "texCoord": 1}, "scale", "offset", "intensity", "extras": {"kiln": {"page",
//     "encoding", "range"}}} (listed in extensionsUsed), and extras.kiln.lightmap =
//     {"index", "scaleOffset": [sx, sy, ox, oy]} (atlasUV = uv1 x (sx, sy) + (ox, oy), glTF
//     texture coordinates);
//   - every KHR_lights_punctual light a node instances: extras.kiln.baked (its direct light is
//     in the lightmaps: a viewer must not add it) and extras.kiln.mode; nodes whose instances
//     of one light differ get a copy of the light;
//   - every node whose lightmap UVs kiln generated gets a new mesh of its own (instancing
//     nodes get different UVs), rebuilt in the node's local space from the original
//     primitives' attributes (every attribute and morph target, gathered through
//     UnwrapResult::vertexRemap) with the new TEXCOORD_1; its data goes to a new buffer
//     "<scene>_lightmap_uv.bin";
//   - with atlasUv, TEXCOORD_1 holds atlas UVs (uv1 x scale + offset) and the transforms are
//     identity: nodes with their own TEXCOORD_1 get a new TEXCOORD_1 accessor (and a mesh of
//     their own when other nodes share theirs);
//   - the output is self-contained: buffers and images with file URIs are copied into the
//     output directory (relative paths inside the input's folder kept, others by file name,
//     clashes renamed "<name>_2.<ext>"), data: URIs kept; a .glb's binary chunk becomes
//     "<scene>.bin". With glb, everything goes into one .glb instead: every buffer merged into
//     its BIN chunk, every image (the lightmap PNGs too) a bufferView with its mimeType.
// Builds everything in memory (files to copy are named, not read, except for a .glb);
// lightmap_writer.cpp writes the files atomically.
#pragma once

#include <cstdint>
#include <nlohmann/json_fwd.hpp>
#include <string>
#include <utility>
#include <vector>

#include "lightmap/lightmap_baker.h"
#include "lightmap/lightmap_writer.h"
#include "kiln/result.h"

namespace kiln {

inline constexpr const char* kLightmapExtension = "MX_lightmap";

struct OutputGltfOptions {
  std::string outDir;
  LdrEncoding ldr = LdrEncoding::Dldr;  // the encoding of the LDR pages (not None)
  std::vector<std::string> ldrPages;    // per lightmap page: its LDR PNG's file name in outDir
  std::vector<std::vector<uint8_t>> ldrPngs;  // per page: the PNG's bytes (needed for glb)
  bool atlasUv = false;  // TEXCOORD_1 = atlas UV, identity scale/offset
  bool glb = false;      // one self-contained "<scene>.glb"
  // Other files written into outDir (EXR pages, manifest.json, ...): copied buffers and
  // images never take these names.
  std::vector<std::string> reservedNames;
};

struct OutputGltf {
  std::string fileName;           // "<scene>.gltf" or "<scene>.glb"
  std::vector<uint8_t> contents;  // the glTF JSON, or the whole .glb
  // Binary files the document references, by file name (relative to the output directory).
  std::vector<std::pair<std::string, std::vector<uint8_t>>> binaries;
  // Files to copy into the output directory: (name relative to it, source path).
  std::vector<std::pair<std::string, std::string>> copies;
  std::vector<std::string> warnings;
};

// MX_lightmap's intensity for an encoding: irradiance E = intensity x the sample as a plain
// MX_lightmap reader uses it (dLDR: 2 pi, the sRGB-decoded rgb spans E/pi / 2; RGBM: pi, after
// the reader's own rgb x a x 8 decode). docs/lightmap_outputs.md, "The output glTF".
double lightmapIntensity(LdrEncoding encoding);

// Builds the output glTF for `result`, baked from `scenePath`. `lightmaps` is the manifest's
// "lightmaps" array. Errors name the input file and element.
Result<OutputGltf> buildOutputGltf(const std::string& scenePath, const LightmapBakeResult& result,
                                   const nlohmann::json& lightmaps,
                                   const OutputGltfOptions& options);

}  // namespace kiln
