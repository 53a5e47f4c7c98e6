// integrator.cpp: the path tracer behind every bake (see integrator.h).
//
// Structure (pbrt-v4's PathIntegrator, reduced to Lambertian surfaces):
//   - at every vertex that reflects light (the estimate's point for irradiance(), then each
//     path vertex) next-event estimation (NEE) samples the punctual lights, one emissive
//     triangle (by power, then uniformly by area) and the sky;
//   - the path continues by cosine-weighted sampling; when it hits an emissive triangle or
//     escapes to the sky, that emission is weighted against the light-sampling pdf of the
//     vertex it left with the power heuristic (Veach 1997, ch. 9), so each emitter's light is
//     counted once by two strategies; punctual lights are deltas and only NEE sees them;
//   - Russian roulette (Arvo & Kirk 1990) after russianRouletteDepth bounces.
// Random numbers: vertex j of a path owns a fixed block of SampleStream dimensions
// (kSlotsPerVertex draws), so a vertex's samples never shift with how many numbers earlier
// vertices drew; draws whose number varies (soft-shadow rays, repeated BLEND pass-throughs)
// come from streams keyed by (key, tag, ...) instead.
#include "src/integrator.h"

namespace kiln {

namespace {

thread_local uint64_t tRayCount = 0;

// Draw slots of one path vertex; SampleStream draws consume two dimensions each.
constexpr uint32_t kSlotEmitterSelect = 0;
constexpr uint32_t kSlotEmitterPoint = 1;
constexpr uint32_t kSlotSky = 2;
constexpr uint32_t kSlotBsdf = 3;
constexpr uint32_t kSlotRoulette = 4;
constexpr uint32_t kSlotBlend = 5;  // the first BLEND pass-through decision on the way in
constexpr uint32_t kSlotsPerVertex = 6;

// Tags for keyed side streams.
constexpr uint64_t kShadowTag = 0x736861646f77ull;  // "shadow"
constexpr uint64_t kBlendTag = 0x626c656e64ull;     // "blend"

constexpr int kMaxPassThroughs = 64;     // BLEND layers one segment may cross
constexpr float kRouletteCap = 0.95f;    // survival never 1: bounds the cost of white rooms
constexpr float kShadowEpsilon = 1e-4f;  // shadow segments stop this fraction short

float draw1D(SampleStream& stream, uint32_t vertex, uint32_t slot) {
  stream.setDimension(2 * (vertex * kSlotsPerVertex + slot));
  return stream.get1D();
}

vec2 draw2D(SampleStream& stream, uint32_t vertex, uint32_t slot) {
  stream.setDimension(2 * (vertex * kSlotsPerVertex + slot));
  return stream.get2D();
}

bool isSoft(const Light& light) {
  return light.type == LightType::Directional ? light.shadowAngle > 0.0f
                                              : light.shadowRadius > 0.0f;
}

bool isBlack(vec3 c) { return !(maxComponent(c) > 0.0f); }

// Position and shading normal at a point of a triangle in one fetch of its vertices: the
// same arithmetic as Scene::positionAt and Scene::shadingNormalAt (bit for bit), which the
// path vertex needs together.
struct SurfaceFrame {
  vec3 position;
  vec3 shadingNormal;
};

SurfaceFrame surfaceAt(const Object& o, uint32_t triangle, vec2 bary) {
  const uvec3 tri = o.triangles[triangle];
  const float b0 = 1.0f - bary.x - bary.y;
  SurfaceFrame f;
  f.position = b0 * o.positions[tri.x] + bary.x * o.positions[tri.y] + bary.y * o.positions[tri.z];
  if (o.normals.empty()) {
    f.shadingNormal = o.faceNormal(triangle);
  } else {
    const vec3 n = b0 * o.normals[tri.x] + bary.x * o.normals[tri.y] + bary.y * o.normals[tri.z];
    const float len = glm::length(n);
    f.shadingNormal = len > 1e-12f ? n / len : o.faceNormal(triangle);
  }
  return f;
}

// Integrator::albedoAt's clamp and boost of a bounce albedo.
vec3 boostAlbedo(vec3 albedo, float boost) {
  vec3 a = glm::clamp(albedo, 0.0f, 1.0f);
  if (boost != 1.0f) a = glm::pow(a, vec3(1.0f / boost));
  return a;
}

vec3 positionOn(const Object& o, uint32_t triangle, vec2 bary) {
  const uvec3 tri = o.triangles[triangle];
  return (1.0f - bary.x - bary.y) * o.positions[tri.x] + bary.x * o.positions[tri.y] +
         bary.y * o.positions[tri.z];
}

}  // namespace

// What the path tracer needs of each material, evaluated once: flags, and the albedo and
// emission of untextured materials (the common case), which are then constants per hit.
struct Integrator::MaterialTable {
  struct Entry {
    vec3 albedo{0.0f};    // albedoAt's value (boost applied) when !albedoTextured
    vec3 emission{0.0f};  // emissionAt's value when !emissionTextured
    bool albedoTextured = false;
    bool emissionTextured = false;
    bool emissive = false;
    bool doubleSided = false;
    AlphaMode alphaMode = AlphaMode::Opaque;
  };
  std::vector<Entry> entries;
};

// Emissive triangles with their sampling distribution (by power) and the reverse map from
// (object, triangle) to table entry for MIS weights of BSDF-sampled hits.
struct Integrator::EmitterTable {
  struct Emitter {
    uint32_t object;
    uint32_t triangle;
    float area;  // m^2
    // Copies of what sampling needs, so that a light sample touches one record: the
    // vertices, Object::faceNormal, the material index.
    vec3 p0, p1, p2;
    vec3 normal;
    uint32_t material;
  };
  std::vector<Emitter> emitters;
  Distribution1D distribution;       // over emitters, weight = power
  std::vector<size_t> objectOffset;  // per object: its first entry in emitterOf
  std::vector<int32_t> emitterOf;    // per scene triangle: emitter index or -1

