// tracer_bench.cpp: closest-hit and occlusion rays per second, kiln::Tracer against raw
// Embree on the same geometry and the same precomputed rays, so that the cost of kiln's
// wrapper (ray setup, normal computation, alpha filters) reads as a ratio in one run.
//
// Scenes: a procedural one built here (always available) and the shipped glTF scenes in
// KILN_SCENES_DIR; a file that fails to load is reported with SkipWithError.
#include <benchmark/benchmark.h>
#include <embree3/rtcore.h>

#include <map>
#include <memory>
#include <random>
#include <string>
#include <vector>

#include "src/gltf_loader.h"
#include "src/tracer.h"
#include "tools/bench/raw_embree.h"

namespace kiln {
namespace {

constexpr int kRayCount = 1 << 16;  // precomputed rays per scene, cycled through
constexpr int kBatch = 256;         // rays per benchmark iteration

// Appends an axis-aligned box (outward faces) or a room (inward faces) as 12 triangles.
void appendBox(Object& o, vec3 lo, vec3 hi, bool inward) {
  auto corner = [&](int i) {
    return vec3(i & 1 ? hi.x : lo.x, i & 2 ? hi.y : lo.y, i & 4 ? hi.z : lo.z);
  };
  const int faces[6][4] = {{0, 4, 6, 2}, {1, 3, 7, 5}, {0, 1, 5, 4},
                           {2, 6, 7, 3}, {0, 2, 3, 1}, {4, 5, 7, 6}};
  for (const auto& f : faces) {
    uint32_t base = uint32_t(o.positions.size());
    for (int k = 0; k < 4; ++k) o.positions.push_back(corner(f[inward ? 3 - k : k]));
    o.triangles.push_back(uvec3(base, base + 1, base + 2));
    o.triangles.push_back(uvec3(base, base + 2, base + 3));
  }
}

// A closed room with a bumpy tessellated floor (32k triangles) and a grid of 100 boxes: a
// stand-in of roughly a shipped scene's size that needs no loader.
Scene proceduralScene() {
  Scene scene;
  Material m;
  m.name = "grey";
  m.baseColorFactor = vec4(0.5f, 0.5f, 0.5f, 1.0f);
  scene.materials.push_back(m);

  Object room;
  room.name = "room";
  appendBox(room, vec3(-10.0f, 0.0f, -10.0f), vec3(10.0f, 8.0f, 10.0f), true);
  const int n = 128;
  Object floor;
  floor.name = "terrain";
  for (int j = 0; j <= n; ++j)
    for (int i = 0; i <= n; ++i) {
      float x = -10.0f + 20.0f * i / n, z = -10.0f + 20.0f * j / n;
      floor.positions.push_back(vec3(x, 0.3f + 0.25f * std::sin(x) * std::cos(1.3f * z), z));
    }
  for (int j = 0; j < n; ++j)
    for (int i = 0; i < n; ++i) {
      uint32_t a = j * (n + 1) + i, b = a + 1, c = a + n + 1, d = c + 1;
      floor.triangles.push_back(uvec3(a, c, d));
      floor.triangles.push_back(uvec3(a, d, b));
    }
  Object blocks;
  blocks.name = "blocks";
  for (int j = 0; j < 10; ++j)
    for (int i = 0; i < 10; ++i) {
      vec3 lo(-9.0f + 1.8f * i, 0.0f, -9.0f + 1.8f * j);
      float h = 0.5f + 3.0f * float((i * 7 + j * 13) % 10) / 10.0f;
      appendBox(blocks, lo, lo + vec3(0.9f, h, 0.9f), false);
    }
  for (Object* o : {&room, &floor, &blocks}) {
    o->triangleMaterial.assign(o->triangles.size(), 0);
    scene.objects.push_back(std::move(*o));
  }
  scene.updateBounds();
  return scene;
}

// One scene prepared for both contenders: kiln's Tracer and a bare Embree scene of the same
// triangles (same flags and build quality, no filter functions).
struct BenchScene {
  std::string error;  // non-empty: the scene could not be prepared
  Scene scene;
  std::unique_ptr<Tracer> tracer;
  RTCDevice device = nullptr;
  RTCScene raw = nullptr;
  std::vector<Ray> rays;
  size_t triangles = 0;

  BenchScene() = default;
  BenchScene(const BenchScene&) = delete;
  ~BenchScene() {
    if (raw) rtcReleaseScene(raw);
    if (device) rtcReleaseDevice(device);
  }

