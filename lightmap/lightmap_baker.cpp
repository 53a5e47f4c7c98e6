// lightmap_baker.cpp: kiln bake's pipeline (see lightmap_baker.h): UVs, atlas, texels,
// push-out, light, post. One function per stage over plain data, each run through
// kiln::parallelFor with progress and the cancel flag (Godot's LightmapperCPU layout).
//
// Choices worth knowing:
//   - Irradiance is estimated with the interpolated shading normal (the normal a shader
//     lights the texel with; scenes without normal maps have nothing finer).
//   - Randomness: texel t of page p draws from the stream hashValues(seed, p, t); its
//     supersample points take disjoint, consecutive index ranges of that stream, so the
//     union of a texel's paths is one stratified Sobol prefix (better than independent
//     streams per point) and nothing depends on the thread that ran it.
//   - Validity is decided per sample point: a point whose first rays see back faces more
//     often than backfaceTolerance is inside geometry and is dropped from its texel's value
//     (a valid texel holds the mean over its unoccluded points); a texel is invalid when all
//     its points are. Invalid texels: those within one ring (8-neighbours) of a texel of
//     their object with a point on the visible surface (outside geometry where it was
//     rasterized, not moved by push-out) are filled from their valid neighbours, because a
//     bilinear lookup at a visible surface point can read them; deeper ones (a floor under
//     a block, a ceiling behind a lamp) keep the mean over all their samples, the physical
//     irradiance of a surface enclosed by geometry (~0: paths end on back faces, shadow
//     rays are blocked).
//     Filling those from lit neighbours too (kiln's first policy) invents light that no
//     surface point there receives; Cycles bakes them black.
//   - Post order: denoise (valid texels only), then fill invalid texels from the denoised
//     values (so filled texels inherit no noise), dilate into padding, stitch seams.
//   - Mixed lighting: the integrator's directLights / indirectLights come from
//     planLightModes (src/light_modes.h). Shadowmask channels hold the visibility of the
//     channel's light at the texel's points (Integrator::lightVisibility, the same shadow
//     rays as direct light: soft shadows over the texel's samples); directions come from
//     the same estimate as the light (Integrator::irradiance's weightedDirection).
#include "lightmap/lightmap_baker.h"

#include <array>
#include <chrono>
#include <cmath>

#include "lightmap/directional.h"
#include "lightmap/postprocess.h"
#include "lightmap/seams.h"
#include "lightmap/texel_raster.h"
#include "src/integrator.h"
#include "src/parallel.h"
#include "src/tracer.h"

