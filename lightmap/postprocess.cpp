// postprocess.cpp: dilation, filling of invalid texels, and the edge-aware à-trous denoiser
// (Dammertz et al. 2010) for lightmap pages.
//
// Every pass reads one buffer and writes another, and each texel's result is a function of
// the input buffer alone, so rows can run in parallel and results never depend on threads.
#include "lightmap/postprocess.h"

#include <algorithm>
#include <array>
#include <cassert>
#include <cmath>

#include "src/sampling.h"

namespace kiln {

namespace {

constexpr int kDx[8] = {-1, 0, 1, -1, 1, -1, 0, 1};
constexpr int kDy[8] = {-1, -1, -1, 0, 0, 1, 1, 1};

ParallelOptions rowOptions(const ParallelOptions& p) {
  ParallelOptions r = p;
  r.grain = 4;  // rows
  r.progress = nullptr;
  return r;
}

// One ring of dilation from `in` into `image` / `out`. A texel joins when it is not set, at
// least one 8-neighbour is set and, when `objectId` is given, belongs to `objectId`'s object
// (neighbours too). Returns the number of texels filled.
size_t dilateRing(Image& image, const std::vector<uint8_t>& in, std::vector<uint8_t>& out,
                  const std::vector<int32_t>* objectId, const ParallelOptions& parallel) {
  const int w = image.width, h = image.height, c = image.channels;
  out = in;
  std::vector<uint32_t> rowCounts(size_t(h), 0);
  parallelFor(
      size_t(h),
      [&](size_t begin, size_t end) {
        std::vector<double> sum(static_cast<size_t>(c));
        for (size_t yy = begin; yy < end; ++yy) {
          const int y = int(yy);
          for (int x = 0; x < w; ++x) {
            const size_t i = size_t(y) * w + x;
            if (in[i]) continue;
            const int32_t id = objectId ? (*objectId)[i] : 0;
            if (objectId && id < 0) continue;
            std::fill(sum.begin(), sum.end(), 0.0);
            int n = 0;
            for (int k = 0; k < 8; ++k) {
              const int nx = x + kDx[k], ny = y + kDy[k];
              if (nx < 0 || ny < 0 || nx >= w || ny >= h) continue;
              const size_t j = size_t(ny) * w + nx;
              if (!in[j] || (objectId && (*objectId)[j] != id)) continue;
              // Reads texels set in `in` only; this ring writes texels unset in `in`.
              const float* q = image.at(nx, ny);
              for (int ch = 0; ch < c; ++ch) sum[size_t(ch)] += q[ch];
              ++n;
            }
            if (n == 0) continue;
            float* p = image.at(x, y);
            for (int ch = 0; ch < c; ++ch) p[ch] = float(sum[size_t(ch)] / n);
            out[i] = 1;
            ++rowCounts[yy];
          }
        }
      },
      rowOptions(parallel));
  size_t filled = 0;
  for (uint32_t r : rowCounts) filled += r;
  return filled;
}

float texelLuminance(const Image& img, int x, int y) {
  const float* p = img.at(x, y);
  return img.channels >= 3 ? luminance(vec3(p[0], p[1], p[2])) : p[0];
}

// Texel i's object on `page` (< 0: none; 0 for every texel of a page without ids), and how
// many objects the page's ids name (at least 1): the per-object sums' sizes.
int32_t texelObject(const LightmapPage& page, size_t i) {
  return page.objectId.empty() ? 0 : page.objectId[i];
}
int32_t objectCount(const LightmapPage& page) {
  int32_t objects = 1;
  for (int32_t id : page.objectId) objects = std::max(objects, id + 1);
  return objects;
}

// Squared difference of two texels summed over the colour channels (the first three).
float colourDistance2(const Image& a, const Image& b, size_t i) {
  const int c = std::min(a.channels, 3);
  float sum = 0.0f;
  for (int ch = 0; ch < c; ++ch) {
    const float d = a.pixels[i * size_t(a.channels) + size_t(ch)] -
                    b.pixels[i * size_t(b.channels) + size_t(ch)];
    sum += d * d;
  }
  return sum;
}

// The variance of a texel's colour (summed over the channels) per unit variance of its
// luminance, when the channels' noise is proportional to their values (one path's light
// scales all three): sum_c x_c^2 / l^2 of the texel's colour x with luminance l.
// In double: faint light (a texel of 1e-27, which the filter makes of a black texel moved
// below 0 by the divergence's perturbation) squares to 0 in float, and 0 / 0 was NaN.
float colourVarianceFactor(const Image& img, size_t i) {
  if (img.channels < 3) return 1.0f;
  const float* p = img.pixels.data() + i * size_t(img.channels);
  const double l = luminance(vec3(p[0], p[1], p[2]));
  if (!(l > 0.0)) return 1.0f;
  const double r = p[0], g = p[1], b = p[2];
  return float((r * r + g * g + b * b) / (l * l));
}

vec3 texel3(const Image& img, int x, int y) {
  const float* p = img.at(x, y);
  return vec3(p[0], p[1], p[2]);
}

// 1 / Phi^-1(3/4): the MAD of Gaussian noise times this is its standard deviation.
constexpr float kMadToSigma = 1.4826f;

// Median of v[0, n) (reorders v): the mean of the two middle values for even n.
float median(float* v, int n) {
  std::sort(v, v + n);
  return n % 2 ? v[n / 2] : 0.5f * (v[n / 2 - 1] + v[n / 2]);
}

// The 1D B3-spline kernel of Dammertz et al. (the à-trous "h" filter).
constexpr float kB3[5] = {1.0f / 16.0f, 1.0f / 4.0f, 3.0f / 8.0f, 1.0f / 4.0f, 1.0f / 16.0f};

// Everything the edge-stopping functions need, shared by the noise estimate and the passes.
struct Guides {
  const LightmapPage& page;
  const DenoiseSettings& s;
  std::vector<float> texelSize;  // h per texel (metres), 0 when there is no position buffer

  bool hasNormal() const { return !page.normal.empty(); }
  bool hasPosition() const { return !page.position.empty(); }

  bool sameObject(size_t i, size_t j) const {
    return page.objectId.empty() || page.objectId[i] == page.objectId[j];
  }

  // Calls f(j) for every valid texel j of p's object in the (2r + 1)^2 window around
  // (x, y) that is geometrically close to p (the guide weight at least 1/2), p included.
  template <class F>
  void forEachCompatible(int x, int y, int r, F&& f) const {
    const int w = page.width(), h = page.height();
    const size_t i = size_t(y) * w + x;
    for (int dy = -r; dy <= r; ++dy)
      for (int dx = -r; dx <= r; ++dx) {
        const int qx = x + dx, qy = y + dy;
        if (qx < 0 || qy < 0 || qx >= w || qy >= h) continue;
        const size_t j = size_t(qy) * w + qx;
        if (!page.valid[j] || !sameObject(i, j)) continue;
        if (j != i && geometric(x, y, qx, qy) < 0.5f) continue;
        f(j);
      }
  }

