// probe_placement.cpp: automatic probe placement (see probe_placement.h and
// docs/probe_placement.md for the algorithm and the measurements behind its choices).
#include "probes/probe_placement.h"

#include <algorithm>
#include <array>
#include <chrono>
#include <cmath>
#include <cstring>
#include <map>
#include <numeric>
#include <set>
#include <tuple>
#include <sstream>

#include "kiln/probe_runtime.h"
#include "probes/object_space.h"
#include "probes/placement_evaluation.h"
#include "probes/tetrahedralize.h"
#include "src/integrator.h"
#include "src/distributed.h"
#include "src/parallel.h"
#include "src/sampling.h"

namespace kiln {

using glm::ivec3;
namespace {

// Streams of random numbers are keyed by what they serve; these tags keep them apart.
constexpr uint64_t kCheckPointTag = 0x636865636bULL;  // "check"
constexpr uint64_t kCandidateTag = 0x63616e64ULL;     // "cand"
constexpr uint64_t kTruthTag = 0x7472757468ULL;       // "truth"
constexpr uint64_t kSpawnTag = 0x737061776eULL;       // "spawn"

std::string formatMetres(float v) {
  std::ostringstream s;
  s.precision(3);
  s << v << " m";
  return s.str();
}

float volumeOf(const Bounds3& b) {
  const vec3 e = b.extent();
  return e.x * e.y * e.z;
}

// Percentile of a copy (nearest rank).
float percentile(std::vector<float> v, double q) {
  if (v.empty()) return 0.0f;
  const size_t k = std::min(v.size() - 1, size_t(std::ceil(q * double(v.size()))) - 1);
  std::nth_element(v.begin(), v.begin() + ptrdiff_t(k), v.end());
  return v[k];
}

}  // namespace

// ---- validity --------------------------------------------------------------------------

PointProbe probePoint(const Scene& scene, const Tracer& tracer, vec3 p, uint32_t rays) {
  PointProbe out;
  const uint64_t key = positionKey(p);
  uint32_t back = 0;
  for (uint32_t s = 0; s < rays; ++s) {
    const vec3 dir = squareToUniformSphere(sobol2D(s, key));
    const std::optional<Hit> hit = tracer.intersect(Ray{p, dir, 0.0f, kInfinity});
    if (!hit) continue;
    const Material& m = scene.materialOf(hit->object, hit->triangle);
    if (hit->backFace && !m.doubleSided && m.alphaMode != AlphaMode::Blend) {
      ++back;
      if (hit->t < out.nearestBackDistance) {
        out.nearestBackDistance = hit->t;
        out.nearestBackDirection = dir;
      }
    }
  }
  out.backfaceRatio = rays ? float(back) / float(rays) : 0.0f;
  if (const std::optional<Tracer::NearestSurface> n = tracer.nearestSurface(p)) {
    out.nearestDistance = n->distance;
    if (n->distance > 0.0f) {
      out.nearestNormal = (p - n->point) / n->distance;
    } else {
      // On the surface: its face normal (either side; the inside test moves points that
      // are inside a solid through its back faces first).
      out.nearestNormal = scene.objects[n->object].faceNormal(n->triangle);
    }
  }
  return out;
}

bool isValidProbePoint(const Scene& scene, const Tracer& tracer, vec3 p,
                       const ProbeValiditySettings& settings) {
  const PointProbe pp = probePoint(scene, tracer, p, settings.rays);
  return pp.backfaceRatio <= settings.invalidBackfaceRatio &&
         pp.nearestDistance >= settings.minSurfaceDistance;
}

RelocatedPoint relocateProbePoint(const Scene& scene, const Tracer& tracer, vec3 p,
                                  const ProbeValiditySettings& settings,
                                  std::span<const Bounds3> volumes) {
  RelocatedPoint out;
  out.position = p;
  // Moves aim 10% past the minimum distance: a margin for float error and for the other
  // surfaces near the point, which the next pass measures again.
  const float target = 1.1f * settings.minSurfaceDistance;
  for (int move = 0; move <= settings.maxMoves; ++move) {
    const PointProbe pp = probePoint(scene, tracer, out.position, settings.rays);
    const bool inside = pp.backfaceRatio > settings.invalidBackfaceRatio;
    const bool tooClose = pp.nearestDistance < settings.minSurfaceDistance;
    if (!inside && !tooClose) {
      bool contained = volumes.empty();
      for (const Bounds3& b : volumes) contained = contained || b.contains(out.position);
      if (contained) {
        out.valid = true;
        return out;
      }
      if (!out.why.empty()) out.why += "; ";
      out.why += "dropped: moved outside the placement volumes";
      return out;
    }
    if (move == settings.maxMoves) break;
    if (!out.why.empty()) out.why += "; ";
    if (inside) {
      if (!std::isfinite(pp.nearestBackDistance)) break;
      // DDGI's relocation: step through the nearest back face, then clear the surface.
      const float step = pp.nearestBackDistance + target;
      out.position += pp.nearestBackDirection * step;
      out.why += "inside geometry (" + std::to_string(int(std::lround(100 * pp.backfaceRatio))) +
                 "% back faces): moved " + formatMetres(step) + " through the nearest back face";
    } else {
      const float step = std::max(target - pp.nearestDistance, 0.01f * target);
      out.position += pp.nearestNormal * step;
      out.why += "within " + formatMetres(pp.nearestDistance) + " of a surface: pushed " +
                 formatMetres(step) + " away from it";
    }
    out.moved = true;
  }
  out.valid = false;
  if (!out.why.empty()) out.why += "; ";
  out.why += "dropped: still inside geometry or too close to a surface";
  return out;
}

std::vector<Bounds3> placementVolumes(const Scene& scene, std::span<const Bounds3> volumes) {
  if (!volumes.empty()) return {volumes.begin(), volumes.end()};
  Bounds3 b;
  for (const Object& o : scene.objects) {
    if (!o.settings.isStatic) continue;
    for (const vec3& v : o.positions) b.extend(v);
  }
  if (b.empty()) b = scene.bounds;
  return {b};
}

std::vector<vec3> randomValidPoints(const Scene& scene, const Tracer& tracer,
                                    std::span<const Bounds3> volumes, uint32_t count,
                                    uint64_t seed, const ProbeValiditySettings& validity,
                                    int threads, const std::function<bool(vec3)>& accept) {
  std::vector<float> weights;
  for (const Bounds3& b : volumes) weights.push_back(volumeOf(b));
  const Distribution1D pick(weights);
  return rejectionSamplePoints(
      count, threads, [&](size_t i, uint32_t attempt) -> std::optional<vec3> {
        SampleStream stream(hashValues(seed, kCheckPointTag, i), attempt);
        const Bounds3& b = volumes[pick.sampleDiscrete(stream.get1D())];
        const vec2 u = stream.get2D();
        const float w = stream.get1D();
        const vec3 p = b.min + b.extent() * vec3(u.x, u.y, w);
        if (isValidProbePoint(scene, tracer, p, validity) && (!accept || accept(p))) return p;
        return std::nullopt;
      });
}

std::vector<vec3> rejectionSamplePoints(
    uint32_t count, int threads,
    const std::function<std::optional<vec3>(size_t i, uint32_t attempt)>& draw) {
  std::vector<vec3> points(count);
  std::vector<uint8_t> found(count, 0);
  ParallelOptions options;
  options.threads = threads;
  options.grain = 8;
  parallelFor(
      count,
      [&](size_t begin, size_t end) {
        for (size_t i = begin; i < end; ++i)
          for (uint32_t attempt = 0; attempt < 256 && !found[i]; ++attempt)
            if (const std::optional<vec3> p = draw(i, attempt)) {
              points[i] = *p;
              found[i] = 1;
            }
      },
      options);
  std::vector<vec3> out;
  for (uint32_t i = 0; i < count; ++i)
    if (found[i]) out.push_back(points[i]);
  return out;
}

std::vector<RelocatedPoint> relocateProbePoints(const Scene& scene, const Tracer& tracer,
                                                std::span<const vec3> points,
                                                const ProbeValiditySettings& settings,
                                                std::span<const Bounds3> volumes, int threads,
                                                const std::atomic<bool>* cancel) {
  std::vector<RelocatedPoint> out(points.size());
  ParallelOptions options;
  options.threads = threads;
  options.grain = 16;
  options.cancel = cancel;
  parallelFor(
      points.size(),
      [&](size_t begin, size_t end) {
        for (size_t i = begin; i < end; ++i)
          out[i] = relocateProbePoint(scene, tracer, points[i], settings, volumes);
      },
      options);
  return out;
}

std::vector<size_t> distinctValidPoints(std::span<const RelocatedPoint> points,
                                        float minSurfaceDistance) {
  const float cell = 0.5f * minSurfaceDistance;
  std::set<std::tuple<int64_t, int64_t, int64_t>> seen;
  std::vector<size_t> kept;
  for (size_t i = 0; i < points.size(); ++i) {
    if (!points[i].valid) continue;
    const vec3 p = points[i].position;
    if (cell > 0.0f && !seen.insert({int64_t(std::floor(p.x / cell)), int64_t(std::floor(p.y / cell)),
                                     int64_t(std::floor(p.z / cell))})
                            .second)
      continue;
    kept.push_back(i);
  }
  return kept;
}

namespace {

// Cell-centred lattice of spacing about h over the volumes, relocated, invalid points dropped,
// duplicates merged.
std::vector<vec3> validGrid(const Scene& scene, const Tracer& tracer,
                            std::span<const Bounds3> volumes, float h,
                            const ProbeValiditySettings& validity, int threads) {
  std::vector<vec3> lattice;
  for (const Bounds3& b : volumes) {
    const vec3 e = b.extent();
    ivec3 n;
    for (int k = 0; k < 3; ++k) n[k] = std::max(1, int(std::lround(e[k] / h)));
    for (int z = 0; z < n.z; ++z)
      for (int y = 0; y < n.y; ++y)
        for (int x = 0; x < n.x; ++x)
          lattice.push_back(b.min + e * (vec3(x, y, z) + 0.5f) / vec3(n));
  }
  const std::vector<RelocatedPoint> moved =
      relocateProbePoints(scene, tracer, lattice, validity, volumes, threads);
  std::vector<vec3> out;
  for (size_t i : distinctValidPoints(moved, validity.minSurfaceDistance))
    out.push_back(moved[i].position);
  return out;
}

}  // namespace

Result<std::vector<vec3>> uniformGridPositions(const Scene& scene, const Tracer& tracer,
                                               std::span<const Bounds3> volumes, uint32_t count,
                                               const ProbeValiditySettings& validity,
                                               int threads) {
  if (count < 4) return Error{"uniform grid: count must be at least 4"};
  float total = 0.0f;
  for (const Bounds3& b : volumes) total += volumeOf(b);
  if (!(total > 0.0f)) return Error{"uniform grid: the volumes are empty"};
  // Find a spacing with at least `count` valid points, then the largest such spacing.
  float lo = std::cbrt(total / float(count));  // count(lo) >= count once found
  std::vector<vec3> best = validGrid(scene, tracer, volumes, lo, validity, threads);
  for (int i = 0; i < 12 && best.size() < count; ++i) {
    lo *= 0.85f;
    best = validGrid(scene, tracer, volumes, lo, validity, threads);
  }
  if (best.size() < count) return Error{"uniform grid: too few valid points in the volumes"};
  return largestSpacingWithCount(lo, 2.0f * lo, count, std::move(best), [&](float h) {
    return std::optional(validGrid(scene, tracer, volumes, h, validity, threads));
  });
}

std::vector<vec3> largestSpacingWithCount(
    float lo, float hi, uint32_t count, std::vector<vec3> best,
    const std::function<std::optional<std::vector<vec3>>(float spacing)>& generate) {
  for (int i = 0; i < 14 && best.size() != count; ++i) {
    const float mid = 0.5f * (lo + hi);
    std::optional<std::vector<vec3>> g = generate(mid);
    if (g && g->size() >= count) {
      lo = mid;
      best = std::move(*g);
    } else {
      hi = mid;
    }
  }
  // Remove the surplus evenly.
  std::vector<vec3> out;
  out.reserve(count);
  for (uint32_t k = 0; k < count; ++k)
    out.push_back(best[size_t(uint64_t(k) * best.size() / count)]);
  return out;
}

// ---- error measurement --------------------------------------------------------------------

namespace {
const std::array<vec3, 6> kAxisNormals = {vec3(1, 0, 0),  vec3(-1, 0, 0), vec3(0, 1, 0),
                                          vec3(0, -1, 0), vec3(0, 0, 1),  vec3(0, 0, -1)};
}

float irradianceRms(const ShL2Rgb& sh) {
  float sum = 0.0f;
  for (const vec3& n : kAxisNormals) {
    const float e = luminance(sh.irradiance(n));
    sum += e * e;
  }
  return std::sqrt(sum / 6.0f);
}

float maxAxisIrradiance(const ShL2Rgb& sh) {
  float m = 0.0f;
  for (const vec3& n : kAxisNormals) m = std::max(m, luminance(sh.irradiance(n)));
  return m;
}

ShL2Rgb lightThroughWall(const Tracer& tracer, const ProbeSet& set, vec3 p,
                         const ProbeLocation& loc, float wallX, size_t* seen) {
  ShL2Rgb sum;
  for (int k = 0; k < 4; ++k) {
    if (loc.probes[k] < 0 || !(loc.weights[k] > 0.0f)) continue;
    const size_t i = size_t(loc.probes[k]);
    if ((set.positions[i].x < wallX) == (p.x < wallX)) continue;  // same side as p
    const vec3 to = set.positions[i] - p;
    const float length = glm::length(to);
    if (!tracer.occluded(Ray{p, to / length, 0.0f, length})) {
      if (seen) ++*seen;
      continue;
    }
    sum += set.sh[i] * loc.weights[k];
  }
  return sum;
}

// Root mean squares over the six axis normals of the luminance of E: of the estimate's
// error, of the truth and of the estimate (relativeIrradianceError and
// symmetricIrradianceError divide the first by the others).
struct AxisRms {
  float error = 0.0f, truth = 0.0f, estimate = 0.0f;
};
static AxisRms axisRms(const ShL2Rgb& truth, const ShL2Rgb& estimate) {
  float diff = 0.0f, ref = 0.0f, est = 0.0f;
  for (const vec3& n : kAxisNormals) {
    const float t = luminance(truth.irradiance(n));
    const float e = luminance(estimate.irradiance(n));
    const float d = e - t;
    diff += d * d;
    ref += t * t;
    est += e * e;
  }
  return {std::sqrt(diff / 6.0f), std::sqrt(ref / 6.0f), std::sqrt(est / 6.0f)};
}

float relativeIrradianceError(const ShL2Rgb& truth, const ShL2Rgb& estimate, float floor) {
  const AxisRms r = axisRms(truth, estimate);
  return r.error / std::max(r.truth, floor);
}

float meanIrradianceRatioError(const ShL2Rgb& truth, const ShL2Rgb& estimate, float floor) {
  const float r = std::max(luminance(estimate.c[0]), floor) /
                  std::max(luminance(truth.c[0]), std::max(floor, 1e-30f));
  return std::max(r, 1.0f / std::max(r, 1e-30f)) - 1.0f;
}

float symmetricIrradianceError(const ShL2Rgb& truth, const ShL2Rgb& estimate, float floor) {
  const AxisRms r = axisRms(truth, estimate);
  return r.error / std::max({r.truth, r.estimate, floor});
}

FieldError measureFieldError(const ProbeSet& set, std::span<const vec3> points,
                             std::span<const ShL2Rgb> truth, float floor, int threads,
                             const ProbeBlendSettings& blend, std::vector<ShL2Rgb>* estimates) {
  FieldError out;
  out.perPoint.assign(points.size(), 0.0f);
  if (estimates) estimates->assign(points.size(), ShL2Rgb{});
  ParallelOptions options;
  options.threads = threads;
  options.grain = 64;
  parallelFor(
      points.size(),
      [&](size_t begin, size_t end) {
        int32_t hint = -1;
        for (size_t i = begin; i < end; ++i) {
          const ProbeLocation loc = locateProbe(set, points[i], hint, blend);
          hint = loc.cell;
          const ShL2Rgb estimate = interpolateProbes(set, loc);
          out.perPoint[i] = relativeIrradianceError(truth[i], estimate, floor);
          if (estimates) (*estimates)[i] = estimate;
        }
      },
      options);
  return summarizeFieldError(std::move(out.perPoint));
}

FieldError summarizeFieldError(std::vector<float> perPoint) {
  FieldError out;
  double sum = 0.0;
  for (float e : perPoint) {
    sum += e;
    out.max = std::max(out.max, e);
  }
  out.mean = perPoint.empty() ? 0.0f : float(sum / double(perPoint.size()));
  out.p95 = percentile(perPoint, 0.95);
  out.perPoint = std::move(perPoint);
  return out;
}

std::vector<ShL2Rgb> bakePointSh(const Scene& scene, const Tracer& tracer,
                                 std::span<const vec3> points, const ProbeBakeSettings& settings,
                                 Progress* progress, const std::atomic<bool>* cancel,
                                 ProbeVisibility* visibility) {
  const Integrator integrator(scene, tracer, probeIntegratorSettings(scene, settings));
  std::vector<ShL2Rgb> out(points.size());
  const bool withVisibility = visibility && settings.visibilityResolution > 0;
  if (visibility) {
    *visibility = ProbeVisibility{};
    if (withVisibility) {
      visibility->resolution = settings.visibilityResolution;
      visibility->maxDistance = probeVisibilityMaxDistances(scene, points, settings);
      visibility->moments.assign(points.size() * visibility->valuesPerProbe(), 0);
    }
  }
  ParallelOptions options;
  options.threads = settings.threads;
  options.grain = 4;
  options.progress = progress;
  options.cancel = cancel;
  // Distributed bakes (src/distributed.h): points dealt one by one across the ranks; every
  // rank gets every point's SH (placement goes on from them on every rank).
  const WorkSplit split = splitWork(points.size(), 1);
  if (progress) progress->splitAcrossRanks();
  const bool done = parallelForLocal(
      split,
      [&](size_t begin, size_t end) {
        for (size_t i = begin; i < end; ++i) {
          VisibilityMapSpec spec;
          if (withVisibility) spec = {visibility->resolution, visibility->maxDistance[i]};
          ProbeSample sample = bakeProbe(integrator, points[i], hashValues(settings.seed, i),
                                         settings.rays, settings.lightSamples, cancel, spec);
          out[i] = sample.sh;
          if (withVisibility)
            std::copy(sample.visibility.begin(), sample.visibility.end(),
                      visibility->moments.begin() +
                          ptrdiff_t(i * visibility->valuesPerProbe()));
        }
      },
      options);
  const bool ok = done && !(cancel && cancel->load());
  if (!exchangeItems(split, out, 1, true, ok, !ok, progress) ||
      (withVisibility && !exchangeItems(split, visibility->moments, visibility->valuesPerProbe(),
                                        true, true, false, nullptr)))
    return {};
  return out;
}

CellCrossing countCellsCrossingGeometry(const Tracer& tracer, const ProbeSet& set) {
  CellCrossing out;
  if (set.dimension != 3) return out;
  out.innerCells = uint32_t(set.innerCellCount);
  for (int32_t c = 0; c < set.innerCellCount; ++c) {
    const glm::ivec4 cell = set.cells[size_t(c)];
    bool crosses = false;
    for (int a = 0; a < 4 && !crosses; ++a)
      for (int b = a + 1; b < 4 && !crosses; ++b) {
        const vec3 pa = set.positions[size_t(cell[a])], pb = set.positions[size_t(cell[b])];
        crosses = tracer.occluded(Ray{pa, pb - pa, 1e-4f, 1.0f - 1e-4f});
      }
    out.crossingCells += crosses ? 1u : 0u;
  }
  return out;
}

// ---- placement ------------------------------------------------------------------------------

namespace {

struct Candidate {
  vec3 position;
  vec3 original;
  bool moved = false;
  std::string why;
  bool fixed = false;  // a fixed probe (ProbePlacementSettings::fixedProbes)
};

// Octree corners over one volume (Godot LightmapGI's candidates): cells split down to maxDepth
// where a surface is within the cell's half-diagonal of its centre or where a baked punctual
// light's visibility differs between the cell's corners. Returns corner keys in the finest
// lattice, sorted.
std::vector<ivec3> octreeCorners(const Scene& scene, const Tracer& tracer,
                                 const Integrator& integrator, const Bounds3& volume, vec3 cell0,
                                 ivec3 n0, int maxDepth, int threads,
                                 const std::atomic<bool>* cancel) {
  const int f = 1 << maxDepth;
  const vec3 fine = cell0 / float(f);
  std::vector<uint32_t> lights;
  for (uint32_t l = 0; l < scene.lights.size(); ++l)
    if (scene.lights[l].mode != LightMode::Realtime) lights.push_back(l);
  auto world = [&](ivec3 k) { return volume.min + vec3(k) * fine; };
  auto needsSplit = [&](ivec3 lo, int size) {
    const vec3 a = world(lo), b = world(lo + ivec3(size));
    const vec3 c = 0.5f * (a + b);
    const float r = 0.5f * glm::length(b - a);
    const uint64_t key = positionKey(c);
    for (uint32_t s = 0; s < 32; ++s) {
      const vec3 dir = squareToUniformSphere(sobol2D(s, key));
      if (tracer.occluded(Ray{c, dir, 0.0f, r})) return true;
    }
    for (uint32_t l : lights) {
      float vmin = kInfinity, vmax = -kInfinity;
      for (int k = 0; k < 8; ++k) {
        const vec3 p = world(lo + ivec3(k & 1, (k >> 1) & 1, (k >> 2) & 1) * size);
        const float v = luminance(integrator.lightVisibility(p, vec3(0.0f), l, key, 0));
        vmin = std::min(vmin, v);
        vmax = std::max(vmax, v);
      }
      if (vmax - vmin > 0.5f) return true;
    }
    return false;
  };
  const size_t baseCells = size_t(n0.x) * size_t(n0.y) * size_t(n0.z);
  std::vector<std::vector<ivec3>> perCell(baseCells);
  ParallelOptions options;
  options.threads = threads;
  options.grain = 4;
  options.cancel = cancel;
  parallelFor(
      baseCells,
      [&](size_t begin, size_t end) {
        for (size_t i = begin; i < end; ++i) {
          const ivec3 base(int(i % size_t(n0.x)), int((i / size_t(n0.x)) % size_t(n0.y)),
                           int(i / (size_t(n0.x) * size_t(n0.y))));
          std::vector<std::pair<ivec3, int>> stack = {{base * f, f}};
          while (!stack.empty()) {
            const auto [lo, size] = stack.back();
            stack.pop_back();
            if (size > 1 && needsSplit(lo, size)) {
              const int h = size / 2;
              for (int k = 0; k < 8; ++k)
                stack.push_back({lo + ivec3(k & 1, (k >> 1) & 1, (k >> 2) & 1) * h, h});
            } else {
              for (int k = 0; k < 8; ++k)
                perCell[i].push_back(lo + ivec3(k & 1, (k >> 1) & 1, (k >> 2) & 1) * size);
            }
          }
        }
      },
      options);
  std::vector<ivec3> all;
  for (auto& v : perCell) all.insert(all.end(), v.begin(), v.end());
  auto less = [](const ivec3& a, const ivec3& b) {
    return std::tie(a.z, a.y, a.x) < std::tie(b.z, b.y, b.x);
  };
  std::sort(all.begin(), all.end(), less);
  all.erase(std::unique(all.begin(), all.end()), all.end());
  return all;
}

}  // namespace

float cellLeakVolumeError(const Tracer& tracer, const std::array<vec3, 4>& p,
                          const std::array<const ShL2Rgb*, 4>& sh, float floor,
                          const CellProbeMaps& maps) {
  bool blocked = false;
  for (int a = 0; a < 4 && !blocked; ++a)
    for (int b = a + 1; b < 4 && !blocked; ++b)
      blocked = tracer.occluded(Ray{p[size_t(a)], p[size_t(b)] - p[size_t(a)], 1e-4f,
                                    1.0f - 1e-4f});
  if (!blocked) return 0.0f;
  const float volume =
      std::abs(glm::dot(p[1] - p[0], glm::cross(p[2] - p[0], p[3] - p[0]))) / 6.0f;
  // Centroid, four points towards the vertices, six towards the edges' midpoints.
  std::vector<vec4> pattern = {vec4(0.25f)};
  for (int v = 0; v < 4; ++v) {
    vec4 w(0.1f);
    w[v] = 0.7f;
    pattern.push_back(w);
  }
  for (int a = 0; a < 4; ++a)
    for (int b = a + 1; b < 4; ++b) {
      vec4 w(0.1f);
      w[a] = w[b] = 0.4f;
      pattern.push_back(w);
    }
  const ProbeBlendSettings runtimeBlend;  // what a lookup without a normal uses
  double sum = 0.0;
  for (const vec4& w : pattern) {
    const vec3 x = w[0] * p[0] + w[1] * p[1] + w[2] * p[2] + w[3] * p[3];
    ShL2Rgb seen;
    float seenWeight = 0.0f;
    std::array<float, 4> runtime{};
    float runtimeSum = 0.0f;
    for (size_t v = 0; v < 4; ++v) {
      if (!tracer.occluded(Ray{x, p[v] - x, 1e-4f, 1.0f - 1e-4f})) {
        seen += *sh[v] * w[int(v)];
        seenWeight += w[int(v)];
      }
      // The runtime's weight (weightByVisibility): barycentric x the probe's visibility.
      runtime[v] = w[int(v)];
      if (maps.resolution > 0)
        runtime[v] *= probeVisibility(maps.moments[v], maps.resolution, maps.maxDistance[v],
                                      x - p[v], runtimeBlend);
      runtimeSum += runtime[v];
    }
    // Inside geometry (sees no probe) or unaffected (sees all): no leak at this point.
    if (seenWeight <= 0.0f || seenWeight >= 0.999f) continue;
    // Plain barycentric weights already sum to 1 (the pattern's do); with maps, the runtime's
    // rule, including its fade where the probes see the point with little weight.
    const float scale =
        maps.resolution > 0 ? visibleWeightScale(runtimeSum, runtimeBlend.minVisibleWeight) : 1.0f;
    ShL2Rgb blend;
    for (size_t v = 0; v < 4; ++v) blend += *sh[v] * (runtime[v] * scale);
    sum += relativeIrradianceError(seen * (1.0f / seenWeight), blend, floor);
  }
  return float(double(volume) * sum / double(pattern.size()));
}

std::vector<vec3> ProbePlacement::positions() const {
  std::vector<vec3> out;
  out.reserve(probes.size());
  for (const PlacedProbe& p : probes) out.push_back(p.position);
  return out;
}

namespace {

// The placement run (docs/probe_placement.md, "Algorithm"): one object holding what the
// stages share (candidates and their bakes, the check points and their truth, the growing
// set), each stage a method. run() calls them in order: candidates, truth, start set, grow,
// prune (which grows again), snapshots.
class ProbePlacer {
 public:
  ProbePlacer(const Scene& scene, const Tracer& tracer, const ProbePlacementSettings& settings,
              const std::atomic<bool>* cancel)
      : scene_(scene), tracer_(tracer), settings_(settings), cancel_(cancel) {}

