// manifest.h: kiln bake's manifest.json (docs/lightmap_outputs.md "manifest.json"): its one
// in-memory form (Manifest), its one writer (manifestText) and its one reader (readManifest,
// readManifestFile). Everything that reads a manifest (--lock-atlas, the preview renderer)
// goes through the reader, so there is one set of checks.
//
// Frames: scaleOffset is Unity's unity_LightmapST in glTF texture coordinates (v down from
// the top-left, (0, 0) = the first image row): atlasUV = uv1 * (sx, sy) + (ox, oy).
#pragma once

#include <cstdint>
#include <nlohmann/json.hpp>
#include <optional>
#include <string>
#include <vector>

#include "kiln/result.h"
#include "kiln/sh.h"
#include "src/light_modes.h"
#include "src/math.h"

namespace kiln {

struct AtlasLayout;
struct LightmapBakeResult;
struct Scene;

inline constexpr int kManifestVersion = 1;
// Largest page width and height a manifest may give, texels. Bounds the texel arithmetic of
// its readers (a page of 65536^2 texels already has 2^32 of them).
inline constexpr int kMaxManifestPageSize = 65536;

// One page's files, names relative to the manifest's folder; empty: not written.
struct ManifestFiles {
  std::string light;       // RGB half EXR, E / pi (always written)
  std::string ao;          // ambient occlusion EXR
  std::string direction;   // directional mode EXR
  std::string shadowmask;  // shadowmask EXR
  std::string coverage;    // visible footprint coverage EXR (--coverage-map)
  std::string lightLdr;    // 8-bit PNG of `light` (RGBM or dLDR)
};

struct ManifestPage {
  int width = 0, height = 0;  // texels, 1..kMaxManifestPageSize
  ManifestFiles files;
};

struct ManifestObject {
  std::string node;                          // the glTF node's name
  int nodeIndex = -1;                        // the glTF node index, >= 0
  int lightmapIndex = -1;                    // page, or -1: no lightmap
  vec4 scaleOffset{1.0f, 1.0f, 0.0f, 0.0f};  // (sx, sy, ox, oy), finite
  // Lightmapped by its settings but too small for a useful lightmap at the bake's resolution
  // (atlas.h, minObjectTexels): lit by probes instead, lightmapIndex -1. Written as
  // "probeLit": true, and only then.
  bool probeLit = false;
  // A probe-lit object's own light (lightmap/probe_lit.h), written as "probeSH": 27 numbers,
  // the 9 radiance SH coefficients of kiln's basis (MISSION.md) in order, each as R, G, B
  // (three.js's SphericalHarmonics3.fromArray order); irradiance E(n) = probeIrradiance(sh, n).
  std::optional<ShL2Rgb> probeSh{};
  // Its shadowmask occlusion (4 channels in [0, 1]), written as "probeOcclusion" when some
  // light has a shadowmask channel.
  std::optional<vec4> probeOcclusion{};
};

// One scene light and what the bake's lighting mode did with it (docs/mixed_lighting.md).
struct ManifestLight {
  std::string name;
  int lightIndex = -1;  // KHR_lights_punctual light index
  int nodeIndex = -1;
  std::string mode;  // "baked", "mixed" or "realtime", as the glTF gives it
  std::optional<bool> bakedDirect, bakedIndirect;
  std::optional<int> shadowmaskChannel;  // 0..3, or -1: none
};

// Unity's Renderer.lightmapScaleOffset (unity_LightmapST) for a manifest scaleOffset, in
// Unity's v-up texture convention: (sx, sy, ox, 1 - sy - oy). Why: glTF texture coordinates
// have v down from the top-left, Unity's v up from the bottom-left. Unity's glTF importers
// (glTFast, UnityGLTF) flip v of mesh UVs, uv1_u = (u, 1 - v), and a texture's first image
// row (the top of the file, glTF v = 0) is Unity's v = 1, so a page point at glTF atlas
// coordinate a_g is at Unity's a_u = (a_g.x, 1 - a_g.y). With a_g = uv1 * s + o:
//   1 - a_g.y = 1 - (v sy + oy) = (1 - v) sy + (1 - sy - oy),
// i.e. a_u = uv1_u * (sx, sy) + (ox, 1 - sy - oy): the scale and ox are unchanged. Computed in
// double and rounded once to float.
vec4 unityLightmapScaleOffset(vec4 scaleOffset);

// The settings fields that kiln's readers use, checked by the reader (absent: not given).
// The writer does not look at these: it writes Manifest::settings as it is.
struct ManifestSettingsFields {
  std::optional<float> resolution;         // > 0, finite
  std::optional<int> padding;              // 0..kMaxManifestPageSize
  std::optional<int> maxSize;              // 1..kMaxManifestPageSize
  std::optional<int> bounces;              // 0..2^20
  std::optional<float> albedoBoost;        // > 0
  std::optional<float> indirectIntensity;  // >= 0
  std::optional<LightingMode> lightingMode;
  std::optional<vec3> shadowColor;  // finite
  // true: the output glTF's TEXCOORD_1 is the atlas UV (kiln bake --atlas-uv), so a reader of
  // that glTF applies no scaleOffset (a reader of the input scene still does).
  std::optional<bool> atlasUv;
};

struct ManifestStats {
  uint64_t texels = 0, invalidTexels = 0, rays = 0;
  // Light texels set to 0 by the baker's final guard (LightmapBakeStats::clampedTexels).
  uint64_t clampedTexels = 0;
  // Paths per texel (adaptive sampling spends them unevenly): "samplesPerTexel":
  // {"min", "mean", "max"}, and "raysPerTexel": texels whose light stage traced
  // [2^b, 2^(b+1)) rays, b = 0, 1, ... (trailing empty buckets left out).
  uint64_t minSamples = 0, maxSamples = 0;
  double meanSamples = 0.0;
  std::vector<uint64_t> raysPerTexelHistogram;
};

struct Manifest {
  int version = kManifestVersion;
  std::vector<ManifestPage> lightmaps;  // page i has "index" i
  std::vector<ManifestObject> objects;  // one per glTF node with a mesh, in the loader's order
  nlohmann::json settings = nlohmann::json::object();  // written as it is
  ManifestSettingsFields settingsFields;               // filled by the reader from `settings`
  std::optional<std::vector<ManifestLight>> lights;    // absent in hand-written manifests
  std::optional<std::string> gltf;                     // the output glTF's file name
  std::string scene;                                   // the input scene's file name
  std::vector<std::string> warnings;
  ManifestStats stats;
};

// The manifest of a bake without its files, settings and glTF: pages (sizes), objects (from
// the atlas), scene lights with what the lighting mode baked of each, the scene's file name,
// the bake's warnings and stats.
Manifest bakeManifest(const LightmapBakeResult& result, const std::string& scenePath);

// Pages and objects of `layout` for `scene` (objects without a lightmap: lightmapIndex -1).
Manifest atlasManifest(const AtlasLayout& layout, const Scene& scene);

// The writer: the manifest as JSON, and as the text kiln writes (2-space indent, a final
// newline). Keys: version, lightmaps [{index, width, height, files}], objects [{node,
// nodeIndex, lightmapIndex, scaleOffset, unityScaleOffset}], settings, lights, gltf (when set),
// scene, warnings, stats.
nlohmann::json manifestJson(const Manifest& manifest);
std::string manifestText(const Manifest& manifest);
// The "lightmaps" array alone (index, width, height, files), as the output glTF repeats it.
nlohmann::json manifestPagesJson(const Manifest& manifest);

// What a reader needs of a manifest.
enum class ManifestUse {
  // The atlas (--lock-atlas): page sizes and objects; "version" and page files are checked
  // when present but may be absent.
  kAtlas,
  // The lightmaps themselves: also "version" 1 and every page's files.light.
  kLightmaps,
};

// The reader: checks `json` and returns its Manifest. Errors name `where` (the file) and the
// field: "out/manifest.json: objects[3].scaleOffset: expected 4 finite numbers [sx, sy, ox,
// oy]". The checks: an object with arrays "lightmaps" and "objects"; version 1; each page's
// "index" unique in [0, pages), "width" and "height" integers in 1..kMaxManifestPageSize and
// no larger than settings.maxSize when that is given, its "files" an object of file names
// (plain relative names: no absolute path, no ".."); each object's "node" a string,
// "nodeIndex" an integer in [0, 2^31) listed once, "lightmapIndex" -1 or a page, "scaleOffset"
// 4 finite floats (required with a page); settings' fields of ManifestSettingsFields in
// range; "lights" entries with their types and shadowmaskChannel -1..3; "warnings" strings;
// "stats" non-negative integers. Other keys are ignored.
Result<Manifest> readManifest(const nlohmann::json& json, const std::string& where,
                              ManifestUse use);
// Reads and checks the file `path` (errors start with `path`).
Result<Manifest> readManifestFile(const std::string& path, ManifestUse use);

}  // namespace kiln
