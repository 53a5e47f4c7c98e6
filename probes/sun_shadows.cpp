// sun_shadows.cpp: the sun layer's ramps (sun_shadows.h).
//
// A straight edge lit by a directional light casts a shadow bounded by the plane through the
// edge and the light's direction; so in a tetrahedron the light's share is, to a good
// approximation, a step across one plane that contains the direction towards the light (a
// ramp as wide as the penumbra for a soft light). The fit: classify points sampled in the
// cell by shadow rays; search the plane's normal over directions perpendicular to the light
// (the best split of the points along each); locate the edge precisely by bisection from the
// points nearest the split (in two rounds); fit the line through those edge points in the
// plane perpendicular to the light; choose the ramp's width; and keep the ramp only if at
// most kMaxWrongPoints of the 64 interior points (32 of them fresh) disagree with it and it
// is clearly closer to the light's share than the plain blend of the probes' shares. When no
// plane passes (two edges cross the cell, or a probe stands in a pocket of shade at a corner
// of a lit cell), the linear share fitted to the interior points by least squares is tried
// under the same rules: in a lit cell whose probes sit in pockets of shade it is the
// constant 1, which the plain blend (darkened by those probes' weights) is not.
#include "probes/sun_shadows.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <numeric>
#include <vector>

#include "src/distributed.h"
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
constexpr int kMaxWrongPoints = 3;       // of the 2 x kSunRampSamples interior points
constexpr float kMinSpread = 0.02f;       // edge points spread over this x the cell fix a plane
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

// Per-vertex values (a ramp's, the probes' shares) mixed by barycentric weights b.
float mixOf(const std::array<float, 4>& b, const vec4& v) {
  return b[0] * v[0] + b[1] * v[1] + b[2] * v[2] + b[3] * v[3];
}

struct Sample {
  std::array<float, 4> b;  // barycentric in the cell
  vec3 p;
  float share;  // the light's share reaching p
};

float rampValue(vec3 normal, float offset, float width, vec3 p) {
  return 0.5f + (glm::dot(normal, p) - offset) / width;
}

// One cell's fit, in named stages (see the file's comment).
class RampFit {
 public:
  RampFit(const Integrator& integrator, uint32_t light, const std::array<vec3, 4>& corners,
          const std::array<float, 4>& shares, uint64_t key)
      : integrator_(integrator), light_(light), corners_(corners), shares_(shares), key_(key) {
    s_ = -glm::normalize(integrator.scene().lights[light].direction);
    u_ = glm::normalize(std::abs(s_.x) < 0.9f ? glm::cross(s_, vec3(1, 0, 0))
                                              : glm::cross(s_, vec3(0, 1, 0)));
    v_ = glm::cross(s_, u_);
    for (int a = 0; a < 4; ++a)
      for (int b = a + 1; b < 4; ++b)
        extent_ = std::max(extent_, glm::distance(corners[size_t(a)], corners[size_t(b)]));
    probeKey_ = hashValues(key, 0x5eedu);
  }

  vec4 run() {
    const vec4 none(std::numeric_limits<float>::quiet_NaN());
    sampleCell();
    // The light's share varies neither inside the cell nor between its probes: the blend is
    // exact.
    if (!sharesDiffer()) return none;
    searchSplit();
    if (fitEdge()) {
      const vec4 candidate = rampWithBestWidth();
      if (validate(candidate)) return candidate;
    }
    // No one plane bounds the shadow in the cell (two edges, a probe in a pocket of shade at
    // a corner): the linear share that fits the interior points best, kept by the same rules.
    const vec4 flat = leastSquaresRamp();
    return !std::isnan(flat.x) && validate(flat) ? flat : none;
  }

 private:
  float share(vec3 q, uint64_t key) const { return sunShare(integrator_, light_, q, key); }

  std::vector<Sample> draw(uint32_t first) const {
    std::vector<Sample> out(kSunRampSamples);
    for (uint32_t j = 0; j < kSunRampSamples; ++j) {
      SampleStream stream(key_, first + j);
      out[j].b = uniformBarycentric(stream);
      out[j].p = pointOf(corners_, out[j].b);
      out[j].share = share(out[j].p, hashValues(key_, first + j));
    }
    return out;
  }

