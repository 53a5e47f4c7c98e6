// probe_lit.cpp: see probe_lit.h.
#include "lightmap/probe_lit.h"

#include "src/distributed.h"
#include "src/integrator.h"
#include "src/progress.h"
#include "src/sampling.h"

namespace kiln {
namespace {

constexpr uint64_t kProbeLitTag = 0x70726f62656c6974ull;  // "probelit"

// One object's result as the ranks exchange it.
struct ProbeLitItem {
  ObjectProbe light;
  uint64_t rays = 0;
};

}  // namespace

ProbeBakeSettings probeLitBakeSettings(LightingMode lightingMode, int bounces, float albedoBoost,
                                       float indirectIntensity) {
  ProbeBakeSettings ps;
  ps.lightingMode = lightingMode;
  ps.bounces = bounces;
  ps.albedoBoost = albedoBoost;
  ps.indirectIntensity = indirectIntensity;
  return ps;
}

bool bakeProbeLitObjects(const Scene& scene, const AtlasLayout& layout, const Tracer& tracer,
                         const ProbeBakeSettings& settings, uint64_t seed, bool showProgress,
                         ParallelOptions parallel,
                         std::vector<std::optional<ObjectProbe>>& out,
                         std::atomic<uint64_t>& rays) {
  out.assign(scene.objects.size(), std::nullopt);
  std::vector<uint32_t> objects;
  for (size_t i = 0; i < layout.objects.size() && i < scene.objects.size(); ++i)
    if (layout.objects[i].probeLit && !scene.objects[i].positions.empty())
      objects.push_back(uint32_t(i));
  if (objects.empty()) return true;
  const Integrator integrator(scene, tracer, probeIntegratorSettings(scene, settings));
  const LightModePlan plan = probeLightModePlan(scene, settings);
  Progress progress("probe-lit objects", objects.size(), "objects", showProgress);
  parallel.progress = &progress;
  parallel.grain = 1;
  std::vector<ProbeLitItem> items(objects.size());
  // Every object costs about the same (7 probes at most): one tile each, dealt round robin.
  const WorkSplit split = splitWork(objects.size(), 1);
  progress.splitAcrossRanks();
  const bool done = parallelForLocal(
      split,
      [&](size_t begin, size_t end) {
        for (size_t i = begin; i < end; ++i) {
          const uint32_t o = objects[i];
          Bounds3 bounds;
          for (const vec3& p : scene.objects[o].positions) bounds.extend(p);
          const uint64_t before = Integrator::threadRayCount();
          items[i].light = bakeObjectProbe(integrator, plan, bounds,
                                           hashValues(seed, kProbeLitTag, o), settings);
          items[i].rays = Integrator::threadRayCount() - before;
        }
      },
      parallel);
  if (!exchangeItems(split, items, 1, false, done, !done, &progress)) return false;
  if (!distributedRoot()) return true;
  for (size_t i = 0; i < objects.size(); ++i) {
    out[objects[i]] = items[i].light;
    rays += items[i].rays;
  }
  progress.finish();
  return true;
}

}  // namespace kiln