  int32_t find(uint32_t object, uint32_t triangle) const {
    if (emitterOf.empty()) return -1;
    return emitterOf[objectOffset[object] + triangle];
  }
};

Integrator::Integrator(const Scene& scene, const Tracer& tracer, IntegratorSettings settings)
    : scene_(scene), tracer_(tracer), settings_(std::move(settings)) {
  auto resolve = [&](std::vector<bool>& selection) {
    std::vector<bool> resolved(scene.lights.size());
    for (size_t i = 0; i < resolved.size(); ++i)
      resolved[i] = selection.empty() ? scene.lights[i].mode != LightMode::Realtime
                                      : i < selection.size() && selection[i];
    selection = std::move(resolved);
  };
  resolve(settings_.directLights);
  resolve(settings_.indirectLights);
  settings_.maxBounces = std::max(0, settings_.maxBounces);
  settings_.russianRouletteDepth = std::max(0, settings_.russianRouletteDepth);
  if (!(settings_.albedoBoost > 0.0f)) settings_.albedoBoost = 1.0f;

  auto table = std::make_shared<EmitterTable>();
  std::vector<float> power;
  for (uint32_t o = 0; o < scene.objects.size(); ++o) {
    const Object& object = scene.objects[o];
    // An object the tracer does not hold (a dynamic one, for a bake) emits into nothing.
    if (!tracer.contains(o)) continue;
    for (uint32_t t = 0; t < object.triangles.size(); ++t) {
      const Material& m = scene.materials[object.triangleMaterial[t]];
      if (!m.isEmissive()) continue;
      vec3 radiance = m.emissiveFactor * m.emissiveStrength;
      if (m.emissiveTexture >= 0 && size_t(m.emissiveTexture) < scene.textures.size())
        radiance *= vec3(scene.textures[m.emissiveTexture].average);
      const float area = object.triangleArea(t);
      // Power (up to the constant pi): area x radiance, both faces when double-sided.
      const float p = area * luminance(radiance) * (m.doubleSided ? 2.0f : 1.0f);
      if (!(p > 0.0f) || !(area > 0.0f)) continue;
      const uvec3 tri = object.triangles[t];
      table->emitters.push_back({o, t, area, object.positions[tri.x], object.positions[tri.y],
                                 object.positions[tri.z], object.faceNormal(t),
                                 object.triangleMaterial[t]});
      power.push_back(p);
    }
  }
  if (!table->emitters.empty()) {
    table->distribution = Distribution1D(std::move(power));
    table->objectOffset.resize(scene.objects.size());
    size_t total = 0;
    for (size_t o = 0; o < scene.objects.size(); ++o) {
      table->objectOffset[o] = total;
      total += scene.objects[o].triangles.size();
    }
    table->emitterOf.assign(total, -1);
    for (size_t i = 0; i < table->emitters.size(); ++i) {
      const auto& e = table->emitters[i];
      table->emitterOf[table->objectOffset[e.object] + e.triangle] = int32_t(i);
    }
  }
  auto materials = std::make_shared<MaterialTable>();
  materials->entries.resize(scene.materials.size());
  for (size_t i = 0; i < scene.materials.size(); ++i) {
    const Material& m = scene.materials[i];
    MaterialTable::Entry& e = materials->entries[i];
    e.albedoTextured = m.baseColorTexture >= 0;
    if (!e.albedoTextured)
      e.albedo = boostAlbedo(Scene::bounceAlbedo(m, vec3(m.baseColorFactor)), settings_.albedoBoost);
    e.emission = m.emissiveFactor * m.emissiveStrength;
    e.emissionTextured = m.emissiveTexture >= 0 && maxComponent(e.emission) > 0.0f;
    e.emissive = m.isEmissive();
    e.doubleSided = m.doubleSided;
    e.alphaMode = m.alphaMode;
  }
  materials_ = std::move(materials);

  sampleEmissive_ =
      settings_.includeEmissive && !table->emitters.empty() && table->distribution.total() > 0.0f;
  sampleSky_ = settings_.includeSky && !scene.sky.isBlack();
  emitters_ = std::move(table);
}

uint64_t Integrator::threadRayCount() { return tRayCount; }

// One shadow ray: rgb transmittance along origin + t direction, t in (0, tMax). BLEND
// surfaces attenuate (Tracer::transmittance) only when the scene has any, since a plain
// occlusion query is cheaper.
// `kind` is LightShadow for punctual lights' shadow rays (objects with castShadows false let
// them through).
vec3 Integrator::transmittance(vec3 origin, vec3 direction, float tMax, RayKind kind) const {
  ++tRayCount;
  Ray ray{origin, direction, 0.0f, tMax};
  if (tracer_.hasTranslucentSurfaces()) return tracer_.transmittance(ray, kind);
  return tracer_.occluded(ray, kind) ? vec3(0.0f) : vec3(1.0f);
}

// Mean transmittance from `origin` to light `light` over `rays` shadow rays. Hard shadows:
// one ray to the light's position (or along -direction). Soft shadows (intensity unchanged,
// visibility only, as Unity's baked soft shadows): point/spot rays go to points uniform on a
// disk of radius shadowRadius centred on the light and facing the origin; directional rays
// go uniformly over the cone of full angle shadowAngle around -direction. Ray r uses sample
// firstIndex + r of the stream keyed by (key, light) at `dimension`, so the rays of
// consecutive samples together form one stratified Sobol set. A light with bakedShadows
// false (and not realtime) is visible from everywhere: no ray. Shadow rays pass objects with
// castShadows false.
vec3 Integrator::visibilityTo(uint32_t light, vec3 origin, uint64_t key, uint32_t firstIndex,
                              uint32_t rays, uint32_t dimension) const {
  const Light& l = scene_.lights[light];
  if (!l.bakedShadows && l.mode != LightMode::Realtime && settings_.honourBakedShadows)
    return vec3(1.0f);
  constexpr RayKind kShadow = RayKind::LightShadow;
  const bool directional = l.type == LightType::Directional;
  if (!isSoft(l)) {
    if (directional) return transmittance(origin, -l.direction, kInfinity, kShadow);
    return transmittance(origin, l.position - origin, 1.0f - kShadowEpsilon, kShadow);
  }
  rays = std::max(1u, rays);
  const uint64_t streamKey = hashValues(key, kShadowTag, light);
  vec3 sum(0.0f);
  if (directional) {
    const float halfAngle = 0.5f * glm::radians(std::min(l.shadowAngle, 180.0f));
    const float cosMax = std::cos(halfAngle);
    const Frame frame = Frame::fromNormal(-l.direction);
    for (uint32_t r = 0; r < rays; ++r) {
      SampleStream stream(streamKey, firstIndex + r);
      stream.setDimension(2 * dimension);
      vec3 dir = frame.toWorld(squareToUniformCone(stream.get2D(), cosMax));
      sum += transmittance(origin, dir, kInfinity, kShadow);
    }
  } else {
    vec3 toOrigin = origin - l.position;
    float len = glm::length(toOrigin);
    const Frame frame = Frame::fromNormal(len > 0.0f ? toOrigin / len : vec3(0, 1, 0));
    for (uint32_t r = 0; r < rays; ++r) {
      SampleStream stream(streamKey, firstIndex + r);
      stream.setDimension(2 * dimension);
      vec2 d = l.shadowRadius * squareToConcentricDisk(stream.get2D());
      vec3 target = l.position + d.x * frame.t + d.y * frame.b;
      sum += transmittance(origin, target - origin, 1.0f - kShadowEpsilon, kShadow);
    }
  }
  return sum / float(rays);
}

// Punctual NEE at x (shading normal ns and geometric normal ng, both on the side light
// arrives from): sum over the selected lights of irradianceAt x cos x visibility. At the
// estimate's point (atOrigin) the lights of directLights count, each with its shadowSamples
// rays; at later vertices those of indirectLights, scaled by bounceIntensity, with one
// shadow ray each (the path average does the rest). `kind` restricts to hard- or
// soft-shadowed lights, so irradiance() can evaluate the noise-free hard ones once.
// `weightedDirection`, when given, gets sum luminance(term) x direction to the light added.
vec3 Integrator::punctualIrradiance(vec3 x, vec3 ns, vec3 ng, bool atOrigin, ShadowKind kind,
                                    uint64_t key, uint32_t sampleIndex, uint32_t vertex,
                                    vec3* weightedDirection) const {
  vec3 sum(0.0f);
  const bool bounced = !atOrigin || settings_.bounceView;  // the lights a bounce sees
  const auto& selection = bounced ? settings_.indirectLights : settings_.directLights;
  for (uint32_t i = 0; i < scene_.lights.size(); ++i) {
    if (!selection[i]) continue;
    const Light& l = scene_.lights[i];
    const bool soft = isSoft(l);
    if ((kind == ShadowKind::Hard && soft) || (kind == ShadowKind::Soft && !soft)) continue;
    const float scale = bounced ? l.bounceIntensity : 1.0f;
    if (!(scale > 0.0f)) continue;
    const vec3 e = l.irradianceAt(x);
    if (isBlack(e)) continue;
    const vec3 wi = l.directionTo(x);
    const float cosTheta = glm::dot(ns, wi);
    if (cosTheta <= 0.0f || glm::dot(ng, wi) <= 0.0f) continue;
    const uint32_t rays = atOrigin && soft ? uint32_t(std::max(1, l.shadowSamples)) : 1u;
    const vec3 vis = visibilityTo(i, offsetRayOrigin(x, ng), key, sampleIndex * rays, rays, vertex);
    const vec3 term = (scale * cosTheta) * e * vis;
    sum += term;
    if (weightedDirection) *weightedDirection += luminance(term) * wi;
  }
  return sum;
}

// Emitter NEE at x: one emissive triangle chosen by power, a point uniform on it. Returns
// the MIS-weighted estimate of the emitters' share of integral L cos dw (W/m^2), i.e.
// Le cos / pdf x w x visibility with pdf in solid angle = pmf / area x d^2 / |cos_light|.
// `direction`, when given, receives the sampled unit direction (when the result is not 0).
vec3 Integrator::sampleEmitters(vec3 x, vec3 ns, vec3 ng, float uSelect, vec2 uPoint,
                                vec3* direction) const {
  const EmitterTable& table = *emitters_;
  float pmf = 0.0f;
  const size_t index = table.distribution.sampleDiscrete(uSelect, &pmf);
  if (!(pmf > 0.0f)) return vec3(0.0f);
  const auto& e = table.emitters[index];
  const vec2 bary = squareToTriangle(uPoint);
  // Scene::positionAt's arithmetic on the copied vertices.
  const vec3 y = (1.0f - bary.x - bary.y) * e.p0 + bary.x * e.p1 + bary.y * e.p2;
  const vec3 d = y - x;
  const float dist2 = glm::dot(d, d);
  if (!(dist2 > 1e-12f)) return vec3(0.0f);
  const vec3 wi = d / std::sqrt(dist2);
  const float cosX = glm::dot(ns, wi);
  if (cosX <= 0.0f || glm::dot(ng, wi) <= 0.0f) return vec3(0.0f);
  const MaterialTable::Entry& m = materials_->entries[e.material];
  const vec3 nl = e.normal;
  float cosL = -glm::dot(nl, wi);  // > 0: x sees the front face
  if (cosL <= 0.0f && !m.doubleSided) return vec3(0.0f);
  cosL = std::abs(cosL);
  if (cosL < 1e-7f) return vec3(0.0f);
  if (m.alphaMode == AlphaMode::Mask &&
      scene_.baseColorAt(e.object, e.triangle, bary).a < scene_.materials[e.material].alphaCutoff)
    return vec3(0.0f);  // a cut-out hole emits nothing (the tracer lets rays through it)
  const vec3 le =
      m.emissionTextured ? scene_.emissionAt(e.object, e.triangle, bary) : m.emission;
  if (isBlack(le)) return vec3(0.0f);
  const float pdfLight = pmf / e.area * dist2 / cosL;
  const float weight = powerHeuristic(pdfLight, cosX * kInvPi);
  const vec3 origin = offsetRayOrigin(x, ng);
  const vec3 target = offsetRayOrigin(y, glm::dot(nl, wi) < 0.0f ? nl : -nl);
  const vec3 vis = transmittance(origin, target - origin, 1.0f - kShadowEpsilon);
  if (direction) *direction = wi;
  return le * (cosX * weight / pdfLight) * vis;
}

// Sky NEE at x: a direction from Sky::sample, MIS-weighted against cosine sampling.
vec3 Integrator::sampleSky(vec3 x, vec3 ns, vec3 ng, vec2 u, vec3* direction) const {
  const Sky::Sample s = scene_.sky.sample(u);
  if (!(s.pdf > 0.0f) || isBlack(s.radiance)) return vec3(0.0f);
  const float cosX = glm::dot(ns, s.direction);
  if (cosX <= 0.0f || glm::dot(ng, s.direction) <= 0.0f) return vec3(0.0f);
  const float weight = powerHeuristic(s.pdf, cosX * kInvPi);
  const vec3 vis = transmittance(offsetRayOrigin(x, ng), s.direction, kInfinity);
  if (direction) *direction = s.direction;
  return s.radiance * (cosX * weight / s.pdf) * vis;
}

// Solid-angle pdf with which emitter NEE would have chosen this point of this triangle.
float Integrator::emitterPdf(uint32_t object, uint32_t triangle, float distance2,
                             float cosLight) const {
  const int32_t i = emitters_->find(object, triangle);
  if (i < 0) return 0.0f;
  const float area = emitters_->emitters[size_t(i)].area;
  return emitters_->distribution.pmf(size_t(i)) / area * distance2 / std::max(cosLight, 1e-7f);
}

// The albedo a path bounces with (tracePath uses MaterialTable's constant when the material
// has no base colour texture; this is the same value).
vec3 Integrator::albedoAt(uint32_t object, uint32_t triangle, vec2 bary) const {
  return boostAlbedo(scene_.bounceAlbedoAt(object, triangle, bary), settings_.albedoBoost);
}

// Follows `ray` from a vertex (vertex 0) through path vertices 1, 2, ... and accumulates
// the radiance arriving back along it: emission found by the first segment goes to
// `direct`, everything else to `indirect`. bsdfPdf > 0 is the solid-angle pdf with which
// vertex 0 cosine-sampled the ray, and means vertex 0 ran emitter/sky NEE (so emission
// hit by this ray is MIS-weighted); bsdfPdf = 0 counts it fully.
// `backFaceHits`, when given, counts a first hit on the back of a single-sided, non-BLEND
// surface (the path started inside geometry).
bool Integrator::crossBlend(const Hit& h, SampleStream& stream, uint64_t key, uint32_t vertex,
                            uint32_t sampleIndex, Ray& ray, vec3& beta, int& passes,
                            bool* absorbed) const {
  // Pass straight through with probability 1 - alpha, tinted by the base colour, which
  // matches Tracer::transmittance's (1 - alpha) x baseColor in expectation.
  const vec4 base = scene_.baseColorAt(h.object, h.triangle, h.bary);
  const float u = passes == 0
                      ? draw1D(stream, vertex, kSlotBlend)
                      : SampleStream(hashValues(key, kBlendTag,
                                                uint64_t(vertex) * kMaxPassThroughs + passes),
                                     sampleIndex)
                            .get1D();
  if (u >= 1.0f - base.a) return false;
  beta *= vec3(base);
  if (++passes > kMaxPassThroughs || isBlack(beta)) {
    *absorbed = true;
    return false;
  }
  const vec3 y = positionOn(scene_.objects[h.object], h.triangle, h.bary);
  const vec3 ng = h.geometricNormal;
  ray.origin = offsetRayOrigin(y, glm::dot(ng, ray.direction) > 0.0f ? ng : -ng);
  ray.tMin = 0.0f;
  ray.tMax = kInfinity;
  return true;
}

void Integrator::tracePath(Ray ray, float bsdfPdf, uint64_t key, uint32_t sampleIndex, vec3& direct,
                           vec3& indirect, uint32_t* backFaceHits) const {
  SampleStream stream(key, sampleIndex);
  vec3 beta(1.0f);  // path throughput since vertex 0
  vec3 from = ray.origin;
  for (uint32_t vertex = 1;; ++vertex) {
    vec3& out = vertex == 1 ? direct : indirect;
    // Find the vertex, crossing the BLEND surfaces the path chooses to pass through.
    Hit h;
    bool hit = false;
    int passes = 0;
    for (;;) {
      ++tRayCount;
      hit = tracer_.intersect(ray, h);
      if (!hit) break;
      const Object& object = scene_.objects[h.object];
      const MaterialTable::Entry& m =
          materials_->entries[object.triangleMaterial[h.triangle]];
      if (settings_.includeEmissive && m.emissive && (!h.backFace || m.doubleSided)) {
        const vec3 le = m.emissionTextured
                            ? scene_.emissionAt(h.object, h.triangle, h.bary)
                            : m.emission;
        float weight = 1.0f;
        if (bsdfPdf > 0.0f && sampleEmissive_) {
          const vec3 y = positionOn(object, h.triangle, h.bary);
          const vec3 d = y - from;
          const float cosL = std::abs(glm::dot(h.geometricNormal, ray.direction));
          weight =
              powerHeuristic(bsdfPdf, emitterPdf(h.object, h.triangle, glm::dot(d, d), cosL));
        }
        out += beta * le * weight;
      }
      if (m.alphaMode != AlphaMode::Blend) break;
      bool absorbed = false;
      if (!crossBlend(h, stream, key, vertex, sampleIndex, ray, beta, passes, &absorbed)) {
        if (absorbed) return;
        break;  // reflect here
      }
    }
    if (!hit) {
      if (settings_.includeSky) {
        const vec3 dir = glm::normalize(ray.direction);
        const vec3 le = scene_.sky.radiance(dir);
        float weight = 1.0f;
        if (bsdfPdf > 0.0f && sampleSky_) weight = powerHeuristic(bsdfPdf, scene_.sky.pdf(dir));
        out += beta * le * weight;
      }
      return;
    }
    const Object& object = scene_.objects[h.object];
    const MaterialTable::Entry& m = materials_->entries[object.triangleMaterial[h.triangle]];
    if (vertex == 1 && backFaceHits && h.backFace && !m.doubleSided &&
        m.alphaMode != AlphaMode::Blend)
      ++*backFaceHits;
    // The back of a single-sided surface is the inside of geometry: it reflects nothing.
    if (h.backFace && !m.doubleSided) return;
    // Vertex maxBounces + 1 only completes the MIS of vertex maxBounces's emitter NEE.
    if (vertex > uint32_t(settings_.maxBounces)) return;

    const SurfaceFrame surface = surfaceAt(object, h.triangle, h.bary);
    const vec3 y = surface.position;
    const vec3 ng = h.backFace ? -h.geometricNormal : h.geometricNormal;
    vec3 ns = surface.shadingNormal;
    if (h.backFace) ns = -ns;
    if (glm::dot(ns, ng) <= 0.0f) ns = ng;  // a shading normal past the horizon: don't trust it
    beta *= m.albedoTextured ? albedoAt(h.object, h.triangle, h.bary) : m.albedo;
    if (isBlack(beta)) return;
    // Final gather: the first pass's light at the first hit (its front: a lightmap holds the
    // front's light) stands for everything the rest of the path would have found there.
    if (vertex == 1 && settings_.bounceCache && !h.backFace) {
      vec3 cached(0.0f);
      if (settings_.bounceCache->lookup(h.object, h.triangle, h.bary, cached)) {
        indirect += beta * cached;
        return;
      }
    }

    // NEE at this vertex: light reflected here has bounced at least once. Lambert's BRDF is
    // albedo / pi (albedo already in beta).
    vec3 e = punctualIrradiance(y, ns, ng, false, ShadowKind::Any, key, sampleIndex, vertex);
    if (sampleEmissive_)
      e += sampleEmitters(y, ns, ng, draw1D(stream, vertex, kSlotEmitterSelect),
                          draw2D(stream, vertex, kSlotEmitterPoint));
    if (sampleSky_) e += sampleSky(y, ns, ng, draw2D(stream, vertex, kSlotSky));
    indirect += beta * kInvPi * e;

    if (vertex >= uint32_t(settings_.russianRouletteDepth)) {
      const float survive = std::min(kRouletteCap, maxComponent(beta));
      if (draw1D(stream, vertex, kSlotRoulette) >= survive) return;
      beta /= survive;
    }
    // Cosine sampling: f cos / pdf = albedo, already in beta.
    const vec3 local = squareToCosineHemisphere(draw2D(stream, vertex, kSlotBsdf));
    const vec3 wi = Frame::fromNormal(ns).toWorld(local);
    bsdfPdf = cosineHemispherePdf(local.z);
    if (!(bsdfPdf > 0.0f) || glm::dot(wi, ng) <= 0.0f) return;
    from = y;
    ray = Ray{offsetRayOrigin(y, ng), wi, 0.0f, kInfinity};
  }
}

bool Integrator::firstRaysSeeBackFaces(vec3 p, vec3 n, uint64_t key, uint32_t firstSample,
                                       uint32_t sampleCount, float share) const {
  const float limit = share * float(sampleCount);
  if (sampleCount == 0) return 0.0f > limit;
  n = glm::normalize(n);
  const Frame frame = Frame::fromNormal(n);
  const vec3 origin = offsetRayOrigin(p, n);
  uint32_t count = 0;
  for (uint32_t s = firstSample; s < firstSample + sampleCount; ++s) {
    // Decided: already above the limit, or not above it even if every ray left were counted.
    if (float(count) > limit) return true;
    if (!(float(count + (firstSample + sampleCount - s)) > limit)) return false;
    SampleStream stream(key, s);
    const vec3 local = squareToCosineHemisphere(draw2D(stream, 0, kSlotBsdf));
    if (!(cosineHemispherePdf(local.z) > 0.0f)) continue;
    // tracePath's first vertex (vertex 1), BLEND pass-throughs included, without its light.
    Ray ray{origin, frame.toWorld(local), 0.0f, kInfinity};
    vec3 beta(1.0f);
    Hit h;
    bool hit = false, absorbed = false;
    int passes = 0;
    for (;;) {
      ++tRayCount;
      hit = tracer_.intersect(ray, h);
      if (!hit) break;
      const Object& object = scene_.objects[h.object];
      const MaterialTable::Entry& m = materials_->entries[object.triangleMaterial[h.triangle]];
      if (m.alphaMode != AlphaMode::Blend) break;
      // Reflecting on a BLEND surface: not counted below.
      if (!crossBlend(h, stream, key, 1, s, ray, beta, passes, &absorbed)) break;
    }
    if (!hit || absorbed) continue;
    const MaterialTable::Entry& m =
        materials_->entries[scene_.objects[h.object].triangleMaterial[h.triangle]];
    if (h.backFace && !m.doubleSided && m.alphaMode != AlphaMode::Blend) ++count;
  }
  return float(count) > limit;
}

LightingEstimate Integrator::irradiance(vec3 p, vec3 n, uint64_t key, uint32_t firstSample,
                                        uint32_t sampleCount, uint32_t* backFaceHits,
                                        vec3* weightedDirection) const {
  LightingEstimate estimate;
  if (sampleCount == 0) return estimate;
  n = glm::normalize(n);
  const Frame frame = Frame::fromNormal(n);
  const vec3 origin = offsetRayOrigin(p, n);
  // Hard-shadowed punctual lights give the same value for every sample: evaluate once.
  vec3 hardDirection(0.0f);
  const vec3 hard = punctualIrradiance(p, n, n, true, ShadowKind::Hard, key, 0, 0,
                                       weightedDirection ? &hardDirection : nullptr);
  glm::dvec3 sumDirect(0.0), sumIndirect(0.0), sumDirection(0.0);
  for (uint32_t s = firstSample; s < firstSample + sampleCount; ++s) {
    SampleStream stream(key, s);
    // Luminance-weighted directions of this sample's terms (only when asked for).
    vec3 dirSum(0.0f);
    vec3* dirOut = weightedDirection ? &dirSum : nullptr;
    vec3 direct = punctualIrradiance(p, n, n, true, ShadowKind::Soft, key, s, 0, dirOut);
    if (sampleEmissive_) {
      vec3 wi(0.0f);
      const vec3 e = sampleEmitters(p, n, n, draw1D(stream, 0, kSlotEmitterSelect),
                                    draw2D(stream, 0, kSlotEmitterPoint), &wi);
      direct += e;
      dirSum += luminance(e) * wi;
    }
    if (sampleSky_) {
      vec3 wi(0.0f);
      const vec3 e = sampleSky(p, n, n, draw2D(stream, 0, kSlotSky), &wi);
      direct += e;
      dirSum += luminance(e) * wi;
    }
    vec3 indirect(0.0f);
    const vec3 local = squareToCosineHemisphere(draw2D(stream, 0, kSlotBsdf));
    const float pdf = cosineHemispherePdf(local.z);
    if (pdf > 0.0f) {
      vec3 ld(0.0f), li(0.0f);
      const vec3 wi = frame.toWorld(local);
      tracePath(Ray{origin, wi, 0.0f, kInfinity}, pdf, key, s, ld, li, backFaceHits);
      // L cos / pdf with pdf = cos / pi.
      direct += kPi * ld;
      indirect += kPi * li;
      dirSum += (luminance(kPi * ld) + luminance(kPi * li) * settings_.indirectIntensity) * wi;
    }
    // A rare NaN/Inf (degenerate geometry) must not poison a texel: drop the sample.
    if (isFinite(direct) && isFinite(indirect) && isFinite(dirSum)) {
      sumDirect += glm::dvec3(direct);
      sumIndirect += glm::dvec3(indirect);
      sumDirection += glm::dvec3(dirSum);
    }
  }
  estimate.direct = hard + vec3(sumDirect / double(sampleCount));
  estimate.indirect = vec3(sumIndirect / double(sampleCount)) * settings_.indirectIntensity;
  if (weightedDirection)
    *weightedDirection += hardDirection + vec3(sumDirection / double(sampleCount));
  return estimate;
}

LightingEstimate Integrator::incomingRadiance(vec3 p, vec3 dir, uint64_t key,
                                              uint32_t sampleIndex) const {
  vec3 direct(0.0f), indirect(0.0f);
  tracePath(Ray{p, glm::normalize(dir), 0.0f, kInfinity}, 0.0f, key, sampleIndex, direct, indirect);
  LightingEstimate estimate;
  if (isFinite(direct) && isFinite(indirect)) {
    estimate.direct = direct;
    estimate.indirect = indirect * settings_.indirectIntensity;
  }
  return estimate;
}

void Integrator::punctualLights(vec3 p, uint64_t key, uint32_t sampleIndex,
                                std::vector<DeltaLight>& out) const {
  for (uint32_t i = 0; i < scene_.lights.size(); ++i) {
    if (!settings_.directLights[i]) continue;
    const Light& l = scene_.lights[i];
    DeltaLight delta;
    delta.light = i;
    delta.direction = l.directionTo(p);
    const vec3 e = l.irradianceAt(p);
    if (!isBlack(e)) {
      const uint32_t rays = isSoft(l) ? uint32_t(std::max(1, l.shadowSamples)) : 1u;
      delta.irradiance = e * visibilityTo(i, p, key, sampleIndex * rays, rays, 0);
    }
    out.push_back(delta);
  }
}

vec3 Integrator::lightVisibility(vec3 p, vec3 n, uint32_t light, uint64_t key,
                                 uint32_t sampleIndex) const {
  const Light& l = scene_.lights[light];
  const vec3 origin = glm::dot(n, n) > 0.0f ? offsetRayOrigin(p, glm::normalize(n)) : p;
  const uint32_t rays = isSoft(l) ? uint32_t(std::max(1, l.shadowSamples)) : 1u;
  return visibilityTo(light, origin, key, sampleIndex * rays, rays, 0);
}

}  // namespace kiln