  void prepare() {
    auto tracerResult = Tracer::create(scene);
    if (!tracerResult) {
      error = tracerResult.error();
      return;
    }
    tracer = std::move(tracerResult).value();

    device = rtcNewDevice(nullptr);
    raw = buildRawEmbreeScene(device, scene, triangles);

    // Origins uniform in the scene's bounds, directions uniform on the sphere; fixed seed so
    // both contenders (and successive runs) trace identical rays.
    std::mt19937 rng(1234);
    std::uniform_real_distribution<float> u(0.0f, 1.0f);
    const Bounds3& b = scene.bounds;
    rays.resize(kRayCount);
    for (Ray& r : rays) {
      vec3 o = b.min + b.extent() * vec3(u(rng), u(rng), u(rng));
      float z = 1.0f - 2.0f * u(rng), phi = 2.0f * kPi * u(rng);
      float s = std::sqrt(std::max(0.0f, 1.0f - z * z));
      r = Ray{o, vec3(s * std::cos(phi), s * std::sin(phi), z)};
    }
  }
};

// Scenes are prepared on first use and kept for the whole run (benchmarks run serially).
BenchScene& getScene(const std::string& name) {
  static std::map<std::string, std::unique_ptr<BenchScene>> cache;
  auto& slot = cache[name];
  if (!slot) {
    slot = std::make_unique<BenchScene>();
    if (name == "procedural") {
      slot->scene = proceduralScene();
    } else {
      LoadOptions options;
      options.loadSkyMap = false;
      auto loaded = loadScene(std::string(KILN_SCENES_DIR) + "/" + name, options);
      if (!loaded) {
        slot->error = loaded.error();
        return *slot;
      }
      slot->scene = std::move(loaded).value();
    }
    slot->prepare();
  }
  return *slot;
}

enum class Query { Intersect, Occluded };
enum class Contender { RawEmbree, Tracer };

// Traces kBatch rays per iteration; reports rays per second (items_per_second) and the hit
// fraction, which must agree between the contenders (same rays, same geometry).
void traceRays(benchmark::State& state, const std::string& name, Query query, Contender who) {
  BenchScene& s = getScene(name);
  if (!s.error.empty()) {
    state.SkipWithError(s.error.c_str());
    return;
  }
  size_t next = 0;
  int64_t hits = 0;
  RTCIntersectContext context;
  rtcInitIntersectContext(&context);
  for (auto _ : state) {
    for (int k = 0; k < kBatch; ++k) {
      const Ray& r = s.rays[next];
      next = (next + 1) & (kRayCount - 1);
      bool hit;
      if (who == Contender::RawEmbree) {
        if (query == Query::Intersect) {
          RTCRayHit rh;
          rh.ray = toRtcRay(r);
          rh.hit.geomID = RTC_INVALID_GEOMETRY_ID;
          rh.hit.instID[0] = RTC_INVALID_GEOMETRY_ID;
          rtcIntersect1(s.raw, &context, &rh);
          hit = rh.hit.geomID != RTC_INVALID_GEOMETRY_ID;
          benchmark::DoNotOptimize(rh.ray.tfar);
        } else {
          RTCRay ray = toRtcRay(r);
          rtcOccluded1(s.raw, &context, &ray);
          hit = ray.tfar < 0.0f;
        }
      } else {
        if (query == Query::Intersect) {
          std::optional<Hit> h = s.tracer->intersect(r);
          hit = h.has_value();
          benchmark::DoNotOptimize(h);
        } else {
          hit = s.tracer->occluded(r);
        }
      }
      hits += hit;
    }
  }
  state.SetItemsProcessed(state.iterations() * kBatch);
  state.counters["hitFraction"] = double(hits) / double(state.iterations() * kBatch);
  state.counters["triangles"] = double(s.triangles);
}

// Registered at static-initialization time (the program's main is benchmark_main); scenes
// load lazily inside the benchmarks.
const bool kRegistered = [] {
  const char* scenes[] = {"procedural", "cornell_box.gltf", "two_rooms.gltf", "courtyard.gltf"};
  for (const char* sceneName : scenes) {
    std::string name = sceneName;
    for (Query q : {Query::Intersect, Query::Occluded}) {
      for (Contender c : {Contender::RawEmbree, Contender::Tracer}) {
        std::string label = std::string(q == Query::Intersect ? "Intersect" : "Occluded") +
                            "/" + (c == Contender::RawEmbree ? "RawEmbree" : "Tracer") + "/" +
                            name;
        benchmark::RegisterBenchmark(label.c_str(), [=](benchmark::State& state) {
          traceRays(state, name, q, c);
        });
      }
    }
  }
  return true;
}();

}  // namespace
}  // namespace kiln
