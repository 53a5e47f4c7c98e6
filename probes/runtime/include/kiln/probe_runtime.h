// probe_runtime.h: finding the probes around a point and blending their SH at run time.
//
// locateProbe walks from a caller-owned hint cell (e.g. last frame's cell for the object) to
// the cell containing the point, crossing each time the face with the most negative
// barycentric coordinate (Cupisz, GDC 2012); without a hint it starts from the seed grid.
// Each step reads one 64-byte record (ProbeWalkCell) and decides in float where the float
// error bound allows (a point still in its hint's cell with one compare), with exact
// predicates near faces: the cell found is the exact walk's.
// Outside the hull the outer cells extrapolate continuously, so a lookup always succeeds.
// When the set has per-probe visibility (ProbeSet::visibility) the barycentric weights are
// multiplied by each probe's visibility of the point and renormalized
// (kiln/probe_visibility.h), so light does not pass through walls between probes on both
// sides of them; ProbeBlendSettings chooses plain or visibility-weighted blending.
// Everything here reads a const ProbeSet: safe from many threads, no allocation per query.
#pragma once

#include <array>
#include <cstdint>
#include <span>

#include <glm/glm.hpp>

#include "kiln/probe_set.h"
#include "kiln/probe_visibility.h"

namespace kiln {

// Where a point is: the cell, its probes and their weights (>= 0, summing to 1, or less where
// the visibility-weighted blend fades out: ProbeBlendSettings::minVisibleWeight). Slots a cell
// does not use (outer cells, lower dimensions) repeat probes[0] with weight 0, so a caller may
// blend all four blindly.
struct ProbeLocation {
  int32_t cell = -1;                // pass back as the next hint
  std::array<int32_t, 4> probes{};  // indices into ProbeSet::positions / sh
  std::array<float, 4> weights{};   // the blend's weights (visibility-weighted when used)
  std::array<float, 4> barycentric{};  // the cell's own (barycentric) weights
  uint16_t steps = 0;               // cells visited by the walk (diagnostics)
  bool bruteForce = false;          // the walk gave up and a scan of all cells was used
  // The weights include the probes' visibility of the point (the set has visibility maps and
  // the blend asked for them). Only then does interpolateProbes apply the sun layer's ramps:
  // a plain blend cannot tell a probe behind a wall, and a ramp would carry sun through it.
  bool visibilityWeighted = false;
};

// Cells a walk may visit before it falls back to scanning every cell.
inline constexpr int kMaxWalkSteps = 4096;

// Locates p (world space). `hint` is any cell index or -1; an out-of-range hint is ignored.
// Returns cell = -1 only for an empty ProbeSet. The cell is chosen exactly whatever the blend;
// `blend` decides the weights (visibility-weighted by default when the set has visibility).
ProbeLocation locateProbe(const ProbeSet& set, glm::vec3 p, int32_t hint = -1,
                          const ProbeBlendSettings& blend = {}) noexcept;

// The same lookup with the exact predicates at every step of the walk (locateProbe trusts
// float barycentric coordinates away from faces and gives the same cell): the reference the
// fast path is tested against.
ProbeLocation locateProbeExact(const ProbeSet& set, glm::vec3 p, int32_t hint = -1,
                               const ProbeBlendSettings& blend = {}) noexcept;

// Replaces location.weights by location.barycentric x each probe's visibility of p, divided by
// max(their sum, blend.minVisibleWeight) (plain barycentric when blend.visibility is false or
// the set has none).
void weightByVisibility(const ProbeSet& set, glm::vec3 p, ProbeLocation& location,
                        const ProbeBlendSettings& blend = {}) noexcept;

// sum_k weights[k] * sh[probes[k]]: radiance SH at the located point.
ShL2Rgb interpolateProbes(const ProbeSet& set, const ProbeLocation& location) noexcept;

// Radiance SH at p (locate + interpolate).
ShL2Rgb sampleProbes(const ProbeSet& set, glm::vec3 p, int32_t hint = -1,
                     const ProbeBlendSettings& blend = {}) noexcept;

// sum_k weights[k] * occlusion[probes[k]]: the shadowmask occlusion of the 4 channels at the
// located point (see ProbeSet), blended with the SH's weights (divided by their float sum, so
// all-1 probes give exactly 1; clamped to [0, 1]); an object at a probe gets that probe's
// values. A set without occlusion gives 1 in every channel. A shader multiplies
// channel c's realtime light (the light set.occlusionLights[c]) by the result's [c] where the
// light has no realtime shadow (as Unity's probe occlusion does).
glm::vec4 interpolateOcclusion(const ProbeSet& set, const ProbeLocation& location) noexcept;

// Occlusion at p (locate + interpolateOcclusion).
glm::vec4 sampleOcclusion(const ProbeSet& set, glm::vec3 p, int32_t hint = -1,
                          const ProbeBlendSettings& blend = {}) noexcept;

// Irradiance E (not E / pi) for unit normal n from radiance SH (Ramamoorthi and Hanrahan
// 2001; see kiln/sh.h).
inline glm::vec3 probeIrradiance(const ShL2Rgb& sh, glm::vec3 n) noexcept {
  return sh.irradiance(n);
}

// Batch forms. `hints` is empty or has points.size() entries: each entry is read as the hint
// for its point and overwritten with the cell found. `out` must have points.size() entries.
// `blend` applies to every point (its normal too; zero for object centres). Each point gets
// exactly locateProbe's result (cell, weights; steps too unless a walk reaches the step
// cap), but the walks of several points advance in turn, so that their cache misses overlap:
// on a large set without hints (or with stale ones) a batch costs much less per point than
// the same number of single calls.
void locateProbes(const ProbeSet& set, std::span<const glm::vec3> points,
                  std::span<int32_t> hints, std::span<ProbeLocation> out,
                  const ProbeBlendSettings& blend = {}) noexcept;
void sampleProbes(const ProbeSet& set, std::span<const glm::vec3> points,
                  std::span<int32_t> hints, std::span<ShL2Rgb> out,
                  const ProbeBlendSettings& blend = {}) noexcept;
// Batch SH and occlusion together (one lookup per point): `sh` and `occlusion` are each empty
// (not wanted) or have points.size() entries.
void sampleProbes(const ProbeSet& set, std::span<const glm::vec3> points, std::span<int32_t> hints,
                  std::span<ShL2Rgb> sh, std::span<glm::vec4> occlusion,
                  const ProbeBlendSettings& blend = {}) noexcept;

}  // namespace kiln
