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
#include <cassert>
#include <algorithm>
#include <chrono>
#include <cmath>
#include <functional>
#include <memory>
#include <unordered_map>

#include "lightmap/directional.h"
#include "lightmap/probe_lit.h"
#include "lightmap/postprocess.h"
#include "lightmap/seams.h"
#include "lightmap/texel_raster.h"
#include "src/distributed.h"
#include "src/integrator.h"
#include "src/parallel.h"
#include "src/tracer.h"

namespace kiln {

namespace {

constexpr uint64_t kAoTag = 0x616f;  // "ao": ambient occlusion rays' stream
constexpr uint64_t kShadowmaskTag = 0x736d;  // "sm": shadowmask rays' stream
constexpr uint64_t kEnclosureTag = 0x656e;  // "en": enclosure rays' stream
constexpr uint64_t kPilotTag = 0x706c;  // "pl": the error target's pilot pass
constexpr uint64_t kCacheTag = 0x6263;  // "bc": the bounce cache's first pass
// Enclosure test: cosine-weighted rays per sample point (it stops at the first that
// escapes, so an open point costs one or two rays).
constexpr uint32_t kEnclosureRays = 32;
// Light batches per texel: the spread of batch means estimates each texel's variance for
// the denoiser (the batches together are exactly the full estimate).
constexpr uint32_t kVarianceBatches = 16;
// Batches per group for the coarse variance estimate (TexelLight::varianceCoarse).
constexpr uint32_t kGroupBatches = 4;
constexpr uint32_t kQmcMinPaths = 4 * kVarianceBatches;
// Push-out: rays in 8 directions of the surface's tangent plane, reaching this many texel
// edges, repeated this many times (a point in a corner of two solids needs two moves).
constexpr int kPushDirections = 8;
constexpr float kPushReachTexels = 1.0f;
constexpr int kPushPasses = 2;
// Footprint grid of texels next to geometry: n x n points (stage 4b).
constexpr int kFootprintGrid = 4;
// Adaptive sampling (allocateSamples): no texel takes more than this many times the mean.
constexpr uint32_t kAdaptiveCap = 8;

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
  if (!(s.errorTarget >= 0.0f) || !std::isfinite(s.errorTarget))
    return bad("errorTarget must be >= 0 (got " + std::to_string(s.errorTarget) + ")");
  if (s.errorTarget > 0.0f && (s.minSamples < 1 || s.pilotSamples < 1))
    return bad("with an errorTarget, minSamples and pilotSamples must be >= 1 (got " +
               std::to_string(s.minSamples) + " and " + std::to_string(s.pilotSamples) + ")");
  if (s.bounces < 0) return bad("bounces must be >= 0 (got " + std::to_string(s.bounces) + ")");
  if (s.bounceCacheSamples < 0)
    return bad("bounceCacheSamples must be >= 0 (got " + std::to_string(s.bounceCacheSamples) +
               ")");
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

// The sample points a texel's light is estimated at without a footprint grid: its
// supersample points, or the main sample (supersampling 1, or a sliver no grid point fell on).
std::pair<TexelPoint*, uint32_t> texelPoints(RasterPage& page, TexelSample& texel,
                                             int supersampling) {
  if (supersampling > 1 && texel.subsampleCount > 0)
    return {&page.subsamples[texel.firstSubsample], texel.subsampleCount};
  return {&texel.sample, 1u};
}

// A texel's footprint grid points (TexelSample::firstGridPoint); empty without a grid.
std::pair<TexelPoint*, uint32_t> gridPoints(RasterPage& page, TexelSample& texel) {
  if (!texel.footprintGrid()) return {nullptr, 0u};
  return {&page.subsamples[texel.firstGridPoint], texel.gridPointCount};
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
      if (!hit) continue;
      const Material& m = scene.materialOf(hit->object, hit->triangle);
      if (m.alphaMode == AlphaMode::Blend) continue;
      if (pass == 0) point.nearSurface = true;
      if (!hit->backFace || m.doubleSided) continue;
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

// Whether covered texel `index` of `page` has an 8-neighbour of its own object whose
// validity (per page, W x H, from the bounce cache's first pass) differs from its own: a
// hidden edge (the lamp's outline on the ceiling behind it) runs through or beside it.
bool onValidityEdge(const RasterPage& page, const std::vector<uint8_t>& validity, size_t index) {
  const int w = page.width, h = page.height;
  const int x = int(index % size_t(w)), y = int(index / size_t(w));
  const int32_t object = page.texels[index].object;
  for (int dy = -1; dy <= 1; ++dy)
    for (int dx = -1; dx <= 1; ++dx) {
      const int nx = x + dx, ny = y + dy;
      if (nx < 0 || ny < 0 || nx >= w || ny >= h) continue;
      const size_t n = size_t(ny) * size_t(w) + size_t(nx);
      if (page.texels[n].object == object && validity[n] != validity[index]) return true;
    }
  return false;
}

// Stage 4b, one grid point: whether the straight path along the surface from the texel's
// main sample `anchor` (after push-out: on the visible surface unless it lies more than
// push-out's reach inside a solid) to grid point `point` crosses geometry. Both ends are
// lifted off the surface along their triangles' geometric normals by the tracer's offset
// plus how far each lies below the other's tangent plane: on a flat surface that is the
// offset alone, so a wall standing on it or a solid's face (even a double-sided one, which
// push-out cannot see into) cuts the segment; on a convex surface (a cylinder, a box's edge
// inside one chart) the segment then clears the surface's own bulge between the two points
// (the sagitta of a chord is a quarter of the depth of its end below the other's tangent
// plane). BLEND surfaces let light through and do not cut it, as in push-out. Returns true
// when the point is hidden from the anchor (a wall or a solid's face in between); adds the
// rays traced to `rays`.
bool hiddenFromAnchor(const Scene& scene, const Tracer& tracer, uint32_t object,
                      const TexelPoint& anchor, const TexelPoint& point, uint64_t& rays) {
  const Object& o = scene.objects[object];
  const vec3 na = o.faceNormal(anchor.triangle), ng = o.faceNormal(point.triangle);
  const float lift = std::max({0.0f, -glm::dot(point.position - anchor.position, na),
                               -glm::dot(anchor.position - point.position, ng)});
  const vec3 from = offsetRayOrigin(anchor.position, na) + lift * na;
  const vec3 to = offsetRayOrigin(point.position, ng) + lift * ng;
  const vec3 d = to - from;
  const float length = glm::length(d);
  if (!(length > 0.0f)) return false;
  Ray ray{from, d / length, 0.0f, length};
  // A BLEND surface in the way: go on past it (at most a few layers of glass).
  for (int layer = 0; layer < 8; ++layer) {
    ++rays;
    const auto hit = tracer.intersect(ray);
    if (!hit) return false;
    if (scene.materialOf(hit->object, hit->triangle).alphaMode != AlphaMode::Blend) return true;
    ray.tMin = hit->t + 1e-4f;
  }
  return true;
}

// Stage 4b: texels next to geometry (a sample point push-out moved, or a tangent-plane ray
// that hit a surface within a texel) and, when the bounce cache's first pass gave each
// texel's validity (`validity`, per page, else null), texels on an edge between valid and
// invalid texels get a kFootprintGrid^2 grid of points over their footprint (at least the
// supersampling grid). A grid point the texel's main sample cannot reach along the surface
// without crossing geometry (hiddenFromAnchor) is hidden: inside a solid standing on the
// surface, or on the far side of a wall the texel straddles (a texel belongs to the side its
// main sample is on, after push-out). The others, found inside in lightTexel (seeing back
// faces, enclosed), are hidden too; the texel's value is the mean over the visible rest.
// Texels elsewhere keep their points: nothing within a texel of them can hide part of their
// footprint. The validity edge finds what push-out's tangent-plane rays cannot: a surface
// hidden behind a parallel one (the ceiling 1 mm above the lamp). One ray per grid point;
// the grid points are not pushed out (a point push-out would move is hidden anyway).
bool footprintStage(std::vector<RasterPage>& pages, const std::vector<TexelRef>& texels,
                    const Scene& scene, const AtlasLayout& layout, const Tracer& tracer,
                    int supersampling, const std::vector<std::vector<uint8_t>>* validity,
                    bool showProgress, ParallelOptions options, std::atomic<uint64_t>& rays,
                    std::string& error) {
  std::vector<std::vector<uint8_t>> masks(pages.size());
  for (size_t p = 0; p < pages.size(); ++p) masks[p].assign(pages[p].texels.size(), 0);
  size_t flagged = 0;
  for (const TexelRef& t : texels) {
    const RasterPage& page = pages[t.page];
    const TexelSample& texel = page.texels[t.index];
    bool near = texel.sample.nearSurface || texel.sample.pushedOut;
    for (uint32_t s = 0; s < texel.subsampleCount && !near; ++s) {
      const TexelPoint& q = page.subsamples[texel.firstSubsample + s];
      near = q.nearSurface || q.pushedOut;
    }
    near = near || (validity && onValidityEdge(page, (*validity)[t.page], t.index));
    masks[t.page][t.index] = near ? 1 : 0;
    flagged += near ? 1 : 0;
  }
  if (flagged == 0) return true;
  RasterSettings raster;
  raster.supersampling = std::max(supersampling, kFootprintGrid);
  raster.subsampleMask = &masks;
  raster.parallel = options;
  raster.parallel.progress = nullptr;
  auto grids = rasterizeAtlas(scene, layout, raster);
  if (!grids) {
    error = grids.error();
    return false;
  }
  // The grid points of the flagged texels, appended to their page's subsamples (after the
  // supersampling points, which stay).
  struct NewPoint {
    uint32_t page, texel, index;
  };
  std::vector<NewPoint> added;
  for (const TexelRef& t : texels) {
    if (!masks[t.page][t.index]) continue;
    const RasterPage& grid = (*grids)[t.page];
    const TexelSample& g = grid.texels[t.index];
    if (g.subsampleCount == 0) continue;  // a sliver no grid point falls on
    RasterPage& page = pages[t.page];
    TexelSample& texel = page.texels[t.index];
    texel.firstGridPoint = uint32_t(page.subsamples.size());
    texel.gridPointCount = g.subsampleCount;
    for (uint32_t s = 0; s < g.subsampleCount; ++s) {
      added.push_back({t.page, t.index, uint32_t(page.subsamples.size())});
      page.subsamples.push_back(grid.subsamples[g.firstSubsample + s]);
    }
  }
  Progress progress("footprint", added.size(), "points", showProgress && !added.empty());
  options.progress = &progress;
  options.grain = 256;
  const bool done = parallelFor(
      added.size(),
      [&](size_t begin, size_t end) {
        uint64_t local = 0;
        for (size_t i = begin; i < end; ++i) {
          RasterPage& page = pages[added[i].page];
          const TexelSample& texel = page.texels[added[i].texel];
          TexelPoint& point = page.subsamples[added[i].index];
          point.hidden = hiddenFromAnchor(scene, tracer, uint32_t(texel.object), texel.sample,
                                          point, local);
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
  // The same from the means of groups of kGroupBatches consecutive batches (4x the paths
  // each): with quasi-Monte Carlo its ratio to `variance` measures how much faster than
  // 1 / N the error falls (qmcVarianceFactor).
  float varianceCoarse = 0.0f;
  float ao = 1.0f;
  vec4 shadowmask{1.0f};  // per channel: visible fraction of that channel's light
  vec4 direction{0.5f, 0.5f, 0.5f, 0.5f};  // encodeDominantDirection
  bool valid = false;
  uint32_t samples = 0;    // paths the texel took (over all its points)
  uint64_t rays = 0;       // rays traced for it in stage 5
  // Footprint weight: value x coverage = the mean of E / pi over the texel's whole footprint,
  // points inside geometry included at their own (dark) estimate; the visible share of the
  // footprint on a footprint grid, 1 elsewhere (LightmapPageResult::coverage).
  float coverage = 1.0f;
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
  uint32_t samples = 1;     // paths per texel
  int supersampling = 1;
  uint64_t seed = 0;
  float backfaceTolerance = 0.5f;
  float enclosedTexels = 8.0f;
  const AtlasLayout* layout = nullptr;  // texelsPerUnit per object (enclosure reach)
  bool ambientOcclusion = false;
  float aoMaxDistance = 1.0f;
  bool directional = false;
  const ChannelLights* shadowmask = nullptr;  // null: no shadowmask
  // Per covered texel (index-aligned with the light stage's texels), its paths instead of
  // `samples` (allocateSamples); null = `samples` everywhere.
  const std::vector<uint32_t>* texelSamples = nullptr;
  // Every texel at its main sample point only (the error target's pilot pass).
  bool mainPointOnly = false;
};

// The points stage 5 traces for a texel: its own points (texelPoints) and its footprint grid
// (gridPoints, empty without one); the pilot pass (mainPointOnly) traces the main sample alone.
struct TexelPointSets {
  std::pair<TexelPoint*, uint32_t> own, grid;
};
TexelPointSets lightPointSets(RasterPage& page, TexelSample& texel, const LightSettings& s) {
  if (s.mainPointOnly) return {{&texel.sample, 1u}, {nullptr, 0u}};
  return {texelPoints(page, texel, s.supersampling), gridPoints(page, texel)};
}

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

// Stage 5, one set of points of a texel: s.samples paths of the texel's stream [0, N), split
// evenly over the points (point i takes [i N / k, (i + 1) N / k)), so the union of the
// texel's paths is one Sobol prefix. They run as kVarianceBatches batches, batch b holding
// slice b of every point's share (so a batch mean is over the whole texel, not one point),
// and the spread of the batch means gives the variance of the texel's mean (for the
// denoiser). How many paths a texel takes is decided before it starts (a fixed count, or the
// error target's pilot pass, allocateSamples), never from its own paths: a rule that stops
// where the texel's own paths happen to agree biases it dark.
// Every decision uses this texel's own samples: the result does not depend on threads.
//
// Points inside geometry (back-face share > tolerance, or enclosed) are left out of a valid
// texel's value, which is then the mean over the texel's unoccluded points (what a visible
// surface point near the texel sees). With `footprintGrid` the points are a grid over the
// texel's footprint (TexelSample::firstGridPoint) whose hidden points (TexelPoint::hidden:
// across a wall or inside a solid from the texel's main sample) are never traced: the texel
// holds the mean over the visible part of its footprint, and `coverage` is that part's
// share. With no visible point the result is invalid; its value is then the plain mean over
// all its points (the physical irradiance of a surface enclosed by geometry, ~0: paths end
// at back faces, shadow rays are blocked), which it keeps unless it is next to a valid
// texel (postPage).
TexelLight lightPoints(const Integrator& integrator, const LightSettings& s, uint64_t key,
                       const TexelPoint* points, uint32_t pointCount, bool footprintGrid,
                       float enclosedReach, uint64_t& extraRays) {
  TexelLight out;
  // Points that take part: on a footprint grid the ones not hidden (the caller gives a grid
  // with at least one), else all.
  std::vector<uint32_t> active;
  for (uint32_t i = 0; i < pointCount; ++i)
    if (!footprintGrid || !points[i].hidden) active.push_back(i);
  assert(!active.empty());
  const uint32_t k = uint32_t(active.size());
  std::vector<PointSums> sums(k);
  std::vector<uint32_t> backFaces(k, 0);
  std::vector<uint8_t> inside(k, 0);
  // Batch luminance sums and sample counts (over the points in use when the batch ran).
  std::vector<std::pair<double, uint32_t>> batches;
  const uint64_t smKey = hashValues(key, kShadowmaskTag);
  const uint64_t aoKey = hashValues(key, kAoTag);
  const Scene& scene = integrator.scene();

  // Samples [first, first + count) at point j, added to sums[j]; returns the luminance sum.
  auto run = [&](uint32_t j, uint32_t first, uint32_t count) -> double {
    const TexelPoint& p = points[active[j]];
    PointSums& point = sums[j];
    vec3 direction(0.0f);
    const vec3 e = integrator
                       .irradiance(p.position, p.normal, key, first, count, &backFaces[j],
                                   s.directional ? &direction : nullptr)
                       .total();
    point.light += glm::dvec3(e) * double(count);
    point.direction += glm::dvec3(direction) * double(count);
    point.samples += count;
    if (s.shadowmask) {
      // Each channel: the visibility of the one light of that channel reaching p, averaged
      // over the point's samples when the light's shadows are soft (one evaluation when
      // hard: every sample would trace the same ray).
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
            for (uint32_t i = first; i < first + count; ++i)
              v += luminance(integrator.lightVisibility(p.position, p.normal, light, smKey, i));
          }
          break;
        }
        point.visibility[c] += v;
      }
    }
    if (s.ambientOcclusion) {
      // Cosine-weighted rays of length aoMaxDistance; the fraction that hits anything.
      const Frame frame = Frame::fromNormal(p.normal);
      const vec3 origin = offsetRayOrigin(p.position, p.normal);
      for (uint32_t i = first; i < first + count; ++i) {
        SampleStream stream(aoKey, i);
        const vec3 dir = frame.toWorld(squareToCosineHemisphere(stream.get2D()));
        if (integrator.tracer().occluded(Ray{origin, dir, 0.0f, s.aoMaxDistance}))
          point.aoOccluded += 1.0;
      }
      extraRays += count;
    }
    return double(luminance(e)) * double(count);
  };

  const uint32_t paths = std::max(s.samples, 1u);
  for (uint32_t b = 0; b < kVarianceBatches; ++b) {
    double lum = 0.0;
    uint32_t n = 0;
    for (uint32_t j = 0; j < k; ++j) {
      const uint32_t first = uint32_t(uint64_t(j) * paths / k);
      const uint32_t count = uint32_t(uint64_t(j + 1) * paths / k) - first;
      // On a footprint grid with fewer paths per point than batches (16 points at 16
      // paths: one each), slice b of every point would put all of them in the last batch,
      // leaving one batch and no variance for the denoiser; point j's slices are then
      // rotated by j, so the points' paths spread over the batches.
      const uint32_t slice =
          footprintGrid && count < kVarianceBatches ? (b + j) % kVarianceBatches : b;
      const uint32_t bFirst = first + slice * count / kVarianceBatches;
      const uint32_t bCount = first + (slice + 1) * count / kVarianceBatches - bFirst;
      if (bCount == 0) continue;
      lum += run(j, bFirst, bCount);
      n += bCount;
    }
    if (n > 0) batches.push_back({lum / double(n) * kInvPi, n});
  }
  // Validity from the texel's rays.
  for (uint32_t j = 0; j < k; ++j)
    inside[j] = float(backFaces[j]) > s.backfaceTolerance * float(sums[j].samples) ||
                enclosed(integrator, points[active[j]], enclosedReach, hashValues(key, active[j]),
                         extraRays);

  PointSums used, all;
  for (uint32_t j = 0; j < k; ++j) {
    sums[j].normal = points[active[j]].normal;
    all.add(sums[j]);
    if (!inside[j]) {
      used.add(sums[j]);
      if (!points[active[j]].pushedOut) out.onVisibleSurface = true;
    }
  }
  out.samples = paths;
  out.valid = used.samples > 0;
  const PointSums& total = out.valid ? used : all;
  if (total.samples == 0) return out;
  const double n = double(total.samples);
  out.value = vec3(total.light / n) * kInvPi;
  // The footprint weight (TexelLight::coverage): the mean over every point of the footprint,
  // each at its own estimate (0 for a point inside a solid), over the value stored. On a
  // footprint grid that is the visible share when the points inside see nothing.
  out.coverage = 1.0f;
  if (footprintGrid) {
    double footprint = 0.0;
    for (uint32_t j = 0; j < k; ++j)
      if (sums[j].samples > 0) footprint += luminance(vec3(sums[j].light / double(sums[j].samples)));
    footprint /= double(pointCount);
    const double stored = luminance(vec3(total.light / n));
    uint32_t visible = 0;
    for (uint32_t j = 0; j < k; ++j) visible += inside[j] ? 0 : 1;
    out.coverage = stored > 0.0 ? float(std::min(1.0, footprint / stored))
                                : float(visible) / float(pointCount);
  }
  if (s.shadowmask) out.shadowmask = glm::clamp(vec4(total.visibility / n), 0.0f, 1.0f);
  if (s.directional) {
    const float len = glm::length(total.normal);
    const vec3 normal = len > 0.0f ? total.normal / len : vec3(0.0f);
    out.direction = encodeDominantDirection(vec3(total.direction / n),
                                            luminance(vec3(total.light / n)), normal);
  }
  if (s.ambientOcclusion) out.ao = 1.0f - float(total.aoOccluded / n);
  // Variance of the mean from the spread of the batch means.
  if (out.valid && batches.size() >= 2) {
    const double mean = double(luminance(out.value));
    double ss = 0.0, count = 0.0;
    for (const auto& [l, nb] : batches) {
      ss += double(nb) * (l - mean) * (l - mean);
      count += nb;
    }
    out.variance = float(ss / double(batches.size() - 1) / count);
    // Groups of kGroupBatches consecutive batches: the batches are slices in order, so a
    // group is again one contiguous, aligned slice of every point's share.
    std::vector<std::pair<double, double>> groups;  // (luminance sum, paths)
    for (size_t b = 0; b < batches.size(); ++b) {
      if (b % kGroupBatches == 0) groups.push_back({0.0, 0.0});
      groups.back().first += batches[b].first * batches[b].second;
      groups.back().second += batches[b].second;
    }
    if (groups.size() >= 2) {
      double gss = 0.0;
      for (const auto& [sum, nb] : groups) {
        const double m = sum / nb;
        gss += nb * (m - mean) * (m - mean);
      }
      out.varianceCoarse = float(gss / double(groups.size() - 1) / count);
    }
  }
  return out;
}

// Whether own point i of a texel's `count` own points is inside geometry, decided as
// lightPoints decides it without a grid (the point's share of the texel's paths, its first
// rays' back faces over backfaceTolerance, else the enclosure test on the same stream),
// without estimating its light: at most one ray per path (it stops once decided), plus
// the enclosure rays.
bool ownPointInside(const Integrator& integrator, const LightSettings& s, uint64_t key,
                    const TexelPoint* points, uint32_t count, uint32_t i, float enclosedReach,
                    uint64_t& extraRays) {
  const uint32_t paths = std::max(s.samples, 1u);
  const uint32_t first = uint32_t(uint64_t(i) * paths / count);
  const uint32_t n = uint32_t(uint64_t(i + 1) * paths / count) - first;
  const TexelPoint& p = points[i];
  return integrator.firstRaysSeeBackFaces(p.position, p.normal, key, first, n,
                                          s.backfaceTolerance) ||
         enclosed(integrator, p, enclosedReach, hashValues(key, i), extraRays);
}

// Stage 5, one texel: with a footprint grid (TexelSample::footprintGrid), the mean over the
// grid's visible points; when the grid has none (every point hidden from the main sample or
// found inside: a texel wholly inside a solid whose main sample push-out moved out, or one
// more than push-out's reach inside, whose main sample sees only the inside), the texel is
// baked as without a grid, at its own points (`points`: the main sample or the supersampling
// points, pushed out): it holds the light just outside the solid, as every texel did before
// the grid, and is invalid only where it was then. Its coverage is 0 (no visible footprint
// point). Both use the texel's stream from sample 0, so the fallback is bit for bit the
// texel's value without a grid.
TexelLight lightTexel(const Integrator& integrator, const LightSettings& s, uint64_t key,
                      const TexelPoint* points, uint32_t pointCount, const TexelPoint* grid,
                      uint32_t gridCount, float enclosedReach, uint64_t& extraRays) {
  bool anyVisible = false;
  for (uint32_t i = 0; i < gridCount && !anyVisible; ++i) anyVisible = !grid[i].hidden;
  if (anyVisible) {
    TexelLight g =
        lightPoints(integrator, s, key, grid, gridCount, true, enclosedReach, extraRays);
    if (g.valid) {
      // A fill seed (TexelLight::onVisibleSurface) exactly as without the grid: one of the
      // texel's own points lies where it was rasterized (push-out did not move it) and is
      // not inside geometry by lightPoints' test on the rays it would trace there (the same
      // first rays, ownPointInside). Its grid points are never moved, so they would make
      // every texel beside a solid a seed, and fill texels inside the solid that no lookup
      // at a visible point reads (a wall 2.5 texels thick standing on a floor: the floor's
      // middle row under it, between the rows push-out moved to either face, took the mean
      // of the sunlit outside and the room). Nor is "not moved" enough: a point more than
      // push-out's reach inside a wall is not moved either, and where another wall's front
      // face stands inside this one (walls that overlap at a corner) some of the texel's
      // grid points see that face and count as valid (dark), so its own point must pass
      // the inside test too (two_rooms at 10 texels per metre: floor texels under the south
      // wall took the mean of the sunlit outside and the room, 0 -> 1.3).
      g.onVisibleSurface = false;
      for (uint32_t i = 0; i < pointCount && !g.onVisibleSurface; ++i)
        g.onVisibleSurface = !points[i].pushedOut &&
                             !ownPointInside(integrator, s, key, points, pointCount, i,
                                             enclosedReach, extraRays);
      return g;
    }
  }
  TexelLight out =
      lightPoints(integrator, s, key, points, pointCount, false, enclosedReach, extraRays);
  if (gridCount > 0) out.coverage = 0.0f;
  return out;
}

// Batch means estimate a texel's variance as if its error fell as 1 / N (plain Monte
// Carlo). The paths are a scrambled Sobol sequence, whose error can fall faster (up to
// N^-1.5 for smooth 2D integrands such as direct light from an area light): batches of
// N / 16 paths then spread more than the full N's error implies, and the
// estimate is too large. With var(n) ~ n^-g, the estimates from batches (N / B paths) and
// from groups of kGroupBatches batches agree when g = 1, and otherwise differ by
// q = coarse / fine = kGroupBatches^(1 - g); extrapolating from the groups to the whole
// (B / kGroupBatches = kGroupBatches times more paths) multiplies by q once more: the
// corrected variance is fine x q^2. q is taken over the page (a per-texel ratio of two
// estimates from 16 and 4 means is too noisy), clamped to [1/4, 1] (1 <= g <= 2), and over
// the texels with at least kQmcMinPaths paths (4 per batch: with fewer, a batch is a
// handful of paths, not a slice of a net, and the ratio says nothing about the rate).
float qmcVarianceFactor(const std::vector<TexelRef>& texels, const std::vector<TexelLight>& light,
                        uint32_t pageIndex) {
  double fine = 0.0, coarse = 0.0;
  for (size_t i = 0; i < texels.size(); ++i)
    if (texels[i].page == pageIndex && light[i].valid &&
        light[i].samples >= kQmcMinPaths) {
      fine += light[i].variance;
      coarse += light[i].varianceCoarse;
    }
  if (!(fine > 0.0)) return 1.0f;
  const double q = std::clamp(coarse / fine, 0.25, 1.0);
  return float(q * q);
}

// Texels per tile of a distributed bake (consecutive covered texels: row strips).
constexpr size_t kTexelTile = 64;

// Stage 5's texels split across the ranks of a distributed bake, in tiles balanced by
// estimated cost: the paths (per texel under adaptive sampling; each sample also traces the
// AO ray and the shadowmask rays when those are baked) plus the enclosure rays of each sample
// point. The scene's triangle count scales every ray alike, so it does not move the balance.
WorkSplit splitTexels(std::vector<RasterPage>& pages, const std::vector<TexelRef>& texels,
                      const LightSettings& s) {
  const double perSample = 1.0 + (s.ambientOcclusion ? 1.0 : 0.0) + (s.shadowmask ? 1.0 : 0.0);
  return splitWork(texels.size(), kTexelTile, [&](size_t i) {
    RasterPage& page = pages[texels[i].page];
    // A footprint grid's points (its fallback to the texel's own points is rare).
    const TexelPointSets sets = lightPointSets(page, page.texels[texels[i].index], s);
    const uint32_t points = sets.grid.second > 0 ? sets.grid.second : sets.own.second;
    // Adaptive sampling's own count per texel, as the light stage uses it.
    const uint32_t samples = s.texelSamples ? std::max((*s.texelSamples)[i], points) : s.samples;
    return double(samples) * perSample + double(points) * double(kEnclosureRays);
  });
}

// Stage 5: light at every covered texel. A distributed bake gathers `out` on rank 0 only,
// or on every rank with `toAll` (a pass whose light every rank reads afterwards: the bounce
// cache).
bool lightStage(std::vector<RasterPage>& pages, const std::vector<TexelRef>& texels,
                const Integrator& integrator, const LightSettings& s, bool showProgress,
                ParallelOptions options, std::vector<TexelLight>& out,
                std::atomic<uint64_t>& rays, const char* phase = "bake", bool toAll = false) {
  Progress progress(phase, texels.size(), "texels", showProgress);
  options.progress = &progress;
  options.grain = 4;
  out.assign(texels.size(), TexelLight{});
  // Distributed bakes (src/distributed.h): this rank lights its tiles of texels, rank 0 (or
  // every rank) gathers every texel's TexelLight; without MPI every texel is local.
  const WorkSplit split = splitTexels(pages, texels, s);
  progress.splitAcrossRanks();
  const bool done = parallelForLocal(
      split,
      [&](size_t begin, size_t end) {
        const uint64_t before = Integrator::threadRayCount();
        uint64_t extraRays = 0;
        for (size_t i = begin; i < end; ++i) {
          RasterPage& page = pages[texels[i].page];
          TexelSample& texel = page.texels[texels[i].index];
          const TexelPointSets sets = lightPointSets(page, texel, s);
          const auto [points, count] = sets.own;
          const auto [grid, gridCount] = sets.grid;
          const uint64_t key = hashValues(s.seed, texels[i].page, texels[i].index);
          const float reach =
              s.enclosedTexels / s.layout->objects[size_t(texel.object)].texelsPerUnit;
          const uint64_t texelStart = Integrator::threadRayCount() + extraRays;
          LightSettings texelSettings = s;
          if (s.texelSamples) texelSettings.samples = std::max((*s.texelSamples)[i], count);
          out[i] = lightTexel(integrator, texelSettings, key, points, count, grid, gridCount,
                              reach, extraRays);
          out[i].rays = Integrator::threadRayCount() + extraRays - texelStart;
        }
        rays += Integrator::threadRayCount() - before + extraRays;
      },
      options);
  if (!exchangeItems(split, out, 1, toAll, done, !done, &progress)) return false;
  // Rank 0: the other ranks' rays (each texel's count came with it).
  for (size_t i = 0; i < out.size() && split.distributed() && distributedRoot(); ++i)
    if (split.owner[i] != 0) rays += out[i].rays;
  progress.finish();
  return true;
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
  const float qmcFactor = qmcVarianceFactor(texels, light, pageIndex);
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
    page.variance[t] = light[i].variance * qmcFactor;
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
  result.variance = page.variance;
  result.samples.assign(n, 0);
  for (size_t i = 0; i < texels.size(); ++i)
    if (texels[i].page == pageIndex) result.samples[texels[i].index] = light[i].samples;
  if (settings.coverageMap) {
    result.coverage = Image(w, h, 1);
    for (size_t i = 0; i < texels.size(); ++i)
      if (texels[i].page == pageIndex) result.coverage.pixels[texels[i].index] = light[i].coverage;
  }
  // Invalid texels before the fill: their own estimate (the footprint mean), for the
  // coverage of those the fill changes.
  const Image physical = settings.coverageMap ? page.radiance : Image();
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
  // A filled texel holds its neighbours' light for bilinear lookups at visible points; its
  // footprint weight brings it back to its own estimate: ~0 inside a solid, and ~0 on a
  // surface behind a single-sided one, such as the ceiling 1 mm above the Cornell box's lamp
  // (kiln's paths end on the lamp's back; Cycles' reference is as dark there, 2e-4 of the
  // ceiling beside the lamp one reference texel in).
  if (settings.coverageMap)
    for (size_t t = 0; t < n; ++t) {
      if (page.objectId[t] < 0 || page.valid[t]) continue;
      const float* f = page.radiance.at(int(t % size_t(w)), int(t / size_t(w)));
      const float* q = physical.at(int(t % size_t(w)), int(t / size_t(w)));
      const float filledLum = luminance(vec3(f[0], f[1], f[2]));
      const float ownLum = luminance(vec3(q[0], q[1], q[2]));
      result.coverage.pixels[t] = filledLum > 0.0f ? std::min(1.0f, ownLum / filledLum) : 1.0f;
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

// The first pass's pages (RGB) as a BounceCache: a hit's lightmap UV through its object's
// scaleOffset to its page, read bilinearly between texel centres with the seam stitcher's
// lookup (sampleBilinear, clamped to the page's edge texels; the pages are dilated into their
// padding, so a read at a chart's border takes no black).
class LightmapBounceCache final : public BounceCache {
 public:
  LightmapBounceCache(const Scene& scene, const AtlasLayout& layout, std::vector<Image> pages)
      : scene_(scene), layout_(layout), pages_(std::move(pages)) {
    for ([[maybe_unused]] const Image& page : pages_) assert(page.channels == 3);
  }

  bool lookup(uint32_t object, uint32_t triangle, vec2 bary, vec3& value) const override {
    const AtlasObject& a = layout_.objects[object];
    if (a.lightmapIndex < 0) return false;
    const Object& o = scene_.objects[object];
    if (o.uv1.empty()) return false;
    const Image& page = pages_[size_t(a.lightmapIndex)];
    const uvec3 t = o.triangles[triangle];
    const vec2 uv = (1.0f - bary.x - bary.y) * o.uv1[t.x] + bary.x * o.uv1[t.y] +
                    bary.y * o.uv1[t.z];
    const vec2 texel((uv.x * a.scaleOffset.x + a.scaleOffset.z) * float(page.width),
                     (uv.y * a.scaleOffset.y + a.scaleOffset.w) * float(page.height));
    sampleBilinear(page, texel, &value.x);
    return true;
  }

 private:
  const Scene& scene_;
  const AtlasLayout& layout_;
  std::vector<Image> pages_;
};

// The final gather's first pass (LightmapBakeSettings::bounceCacheSamples): every texel's
// light as a bounce sees it (IntegratorSettings::bounceView, one bounce fewer, no
// indirectIntensity), from `samples` full paths on its own stream, post-processed like the
// light pages (invalid texels filled, dilated, stitched; not denoised, see below) so that a
// read anywhere on a visible surface finds the light there. `validity` receives each
// texel's validity from this pass (per page, W x H). Returns null when cancelled.
std::unique_ptr<LightmapBounceCache> bounceCachePass(
    std::vector<RasterPage>& pages, const std::vector<TexelRef>& texels, const Scene& scene,
    const AtlasLayout& layout, const Tracer& tracer, IntegratorSettings is,
    const LightmapBakeSettings& settings, bool showProgress, ParallelOptions parallel,
    std::atomic<uint64_t>& rays, std::vector<std::vector<uint8_t>>& validity,
    std::vector<float>& pathSpread) {
  is.bounceView = true;
  is.indirectIntensity = 1.0f;
  is.maxBounces = std::max(0, is.maxBounces - 1);
  is.bounceCache = nullptr;
  const Integrator integrator(scene, tracer, is);
  LightSettings ls;
  ls.samples = uint32_t(settings.bounceCacheSamples);
  ls.supersampling = 1;
  ls.seed = hashValues(settings.seed, kCacheTag);
  ls.backfaceTolerance = settings.backfaceTolerance;
  ls.enclosedTexels = settings.enclosedTexels;
  ls.layout = &layout;
  std::vector<TexelLight> light;
  // Every rank of a distributed bake reads the cache (its texels' paths end on it), and
  // adaptive sampling splits the main pass by this pass's spread: the light goes to all.
  if (!lightStage(pages, texels, integrator, ls, showProgress, parallel, light, rays,
                  "bounce cache", true))
    return nullptr;
  pathSpread.assign(texels.size(), -1.0f);
  for (size_t i = 0; i < texels.size(); ++i)
    if (light[i].valid) pathSpread[i] = std::sqrt(light[i].variance * float(light[i].samples));
  validity.resize(pages.size());
  for (size_t p = 0; p < pages.size(); ++p) validity[p].assign(pages[p].texels.size(), 0);
  for (size_t i = 0; i < texels.size(); ++i)
    validity[texels[i].page][texels[i].index] = light[i].valid ? 1 : 0;
  LightmapBakeSettings post = settings;
  post.ambientOcclusion = false;
  post.directional = false;
  post.coverageMap = false;
  // Not denoised: a gather reads the cache over the whole hemisphere, i.e. averages many
  // texels, which does what the denoiser would (Cornell box, --resolution 200: 1.01% RMSE
  // against Cycles with the cache denoised or not) at none of its cost (as much CPU as the
  // rest of the bake).
  post.denoise = false;
  std::vector<Image> images(pages.size());
  PostProgress progress(0, 0, 0, false);
  size_t clamped = 0;
  for (uint32_t p = 0; p < pages.size(); ++p) {
    LightmapPageResult page;
    postPage(scene, layout, p, pages[p], texels, light, post, false, parallel, progress, page,
             clamped);
    images[p] = std::move(page.light);
    if (cancelled(parallel.cancel)) return nullptr;
  }
  return std::make_unique<LightmapBounceCache>(scene, layout, std::move(images));
}

// Each covered texel's mean of `value` over the texels of its object among its 3 x 3
// neighbours (itself included) that have one (value >= 0; -1 = none, e.g. an invalid texel,
// which says nothing about the light beside it); 0 when none has. The passes that measure
// the light for the allocation below take few paths per texel: their neighbours' agree with
// them on smooth light and add up to 9x the paths. In texel order: the same at any thread
// count.
std::vector<double> neighbourMean(const std::vector<RasterPage>& pages,
                                  const std::vector<TexelRef>& texels,
                                  const std::vector<float>& value) {
  std::vector<std::vector<int32_t>> where(pages.size());  // texel -> index in `texels`
  for (size_t p = 0; p < pages.size(); ++p) where[p].assign(pages[p].texels.size(), -1);
  for (size_t i = 0; i < texels.size(); ++i) where[texels[i].page][texels[i].index] = int32_t(i);
  std::vector<double> mean(texels.size(), 0.0);
  for (size_t i = 0; i < texels.size(); ++i) {
    const RasterPage& page = pages[texels[i].page];
    const int w = page.width, h = page.height;
    const int x = int(texels[i].index % uint32_t(w)), y = int(texels[i].index / uint32_t(w));
    double sum = 0.0;
    int n = 0;
    for (int dy = -1; dy <= 1; ++dy)
      for (int dx = -1; dx <= 1; ++dx) {
        const int nx = x + dx, ny = y + dy;
        if (nx < 0 || ny < 0 || nx >= w || ny >= h) continue;
        const int32_t j = where[texels[i].page][size_t(ny) * size_t(w) + size_t(nx)];
        if (j < 0 || value[size_t(j)] < 0.0f ||
            page.texels[texels[size_t(j)].index].object != page.texels[texels[i].index].object)
          continue;
        sum += value[size_t(j)];
        ++n;
      }
    mean[i] = n > 0 ? sum / n : 0.0;
  }
  return mean;
}

// Paths per texel in proportion to the spread of one path's value there (Neyman's
// allocation, which minimises the summed squared error of the texels for a given total of
// paths: sum sigma_t^2 / n_t subject to sum n_t = N gives n_t ~ sigma_t), n_t =
// clamp(round(k sigma_t), lo, cap), with the smallest k (bisection) that reaches the goal:
//   - adaptive sampling (LightmapBakeSettings::adaptiveSamples; `target` 0): the counts sum
//     to meanCount x texels; the spread comes from the bounce cache's first pass;
//   - the error target (LightmapBakeSettings::errorTarget = `target` > 0): the relative RMSE
//     over the texels the counts predict, sqrt(sum sigma_t^2 / n_t / sum mu_t^2), is at most
//     the target (mu_t = `pilotMean`); the spread and means come from the pilot pass.
// Both passes have random numbers of their own: a texel's count does not depend on the paths
// that make its value, so it cannot bias it (a rule that stops where the texel's own paths
// happen to agree stops low: kiln's first error target did, and darkened). Spreads and means
// are the mean over each texel's valid neighbours (neighbourMean). Computed in texel order:
// the same at any thread count.
std::vector<uint32_t> allocateSamples(const std::vector<RasterPage>& pages,
                                      const std::vector<TexelRef>& texels,
                                      const std::vector<float>& pathSpread, uint32_t lo,
                                      uint32_t cap, double meanCount, double target = 0.0,
                                      const std::vector<float>* pilotMean = nullptr) {
  const std::vector<double> spread = neighbourMean(pages, texels, pathSpread);
  auto count = [&](double k, size_t i) {
    return std::clamp(std::round(k * spread[i]), double(lo), double(cap));
  };
  std::function<bool(double)> reached;
  if (target > 0.0) {
    const std::vector<double> mean = neighbourMean(pages, texels, *pilotMean);
    double sumSq = 0.0;
    for (double m : mean) sumSq += m * m;
    const double allowed = target * target * sumSq;
    reached = [&, allowed](double k) {
      double variance = 0.0;
      for (size_t i = 0; i < spread.size(); ++i) variance += spread[i] * spread[i] / count(k, i);
      return variance <= allowed;
    };
  } else {
    const double total = meanCount * double(texels.size());
    reached = [&, total](double k) {
      double t = 0.0;
      for (size_t i = 0; i < spread.size(); ++i) t += count(k, i);
      return t >= total;
    };
  }
  double kLo = 0.0, kHi = 1.0;
  while (!reached(kHi) && kHi < 1e30) kHi *= 2.0;
  for (int it = 0; it < 60; ++it) {
    const double k = 0.5 * (kLo + kHi);
    (reached(k) ? kHi : kLo) = k;
  }
  // Adaptive sampling keeps the bisection's lower end (its sum may fall short of the mean
  // by rounding); the error target the upper one, which reaches the target.
  const double k = target > 0.0 ? kHi : kLo;
  std::vector<uint32_t> counts(texels.size());
  for (size_t i = 0; i < texels.size(); ++i) counts[i] = uint32_t(count(k, i));
  return counts;
}

// The error target's pilot pass: LightmapBakeSettings::pilotSamples paths at every texel's
// main sample point on their own stream, through the bake's own integrator (with the bounce
// cache when there is one, so that it measures the spread of the paths the bake will take),
// light only. The main point alone keeps the pass at pilotSamples paths a texel whatever the
// supersampling or footprint grid (its paths at every point of a 4 x 4 grid cost more than
// the light of a preview); the spread there stands for that of the texel's points, which
// the light stage's estimate splits its paths over (a little more than theirs, since the
// stage stratifies over the points).
// `pathSpread` and `mean` receive per texel the standard deviation of one
// path's luminance (E / pi) and the mean luminance, -1 where the pass found the texel
// invalid. Every rank of a distributed bake allocates from it: the light goes to all.
// Returns false when cancelled.
bool pilotPass(std::vector<RasterPage>& pages, const std::vector<TexelRef>& texels,
               const Integrator& integrator, const LightmapBakeSettings& settings,
               const AtlasLayout& layout, bool showProgress, ParallelOptions parallel,
               std::atomic<uint64_t>& rays, std::vector<float>& pathSpread,
               std::vector<float>& mean) {
  LightSettings ls;
  ls.samples = uint32_t(settings.pilotSamples);
  ls.supersampling = 1;
  ls.mainPointOnly = true;
  ls.seed = hashValues(settings.seed, kPilotTag);
  ls.backfaceTolerance = settings.backfaceTolerance;
  ls.enclosedTexels = settings.enclosedTexels;
  ls.layout = &layout;
  std::vector<TexelLight> light;
  if (!lightStage(pages, texels, integrator, ls, showProgress, parallel, light, rays, "pilot",
                  true))
    return false;
  pathSpread.assign(texels.size(), -1.0f);
  mean.assign(texels.size(), -1.0f);
  for (size_t i = 0; i < texels.size(); ++i)
    if (light[i].valid) {
      pathSpread[i] = std::sqrt(light[i].variance * float(light[i].samples));
      mean[i] = luminance(light[i].value);
    }
  return true;
}

}  // namespace

Status applyLightmapPreset(const std::string& preset, LightmapBakeSettings& settings) {
  // Error targets with a cap (LightmapBakeSettings::errorTarget). Each step halves the target
  // (4x the paths) and quadruples the cap and the minimum; supersampling starts at "high",
  // where 2 x 2 points per texel resolve shadow edges inside a texel at no extra path cost,
  // while below it every path is better spent on noise. The targets are the relative RMS
  // error (before denoising) of the fixed counts they replace (preview 16, low 64, medium 256,
  // high 1024, production 4096 paths per texel) on the Cornell box, the project's reference
  // scene; the cap is 4x and the minimum 1/8 of that count (at least 8). Scenes whose light
  // is easier now stop at the target with fewer paths (docs/lightmap_outputs.md "Quality
  // presets").
  struct Preset {
    const char* name;
    float target;
    int minSamples, cap, supersampling, pilot;
  };
  static constexpr Preset kPresets[] = {{"preview", 0.12f, 8, 64, 1, 4},
                                        {"low", 0.06f, 8, 256, 1, 4},
                                        {"medium", 0.03f, 32, 1024, 1, 8},
                                        {"high", 0.015f, 128, 4096, 2, 8},
                                        {"production", 0.0075f, 512, 16384, 2, 8}};
  for (const Preset& p : kPresets) {
    if (preset != p.name) continue;
    settings.errorTarget = p.target;
    settings.minSamples = p.minSamples;
    settings.samplesPerTexel = p.cap;
    settings.supersampling = p.supersampling;
    settings.pilotSamples = p.pilot;
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
  if (settings.lockedAtlas) {
    // What the manifest gives a page keeps its charts; objects are matched by node.
    std::unordered_map<int, size_t> byNode;
    for (size_t i = 0; i < result.scene.objects.size(); ++i)
      byNode[result.scene.objects[i].nodeIndex] = i;
    unwrap.keepCharts.assign(result.scene.objects.size(), 0);
    for (const ManifestObject& mo : settings.lockedAtlas->manifest.objects)
      if (auto found = byNode.find(mo.nodeIndex); found != byNode.end() && mo.lightmapIndex >= 0)
        unwrap.keepCharts[found->second] = 1;
  }
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
  if (settings.lockedAtlas) {
    Result<AtlasLayout> locked = atlasFromManifest(settings.lockedAtlas->manifest, result.scene,
                                                   settings.lockedAtlas->file);
    if (!locked) return Error{"locked atlas: " + locked.error()};
    atlas.locked = std::move(locked).value();
  }
  atlas.showProgress = showProgress;
  atlas.cancel = cancel;
  auto layout = packAtlas(result.scene, atlas);
  if (cancelled(cancel)) return Error{"cancelled"};
  if (!layout) return Error{"lightmap atlas: " + layout.error()};
  result.layout = std::move(layout).value();
  if (Status s = packChartsIntoPages(result.scene, result.layout, atlas, result.unwraps); !s)
    return Error{"lightmap atlas: " + s.error()};
  if (cancelled(cancel)) return Error{"cancelled"};
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

  // Stage 5: light (with a bounce cache, its first pass, then the footprint grid, which uses
  // that pass's validity, then the light stage).
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
  std::unique_ptr<LightmapBounceCache> bounceCache;
  std::vector<std::vector<uint8_t>> cacheValidity;
  std::vector<float> pathSpread;
  if (settings.bounceCacheSamples > 0 && settings.bounces > 0) {
    bounceCache = bounceCachePass(pages, texels, result.scene, result.layout, **tracer, is,
                                  settings, showProgress, parallel, rays, cacheValidity,
                                  pathSpread);
    if (!bounceCache || cancelled(cancel)) return Error{"cancelled"};
    is.bounceCache = bounceCache.get();
  }
  std::string footprintError;
  if ((settings.footprintGrid &&
       !footprintStage(pages, texels, result.scene, result.layout, **tracer,
                       settings.supersampling, bounceCache ? &cacheValidity : nullptr,
                       showProgress, parallel, rays, footprintError)) ||
      cancelled(cancel))
    return Error{footprintError.empty() || cancelled(cancel) ? "cancelled"
                                                               : "lightmap texels: " + footprintError};
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
  std::vector<uint32_t> texelSamples;
  if (settings.errorTarget > 0.0f) {
    std::vector<float> pilotMean;
    if (!pilotPass(pages, texels, integrator, settings, result.layout, showProgress, parallel,
                   rays, pathSpread, pilotMean) ||
        cancelled(cancel))
      return Error{"cancelled"};
    texelSamples = allocateSamples(
        pages, texels, pathSpread, uint32_t(std::clamp(settings.minSamples, 1, int(ls.samples))),
        ls.samples, 0.0, settings.errorTarget, &pilotMean);
    ls.texelSamples = &texelSamples;
  } else if (settings.adaptiveSamples && bounceCache) {
    texelSamples = allocateSamples(pages, texels, pathSpread, std::max(1u, ls.samples / 2),
                                   ls.samples * kAdaptiveCap, ls.samples);
    ls.texelSamples = &texelSamples;
  }
  std::vector<TexelLight> light;
  if (!lightStage(pages, texels, integrator, ls, showProgress, parallel, light, rays) ||
      cancelled(cancel))
    return Error{"cancelled"};
  // Probe-lit objects: their own SH, from the same transport settings and tracer.
  if (!bakeProbeLitObjects(result.scene, result.layout, **tracer,
                           probeLitBakeSettings(settings.lightingMode, settings.bounces,
                                                settings.albedoBoost, settings.indirectIntensity),
                           settings.seed, showProgress, parallel, result.objectProbes, rays) ||
      cancelled(cancel))
    return Error{"cancelled"};
  result.stats.seconds =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  // A distributed bake's other ranks are done: rank 0 post-processes and writes.
  if (!distributedRoot()) return result;

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
  if (!light.empty()) {
    LightmapBakeStats& st = result.stats;
    st.minSamples = light[0].samples;
    double sumSamples = 0.0;
    for (const TexelLight& t : light) {
      st.minSamples = std::min(st.minSamples, t.samples);
      st.maxSamples = std::max(st.maxSamples, t.samples);
      sumSamples += t.samples;
      size_t bucket = 0;  // [2^b, 2^(b+1)) rays; 0 also holds texels with 0 or 1 ray
      while (bucket + 1 < st.raysPerTexelHistogram.size() && (t.rays >> (bucket + 1)) > 0)
        ++bucket;
      ++st.raysPerTexelHistogram[bucket];
    }
    st.meanSamples = sumSamples / double(light.size());
  }
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
