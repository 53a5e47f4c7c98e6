// integrator.h: light transport estimates shared by the lightmap and probe bakers.
//
// A unidirectional path tracer with next-event estimation:
//   - punctual lights (KHR_lights_punctual) with hard or soft shadows (shadowRadius,
//     shadowAngle, shadowSamples), glTF spot falloff and range window (MISSION.md);
//   - emissive triangles, chosen in proportion to their power and sampled by area;
//   - the sky (constant or an importance-sampled equirectangular map);
// emissive triangles and the sky are combined with cosine-weighted BSDF sampling by
// multiple importance sampling (power heuristic). Surfaces are Lambertian with the bounce
// albedo of Scene::bounceAlbedoAt, raised to 1/albedoBoost. Back faces of single-sided
// materials reflect nothing (they are the inside of geometry). Paths continue with cosine
// sampling and Russian roulette up to maxBounces.
//
// Units: irradiance E in W/m^2 (lux in glTF's photometric reading, no 683 factor);
// radiance L in W/(m^2 sr). A lightmap texel stores E / pi.
// Determinism: every estimate is a pure function of its arguments (see sampling.h).
// What takes part: the objects the Tracer holds (a baking Tracer holds static objects only,
// src/tracer.h), so emissive triangles of objects it leaves out are no emitters either.
// Shadows: the shadow rays of punctual lights pass objects with castShadows false
// (RayKind::LightShadow) and are not traced at all for a light with bakedShadows false
// (visibility 1); sky and emitter samples are shadowed by every surface the tracer holds,
// since their light is also found by the paths, which hit such objects (a shadow ray that
// ignored an object that the path hits would count its light twice).
#pragma once

#include <memory>
#include <vector>

#include "src/math.h"
#include "src/sampling.h"
#include "src/scene.h"
#include "src/tracer.h"

namespace kiln {

// Light a first, cheaper pass of a bake already computed, which later paths read instead of
// tracing on (a final gather: Beast's and Lightmass's final gather over an irradiance cache,
// Godot's and Enlighten's bounce from the previous pass's lightmap). The lightmap baker
// implements it over its first-pass pages (lightmap_baker.cpp, LightmapBounceCache).
class BounceCache {
 public:
  virtual ~BounceCache() = default;
  // E / pi at the front of triangle `triangle` of `object` at Embree barycentrics `bary`,
  // as a bounce sees it: the irradiance from the lights of IntegratorSettings::indirectLights
  // (x bounceIntensity), emitters and the sky, plus indirect light with maxBounces - 1
  // bounces, not x indirectIntensity (an Integrator with bounceView and indirectIntensity 1
  // estimates it). Returns false where the cache holds nothing (an object without a
  // lightmap): the path then goes on as without a cache.
  virtual bool lookup(uint32_t object, uint32_t triangle, vec2 bary, vec3& value) const = 0;
};

struct IntegratorSettings {
  int maxBounces = 4;            // bounces of indirect light; 0 = direct light only
  int russianRouletteDepth = 2;  // bounces before Russian roulette starts
  float albedoBoost = 1.0f;      // albedo' = pow(albedo, 1 / albedoBoost)
  float indirectIntensity = 1.0f;  // multiplies all indirect light
  // Per scene light: whether its unbounced light is included (direct) and whether its
  // light is included after bouncing (indirect). Empty = every light that is not realtime.
  // Integrator::settings() returns them resolved: one entry per scene light (entries
  // missing from a shorter vector are false).
  std::vector<bool> directLights;
  std::vector<bool> indirectLights;
  bool includeSky = true;
  bool includeEmissive = true;
  // Whether Light::bakedShadows applies (lights that are not realtime). The preview renderer
  // turns it off for its run-time direct light, whose shadows are the engine's.
  bool honourBakedShadows = true;
  // irradiance() counts at its point the lights a bounce sees (indirectLights, each x its
  // bounceIntensity) instead of directLights: the estimate a BounceCache holds.
  bool bounceView = false;
  // When set, a path's first hit on the front of a surface the cache covers ends the path:
  // the light reflected there is albedo x the cached E / pi (no NEE, no further bounce).
  // The cache must outlive the Integrator.
  const BounceCache* bounceCache = nullptr;
};

// An estimate split into the light that arrives without bouncing and the rest.
struct LightingEstimate {
  vec3 direct{0.0f};    // straight from lights, emissive surfaces or the sky
  vec3 indirect{0.0f};  // after one or more bounces (already x indirectIntensity)
  vec3 total() const { return direct + indirect; }
};

// A punctual light's contribution at a point, as a delta in direction.
struct DeltaLight {
  uint32_t light = 0;    // index into Scene::lights
  vec3 direction{0.0f};  // unit, towards the light
  vec3 irradiance{0.0f};  // on a surface facing the light, x visibility (mean of shadow rays)
};

class Integrator {
 public:
  // `scene` and `tracer` must outlive the Integrator.
  Integrator(const Scene& scene, const Tracer& tracer, IntegratorSettings settings = {});

