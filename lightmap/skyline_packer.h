// skyline_packer.h: deterministic rectangle packing into a fixed bin (skyline, bottom-left).
//
// Skyline-Bottom-Left from J. Jylänki, "A Thousand Ways to Pack the Bin" (2010): the bin's
// filled region is kept as a "skyline" of horizontal segments; each rectangle goes where its
// far edge is lowest, ties to the smallest x. Used twice: charts into an object's UV square
// (uv_unwrap.cpp) and objects into lightmap pages (atlas.cpp). Integer texel coordinates;
// "y" grows away from the bin's origin edge (for images: downwards from the top row).
#pragma once

#include <cstdint>
#include <glm/glm.hpp>
#include <cstdlib>
#include <optional>
#include <vector>

namespace kiln {

// One bin. Not thread-safe; cheap to construct.
class SkylinePacker {
 public:
  SkylinePacker(int width, int height);

  // Places a width x height rectangle (both >= 1) and returns its minimum corner, or nullopt
  // when it does not fit anywhere in the bin (the bin is then unchanged).
  std::optional<glm::ivec2> insert(int width, int height);

  int width() const { return width_; }
  int height() const { return height_; }
  // The highest far edge of the rectangles placed so far (0 when empty): the bin could have
  // been this tall.
  int usedHeight() const;

 private:
  struct Segment {
    int x, y, width;  // the skyline is at height y over [x, x + width)
  };
  int width_, height_;
  std::vector<Segment> skyline_;  // sorted by x, covering [0, width_)
};

// Packs `sizes` in `order` into bins of each width in `widths` (ascending) and height
// maxHeight, and keeps the packing whose page(width, usedHeight) has the smallest area (ties:
// the squarer page, then the narrower). `page` maps a bin width and its used height to the
// page that would hold it (padding, alignment). nullopt when no width holds every rectangle.
struct BinPacking {
  glm::ivec2 page{0};
  std::vector<glm::ivec2> corners;  // per entry of sizes (those in order), in the bin
};
template <typename PageOf>
std::optional<BinPacking> packSmallest(const std::vector<glm::ivec2>& sizes,
                                       const std::vector<uint32_t>& order,
                                       const std::vector<int>& widths, int maxHeight,
                                       PageOf page) {
  std::optional<BinPacking> best;
  std::vector<glm::ivec2> corners(sizes.size());
  for (int w : widths) {
    SkylinePacker packer(w, maxHeight);
    bool fits = true;
    for (uint32_t i : order) {
      const auto at = packer.insert(sizes[i].x, sizes[i].y);
      if (!at) {
        fits = false;
        break;
      }
      corners[i] = *at;
    }
    if (!fits) continue;
    const glm::ivec2 p = page(w, packer.usedHeight());
    const int64_t a = int64_t(p.x) * p.y;
    const int64_t b = best ? int64_t(best->page.x) * best->page.y : 0;
    if (!best || a < b ||
        (a == b && std::abs(p.x - p.y) < std::abs(best->page.x - best->page.y)))
      best = BinPacking{p, corners};
  }
  return best;
}

// Up to `count` widths from lo to hi (inclusive, ascending), multiples of `align` except
// possibly hi itself.
std::vector<int> candidateWidths(int lo, int hi, int align, int count);

// The order rectangles are inserted in: height descending, then width descending, then index
// ascending, so that equal inputs always pack the same way (a total order: no unstable sort).
std::vector<uint32_t> packingOrder(const std::vector<glm::ivec2>& sizes);

}  // namespace kiln
