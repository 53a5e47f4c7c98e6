// placement_evaluation.cpp: the truth points and probe-set error shared by placement,
// compare-placement and the placement chart (see placement_evaluation.h).
#include "probes/placement_evaluation.h"

#include <algorithm>
#include <cmath>
#include <functional>

#include "probes/sun_shadows.h"
#include "src/parallel.h"
#include "src/sampling.h"

namespace kiln {

namespace {
constexpr uint64_t kObjectPointTag = 0x6f626a656374ULL;  // "object"
}

std::vector<vec3> randomPlacementPoints(const Scene& scene, const Tracer& tracer,
                                        std::span<const Bounds3> volumes, uint32_t count,
                                        uint64_t seed, const ProbeValiditySettings& validity,
                                        const PointSampling& sampling, int threads,
                                        size_t* objectPoints) {
  const ReachableSpace* reachable = sampling.reachable;
  std::function<bool(vec3)> accept;
  if (reachable && reachable->enabled())
    accept = [reachable](vec3 p) { return reachable->reachable(p); };
  const uint32_t objects = std::min(
      count,
      uint32_t(std::lround(double(count) * double(std::clamp(sampling.objectShare, 0.0f, 1.0f)))));
  std::vector<vec3> out = rejectionSamplePoints(
      objects, threads, [&](size_t i, uint32_t attempt) -> std::optional<vec3> {
        SampleStream stream(hashValues(seed, kObjectPointTag, i), attempt);
        const vec2 uxz = stream.get2D();
        const vec2 u = stream.get2D();
        const std::optional<vec3> p = objectPoint(scene, tracer, volumes, uxz, u.x, u.y,
                                                  sampling.minHeight, sampling.maxHeight);
        if (p && isValidProbePoint(scene, tracer, *p, validity) && (!accept || accept(*p)))
          return p;
        return std::nullopt;
      });
  if (objectPoints) *objectPoints = out.size();
  const std::vector<vec3> uniform =
      randomValidPoints(scene, tracer, volumes, count - objects, seed, validity, threads, accept);
  out.insert(out.end(), uniform.begin(), uniform.end());
  return out;
}

Result<TruthPoints> bakeTruthPoints(const Scene& scene, const Tracer& tracer,
                                    std::span<const Bounds3> volumes, uint32_t count,
                                    uint64_t pointSeed, const ProbeValiditySettings& validity,
                                    const ProbeBakeSettings& bake, Progress* progress,
                                    const std::atomic<bool>* cancel,
                                    const PointSampling& sampling) {
  TruthPoints out;
  out.points = randomPlacementPoints(scene, tracer, volumes, count, pointSeed, validity, sampling,
                                     bake.threads, &out.objectPoints);
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

Result<ProbeSet> PlacementEvaluation::bake(std::span<const vec3> positions,
                                           const std::atomic<bool>* cancel) const {
  return bakeProbes(scene_, tracer_, positions, bake_, nullptr, cancel);
}

ProbeSetError PlacementEvaluation::measure(const ProbeSet& set) const {
  ProbeSetError out;
  ProbeBlendSettings plainBlend;
  plainBlend.visibility = false;
  out.visibility = measureFieldError(set, truth_.points, truth_.sh, truth_.floor, bake_.threads);
  out.plain =
      measureFieldError(set, truth_.points, truth_.sh, truth_.floor, bake_.threads, plainBlend);
  out.nearWall = nearWallMean(out.visibility.perPoint);
  out.nearWallPlain = nearWallMean(out.plain.perPoint);
  out.crossing = countCellsCrossingGeometry(tracer_, set);
  return out;
}

Result<ProbeSetError> PlacementEvaluation::measure(std::span<const vec3> positions,
                                                   const std::atomic<bool>* cancel) const {
  Result<ProbeSet> set = bake(positions, cancel);
  if (!set) return Error{set.error()};
  return measure(*set);
}

SphereError sphereError(const ProbeSet& set, const TruthPoints& truth, int threads) {
  SphereError out;
  out.points = truth.points.size();
  out.perPoint.assign(out.points, 0.0f);
  out.ratio.assign(out.points, 1.0f);
  ParallelOptions options;
  options.threads = threads;
  options.grain = 32;
  parallelFor(
      out.points,
      [&](size_t begin, size_t end) {
        int32_t hint = -1;
        for (size_t i = begin; i < end; ++i) {
          const ProbeLocation loc = locateProbe(set, truth.points[i], hint);
          hint = loc.cell;
          const ShL2Rgb estimate = interpolateProbes(set, loc);
          out.perPoint[i] = relativeIrradianceError(truth.sh[i], estimate, truth.floor);
          const float t = luminance(truth.sh[i].c[0]), e = luminance(estimate.c[0]);
          out.ratio[i] = t > 0.0f ? e / t : (e > 0.0f ? kInfinity : 1.0f);
        }
      },
      options);
  if (out.points == 0) return out;
  std::vector<float> sorted = out.perPoint;
  std::sort(sorted.begin(), sorted.end());
  out.median = sorted[sorted.size() / 2];
  double sum = 0.0;
  for (float e : sorted) sum += e;
  out.mean = float(sum / double(sorted.size()));
  out.worstRatio = 1.0f;
  for (float r : out.ratio)
    out.worstRatio = std::max(out.worstRatio, r > 0.0f ? std::max(r, 1.0f / r) : kInfinity);
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

std::vector<float> PlacementEvaluation::sunShares(const std::atomic<bool>* cancel) const {
  const Integrator integrator(scene_, tracer_, probeIntegratorSettings(scene_, bake_));
  const int32_t light = sunLayerLight(scene_, integrator.settings());
  if (light < 0) return {};
  std::vector<float> out(truth_.points.size(), 0.0f);
  ParallelOptions options;
  options.threads = bake_.threads;
  options.grain = 64;
  options.cancel = cancel;
  parallelFor(
      out.size(),
      [&](size_t begin, size_t end) {
        for (size_t i = begin; i < end; ++i)
          out[i] = sunShare(integrator, uint32_t(light), truth_.points[i],
                            positionKey(truth_.points[i]));
      },
      options);
  if (cancel && cancel->load()) return {};
  return out;
}

FieldError PlacementEvaluation::measureWithExactSunShares(const ProbeSet& set,
                                                          std::span<const float> shares) const {
  ProbeSet layerless = set;
  layerless.sun.ramps.clear();  // the blend without ramps; the shares are added below
  std::vector<float> errors(truth_.points.size(), 0.0f);
  ParallelOptions options;
  options.threads = bake_.threads;
  options.grain = 64;
  parallelFor(
      errors.size(),
      [&](size_t begin, size_t end) {
        int32_t hint = -1;
        for (size_t i = begin; i < end; ++i) {
          const ProbeLocation loc = locateProbe(layerless, truth_.points[i], hint);
          hint = loc.cell;
          ShL2Rgb estimate = interpolateProbes(layerless, loc);
          // Where the runtime applies a layer: visibility-weighted blends in inner cells.
          if (!layerless.sun.empty() && i < shares.size() && loc.cell >= 0 &&
              loc.visibilityWeighted && !layerless.isOuter(loc.cell)) {
            float mixed = 0.0f;
            for (int k = 0; k < 4; ++k)
              mixed += loc.weights[k] * layerless.sun.visibility[size_t(loc.probes[k])];
            for (int c = 0; c < kShL2Count; ++c)
              estimate.c[c] += (shares[i] - mixed) * layerless.sun.sh.c[c];
          }
          errors[i] = relativeIrradianceError(truth_.sh[i], estimate, truth_.floor);
        }
      },
      options);
  return summarizeFieldError(std::move(errors));
}

}  // namespace kiln
