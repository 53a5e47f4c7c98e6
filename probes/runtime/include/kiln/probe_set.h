// probe_set.h: the runtime light-probe data (flat arrays, as Godot's LightmapGI stores them)
// and the .kprobe file that carries it from the bake to a game.
//
// Layout (Cupisz, "Light probe interpolation using tetrahedral tessellations", GDC 2012):
// the probes are tetrahedralized (Delaunay); every triangle of the convex hull gets an "outer
// cell" that reaches to infinity, swept along the hull's vertex normals, so every point of
// space lies in exactly one cell and extrapolation outside the hull is continuous.
// Degenerate probe sets use the same arrays with a lower `dimension` (see ProbeSet).
#pragma once

#include <array>
#include <cstdint>
#include <span>
#include <string>
#include <string_view>
#include <vector>

#include <glm/glm.hpp>

#include "kiln/probe_visibility.h"
#include "kiln/result.h"
#include "kiln/sh.h"

namespace kiln {

// Extrapolation data of one outer cell (hull triangle A, B, C, outward-wound).
// For a point p outside, Cupisz finds t >= 0 such that p lies in the plane of the triangle
// A + t nA, B + t nB, C + t nC; that condition is the cubic a t^3 + b t^2 + c t + d = 0 whose
// coefficients are affine in q = p - A: (a, b, c, d)[i] = dot(cubic[i].xyz, q) + cubic[i].w.
// Dimension 2 (hull edges) uses normals[0] for the unit normal of the probes' plane (the same
// in every outer cell) and normals[1] for the edge's outward normal in that plane.
struct OuterCell {
  std::array<glm::vec3, 3> normals{};  // unit hull vertex normals of the cell's 3 probes
  std::array<glm::vec4, 4> cubic{};    // rows for a, b, c, d (see above)
};

// Uniform grid of seed cells over the probe bounds: the walk starts from seeds[cell of p]
// when the caller has no hint. Points outside the bounds use the nearest grid cell.
struct ProbeSeedGrid {
  glm::vec3 min{0.0f};
  glm::vec3 max{0.0f};
  glm::ivec3 size{0};            // grid cells per axis (0 when there is no grid)
  std::vector<int32_t> seeds;    // size.x * size.y * size.z cell indices, x fastest
};

// All runtime probe data. Positions are in glTF world space (metres); `sh` holds RADIANCE
// SH in kiln's basis (kiln/sh.h). Plain data: const access from many threads is safe.
//
// Cells by `dimension`:
//  3: cells [0, innerCellCount) are tetrahedra {p0, p1, p2, p3} with orient3d > 0; cells
//     [innerCellCount, size) are outer cells {a, b, c, -1}, a hull triangle wound so that
//     cross(b - a, c - a) points out of the hull. neighbours[c][k] is the cell across the face
//     opposite vertex k; for an outer cell, k = 3 (opposite the "vertex at infinity") is the
//     tetrahedron inside the hull, k < 3 the outer cell across the swept hull edge.
//  2: probes all lie in one plane. Inner cells are triangles {a, b, c, -1} (2D Delaunay in the
//     plane, wound alike), outer cells are hull edges {a, b, -1, -1}; neighbours[k] for k < 3
//     as above, and neighbours[2] of a hull edge is its triangle. Queries are projected onto
//     the plane; outside the hull they take the nearest point of the hull boundary.
//  1: probes all lie on one line. Cells are segments {a, b, -1, -1} ordered along the line;
//     neighbours {next, previous, -1, -1}. Queries are projected on the line and clamped.
//  0: a single distinct position: one cell {probe, -1, -1, -1}; every query gets that probe.
// Probes merged into another (near-duplicates) keep their slot in `positions` and `sh` but
// appear in no cell.
//
// Probe occlusion (Unity's "probe occlusion" for Shadowmask mixed lighting): occlusion[i][c]
// is the fraction of shadowmask channel c's light that reaches probe i unblocked, in [0, 1]
// (1 = fully lit, 0 = in its hard shadow; soft shadows give values between), as the
// shadowmask texture holds it for lightmapped surfaces. A dynamic object blends it with the
// same weights as the SH (interpolateOcclusion) and multiplies the light's realtime direct
// contribution by it beyond the realtime shadow distance. occlusionLights[c] is the scene
// light (index into the glTF's KHR_lights_punctual lights) that owns channel c, -1 for an
// unused channel, whose occlusion is always 1.
inline constexpr int kProbeOcclusionChannels = 4;

// Per-probe visibility for leak-free blending (kiln/probe_visibility.h): for probe i, an
// octahedral map of resolution x resolution texels, each {mu, sigma, far}: the depth of the
// first surface at the texel's centre direction, the RMS spread about the texel's plane fit,
// and the largest depth any of the texel's rays reached, all as fractions of maxDistance[i],
// stored as unorm16 (value / 65535). resolution 0 = no visibility (plain blending).
inline constexpr size_t kVisibilityValuesPerTexel = 3;
// Bytes the .kprobe visibility block holds per probe at `resolution`: its maxDistance (f32)
// and resolution^2 texels of kVisibilityValuesPerTexel unorm16 (0 for no visibility).
inline constexpr uint64_t visibilityBytesPerProbe(uint64_t resolution) {
  return resolution > 0 ? 4 + resolution * resolution * kVisibilityValuesPerTexel * 2 : 0;
}
struct ProbeVisibility {
  int32_t resolution = 0;
  std::vector<float> maxDistance;  // per probe, metres (> 0)
  std::vector<uint16_t> moments;   // probeCount x resolution^2 x 3, probe-major

