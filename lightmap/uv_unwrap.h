// uv_unwrap.h: lightmap UV generation for an object without TEXCOORD_1 (MISSION.md
// "Lightmaps": charts, parameterize, pack).
//
// Pipeline: weld vertices by position (glTF splits vertices at normal and UV seams), grow
// charts over edge connectivity while every triangle normal stays within a cone around the
// chart's seed normal, parameterize each chart (planar charts: orthogonal projection, zero
// stretch; curved charts: least squares conformal maps, Lévy et al. 2002), scale every chart
// so that its UV area equals its world area, orient it by its minimum-area bounding
// rectangle, and pack the charts (skyline, Jylänki 2010) with a gutter measured in texels at
// the object's expected texel density. The result is uniform: one world unit is the same UV
// length in every chart (`worldPerUv`). Guarantees: no flipped and no overlapping UV
// triangles (every chart is checked; failures are split until they pass).
#pragma once

#include <atomic>
#include <cstdint>
#include <optional>
#include <vector>

#include "kiln/result.h"
#include "lightmap/atlas.h"
#include "src/scene.h"

namespace kiln {

struct UnwrapSettings {
  // Expected texel density in texels per world unit: the bake's resolution x the object's
  // scaleInLightmap. Sets the gutter's size in UV and rounds charts up to whole texels.
  float texelsPerUnit = 10.0f;
  // Empty texels between charts, so that bilinear filtering and dilation of one chart never
  // reach another.
  int gutterTexels = 2;
  // A chart grows over soft edges (not over creases, where the mesh's vertex normals are
  // split) while every new triangle's normal is within this angle of the chart's current
  // area-weighted mean normal; charts are then merged into neighbours while every normal of
  // the union stays strictly within this angle of the union's mean normal. 60 degrees: a
  // chart spans up to about 120 degrees of arc (a cylinder unrolls in 3 charts, a sphere in
  // about 10) while LSCM's area distortion stays within kMaxAreaDistortion; a box's faces
  // (90 degrees apart, exactly 45 from their mean) are creases and stay apart anyway.
  // Charts that LSCM maps with a fold, an overlap or too much area distortion are regrown
  // with half the angle (down to 2 degrees, then one chart per triangle).
  float maxChartAngleDegrees = 60.0f;
  // Charts smaller than this many texels (at texelsPerUnit) are merged into a neighbour even
  // across a crease or beyond the cone, when the union still parameterizes without a fold,
  // an overlap or too much distortion: every chart costs a gutter on each side, which on a
  // chart of a few texels is most of its space.
  float smallChartTexels = 100.0f;
  // Charts whose normals all lie within this angle of their mean normal are projected onto
  // the plane instead of solved with LSCM (stretch <= 1 / cos(angle) - 1 = 1.5e-4).
  float planarAngleDegrees = 1.0f;
  // Charts whose triangles no light reaches (sealed_surfaces.h: a box's face resting on the
  // floor, the backs of a closed shell) are shrunk to at most sealedTexels texels across:
  // their lightmap is black or meaningless, and full resolution would spend atlas space on
  // it. generateLightmapUvs takes the sealed triangles from its caller;
  // generateMissingLightmapUvs finds them with rays when this is true. 0 < sealedTexels.
  bool shrinkSealed = true;
  float sealedTexels = 1.0f;
  // generateMissingLightmapUvs only: objects too small for a useful lightmap
  // (atlas.h tooSmallForLightmap with this threshold; keep it equal to the atlas's
  // minObjectTexels) are lit by probes and get no UVs.
  float minObjectTexels = kMinObjectTexels;
  // generateMissingLightmapUvs only, per scene object (empty: none): objects a locked atlas
  // (--lock-atlas) gives a page get their charts whatever minObjectTexels says, so that a
  // manifest from an earlier rule (or from --min-object-texels 0) still locks.
  std::vector<uint8_t> keepCharts;
  // generateMissingLightmapUvs only: a progress line on stderr ("UV generation", in
  // triangles), and a flag polled between objects that stops it with an Error "cancelled".
  bool showProgress = false;
  const std::atomic<bool>* cancel = nullptr;
};

// Distortion and packing statistics of an unwrap.
struct UnwrapStats {
  int chartCount = 0;           // charts with area (degenerate triangles are not counted)
  int planarCharts = 0;         // of which projected rather than solved with LSCM
  int degenerateTriangles = 0;  // zero-area triangles, mapped to a point of UV space
  int flippedTriangles = 0;     // UV triangles with non-positive signed area (should be 0)
  int sealedCharts = 0;         // charts shrunk because no light reaches them
  int sealedTriangles = 0;      // triangles in them
  // Area-weighted L2 stretch (Sander et al. 2001) of the map surface -> UV in world units:
  // sqrt(sum A (s1^2 + s2^2) / 2 / sum A), where s1 >= s2 are the Jacobian's singular values.
  // 1 when every chart is an isometry.
  double l2Stretch = 1.0;
  double maxAnisotropy = 1.0;      // max s1 / s2 over triangles (1 = conformal)
  double maxAreaDistortion = 1.0;  // max over triangles of max(s1 s2, 1 / (s1 s2))
  // Sum of UV triangle areas / area of the UV bounding rectangle.
  double packingEfficiency = 0.0;
  // Over the charts not shrunk as sealed, at texelsPerUnit: the texels their surface holds
  // (world area x texelsPerUnit^2) and the texels their footprints touch (chart_packer.h: the
  // texels the conservative rasterizer gives samples). surfaceTexels / coveredTexels is the
  // share of a touched texel that is the object's surface on average: near 1 for broad
  // charts, under 0.25 for charts about a texel across (thin legs, rods, handles).
  double surfaceTexels = 0.0;
  double coveredTexels = 0.0;
};

// New vertex arrays for an object: vertices split where charts meet. Triangle i of the result
// is triangle i of the input (same order, so triangleMaterial stays valid).
struct UnwrapResult {
  std::vector<uint32_t> vertexRemap;    // new vertex -> the object's original vertex index
  std::vector<uvec3> triangles;         // indices into the new vertices
  std::vector<vec2> uv1;                // per new vertex, in [0, 1]^2; max(extent) == 1
  std::vector<uint32_t> triangleChart;  // per triangle, chart index (degenerate: own index)
  // World units per UV unit, the same in every chart but the sealed ones (shrunk): a UV
  // length l is l x worldPerUv metres.
  double worldPerUv = 1.0;
  UnwrapStats stats;
};

// Generates lightmap UVs for `object` (world-space positions and normals; uv0 and uv1 are not
// read). `sealed` (optional, one entry per triangle, 1 = no light reaches it) marks the
// triangles that get charts of their own, shrunk when settings.shrinkSealed. Deterministic:
// the same object and settings give bit-identical output. Thread-safe (no shared state).
// Errors name the object: no triangles, an index out of range, or a settings value out of
// range.
Result<UnwrapResult> generateLightmapUvs(const Object& object, const UnwrapSettings& settings,
                                         const std::vector<uint8_t>* sealed = nullptr);

// The object rebuilt on the unwrap's vertices: positions, normals and uv0 gathered through
// vertexRemap, triangles and uv1 from the result; name, material and settings kept.
Object applyUnwrap(const Object& object, const UnwrapResult& unwrap);

// For the bake: generates UVs for every lightmapped object (atlas.h isLightmapped) of the
// scene that has no TEXCOORD_1 and is not too small for a lightmap (settings.minObjectTexels),
// except, with the automatic rule (settings.minObjectTexels < 0), objects whose generated
// charts come out too thin (atlas.h chartsTooThin): those keep no UVs, get
// Object::thinCharts and are lit by probes (packAtlas marks them probeLit); objects marked
// in settings.keepCharts get UVs in every case;
// with its sealed triangles found by rays over the scene's static objects when
// settings.shrinkSealed, at texelsPerUnit = resolution x its scaleInLightmap (the
// other fields of `settings` as given), and replaces the object with applyUnwrap's. Returns,
// per scene object, its unwrap (nullopt: kept its own UVs, or not lightmapped) so that the
// output glTF writer can rebuild the primitives. Objects run in parallel; deterministic.
// Errors name the object; a cancel (settings.cancel) returns Error "cancelled".
Result<std::vector<std::optional<UnwrapResult>>> generateMissingLightmapUvs(
    Scene& scene, float resolution, const UnwrapSettings& settings = {});

}  // namespace kiln
