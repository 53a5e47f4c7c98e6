// preview_renderer.h: kiln's preview renderer (`kiln render`): an image of a scene from a
// camera, shaded the way a game shades it from kiln's baked data, and a path-traced reference
// of the same view to compare it with.
//
// Preview (RenderMode::Preview), one primary ray per pixel through the pixel centre (kiln's
// Tracer, Embree), back faces of single-sided materials culled as a rasterizer culls them:
//   - lightmapped objects: outgoing radiance = emission + albedo x lightmap, the lightmap
//     (texel value E / pi, docs/lightmap_outputs.md) sampled bilinearly at atlasUV = uv1 x
//     scaleOffset.xy + scaleOffset.zw; with direction maps Unity's directional decode
//     (lightmap/directional.h); plus the realtime direct light of every light the lightmaps
//     do not hold directly (realtime lights; mixed lights under baked-indirect and
//     shadowmask), each with shadow rays (static geometry through the tracer, soft shadows as
//     the bake has them, and the dynamic spheres) and, for shadowmask lights, the baked
//     visibility min(realtime shadow, shadowmask[channel]); under subtractive, the spheres'
//     realtime shadows of the main light subtracted from the lightmap (Unity's
//     SubtractMainLightWithRealtimeAttenuationFromLightmap, docs/mixed_lighting.md);
//   - objects without a lightmap (dynamic meshes, receiveGI probes) and dynamic spheres:
//     albedo x E / pi with E the probes' SH irradiance for the pixel's normal: the SH from
//     one tetrahedral lookup at the object's centre (Cupisz 2012), or, for objects that ask
//     for it ("lppv"), from a light probe proxy volume over their bounds sampled per pixel
//     (probes/lppv.h); plus realtime direct light as above, with the probes' shadowmask
//     occlusion in place of the shadowmask texture;
//   - rays that hit nothing: the sky's radiance.
// Semi-transparent (BLEND) surfaces are composited over what lies behind them:
// alpha x shaded + (1 - alpha) x baseColor x behind (the tracer's transmittance rule).
//
// Reference (RenderMode::Reference): the same primary rays through a scene that holds the
// spheres as tessellated geometry (so they bounce light and cast shadows); at the hit,
// radiance = emission + albedo x E / pi with E kiln's path-traced irradiance estimate
// (Integrator::irradiance, `samples` paths) from every light's direct light and the indirect
// light of every light that is not realtime (what the preview shows, computed without
// baking); bounces, albedo boost and indirect intensity from the manifest when given.
//
// Units: radiance in W/(m^2 sr) (kiln's photometric reading, no 683 factor), linear. Images
// have row 0 at the top. Determinism: pixel (x, y) draws its randoms from a stream keyed by
// (seed, y * width + x), and rows run through kiln::parallelFor, so the output is
// bit-identical at any thread count.
#pragma once

#include <atomic>
#include <optional>
#include <string>
#include <vector>

#include "kiln/probe_set.h"
#include "kiln/sh.h"
#include "src/image.h"
#include "src/light_modes.h"
#include "src/math.h"
#include "kiln/result.h"
#include "src/scene.h"
#include "src/tracer.h"

