// lightmap_bench.cpp: the lightmap bake's throughput on the shipped scenes, single-threaded,
// against raw Embree tracing exactly the rays the bake traced:
//   kiln_bench --benchmark_filter='Lightmap/'
// Counters: rays_per_s = the bake's rays (push-out, paths, shadow and AO rays) over the wall
// time of the stages that trace them; raw_rays_per_s = the same rays (captured from a second,
// identical bake with Tracer::captureRays, the same closest-hit or occlusion query each) traced
// by a bare Embree scene of the same triangles (raw_embree.h: no filter functions, no
// shading, no sampling); ratio = rays_per_s / raw_rays_per_s, the share of the bake's time
// that Embree alone would need: 1 - ratio is kiln's overhead. tracer_bench's RawEmbree
// benchmarks give a second baseline on random rays (origins uniform in the scene's bounds),
// a different ray distribution.
#include <benchmark/benchmark.h>
#include <embree3/rtcore.h>

#include <chrono>
#include <string>
#include <utility>
#include <vector>

#include "lightmap/lightmap_baker.h"
#include "src/gltf_loader.h"
#include "tools/bench/raw_embree.h"

namespace kiln {
namespace {

// Seconds for raw Embree to trace `rays` (each with its own query) on `scene`'s triangles.
double rawSeconds(const Scene& scene, const std::vector<Tracer::CapturedRay>& rays) {
  RTCDevice device = rtcNewDevice(nullptr);
  size_t triangles = 0;
  RTCScene raw = buildRawEmbreeScene(device, scene, triangles);
  RTCIntersectContext context;
  rtcInitIntersectContext(&context);
  size_t hits = 0;
  const auto start = std::chrono::steady_clock::now();
  for (const Tracer::CapturedRay& c : rays) {
    if (c.closestHit) {
      RTCRayHit rh;
      rh.ray = toRtcRay(c.ray);
      rh.hit.geomID = RTC_INVALID_GEOMETRY_ID;
      rh.hit.instID[0] = RTC_INVALID_GEOMETRY_ID;
      rtcIntersect1(raw, &context, &rh);
      hits += rh.hit.geomID != RTC_INVALID_GEOMETRY_ID;
    } else {
      RTCRay ray = toRtcRay(c.ray);
      rtcOccluded1(raw, &context, &ray);
      hits += ray.tfar < 0.0f;
    }
  }
  const double seconds =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  benchmark::DoNotOptimize(hits);
  rtcReleaseScene(raw);
  rtcReleaseDevice(device);
  return seconds;
}

// Samples per texel (default bounce cap: 64, Russian roulette) chosen per scene so that each
// bake traces 1.5-2.5 M rays: the Cornell box has 360 texels at its resolution, two_rooms
// 29.6 k, the courtyard 7.1 k.
void bakeScene(benchmark::State& state, const std::string& name, int samples) {
  LoadOptions options;
  options.loadSkyMap = false;
  auto scene = loadScene(std::string(KILN_SCENES_DIR) + "/" + name, options);
  if (!scene) {
    state.SkipWithError(scene.error().c_str());
    return;
  }
  LightmapBakeSettings settings;
  settings.resolution = scene->settings.lightmapResolution.value_or(10.0f);
  settings.samplesPerTexel = samples;
  settings.threads = 1;
  double seconds = 0.0, rays = 0.0, texels = 0.0;
  for (auto _ : state) {
    auto result = bakeLightmaps(*scene, settings);
    if (!result) {
      state.SkipWithError(result.error().c_str());
      return;
    }
    seconds += result->stats.seconds;
    rays += double(result->stats.rays);
    texels += double(result->stats.texels);
  }
  state.counters["texels"] = texels / double(state.iterations());
  state.counters["texels_per_s"] = texels / seconds;
  state.counters["rays_per_s"] = rays / seconds;
  state.counters["rays_per_texel"] = rays / texels;

  // The baseline, outside the timed loop: the same bake once more with its rays captured
  // (the bake's own scene, whose objects may have been re-meshed by the unwrap).
  std::vector<Tracer::CapturedRay> captured;
  captured.reserve(size_t(rays / double(state.iterations())) + 1024);
  Tracer::captureRays(&captured);
  auto again = bakeLightmaps(*scene, settings);
  Tracer::captureRays(nullptr);
  if (!again) {
    state.SkipWithError(again.error().c_str());
    return;
  }
  const double raw = double(captured.size()) / rawSeconds(again->scene, captured);
  // The bake counts a transmittance query as one ray; captured rays include the closest-hit
  // steps of walks through BLEND surfaces, so per-ray rates use the captured count for both.
  const double bakeRate = double(captured.size()) / again->stats.seconds;
  state.counters["captured_rays"] = double(captured.size());
  state.counters["raw_rays_per_s"] = raw;
  state.counters["ratio"] = bakeRate / raw;
}

const bool kRegistered = [] {
  for (auto [sceneName, samples] : {std::pair{"cornell_box.gltf", 1024},
                                    std::pair{"two_rooms.gltf", 16},
                                    std::pair{"courtyard.gltf", 64}}) {
    const std::string name = sceneName;
    benchmark::RegisterBenchmark(
        ("Lightmap/" + name).c_str(),
        [name, samples = samples](benchmark::State& state) { bakeScene(state, name, samples); })
        ->Unit(benchmark::kMillisecond)
        ->Iterations(1);
  }
  return true;
}();

}  // namespace
}  // namespace kiln