  // Calls f(x, y, i) for every valid texel, rows in parallel.
  template <class F>
  void forEachValid(const ParallelOptions& rows, F&& f) const {
    const int w = page.width();
    parallelFor(
        size_t(page.height()),
        [&](size_t begin, size_t end) {
          for (size_t yy = begin; yy < end; ++yy)
            for (int x = 0; x < w; ++x) {
              const size_t i = yy * size_t(w) + size_t(x);
              if (page.valid[i]) f(x, int(yy), i);
            }
        },
        rows);
  }

  // Product of the normal and position weights between p and q, q at texel offset
  // (ox, oy) from p.
  float geometric(int px, int py, int qx, int qy) const {
    float w = 1.0f;
    vec3 np(0.0f);
    if (hasNormal()) {
      np = texel3(page.normal, px, py);
      const float d = std::max(0.0f, glm::dot(np, texel3(page.normal, qx, qy)));
      w *= std::pow(d, s.sigmaNormal);
      if (w == 0.0f) return 0.0f;
    }
    if (hasPosition()) {
      const float hp = texelSize[size_t(py) * page.width() + px];
      if (hp > 0.0f) {
        const vec3 d = texel3(page.position, qx, qy) - texel3(page.position, px, py);
        const float plane = hasNormal() ? glm::dot(np, d) : 0.0f;
        const float ox = float(qx - px), oy = float(qy - py);
        const float excess =
            std::max(0.0f, glm::length(d) - 2.0f * hp * std::sqrt(ox * ox + oy * oy));
        const float sigma = s.sigmaPosition * hp;
        w *= std::exp(-(plane * plane + excess * excess) / (sigma * sigma));
      }
    }
    return w;
  }
};

// World size of each valid texel's edge from its neighbours' positions: per axis the
// nearer of the two same-object valid neighbours (a chart border has only one, or a far one
// across a UV gap), averaged over the axes that have one; texels with no neighbour get the
// page's mean. Only used when the caller gives no texelWorldSize.
std::vector<float> estimateTexelSize(const LightmapPage& page) {
  const int w = page.width(), h = page.height();
  std::vector<float> size(page.texelCount(), 0.0f);
  auto ok = [&](size_t i, int x, int y) {
    if (x < 0 || y < 0 || x >= w || y >= h) return false;
    const size_t j = size_t(y) * w + x;
    return page.valid[j] && (page.objectId.empty() || page.objectId[i] == page.objectId[j]);
  };
  double total = 0.0;
  size_t count = 0;
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x) {
      const size_t i = size_t(y) * w + x;
      if (!page.valid[i]) continue;
      const vec3 p = texel3(page.position, x, y);
      float sum = 0.0f;
      int axes = 0;
      for (int axis = 0; axis < 2; ++axis) {
        float best = kInfinity;
        for (int sgn = -1; sgn <= 1; sgn += 2) {
          const int nx = x + (axis == 0 ? sgn : 0), ny = y + (axis == 1 ? sgn : 0);
          if (!ok(i, nx, ny)) continue;
          best = std::min(best, glm::length(texel3(page.position, nx, ny) - p));
        }
        if (best < kInfinity) {
          sum += best;
          ++axes;
        }
      }
      if (axes > 0) {
        size[i] = sum / float(axes);
        total += size[i];
        ++count;
      }
    }
  const float mean = count ? float(total / double(count)) : 0.0f;
  for (size_t i = 0; i < size.size(); ++i)
    if (page.valid[i] && size[i] <= 0.0f) size[i] = mean;
  return size;
}

// Perturbation of the Monte-Carlo divergence estimate, as a fraction of each texel's noise.
constexpr float kDivergenceStep = 0.02f;
// The per-object step (denoise): standard errors taken off SURE's estimate of the noise the
// result removes, for a noisy object (relative noise >= kNoisy) and for a nearly converged
// one (<= kConverged; in between it rises linearly). Where the noise is large the gain is
// large and 1 keeps most of it; where the samples have resolved the light the gain the
// filter can make is a few percent and SURE's misses cost more than the gain. An object
// with fewer than kReliableTexels valid texels always takes kConvergedMargin: its estimate
// sums too few texels (the Cornell box's 9-texel block sides are dark enough to count as
// noisy at 256 samples; with the noisy margin they took shares that lost on 4-5 of 64
// seeds, up to +0.02% on the page). The converged margin is 3 since the trend candidate
// (ObjectTrend): with 2, the per-seed CLI check (docs/charts.md) at 256 samples had seed 0
// 0.17% above raw (2.5) and chart 1 one of 8 seeds 0.055% above raw at 1024 samples (2).
constexpr double kObjectMargin = 1.0;
constexpr double kConvergedMargin = 3.0;
constexpr double kNoisy = 0.1, kConverged = 0.05;
constexpr double kReliableTexels = 16.0;
// Interior texels an object needs for its own variance check (calibrateVariance).
constexpr size_t kCalibrationTexels = 16;
// The safeguard window: (2r + 1)^2 texels.
constexpr int kSafeguardRadius = 5;
// The trend candidate (ObjectTrend): objects with at least this many valid texels may be
// filtered as a quadratic fit plus the filtered residual; a texel's result then keeps at
// least kTrendFloor of its own value. (8 against 16 or 32: the same 0 of 512 seeds above
// raw at 64 samples, lower errors on the Cornell box's 9- and 15-texel block sides.)
constexpr double kTrendTexels = 8.0;
constexpr float kTrendFloor = 1.0f / 16.0f;

// Per object, the least-squares fit of each channel by a quadratic in world position (1, u,
// v, w, u^2, v^2, w^2, uv, uw, vw of the position centred on the object's mean and scaled
// by its largest offset) over its valid texels. The à-trous filter blurs whatever the
// luminance weights let through, the light's own curvature included: on the Cornell box's
// ceiling (a peak under the lamp across 8 texels) the blurred signal was as large as the
// noise removed, and the error of that bias against each bake's noise decided whether the
// bake lost (docs/charts.md, "Per seed"). A smooth trend is what a quadratic fit holds; the
// filter then only sees the residual, noise and what the fit misses, and its bias is that
// of the residual. The fit is linear in the texels (a fixed hat matrix per object), so the
// divergence by perturbation and the object sums see it as part of the filter. A global
// quadratic does not hold a shadow edge: across one the fit is steep, and the filter's
// one-sided average of the residual next to the edge is off by the fit's slope (the step
// page of lightmap_post_test: the edge column 9% off); denoise therefore runs the filter
// with and without the trend and lets each object keep the one whose guaranteed gain is
// larger. A small
// ridge (1e-6 x texels on the diagonal) keeps the normal equations definite on planar
// objects (w constant: u^2 and w, ... are then one direction) and tiny ones.
class ObjectTrend {
 public:
  static constexpr int kBasis = 10;

