// sun_shadows.h: the probe set's sun layer (kiln/probe_set.h, ProbeSunLayer; docs/probes.md,
// "Sun shadows"): per tetrahedron, the ramp across the plane that bounds a baked directional
// light's shadow in it, fitted to shadow rays traced inside the cell.
#pragma once

#include <array>
#include <atomic>
#include <cstdint>
#include <span>

#include "kiln/probe_set.h"
#include "src/integrator.h"
#include "src/progress.h"

namespace kiln {

// The light the sun layer carries: the directional light with the most irradiance among those
// whose direct light the integrator bakes (IntegratorSettings::directLights), or -1 (none:
// no layer).
int32_t sunLayerLight(const Scene& scene, const IntegratorSettings& settings);

// The light's share reaching q unblocked, in [0, 1] (the luminance of
// Integrator::lightVisibility, over the light's shadow samples).
float sunShare(const Integrator& integrator, uint32_t light, glm::vec3 q, uint64_t key);

// Shadow rays per cell: interior points sampled to classify the cell and, for a cell whose
// points disagree, to check the fitted ramp against the plain blend.
inline constexpr uint32_t kSunRampSamples = 32;

// The ramp of tetrahedron `corners` (positively oriented) whose probes hold the light's
// shares `shares` (ProbeSunLayer::ramps): its value at the four vertices: the step across
// the shadow's plane, or where no plane passes the linear share fitted to the interior points
// (a lit cell whose probes stand in pockets of shade). NaN (all four) when the light's share
// does not vary in the cell, when both are wrong at more than 3 of 64 interior points (two
// edges at an angle, stripes), or when the plain blend (the shares mixed by barycentric
// weights) fits the share about as well. Samples the cell with `key` (deterministic).
glm::vec4 fitSunRamp(const Integrator& integrator, uint32_t light,
                     const std::array<glm::vec3, 4>& corners, const std::array<float, 4>& shares,
                     uint64_t key);

// Fills set.sun's ramps for every inner cell (dimension 3; none otherwise) from its
// visibility (one share per probe, already set) and light. Cell c uses key hashValues(seed,
// c), so the result does not depend on the thread count. Returns false when cancelled.
bool bakeSunRamps(const Integrator& integrator, ProbeSet& set, uint64_t seed, int threads,
                  Progress* progress = nullptr, const std::atomic<bool>* cancel = nullptr);

}  // namespace kiln