  // The interior points, then the four probes with their shares (which the SH holds: the
  // mean over a footprint for a probe baked over one).
  void sampleCell() {
    train_ = draw(0);
    for (int k = 0; k < 4; ++k) {
      Sample vertex{{0.0f, 0.0f, 0.0f, 0.0f}, corners_[size_t(k)], shares_[size_t(k)]};
      vertex.b[size_t(k)] = 1.0f;
      train_.push_back(vertex);
    }
  }

  bool sharesDiffer() const {
    float lo = 1.0f, hi = 0.0f;
    for (const Sample& x : train_) {
      lo = std::min(lo, x.share);
      hi = std::max(hi, x.share);
    }
    return hi - lo >= 0.02f;
  }

  // The best split of the points along each normal perpendicular to the light: normal_ and
  // offset_ (lit where dot(normal_, p) > offset_).
  void searchSplit() {
    float bestCost = std::numeric_limits<float>::max();
    std::vector<uint32_t> order(train_.size());
    std::vector<float> t(train_.size());
    float total = 0.0f;
    for (const Sample& x : train_) total += x.share;
    for (uint32_t d = 0; d < kDirections; ++d) {
      const float angle = float(kPi) * float(d) / float(kDirections);
      const vec3 n = std::cos(angle) * u_ + std::sin(angle) * v_;
      for (size_t j = 0; j < train_.size(); ++j) t[j] = glm::dot(n, train_[j].p);
      std::iota(order.begin(), order.end(), 0u);
      std::sort(order.begin(), order.end(), [&](uint32_t a, uint32_t b) { return t[a] < t[b]; });
      // The cost of the split after sorted position i, lit above it, and its mirror.
      float litBelow = 0.0f;
      for (size_t i = 0; i + 1 < order.size(); ++i) {
        litBelow += train_[order[i]].share;
        const float below = float(i + 1), above = float(order.size() - i - 1);
        const float litAbove = total - litBelow;
        const float up = litBelow + (above - litAbove);
        const float down = (below - litBelow) + litAbove;
        const float threshold = 0.5f * (t[order[i]] + t[order[i + 1]]);
        if (up < bestCost) {
          bestCost = up;
          offset_ = threshold;
          normal_ = n;
        }
        if (down < bestCost) {
          bestCost = down;
          offset_ = -threshold;
          normal_ = -n;
        }
      }
    }
  }

  // Bisects the segment a-b when its ends differ (lit or not) and appends the edge point.
  void bisect(vec3 a, vec3 b) {
    const bool litA = share(a, probeKey_++) > 0.5f;
    if (litA == (share(b, probeKey_++) > 0.5f)) return;
    for (int k = 0; k < kBisections; ++k) {
      const vec3 mid = 0.5f * (a + b);
      ((share(mid, probeKey_++) > 0.5f) == litA ? a : b) = mid;
    }
    edge_.push_back(0.5f * (a + b));
  }

  float distanceToPlane(uint32_t j) const {
    return std::abs(glm::dot(normal_, train_[j].p) - offset_);
  }

  // Second moments of the edge points' coordinates across the light (in the plane
  // perpendicular to it), about their mean.
  struct EdgeMoments {
    float xx = 0.0f, xy = 0.0f, yy = 0.0f;
  };
  EdgeMoments edgeMoments() const {
    glm::vec2 mean(0.0f);
    for (const vec3& e : edge_) mean += glm::vec2(glm::dot(u_, e), glm::dot(v_, e));
    mean /= float(std::max<size_t>(edge_.size(), 1));
    EdgeMoments m;
    for (const vec3& e : edge_) {
      const glm::vec2 d = glm::vec2(glm::dot(u_, e), glm::dot(v_, e)) - mean;
      m.xx += d.x * d.x;
      m.xy += d.x * d.y;
      m.yy += d.y * d.y;
    }
    return m;
  }

  // Whether the edge points spread (RMS, across the light) over more than kMinSpread of the
  // cell: enough to fix the plane's direction.
  bool spreadFixesDirection(const EdgeMoments& m) const {
    const float minSpread = kMinSpread * extent_;
    return m.xx + m.yy > minSpread * minSpread * float(edge_.size());
  }

