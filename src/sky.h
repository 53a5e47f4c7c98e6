// sky.h: the environment around the scene: a constant radiance or an equirectangular
// (latitude-longitude) HDR/EXR map times an intensity, importance-sampled.
//
// Map convention: direction d (glTF world, unit) maps to texture coordinates
//   u = 0.5 + atan2(d.x, -d.z) / (2 pi),   v = acos(d.y) / pi,
// so the image centre looks down -Z, u = 0.75 looks down +X, row 0 is straight up (+Y).
#pragma once

#include <string>

#include "src/image.h"
#include "src/math.h"
#include "kiln/result.h"
#include "src/sampling.h"

namespace kiln {

class Sky {
 public:
  // A constant sky of radiance `color` (W/(m^2 sr) in kiln's units; black = no sky).
  static Sky constant(vec3 color);
  // An equirectangular map loaded from `path` (Radiance .hdr or OpenEXR), scaled by
  // `intensity`, rotated by `rotationDegrees` about +Y (counter-clockwise seen from above).
  static Result<Sky> fromFile(const std::string& path, float intensity = 1.0f,
                              float rotationDegrees = 0.0f);
  // Same, from an image already in memory (tests).
  static Sky fromImage(Image map, float intensity = 1.0f, float rotationDegrees = 0.0f);

  Sky() = default;

  bool isBlack() const { return !hasMap_ && maxComponent(color_) <= 0.0f; }
  bool hasMap() const { return hasMap_; }
  vec3 color() const { return color_; }
  const std::string& path() const { return path_; }
  float intensity() const { return intensity_; }
  float rotationDegrees() const { return rotationDegrees_; }

  // Radiance arriving from direction `dir` (unit, pointing away from the receiver).
  vec3 radiance(vec3 dir) const;

  struct Sample {
    vec3 direction;  // unit, towards the sky
    vec3 radiance;
    float pdf;  // solid angle; 0 only for a degenerate sample exactly at a pole (skip it)
  };
  // Importance-samples a direction (by the map's luminance x sin(theta); uniform sphere for
  // a constant sky).
  Sample sample(vec2 u) const;
  float pdf(vec3 dir) const;

 private:
  vec3 color_{0.0f};
  bool hasMap_ = false;
  std::string path_;
  float intensity_ = 1.0f;
  float rotationDegrees_ = 0.0f;
  float cosRot_ = 1.0f, sinRot_ = 0.0f;
  Image map_;
  Distribution2D distribution_;
};

}  // namespace kiln