  Result<ProbePlacement> run();

 private:
  // A set's score: its mean error at the scoring check points plus leakWeight x its leak
  // estimate. `field` holds the error at every check point (the pick points too).
  struct Scored {
    FieldError field;
    // With symmetricPicks, per check point: the error relative to the larger of the truth's
    // and the estimate's light (symmetricIrradianceError), a second ranking for growth.
    std::vector<float> pickError;
    // Growth's ranking, per check point: with objectRatioPicks the points where objects
    // stand by meanIrradianceRatioError, the others by their error in `field`; empty when
    // off (then `field` ranks).
    std::vector<float> rankError;
    float leak = 0.0f;
    float score = 0.0f;
  };

  static Status checkSettings(const ProbePlacementSettings& settings);
  bool isCancelled() const { return cancel_ && cancel_->load(); }

  // Stages.
  Status makeCandidates();  // 1. octree corners over the volumes, relocated
  Status bakeTruth();       // 2. cheap bakes of the candidates; check points and their truth
  Status chooseStart();     // 3. the better of two coarse start sets
  void grow();              // 4. add probes at the worst check points up to the budget
  bool prune();             // 5. remove probes that add nothing (true: some were removed)
  void finishSnapshots();   // 6. the best set of at most N probes for every snapshot count
  ProbePlacement finish();

