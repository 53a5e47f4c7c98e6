// lppv_volume.h: light probe proxy volumes (LPPV, as Unity calls them) at run time: a 3D grid
// of L2 SH over an axis-aligned box, sampled per point with trilinear filtering, and the
// .klppv file that carries a baked grid from `kiln probes lppv` to a game.
//
// A large dynamic object lit from one blended probe looks flat; a volume over its bounds gives
// every pixel its own lighting. The grid is filled from the probe field (tetrahedral
// interpolation, Cupisz 2012) at bake time, or again at run time when the object has moved
// (fillLppvFromProbes, what Unity's "Refresh Mode: Every Frame" does), and sampled like a 3D
// texture with clamp-to-edge trilinear filtering (what a GPU does with the packed L1 texture,
// see docs/lppv.md).
#pragma once

#include <array>
#include <cstdint>
#include <glm/glm.hpp>
#include <span>
#include <string>
#include <string_view>
#include <vector>

#include "kiln/probe_set.h"
#include "kiln/result.h"
#include "kiln/sh.h"

namespace kiln {

// Where the grid samples sit inside the bounds [min, max], per axis with n samples:
//   kCellCenter: the box is cut into n cells and sample i sits at the centre of cell i,
//                min + (i + 0.5) (max - min) / n, as texels of a 3D texture stretched over the
//                box (Unity's LPPV). Between the outermost samples and the faces of the box
//                the value is held constant (clamp to edge).
//   kCellCorner: sample i sits at min + i (max - min) / (n - 1): the outermost samples lie
//                on the faces of the box, so the whole box is interpolated (needs n >= 2;
//                an axis with n = 1 puts its one sample at the centre of the box).
enum class LppvPlacement : uint32_t { kCellCenter = 0, kCellCorner = 1 };

// A grid of radiance SH over an axis-aligned world-space box. Plain data: const access from
// many threads is safe.
//
// Memory layout: cell (x, y, z) is at index x + nx (y + ny z) (x fastest) in `sh` and
// `validity`. `sh` holds RADIANCE SH in kiln's basis (kiln/sh.h: c_i = int L Y_i dw, glTF world
// axes); irradiance is probeIrradiance(sh, n) = E (not E / pi). `validity` is the blend of
// the probes' validity with the interpolation weights: 1 where every probe the cell draws on
// is valid, less where some lie inside geometry (a quality mask, not light occlusion).
// `occlusion` is the probes' shadowmask occlusion (ProbeSet::occlusion, channel c for the
// light ProbeSet::occlusionLights[c]) blended with the same weights: empty = 1 everywhere.
struct LppvVolume {
  glm::vec3 boundsMin{0.0f};  // world space, metres; boundsMin < boundsMax on every axis
  glm::vec3 boundsMax{1.0f};
  glm::ivec3 resolution{1};  // samples per axis, each in [1, kLppvMaxAxis]
  LppvPlacement placement = LppvPlacement::kCellCenter;
  std::vector<ShL2Rgb> sh;  // cellCount() entries
  std::vector<float> validity;
  std::vector<glm::vec4> occlusion;  // cellCount() entries in [0, 1], or empty

