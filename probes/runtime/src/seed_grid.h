// seed_grid.h: the seed grid's construction in steps (private to kiln): buildProbeSeedGrid runs
// them over a finished topology, and the topology build offers each cell as it writes it, in
// the same order (no second pass over the cells and their probes). Both give the same grid.
#pragma once

#include <cstdint>
#include <vector>

#include <glm/glm.hpp>

#include "kiln/probe_set.h"

namespace kiln::runtime_detail {

class SeedGridBuilder {
 public:
  // The grid over the bounds of every probe, sized for `innerCellCount` cells; `active` is
  // false (and offer must not be called) when the set gets no grid (dimension below 2, or no
  // inner cell).
  SeedGridBuilder(const std::vector<glm::vec3>& positions, int dimension, int32_t innerCellCount,
                  int targetCellsPerSeed);
  bool active() const { return active_; }
  // Inner cell c, offered in increasing c, with `cornerSum` the float sum of its corners in
  // slot order ((p0 + p1) + p2, then + p3 in dimension 3).
  void offer(int32_t c, glm::vec3 cornerSum) {
    const glm::vec3 f = (cornerSum * inv_ - lo_) * scale_;
    const glm::ivec3 g = glm::clamp(glm::ivec3(f), glm::ivec3(0), grid_.size - 1);
    const glm::vec3 d = f - (glm::vec3(g) + 0.5f);
    const float d2 = glm::dot(d, d);
    const size_t i = size_t(g.x) + size_t(grid_.size.x) * (size_t(g.y) +
                                                           size_t(grid_.size.y) * size_t(g.z));
    if (d2 < best_[i]) {
      best_[i] = d2;
      grid_.seeds[i] = c;
    }
  }
  // Fills the grid cells that no centroid fell in and returns the grid.
  ProbeSeedGrid finish();

 private:
  bool active_ = false;
  ProbeSeedGrid grid_;
  std::vector<float> best_;
  glm::vec3 lo_{0.0f}, scale_{0.0f};
  float inv_ = 0.25f;
};

}  // namespace kiln::runtime_detail
