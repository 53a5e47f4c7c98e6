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
// The SH stored is RADIANCE SH (kiln/sh.h); irradiance for a normal is ShL2Rgb::irradiance(n)
// (E itself, not E / pi).
//
// Which light goes into the SH follows the scene's lighting mode (src/light_modes.h, Unity's
// Mixed Lighting): realtime lights never; baked lights direct + indirect; mixed lights
// indirect only under baked-indirect and shadowmask (their direct light is added in real time,
// for dynamic objects as for static ones), direct + indirect under subtractive, and a
// shadowmask light that got no channel is baked fully. Under shadowmask every channelled light
// also gets its probe occlusion (ProbeSet::occlusion): the fraction of the light that reaches
// the probe unblocked, soft shadows included, so dynamic objects get the baked shadows too.
#pragma once

#include <atomic>
#include <optional>
#include <span>
#include <string>
#include <string_view>
#include <vector>

#include "kiln/probe_set.h"
#include "probes/tetrahedralize.h"
#include "probes/visibility_bake.h"
#include "src/integrator.h"
#include "src/light_modes.h"
#include "src/progress.h"
#include "kiln/result.h"
#include "src/scene.h"
#include "src/tracer.h"

namespace kiln {

// Bounces used when neither the settings nor the scene's extras.kiln.bounces give a count.
// Probes in enclosed rooms see a lot of multiply bounced light (a white Cornell box loses
// ~5% of its irradiance at 8 bounces); Russian roulette keeps the long paths cheap.
inline constexpr int kDefaultProbeBounces = 16;
// Largest probe coordinate accepted (metres, each axis): 10,000 km, far beyond any level and
// far inside what Embree can trace from (a probe at 1e20 aborted inside it).
inline constexpr float kMaxProbeCoordinate = 1e7f;

// Side of the per-probe visibility map a bake stores by default (docs/probes.md, "Leak-free
// blending", says why).
inline constexpr int32_t kDefaultVisibilityResolution = 32;

// Largest ProbeBakeSettings::footprint: half the nearest-neighbour distance is where two
// neighbours' balls touch.
inline constexpr float kMaxProbeFootprint = 0.5f;

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
  // Mixed lighting mode (which lights bake what, shadowmask channels): nullopt = the scene's
  // extras.kiln.lightingMode, else baked-indirect.
  std::optional<LightingMode> lightingMode;
  // Visibility evaluations (each of the light's shadowSamples rays) averaged into the probe
  // occlusion of a soft-shadowed shadowmask light (0 counts as 1); hard shadows need 1.
  uint32_t occlusionSamples = 64;
  // A probe whose share of rays that first hit a back face (of a single-sided surface)
  // exceeds this is inside geometry (DDGI, Majercik et al. 2019): it is counted invalid
  // and, with fillInvalid, its SH is replaced by the mean of its valid neighbours'.
  float invalidBackfaceRatio = 0.25f;
  bool fillInvalid = true;
  // Dering the radiance SH of probes whose reconstructed irradiance goes negative somewhere:
  // the nearest SH (in irradiance, c0 kept) whose irradiance is >= 0 for every normal
  // (deringProbeSh); probes whose irradiance is already >= 0 everywhere are left bit-for-bit
  // unchanged.
  bool dering = true;
  // Per-probe visibility for leak-free blending (kiln/probe_visibility.h): the side of each
  // probe's octahedral depth-moment map, 0 = none (plain barycentric blending at run time).
  // 32 x 32 (6 KB per probe): smaller texels leak at silhouettes (docs/probes.md, "Why these
  // choices"; docs/charts.md, chart 6).
  int32_t visibilityResolution = kDefaultVisibilityResolution;
  // Footprint (spatial prefilter, docs/probes.md "The footprint"): each probe's radiance SH
  // is the mean over a ball around it instead of the value at its centre, so that light and
  // shade finer than the probes (a sunbeam striped by a blind) is averaged instead of
  // aliased. The ball's radius is footprint x the distance to the nearest other probe of the
  // set, at most footprintMaxRadius; 0 = a point bake. It applies only to probes that stand
  // in such light (inThinLightSheet) unless footprintEverywhere. Every ray (and
  // every punctual-light sample) starts at its own deterministic point of the part of the ball
  // the probe sees (footprintOrigin); validity, the visibility map and the probe occlusion
  // stay those of the centre. In [0, kMaxProbeFootprint]. The defaults were chosen on the
  // breakfast room, the atrium and the Cornell reference (docs/probe_placement.md, round 8).
  float footprint = 0.5f;
  float footprintMaxRadius = 0.1f;  // metres, > 0
  // false: the footprint applies only to probes in a sheet of light or shade of a baked
  // punctual light thinner than 18 cm (inThinLightSheet); elsewhere probes are point bakes,
  // which are more accurate where light varies no faster than the probes (near surfaces a
  // ball clipped by the surface is off-centre; docs/probe_placement.md, round 8).
  bool footprintEverywhere = false;
  // The sun layer (kiln/probe_set.h, ProbeSunLayer; docs/probes.md, "Sun shadows"): sharp
  // shadow edges of the brightest baked directional light for probe-lit objects, from a ramp
  // per tetrahedron fitted to shadow rays in it. false = no layer (the plain blend).
  bool sunShadows = true;
  // Distance (metres) the depths are clamped to; 0 = per probe, the distance to the farthest
  // corner of the static objects' bounds and the probes (visibilityMaxDistances).
  float visibilityMaxDistance = 0.0f;
  int threads = 0;  // 0 = all cores
};

