// visibility_bake.cpp: see visibility_bake.h.
#include "probes/visibility_bake.h"

#include <algorithm>
#include <cmath>

#include "kiln/probe_visibility.h"

namespace kiln {

VisibilityMapBuilder::VisibilityMapBuilder(const VisibilityMapSpec& spec)
    : spec_(spec), sums_(3 * size_t(spec.resolution) * size_t(spec.resolution), 0.0) {}

void VisibilityMapBuilder::splat(int32_t texel, float weight, float s) {
  double* t = &sums_[3 * size_t(texel)];
  t[0] += weight;
  t[1] += double(weight) * s;
  t[2] += double(weight) * s * s;
}

void VisibilityMapBuilder::add(vec3 direction, float distance) {
  if (spec_.resolution <= 0) return;
  const float s = std::isfinite(distance) ? std::clamp(distance / spec_.maxDistance, 0.0f, 1.0f)
                                          : 1.0f;
  const OctahedralFootprint f = octahedralFootprint(octahedralEncode(direction), spec_.resolution);
  for (int k = 0; k < 4; ++k)
    if (f.weight[k] > 0.0f) splat(f.texel[k], f.weight[k], s);
}

std::vector<uint16_t> VisibilityMapBuilder::finish(const Tracer& tracer, vec3 probe) {
  const int32_t r = spec_.resolution;
  std::vector<uint16_t> out(2 * size_t(r) * size_t(r), 0);
  for (int32_t j = 0; j < r; ++j) {
    for (int32_t i = 0; i < r; ++i) {
      const int32_t texel = j * r + i;
      if (sums_[3 * size_t(texel)] < 0.5) {
        const vec2 uv((float(i) + 0.5f) * 2.0f / float(r) - 1.0f,
                      (float(j) + 0.5f) * 2.0f / float(r) - 1.0f);
        const vec3 d = octahedralDecode(uv);
        const std::optional<Hit> hit = tracer.intersect(Ray{probe, d, 0.0f, kInfinity});
        const float s = hit ? std::clamp(hit->t / spec_.maxDistance, 0.0f, 1.0f) : 1.0f;
        splat(texel, 1.0f, s);
      }
      const double* t = &sums_[3 * size_t(texel)];
      const double mean = t[1] / t[0], meanSquare = t[2] / t[0];
      auto unorm = [](double v) { return uint16_t(std::lround(std::clamp(v, 0.0, 1.0) * 65535.0)); };
      out[2 * size_t(texel)] = unorm(mean);
      out[2 * size_t(texel) + 1] = unorm(std::max(meanSquare, mean * mean));
    }
  }
  return out;
}

std::vector<float> visibilityMaxDistances(std::span<const vec3> positions,
                                          std::span<const glm::ivec4> cells) {
  std::vector<float> d(positions.size(), 0.0f);
  for (const glm::ivec4& c : cells) {
    for (int a = 0; a < 4; ++a) {
      if (c[a] < 0) continue;
      for (int b = a + 1; b < 4; ++b) {
        if (c[b] < 0) continue;
        const float l = glm::length(positions[size_t(c[a])] - positions[size_t(c[b])]);
        d[size_t(c[a])] = std::max(d[size_t(c[a])], l);
        d[size_t(c[b])] = std::max(d[size_t(c[b])], l);
      }
    }
  }
  float largest = 0.0f;
  for (float v : d) largest = std::max(largest, v);
  if (!(largest > 0.0f) || !std::isfinite(largest)) largest = 1.0f;
  for (float& v : d)
    if (!(v > 0.0f) || !std::isfinite(v)) v = largest;
  return d;
}

}  // namespace kiln
