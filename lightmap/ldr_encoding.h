// ldr_encoding.h: 8-bit encodings of lightmaps for LDR targets (MISSION.md "Lightmaps:
// Output"): RGBM and double-LDR (dLDR), after Unity's encodings of the same names, and their
// PNG files.
//
// Input texels are linear E/pi (MISSION.md "Conventions"); bytes are row-major from the top
// row (row 0 = v 0), so the PNG needs no flip for glTF texture coordinates.
//
// Decoding in a shader (s = the texture sample in [0, 1], as the GPU returns it):
//
//   kiln RGBM (range R = 8; sample the PNG as a LINEAR / UNORM texture, not sRGB):
//     vec3 lightmap = s.rgb * s.a * 8.0;
//   kiln dLDR, sRGB variant (the default; sample the PNG as an sRGB texture so the GPU
//   linearises it):
//     vec3 lightmap = 2.0 * s.rgb;
//   kiln dLDR, linear variant (sample as a LINEAR / UNORM texture):
//     vec3 lightmap = 2.0 * s.rgb;
//
// The result is the linear lightmap value E/pi; shade with albedo * lightmap. Unity's own
// RGBM (range 5, gamma space) and dLDR (2 x gamma value, or 4.59 x linear value) differ from
// kiln's in where the transfer function sits; kiln keeps everything linear except the
// optional sRGB storage of dLDR, which the sampler undoes.
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include "src/image.h"
#include "kiln/result.h"

namespace kiln {

// kiln's RGBM range: decoded values span [0, 8] (E/pi).
inline constexpr float kRgbmRange = 8.0f;
// dLDR's range: decoded values span [0, 2].
inline constexpr float kDldrRange = 2.0f;

// 8-bit image, row-major from the top row, `channels` interleaved bytes per texel.
struct LdrImage {
  int width = 0;
  int height = 0;
  int channels = 0;  // 4 for RGBM, 3 for dLDR
  std::vector<uint8_t> bytes;
};

// RGBM, all linear. Per texel, with c = clamp(rgb, 0, range) (NaN -> 0):
//   A = max(1, ceil(255 * max(c.r, c.g, c.b) / range))       (the multiplier M = A / 255)
//   RGB = round(255 * c / (M * range))                       (in [0, 255] since max(c) <= M R)
// Decode: rgb = RGB / 255 * A / 255 * range. Rounding up M keeps the largest channel's code
// near 255, so every channel's error is at most 0.5 / 255 * M * range
// <= 0.5 / 255 * (max(c) + range / 255): relative precision near 1/510 over the whole range.
// Values above `range` clamp to it. The image needs >= 3 channels (a grey image: >= 1).
LdrImage encodeRgbm(const Image& image, float range = kRgbmRange);
// The inverse: a 3-channel linear image. `ldr` must have 4 channels.
Image decodeRgbm(const LdrImage& ldr, float range = kRgbmRange);

// Double LDR: stored = clamp(rgb, 0, 2) / 2 in [0, 1], as
//   srgb:   byte = round(255 * linearToSrgb(stored))  (decode: 2 * srgbToLinear(byte / 255))
//   linear: byte = round(255 * stored)                (decode: 2 * byte / 255)
// The sRGB variant spends its codes on dark values like an sRGB texture does: its error is at
// most half the decoded step between neighbouring codes; the linear variant's is 1 / 255.
LdrImage encodeDldr(const Image& image, bool srgb = true);
Image decodeDldr(const LdrImage& ldr, bool srgb = true);

// Writes an 8-bit PNG of `ldr` (3 or 4 channels), first to `path`.tmp, then renamed.
// Errors name the file.
Status writeLdrPng(const std::string& path, const LdrImage& ldr);

}  // namespace kiln
