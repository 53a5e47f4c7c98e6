// scene.cpp: geometric and material queries on the scene model, and punctual-light falloff
// as MISSION.md "Conventions" fixes it (glTF's KHR_lights_punctual recommendations).
#include "src/scene.h"

namespace kiln {

namespace {

// Interpolates a per-vertex attribute with Embree's barycentrics (b1, b2).
template <typename T>
T interpolate(const std::vector<T>& attribute, uvec3 tri, vec2 bary) {
  return (1.0f - bary.x - bary.y) * attribute[tri.x] + bary.x * attribute[tri.y] +
         bary.y * attribute[tri.z];
}

float saturate(float x) { return std::clamp(x, 0.0f, 1.0f); }

vec2 texCoordAt(const Object& o, uint32_t triangle, vec2 bary, int set) {
  const auto& uv = set == 1 ? o.uv1 : o.uv0;
  if (uv.empty()) return vec2(0.0f);
  return interpolate(uv, o.triangles[triangle], bary);
}

}  // namespace

vec3 Object::faceNormal(uint32_t t) const {
  const uvec3 tri = triangles[t];
  vec3 n = glm::cross(positions[tri.y] - positions[tri.x], positions[tri.z] - positions[tri.x]);
  float len = glm::length(n);
  return len > 0.0f ? n / len : vec3(0.0f, 1.0f, 0.0f);
}

float Object::triangleArea(uint32_t t) const {
  const uvec3 tri = triangles[t];
  return 0.5f *
         glm::length(glm::cross(positions[tri.y] - positions[tri.x], positions[tri.z] - positions[tri.x]));
}

float Object::surfaceArea() const {
  double area = 0.0;
  for (uint32_t t = 0; t < triangles.size(); ++t) area += triangleArea(t);
  return float(area);
}

vec3 Light::irradianceAt(vec3 p) const {
  const vec3 radiant = color * intensity;
  if (type == LightType::Directional) return radiant;
  const vec3 toPoint = p - position;
  const float d2 = std::max(glm::dot(toPoint, toPoint), 1e-12f);
  float attenuation = 1.0f / d2;
  if (range > 0.0f) {
    // glTF's recommended window: saturate(1 - (d / range)^4)^2.
    float r4 = (d2 * d2) / (range * range * range * range);
    float w = saturate(1.0f - r4);
    attenuation *= w * w;
  }
  if (type == LightType::Spot) {
    const float cosAngle = glm::dot(direction, toPoint / std::sqrt(d2));
    const float cosOuter = std::cos(outerConeAngle);
    const float cosInner = std::cos(innerConeAngle);
    // glTF's sample implementation: t = saturate((cos - cos outer) / (cos inner - cos outer)),
    // attenuation t^2. Equal cones give a hard edge.
    float t;
    if (cosInner - cosOuter > 1e-6f)
      t = saturate((cosAngle - cosOuter) / (cosInner - cosOuter));
    else
      t = cosAngle >= cosOuter ? 1.0f : 0.0f;
    attenuation *= t * t;
  }
  return radiant * attenuation;
}

vec3 Light::directionTo(vec3 p) const {
  if (type == LightType::Directional) return -direction;
  vec3 d = position - p;
  float len = glm::length(d);
  return len > 0.0f ? d / len : vec3(0.0f, 1.0f, 0.0f);
}

float Light::distanceTo(vec3 p) const {
  return type == LightType::Directional ? kInfinity : glm::length(position - p);
}

vec4 Scene::baseColorAt(uint32_t object, uint32_t triangle, vec2 bary) const {
  const Material& m = materialOf(object, triangle);
  vec4 color = m.baseColorFactor;
  if (m.baseColorTexture >= 0) {
    vec2 uv = texCoordAt(objects[object], triangle, bary, m.baseColorTexCoord);
    color *= textures[m.baseColorTexture].sample(m.baseColorTransform.apply(uv));
  }
  return color;
}

vec3 Scene::emissionAt(uint32_t object, uint32_t triangle, vec2 bary) const {
  const Material& m = materialOf(object, triangle);
  vec3 emission = m.emissiveFactor * m.emissiveStrength;
  if (m.emissiveTexture >= 0 && maxComponent(emission) > 0.0f) {
    vec2 uv = texCoordAt(objects[object], triangle, bary, m.emissiveTexCoord);
    emission *= vec3(textures[m.emissiveTexture].sample(m.emissiveTransform.apply(uv)));
  }
  return emission;
}

vec3 Scene::bounceAlbedoAt(uint32_t object, uint32_t triangle, vec2 bary) const {
  return bounceAlbedo(materialOf(object, triangle), vec3(baseColorAt(object, triangle, bary)));
}

vec3 Scene::bounceAlbedo(const Material& m, vec3 base) {
  // Dielectrics: Lambertian with the base colour (as Cycles' diffuse bake treats them; their
  // 4% specular mostly leaves as glossy reflection a diffuse baker cannot place). Metals: no
  // diffuse; specular (F0 = base colour) x roughness x 0.5, as Unity's meta pass
  // (UnityLightmappingAlbedo) lets rough metals bounce light and shiny ones not.
  const float metallic = std::clamp(m.metallic, 0.0f, 1.0f);
  const float roughness = std::clamp(m.roughness, 0.0f, 1.0f);
  return glm::clamp(base * (1.0f - metallic) + base * metallic * roughness * 0.5f, 0.0f, 1.0f);
}

vec3 Scene::shadingNormalAt(uint32_t object, uint32_t triangle, vec2 bary) const {
  const Object& o = objects[object];
  if (o.normals.empty()) return o.faceNormal(triangle);
  vec3 n = interpolate(o.normals, o.triangles[triangle], bary);
  float len = glm::length(n);
  return len > 1e-12f ? n / len : o.faceNormal(triangle);
}

vec3 Scene::positionAt(uint32_t object, uint32_t triangle, vec2 bary) const {
  const Object& o = objects[object];
  return interpolate(o.positions, o.triangles[triangle], bary);
}

void Scene::updateBounds() {
  bounds = Bounds3();
  for (const Object& o : objects)
    for (const vec3& p : o.positions) bounds.extend(p);
}

}  // namespace kiln
