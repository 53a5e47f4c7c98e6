// postprocess.h: the lightmap page post-process (MISSION.md "Lightmaps: Post"): filling
// invalid texels from valid neighbours, dilation into padding, and an edge-aware à-trous
// denoiser guided by normals and positions (Dammertz et al. 2010, "Edge-Avoiding À-Trous
// Wavelet Transform for fast Global Illumination Filtering").
//
// Everything works on plain images and masks: a page is W x H texels, row-major from the top
// row (row 0 = v 0, MISSION.md "Conventions"), texel values are E/pi (linear). Masks are
// W x H bytes, 1 = set. Suggested order: fillInvalid, denoise, dilate, then seam stitching
// (lightmap/seams.h), which reads the texels bilinear filtering reads at chart borders.
// All functions are deterministic: results do not depend on the thread count.
#pragma once

#include <cstdint>
#include <vector>

#include "src/image.h"
#include "src/parallel.h"

namespace kiln {

// A working view of one lightmap page with the guide buffers the denoiser needs. All
// per-texel vectors are W x H, row-major from the top row; optional ones may be empty.
struct LightmapPage {
  Image radiance;                 // W x H, >= 1 channels (RGB E/pi); filtered in place
  std::vector<uint8_t> valid;     // 1 = a texel with a trusted value; 0 = padding/empty/invalid
  std::vector<int32_t> objectId;  // scene object per texel, -1 = none; empty = one object
  Image normal;                   // W x H x 3, world unit shading normal; empty = no normal term
  Image position;                 // W x H x 3, world position (metres); empty = no position term
  // Optional variance of each texel's luminance estimate (e.g. sample variance / sample
  // count). Empty: the denoiser estimates the noise level from each texel's 3x3 neighbours.
  std::vector<float> variance;
  // Optional world size of a texel's edge (metres), e.g. 1 / AtlasObject::texelsPerUnit.
  // Empty: estimated from the distances to neighbouring texels' positions.
  std::vector<float> texelWorldSize;

