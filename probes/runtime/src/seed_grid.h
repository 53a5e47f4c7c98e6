// seed_grid.h: the seed grid's construction in steps (private to kiln): buildProbeSeedGrid runs
// them over a finished topology, and the topology build offers each cell as it writes it, in
// the same order (no second pass over the cells and their probes). Both give the same grid.
#pragma once

#include <algorithm>
#include <bit>
#include <cstdint>
#include <limits>
#include <vector>

#include <glm/glm.hpp>

#include "kiln/probe_set.h"
#include "prefetch.h"

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
  void offer(int32_t c, glm::vec3 cornerSum) { commit(prepare(c, cornerSum)); }
  // offer in two steps, for a caller that prepares each offer a few cells ahead of committing
  // it (in the same order) so that the grid cell's line, fetched by prepare, has arrived: the
  // grid is 5 MB at 100k probes, and its lines are first read in this pass.
  struct Offer {
    size_t index;  // grid cell
    uint64_t key;
  };
  Offer prepare(int32_t c, glm::vec3 cornerSum) const {
    const glm::vec3 f = (cornerSum * inv_ - lo_) * scale_;
    const glm::ivec3 g = glm::clamp(glm::ivec3(f), glm::ivec3(0), grid_.size - 1);
    const glm::vec3 d = f - (glm::vec3(g) + 0.5f);
    const float d2 = glm::dot(d, d);
    const size_t i = size_t(g.x) + size_t(grid_.size.x) * (size_t(g.y) +
                                                           size_t(grid_.size.y) * size_t(g.z));
    // The nearest centroid so far and its cell in one word (d2 >= 0, so its float bits order
    // as its values; on a tie the smaller c, the earlier offer, wins): one line per offer. A
    // distance that is not below infinity (overflow, NaN) never takes a grid cell.
    const uint64_t k = d2 < std::numeric_limits<float>::infinity()
                           ? uint64_t(std::bit_cast<uint32_t>(d2)) << 32 | uint32_t(c)
                           : kEmpty;
    prefetch(&key_[i]);
    return {i, k};
  }
  void commit(Offer o) { key_[o.index] = std::min(key_[o.index], o.key); }
  // Fills the grid cells that no centroid fell in and returns the grid.
  ProbeSeedGrid finish();

 private:
  bool active_ = false;
  static constexpr uint64_t kEmpty = ~uint64_t(0);
  ProbeSeedGrid grid_;
  // Per grid cell: the float bits of the best squared distance << 32 | its cell, or kEmpty.
  std::vector<uint64_t> key_;
  glm::vec3 lo_{0.0f}, scale_{0.0f};
  float inv_ = 0.25f;
};

}  // namespace kiln::runtime_detail
