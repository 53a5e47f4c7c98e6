// chart_packer.cpp: column-profile ("Tetris") packing of UV charts; see chart_packer.h.
#include "lightmap/chart_packer.h"

#include <algorithm>
#include <climits>
#include <cmath>
#include <cstdlib>

#include "lightmap/skyline_packer.h"

namespace kiln {

namespace {

// A chart edge on a texel boundary (2.0) may come out of the float UVs a hair past it
// (1.99999), touching one more texel than the footprint says. Charts are therefore centred
// in their footprint with at least kSlack to spare on every side, and a texel counts as
// touched when a triangle comes within kSlack of it.
constexpr double kSlack = 1e-3;

}  // namespace

ChartFootprint chartFootprint(const std::vector<std::array<glm::dvec2, 3>>& triangles,
                              glm::dvec2 extent) {
  const glm::ivec2 size(int(std::ceil(extent.x + 2.0 * kSlack)),
                        int(std::ceil(extent.y + 2.0 * kSlack)));
  const glm::dvec2 offset = (glm::dvec2(size) - extent) * 0.5;
  std::vector<std::array<glm::dvec2, 3>> shifted(triangles.size());
  for (size_t i = 0; i < triangles.size(); ++i)
    for (int k = 0; k < 3; ++k) shifted[i][size_t(k)] = triangles[i][size_t(k)] + offset;
  ChartFootprint f = footprintInFrame(shifted, size);
  f.offset = offset;
  return f;
}

ChartFootprint footprintInFrame(const std::vector<std::array<glm::dvec2, 3>>& triangles,
                                glm::ivec2 size) {
  ChartFootprint f;
  f.columns = size.x;
  f.rows = size.y;
  std::vector<double> lo(size_t(f.columns), 1e300), hi(size_t(f.columns), -1e300);
  for (const auto& t : triangles) {
    const double minX = std::min({t[0].x, t[1].x, t[2].x});
    const double maxX = std::max({t[0].x, t[1].x, t[2].x});
    const int first = std::clamp(int(std::floor(minX - kSlack)), 0, f.columns - 1);
    const int last = std::clamp(int(std::ceil(maxX + kSlack)) - 1, first, f.columns - 1);
    for (int c = first; c <= last; ++c) {
      // The triangle's y range over the slab x in [c, c + 1]: reached at its vertices inside
      // the slab or where its edges cross the slab's sides.
      const double x0 = c - kSlack, x1 = c + 1.0 + kSlack;
      double yl = 1e300, yh = -1e300;
      for (int k = 0; k < 3; ++k) {
        const glm::dvec2 p = t[k], q = t[(k + 1) % 3];
        if (p.x >= x0 && p.x <= x1) {
          yl = std::min(yl, p.y);
          yh = std::max(yh, p.y);
        }
        for (double x : {x0, x1})
          if ((p.x - x) * (q.x - x) < 0.0) {
            const double y = p.y + (q.y - p.y) * (x - p.x) / (q.x - p.x);
            yl = std::min(yl, y);
            yh = std::max(yh, y);
          }
      }
      lo[size_t(c)] = std::min(lo[size_t(c)], yl);
      hi[size_t(c)] = std::max(hi[size_t(c)], yh);
    }
  }
  f.bottom.assign(size_t(f.columns), 0);
  f.top.assign(size_t(f.columns), 0);
  for (size_t c = 0; c < size_t(f.columns); ++c) {
    if (lo[c] > hi[c]) continue;  // no triangle over this column
    f.bottom[c] = std::clamp(int(std::floor(lo[c] - kSlack)), 0, f.rows - 1);
    f.top[c] = std::clamp(int(std::ceil(hi[c] + kSlack)), f.bottom[c] + 1, f.rows);
  }
  return f;
}

namespace {

// A footprint as the height map sees it: `top` per column (where the chart ends), and
// `floor` per column of the chart widened by the gutter on both sides (where anything below
// must end): min over columns within `gutter` of bottom, minus gutter.
struct Shape {
  int columns = 0;
  int first = 0, last = -1;  // covered columns [first, last]
  int lowest = 0, highest = 0;  // covered rows [lowest, highest)
  std::vector<int> top;       // per column, -1 when empty
  std::vector<int> bottom;    // per column, INT_MAX when empty
  std::vector<int> floor;     // per widened column (columns + 2 gutter), INT_MAX when none
};

Shape makeShape(const ChartFootprint& f, bool turned, int gutter) {
  Shape s;
  s.columns = f.columns;
  s.first = f.columns;
  s.lowest = f.rows;
  s.top.assign(size_t(f.columns), -1);
  std::vector<int>& bottom = s.bottom;
  bottom.assign(size_t(f.columns), INT_MAX);
  for (int c = 0; c < f.columns; ++c) {
    const int src = turned ? f.columns - 1 - c : c;
    const int b = f.bottom[size_t(src)], t = f.top[size_t(src)];
    if (b >= t) continue;
    bottom[size_t(c)] = turned ? f.rows - t : b;
    s.top[size_t(c)] = turned ? f.rows - b : t;
    s.first = std::min(s.first, c);
    s.last = c;
    s.lowest = std::min(s.lowest, bottom[size_t(c)]);
    s.highest = std::max(s.highest, s.top[size_t(c)]);
  }
  if (s.last < 0) s.first = s.lowest = 0;  // nothing covered
  s.floor.assign(size_t(f.columns + 2 * gutter), INT_MAX);
  for (int c = 0; c < f.columns; ++c) {
    if (bottom[size_t(c)] == INT_MAX) continue;
    for (int w = c; w <= c + 2 * gutter; ++w)
      s.floor[size_t(w)] = std::min(s.floor[size_t(w)], bottom[size_t(c)] - gutter);
  }
  return s;
}

struct Placement {
  int x = 0, y = 0, end = INT_MAX;  // end: the top of the chart's covered rows
  int64_t waste = INT64_MAX;        // empty texels left under the chart's columns

