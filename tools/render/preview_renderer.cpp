// preview_renderer.cpp: kiln's preview and reference renderer (see preview_renderer.h).
#include "tools/render/preview_renderer.h"

#include <stb_image.h>

#include <algorithm>
#include <array>
#include <cassert>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <map>
#include <memory>
#include <nlohmann/json.hpp>
#include <sstream>

#include "kiln/lppv_volume.h"
#include "kiln/probe_runtime.h"
#include "lightmap/directional.h"
#include "lightmap/manifest.h"
#include "lightmap/probe_lit.h"
#include "lightmap/seams.h"
#include "probes/lppv.h"
#include "probes/probe_baker.h"
#include "src/integrator.h"
#include "src/parallel.h"
#include "src/progress.h"
#include "src/sampling.h"
#include "src/text_file.h"

namespace kiln {
namespace {

using Json = nlohmann::json;
namespace fs = std::filesystem;

std::string quoted(const std::string& s) { return "\"" + s + "\""; }

bool readFinite(const Json& j, float& out) {
  if (!j.is_number()) return false;
  const double v = j.get<double>();
  if (!std::isfinite(v) || std::abs(v) > 3.0e38) return false;
  out = float(v);
  return true;
}

bool readVec3(const Json& j, vec3& out) {
  if (!j.is_array() || j.size() != 3) return false;
  for (int i = 0; i < 3; ++i)
    if (!readFinite(j[size_t(i)], out[i])) return false;
  return true;
}

}  // namespace

// ---------------------------------------------------------------------------------------------
// Spheres
// ---------------------------------------------------------------------------------------------

Result<std::vector<RenderSphere>> parseSpheres(const std::string& text, const std::string& name) {
  Json j;
  try {
    j = Json::parse(text);
  } catch (const Json::exception& e) {
    return Error{name + ": malformed JSON: " + e.what()};
  }
  if (!j.is_object() || !j.contains("spheres") || !j["spheres"].is_array())
    return Error{name + ": spheres: expected an object {\"spheres\": [...]}"};
  std::vector<RenderSphere> spheres;
  const Json& list = j["spheres"];
  for (size_t i = 0; i < list.size(); ++i) {
    const std::string element = name + ": spheres[" + std::to_string(i) + "]";
    const Json& s = list[i];
    if (!s.is_object()) return Error{element + ": expected an object"};
    for (const auto& [key, value] : s.items())
      if (key != "center" && key != "radius" && key != "albedo" && key != "lppv")
        return Error{element + ": unknown field " + quoted(key) +
                     " (expected center, radius, albedo, lppv)"};
    RenderSphere sphere;
    if (!s.contains("center") || !readVec3(s["center"], sphere.center))
      return Error{element + ".center: expected 3 finite numbers [x, y, z]"};
    if (!s.contains("radius") || !readFinite(s["radius"], sphere.radius) ||
        !(sphere.radius > 0.0f))
      return Error{element + ".radius: must be a finite number > 0"};
    if (s.contains("albedo")) {
      if (!readVec3(s["albedo"], sphere.albedo) || sphere.albedo.r < 0.0f ||
          sphere.albedo.g < 0.0f || sphere.albedo.b < 0.0f || maxComponent(sphere.albedo) > 1.0f)
        return Error{element + ".albedo: expected 3 numbers in [0, 1] [r, g, b]"};
    }
    if (s.contains("lppv")) {
      if (!s["lppv"].is_boolean()) return Error{element + ".lppv: expected true or false"};
      sphere.lppv = s["lppv"].get<bool>();
    }
    spheres.push_back(sphere);
  }
  return spheres;
}

Result<std::vector<RenderSphere>> loadSpheres(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  if (!in) return Error{path + ": cannot open the spheres file"};
  std::stringstream text;
  text << in.rdbuf();
  return parseSpheres(text.str(), path);
}

std::optional<float> intersectSphere(const RenderSphere& sphere, vec3 origin, vec3 direction,
                                     float tMin, float tMax) {
  // |o + t d - c|^2 = r^2 with |d| = 1: t^2 + 2 b t + c = 0, b = d.(o - c). The form
  // t = -b -+ sqrt(r^2 - |(o - c) - (d.(o - c)) d|^2) avoids cancellation for far spheres.
  const vec3 oc = origin - sphere.center;
  const float b = glm::dot(direction, oc);
  const vec3 perp = oc - b * direction;
  const float disc = sphere.radius * sphere.radius - glm::dot(perp, perp);
  if (disc < 0.0f) return std::nullopt;
  const float root = std::sqrt(disc);
  const float t0 = -b - root, t1 = -b + root;
  if (t0 > tMin && t0 < tMax) return t0;
  if (t1 > tMin && t1 < tMax) return t1;
  return std::nullopt;
}

// ---------------------------------------------------------------------------------------------
// Lightmaps
// ---------------------------------------------------------------------------------------------

vec4 sampleBilinear(const Image& image, vec2 uv) {
  vec4 out(0.0f);
  if (image.empty()) return out;
  // The seam stitcher's lookup (lightmap/seams.h) on page texel points, which clamps to the
  // edge texels; clamping the point first keeps huge or non-finite coordinates defined.
  const vec2 size(float(image.width), float(image.height));
  vec2 p = uv * size;
  for (int a = 0; a < 2; ++a) p[a] = std::isfinite(p[a]) ? std::clamp(p[a], 0.0f, size[a]) : 0.0f;
  std::array<float, 8> values{};
  assert(image.channels <= int(values.size()));
  kiln::sampleBilinear(image, p, values.data());
  for (int c = 0; c < std::min(image.channels, 4); ++c) out[c] = values[size_t(c)];
  return out;
}

Result<LightmapSet> loadLightmapSet(const std::string& dir, const Scene& scene) {
  std::error_code ec;
  if (!fs::is_directory(dir, ec))
    return Error{dir + ": no such directory (--lightmaps takes the --out directory of kiln bake)"};
  const std::string manifestPath = (fs::path(dir) / "manifest.json").string();
  if (!fs::exists(manifestPath, ec))
    return Error{manifestPath + ": missing (--lightmaps takes the --out directory of kiln bake)"};
  // The manifest by itself (sizes, indices, finite scaleOffset, files.light, settings) is
  // checked by its reader; what is left is whether it fits `scene` and its images.
  Result<Manifest> read = readManifestFile(manifestPath, ManifestUse::kLightmaps);
  if (!read) return Error{read.error()};
  const Manifest& m = *read;
  const std::string& mp = manifestPath;

  LightmapSet set;
  const ManifestSettingsFields& s = m.settingsFields;
  if (s.lightingMode) set.lightingMode = *s.lightingMode;
  if (s.shadowColor) set.shadowColor = *s.shadowColor;
  if (s.bounces) set.bounces = *s.bounces;
  if (s.albedoBoost) set.albedoBoost = *s.albedoBoost;
  if (s.indirectIntensity) set.indirectIntensity = *s.indirectIntensity;

  // Pages.
  set.pages.resize(m.lightmaps.size());
  for (size_t i = 0; i < m.lightmaps.size(); ++i) {
    const std::string element = mp + ": lightmaps[" + std::to_string(i) + "]";
    const ManifestPage& p = m.lightmaps[i];
    PreviewLightmapPage& page = set.pages[i];
    for (auto [kind, name, image] :
         {std::tuple{"light", &p.files.light, &page.light},
          std::tuple{"direction", &p.files.direction, &page.direction},
          std::tuple{"shadowmask", &p.files.shadowmask, &page.shadowmask}}) {
      if (name->empty()) continue;
      const std::string file = (fs::path(dir) / *name).string();
      Result<Image> loaded = readHdrImage(file);
      if (!loaded) return Error{element + ".files." + kind + ": " + loaded.error()};
      if (loaded->width != p.width || loaded->height != p.height)
        return Error{element + ".files." + kind + ": " + file + " is " +
                     std::to_string(loaded->width) + " x " + std::to_string(loaded->height) +
                     ", the manifest says " + std::to_string(p.width) + " x " +
                     std::to_string(p.height)};
      *image = std::move(loaded).value();
    }
  }

  // Rendering the output glTF of an --atlas-uv bake: its TEXCOORD_1 is already the atlas UV.
  bool uv1IsAtlasUv = false;
  if (s.atlasUv.value_or(false) && m.gltf) {
    const fs::path output = fs::path(dir) / *m.gltf;
    uv1IsAtlasUv = fs::exists(output, ec) && fs::equivalent(output, scene.path, ec) && !ec;
  }

  // Objects, matched to the scene's mesh nodes.
  std::map<int, size_t> objectOfNode;
  for (size_t o = 0; o < scene.objects.size(); ++o) objectOfNode[scene.objects[o].nodeIndex] = o;
  set.objects.assign(scene.objects.size(), PreviewLightmapObject{});
  std::vector<bool> listed(scene.objects.size(), false);
  for (size_t i = 0; i < m.objects.size(); ++i) {
    const std::string element = mp + ": objects[" + std::to_string(i) + "]";
    const ManifestObject& e = m.objects[i];
    auto it = objectOfNode.find(e.nodeIndex);
    if (it == objectOfNode.end())
      return Error{element + ".nodeIndex: " + std::to_string(e.nodeIndex) +
                   " is not a mesh node of " + scene.path +
                   " (was the manifest baked from another scene?)"};
    const size_t o = it->second;
    const Object& object = scene.objects[o];
    if (e.node != object.name)
      return Error{element + ".node: " + quoted(e.node) + " but node " +
                   std::to_string(e.nodeIndex) + " of " + scene.path + " is " +
                   quoted(object.name) + " (was the manifest baked from another scene?)"};
    listed[o] = true;
    PreviewLightmapObject& entry = set.objects[o];
    entry.lightmapIndex = e.lightmapIndex;
    entry.probeLit = e.probeLit;
    entry.probeSh = e.probeSh;
    entry.probeOcclusion = e.probeOcclusion;
    if (entry.lightmapIndex < 0) continue;
    entry.scaleOffset = uv1IsAtlasUv ? vec4(1.0f, 1.0f, 0.0f, 0.0f) : e.scaleOffset;
    if (object.uv1.empty())
      return Error{element + ": node " + quoted(object.name) + " has a lightmap but no " +
                   "TEXCOORD_1 in " + scene.path + ": kiln generated its lightmap UVs, so " +
                   "render the bake's output glTF in " + dir + " instead"};
  }
  for (size_t o = 0; o < scene.objects.size(); ++o)
    if (!listed[o])
      return Error{mp + ": objects: no entry for node " +
                   std::to_string(scene.objects[o].nodeIndex) + " (" +
                   quoted(scene.objects[o].name) + ") of " + scene.path +
                   " (was the manifest baked from another scene?)"};

  // Lights: what the bake did with each; without a "lights" list, the plan of the mode.
  const LightModePlan plan = planLightModes(scene, set.lightingMode);
  set.lights.resize(scene.lights.size());
  for (size_t l = 0; l < scene.lights.size(); ++l)
    set.lights[l] = {bool(plan.bakeDirect[l]), bool(plan.bakeIndirect[l]),
                     plan.shadowmaskChannel[l]};
  if (m.lights) {
    if (m.lights->size() != scene.lights.size())
      return Error{mp + ": lights: expected one entry per light of " + scene.path + " (" +
                   std::to_string(scene.lights.size()) + ")"};
    for (size_t l = 0; l < m.lights->size(); ++l) {
      const ManifestLight& e = (*m.lights)[l];
      if (!e.name.empty() && e.name != scene.lights[l].name)
        return Error{mp + ": lights[" + std::to_string(l) + "].name: " + quoted(e.name) +
                     " but light " + std::to_string(l) + " of " + scene.path + " is " +
                     quoted(scene.lights[l].name)};
      PreviewLightBake& bake = set.lights[l];
      if (e.bakedDirect) bake.bakedDirect = *e.bakedDirect;
      if (e.bakedIndirect) bake.bakedIndirect = *e.bakedIndirect;
      if (e.shadowmaskChannel) bake.shadowmaskChannel = *e.shadowmaskChannel;
    }
  }
  bool needsMask = false;
  for (const PreviewLightBake& b : set.lights) needsMask |= b.shadowmaskChannel >= 0;
  if (needsMask)
    for (size_t i = 0; i < set.pages.size(); ++i)
      if (set.pages[i].shadowmask.empty())
        return Error{mp + ": lightmaps[" + std::to_string(i) +
                     "].files.shadowmask: missing, but lights have shadowmask channels"};
  return set;
}

// ---------------------------------------------------------------------------------------------
// Cameras
// ---------------------------------------------------------------------------------------------

RenderCamera lookAtCamera(vec3 from, vec3 at, float fovDegrees) {
  RenderCamera c;
  c.position = from;
  vec3 f = at - from;
  c.forward = glm::length(f) > 0.0f ? glm::normalize(f) : vec3(0, 0, -1);
  vec3 upHint(0.0f, 1.0f, 0.0f);
  if (glm::length(glm::cross(c.forward, upHint)) < 1e-4f) upHint = vec3(0.0f, 0.0f, -1.0f);
  c.right = glm::normalize(glm::cross(c.forward, upHint));
  c.up = glm::cross(c.right, c.forward);
  c.yfov = glm::radians(fovDegrees);
  return c;
}

RenderCamera cameraFromScene(const Camera& camera) {
  RenderCamera c;
  const mat4& w = camera.worldFromCamera;
  c.position = vec3(w[3]);
  c.forward = -glm::normalize(vec3(w[2]));
  vec3 up = vec3(w[1]);
  up = up - glm::dot(up, c.forward) * c.forward;
  c.up = glm::length(up) > 0.0f ? glm::normalize(up) : vec3(0, 1, 0);
  c.right = glm::cross(c.forward, c.up);
  c.perspective = camera.perspective;
  c.yfov = camera.yfov;
  c.ymag = camera.ymag;
  return c;
}

Result<RenderCamera> resolveCamera(const Scene& scene, const CameraRequest& request) {
  if (!request.name.empty()) {
    // Scene::cameras carry the glTF camera's name, or its node's when it has none.
    for (const Camera& cam : scene.cameras)
      if (cam.name == request.name) return cameraFromScene(cam);
    std::string names;
    for (const Camera& cam : scene.cameras) names += (names.empty() ? "" : ", ") + quoted(cam.name);
    return Error{scene.path + ": cameras: no camera named " + quoted(request.name) +
                 (names.empty() ? std::string(" (the scene has no cameras)")
                                : " (the scene's cameras: " + names + ")")};
  }
  if (request.lookFrom && request.lookAt)
    return lookAtCamera(*request.lookFrom, *request.lookAt, request.fovDegrees);
  if (!scene.cameras.empty()) return cameraFromScene(scene.cameras.front());
  // Frame the scene: its bounding sphere fits the vertical field of view.
  Bounds3 b = scene.bounds;
  if (b.empty()) b.extend(vec3(0.0f));
  const vec3 centre = b.center();
  const float radius = std::max(0.5f * b.diagonal(), 1e-3f);
  const float distance = 1.05f * radius / std::sin(0.5f * glm::radians(request.fovDegrees));
  const vec3 dir = glm::normalize(vec3(0.45f, 0.35f, 1.0f));
  return lookAtCamera(centre + dir * distance, centre, request.fovDegrees);
}

Ray cameraRay(const RenderCamera& camera, int width, int height, float px, float py) {
  const float aspect = float(width) / float(height);
  const float sx = 2.0f * px / float(width) - 1.0f;   // -1 left, +1 right
  const float sy = 1.0f - 2.0f * py / float(height);  // +1 top, -1 bottom
  Ray ray;
  if (camera.perspective) {
    const float tanY = std::tan(0.5f * camera.yfov);
    ray.origin = camera.position;
    ray.direction =
        glm::normalize(camera.forward + camera.right * (sx * tanY * aspect) + camera.up * (sy * tanY));
  } else {
    ray.origin = camera.position + camera.right * (sx * camera.ymag * aspect) +
                 camera.up * (sy * camera.ymag);
    ray.direction = camera.forward;
  }
  return ray;
}

std::optional<vec2> projectToPixel(const RenderCamera& camera, int width, int height, vec3 p) {
  const float aspect = float(width) / float(height);
  const vec3 d = p - camera.position;
  const float z = glm::dot(d, camera.forward);
  float sx, sy;
  if (camera.perspective) {
    if (!(z > 0.0f)) return std::nullopt;
    const float tanY = std::tan(0.5f * camera.yfov);
    sx = glm::dot(d, camera.right) / z / (tanY * aspect);
    sy = glm::dot(d, camera.up) / z / tanY;
  } else {
    sx = glm::dot(d, camera.right) / (camera.ymag * aspect);
    sy = glm::dot(d, camera.up) / camera.ymag;
  }
  return vec2((sx + 1.0f) * 0.5f * float(width), (1.0f - sy) * 0.5f * float(height));
}

// ---------------------------------------------------------------------------------------------
// Rendering
// ---------------------------------------------------------------------------------------------

namespace {

// Probe light of one object: SH from one lookup at its centre, or a volume over its bounds.
struct ObjectProbeLight {
  bool available = false;
  ShL2Rgb sh;
  glm::vec4 occlusion{1.0f};
  std::optional<LppvVolume> volume;