// What the bake did, for the caller to report.
struct ProbeBakeReport {
  std::vector<std::string> warnings;   // topology warnings and invalid probes
  std::vector<int32_t> invalidProbes;  // back-face ratio > invalidBackfaceRatio
  int32_t filledProbes = 0;            // invalid probes given their neighbours' SH
  int32_t deringedProbes = 0;          // probes whose SH the deringing fit changed
  int32_t footprintProbes = 0;         // probes baked over a footprint (not at their point)
  int32_t sunRampCells = 0;            // cells whose sun layer has a ramp (ProbeSunLayer)
  uint64_t rays = 0;                   // rays traced by the integrator (all threads)
  IntegratorSettings integrator;       // as resolved from the scene and the settings
  LightModePlan lightModes;            // what each light baked, shadowmask channels
};

// The lighting mode a bake uses: settings.lightingMode, else the scene's
// extras.kiln.lightingMode, else baked-indirect.
LightingMode probeLightingMode(const Scene& scene, const ProbeBakeSettings& settings);
// planLightModes(scene, probeLightingMode(scene, settings)).
LightModePlan probeLightModePlan(const Scene& scene, const ProbeBakeSettings& settings);

// The integrator settings a probe bake uses for `scene` (bounces, albedo boost, indirect
// intensity: settings, else the scene's extras.kiln, else defaults). Lights: direct and
// indirect light per probeLightModePlan (see the header comment).
IntegratorSettings probeIntegratorSettings(const Scene& scene, const ProbeBakeSettings& settings);

// Bakes probes at `positions` (world space, metres). The ProbeSet has one probe per position
// in the same order (near-duplicates merged by the topology keep their slot and get their
// own SH), RADIANCE SH (each probe's the mean over its footprint ball when
// settings.footprint > 0 and the probe is in a thin light sheet or footprintEverywhere: radii
// from probeFootprintRadii), and validity = 1 - (share of rays whose first hit is the back face
// of a single-sided surface), the raw fraction in [0, 1] (1 = open space); occlusion per
// probe (bakeProbeOcclusion; all 1 outside shadowmask mode) and occlusionLights from the plan.
// Invalid probes that are filled get their valid neighbours' mean occlusion too. The plan's
// warnings (lights that fell back to baked) go into the report.
// Deterministic: bit-identical output for any thread count. `progress` (unit: probes) and
// `cancel` are optional; a cancelled bake returns an error "cancelled". Errors: no
// positions, non-finite positions, rays == 0, topology failure.
Result<ProbeSet> bakeProbes(const Scene& scene, const Tracer& tracer,
                            std::span<const vec3> positions, const ProbeBakeSettings& settings,
                            Progress* progress = nullptr, const std::atomic<bool>* cancel = nullptr,
                            ProbeBakeReport* report = nullptr);