  // Lower end first; at the same end, less waste (an L whose wide arm is up leaves a hollow
  // under it that nothing can reach; turned, it leaves one on top that the next L fills).
  bool before(const Placement& o) const {
    return end != o.end ? end < o.end : waste < o.waste;
  }
};

// Lowest placement of `s` in the height map (columns [0, width)): its covered texels inside
// the bin, its empty margin possibly outside.
Placement place(const Shape& s, const std::vector<int>& heights, int width, int gutter) {
  Placement best;
  for (int x = -s.first; x + s.last < width; ++x) {
    int y = -s.lowest;
    for (int w = 0; w < s.columns + 2 * gutter; ++w) {
      const int column = x + w - gutter;
      if (column < 0 || column >= width || s.floor[size_t(w)] == INT_MAX) continue;
      y = std::max(y, heights[size_t(column)] - s.floor[size_t(w)]);
    }
    if (y + s.highest > best.end) continue;
    Placement here{x, y, y + s.highest, 0};
    for (int c = s.first; c <= s.last; ++c)
      if (s.bottom[size_t(c)] != INT_MAX)
        here.waste += y + s.bottom[size_t(c)] - heights[size_t(x + c)];
    if (here.before(best)) best = here;
  }
  return best;
}

}  // namespace

ChartPacking packCharts(const std::vector<ChartFootprint>& upright,
                        const std::vector<ChartFootprint>& quarter, int gutter,
                        const ChartPackOptions& options) {
  ChartPacking best;
  const std::vector<ChartFootprint>& charts = upright;
  if (charts.empty()) return best;
  const bool quarters = quarter.size() == charts.size();
  std::vector<glm::ivec2> sizes(charts.size());
  double area = 0.0;
  int widest = 1;
  // Per chart: upright, upright turned, quarter, quarter turned.
  std::vector<std::vector<Shape>> shapes(charts.size());
  for (size_t i = 0; i < charts.size(); ++i) {
    sizes[i] = glm::ivec2(charts[i].columns, charts[i].rows);
    area += double(sizes[i].x + gutter) * double(sizes[i].y + gutter);
    widest = std::max(widest, quarters ? std::min(charts[i].columns, quarter[i].columns)
                                       : charts[i].columns);
    // Index o: quarter-turned when o >= 2, turned by 180 degrees when o is odd.
    const bool rigid = i < options.rigid.size() && options.rigid[i];
    if (rigid) widest = std::max(widest, charts[i].columns);
    for (int o = 0; o < (rigid ? 1 : quarters ? 4 : 2); ++o)
      shapes[i].push_back(makeShape(o >= 2 ? quarter[i] : charts[i], o % 2 == 1, gutter));
  }
  const std::vector<uint32_t> order = packingOrder(sizes);
  // Each width costs about width x sum of chart widths; bound the work per object.
  const int lowest = options.fromWidest ? widest : std::max(widest, int(std::sqrt(area) / 2.0));
  const int highest = std::min(options.maxWidth,
                               std::max(lowest, int(std::ceil(2.0 * std::sqrt(area)))));
  if (highest < widest) return best;
  double columnSum = 0.0;
  for (const ChartFootprint& f : charts) columnSum += f.columns + 2 * gutter;
  const double orientations = quarters ? 4.0 : 2.0;
  const int count =
      int(std::clamp(8e7 / (orientations * columnSum * highest + 1.0), 2.0, 48.0));
  int64_t bestScore = INT64_MAX;
  std::vector<int> heights;
  ChartPacking trial;
  for (int width : candidateWidths(lowest, highest, 1, count)) {
    heights.assign(size_t(width), 0);
    trial.corners.assign(charts.size(), glm::ivec2(0));
    trial.quarter.assign(charts.size(), false);
    trial.turned.assign(charts.size(), false);
    int usedWidth = 0, usedHeight = 0;
    bool fits = true;
    for (uint32_t i : order) {
      Placement p;
      size_t chosen = 0;
      for (size_t o = 0; o < shapes[i].size(); ++o) {
        const Placement q = place(shapes[i][o], heights, width, gutter);
        if (q.before(p)) {
          p = q;
          chosen = o;
        }
      }
      if (p.end == INT_MAX) {  // wider than the bin in every orientation
        fits = false;
        break;
      }
      const Shape& s = shapes[i][chosen];
      for (int c = 0; c < s.columns; ++c)
        if (s.top[size_t(c)] >= 0)
          heights[size_t(p.x + c)] = std::max(heights[size_t(p.x + c)], p.y + s.top[size_t(c)]);
      trial.corners[i] = glm::ivec2(p.x, p.y);
      trial.quarter[i] = chosen >= 2;
      trial.turned[i] = chosen % 2 == 1;
      usedWidth = std::max(usedWidth, p.x + s.last + 1);
      usedHeight = std::max(usedHeight, p.y + s.highest);
    }
    if (!fits) continue;
    trial.size = glm::ivec2(usedWidth, usedHeight);
    const int64_t score = options.cost ? options.cost(usedWidth, usedHeight)
                                       : int64_t(std::max(usedWidth, (usedHeight + 1) / 2)) *
                                             std::max(usedHeight, (usedWidth + 1) / 2);
    if (score < bestScore) {
      bestScore = score;
      best = trial;
    }
  }
  return best;
}

}  // namespace kiln
