// placement_evaluation.h: the one harness that judges probe sets by interpolation error
// (docs/probe_placement.md, "Error"): random valid points over the placement volumes with SH
// baked at them (the truth), and a probe set's error there. Automatic placement scores its
// sets against such points (its check points), `kiln probes compare-placement` and the
// placement chart (`kiln chart`) measure every method's baked probes against them.
#pragma once

#include <atomic>
#include <cstdint>
#include <span>
#include <vector>

#include "kiln/probe_runtime.h"
#include "kiln/result.h"
#include "probes/object_space.h"
#include "probes/probe_baker.h"
#include "probes/probe_placement.h"
#include "src/math.h"
#include "src/progress.h"
#include "src/scene.h"
#include "src/tracer.h"

namespace kiln {

// Points and the SH baked at them (bakePointSh with the probe bake's estimator, no
// visibility maps), with the error floor relativeIrradianceError uses there:
// kErrorFloorFraction x the mean irradianceRms of the truth.
struct TruthPoints {
  std::vector<vec3> points;
  size_t objectPoints = 0;  // the first ones, drawn where objects stand (PointSampling)
  std::vector<ShL2Rgb> sh;
  float floor = 0.0f;
};

// Which random points: valid ones (isValidProbePoint) in reachable space, a share of them
// where objects stand.
struct PointSampling {
  const ReachableSpace* reachable = nullptr;  // null: every valid point counts
  // The first round(count x objectShare) points are drawn 0.3-2 m above a walkable surface
  // (objectPoint), the others uniform over the volumes (randomValidPoints).
  float objectShare = 0.0f;
  float minHeight = 0.3f, maxHeight = 2.0f;
};

// `count` random points as `sampling` says, keyed by `seed`; with the defaults exactly
// randomValidPoints(..., seed, ...). Fewer come back where few are possible (points whose 256
// attempts all fail are left out). Deterministic at any thread count. `objectPoints`, when
// given, receives how many of the first points were drawn where objects stand.
std::vector<vec3> randomPlacementPoints(const Scene& scene, const Tracer& tracer,
                                        std::span<const Bounds3> volumes, uint32_t count,
                                        uint64_t seed, const ProbeValiditySettings& validity,
                                        const PointSampling& sampling, int threads = 0,
                                        size_t* objectPoints = nullptr);

// `count` random points (randomPlacementPoints with `pointSeed`) and their truth baked with
// `bake` (its own seed, rays, dering...). Errors: no valid point in the volumes, "cancelled".
// Deterministic at any thread count.
Result<TruthPoints> bakeTruthPoints(const Scene& scene, const Tracer& tracer,
                                    std::span<const Bounds3> volumes, uint32_t count,
                                    uint64_t pointSeed, const ProbeValiditySettings& validity,
                                    const ProbeBakeSettings& bake, Progress* progress = nullptr,
                                    const std::atomic<bool>* cancel = nullptr,
                                    const PointSampling& sampling = {});

// A baked probe set's error at the truth points, with the runtime's visibility-weighted blend
// and with the plain barycentric blend of the same probes.
struct ProbeSetError {
  FieldError visibility;
  FieldError plain;
  float nearWall = 0.0f;       // mean error (visibility) over points within 0.5 m of a surface
  float nearWallPlain = 0.0f;  // ... plain
  CellCrossing crossing;       // inner cells with an edge through geometry
};

// Spheres lit by a probe set (the runtime's visibility-weighted blend at their centres)
// against spheres lit by SH baked at the centres: per point relativeIrradianceError (over the
// six axis normals), and the ratio of the sphere's mean irradiance (the luminance of the L00
// term: E averaged over all normals) to the truth's.
struct SphereError {
  float median = 0.0f;  // median relative error
  float mean = 0.0f;
  float worstRatio = 1.0f;  // max over points of max(ratio, 1 / ratio)
  size_t points = 0;
  std::vector<float> perPoint, ratio;
};
SphereError sphereError(const ProbeSet& set, const TruthPoints& truth, int threads = 0);

// Measures probe positions against a truth: each set is baked with bakeProbes and `bake`
// (visibility maps as `kiln probes bake` makes them when bake.visibilityResolution > 0).
// Holds references to the scene, tracer and truth: they must outlive it.
class PlacementEvaluation {
 public:
  PlacementEvaluation(const Scene& scene, const Tracer& tracer, const TruthPoints& truth,
                      const ProbeBakeSettings& bake);

  // Bakes the probes at `positions` and measures them. Errors: the bake's (topology, too
  // few probes), "cancelled".
  Result<ProbeSetError> measure(std::span<const vec3> positions,
                                const std::atomic<bool>* cancel = nullptr) const;
  // The same in two steps: the bake (shared by several truths), then the measure.
  Result<ProbeSet> bake(std::span<const vec3> positions,
                        const std::atomic<bool>* cancel = nullptr) const;
  ProbeSetError measure(const ProbeSet& set) const;
  // The error of another bake of the truth points (bake settings of the truth, seed
  // `seed`): the measure's own noise, below which no method can go by much.
  Result<FieldError> noise(const ProbeBakeSettings& truthBake, uint64_t seed,
                           Progress* progress = nullptr,
                           const std::atomic<bool>* cancel = nullptr) const;
  // Mean of per-point errors over the points within 0.5 m of a surface.
  float nearWallMean(std::span<const float> perPoint) const;
  // A bound for the sun layer (docs/probes.md, "Sun shadows"), not a method: the share of
  // the sun layer's light (sunLayerLight of the bake's integrator) reaching each truth point
  // (sunShare, keyed by the point's position); empty when the bake has no such light. Then
  // the set's error with the visibility-weighted blend when its ramps are replaced by those
  // exact shares: sh += (share - sum_k w_k v_k) x the light's SH wherever the runtime applies
  // a layer (visibility-weighted blends in inner cells; elsewhere the blend is the runtime's),
  // as if the layer were perfect.
  std::vector<float> sunShares(const std::atomic<bool>* cancel = nullptr) const;
  FieldError measureWithExactSunShares(const ProbeSet& set, std::span<const float> shares) const;
  const std::vector<uint8_t>& nearWall() const { return nearWall_; }

 private:
  const Scene& scene_;
  const Tracer& tracer_;
  const TruthPoints& truth_;
  ProbeBakeSettings bake_;
  std::vector<uint8_t> nearWall_;  // per point: within 0.5 m of a surface
};

}  // namespace kiln