// The bake's deringing step (ProbeBakeSettings::dering), exposed so that a raw bake can be
// compared with the default one: every SH whose irradiance goes negative for some normal is
// replaced by deringSh's fit (src/sh_projection.h: the nearest SH in irradiance, c0 kept,
// whose irradiance is >= 0 for every normal); the others are untouched. Returns how many
// changed. Each probe on its own (parallelFor over `threads`, 0 = all cores): bit-identical
// for any thread count.
int32_t deringProbeSh(std::span<ShL2Rgb> sh, int threads = 0);

// Each probe's visibility maxDistance D for a bake at `positions`: settings.visibilityMaxDistance
// when > 0, else per probe the distance to the farthest corner of the static objects' bounds
// and the probes (visibilityMaxDistances; dynamic objects are not baked). Empty when
// settings.visibilityResolution is 0.
std::vector<float> probeVisibilityMaxDistances(const Scene& scene, std::span<const vec3> positions,
                                               const ProbeBakeSettings& settings);

// Radiance SH and validity of one probe at p (the per-probe step of bakeProbes, exposed for
// tests): `key` keys its random numbers. Thread-safe. When `cancel` becomes true the loop
// stops early (checked every 4096 rays) and the result is incomplete. With a visibility
// resolution > 0 the same rays' first-hit distances also fill the probe's visibility map
// (VisibilityMapBuilder).
struct ProbeSample {
  ShL2Rgb sh;
  float validity = 1.0f;
  std::vector<uint16_t> visibility;  // resolution^2 x {mu, sigma, far} unorm16, or empty
  // The share of the sun layer's light (sunLayerLight) in the SH: its visibility, averaged
  // as the SH averages it (over the light's samples, or the footprint's origins); 0 when the
  // integrator bakes no such light.
  float sunShare = 0.0f;
};
// `footprintRadius` > 0 bakes the mean over a ball of that radius around p (see
// ProbeBakeSettings::footprint): ray s starts at footprintOrigin(tracer, p, radius, key, s)
// and one punctual-light evaluation is made per ray at that origin (instead of lightSamples
// at p).
ProbeSample bakeProbe(const Integrator& integrator, vec3 p, uint64_t key, uint32_t rays,
                      uint32_t lightSamples, const std::atomic<bool>* cancel = nullptr,
                      const VisibilityMapSpec& visibility = {}, float footprintRadius = 0.0f);

// A key from a position's bits: the rays probing a point depend on where it is, not on which
// list it is in or which thread looks.
uint64_t positionKey(vec3 p);

// True when p lies in a sheet of light or shade of a punctual light thinner than 2 x 9 cm:
// along some axis, the light's visibility at p differs from both points at +-r (r = 3, 6 or
// 9 cm). Only lights whose direct light the integrator bakes count (a mixed light under
// baked-indirect puts only its smooth bounced light into the probes). A blind's slats stripe
// a sunbeam so (the breakfast room: 3 cm lit sheets between 4.7 cm of shade,
// docs/probe_placement.md round 6); no probe field resolves such light: point-baked probes
// there alias (each lit or shaded at random), and placement's picks for such points spread it
// over the shade beside them (round 7).
bool inThinLightSheet(const Scene& scene, const Integrator& integrator, vec3 p);

