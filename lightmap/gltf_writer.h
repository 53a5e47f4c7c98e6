// gltf_writer.h: the output glTF of `kiln bake`: the input document, edited, that references
// the lightmaps and carries generated lightmap UVs (docs/lightmap_outputs.md).
//
// Edits, and nothing else (unknown extensions and extras are kept as they are):
//   - root extras.kiln.lightmaps = the manifest's "lightmaps" array (index, size, files);
//   - every lightmapped node: extras.kiln.lightmap = {"index", "scaleOffset": [sx, sy, ox, oy]}
//     (atlasUV = uv1 x (sx, sy) + (ox, oy), glTF texture coordinates);
//   - every node whose lightmap UVs kiln generated gets a new mesh of its own (instancing
//     nodes get different UVs), rebuilt in the node's local space from the original
//     primitives' attributes (every attribute and morph target, gathered through
//     UnwrapResult::vertexRemap) with the new TEXCOORD_1; its data goes to a new buffer
//     "<scene>_lightmap_uv.bin";
//   - buffers and images keep their files: relative URIs are prefixed with the path from the
//     output directory to the input's directory (data: URIs are kept), and a .glb's binary
//     chunk becomes "<scene>.bin" beside the output.
// Builds everything in memory; lightmap_writer.cpp writes the files atomically.
#pragma once

#include <cstdint>
#include <nlohmann/json_fwd.hpp>
#include <string>
#include <utility>
#include <vector>

#include "lightmap/lightmap_baker.h"
#include "kiln/result.h"

namespace kiln {

struct OutputGltf {
  std::string fileName;  // "<scene>.gltf"
  std::string text;      // the glTF JSON
  // Binary files the document references, by file name (relative to the output directory).
  std::vector<std::pair<std::string, std::vector<uint8_t>>> binaries;
  std::vector<std::string> warnings;
};

// Builds the output glTF for `result`, baked from `scenePath`, to be written into `outDir`.
// `lightmaps` is the manifest's "lightmaps" array. Errors name the input file and element.
Result<OutputGltf> buildOutputGltf(const std::string& scenePath, const LightmapBakeResult& result,
                                   const nlohmann::json& lightmaps, const std::string& outDir);

}  // namespace kiln
