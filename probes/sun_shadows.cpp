// sun_shadows.cpp: the sun layer's ramps (sun_shadows.h).
//
// A straight edge lit by a directional light casts a shadow bounded by the plane through the
// edge and the light's direction; so in a tetrahedron the light's share is, to a good
// approximation, a step across one plane that contains the direction towards the light (a
// ramp as wide as the penumbra for a soft light). The fit: classify points sampled in the
// cell by shadow rays; search the plane's normal over directions perpendicular to the light
// (the best split of the points along each); locate the edge precisely by bisection from the
// points nearest the split; fit the line through those edge points in the plane
// perpendicular to the light; choose the ramp's width; and keep the ramp only if, at fresh
// points, it is clearly closer to the light's share than the plain blend of the probes'.
#include "probes/sun_shadows.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <numeric>
#include <vector>

#include "src/math.h"
#include "src/parallel.h"
#include "src/sampling.h"

namespace kiln {
namespace {

using glm::vec3;
using glm::vec4;

constexpr uint32_t kDirections = 36;      // plane normals searched, 5 degrees apart
constexpr uint32_t kEdgePoints = 6;       // bisections locating the edge
constexpr int kBisections = 14;           // each: the edge to 1/16384 of its bracket
constexpr float kKeepRatio = 0.8f;        // the ramp's error at most this x the plain blend's
constexpr std::array<float, 7> kWidths = {0.01f, 0.02f, 0.05f, 0.1f, 0.2f, 0.5f, 1.0f};

// Uniform point of the tetrahedron: barycentric weights from four exponentials (a flat
// Dirichlet distribution).
std::array<float, 4> uniformBarycentric(SampleStream& stream) {
  std::array<float, 4> b{};
  float sum = 0.0f;
  for (float& x : b) {
    x = -std::log(std::max(1.0f - stream.get1D(), 1e-12f));
    sum += x;
  }
  for (float& x : b) x /= sum;
  return b;
}

vec3 pointOf(const std::array<vec3, 4>& c, const std::array<float, 4>& b) {
  return b[0] * c[0] + b[1] * c[1] + b[2] * c[2] + b[3] * c[3];
}

struct Sample {
  std::array<float, 4> b;
  vec3 p;
  float share;
};

float rampValue(vec3 normal, float offset, float width, vec3 p) {
  return 0.5f + (glm::dot(normal, p) - offset) / width;
}

}  // namespace

int32_t sunLayerLight(const Scene& scene, const IntegratorSettings& settings) {
  int32_t best = -1;
  float bestIrradiance = 0.0f;
  for (size_t l = 0; l < scene.lights.size(); ++l) {
    const Light& light = scene.lights[l];
    if (light.type != LightType::Directional) continue;
    if (l >= settings.directLights.size() || !settings.directLights[l]) continue;
    if (!light.bakedShadows) continue;  // no shadow to sharpen
    const float e = luminance(light.color * light.intensity);
    if (e > bestIrradiance) {
      bestIrradiance = e;
      best = int32_t(l);
    }
  }
  return best;
}

float sunShare(const Integrator& integrator, uint32_t light, vec3 q, uint64_t key) {
  const float v = luminance(integrator.lightVisibility(q, vec3(0.0f), light, key, 0));
  return std::clamp(v, 0.0f, 1.0f);
}

vec4 fitSunRamp(const Integrator& integrator, uint32_t light, const std::array<vec3, 4>& corners,
                const std::array<float, 4>& shares, uint64_t key) {
  const vec4 none(std::numeric_limits<float>::quiet_NaN());
  const Light& sun = integrator.scene().lights[light];
  const vec3 s = -glm::normalize(sun.direction);
  const vec3 u = glm::normalize(std::abs(s.x) < 0.9f ? glm::cross(s, vec3(1, 0, 0))
                                                     : glm::cross(s, vec3(0, 1, 0)));
  const vec3 v = glm::cross(s, u);
  auto share = [&](vec3 q, uint64_t sampleKey) {
    return sunShare(integrator, light, q, sampleKey);
  };
  auto draw = [&](uint32_t first) {
    std::vector<Sample> out(kSunRampSamples);
    for (uint32_t j = 0; j < kSunRampSamples; ++j) {
      SampleStream stream(key, first + j);
      out[j].b = uniformBarycentric(stream);
      out[j].p = pointOf(corners, out[j].b);
      out[j].share = share(out[j].p, hashValues(key, first + j));
    }
    return out;
  };
  const std::vector<Sample> train = draw(0);
  float lo = 1.0f, hi = 0.0f;
  for (const Sample& x : train) {
    lo = std::min(lo, x.share);
    hi = std::max(hi, x.share);
  }
  const float shareLo = std::min({shares[0], shares[1], shares[2], shares[3]});
  const float shareHi = std::max({shares[0], shares[1], shares[2], shares[3]});
  // The light's share does not vary in the cell, nor do the probes': the blend is exact.
  if (hi - lo < 0.02f && shareHi - shareLo < 0.02f) return none;

  vec4 candidate;
  if (hi - lo < 0.02f) {
    // Constant inside, though the probes differ (an edge through a corner of the cell).
    const float m = 0.5f * (lo + hi);
    candidate = vec4(m);
  } else {
    // The best split along each normal perpendicular to the light.
    float bestCost = std::numeric_limits<float>::max(), bestThreshold = 0.0f;
    vec3 bestNormal = u;
    std::vector<uint32_t> order(train.size());
    std::vector<float> t(train.size());
    for (uint32_t d = 0; d < kDirections; ++d) {
      const float angle = float(kPi) * float(d) / float(kDirections);
      const vec3 n = std::cos(angle) * u + std::sin(angle) * v;
      for (size_t j = 0; j < train.size(); ++j) t[j] = glm::dot(n, train[j].p);
      std::iota(order.begin(), order.end(), 0u);
      std::sort(order.begin(), order.end(), [&](uint32_t a, uint32_t b) { return t[a] < t[b]; });
      // Cost of "shaded below, lit above" split after sorted position i, and its mirror.
      float litBelow = 0.0f, total = 0.0f;
      for (const Sample& x : train) total += x.share;
      for (size_t i = 0; i + 1 < order.size(); ++i) {
        litBelow += train[order[i]].share;
        const float below = float(i + 1), above = float(order.size() - i - 1);
        const float litAbove = total - litBelow;
        const float up = litBelow + (above - litAbove);    // lit above
        const float down = (below - litBelow) + litAbove;  // lit below
        const float threshold = 0.5f * (t[order[i]] + t[order[i + 1]]);
        if (up < bestCost) {
          bestCost = up;
          bestThreshold = threshold;
          bestNormal = n;
        }
        if (down < bestCost) {
          bestCost = down;
          bestThreshold = -threshold;
          bestNormal = -n;
        }
      }
    }
    // The edge located by bisection along the normal, from the points nearest the split.
    float tMin = std::numeric_limits<float>::max(), tMax = -tMin;
    for (const Sample& x : train) {
      tMin = std::min(tMin, glm::dot(bestNormal, x.p));
      tMax = std::max(tMax, glm::dot(bestNormal, x.p));
    }
    const float bracket = 0.25f * (tMax - tMin);
    std::vector<uint32_t> nearest(train.size());
    std::iota(nearest.begin(), nearest.end(), 0u);
    std::sort(nearest.begin(), nearest.end(), [&](uint32_t a, uint32_t b) {
      const float da = std::abs(glm::dot(bestNormal, train[a].p) - bestThreshold);
      const float db = std::abs(glm::dot(bestNormal, train[b].p) - bestThreshold);
      return da < db;
    });
    std::vector<vec3> edge;
    uint64_t probeKey = hashValues(key, 0x5eedu);
    for (uint32_t i = 0; i < nearest.size() && edge.size() < kEdgePoints; ++i) {
      const vec3 p = train[nearest[i]].p;
      const vec3 q0 = p + (bestThreshold - glm::dot(bestNormal, p)) * bestNormal;
      vec3 shaded = q0 - bracket * bestNormal, lit = q0 + bracket * bestNormal;
      if (share(shaded, probeKey++) > 0.5f || share(lit, probeKey++) < 0.5f) continue;
      for (int k = 0; k < kBisections; ++k) {
        const vec3 mid = 0.5f * (shaded + lit);
        (share(mid, probeKey++) > 0.5f ? lit : shaded) = mid;
      }
      edge.push_back(0.5f * (shaded + lit));
    }
    if (edge.empty()) return none;
    vec3 normal = bestNormal;
    if (edge.size() >= 2) {
      // The line through the edge points in the plane perpendicular to the light: the
      // principal axis of their (u, v) coordinates; its perpendicular is the normal.
      glm::vec2 mean(0.0f);
      for (const vec3& e : edge) mean += glm::vec2(glm::dot(u, e), glm::dot(v, e));
      mean /= float(edge.size());
      float sxx = 0.0f, sxy = 0.0f, syy = 0.0f;
      for (const vec3& e : edge) {
        const glm::vec2 d = glm::vec2(glm::dot(u, e), glm::dot(v, e)) - mean;
        sxx += d.x * d.x;
        sxy += d.x * d.y;
        syy += d.y * d.y;
      }
      const float axis = 0.5f * std::atan2(2.0f * sxy, sxx - syy);  // the principal direction
      const vec3 along = std::cos(axis) * u + std::sin(axis) * v;
      normal = glm::normalize(glm::cross(s, along));
      if (glm::dot(normal, bestNormal) < 0.0f) normal = -normal;  // lit side positive
    }
    float offset = 0.0f;
    for (const vec3& e : edge) offset += glm::dot(normal, e);
    offset /= float(edge.size());
    // The ramp's width: the one of kWidths that fits the training points best (a hard
    // shadow takes the narrowest; a penumbra a wider one).
    float width = kWidths[0], widthCost = std::numeric_limits<float>::max();
    for (float w : kWidths) {
      float c = 0.0f;
      for (const Sample& x : train)
        c += std::abs(std::clamp(rampValue(normal, offset, w, x.p), 0.0f, 1.0f) - x.share);
      if (c < widthCost) {
        widthCost = c;
        width = w;
      }
    }
    for (int k = 0; k < 4; ++k) candidate[k] = rampValue(normal, offset, width, corners[k]);
  }
  // Kept only if clearly closer to the light's share than the plain blend, at fresh points.
  const std::vector<Sample> check = draw(kSunRampSamples);
  float rampError = 0.0f, blendError = 0.0f;
  for (const Sample& x : check) {
    const float r = x.b[0] * candidate.x + x.b[1] * candidate.y + x.b[2] * candidate.z +
                    x.b[3] * candidate.w;
    const float plain = x.b[0] * shares[0] + x.b[1] * shares[1] + x.b[2] * shares[2] +
                        x.b[3] * shares[3];
    rampError += std::abs(std::clamp(r, 0.0f, 1.0f) - x.share);
    blendError += std::abs(plain - x.share);
  }
  return rampError < kKeepRatio * blendError ? candidate : none;
}

bool bakeSunRamps(const Integrator& integrator, ProbeSet& set, uint64_t seed, int threads,
                  Progress* progress, const std::atomic<bool>* cancel) {
  set.sun.ramps.clear();
  if (set.sun.empty() || set.dimension != 3) return true;
  const size_t cells = size_t(set.innerCellCount);
  set.sun.ramps.assign(cells, vec4(std::numeric_limits<float>::quiet_NaN()));
  ParallelOptions options;
  options.threads = threads;
  options.grain = 16;
  options.progress = progress;
  options.cancel = cancel;
  return parallelFor(
      cells,
      [&](size_t begin, size_t end) {
        for (size_t c = begin; c < end; ++c) {
          const glm::ivec4 cell = set.cells[c];
          std::array<vec3, 4> corners;
          std::array<float, 4> shares;
          for (int k = 0; k < 4; ++k) {
            corners[size_t(k)] = set.positions[size_t(cell[k])];
            shares[size_t(k)] = set.sun.visibility[size_t(cell[k])];
          }
          set.sun.ramps[c] = fitSunRamp(integrator, uint32_t(set.sun.light), corners, shares,
                                        hashValues(seed, uint64_t(c)));
        }
      },
      options);
}

}  // namespace kiln