// Origin of ray s of a probe at p baked over a ball of `radius` (key as bakeProbe's): a
// point of the ball (a Sobol point of sample s of a side stream of `key`, uniform in volume)
// whose segment from p is free of geometry up to 1% of the radius beyond it; a blocked point
// is re-drawn (up to 16 draws, the last then pulled back towards p to 1% of the radius short
// of the surface), so origins are uniform over the part of the ball the probe sees.
// p itself when radius <= 0. Deterministic.
vec3 footprintOrigin(const Tracer& tracer, vec3 p, float radius, uint64_t key, uint32_t s);

// Per position, settings.footprint x the distance to the nearest other position (positions
// at exactly the same point are not counted), at most settings.footprintMaxRadius; 0 for a
// lone position or footprint 0. A uniform grid search.
std::vector<float> probeFootprintRadii(std::span<const vec3> positions,
                                       const ProbeBakeSettings& settings);

// Probe occlusion of scene light `light` at p: the mean over `samples` evaluations j of
// Integrator::lightVisibility(p, 0, light, hashValues(key, tag, light), j) (tag fixed in
// probe_baker.cpp), each the mean of the light's shadowSamples shadow rays, taken as the mean
// of its RGB transmittance; one evaluation when the light's shadows are hard. In [0, 1].
float probeLightOcclusion(const Integrator& integrator, vec3 p, uint32_t light, uint64_t key,
                          uint32_t samples);
// The 4 channels at p: channel plan.shadowmaskChannel[l] = probeLightOcclusion of light l,
// unused channels 1. `key` as bakeProbe's (bakeProbes passes hashValues(seed, i)).
glm::vec4 bakeProbeOcclusion(const Integrator& integrator, const LightModePlan& plan, vec3 p,
                             uint64_t key, uint32_t samples);

// Light of one object that probes light without a probe field: kiln bake's probe-lit objects
// (too small for a lightmap, AtlasObject::probeLit; written to the manifest and the output
// glTF) and kiln render's fallback for bakes that predate them. Unity samples one probe at a
// renderer's bounds centre; a small prop's centre is often inside it (a cup's inside is dark)
// or in its shadow, so this bakes a probe (bakeProbe, settings.rays and .lightSamples) just
// outside the middle of each face of `bounds` (a margin of 5% of the diagonal + 1 mm) and
// averages their radiance SH and occlusion (bakeProbeOcclusion, settings.occlusionSamples)
// with their validity as weights, leaving out the probes bakeProbes counts invalid (more than
// settings.invalidBackfaceRatio of their rays on back faces: under a floor, inside a wall);
// when none is valid, the probe at the centre alone. The mean is deringed
// (deringSh: irradiance >= 0 for every normal, as bakeProbes does). Probe k (0..5: -x, +x, -y,
// +y, -z, +z; 6: the centre) draws its random numbers from hashValues(key, k). Thread-safe,
// deterministic. `rays` (optional) receives the rays traced on the calling thread.
struct ObjectProbe {
  ShL2Rgb sh;                 // radiance SH, kiln's basis
  glm::vec4 occlusion{1.0f};  // shadowmask channels (1 where no light has that channel)
};
ObjectProbe bakeObjectProbe(const Integrator& integrator, const LightModePlan& plan,
                            const Bounds3& bounds, uint64_t key,
                            const ProbeBakeSettings& settings);

// Probe positions from JSON text {"positions": [[x, y, z], ...]}; `name` (the file) prefixes
// messages, e.g. "probes.json: positions[3]: expected 3 finite numbers".
Result<std::vector<vec3>> parseProbePositions(std::string_view json, std::string_view name);
// Reads and parses a positions file.
Result<std::vector<vec3>> loadProbePositions(const std::string& path);
// Every position of the scene's probe groups (extras.kiln.probes on nodes), in group order.
std::vector<vec3> sceneProbePositions(const Scene& scene);

}  // namespace kiln
