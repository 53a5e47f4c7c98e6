// probe_baker.cpp: the probe SH bake (see probe_baker.h).
//
// Sampling: probe i owns the stream key hashValues(seed, i). Ray s takes its direction from
// dimensions 0-1 of SampleStream(key, s); Integrator::incomingRadiance draws from the same
// (key, s) stream but only from dimensions of path vertices >= 1 (integrator.cpp gives
// vertex 0, the probe, dimensions 0-11 and never draws them in incomingRadiance), so the
// direction is independent of everything along the path. Punctual-light visibility uses a
// side stream keyed by (key, "lights").
// Validity: the first segment of every ray is traced here too, to see whether it ends on
// the back face of a single-sided surface (the inside of geometry). Such a ray carries no
// light (the integrator's back faces reflect nothing), so the integrator is skipped for it.
#include "probes/probe_baker.h"

#include <algorithm>
#include <cmath>
#include <cstring>
#include <fstream>
#include <nlohmann/json.hpp>
#include <sstream>
#include <unordered_map>

#include "probes/sun_shadows.h"
#include "src/distributed.h"
#include "src/parallel.h"
#include "src/sampling.h"
#include "src/sh_projection.h"
#include "src/text_file.h"

namespace kiln {

namespace {

constexpr uint64_t kLightsTag = 0x6c6967687473ull;       // "lights"
constexpr uint64_t kOcclusionTag = 0x6f63636c75646eull;  // "occludn"
constexpr uint64_t kFootprintTag = 0x666f6f74707274ull;  // "footprt"
constexpr uint64_t kSunRampsTag = 0x73756e72616d70ull;   // "sunramp"
// A footprint origin stops this fraction of the radius short of the surface between it and
// the probe.
constexpr float kFootprintGap = 0.01f;
// Draws of a footprint origin before the last is pulled back to the surface instead: re-drawn
// points are uniform over the part of the ball the probe sees (pulling every blocked point
// back would pile samples onto the surfaces).
constexpr uint32_t kFootprintDraws = 16;

bool isSoftShadowed(const Light& light) {
  return light.type == LightType::Directional ? light.shadowAngle > 0.0f
                                              : light.shadowRadius > 0.0f;
}

// Mean SH of the valid probes that share a cell with probe `i`; nullopt when there is none.
std::optional<ShL2Rgb> validNeighbourMean(const ProbeSet& set,
                                          const std::vector<std::vector<int32_t>>& adjacency,
                                          const std::vector<char>& valid, int32_t i) {
  std::array<glm::dvec3, kShL2Count> sum{};
  int n = 0;
  for (int32_t j : adjacency[i]) {
    if (!valid[j]) continue;
    for (int k = 0; k < kShL2Count; ++k) sum[k] += glm::dvec3(set.sh[j].c[k]);
    ++n;
  }
  if (n == 0) return std::nullopt;
  ShL2Rgb mean;
  for (int k = 0; k < kShL2Count; ++k) mean.c[k] = vec3(sum[k] / double(n));
  return mean;
}

// Mean of value(j) (a T) over the valid probes j that share a cell with probe `i`; nullopt
// when there is none.
template <class T, class Value>
std::optional<T> validNeighbourMeanOf(const std::vector<std::vector<int32_t>>& adjacency,
                                      const std::vector<char>& valid, int32_t i, Value value) {
  T sum(0.0);
  int n = 0;
  for (int32_t j : adjacency[i]) {
    if (!valid[j]) continue;
    sum += value(j);
    ++n;
  }
  if (n == 0) return std::nullopt;
  return sum / double(n);
}

// Mean occlusion of the valid probes that share a cell with probe `i`; nullopt when none.
std::optional<glm::vec4> validNeighbourOcclusion(const ProbeSet& set,
                                                 const std::vector<std::vector<int32_t>>& adjacency,
                                                 const std::vector<char>& valid, int32_t i) {
  const auto mean = validNeighbourMeanOf<glm::dvec4>(
      adjacency, valid, i, [&](int32_t j) { return glm::dvec4(set.occlusion[size_t(j)]); });
  if (!mean) return std::nullopt;
  return glm::vec4(*mean);
}

// Probes sharing a cell, per probe (sorted, unique).
std::vector<std::vector<int32_t>> cellAdjacency(const ProbeSet& set) {
  std::vector<std::vector<int32_t>> adjacency(set.positions.size());
  for (const glm::ivec4& c : set.cells) {
    for (int a = 0; a < 4; ++a) {
      for (int b = 0; b < 4; ++b) {
        if (a != b && c[a] >= 0 && c[b] >= 0 && c[a] != c[b]) adjacency[c[a]].push_back(c[b]);
      }
    }
  }
  for (auto& list : adjacency) {
    std::sort(list.begin(), list.end());
    list.erase(std::unique(list.begin(), list.end()), list.end());
  }
  return adjacency;
}

std::string vecText(vec3 p) {
  std::ostringstream s;
  s << "(" << p.x << ", " << p.y << ", " << p.z << ")";
  return s.str();
}

}  // namespace

LightingMode probeLightingMode(const Scene& scene, const ProbeBakeSettings& settings) {
  if (settings.lightingMode) return *settings.lightingMode;
  if (scene.settings.lightingMode) {
    // The glTF loader only accepts the three names, so this parse cannot fail.
    if (Result<LightingMode> m = parseLightingMode(*scene.settings.lightingMode)) return *m;
  }
  return LightingMode::BakedIndirect;
}

LightModePlan probeLightModePlan(const Scene& scene, const ProbeBakeSettings& settings) {
  return planLightModes(scene, probeLightingMode(scene, settings));
}

IntegratorSettings probeIntegratorSettings(const Scene& scene, const ProbeBakeSettings& settings) {
  const LightModePlan plan = probeLightModePlan(scene, settings);
  IntegratorSettings is;
  is.maxBounces = settings.bounces.value_or(scene.settings.bounces.value_or(kDefaultProbeBounces));
  is.albedoBoost = settings.albedoBoost.value_or(scene.settings.albedoBoost.value_or(1.0f));
  is.indirectIntensity =
      settings.indirectIntensity.value_or(scene.settings.indirectIntensity.value_or(1.0f));
  is.russianRouletteDepth = settings.russianRouletteDepth;
  is.directLights.resize(scene.lights.size());
  is.indirectLights.resize(scene.lights.size());
  for (size_t i = 0; i < scene.lights.size(); ++i) {
    is.directLights[i] = plan.bakeDirect[i];
    is.indirectLights[i] = plan.bakeIndirect[i];
  }
  return is;
}

float probeLightOcclusion(const Integrator& integrator, vec3 p, uint32_t light, uint64_t key,
                          uint32_t samples) {
  const Light& l = integrator.scene().lights[light];
  const uint32_t evaluations = isSoftShadowed(l) ? std::max(1u, samples) : 1u;
  const uint64_t k = hashValues(key, kOcclusionTag, light);
  double sum = 0.0;
  for (uint32_t j = 0; j < evaluations; ++j) {
    const vec3 v = integrator.lightVisibility(p, vec3(0.0f), light, k, j);
    sum += (double(v.x) + double(v.y) + double(v.z)) / 3.0;
  }
  const double mean = sum / double(evaluations);
  return std::isfinite(mean) ? float(std::clamp(mean, 0.0, 1.0)) : 1.0f;
}

glm::vec4 bakeProbeOcclusion(const Integrator& integrator, const LightModePlan& plan, vec3 p,
                             uint64_t key, uint32_t samples) {
  glm::vec4 occlusion(1.0f);
  for (size_t l = 0; l < plan.shadowmaskChannel.size(); ++l) {
    const int c = plan.shadowmaskChannel[l];
    if (c >= 0 && c < kProbeOcclusionChannels)
      occlusion[c] = probeLightOcclusion(integrator, p, uint32_t(l), key, samples);
  }
  return occlusion;
}

std::vector<float> probeVisibilityMaxDistances(const Scene& scene, std::span<const vec3> positions,
                                               const ProbeBakeSettings& settings) {
  if (settings.visibilityResolution <= 0) return {};
  if (settings.visibilityMaxDistance > 0.0f)
    return std::vector<float>(positions.size(), settings.visibilityMaxDistance);
  // Over the static objects only: the dynamic ones are not in the baking tracer, and a
  // probe's visibility map must not change with them (src/tracer.h).
  Bounds3 bakedBounds;
  for (const Object& o : scene.objects)
    if (o.settings.isStatic)
      for (const vec3& v : o.positions) bakedBounds.extend(v);
  return visibilityMaxDistances(positions, bakedBounds);
}

uint64_t positionKey(vec3 p) {
  uint32_t b[3];
  std::memcpy(b, &p, sizeof b);
  return hashValues(b[0], (uint64_t(b[1]) << 32) | b[2]);
}

bool inThinLightSheet(const Scene& scene, const Integrator& integrator, vec3 p) {
  const uint64_t key = positionKey(p);
  // The lights whose unbounced light the integrator bakes (resolved: one entry per light).
  const std::vector<bool>& direct = integrator.settings().directLights;
  for (uint32_t l = 0; l < scene.lights.size(); ++l) {
    if (l >= direct.size() || !direct[l]) continue;
    auto lit = [&](vec3 q) {
      return luminance(integrator.lightVisibility(q, vec3(0.0f), l, key, 0)) > 0.5f;
    };
    const bool here = lit(p);
    for (int axis = 0; axis < 3; ++axis)
      for (float r : {0.03f, 0.06f, 0.09f}) {
        vec3 d(0.0f);
        d[axis] = r;
        if (lit(p - d) != here && lit(p + d) != here) return true;
      }
  }
  return false;
}

vec3 footprintOrigin(const Tracer& tracer, vec3 p, float radius, uint64_t key, uint32_t s) {
  if (!(radius > 0.0f)) return p;
  SampleStream stream(hashValues(key, kFootprintTag), s);
  const float gap = kFootprintGap * radius;
  vec3 clipped = p;
  for (uint32_t draw = 0; draw < kFootprintDraws; ++draw) {
    stream.setDimension(4 * draw);
    const vec3 dir = squareToUniformSphere(stream.get2D());
    const float r = radius * std::cbrt(stream.get1D());  // uniform in the ball's volume
    const std::optional<Hit> hit = tracer.intersect(Ray{p, dir, 0.0f, r + gap});
    if (!hit) return p + r * dir;  // the segment from p is free: a point of the visible ball
    clipped = p + std::max(0.0f, hit->t - gap) * dir;
  }
  return clipped;  // every draw behind geometry: the last, pulled back
}

std::vector<float> probeFootprintRadii(std::span<const vec3> positions,
                                       const ProbeBakeSettings& settings) {
  const size_t n = positions.size();
  std::vector<float> out(n, 0.0f);
  if (!(settings.footprint > 0.0f) || !(settings.footprintMaxRadius > 0.0f) || n < 2) return out;
  // Neighbours farther than `reach` give the cap anyway.
  const double reach = double(settings.footprintMaxRadius) / double(settings.footprint);
  Bounds3 bounds;
  for (const vec3& q : positions) bounds.extend(q);
  const glm::dvec3 extent = glm::dvec3(bounds.max - bounds.min);
  const double largest = std::max({extent.x, extent.y, extent.z});
  if (!(largest > 0.0)) return out;  // every position at one point
  // Cells about the mean spacing of a set spread over its bounds' largest side, never
  // more than 1024 per axis.
  const double cell = std::max(largest / std::max(1.0, std::cbrt(double(n))), largest / 1024.0);
  auto cellOf = [&](const vec3& q) {
    return glm::ivec3(glm::floor((glm::dvec3(q) - glm::dvec3(bounds.min)) / cell));
  };
  auto cellKey = [](glm::ivec3 c) {
    return (uint64_t(uint32_t(c.x) & 0x1fffffu) << 42) | (uint64_t(uint32_t(c.y) & 0x1fffffu) << 21) |
           uint64_t(uint32_t(c.z) & 0x1fffffu);
  };
  std::unordered_map<uint64_t, std::vector<uint32_t>> grid;
  for (size_t i = 0; i < n; ++i) grid[cellKey(cellOf(positions[i]))].push_back(uint32_t(i));
  const glm::ivec3 cells = glm::ivec3(glm::floor(extent / cell)) + 1;
  const int maxRing = std::max({cells.x, cells.y, cells.z});
  for (size_t i = 0; i < n; ++i) {
    const glm::ivec3 c = cellOf(positions[i]);
    double best = kInfinity;
    for (int k = 0; k <= maxRing; ++k) {
      // Every point of a cell at ring k is at least (k - 1) cells away.
      if (k >= 1 && double(k - 1) * cell >= std::min(best, reach)) break;
      for (int dz = -k; dz <= k; ++dz)
        for (int dy = -k; dy <= k; ++dy)
          for (int dx = -k; dx <= k; ++dx) {
            if (std::max({std::abs(dx), std::abs(dy), std::abs(dz)}) != k) continue;
            const glm::ivec3 o = c + glm::ivec3(dx, dy, dz);
            if (glm::any(glm::lessThan(o, glm::ivec3(0))) || glm::any(glm::greaterThanEqual(o, cells)))
              continue;
            const auto it = grid.find(cellKey(o));
            if (it == grid.end()) continue;
            for (uint32_t j : it->second) {
              const double d = glm::length(glm::dvec3(positions[j]) - glm::dvec3(positions[i]));
              if (j != i && d > 0.0) best = std::min(best, d);
            }
          }
    }
    out[i] = float(std::min(double(settings.footprint) * best, double(settings.footprintMaxRadius)));
  }
  return out;
}

ProbeSample bakeProbe(const Integrator& integrator, vec3 p, uint64_t key, uint32_t rays,
                      uint32_t lightSamples, const std::atomic<bool>* cancel,
                      const VisibilityMapSpec& visibility, float footprintRadius) {
  const Scene& scene = integrator.scene();
  const Tracer& tracer = integrator.tracer();
  ShL2Accumulator sum;
  const double weight = 4.0 * double(kPi) / double(rays);
  uint32_t backFaces = 0;
  const bool withVisibility = visibility.resolution > 0;
  const bool footprint = footprintRadius > 0.0f;
  // With a footprint, ray s and light evaluation s share the origin footprintOrigin(.., s).
  std::vector<vec3> origins;
  if (footprint) {
    origins.resize(rays);
    for (uint32_t s = 0; s < rays; ++s)
      origins[s] = footprintOrigin(tracer, p, footprintRadius, key, s);
  }
  VisibilityMapBuilder map(withVisibility ? visibility : VisibilityMapSpec{});
  for (uint32_t s = 0; s < rays; ++s) {
    // A probe can take seconds: let Ctrl-C through without waiting for it.
    if (cancel && (s & 4095u) == 4095u && cancel->load(std::memory_order_relaxed)) break;
    SampleStream stream(key, s);
    stream.setDimension(0);
    const vec3 dir = squareToUniformSphere(stream.get2D());
    const std::optional<Hit> hit = tracer.intersect(Ray{p, dir, 0.0f, kInfinity});
    if (withVisibility) map.add(dir, hit ? hit->t : kInfinity);
    if (hit) {
      const Material& m = scene.materialOf(hit->object, hit->triangle);
      if (hit->backFace && !m.doubleSided && m.alphaMode != AlphaMode::Blend) {
        ++backFaces;
        continue;  // inside geometry: no light (what incomingRadiance would return)
      }
    }
    sum.add(dir, integrator.incomingRadiance(footprint ? origins[s] : p, dir, key, s).total(),
            weight);
  }

  // Punctual lights: exact delta projection c_i += E Y_i(s), visibility averaged (over the
  // rays' origins with a footprint: one evaluation per ray).
  bool soft = false;
  for (const Light& l : scene.lights) soft = soft || isSoftShadowed(l);
  const uint32_t evaluations = footprint ? rays : soft ? std::max(1u, lightSamples) : 1u;
  const uint64_t lightKey = hashValues(key, kLightsTag);
  std::vector<DeltaLight> deltas;
  for (uint32_t j = 0; j < evaluations; ++j) {
    if (cancel && (j & 4095u) == 4095u && cancel->load(std::memory_order_relaxed)) break;
    integrator.punctualLights(footprint ? origins[j] : p, lightKey, j, deltas);
  }
  const int32_t sun = sunLayerLight(scene, integrator.settings());
  const float sunIrradiance = sun >= 0 ? luminance(scene.lights[size_t(sun)].irradianceAt(p)) : 0.0f;
  double sunShare = 0.0;
  for (const DeltaLight& d : deltas) {
    if (!isFinite(d.irradiance)) continue;
    sum.add(d.direction, d.irradiance, 1.0 / double(evaluations));
    if (int32_t(d.light) == sun && sunIrradiance > 0.0f)
      sunShare += double(luminance(d.irradiance) / sunIrradiance) / double(evaluations);
  }

  ProbeSample out;
  out.sunShare = float(std::clamp(sunShare, 0.0, 1.0));
  out.sh = sum.result();
  out.validity = 1.0f - float(backFaces) / float(rays);
  if (withVisibility) out.visibility = map.finish(tracer, p);
  return out;
}

Result<ProbeSet> bakeProbes(const Scene& scene, const Tracer& tracer,
                            std::span<const vec3> positions, const ProbeBakeSettings& settings,
                            Progress* progress, const std::atomic<bool>* cancel,
                            ProbeBakeReport* report) {
  if (positions.empty()) return Error{"no probe positions"};
  if (settings.rays == 0) return Error{"rays per probe must be > 0"};
  if (!(settings.footprint >= 0.0f && settings.footprint <= kMaxProbeFootprint))
    return Error{"footprint must be in [0, " + std::to_string(kMaxProbeFootprint).substr(0, 3) +
                 "] (a fraction of the distance to the nearest probe)"};
  if (!(settings.footprintMaxRadius > 0.0f) || !std::isfinite(settings.footprintMaxRadius))
    return Error{"footprint max radius must be a finite number > 0"};
  if (!isVisibilityResolution(settings.visibilityResolution))
    return Error{"visibility resolution must be 0 or in [" +
                 std::to_string(kMinVisibilityResolution) + ", " +
                 std::to_string(kMaxVisibilityResolution) + "]"};
  if (!(settings.visibilityMaxDistance >= 0.0f) || !std::isfinite(settings.visibilityMaxDistance))
    return Error{"visibility max distance must be a finite number >= 0"};
  for (size_t i = 0; i < positions.size(); ++i) {
    if (!isFinite(positions[i])) return Error{"positions[" + std::to_string(i) + "]: not finite"};
    if (glm::any(glm::greaterThan(glm::abs(positions[i]), vec3(kMaxProbeCoordinate))))
      return Error{"positions[" + std::to_string(i) + "]: a coordinate beyond " +
                   std::to_string(int64_t(kMaxProbeCoordinate)) + " m"};
  }
  ProbeBakeReport local;
  ProbeBakeReport& rep = report ? *report : local;
  rep = ProbeBakeReport{};

  Result<ProbeSet> topology = buildProbeTopology(positions, settings.topology, &rep.warnings);
  if (!topology) return Error{"tetrahedralization: " + topology.error()};
  ProbeSet set = std::move(topology).value();

  rep.lightModes = probeLightModePlan(scene, settings);
  rep.warnings.insert(rep.warnings.end(), rep.lightModes.warnings.begin(),
                      rep.lightModes.warnings.end());
  const LightModePlan& plan = rep.lightModes;
  bool anyChannel = false;
  for (size_t l = 0; l < plan.shadowmaskChannel.size(); ++l) {
    const int c = plan.shadowmaskChannel[l];
    if (c >= 0 && c < kProbeOcclusionChannels) {
      set.occlusionLights[size_t(c)] = int32_t(l);
      anyChannel = true;
    }
  }
  const Integrator integrator(scene, tracer, probeIntegratorSettings(scene, settings));
  rep.integrator = integrator.settings();
  const size_t count = positions.size();
  // Per probe: what bakeProbe returns but the visibility map (kept in `moments`), and the
  // rays it traced (+ the first segments traced for validity).
  struct ProbeOut {
    ShL2Rgb sh;
    float validity = 1.0f;
    uint64_t rays = 0;
    bool footprint = false;  // baked over a ball
    float sunShare = 0.0f;
  };
  std::vector<ProbeOut> outs(count);
  const std::vector<float> maxDistance = probeVisibilityMaxDistances(scene, positions, settings);
  const size_t perProbe = settings.visibilityResolution > 0
                              ? kVisibilityValuesPerTexel *
                                    size_t(settings.visibilityResolution) *
                                    size_t(settings.visibilityResolution)
                              : 0;
  std::vector<uint16_t> moments(count * perProbe);
  std::vector<glm::vec4> occlusion(count, glm::vec4(1.0f));
  const std::vector<float> footprintRadius = probeFootprintRadii(positions, settings);
  ParallelOptions options;
  options.threads = settings.threads;
  options.grain = 1;  // a probe is thousands of paths: balance load probe by probe
  options.progress = progress;
  options.cancel = cancel;
  // Distributed bakes (src/distributed.h): probes dealt one by one across the ranks (every
  // probe costs the same rays), every rank gets every probe back (placement bakes again).
  const WorkSplit split = splitWork(count, 1);
  if (progress) progress->splitAcrossRanks();
  const bool finished = parallelForLocal(
      split,
      [&](size_t begin, size_t end) {
        for (size_t i = begin; i < end; ++i) {
          const uint64_t before = Integrator::threadRayCount();
          const uint64_t key = hashValues(settings.seed, i);
          VisibilityMapSpec vis;
          if (!maxDistance.empty()) vis = {settings.visibilityResolution, maxDistance[i]};
          // Only where light and shade are finer than the probes, unless asked everywhere.
          const float radius = footprintRadius[i] > 0.0f &&
                                       (settings.footprintEverywhere ||
                                        inThinLightSheet(scene, integrator, positions[i]))
                                   ? footprintRadius[i]
                                   : 0.0f;
          const ProbeSample sample = bakeProbe(integrator, positions[i], key, settings.rays,
                                               settings.lightSamples, cancel, vis, radius);
          outs[i].sh = sample.sh;
          outs[i].validity = sample.validity;
          outs[i].footprint = radius > 0.0f;
          outs[i].sunShare = sample.sunShare;
          std::copy(sample.visibility.begin(), sample.visibility.end(),
                    moments.begin() + ptrdiff_t(i * perProbe));
          if (anyChannel) {
            occlusion[i] =
                bakeProbeOcclusion(integrator, plan, positions[i], key, settings.occlusionSamples);
          }
          outs[i].rays = Integrator::threadRayCount() - before + settings.rays;
        }
      },
      options);
  const bool ok = finished && !(cancel && cancel->load());
  if (!exchangeItems(split, outs, 1, true, ok, !ok, progress) ||
      !exchangeItems(split, moments, perProbe, true, true, false, nullptr) ||
      !exchangeItems(split, occlusion, 1, true, true, false, nullptr))
    return Error{"cancelled"};
  if (progress) progress->finish();
  for (const ProbeOut& o : outs) {
    rep.rays += o.rays;
    rep.footprintProbes += o.footprint ? 1 : 0;
  }

  const int32_t sun = settings.sunShadows ? sunLayerLight(scene, integrator.settings()) : -1;
  if (sun >= 0) {
    set.sun.light = sun;
    const Light& light = scene.lights[size_t(sun)];
    // The light's raw delta, c_i = E Y_i(s): what a probe's SH holds of the light before
    // deringing (which the probes keep as before, on the sum; docs/probes.md, "Sun shadows").
    set.sun.sh = ShL2Rgb{};
    set.sun.sh.addSample(-glm::normalize(light.direction), light.color * light.intensity, 1.0f);
    set.sun.visibility.resize(count);
  }
  for (size_t i = 0; i < count; ++i) {
    set.sh[i] = outs[i].sh;
    set.validity[i] = outs[i].validity;
    if (sun >= 0) set.sun.visibility[i] = outs[i].sunShare;
  }
  set.occlusion = std::move(occlusion);
  if (settings.visibilityResolution > 0) {
    set.visibility.resolution = settings.visibilityResolution;
    set.visibility.maxDistance = maxDistance;
    set.visibility.moments = std::move(moments);
  }

  // Validity: probes inside geometry get their valid neighbours' mean (from the raw bake).
  std::vector<char> valid(count);
  for (size_t i = 0; i < count; ++i)
    valid[i] = (1.0f - set.validity[i]) <= settings.invalidBackfaceRatio;
  std::vector<std::vector<int32_t>> adjacency;
  const ProbeSet raw = set;
  for (size_t i = 0; i < count; ++i) {
    if (valid[i]) continue;
    rep.invalidProbes.push_back(int32_t(i));
    bool filled = false;
    if (settings.fillInvalid) {
      if (adjacency.empty()) adjacency = cellAdjacency(raw);
      if (auto mean = validNeighbourMean(raw, adjacency, valid, int32_t(i))) {
        set.sh[i] = *mean;
        // Inside geometry every shadow ray is blocked: take the neighbours' occlusion too.
        if (auto o = validNeighbourOcclusion(raw, adjacency, valid, int32_t(i)))
          set.occlusion[i] = *o;
        // ... and their share of the sun layer's light, which their SH now holds.
        if (sun >= 0) {
          if (auto v = validNeighbourMeanOf<double>(adjacency, valid, int32_t(i), [&](int32_t j) {
                return double(raw.sun.visibility[size_t(j)]);
              }))
            set.sun.visibility[i] = float(*v);
        }
        filled = true;
        ++rep.filledProbes;
      }
    }
    rep.warnings.push_back("probe " + std::to_string(i) + " at " + vecText(positions[i]) +
                           " is inside geometry (" +
                           std::to_string(int(std::lround(100.0 * (1.0 - set.validity[i])))) +
                           "% of its rays hit back faces)" +
                           (filled ? "; its SH is the mean of its valid neighbours'" : ""));
  }

  if (settings.dering) rep.deringedProbes = deringProbeSh(set.sh, settings.threads);
  if (sun >= 0 && set.dimension == 3) {
    std::optional<Progress> rampProgress;
    if (progress) rampProgress.emplace("sun ramps", size_t(set.innerCellCount), "cells");
    if (!bakeSunRamps(integrator, set, hashValues(settings.seed, kSunRampsTag), settings.threads,
                      rampProgress ? &*rampProgress : nullptr, cancel))
      return Error{"cancelled"};
    if (rampProgress) rampProgress->finish();
    for (const glm::vec4& a : set.sun.ramps) rep.sunRampCells += std::isnan(a.x) ? 0 : 1;
  }
  return set;
}

ObjectProbe bakeObjectProbe(const Integrator& integrator, const LightModePlan& plan,
                            const Bounds3& bounds, uint64_t key,
                            const ProbeBakeSettings& settings) {
  const vec3 centre = 0.5f * (bounds.min + bounds.max), half = 0.5f * (bounds.max - bounds.min);
  const float margin = 0.05f * glm::length(bounds.max - bounds.min) + 1e-3f;
  ObjectProbe light;
  light.occlusion = glm::vec4(0.0f);
  float weights = 0.0f;
  for (int k = 0; k < 7; ++k) {
    if (k == 6 && weights > 0.0f) break;  // the centre only when no face point is valid
    vec3 p = centre;
    if (k < 6) p[k / 2] += (k % 2 ? 1.0f : -1.0f) * (half[k / 2] + margin);
    const uint64_t probeKey = hashValues(key, uint64_t(k));
    const ProbeSample sample =
        bakeProbe(integrator, p, probeKey, settings.rays, settings.lightSamples);
    // Valid as bakeProbes counts a probe: at most invalidBackfaceRatio of its rays on back faces.
    const float w = k == 6                                                    ? 1.0f
                    : sample.validity >= 1.0f - settings.invalidBackfaceRatio ? sample.validity
                                                                              : 0.0f;
    if (w <= 0.0f) continue;
    light.sh += w * sample.sh;
    light.occlusion +=
        w * bakeProbeOcclusion(integrator, plan, p, probeKey, settings.occlusionSamples);
    weights += w;
  }
  light.sh *= 1.0f / weights;
  light.occlusion /= weights;
  if (settings.dering) {
    const DeringResult d = deringSh(light.sh);
    if (d.changed) light.sh = d.sh;
  }
  return light;
}

int32_t deringProbeSh(std::span<ShL2Rgb> sh, int threads) {
  std::vector<char> changed(sh.size(), 0);
  ParallelOptions options;
  options.threads = threads;
  options.grain = 64;  // ~0.2 ms per probe that needs the fit, ~3 us per probe that does not
  parallelFor(
      sh.size(),
      [&](size_t begin, size_t end) {
        for (size_t i = begin; i < end; ++i) {
          DeringResult d = deringSh(sh[i]);
          if (d.changed) {
            sh[i] = d.sh;
            changed[i] = 1;
          }
        }
      },
      options);
  int32_t count = 0;
  for (char c : changed) count += c;
  return count;
}

Result<std::vector<vec3>> parseProbePositions(std::string_view text, std::string_view name) {
  const std::string prefix = std::string(name) + ": ";
  nlohmann::json doc = nlohmann::json::parse(text, nullptr, /*allow_exceptions=*/false);
  if (doc.is_discarded()) return Error{prefix + "not valid JSON"};
  if (!doc.is_object() || !doc.contains("positions"))
    return Error{prefix + "positions: missing (expected {\"positions\": [[x, y, z], ...]})"};
  const nlohmann::json& list = doc["positions"];
  if (!list.is_array()) return Error{prefix + "positions: expected an array"};
  std::vector<vec3> out;
  out.reserve(list.size());
  for (size_t i = 0; i < list.size(); ++i) {
    const nlohmann::json& p = list[i];
    bool ok = p.is_array() && p.size() == 3;
    vec3 v(0.0f);
    for (int k = 0; ok && k < 3; ++k) {
      ok = p[k].is_number();
      if (ok) v[k] = p[k].get<float>();
    }
    if (!ok || !isFinite(v))
      return Error{prefix + "positions[" + std::to_string(i) + "]: expected 3 finite numbers"};
    if (glm::any(glm::greaterThan(glm::abs(v), vec3(kMaxProbeCoordinate))))
      return Error{prefix + "positions[" + std::to_string(i) + "]: a coordinate beyond " +
                   std::to_string(int64_t(kMaxProbeCoordinate)) + " m"};
    out.push_back(v);
  }
  if (out.empty()) return Error{prefix + "positions: empty"};
  return out;
}

Result<std::vector<vec3>> loadProbePositions(const std::string& path) {
  if (Status regular = checkRegularFile(path); !regular) return Error{regular.error()};
  std::ifstream in(path, std::ios::binary);
  if (!in) return Error{path + ": cannot open"};
  std::ostringstream text;
  text << in.rdbuf();
  if (in.bad()) return Error{path + ": read error"};
  return parseProbePositions(text.str(), path);
}

std::vector<vec3> sceneProbePositions(const Scene& scene) {
  std::vector<vec3> out;
  for (const ProbeGroup& g : scene.probeGroups)
    out.insert(out.end(), g.positions.begin(), g.positions.end());
  return out;
}

}  // namespace kiln
