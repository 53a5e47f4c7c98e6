// probe_baker.h: the light-probe SH bake: positions -> a complete ProbeSet (topology from
// tetrahedralize.h, radiance SH and validity per probe from the path tracer in integrator.h).
//
// Per probe, `rays` directions cover the sphere uniformly (Owen-scrambled Sobol points from
// sampling.h, stratified for a power-of-two count, warped by squareToUniformSphere); the
// radiance arriving along each (Integrator::incomingRadiance, direct + indirect) is projected
// onto kiln's L2 basis with quadrature weight 4 pi / rays. Punctual lights are deltas in
// direction, never hit by rays, so they are projected exactly: a light of irradiance E
// (on a surface facing it, x shadow visibility) from unit direction s has radiance
// E delta(w - s), whose coefficients are c_i = E Y_i(s).
// The SH stored is RADIANCE SH (src/sh.h); irradiance for a normal is ShL2Rgb::irradiance(n)
// (E itself, not E / pi).
#pragma once

#include <atomic>
#include <optional>
#include <span>
#include <string>
#include <string_view>
#include <vector>

#include "kiln/probe_set.h"
#include "probes/tetrahedralize.h"
#include "src/integrator.h"
#include "src/progress.h"
#include "src/result.h"
#include "src/scene.h"
#include "src/tracer.h"

namespace kiln {

// Bounces used when neither the settings nor the scene's extras.kiln.bounces give a count.
// Probes in enclosed rooms see a lot of multiply bounced light (a white Cornell box loses
// ~5% of its irradiance at 8 bounces); Russian roulette keeps the long paths cheap.
inline constexpr int kDefaultProbeBounces = 16;

struct ProbeBakeSettings {
  uint32_t rays = 4096;  // rays per probe (> 0); a power of two keeps the Sobol set stratified
  uint64_t seed = 0;     // keys every random number: probe i uses hashValues(seed, i)
  ProbeTopologySettings topology;  // Delaunay backend, merge tolerance
  // Integrator: nullopt = the scene's extras.kiln value, else kDefaultProbeBounces / 1.
  std::optional<int> bounces;
  std::optional<float> albedoBoost;
  std::optional<float> indirectIntensity;
  int russianRouletteDepth = 3;
  // Shadow-visibility evaluations per punctual light (each of the light's shadowSamples
  // rays); more than 1 only matters for soft shadows.
  uint32_t lightSamples = 16;
  // A probe whose share of rays that first hit a back face (of a single-sided surface)
  // exceeds this is inside geometry (DDGI, Majercik et al. 2019): it is counted invalid
  // and, with fillInvalid, its SH is replaced by the mean of its valid neighbours'.
  float invalidBackfaceRatio = 0.25f;
  bool fillInvalid = true;
  // Window (Sloan 2017) the radiance SH of probes whose reconstructed irradiance goes
  // negative somewhere, with the weakest sinc^4 window that makes it >= 0; probes whose
  // irradiance is already >= 0 everywhere are left bit-for-bit unchanged.
  bool dering = true;
  int threads = 0;  // 0 = all cores
};

// What the bake did, for the caller to report.
struct ProbeBakeReport {
  std::vector<std::string> warnings;   // topology warnings and invalid probes
  std::vector<int32_t> invalidProbes;  // back-face ratio > invalidBackfaceRatio
  int32_t filledProbes = 0;            // invalid probes given their neighbours' SH
  int32_t deringedProbes = 0;          // probes whose SH was windowed
  uint64_t rays = 0;                   // rays traced by the integrator (all threads)
  IntegratorSettings integrator;       // as resolved from the scene and the settings
};

// The integrator settings a probe bake uses for `scene` (bounces, albedo boost, indirect
// intensity: settings, else the scene's extras.kiln, else defaults). Light modes: a baked
// light contributes direct and indirect light; a mixed light only indirect light (its
// direct light is computed in real time for dynamic objects in every lighting mode, as in
// Unity); a realtime light nothing.
IntegratorSettings probeIntegratorSettings(const Scene& scene, const ProbeBakeSettings& settings);

// Bakes probes at `positions` (world space, metres). The ProbeSet has one probe per position
// in the same order (near-duplicates merged by the topology keep their slot and get their
// own SH), RADIANCE SH, and validity = 1 - (share of rays whose first hit is the back face
// of a single-sided surface), the raw fraction in [0, 1] (1 = open space).
// Deterministic: bit-identical output for any thread count. `progress` (unit: probes) and
// `cancel` are optional; a cancelled bake returns an error "cancelled". Errors: no
// positions, non-finite positions, rays == 0, topology failure.
Result<ProbeSet> bakeProbes(const Scene& scene, const Tracer& tracer,
                            std::span<const vec3> positions, const ProbeBakeSettings& settings,
                            Progress* progress = nullptr, const std::atomic<bool>* cancel = nullptr,
                            ProbeBakeReport* report = nullptr);

// Radiance SH and validity of one probe at p (the per-probe step of bakeProbes, exposed for
// tests): `key` keys its random numbers. Thread-safe. When `cancel` becomes true the loop
// stops early (checked every 4096 rays) and the result is incomplete.
struct ProbeSample {
  ShL2Rgb sh;
  float validity = 1.0f;
};
ProbeSample bakeProbe(const Integrator& integrator, vec3 p, uint64_t key, uint32_t rays,
                      uint32_t lightSamples, const std::atomic<bool>* cancel = nullptr);

// Probe positions from JSON text {"positions": [[x, y, z], ...]}; `name` (the file) prefixes
// messages, e.g. "probes.json: positions[3]: expected 3 finite numbers".
Result<std::vector<vec3>> parseProbePositions(std::string_view json, std::string_view name);
// Reads and parses a positions file.
Result<std::vector<vec3>> loadProbePositions(const std::string& path);
// Every position of the scene's probe groups (extras.kiln.probes on nodes), in group order.
std::vector<vec3> sceneProbePositions(const Scene& scene);

}  // namespace kiln
