// octree_placement.h: the Godot-style probe placement baseline (Godot 4 LightmapGI's
// "generate probes"): an octree over the scene is subdivided down to a fixed level in every
// cell that a static triangle touches, and the corners of those finest cells become probes.
// Probes are therefore dense on every surface and absent from open space, whatever the light.
//
// kiln uses it as a baseline for its own lighting-driven placement (probe_placement.h) in
// `kiln chart` (docs/charts.md) and `kiln probes compare-placement` (at an exact probe count,
// octreeCornerPositions). Unlike Godot, which keeps corners that land inside walls,
// corners go through the same validity test and relocation as kiln's other placements
// (relocateProbePoint), so that the comparison measures where probes are, not probes buried
// in geometry.
#pragma once

#include <cstdint>
#include <span>
#include <vector>

#include "probes/probe_placement.h"
#include "src/math.h"
#include "kiln/result.h"
#include "src/scene.h"
#include "src/tracer.h"

namespace kiln {

struct OctreePlacementSettings {
  // Where probes may go: empty = the bounds of the static objects (placementVolumes). The
  // octree's root is the bounding box of the volumes' union, its finest cells are cubes of
  // side (longest extent of that box) / 2^level (Godot's subdiv 8, 16, 32, 64 are levels
  // 3, 4, 5, 6), laid from the box's minimum corner.
  std::vector<Bounds3> volumes;
  int level = 4;  // 1..10
  // > 0: the finest cells' side in metres instead of `level` (the root is then the smallest
  // cube of side cellSize x 2^L, L <= 10, that covers the volumes, laid from their minimum
  // corner), so a probe count can be matched; Godot offers the levels only.
  float cellSize = 0.0f;
  // true: corners inside geometry or too close to a surface are moved out as
  // relocateProbePoint does (dropped when that fails); false: they are dropped.
  bool relocate = true;
  ProbeValiditySettings validity;
  int threads = 0;  // 0 = all cores
};

struct OctreePlacement {
  std::vector<vec3> positions;  // world space, metres; sorted lattice order, duplicates merged
  float cellSize = 0.0f;        // side of the finest cells (m)
  uint32_t leafCells = 0;       // finest cells touching a static triangle
  uint32_t corners = 0;         // their distinct corners inside the volumes
  uint32_t moved = 0;           // corners relocated
  uint32_t dropped = 0;         // corners invalid and not relocatable (or relocate = false)
};

// The integer corners (lattice coordinates, in units of the finest cell from `origin`) of the
// finest cells of an octree of `level` levels over the cube [origin, origin + side]^3 that a
// triangle of a static object touches (closed triangle-box overlap, Akenine-Moller's
// separating-axis test). Deterministic; sorted (z, y, x) and distinct. Pure geometry: no rays.
// Cells are found by descending the octree from the root per triangle (Godot's
// _plot_triangle_into_octree), so large empty regions cost nothing.
std::vector<glm::ivec3> octreeLeafCorners(const Scene& scene, vec3 origin, float side, int level,
                                          uint32_t* leafCells = nullptr);

// Godot-style placement (see the file comment). Errors: level out of range, empty volumes,
// no static geometry, no valid corner. Deterministic at any thread count.
Result<OctreePlacement> octreeCornerPlacement(const Scene& scene, const Tracer& tracer,
                                              const OctreePlacementSettings& settings);

// Godot-style placement with exactly `count` probes (>= 4), for comparisons at equal counts:
// the largest finest-cell size (settings.cellSize; settings.level is ignored) whose valid
// corners number at least `count` is searched (bisection between the levels around it), and
// the surplus is removed evenly (every k-th in lattice order), as uniformGridPositions does.
// Errors: as octreeCornerPlacement, or fewer than `count` valid corners at 1024 cells per side.
Result<std::vector<vec3>> octreeCornerPositions(const Scene& scene, const Tracer& tracer,
                                                const OctreePlacementSettings& settings,
                                                uint32_t count);

// Separating-axis test of triangle (a, b, c) against the axis-aligned box centre +- half
// (closed: touching counts). Exposed for tests.
bool triangleBoxOverlap(vec3 centre, vec3 half, vec3 a, vec3 b, vec3 c);

}  // namespace kiln
