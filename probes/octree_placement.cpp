// octree_placement.cpp: Godot-style octree-corner probe placement (see octree_placement.h).
#include "probes/octree_placement.h"

#include <algorithm>
#include <cmath>
#include <string>

#include "src/parallel.h"

namespace kiln {

using glm::ivec3;

bool triangleBoxOverlap(vec3 centre, vec3 half, vec3 a, vec3 b, vec3 c) {
  // Separating-axis theorem (Akenine-Moller 2001): the box and the triangle are disjoint iff
  // their projections are disjoint on one of 13 axes: the box's 3 face normals, the
  // triangle's normal, and the 9 cross products of box axes with triangle edges.
  const vec3 v[3] = {a - centre, b - centre, c - centre};
  const vec3 e[3] = {v[1] - v[0], v[2] - v[1], v[0] - v[2]};
  auto separated = [&](vec3 axis) {
    const float p0 = glm::dot(axis, v[0]), p1 = glm::dot(axis, v[1]), p2 = glm::dot(axis, v[2]);
    const float r = half.x * std::abs(axis.x) + half.y * std::abs(axis.y) +
                    half.z * std::abs(axis.z);
    return std::min({p0, p1, p2}) > r || std::max({p0, p1, p2}) < -r;
  };
  for (int k = 0; k < 3; ++k) {
    const float lo = std::min({v[0][k], v[1][k], v[2][k]});
    const float hi = std::max({v[0][k], v[1][k], v[2][k]});
    if (lo > half[k] || hi < -half[k]) return false;
  }
  if (separated(glm::cross(e[0], e[1]))) return false;
  for (int i = 0; i < 3; ++i) {
    vec3 axis(0.0f);
    axis[i] = 1.0f;
    for (int j = 0; j < 3; ++j)
      if (separated(glm::cross(axis, e[j]))) return false;
  }
  return true;
}

namespace {

// Lattice coordinates (each < 2^21) packed so that sorting the keys sorts by (z, y, x).
uint64_t packKey(ivec3 p) {
  return (uint64_t(p.z) << 42) | (uint64_t(p.y) << 21) | uint64_t(p.x);
}
ivec3 unpackKey(uint64_t k) {
  constexpr uint64_t mask = (1u << 21) - 1;
  return ivec3(int(k & mask), int((k >> 21) & mask), int(k >> 42));
}

// The box around the volumes, and the side of the cube the octree's root covers from its
// minimum corner (0 when the box is empty).
Bounds3 boundsOf(std::span<const Bounds3> volumes) {
  Bounds3 box;
  for (const Bounds3& b : volumes) box.extend(b);
  return box;
}
float rootSide(const Bounds3& box) {
  if (box.empty()) return 0.0f;
  const vec3 extent = box.extent();
  return std::max({extent.x, extent.y, extent.z});
}

struct OctreeWalk {
  vec3 origin;
  float cell;  // finest cell side
  vec3 a, b, c;
  std::vector<uint64_t>* leaves;