  vec3 irradiance(vec3 p, vec3 n) const {
    if (volume) return lppvIrradiance(*volume, p, n);
    return probeIrradiance(sh, n);
  }
  glm::vec4 occlusionAt(vec3 p) const {
    return volume ? sampleLppvOcclusion(*volume, p) : occlusion;
  }
};

Result<ObjectProbeLight> probeLightFor(const ProbeSet& probes, vec3 boundsMin, vec3 boundsMax,
                                       bool lppv, int threads) {
  ObjectProbeLight light;
  light.available = true;
  if (!lppv) {
    const ProbeLocation loc = locateProbe(probes, 0.5f * (boundsMin + boundsMax));
    light.sh = interpolateProbes(probes, loc);
    light.occlusion = interpolateOcclusion(probes, loc);
    return light;
  }
  // A flat object still needs a box with min < max on every axis.
  const float pad = 1e-3f * std::max(glm::length(boundsMax - boundsMin), 1e-3f);
  LppvBuildSettings s;
  s.boundsMin = boundsMin - vec3(pad);
  s.boundsMax = boundsMax + vec3(pad);
  s.threads = threads;
  Result<LppvBuild> built = buildLppvFromProbes(probes, s);
  if (!built) return Error{built.error()};
  light.volume = std::move(built->volume);
  return light;
}

// A UV sphere as a scene object (vertices on the sphere, outward normals, CCW from outside).
Object tessellateSphere(const RenderSphere& s, const std::string& name, uint32_t material) {
  constexpr int kRings = 48, kSegments = 96;
  Object o;
  o.name = name;
  o.settings.isStatic = false;
  for (int i = 0; i <= kRings; ++i) {
    const float theta = kPi * float(i) / kRings;
    for (int j = 0; j <= kSegments; ++j) {
      const float phi = 2.0f * kPi * float(j) / kSegments;
      const vec3 n(std::sin(theta) * std::cos(phi), std::cos(theta), std::sin(theta) * std::sin(phi));
      o.positions.push_back(s.center + s.radius * n);
      o.normals.push_back(n);
    }
  }
  auto v = [](int i, int j) { return uint32_t(i * (kSegments + 1) + j); };
  for (int i = 0; i < kRings; ++i)
    for (int j = 0; j < kSegments; ++j) {
      // Seen from outside, (i, j) -> (i, j+1) -> (i+1, j) runs clockwise with this phi
      // direction, so wind the other way.
      if (i > 0) o.triangles.push_back(uvec3(v(i, j), v(i, j + 1), v(i + 1, j)));
      if (i < kRings - 1) o.triangles.push_back(uvec3(v(i, j + 1), v(i + 1, j + 1), v(i + 1, j)));
    }
  o.triangleMaterial.assign(o.triangles.size(), material);
  return o;
}

struct PrimaryHit {
  enum Kind { None, Surface, Sphere } kind = None;
  Hit hit;
  int sphere = -1;
  float t = kInfinity;
};

class Renderer {
 public:
  Renderer(const RenderInputs& in, const RenderSettings& settings)
      : in_(in), scene_(*in.scene), settings_(settings) {}