  int width() const { return radiance.width; }
  int height() const { return radiance.height; }
  size_t texelCount() const { return size_t(radiance.width) * size_t(radiance.height); }
};

// Dilation into padding: every texel without a value (mask 0) that has at least one texel
// with a value among its 8 neighbours gets the plain average of those neighbours; the newly
// filled ring then takes part in the next ring. Runs `iterations` rings (<= 0: until every
// texel is filled or nothing changes), so bilinear filtering at chart borders reads the
// border colour instead of black. Texels with mask 1 are never changed. All channels are
// dilated. Returns the mask of texels holding a value afterwards (`valid` | filled).
// `valid` must hold width x height entries.
std::vector<uint8_t> dilate(Image& image, const std::vector<uint8_t>& valid, int iterations,
                            const ParallelOptions& parallel = {});

struct FillSettings {
  float radius = 3.0f;  // texels: valid texels at Euclidean texel distance <= radius are used
  // How far the fill reaches, in rings (8-neighbour steps within the object) from the
  // object's valid texels. <= 0: every invalid texel that can be reached is filled. k > 0:
  // only invalid texels within k rings are filled; the deeper ones keep the value they hold
  // (the baker's physical estimate, ~0 for a texel enclosed by geometry) and count as set
  // in the returned mask, so dilation leaves them alone. A bilinear lookup at a visible
  // surface point reads texels at most one ring from a valid one: k = 1 is what rendering
  // needs (lightmap_baker.cpp).
  int maxRings = 0;
  // With maxRings > 0: the texels rings are counted from (W x H, each also valid); null =
  // every valid texel. The baker passes the valid texels whose centre lies on the visible
  // surface, not the ones push-out moved out of a solid: a texel beyond those is more than a
  // texel from any visible point, out of reach of bilinear lookups.
  const std::vector<uint8_t>* ringSeeds = nullptr;
  ParallelOptions parallel;
};

// Fills the texels that belong to an object (objectId >= 0) but are not valid, e.g. texels
// whose rays mostly saw back faces (inside geometry): each gets the inverse-square-distance
// weighted average (Shepard interpolation, weight 1 / d^2 with d in texels) of the valid
// texels of the same object within `radius`. Texels with none in reach are then filled ring
// by ring from their filled or valid same-object 8-neighbours (dilation restricted to the
// object) until none is left that can be reached. With settings.maxRings > 0 only texels
// within that many rings of a valid texel (or of a ringSeeds texel) of their object are
// filled (and only from texels within those rings); deeper ones keep their values. Padding
// (objectId < 0) is left for dilate. `objectId` empty = all texels belong to one object.
// Returns the mask afterwards (`valid` | filled | kept). Weights use valid texels only, so
// the result is order-independent.
std::vector<uint8_t> fillInvalid(Image& image, const std::vector<uint8_t>& valid,
                                 const std::vector<int32_t>& objectId,
                                 const FillSettings& settings = {});

struct DenoiseSettings {
  // À-trous passes with steps 1, 2, 4, ...: 5 passes reach +-2 x 16 = 32 texels.
  int iterations = 5;
  // Normal edge-stopping weight max(0, dot(n_p, n_q))^sigmaNormal (as in SVGF, Schied et al.
  // 2017; Dammertz uses a Gaussian of |n_p - n_q|, which behaves the same for small angles).
  float sigmaNormal = 64.0f;
  // Position weight exp(-(plane^2 + excess^2) / (sigmaPosition h)^2), with h the texel's world
  // size, plane = |dot(n_p, x_q - x_p)| the distance of q from p's tangent plane, excess how
  // far |x_q - x_p| exceeds twice the texel distance (charts adjacent in UV but apart in 3D).
  float sigmaPosition = 1.0f;
  // Luminance weight exp(-(l_p - l_q)^2 / (2 sigmaLuminance^2 (var_p + var_q))): a Gaussian
  // in the difference over its own standard error (var = the variance of each texel's
  // current value: the given variance or the spatial estimate at the start, then carried
  // through the passes as SVGF does, Schied et al. 2017). Differences the noise explains
  // mix; the filter fades out as the variance falls, so it does not blur converged light.
  float sigmaLuminance = 1.5f;
  // Blend between input (0) and the safeguarded filter output (1). 0 returns the page
  // unchanged bit for bit.
  float strength = 1.0f;
  ParallelOptions parallel;
};

// Edge-aware, variance-guided à-trous wavelet filter (Dammertz et al. 2010) of
// page.radiance, in place. Each pass takes the 5x5 B3-spline taps (1/16, 1/4, 3/8, 1/4,
// 1/16)^2 dilated by the pass's step, with pair weights w_pq = B3 x the normal and position
// weights (the smaller of both directions) x the luminance weight above, all symmetric in p
// and q, and moves each texel towards its neighbours: out_p = x_p + sum_q a_pq (x_q - x_p)
// with a_pq = w_pq / max(W_p, W_q), W the texel's total weight. a is symmetric, so the sum
// of each object's valid texels (their mean) is unchanged by every pass, and sum_q a_pq < 1,
// so a texel is a convex combination that keeps a positive share of itself: never negative,
// never 0 where it was > 0. Only valid texels contribute and change; objects never mix. All
// channels move with the weights of the luminance of the first three (or the first, for grey
// images).
// The safeguards below judge by the given variance checked against the texels (per object:
// the spread of each texel about the mean of its 8 neighbours bounds the noise from above,
// a linear gradient cancelling), lowered where it is larger than that bound, never raised;
// the filter's weights use the variance as given.
// Then a safeguard, so that the filter does not add error where it blurs light the samples
// resolved (a gradient along which the luminance weights still mix): each texel becomes
// x + a (f - x), raw x, filtered f, with the share a in [0, 1] that minimises Stein's
// unbiased risk estimate (SURE) over an 11x11 window of its object, a = sum var_q (1 - div_q)
// / sum |f_q - x_q|^2 over the colour channels (var_q per unit of luminance variance scaled
// by sum_c f_c^2 / l^2), div = d f_q / d x_q estimated by filtering a perturbed copy once more
// (Monte-Carlo SURE, Ramani et al. 2008). Where the filter only removed noise a ~ 1; where it
// moved texels by more than their noise explains a -> 0. Then, per object, how much of the
// whole result's change d = out - x to keep: x + s d with s in [0, 1]. The squared error
// changes by s^2 D - s G, D = sum |d|^2 and G the noise the change removes (-2 <d, e>, e the
// raw error), which SURE estimates in colour (its divergence again by perturbation). s is the
// share that maximises the lower bound of the gain, (G - margin x spread) / (2 D), the spread
// being that of the estimate and of this bake's realised gain about it (margin 1 standard
// error for a noisy object, 3 for one whose relative noise is 5% or less or that has fewer
// than 16 texels): the bake loses only if its realised G falls below half that lower bound,
// which leaves room for SURE's own bias where the given variance overstates the noise.
// s = 0 (raw texels) where the lower bound is not positive.
// With a position buffer, all of the above also runs in a second form: on each object of at
// least 8 valid texels the filter works on the residual of a least-squares quadratic fit in
// world position and adds the fit back (at least 1/16 of the texel's own value), so that it
// does not blur the light's smooth curvature (a peak under a lamp), whose blurring otherwise
// dominates D on such objects and makes the bake's gain hinge on how its noise happens to
// lie against that blur. Each object keeps the form whose lower bound guarantees the larger
// gain, (G - margin x spread)^2 / (4 D). Last, each object's sum per channel is restored by
// one factor (> 0: no texel turns negative or 0). Costs eight filter runs (four without a
// position buffer). Deterministic at any thread count.
void denoise(LightmapPage& page, const DenoiseSettings& settings = {});

}  // namespace kiln
