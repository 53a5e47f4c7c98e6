// placement_evaluation.cpp: the truth points and probe-set error shared by placement,
// compare-placement and the placement chart (see placement_evaluation.h).
#include "probes/placement_evaluation.h"

namespace kiln {

Result<TruthPoints> bakeTruthPoints(const Scene& scene, const Tracer& tracer,
                                    std::span<const Bounds3> volumes, uint32_t count,
                                    uint64_t pointSeed, const ProbeValiditySettings& validity,
                                    const ProbeBakeSettings& bake, Progress* progress,
                                    const std::atomic<bool>* cancel) {
  TruthPoints out;
  out.points = randomValidPoints(scene, tracer, volumes, count, pointSeed, validity,
                                 bake.threads);
  if (out.points.empty()) return Error{"no valid points in the volumes"};
  out.sh = bakePointSh(scene, tracer, out.points, bake, progress, cancel);
  if (out.sh.empty() || (cancel && cancel->load())) return Error{"cancelled"};
  double meanRms = 0.0;
  for (const ShL2Rgb& t : out.sh) meanRms += irradianceRms(t);
  out.floor = float(kErrorFloorFraction * meanRms / double(out.sh.size()));
  return out;
}

PlacementEvaluation::PlacementEvaluation(const Scene& scene, const Tracer& tracer,
                                         const TruthPoints& truth, const ProbeBakeSettings& bake)
    : scene_(scene), tracer_(tracer), truth_(truth), bake_(bake) {
  nearWall_.resize(truth.points.size());
  for (size_t i = 0; i < truth.points.size(); ++i)
    nearWall_[i] = probePoint(scene, tracer, truth.points[i], 256).nearestDistance < 0.5f;
}

float PlacementEvaluation::nearWallMean(std::span<const float> perPoint) const {
  double sum = 0.0;
  size_t n = 0;
  for (size_t i = 0; i < perPoint.size() && i < nearWall_.size(); ++i)
    if (nearWall_[i]) sum += perPoint[i], ++n;
  return n ? float(sum / double(n)) : 0.0f;
}

Result<ProbeSetError> PlacementEvaluation::measure(std::span<const vec3> positions,
                                                   const std::atomic<bool>* cancel) const {
  Result<ProbeSet> set = bakeProbes(scene_, tracer_, positions, bake_, nullptr, cancel);
  if (!set) return Error{set.error()};
  ProbeSetError out;
  ProbeBlendSettings plainBlend;
  plainBlend.visibility = false;
  out.visibility = measureFieldError(*set, truth_.points, truth_.sh, truth_.floor, bake_.threads);
  out.plain = measureFieldError(*set, truth_.points, truth_.sh, truth_.floor, bake_.threads,
                                plainBlend);
  out.nearWall = nearWallMean(out.visibility.perPoint);
  out.nearWallPlain = nearWallMean(out.plain.perPoint);
  out.crossing = countCellsCrossingGeometry(tracer_, *set);
  return out;
}

Result<FieldError> PlacementEvaluation::noise(const ProbeBakeSettings& truthBake, uint64_t seed,
                                              Progress* progress,
                                              const std::atomic<bool>* cancel) const {
  ProbeBakeSettings again = truthBake;
  again.seed = seed;
  const std::vector<ShL2Rgb> rebaked =
      bakePointSh(scene_, tracer_, truth_.points, again, progress, cancel);
  if (rebaked.empty() || (cancel && cancel->load())) return Error{"cancelled"};
  std::vector<float> errors(truth_.points.size());
  for (size_t i = 0; i < errors.size(); ++i)
    errors[i] = relativeIrradianceError(truth_.sh[i], rebaked[i], truth_.floor);
  return summarizeFieldError(std::move(errors));
}

}  // namespace kiln