  Result<RenderResult> run(const RenderCamera& camera) {
    const bool preview = settings_.mode == RenderMode::Preview;
    if (settings_.width < 1 || settings_.height < 1 || settings_.width > 16384 ||
        settings_.height > 16384)
      return Error{"image size " + std::to_string(settings_.width) + " x " +
                   std::to_string(settings_.height) + " must be 1..16384 on each side"};
    if (settings_.samples < 1) return Error{"samples must be >= 1"};
    const LightmapSet* lm = in_.lightmaps;
    if (preview && !lm) return Error{"the preview needs lightmaps"};
    if (lm && (lm->objects.size() != scene_.objects.size() ||
               lm->lights.size() != scene_.lights.size()))
      return Error{"the lightmaps do not belong to " + scene_.path};

    // Over every object: the camera sees dynamic objects (lit by the probes) and they cast
    // the run-time lights' shadows; bakes leave them out (TracerGeometry::BakedGI).
    Result<std::unique_ptr<Tracer>> tracer = Tracer::create(scene_, TracerGeometry::All);
    if (!tracer) return Error{tracer.error()};
    tracer_ = std::move(tracer).value();

    if (preview) {
      if (Status s = setUpPreview(); !s) return Error{s.error()};
    } else {
      if (Status s = setUpReference(); !s) return Error{s.error()};
    }

    RenderResult result;
    result.warnings = warnings_;
    result.radiance = Image(settings_.width, settings_.height, 3);
    Progress progress("render", size_t(settings_.height), "rows", settings_.showProgress);
    ParallelOptions options;
    options.threads = settings_.threads;
    options.grain = 1;
    options.progress = &progress;
    options.cancel = settings_.cancel;
    Image& image = result.radiance;
    const bool done = parallelFor(
        size_t(settings_.height),
        [&](size_t begin, size_t end) {
          for (size_t y = begin; y < end; ++y)
            for (int x = 0; x < settings_.width; ++x) {
              const uint64_t key =
                  hashValues(settings_.seed, uint64_t(y) * uint64_t(settings_.width) + uint64_t(x));
              const Ray ray = cameraRay(camera, settings_.width, settings_.height, float(x) + 0.5f,
                                        float(y) + 0.5f);
              const vec3 l = radiance(ray, key);
              float* px = image.at(x, int(y));
              px[0] = l.r;
              px[1] = l.g;
              px[2] = l.b;
            }
        },
        options);
    if (!done) return Error{"cancelled"};
    progress.finish();
    return result;
  }

