// tracer.cpp: the Embree 3 scene behind kiln::Tracer (geometry upload, alpha-mask and BLEND
// filters, closest-hit / any-hit / transmittance / nearest-surface queries, ray capture).
#include "src/tracer.h"

#include <embree3/rtcore.h>

#include <atomic>
#include <cmath>
#include <limits>
#include <mutex>
#include <string>
#include <vector>

namespace kiln {
namespace {

// Per-geometry data the filter function needs; lives in Tracer::Impl so that its address is
// stable for the lifetime of the Embree scene.
struct GeometryData {
  const Scene* scene = nullptr;
  uint32_t object = 0;
  bool castsShadows = true;  // Object::settings.castShadows
};

// The context of every closest-hit query: Embree hands it to the intersection filter, which
// with lightShadow set lets rays pass objects that cast no shadows (the transmittance walk
// of a punctual light's shadow ray).
struct IntersectContext {
  RTCIntersectContext base;  // first member: Embree's pointer to it is a pointer to this
  bool lightShadow = false;
};

// The context of every occlusion query: Embree hands it to the occlusion filter, which
// with opaqueOnly set lets rays pass BLEND surfaces (noting that one was there) instead of
// stopping at them, so that transmittance() needs no closest-hit walk for the segments an
// opaque surface blocks.
// lightShadow lets rays pass objects that cast no shadows, as above.
struct OcclusionContext {
  RTCIntersectContext base;  // first member: Embree's pointer to it is a pointer to this
  bool opaqueOnly = false;
  bool sawBlend = false;
  bool lightShadow = false;
};

// A hit on a MASK triangle whose alpha (base colour factor x texture at UV0) is below the
// material's cutoff: no surface for any query.
bool cutOut(const Scene& scene, uint32_t object, uint32_t prim, vec2 bary) {
  const Material& m = scene.materials[scene.objects[object].triangleMaterial[prim]];
  if (m.alphaMode != AlphaMode::Mask) return false;
  const float alpha =
      m.baseColorTexture < 0 ? m.baseColorFactor.a : scene.baseColorAt(object, prim, bary).a;
  return alpha < m.alphaCutoff;
}

// The intersection filter: rejects cut-out hits. The occlusion filter below rejects the same
// ones: both must agree, or a shadow ray and a closest-hit ray would disagree about the same
// surface. Both are stateless per hit (the sawBlend flag only ever turns on), so being called
// more than once for one primitive is harmless.
void intersectFilter(const RTCFilterFunctionNArguments* args) {
  const auto* data = static_cast<const GeometryData*>(args->geometryUserPtr);
  const auto* context = reinterpret_cast<const IntersectContext*>(args->context);
  for (unsigned int i = 0; i < args->N; ++i) {
    if (args->valid[i] == 0) continue;  // inactive lane: its hit data is undefined
    if (context->lightShadow && !data->castsShadows) {
      args->valid[i] = 0;
      continue;
    }
    const uint32_t prim = RTCHitN_primID(args->hit, args->N, i);
    const vec2 bary(RTCHitN_u(args->hit, args->N, i), RTCHitN_v(args->hit, args->N, i));
    if (cutOut(*data->scene, data->object, prim, bary)) args->valid[i] = 0;
  }
}

void occlusionFilter(const RTCFilterFunctionNArguments* args) {
  const auto* data = static_cast<const GeometryData*>(args->geometryUserPtr);
  auto* context = reinterpret_cast<OcclusionContext*>(args->context);
  const Scene& scene = *data->scene;
  for (unsigned int i = 0; i < args->N; ++i) {
    if (args->valid[i] == 0) continue;
    if (context->lightShadow && !data->castsShadows) {
      args->valid[i] = 0;
      continue;
    }
    const uint32_t prim = RTCHitN_primID(args->hit, args->N, i);
    const vec2 bary(RTCHitN_u(args->hit, args->N, i), RTCHitN_v(args->hit, args->N, i));
    if (cutOut(scene, data->object, prim, bary)) {
      args->valid[i] = 0;
    } else if (context->opaqueOnly &&
               scene.materials[scene.objects[data->object].triangleMaterial[prim]].alphaMode ==
                   AlphaMode::Blend) {
      context->sawBlend = true;
      args->valid[i] = 0;
    }
  }
}

// Whether any triangle of `object` can be cut out, i.e. needs the filters at all.
bool mayBeCutOut(const Scene& scene, const Object& object) {
  for (uint32_t mi : object.triangleMaterial) {
    const Material& m = scene.materials[mi];
    if (m.alphaMode != AlphaMode::Mask) continue;
    if (m.baseColorTexture >= 0 || m.baseColorFactor.a < m.alphaCutoff) return true;
  }
  return false;
}

bool hasBlendTriangles(const Scene& scene, const Object& object) {
  for (uint32_t mi : object.triangleMaterial)
    if (scene.materials[mi].alphaMode == AlphaMode::Blend) return true;
  return false;
}

RTCRay makeRay(const Ray& ray) {
  RTCRay r;
  r.org_x = ray.origin.x;
  r.org_y = ray.origin.y;
  r.org_z = ray.origin.z;
  r.dir_x = ray.direction.x;
  r.dir_y = ray.direction.y;
  r.dir_z = ray.direction.z;
  r.tnear = ray.tMin;
  r.tfar = ray.tMax;
  r.time = 0.0f;
  r.mask = 0xFFFFFFFFu;
  r.id = 0;
  r.flags = 0;
  return r;
}

RTCRayHit makeRayHit(const Ray& ray) {
  RTCRayHit rh;
  rh.ray = makeRay(ray);
  rh.hit.geomID = RTC_INVALID_GEOMETRY_ID;
  rh.hit.primID = RTC_INVALID_GEOMETRY_ID;
  rh.hit.instID[0] = RTC_INVALID_GEOMETRY_ID;
  return rh;
}

const char* errorName(RTCError code) {
  switch (code) {
    case RTC_ERROR_NONE: return "no error";
    case RTC_ERROR_UNKNOWN: return "unknown error";
    case RTC_ERROR_INVALID_ARGUMENT: return "invalid argument";
    case RTC_ERROR_INVALID_OPERATION: return "invalid operation";
    case RTC_ERROR_OUT_OF_MEMORY: return "out of memory";
    case RTC_ERROR_UNSUPPORTED_CPU: return "unsupported CPU";
    case RTC_ERROR_CANCELLED: return "cancelled";
  }
  return "unknown error";
}

// Transmittance walk limits: a ray never crosses more BLEND surfaces than this (a guard
// against pathological stacks, not a quality setting).
constexpr int kMaxBlendCrossings = 256;
// After a BLEND hit at t the walk restarts at t * (1 + kRelativeStep): far enough to skip the
// same surface when the ray crosses a shared edge and both triangles report it (their t
// differ by a few ulps), near enough not to skip a distinct surface in practice.
constexpr float kRelativeStep = 1e-5f;

std::atomic<std::vector<Tracer::CapturedRay>*> gCapture{nullptr};
std::mutex gCaptureMutex;

[[gnu::noinline]] void appendCaptured(const Ray& ray, bool closestHit) {
  std::lock_guard<std::mutex> lock(gCaptureMutex);
  if (std::vector<Tracer::CapturedRay>* log = gCapture.load(std::memory_order_relaxed))
    log->push_back({ray, closestHit});
}

inline void capture(const Ray& ray, bool closestHit) {
  if (gCapture.load(std::memory_order_relaxed) != nullptr) [[unlikely]]
    appendCaptured(ray, closestHit);
}

}  // namespace

void Tracer::captureRays(std::vector<CapturedRay>* log) {
  std::lock_guard<std::mutex> lock(gCaptureMutex);
  gCapture.store(log, std::memory_order_relaxed);
}

struct Tracer::Impl {
  RTCDevice device = nullptr;
  RTCScene rtcScene = nullptr;
  std::vector<GeometryData> geometryData;  // indexed by object (= geometry ID)
  // Unit front-side normals of all triangles, object after object: normals[firstTriangle[o]
  // + t]. Precomputed so that a hit costs one load instead of a walk through the Object.
  std::vector<uint32_t> firstTriangle;
  std::vector<vec3> normals;

