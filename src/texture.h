// texture.h: material textures, decoded to linear float RGBA and sampled with glTF samplers.
#pragma once

#include <cmath>
#include <string>

#include "src/image.h"
#include "src/math.h"

namespace kiln {

// glTF sampler wrap modes (the glTF enum values).
enum class Wrap { Repeat = 10497, ClampToEdge = 33071, MirroredRepeat = 33648 };

struct TextureSampler {
  Wrap wrapS = Wrap::Repeat;
  Wrap wrapT = Wrap::Repeat;
  bool nearest = false;  // magFilter NEAREST; otherwise bilinear
};

// KHR_texture_transform on one textureInfo: uv' = T(offset) * R(rotation) * S(scale) * uv, with
// the ratified extension's rotation (counter-clockwise in UV space: u' = cos u + sin v,
// v' = -sin u + cos v, which turns the image clockwise). Identity when absent.
struct TextureTransform {
  vec2 offset{0.0f};
  float rotation = 0.0f;  // radians
  vec2 scale{1.0f};

  vec2 apply(vec2 uv) const {
    const float c = std::cos(rotation), s = std::sin(rotation);
    const vec2 p = uv * scale;
    return vec2(c * p.x + s * p.y, -s * p.x + c * p.y) + offset;
  }
};

// A texture as a material uses it: an RGBA image in linear values (colour textures are
// converted from sRGB when loaded; alpha is always linear) plus its sampler.
struct Texture {
  std::string name;  // for messages: "textures[3] (leaves.png)"
  Image image;       // 4 channels, linear
  TextureSampler sampler;
  vec4 average{0.0f};  // mean RGBA over the image, used for emissive power estimates

  // Samples at glTF texture coordinate uv ((0,0) = top-left of the image) with the
  // texture's wrap modes and filter. Thread-safe.
  vec4 sample(vec2 uv) const;
};

}  // namespace kiln
