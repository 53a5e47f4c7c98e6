// reference_compare.h: kiln's lightmaps against an independent renderer's per-object bakes
// (../shared/reference/cornell_box: Blender Cycles, one EXR per object over its whole UV1
// square, with a coverage mask; see that folder's README.md).
//
// For every reference texel (x, y) whose 3 x 3 neighbourhood is inside the mask (texels next
// to UV edges hold Cycles' margin fill and are unreliable), its UV1 footprint
// [x, x + 1] / W x [y, y + 1] / H (glTF orientation, row 0 = v 0) is mapped through the
// object's scaleOffset from kiln's manifest into its atlas page, and kiln's texels are
// averaged over it (8 x 8 lookups of the nearest texel: each kiln texel weighted by its
// overlap). A reference texel is the mean of E/pi over its footprint (README), and so is
// this; kiln's value at the footprint's centre would not be, wherever light changes within
// it (shadow edges, the foot of a block, the ceiling around the lamp). Accumulated per
// object and overall, over R, G and B:
//   relative RMSE = sqrt(sum (k - r)^2 / sum r^2),   mean ratio = sum k / sum r.
// A second set of sums, "visible", also leaves out texels with a hidden neighbour: a texel
// whose 3 x 3 neighbourhood holds a reference texel with R + G + B < kHiddenReference, i.e.
// a surface point no light reaches: inside a closed solid (the floor under the Cornell box's
// blocks, the ceiling behind the light). Cycles bakes those black, and so does kiln except
// for the invalid texels next to valid ones, which it fills from them so that bilinear
// lookups at visible points read lit values (docs/lightmap_outputs.md). Lit texels in the
// scene are 2 to 3 orders of magnitude above the threshold.
// Used by the kiln_compare_reference tool and by tests/lightmap_reference_test.cpp.
#pragma once

#include <string>
#include <vector>

#include "src/image.h"
#include "kiln/result.h"

namespace kiln {

struct ReferenceErrorSums {
  size_t texels = 0;
  double sumSquaredError = 0.0;      // sum over texels and RGB of (k - r)^2
  double sumSquaredReference = 0.0;  // sum of r^2
  double sumKiln = 0.0, sumReference = 0.0;

  void add(const ReferenceErrorSums& o);
  double relativeRmse() const;  // sqrt(sumSquaredError / sumSquaredReference)
  double meanRatio() const;     // sumKiln / sumReference
};

inline constexpr float kHiddenReference = 1e-3f;

// One page of a kiln bake against the same page of another bake of the same atlas, texel by
// texel (kiln_compare_bakes): adds to `sums` the texels of the reference's baked, visible
// footprint, coverage > 0 where `coverage` is given (a --coverage-map reference: padding and
// hidden texels have 0), else every texel whose reference value is not 0 (padding included,
// as dilated copies). The sums are over R, G and B, the mean ratio's over luminance. The
// images must be the same size.
void addBakeDifference(const Image& bake, const Image& reference, const Image* coverage,
                       ReferenceErrorSums& sums);

struct ObjectReferenceError {
  std::string node;
  int nodeIndex = -1;
  ReferenceErrorSums sums;     // every compared texel
  ReferenceErrorSums visible;  // without texels next to hidden ones
  // The bake has a coverage map (kiln bake --coverage-map) and lookups were weighted by it.
  bool coverageWeighted = false;
  // With keepImages: kiln's lightmap resampled onto the reference's texels (0 where the
  // texel is not compared), and the reference itself.
  Image kiln, reference;
};

struct ReferenceComparison {
  std::vector<ObjectReferenceError> objects;  // in the reference's index.json order
  ReferenceErrorSums overall;
  ReferenceErrorSums overallVisible;
};

// Compares the bake in `bakeDir` (manifest.json and its light EXRs) with the reference in
// `referenceDir` (index.json, <node>.exr, <node>_mask.exr). Objects are matched by
// nodeIndex (their names must agree). Errors name the file and the object.
Result<ReferenceComparison> compareWithReference(const std::string& referenceDir,
                                                 const std::string& bakeDir,
                                                 bool keepImages = false);

// A plain-text table: object, then texels, relative RMSE (%) and mean ratio over all compared
// texels and over the visible ones; then the overall row.
std::string formatReferenceTable(const ReferenceComparison& comparison);

}  // namespace kiln
