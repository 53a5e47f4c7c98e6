// probe_reference.h: the reader of ../shared/reference/<scene>/probes.json, irradiance at
// points of a scene rendered by an independent renderer (Blender Cycles; the format is
// described in ../shared/reference/README.md). Used by chart 3 (docs/charts.md) and
// tests/probe_reference_test.cpp.
#pragma once

#include <array>
#include <string>
#include <vector>

#include "kiln/result.h"
#include "kiln/sh.h"
#include "src/math.h"

namespace kiln::chart {

// The six axis normals of the reference, in the file's order: +x, -x, +y, -y, +z, -z (glTF
// world axes).
inline constexpr const char* kReferenceAxisNames[6] = {"+x", "-x", "+y", "-y", "+z", "-z"};
inline const std::array<vec3, 6> kReferenceAxes = {vec3(1, 0, 0),  vec3(-1, 0, 0), vec3(0, 1, 0),
                                                   vec3(0, -1, 0), vec3(0, 0, 1),  vec3(0, 0, -1)};

struct ProbeReferencePoint {
  vec3 position;                     // world space, metres
  std::array<glm::dvec3, 6> exact;   // irradiance_axis: exact E (not E/pi) per axis
  std::array<glm::dvec3, 6> fromSh;  // irradiance_axis_from_sh: E of the L2 projection
  ShL2Rgb sh;                        // sh_radiance: radiance SH, kiln's basis and order
};

// Reads the reference at `path`. Errors name the file and the field ("probes.json:
// probes[3].irradiance_axis.+x: expected 3 numbers"); a header whose SH order is not kiln's
// (sh.h) is refused.
Result<std::vector<ProbeReferencePoint>> loadProbeReference(const std::string& path);

}  // namespace kiln::chart
