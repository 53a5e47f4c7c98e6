// image.h: float images in memory and their files (OpenEXR, Radiance HDR, PNG).
//
// Orientation: row 0 is the top of the image, which is glTF's texture coordinate v = 0
// (MISSION.md, "Conventions"). Pixel (x, y) covers u in [x, x+1]/width, v in [y, y+1]/height.
// Values are linear; nothing here applies a transfer function unless the name says so.
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include "src/math.h"
#include "kiln/result.h"

namespace kiln {

// A float image with 1 to 4 interleaved channels, row-major from the top row.
struct Image {
  int width = 0;
  int height = 0;
  int channels = 0;
  std::vector<float> pixels;  // width * height * channels

  Image() = default;
  Image(int w, int h, int c) : width(w), height(h), channels(c), pixels(size_t(w) * h * c, 0.0f) {}

  bool empty() const { return width == 0 || height == 0; }
  float* at(int x, int y) { return &pixels[(size_t(y) * width + x) * channels]; }
  const float* at(int x, int y) const { return &pixels[(size_t(y) * width + x) * channels]; }
  // The first three channels as RGB (a 1-channel image gives grey).
  vec3 rgb(int x, int y) const;
};

// Reads an OpenEXR (RGB or RGBA; missing channels are filled: A = 1) or a Radiance .hdr
// image, chosen by the file's contents. Errors name the file.
Result<Image> readHdrImage(const std::string& path);

// Writes an OpenEXR with HALF (or FLOAT when `fullFloat`) channels R, G, B (and A when the
// image has 4 channels). Writes `path`.tmp first and renames it, so a failed or interrupted
// write never leaves a half-written file at `path`.
Status writeExr(const std::string& path, const Image& image, bool fullFloat = false);

// Writes an 8-bit PNG of the image's values clamped to [0, 1] (no transfer function is
// applied: convert first if you want sRGB). Atomic like writeExr.
Status writePng(const std::string& path, const Image& image);

// sRGB transfer functions (IEC 61966-2-1).
float srgbToLinear(float c);
float linearToSrgb(float c);

}  // namespace kiln