  size_t cellCount() const {
    return size_t(resolution.x) * size_t(resolution.y) * size_t(resolution.z);
  }
  size_t cellIndex(int x, int y, int z) const {
    return size_t(x) + size_t(resolution.x) * (size_t(y) + size_t(resolution.y) * size_t(z));
  }
  // World-space position of sample (x, y, z) (see LppvPlacement).
  glm::vec3 samplePosition(int x, int y, int z) const;
};

// Largest resolution per axis the file format and the loader accept.
inline constexpr int kLppvMaxAxis = 1024;
// Largest cell count the loader accepts (x * y * z).
inline constexpr uint64_t kLppvMaxCells = uint64_t(1) << 24;

// An empty (zero SH, validity 1, occlusion 1) volume with the given box, resolution and
// placement, sized for fillLppvFromProbes. Asserts the arguments are valid (see
// validateLppvVolume).
LppvVolume makeLppvVolume(glm::vec3 boundsMin, glm::vec3 boundsMax, glm::ivec3 resolution,
                          LppvPlacement placement);

// Checks what sampling relies on: resolution in range, finite bounds with min < max, sizes
// agree with the resolution, SH finite, validity and occlusion (when present) in [0, 1].
// Messages read "<name>: <field>[i]: problem". Safe for untrusted data.
Status validateLppvVolume(const LppvVolume& volume, std::string_view name);

// ---------------------------------------------------------------------------------------------
// Sampling
// ---------------------------------------------------------------------------------------------

// The 8 cells around a point and their trilinear weights (>= 0, summing to 1), cells[k] for
// corner k = (k & 1, k >> 1 & 1, k >> 2 & 1) of the surrounding sample cube. On an axis with
// one sample, or outside the outermost samples, both corners of that axis are the same cell
// (clamp to edge), so a caller may blend all 8 blindly.
struct LppvTrilinear {
  std::array<uint32_t, 8> cells{};
  std::array<float, 8> weights{};
};

// Trilinear cells and weights at world-space point p: p maps to the continuous grid
// coordinate f = (p - min) / (max - min) n - 0.5 (kCellCenter) or (p - min) / (max - min)
// (n - 1) (kCellCorner), clamped to [0, n - 1] per axis (NaN counts as 0). noexcept, no
// allocation. The volume must be valid (validateLppvVolume).
LppvTrilinear locateLppv(const LppvVolume& volume, glm::vec3 p) noexcept;

// Radiance SH at p: the trilinear blend of the 8 surrounding samples.
ShL2Rgb sampleLppv(const LppvVolume& volume, glm::vec3 p) noexcept;
// Validity at p (same blend).
float sampleLppvValidity(const LppvVolume& volume, glm::vec3 p) noexcept;
// Shadowmask occlusion at p (same blend; 1 when the volume has none).
glm::vec4 sampleLppvOcclusion(const LppvVolume& volume, glm::vec3 p) noexcept;
// Irradiance E (not E / pi) at p for unit normal n: probeIrradiance(sampleLppv(p), n).
glm::vec3 lppvIrradiance(const LppvVolume& volume, glm::vec3 p, glm::vec3 n) noexcept;

// Batch form: out[i] = sampleLppv(volume, points[i]); `out` must have points.size() entries.
void sampleLppv(const LppvVolume& volume, std::span<const glm::vec3> points,
                std::span<ShL2Rgb> out) noexcept;

// ---------------------------------------------------------------------------------------------
// Filling from the probe field
// ---------------------------------------------------------------------------------------------

// Sets the cells of grid rows [rowBegin, rowEnd) (row r = y + ny z holds cells x = 0..nx-1)
// to the probe field at their sample positions: sampleProbes's tetrahedral interpolation
// (outer cells outside the hull), validity and occlusion (interpolateOcclusion; only when
// volume.occlusion is sized) blended with the same weights and clamped to [0, 1]. Each row
// starts its walk from the seed grid and every further lookup from the previous sample's
// cell, so a row costs about one step per sample, and a row's values do not depend on how the
// rows are split. noexcept, no allocation: `volume` must already be sized
// (makeLppvVolume) and `set` valid. Disjoint row ranges may be filled from different threads.
void fillLppvRows(const ProbeSet& set, LppvVolume& volume, size_t rowBegin, size_t rowEnd) noexcept;

// All rows: re-fills the volume where it now is (move it by changing its bounds first).
inline void fillLppvFromProbes(const ProbeSet& set, LppvVolume& volume) noexcept {
  fillLppvRows(set, volume, 0, size_t(volume.resolution.y) * size_t(volume.resolution.z));
}

// ---------------------------------------------------------------------------------------------
// .klppv file
// ---------------------------------------------------------------------------------------------
//
// .klppv, version 2, little-endian:
//   header (64 bytes): "KLPV", u32 version, u32 resolution[3], u32 placement (0 cell centre,
//     1 cell corner), f32 boundsMin[3], f32 boundsMax[3], u32 reserved[2] = 0,
//     u64 checksum = FNV-1a 64 of header bytes [0, 56) followed by the whole payload;
//   payload: f32 sh[cellCount][9][3] (cells x fastest, then y, then z; coefficient-major,
//     RGB innermost: radiance SH in kiln's basis), f32 validity[cellCount],
//     f32 occlusion[cellCount][4] (version 2 on: shadowmask occlusion per channel, in [0, 1]);
//   so the file is exactly 64 + 128 cellCount bytes (version 1: 64 + 112 cellCount, no
//   occlusion; the reader accepts it and gives occlusion 1).
inline constexpr uint32_t kLppvFileVersion = 2;
inline constexpr uint32_t kLppvFileMinVersion = 1;
inline constexpr size_t kLppvFileHeaderSize = 64;
inline constexpr size_t kLppvFileChecksumOffset = 56;  // the header's checksum field

// Serialization (no validation: writes what it is given, so tests can craft bad files).
// `version` 1 drops the occlusion; an empty `occlusion` is written as 1.
std::vector<uint8_t> serializeLppvVolume(const LppvVolume& volume,
                                         uint32_t version = kLppvFileVersion);
// Parses and validates a whole file image; `name` prefixes messages. Allocates only after the
// header's counts have been checked against the input size. Safe for untrusted input.
Result<LppvVolume> parseLppvVolume(std::span<const uint8_t> bytes, std::string_view name);

// Writes `path` atomically (to path + ".tmp", then rename).
Status writeLppvFile(const LppvVolume& volume, const std::string& path);
// Reads and validates `path`; messages name the file and the field.
Result<LppvVolume> loadLppvFile(const std::string& path);

}  // namespace kiln
