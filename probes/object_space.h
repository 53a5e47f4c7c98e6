// object_space.h: where dynamic objects can be, for probe placement (docs/probe_placement.md,
// "Where objects go"):
// - reachable space: a flood fill over a grid of cells covering the placement volumes, from
//   the cells that see the sky and the cells holding a punctual light, a camera or a user
//   probe, to neighbouring cells whose centres see each other (an unoccluded segment). What
//   the fill does not reach is sealed: the cavities inside thick walls, closed boxes, the
//   space behind an outer shell. Rays alone cannot tell a sealed void from a room (a point in
//   it sees only front faces), connectivity can.
// - walkable surfaces: upward-facing static geometry (found by vertical rays), the floors,
//   table tops and roofs objects stand on; probes belong from close above them (0.3-0.5 m,
//   where Unity's APV and Godot put probes near geometry) up through the volume, denser near
//   the floor than in open air.
#pragma once

#include <atomic>
#include <cstdint>
#include <span>
#include <vector>

#include "src/math.h"
#include "src/scene.h"
#include "src/tracer.h"

namespace kiln {

struct ReachableSpaceSettings {
  float cellSize = 0.0f;    // grid cell side (m); 0 = about 100,000 cells over the volumes
  uint32_t skyRays = 16;    // directions tested per cell for an escape to the sky
  std::vector<vec3> seeds;  // extra points in reachable space (user probes...)
  int threads = 0;
};

// The reachable part of the placement volumes (see the file comment). Immutable once built;
// reachable() is thread-safe. Holds a reference to the tracer: it must outlive this object.
class ReachableSpace {
 public:
  // Seeds: cells that see the sky (a ray in one of skyRays directions escapes the scene),
  // cells holding a point or spot light or a camera, and settings.seeds. Without any seed
  // every point counts as reachable (enabled() false): a closed scene lit only by emissive
  // surfaces gives nothing to start from. Empty `volumes` = always reachable.
  static ReachableSpace build(const Scene& scene, const Tracer& tracer,
                              std::span<const Bounds3> volumes,
                              const ReachableSpaceSettings& settings,
                              const std::atomic<bool>* cancel = nullptr);

  // True when p can be reached from a seed through free space: its cell was reached and p
  // sees the cell's centre, or p sees the centre of a reached neighbouring cell (a point near
  // a wall can lie in a cell whose centre is inside the wall). Points outside the grid: false.
  bool reachable(vec3 p) const;
  bool enabled() const { return enabled_; }
  uint32_t cells() const { return uint32_t(reached_.size()); }
  uint32_t seedCells() const { return seedCells_; }
  uint32_t reachedCells() const { return reachedCells_; }
  float cellSize() const { return cell_; }

 private:
  explicit ReachableSpace(const Tracer& tracer) : tracer_(&tracer) {}
  int64_t index(glm::ivec3 c) const;
  vec3 centre(glm::ivec3 c) const;

  const Tracer* tracer_;
  bool enabled_ = false;
  Bounds3 box_;
  glm::ivec3 dims_{0};
  float cell_ = 0.0f;
  std::vector<uint8_t> reached_;
  uint32_t seedCells_ = 0, reachedCells_ = 0;
};

// An upward-facing surface (a floor) under a point of the plane, and the free height above it.
struct Floor {
  vec3 point{0.0f};        // on the surface
  float clearance = 0.0f;  // to the next surface above (or to `top`)
};
// The floors in the vertical line at (x, z) below `top`, from the top down: front faces of
// static surfaces whose normal's y is at least 0.7 (slopes up to 45 degrees), not inside a
// solid (an upward face under a block standing on it).
std::vector<Floor> floorsBelow(const Scene& scene, const Tracer& tracer, float x, float z,
                               float top, float bottom);

// Points above the floors of a column grid of side `columnSpacing` over the volumes: at
// heights firstHeight, then gaps of 2, 3, 5, 10 x firstHeight (0.4, 1.2, 2.4, 4.4, 8.4 m for
// 0.4), below the floor's clearance less `headroom`, inside a volume. Not tested for validity.
std::vector<vec3> pointsAboveFloors(const Scene& scene, const Tracer& tracer,
                                    std::span<const Bounds3> volumes, float columnSpacing,
                                    float firstHeight, float headroom);

// A random point where an object stands, from three uniform numbers and one to choose the
// floor: (x, z) uniform over the volumes' box, one of the floors below uniformly, height
// uniform in [minHeight, maxHeight] above it (below its clearance less 0.1 m). nullopt when
// the line has no floor or the point leaves every volume.
std::optional<vec3> objectPoint(const Scene& scene, const Tracer& tracer,
                                std::span<const Bounds3> volumes, vec2 uxz, float uFloor,
                                float uHeight, float minHeight, float maxHeight);

}  // namespace kiln
