// probe_visibility.h: per-probe visibility (depth moments over an octahedral map) and the
// Chebyshev weight that keeps probe blending from leaking light through walls.
//
// Every probe stores, for each direction texel of an R x R octahedral map, where the first
// surface lies along the texel's directions and how much that varies inside the texel: from the
// probe bake's rays, s = min(t, D) / D with t the distance to the first hit (a ray that hits
// nothing counts as D; D is the probe's maxDistance) is fitted per texel by a plane in the
// map's coordinates (least squares over the texel's rays); the fit's value at the texel centre
// (mu), the RMS of the residual (sigma) and the largest s of the texel's rays (far) are stored
// as unorm16. The plane removes the trend of a tilted wall across the texel, so sigma measures
// depth edges and noise, not the tilt. At run time the weight of probe k for a point p is its
// barycentric weight times
//
//   v_k(p) = max(c(d) * clamp(1 - (d - far) / w, 1e-12, 1), kVisibilityFloor),
//   c(d)   = 1                                           if d <= mu
//          = (s2 / (s2 + (d - mu)^2))^3                  otherwise,    w = minSigma / D,
//
// where d = min(|p' - x_k| - distanceBias, D) / D is the normalized distance from the probe to
// the biased point p' = p + normalBias * n (n: the surface normal at p, when the caller has
// one), mu, sigma and far are bilinearly interpolated from the four texels around the
// direction from the probe to p', and s2 = max(sigma, w)^2. c is the one-sided Chebyshev
// bound on the probability that the surface along that direction lies beyond d (variance
// shadow maps; DDGI, Majercik et al. 2019, cubes it to sharpen the cut-off); the second factor
// hides a point beyond the farthest depth the texels' rays reached, which a texel holding two
// surfaces (a probe next to a wall looking along it) would otherwise let through with a loose
// bound. The weights b_k v_k are divided by max(sum_j b_j v_j, minVisibleWeight): they sum to
// 1 where the cell's probes see the point with at least that share of the barycentric weight,
// and fade towards 0 (black) at a point that none of them sees. v never reaches 0, so the
// blend is always defined, and it is continuous in p (the map is sampled with octahedral
// wrapping, the test is continuous in d, mu, sigma and far, and a face shared by two cells has
// the same three probes with the same weights on both sides).
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
// A resolution a file, a bake or a command line may give: 0 (no visibility) or in range.
inline constexpr bool isVisibilityResolution(int64_t r) {
  return r == 0 || (r >= kMinVisibilityResolution && r <= kMaxVisibilityResolution);
}
// v_k never falls below this (far below any v the test gives, about 1e-29 at its smallest):
// the renormalized blend stays defined and continuous when every probe of the cell is hidden
// from the point, weighted by how hidden each is (equal floors give the barycentric blend).
inline constexpr float kVisibilityFloor = 1e-30f;

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
  // The weights b_k v_k are divided by max(sum_j b_j v_j, minVisibleWeight): a point that the
  // probes of its cell see with at least this share of the barycentric weight gets weights
  // summing to 1; below it the blend fades out (towards black, at a point no probe sees)
  // instead of handing the whole weight to whichever hidden probe is least hidden, which may
  // be on the far side of a wall. 0 = always renormalize fully.
  float minVisibleWeight = 0.01f;
};

// The factor that turns the products b_k v_k of a cell's probes into the blend's weights:
// 1 / max(their sum, minVisibleWeight) (ProbeBlendSettings). weightByVisibility and
// placement's leak estimate both use it, so that placement scores the blend the runtime gives.
inline float visibleWeightScale(float sum, float minVisibleWeight) noexcept {
  return 1.0f / (sum > minVisibleWeight ? sum : minVisibleWeight);
}

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
// texels x {mu, sigma, far}, unorm16) for a point at `offset` = p' - probe position (metres,
// before distanceBias), with maxDistance D.
float probeVisibility(std::span<const uint16_t> moments, int32_t resolution, float maxDistance,
                      glm::vec3 offset, const ProbeBlendSettings& settings) noexcept;

}  // namespace kiln