 private:
  // Probe light for an object the bake left to probes, without a probe file: the light the
  // bake gave it (manifest "probeSH"), or for a bake that has none, bakeObjectProbe's probes
  // around its bounds baked as kiln bake bakes them (the lightmaps' lighting mode and
  // transport settings; this tracer also holds the dynamic objects).
  ObjectProbeLight probeLightAround(const LightmapSet& lm, const Bounds3& b, size_t object) const {
    const PreviewLightmapObject& entry = lm.objects[object];
    ObjectProbeLight light;
    light.available = true;
    if (entry.probeSh) {
      light.sh = *entry.probeSh;
      light.occlusion = entry.probeOcclusion.value_or(glm::vec4(1.0f));
      return light;
    }
    const ProbeBakeSettings ps =
        probeLitBakeSettings(lm.lightingMode, lm.bounces, lm.albedoBoost, lm.indirectIntensity);
    const Integrator integrator(scene_, *tracer_, probeIntegratorSettings(scene_, ps));
    const ObjectProbe probe = bakeObjectProbe(integrator, probeLightModePlan(scene_, ps), b,
                                              hashValues(settings_.seed, uint64_t(object)), ps);
    light.sh = probe.sh;
    light.occlusion = probe.occlusion;
    return light;
  }

  Status setUpPreview() {
    const LightmapSet& lm = *in_.lightmaps;
    if (!in_.spheres.empty() && !in_.probes)
      return Error{"dynamic spheres need probes (--probes FILE.kprobe) in the preview"};
    // Only for the run-time lights' shadows, which bakedShadows (a bake setting) leaves alone.
    IntegratorSettings runtime;
    runtime.honourBakedShadows = false;
    integrator_ = std::make_unique<Integrator>(scene_, *tracer_, runtime);
    // Probe light per object without a lightmap, and per sphere.
    objectProbes_.resize(scene_.objects.size());
    for (size_t o = 0; o < scene_.objects.size(); ++o) {
      if (lm.objects[o].lightmapIndex >= 0) continue;
      const Object& object = scene_.objects[o];
      Bounds3 b;
      for (vec3 p : object.positions) b.extend(p);
      if (!in_.probes && lm.objects[o].probeLit && !b.empty()) {
        // Too small for a lightmap (kiln bake --min-object-texels): the light the bake
        // gave it, so that a preview without a probe file does not draw it black.
        objectProbes_[o] = probeLightAround(lm, b, o);
        continue;
      }
      if (!in_.probes) {
        warnings_.push_back("node " + quoted(object.name) +
                            " has no lightmap and no probes were given (--probes): drawn with "
                            "realtime lights and emission only");
        continue;
      }
      if (b.empty()) continue;
      Result<ObjectProbeLight> light =
          probeLightFor(*in_.probes, b.min, b.max, object.settings.lppv, settings_.threads);
      if (!light) return Error{"node " + quoted(object.name) + ": " + light.error()};
      objectProbes_[o] = std::move(light).value();
    }
    for (size_t i = 0; i < in_.spheres.size(); ++i) {
      const RenderSphere& s = in_.spheres[i];
      Result<ObjectProbeLight> light = probeLightFor(*in_.probes, s.center - vec3(s.radius),
                                                     s.center + vec3(s.radius), s.lppv,
                                                     settings_.threads);
      if (!light) return Error{"spheres[" + std::to_string(i) + "]: " + light.error()};
      sphereProbes_.push_back(std::move(light).value());
    }
    // Probe occlusion channels must be the lightmaps' (both follow the same light plan).
    if (in_.probes)
      for (size_t l = 0; l < lm.lights.size(); ++l) {
        const int c = lm.lights[l].shadowmaskChannel;
        if (c >= 0 && in_.probes->occlusionLights[size_t(c)] != scene_.lights[l].lightIndex)
          warnings_.push_back("light " + quoted(scene_.lights[l].name) +
                              " has shadowmask channel " + std::to_string(c) +
                              " in the lightmaps but not in the probe file: bake both with the "
                              "same --lighting-mode");
      }
    // Subtractive: the main light is the brightest mixed directional light (Unity's).
    if (lm.lightingMode == LightingMode::Subtractive) {
      float best = 0.0f;
      for (size_t l = 0; l < scene_.lights.size(); ++l) {
        const Light& light = scene_.lights[l];
        const float power = luminance(light.color) * light.intensity;
        if (light.mode == LightMode::Mixed && light.type == LightType::Directional &&
            power > best) {
          best = power;
          mainLight_ = int(l);
        }
      }
    }
    return Status::success();
  }

