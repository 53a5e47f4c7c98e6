// probe_visibility.h: per-probe visibility (depth moments over an octahedral map) and the
// Chebyshev weight that keeps probe blending from leaking light through walls.
//
// Every probe stores, for each direction texel of an R x R octahedral map, the mean and the
// mean square of the distance its bake rays travelled before their first hit (clamped to a
// per-probe maxDistance D, a ray that hits nothing counting as D), both divided by D (resp.
// D^2) and stored as unorm16. At run time the weight of probe k for a point p is its
// barycentric weight times
//
//   v_k(p) = 1                                           if d <= mu
//          = (sigma^2 / (sigma^2 + (d - mu)^2))^3        otherwise
//
// where d = min(|p' - x_k| - distanceBias, D) / D is the normalized distance from the probe to
// the biased point p' = p + normalBias * n (n: the surface normal at p, when the caller has
// one), mu and m2 are the moments bilinearly sampled in the direction from the probe to p',
// and sigma^2 = max(m2 - mu^2, (minSigma / D)^2). That is the one-sided Chebyshev bound on the
// probability that the probe's rays reach distance d (variance shadow maps; DDGI, Majercik et
// al. 2019, cubes it to sharpen the cut-off). The weights are renormalized; each v is floored
// at kVisibilityFloor, so a point that no probe of its cell sees gets the plain barycentric
// blend, and the blend is continuous in p (the map is sampled with octahedral wrapping, the
// test is continuous in d and mu, and a face shared by two cells has the same three probes
// with the same weights on both sides).
//
// Only GLM: this is part of kiln_runtime.
#pragma once

#include <cstdint>
#include <span>

#include <glm/glm.hpp>

namespace kiln {

// Smallest and largest octahedral map side a file may hold.
inline constexpr int32_t kMinVisibilityResolution = 4;
inline constexpr int32_t kMaxVisibilityResolution = 64;
// v_k never falls below this: the blend stays defined (and continuous) when every probe of the
// cell is hidden from the point, and then equals the barycentric blend.
inline constexpr float kVisibilityFloor = 1e-6f;

// How a lookup blends the probes of the cell around a point.
struct ProbeBlendSettings {
  // Weight probes by their visibility of the point when the set has visibility data; false
  // gives the plain barycentric blend (Cupisz 2012), as for files without visibility.
  bool visibility = true;
  // Unit surface normal at the point, or zero when the query is an object's centre.
  glm::vec3 normal{0.0f};
  // Metres the point is moved along `normal` before the test (keeps a surface point from
  // shadowing itself against the wall it lies on).
  float normalBias = 0.05f;
  // Metres subtracted from the probe-to-point distance (a point lying on a surface the probe
  // sees is not hidden by that surface's own depth).
  float distanceBias = 0.02f;
  // Smallest standard deviation of the depth distribution (metres): flat, noise-free texels
  // would otherwise make the test a hard step in d.
  float minSigma = 0.02f;
};

// Octahedral map of unit directions (x, y, z in world axes) to [-1, 1]^2 with +z at the
// centre and -z at the four corners (Cigolle et al. 2014, "A Survey of Efficient
// Representations for Independent Unit Vectors"). Texel (i, j) of an R x R map covers
// u in [2i/R - 1, 2(i+1)/R - 1], v likewise with j; it is stored at index j * R + i.
glm::vec2 octahedralEncode(glm::vec3 direction) noexcept;
glm::vec3 octahedralDecode(glm::vec2 uv) noexcept;  // unit length

// Bilinear footprint of a point of the map: four texel indices (j * R + i) and weights
// summing to 1. Texels beyond an edge wrap to the texel that holds the same directions
// (the edge u = 1 folds v to -v, and likewise the others), so a sample is continuous in
// direction across every seam.
struct OctahedralFootprint {
  int32_t texel[4];
  float weight[4];
};
OctahedralFootprint octahedralFootprint(glm::vec2 uv, int32_t resolution) noexcept;

// The Chebyshev visibility v (see the file comment) of a probe's map `moments` (resolution^2
// texels x {mean, mean square}, unorm16) for a point at `offset` = p' - probe position (metres,
// before distanceBias), with maxDistance D.
float probeVisibility(std::span<const uint16_t> moments, int32_t resolution, float maxDistance,
                      glm::vec3 offset, const ProbeBlendSettings& settings) noexcept;

}  // namespace kiln