  bool empty() const { return resolution == 0; }
  size_t valuesPerProbe() const {
    return kVisibilityValuesPerTexel * size_t(resolution) * size_t(resolution);
  }
  std::span<const uint16_t> probe(int32_t i) const {
    return {moments.data() + size_t(i) * valuesPerProbe(), valuesPerProbe()};
  }
};

// The sun layer (docs/probes.md, "Sun shadows"): sharp shadow edges of one baked directional
// light for objects lit by the probes. A probe's SH holds that light's direct light times
// visibility[i], the share of the light reaching probe i unblocked (in [0, 1]); blended, the
// light's share is the weights' mix of those, which smears a shadow edge over the cells that
// straddle it. The shadow of a straight edge under a directional light is bounded by a plane
// that contains the light's direction, so in a tetrahedron the light's share is well described
// by a ramp across one plane: S(p) = dot(b, ramps[cell]), where b is p's barycentric
// coordinates in the cell and ramps[cell][k] the ramp's (unclamped) value at the cell's
// vertex k. A visibility-weighted blend replaces the mixed share by S, clamped to the shares
// of the probes that see p: sh += (S - sum_k w_k visibility[probe_k]) * this->sh, where
// this->sh is the light's direct light at a fully lit point (a plain blend, which cannot tell
// a probe behind a wall, leaves the layer out). ramps[cell].x NaN = no ramp (the plain blend: edges that no plane fits, such as
// corners and stripes, or cells the light's share does not vary in). Outer cells have none.
// validateProbeSet's rules: light -1 with visibility and ramps empty, or light >= 0 (an index
// into the scene's lights, unbounded here like occlusionLights) with sh finite, visibility one
// value in [0, 1] per probe, ramps empty or one per inner cell of a dimension 3 set, each all
// four finite or all four NaN. Stored in .kprobe version 4 (below).
struct ProbeSunLayer {
  int32_t light = -1;  // the scene light (KHR_lights_punctual index); -1 = no layer
  ShL2Rgb sh;          // radiance SH of the light's direct light on a fully lit probe
  std::vector<float> visibility;  // per probe, in [0, 1]
  std::vector<glm::vec4> ramps;   // per inner cell (dimension 3) or empty, see above

