// object_space.cpp: reachable space (flood fill) and walkable surfaces (see object_space.h).
#include "probes/object_space.h"

#include <algorithm>
#include <cmath>
#include <deque>
#include <optional>

#include "src/parallel.h"
#include "src/sampling.h"

namespace kiln {

using glm::ivec3;

namespace {

constexpr uint64_t kSkyTag = 0x736b79ULL;  // "sky"

bool insideAny(std::span<const Bounds3> volumes, vec3 p) {
  for (const Bounds3& b : volumes)
    if (b.contains(p)) return true;
  return false;
}

bool sees(const Tracer& tracer, vec3 a, vec3 b) {
  return !tracer.occluded(Ray{a, b - a, 1e-4f, 1.0f - 1e-4f});
}

}  // namespace

int64_t ReachableSpace::index(ivec3 c) const {
  if (c.x < 0 || c.y < 0 || c.z < 0 || c.x >= dims_.x || c.y >= dims_.y || c.z >= dims_.z)
    return -1;
  return (int64_t(c.z) * dims_.y + c.y) * dims_.x + c.x;
}

vec3 ReachableSpace::centre(ivec3 c) const { return box_.min + (vec3(c) + 0.5f) * cell_; }

ReachableSpace ReachableSpace::build(const Scene& scene, const Tracer& tracer,
                                     std::span<const Bounds3> volumes,
                                     const ReachableSpaceSettings& settings,
                                     const std::atomic<bool>* cancel) {
  ReachableSpace out(tracer);
  for (const Bounds3& b : volumes) out.box_.extend(b);
  if (out.box_.empty()) return out;
  const vec3 e = out.box_.extent();
  out.cell_ = settings.cellSize > 0.0f ? settings.cellSize
                                       : std::max(0.02f, std::cbrt(e.x * e.y * e.z / 1e5f));
  for (int k = 0; k < 3; ++k) out.dims_[k] = std::clamp(int(std::ceil(e[k] / out.cell_)), 1, 1024);
  const size_t n = size_t(out.dims_.x) * size_t(out.dims_.y) * size_t(out.dims_.z);
  auto cellOf = [&](size_t i) {
    return ivec3(int(i % size_t(out.dims_.x)), int((i / size_t(out.dims_.x)) % size_t(out.dims_.y)),
                 int(i / (size_t(out.dims_.x) * size_t(out.dims_.y))));
  };
  // Per cell: bit k = connected to its +k neighbour; bit 3 = sees the sky.
  std::vector<uint8_t> flags(n, 0);
  ParallelOptions options;
  options.threads = settings.threads;
  options.grain = 256;
  options.cancel = cancel;
  const float h = out.cell_;
  parallelFor(
      n,
      [&](size_t begin, size_t end) {
        for (size_t i = begin; i < end; ++i) {
          const ivec3 c = cellOf(i);
          const vec3 p = out.centre(c);
          uint8_t f = 0;
          for (int k = 0; k < 3; ++k) {
            ivec3 d(0);
            d[k] = 1;
            if (out.index(c + d) < 0) continue;
            // The centres' segment, or one of four beside it (a gap narrower than a cell
            // between the centres' line and a wall still connects).
            const vec3 step = vec3(d) * h;
            const int u = (k + 1) % 3, v = (k + 2) % 3;
            bool open = sees(tracer, p, p + step);
            for (int s = 0; s < 4 && !open; ++s) {
              vec3 off(0.0f);
              off[s < 2 ? u : v] = (s % 2 ? 0.3f : -0.3f) * h;
              open = sees(tracer, p + off, p + off + step) && sees(tracer, p, p + off) &&
                     sees(tracer, p + step, p + off + step);
            }
            if (open) f |= uint8_t(1u << k);
          }
          for (uint32_t s = 0; s < settings.skyRays; ++s) {
            const vec3 dir = squareToUniformSphere(sobol2D(s, kSkyTag));
            if (!tracer.occluded(Ray{p, dir, 0.0f, kInfinity})) {
              f |= 8u;
              break;
            }
          }
          flags[i] = f;
        }
      },
      options);
  if (cancel && cancel->load()) return out;

  out.reached_.assign(n, 0);
  std::deque<size_t> queue;
  auto seed = [&](size_t i) {
    if (out.reached_[i]) return;
    out.reached_[i] = 1;
    ++out.seedCells_;
    queue.push_back(i);
  };
  for (size_t i = 0; i < n; ++i)
    if (flags[i] & 8u) seed(i);
  std::vector<vec3> points = settings.seeds;
  for (const Light& l : scene.lights)
    if (l.type != LightType::Directional) points.push_back(l.position);
  for (const Camera& c : scene.cameras) points.push_back(vec3(c.worldFromCamera[3]));
  for (const vec3& p : points) {
    if (!out.box_.contains(p)) continue;
    const ivec3 c = glm::clamp(ivec3(glm::floor((p - out.box_.min) / h)), ivec3(0), out.dims_ - 1);
    // The cell itself when p sees its centre (p may sit in a wall's cell), else any
    // neighbour whose centre p sees.
    for (int dz = -1; dz <= 1; ++dz)
      for (int dy = -1; dy <= 1; ++dy)
        for (int dx = -1; dx <= 1; ++dx) {
          const int64_t j = out.index(c + ivec3(dx, dy, dz));
          if (j >= 0 && sees(tracer, p, out.centre(c + ivec3(dx, dy, dz)))) seed(size_t(j));
        }
  }
  if (queue.empty()) {
    out.reached_.clear();
    return out;  // nothing to start from: everything counts as reachable
  }
  out.enabled_ = true;
  while (!queue.empty()) {
    const size_t i = queue.front();
    queue.pop_front();
    const ivec3 c = cellOf(i);
    for (int k = 0; k < 3; ++k)
      for (int sign : {1, -1}) {
        ivec3 d(0);
        d[k] = sign;
        const int64_t j = out.index(c + d);
        if (j < 0 || out.reached_[size_t(j)]) continue;
        const uint8_t linkFlags = sign > 0 ? flags[i] : flags[size_t(j)];
        if (!(linkFlags & (1u << k))) continue;
        out.reached_[size_t(j)] = 1;
        queue.push_back(size_t(j));
      }
  }
  for (uint8_t r : out.reached_) out.reachedCells_ += r;
  return out;
}

bool ReachableSpace::reachable(vec3 p) const {
  if (!enabled_) return true;
  if (!box_.contains(p)) return false;
  const ivec3 c = glm::clamp(ivec3(glm::floor((p - box_.min) / cell_)), ivec3(0), dims_ - 1);
  const int64_t own = index(c);
  if (reached_[size_t(own)] && sees(*tracer_, p, centre(c))) return true;
  for (int dz = -1; dz <= 1; ++dz)
    for (int dy = -1; dy <= 1; ++dy)
      for (int dx = -1; dx <= 1; ++dx) {
        const ivec3 q = c + ivec3(dx, dy, dz);
        const int64_t j = index(q);
        if (j >= 0 && j != own && reached_[size_t(j)] && sees(*tracer_, p, centre(q))) return true;
      }
  return false;
}

std::vector<Floor> floorsBelow(const Scene& scene, const Tracer& tracer, float x, float z,
                               float top, float bottom) {
  std::vector<Floor> out;
  float ceiling = top;
  vec3 origin(x, top, z);
  // Solids entered minus left along the ray (front faces of single-sided surfaces enter,
  // their back faces leave; never below 0, as above a room's ceiling seen from outside): an
  // upward face inside a solid (a floor under a block standing on it) is no floor.
  int depth = 0;
  for (int k = 0; k < 64 && origin.y > bottom; ++k) {
    Hit hit;
    if (!tracer.intersect(Ray{origin, vec3(0.0f, -1.0f, 0.0f), 0.0f, origin.y - bottom}, hit))
      break;
    const vec3 p = origin + vec3(0.0f, -hit.t, 0.0f);
    if (!hit.backFace && hit.geometricNormal.y >= 0.7f && depth <= 0)
      out.push_back(Floor{p, ceiling - p.y});
    if (!scene.materialOf(hit.object, hit.triangle).doubleSided)
      depth = std::max(0, depth + (hit.backFace ? -1 : 1));  // from outside into a room: 0
    ceiling = p.y;
    origin = vec3(x, p.y - 1e-4f, z);
  }
  return out;
}

std::vector<vec3> pointsAboveFloors(const Scene& scene, const Tracer& tracer,
                                    std::span<const Bounds3> volumes, float columnSpacing,
                                    float firstHeight, float headroom) {
  std::vector<vec3> out;
  Bounds3 box;
  for (const Bounds3& b : volumes) box.extend(b);
  if (box.empty() || !(columnSpacing > 0.0f)) return out;
  const vec3 e = box.extent();
  const int nx = std::clamp(int(std::lround(e.x / columnSpacing)), 1, 4096);
  const int nz = std::clamp(int(std::lround(e.z / columnSpacing)), 1, 4096);
  const float gaps[] = {0.0f, 2.0f, 3.0f, 5.0f, 10.0f};
  for (int iz = 0; iz < nz; ++iz)
    for (int ix = 0; ix < nx; ++ix) {
      const float x = box.min.x + e.x * (float(ix) + 0.5f) / float(nx);
      const float z = box.min.z + e.z * (float(iz) + 0.5f) / float(nz);
      for (const Floor& f :
           floorsBelow(scene, tracer, x, z, box.max.y + 1e-3f, box.min.y - 1e-3f)) {
        float height = firstHeight;
        for (float gap : gaps) {
          height += gap * firstHeight;
          if (height > f.clearance - headroom) break;
          const vec3 p = f.point + vec3(0.0f, height, 0.0f);
          if (insideAny(volumes, p)) out.push_back(p);
        }
      }
    }
  return out;
}

std::optional<vec3> objectPoint(const Scene& scene, const Tracer& tracer,
                                std::span<const Bounds3> volumes, vec2 uxz, float uFloor,
                                float uHeight, float minHeight, float maxHeight) {
  Bounds3 box;
  for (const Bounds3& b : volumes) box.extend(b);
  if (box.empty()) return std::nullopt;
  const float x = box.min.x + box.extent().x * uxz.x;
  const float z = box.min.z + box.extent().z * uxz.y;
  const std::vector<Floor> floors =
      floorsBelow(scene, tracer, x, z, box.max.y + 1e-3f, box.min.y - 1e-3f);
  if (floors.empty()) return std::nullopt;
  const Floor& f = floors[std::min(floors.size() - 1, size_t(uFloor * float(floors.size())))];
  const float hi = std::min(maxHeight, f.clearance - 0.1f);
  if (hi < minHeight) return std::nullopt;
  const vec3 p = f.point + vec3(0.0f, minHeight + (hi - minHeight) * uHeight, 0.0f);
  if (!insideAny(volumes, p)) return std::nullopt;
  return p;
}

}  // namespace kiln