  explicit ObjectTrend(const LightmapPage& page) : page_(page) {
    const int32_t objects = objectCount(page);
    active_.assign(size_t(objects), 0);
    centre_.assign(size_t(objects), glm::dvec3(0.0));
    scale_.assign(size_t(objects), 0.0);
    factor_.assign(size_t(objects), {});
    if (page.position.empty()) return;
    std::vector<double> count(size_t(objects), 0.0);
    forEachTexel([&](size_t i, size_t o) {
      centre_[o] += glm::dvec3(position(i));
      count[o] += 1.0;
    });
    for (size_t o = 0; o < size_t(objects); ++o)
      if (count[o] >= kTrendTexels) {
        active_[o] = 1;
        centre_[o] /= count[o];
      }
    forEachActive([&](size_t i, size_t o) {
      const glm::dvec3 d = glm::dvec3(position(i)) - centre_[o];
      scale_[o] = std::max({scale_[o], std::abs(d.x), std::abs(d.y), std::abs(d.z)});
    });
    std::vector<std::array<double, kBasis * kBasis>> gram(static_cast<size_t>(objects));
    for (auto& m : gram) m.fill(0.0);
    for (size_t o = 0; o < size_t(objects); ++o)
      if (!(scale_[o] > 0.0)) active_[o] = 0;
    forEachActive([&](size_t i, size_t o) {
      const std::array<double, kBasis> phi = basis(i, o);
      for (int a = 0; a < kBasis; ++a)
        for (int b = 0; b <= a; ++b)
          gram[o][size_t(a * kBasis + b)] += phi[size_t(a)] * phi[size_t(b)];
    });
    for (size_t o = 0; o < size_t(objects); ++o) {
      if (!active_[o]) continue;
      for (int a = 0; a < kBasis; ++a) gram[o][size_t(a * kBasis + a)] += 1e-6 * count[o];
      active_[o] = cholesky(gram[o], factor_[o]) ? 1 : 0;
    }
  }

  bool any() const {
    return std::any_of(active_.begin(), active_.end(), [](uint8_t a) { return a != 0; });
  }
  bool covers(size_t i) const {
    const int32_t o = texelObject(page_, i);
    return page_.valid[i] && o >= 0 && active_[size_t(o)];
  }

  // The fit of `in` (every channel) at the valid texels of the objects it covers; other
  // texels hold `in`.
  Image fit(const Image& in) const {
    const int c = in.channels;
    const size_t objects = active_.size();
    std::vector<double> rhs(objects * size_t(c) * kBasis, 0.0);
    forEachActive([&](size_t i, size_t o) {
      const std::array<double, kBasis> phi = basis(i, o);
      for (int ch = 0; ch < c; ++ch) {
        const double v = in.pixels[i * size_t(c) + size_t(ch)];
        double* r = rhs.data() + (o * size_t(c) + size_t(ch)) * kBasis;
        for (int a = 0; a < kBasis; ++a) r[a] += phi[size_t(a)] * v;
      }
    });
    for (size_t o = 0; o < objects; ++o)
      if (active_[o])
        for (int ch = 0; ch < c; ++ch)
          solve(factor_[o], rhs.data() + (o * size_t(c) + size_t(ch)) * kBasis);
    Image out = in;
    forEachActive([&](size_t i, size_t o) {
      const std::array<double, kBasis> phi = basis(i, o);
      for (int ch = 0; ch < c; ++ch) {
        const double* coef = rhs.data() + (o * size_t(c) + size_t(ch)) * kBasis;
        double v = 0.0;
        for (int a = 0; a < kBasis; ++a) v += coef[a] * phi[size_t(a)];
        out.pixels[i * size_t(c) + size_t(ch)] = float(v);
      }
    });
    return out;
  }

 private:
  vec3 position(size_t i) const {
    const float* q = page_.position.pixels.data() + i * size_t(page_.position.channels);
    return vec3(q[0], q[1], q[2]);
  }
  template <class F>
  void forEachTexel(F&& f) const {
    for (size_t i = 0; i < page_.texelCount(); ++i) {
      const int32_t o = texelObject(page_, i);
      if (page_.valid[i] && o >= 0) f(i, size_t(o));
    }
  }
  template <class F>
  void forEachActive(F&& f) const {
    forEachTexel([&](size_t i, size_t o) {
      if (active_[o]) f(i, o);
    });
  }
  std::array<double, kBasis> basis(size_t i, size_t o) const {
    const glm::dvec3 u = (glm::dvec3(position(i)) - centre_[o]) / scale_[o];
    return {1.0, u.x, u.y, u.z, u.x * u.x, u.y * u.y, u.z * u.z, u.x * u.y, u.x * u.z, u.y * u.z};
  }
  // Lower Cholesky factor of the symmetric matrix whose lower triangle `m` holds; false if
  // it is not positive definite.
  static bool cholesky(const std::array<double, kBasis * kBasis>& m,
                       std::array<double, kBasis * kBasis>& l) {
    l.fill(0.0);
    for (int a = 0; a < kBasis; ++a)
      for (int b = 0; b <= a; ++b) {
        double sum = m[size_t(a * kBasis + b)];
        for (int k = 0; k < b; ++k) sum -= l[size_t(a * kBasis + k)] * l[size_t(b * kBasis + k)];
        if (a == b) {
          if (!(sum > 0.0)) return false;
          l[size_t(a * kBasis + a)] = std::sqrt(sum);
        } else {
          l[size_t(a * kBasis + b)] = sum / l[size_t(b * kBasis + b)];
        }
      }
    return true;
  }
  // Solves L L^T x = r in place.
  static void solve(const std::array<double, kBasis * kBasis>& l, double* r) {
    for (int a = 0; a < kBasis; ++a) {
      for (int k = 0; k < a; ++k) r[a] -= l[size_t(a * kBasis + k)] * r[k];
      r[a] /= l[size_t(a * kBasis + a)];
    }
    for (int a = kBasis - 1; a >= 0; --a) {
      for (int k = a + 1; k < kBasis; ++k) r[a] -= l[size_t(k * kBasis + a)] * r[k];
      r[a] /= l[size_t(a * kBasis + a)];
    }
  }