  Status setUpReference() {
    // The spheres become scene geometry so that they bounce light and cast shadows.
    augmented_ = std::make_unique<Scene>(scene_);
    for (size_t i = 0; i < in_.spheres.size(); ++i) {
      Material m;
      m.name = "sphere " + std::to_string(i);
      m.baseColorFactor = vec4(in_.spheres[i].albedo, 1.0f);
      m.metallic = 0.0f;
      m.roughness = 1.0f;
      augmented_->materials.push_back(m);
      augmented_->objects.push_back(tessellateSphere(in_.spheres[i], m.name,
                                                     uint32_t(augmented_->materials.size() - 1)));
    }
    augmented_->updateBounds();
    // Every object, the dynamic ones too: the reference is the path-traced truth of the view.
    Result<std::unique_ptr<Tracer>> tracer = Tracer::create(*augmented_, TracerGeometry::All);
    if (!tracer) return Error{tracer.error()};
    augmentedTracer_ = std::move(tracer).value();
    IntegratorSettings is;
    const LightmapSet* lm = in_.lightmaps;
    is.maxBounces = lm ? lm->bounces : scene_.settings.bounces.value_or(3);
    is.albedoBoost = lm ? lm->albedoBoost : scene_.settings.albedoBoost.value_or(1.0f);
    is.indirectIntensity =
        lm ? lm->indirectIntensity : scene_.settings.indirectIntensity.value_or(1.0f);
    // Every light's direct light (baked into the lightmaps or added in real time, the preview
    // shows it either way); bounced light of every light that is not realtime.
    is.directLights.assign(scene_.lights.size(), true);
    is.indirectLights.resize(scene_.lights.size());
    for (size_t l = 0; l < scene_.lights.size(); ++l)
      is.indirectLights[l] = scene_.lights[l].mode != LightMode::Realtime;
    integrator_ = std::make_unique<Integrator>(*augmented_, *augmentedTracer_, is);
    return Status::success();
  }

