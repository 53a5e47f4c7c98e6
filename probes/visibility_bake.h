// visibility_bake.h: building a probe's visibility map (kiln/probe_visibility.h) from the
// distances its bake rays travel (bake time; the runtime only reads the maps).
//
// Each ray's first-hit distance t (a miss counts as maxDistance D), clamped to D and divided
// by it, is splatted into the octahedral map with the bilinear footprint of its direction (the
// same footprint the runtime samples with, seams wrapped), accumulating weight, weight x s
// and weight x s^2. A texel that receives less than half a ray's weight (few rays per texel,
// e.g. the 1024-ray bakes placement uses at 16 x 16) gets one more ray along its centre
// direction, so no texel is left without data.
#pragma once

#include <cstdint>
#include <span>
#include <vector>

#include "src/math.h"
#include "src/tracer.h"

namespace kiln {

// What a bake should record: the map's side (0 = no visibility) and D in metres.
struct VisibilityMapSpec {
  int32_t resolution = 0;
  float maxDistance = 0.0f;
};

class VisibilityMapBuilder {
 public:
  explicit VisibilityMapBuilder(const VisibilityMapSpec& spec);

  // One ray from the probe: unit direction, first-hit distance (kInfinity for a miss).
  void add(vec3 direction, float distance);
  // The unorm16 moments (resolution^2 x {mean, mean square}); traces the centre rays of
  // under-sampled texels from `probe` with `tracer`.
  std::vector<uint16_t> finish(const Tracer& tracer, vec3 probe);

 private:
  void splat(int32_t texel, float weight, float s);
  VisibilityMapSpec spec_;
  std::vector<double> sums_;  // per texel: weight, weight x s, weight x s^2
};

// Each probe's maxDistance for a topology: the longest of its own edges in any cell (every
// point of an inner cell lies within that distance of each of the cell's probes, since
// distance to a probe is convex and so largest at one of the cell's vertices). Probes in no cell (merged duplicates) and sets
// of one distinct position get the largest such value, or 1 m.
std::vector<float> visibilityMaxDistances(std::span<const vec3> positions,
                                          std::span<const glm::ivec4> cells);

}  // namespace kiln