  const LightmapPage& page_;
  std::vector<uint8_t> active_;
  std::vector<glm::dvec3> centre_;
  std::vector<double> scale_;
  std::vector<std::array<double, kBasis * kBasis>> factor_;
};

// The safeguard: per texel, the share a of the filtered value f in the output
// x + a (f - x) (x the raw value) that minimises the expected squared error. With e the
// raw texel's noise (variance s2), f = truth + b + e_f (b the filter's bias, from blurred
// gradients; c = cov(e_f, e)) and d = f - x, the error of the output is e + a (b + e_f - e)
// and its mean square is smallest at a = (s2 - c) / E[d^2] (a Wiener / SURE-style
// shrinkage). E[d^2] = b^2 + var(d) is measured: the mean of d^2 over the texel's
// geometrically compatible neighbours of its object in an 11x11 window (one texel's d^2 alone
// is too noisy a guess; the bias of a blurred gradient is smooth across a few texels). Where the
// filter only removed noise, d^2 ~ s2 - 2c and a ~ 1; where it moved a texel by much more than the
// texel's own standard error, the difference is signal and a -> 0 (the raw value stays).
// s2 is the 3x3 mean of the texels' variance too, so that a texel whose few paths all
// agreed (variance estimate 0) still trusts its neighbours as much as they do; c ~ self x s2
// with `self` the texel's share of its own input in f.
std::vector<float> safeguardWeights(const Guides& g, const Image& raw, const Image& filtered,
                                    const std::vector<float>& sigma,
                                    const std::vector<float>& divergence,
                                    const ParallelOptions& rows) {
  const LightmapPage& page = g.page;
  const int w = page.width(), h = page.height();
  std::vector<float> d2(page.texelCount(), 0.0f), blend(page.texelCount(), 0.0f);
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x) {
      const size_t i = size_t(y) * w + x;
      d2[i] = colourDistance2(filtered, raw, i);
    }
  g.forEachValid(rows, [&](int x, int y, size_t i) {
    double sumD2 = 0.0, gain = 0.0;
    g.forEachCompatible(x, y, kSafeguardRadius, [&](size_t j) {
      sumD2 += d2[j];
      gain += double(sigma[j]) * sigma[j] * colourVarianceFactor(filtered, j) *
              (1.0 - double(divergence[j]));
    });
    blend[i] = sumD2 > 0.0 ? float(std::clamp(gain / sumD2, 0.0, 1.0)) : 1.0f;
  });
  return blend;
}

// The given variance checked against the texels themselves, per object. Each interior
// texel p (all 8 neighbours valid, of its object and geometrically compatible) is compared
// with the mean m_p of those neighbours: a linear gradient cancels in x_p - m_p, and with
// independent texels E[(x_p - m_p)^2] = var_p + sum_q var_q / 64 + c_p^2, c_p the light's
// curvature. So R = sum (x_p - m_p)^2 / sum (var_p + sum_q var_q / 64) is, in expectation,
// at least the ratio of the true variance to the given one: where R < 1 the given variance
// is too large (a quasi-Monte Carlo texel whose batch spread overstates its error), and
// every sigma of the object is scaled by sqrt(R). R >= 1 (a gradient with curvature, or
// variance given too small) changes nothing: the correction only ever lowers the variance,
// which makes both SURE safeguards more cautious, never less. An object with fewer than
// kCalibrationTexels interior texels takes the pooled R of the page's small objects.
void calibrateVariance(const Guides& g, std::vector<float>& sigma) {
  const LightmapPage& page = g.page;
  const int w = page.width(), h = page.height();
  const int32_t objects = objectCount(page);
  std::vector<double> residual(size_t(objects), 0.0), expected(size_t(objects), 0.0);
  std::vector<size_t> count(size_t(objects), 0);
  for (int y = 1; y + 1 < h; ++y)
    for (int x = 1; x + 1 < w; ++x) {
      const size_t i = size_t(y) * w + x;
      if (!page.valid[i] || texelObject(page, i) < 0) continue;
      double sum = 0.0, var = 0.0;
      int m = 0;
      g.forEachCompatible(x, y, 1, [&](size_t j) {
        if (j == i) return;
        sum += texelLuminance(page.radiance, int(j % size_t(w)), int(j / size_t(w)));
        var += double(sigma[j]) * sigma[j];
        ++m;
      });
      if (m < 8) continue;
      const double d = texelLuminance(page.radiance, x, y) - sum / 8.0;
      const size_t o = size_t(texelObject(page, i));
      residual[o] += d * d;
      expected[o] += double(sigma[i]) * sigma[i] + var / 64.0;
      ++count[o];
    }
  double smallResidual = 0.0, smallExpected = 0.0;
  for (size_t o = 0; o < size_t(objects); ++o)
    if (count[o] < kCalibrationTexels) {
      smallResidual += residual[o];
      smallExpected += expected[o];
    }
  std::vector<float> scale(size_t(objects), 1.0f);
  for (size_t o = 0; o < size_t(objects); ++o) {
    const bool own = count[o] >= kCalibrationTexels;
    const double r = own ? residual[o] : smallResidual, e = own ? expected[o] : smallExpected;
    if (e > 0.0 && r < e) scale[o] = float(std::sqrt(r / e));
  }
  for (size_t i = 0; i < sigma.size(); ++i)
    if (page.valid[i] && texelObject(page, i) >= 0) sigma[i] *= scale[size_t(texelObject(page, i))];
}

// Scales each object's valid texels, per channel, so that their sum is the raw sum again:
// the per-texel blend of the safeguard does not keep it exactly (the filter alone does).
// A factor > 0 keeps every texel non-negative and keeps texels > 0 above 0.
void restoreObjectSums(LightmapPage& page, const Image& raw) {
  const int c = page.radiance.channels;
  const int32_t objects = objectCount(page);
  std::vector<double> rawSum(size_t(objects) * c, 0.0), outSum(size_t(objects) * c, 0.0);
  for (size_t i = 0; i < page.texelCount(); ++i) {
    const int32_t object = texelObject(page, i);
    if (!page.valid[i] || object < 0) continue;
    for (int ch = 0; ch < c; ++ch) {
      const size_t k = i * size_t(c) + size_t(ch), o = size_t(object) * c + size_t(ch);
      rawSum[o] += raw.pixels[k];
      outSum[o] += page.radiance.pixels[k];
    }
  }
  for (size_t i = 0; i < page.texelCount(); ++i) {
    const int32_t object = texelObject(page, i);
    if (!page.valid[i] || object < 0) continue;
    for (int ch = 0; ch < c; ++ch) {
      const size_t k = i * size_t(c) + size_t(ch), o = size_t(object) * c + size_t(ch);
      if (outSum[o] > 0.0)
        page.radiance.pixels[k] = float(double(page.radiance.pixels[k]) * rawSum[o] / outSum[o]);
    }
  }
}

}  // namespace