  bool empty() const { return light < 0; }
};

// What one step of the walk through a tetrahedron reads, in one 64-byte record (derived from
// positions and cells by prepareProbeLookup; not stored in the .kprobe file): the barycentric
// coordinates of p in float, l_k = c_k + x[k] q.x + y[k] q.y + z[k] q.z with q = p - origin,
// origin = v0 and c = (1, 0, 0, 0), each lane its own affine function of p. Lanes 1..3 hold the
// rows of the inverse of the edge matrix [v1 - v0, v2 - v0, v3 - v0]; lane 0 the gradient of
// l_0 = 1 - l_1 - l_2 - l_3, computed as its own cross product (-(v2 - v1) x (v3 - v1) over the
// determinant), so that the four coordinates are four lanes of one SIMD register. `inside`
// bounds the float error of every l_k for any p inside the cell: l_k > inside for every k
// proves p inside (probe_runtime.cpp derives it), so a lookup whose point stayed in its cell
// decides with one compare. The neighbours a step leaves to are ProbeSet::neighbours. The
// lookup trusts the float signs only beyond an error bound and uses the exact predicates
// otherwise; the gradients are NaN and `inside` infinite for a cell whose map cannot be made
// accurate to float precision (an extreme sliver), which then always takes the exact path.
struct alignas(64) ProbeWalkCell {
  std::array<float, 4> x{}, y{}, z{};  // lane k: the gradient of l_k
  glm::vec3 origin{0.0f};
  float inside = 0.0f;
  glm::vec3 gradient(int k) const { return {x[size_t(k)], y[size_t(k)], z[size_t(k)]}; }
};
static_assert(sizeof(ProbeWalkCell) == 64);

struct ProbeSet {
  int32_t dimension = 3;
  std::vector<glm::vec3> positions;
  std::vector<ShL2Rgb> sh;
  std::vector<float> validity;  // per probe, 1 = valid, 0 = inside geometry (DDGI-style)
  std::vector<glm::ivec4> cells;
  std::vector<glm::ivec4> neighbours;
  int32_t innerCellCount = 0;
  std::vector<OuterCell> outerCells;  // cells.size() - innerCellCount entries
  ProbeSeedGrid grid;
  // Per probe shadowmask occlusion (see above); empty = 1 everywhere (no shadowmask lights).
  std::vector<glm::vec4> occlusion;
  std::array<int32_t, kProbeOcclusionChannels> occlusionLights{-1, -1, -1, -1};
  ProbeVisibility visibility;  // empty = blend by barycentric weights alone
  ProbeSunLayer sun;           // empty = no sharp sun shadows
  // Derived walk records, one per inner cell (dimension 3): filled by prepareProbeLookup,
  // which buildProbeTopology and the .kprobe readers call. Empty (or stale in size) = the
  // lookup walks with the exact predicates alone. Call prepareProbeLookup again after
  // changing positions or cells.
  std::vector<ProbeWalkCell> walk;

