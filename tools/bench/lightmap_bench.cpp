// lightmap_bench.cpp: the lightmap bake's throughput on the shipped scenes (texels and rays
// per second of the light stage), single-threaded so that it reads against tracer_bench's
// raw Embree rays per second in the same run:
//   kiln_bench --benchmark_filter='Lightmap|Raw'
// ratio = Lightmap/<scene> rays_per_s / Intersect/RawEmbree/<scene> items_per_second (the
// bake's rays are a mix of closest-hit and occlusion rays plus the integrator's shading).
#include <benchmark/benchmark.h>

#include <string>

#include "lightmap/lightmap_baker.h"
#include "src/gltf_loader.h"

namespace kiln {
namespace {

void bakeScene(benchmark::State& state, const std::string& name) {
  LoadOptions options;
  options.loadSkyMap = false;
  auto scene = loadScene(std::string(KILN_SCENES_DIR) + "/" + name, options);
  if (!scene) {
    state.SkipWithError(scene.error().c_str());
    return;
  }
  LightmapBakeSettings settings;
  settings.resolution = scene->settings.lightmapResolution.value_or(10.0f);
  settings.samplesPerTexel = 16;  // the default bounce cap (64, Russian roulette)
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
}

const bool kRegistered = [] {
  for (const char* sceneName : {"cornell_box.gltf", "two_rooms.gltf", "courtyard.gltf"}) {
    const std::string name = sceneName;
    benchmark::RegisterBenchmark(("Lightmap/" + name).c_str(),
                                 [=](benchmark::State& state) { bakeScene(state, name); })
        ->Unit(benchmark::kMillisecond)
        ->Iterations(1);
  }
  return true;
}();

}  // namespace
}  // namespace kiln
