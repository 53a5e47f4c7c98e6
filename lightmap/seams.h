// seams.h: finding UV seams of a lightmapped object and stitching its lightmap across them
// (MISSION.md "Lightmaps: Post").
//
// A seam is a mesh edge shared by two triangles in 3D whose two sides lie in different places
// of the lightmap (glTF splits vertices where UVs differ, so vertices are welded by position).
// Bilinear filtering on either side reads different texels there, so the lighting jumps at
// the seam. Stitching moves the texels that bilinear lookups along the seam read, on both
// sides, by the least change that makes corresponding lookups agree: the least-squares
// formulation of M. Iwanicki, "Lighting Technology of The Last of Us" (SIGGRAPH 2013), as
// implemented by ands' seamoptimizer.h beside lightmapper.h; Unity's "Stitch Seams" does the
// same job. As in both, only edges within one object are stitched, and (as seamoptimizer)
// only smooth ones.
//
// Frame: page texel coordinates; texel (x, y) covers [x, x+1] x [y, y+1], its centre is at
// (x + 0.5, y + 0.5), row 0 = v 0 = top (MISSION.md "Conventions"). An object vertex's
// texel point is (uv1 * (sx, sy) + (ox, oy)) * (W, H).
#pragma once

#include <cstdint>
#include <vector>

#include "src/image.h"
#include "src/scene.h"

namespace kiln {

// One seam edge: the same 3D edge seen from its two triangles, in page texel coordinates.
// a0 and b0 are the same 3D point, as are a1 and b1.
struct SeamEdge {
  vec2 a0{0.0f}, a1{0.0f};
  vec2 b0{0.0f}, b1{0.0f};
  uint32_t triangleA = 0, triangleB = 0;  // triangleA < triangleB
};

struct SeamSettings {
  // Vertices closer than this (metres, per axis) are the same 3D point.
  float weldTolerance = 1e-5f;
  // Endpoints whose UV1 texel points differ by more than this (texels) are split.
  float uvTolerance = 1e-3f;
  // Only smooth edges are seams: both endpoints' vertex normals must agree to this cosine.
  // Across a hard edge the lighting is legitimately discontinuous. -1 stitches every edge.
  float minNormalCos = 0.98f;
};

// The seams of one object whose UV1 is mapped into a pageWidth x pageHeight page by
// scaleOffset (sx, sy, ox, oy) (Unity's unity_LightmapST). Only edges shared by exactly two
// triangles count. Sorted by (triangleA, triangleB, edge): deterministic. Needs uv1 (returns
// nothing without it). Thread-safe (reads only).
std::vector<SeamEdge> findSeams(const Object& object, vec4 scaleOffset, int pageWidth,
                                int pageHeight, const SeamSettings& settings = {});

struct StitchSettings {
  int iterations = 64;        // conjugate-gradient iterations per channel (stops earlier)
  float samplesPerTexel = 4;  // matching points per texel of seam length
  // Weight of "stay close to the original value" against "both sides agree": the solution
  // is the least change that makes the sides agree, and the residual disagreement scales
  // with this weight.
  float regularization = 1e-4f;
  // Texel values stay >= 0 (light, AO, shadowmask and encoded direction maps all are): texels
  // the solve would take below 0 are held at 0 and the rest solved again. false: plain least
  // squares.
  bool nonNegative = true;
};

struct StitchStats {
  size_t samples = 0;      // matching point pairs used
  size_t texels = 0;       // texels allowed to move
  double rmsBefore = 0.0;  // RMS difference of the pairs' bilinear lookups, all channels
  double rmsAfter = 0.0;
};

// Bilinear lookup of all channels at page texel point p (texel centres at +0.5), clamping
// to the edge like a GPU sampler in clamp mode. `out` holds image.channels floats.
void sampleBilinear(const Image& image, vec2 p, float* out);

// Stitches `image` across `seams`: along each seam, pairs of matching points (samplesPerTexel
// per texel of the longer side, at the centres of equal parts) are sampled bilinearly on both
// sides, and the texels those lookups read solve
//   min sum_pairs |bilinearA - bilinearB|^2 + regularization sum_texels |x - x_original|^2
// (CGLS, per channel), so the sides move towards each other and agree. A pair whose lookup
// reads a texel with mask 0 is skipped: dilate first so that chart borders have padding
// values. Only texels read by the lookups change. With settings.nonNegative (default) the
// minimum is taken over values >= 0: texels the plain solution takes below 0 (a seam with a
// bright and a dark side) are held at 0 and the others solved again, until none is below.
// Deterministic (serial).
StitchStats stitchSeams(Image& image, const std::vector<uint8_t>& mask,
                        const std::vector<SeamEdge>& seams, const StitchSettings& settings = {});

}  // namespace kiln
