// texel_raster.h: conservative rasterization of lightmapped objects into their atlas pages:
// which surface point each texel bakes (MISSION.md "Lightmaps: Texels").
//
// Frame: page texel coordinates, texel (x, y) covering [x, x+1] x [y, y+1], i.e. atlas UV
// [x, x+1]/W x [y, y+1]/H with (0, 0) the top-left = first image row (MISSION.md
// "Conventions"); a triangle's texel-space corners are (uv1 * (sx, sy) + (ox, oy)) * (W, H).
// Conservative: a texel belongs to an object when any of its triangles overlaps the texel's
// square with positive area. Its sample point is the texel centre when the centre lies in one
// of the object's triangles (the first in triangle order, for centres on shared edges),
// otherwise the centroid of the part of the texel covered by the triangle that covers the
// most of it (texel square clipped to the triangle, Sutherland and Hodgman 1974); a convex
// piece's centroid always lies inside the triangle.
#pragma once

#include <cstdint>
#include <vector>

#include "lightmap/atlas.h"
#include "src/parallel.h"
#include "kiln/result.h"
#include "src/scene.h"

namespace kiln {

struct RasterSettings {
  // Supersampling: n x n points per texel on a regular stratified grid at
  // ((i + 0.5) / n, (j + 0.5) / n); 1 = only the main sample. At most 16.
  int supersampling = 1;
  // Optional, one W x H mask per page: only texels with mask 1 get supersampling points (the
  // others get their main sample alone). The baker's second pass uses it to give the
  // texels next to hidden geometry a finer grid of footprint points (lightmap_baker.cpp).
  const std::vector<std::vector<uint8_t>>* subsampleMask = nullptr;
  ParallelOptions parallel;  // rows run in parallel; the output does not depend on threads
};

// A surface point of a texel: triangle of the texel's object, Embree barycentrics (b1, b2)
// (p = (1-b1-b2) p0 + b1 p1 + b2 p2), the point in page texel coordinates, and the world
// position and unit shading normal there.
struct TexelPoint {
  uint32_t triangle = 0;
  vec2 bary{0.0f};
  vec2 point{0.0f};
  vec3 position{0.0f};
  vec3 normal{0.0f};
  bool pushedOut = false;  // set by the baker's push-out: the point lay inside a solid
  // Set by the baker's push-out: one of its tangent-plane rays hit a surface within reach
  // (front or back), so the texel's footprint may be partly hidden by that geometry.
  bool nearSurface = false;
  // Set by the baker on footprint grid points: the segment along the surface from the
  // texel's main sample to this point crosses geometry (a wall, a solid's face), so the point
  // lies inside a solid or on the far side of a wall and is not part of the texel's surface.
  bool hidden = false;
};

struct TexelSample {
  int32_t object = -1;    // scene object index; -1 = no geometry (padding, empty space)
  TexelPoint sample;      // the main sample (texel centre or covered-part centroid)
  float coverage = 0.0f;  // covered fraction of the texel's area, in (0, 1]
  // Supersampling points inside the object's triangles: subsamples[first, first + count)
  // of the page. May be empty for a sliver no grid point falls on: use `sample`.
  uint32_t firstSubsample = 0;
  uint32_t subsampleCount = 0;
  // Set by the baker for texels next to geometry: a grid of points over the footprint,
  // subsamples[firstGridPoint, firstGridPoint + gridPointCount), whose hidden points
  // (TexelPoint::hidden) are left out of the texel's value (the mean over the visible part
  // of the footprint). The supersampling points above stay, for a texel whose grid has no
  // visible point. 0 = no grid.
  uint32_t firstGridPoint = 0;
  uint32_t gridPointCount = 0;

  bool valid() const { return object >= 0; }
  bool footprintGrid() const { return gridPointCount > 0; }
};

struct RasterPage {
  int width = 0, height = 0;
  std::vector<TexelSample> texels;  // row-major from the top row: index y * width + x
  std::vector<TexelPoint> subsamples;

  const TexelSample& at(int x, int y) const { return texels[size_t(y) * width + x]; }
};

// Rasterizes every object with a page in `layout` (index-aligned with scene.objects) into its
// page. Deterministic at any thread count. Thread-safe for concurrent calls (reads only).
// Errors: a layout that does not match the scene, an object without UV1, supersampling out of
// [1, 16]. Two objects on one texel cannot happen with a padded atlas (asserted).
Result<std::vector<RasterPage>> rasterizeAtlas(const Scene& scene, const AtlasLayout& layout,
                                               const RasterSettings& settings);

}  // namespace kiln
