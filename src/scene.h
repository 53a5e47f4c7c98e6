// scene.h: kiln's scene model, what the glTF loader produces and every stage consumes.
//
// Everything is flattened into world space when loaded: one Object per glTF node that has a
// mesh (its primitives concatenated), lights and cameras with their world transforms.
// Conventions (MISSION.md): glTF axes (+Y up), metres; front faces wind counter-clockwise
// (nodes with a mirroring transform have their winding flipped so this still holds);
// light intensities in glTF units (lux, candela), no 683 factor.
#pragma once

#include <optional>
#include <string>
#include <vector>

#include "src/math.h"
#include "src/sky.h"
#include "src/texture.h"

namespace kiln {

enum class AlphaMode { Opaque, Mask, Blend };

struct Material {
  std::string name;
  vec4 baseColorFactor{1.0f};
  int baseColorTexture = -1;  // index into Scene::textures, -1 = none
  int baseColorTexCoord = 0;  // which UV set the texture uses (0 or 1)
  TextureTransform baseColorTransform;  // KHR_texture_transform (also the cutout's alpha)
  float metallic = 1.0f;      // glTF defaults
  float roughness = 1.0f;
  AlphaMode alphaMode = AlphaMode::Opaque;
  float alphaCutoff = 0.5f;
  bool doubleSided = false;
  vec3 emissiveFactor{0.0f};
  int emissiveTexture = -1;
  int emissiveTexCoord = 0;
  TextureTransform emissiveTransform;
  float emissiveStrength = 1.0f;  // KHR_materials_emissive_strength

  bool isEmissive() const { return maxComponent(emissiveFactor) * emissiveStrength > 0.0f; }
};

// Per-node settings from the node's extras.kiln (MISSION.md "Scene input").
enum class ReceiveGI { Lightmaps, Probes };
struct ObjectSettings {
  // "static" (Unity's Contribute GI): a static object casts shadows, bounces and emits light
  // into the baked data (lightmaps, probes, probe placement and visibility) and can get a
  // lightmap. A dynamic one (false) is left out of every bake (the baking Tracer does not
  // hold it, src/tracer.h), gets no lightmap and is lit by the probes at run time.
  bool isStatic = true;
  float scaleInLightmap = 1.0f;  // 0 = no lightmap, still casts and bounces
  // "castShadows" (Beast's Cast Shadows): false = the object does not block the shadow rays
  // of punctual lights (KHR_lights_punctual), its own included; it still gets a lightmap,
  // bounces light, emits, and blocks every other ray (paths, sky and emitter samples).
  bool castShadows = true;
  ReceiveGI receiveGI = ReceiveGI::Lightmaps;
  bool lppv = false;  // use a light probe proxy volume (dynamic objects)
};

// One glTF node with a mesh, in world space.
struct Object {
  std::string name;  // the glTF node name, or "nodes[N]" when it has none
  int nodeIndex = -1;
  int meshIndex = -1;
  std::vector<vec3> positions;  // world space
  std::vector<vec3> normals;    // world space, unit length (generated when missing)
  std::vector<vec2> uv0;        // empty when the mesh has no TEXCOORD_0
  std::vector<vec2> uv1;        // empty when the mesh has no TEXCOORD_1 (lightmap UVs)
  std::vector<uvec3> triangles;           // counter-clockwise = front
  std::vector<uint32_t> triangleMaterial;  // index into Scene::materials, per triangle
  ObjectSettings settings;
  // Set by generateMissingLightmapUvs (lightmap/uv_unwrap.h) under the automatic probe-lit
  // rule: its generated charts were too thin for a lightmap (atlas.h chartsTooThin), so it
  // has no UV1 and is lit by probes (atlas.h tooSmallForLightmap).
  bool thinCharts = false;

  // Unit geometric normal of triangle t (front side), and its world-space area.
  vec3 faceNormal(uint32_t t) const;
  float triangleArea(uint32_t t) const;
  float surfaceArea() const;
};

enum class LightType { Directional, Point, Spot };
enum class LightMode { Baked, Mixed, Realtime };

// A KHR_lights_punctual light with kiln's per-light settings (extras.kiln).
struct Light {
  std::string name;  // the light's name, or "lights[N]"
  int lightIndex = -1;
  int nodeIndex = -1;
  LightType type = LightType::Point;
  vec3 color{1.0f};
  float intensity = 1.0f;    // lux (directional) or candela (point, spot)
  vec3 position{0.0f};       // world (point, spot)
  vec3 direction{0, 0, -1};  // world, unit: the direction light travels (node's -Z)
  float range = 0.0f;        // 0 = unlimited
  float innerConeAngle = 0.0f;        // radians (spot)
  float outerConeAngle = kPi / 4.0f;  // radians (spot)
  LightMode mode = LightMode::Baked;
  float bounceIntensity = 1.0f;  // scales this light's light after its first bounce
  float shadowRadius = 0.0f;     // metres, point/spot soft shadows (0 = hard)
  float shadowAngle = 0.0f;      // degrees, directional soft shadows: the cone's full angle
  int shadowSamples = 1;         // shadow rays per light evaluation
  // "bakedShadows" (Beast's per-light Cast Shadows): false = this light's baked light
  // (direct, bounced, shadowmask, probe occlusion) ignores occlusion: no shadow rays. Realtime
  // lights are never baked and keep their shadows.
  bool bakedShadows = true;

