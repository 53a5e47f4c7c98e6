// light_modes.cpp: lighting-mode plan and shadowmask channel colouring (see light_modes.h).
#include "src/light_modes.h"

#include <algorithm>
#include <numeric>

namespace kiln {

Result<LightingMode> parseLightingMode(const std::string& name) {
  if (name == "baked-indirect") return LightingMode::BakedIndirect;
  if (name == "shadowmask") return LightingMode::Shadowmask;
  if (name == "subtractive") return LightingMode::Subtractive;
  return Error{"unknown lighting mode '" + name +
               "' (expected baked-indirect, shadowmask or subtractive)"};
}

const char* lightingModeName(LightingMode mode) {
  switch (mode) {
    case LightingMode::Shadowmask:
      return "shadowmask";
    case LightingMode::Subtractive:
      return "subtractive";
    case LightingMode::BakedIndirect:
    default:
      return "baked-indirect";
  }
}

const char* lightModeName(LightMode mode) {
  switch (mode) {
    case LightMode::Mixed:
      return "mixed";
    case LightMode::Realtime:
      return "realtime";
    case LightMode::Baked:
      break;
  }
  return "baked";
}

bool lightsOverlap(const Light& a, const Light& b) {
  if (a.type == LightType::Directional || b.type == LightType::Directional) return true;
  if (!(a.range > 0.0f) || !(b.range > 0.0f)) return true;  // unbounded influence
  return glm::length(a.position - b.position) < a.range + b.range;
}

LightModePlan planLightModes(const Scene& scene, LightingMode mode) {
  const size_t n = scene.lights.size();
  LightModePlan plan;
  plan.mode = mode;
  plan.bakeDirect.assign(n, false);
  plan.bakeIndirect.assign(n, false);
  plan.shadowmaskChannel.assign(n, -1);

  std::vector<size_t> mixed;
  for (size_t i = 0; i < n; ++i) {
    const Light& l = scene.lights[i];
    switch (l.mode) {
      case LightMode::Realtime:
        break;
      case LightMode::Baked:
        plan.bakeDirect[i] = plan.bakeIndirect[i] = true;
        break;
      case LightMode::Mixed:
        plan.bakeIndirect[i] = true;
        plan.bakeDirect[i] = mode == LightingMode::Subtractive;
        if (mode == LightingMode::Shadowmask) mixed.push_back(i);
        break;
    }
  }

  // Greedy colouring in a fixed order: the lights most likely to matter get channels first.
  std::stable_sort(mixed.begin(), mixed.end(), [&](size_t a, size_t b) {
    const Light& la = scene.lights[a];
    const Light& lb = scene.lights[b];
    const bool da = la.type == LightType::Directional, db = lb.type == LightType::Directional;
    if (da != db) return da;
    const float ia = la.intensity * luminance(la.color), ib = lb.intensity * luminance(lb.color);
    if (ia != ib) return ia > ib;
    return a < b;
  });
  for (size_t i : mixed) {
    bool taken[kShadowmaskChannels] = {};
    for (size_t j : mixed) {
      const int c = plan.shadowmaskChannel[j];
      if (j != i && c >= 0 && lightsOverlap(scene.lights[i], scene.lights[j])) taken[c] = true;
    }
    for (int c = 0; c < kShadowmaskChannels; ++c)
      if (!taken[c]) {
        plan.shadowmaskChannel[i] = c;
        break;
      }
    if (plan.shadowmaskChannel[i] < 0) {
      plan.bakeDirect[i] = true;
      plan.warnings.push_back("light '" + scene.lights[i].name +
                              "': more than 4 overlapping mixed lights, no shadowmask channel "
                              "left; baked fully instead");
    }
  }
  return plan;
}

}  // namespace kiln
