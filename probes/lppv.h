// lppv.h: building light probe proxy volumes (LPPV) at bake time and writing them out: the
// automatic resolution rule, the fill from a ProbeSet (in parallel over grid rows), Unity's L1
// packing (SHAr, SHAg, SHAb + probe occlusion) as an EXR atlas, and the JSON description.
//
// The runtime side (the grid type, trilinear sampling, the .klppv file) is
// probes/runtime/include/kiln/lppv_volume.h; docs/lppv.md documents every output and the
// shader-side decode.
#pragma once

#include <glm/glm.hpp>
#include <optional>
#include <string>
#include <vector>

#include "kiln/lppv_volume.h"
#include "kiln/probe_set.h"
#include "src/image.h"
#include "kiln/result.h"
#include "kiln/sh.h"
#include "src/sh_projection.h"

namespace kiln {

// ---------------------------------------------------------------------------------------------
// Resolution
// ---------------------------------------------------------------------------------------------

struct LppvAutoSettings {
  // Grid samples per probe spacing along each axis (1: the volume holds about as many
  // samples as there are probes in its bounds, and no more detail than they carry).
  double samplesPerProbeSpacing = 1.0;
  // Cap per axis (32 is Unity's LPPV maximum).
  int maxResolution = 32;
};

struct LppvAutoResolution {
  glm::ivec3 resolution{1};
  double probeSpacing = 0.0;     // s in metres (0: the probe set has no measurable density)
  int probesInBounds = 0;        // m below
  bool wholeSetDensity = false;  // no probe in the bounds: the whole set's density was used
};

// Resolution from the density of the probes ("automatic" in Unity's LPPV). The rule:
//   1. Count the m probes (those used by some cell: merged duplicates are not counted)
//      inside the closed bounds box B, of volume V = ex ey ez.
//   2. m >= 1: the mean probe spacing is s = cbrt(V / m).
//      m == 0: the whole set's spacing: with E the box around all N used probes, the axes
//      whose extent exceeds 1e-3 x its largest extent are spanned (d of them, so flat and
//      linear layouts work), and s = (product of the spanned extents / N)^(1/d); d == 0 (a
//      single position) gives no spacing and the minimum resolution.
//   3. The grid step is h = s / samplesPerProbeSpacing; per axis a with k = e_a / h:
//      cell centre n_a = ceil(k), cell corner n_a = ceil(k) + 1 (its samples span the box),
//      where ceil ignores 1e-6 of a sample (so k = 5 + rounding gives 5), then clamped to
//      [1 (centre) or 2 (corner), maxResolution].
// Bounds must be finite with min < max (asserted).
LppvAutoResolution autoLppvResolution(const ProbeSet& set, glm::vec3 boundsMin, glm::vec3 boundsMax,
                                      LppvPlacement placement,
                                      const LppvAutoSettings& settings = {});

// ---------------------------------------------------------------------------------------------
// Building
// ---------------------------------------------------------------------------------------------

struct LppvBuildSettings {
  glm::vec3 boundsMin{0.0f};  // world space (glTF axes), metres
  glm::vec3 boundsMax{1.0f};
  std::optional<glm::ivec3> resolution;  // custom; empty = autoLppvResolution
  LppvPlacement placement = LppvPlacement::kCellCenter;
  LppvAutoSettings autoSettings;
  int threads = 0;  // 0 = all cores
};

struct LppvBuild {
  LppvVolume volume;
  std::optional<LppvAutoResolution> autoResolution;  // set when the resolution was automatic
};

// Checks the settings (bounds finite with min < max, custom resolution in
// [1, kLppvMaxAxis] with at most kLppvMaxCells cells); errors name the field.
Status validateLppvBuildSettings(const LppvBuildSettings& settings);

// A volume over the settings' box filled from the probe field: every sample gets the
// tetrahedral interpolation of the probes' radiance SH at its position (fillLppvRows; outer
// cells extrapolate outside the hull), the blended validity and the blended shadowmask
// occlusion. Rows run in parallel, each starting its walk from the seed grid, so the result
// is identical at any thread count.
// `set` must be valid (loadProbeFile / validateProbeSet).
Result<LppvBuild> buildLppvFromProbes(const ProbeSet& set, const LppvBuildSettings& settings);

// Sample positions of a volume in cell order (x fastest), for baking the grid directly: bake
// radiance SH at positions[i] into volume.sh[i] (and volume.validity[i]) instead of filling
// from the probes.
std::vector<glm::vec3> lppvSamplePositions(const LppvVolume& volume);

// ---------------------------------------------------------------------------------------------
// Unity L1 packing
// ---------------------------------------------------------------------------------------------

// The L1 part of Unity's SH9 packing, what Unity's LPPV texture holds and its shader's
// SHEvalLinearL0L1 evaluates: per channel c, dot(SHAc, (n, 1)) = E_L1(n) / pi, the L1
// irradiance (ShL1Rgb::irradiance, bands 0-1 only, A0 = pi, A1 = 2 pi / 3) over pi. So
//   SHAc.xyz = (2/3) 0.488603 (c3, c1, c2)   (x, y, z terms)
//   SHAc.w   = 0.282095 c0                   (constant)
// for radiance SH c (channel c). Unlike packUnitySh9's SHA, band 2's constant is not folded
// into w: an L1 volume is evaluated without SHB / SHC. Axes as packUnitySh9 (kUnity negates
// the x term).
struct UnityShL1 {
  glm::vec4 shAr{0.0f}, shAg{0.0f}, shAb{0.0f};
};
UnityShL1 packUnityShL1(const ShL2Rgb& radiance, ShAxes axes = ShAxes::kGltf);
// dot(SHAc, (n, 1)) per channel: E_L1(n) / pi for a unit normal in the packing's axes.
glm::vec3 evalUnityShL1(const UnityShL1& packed, glm::vec3 n);

// Unity's LPPV layout in one RGBA image: width 4 nx, height ny nz. Texel (X, Y) with
// block b = X / nx, column i = X % nx, slice z = Y / ny, row j = Y % ny holds grid sample
// (i, j, z) (image row 0 = y = 0: the rows in file order are Texture3D.SetPixels order,
// x fastest, then y, then z); block 0 = SHAr, 1 = SHAg, 2 = SHAb, 3 = probe occlusion,
// as the four quarters of unity_ProbeVolumeSH along x. Occlusion is volume.occlusion (the
// probes' shadowmask occlusion, channel c in component c; 1 when the volume has none).
// With ShAxes::kUnity the grid is also mirrored in x (column i holds sample nx - 1 - i), so
// it fits Unity's bounds (-max.x, min.y, min.z) to (-min.x, max.y, max.z).
Image lppvUnityL1Image(const LppvVolume& volume, ShAxes axes = ShAxes::kGltf);

// ---------------------------------------------------------------------------------------------
// Output files
// ---------------------------------------------------------------------------------------------

struct LppvOutputOptions {
  ShAxes axes = ShAxes::kGltf;  // axes of the Unity L1 EXR (the .klppv is always glTF)
  bool halfFloat = false;       // EXR channels as HALF instead of FLOAT
  std::string source;           // recorded in the JSON (e.g. the probe file's path)
  std::optional<LppvAutoResolution> autoResolution;  // recorded in the JSON when set
};

struct LppvOutputFiles {
  std::string volume;    // PREFIX.klppv  (L2, runtime file)
  std::string unityL1;   // PREFIX_L1.exr (lppvUnityL1Image)
  std::string metadata;  // PREFIX.json
};

// Writes PREFIX.klppv, PREFIX_L1.exr and, last, PREFIX.json (bounds, resolution, placement,
// file names relative to the JSON, the packing), each atomically (temporary file + rename).
// The volume must be valid.
Result<LppvOutputFiles> writeLppvOutputs(const LppvVolume& volume, const std::string& prefix,
                                         const LppvOutputOptions& options = {});

}  // namespace kiln
