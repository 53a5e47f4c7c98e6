// info_command.cpp: `kiln info SCENE [--json]`, a summary of what kiln reads from a glTF
// file: objects, materials, textures, lights, cameras, probe groups, sky, scene settings,
// bounds and the loader's warnings. The text and JSON forms carry the same facts.
#include <cstdio>
#include <iostream>
#include <memory>
#include <nlohmann/json.hpp>
#include <sstream>

#include "src/light_modes.h"
#include "tools/kiln/cli_common.h"

namespace kiln::cli {
namespace {

using Json = nlohmann::json;

const char* alphaModeName(AlphaMode m) {
  switch (m) {
    case AlphaMode::Opaque:
      return "OPAQUE";
    case AlphaMode::Mask:
      return "MASK";
    case AlphaMode::Blend:
      return "BLEND";
  }
  return "?";
}

const char* lightTypeName(LightType t) {
  switch (t) {
    case LightType::Directional:
      return "directional";
    case LightType::Point:
      return "point";
    case LightType::Spot:
      return "spot";
  }
  return "?";
}

Json vecJson(vec3 v) { return Json::array({v.x, v.y, v.z}); }

size_t triangleCount(const Scene& s) {
  size_t n = 0;
  for (const Object& o : s.objects) n += o.triangles.size();
  return n;
}

// The scene settings that the file sets, as JSON (absent ones are left out).
Json settingsJson(const SceneSettings& s) {
  Json j = Json::object();
  auto put = [&j](const char* key, const auto& value) {
    if (value) j[key] = *value;
  };
  put("lightingMode", s.lightingMode);
  put("lightmapResolution", s.lightmapResolution);
  put("lightmapPadding", s.lightmapPadding);
  put("lightmapMaxSize", s.lightmapMaxSize);
  put("directionalMode", s.directionalMode);
  put("bounces", s.bounces);
  put("albedoBoost", s.albedoBoost);
  put("indirectIntensity", s.indirectIntensity);
  put("ambientOcclusion", s.ambientOcclusion);
  put("aoMaxDistance", s.aoMaxDistance);
  put("aoAmount", s.aoAmount);
  put("quality", s.quality);
  return j;
}

Json skyJson(const Sky& sky) {
  if (sky.hasMap())
    return {{"type", "map"},
            {"map", sky.path()},
            {"intensity", sky.intensity()},
            {"rotation", sky.rotationDegrees()}};
  if (sky.isBlack()) return {{"type", "none"}};
  return {{"type", "constant"}, {"color", vecJson(sky.color())}};
}

Json infoJson(const Scene& scene) {
  Json j;
  j["file"] = scene.path;
  Json objects = Json::array();
  for (const Object& o : scene.objects)
    objects.push_back(
        {{"name", o.name},
         {"node", o.nodeIndex},
         {"mesh", o.meshIndex},
         {"vertices", o.positions.size()},
         {"triangles", o.triangles.size()},
         {"hasUV0", !o.uv0.empty()},
         {"hasUV1", !o.uv1.empty()},
         {"static", o.settings.isStatic},
         {"scaleInLightmap", o.settings.scaleInLightmap},
         {"receiveGI", o.settings.receiveGI == ReceiveGI::Probes ? "probes" : "lightmaps"},
         {"lppv", o.settings.lppv}});
  j["objectCount"] = scene.objects.size();
  j["triangleCount"] = triangleCount(scene);
  j["objects"] = std::move(objects);
  Json materials = Json::array();
  for (const Material& m : scene.materials)
    materials.push_back({{"name", m.name},
                         {"alphaMode", alphaModeName(m.alphaMode)},
                         {"doubleSided", m.doubleSided},
                         {"emissive", m.isEmissive()},
                         {"emissiveFactor", vecJson(m.emissiveFactor)},
                         {"emissiveStrength", m.emissiveStrength},
                         {"baseColorTexture", m.baseColorTexture},
                         {"emissiveTexture", m.emissiveTexture}});
  j["materials"] = std::move(materials);
  Json textures = Json::array();
  for (const Texture& t : scene.textures)
    textures.push_back({{"name", t.name}, {"width", t.image.width}, {"height", t.image.height}});
  j["textures"] = std::move(textures);
  Json lights = Json::array();
  for (const Light& l : scene.lights)
    lights.push_back({{"name", l.name},
                      {"type", lightTypeName(l.type)},
                      {"mode", lightModeName(l.mode)},
                      {"intensity", l.intensity},
                      {"color", vecJson(l.color)}});
  j["lights"] = std::move(lights);
  Json cameras = Json::array();
  for (const Camera& c : scene.cameras) {
    Json cj = {{"name", c.name},
               {"type", c.perspective ? "perspective" : "orthographic"},
               {"position", vecJson(vec3(c.worldFromCamera[3]))}};
    if (c.perspective)
      cj["yfov"] = c.yfov;
    else
      cj["xmag"] = c.xmag, cj["ymag"] = c.ymag;
    cameras.push_back(std::move(cj));
  }
  j["cameras"] = std::move(cameras);
  Json probes = Json::array();
  for (const ProbeGroup& g : scene.probeGroups)
    probes.push_back({{"name", g.name}, {"probes", g.positions.size()}});
  j["probeGroups"] = std::move(probes);
  j["sky"] = skyJson(scene.sky);
  j["settings"] = settingsJson(scene.settings);
  if (scene.bounds.empty())
    j["bounds"] = nullptr;
  else
    j["bounds"] = {{"min", vecJson(scene.bounds.min)}, {"max", vecJson(scene.bounds.max)}};
  j["warnings"] = scene.warnings;
  return j;
}

std::string fmt(float v) {
  char buf[32];
  std::snprintf(buf, sizeof buf, "%g", double(v));
  return buf;
}
std::string fmt(vec3 v) { return "(" + fmt(v.x) + ", " + fmt(v.y) + ", " + fmt(v.z) + ")"; }

void printText(const Scene& scene, std::ostream& out) {
  out << "file: " << scene.path << "\n";
  out << "objects: " << scene.objects.size() << "\n";
  for (const Object& o : scene.objects)
    out << "  " << o.name << ": " << o.triangles.size() << " triangles, UV1 "
        << (o.uv1.empty() ? "no" : "yes") << ", " << (o.settings.isStatic ? "static" : "dynamic")
        << (o.settings.scaleInLightmap != 1.0f
                ? ", scaleInLightmap " + fmt(o.settings.scaleInLightmap)
                : "")
        << (o.settings.receiveGI == ReceiveGI::Probes ? ", receives GI from probes" : "")
        << (o.settings.lppv ? ", LPPV" : "") << "\n";
  out << "triangles: " << triangleCount(scene) << "\n";
  out << "materials: " << scene.materials.size() << "\n";
  for (const Material& m : scene.materials) {
    out << "  " << m.name << ": " << alphaModeName(m.alphaMode);
    if (m.alphaMode == AlphaMode::Mask) out << " (cutoff " << fmt(m.alphaCutoff) << ")";
    if (m.doubleSided) out << ", double-sided";
    if (m.isEmissive())
      out << ", emissive " << fmt(m.emissiveFactor * m.emissiveStrength)
          << (m.emissiveTexture >= 0 ? " x texture" : "");
    out << "\n";
  }
  out << "textures: " << scene.textures.size() << "\n";
  for (const Texture& t : scene.textures)
    out << "  " << t.name << ": " << t.image.width << "x" << t.image.height << "\n";
  out << "lights: " << scene.lights.size() << "\n";
  for (const Light& l : scene.lights)
    out << "  " << l.name << ": " << lightTypeName(l.type) << ", " << lightModeName(l.mode)
        << ", intensity " << fmt(l.intensity) << (l.type == LightType::Directional ? " lx" : " cd")
        << ", colour " << fmt(l.color) << "\n";
  out << "cameras: " << scene.cameras.size() << "\n";
  for (const Camera& c : scene.cameras)
    out << "  " << c.name << ": " << (c.perspective ? "perspective" : "orthographic") << " at "
        << fmt(vec3(c.worldFromCamera[3])) << "\n";
  out << "probe groups: " << scene.probeGroups.size() << "\n";
  for (const ProbeGroup& g : scene.probeGroups)
    out << "  " << g.name << ": " << g.positions.size() << " probes\n";
  out << "sky: ";
  if (scene.sky.hasMap())
    out << "map " << scene.sky.path() << " x " << fmt(scene.sky.intensity()) << ", rotated "
        << fmt(scene.sky.rotationDegrees()) << " degrees\n";
  else if (scene.sky.isBlack())
    out << "none\n";
  else
    out << "constant " << fmt(scene.sky.color()) << "\n";
  Json settings = settingsJson(scene.settings);
  out << "scene settings: " << settings.size() << "\n";
  for (auto it = settings.begin(); it != settings.end(); ++it)
    out << "  " << it.key() << ": " << it.value().dump() << "\n";
  out << "bounds: ";
  if (scene.bounds.empty())
    out << "empty\n";
  else
    out << fmt(scene.bounds.min) << " to " << fmt(scene.bounds.max) << "\n";
  out << "warnings: " << scene.warnings.size() << "\n";
  for (const std::string& w : scene.warnings) out << "  " << w << "\n";
}

}  // namespace

void registerInfoCommand(CLI::App& app) {
  struct Options {
    std::string scene;
    int gltfScene = -1;  // --scene
    bool json = false;
  };
  auto options = std::make_shared<Options>();
  CLI::App* sub = app.add_subcommand("info", "Summarize what kiln reads from a glTF scene");
  sub->add_option("scene", options->scene, "glTF 2.0 file (.gltf or .glb)")->required();
  sub->add_option("--scene", options->gltfScene, "glTF scene to load, numbered from 0 (default: the file's 'scene', else 0)")
      ->check(CLI::NonNegativeNumber);
  sub->add_flag("--json", options->json, "Print the summary as a JSON object");
  sub->callback(commandCallback([options]() {
    Scene scene;
    // Warnings are part of the report itself, so they are not also printed to stderr.
    LoadOptions load;
    load.scene = options->gltfScene;
    if (int code = loadSceneOrReport(options->scene, load, &scene, false)) return code;
    if (options->json)
      std::cout << infoJson(scene).dump(2) << "\n";
    else
      printText(scene, std::cout);
    return kExitOk;
  }));
}

}  // namespace kiln::cli
