// visibility_bake.cpp: see visibility_bake.h.
#include "probes/visibility_bake.h"

#include <algorithm>
#include <cmath>
#include <optional>

#include "kiln/probe_set.h"
#include "kiln/probe_visibility.h"

namespace kiln {
namespace {

constexpr int kSums = 11;  // 10 sums and the largest s

uint16_t unorm16(double v) { return uint16_t(std::lround(std::clamp(v, 0.0, 1.0) * 65535.0)); }

double det3(const double m[3][3]) {
  return m[0][0] * (m[1][1] * m[2][2] - m[1][2] * m[2][1]) -
         m[0][1] * (m[1][0] * m[2][2] - m[1][2] * m[2][0]) +
         m[0][2] * (m[1][0] * m[2][1] - m[1][1] * m[2][0]);
}

}  // namespace

VisibilityMapBuilder::VisibilityMapBuilder(const VisibilityMapSpec& spec)
    : spec_(spec), sums_(kSums * size_t(spec.resolution) * size_t(spec.resolution), 0.0) {}

void VisibilityMapBuilder::accumulate(int32_t texel, float xf, float yf, float sf) {
  const double x = xf, y = yf, s = sf;
  double* t = &sums_[kSums * size_t(texel)];
  t[0] += 1.0;
  t[1] += x;
  t[2] += y;
  t[3] += x * x;
  t[4] += x * y;
  t[5] += y * y;
  t[6] += s;
  t[7] += s * x;
  t[8] += s * y;
  t[9] += s * s;
  t[10] = std::max(t[10], s);
}

void VisibilityMapBuilder::add(vec3 direction, float distance) {
  const int32_t r = spec_.resolution;
  if (r <= 0) return;
  const float s = std::isfinite(distance) ? std::clamp(distance / spec_.maxDistance, 0.0f, 1.0f)
                                          : 1.0f;
  const vec2 uv = octahedralEncode(direction);
  const float fx = std::clamp((uv.x + 1.0f) * 0.5f * float(r), 0.0f, float(r) - 1e-3f);
  const float fy = std::clamp((uv.y + 1.0f) * 0.5f * float(r), 0.0f, float(r) - 1e-3f);
  const int32_t i = int32_t(fx), j = int32_t(fy);
  accumulate(j * r + i, fx - float(i) - 0.5f, fy - float(j) - 0.5f, s);
}

std::vector<uint16_t> VisibilityMapBuilder::finish(const Tracer& tracer, vec3 probe) {
  const int32_t r = spec_.resolution;
  std::vector<uint16_t> out(kVisibilityValuesPerTexel * size_t(r) * size_t(r), 0);
  for (int32_t j = 0; j < r; ++j) {
    for (int32_t i = 0; i < r; ++i) {
      const int32_t texel = j * r + i;
      if (sums_[kSums * size_t(texel)] < double(kMinRaysPerTexel)) {
        for (int k = 0; k < 4; ++k) {
          const float x = (k & 1) ? 0.25f : -0.25f, y = (k & 2) ? 0.25f : -0.25f;
          const vec2 uv((float(i) + 0.5f + x) * 2.0f / float(r) - 1.0f,
                        (float(j) + 0.5f + y) * 2.0f / float(r) - 1.0f);
          const std::optional<Hit> hit =
              tracer.intersect(Ray{probe, octahedralDecode(uv), 0.0f, kInfinity});
          const float s = hit ? std::clamp(hit->t / spec_.maxDistance, 0.0f, 1.0f) : 1.0f;
          accumulate(texel, x, y, s);
        }
      }
      // Least squares s = mu + a x + b y: the normal equations, with a small ridge on a and b
      // so that a texel whose rays fall on a line (or on one point) still solves (its slope
      // then goes to 0 and mu to the mean).
      const double* t = &sums_[kSums * size_t(texel)];
      const double n = t[0], ridge = 1e-3 * n;
      const double m[3][3] = {{n, t[1], t[2]}, {t[1], t[3] + ridge, t[4]}, {t[2], t[4], t[5] + ridge}};
      const double rhs[3] = {t[6], t[7], t[8]};
      const double det = det3(m);
      double c[3] = {t[6] / n, 0.0, 0.0};
      if (std::fabs(det) > 1e-12 * n * n * n) {
        // Cramer's rule, column k replaced by the right-hand side.
        for (int k = 0; k < 3; ++k) {
          double a[3][3];
          for (int row = 0; row < 3; ++row)
            for (int col = 0; col < 3; ++col) a[row][col] = col == k ? rhs[row] : m[row][col];
          c[k] = det3(a) / det;
        }
      }
      // Residual sum of squares: sum (s - c0 - c1 x - c2 y)^2 expanded over the sums.
      const double sse = t[9] - 2.0 * (c[0] * t[6] + c[1] * t[7] + c[2] * t[8]) +
                         c[0] * c[0] * n + c[1] * c[1] * t[3] + c[2] * c[2] * t[5] +
                         2.0 * (c[0] * c[1] * t[1] + c[0] * c[2] * t[2] + c[1] * c[2] * t[4]);
      uint16_t* o = &out[kVisibilityValuesPerTexel * size_t(texel)];
      o[0] = unorm16(c[0]);
      o[1] = unorm16(std::min(std::sqrt(std::max(sse / n, 0.0)), 0.5));
      o[2] = unorm16(t[10]);
    }
  }
  return out;
}

std::vector<float> visibilityMaxDistances(std::span<const vec3> positions, const Bounds3& bounds) {
  Bounds3 b = bounds;
  for (const vec3& p : positions) b.extend(p);
  std::vector<float> d(positions.size(), 1.0f);
  for (size_t i = 0; i < positions.size(); ++i) {
    const vec3 far = glm::max(glm::abs(b.max - positions[i]), glm::abs(positions[i] - b.min));
    const float l = glm::length(far);
    d[i] = std::isfinite(l) ? std::max(l, 1e-3f) : 1.0f;
  }
  return d;
}

}  // namespace kiln