  // Helpers of the stages.
  float leakOf(const ProbeSet& set, const std::vector<uint32_t>& sel);
  Result<ProbeSet> topology(const std::vector<uint32_t>& sel) const;
  std::optional<Scored> evaluate(const std::vector<uint32_t>& sel);
  std::optional<float> leakOfSelection(const std::vector<uint32_t>& sel);
  std::vector<uint32_t> startSet(bool withCorners) const;
  std::vector<uint32_t> pickOrder(const std::vector<float>& error) const;
  void takeSnapshots(const std::vector<uint32_t>& bestSoFar);
  int64_t nearestCandidate(vec3 p, const std::vector<uint32_t>& exclude) const;
  bool addSpawned(const std::vector<vec3>& spawned);
  void rejectLeakyPicks(std::vector<uint32_t>* picks);
  void keepBest();

  const Scene& scene_;
  const Tracer& tracer_;
  const ProbePlacementSettings& settings_;
  const std::atomic<bool>* cancel_;
  std::chrono::steady_clock::time_point start_ = std::chrono::steady_clock::now();
  ProbePlacement result_;

  std::vector<Bounds3> volumes_;
  std::optional<ReachableSpace> reachable_;  // when settings.reachableOnly
  float totalVolume_ = 0.0f;
  float spacing_ = 0.0f;
  ProbeBakeSettings bake_;           // the cheap bakes' settings (rays = candidateRays)
  ProbeBakeSettings candidateBake_;  // ... keyed for the candidates

