// lightmap_baker.h: kiln bake's pipeline from a loaded Scene to lightmap pages in memory.
//
// Stages (Godot's LightmapperCPU style, each a function over plain data run through
// kiln::parallelFor with progress and cancellation):
//   1. UVs: objects without TEXCOORD_1 get generated lightmap UVs (uv_unwrap.h);
//   2. atlas: every lightmapped object gets a page rectangle (atlas.h), or a locked layout;
//   3. texels: conservative rasterization gives each texel its sample point(s) (texel_raster.h);
//   4. sample points pushed out of nearby geometry (walls meeting floors neither leak nor
//      self-shadow);
//   5. light: the integrator's irradiance at every sample point; texel value = E / pi;
//      validity from the share of back-face hits and from enclosure (rays that all hit
//      geometry close by); optional ambient occlusion; what each
//      light contributes follows the lighting mode (src/light_modes.h); optionally the
//      dominant direction (lightmap/directional.h) and the mixed lights' shadowmask;
//   6. post: invalid texels that bilinear lookups at visible points can reach filled from
//      valid neighbours (deeper ones keep their physical value, 0 when enclosed), denoised,
//      dilated into padding, seams stitched
//      (postprocess.h, seams.h); ambient occlusion applied when aoAmount > 0; a last guard
//      sets any negative texel left to 0 and counts it (stats.clampedTexels).
// Besides the texels, after stage 5: every probe-lit object (too small for a lightmap,
// AtlasObject::probeLit) gets its own L2 SH from probes around it (lightmap/probe_lit.h), so
// that the outputs light it without a probe field.
// Output files (EXR, manifest, glTF) are written by lightmap_writer.h, not here.
#pragma once

#include <array>
#include <atomic>
#include <optional>
#include <string>
#include <vector>

#include "lightmap/atlas.h"
#include "lightmap/manifest.h"
#include "probes/probe_baker.h"
#include "lightmap/uv_unwrap.h"
#include "src/image.h"
#include "src/light_modes.h"
#include "src/progress.h"
#include "kiln/result.h"
#include "src/scene.h"