  // The first visible surface along the ray: scene triangles (back faces of single-sided
  // materials culled) or a sphere.
  PrimaryHit trace(Ray ray) const {
    PrimaryHit best;
    for (int guard = 0; guard < 64; ++guard) {
      std::optional<Hit> h = tracer_->intersect(ray);
      if (!h) break;
      if (h->backFace && !scene_.materialOf(h->object, h->triangle).doubleSided) {
        ray.tMin = h->t + 1e-5f * std::max(1.0f, h->t);
        continue;
      }
      best.kind = PrimaryHit::Surface;
      best.hit = *h;
      best.t = h->t;
      break;
    }
    for (size_t i = 0; i < in_.spheres.size(); ++i)
      if (std::optional<float> t =
              intersectSphere(in_.spheres[i], ray.origin, ray.direction, ray.tMin, best.t)) {
        best.kind = PrimaryHit::Sphere;
        best.sphere = int(i);
        best.t = *t;
      }
    return best;
  }

  // 1 when no sphere lies on the segment from p along unit dir up to distance, else 0.
  float sphereVisibility(vec3 p, vec3 dir, float distance, int skipSphere = -1) const {
    for (size_t i = 0; i < in_.spheres.size(); ++i)
      if (int(i) != skipSphere &&
          intersectSphere(in_.spheres[i], p, dir, 0.0f, distance).has_value())
        return 0.0f;
    return 1.0f;
  }

  // Realtime direct light (E / pi, before the albedo) at p from every light the bake left to
  // run time. `mask(channel)` gives the baked visibility of a shadowmask channel.
  template <typename Mask>
  vec3 realtimeDirect(vec3 p, vec3 n, vec3 ng, uint64_t key, int skipSphere, Mask mask) const {
    vec3 sum(0.0f);
    const LightmapSet& lm = *in_.lightmaps;
    for (size_t l = 0; l < scene_.lights.size(); ++l) {
      if (lm.lights[l].bakedDirect) continue;
      const Light& light = scene_.lights[l];
      const vec3 e = light.irradianceAt(p);
      if (maxComponent(e) <= 0.0f) continue;
      const vec3 toLight = light.directionTo(p);
      const float cosine = glm::dot(n, toLight);
      if (cosine <= 0.0f || glm::dot(ng, toLight) <= 0.0f) continue;
      vec3 visibility = integrator_->lightVisibility(p, ng, uint32_t(l), hashValues(key, l), 0);
      visibility *= sphereVisibility(offsetRayOrigin(p, ng), toLight, light.distanceTo(p),
                                     skipSphere);
      const int channel = lm.lights[l].shadowmaskChannel;
      if (channel >= 0) visibility = glm::min(visibility, vec3(mask(channel)));
      sum += e * cosine * kInvPi * visibility;
    }
    return sum;
  }

