// sealed_surfaces.h: which triangles no light can reach, so that generated lightmap UVs give
// them the minimum of atlas space (issue 17: 63% of the texels of Sponza's walls were exactly
// 0, the sealed backs of its outer shell; a box's face resting on a floor is the small case).
//
// Light reaches a triangle's front side when, from points on it:
//   - a punctual light (any mode) is visible in front of it (a shadow ray), or
//   - a ray leaves the scene and the sky is not black, or
//   - a ray hits an emissive surface, a BLEND (semi-transparent) surface, a double-sided
//     surface, or the front of a triangle light reaches (propagated to a fixed point over the
//     traced rays: a surface lit only by bounces counts).
// Every static triangle casts `raysPerTriangle` cosine-distributed rays from points spread
// over it; a triangle none of whose rays and shadow rays finds light is sealed. Sampling can
// miss a light seen through a small opening, so the decision is made per chart by the caller
// (uv_unwrap.cpp: a chart is shrunk only when all its triangles are sealed), and
// double-sided triangles (lit from either side) are never sealed.
#pragma once

#include <cstdint>
#include <vector>

#include "src/parallel.h"
#include "src/scene.h"
#include "src/tracer.h"

namespace kiln {

struct SealedSettings {
  int raysPerTriangle = 8;
  ParallelOptions parallel;
};

// Per scene object, per triangle: 1 when no light reaches its front side (see above), 0
// otherwise; empty for objects the tracer does not hold (dynamic ones). Deterministic.
std::vector<std::vector<uint8_t>> findSealedTriangles(const Scene& scene, const Tracer& tracer,
                                                      const SealedSettings& settings = {});

}  // namespace kiln