  // Embree reports errors through this callback, possibly from its build threads.
  std::mutex errorMutex;
  std::string firstError;

  static void onError(void* user, RTCError code, const char* message) {
    auto* impl = static_cast<Impl*>(user);
    std::lock_guard<std::mutex> lock(impl->errorMutex);
    if (!impl->firstError.empty()) return;
    impl->firstError = std::string("Embree: ") + errorName(code) + (message ? ": " : "") +
                       (message ? message : "");
  }
  std::string takeError() {
    std::lock_guard<std::mutex> lock(errorMutex);
    return firstError;
  }

  ~Impl() {
    if (rtcScene) rtcReleaseScene(rtcScene);
    if (device) rtcReleaseDevice(device);
  }
};

Tracer::Tracer(const Scene& scene) : scene_(scene), impl_(std::make_unique<Impl>()) {}
Tracer::~Tracer() = default;

Result<std::unique_ptr<Tracer>> Tracer::create(const Scene& scene, TracerGeometry geometry) {
  const std::string where = scene.path.empty() ? std::string("scene") : scene.path;

  // Validate what the filter function and the buffers index, so that a malformed scene is an
  // Error here and never an out-of-bounds read inside Embree.
  for (size_t o = 0; o < scene.objects.size(); ++o) {
    const Object& obj = scene.objects[o];
    if (obj.triangleMaterial.size() != obj.triangles.size())
      return Error{where + ": object " + std::to_string(o) + " (" + obj.name +
                   "): triangleMaterial has " + std::to_string(obj.triangleMaterial.size()) +
                   " entries for " + std::to_string(obj.triangles.size()) + " triangles"};
    for (size_t t = 0; t < obj.triangles.size(); ++t) {
      uvec3 tri = obj.triangles[t];
      if (tri.x >= obj.positions.size() || tri.y >= obj.positions.size() ||
          tri.z >= obj.positions.size())
        return Error{where + ": object " + std::to_string(o) + " (" + obj.name +
                     "): triangle " + std::to_string(t) + " indexes past its " +
                     std::to_string(obj.positions.size()) + " vertices"};
      if (obj.triangleMaterial[t] >= scene.materials.size())
        return Error{where + ": object " + std::to_string(o) + " (" + obj.name +
                     "): triangle " + std::to_string(t) + " uses material " +
                     std::to_string(obj.triangleMaterial[t]) + " of " +
                     std::to_string(scene.materials.size())};
    }
  }

  std::unique_ptr<Tracer> tracer(new Tracer(scene));
  Impl& impl = *tracer->impl_;
  tracer->geometry_ = geometry;
  tracer->contains_.resize(scene.objects.size());
  for (size_t o = 0; o < scene.objects.size(); ++o)
    tracer->contains_[o] = !scene.objects[o].triangles.empty() &&
                           (geometry == TracerGeometry::All || scene.objects[o].settings.isStatic);

  impl.device = rtcNewDevice(nullptr);
  if (!impl.device)
    return Error{std::string("Embree: cannot create a device: ") +
                 errorName(rtcGetDeviceError(nullptr))};
  rtcSetDeviceErrorFunction(impl.device, &Impl::onError, &impl);

  // kiln's surfaces are two-sided and MASK needs filters: refuse an Embree built otherwise
  // rather than silently returning wrong visibility.
  if (rtcGetDeviceProperty(impl.device, RTC_DEVICE_PROPERTY_BACKFACE_CULLING_ENABLED) != 0)
    return Error{"Embree: this build culls back faces; kiln needs two-sided triangles"};
  if (rtcGetDeviceProperty(impl.device, RTC_DEVICE_PROPERTY_FILTER_FUNCTION_SUPPORTED) == 0)
    return Error{"Embree: this build does not support filter functions (alpha cut-outs)"};

  impl.rtcScene = rtcNewScene(impl.device);
  // ROBUST: watertight traversal (no rays escaping through shared edges of closed meshes).
  // MEDIUM quality: HIGH enables spatial splits, which may run filter callbacks more than
  // once for one primitive.
  rtcSetSceneFlags(impl.rtcScene, RTC_SCENE_FLAG_ROBUST);
  rtcSetSceneBuildQuality(impl.rtcScene, RTC_BUILD_QUALITY_MEDIUM);

  impl.geometryData.resize(scene.objects.size());
  impl.firstTriangle.resize(scene.objects.size());
  size_t triangleCount = 0;
  for (const Object& obj : scene.objects) triangleCount += obj.triangles.size();
  if (triangleCount > std::numeric_limits<uint32_t>::max())
    return Error{where + ": more than 2^32 triangles"};
  impl.normals.reserve(triangleCount);
  for (uint32_t o = 0; o < scene.objects.size(); ++o) {
    const Object& obj = scene.objects[o];
    impl.firstTriangle[o] = uint32_t(impl.normals.size());
    for (uvec3 tri : obj.triangles) {
      // In double, so that slivers whose float cross product would underflow still get a
      // direction. A triangle without area cannot be hit; it gets zero.
      glm::dvec3 p0(obj.positions[tri.x]);
      glm::dvec3 n = glm::cross(glm::dvec3(obj.positions[tri.y]) - p0,
                                glm::dvec3(obj.positions[tri.z]) - p0);
      double len = glm::length(n);
      impl.normals.push_back(len > 0.0 ? vec3(n / len) : vec3(0.0f));
    }
  }
  for (uint32_t o = 0; o < scene.objects.size(); ++o) {
    const Object& obj = scene.objects[o];
    impl.geometryData[o] = GeometryData{&scene, o, obj.settings.castShadows};
    // Objects without triangles, and those `geometry` leaves out, get no geometry; IDs stay
    // equal to object indices because geometries are attached by ID (Embree allows gaps).
    // Leaving a dynamic object out of the BVH (rather than filtering its hits) makes a bake
    // with it the same computation as one without it: the same BVH over the same triangles.
    if (!tracer->contains_[o]) continue;

    RTCGeometry geom = rtcNewGeometry(impl.device, RTC_GEOMETRY_TYPE_TRIANGLE);
    // Embree over-allocates buffers it creates so that the last vertex can be read with a
    // 16-byte load; kiln's tightly packed vec3 array could not be shared for that reason.
    auto* vertices = static_cast<float*>(rtcSetNewGeometryBuffer(
        geom, RTC_BUFFER_TYPE_VERTEX, 0, RTC_FORMAT_FLOAT3, 3 * sizeof(float),
        obj.positions.size()));
    auto* indices = static_cast<uint32_t*>(rtcSetNewGeometryBuffer(
        geom, RTC_BUFFER_TYPE_INDEX, 0, RTC_FORMAT_UINT3, 3 * sizeof(uint32_t),
        obj.triangles.size()));
    if (!vertices || !indices) {
      rtcReleaseGeometry(geom);
      std::string e = impl.takeError();
      return Error{e.empty() ? "Embree: cannot allocate geometry buffers" : e};
    }
    for (size_t i = 0; i < obj.positions.size(); ++i) {
      vertices[3 * i + 0] = obj.positions[i].x;
      vertices[3 * i + 1] = obj.positions[i].y;
      vertices[3 * i + 2] = obj.positions[i].z;
    }
    for (size_t i = 0; i < obj.triangles.size(); ++i) {
      indices[3 * i + 0] = obj.triangles[i].x;
      indices[3 * i + 1] = obj.triangles[i].y;
      indices[3 * i + 2] = obj.triangles[i].z;
    }
    const bool cutouts = mayBeCutOut(scene, obj), blend = hasBlendTriangles(scene, obj);
    const bool noShadows = !obj.settings.castShadows;
    if (cutouts || blend || noShadows) rtcSetGeometryUserData(geom, &impl.geometryData[o]);
    if (cutouts || noShadows) rtcSetGeometryIntersectFilterFunction(geom, &intersectFilter);
    if (cutouts || blend || noShadows) rtcSetGeometryOccludedFilterFunction(geom, &occlusionFilter);
    rtcCommitGeometry(geom);
    rtcAttachGeometryByID(impl.rtcScene, geom, o);
    rtcReleaseGeometry(geom);  // the scene holds its own reference
  }
  rtcCommitScene(impl.rtcScene);
  if (std::string e = impl.takeError(); !e.empty()) return Error{where + ": " + e};

  // Only materials some triangle uses count: an unused BLEND material must not cost every
  // shadow ray the slow transmittance walk.
  for (uint32_t o = 0; o < scene.objects.size(); ++o)
    if (tracer->contains_[o]) tracer->hasBlend_ |= hasBlendTriangles(scene, scene.objects[o]);
  return tracer;
}

std::optional<Hit> Tracer::intersect(const Ray& ray) const {
  Hit hit;
  if (!intersect(ray, hit)) return std::nullopt;
  return hit;
}

bool Tracer::intersect(const Ray& ray, Hit& hit) const {
  return intersectQuery(ray, hit, RayKind::Any);
}

bool Tracer::intersectQuery(const Ray& ray, Hit& hit, RayKind kind) const {
  IntersectContext context;
  rtcInitIntersectContext(&context.base);
  context.lightShadow = kind == RayKind::LightShadow;
  RTCRayHit rh = makeRayHit(ray);
  capture(ray, true);
  rtcIntersect1(impl_->rtcScene, &context.base, &rh);
  if (rh.hit.geomID == RTC_INVALID_GEOMETRY_ID) return false;

  hit.t = rh.ray.tfar;
  hit.object = rh.hit.geomID;
  hit.triangle = rh.hit.primID;
  hit.bary = vec2(rh.hit.u, rh.hit.v);
  // The normal from kiln's own positions (precomputed), so that its orientation follows
  // kiln's CCW convention rather than Embree's.
  vec3 n = impl_->normals[impl_->firstTriangle[hit.object] + hit.triangle];
  if (n == vec3(0.0f)) n = -glm::normalize(ray.direction);  // no area: cannot be hit
  hit.geometricNormal = n;
  hit.backFace = glm::dot(ray.direction, n) > 0.0f;
  return true;
}

namespace {
// rtcOccluded1 over (tMin, tMax); false for an empty range, which Embree would leave
// untouched and whose negative tMax must not be mistaken for its "occluded" mark.
bool occludedQuery(RTCScene scene, const Ray& ray, OcclusionContext& context) {
  if (!(ray.tMin <= ray.tMax)) return false;
  rtcInitIntersectContext(&context.base);
  RTCRay r = makeRay(ray);
  capture(ray, false);
  rtcOccluded1(scene, &context.base, &r);
  // Embree marks an occluded ray by setting tfar to -infinity.
  return r.tfar < 0.0f && std::isinf(r.tfar);
}
}  // namespace

bool Tracer::occluded(const Ray& ray, RayKind kind) const {
  OcclusionContext context;
  context.lightShadow = kind == RayKind::LightShadow;
  return occludedQuery(impl_->rtcScene, ray, context);
}

vec3 Tracer::transmittance(const Ray& ray, RayKind kind) const {
  if (!hasBlend_) return occluded(ray, kind) ? vec3(0.0f) : vec3(1.0f);
  // One any-hit query that passes BLEND surfaces: an opaque surface anywhere on the segment
  // makes it 0 whatever it crosses first; a segment that met no BLEND surface is clear.
  OcclusionContext context;
  context.opaqueOnly = true;
  context.lightShadow = kind == RayKind::LightShadow;
  if (occludedQuery(impl_->rtcScene, ray, context)) return vec3(0.0f);
  if (!context.sawBlend) return vec3(1.0f);

  // Only BLEND surfaces in the way: walk their closest hits front to back, each filtering
  // the light. The origin and direction stay fixed and only tMin moves, so Embree recomputes
  // the same t for a surface already crossed and the step below skips it.
  vec3 result(1.0f);
  Ray segment = ray;
  for (int i = 0; i < kMaxBlendCrossings; ++i) {
    Hit h;
    if (!intersectQuery(segment, h, kind)) return result;
    const Hit* hit = &h;
    const Material& m = scene_.materialOf(hit->object, hit->triangle);
    if (m.alphaMode != AlphaMode::Blend) return vec3(0.0f);  // at the segment's very end
    vec4 base = scene_.baseColorAt(hit->object, hit->triangle, hit->bary);
    result *= (1.0f - glm::clamp(base.a, 0.0f, 1.0f)) * glm::max(vec3(base), vec3(0.0f));
    if (maxComponent(result) <= 0.0f) return vec3(0.0f);
    float t = hit->t;
    segment.tMin = std::max(std::nextafter(t, kInfinity), t + std::abs(t) * kRelativeStep);
    if (!(segment.tMin < segment.tMax)) return result;
  }
  return result;  // more crossings than the cap: what is left is negligible in practice
}

namespace {

struct NearestQuery {
  const Scene* scene;
  vec3 p;
  Tracer::NearestSurface best;
  bool found = false;
};

// Called by rtcPointQuery for every triangle whose bounds meet the query sphere; shrinking the
// radius (and returning true) prunes the rest of the traversal.
bool nearestTriangle(RTCPointQueryFunctionArguments* args) {
  auto* q = static_cast<NearestQuery*>(args->userPtr);
  const Object& o = q->scene->objects[args->geomID];
  const uvec3 t = o.triangles[args->primID];
  const vec3 x = closestPointOnTriangle(q->p, o.positions[t.x], o.positions[t.y], o.positions[t.z]);
  const float d = glm::length(x - q->p);
  if (!(d < args->query->radius)) return false;
  args->query->radius = d;
  q->best = {d, x, args->geomID, args->primID};
  q->found = true;
  return true;
}

}  // namespace

std::optional<Tracer::NearestSurface> Tracer::nearestSurface(vec3 p, float maxDistance) const {
  RTCPointQuery query;
  query.x = p.x;
  query.y = p.y;
  query.z = p.z;
  query.time = 0.0f;
  query.radius = maxDistance;
  RTCPointQueryContext context;
  rtcInitPointQueryContext(&context);
  NearestQuery nearest{&scene_, p, {}, false};
  rtcPointQuery(impl_->rtcScene, &query, &context, &nearestTriangle, &nearest);
  if (!nearest.found) return std::nullopt;
  return nearest.best;
}

}  // namespace kiln
