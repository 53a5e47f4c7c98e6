// probe_reference.cpp: reader of the Cycles probe reference (probe_reference.h).
#include "tools/chart/probe_reference.h"

#include <nlohmann/json.hpp>

#include "src/text_file.h"

namespace kiln::chart {

namespace {

using Json = nlohmann::json;

// An RGB triple or a position; false when `v` is not 3 numbers.
bool tripleOf(const Json& v, glm::dvec3& out) {
  if (!v.is_array() || v.size() != 3) return false;
  for (int k = 0; k < 3; ++k) {
    if (!v[size_t(k)].is_number()) return false;
    out[k] = v[size_t(k)].get<double>();
  }
  return true;
}

// parent[key] as a triple; false when missing or not 3 numbers.
bool fieldTriple(const Json& parent, const char* key, glm::dvec3& out) {
  return parent.is_object() && parent.contains(key) && tripleOf(parent[key], out);
}

}  // namespace

Result<std::vector<ProbeReferencePoint>> loadProbeReference(const std::string& path) {
  Result<Json> doc = readJsonFile(path);
  if (!doc) return Error{doc.error()};
  const std::vector<std::string> kOrder = {"Y00",  "Y1-1", "Y10", "Y11", "Y2-2",
                                           "Y2-1", "Y20",  "Y21", "Y22"};
  const Json& root = *doc;
  if (!root.is_object() || !root.contains("header") || !root["header"].is_object() ||
      !root["header"].contains("order") || root["header"]["order"] != Json(kOrder))
    return Error{path + ": header.order: expected kiln's SH order (Y00, Y1-1, ..., Y22)"};
  if (!root.contains("probes") || !root["probes"].is_array() || root["probes"].empty())
    return Error{path + ": probes: expected a non-empty array"};
  const Json& probes = root["probes"];
  std::vector<ProbeReferencePoint> points;
  for (size_t p = 0; p < probes.size(); ++p) {
    const std::string where = path + ": probes[" + std::to_string(p) + "]";
    const Json& j = probes[p];
    ProbeReferencePoint r;
    glm::dvec3 position;
    if (!fieldTriple(j, "position", position))
      return Error{where + ".position: expected 3 numbers"};
    r.position = vec3(position);
    for (const char* field : {"irradiance_axis", "irradiance_axis_from_sh"}) {
      auto& values = std::string(field) == "irradiance_axis" ? r.exact : r.fromSh;
      for (int a = 0; a < 6; ++a)
        if (!j.is_object() || !j.contains(field) ||
            !fieldTriple(j[field], kReferenceAxisNames[a], values[size_t(a)]))
          return Error{where + "." + field + "." + kReferenceAxisNames[a] + ": expected 3 numbers"};
    }
    if (!j.contains("sh_radiance") || !j["sh_radiance"].is_array() ||
        j["sh_radiance"].size() != size_t(kShL2Count))
      return Error{where + ".sh_radiance: expected 9 RGB triples"};
    for (int i = 0; i < kShL2Count; ++i) {
      glm::dvec3 c;
      if (!tripleOf(j["sh_radiance"][size_t(i)], c))
        return Error{where + ".sh_radiance[" + std::to_string(i) + "]: expected 3 numbers"};
      r.sh.c[i] = vec3(c);
    }
    points.push_back(r);
  }
  return points;
}

}  // namespace kiln::chart
