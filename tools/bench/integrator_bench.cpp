// integrator_bench.cpp: paths per second of kiln::Integrator on the shipped scenes, with the
// rays each path traces (shadow + continuation), so that the integrator's overhead over raw
// ray casting reads against tracer_bench's rays/s measured in the same run:
//   overhead = 1 - (paths/s x rays/path) / (Tracer or RawEmbree rays/s).
//
// Two workloads per scene: an irradiance estimate at a point on a static surface (lightmap
// texels: NEE at the point, then the path) and incomingRadiance along a random direction
// from a point in the scene's bounds (probe rays). One path per estimate, a fresh key each.
// Scenes load from KILN_SCENES_DIR; a file that fails to load is reported with
// SkipWithError.
#include <benchmark/benchmark.h>

#include <map>
#include <memory>
#include <random>
#include <string>
#include <vector>

#include "src/gltf_loader.h"
#include "src/integrator.h"
#include "src/sampling.h"
#include "src/tracer.h"

namespace kiln {
namespace {

constexpr int kPointCount = 1 << 14;  // precomputed estimate points, cycled through
constexpr int kBatch = 64;            // paths per benchmark iteration

struct SurfacePoint {
  vec3 p, n;
};

struct IntegratorScene {
  std::string error;
  Scene scene;
  std::unique_ptr<Tracer> tracer;
  std::unique_ptr<Integrator> integrator;
  std::vector<SurfacePoint> surfacePoints;  // on static triangles, area-uniform, front side
  std::vector<SurfacePoint> probeRays;      // origin in the bounds, unit direction

  void prepare() {
    auto created = Tracer::create(scene);
    if (!created) {
      error = created.error();
      return;
    }
    tracer = std::move(created).value();
    IntegratorSettings settings;
    settings.maxBounces = scene.settings.bounces.value_or(settings.maxBounces);
    settings.albedoBoost = scene.settings.albedoBoost.value_or(settings.albedoBoost);
    settings.indirectIntensity =
        scene.settings.indirectIntensity.value_or(settings.indirectIntensity);
    integrator = std::make_unique<Integrator>(scene, *tracer, settings);

    // Area-weighted triangles of static objects (what a lightmap bake shades).
    std::vector<float> areas;
    std::vector<std::pair<uint32_t, uint32_t>> tris;
    for (uint32_t o = 0; o < scene.objects.size(); ++o) {
      const Object& obj = scene.objects[o];
      if (!obj.settings.isStatic) continue;
      for (uint32_t t = 0; t < obj.triangles.size(); ++t) {
        areas.push_back(obj.triangleArea(t));
        tris.emplace_back(o, t);
      }
    }
    if (tris.empty()) {
      error = "no static triangles";
      return;
    }
    Distribution1D pick(areas);
    std::mt19937 rng(4321);
    std::uniform_real_distribution<float> u(0.0f, 1.0f);
    surfacePoints.resize(kPointCount);
    for (SurfacePoint& s : surfacePoints) {
      auto [o, t] = tris[pick.sampleDiscrete(u(rng))];
      vec2 bary = squareToTriangle(vec2(u(rng), u(rng)));
      s.n = scene.objects[o].faceNormal(t);
      s.p = offsetRayOrigin(scene.positionAt(o, t, bary), s.n);
    }
    const Bounds3& b = scene.bounds;
    probeRays.resize(kPointCount);
    for (SurfacePoint& s : probeRays) {
      s.p = b.min + b.extent() * vec3(u(rng), u(rng), u(rng));
      s.n = squareToUniformSphere(vec2(u(rng), u(rng)));
    }
  }
};

IntegratorScene& getScene(const std::string& name) {
  static std::map<std::string, std::unique_ptr<IntegratorScene>> cache;
  auto& slot = cache[name];
  if (!slot) {
    slot = std::make_unique<IntegratorScene>();
    auto loaded = loadScene(std::string(KILN_SCENES_DIR) + "/" + name);
    if (!loaded) {
      slot->error = loaded.error();
      return *slot;
    }
    slot->scene = std::move(loaded).value();
    slot->prepare();
  }
  return *slot;
}

enum class Workload { Irradiance, Probe };

void tracePaths(benchmark::State& state, const std::string& name, Workload workload) {
  IntegratorScene& s = getScene(name);
  if (!s.error.empty()) {
    state.SkipWithError(s.error.c_str());
    return;
  }
  const Integrator& integrator = *s.integrator;
  uint64_t key = 0;
  const uint64_t raysBefore = Integrator::threadRayCount();
  double sum = 0.0;
  for (auto _ : state) {
    for (int k = 0; k < kBatch; ++k, ++key) {
      const SurfacePoint& sp =
          (workload == Workload::Irradiance ? s.surfacePoints : s.probeRays)[key % kPointCount];
      LightingEstimate e = workload == Workload::Irradiance
                               ? integrator.irradiance(sp.p, sp.n, key, 0, 1)
                               : integrator.incomingRadiance(sp.p, sp.n, key, 0);
      sum += double(e.total().x);
    }
  }
  const double paths = double(state.iterations()) * kBatch;
  const double rays = double(Integrator::threadRayCount() - raysBefore);
  state.SetItemsProcessed(int64_t(paths));
  state.counters["raysPerPath"] = paths > 0 ? rays / paths : 0.0;
  state.counters["rays"] = benchmark::Counter(rays, benchmark::Counter::kIsRate);
  state.counters["meanE"] = paths > 0 ? sum / paths : 0.0;  // sanity: non-zero and stable
}

const bool kRegistered = [] {
  for (const char* sceneName : {"cornell_box.gltf", "two_rooms.gltf", "courtyard.gltf"}) {
    std::string name = sceneName;
    benchmark::RegisterBenchmark(
        ("Integrator/Irradiance/" + name).c_str(),
        [=](benchmark::State& state) { tracePaths(state, name, Workload::Irradiance); });
    benchmark::RegisterBenchmark(
        ("Integrator/ProbeRadiance/" + name).c_str(),
        [=](benchmark::State& state) { tracePaths(state, name, Workload::Probe); });
  }
  return true;
}();

}  // namespace
}  // namespace kiln
