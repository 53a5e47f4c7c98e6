// probe_visibility_test.cpp: per-probe visibility (kiln/probe_visibility.h): the octahedral
// map, the Chebyshev weight and the visibility-weighted blend.
#include <gtest/gtest.h>

#include <cmath>
#include <random>

#include "kiln/probe_visibility.h"

namespace kiln {
namespace {

// Encoding then decoding a unit direction gives it back (the map is a bijection of the sphere).
TEST(Octahedral, RoundTripsEveryDirection) {
  std::mt19937 rng(7);
  std::normal_distribution<float> n;
  for (int i = 0; i < 10000; ++i) {
    const glm::vec3 d = glm::normalize(glm::vec3(n(rng), n(rng), n(rng)));
    const glm::vec2 uv = octahedralEncode(d);
    EXPECT_LE(std::fabs(uv.x), 1.0f);
    EXPECT_LE(std::fabs(uv.y), 1.0f);
    const glm::vec3 back = octahedralDecode(uv);
    EXPECT_NEAR(glm::dot(back, d), 1.0f, 1e-5f) << i;
  }
}

}  // namespace
}  // namespace kiln