std::vector<uint8_t> dilate(Image& image, const std::vector<uint8_t>& valid, int iterations,
                            const ParallelOptions& parallel) {
  assert(valid.size() == size_t(image.width) * size_t(image.height));
  std::vector<uint8_t> mask = valid, next;
  for (int ring = 0; iterations <= 0 || ring < iterations; ++ring) {
    if (dilateRing(image, mask, next, nullptr, parallel) == 0) break;
    mask.swap(next);
  }
  return mask;
}

std::vector<uint8_t> fillInvalid(Image& image, const std::vector<uint8_t>& valid,
                                 const std::vector<int32_t>& objectId,
                                 const FillSettings& settings) {
  const int w = image.width, h = image.height, c = image.channels;
  assert(valid.size() == size_t(w) * size_t(h));
  assert(objectId.empty() || objectId.size() == valid.size());
  const std::vector<int32_t> oneObject =
      objectId.empty() ? std::vector<int32_t>(valid.size(), 0) : std::vector<int32_t>();
  const std::vector<int32_t>& given = objectId.empty() ? oneObject : objectId;
  // With maxRings, the texels beyond reach drop out of the fill: object id -1 (like padding)
  // in `limited`, so neither pass writes or reads them; they are added to the mask at the end.
  std::vector<int32_t> limited;
  std::vector<uint8_t> kept;
  if (settings.maxRings > 0) {
    std::vector<uint8_t> reach = valid, next;
    if (settings.ringSeeds) {
      assert(settings.ringSeeds->size() == valid.size());
      for (size_t i = 0; i < reach.size(); ++i) reach[i] &= (*settings.ringSeeds)[i];
    }
    for (int ring = 0; ring < settings.maxRings; ++ring) {
      next = reach;
      for (int y = 0; y < h; ++y)
        for (int x = 0; x < w; ++x) {
          const size_t i = size_t(y) * w + x;
          if (reach[i] || given[i] < 0) continue;
          for (int k = 0; k < 8 && !next[i]; ++k) {
            const int nx = x + kDx[k], ny = y + kDy[k];
            if (nx < 0 || ny < 0 || nx >= w || ny >= h) continue;
            const size_t j = size_t(ny) * w + nx;
            if (reach[j] && given[j] == given[i]) next[i] = 1;
          }
        }
      reach.swap(next);
    }
    limited = given;
    kept.assign(valid.size(), 0);
    for (size_t i = 0; i < valid.size(); ++i)
      if (given[i] >= 0 && !valid[i] && !reach[i]) {
        limited[i] = -1;
        kept[i] = 1;
      }
  }
  const std::vector<int32_t>& ids = settings.maxRings > 0 ? limited : given;
  const int r = std::max(0, int(std::floor(settings.radius)));
  const float r2 = settings.radius * settings.radius;

  // Shepard pass: reads valid texels only and writes invalid ones, so in place is safe.
  std::vector<uint8_t> mask = valid;
  parallelFor(
      size_t(h),
      [&](size_t begin, size_t end) {
        std::vector<double> sum(static_cast<size_t>(c));
        for (size_t yy = begin; yy < end; ++yy) {
          const int y = int(yy);
          for (int x = 0; x < w; ++x) {
            const size_t i = size_t(y) * w + x;
            if (valid[i] || ids[i] < 0) continue;
            std::fill(sum.begin(), sum.end(), 0.0);
            double weight = 0.0;
            for (int dy = -r; dy <= r; ++dy)
              for (int dx = -r; dx <= r; ++dx) {
                const int d2 = dx * dx + dy * dy;
                const int nx = x + dx, ny = y + dy;
                if (d2 == 0 || float(d2) > r2 || nx < 0 || ny < 0 || nx >= w || ny >= h) continue;
                const size_t j = size_t(ny) * w + nx;
                if (!valid[j] || ids[j] != ids[i]) continue;
                const double wq = 1.0 / double(d2);
                const float* q = image.at(nx, ny);
                for (int ch = 0; ch < c; ++ch) sum[size_t(ch)] += wq * q[ch];
                weight += wq;
              }
            if (weight <= 0.0) continue;
            float* p = image.at(x, y);
            for (int ch = 0; ch < c; ++ch) p[ch] = float(sum[size_t(ch)] / weight);
            mask[i] = 1;
          }
        }
      },
      rowOptions(settings.parallel));

  // Fallback: same-object rings for texels farther than `radius` from any valid texel.
  std::vector<uint8_t> next;
  while (dilateRing(image, mask, next, &ids, settings.parallel) > 0) mask.swap(next);
  for (size_t i = 0; i < kept.size(); ++i) mask[i] |= kept[i];
  return mask;
}

namespace {

// denoise's stages over one page (postprocess.h): the noise per texel, the filter (à-trous
// passes, optionally on the residual of each object's trend), the per-texel safeguard, and
// the per-object share of the change, from SURE's lower bound on its gain.
class Denoiser {
 public:
  Denoiser(LightmapPage& page, const DenoiseSettings& settings)
      : page_(page),
        settings_(settings),
        w_(page.width()),
        h_(page.height()),
        c_(page.radiance.channels),
        n_(page.texelCount()),
        g_{page, settings, {}},
        rows_(rowOptions(settings.parallel)),
        trend_(page),
        objects_(objectCount(page)) {
    if (g_.hasPosition())
      g_.texelSize = page.texelWorldSize.empty() ? estimateTexelSize(page) : page.texelWorldSize;
  }

  void run() {
    estimateNoise();
    input_ = page_.radiance;
    page_.radiance = safeguarded(input_, false);
    std::vector<float> div = chainDivergence(page_.radiance, false);
    ObjectStep step = objectStep(page_.radiance, div);
    if (trend_.any()) takeTrendWhereItGuaranteesMore(step, div);
    applyShares(step);
    restoreObjectSums(page_, input_);
  }

 private:
  // Per object, SURE's estimate of the noise the change out - input removes (G), the
  // change's size (D), the estimate's spread, and the lower bound on G (applyShares).
  struct ObjectStep {
    std::vector<double> change, removed, spread, low;
  };

