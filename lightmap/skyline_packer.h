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

 private:
  struct Segment {
    int x, y, width;  // the skyline is at height y over [x, x + width)
  };
  int width_, height_;
  std::vector<Segment> skyline_;  // sorted by x, covering [0, width_)
};

// The order rectangles are inserted in: height descending, then width descending, then index
// ascending, so that equal inputs always pack the same way (a total order: no unstable sort).
std::vector<uint32_t> packingOrder(const std::vector<glm::ivec2>& sizes);

}  // namespace kiln
