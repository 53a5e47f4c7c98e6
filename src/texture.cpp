// texture.cpp: glTF texture sampling (wrap modes, nearest or bilinear filtering).
#include "src/texture.h"

#include <cmath>

namespace kiln {

namespace {

// Maps an integer texel coordinate into [0, size) by the glTF wrap mode.
int wrapIndex(int i, int size, Wrap wrap) {
  switch (wrap) {
    case Wrap::ClampToEdge:
      return std::clamp(i, 0, size - 1);
    case Wrap::MirroredRepeat: {
      int period = 2 * size;
      int m = ((i % period) + period) % period;
      return m < size ? m : period - 1 - m;
    }
    case Wrap::Repeat:
    default:
      return ((i % size) + size) % size;
  }
}

vec4 texel(const Image& image, int x, int y) {
  const float* p = image.at(x, y);
  return vec4(p[0], p[1], p[2], p[3]);
}

}  // namespace

vec4 Texture::sample(vec2 uv) const {
  if (image.empty() || image.channels != 4 || !std::isfinite(uv.x) || !std::isfinite(uv.y))
    return vec4(1.0f);
  const int w = image.width, h = image.height;
  // Texel (x, y) covers [x, x+1] / w: its centre is at (x + 0.5) / w.
  float fx = uv.x * float(w) - 0.5f;
  float fy = uv.y * float(h) - 0.5f;
  // Keep integer conversions defined for huge coordinates: clamped axes saturate, repeating
  // axes are reduced by a whole number of periods (w * 1024 is a multiple of both periods).
  auto reduce = [](float f, int size, Wrap wrap) {
    if (wrap == Wrap::ClampToEdge) return std::clamp(f, -1.0f, float(size));
    return std::fmod(f, float(size) * 1024.0f);
  };
  fx = reduce(fx, w, sampler.wrapS);
  fy = reduce(fy, h, sampler.wrapT);
  if (sampler.nearest) {
    int x = wrapIndex(int(std::floor(fx + 0.5f)), w, sampler.wrapS);
    int y = wrapIndex(int(std::floor(fy + 0.5f)), h, sampler.wrapT);
    return texel(image, x, y);
  }
  const float x0f = std::floor(fx), y0f = std::floor(fy);
  const float tx = fx - x0f, ty = fy - y0f;
  const int x0 = int(x0f), y0 = int(y0f);
  const int xa = wrapIndex(x0, w, sampler.wrapS), xb = wrapIndex(x0 + 1, w, sampler.wrapS);
  const int ya = wrapIndex(y0, h, sampler.wrapT), yb = wrapIndex(y0 + 1, h, sampler.wrapT);
  const vec4 top = glm::mix(texel(image, xa, ya), texel(image, xb, ya), tx);
  const vec4 bottom = glm::mix(texel(image, xa, yb), texel(image, xb, yb), tx);
  return glm::mix(top, bottom, ty);
}

}  // namespace kiln
