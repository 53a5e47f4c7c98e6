// visibility_bake.h: building a probe's visibility map (kiln/probe_visibility.h) from the
// distances its bake rays travel (bake time; the runtime only reads the maps).
//
// Each ray's first-hit distance t (a miss counts as maxDistance D), as s = min(t, D) / D, goes
// to the texel its direction falls in, with its position inside the texel. Per texel a plane
// s = mu + a x + b y in the texel's own coordinates (x, y in [-1/2, 1/2]) is fitted by least
// squares; mu (the plane at the texel centre), the RMS residual sigma and the largest s of the
// texel's rays are stored. A texel
// with fewer than kMinRaysPerTexel rays (few rays per texel, e.g. the 1024-ray bakes placement
// uses at 16 x 16) also gets a ray through each of four points of a 2 x 2 grid inside it, so
// that every fit has a spread of points.
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

inline constexpr uint32_t kMinRaysPerTexel = 6;

class VisibilityMapBuilder {
 public:
  explicit VisibilityMapBuilder(const VisibilityMapSpec& spec);

  // One ray from the probe: unit direction, first-hit distance (kInfinity for a miss).
  void add(vec3 direction, float distance);
  // The unorm16 maps (resolution^2 x {mu, sigma, far}); traces the extra rays of under-sampled
  // texels from `probe` with `tracer`.
  std::vector<uint16_t> finish(const Tracer& tracer, vec3 probe);

 private:
  void accumulate(int32_t texel, float x, float y, float s);
  VisibilityMapSpec spec_;
  // Per texel the sums of the normal equations: n, x, y, xx, xy, yy, s, sx, sy, ss; and the
  // largest s.
  std::vector<double> sums_;
};

// Each probe's maxDistance: the distance from the probe to the farthest corner of `bounds`
// (the scene's and every probe's), so that no query inside them is clamped (clamping would
// turn "a wall 4 m away" into "clear to D" for a point beyond D), at least 1 mm.
std::vector<float> visibilityMaxDistances(std::span<const vec3> positions, const Bounds3& bounds);

}  // namespace kiln
