// sky.cpp: constant or equirectangular environment radiance, with importance sampling.
//
// The map is sampled as in pbrt-v4's image infinite light (Pharr et al., sec. 12.5): a
// piecewise-constant distribution over (u, v) in [0,1)^2, mapped to the sphere by
// theta = pi v, phi = 2 pi (u - 0.5), whose Jacobian is 2 pi^2 sin(theta), so
// pdf_solid_angle = pdf_uv / (2 pi^2 sin(theta)).
#include "src/sky.h"

#include <algorithm>
#include <cmath>

namespace kiln {

namespace {

constexpr float kTwoPi = 2.0f * kPi;

// Map direction (before rotation) -> texture coordinates, per sky.h.
vec2 directionToUv(vec3 d) {
  float u = 0.5f + std::atan2(d.x, -d.z) / kTwoPi;
  float v = std::acos(std::clamp(d.y, -1.0f, 1.0f)) * kInvPi;
  return vec2(u, v);
}

// Inverse of directionToUv; also returns sin(theta).
vec3 uvToDirection(vec2 uv, float* sinTheta) {
  float theta = kPi * uv.y, phi = kTwoPi * (uv.x - 0.5f);
  float s = std::sin(theta);
  if (sinTheta) *sinTheta = s;
  return vec3(s * std::sin(phi), std::cos(theta), -s * std::cos(phi));
}

}  // namespace

Sky Sky::constant(vec3 color) {
  Sky sky;
  sky.color_ = glm::max(color, vec3(0.0f));
  return sky;
}

Result<Sky> Sky::fromFile(const std::string& path, float intensity, float rotationDegrees) {
  auto image = readHdrImage(path);
  if (!image.ok()) return Error{"sky map: " + image.error()};
  Sky sky = fromImage(std::move(image).value(), intensity, rotationDegrees);
  sky.path_ = path;
  return sky;
}

Sky Sky::fromImage(Image map, float intensity, float rotationDegrees) {
  Sky sky;
  sky.intensity_ = intensity;
  sky.rotationDegrees_ = rotationDegrees;
  float radians = rotationDegrees * kPi / 180.0f;
  sky.cosRot_ = std::cos(radians);
  sky.sinRot_ = std::sin(radians);
  if (map.empty()) return sky;  // nothing to show: a black sky

  const int w = map.width, h = map.height;
  // Store RGB premultiplied by the intensity; negative and non-finite values become 0.
  Image rgb(w, h, 3);
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x) {
      vec3 c = map.rgb(x, y) * intensity;
      for (int k = 0; k < 3; ++k)
        rgb.at(x, y)[k] = std::isfinite(c[k]) ? std::max(c[k], 0.0f) : 0.0f;
    }
  sky.map_ = std::move(rgb);
  sky.hasMap_ = true;

  // Sampling weights per pixel cell. radiance() interpolates bilinearly, so a cell also
  // receives light from its 8 neighbours: weighting by the neighbourhood's maximum keeps the
  // pdf positive wherever the radiance is, which keeps the estimator unbiased. Times
  // sin(theta) of the cell centre for the equirectangular area distortion.
  std::vector<float> lum(size_t(w) * h);
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x) lum[size_t(y) * w + x] = luminance(sky.map_.rgb(x, y));
  std::vector<float> weights(size_t(w) * h);
  double sum = 0.0;
  for (int y = 0; y < h; ++y) {
    float sinTheta = std::sin(kPi * (y + 0.5f) / h);
    for (int x = 0; x < w; ++x) {
      float m = 0.0f;
      for (int dy = -1; dy <= 1; ++dy) {
        int yy = std::clamp(y + dy, 0, h - 1);
        for (int dx = -1; dx <= 1; ++dx) {
          int xx = ((x + dx) % w + w) % w;
          m = std::max(m, lum[size_t(yy) * w + xx]);
        }
      }
      weights[size_t(y) * w + x] = m * sinTheta;
      sum += weights[size_t(y) * w + x];
    }
  }
  // A small floor (relative to the mean) bounds radiance/pdf for pixels whose colour has
  // almost no luminance; all-black maps sample uniformly (Distribution2D's fallback).
  if (sum > 0.0) {
    float floor = float(1e-3 * sum / double(weights.size()));
    for (int y = 0; y < h; ++y) {
      float sinTheta = std::sin(kPi * (y + 0.5f) / h);
      for (int x = 0; x < w; ++x) weights[size_t(y) * w + x] += floor * sinTheta;
    }
  }
  sky.distribution_ = Distribution2D(weights, w, h);
  return sky;
}

vec3 Sky::radiance(vec3 dir) const {
  if (!hasMap_) return color_;
  // Undo the rotation about +Y (the map turned counter-clockwise seen from above by R, so
  // look it up at R^-1 dir).
  vec3 d(cosRot_ * dir.x - sinRot_ * dir.z, dir.y, sinRot_ * dir.x + cosRot_ * dir.z);
  vec2 uv = directionToUv(d);
  const int w = map_.width, h = map_.height;
  // Bilinear between pixel centres; wrap in u (longitude), clamp in v (poles).
  float fx = uv.x * w - 0.5f, fy = uv.y * h - 0.5f;
  float x0f = std::floor(fx), y0f = std::floor(fy);
  float tx = fx - x0f, ty = fy - y0f;
  int x0 = int(x0f), y0 = int(y0f);
  int xa = ((x0 % w) + w) % w, xb = (xa + 1) % w;
  int ya = std::clamp(y0, 0, h - 1), yb = std::clamp(y0 + 1, 0, h - 1);
  vec3 top = glm::mix(map_.rgb(xa, ya), map_.rgb(xb, ya), tx);
  vec3 bottom = glm::mix(map_.rgb(xa, yb), map_.rgb(xb, yb), tx);
  return glm::mix(top, bottom, ty);
}

Sky::Sample Sky::sample(vec2 u) const {
  Sample s;
  if (!hasMap_) {
    s.direction = squareToUniformSphere(u);
    s.radiance = color_;
    s.pdf = 1.0f / (4.0f * kPi);
    return s;
  }
  float pdfUv;
  vec2 uv = distribution_.sample(u, &pdfUv);
  float sinTheta;
  vec3 d = uvToDirection(uv, &sinTheta);
  // Rotate the map direction into the world.
  s.direction =
      glm::normalize(vec3(cosRot_ * d.x + sinRot_ * d.z, d.y, -sinRot_ * d.x + cosRot_ * d.z));
  s.radiance = radiance(s.direction);
  s.pdf = sinTheta > 0.0f ? pdfUv / (2.0f * kPi * kPi * sinTheta) : 0.0f;
  return s;
}

float Sky::pdf(vec3 dir) const {
  if (!hasMap_) return 1.0f / (4.0f * kPi);
  vec3 d(cosRot_ * dir.x - sinRot_ * dir.z, dir.y, sinRot_ * dir.x + cosRot_ * dir.z);
  // sin(theta) from the horizontal components: accurate near the poles, unlike 1 - y^2.
  float sinTheta = std::sqrt(d.x * d.x + d.z * d.z);
  if (sinTheta <= 0.0f) return 0.0f;
  return distribution_.pdf(directionToUv(d)) / (2.0f * kPi * kPi * sinTheta);
}

}  // namespace kiln