namespace kiln {

namespace {

constexpr uint64_t kAoTag = 0x616f;  // "ao": ambient occlusion rays' stream
constexpr uint64_t kShadowmaskTag = 0x736d;  // "sm": shadowmask rays' stream
constexpr uint64_t kEnclosureTag = 0x656e;  // "en": enclosure rays' stream
// Enclosure test: cosine-weighted rays per sample point (it stops at the first that
// escapes, so an open point costs one or two rays).
constexpr uint32_t kEnclosureRays = 32;
// Light batches per texel: the spread of batch means estimates each texel's variance for
// the denoiser (the batches together are exactly the full estimate).
constexpr uint32_t kVarianceBatches = 4;
// Push-out: rays in 8 directions of the surface's tangent plane, reaching this many texel
// edges, repeated this many times (a point in a corner of two solids needs two moves).
constexpr int kPushDirections = 8;
constexpr float kPushReachTexels = 1.0f;
constexpr int kPushPasses = 2;

Status validate(const LightmapBakeSettings& s) {
  auto bad = [](const std::string& what) { return Status(Error{"lightmap bake: " + what}); };
  if (!(s.resolution > 0.0f) || !std::isfinite(s.resolution))
    return bad("resolution must be > 0 texels per unit (got " + std::to_string(s.resolution) + ")");
  if (s.padding < 0) return bad("padding must be >= 0 (got " + std::to_string(s.padding) + ")");
  if (s.maxSize < 1 + 2 * s.padding)
    return bad("maxSize " + std::to_string(s.maxSize) + " cannot hold one texel with padding " +
               std::to_string(s.padding) +
               " on both sides (needs >= " + std::to_string(1 + 2 * s.padding) + ")");
  if (s.samplesPerTexel < 1)
    return bad("samplesPerTexel must be >= 1 (got " + std::to_string(s.samplesPerTexel) + ")");
  if (s.supersampling < 1 || s.supersampling > 16)
    return bad("supersampling must be in [1, 16] (got " + std::to_string(s.supersampling) + ")");
  if (s.samplesPerTexel < s.supersampling * s.supersampling)
    return bad("samplesPerTexel " + std::to_string(s.samplesPerTexel) +
               " is fewer than the supersampling's " +
               std::to_string(s.supersampling * s.supersampling) +
               " points per texel (every point needs a sample)");
  if (s.bounces < 0) return bad("bounces must be >= 0 (got " + std::to_string(s.bounces) + ")");
  if (!(s.albedoBoost > 0.0f))
    return bad("albedoBoost must be > 0 (got " + std::to_string(s.albedoBoost) + ")");
  if (!(s.indirectIntensity >= 0.0f))
    return bad("indirectIntensity must be >= 0 (got " + std::to_string(s.indirectIntensity) + ")");
  if (!(s.backfaceTolerance >= 0.0f && s.backfaceTolerance <= 1.0f))
    return bad("backfaceTolerance must be in [0, 1] (got " + std::to_string(s.backfaceTolerance) +
               ")");
  if (s.ambientOcclusion && !(s.aoMaxDistance > 0.0f))
    return bad("aoMaxDistance must be > 0 (got " + std::to_string(s.aoMaxDistance) + ")");
  if (!(s.enclosedTexels >= 0.0f) || !std::isfinite(s.enclosedTexels))
    return bad("enclosedTexels must be >= 0 (got " + std::to_string(s.enclosedTexels) + ")");
  if (s.ambientOcclusion && !(s.aoAmount >= 0.0f && s.aoAmount <= 1.0f))
    return bad("aoAmount must be in [0, 1] (got " + std::to_string(s.aoAmount) + ")");
  for (int c = 0; c < 3; ++c)
    if (!(s.shadowColor[c] >= 0.0f) || !std::isfinite(s.shadowColor[c]))
      return bad("shadowColor components must be finite and >= 0 (got " +
                 std::to_string(s.shadowColor[c]) + ")");
  return Status::success();
}

bool cancelled(const std::atomic<bool>* cancel) { return cancel && cancel->load(); }

// A covered texel: its page and index in the page.
struct TexelRef {
  uint32_t page;
  uint32_t index;
};

std::vector<TexelRef> coveredTexels(const std::vector<RasterPage>& pages) {
  std::vector<TexelRef> refs;
  for (uint32_t p = 0; p < pages.size(); ++p)
    for (uint32_t i = 0; i < pages[p].texels.size(); ++i)
      if (pages[p].texels[i].valid()) refs.push_back({p, i});
  return refs;
}

// The sample points a texel's light is estimated at: its supersample points, or the main
// sample (supersampling 1, or a sliver no grid point fell on).
std::pair<TexelPoint*, uint32_t> texelPoints(RasterPage& page, TexelSample& texel,
                                             int supersampling) {
  if (supersampling > 1 && texel.subsampleCount > 0)
    return {&page.subsamples[texel.firstSubsample], texel.subsampleCount};
  return {&texel.sample, 1u};
}

// Stage 4, one point: rays along the surface's tangent plane (geometric normal of its
// triangle) of length `reach`; when one hits the back of a single-sided solid surface, the
// point lies inside that solid (a floor under a wall, a box standing on it), so it moves
// past the nearest such surface along that ray. The classic lightmapper fix (Bakery's and
// lightmapper.h's sample push-off, Unity's "Push Off"): without it, texels under a wall
// take light from the other side (leaks) and texels at its base shadow themselves.
// Returns the rays traced.
uint32_t pushOutPoint(const Scene& scene, const Tracer& tracer, uint32_t object, float reach,
                      TexelPoint& point) {
  const vec3 ng = scene.objects[object].faceNormal(point.triangle);
  if (!(glm::dot(ng, ng) > 0.0f)) return 0;
  const Frame frame = Frame::fromNormal(ng);
  uint32_t rays = 0;
  for (int pass = 0; pass < kPushPasses; ++pass) {
    const vec3 origin = offsetRayOrigin(point.position, ng);
    float nearest = reach;
    vec3 direction(0.0f);
    for (int d = 0; d < kPushDirections; ++d) {
      const float phi = 2.0f * kPi * float(d) / float(kPushDirections);
      const vec3 dir = std::cos(phi) * frame.t + std::sin(phi) * frame.b;
      ++rays;
      const auto hit = tracer.intersect(Ray{origin, dir, 0.0f, nearest});
      if (!hit || !hit->backFace) continue;
      const Material& m = scene.materialOf(hit->object, hit->triangle);
      if (m.doubleSided || m.alphaMode == AlphaMode::Blend) continue;
      nearest = hit->t;
      direction = dir;
    }
    if (!(glm::dot(direction, direction) > 0.0f)) break;
    // Past the surface by the tracer's own offset (scale-aware) plus a thousandth of a texel.
    const vec3 exit = origin + nearest * direction;
    point.position = offsetRayOrigin(exit, direction) + (1e-3f * reach) * direction;
    point.pushedOut = true;
  }
  return rays;
}

// Stage 4: every sample point of every covered texel, pushed out of nearby geometry.
bool pushOutStage(std::vector<RasterPage>& pages, const std::vector<TexelRef>& texels,
                  const Scene& scene, const AtlasLayout& layout, const Tracer& tracer,
                  bool showProgress, ParallelOptions options, std::atomic<uint64_t>& rays) {
  Progress progress("push-out", texels.size(), "texels", showProgress);
  options.progress = &progress;
  options.grain = 64;
  const bool done = parallelFor(
      texels.size(),
      [&](size_t begin, size_t end) {
        uint64_t local = 0;
        for (size_t i = begin; i < end; ++i) {
          RasterPage& page = pages[texels[i].page];
          TexelSample& texel = page.texels[texels[i].index];
          const uint32_t object = uint32_t(texel.object);
          const float reach = kPushReachTexels / layout.objects[object].texelsPerUnit;
          local += pushOutPoint(scene, tracer, object, reach, texel.sample);
          for (uint32_t s = 0; s < texel.subsampleCount; ++s)
            local += pushOutPoint(scene, tracer, object, reach,
                                  page.subsamples[texel.firstSubsample + s]);
        }
        rays += local;
      },
      options);
  if (done) progress.finish();
  return done;
}

// Stage 5 output for one covered texel.
struct TexelLight {
  vec3 value{0.0f};       // E / pi over the texel's valid points
  float variance = 0.0f;  // of the luminance of `value` (from batch means)
  float ao = 1.0f;
  vec4 shadowmask{1.0f};  // per channel: visible fraction of that channel's light
  vec4 direction{0.5f, 0.5f, 0.5f, 0.5f};  // encodeDominantDirection
  bool valid = false;
  // One of its points lies on the visible surface where it was rasterized (not inside a
  // solid, not moved by push-out): bilinear lookups at visible points read this texel.
  bool onVisibleSurface = false;
};

// Per shadowmask channel, the scene lights that hold it (lights in one channel never
// overlap, so at most one reaches a given point).
using ChannelLights = std::array<std::vector<uint32_t>, kShadowmaskChannels>;

ChannelLights channelLights(const LightModePlan& plan) {
  ChannelLights lights;
  for (uint32_t i = 0; i < plan.shadowmaskChannel.size(); ++i)
    if (plan.shadowmaskChannel[i] >= 0) lights[size_t(plan.shadowmaskChannel[i])].push_back(i);
  return lights;
}

// The influence test of light_modes.h's colouring: a point/spot light with a range reaches
// only the inside of its range sphere.
bool lightReaches(const Light& light, vec3 p) {
  if (light.type == LightType::Directional || !(light.range > 0.0f)) return true;
  return glm::length(p - light.position) < light.range;
}

struct LightSettings {
  uint32_t samples = 1;
  int supersampling = 1;
  uint64_t seed = 0;
  float backfaceTolerance = 0.5f;
  float enclosedTexels = 8.0f;
  const AtlasLayout* layout = nullptr;  // texelsPerUnit per object (enclosure reach)
  bool ambientOcclusion = false;
  float aoMaxDistance = 1.0f;
  bool directional = false;
  const ChannelLights* shadowmask = nullptr;  // null: no shadowmask
};

// Running sums over sample points (each term x the point's sample count).
struct PointSums {
  glm::dvec3 light{0.0};        // irradiance E
  glm::dvec3 direction{0.0};    // luminance-weighted directions
  vec3 normal{0.0f};            // sum of the points' normals (not weighted)
  glm::dvec4 visibility{0.0};   // per shadowmask channel
  double aoOccluded = 0.0;      // AO rays that hit something
  uint32_t samples = 0;

