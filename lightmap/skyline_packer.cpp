// skyline_packer.cpp: Skyline-Bottom-Left packing (Jylänki 2010, "A Thousand Ways to Pack the
// Bin", section 4).
#include "lightmap/skyline_packer.h"

#include <algorithm>
#include <cassert>
#include <climits>
#include <numeric>

namespace kiln {

SkylinePacker::SkylinePacker(int width, int height) : width_(width), height_(height) {
  if (width_ > 0 && height_ > 0) skyline_.push_back({0, 0, width_});
}

std::optional<glm::ivec2> SkylinePacker::insert(int width, int height) {
  assert(width >= 1 && height >= 1);
  int bestIndex = -1, bestTop = INT_MAX, bestX = 0, bestY = 0;
  for (size_t i = 0; i < skyline_.size(); ++i) {
    const int x = skyline_[i].x;
    if (x + width > width_) break;  // segments are sorted by x: no later start fits either
    // The rectangle rests on the highest segment under [x, x + width).
    int y = 0;
    for (size_t j = i, covered = 0; covered < size_t(width); ++j) {
      y = std::max(y, skyline_[j].y);
      covered += size_t(skyline_[j].width);
    }
    if (y + height > height_) continue;
    if (y + height < bestTop) {  // strict: ties keep the smaller x
      bestTop = y + height;
      bestIndex = int(i);
      bestX = x;
      bestY = y;
    }
  }
  if (bestIndex < 0) return std::nullopt;

  // Raise the skyline over [bestX, bestX + width).
  skyline_.insert(skyline_.begin() + bestIndex, Segment{bestX, bestY + height, width});
  const int end = bestX + width;
  for (size_t i = size_t(bestIndex) + 1; i < skyline_.size();) {
    Segment& s = skyline_[i];
    if (s.x >= end) break;
    if (s.x + s.width <= end) {
      skyline_.erase(skyline_.begin() + long(i));
      continue;
    }
    s.width -= end - s.x;
    s.x = end;
    break;
  }
  // Merge neighbours at the same height.
  for (size_t i = 0; i + 1 < skyline_.size();) {
    if (skyline_[i].y == skyline_[i + 1].y) {
      skyline_[i].width += skyline_[i + 1].width;
      skyline_.erase(skyline_.begin() + long(i) + 1);
    } else {
      ++i;
    }
  }
  return glm::ivec2(bestX, bestY);
}

int SkylinePacker::usedHeight() const {
  int y = 0;
  for (const Segment& s : skyline_) y = std::max(y, s.y);
  return y;
}

std::vector<int> candidateWidths(int lo, int hi, int align, int count) {
  lo = std::min((lo + align - 1) / align * align, hi);
  const int step = std::max(align, (hi - lo) / std::max(1, count - 1) / align * align);
  std::vector<int> widths;
  for (int w = lo; w < hi; w += step) widths.push_back(w);
  widths.push_back(hi);
  return widths;
}

std::vector<uint32_t> packingOrder(const std::vector<glm::ivec2>& sizes) {
  std::vector<uint32_t> order(sizes.size());
  std::iota(order.begin(), order.end(), 0u);
  std::sort(order.begin(), order.end(), [&](uint32_t a, uint32_t b) {
    if (sizes[a].y != sizes[b].y) return sizes[a].y > sizes[b].y;
    if (sizes[a].x != sizes[b].x) return sizes[a].x > sizes[b].x;
    return a < b;
  });
  return order;
}

}  // namespace kiln
