// lppv.cpp: LPPV at bake time (lppv.h): the automatic resolution rule, the parallel fill from a
// ProbeSet, Unity's L1 packing into an EXR atlas, and the JSON that describes the outputs.
#include "probes/lppv.h"

#include <algorithm>
#include <cassert>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <nlohmann/json.hpp>
#include <system_error>

#include "src/parallel.h"
#include "src/text_file.h"

namespace kiln {
namespace {

using Json = nlohmann::json;

bool finite(glm::vec3 v) { return std::isfinite(v.x) && std::isfinite(v.y) && std::isfinite(v.z); }

bool inside(glm::vec3 p, glm::vec3 lo, glm::vec3 hi) {
  return p.x >= lo.x && p.y >= lo.y && p.z >= lo.z && p.x <= hi.x && p.y <= hi.y && p.z <= hi.z;
}

// Probes used by some cell (merged near-duplicates keep a slot but are in no cell).
std::vector<bool> usedProbes(const ProbeSet& set) {
  std::vector<bool> used(set.positions.size(), false);
  for (const glm::ivec4& c : set.cells) {
    for (int k = 0; k < 4; ++k) {
      if (c[k] >= 0 && size_t(c[k]) < used.size()) used[size_t(c[k])] = true;
    }
  }
  return used;
}

Json vecJson(glm::vec3 v) { return Json::array({v.x, v.y, v.z}); }

const char* placementName(LppvPlacement p) {
  return p == LppvPlacement::kCellCorner ? "cellCorner" : "cellCenter";
}

}  // namespace

LppvAutoResolution autoLppvResolution(const ProbeSet& set, glm::vec3 boundsMin, glm::vec3 boundsMax,
                                      LppvPlacement placement, const LppvAutoSettings& settings) {
  assert(finite(boundsMin) && finite(boundsMax));
  assert(boundsMin.x < boundsMax.x && boundsMin.y < boundsMax.y && boundsMin.z < boundsMax.z);
  const glm::dvec3 extent = glm::dvec3(boundsMax) - glm::dvec3(boundsMin);
  const int minN = placement == LppvPlacement::kCellCorner ? 2 : 1;
  const int maxN = std::clamp(settings.maxResolution, minN, kLppvMaxAxis);

  LppvAutoResolution r;
  const std::vector<bool> used = usedProbes(set);
  size_t usedCount = 0;
  glm::dvec3 lo(std::numeric_limits<double>::infinity()), hi(-lo);
  for (size_t i = 0; i < used.size(); ++i) {
    if (!used[i]) continue;
    ++usedCount;
    lo = glm::min(lo, glm::dvec3(set.positions[i]));
    hi = glm::max(hi, glm::dvec3(set.positions[i]));
    if (inside(set.positions[i], boundsMin, boundsMax)) ++r.probesInBounds;
  }
  if (r.probesInBounds > 0) {
    r.probeSpacing = std::cbrt(extent.x * extent.y * extent.z / double(r.probesInBounds));
  } else if (usedCount > 0) {
    r.wholeSetDensity = true;
    const glm::dvec3 e = hi - lo;
    const double largest = std::max(e.x, std::max(e.y, e.z));
    double product = 1.0;
    int spanned = 0;
    for (int a = 0; a < 3; ++a) {
      if (e[a] > 1e-3 * largest) {
        product *= e[a];
        ++spanned;
      }
    }
    if (spanned > 0) r.probeSpacing = std::pow(product / double(usedCount), 1.0 / spanned);
  }
  for (int a = 0; a < 3; ++a) {
    int n = minN;
    if (r.probeSpacing > 0.0 && settings.samplesPerProbeSpacing > 0.0) {
      const double step = r.probeSpacing / settings.samplesPerProbeSpacing;
      const double k = std::ceil(extent[a] / step - 1e-6);
      // Clamp in double first: a tiny step must not overflow the int conversion.
      const double cells = std::min(k, double(kLppvMaxAxis));
      n = int(cells) + (placement == LppvPlacement::kCellCorner ? 1 : 0);
    }
    r.resolution[a] = std::clamp(n, minN, maxN);
  }
  return r;
}

Status validateLppvBuildSettings(const LppvBuildSettings& s) {
  if (!finite(s.boundsMin) || !finite(s.boundsMax)) return Error{"bounds: not finite"};
  static const char* kAxis[3] = {"x", "y", "z"};
  for (int a = 0; a < 3; ++a) {
    if (!(s.boundsMax[a] > s.boundsMin[a]) ||
        !std::isfinite(1.0f / (s.boundsMax[a] - s.boundsMin[a]))) {
      return Error{std::string("bounds: max.") + kAxis[a] + " must exceed min." + kAxis[a]};
    }
  }
  if (s.resolution) {
    uint64_t cells = 1;
    for (int a = 0; a < 3; ++a) {
      const int n = (*s.resolution)[a];
      if (n < 1 || n > kLppvMaxAxis) {
        return Error{std::string("resolution.") + kAxis[a] + ": " + std::to_string(n) +
                     " is not in [1, " + std::to_string(kLppvMaxAxis) + "]"};
      }
      cells *= uint64_t(n);
    }
    if (cells > kLppvMaxCells) {
      return Error{"resolution: " + std::to_string(cells) + " cells, more than " +
                   std::to_string(kLppvMaxCells)};
    }
  }
  if (!(s.autoSettings.samplesPerProbeSpacing > 0.0) ||
      !std::isfinite(s.autoSettings.samplesPerProbeSpacing)) {
    return Error{"samplesPerProbeSpacing: must be a positive number"};
  }
  if (s.autoSettings.maxResolution < 1) return Error{"maxResolution: must be at least 1"};
  return Status::success();
}

Result<LppvBuild> buildLppvFromProbes(const ProbeSet& set, const LppvBuildSettings& settings) {
  if (Status st = validateLppvBuildSettings(settings); !st) return Error{st.error()};
  if (set.positions.empty() || set.cells.empty()) return Error{"probes: empty probe set"};
  LppvBuild build;
  glm::ivec3 resolution;
  if (settings.resolution) {
    resolution = *settings.resolution;
  } else {
    build.autoResolution = autoLppvResolution(set, settings.boundsMin, settings.boundsMax,
                                              settings.placement, settings.autoSettings);
    resolution = build.autoResolution->resolution;
  }
  build.volume =
      makeLppvVolume(settings.boundsMin, settings.boundsMax, resolution, settings.placement);
  LppvVolume& volume = build.volume;
  const size_t rows = size_t(resolution.y) * size_t(resolution.z);
  ParallelOptions options;
  options.threads = settings.threads;
  options.grain = std::max<size_t>(1, 256 / size_t(resolution.x));  // ~256 samples per task
  parallelFor(
      rows, [&](size_t begin, size_t end) { fillLppvRows(set, volume, begin, end); }, options);
  return build;
}

std::vector<glm::vec3> lppvSamplePositions(const LppvVolume& v) {
  std::vector<glm::vec3> positions;
  positions.reserve(v.cellCount());
  for (int z = 0; z < v.resolution.z; ++z) {
    for (int y = 0; y < v.resolution.y; ++y) {
      for (int x = 0; x < v.resolution.x; ++x) positions.push_back(v.samplePosition(x, y, z));
    }
  }
  return positions;
}

UnityShL1 packUnityShL1(const ShL2Rgb& radiance, ShAxes axes) {
  // packUnitySh9 of the L1 part: with band 2 zero, its SHA carries no folded Y20 constant.
  ShL2Rgb l1;
  for (int i = 0; i < kShL1Count; ++i) l1.c[i] = radiance.c[i];
  const UnitySh9 p = packUnitySh9(l1, axes);
  return UnityShL1{p.shAr, p.shAg, p.shAb};
}

glm::vec3 evalUnityShL1(const UnityShL1& p, glm::vec3 n) {
  const glm::vec4 n1(n, 1.0f);
  return glm::vec3(glm::dot(p.shAr, n1), glm::dot(p.shAg, n1), glm::dot(p.shAb, n1));
}

Image lppvUnityL1Image(const LppvVolume& v, ShAxes axes) {
  const int nx = v.resolution.x, ny = v.resolution.y, nz = v.resolution.z;
  Image image(4 * nx, ny * nz, 4);
  for (int z = 0; z < nz; ++z) {
    for (int y = 0; y < ny; ++y) {
      for (int i = 0; i < nx; ++i) {
        const int x = axes == ShAxes::kUnity ? nx - 1 - i : i;
        const UnityShL1 p = packUnityShL1(v.sh[v.cellIndex(x, y, z)], axes);
        // Probe occlusion per shadowmask channel (what Unity's 4th block holds).
        const int row = z * ny + y;
        const size_t cell = v.cellIndex(x, y, z);
        const glm::vec4 occlusion =
            v.occlusion.size() == v.cellCount() ? v.occlusion[cell] : glm::vec4(1.0f);
        const glm::vec4 blocks[4] = {p.shAr, p.shAg, p.shAb, occlusion};
        for (int b = 0; b < 4; ++b) {
          float* px = image.at(b * nx + i, row);
          for (int c = 0; c < 4; ++c) px[c] = blocks[b][c];
        }
      }
    }
  }
  return image;
}

Result<LppvOutputFiles> writeLppvOutputs(const LppvVolume& volume, const std::string& prefix,
                                         const LppvOutputOptions& options) {
  if (Status st = validateLppvVolume(volume, prefix); !st) return Error{st.error()};
  LppvOutputFiles files{prefix + ".klppv", prefix + "_L1.exr", prefix + ".json"};
  if (Status st = writeLppvFile(volume, files.volume); !st) return Error{st.error()};
  if (Status st =
          writeExr(files.unityL1, lppvUnityL1Image(volume, options.axes), !options.halfFloat);
      !st) {
    return Error{st.error()};
  }

  const bool unity = options.axes == ShAxes::kUnity;
  const glm::vec3 l1Min =
      unity ? glm::vec3(-volume.boundsMax.x, volume.boundsMin.y, volume.boundsMin.z)
            : volume.boundsMin;
  const glm::vec3 l1Max =
      unity ? glm::vec3(-volume.boundsMin.x, volume.boundsMax.y, volume.boundsMax.z)
            : volume.boundsMax;
  const glm::ivec3 n = volume.resolution;
  const auto fileName = [](const std::string& p) {
    return std::filesystem::path(p).filename().string();
  };
  Json j;
  j["version"] = 1;
  j["kind"] = "kiln.lppv";
  j["bounds"] = {{"min", vecJson(volume.boundsMin)}, {"max", vecJson(volume.boundsMax)}};
  j["resolution"] = Json::array({n.x, n.y, n.z});
  j["placement"] = placementName(volume.placement);
  j["samplePosition"] = volume.placement == LppvPlacement::kCellCorner
                            ? "min + i (max - min) / (n - 1) per axis (the centre when n = 1)"
                            : "min + (i + 0.5) (max - min) / n per axis";
  j["files"] = {{"l2", fileName(files.volume)}, {"unityL1", fileName(files.unityL1)}};
  j["l2"] = {
      {"format",
       "klppv version " + std::to_string(kLppvFileVersion) + " (little-endian; see docs/lppv.md)"},
      {"cellOrder", "x fastest, then y, then z"},
      {"sh",
       "radiance SH, 9 coefficients x RGB, real orthonormal basis, glTF world axes; "
       "irradiance E(n) = sum A_l c_i Y_i(n), A = (pi, 2pi/3, pi/4)"},
      {"validity", "per cell, blended probe validity in [0, 1]"},
      {"occlusion", "per cell, RGBA = shadowmask channels 0-3: blended probe occlusion in [0, 1]"}};
  j["unityL1"] = {
      {"width", 4 * n.x},
      {"height", n.y * n.z},
      {"channels", "RGBA"},
      {"pixelType", options.halfFloat ? "half" : "float"},
      {"blocks", Json::array({"SHAr", "SHAg", "SHAb", "occlusion"})},
      {"layout",
       "texel (X, Y): block X / nx, sample (X % nx, Y % ny, Y / ny); image row 0 is "
       "y = 0, so rows in file order are Texture3D.SetPixels order of a "
       "(4 nx, ny, nz) texture"},
      {"evaluates", "per channel dot(SHAc, (n, 1)) = L1 irradiance / pi (E / pi)"},
      {"axes", unity ? "unity" : "gltf"},
      {"xMirrored", unity},
      {"bounds", {{"min", vecJson(l1Min)}, {"max", vecJson(l1Max)}}},
      {"occlusion",
       "RGBA = shadowmask channels 0-3: fraction of the channel's light unshadowed (probe "
       "occlusion blended like the SH; 1 for unused channels)"}};
  Json source = Json::object();
  if (!options.source.empty()) source["probes"] = options.source;
  if (options.autoResolution) {
    const LppvAutoResolution& a = *options.autoResolution;
    source["resolutionMode"] = "auto";
    source["probeSpacing"] = a.probeSpacing;
    source["probesInBounds"] = a.probesInBounds;
    source["wholeSetDensity"] = a.wholeSetDensity;
  } else {
    source["resolutionMode"] = "custom";
  }
  j["source"] = std::move(source);
  if (Status st = writeTextFileAtomically(files.metadata, j.dump(2) + "\n"); !st) {
    return Error{st.error()};
  }
  return files;
}

}  // namespace kiln