  vec3 shadeSphere(const PrimaryHit& ph, const Ray& ray, uint64_t key) const {
    const RenderSphere& s = in_.spheres[size_t(ph.sphere)];
    const vec3 n = glm::normalize(ray.origin + ph.t * ray.direction - s.center);
    const vec3 p = s.center + s.radius * n;  // on the sphere, not behind it by rounding
    if (settings_.mode == RenderMode::Reference)
      return s.albedo * integrator_->irradiance(p, n, key, 0, settings_.samples).total() * kInvPi;
    const ObjectProbeLight& probe = sphereProbes_[size_t(ph.sphere)];
    const glm::vec4 occlusion = probe.occlusionAt(p);
    vec3 light = glm::max(probe.irradiance(p, n), vec3(0.0f)) * kInvPi;
    light += realtimeDirect(p, n, n, key, ph.sphere, [&](int c) { return occlusion[c]; });
    return s.albedo * light;
  }

  // Outgoing radiance of a scene surface towards the camera, without what lies behind a
  // BLEND surface. `albedo` is the base colour.
  vec3 shadeSurface(const Hit& hit, vec3 albedo, uint64_t key) const {
    const uint32_t o = hit.object, t = hit.triangle;
    const Material& material = scene_.materialOf(o, t);
    vec3 ng = hit.geometricNormal;
    vec3 n = scene_.shadingNormalAt(o, t, hit.bary);
    if (hit.backFace) {
      ng = -ng;
      n = -n;
    }
    if (glm::dot(n, ng) <= 0.0f) n = ng;
    const vec3 p = scene_.positionAt(o, t, hit.bary);
    const vec3 emission =
        (!hit.backFace || material.doubleSided) ? scene_.emissionAt(o, t, hit.bary) : vec3(0.0f);
    if (settings_.mode == RenderMode::Reference)
      return emission + albedo * integrator_->irradiance(p, n, key, 0, settings_.samples).total() *
                            kInvPi;

    const LightmapSet& lm = *in_.lightmaps;
    const PreviewLightmapObject& entry = lm.objects[o];
    vec3 light(0.0f);
    if (entry.lightmapIndex >= 0) {
      const PreviewLightmapPage& page = lm.pages[size_t(entry.lightmapIndex)];
      const vec2 uv1 = uv1At(o, t, hit.bary);
      const vec2 atlasUv = uv1 * vec2(entry.scaleOffset.x, entry.scaleOffset.y) +
                           vec2(entry.scaleOffset.z, entry.scaleOffset.w);
      light = vec3(sampleBilinear(page.light, atlasUv));
      if (!page.direction.empty())
        light = decodeDirectionalLightmap(light, sampleBilinear(page.direction, atlasUv), n);
      if (mainLight_ >= 0) {
        // Subtractive: the spheres' realtime shadows of the main light.
        const Light& main = scene_.lights[size_t(mainLight_)];
        const vec3 toLight = main.directionTo(p);
        const float attenuation =
            sphereVisibility(offsetRayOrigin(p, ng), toLight, main.distanceTo(p));
        light = subtractiveLightmap(light, n, toLight, attenuation,
                                    main.color * main.intensity * kInvPi, lm.shadowColor);
      }
      const vec4 mask = page.shadowmask.empty() ? vec4(1.0f) : sampleBilinear(page.shadowmask, atlasUv);
      light += realtimeDirect(p, n, ng, key, -1, [&](int c) { return mask[c]; });
    } else {
      const ObjectProbeLight& probe = objectProbes_[o];
      glm::vec4 occlusion(1.0f);
      if (probe.available) {
        light = glm::max(probe.irradiance(p, n), vec3(0.0f)) * kInvPi;
        occlusion = probe.occlusionAt(p);
      }
      light += realtimeDirect(p, n, ng, key, -1, [&](int c) { return occlusion[c]; });
    }
    return emission + albedo * light;
  }

  vec2 uv1At(uint32_t o, uint32_t t, vec2 bary) const {
    const Object& object = scene_.objects[o];
    const uvec3 tri = object.triangles[t];
    return (1.0f - bary.x - bary.y) * object.uv1[tri.x] + bary.x * object.uv1[tri.y] +
           bary.y * object.uv1[tri.z];
  }

  // Radiance towards the camera along a primary ray, compositing BLEND surfaces.
  vec3 radiance(Ray ray, uint64_t key) const {
    vec3 sum(0.0f), throughput(1.0f);
    for (uint32_t layer = 0; layer < 8; ++layer) {
      const uint64_t layerKey = layer == 0 ? key : hashValues(key, layer);
      const PrimaryHit ph = trace(ray);
      if (ph.kind == PrimaryHit::None) {
        sum += throughput * scene_.sky.radiance(ray.direction);
        break;
      }
      if (ph.kind == PrimaryHit::Sphere) {
        sum += throughput * shadeSphere(ph, ray, layerKey);
        break;
      }
      const Hit& hit = ph.hit;
      const Material& material = scene_.materialOf(hit.object, hit.triangle);
      const vec4 base = scene_.baseColorAt(hit.object, hit.triangle, hit.bary);
      const vec3 shaded = shadeSurface(hit, vec3(base), layerKey);
      if (material.alphaMode != AlphaMode::Blend) {
        sum += throughput * shaded;
        break;
      }
      // Semi-transparent: alpha of the lit surface, the rest passes tinted by the colour.
      const float alpha = std::clamp(base.a, 0.0f, 1.0f);
      const vec3 emission = (!hit.backFace || material.doubleSided)
                                ? scene_.emissionAt(hit.object, hit.triangle, hit.bary)
                                : vec3(0.0f);
      sum += throughput * (emission + alpha * (shaded - emission));
      throughput *= (1.0f - alpha) * vec3(base);
      if (maxComponent(throughput) <= 0.0f) break;
      ray.tMin = ph.t + 1e-5f * std::max(1.0f, ph.t);
    }
    return sum;
  }

