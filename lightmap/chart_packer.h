// chart_packer.h: packing an object's UV charts by their shape (column profiles), for
// generated lightmap UVs (uv_unwrap.cpp).
//
// Bounding rectangles waste what a chart does not cover of its rectangle (an L-shaped chart
// or a curved strip leaves half of it empty). Here every chart is described per texel column
// by the rows it covers (its lowest and highest covered row, conservatively: every texel the
// chart touches), and charts are dropped into a height map one after the other, each at the
// column where its top ends lowest (ties: leftmost), in its orientation or turned by 90, 180
// or 270 degrees, so that a chart nests into the hollows the charts below it leave ("Tetris"
// packing over column profiles, as in B. Lévy et al. 2002, section 5, with the quarter turns
// of xatlas). The bin width is chosen among candidates to give the smallest rectangle.
// Integer texel coordinates; deterministic.
#pragma once

#include <array>
#include <climits>
#include <cstdint>
#include <functional>
#include <glm/glm.hpp>
#include <optional>
#include <vector>

namespace kiln {

// A chart's footprint in texels, per column (column x = [x, x + 1)): a chart whose texel
// coordinates lie in [0, extent] has its point p at p + offset of the footprint, centred in
// ceil(extent + 2e-3) texels (so that float rounding at its edges stays inside).
struct ChartFootprint {
  int columns = 0, rows = 0;
  glm::dvec2 offset{0.0};
  std::vector<int> bottom, top;  // per column: covered rows [bottom, top); bottom >= top: none
};

// The footprint of triangles given in texel units, all inside [0, extent.x] x [0, extent.y];
// a texel counts as covered when a triangle comes within 1e-3 texel of it.
ChartFootprint chartFootprint(const std::vector<std::array<glm::dvec2, 3>>& triangles,
                              glm::dvec2 extent);

// The footprint of triangles given in a fixed frame of size.x columns and size.y rows (all
// inside [0, size]; offset 0): what an object's UV1 rectangle covers in its texel rectangle
// (atlas.cpp), with the same 1e-3 texel tolerance.
ChartFootprint footprintInFrame(const std::vector<std::array<glm::dvec2, 3>>& triangles,
                                glm::ivec2 size);

struct ChartPacking {
  glm::ivec2 size{0};               // [0, size) holds every covered texel
  std::vector<glm::ivec2> corners;  // per chart: where its (chosen) footprint's (0, 0) goes
  std::vector<bool> quarter;        // per chart: its quarter-turned footprint was used
  std::vector<bool> turned;         // per chart: that footprint turned by 180 degrees
                                    // (x -> columns - x, y -> rows - y)
};

struct ChartPackOptions {
  // Per chart (or empty: none): placed upright only, never turned (an object placed by one
  // scale and offset, which cannot turn it).
  std::vector<bool> rigid;
  // The cost of a packing whose covered texels span [0, w) x [0, h); the smallest wins
  // (ties: the first width tried). Empty: the area as if widened to an aspect ratio of at
  // most 2, max(w, ceil(h / 2)) x max(h, ceil(w / 2)). A packing whose cost is INT64_MAX
  // does not count (e.g. it would not fit a page).
  std::function<int64_t(int w, int h)> cost;
  // Widest bin tried (e.g. a page's side less its padding).
  int maxWidth = INT_MAX;
  // Bins from the widest chart on (a page of a few tall charts may be a column of them), else
  // from half the side of the charts' area (an object's charts, packed squarish).
  bool fromWidest = false;
};

// Packs charts with at least `gutter` empty texels between the covered texels of any two
// (Chebyshev distance; none between a chart and the rectangle's border). `upright[i]` is
// chart i's footprint, `quarter[i]` (optional: empty = upright only) the footprint of the
// same chart turned by 90 degrees; each is also tried turned by 180 degrees (charts not
// options.rigid). Tries bin widths from the widest chart to a few times the side
// of the charts' area and keeps the packing of least options.cost. Charts go in order of
// height, then width (descending), then index. size (0, 0) when no width counted.
ChartPacking packCharts(const std::vector<ChartFootprint>& upright,
                        const std::vector<ChartFootprint>& quarter, int gutter,
                        const ChartPackOptions& options = {});

}  // namespace kiln