  // Points on the edge from the current plane: bisection from the shaded points nearest it,
  // each along the normal to a point a tenth of the cell beyond it (or, failing that,
  // towards the nearest lit point). Points found from one lit point (a lit corner of the
  // cell) lie on one line along the light and fix no direction: then the edge is also sought
  // from the point of each class nearest the plane, along 8 directions across the light.
  void findEdgePoints() {
    std::vector<uint32_t> shaded, lit;
    for (uint32_t j = 0; j < train_.size(); ++j)
      (train_[j].share > 0.5f ? lit : shaded).push_back(j);
    std::sort(shaded.begin(), shaded.end(),
              [&](uint32_t a, uint32_t b) { return distanceToPlane(a) < distanceToPlane(b); });
    const size_t before = edge_.size();
    for (uint32_t i = 0; i < shaded.size() && edge_.size() < before + kEdgePoints; ++i) {
      const vec3 p = train_[shaded[i]].p;
      bisect(p, p + (offset_ - glm::dot(normal_, p) + 0.1f * extent_) * normal_);
    }
    for (uint32_t i = 0; i < shaded.size() && !lit.empty() && edge_.size() < before + 3; ++i) {
      const vec3 p = train_[shaded[i]].p;
      uint32_t nearest = lit[0];
      for (uint32_t j : lit)
        if (glm::distance(train_[j].p, p) < glm::distance(train_[nearest].p, p)) nearest = j;
      bisect(p, train_[nearest].p);
    }
    if (spreadFixesDirection(edgeMoments())) return;
    for (const std::vector<uint32_t>* side : {&lit, &shaded}) {
      if (side->empty()) continue;
      const uint32_t nearest = *std::min_element(
          side->begin(), side->end(),
          [&](uint32_t a, uint32_t b) { return distanceToPlane(a) < distanceToPlane(b); });
      for (int k = 0; k < 8; ++k) {
        const float phi = float(kPi) * 0.25f * float(k);
        bisect(train_[nearest].p,
               train_[nearest].p + extent_ * (std::cos(phi) * u_ + std::sin(phi) * v_));
      }
    }
  }

  // The plane through the edge points, containing the light's direction: the principal axis
  // of their coordinates across the light gives its direction (when they spread over more
  // than kMinSpread of the cell; else the current normal is kept), their mean its offset,
  // and the points' shares its lit side (the search's sign is a guess when many splits tie).
  void fitPlane() {
    const EdgeMoments m = edgeMoments();
    if (spreadFixesDirection(m)) {
      const float axis = 0.5f * std::atan2(2.0f * m.xy, m.xx - m.yy);
      const vec3 along = std::cos(axis) * u_ + std::sin(axis) * v_;
      const vec3 fitted = glm::normalize(glm::cross(s_, along));
      normal_ = glm::dot(fitted, normal_) < 0.0f ? -fitted : fitted;
    }
    offset_ = 0.0f;
    for (const vec3& e : edge_) offset_ += glm::dot(normal_, e);
    offset_ /= float(edge_.size());
    float agreement = 0.0f;
    for (const Sample& x : train_)
      agreement += (x.share - 0.5f) * (glm::dot(normal_, x.p) - offset_);
    if (agreement < 0.0f) {
      normal_ = -normal_;
      offset_ = -offset_;
    }
  }

  // Two rounds of edge points and plane, the second from the first's plane (every point
  // found lies on the edge, so all are kept). False when no edge point was found.
  bool fitEdge() {
    for (int round = 0; round < 2; ++round) {
      findEdgePoints();
      if (edge_.empty()) return false;
      fitPlane();
    }
    return true;
  }

  // The linear function of the barycentric coordinates closest (least squares) to the
  // interior points' shares, fitted again without the points it misses by more than
  // kMaxPointError (a few points in a pocket of shade would otherwise tilt it across the
  // whole cell; validation still counts them): its values at the four vertices, or NaN. The
  // probes' own shares are left out: they are what the plain blend already uses.
  vec4 leastSquaresRamp() const {
    const vec4 none(std::numeric_limits<float>::quiet_NaN());
    std::vector<uint8_t> use(kSunRampSamples, 1);
    vec4 ramp = none;
    for (int round = 0; round < 2; ++round) {
      glm::dmat4 a(0.0);
      glm::dvec4 y(0.0);
      for (size_t j = 0; j < kSunRampSamples; ++j) {
        if (!use[j]) continue;
        const glm::dvec4 b(train_[j].b[0], train_[j].b[1], train_[j].b[2], train_[j].b[3]);
        a += glm::outerProduct(b, b);
        y += b * double(train_[j].share);
      }
      // Points near one face only (a few left) leave the fit undetermined.
      if (!(std::abs(glm::determinant(a)) > 1e-9)) return round == 0 ? none : ramp;
      ramp = vec4(glm::inverse(a) * y);
      for (size_t j = 0; j < kSunRampSamples; ++j) {
        const float r = std::clamp(mixOf(train_[j].b, ramp), 0.0f, 1.0f);
        use[j] = std::abs(r - train_[j].share) <= kMaxPointError;
      }
    }
    return ramp;
  }