  void add(const PointSums& o) {
    light += o.light;
    direction += o.direction;
    normal += o.normal;
    visibility += o.visibility;
    aoOccluded += o.aoOccluded;
    samples += o.samples;
  }
};

// Validity on double-sided geometry: the point is enclosed when every one of
// kEnclosureRays cosine-weighted rays hits geometry within `reach` and none of those hits is
// the front of a single-sided surface (single-sided walls facing the point make a room, not
// a solid; the back-face test covers single-sided solids). Double-sided surfaces have no
// inside for the back-face test to see, so a floor under a closed double-sided box (all of
// its rays end on the box within its size) is caught here. BLEND surfaces let light through:
// a hit on one counts as escaping. Adds the rays traced to `rays`.
bool enclosed(const Integrator& integrator, const TexelPoint& p, float reach, uint64_t key,
              uint64_t& rays) {
  if (!(reach > 0.0f)) return false;
  const Scene& scene = integrator.scene();
  const Frame frame = Frame::fromNormal(p.normal);
  const vec3 origin = offsetRayOrigin(p.position, p.normal);
  const uint64_t enKey = hashValues(key, kEnclosureTag);
  for (uint32_t j = 0; j < kEnclosureRays; ++j) {
    SampleStream stream(enKey, j);
    const vec3 dir = frame.toWorld(squareToCosineHemisphere(stream.get2D()));
    ++rays;
    const auto hit = integrator.tracer().intersect(Ray{origin, dir, 0.0f, reach});
    if (!hit) return false;
    const Material& m = scene.materialOf(hit->object, hit->triangle);
    if (m.alphaMode == AlphaMode::Blend) return false;
    if (!m.doubleSided && !hit->backFace) return false;
  }
  return true;
}

// Stage 5, one texel: samples split evenly over its points (point i takes indices
// [i S / k, (i + 1) S / k) of the texel's stream), each point's share in kVarianceBatches
// batches. Points inside geometry (back-face share > tolerance) are left out of a valid
// texel's value, which is then the mean over the texel's unoccluded points (what a visible
// surface point near the texel sees). A texel with no such point is invalid; its value is
// then the plain mean over all its points: the physical irradiance of a surface enclosed by
// geometry, ~0 (paths end at back faces, shadow rays are blocked), which is what it keeps
// unless it is next to a valid texel (lightmap_baker.h, postPage).
TexelLight lightTexel(const Integrator& integrator, const LightSettings& s, uint64_t key,
                      const TexelPoint* points, uint32_t pointCount, float enclosedReach,
                      uint64_t& extraRays) {
  TexelLight out;
  PointSums used, all;
  std::vector<std::pair<double, uint32_t>> batches;  // (luminance of batch mean, size)
  for (uint32_t i = 0; i < pointCount; ++i) {
    const uint32_t first = uint32_t(uint64_t(i) * s.samples / pointCount);
    const uint32_t count = uint32_t(uint64_t(i + 1) * s.samples / pointCount) - first;
    if (count == 0) continue;
    const TexelPoint& p = points[i];
    uint32_t backFaces = 0;
    const uint32_t nb = std::min(kVarianceBatches, count);
    PointSums point;
    point.samples = count;
    point.normal = p.normal;
    const size_t batchStart = batches.size();
    for (uint32_t b = 0; b < nb; ++b) {
      const uint32_t bFirst = first + b * count / nb;
      const uint32_t bCount = first + (b + 1) * count / nb - bFirst;
      vec3 direction(0.0f);
      const vec3 e = integrator
                         .irradiance(p.position, p.normal, key, bFirst, bCount, &backFaces,
                                     s.directional ? &direction : nullptr)
                         .total();
      point.light += glm::dvec3(e) * double(bCount);
      point.direction += glm::dvec3(direction) * double(bCount);
      batches.push_back({double(luminance(e)) * kInvPi, bCount});
    }
    const bool inside = float(backFaces) > s.backfaceTolerance * float(count) ||
                        enclosed(integrator, p, enclosedReach, hashValues(key, i), extraRays);
    if (inside) batches.resize(batchStart);  // does not count towards a valid texel's value
    if (s.shadowmask) {
      // Each channel: the visibility of the one light of that channel reaching p, averaged
      // over the point's samples when the light's shadows are soft (one evaluation when
      // hard: every sample would trace the same ray).
      const uint64_t smKey = hashValues(key, kShadowmaskTag);
      const Scene& scene = integrator.scene();
      for (int c = 0; c < kShadowmaskChannels; ++c) {
        double v = double(count);  // unreached: unshadowed
        for (uint32_t light : (*s.shadowmask)[size_t(c)]) {
          const Light& l = scene.lights[light];
          if (!lightReaches(l, p.position)) continue;
          const bool soft = l.type == LightType::Directional ? l.shadowAngle > 0.0f
                                                             : l.shadowRadius > 0.0f;
          if (!soft) {
            v = double(count) *
                luminance(integrator.lightVisibility(p.position, p.normal, light, smKey, 0));
          } else {
            v = 0.0;
            for (uint32_t j = first; j < first + count; ++j)
              v += luminance(integrator.lightVisibility(p.position, p.normal, light, smKey, j));
          }
          break;
        }
        point.visibility[c] = v;
      }
    }
    if (s.ambientOcclusion) {
      // Cosine-weighted rays of length aoMaxDistance; the fraction that hits anything.
      const Frame frame = Frame::fromNormal(p.normal);
      const vec3 origin = offsetRayOrigin(p.position, p.normal);
      const uint64_t aoKey = hashValues(key, kAoTag);
      for (uint32_t j = first; j < first + count; ++j) {
        SampleStream stream(aoKey, j);
        const vec3 dir = frame.toWorld(squareToCosineHemisphere(stream.get2D()));
        if (integrator.tracer().occluded(Ray{origin, dir, 0.0f, s.aoMaxDistance}))
          point.aoOccluded += 1.0;
      }
      extraRays += count;
    }
    all.add(point);
    if (!inside) used.add(point);
    if (!inside && !p.pushedOut) out.onVisibleSurface = true;
  }
  out.valid = used.samples > 0;
  const PointSums& sums = out.valid ? used : all;
  if (sums.samples == 0) return out;
  const double n = double(sums.samples);
  out.value = vec3(sums.light / n) * kInvPi;
  if (s.shadowmask) out.shadowmask = glm::clamp(vec4(sums.visibility / n), 0.0f, 1.0f);
  if (s.directional) {
    const float len = glm::length(sums.normal);
    const vec3 normal = len > 0.0f ? sums.normal / len : vec3(0.0f);
    out.direction = encodeDominantDirection(vec3(sums.direction / n),
                                            luminance(vec3(sums.light / n)), normal);
  }
  if (s.ambientOcclusion) out.ao = 1.0f - float(sums.aoOccluded / n);
  // Variance of the mean from the spread of the batch means (batches of near-equal size).
  if (out.valid && batches.size() >= 2) {
    const double mean = double(luminance(out.value));
    double ss = 0.0;
    for (const auto& [l, count] : batches) ss += (l - mean) * (l - mean);
    const double m = double(batches.size());
    out.variance = float(ss / (m * (m - 1.0)));
  }
  return out;
}

// Stage 5: light at every covered texel.
bool lightStage(std::vector<RasterPage>& pages, const std::vector<TexelRef>& texels,
                const Integrator& integrator, const LightSettings& s, bool showProgress,
                ParallelOptions options, std::vector<TexelLight>& out,
                std::atomic<uint64_t>& rays) {
  Progress progress("bake", texels.size(), "texels", showProgress);
  options.progress = &progress;
  options.grain = 4;
  out.assign(texels.size(), TexelLight{});
  const bool done = parallelFor(
      texels.size(),
      [&](size_t begin, size_t end) {
        const uint64_t before = Integrator::threadRayCount();
        uint64_t extraRays = 0;
        for (size_t i = begin; i < end; ++i) {
          RasterPage& page = pages[texels[i].page];
          TexelSample& texel = page.texels[texels[i].index];
          const auto [points, count] = texelPoints(page, texel, s.supersampling);
          const uint64_t key = hashValues(s.seed, texels[i].page, texels[i].index);
          const float reach =
              s.enclosedTexels / s.layout->objects[size_t(texel.object)].texelsPerUnit;
          out[i] = lightTexel(integrator, s, key, points, count, reach, extraRays);
        }
        rays += Integrator::threadRayCount() - before + extraRays;
      },
      options);
  if (done) progress.finish();
  return done;
}

// Progress of stage 6's steps over all pages, in texels of the maps each step processes
// (the light, then the shadowmask, direction and AO maps).
struct PostProgress {
  Progress denoise, fill, dilation, seams;
  PostProgress(size_t denoised, size_t filled, size_t stitched, bool show)
      : denoise("denoise", denoised, "texels", show && denoised > 0),
        fill("fill", filled, "texels", show),
        dilation("dilation", filled, "texels", show),
        seams("seams", stitched, "texels", show && stitched > 0) {}
  void finish() {
    denoise.finish();
    fill.finish();
    dilation.finish();
    seams.finish();
  }
};

// Stage 6 for one page: denoise, fill invalid texels, dilate into padding, stitch seams.
void postPage(const Scene& scene, const AtlasLayout& layout, uint32_t pageIndex,
              const RasterPage& raster,
              const std::vector<TexelRef>& texels,
              const std::vector<TexelLight>& light, const LightmapBakeSettings& settings,
              bool withShadowmask, const ParallelOptions& parallel, PostProgress& progress,
              LightmapPageResult& result, size_t& clampedTexels) {
  const int w = raster.width, h = raster.height;
  const size_t n = size_t(w) * size_t(h);
  LightmapPage page;
  page.radiance = Image(w, h, 3);
  page.valid.assign(n, 0);
  page.objectId.assign(n, -1);
  page.normal = Image(w, h, 3);
  page.position = Image(w, h, 3);
  page.variance.assign(n, 0.0f);
  page.texelWorldSize.assign(n, 0.0f);
  Image ao = settings.ambientOcclusion ? Image(w, h, 1) : Image();
  Image shadowmask = withShadowmask ? Image(w, h, 4) : Image();
  Image direction = settings.directional ? Image(w, h, 4) : Image();
  for (size_t i = 0; i < texels.size(); ++i) {
    if (texels[i].page != pageIndex) continue;
    const size_t t = texels[i].index;
    const TexelSample& texel = raster.texels[t];
    page.objectId[t] = texel.object;
    page.valid[t] = light[i].valid ? 1 : 0;
    page.variance[t] = light[i].variance;
    page.texelWorldSize[t] = 1.0f / layout.objects[size_t(texel.object)].texelsPerUnit;
    for (int c = 0; c < 3; ++c) {
      page.radiance.pixels[3 * t + c] = light[i].value[c];
      page.normal.pixels[3 * t + c] = texel.sample.normal[c];
      page.position.pixels[3 * t + c] = texel.sample.position[c];
    }
    if (!ao.empty()) ao.pixels[t] = light[i].ao;
    for (int c = 0; c < 4; ++c) {
      if (!shadowmask.empty()) shadowmask.pixels[4 * t + c] = light[i].shadowmask[c];
      if (!direction.empty()) direction.pixels[4 * t + c] = light[i].direction[c];
    }
  }
  result.valid = page.valid;
  result.position = page.position;

  // Invalid texels (inside geometry): those next to a texel of their object with a point on
  // the visible surface (TexelLight::onVisibleSurface; a texel whose centre push-out did not
  // move may still lie more than a texel inside a solid) are read by bilinear lookups at
  // visible points, so they take the inverse-square average of their valid 8-neighbours
  // (radius 1.5 texels: only the adjacent ones, so a texel under a thin wall takes the side
  // it touches, not light from across the wall). The others are more than a texel from any
  // visible point and keep their physical value (lightTexel: ~0), as an independent renderer
  // bakes them (docs/lightmap_outputs.md).
  std::vector<uint8_t> onVisible(n, 0);
  for (size_t i = 0; i < texels.size(); ++i)
    if (texels[i].page == pageIndex) onVisible[texels[i].index] = light[i].onVisibleSurface;
  FillSettings fill;
  fill.parallel = parallel;
  fill.radius = 1.5f;
  fill.maxRings = 1;
  fill.ringSeeds = &onVisible;
  DenoiseSettings denoiseSettings;
  denoiseSettings.parallel = parallel;
  // Each step runs inside its progress line's Busy, so the line's time is the step's own.
  if (settings.denoise) {
    auto busy = progress.denoise.busy();
    denoise(page, denoiseSettings);
    progress.denoise.advance(n);
  }
  std::vector<uint8_t> filled;
  {
    auto busy = progress.fill.busy();
    filled = fillInvalid(page.radiance, page.valid, page.objectId, fill);
    progress.fill.advance(n);
  }
  // Rings enough to cover the gutters between objects (2 x padding) and between charts.
  const int rings = std::max(2, 2 * settings.padding);
  std::vector<uint8_t> mask;
  {
    auto busy = progress.dilation.busy();
    mask = dilate(page.radiance, filled, rings, parallel);
    progress.dilation.advance(n);
  }
  auto stitch = [&](Image& image, const std::vector<uint8_t>& imageMask) {
    if (!settings.stitchSeams) return;
    auto busy = progress.seams.busy();
    for (size_t o = 0; o < scene.objects.size(); ++o) {
      if (layout.objects[o].lightmapIndex != int(pageIndex)) continue;
      const auto seams = findSeams(scene.objects[o], layout.objects[o].scaleOffset, w, h);
      if (!seams.empty()) (void)stitchSeams(image, imageMask, seams);
    }
    progress.seams.advance(n);
  };
  stitch(page.radiance, mask);
  result.light = std::move(page.radiance);

  // Shadowmask and direction maps: no denoising (see lightmap_baker.h), the same fill,
  // dilation and stitching as the light, so that bilinear lookups at chart borders and
  // seams read the same texels in every map. Padding starts unshadowed / undirected (what
  // dilation does not reach keeps it); invalid texels hold their own estimate (lightTexel).
  for (Image* image : {&shadowmask, &direction}) {
    if (image->empty()) continue;
    for (size_t t = 0; t < n; ++t)
      if (page.objectId[t] < 0)
        for (int c = 0; c < 4; ++c)
          image->pixels[4 * t + c] = image == &shadowmask ? 1.0f : 0.5f;
    std::vector<uint8_t> f, m;
    {
      auto busy = progress.fill.busy();
      f = fillInvalid(*image, page.valid, page.objectId, fill);
      progress.fill.advance(n);
    }
    {
      auto busy = progress.dilation.busy();
      m = dilate(*image, f, rings, parallel);
      progress.dilation.advance(n);
    }
    stitch(*image, m);
  }
  result.shadowmask = std::move(shadowmask);
  result.direction = std::move(direction);

  if (!ao.empty()) {
    if (settings.denoise) {
      auto busy = progress.denoise.busy();
      LightmapPage aoPage = page;  // guides; radiance replaced by the AO map
      aoPage.radiance = std::move(ao);
      aoPage.variance.clear();
      denoise(aoPage, denoiseSettings);
      ao = std::move(aoPage.radiance);
      progress.denoise.advance(n);
    }
    std::vector<uint8_t> aoFilled;
    {
      auto busy = progress.fill.busy();
      aoFilled = fillInvalid(ao, page.valid, page.objectId, fill);
      progress.fill.advance(n);
    }
    {
      auto busy = progress.dilation.busy();
      (void)dilate(ao, aoFilled, rings, parallel);
      progress.dilation.advance(n);
    }
    // Applied after both maps are final, texel by texel, so that every texel of the written
    // pages satisfies light = light without AO x (1 - aoAmount (1 - ao)) (the factor is in
    // [1 - aoAmount, 1]: it cannot make a texel negative).
    if (settings.aoAmount > 0.0f)
      for (size_t t = 0; t < n; ++t) {
        const float factor = 1.0f - settings.aoAmount * (1.0f - ao.pixels[t]);
        for (int c = 0; c < 3; ++c) result.light.pixels[3 * t + c] *= factor;
      }
    result.ambientOcclusion = std::move(ao);
  }

  // Last guard: a light map holds E / pi, never below 0 (unsigned encodings clamp it
  // anyway). Every stage above keeps values >= 0 (integrator estimates, convex kernels in
  // denoise / fill / dilate, the stitcher's non-negative solve), so nothing should reach
  // here; what does is set to 0 and counted in stats.clampedTexels (the manifest's stats),
  // not hidden.
  for (size_t t = 0; t < n; ++t) {
    bool clamped = false;
    for (int c = 0; c < 3; ++c) {
      float& v = result.light.pixels[3 * t + c];
      if (!(v >= 0.0f) || !std::isfinite(v)) {
        v = 0.0f;
        clamped = true;
      }
    }
    clampedTexels += clamped ? 1 : 0;
  }
}

}  // namespace

Status applyLightmapPreset(const std::string& preset, LightmapBakeSettings& settings) {
  struct Preset {
    const char* name;
    int samples;
    int supersampling;
  };
  static constexpr Preset kPresets[] = {{"preview", 16, 1},
                                        {"low", 64, 1},
                                        {"medium", 256, 1},
                                        {"high", 1024, 2},
                                        {"production", 4096, 2}};
  for (const Preset& p : kPresets) {
    if (preset != p.name) continue;
    settings.samplesPerTexel = p.samples;
    settings.supersampling = p.supersampling;
    return Status::success();
  }
  return Error{"unknown quality preset \"" + preset +
               "\" (valid: preview, low, medium, high, production)"};
}

Result<LightmapBakeResult> bakeLightmaps(const Scene& scene, const LightmapBakeSettings& settings,
                                         bool showProgress, const std::atomic<bool>* cancel) {
  if (Status s = validate(settings); !s) return Error{s.error()};
  if (cancelled(cancel)) return Error{"cancelled"};
  ParallelOptions parallel;
  parallel.threads = settings.threads;
  parallel.cancel = cancel;

  LightmapBakeResult result;
  result.scene = scene;
  // Stage 1: UVs.
  UnwrapSettings unwrap;
  unwrap.gutterTexels = std::max(1, settings.padding);
  unwrap.minObjectTexels = settings.minObjectTexels;
  unwrap.showProgress = showProgress;
  unwrap.cancel = cancel;
  auto unwraps = generateMissingLightmapUvs(result.scene, settings.resolution, unwrap);
  if (cancelled(cancel)) return Error{"cancelled"};
  if (!unwraps) return Error{"lightmap UVs: " + unwraps.error()};
  result.unwraps = std::move(unwraps).value();

  // Stage 2: atlas.
  AtlasSettings atlas;
  atlas.resolution = settings.resolution;
  atlas.padding = settings.padding;
  atlas.maxSize = settings.maxSize;
  atlas.minObjectTexels = settings.minObjectTexels;
  for (const std::optional<UnwrapResult>& u : result.unwraps)
    atlas.worldPerUv.push_back(u ? u->worldPerUv : 0.0);
  atlas.locked = settings.lockedAtlas;
  atlas.showProgress = showProgress;
  atlas.cancel = cancel;
  auto layout = packAtlas(result.scene, atlas);
  if (cancelled(cancel)) return Error{"cancelled"};
  if (!layout) return Error{"lightmap atlas: " + layout.error()};
  result.layout = std::move(layout).value();
  result.warnings = result.layout.warnings;

  // Stage 3: texels.
  RasterSettings raster;
  raster.supersampling = settings.supersampling;
  raster.parallel = parallel;
  size_t rasterRows = 0;  // rasterizeAtlas runs in parallel over each page's rows
  for (const AtlasPage& p : result.layout.pages) rasterRows += size_t(p.height);
  Progress rasterProgress("rasterization", rasterRows, "rows", showProgress && rasterRows > 0);
  raster.parallel.progress = &rasterProgress;
  auto rasterPages = rasterizeAtlas(result.scene, result.layout, raster);
  if (cancelled(cancel)) return Error{"cancelled"};
  if (!rasterPages) return Error{"lightmap texels: " + rasterPages.error()};
  rasterProgress.finish();
  std::vector<RasterPage> pages = std::move(rasterPages).value();
  const std::vector<TexelRef> texels = coveredTexels(pages);

  // Static objects only: dynamic ones cast, bounce and emit nothing into the lightmaps.
  auto tracer = Tracer::create(result.scene, TracerGeometry::BakedGI);
  if (!tracer) return Error{"lightmap bake: " + tracer.error()};
  std::atomic<uint64_t> rays{0};

  // Stage 4: push-out.
  const auto start = std::chrono::steady_clock::now();
  if (!pushOutStage(pages, texels, result.scene, result.layout, **tracer, showProgress, parallel,
                    rays) ||
      cancelled(cancel))
    return Error{"cancelled"};

  // Stage 5: light.
  result.lightModes = planLightModes(result.scene, settings.lightingMode);
  for (const std::string& w : result.lightModes.warnings) result.warnings.push_back(w);
  const ChannelLights shadowmaskLights = channelLights(result.lightModes);
  bool withShadowmask = false;
  for (int c : result.lightModes.shadowmaskChannel) withShadowmask |= c >= 0;
  IntegratorSettings is;
  is.directLights = result.lightModes.bakeDirect;
  is.indirectLights = result.lightModes.bakeIndirect;
  is.maxBounces = settings.bounces;
  is.albedoBoost = settings.albedoBoost;
  is.indirectIntensity = settings.indirectIntensity;
  const Integrator integrator(result.scene, **tracer, is);
  LightSettings ls;
  ls.samples = uint32_t(settings.samplesPerTexel);
  ls.supersampling = settings.supersampling;
  ls.seed = settings.seed;
  ls.backfaceTolerance = settings.backfaceTolerance;
  ls.ambientOcclusion = settings.ambientOcclusion;
  ls.aoMaxDistance = settings.aoMaxDistance;
  ls.enclosedTexels = settings.enclosedTexels;
  ls.layout = &result.layout;
  ls.directional = settings.directional;
  ls.shadowmask = withShadowmask ? &shadowmaskLights : nullptr;
  std::vector<TexelLight> light;
  if (!lightStage(pages, texels, integrator, ls, showProgress, parallel, light, rays) ||
      cancelled(cancel))
    return Error{"cancelled"};
  result.stats.seconds =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();

  // Stage 6: post, page by page (each post function is parallel inside).
  result.pages.resize(pages.size());
  size_t pageTexels = 0;
  for (const RasterPage& p : pages) pageTexels += size_t(p.width) * size_t(p.height);
  // Maps per step (postPage): light, shadowmask, direction and AO are filled and dilated;
  // light and AO denoised; light, shadowmask and direction stitched.
  const size_t extraMaps = size_t(withShadowmask) + size_t(settings.directional);
  const size_t aoMaps = settings.ambientOcclusion ? 1 : 0;
  PostProgress postProgress(settings.denoise ? pageTexels * (1 + aoMaps) : 0,
                            pageTexels * (1 + extraMaps + aoMaps),
                            settings.stitchSeams ? pageTexels * (1 + extraMaps) : 0,
                            showProgress);
  for (uint32_t p = 0; p < pages.size(); ++p) {
    postPage(result.scene, result.layout, p, pages[p], texels, light, settings,
             withShadowmask,
             parallel, postProgress, result.pages[p], result.stats.clampedTexels);
    if (cancelled(cancel)) return Error{"cancelled"};
  }
  postProgress.finish();

  result.stats.texels = texels.size();
  for (const TexelLight& t : light) result.stats.invalidTexels += t.valid ? 0 : 1;
  result.stats.rays = rays.load();
  if (result.stats.clampedTexels > 0)
    result.warnings.push_back(std::to_string(result.stats.clampedTexels) +
                              " light map texel(s) were negative or not finite after "
                              "post-processing and were set to 0 (stats.clampedTexels)");
  if (result.stats.invalidTexels > 0 && result.stats.invalidTexels * 10 > texels.size())
    result.warnings.push_back(std::to_string(result.stats.invalidTexels) + " of " +
                              std::to_string(texels.size()) +
                              " texels are inside geometry (see texel validity in docs/lightmap_outputs.md)");
  return result;
}

}  // namespace kiln