  // Radiance-free description of what reaches a point: irradiance on a surface facing the
  // light (lux, i.e. W/m^2 in kiln's units) before visibility, at world point p. Zero
  // outside the range or the cone. Directional: color * intensity.
  vec3 irradianceAt(vec3 p) const;
  // Unit direction from p towards the light (directional: -direction).
  vec3 directionTo(vec3 p) const;
  // Distance from p to the light (directional: infinity).
  float distanceTo(vec3 p) const;
};

struct Camera {
  std::string name;
  int nodeIndex = -1;
  bool perspective = true;
  float yfov = 0.8f;          // radians (perspective)
  float aspectRatio = 0.0f;   // 0 = unspecified
  float znear = 0.01f;
  float zfar = 0.0f;          // 0 = infinite
  float xmag = 1.0f, ymag = 1.0f;  // orthographic half extents
  mat4 worldFromCamera{1.0f};      // camera looks down its -Z, +Y up
};

// User-placed light probe positions (a node's extras.kiln.probes), world space.
struct ProbeGroup {
  std::string name;
  int nodeIndex = -1;
  std::vector<vec3> positions;
};

// Scene-wide settings from the scene's extras.kiln. Absent values stay unset so that the
// command line can override them and the tools can apply their own defaults.
struct SceneSettings {
  std::optional<std::string> lightingMode;     // "baked-indirect" | "shadowmask" | "subtractive"
  std::optional<float> lightmapResolution;     // texels per world unit
  std::optional<int> lightmapPadding;          // texels
  std::optional<int> lightmapMaxSize;          // texels
  std::optional<std::string> directionalMode;  // "non-directional" | "directional" | "sh"
  std::optional<int> bounces;
  std::optional<float> albedoBoost;
  std::optional<float> indirectIntensity;
  std::optional<bool> ambientOcclusion;
  std::optional<float> aoMaxDistance;
  std::optional<float> aoAmount;
  std::optional<std::string> quality;  // preset name
  std::optional<vec3> shadowColor;     // Subtractive's realtime shadow colour (E / pi units)
};

struct Scene {
  std::string path;  // the file it was loaded from (for messages)
  std::vector<Object> objects;
  std::vector<Material> materials;  // the last one is glTF's default material when used
  std::vector<Texture> textures;
  std::vector<Light> lights;
  std::vector<Camera> cameras;
  std::vector<ProbeGroup> probeGroups;
  Sky sky;
  SceneSettings settings;
  Bounds3 bounds;  // of all object vertices
  std::vector<std::string> warnings;
  int gltfScene = -1;  // the glTF scenes[] index loaded (-1: the file has no scenes)

  // Base colour (rgb) and alpha at a point of a triangle, given its barycentrics (b1, b2)
  // in Embree's convention (p = (1-b1-b2) p0 + b1 p1 + b2 p2): factor x texture at UV0.
  vec4 baseColorAt(uint32_t object, uint32_t triangle, vec2 bary) const;
  // Emitted radiance of the triangle's front face (and back face when double-sided) at a
  // point: emissiveFactor x strength x emissive texture.
  vec3 emissionAt(uint32_t object, uint32_t triangle, vec2 bary) const;
  // The albedo light bounces with (MISSION.md): dielectrics are Lambertian with their base
  // colour; metals add specular x roughness x 0.5 as Unity's meta pass does:
  // albedo = base * (1 - metallic) + base * metallic * roughness * 0.5.
  vec3 bounceAlbedoAt(uint32_t object, uint32_t triangle, vec2 bary) const;
  // The same albedo from a material and its base colour (rgb) at the point: what
  // bounceAlbedoAt returns, so that callers may evaluate untextured materials once.
  static vec3 bounceAlbedo(const Material& m, vec3 baseColor);
  // Shading normal (interpolated vertex normals, unit length) at a point of a triangle.
  vec3 shadingNormalAt(uint32_t object, uint32_t triangle, vec2 bary) const;
  vec3 positionAt(uint32_t object, uint32_t triangle, vec2 bary) const;
  const Material& materialOf(uint32_t object, uint32_t triangle) const {
    return materials[objects[object].triangleMaterial[triangle]];
  }

  // Recomputes `bounds` from the objects.
  void updateBounds();
};

}  // namespace kiln
