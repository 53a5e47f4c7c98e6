// directional.h: directional lightmaps (Unity's "Directional" mode) and the reference
// implementations of the shader decodes of kiln's baked mixed-lighting data (shadowmask,
// subtractive), so that tests check exactly the formulas docs/mixed_lighting.md gives.
//
// Directional encoding (lightmap-<i>_direction.exr, RGBA, linear):
//   D = sum_i luminance(E_i) w_i / sum_i luminance(E_i), over the terms E_i of the texel's
//       irradiance estimate (punctual lights, emitter and sky samples, paths), w_i the unit
//       world direction (glTF axes) each arrives from. |D| <= 1 is the directionality:
//       1 = all light from one direction, 0 = light from opposite directions cancels.
//   RGB = D x 0.5 + 0.5;
//   A   = w = dot(n, D) x 0.5 + 0.5 with n the texel's (interpolated vertex) normal: the
//         rebalancing coefficient Unity's decoder divides by (Enlighten's comment: "using it
//         for half Lambert and then dividing by a rebalancing coefficient gives a result close
//         to plain diffuse response lightmaps, but normalmapped"). With it the decode below
//         gives the lightmap value back exactly for n, and a half-Lambert estimate of the
//         irradiance for a bent (normal-mapped) normal.
// Decode (Unity's DecodeDirectionalLightmap):
//   colour = light x (dot(normal, RGB - 0.5) + 0.5) / max(1e-4, A).
#pragma once

#include <algorithm>

#include "src/math.h"

namespace kiln {

// The RGBA texel of a direction map from the luminance-weighted direction sum `weighted`
// (sum luminance(E_i) w_i, Integrator::irradiance's weightedDirection), the luminance of the
// irradiance estimate `luminanceSum` (same normalisation) and the texel's unit normal.
// Black texels (luminanceSum <= 0) get D = 0, i.e. RGB 0.5 and A 0.5.
inline vec4 encodeDominantDirection(vec3 weighted, float luminanceSum, vec3 normal) {
  vec3 d(0.0f);
  if (luminanceSum > 0.0f) d = weighted / luminanceSum;
  const float len = glm::length(d);
  if (len > 1.0f) d /= len;  // rounding only: a mean of unit vectors is never longer than 1
  return vec4(d * 0.5f + 0.5f, glm::dot(normal, d) * 0.5f + 0.5f);
}

// Unity's DecodeDirectionalLightmap: `light` is the lightmap texel (E / pi), `direction` the
// direction map texel, `normal` the unit world normal to shade with.
inline vec3 decodeDirectionalLightmap(vec3 light, vec4 direction, vec3 normal) {
  const float halfLambert = glm::dot(normal, vec3(direction) - 0.5f) + 0.5f;
  return light * halfLambert / std::max(1e-4f, direction.w);
}

// Shadowmask decode: the realtime direct light of a mixed light in Shadowmask mode is
// multiplied by its baked visibility, the texel's value in the light's channel
// (manifest "lights"[k].shadowmaskChannel; 1 = unshadowed). Unity combines it with the
// realtime shadow map as min(realtimeShadow, bakedVisibility) inside the shadow distance.
inline float shadowmaskVisibility(vec4 shadowmask, int channel) {
  return channel >= 0 && channel < 4 ? shadowmask[channel] : 1.0f;
}

// Subtractive decode (Unity's SubtractMainLightWithRealtimeAttenuationFromLightmap), per
// channel, for the main (mixed, directional) light:
//   estimate = max(0, dot(n, l)) x (1 - attenuation) x lightColor
//   shadowed = lerp(max(lightmap - estimate, shadowColor), lightmap, shadowStrength')
//   colour   = min(lightmap, shadowed)
// where l is the unit direction towards the light, attenuation the realtime shadow term
// (1 = lit, 0 = in a dynamic object's realtime shadow), lightColor the light's irradiance in
// lightmap units (colour x intensity / pi: lux / pi, since texels hold E / pi),
// shadowColor the manifest's "shadowColor" and shadowStrength' = 1 - the light's shadow
// strength (Unity's _LightShadowData.x; 0 for full-strength shadows).
inline vec3 subtractiveLightmap(vec3 lightmap, vec3 normal, vec3 toLight, float attenuation,
                                vec3 lightColor, vec3 shadowColor, float shadowStrength = 0.0f) {
  const float ndotl = std::max(0.0f, glm::dot(normal, toLight));
  const vec3 estimate = ndotl * (1.0f - attenuation) * lightColor;
  const vec3 subtracted = lightmap - estimate;
  vec3 shadowed = glm::max(subtracted, shadowColor);
  shadowed = shadowed + (lightmap - shadowed) * shadowStrength;
  return glm::min(lightmap, shadowed);
}

}  // namespace kiln