  // Cell at `offset` (finest-cell units) of `size` finest cells per side: visits its eight
  // children, descending into those the triangle touches (Godot's _plot_triangle_into_octree).
  void descend(ivec3 offset, int size) const {
    const int half = size / 2;
    for (int i = 0; i < 8; ++i) {
      const ivec3 pos = offset + half * ivec3(i & 1, (i >> 1) & 1, (i >> 2) & 1);
      const vec3 centre = origin + (vec3(pos) + 0.5f * float(half)) * cell;
      const vec3 extent(0.5f * float(half) * cell);
      if (!triangleBoxOverlap(centre, extent, a, b, c)) continue;
      if (half == 1)
        leaves->push_back(packKey(pos));
      else
        descend(pos, half);
    }
  }
};

}  // namespace

std::vector<ivec3> octreeLeafCorners(const Scene& scene, vec3 origin, float side, int level,
                                     uint32_t* leafCells) {
  std::vector<uint64_t> leaves;
  if (level >= 1 && level <= 20 && side > 0.0f) {
    const int size = 1 << level;
    OctreeWalk walk{origin, side / float(size), vec3(0.0f), vec3(0.0f), vec3(0.0f), &leaves};
    for (const Object& o : scene.objects) {
      if (!o.settings.isStatic) continue;
      for (const uvec3& t : o.triangles) {
        walk.a = o.positions[t.x];
        walk.b = o.positions[t.y];
        walk.c = o.positions[t.z];
        walk.descend(ivec3(0), size);
      }
    }
  }
  std::sort(leaves.begin(), leaves.end());
  leaves.erase(std::unique(leaves.begin(), leaves.end()), leaves.end());
  if (leafCells) *leafCells = uint32_t(leaves.size());
  std::vector<uint64_t> corners;
  corners.reserve(leaves.size() * 8);
  for (uint64_t k : leaves) {
    const ivec3 p = unpackKey(k);
    for (int i = 0; i < 8; ++i) corners.push_back(packKey(p + ivec3(i & 1, (i >> 1) & 1, i >> 2)));
  }
  std::sort(corners.begin(), corners.end());
  corners.erase(std::unique(corners.begin(), corners.end()), corners.end());
  std::vector<ivec3> out;
  out.reserve(corners.size());
  for (uint64_t k : corners) out.push_back(unpackKey(k));
  return out;
}

Result<OctreePlacement> octreeCornerPlacement(const Scene& scene, const Tracer& tracer,
                                              const OctreePlacementSettings& settings) {
  if (settings.cellSize <= 0.0f && (settings.level < 1 || settings.level > 10))
    return Error{"octree placement: level " + std::to_string(settings.level) +
                 " is outside 1..10"};
  if (!(settings.cellSize >= 0.0f) || !std::isfinite(settings.cellSize))
    return Error{"octree placement: cellSize must be a finite number >= 0"};
  const std::vector<Bounds3> volumes = placementVolumes(scene, settings.volumes);
  const Bounds3 box = boundsOf(volumes);
  const float side = rootSide(box);
  if (!(side > 0.0f)) return Error{"octree placement: the volumes are empty"};

  OctreePlacement out;
  int level = settings.level;
  float rootCube = side;
  if (settings.cellSize > 0.0f) {
    level = 1;
    while (level < 10 && settings.cellSize * float(1 << level) < side) ++level;
    rootCube = settings.cellSize * float(1 << level);
    if (rootCube < side)
      return Error{"octree placement: cellSize " + std::to_string(settings.cellSize) +
                   " m needs more than 1024 cells across the volumes"};
  }
  out.cellSize = rootCube / float(1 << level);
  const std::vector<ivec3> lattice =
      octreeLeafCorners(scene, box.min, rootCube, level, &out.leafCells);
  if (out.leafCells == 0) return Error{"octree placement: no static triangle in the volumes"};

  // Corners inside the volumes (a hair of tolerance: corners on a volume's face count).
  const float tolerance = 1e-5f * side;
  std::vector<vec3> corners;
  for (const ivec3& k : lattice) {
    const vec3 p = box.min + vec3(k) * out.cellSize;
    for (const Bounds3& b : volumes) {
      Bounds3 grown = b;
      grown.min -= vec3(tolerance);
      grown.max += vec3(tolerance);
      if (grown.contains(p)) {
        corners.push_back(glm::clamp(p, box.min, box.max));
        break;
      }
    }
  }
  out.corners = uint32_t(corners.size());

  std::vector<RelocatedPoint> judged(corners.size());
  ParallelOptions options;
  options.threads = settings.threads;
  options.grain = 16;
  parallelFor(
      corners.size(),
      [&](size_t begin, size_t end) {
        for (size_t i = begin; i < end; ++i) {
          if (settings.relocate) {
            judged[i] =
                relocateProbePoint(scene, tracer, corners[i], settings.validity, volumes);
          } else {
            judged[i].position = corners[i];
            judged[i].valid = isValidProbePoint(scene, tracer, corners[i], settings.validity);
          }
        }
      },
      options);

  // Relocated corners that landed on the same spot are merged (as the uniform grid does).
  for (const RelocatedPoint& r : judged) {
    out.dropped += r.valid ? 0u : 1u;
    out.moved += r.valid && r.moved ? 1u : 0u;
  }
  for (size_t i : distinctValidPoints(judged, settings.validity.minSurfaceDistance))
    out.positions.push_back(judged[i].position);
  if (out.positions.empty())
    return Error{"octree placement: no valid corner at level " + std::to_string(level)};
  return out;
}

Result<std::vector<vec3>> octreeCornerPositions(const Scene& scene, const Tracer& tracer,
                                                const OctreePlacementSettings& settings,
                                                uint32_t count) {
  if (count < 4) return Error{"octree placement: count must be at least 4"};
  const std::vector<Bounds3> volumes = placementVolumes(scene, settings.volumes);
  const Bounds3 box = boundsOf(volumes);
  const float side = rootSide(box);
  if (!(side > 0.0f)) return Error{"octree placement: the volumes are empty"};
  OctreePlacementSettings s = settings;
  auto place = [&](float cell) -> Result<std::vector<vec3>> {
    s.cellSize = cell;
    Result<OctreePlacement> r = octreeCornerPlacement(scene, tracer, s);
    if (!r) return Error{r.error()};
    return std::move(r->positions);
  };
  // The coarsest level with enough corners (fewer cells hold fewer corners, up to the lattice's
  // phase), then the largest cell size between it and the next coarser level that still does.
  float lo = 0.0f, hi = side;
  std::vector<vec3> best;
  for (int level = 1; level <= 10; ++level) {
    const float cell = side / float(1 << level);
    Result<std::vector<vec3>> r = place(cell);
    if (!r) {
      // A level with no triangle-touching cell or no valid corner: finer ones may have some.
      hi = cell;
      continue;
    }
    if (r->size() >= count) {
      lo = cell;
      best = std::move(*r);
      break;
    }
    hi = cell;
  }
  if (best.size() < count)
    return Error{"octree placement: fewer than " + std::to_string(count) +
                 " valid corners at 1024 cells across the volumes"};
  return largestSpacingWithCount(lo, hi, count, std::move(best),
                                 [&](float cell) -> std::optional<std::vector<vec3>> {
                                   Result<std::vector<vec3>> r = place(cell);
                                   if (!r) return std::nullopt;
                                   return std::move(r).value();
                                 });
}

}  // namespace kiln
