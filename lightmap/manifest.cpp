// manifest.cpp: kiln bake's manifest.json, its writer and its reader (see manifest.h).
#include "lightmap/manifest.h"

#include <array>
#include <cmath>
#include <filesystem>
#include <limits>
#include <set>

#include "lightmap/atlas.h"
#include "lightmap/lightmap_baker.h"
#include "src/text_file.h"

namespace kiln {
namespace {

using Json = nlohmann::json;

// The kinds of page file, in the order the reader reports them.
constexpr std::pair<const char*, std::string ManifestFiles::*> kFileKinds[] = {
    {"light", &ManifestFiles::light},         {"ao", &ManifestFiles::ao},
    {"direction", &ManifestFiles::direction}, {"shadowmask", &ManifestFiles::shadowmask},
    {"lightLdr", &ManifestFiles::lightLdr},   {"coverage", &ManifestFiles::coverage},
};

Json pageJson(const ManifestPage& page, size_t index) {
  Json files = Json::object();
  for (const auto& [key, member] : kFileKinds)
    if (!(page.files.*member).empty()) files[key] = page.files.*member;
  Json j = {{"index", index}, {"width", page.width}, {"height", page.height}};
  if (!files.empty()) j["files"] = std::move(files);  // the atlas alone has no files
  return j;
}

// An integer in [lo, hi] (JSON integers may be signed or unsigned 64-bit).
bool readInt(const Json& j, int64_t lo, int64_t hi, int64_t& out) {
  if (j.is_number_unsigned()) {
    const uint64_t v = j.get<uint64_t>();
    if (v > uint64_t(std::numeric_limits<int64_t>::max()) || int64_t(v) < lo || int64_t(v) > hi)
      return false;
    out = int64_t(v);
    return true;
  }
  if (!j.is_number_integer()) return false;
  const int64_t v = j.get<int64_t>();
  if (v < lo || v > hi) return false;
  out = v;
  return true;
}

bool readInt(const Json& j, int64_t lo, int64_t hi, int& out) {
  int64_t v = 0;
  if (!readInt(j, lo, hi, v)) return false;
  out = int(v);
  return true;
}

// A number that is finite as a float.
bool readFloat(const Json& j, float& out) {
  if (!j.is_number()) return false;
  const double v = j.get<double>();
  if (!std::isfinite(v) || std::abs(v) > double(std::numeric_limits<float>::max())) return false;
  out = float(v);
  return true;
}

bool readFloats(const Json& j, float* out, size_t count) {
  if (!j.is_array() || j.size() != count) return false;
  for (size_t i = 0; i < count; ++i)
    if (!readFloat(j[i], out[i])) return false;
  return true;
}

// A file name the manifest may give: relative, inside the manifest's folder.
bool plainFileName(const std::string& name) {
  if (name.empty()) return false;
  const std::filesystem::path p(name);
  if (p.is_absolute() || p.has_root_name() || p.has_root_directory()) return false;
  for (const auto& part : p)
    if (part == "..") return false;
  return true;
}

// Reads settings' fields of ManifestSettingsFields. Returns an error message naming the field.
std::optional<std::string> readSettingsFields(const Json& s, ManifestSettingsFields& f) {
  auto has = [&](const char* key) { return s.contains(key) && !s[key].is_null(); };
  if (has("resolution")) {
    float v = 0.0f;
    if (!readFloat(s["resolution"], v) || !(v > 0.0f))
      return std::string("settings.resolution: expected a number > 0 (texels per unit)");
    f.resolution = v;
  }
  for (auto [key, field, lo] :
       {std::tuple{"padding", &f.padding, 0}, std::tuple{"maxSize", &f.maxSize, 1}}) {
    if (!has(key)) continue;
    int v = 0;
    if (!readInt(s[key], lo, kMaxManifestPageSize, v))
      return "settings." + std::string(key) + ": expected an integer in " + std::to_string(lo) +
             ".." + std::to_string(kMaxManifestPageSize);
    *field = v;
  }
  if (has("bounces")) {
    int v = 0;
    if (!readInt(s["bounces"], 0, 1 << 20, v))
      return std::string("settings.bounces: expected an integer >= 0");
    f.bounces = v;
  }
  if (has("albedoBoost")) {
    float v = 0.0f;
    if (!readFloat(s["albedoBoost"], v) || !(v > 0.0f))
      return std::string("settings.albedoBoost: expected a number > 0");
    f.albedoBoost = v;
  }
  if (has("indirectIntensity")) {
    float v = 0.0f;
    if (!readFloat(s["indirectIntensity"], v) || v < 0.0f)
      return std::string("settings.indirectIntensity: expected a number >= 0");
    f.indirectIntensity = v;
  }
  if (has("lightingMode")) {
    if (!s["lightingMode"].is_string())
      return std::string("settings.lightingMode: expected a string");
    Result<LightingMode> mode = parseLightingMode(s["lightingMode"].get<std::string>());
    if (!mode) return "settings.lightingMode: " + mode.error();
    f.lightingMode = *mode;
  }
  if (has("shadowColor")) {
    vec3 c(0.0f);
    if (!readFloats(s["shadowColor"], &c.x, 3))
      return std::string("settings.shadowColor: expected 3 finite numbers");
    f.shadowColor = c;
  }
  if (has("atlasUv")) {
    if (!s["atlasUv"].is_boolean()) return std::string("settings.atlasUv: expected true or false");
    f.atlasUv = s["atlasUv"].get<bool>();
  }
  return std::nullopt;
}

}  // namespace

vec4 unityLightmapScaleOffset(vec4 so) {
  return vec4(so.x, so.y, so.z, float(1.0 - double(so.y) - double(so.w)));
}

Manifest atlasManifest(const AtlasLayout& layout, const Scene& scene) {
  Manifest m;
  for (const AtlasPage& p : layout.pages) m.lightmaps.push_back({p.width, p.height, {}});
  for (size_t i = 0; i < layout.objects.size() && i < scene.objects.size(); ++i) {
    const AtlasObject& o = layout.objects[i];
    m.objects.push_back(
        {scene.objects[i].name, scene.objects[i].nodeIndex, o.lightmapIndex, o.scaleOffset,
         o.probeLit});
  }
  return m;
}

Manifest bakeManifest(const LightmapBakeResult& result, const std::string& scenePath) {
  Manifest m = atlasManifest(result.layout, result.scene);
  // Every scene light: its name and mode as the glTF gives them, what the lighting mode baked
  // of it, and its shadowmask channel (-1: none).
  const LightModePlan& plan = result.lightModes;
  std::vector<ManifestLight> lights;
  for (size_t l = 0; l < result.scene.lights.size(); ++l) {
    const Light& light = result.scene.lights[l];
    ManifestLight e;
    e.name = light.name;
    e.lightIndex = light.lightIndex;
    e.nodeIndex = light.nodeIndex;
    e.mode = lightModeName(light.mode);
    if (l < plan.bakeDirect.size()) e.bakedDirect = bool(plan.bakeDirect[l]);
    if (l < plan.bakeIndirect.size()) e.bakedIndirect = bool(plan.bakeIndirect[l]);
    if (l < plan.shadowmaskChannel.size()) e.shadowmaskChannel = plan.shadowmaskChannel[l];
    lights.push_back(e);
  }
  m.lights = std::move(lights);
  bool withShadowmask = false;
  for (int c : plan.shadowmaskChannel) withShadowmask |= c >= 0;
  for (size_t i = 0; i < m.objects.size() && i < result.objectProbes.size(); ++i)
    if (const std::optional<ObjectProbe>& probe = result.objectProbes[i]) {
      m.objects[i].probeSh = probe->sh;
      if (withShadowmask) m.objects[i].probeOcclusion = probe->occlusion;
    }
  m.scene = std::filesystem::path(scenePath).filename().string();
  m.warnings = result.warnings;
  m.stats.texels = result.stats.texels;
  m.stats.invalidTexels = result.stats.invalidTexels;
  m.stats.rays = result.stats.rays;
  m.stats.clampedTexels = result.stats.clampedTexels;
  m.stats.minSamples = result.stats.minSamples;
  m.stats.maxSamples = result.stats.maxSamples;
  m.stats.meanSamples = result.stats.meanSamples;
  const auto& histogram = result.stats.raysPerTexelHistogram;
  size_t used = histogram.size();
  while (used > 0 && histogram[used - 1] == 0) --used;
  m.stats.raysPerTexelHistogram.assign(histogram.begin(), histogram.begin() + used);
  return m;
}

Json manifestPagesJson(const Manifest& manifest) {
  Json pages = Json::array();
  for (size_t i = 0; i < manifest.lightmaps.size(); ++i)
    pages.push_back(pageJson(manifest.lightmaps[i], i));
  return pages;
}

Json manifestJson(const Manifest& m) {
  Json j;
  j["version"] = m.version;
  j["lightmaps"] = manifestPagesJson(m);
  Json objects = Json::array();
  for (const ManifestObject& o : m.objects) {
    const vec4 so = o.scaleOffset, uso = unityLightmapScaleOffset(so);
    objects.push_back({{"node", o.node},
                       {"nodeIndex", o.nodeIndex},
                       {"lightmapIndex", o.lightmapIndex},
                       {"scaleOffset", {so.x, so.y, so.z, so.w}},
                       {"unityScaleOffset", {uso.x, uso.y, uso.z, uso.w}}});
    if (o.probeLit) objects.back()["probeLit"] = true;
    if (o.probeSh) {
      Json sh = Json::array();
      for (const vec3& c : o.probeSh->c) sh.insert(sh.end(), {c.x, c.y, c.z});
      objects.back()["probeSH"] = std::move(sh);
    }
    if (o.probeOcclusion) {
      const vec4 v = *o.probeOcclusion;
      objects.back()["probeOcclusion"] = {v.x, v.y, v.z, v.w};
    }
  }
  j["objects"] = std::move(objects);
  j["settings"] = m.settings;
  if (m.lights) {
    Json lights = Json::array();
    for (const ManifestLight& l : *m.lights) {
      Json e = {{"name", l.name},
                {"lightIndex", l.lightIndex},
                {"nodeIndex", l.nodeIndex},
                {"mode", l.mode}};
      if (l.bakedDirect) e["bakedDirect"] = *l.bakedDirect;
      if (l.bakedIndirect) e["bakedIndirect"] = *l.bakedIndirect;
      if (l.shadowmaskChannel) e["shadowmaskChannel"] = *l.shadowmaskChannel;
      lights.push_back(std::move(e));
    }
    j["lights"] = std::move(lights);
  }
  if (m.gltf) j["gltf"] = *m.gltf;
  j["scene"] = m.scene;
  j["warnings"] = m.warnings;
  // No times: the files stay deterministic.
  j["stats"] = {
      {"texels", m.stats.texels}, {"invalidTexels", m.stats.invalidTexels}, {"rays", m.stats.rays},
      {"clampedTexels", m.stats.clampedTexels},
      {"samplesPerTexel",
       {{"min", m.stats.minSamples}, {"mean", m.stats.meanSamples}, {"max", m.stats.maxSamples}}},
      {"raysPerTexel", m.stats.raysPerTexelHistogram}};
  return j;
}

std::string manifestText(const Manifest& manifest) { return manifestJson(manifest).dump(2) + "\n"; }

Result<Manifest> readManifest(const Json& j, const std::string& where, ManifestUse use) {
  auto fail = [&](const std::string& field, const std::string& what) -> Result<Manifest> {
    return Error{where + ": " + field + ": " + what};
  };
  if (!j.is_object()) return Error{where + ": expected a JSON object"};
  Manifest m;
  if (j.contains("version") || use == ManifestUse::kLightmaps) {
    if (!j.contains("version") ||
        !readInt(j["version"], kManifestVersion, kManifestVersion, m.version))
      return fail("version", "expected " + std::to_string(kManifestVersion));
  }
  if (!j.contains("lightmaps") || !j["lightmaps"].is_array())
    return fail("lightmaps", "expected an array");
  if (!j.contains("objects") || !j["objects"].is_array())
    return fail("objects", "expected an array");

  // Settings first: pages are checked against maxSize.
  if (j.contains("settings")) {
    if (!j["settings"].is_object()) return fail("settings", "expected an object");
    m.settings = j["settings"];
    if (std::optional<std::string> e = readSettingsFields(m.settings, m.settingsFields))
      return Error{where + ": " + *e};
  }

  const Json& pages = j["lightmaps"];
  m.lightmaps.resize(pages.size());
  std::vector<bool> seen(pages.size(), false);
  for (size_t i = 0; i < pages.size(); ++i) {
    const std::string at = "lightmaps[" + std::to_string(i) + "]";
    const Json& p = pages[i];
    if (!p.is_object()) return fail(at, "expected an object");
    int64_t index = -1;
    if (!p.contains("index") || !readInt(p["index"], 0, int64_t(pages.size()) - 1, index) ||
        seen[size_t(index)])
      return fail(at + ".index",
                  "expected a unique integer in [0, " + std::to_string(pages.size()) + ")");
    seen[size_t(index)] = true;
    ManifestPage& page = m.lightmaps[size_t(index)];
    for (auto [key, value] : {std::pair{"width", &page.width}, std::pair{"height", &page.height}}) {
      if (!p.contains(key) || !readInt(p[key], 1, kMaxManifestPageSize, *value))
        return fail(at + "." + key,
                    "expected an integer in 1.." + std::to_string(kMaxManifestPageSize));
      if (m.settingsFields.maxSize && *value > *m.settingsFields.maxSize)
        return fail(at + "." + key, std::to_string(*value) + " exceeds settings.maxSize " +
                                        std::to_string(*m.settingsFields.maxSize));
    }
    if (p.contains("files")) {
      const Json& files = p["files"];
      if (!files.is_object()) return fail(at + ".files", "expected an object");
      for (const auto& [key, member] : kFileKinds) {
        if (!files.contains(key)) continue;
        if (!files[key].is_string() || !plainFileName(files[key].get<std::string>()))
          return fail(at + ".files." + key,
                      "expected a file name in the manifest's folder (relative, no \"..\")");
        page.files.*member = files[key].get<std::string>();
      }
    }
    if (use == ManifestUse::kLightmaps && page.files.light.empty())
      return fail(at + ".files.light", "expected a file name");
  }

  const Json& objects = j["objects"];
  std::set<int> nodes;
  for (size_t i = 0; i < objects.size(); ++i) {
    const std::string at = "objects[" + std::to_string(i) + "]";
    const Json& e = objects[i];
    if (!e.is_object()) return fail(at, "expected an object");
    ManifestObject o;
    if (!e.contains("nodeIndex") ||
        !readInt(e["nodeIndex"], 0, std::numeric_limits<int32_t>::max(), o.nodeIndex))
      return fail(at + ".nodeIndex", "expected an integer >= 0");
    if (!nodes.insert(o.nodeIndex).second)
      return fail(at + ".nodeIndex", "node " + std::to_string(o.nodeIndex) + " listed twice");
    if (!e.contains("node") || !e["node"].is_string())
      return fail(at + ".node", "expected the node's name");
    o.node = e["node"].get<std::string>();
    if (!e.contains("lightmapIndex") ||
        !readInt(e["lightmapIndex"], -1, int64_t(m.lightmaps.size()) - 1, o.lightmapIndex))
      return fail(at + ".lightmapIndex",
                  "expected -1 or a page index below " + std::to_string(m.lightmaps.size()));
    if (e.contains("scaleOffset") || o.lightmapIndex >= 0)
      if (!e.contains("scaleOffset") || !readFloats(e["scaleOffset"], &o.scaleOffset.x, 4))
        return fail(at + ".scaleOffset", "expected 4 finite numbers [sx, sy, ox, oy]");
    if (e.contains("probeLit")) {
      if (!e["probeLit"].is_boolean())
        return fail(at + ".probeLit", "expected true or false");
      o.probeLit = e["probeLit"].get<bool>();
      if (o.probeLit && o.lightmapIndex >= 0)
        return fail(at + ".probeLit", "a probe-lit object has lightmapIndex -1");
    }
    if (e.contains("probeSH")) {
      std::array<float, 3 * kShL2Count> v{};
      if (!readFloats(e["probeSH"], v.data(), v.size()))
        return fail(at + ".probeSH",
                    "expected 27 finite numbers (9 radiance SH coefficients x R, G, B)");
      if (!o.probeLit) return fail(at + ".probeSH", "only a probe-lit object has one");
      ShL2Rgb sh;
      for (int k = 0; k < kShL2Count; ++k)
        sh.c[size_t(k)] = vec3(v[size_t(3 * k)], v[size_t(3 * k + 1)], v[size_t(3 * k + 2)]);
      o.probeSh = sh;
    }
    if (e.contains("probeOcclusion")) {
      vec4 v(1.0f);
      if (!readFloats(e["probeOcclusion"], &v.x, 4) || glm::any(glm::lessThan(v, vec4(0.0f))) ||
          glm::any(glm::greaterThan(v, vec4(1.0f))))
        return fail(at + ".probeOcclusion", "expected 4 numbers in [0, 1]");
      if (!o.probeLit) return fail(at + ".probeOcclusion", "only a probe-lit object has one");
      o.probeOcclusion = v;
    }
    m.objects.push_back(std::move(o));
  }

  if (j.contains("lights")) {
    const Json& lights = j["lights"];
    if (!lights.is_array()) return fail("lights", "expected an array");
    m.lights.emplace();
    for (size_t l = 0; l < lights.size(); ++l) {
      const std::string at = "lights[" + std::to_string(l) + "]";
      const Json& e = lights[l];
      if (!e.is_object()) return fail(at, "expected an object");
      ManifestLight light;
      for (auto [key, field] : {std::pair{"name", &light.name}, std::pair{"mode", &light.mode}}) {
        if (!e.contains(key)) continue;
        if (!e[key].is_string()) return fail(at + "." + key, "expected a string");
        *field = e[key].get<std::string>();
      }
      for (auto [key, field] :
           {std::pair{"lightIndex", &light.lightIndex}, std::pair{"nodeIndex", &light.nodeIndex}})
        if (e.contains(key) && !readInt(e[key], -1, std::numeric_limits<int32_t>::max(), *field))
          return fail(at + "." + key, "expected an integer >= -1");
      for (auto [key, field] : {std::pair{"bakedDirect", &light.bakedDirect},
                                std::pair{"bakedIndirect", &light.bakedIndirect}}) {
        if (!e.contains(key)) continue;
        if (!e[key].is_boolean()) return fail(at + "." + key, "expected true or false");
        *field = e[key].get<bool>();
      }
      if (e.contains("shadowmaskChannel")) {
        int c = -1;
        if (!readInt(e["shadowmaskChannel"], -1, kShadowmaskChannels - 1, c))
          return fail(at + ".shadowmaskChannel",
                      "expected -1.." + std::to_string(kShadowmaskChannels - 1));
        light.shadowmaskChannel = c;
      }
      m.lights->push_back(std::move(light));
    }
  }

  if (j.contains("gltf")) {
    if (!j["gltf"].is_string()) return fail("gltf", "expected a file name");
    m.gltf = j["gltf"].get<std::string>();
  }
  if (j.contains("scene")) {
    if (!j["scene"].is_string()) return fail("scene", "expected a file name");
    m.scene = j["scene"].get<std::string>();
  }
  if (j.contains("warnings")) {
    const Json& w = j["warnings"];
    if (!w.is_array()) return fail("warnings", "expected an array of strings");
    for (size_t i = 0; i < w.size(); ++i) {
      if (!w[i].is_string())
        return fail("warnings[" + std::to_string(i) + "]", "expected a string");
      m.warnings.push_back(w[i].get<std::string>());
    }
  }
  if (j.contains("stats")) {
    const Json& s = j["stats"];
    if (!s.is_object()) return fail("stats", "expected an object");
    for (auto [key, field] :
         {std::pair{"texels", &m.stats.texels}, std::pair{"invalidTexels", &m.stats.invalidTexels},
          std::pair{"rays", &m.stats.rays}, std::pair{"clampedTexels", &m.stats.clampedTexels}}) {
      if (!s.contains(key)) continue;
      if (!s[key].is_number_integer() ||
          (s[key].is_number_integer() && !s[key].is_number_unsigned() && s[key].get<int64_t>() < 0))
        return fail("stats." + std::string(key), "expected an integer >= 0");
      *field = s[key].get<uint64_t>();
    }
    if (s.contains("samplesPerTexel")) {
      const Json& sp = s["samplesPerTexel"];
      if (!sp.is_object() || !sp.value("min", Json()).is_number_unsigned() ||
          !sp.value("max", Json()).is_number_unsigned() || !sp.value("mean", Json()).is_number() ||
          !(sp["mean"].get<double>() >= 0.0))
        return fail("stats.samplesPerTexel", "expected {\"min\", \"mean\", \"max\"} >= 0");
      m.stats.minSamples = sp["min"].get<uint64_t>();
      m.stats.meanSamples = sp["mean"].get<double>();
      m.stats.maxSamples = sp["max"].get<uint64_t>();
    }
    if (s.contains("raysPerTexel")) {
      const Json& h = s["raysPerTexel"];
      if (!h.is_array() || h.size() > 64)
        return fail("stats.raysPerTexel", "expected an array of at most 64 counts");
      for (const Json& b : h) {
        if (!b.is_number_unsigned())
          return fail("stats.raysPerTexel", "expected integers >= 0");
        m.stats.raysPerTexelHistogram.push_back(b.get<uint64_t>());
      }
    }
  }
  return m;
}

Result<Manifest> readManifestFile(const std::string& path, ManifestUse use) {
  Result<Json> json = readJsonFile(path);
  if (!json) return Error{json.error()};
  return readManifest(*json, path, use);
}

}  // namespace kiln
