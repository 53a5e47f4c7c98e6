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
constexpr float kMaxPointError = 0.25f;   // the ramp's error at any sampled point, at most
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
  // The interior points, then the four probes with their shares (which the SH holds: the
  // mean over a footprint for a probe baked over one).
  std::vector<Sample> train = draw(0);
  for (int k = 0; k < 4; ++k) {
    Sample vertex{{0.0f, 0.0f, 0.0f, 0.0f}, corners[size_t(k)], shares[size_t(k)]};
    vertex.b[size_t(k)] = 1.0f;
    train.push_back(vertex);
  }
  float lo = 1.0f, hi = 0.0f;
  for (const Sample& x : train) {
    lo = std::min(lo, x.share);
    hi = std::max(hi, x.share);
  }
  // The light's share varies neither inside the cell nor between its probes: the blend is
  // exact.
  if (hi - lo < 0.02f) return none;

  vec4 candidate;
  {
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
    // The edge, in two rounds: points on it located by bisection from the shaded points
    // nearest the current plane, each along its normal to a point a tenth of the cell beyond
    // it (or, failing that, towards the nearest lit point), then the plane through them. The
    // shaded points spread over the cell, so the edge points do too and fix the plane's
    // direction; the second round starts from the first's plane (the search's normal can be
    // far off when few points are lit: many splits then cost nothing).
    float extent = 0.0f;
    for (int a = 0; a < 4; ++a)
      for (int b = a + 1; b < 4; ++b)
        extent = std::max(extent, glm::distance(corners[size_t(a)], corners[size_t(b)]));
    uint64_t probeKey = hashValues(key, 0x5eedu);
    // Bisects the segment a-b when its ends differ (lit or not) and appends the edge point.
    auto bisect = [&](vec3 a, vec3 b, std::vector<vec3>& edge) {
      const bool litA = share(a, probeKey++) > 0.5f;
      if (litA == (share(b, probeKey++) > 0.5f)) return;
      for (int k = 0; k < kBisections; ++k) {
        const vec3 mid = 0.5f * (a + b);
        ((share(mid, probeKey++) > 0.5f) == litA ? a : b) = mid;
      }
      edge.push_back(0.5f * (a + b));
    };
    vec3 normal = bestNormal;
    float offset = bestThreshold;
    std::vector<vec3> edge;  // every point found is on the edge: kept over the rounds
    for (int round = 0; round < 2; ++round) {
      std::vector<uint32_t> shaded, lit;
      for (uint32_t j = 0; j < train.size(); ++j) (train[j].share > 0.5f ? lit : shaded).push_back(j);
      std::sort(shaded.begin(), shaded.end(), [&](uint32_t a, uint32_t b) {
        return std::abs(glm::dot(normal, train[a].p) - offset) <
               std::abs(glm::dot(normal, train[b].p) - offset);
      });
      const size_t before = edge.size();
      for (uint32_t i = 0; i < shaded.size() && edge.size() < before + kEdgePoints; ++i) {
        const vec3 p = train[shaded[i]].p;
        bisect(p, p + (offset - glm::dot(normal, p) + 0.1f * extent) * normal, edge);
      }
      for (uint32_t i = 0; i < shaded.size() && edge.size() < before + 3; ++i) {
        const vec3 p = train[shaded[i]].p;
        uint32_t nearest = lit.empty() ? shaded[i] : lit[0];
        for (uint32_t j : lit)
          if (glm::distance(train[j].p, p) < glm::distance(train[nearest].p, p)) nearest = j;
        bisect(p, train[nearest].p, edge);
      }
      // Points found from one lit point (a lit corner of the cell) lie on one line along the
      // light and fix no direction: then the edge is also sought from the points of each
      // class nearest the plane, along 8 directions perpendicular to the light.
      auto spread = [&] {
        glm::vec2 m(0.0f);
        for (const vec3& e : edge) m += glm::vec2(glm::dot(u, e), glm::dot(v, e));
        m /= float(std::max<size_t>(edge.size(), 1));
        float sum = 0.0f;
        for (const vec3& e : edge) {
          const glm::vec2 d = glm::vec2(glm::dot(u, e), glm::dot(v, e)) - m;
          sum += glm::dot(d, d);
        }
        return std::sqrt(sum / float(std::max<size_t>(edge.size(), 1)));
      };
      if (spread() <= 0.02f * extent) {
        for (const std::vector<uint32_t>* side : {&lit, &shaded}) {
          uint32_t nearest = uint32_t(-1);
          for (uint32_t j : *side)
            if (nearest == uint32_t(-1) ||
                std::abs(glm::dot(normal, train[j].p) - offset) <
                    std::abs(glm::dot(normal, train[nearest].p) - offset))
              nearest = j;
          if (nearest == uint32_t(-1)) continue;
          for (int k = 0; k < 8; ++k) {
            const float phi = float(kPi) * 0.25f * float(k);
            const vec3 d = std::cos(phi) * u + std::sin(phi) * v;
            bisect(train[nearest].p, train[nearest].p + extent * d, edge);
          }
        }
      }
      if (edge.empty()) return none;
      // The line through the edge points in the plane perpendicular to the light (the
      // principal axis of their (u, v) coordinates; its perpendicular is the normal) when
      // they spread over more than 2% of the cell, else the current normal.
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
      const float minSpread = 0.02f * extent;
      if (sxx + syy > minSpread * minSpread * float(edge.size())) {
        const float axis = 0.5f * std::atan2(2.0f * sxy, sxx - syy);
        const vec3 along = std::cos(axis) * u + std::sin(axis) * v;
        const vec3 fitted = glm::normalize(glm::cross(s, along));
        normal = glm::dot(fitted, normal) < 0.0f ? -fitted : fitted;  // lit side positive
      }
      offset = 0.0f;
      for (const vec3& e : edge) offset += glm::dot(normal, e);
      offset /= float(edge.size());
      // Lit side positive, as the points say (the search's sign is a guess when many splits
      // tie).
      float agreement = 0.0f;
      for (const Sample& x : train) agreement += (x.share - 0.5f) * (glm::dot(normal, x.p) - offset);
      if (agreement < 0.0f) {
        normal = -normal;
        offset = -offset;
      }
    }
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
  // Kept only if it is right at every point, the training ones and fresh ones (a ramp wrong
  // in part of the cell, such as a corner where a second edge cuts it, would light or shade
  // an object there fully wrong), and clearly closer to the light's share than the plain
  // blend at the fresh ones.
  auto rampAt = [&](const Sample& x) {
    const float r = x.b[0] * candidate.x + x.b[1] * candidate.y + x.b[2] * candidate.z +
                    x.b[3] * candidate.w;
    return std::clamp(r, 0.0f, 1.0f);
  };
  // A point inside the ramp's band (its value strictly between 0 and 1) is not judged: its
  // share there depends on where in the penumbra it stands.
  auto wrong = [&](const Sample& x) {
    const float r = rampAt(x);
    return (r == 0.0f || r == 1.0f) && std::abs(r - x.share) > kMaxPointError;
  };
  for (size_t j = 0; j < kSunRampSamples; ++j)  // the interior points (not the probes)
    if (wrong(train[j])) return none;
  const std::vector<Sample> check = draw(kSunRampSamples);
  float rampError = 0.0f, blendError = 0.0f;
  for (const Sample& x : check) {
    const float plain = x.b[0] * shares[0] + x.b[1] * shares[1] + x.b[2] * shares[2] +
                        x.b[3] * shares[3];
    if (wrong(x)) return none;
    const float e = std::abs(rampAt(x) - x.share);
    rampError += e;
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