  // Noise standard deviation per texel (sigma_): from the given variance, or else a spatial
  // estimate over the geometrically compatible valid 3x3 neighbours, as SVGF does without
  // history; but robust: the median absolute deviation (x 1.4826, consistent for Gaussian
  // noise) rather than the standard deviation, so that a texel beside a shadow edge, with at
  // most 3 of its 9 neighbours across the edge, measures its own side's noise and not the
  // step. Texels with fewer than three such texels get the page's mean estimate.
  // Then checked_, the noise the safeguards judge the filter by: the given variance bounded
  // by the texels' own spread (calibrateVariance). The filter's weights keep the variance as
  // given: where it overstates the noise they mix more, and the safeguards, with the bounded
  // variance, decide how much of that to keep.
  void estimateNoise() {
    sigma_.assign(n_, 0.0f);
    if (!page_.variance.empty()) {
      for (size_t i = 0; i < n_; ++i) sigma_[i] = std::sqrt(std::max(0.0f, page_.variance[i]));
    } else {
      std::vector<uint8_t> estimated(n_, 0);
      g_.forEachValid(rows_, [&](int x, int y, size_t i) {
        std::array<float, 9> lum;
        int count = 0;
        g_.forEachCompatible(x, y, 1, [&](size_t j) {
          lum[size_t(count++)] =
              texelLuminance(page_.radiance, int(j % size_t(w_)), int(j / size_t(w_)));
        });
        if (count < 3) return;
        const float med = median(lum.data(), count);
        for (int k = 0; k < count; ++k) lum[size_t(k)] = std::abs(lum[size_t(k)] - med);
        sigma_[i] = kMadToSigma * median(lum.data(), count);
        estimated[i] = 1;
      });
      double total = 0.0;
      size_t count = 0;
      for (size_t i = 0; i < n_; ++i)
        if (estimated[i]) {
          total += sigma_[i];
          ++count;
        }
      const float mean = count ? float(total / double(count)) : 0.0f;
      for (size_t i = 0; i < n_; ++i)
        if (page_.valid[i] && !estimated[i]) sigma_[i] = mean;
    }
    checked_ = sigma_;
    if (!page_.variance.empty()) calibrateVariance(g_, checked_);
  }

  // The à-trous passes over `in` (page.radiance, a perturbed copy or a residual): the
  // filtered image. With clampAtZero false (a residual) values may be < 0.
  Image filterPasses(const Image& in, bool clampAtZero) const {
    const int w = w_, h = h_, c = c_;
    const size_t n = n_;
    const LightmapPage& page = page_;
    const Guides& g = g_;
    // Variance of each texel's current value, carried through the passes as SVGF does: a
    // weighted mean with weights w has variance sum(w^2 var) / (sum w)^2 (neighbours taken as
    // independent), so the luminance threshold shrinks as the noise does.
    std::vector<float> var(n), nextVar(n, 0.0f);
    for (size_t i = 0; i < n; ++i) var[i] = sigma_[i] * sigma_[i];
    Image src = in, dst = in;
    // Pair weight of texels p and q (q at a 5x5 à-trous tap of p), symmetric in p and q:
    // B3 kernel x geometric guides (the smaller of the two directions) x a Gaussian in the
    // luminance difference over its own standard error, sqrt(var_p + var_q): neighbours whose
    // difference the noise explains mix, differences the noise does not explain (edges,
    // gradients resolved by the samples) stop the filter. As the variance falls, so does every
    // weight: the filter fades out where the estimate is already converged.
    std::vector<float> lum(n, 0.0f), rowWeight(n, 0.0f);
    for (int pass = 0; pass < settings_.iterations; ++pass) {
      const int step = 1 << pass;
      for (int y = 0; y < h; ++y)
        for (int x = 0; x < w; ++x) lum[size_t(y) * w + x] = texelLuminance(src, x, y);
      auto pairWeight = [&](int x, int y, int kx, int ky, size_t i, size_t j) -> float {
        const int qx = x + (kx - 2) * step, qy = y + (ky - 2) * step;
        float wq = kB3[kx] * kB3[ky];
        wq *= std::min(g.geometric(x, y, qx, qy), g.geometric(qx, qy, x, y));
        if (wq <= 0.0f) return 0.0f;
        const float d = lum[j] - lum[i];
        const float v = var[i] + var[j];
        const float k = settings_.sigmaLuminance;
        if (!(v > 0.0f)) return d == 0.0f ? wq : 0.0f;
        return wq * std::exp(-0.5f * d * d / (k * k * v));
      };
      auto forEachTap = [&](int x, int y, auto&& f) {
        const size_t i = size_t(y) * w + x;
        for (int ky = 0; ky < 5; ++ky) {
          const int qy = y + (ky - 2) * step;
          if (qy < 0 || qy >= h) continue;
          for (int kx = 0; kx < 5; ++kx) {
            const int qx = x + (kx - 2) * step;
            if (qx < 0 || qx >= w || (kx == 2 && ky == 2)) continue;
            const size_t j = size_t(qy) * w + qx;
            if (!page.valid[j] || !g.sameObject(i, j)) continue;
            f(kx, ky, j);
          }
        }
      };
      // Each texel's total weight (its own B3 weight included).
      parallelFor(
          size_t(h),
          [&](size_t begin, size_t end) {
            for (size_t yy = begin; yy < end; ++yy)
              for (int x = 0; x < w; ++x) {
                const int y = int(yy);
                const size_t i = size_t(y) * w + x;
                if (!page.valid[i]) continue;
                double total = double(kB3[2]) * kB3[2];
                forEachTap(x, y, [&](int kx, int ky, size_t j) {
                  total += pairWeight(x, y, kx, ky, i, j);
                });
                rowWeight[i] = float(total);
              }
          },
          rows_);
      // out_p = x_p + sum_q a_pq (x_q - x_p), a_pq = w_pq / max(W_p, W_q): a is symmetric, so
      // the texels' sum (their mean) is kept exactly, and sum_q a_pq < 1, so out_p is a convex
      // combination of non-negative values with a positive share of x_p: never negative, and
      // never 0 where x_p > 0.
      parallelFor(
          size_t(h),
          [&](size_t begin, size_t end) {
            std::vector<double> sum(static_cast<size_t>(c));
            for (size_t yy = begin; yy < end; ++yy) {
              const int y = int(yy);
              for (int x = 0; x < w; ++x) {
                const size_t i = size_t(y) * w + x;
                if (!page.valid[i]) continue;  // dst already holds the input value
                const float* p = src.at(x, y);
                std::fill(sum.begin(), sum.end(), 0.0);
                double share = 0.0, outVar = 0.0;
                forEachTap(x, y, [&](int kx, int ky, size_t j) {
                  const float wq = pairWeight(x, y, kx, ky, i, j);
                  if (wq <= 0.0f) return;
                  const double a = double(wq) / double(std::max(rowWeight[i], rowWeight[j]));
                  const float* q = src.pixels.data() + j * size_t(c);
                  for (int ch = 0; ch < c; ++ch) sum[size_t(ch)] += a * (double(q[ch]) - p[ch]);
                  share += a;
                  outVar += a * a * var[j];
                });
                float* out = dst.at(x, y);
                for (int ch = 0; ch < c; ++ch)
                  out[ch] = clampAtZero ? float(std::max(0.0, double(p[ch]) + sum[size_t(ch)]))
                                        : float(double(p[ch]) + sum[size_t(ch)]);
                nextVar[i] = float(outVar + (1.0 - share) * (1.0 - share) * var[i]);
              }
            }
          },
          rows_);
      std::swap(src, dst);
      std::swap(var, nextVar);
    }
    return src;
  }

