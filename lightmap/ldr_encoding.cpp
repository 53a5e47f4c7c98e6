// ldr_encoding.cpp: RGBM and dLDR 8-bit lightmap encodings (formulas in ldr_encoding.h) and
// their PNG writer.
#include "lightmap/ldr_encoding.h"

#include <algorithm>
#include <cassert>
#include <cmath>

namespace kiln {

namespace {

float clean(float v, float hi) { return std::isnan(v) ? 0.0f : std::clamp(v, 0.0f, hi); }

uint8_t toByte(float unit) { return uint8_t(std::lround(std::clamp(unit, 0.0f, 1.0f) * 255.0f)); }

vec3 texelRgb(const Image& image, size_t i) {
  const float* p = &image.pixels[i * size_t(image.channels)];
  return image.channels >= 3 ? vec3(p[0], p[1], p[2]) : vec3(p[0]);
}

}  // namespace

LdrImage encodeRgbm(const Image& image, float range) {
  assert(image.channels >= 1 && range > 0.0f);
  LdrImage out{image.width, image.height, 4, {}};
  const size_t n = size_t(image.width) * size_t(image.height);
  out.bytes.resize(n * 4);
  for (size_t i = 0; i < n; ++i) {
    const vec3 rgb = texelRgb(image, i);
    const vec3 c(clean(rgb.r, range), clean(rgb.g, range), clean(rgb.b, range));
    // Round the multiplier up so that c / (M range) <= 1 and the largest channel uses the top
    // of the 8-bit range; at least 1 so that black decodes to exactly 0 without dividing by 0.
    const int a = std::clamp(int(std::ceil(255.0 * double(maxComponent(c)) / range)), 1, 255);
    const double m = double(a) / 255.0 * range;
    uint8_t* o = &out.bytes[i * 4];
    for (int k = 0; k < 3; ++k)
      o[k] = uint8_t(std::clamp<long>(std::lround(255.0 * double(c[k]) / m), 0, 255));
    o[3] = uint8_t(a);
  }
  return out;
}

Image decodeRgbm(const LdrImage& ldr, float range) {
  assert(ldr.channels == 4);
  Image out(ldr.width, ldr.height, 3);
  const size_t n = size_t(ldr.width) * size_t(ldr.height);
  for (size_t i = 0; i < n; ++i) {
    const uint8_t* b = &ldr.bytes[i * 4];
    const float m = float(b[3]) / 255.0f * range;
    for (int k = 0; k < 3; ++k) out.pixels[i * 3 + size_t(k)] = float(b[k]) / 255.0f * m;
  }
  return out;
}

LdrImage encodeDldr(const Image& image, bool srgb) {
  assert(image.channels >= 1);
  LdrImage out{image.width, image.height, 3, {}};
  const size_t n = size_t(image.width) * size_t(image.height);
  out.bytes.resize(n * 3);
  for (size_t i = 0; i < n; ++i) {
    const vec3 rgb = texelRgb(image, i);
    for (int k = 0; k < 3; ++k) {
      const float stored = clean(rgb[k], kDldrRange) / kDldrRange;
      out.bytes[i * 3 + size_t(k)] = toByte(srgb ? linearToSrgb(stored) : stored);
    }
  }
  return out;
}

Image decodeDldr(const LdrImage& ldr, bool srgb) {
  assert(ldr.channels == 3);
  Image out(ldr.width, ldr.height, 3);
  for (size_t i = 0; i < ldr.bytes.size(); ++i) {
    const float s = float(ldr.bytes[i]) / 255.0f;
    out.pixels[i] = kDldrRange * (srgb ? srgbToLinear(s) : s);
  }
  return out;
}

Status writeLdrPng(const std::string& path, const LdrImage& ldr) {
  assert(ldr.channels >= 1 && ldr.channels <= 4);
  assert(ldr.bytes.size() == size_t(ldr.width) * size_t(ldr.height) * size_t(ldr.channels));
  // writePng quantises lround(v * 255) of values in [0, 1]; b / 255 comes back as exactly b
  // (the float error is far below half a code), so its atomic writer is reused as is.
  Image image(ldr.width, ldr.height, ldr.channels);
  for (size_t i = 0; i < ldr.bytes.size(); ++i) image.pixels[i] = float(ldr.bytes[i]) / 255.0f;
  return writePng(path, image);
}

}  // namespace kiln