  // Irradiance E at point p on a surface with unit normal n (the side light arrives from),
  // averaged over samples [firstSample, firstSample + sampleCount) of the stream `key`.
  // p should already lie outside geometry; rays leave from p offset along n.
  // When `backFaceHits` is given, the number of samples whose first (cosine-sampled) ray
  // hit the back face of a single-sided, non-BLEND surface is added to it: a point whose
  // rays mostly see back faces is inside geometry (lightmap texel validity, as probe
  // validity in Unity's Adaptive Probe Volumes). Does not change the estimate.
  // When `weightedDirection` is given, the luminance-weighted incoming direction of the
  // estimate is added to it: the mean over the samples of sum_i luminance(c_i) w_i, where c_i
  // runs over the terms of the estimate (punctual lights, emitter and sky light samples, the
  // cosine-sampled path, each x indirectIntensity where the estimate applies it) and w_i is
  // the unit world direction that term's light arrives from. Divided by
  // luminance(estimate.total()) it is the dominant direction of directional lightmaps, whose
  // length (<= 1) is the directionality (lightmap/directional.h). Does not change the estimate.
  LightingEstimate irradiance(vec3 p, vec3 n, uint64_t key, uint32_t firstSample,
                              uint32_t sampleCount, uint32_t* backFaceHits = nullptr,
                              vec3* weightedDirection = nullptr) const;

  // Whether the count irradiance(p, n, key, firstSample, sampleCount, &backFaceHits) adds
  // to backFaceHits exceeds share x sampleCount, without estimating any light: the first
  // cosine-sampled ray of each sample (the same direction, and the same BLEND pass-throughs,
  // as irradiance's path) counts when it ends on the back of a single-sided, non-BLEND
  // surface; it stops as soon as the answer is known. At most one ray per sample (more only
  // through BLEND layers). The lightmap baker decides with it whether a texel's own points
  // are inside geometry when it estimates the texel's light elsewhere (its footprint grid),
  // so that the decision is the one a bake without the grid makes.
  bool firstRaysSeeBackFaces(vec3 p, vec3 n, uint64_t key, uint32_t firstSample,
                             uint32_t sampleCount, float share) const;

  // Radiance arriving at p from unit direction `dir` (one path, sample `sampleIndex` of
  // stream `key`): direct = emission seen along the ray (sky, emissive surface); indirect =
  // light reflected towards p by the first surface hit. Punctual lights are deltas and are
  // never hit: add them with punctualLights().
  LightingEstimate incomingRadiance(vec3 p, vec3 dir, uint64_t key, uint32_t sampleIndex) const;

  // The punctual lights selected by settings.directLights at p, with visibility (averaged
  // over each light's shadowSamples; soft shadows jittered by sample `sampleIndex` of
  // stream `key`). Appends to `out`.
  void punctualLights(vec3 p, uint64_t key, uint32_t sampleIndex,
                      std::vector<DeltaLight>& out) const;

  // Visibility of scene light `light` from p (shadow rays leave p offset along unit n; pass
  // n = 0 for a point in free space such as a probe): the mean transmittance (rgb, 1 =
  // unoccluded) over the light's shadowSamples rays, jittered by sample `sampleIndex` of
  // stream `key` when the light has soft shadows. Ignores the light's falloff, cone and the
  // light selection (for shadowmask and probe occlusion of mixed lights).
  vec3 lightVisibility(vec3 p, vec3 n, uint32_t light, uint64_t key, uint32_t sampleIndex) const;

  // Rays (shadow, continuation and first rays) traced by Integrator calls on the calling
  // thread since the thread started. A plain thread-local counter, for benchmarks; read it
  // before and after a batch of work on one thread.
  static uint64_t threadRayCount();

  const IntegratorSettings& settings() const { return settings_; }
  const Scene& scene() const { return scene_; }
  const Tracer& tracer() const { return tracer_; }

 private:
  struct EmitterTable;
  struct MaterialTable;
  enum class ShadowKind { Any, Hard, Soft };
  // Helpers, defined and documented in integrator.cpp.
  vec3 transmittance(vec3 origin, vec3 direction, float tMax, RayKind kind = RayKind::Any) const;
  vec3 visibilityTo(uint32_t light, vec3 origin, uint64_t key, uint32_t firstIndex, uint32_t rays,
                    uint32_t dimension) const;
  vec3 punctualIrradiance(vec3 x, vec3 ns, vec3 ng, bool atOrigin, ShadowKind kind, uint64_t key,
                          uint32_t sampleIndex, uint32_t vertex,
                          vec3* weightedDirection = nullptr) const;
  vec3 sampleEmitters(vec3 x, vec3 ns, vec3 ng, float uSelect, vec2 uPoint,
                      vec3* direction = nullptr) const;
  vec3 sampleSky(vec3 x, vec3 ns, vec3 ng, vec2 u, vec3* direction = nullptr) const;
  float emitterPdf(uint32_t object, uint32_t triangle, float distance2, float cosLight) const;
  vec3 albedoAt(uint32_t object, uint32_t triangle, vec2 bary) const;
  // A path segment's hit h on a BLEND surface: passes straight through with probability
  // 1 - alpha (tinting beta by the base colour and moving ray on past h), or reflects there.
  // Returns false when the path stops crossing: it reflects (*absorbed false) or it is
  // absorbed (too many layers or beta black: *absorbed true). The random numbers of vertex
  // `vertex` of path `sampleIndex`, as tracePath draws them.
  bool crossBlend(const Hit& h, SampleStream& stream, uint64_t key, uint32_t vertex,
                  uint32_t sampleIndex, Ray& ray, vec3& beta, int& passes,
                  bool* absorbed) const;
  void tracePath(Ray ray, float bsdfPdf, uint64_t key, uint32_t sampleIndex, vec3& direct,
                 vec3& indirect, uint32_t* backFaceHits = nullptr) const;

  const Scene& scene_;
  const Tracer& tracer_;
  IntegratorSettings settings_;
  std::shared_ptr<const EmitterTable> emitters_;
  std::shared_ptr<const MaterialTable> materials_;  // per Scene::materials entry
  bool sampleEmissive_ = false;  // emitter NEE runs (includeEmissive and emitters exist)
  bool sampleSky_ = false;       // sky NEE runs (includeSky and the sky is not black)
};

}  // namespace kiln
