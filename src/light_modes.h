// light_modes.h: what each light contributes to baked data under a lighting mode (Unity's
// Mixed Lighting modes), and the shadowmask channel of every mixed light.
//
// Per light mode (extras.kiln.mode) and scene lighting mode:
//   realtime                 -> nothing is baked (neither lightmaps nor probes);
//   baked                    -> direct and indirect light baked;
//   mixed, baked-indirect    -> indirect light only; the game adds direct light in real time;
//   mixed, shadowmask        -> indirect light only, plus the light's visibility in its
//                               shadowmask channel; a mixed light that gets no channel (more
//                               than 4 overlap) is baked fully instead, with a warning;
//   mixed, subtractive       -> direct and indirect baked (the game subtracts the main light
//                               in realtime shadow).
// Shadowmask channels are assigned by greedy graph colouring of the lights whose influence
// overlaps: a directional light overlaps every light; point and spot lights are bounded by
// the sphere of their range (no range: unbounded), a conservative test for spots. Lights are
// coloured in a fixed order (directional lights first, then by decreasing intensity, then by
// index), each taking the lowest channel no overlapping coloured light holds.
#pragma once

#include <string>
#include <vector>

#include "kiln/result.h"
#include "src/scene.h"

namespace kiln {

enum class LightingMode { BakedIndirect, Shadowmask, Subtractive };

// "baked-indirect", "shadowmask" or "subtractive"; an error lists the valid names.
Result<LightingMode> parseLightingMode(const std::string& name);
const char* lightingModeName(LightingMode mode);
// A light's mode as glTF's extras.kiln.mode spells it: "baked", "mixed" or "realtime".
const char* lightModeName(LightMode mode);

inline constexpr int kShadowmaskChannels = 4;

struct LightModePlan {
  LightingMode mode = LightingMode::BakedIndirect;
  std::vector<bool> bakeDirect;          // per light: its direct light goes into baked data
  std::vector<bool> bakeIndirect;        // per light: its bounced light goes into baked data
  std::vector<int> shadowmaskChannel;    // per light: 0..3, or -1
  std::vector<std::string> warnings;     // lights that fell back to baked
};

// True when the influence regions of two lights can overlap (see the header comment).
bool lightsOverlap(const Light& a, const Light& b);

LightModePlan planLightModes(const Scene& scene, LightingMode mode);

}  // namespace kiln
