// sealed_surfaces.cpp: triangles no light reaches (see sealed_surfaces.h): rays from every
// static triangle, seeds where light is seen directly, then propagation over the rays' hits.
#include "lightmap/sealed_surfaces.h"

#include <deque>

#include "src/sampling.h"

namespace kiln {

namespace {

constexpr uint32_t kNone = 0xffffffffu;

}  // namespace

std::vector<std::vector<uint8_t>> findSealedTriangles(const Scene& scene, const Tracer& tracer,
                                                      const SealedSettings& settings) {
  const size_t objects = scene.objects.size();
  std::vector<uint32_t> first(objects + 1, 0);  // global triangle index of each object's first
  for (size_t o = 0; o < objects; ++o)
    first[o + 1] = first[o] + (tracer.contains(uint32_t(o))
                                   ? uint32_t(scene.objects[o].triangles.size())
                                   : 0u);
  const size_t total = first[objects];
  const int k = std::max(1, settings.raysPerTriangle);
  // Per triangle: lit directly; per ray: the triangle whose lit front it reached, or kNone.
  std::vector<uint8_t> lit(total, 0);
  std::vector<uint32_t> reached(total * size_t(k), kNone);
  const bool sky = !scene.sky.isBlack();
  auto globalIndex = [&](uint32_t object, uint32_t triangle) { return first[object] + triangle; };

  ParallelOptions options = settings.parallel;
  options.grain = 256;
  parallelFor(
      total,
      [&](size_t begin, size_t end) {
        for (size_t g = begin; g < end; ++g) {
          const uint32_t o = uint32_t(std::upper_bound(first.begin(), first.end(), uint32_t(g)) -
                                      first.begin() - 1);
          const uint32_t t = uint32_t(g - first[o]);
          const Object& object = scene.objects[o];
          const Material& material = scene.materialOf(o, t);
          if (material.doubleSided || material.isEmissive() || object.triangleArea(t) <= 0.0f) {
            lit[g] = 1;  // lit from either side, emitting, or without a surface: never sealed
            continue;
          }
          const vec3 n = object.faceNormal(t);
          const Frame frame = Frame::fromNormal(n);
          const uvec3 tri = object.triangles[t];
          for (int r = 0; r < k && !lit[g]; ++r) {
            // Sobol points per triangle: points and directions spread evenly.
            const vec2 b = squareToTriangle(sobol2D(uint32_t(r), hashValues(g, 0x5ea1edull)));
            const vec3 p = (1.0f - b.x - b.y) * object.positions[tri.x] +
                           b.x * object.positions[tri.y] + b.y * object.positions[tri.z];
            const vec3 origin = offsetRayOrigin(p, n);
            // Punctual lights in front of the point, unoccluded.
            for (const Light& light : scene.lights) {
              const vec3 to = light.type == LightType::Directional ? -light.direction
                                                                    : light.position - origin;
              if (glm::dot(to, n) <= 0.0f) continue;
              Ray shadow{origin, to, 0.0f,
                         light.type == LightType::Directional ? kInfinity : 1.0f - 1e-4f};
              if (!tracer.occluded(shadow, RayKind::LightShadow)) {
                lit[g] = 1;
                break;
              }
            }
            if (lit[g]) break;
            const vec3 dir = frame.toWorld(
                squareToCosineHemisphere(sobol2D(uint32_t(r), hashValues(g, 0xd1ec7ull))));
            Hit hit;
            if (!tracer.intersect(Ray{origin, dir}, hit)) {
              if (sky) lit[g] = 1;
              continue;
            }
            const Material& seen = scene.materialOf(hit.object, hit.triangle);
            if (seen.alphaMode == AlphaMode::Blend || seen.isEmissive()) {
              lit[g] = 1;  // light passes through, or is emitted
              continue;
            }
            if (!hit.backFace || seen.doubleSided)
              reached[g * size_t(k) + size_t(r)] = globalIndex(hit.object, hit.triangle);
          }
        }
      },
      options);

  // Propagation: a triangle is lit when one of its rays reached a lit triangle's front.
  std::vector<uint32_t> offsets(total + 1, 0);
  for (uint32_t target : reached)
    if (target != kNone) ++offsets[target + 1];
  for (size_t i = 0; i < total; ++i) offsets[i + 1] += offsets[i];
  std::vector<uint32_t> seenBy(offsets[total]);
  {
    std::vector<uint32_t> fill(offsets.begin(), offsets.end() - 1);
    for (size_t g = 0; g < total; ++g)
      for (int r = 0; r < k; ++r) {
        const uint32_t target = reached[g * size_t(k) + size_t(r)];
        if (target != kNone) seenBy[fill[target]++] = uint32_t(g);
      }
  }
  std::deque<uint32_t> queue;
  for (size_t g = 0; g < total; ++g)
    if (lit[g]) queue.push_back(uint32_t(g));
  while (!queue.empty()) {
    const uint32_t h = queue.front();
    queue.pop_front();
    for (uint32_t i = offsets[h]; i < offsets[h + 1]; ++i)
      if (!lit[seenBy[i]]) {
        lit[seenBy[i]] = 1;
        queue.push_back(seenBy[i]);
      }
  }

  std::vector<std::vector<uint8_t>> sealed(objects);
  for (size_t o = 0; o < objects; ++o) {
    if (!tracer.contains(uint32_t(o))) continue;
    sealed[o].resize(scene.objects[o].triangles.size());
    for (size_t t = 0; t < sealed[o].size(); ++t) sealed[o][t] = lit[first[o] + t] ? 0 : 1;
  }
  return sealed;
}

}  // namespace kiln