  // Candidates (spawned probes are appended), their SH and visibility maps (resolution 0
  // when visibility is off).
  std::vector<Candidate> candidates_;
  std::vector<ShL2Rgb> candidateSh_;
  ProbeVisibility candidateVisibility_;
  // Check points and the SH baked at them.
  std::vector<vec3> checks_;
  std::vector<ShL2Rgb> truth_;
  float floor_ = 0.0f;
  size_t objectChecks_ = 0;  // the first check points, drawn where objects stand
  // Per check point where objects stand (objectRatioPicks): it lies in a sheet of light or
  // shade under about 18 cm thick (inThinLightSheet), and growth ranks it by its relative
  // error as the uniform ones.
  std::vector<uint8_t> striped_;
  // Per check point: 1 = it scores sets, 0 = it drives growth's picks (holdOut), or 1 for
  // every point when they do both.
  std::vector<uint8_t> scoring_;
  bool picksFromScoring_ = true;  // !holdOut: the scoring points drive picks too

  std::string topologyError_;
  std::map<std::array<uint32_t, 4>, float> leakCache_;  // by sorted candidate indices

  // The growing set (indices into candidates_), its score, and the best set seen.
  std::vector<uint32_t> selected_;
  std::vector<uint8_t> inSet_, rejected_;
  std::optional<Scored> current_;
  std::vector<uint32_t> bestSelected_;
  Scored best_;
  std::vector<uint8_t> spawnedFrom_;  // per check point: it spawned a probe already
  // Every set the run accepted, by score: the snapshots are the best of at most N probes.
  std::vector<std::pair<float, std::vector<uint32_t>>> accepted_;
  std::vector<uint32_t> snapshotsLeft_;
  std::vector<uint32_t> snapshotRequested_;  // the count each recorded snapshot stands for
  bool ranOutOfPicks_ = false;  // growth stopped: no candidate left near a bad check point
};

Status ProbePlacer::checkSettings(const ProbePlacementSettings& settings) {
  if (settings.budget < 4) return Error{"placement: budget must be at least 4"};
  if (!settings.fixedProbes.empty() && settings.budget <= settings.fixedProbes.size())
    return Error{"placement: the budget (" + std::to_string(settings.budget) +
                 ") must exceed the fixed probes (" + std::to_string(settings.fixedProbes.size()) +
                 ")"};
  for (size_t i = 0; i < settings.fixedProbes.size(); ++i)
    if (!isFinite(settings.fixedProbes[i]))
      return Error{"placement: fixed probe " + std::to_string(i) + ": not finite"};
  if (!(settings.floorHeight >= 0.0f) || !std::isfinite(settings.floorHeight))
    return Error{"placement: floorHeight must be a finite number >= 0"};
  if (settings.maxDepth < 0 || settings.maxDepth > 6)
    return Error{"placement: maxDepth must be in [0, 6]"};
  if (settings.candidateRays == 0 || settings.checkPoints == 0)
    return Error{"placement: candidateRays and checkPoints must be positive"};
  const int32_t visibilityResolution = settings.bake.visibilityResolution;
  if (!isVisibilityResolution(visibilityResolution))
    return Error{"placement: bake.visibilityResolution must be 0 or in [" +
                 std::to_string(kMinVisibilityResolution) + ", " +
                 std::to_string(kMaxVisibilityResolution) + "]"};
  if (!(settings.bake.visibilityMaxDistance >= 0.0f) ||
      !std::isfinite(settings.bake.visibilityMaxDistance))
    return Error{"placement: bake.visibilityMaxDistance must be a finite number >= 0"};
  for (size_t i = 0; i < settings.volumes.size(); ++i) {
    const Bounds3& b = settings.volumes[i];
    if (!isFinite(b.min) || !isFinite(b.max) || volumeOf(b) <= 0.0f)
      return Error{"placement: volumes[" + std::to_string(i) + "]: empty or not finite"};
  }
  return Status::success();
}

Result<ProbePlacement> ProbePlacer::run() {
  if (Status s = checkSettings(settings_); !s) return Error{s.error()};
  volumes_ = placementVolumes(scene_, settings_.volumes);
  for (const Bounds3& b : volumes_) totalVolume_ += volumeOf(b);
  if (!(totalVolume_ > 0.0f)) return Error{"placement: the scene bounds are empty"};
  spacing_ = settings_.spacing > 0.0f ? settings_.spacing
                                      : std::cbrt(totalVolume_ / float(settings_.budget));
  bake_ = settings_.bake;
  bake_.rays = settings_.candidateRays;
  bake_.threads = settings_.threads;
  if (settings_.reachableOnly) {
    ReachableSpaceSettings rs;
    rs.seeds = settings_.fixedProbes;
    rs.threads = settings_.threads;
    reachable_ = ReachableSpace::build(scene_, tracer_, volumes_, rs, cancel_);
    if (isCancelled()) return Error{"cancelled"};
    if (reachable_->enabled()) {
      result_.reachableCells = reachable_->reachedCells();
      result_.gridCells = reachable_->cells();
    }
  }

  if (Status s = makeCandidates(); !s) return Error{s.error()};
  if (Status s = bakeTruth(); !s) return Error{s.error()};
  if (Status s = chooseStart(); !s) return Error{s.error()};
  grow();
  // Prune, then grow again into the freed budget (two cycles).
  for (int cycle = 0; settings_.prune && cycle < 2 && !isCancelled(); ++cycle) {
    if (!prune()) break;
    grow();
  }
  if (isCancelled()) return Error{"cancelled"};
  finishSnapshots();
  return finish();
}

Status ProbePlacer::makeCandidates() {
  const Integrator integrator(scene_, tracer_, probeIntegratorSettings(scene_, bake_));
  std::vector<vec3> raw;
  const int f = 1 << settings_.maxDepth;
  for (const Bounds3& b : volumes_) {
    const vec3 e = b.extent();
    ivec3 n0;
    for (int k = 0; k < 3; ++k) n0[k] = std::max(1, int(std::ceil(e[k] / spacing_ - 1e-4f)));
    const vec3 cell0 = e / vec3(n0);
    for (const ivec3& k : octreeCorners(scene_, tracer_, integrator, b, cell0, n0,
                                        settings_.maxDepth, settings_.threads, cancel_))
      raw.push_back(b.min + vec3(k) * cell0 / float(f));
  }
  // Above walkable surfaces: where objects stand, which the octree's corners reach only at
  // its cells' heights.
  const size_t octreeCount = raw.size();
  if (settings_.floorHeight > 0.0f) {
    const std::vector<vec3> floors =
        pointsAboveFloors(scene_, tracer_, volumes_, 0.5f * spacing_, settings_.floorHeight,
                          settings_.validity.minSurfaceDistance);
    raw.insert(raw.end(), floors.begin(), floors.end());
  }
  if (isCancelled()) return Error{"cancelled"};
  std::vector<RelocatedPoint> relocated = relocateProbePoints(
      scene_, tracer_, raw, settings_.validity, volumes_, settings_.threads, cancel_);
  if (isCancelled()) return Error{"cancelled"};
  for (const RelocatedPoint& r : relocated) result_.candidatesDropped += r.valid ? 0u : 1u;
  // Sealed space: relocation can also move a point out of a wall into a cavity inside it.
  if (reachable_ && reachable_->enabled()) {
    std::vector<uint8_t> unreachable(relocated.size(), 0);
    ParallelOptions options;
    options.threads = settings_.threads;
    options.grain = 64;
    parallelFor(
        relocated.size(),
        [&](size_t begin, size_t end) {
          for (size_t i = begin; i < end; ++i)
            unreachable[i] = relocated[i].valid && !reachable_->reachable(relocated[i].position);
        },
        options);
    for (size_t i = 0; i < relocated.size(); ++i)
      if (unreachable[i]) {
        relocated[i].valid = false;
        ++result_.candidatesUnreachable;
      }
  }
  // Fixed probes first (indices 0..F-1), as given; candidates on top of one are left out.
  for (const vec3& p : settings_.fixedProbes) {
    Candidate c{p, p, false, "", true};
    candidates_.push_back(c);
  }
  result_.fixedProbes = uint32_t(settings_.fixedProbes.size());
  for (size_t i : distinctValidPoints(relocated, settings_.validity.minSurfaceDistance)) {
    const RelocatedPoint& r = relocated[i];
    bool onFixed = false;
    for (const vec3& fixedAt : settings_.fixedProbes)
      onFixed = onFixed || glm::length(fixedAt - r.position) <
                               0.5f * settings_.validity.minSurfaceDistance;
    if (onFixed) continue;
    candidates_.push_back(Candidate{r.position, raw[i], r.moved, r.why});
    result_.candidatesMoved += r.moved ? 1u : 0u;
    result_.candidatesAboveFloors += i >= octreeCount ? 1u : 0u;
  }
  result_.candidates = uint32_t(candidates_.size() - settings_.fixedProbes.size());
  if (candidates_.size() < 4) return Error{"placement: fewer than 4 valid candidates"};
  return Status::success();
}

Status ProbePlacer::bakeTruth() {
  // The same estimator for candidates and check points, so SH truncation and bias cancel.
  std::vector<vec3> candidatePositions;
  for (const Candidate& c : candidates_) candidatePositions.push_back(c.position);
  candidateBake_ = bake_;
  candidateBake_.seed = hashValues(settings_.seed, kCandidateTag);
  {
    Progress progress("placement candidates", candidatePositions.size(), "probes",
                      settings_.showProgress);
    candidateSh_ = bakePointSh(scene_, tracer_, candidatePositions, candidateBake_, &progress,
                               cancel_, &candidateVisibility_);
    progress.finish();
  }
  if (candidateSh_.empty()) return Error{"cancelled"};
  ProbeBakeSettings truthBake = bake_;
  truthBake.seed = hashValues(settings_.seed, kTruthTag);
  PointSampling sampling;
  sampling.reachable = reachable_ ? &*reachable_ : nullptr;
  sampling.objectShare = settings_.floorHeight > 0.0f ? settings_.objectCheckShare : 0.0f;
  Result<TruthPoints> truth =
      bakeTruthPoints(scene_, tracer_, volumes_, settings_.checkPoints,
                      placementCheckPointSeed(settings_.seed), settings_.validity, truthBake,
                      nullptr, cancel_, sampling);
  if (!truth) {
    if (isCancelled()) return Error{"cancelled"};
    return Error{"placement: check points: " + truth.error()};
  }
  checks_ = std::move(truth->points);
  truth_ = std::move(truth->sh);
  floor_ = truth->floor;
  result_.checkPoints = uint32_t(checks_.size());
  // Held out: even-numbered points pick, odd-numbered ones score; both halves hold points
  // where objects stand (the first ones) and uniform ones (the rest).
  picksFromScoring_ = !settings_.holdOut || checks_.size() < 8;
  scoring_.assign(checks_.size(), 1);
  if (!picksFromScoring_)
    for (size_t i = 0; i < checks_.size(); i += 2) scoring_[i] = 0;
  objectChecks_ = truth->objectPoints;
  result_.checkPointsAboveFloors = uint32_t(objectChecks_);
  if (settings_.objectRatioPicks && objectChecks_ > 0) {
    const Integrator integrator(scene_, tracer_, probeIntegratorSettings(scene_, bake_));
    striped_.assign(objectChecks_, 0);
    ParallelOptions options;
    options.threads = settings_.threads;
    options.grain = 16;
    parallelFor(
        objectChecks_,
        [&](size_t begin, size_t end) {
          for (size_t i = begin; i < end; ++i)
            striped_[i] = inThinLightSheet(scene_, integrator, checks_[i]) ? 1 : 0;
        },
        options);
  }
  return Status::success();
}

// The leak estimate of a set (cellLeakVolumeError summed over the inner cells, divided by the
// volumes' total): the expected error the check points miss in cells that span walls. Blends
// as the runtime will: with the candidates' visibility maps when they have them.
float ProbePlacer::leakOf(const ProbeSet& set, const std::vector<uint32_t>& sel) {
  if (set.dimension != 3) return 0.0f;
  std::vector<std::array<uint32_t, 4>> keys(size_t(set.innerCellCount));
  std::vector<std::array<uint32_t, 4>> missing;
  for (int32_t c = 0; c < set.innerCellCount; ++c) {
    const glm::ivec4 cell = set.cells[size_t(c)];
    std::array<uint32_t, 4> key;
    for (int v = 0; v < 4; ++v) key[size_t(v)] = sel[size_t(cell[v])];
    std::sort(key.begin(), key.end());
    keys[size_t(c)] = key;
    if (!leakCache_.count(key)) missing.push_back(key);
  }
  std::sort(missing.begin(), missing.end());
  missing.erase(std::unique(missing.begin(), missing.end()), missing.end());
  std::vector<float> computed(missing.size(), 0.0f);
  ParallelOptions options;
  options.threads = settings_.threads;
  options.grain = 16;
  parallelFor(
      missing.size(),
      [&](size_t begin, size_t end) {
        for (size_t m = begin; m < end; ++m) {
          std::array<vec3, 4> p;
          std::array<const ShL2Rgb*, 4> sh;
          CellProbeMaps maps;
          maps.resolution = candidateVisibility_.resolution;
          for (size_t v = 0; v < 4; ++v) {
            const uint32_t c = missing[m][v];
            p[v] = candidates_[c].position;
            sh[v] = &candidateSh_[c];
            if (maps.resolution > 0) {
              maps.moments[v] = candidateVisibility_.probe(int32_t(c));
              maps.maxDistance[v] = candidateVisibility_.maxDistance[c];
            }
          }
          computed[m] = cellLeakVolumeError(tracer_, p, sh, floor_, maps);
        }
      },
      options);
  for (size_t m = 0; m < missing.size(); ++m) leakCache_[missing[m]] = computed[m];
  double leak = 0.0;
  for (const auto& key : keys) leak += leakCache_[key];
  return float(leak / double(totalVolume_));
}

Result<ProbeSet> ProbePlacer::topology(const std::vector<uint32_t>& sel) const {
  std::vector<vec3> pos;
  pos.reserve(sel.size());
  for (uint32_t i : sel) pos.push_back(candidates_[i].position);
  return buildProbeTopology(pos, ProbeTopologySettings{});
}

std::optional<ProbePlacer::Scored> ProbePlacer::evaluate(const std::vector<uint32_t>& sel) {
  Result<ProbeSet> set = topology(sel);
  if (!set) {
    topologyError_ = set.error();
    return std::nullopt;
  }
  for (size_t k = 0; k < sel.size(); ++k) set->sh[k] = candidateSh_[sel[k]];
  if (!candidateVisibility_.empty()) {
    ProbeVisibility& vis = set->visibility;
    vis.resolution = candidateVisibility_.resolution;
    vis.maxDistance.reserve(sel.size());
    vis.moments.reserve(sel.size() * vis.valuesPerProbe());
    for (uint32_t i : sel) {
      vis.maxDistance.push_back(candidateVisibility_.maxDistance[i]);
      const std::span<const uint16_t> m = candidateVisibility_.probe(int32_t(i));
      vis.moments.insert(vis.moments.end(), m.begin(), m.end());
    }
  }
  // No sun layer (set->sun stays empty): its ramps are fitted per cell of the final set by the
  // bake, and without them the candidates' SH (which hold the light's share) blend plainly.
  Scored out;
  std::vector<ShL2Rgb> estimates;
  const bool ratioPicks = settings_.objectRatioPicks && objectChecks_ > 0;
  out.field = measureFieldError(*set, checks_, truth_, floor_, settings_.threads, {},
                                settings_.symmetricPicks || ratioPicks ? &estimates : nullptr);
  if (settings_.symmetricPicks)
    for (size_t i = 0; i < estimates.size(); ++i)
      out.pickError.push_back(symmetricIrradianceError(truth_[i], estimates[i], floor_));
  if (ratioPicks) {
    // The floor: half the error floor, taken as an L00 luminance (about 2.5% of the mean
    // light; what was measured in round 7).
    out.rankError = out.field.perPoint;
    for (size_t i = 0; i < objectChecks_; ++i)
      if (!striped_[i])
        out.rankError[i] = meanIrradianceRatioError(truth_[i], estimates[i], 0.5f * floor_);
  }
  double sum = 0.0;
  size_t n = 0;
  for (size_t i = 0; i < checks_.size(); ++i)
    if (scoring_[i]) sum += out.field.perPoint[i], ++n;
  if (settings_.leakWeight > 0.0f) out.leak = leakOf(*set, sel);
  out.score = float(sum / double(std::max<size_t>(n, 1))) + settings_.leakWeight * out.leak;
  return out;
}

// The leak a pick brings: the set's leak with it minus without it (0 when leaks are off).
std::optional<float> ProbePlacer::leakOfSelection(const std::vector<uint32_t>& sel) {
  Result<ProbeSet> set = topology(sel);
  if (!set) return std::nullopt;
  return leakOf(*set, sel);
}

// The candidates nearest the cells' centres of a coarse lattice of about `initial` cells (a
// small uniform grid snapped to valid candidates), with each volume's eight corners as well
// when `withCorners`. Farthest-point sampling would start from the volumes' corners, all of
// them against walls.
std::vector<uint32_t> ProbePlacer::startSet(bool withCorners) const {
  uint32_t initial = std::max(8u, settings_.budget / 10u);
  if (!snapshotsLeft_.empty()) initial = std::min(initial, std::max(4u, snapshotsLeft_.front()));
  initial = std::min({initial, settings_.budget, uint32_t(candidates_.size())});
  std::vector<uint32_t> sel;
  std::vector<uint8_t> in(candidates_.size(), 0);
  const uint32_t fixed = uint32_t(settings_.fixedProbes.size());
  for (float h = std::cbrt(totalVolume_ / float(initial)); sel.size() < 4; h *= 0.8f) {
    sel.clear();
    std::fill(in.begin(), in.end(), 0);
    for (uint32_t i = 0; i < fixed; ++i) {
      in[i] = 1;
      sel.push_back(i);
    }
    for (const Bounds3& b : volumes_) {
      const vec3 e = b.extent();
      ivec3 n;
      for (int k = 0; k < 3; ++k) n[k] = std::max(1, int(std::lround(e[k] / h)));
      std::vector<vec3> targets;
      for (int z = 0; z < n.z; ++z)
        for (int y = 0; y < n.y; ++y)
          for (int x = 0; x < n.x; ++x)
            targets.push_back(b.min + e * (vec3(x, y, z) + 0.5f) / vec3(n));
      if (withCorners)
        for (int k = 0; k < 8; ++k)
          targets.push_back(b.min + e * vec3(k & 1, (k >> 1) & 1, (k >> 2) & 1));
      for (const vec3& c : targets) {
        if (sel.size() >= settings_.budget) break;
        uint32_t nearest = 0;
        float nearestDistance = kInfinity;
        for (uint32_t i = 0; i < candidates_.size(); ++i) {
          const float d = glm::length(candidates_[i].position - c);
          if (d < nearestDistance) nearestDistance = d, nearest = i;
        }
        if (!in[nearest]) {
          in[nearest] = 1;
          sel.push_back(nearest);
        }
      }
    }
    if (h < 1e-3f) break;
  }
  return sel;
}

Status ProbePlacer::chooseStart() {
  snapshotsLeft_ = settings_.snapshotCounts;
  std::sort(snapshotsLeft_.begin(), snapshotsLeft_.end());
  inSet_.assign(candidates_.size(), 0);
  rejected_.assign(candidates_.size(), 0);
  // Two start sets, the lattice's cell centres alone and with each volume's eight corners as
  // well; the one with the lower score is kept. The corners put the whole open volume inside
  // the start hull (the courtyard: no extrapolated regions), but in a closed building whose
  // bounds include a thin shell outside its walls they are sunlit probes that leak into the
  // rooms, which the leak estimate sees.
  for (bool withCorners : {false, true}) {
    std::vector<uint32_t> sel = startSet(withCorners);
    if (sel.size() < 4 || sel == selected_) continue;
    std::optional<Scored> e = evaluate(sel);
    if (e && (!current_ || e->score < current_->score)) {
      current_ = std::move(e);
      selected_ = std::move(sel);
    }
  }
  if (selected_.size() < 4) return Error{"placement: fewer than 4 distinct start probes"};
  if (!current_) return Error{"placement: " + topologyError_};
  for (uint32_t i : selected_) inSet_[i] = 1;
  accepted_ = {{current_->score, selected_}};
  result_.initialError = current_->score;
  result_.largestSet = uint32_t(selected_.size());
  result_.errorHistory.push_back(current_->score);
  takeSnapshots(selected_);
  spawnedFrom_.assign(checks_.size(), 0);
  // Growth always adds (one probe rarely helps on its own: it changes the triangulation
  // around it, and the walls between a few probes need several on each side); the best set
  // seen is kept, so the result never has a higher check error than the start.
  bestSelected_ = selected_;
  best_ = *current_;
  return Status::success();
}

// Snapshot s, once the growing set has reached s probes: `bestSoFar`, the best-scoring set
// of at most s probes.
void ProbePlacer::takeSnapshots(const std::vector<uint32_t>& bestSoFar) {
  while (!snapshotsLeft_.empty() && selected_.size() >= snapshotsLeft_.front()) {
    std::vector<vec3> pos;
    for (uint32_t i : bestSoFar) pos.push_back(candidates_[i].position);
    result_.snapshots.push_back(std::move(pos));
    result_.snapshotCounts.push_back(uint32_t(bestSoFar.size()));
    snapshotRequested_.push_back(snapshotsLeft_.front());
    snapshotsLeft_.erase(snapshotsLeft_.begin());
  }
}

// The nearest candidate to p not in the set, preferring one that sees p (a probe on the far
// side of a wall does not fix the error at p).
int64_t ProbePlacer::nearestCandidate(vec3 p, const std::vector<uint32_t>& exclude) const {
  std::vector<std::pair<float, uint32_t>> near;
  for (uint32_t i = 0; i < candidates_.size(); ++i) {
    if (inSet_[i] || rejected_[i]) continue;
    if (std::find(exclude.begin(), exclude.end(), i) != exclude.end()) continue;
    near.push_back({glm::length(candidates_[i].position - p), i});
  }
  if (near.empty()) return -1;
  const size_t k = std::min<size_t>(16, near.size());
  std::partial_sort(near.begin(), near.begin() + ptrdiff_t(k), near.end());
  for (size_t j = 0; j < k; ++j) {
    const vec3 q = candidates_[near[j].second].position;
    if (!tracer_.occluded(Ray{p, q - p, 1e-4f, 1.0f - 1e-4f})) return near[j].second;
  }
  return near[0].second;
}

// Bakes probes at `spawned` check points and appends them to the candidates; false when
// cancelled.
bool ProbePlacer::addSpawned(const std::vector<vec3>& spawned) {
  ProbeBakeSettings spawnBake = candidateBake_;
  spawnBake.seed = hashValues(settings_.seed, kSpawnTag, result_.rounds);
  ProbeVisibility spawnedVisibility;
  const std::vector<ShL2Rgb> sh =
      bakePointSh(scene_, tracer_, spawned, spawnBake, nullptr, cancel_, &spawnedVisibility);
  if (sh.empty()) return false;
  for (size_t k = 0; k < spawned.size(); ++k) {
    candidates_.push_back(Candidate{spawned[k], spawned[k], false, ""});
    candidateSh_.push_back(sh[k]);
    inSet_.push_back(0);
    rejected_.push_back(0);
  }
  if (!candidateVisibility_.empty()) {
    candidateVisibility_.maxDistance.insert(candidateVisibility_.maxDistance.end(),
                                            spawnedVisibility.maxDistance.begin(),
                                            spawnedVisibility.maxDistance.end());
    candidateVisibility_.moments.insert(candidateVisibility_.moments.end(),
                                        spawnedVisibility.moments.begin(),
                                        spawnedVisibility.moments.end());
  }
  result_.spawned += uint32_t(spawned.size());
  return true;
}

// Leak-aware acceptance: a pick whose own leak (the set's leak with all picks minus without
// it) exceeds the mean error share of one probe is dropped for good. It would bridge a wall
// between differently lit sides (e.g. a sunlit probe outside a building joined to probes in a
// dark room) for a gain the check points overrate.
void ProbePlacer::rejectLeakyPicks(std::vector<uint32_t>* picks) {
  std::vector<uint32_t> all = selected_;
  all.insert(all.end(), picks->begin(), picks->end());
  const std::optional<float> with = leakOfSelection(all);
  const float share = best_.score / float(selected_.size());
  std::vector<uint32_t> kept;
  for (size_t k = 0; with && k < picks->size(); ++k) {
    std::vector<uint32_t> without = selected_;
    for (size_t m = 0; m < picks->size(); ++m)
      if (m != k) without.push_back((*picks)[m]);
    const std::optional<float> w = leakOfSelection(without);
    if (w && settings_.leakWeight * (*with - *w) > share)
      rejected_[(*picks)[k]] = 1;
    else
      kept.push_back((*picks)[k]);
  }
  if (with) {
    result_.leakRejected += uint32_t(picks->size() - kept.size());
    *picks = std::move(kept);
  }
}

void ProbePlacer::grow() {
  const float exclusion = 0.5f * spacing_;
  const float reach = settings_.candidateReach * spacing_;
  while (selected_.size() < settings_.budget && best_.score > settings_.targetError &&
         !isCancelled()) {
    uint32_t batch = std::max(1u, uint32_t(std::lround(settings_.batchFraction *
                                                        float(selected_.size()))));
    batch = std::min(batch, settings_.budget - uint32_t(selected_.size()));
    if (!snapshotsLeft_.empty() && snapshotsLeft_.front() > selected_.size())
      batch = std::min(batch, snapshotsLeft_.front() - uint32_t(selected_.size()));
    // A batch from the check points ranked by their relative error (the score's measure: a
    // shaded point lit too bright ranks first) and, with symmetricPicks, one ranked by the
    // symmetric error (a sunlit point lit too dark ranks as high): whichever scores lower is
    // taken. Neither ranking wins everywhere (docs/probe_placement.md, "Symmetric picks").
    std::vector<vec3> spawned;
    std::vector<uint32_t> spawnedCheck;  // the check point each spawned probe stands on
    auto makeBatch = [&](const std::vector<float>& error) {
      std::vector<uint32_t> picks;
      std::vector<vec3> pickPositions;
      for (uint32_t j : pickOrder(error)) {
        if (picks.size() >= batch) break;
        bool covered = false;
        for (const vec3& q : pickPositions)
          covered = covered || glm::length(q - checks_[j]) < exclusion;
        if (covered) continue;
        const int64_t c = nearestCandidate(checks_[j], picks);
        // No candidate near the bad point (open air, where the octree is coarse): a new probe
        // at the point itself (it is valid: check points are), baked below. Each check point
        // spawns at most one.
        const bool far =
            c < 0 || glm::length(candidates_[size_t(c)].position - checks_[j]) > reach;
        const auto earlier = std::find(spawnedCheck.begin(), spawnedCheck.end(), j);
        if (far && earlier != spawnedCheck.end()) {  // spawned by the other batch
          picks.push_back(uint32_t(candidates_.size()) +
                          uint32_t(earlier - spawnedCheck.begin()));
          pickPositions.push_back(checks_[j]);
        } else if (far && !spawnedFrom_[j]) {
          spawnedFrom_[j] = 1;
          picks.push_back(uint32_t(candidates_.size() + spawned.size()));
          spawned.push_back(checks_[j]);
          spawnedCheck.push_back(j);
          pickPositions.push_back(checks_[j]);
        } else if (c >= 0) {
          picks.push_back(uint32_t(c));
          pickPositions.push_back(candidates_[size_t(c)].position);
        }
      }
      return picks;
    };
    std::vector<std::vector<uint32_t>> batches = {makeBatch(
        current_->rankError.empty() ? current_->field.perPoint : current_->rankError)};
    if (settings_.symmetricPicks) {
      std::vector<uint32_t> symmetric = makeBatch(current_->pickError);
      if (symmetric != batches[0]) batches.push_back(std::move(symmetric));
    }
    if (batches[0].empty() && batches.size() == 1) {
      ranOutOfPicks_ = true;
      break;
    }
    if (!spawned.empty() && !addSpawned(spawned)) break;  // cancelled
    std::vector<uint32_t> picks, trial;
    std::optional<Scored> e;
    for (std::vector<uint32_t>& b : batches) {
      if (settings_.leakWeight > 0.0f && !b.empty()) rejectLeakyPicks(&b);
      if (b.empty()) continue;
      std::vector<uint32_t> t = selected_;
      t.insert(t.end(), b.begin(), b.end());
      std::optional<Scored> eb = evaluate(t);
      if (!eb) {
        for (uint32_t c : b) rejected_[c] = 1;  // degenerate topology: try others
        continue;
      }
      if (!e || eb->score < e->score) {
        e = std::move(eb);
        picks = b;
        trial = std::move(t);
      }
    }
    if (!e) continue;
    for (uint32_t c : picks) inSet_[c] = 1;
    selected_ = std::move(trial);
    current_ = std::move(e);
    accepted_.push_back({current_->score, selected_});
    result_.largestSet = std::max(result_.largestSet, uint32_t(selected_.size()));
    ++result_.rounds;
    if (current_->score <= best_.score) {
      best_ = *current_;
      bestSelected_ = selected_;
      result_.errorHistory.push_back(best_.score);
    }
    takeSnapshots(bestSelected_);
  }
  keepBest();
}

// The pick points (all check points unless held out) with some error, worst first (ties
// in index order).
std::vector<uint32_t> ProbePlacer::pickOrder(const std::vector<float>& error) const {
  std::vector<uint32_t> order;
  for (uint32_t j = 0; j < checks_.size(); ++j)
    if ((picksFromScoring_ || !scoring_[j]) && error[j] > 0.0f) order.push_back(j);
  std::stable_sort(order.begin(), order.end(),
                   [&](uint32_t a, uint32_t b) { return error[a] > error[b]; });
  return order;
}

// Back to the best-scoring set seen.
void ProbePlacer::keepBest() {
  selected_ = bestSelected_;
  current_ = best_;
  std::fill(inSet_.begin(), inSet_.end(), 0);
  for (uint32_t i : selected_) inSet_[i] = 1;
}

// Tries removing the probes that differ least from their four nearest neighbours' mean;
// keeps a removal only when the score does not rise.
bool ProbePlacer::prune() {
  if (selected_.size() <= 5) return false;
  std::vector<std::pair<float, uint32_t>> redundancy;
  for (size_t k = 0; k < selected_.size(); ++k) {
    if (candidates_[selected_[k]].fixed) continue;  // the user's: kept
    const vec3 p = candidates_[selected_[k]].position;
    std::vector<std::pair<float, size_t>> near;
    for (size_t m = 0; m < selected_.size(); ++m)
      if (m != k) near.push_back({glm::length(candidates_[selected_[m]].position - p), m});
    const size_t kn = std::min<size_t>(4, near.size());
    std::partial_sort(near.begin(), near.begin() + ptrdiff_t(kn), near.end());
    ShL2Rgb mean;
    for (size_t j = 0; j < kn; ++j) mean += candidateSh_[selected_[near[j].second]] * (1.0f / kn);
    redundancy.push_back(
        {relativeIrradianceError(candidateSh_[selected_[k]], mean, floor_), selected_[k]});
  }
  std::stable_sort(redundancy.begin(), redundancy.end(),
                   [](const auto& a, const auto& b) { return a.first < b.first; });
  const size_t trials = std::min<size_t>({64, selected_.size() / 4, redundancy.size()});
  uint32_t removed = 0;
  for (size_t t = 0; t < trials && selected_.size() > 5 && !isCancelled(); ++t) {
    const uint32_t victim = redundancy[t].second;
    std::vector<uint32_t> trial;
    for (uint32_t i : selected_)
      if (i != victim) trial.push_back(i);
    std::optional<Scored> e = evaluate(trial);
    if (e && e->score <= current_->score) {
      selected_ = std::move(trial);
      inSet_[victim] = 0;
      rejected_[victim] = 1;  // do not add it straight back
      current_ = std::move(e);
      best_ = *current_;
      bestSelected_ = selected_;
      accepted_.push_back({current_->score, selected_});
      result_.errorHistory.push_back(current_->score);
      ++removed;
    }
  }
  result_.pruned += removed;
  return removed > 0;
}

// Snapshot s: the lowest-score set of at most s probes accepted at any point of the run
// (growth, pruning, regrowth).
void ProbePlacer::finishSnapshots() {
  for (size_t k = 0; k < result_.snapshotCounts.size(); ++k) {
    const uint32_t limit = snapshotRequested_[k];
    const std::vector<uint32_t>* bestSet = nullptr;
    float bestScore = kInfinity;
    for (const auto& [score, set] : accepted_)
      if (set.size() <= limit && score < bestScore) bestScore = score, bestSet = &set;
    if (!bestSet) continue;
    std::vector<vec3> pos;
    for (uint32_t i : *bestSet) pos.push_back(candidates_[i].position);
    result_.snapshots[k] = std::move(pos);
    result_.snapshotCounts[k] = uint32_t(bestSet->size());
  }
}

ProbePlacement ProbePlacer::finish() {
  // Fewer than 90% of the budget: say why (the CLI warns with it).
  if (uint64_t(selected_.size()) * 10 < uint64_t(settings_.budget) * 9) {
    std::ostringstream why;
    why << selected_.size() << " of " << settings_.budget << " probes: ";
    if (best_.score <= settings_.targetError) {
      why << "the target error " << settings_.targetError << " was reached";
    } else if (result_.largestSet < uint64_t(settings_.budget) * 9 / 10 && ranOutOfPicks_) {
      why << "no free candidate was left near the worst check points (" << result_.candidates
          << " candidates, " << result_.leakRejected
          << " picks dropped for leaks); more candidates (--depth, --spacing) would help";
    } else {
      why << "the best-scoring set is smaller: sets of up to " << result_.largestSet
          << " probes scored worse at the check points (mean error + leak " << best_.score
          << " at " << selected_.size()
          << "); the cheap bakes' noise can outweigh what more probes add (--rays, "
             "--check-points)";
    }
    result_.belowBudget = why.str();
  }
  result_.estimatedError = current_->score;
  result_.estimatedLeak = current_->leak;
  result_.estimatedError95 = current_->field.p95;
  std::sort(selected_.begin(), selected_.end());
  for (uint32_t i : selected_) {
    const Candidate& c = candidates_[i];
    result_.probes.push_back(PlacedProbe{c.position, c.original, c.moved, c.fixed, c.why});
  }
  result_.seconds =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - start_).count();
  return std::move(result_);
}

}  // namespace

uint64_t placementCheckPointSeed(uint64_t seed) { return hashValues(seed, kCheckPointTag); }

Result<ProbePlacement> placeProbes(const Scene& scene, const Tracer& tracer,
                                   const ProbePlacementSettings& settings,
                                   const std::atomic<bool>* cancel) {
  return ProbePlacer(scene, tracer, settings, cancel).run();
}

}  // namespace kiln