  // The filter (on page.radiance or a perturbed copy): with `trend`, on the objects
  // ObjectTrend covers, the fit plus the filtered residual, at least kTrendFloor of the
  // texel's own value (so a texel > 0 never turns 0 or negative); elsewhere the passes alone.
  Image filter(const Image& in, bool trend) const {
    if (!trend) return filterPasses(in, true);
    const Image fit = trend_.fit(in);
    Image residual = in;
    for (size_t k = 0; k < residual.pixels.size(); ++k) residual.pixels[k] -= fit.pixels[k];
    Image out = filterPasses(residual, false);
    for (size_t i = 0; i < n_; ++i) {
      if (!page_.valid[i]) continue;
      const bool fitted = trend_.covers(i);
      for (int ch = 0; ch < c_; ++ch) {
        const size_t k = i * size_t(c_) + size_t(ch);
        out.pixels[k] = fitted ? std::max(out.pixels[k] + fit.pixels[k],
                                          kTrendFloor * std::max(in.pixels[k], 0.0f))
                               : std::max(out.pixels[k], 0.0f);
      }
    }
    return out;
  }

  // The divergence of an operator `op` on the page, d op(x)_p / d x_p, by a Monte-Carlo
  // perturbation (Ramani et al. 2008, "Monte-Carlo SURE"): every texel's luminance moves by
  // eps_p b_p, b_p = +-1 from a hash of its index and `salt`, and b_p (op(x + eps b)_p -
  // op(x)_p) / eps_p estimates it (the cross terms b_p b_q d op_p / d x_q average out over
  // a window). eps_p is a small fraction of the texel's noise, where the weights'
  // dependence on the values lives.
  template <typename Op>
  std::vector<float> divergenceOf(const Image& in, const Image& out, uint64_t salt,
                                  const Op& op) const {
    Image perturbed = in;
    std::vector<float> eps(n_, 0.0f), div(n_, 0.0f);
    for (size_t i = 0; i < n_; ++i) {
      if (!page_.valid[i]) continue;
      const float x = texelLuminance(in, int(i % size_t(w_)), int(i / size_t(w_)));
      eps[i] = std::max(kDivergenceStep * sigma_[i], 1e-5f * std::max(x, 1e-3f));
      if (mixBits(hashValues(salt, i)) & 1) eps[i] = -eps[i];
      for (int ch = 0; ch < std::min(c_, 3); ++ch)
        perturbed.pixels[i * size_t(c_) + size_t(ch)] += eps[i];
    }
    const Image moved = op(perturbed);
    for (int y = 0; y < h_; ++y)
      for (int x = 0; x < w_; ++x) {
        const size_t i = size_t(y) * w_ + x;
        if (page_.valid[i])
          div[i] = (texelLuminance(moved, x, y) - texelLuminance(out, x, y)) / eps[i];
      }
    return div;
  }

  // The filter (with or without the trend), then the per-texel safeguard (safeguardWeights)
  // on `in`.
  Image safeguarded(const Image& in, bool trend) const {
    const Image filtered = filter(in, trend);
    const std::vector<float> blend = safeguardWeights(
        g_, in, filtered, checked_,
        divergenceOf(in, filtered, 1, [&](const Image& x) { return filter(x, trend); }), rows_);
    Image out = in;
    for (size_t i = 0; i < n_; ++i) {
      const float a = settings_.strength * blend[i];
      for (int ch = 0; ch < c_; ++ch) {
        const size_t k = i * size_t(c_) + size_t(ch);
        out.pixels[k] = in.pixels[k] + a * (filtered.pixels[k] - in.pixels[k]);
      }
    }
    return out;
  }

