// tracer.h: ray queries against a Scene through Embree 3.
//
// The Embree scene is built once (one triangle geometry per Object, geometry ID = object
// index) and is immutable afterwards; every query is const and thread-safe.
// Materials act on rays as follows:
//   - alphaMode MASK: a hit where baseColor alpha (factor x texture at UV0) < alphaCutoff is
//     ignored by every query (Embree intersection and occlusion filter functions);
//   - alphaMode BLEND: a surface for intersect() and occluded(); transmittance() lets light
//     through it, multiplied by (1 - alpha) x baseColor.rgb (coloured transparency, as
//     Beast's RGB transparency did);
//   - everything else is an opaque surface, both faces.
// Which objects the Embree scene holds (TracerGeometry): a Tracer for baking holds only the
// static objects (Unity's rule: only static objects contribute to baked GI; dynamic ones are
// lit by the probes), so a dynamic object casts no baked shadow, bounces and emits nothing
// into lightmaps or probes and does not move or invalidate probes; the preview renderer
// builds one over every object. Objects with castShadows false are held but let the shadow
// rays of punctual lights through (RayKind::LightShadow).
#pragma once

#include <memory>
#include <optional>
#include <vector>

#include "src/math.h"
#include "kiln/result.h"
#include "src/scene.h"

namespace kiln {

struct Ray {
  vec3 origin;
  vec3 direction;  // need not be unit length; t is in units of |direction|
  float tMin = 0.0f;
  float tMax = kInfinity;
};

struct Hit {
  float t = 0.0f;
  uint32_t object = 0;    // index into Scene::objects
  uint32_t triangle = 0;  // index into Object::triangles
  vec2 bary{0.0f};        // (b1, b2): p = (1-b1-b2) p0 + b1 p1 + b2 p2
  vec3 geometricNormal{0.0f};  // unit, the triangle's front side (CCW)
  bool backFace = false;       // the ray arrived at the back side: dot(direction, Ng) > 0
};

// The objects a Tracer's Embree scene holds.
enum class TracerGeometry {
  BakedGI,  // static objects only (Object::settings.isStatic): every bake's view of the scene
  All,      // every object: what a camera sees (the preview renderer)
};

// What a query is for, where it matters: the shadow rays of punctual lights pass through
// objects with castShadows false; every other query sees them.
enum class RayKind { Any, LightShadow };

class Tracer {
 public:
  // Builds the acceleration structure over the objects `geometry` selects. `scene` must
  // outlive the Tracer. Hit::object stays the index into Scene::objects either way.
  static Result<std::unique_ptr<Tracer>> create(const Scene& scene,
                                                TracerGeometry geometry = TracerGeometry::BakedGI);
  ~Tracer();
  Tracer(const Tracer&) = delete;
  Tracer& operator=(const Tracer&) = delete;

  // Closest hit in (tMin, tMax), or nothing.
  std::optional<Hit> intersect(const Ray& ray) const;
  // The same query writing into `hit`: true (and `hit` filled) when there is a hit, false
  // (and `hit` unchanged) otherwise. Saves the optional's copy on hot paths.
  bool intersect(const Ray& ray, Hit& hit) const;
  // True when anything (including BLEND surfaces) lies in (tMin, tMax).
  bool occluded(const Ray& ray, RayKind kind = RayKind::Any) const;
  // Fraction of light that passes along the segment: 0 when an opaque surface lies in
  // (tMin, tMax), else the product over the BLEND surfaces crossed.
  vec3 transmittance(const Ray& ray, RayKind kind = RayKind::Any) const;

  // Over the objects held only.
  bool hasTranslucentSurfaces() const { return hasBlend_; }
  // Whether Scene::objects[object] is in the Embree scene (can be hit at all).
  bool contains(uint32_t object) const {
    return object < contains_.size() && contains_[object];
  }
  TracerGeometry geometry() const { return geometry_; }

  // The surface point nearest to p within maxDistance (Embree's BVH point query, exact
  // point-triangle distances), over every triangle: cut-out and BLEND ones count as surfaces.
  struct NearestSurface {
    float distance = kInfinity;
    vec3 point{0.0f};
    uint32_t object = 0;
    uint32_t triangle = 0;
  };
  std::optional<NearestSurface> nearestSurface(vec3 p, float maxDistance = kInfinity) const;

  // Ray capture, for benchmarks that time raw Embree on exactly the rays a bake traced:
  // while a log is set, every Embree query of every Tracer (from any thread, serialized by a
  // mutex) appends its ray to it. Off (nullptr) by default, and then one relaxed load.
  struct CapturedRay {
    Ray ray;
    bool closestHit = false;  // rtcIntersect1; else rtcOccluded1
  };
  static void captureRays(std::vector<CapturedRay>* log);

  const Scene& scene() const { return scene_; }

 private:
  explicit Tracer(const Scene& scene);
  bool intersectQuery(const Ray& ray, Hit& hit, RayKind kind) const;
  struct Impl;
  const Scene& scene_;
  std::unique_ptr<Impl> impl_;
  bool hasBlend_ = false;
  TracerGeometry geometry_ = TracerGeometry::BakedGI;
  std::vector<bool> contains_;  // per object
};

}  // namespace kiln