  // The ramp across the plane with the width of kWidths that fits the points best (a hard
  // shadow takes the narrowest, a penumbra a wider one): its values at the four vertices.
  vec4 rampWithBestWidth() const {
    float width = kWidths[0], widthCost = std::numeric_limits<float>::max();
    // A hard shadow has no penumbra: only the narrowest ramp (a wider one would pass for
    // light and shade finer than itself, such as stripes).
    const bool hard = !(integrator_.scene().lights[light_].shadowAngle > 0.0f);
    for (float w : kWidths) {
      if (hard && w > kWidths[0]) break;
      float c = 0.0f;
      for (const Sample& x : train_)
        c += std::abs(std::clamp(rampValue(normal_, offset_, w, x.p), 0.0f, 1.0f) - x.share);
      if (c < widthCost) {
        widthCost = c;
        width = w;
      }
    }
    vec4 ramp;
    for (int k = 0; k < 4; ++k) ramp[k] = rampValue(normal_, offset_, width, corners_[size_t(k)]);
    return ramp;
  }

  // Kept only if right at every interior point, the training ones and fresh ones (a ramp
  // wrong in part of the cell, such as a corner where a second edge cuts it, would light or
  // shade an object there fully wrong), and clearly closer to the light's share than the
  // plain blend at the fresh ones. A point inside the ramp's band (its value strictly
  // between 0 and 1) is judged more loosely: its share depends on where in the penumbra it
  // stands. The fresh points are drawn once per cell: a plane ramp and the least-squares
  // one are judged at the same points.
  bool validate(const vec4& ramp) {
    auto rampAt = [&](const Sample& x) { return std::clamp(mixOf(x.b, ramp), 0.0f, 1.0f); };
    auto wrong = [&](const Sample& x) {
      const float r = rampAt(x);
      const bool inBand = r > 0.0f && r < 1.0f;
      return std::abs(r - x.share) > (inBand ? 2.0f * kMaxPointError : kMaxPointError);
    };
    int wrongPoints = 0;
    for (size_t j = 0; j < kSunRampSamples; ++j)  // the interior points (not the probes)
      wrongPoints += wrong(train_[j]) ? 1 : 0;
    float rampError = 0.0f, blendError = 0.0f;
    if (fresh_.empty()) fresh_ = draw(kSunRampSamples);
    const vec4 probeShares(shares_[0], shares_[1], shares_[2], shares_[3]);
    for (const Sample& x : fresh_) {
      wrongPoints += wrong(x) ? 1 : 0;
      if (wrongPoints > kMaxWrongPoints) return false;
      const float plain = mixOf(x.b, probeShares);
      rampError += std::abs(rampAt(x) - x.share);
      blendError += std::abs(plain - x.share);
    }
    return rampError < kKeepRatio * blendError;
  }

  const Integrator& integrator_;
  uint32_t light_;
  const std::array<vec3, 4>& corners_;
  const std::array<float, 4>& shares_;
  uint64_t key_;
  vec3 s_, u_, v_;       // towards the light; two unit vectors across it
  float extent_ = 0.0f;  // the cell's longest edge
  uint64_t probeKey_;    // keys the bisections' shadow rays
  std::vector<Sample> train_;
  std::vector<Sample> fresh_;  // validation's fresh interior points, once drawn
  vec3 normal_{0.0f};
  float offset_ = 0.0f;
  std::vector<vec3> edge_;
};

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
  return RampFit(integrator, light, corners, shares, key).run();
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
  // Distributed bakes (src/distributed.h): cells dealt across the ranks, every rank gets
  // every ramp (each cell's key is its index, so the ramps are those of one process).
  const WorkSplit split = splitWork(cells, 1);
  if (progress) progress->splitAcrossRanks();
  const bool done = parallelForLocal(
      split,
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
  const bool ok = done && !(cancel && cancel->load());
  return bool(exchangeItems(split, set.sun.ramps, 1, true, ok, !ok, progress)) && ok;
}

}  // namespace kiln