  const RenderInputs& in_;
  const Scene& scene_;
  RenderSettings settings_;
  std::unique_ptr<Tracer> tracer_;
  std::unique_ptr<Scene> augmented_;
  std::unique_ptr<Tracer> augmentedTracer_;
  std::unique_ptr<Integrator> integrator_;
  std::vector<ObjectProbeLight> objectProbes_;
  std::vector<ObjectProbeLight> sphereProbes_;
  int mainLight_ = -1;
  std::vector<std::string> warnings_;
};

}  // namespace

Result<RenderResult> renderImage(const RenderInputs& inputs, const RenderCamera& camera,
                                 const RenderSettings& settings) {
  assert(inputs.scene);
  Renderer renderer(inputs, settings);
  return renderer.run(camera);
}

// ---------------------------------------------------------------------------------------------
// Display and comparison
// ---------------------------------------------------------------------------------------------

float acesFilmic(float x) {
  if (!(x > 0.0f)) return 0.0f;
  const float y = x * (2.51f * x + 0.03f) / (x * (2.43f * x + 0.59f) + 0.14f);
  return std::clamp(y, 0.0f, 1.0f);
}

Image toneMap(const Image& radiance, float exposureEv) {
  Image out(radiance.width, radiance.height, 3);
  const float scale = std::exp2(exposureEv);
  for (int y = 0; y < radiance.height; ++y)
    for (int x = 0; x < radiance.width; ++x) {
      const vec3 c = radiance.rgb(x, y) * scale;
      float* o = out.at(x, y);
      for (int k = 0; k < 3; ++k) o[k] = linearToSrgb(acesFilmic(c[k]));
    }
  return out;
}

Result<Image> readImageFile(const std::string& path) {
  std::string ext = fs::path(path).extension().string();
  std::transform(ext.begin(), ext.end(), ext.begin(), [](unsigned char c) { return char(std::tolower(c)); });
  if (ext == ".exr" || ext == ".hdr") {
    Result<Image> img = readHdrImage(path);
    if (!img) return img;
    Image rgb(img->width, img->height, 3);
    for (int y = 0; y < img->height; ++y)
      for (int x = 0; x < img->width; ++x) {
        const vec3 c = img->rgb(x, y);
        float* o = rgb.at(x, y);
        o[0] = c.r;
        o[1] = c.g;
        o[2] = c.b;
      }
    return rgb;
  }
  int w = 0, h = 0, n = 0;
  unsigned char* data = stbi_load(path.c_str(), &w, &h, &n, 3);
  if (!data) {
    const char* reason = stbi_failure_reason();
    return Error{path + ": cannot read the image (" + (reason ? reason : "unknown error") + ")"};
  }
  Image img(w, h, 3);
  for (size_t i = 0; i < img.pixels.size(); ++i) img.pixels[i] = float(data[i]) / 255.0f;
  stbi_image_free(data);
  return img;
}

Result<ImageComparison> compareImages(const Image& a, const Image& b, float diffScale) {
  if (a.width != b.width || a.height != b.height)
    return Error{"the images differ in size: " + std::to_string(a.width) + " x " +
                 std::to_string(a.height) + " and " + std::to_string(b.width) + " x " +
                 std::to_string(b.height)};
  ImageComparison c;
  c.difference = Image(a.width, a.height, 3);
  c.sideBySide = Image(3 * a.width, a.height, 3);
  double sumDiff = 0.0, sumA = 0.0, sumB = 0.0;
  for (int y = 0; y < a.height; ++y)
    for (int x = 0; x < a.width; ++x) {
      const vec3 va = a.rgb(x, y), vb = b.rgb(x, y);
      const vec3 d = glm::abs(va - vb);
      sumDiff += double(d.r) + d.g + d.b;
      sumA += double(va.r) + va.g + va.b;
      sumB += double(std::abs(vb.r)) + std::abs(vb.g) + std::abs(vb.b);
      const vec3 shown = glm::clamp(d * diffScale, vec3(0.0f), vec3(1.0f));
      for (int k = 0; k < 3; ++k) {
        c.difference.at(x, y)[k] = shown[k];
        c.sideBySide.at(x, y)[k] = va[k];
        c.sideBySide.at(x + a.width, y)[k] = vb[k];
        c.sideBySide.at(x + 2 * a.width, y)[k] = shown[k];
      }
    }
  const double count = 3.0 * double(a.width) * double(a.height);
  c.meanAbsoluteDifference = count > 0 ? sumDiff / count : 0.0;
  c.relativeMeanDifference = sumB > 0 ? sumDiff / sumB : 0.0;
  c.meanA = count > 0 ? sumA / count : 0.0;
  c.meanB = count > 0 ? sumB / count : 0.0;
  return c;
}

}  // namespace kiln