  int32_t probeCount() const { return int32_t(positions.size()); }
  int32_t cellCount() const { return int32_t(cells.size()); }
  bool isOuter(int32_t cell) const { return cell >= innerCellCount; }
};

// Fills outerCells[i].cubic from the cells' triangles and outerCells[i].normals (dimension 3;
// zeros otherwise). Called by the bake after the normals are set.
void computeOuterCellCubics(ProbeSet& set);

// Fills set.walk from positions and cells (dimension 3; cleared otherwise).
// Requires a complete, valid topology (validateProbeSet).
void prepareProbeLookup(ProbeSet& set);
// One inner cell's record as prepareProbeLookup makes it, from the tetrahedron's four
// positions (positively oriented): for a builder that writes the records in its own pass over
// the cells (buildProbeTopology).
void makeProbeWalkCell(const std::array<glm::vec3, 4>& corners, ProbeWalkCell& out);
// The records of `cells` (inner tetrahedra, positively oriented, indices into `positions`)
// into out[0 .. cells.size()), each equal bit for bit to makeProbeWalkCell's (four cells at a
// time in SIMD lanes; prepareProbeLookup and buildProbeTopology use it).
void makeProbeWalkCells(std::span<const glm::vec3> positions, std::span<const glm::ivec4> cells,
                        ProbeWalkCell* out);

// Builds set.grid: about `targetCellsPerSeed` cells per grid cell, at most kSeedGridMaxAxis
// per axis, each seed a cell whose centroid lies in the grid cell (the one nearest its
// centre), or for a grid cell no centroid falls in, the nearest grid cell's seed. Requires a
// complete topology.
inline constexpr int kSeedGridMaxAxis = 128;
void buildProbeSeedGrid(ProbeSet& set, int targetCellsPerSeed = 4);

// Checks everything the lookup relies on: sizes agree, indices in range, neighbour links
// symmetric, values finite, occlusion empty or one entry per probe in [0, 1], channel lights
// >= -1, visibility empty or a resolution in [kMinVisibilityResolution,
// kMaxVisibilityResolution] with one finite maxDistance > 0 and one map per probe whose
// spreads are at most 1/2 (no distribution on [0, 1] spreads more), and a sun layer that is
// empty (light -1, no visibility, no ramps) or has a light >= 0, a finite lobe, one visibility
// in [0, 1] per probe and no ramps or one per inner cell (dimension 3 only), each four finite
// values or four NaNs. Messages read "<name>: <field>[i]: problem". Safe for untrusted data.
Status validateProbeSet(const ProbeSet& set, std::string_view name);

// .kprobe file, version 4, little-endian:
//   header (72 bytes): "KPRB", u32 version, u32 dimension, u32 probeCount, u32 cellCount,
//     u32 innerCellCount, u32 gridSize[3], f32 gridMin[3], f32 gridMax[3],
//     u32 visibilityResolution (version 3 on; 0 = no visibility; "reserved", 0, before),
//     u64 checksum = FNV-1a 64 of header bytes [0, 64) followed by the whole payload;
//   payload: f32 positions[probeCount][3], f32 sh[probeCount][9][3] (coefficient-major,
//     RGB innermost), f32 validity[probeCount], i32 cells[cellCount][4],
//     i32 neighbours[cellCount][4], f32 outerNormals[outerCount][3][3],
//     f32 outerCubic[outerCount][4][4], i32 seeds[gridSize product],
//     from version 2 on: i32 occlusionLights[4] (scene light per shadowmask channel, -1
//     unused), f32 occlusion[probeCount][4] (each in [0, 1]; unused channels 1),
//     from version 3 on, when visibilityResolution R > 0: f32 visibilityMaxDistance
//     [probeCount], u16 visibilityMoments[probeCount][R * R][3] ({mu, sigma, far}, see
//     ProbeVisibility),
//     from version 4 on: i32 sunLight (ProbeSunLayer::light; -1 = no sun layer, and nothing
//     more follows), and when sunLight >= 0: f32 sunSh[9][3], f32 sunVisibility[probeCount],
//     u32 rampCount (0, or innerCellCount in dimension 3), f32 ramps[rampCount][4] (x NaN =
//     no ramp, then y, z, w NaN too);
//   where outerCount = cellCount - innerCellCount.
// Version 1 is version 2 without the occlusion block, version 2 is version 3 without
// visibility, version 3 is version 4 without the sun block; the reader accepts all four and
// gives a version 1 file occlusion 1 in every channel and no channel lights, version 1 and 2
// files no visibility (plain blending), and version 1 to 3 files no sun layer. The header's
// counts bound the file's size (the sun block from sunLight -1 alone to a full layer with
// ramps), so the reader allocates nothing a corrupt count asks for beyond that.
inline constexpr uint32_t kProbeFileVersion = 4;
inline constexpr uint32_t kProbeFileMinVersion = 1;
inline constexpr size_t kProbeFileHeaderSize = 72;
inline constexpr size_t kProbeFileChecksumOffset = 64;  // the header's checksum field

// Serialization (no validation: write what is given, so tests can craft bad files). `version`
// 1 drops the occlusion, 2 the visibility and 3 the sun layer (for readers that predate them);
// an empty `occlusion` is written as 1.
std::vector<uint8_t> serializeProbeSet(const ProbeSet& set, uint32_t version = kProbeFileVersion);
// Parses and validates a whole file image; `name` prefixes messages. Never allocates more than
// the input size justifies. Safe for untrusted input.
Result<ProbeSet> parseProbeSet(std::span<const uint8_t> bytes, std::string_view name);

// Writes `path` atomically (to path + ".tmp", then rename).
Status writeProbeFile(const ProbeSet& set, const std::string& path);
// Reads and validates `path`; messages name the file and the field.
Result<ProbeSet> loadProbeFile(const std::string& path);

// FNV-1a 64-bit hash, continuing from `hash` (start with kFnvOffset).
inline constexpr uint64_t kFnvOffset = 14695981039346656037ull;
uint64_t fnv1a64(std::span<const uint8_t> bytes, uint64_t hash = kFnvOffset);
// The checksum a kiln binary file (.kprobe, .klppv) stores in its header at
// `checksumOffset`: FNV-1a over the header bytes before that field, then over the payload
// after the `headerSize`-byte header. `file` holds at least `headerSize` bytes.
uint64_t binaryFileChecksum(std::span<const uint8_t> file, size_t checksumOffset,
                            size_t headerSize);

}  // namespace kiln