namespace kiln {

// ---------------------------------------------------------------------------------------------
// Dynamic spheres
// ---------------------------------------------------------------------------------------------

// A dynamic object of the preview: a Lambertian sphere lit by the probes (world space,
// metres; albedo linear).
struct RenderSphere {
  vec3 center{0.0f};
  float radius = 1.0f;
  vec3 albedo{0.8f};
  bool lppv = false;  // per-pixel light from a probe volume over its bounds
};

// Parses {"spheres": [{"center": [x, y, z], "radius": r, "albedo": [r, g, b],
// "lppv": false}]} ("albedo" defaults to 0.8 grey, "lppv" to false). Errors name `name` and
// the field: "spheres.json: spheres[1].radius: must be a finite number > 0".
Result<std::vector<RenderSphere>> parseSpheres(const std::string& text, const std::string& name);
Result<std::vector<RenderSphere>> loadSpheres(const std::string& path);

// Nearest intersection of a ray (unit direction) with a sphere in (tMin, tMax); nullopt
// when there is none. Exposed for tests.
std::optional<float> intersectSphere(const RenderSphere& sphere, vec3 origin, vec3 direction,
                                     float tMin, float tMax);

// ---------------------------------------------------------------------------------------------
// Lightmaps (what `kiln bake` wrote)
// ---------------------------------------------------------------------------------------------

struct PreviewLightmapPage {
  Image light;       // RGB, E / pi, row 0 = v 0
  Image direction;   // RGBA or empty (directional mode)
  Image shadowmask;  // RGBA or empty (shadowmask mode)
};

struct PreviewLightmapObject {
  int lightmapIndex = -1;                    // page, or -1: no lightmap
  vec4 scaleOffset{1.0f, 1.0f, 0.0f, 0.0f};  // atlasUV = uv1 * xy + zw
  // Lightmapped by its settings but too small for a lightmap (manifest "probeLit"): lit by
  // probes; without --probes by the light the bake gave it (manifest "probeSH",
  // "probeOcclusion"), or for a bake without it by bakeObjectProbe (probes/probe_baker.h) run
  // by the preview.
  bool probeLit = false;
  std::optional<ShL2Rgb> probeSh;     // radiance SH
  std::optional<vec4> probeOcclusion;  // shadowmask channels
};

// What the bake did with one scene light.
struct PreviewLightBake {
  bool bakedDirect = true;     // its direct light is in the lightmaps (and probes)
  bool bakedIndirect = true;   // its bounced light is
  int shadowmaskChannel = -1;  // 0..3, or -1
};

struct LightmapSet {
  std::vector<PreviewLightmapPage> pages;
  std::vector<PreviewLightmapObject> objects;  // one per Scene::objects entry
  std::vector<PreviewLightBake> lights;        // one per Scene::lights entry
  LightingMode lightingMode = LightingMode::BakedIndirect;
  vec3 shadowColor{0.42f, 0.478f, 0.627f};  // subtractive: realtime shadow colour (E / pi)
  // Light transport settings of the bake (the reference render uses the same).
  int bounces = 3;
  float albedoBoost = 1.0f;
  float indirectIntensity = 1.0f;
};

// Reads DIR/manifest.json (through readManifestFile, lightmap/manifest.h, which checks it by
// itself: lightmapIndex names a page, scaleOffset is 4 finite numbers, ...) and the EXR pages
// it lists, and checks them against `scene`: every manifest object must name a mesh node of
// the scene (nodeIndex and node name agree) and every mesh node must be listed, a lightmapped
// object must have UV1, images must have the manifest's size, lights match the scene's.
// Errors name the file and the field ("out/manifest.json: objects[3].node: ...").
Result<LightmapSet> loadLightmapSet(const std::string& dir, const Scene& scene);

// Bilinear sample of an image at glTF texture coordinate uv (texel centres at (x + 0.5) / W,
// clamped to the edge texels). Returns the first `channels` values (missing ones 0).
vec4 sampleBilinear(const Image& image, vec2 uv);

// ---------------------------------------------------------------------------------------------
// Cameras
// ---------------------------------------------------------------------------------------------

// A pinhole (or orthographic) camera in world space. Looks down `forward`; `up` and `right`
// complete an orthonormal frame; yfov is the full vertical angle in radians. The horizontal
// extent follows the image's aspect ratio.
struct RenderCamera {
  vec3 position{0.0f};
  vec3 forward{0.0f, 0.0f, -1.0f};
  vec3 up{0.0f, 1.0f, 0.0f};
  vec3 right{1.0f, 0.0f, 0.0f};
  bool perspective = true;
  float yfov = 0.8f;  // radians (perspective)
  float ymag = 1.0f;  // half height in metres (orthographic)
};

struct CameraRequest {
  std::string name;              // a glTF camera's name or its node's name
  std::optional<vec3> lookFrom;  // with lookAt
  std::optional<vec3> lookAt;
  float fovDegrees = 50.0f;  // vertical, with lookFrom/lookAt and for the framing view
};

// A camera looking from `from` at `at` with +Y up (any other up when looking straight up or
// down); fovDegrees is the vertical field of view.
RenderCamera lookAtCamera(vec3 from, vec3 at, float fovDegrees);
// A camera from a glTF camera (its node's world transform; scale removed).
RenderCamera cameraFromScene(const Camera& camera);
// The request resolved: the named camera, else look-from/look-at, else the scene's first
// camera, else a view of the whole scene bounds from +Z, above and to the side, at a distance
// where the bounding sphere fits the vertical field of view. An unknown name is an error that
// lists the scene's cameras.
Result<RenderCamera> resolveCamera(const Scene& scene, const CameraRequest& request);

// The ray through continuous pixel position (px, py) of a width x height image ((0, 0) = top-
// left corner, pixel centres at +0.5). Unit direction.
Ray cameraRay(const RenderCamera& camera, int width, int height, float px, float py);
// The continuous pixel position where world point p appears, nullopt behind the camera.
std::optional<vec2> projectToPixel(const RenderCamera& camera, int width, int height, vec3 p);

// ---------------------------------------------------------------------------------------------
// Rendering
// ---------------------------------------------------------------------------------------------

enum class RenderMode { Preview, Reference };

struct RenderSettings {
  int width = 480;
  int height = 360;
  RenderMode mode = RenderMode::Preview;
  uint32_t samples = 64;  // reference: paths per pixel
  uint64_t seed = 0;
  int threads = 0;  // 0 = all cores
  bool showProgress = false;
  const std::atomic<bool>* cancel = nullptr;
};

struct RenderInputs {
  const Scene* scene = nullptr;          // required
  const LightmapSet* lightmaps = nullptr;  // required for the preview; optional for reference
  const ProbeSet* probes = nullptr;      // needed by the preview for probe-lit objects
  std::vector<RenderSphere> spheres;
};

struct RenderResult {
  Image radiance;  // RGB, linear outgoing radiance towards the camera per pixel
  std::vector<std::string> warnings;
};

// Renders the view. Errors: missing inputs the mode needs (lightmaps; probes when spheres
// are given in preview), lightmaps that do not match the scene, an invalid probe set for a
// volume, "cancelled" when *cancel became true.
Result<RenderResult> renderImage(const RenderInputs& inputs, const RenderCamera& camera,
                                 const RenderSettings& settings);

// ---------------------------------------------------------------------------------------------
// Display and comparison
// ---------------------------------------------------------------------------------------------

// ACES filmic curve, Narkowicz's fit (2015): f(x) = x (2.51 x + 0.03) / (x (2.43 x + 0.59) +
// 0.14), clamped to [0, 1].
float acesFilmic(float x);
// Display image (RGB in [0, 1], sRGB-encoded) from linear radiance: x 2^exposureEv, ACES per
// channel, then the sRGB transfer function. Write it with writePng.
Image toneMap(const Image& radiance, float exposureEv);

// Reads an 8-bit PNG (values / 255, no transfer function undone) or an EXR/HDR image (linear)
// as an RGB image. Errors name the file.
Result<Image> readImageFile(const std::string& path);

struct ImageComparison {
  // Over every pixel and channel: mean |a - b|, and sum |a - b| / sum |b| (b the reference).
  double meanAbsoluteDifference = 0.0;
  double relativeMeanDifference = 0.0;
  double meanA = 0.0, meanB = 0.0;  // mean values
  Image sideBySide;  // a | b | difference, RGB
  Image difference;  // |a - b| x diffScale, clamped to [0, 1], RGB
};

// Compares two RGB images of the same size (else an error naming both sizes).
Result<ImageComparison> compareImages(const Image& a, const Image& b, float diffScale = 4.0f);

}  // namespace kiln