  // Per object, how much of the change d = out - x to keep: out_a = x + a d, a in [0, 1].
  // With raw error e, the realised change of the squared error (over the colour channels:
  // the error a reader of the lightmap sees; luminance alone misses colour the filter blurs
  // across, e.g. the bleeding from a red wall) is |out_a - truth|^2 - |e|^2 = a^2 D - a G
  // with D = sum |d|^2, known, and G = -2 sum <d, e>, the noise the change removes, which
  // Stein's lemma estimates as G ~ 2 sum var_rgb (1 - div) over the object's valid texels
  // (div that of the whole filter-and-safeguard, var_rgb = var x sum_c out_c^2 / l^2: each
  // channel's noise in proportion to its value). a = G / (2 D) would minimise the expected
  // error; a loses only where a > G / D. SURE's G is uncertain: the per-texel terms' own
  // spread (sqrt of the sum of their squares) and the spread of the realised 2 <d, e> about
  // its expectation (variance 4 var_c d_c^2 per texel), and biased up wherever the given
  // variance still overstates the noise (quasi-Monte Carlo paths: on the Cornell box's
  // ceiling at 64 samples SURE's G was 1.3x the realised one on average over 64 seeds and
  // 2-2.5x on the seeds the old keep-or-raw test lost). So the object takes the a that
  // maximises the lower bound of its gain, G_low = G - margin x spread: a = G_low / (2 D),
  // clamped to [0, 1]. Its realised gain is > 0 whenever the realised G exceeds G_low / 2:
  // half of SURE's lower bound. An object the filter leaves unchanged, or whose G_low <= 0,
  // keeps its raw texels. The old rule (keep the whole change when G - D exceeds the margin
  // x spread, else raw) took a = 1 on objects whose realised G fell below D, and lost (7 of
  // 64 Cornell seeds at 64 samples, worst +1.15%; docs/charts.md).
  ObjectStep objectStep(const Image& out, const std::vector<float>& div) const {
    ObjectStep st;
    st.change.assign(size_t(objects_), 0.0);
    st.removed.assign(size_t(objects_), 0.0);
    st.spread.assign(size_t(objects_), 0.0);
    st.low.assign(size_t(objects_), 0.0);
    std::vector<double> texels(size_t(objects_), 0.0), noise(size_t(objects_), 0.0),
        light(size_t(objects_), 0.0);
    for (int y = 0; y < h_; ++y)
      for (int x = 0; x < w_; ++x) {
        const size_t i = size_t(y) * w_ + x;
        const int32_t object = texelObject(page_, i);
        if (!page_.valid[i] || object < 0) continue;
        const size_t o = size_t(object);
        const float* o3 = out.pixels.data() + i * size_t(c_);
        const float* raw = input_.pixels.data() + i * size_t(c_);
        const double var = double(checked_[i]) * checked_[i];
        const double d2 = colourDistance2(out, input_, i);
        const double gain = 2.0 * var * colourVarianceFactor(out, i) * (1.0 - double(div[i]));
        // SURE's per-texel term of the risk change at a = 1, d^2 - gain: its spread.
        const double t = d2 - gain;
        // 4 var_c d_c^2: the variance of 2 e d, the part of the realised gain SURE averages.
        const float l = texelLuminance(out, x, y);
        double realised = 0.0;
        for (int ch = 0; ch < std::min(c_, 3); ++ch) {
          const double share = l > 0.0f ? double(o3[ch]) / l : 1.0;
          const double d = double(o3[ch]) - raw[ch];
          realised += 4.0 * var * share * share * d * d;
        }
        st.change[o] += d2;
        st.removed[o] += gain;
        st.spread[o] += t * t + realised;
        texels[o] += 1.0;
        const double lr = texelLuminance(input_, x, y);
        noise[o] += var;
        light[o] += lr * lr;
      }
    // The margin: kObjectMargin for a noisy object, rising to kConvergedMargin as its
    // relative noise sqrt(sum var / sum l^2) falls from kNoisy to kConverged; always
    // kConvergedMargin for an object of fewer than kReliableTexels texels.
    for (size_t o = 0; o < size_t(objects_); ++o) {
      const double relative = light[o] > 0.0 ? std::sqrt(noise[o] / light[o]) : 1.0;
      const double u = texels[o] < kReliableTexels
                           ? 1.0
                           : std::clamp((kNoisy - relative) / (kNoisy - kConverged), 0.0, 1.0);
      const double margin = kObjectMargin + u * (kConvergedMargin - kObjectMargin);
      st.low[o] = st.removed[o] - margin * std::sqrt(st.spread[o]);
    }
    return st;
  }

  // The divergence of the whole filter-and-safeguard chain at the input, whose result is `out`.
  std::vector<float> chainDivergence(const Image& out, bool trend) const {
    return divergenceOf(input_, out, 2, [&](const Image& x) { return safeguarded(x, trend); });
  }

  // The gain the share rule guarantees an object (its lower bound at the share it takes):
  // low^2 / (4 D) where low > 0, else 0.
  static double guaranteed(const ObjectStep& st, size_t o) {
    return st.low[o] > 0.0 && st.change[o] > 0.0 ? st.low[o] * st.low[o] / (4.0 * st.change[o])
                                                 : 0.0;
  }

  // The same chain with the trend (ObjectTrend); each object keeps the candidate whose
  // guaranteed gain is larger: its texels in page.radiance, its divergence and its step.
  void takeTrendWhereItGuaranteesMore(ObjectStep& step, std::vector<float>& div) {
    const Image withTrend = safeguarded(input_, true);
    const std::vector<float> divTrend = chainDivergence(withTrend, true);
    const ObjectStep stepTrend = objectStep(withTrend, divTrend);
    std::vector<uint8_t> pick(size_t(objects_), 0);
    for (size_t o = 0; o < size_t(objects_); ++o)
      pick[o] = guaranteed(stepTrend, o) > guaranteed(step, o) ? 1 : 0;
    for (size_t i = 0; i < n_; ++i) {
      const int32_t object = texelObject(page_, i);
      if (!page_.valid[i] || object < 0 || !pick[size_t(object)]) continue;
      div[i] = divTrend[i];
      for (int ch = 0; ch < c_; ++ch)
        page_.radiance.pixels[i * size_t(c_) + size_t(ch)] =
            withTrend.pixels[i * size_t(c_) + size_t(ch)];
    }
    for (size_t o = 0; o < size_t(objects_); ++o)
      if (pick[o]) {
        step.change[o] = stepTrend.change[o];
        step.removed[o] = stepTrend.removed[o];
        step.spread[o] = stepTrend.spread[o];
        step.low[o] = stepTrend.low[o];
      }
  }

  // Each object keeps the share a = low / (2 D) in [0, 1] of its change (objectStep).
  void applyShares(const ObjectStep& step) {
    std::vector<double> share(size_t(objects_), 0.0);
    for (size_t o = 0; o < size_t(objects_); ++o)
      share[o] =
          step.change[o] > 0.0 ? std::clamp(step.low[o] / (2.0 * step.change[o]), 0.0, 1.0) : 0.0;
    for (size_t i = 0; i < n_; ++i) {
      const int32_t object = texelObject(page_, i);
      if (!page_.valid[i] || object < 0) continue;
      const double a = share[size_t(object)];
      for (int ch = 0; ch < c_; ++ch) {
        const size_t k = i * size_t(c_) + size_t(ch);
        page_.radiance.pixels[k] = float(double(input_.pixels[k]) +
                                         a * (double(page_.radiance.pixels[k]) - input_.pixels[k]));
      }
    }
  }

  LightmapPage& page_;
  const DenoiseSettings& settings_;
  const int w_, h_, c_;
  const size_t n_;
  Guides g_;
  const ParallelOptions rows_;
  const ObjectTrend trend_;
  const int32_t objects_;
  std::vector<float> sigma_, checked_;
  Image input_;  // the page's radiance before denoising
};

}  // namespace

void denoise(LightmapPage& page, const DenoiseSettings& settings) {
  [[maybe_unused]] const int w = page.width(), h = page.height();
  const size_t n = page.texelCount();
  assert(page.valid.size() == n);
  assert(page.objectId.empty() || page.objectId.size() == n);
  assert(page.normal.empty() ||
         (page.normal.width == w && page.normal.height == h && page.normal.channels >= 3));
  assert(page.position.empty() ||
         (page.position.width == w && page.position.height == h && page.position.channels >= 3));
  assert(page.variance.empty() || page.variance.size() == n);
  assert(page.texelWorldSize.empty() || page.texelWorldSize.size() == n);
  if (settings.strength <= 0.0f || settings.iterations <= 0 || n == 0) return;
  Denoiser(page, settings).run();
}

}  // namespace kiln