namespace kiln {

// Everything a bake needs besides the scene. The CLI fills it from presets, the scene's
// extras.kiln and the command line (command line wins).
struct LightmapBakeSettings {
  // Atlas.
  float resolution = 10.0f;  // texels per world unit, before each object's scaleInLightmap
  int padding = 2;           // texels
  int maxSize = 1024;        // page width/height limit, texels
  // Objects whose surface would get fewer texels are lit by probes instead (atlas.h).
  float minObjectTexels = kMinObjectTexels;
  // --lock-atlas: an earlier bake's manifest (readManifest, ManifestUse::kAtlas) and its
  // file, which starts the layout's error messages. The objects it gives a page keep their
  // charts (uv_unwrap.h keepCharts), the others' UVs are generated as always, and the atlas
  // is the manifest's (atlasFromManifest, on the scene with its UVs generated).
  struct LockedAtlas {
    Manifest manifest;
    std::string file;
  };
  std::optional<LockedAtlas> lockedAtlas;
  // Sampling.
  // Paths per texel (split over the supersamples); with errorTarget > 0, the cap.
  int samplesPerTexel = 256;
  // Error target (lightmap_baker.cpp, pilotPass and allocateSamples): > 0 = a pilot pass
  // of pilotSamples paths (main sample point) on its own random stream measures, at every
  // texel, the spread sigma of one path's luminance and its mean mu (each averaged over its
  // valid 3 x 3 neighbours of the same object); the texels then take paths in proportion to
  // sigma (Neyman's allocation, as adaptiveSamples), clamped to [minSamples,
  // samplesPerTexel], with the fewest in total for which the relative RMS error they
  // predict over the texels, sqrt(sum sigma^2 / n / sum mu^2), is at most errorTarget. The
  // pilot's paths do not enter any texel's value and the counts depend only on them, so the
  // estimate is unbiased (a stopping rule on the texel's own paths, kiln's first error
  // target, was not: it stopped where a few paths agreed, and darkened). The prediction
  // assumes plain Monte Carlo's 1 / n; the Sobol paths and the denoiser do better, so the
  // output's error is at most the target where the cap does not bind.
  // 0 = every texel takes samplesPerTexel paths.
  float errorTarget = 0.0f;
  int minSamples = 32;
  int pilotSamples = 8;       // at each texel's main sample point, with errorTarget > 0
  int supersampling = 1;      // n x n sample points per texel
  // Final gather (lightmap_baker.cpp, bounceCachePass): > 0 = a first pass bakes every
  // texel with this many full paths (post-processed like the light: filled, dilated,
  // stitched), and the paths of the light stage end at their first hit, where they read that
  // pass's light (x the albedo) instead of tracing on. Each path then costs about two rays
  // instead of five and carries far less variance, for a small bias from the first pass's
  // texel size. 0 = independent full paths per texel.
  int bounceCacheSamples = 0;
  // With a bounce cache (and no errorTarget): the light stage's paths go to the texels in
  // proportion to the spread of one path's value that the first pass measured around each
  // (Neyman allocation, lightmap_baker.cpp allocateSamples): samplesPerTexel on average,
  // between half of it and 8x. false = samplesPerTexel at every texel.
  bool adaptiveSamples = false;
  uint64_t seed = 0;
  // Light transport (see IntegratorSettings).
  // Bounce cap. Russian roulette (IntegratorSettings) ends most paths long before it, so a
  // high cap costs little (Cornell box: +11% rays over 3 bounces) and closed rooms keep the
  // light of late bounces (3 bounces: 5.7% dark against a 64-bounce reference).
  int bounces = 64;
  float albedoBoost = 1.0f;
  float indirectIntensity = 1.0f;
  // Validity: a texel whose rays see back faces more often than this is inside geometry.
  float backfaceTolerance = 0.5f;
  // Validity that also works on double-sided geometry (whose back faces do not count above):
  // a sample point whose rays all hit geometry within this many texel edges (of its
  // object's lightmap resolution) is enclosed, e.g. a floor under a closed box. 0 = off.
  // docs/lightmap_outputs.md, "Texel validity".
  float enclosedTexels = 8.0f;
  // Ambient occlusion map (0 = fully occluded, 1 = open): the fraction of cosine-weighted
  // rays of length aoMaxDistance that escape. aoAmount > 0 also applies it to the light map
  // (Unity's Progressive Lightmapper "Ambient Occlusion" with equal direct and indirect
  // contributions): light x (1 - aoAmount (1 - ao)), i.e. mix(1, ao, aoAmount); 0 = the map
  // is written but not applied.
  bool ambientOcclusion = false;
  float aoMaxDistance = 1.0f;
  float aoAmount = 0.0f;
  // Mixed lighting (docs/mixed_lighting.md): what mixed lights bake (src/light_modes.h).
  // Realtime lights are never baked; baked lights always fully.
  LightingMode lightingMode = LightingMode::BakedIndirect;
  // Subtractive: the colour realtime shadows are clamped to (lightmap units, E / pi).
  // Recorded in the manifest only. Unity's default Realtime Shadow Color.
  vec3 shadowColor{0.42f, 0.478f, 0.627f};
  // Directional mode: also bake the dominant direction map (lightmap/directional.h).
  bool directional = false;
  // Post.
  bool denoise = true;
  bool stitchSeams = true;
  // Hidden-edge texels (lightmap_baker.cpp, footprintStage): texels next to geometry get a
  // 4 x 4 grid of points over their footprint, and the points their main sample cannot reach
  // along the surface (inside a solid, across a wall) or found inside are left out of their
  // value; a texel with no visible grid point is baked at its own points, as without the
  // grid. false = every texel at its main sample (or supersampling points).
  bool footprintGrid = true;
  // Keep each page's visible footprint coverage (LightmapPageResult::coverage).
  bool coverageMap = false;
  // Execution.
  int threads = 0;  // 0 = all cores
};

// Applies a quality preset ("preview", "low", "medium", "high", "production") to the
// sampling settings. Returns an error naming the valid presets for an unknown name.
// Presets are error targets with a cap (errorTarget, minSamples, samplesPerTexel as the cap,
// supersampling; docs/lightmap_outputs.md "Quality presets" for how they were chosen and
// what they cost against the fixed counts they replace).
Status applyLightmapPreset(const std::string& preset, LightmapBakeSettings& settings);

struct LightmapPageResult {
  Image light;                 // RGB, E / pi, glTF orientation (row 0 = v 0)
  // 1 channel when settings.ambientOcclusion, else empty: the fraction of AO rays that
  // escape (not blended with aoAmount; `light` already holds light x mix(1, ao, aoAmount)).
  Image ambientOcclusion;
  // RGBA, present when some light has a shadowmask channel (Shadowmask mode): channel c holds
  // the visible fraction (0 = fully shadowed, 1 = unshadowed; soft shadows give fractions)
  // of the mixed light of channel c whose influence (range sphere) holds the texel; 1 where
  // no light of that channel reaches and in unused channels. Filled, dilated and stitched
  // like `light`; not denoised (hard-shadow masks are exact, soft ones average many rays).
  Image shadowmask;
  // RGBA, present when settings.directional: RGB = dominant direction D x 0.5 + 0.5 (world,
  // glTF axes, |D| = directionality), A = rebalancing coefficient dot(n, D) x 0.5 + 0.5
  // (lightmap/directional.h). Filled, dilated and stitched like `light`; not denoised.
  Image direction;
  std::vector<uint8_t> valid;  // per texel: 1 = baked and valid, 0 = padding/filled
  // 1 channel when settings.coverageMap, else empty: the share of each texel's footprint
  // that is visible surface (not inside geometry), 0 for padding and hidden texels. A texel
  // holds the mean light over that visible part, so light x coverage is the mean over the
  // whole footprint with hidden points counted as 0 (what a renderer that bakes hidden
  // surface points black, such as Cycles, stores): tools/lightmap_compare uses it.
  Image coverage;
  // W x H: the variance of each valid texel's luminance (E / pi) as the denoiser takes it
  // (batch means, corrected for the sequence's faster-than-1/N convergence); 0 elsewhere.
  // For the denoiser's calibration (chart 1) and tests.
  std::vector<float> variance;
  // W x H: paths each covered texel took (0 for padding); with adaptive sampling they differ.
  std::vector<uint32_t> samples;
  // W x H x 3: world position of each covered texel's main sample point after push-out
  // (the point whose light the texel holds when supersampling is 1); 0 for padding. For
  // tests, debugging and the reference comparison.
  Image position;
};

struct LightmapBakeStats {
  size_t texels = 0;        // texels baked (covered by objects)
  size_t invalidTexels = 0;  // inside geometry, filled from neighbours
  // Texels of the light pages (padding included) that still held a negative or non-finite
  // component after post-processing and were set to 0 by the final guard. Every stage keeps
  // values >= 0 by itself, so this is 0 unless something is wrong: it is reported, not hidden.
  size_t clampedTexels = 0;
  uint64_t rays = 0;        // every ray traced (push-out, integrator, AO)
  // Paths per texel (stage 5): minimum, mean, maximum; with adaptive sampling they differ.
  uint32_t minSamples = 0, maxSamples = 0;
  double meanSamples = 0.0;
  // Texels whose stage 5 traced [2^b, 2^(b+1)) rays, b = 0..31 (bucket 0 also holds 0 rays).
  std::array<uint64_t, 32> raysPerTexelHistogram{};
  double seconds = 0.0;     // wall time of the stages that trace them (push-out and light)
};

struct LightmapBakeResult {
  // The scene as baked: objects whose UVs were generated are replaced by their unwrapped
  // copies (vertices split at chart seams, uv1 set).
  Scene scene;
  // Per Scene::objects entry: the unwrap that produced its uv1, when generated (the glTF
  // writer rebuilds those meshes).
  std::vector<std::optional<UnwrapResult>> unwraps;
  AtlasLayout layout;
  std::vector<LightmapPageResult> pages;  // one per layout.pages entry
  // Per Scene::objects entry: for a probe-lit object (layout.objects[i].probeLit) the light
  // the bake gives it (lightmap/probe_lit.h); nullopt for every other object.
  std::vector<std::optional<ObjectProbe>> objectProbes;
  // What each scene light contributed, and its shadowmask channel (settings.lightingMode).
  LightModePlan lightModes;
  std::vector<std::string> warnings;  // includes lightModes.warnings
  LightmapBakeStats stats;
};

// Bakes every lightmapped object of `scene`. Deterministic: the same scene and settings give
// bit-identical pages at any thread count. Reports progress when `progress` is given; stops
// early and returns an Error "cancelled" when *cancel becomes true. Errors name the object
// and the setting at fault (e.g. a maxSize that cannot fit one object).
Result<LightmapBakeResult> bakeLightmaps(const Scene& scene, const LightmapBakeSettings& settings,
                                         bool showProgress = false,
                                         const std::atomic<bool>* cancel = nullptr);

}  // namespace kiln
