// chart_lightmap.cpp: chart 1, lightmap samples per texel vs relative error vs bake time, on
// the Cornell box (chart_measure.h, docs/charts.md).
#include <algorithm>
#include <chrono>
#include <cmath>

#include "lightmap/lightmap_baker.h"
#include "src/gltf_loader.h"
#include "src/progress.h"
#include "src/sampling.h"
#include "tools/chart/chart_measure.h"

namespace kiln::chart {
namespace {

constexpr uint64_t kReferenceTag = 0x7265666572656eULL;  // "referen": the reference's seed

struct ErrorSums {
  double diff2 = 0.0, ref2 = 0.0;
  double sum = 0.0, refSum = 0.0;  // for the mean ratio
  // Sum of the baker's per-texel luminance variance and of the squared luminance error:
  // their ratio says whether the variance the denoiser is given matches the actual error.
  double variance = 0.0, lumDiff2 = 0.0;
  size_t texels = 0;
  double relative() const { return ref2 > 0.0 ? std::sqrt(diff2 / ref2) : 0.0; }
  double ratio() const { return refSum > 0.0 ? sum / refSum : 0.0; }
};

// Sums over texels valid in both bakes (RGB) of the squared difference and squared reference.
ErrorSums compareBakes(const LightmapBakeResult& a, const LightmapBakeResult& reference) {
  ErrorSums s;
  for (size_t p = 0; p < a.pages.size() && p < reference.pages.size(); ++p) {
    const LightmapPageResult& x = a.pages[p];
    const LightmapPageResult& r = reference.pages[p];
    for (size_t i = 0; i < x.valid.size(); ++i) {
      if (!x.valid[i] || !r.valid[i]) continue;
      for (int c = 0; c < 3; ++c) {
        const double d = double(x.light.pixels[3 * i + c]) - double(r.light.pixels[3 * i + c]);
        const double v = double(r.light.pixels[3 * i + c]);
        s.diff2 += d * d;
        s.ref2 += v * v;
        s.sum += double(x.light.pixels[3 * i + c]);
        s.refSum += v;
      }
      if (!x.variance.empty()) s.variance += x.variance[i];
      const double dl = double(luminance(vec3(x.light.pixels[3 * i], x.light.pixels[3 * i + 1],
                                              x.light.pixels[3 * i + 2]))) -
                        double(luminance(vec3(r.light.pixels[3 * i], r.light.pixels[3 * i + 1],
                                              r.light.pixels[3 * i + 2])));
      s.lumDiff2 += dl * dl;
      ++s.texels;
    }
  }
  return s;
}

// One bake of `scene` (loaded from `path`), its wall time in *seconds; advances `progress`.
Result<LightmapBakeResult> timedLightmapBake(const Scene& scene, const std::string& path,
                                            const LightmapBakeSettings& settings,
                                            const std::atomic<bool>* cancel, Progress& progress,
                                            double* seconds) {
  const auto t0 = std::chrono::steady_clock::now();
  Result<LightmapBakeResult> r = bakeLightmaps(scene, settings, false, cancel);
  *seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  progress.advance();
  if (!r) return Error{path + ": " + r.error()};
  return r;
}

// The Cornell-box bake settings charts 1 and 7 share (one page, three bounces, no seam
// stitching), so both compare bakes of the same texels.
LightmapBakeSettings cornellChartSettings(const ChartOptions& o) {
  LightmapBakeSettings s;
  s.resolution = o.quick ? 8.0f : 14.0f;
  s.maxSize = 256;
  s.bounces = 3;
  s.stitchSeams = false;
  s.seed = o.seed;
  s.threads = o.threads;
  return s;
}

// The converged reference a chart's bakes are judged against: `s` with `samples` paths per
// texel, not denoised, and an independent seed, so that its own noise adds to the error
// measured (1/16 of the largest count's variance at 16x its samples) rather than cancels.
LightmapBakeSettings referenceSettings(const LightmapBakeSettings& s, int samples,
                                       uint64_t seed) {
  LightmapBakeSettings r = s;
  r.denoise = false;
  r.samplesPerTexel = samples;
  r.seed = hashValues(seed, kReferenceTag);
  return r;
}

}  // namespace

Result<ChartTable> lightmapSamplesChart(const ChartOptions& o) {
  const std::string path = o.scenesDir + "/cornell_box.gltf";
  Result<Scene> scene = loadScene(path);
  if (!scene) return Error{scene.error()};

  LightmapBakeSettings s = cornellChartSettings(o);
  s.denoise = false;
  const std::vector<int> samples =
      o.quick ? std::vector<int>{4, 16, 64} : std::vector<int>{4, 16, 64, 256, 1024};
  const int referenceSamples = 16 * samples.back();
  // Seeds per count: one seed's mean ratio over the ~430 texels spreads by 1.4% at 4 paths
  // per texel (0.6% at 16, 0.3% at 64: measured over 200 seeds), so the low counts take
  // more seeds (about the same paths per count) for a mean ratio known to ~0.2%, and every
  // count at least kMinSeeds, so that "denoised <= raw" is seen on several seeds.
  const int minSeeds = o.quick ? 2 : 8;
  const int pathsPerCount = o.quick ? 16 : 256;
  auto seedsFor = [&](int count) { return std::max(minSeeds, pathsPerCount / count); };
  const std::vector<bool> denoised = {false, true};
  size_t bakes = 1;
  int rounds = 0;
  for (int count : samples) {
    bakes += denoised.size() * size_t(seedsFor(count));
    rounds = std::max(rounds, seedsFor(count));
  }

  Progress progress("chart lightmap", bakes, "bakes", o.progress);
  auto timedBake = [&](const LightmapBakeSettings& settings, double* seconds) {
    return timedLightmapBake(*scene, path, settings, o.cancel, progress, seconds);
  };

  // The reference: the same bake with 16x the largest sample count (see referenceSettings).
  double refSeconds = 0.0;
  Result<LightmapBakeResult> reference =
      timedBake(referenceSettings(s, referenceSamples, o.seed), &refSeconds);
  if (!reference) return Error{reference.error()};

  // Every (variant, count) bake once per seed o.seed, o.seed + 1, ..., the seeds
  // interleaved: round r bakes every variant and count that takes seed r, so that a slow
  // spell of the machine hits all variants alike. Each seed's bake is also a timing repeat.
  struct Cell {
    std::vector<double> wall, light;
    std::vector<double> relative, rms, ratio;  // per seed
    double variance = 0.0, lumDiff2 = 0.0;     // pooled over seeds
    size_t texels = 0;
    uint64_t rays = 0;
  };
  std::vector<Cell> cells(samples.size() * denoised.size());
  for (int r = 0; r < rounds; ++r)
    for (size_t v = 0; v < denoised.size(); ++v)
      for (size_t k = 0; k < samples.size(); ++k) {
        if (r >= seedsFor(samples[k])) continue;
        LightmapBakeSettings settings = s;
        settings.samplesPerTexel = samples[k];
        settings.denoise = denoised[v];
        settings.seed = o.seed + uint64_t(r);
        double wall = 0.0;
        Result<LightmapBakeResult> bake = timedBake(settings, &wall);
        if (!bake) return Error{bake.error()};
        Cell& c = cells[v * samples.size() + k];
        c.wall.push_back(wall);
        c.light.push_back(bake->stats.seconds);
        const ErrorSums e = compareBakes(*bake, *reference);
        c.relative.push_back(e.relative());
        c.rms.push_back(std::sqrt(e.diff2 / (double(std::max<size_t>(e.texels, 1)) * 3.0)));
        c.ratio.push_back(e.ratio());
        c.variance += e.variance;
        c.lumDiff2 += e.lumDiff2;
        c.texels = e.texels;
        if (r == 0) c.rays = bake->stats.rays;
      }
  progress.finish();

  auto mean = [](const std::vector<double>& x) {
    double sum = 0.0;
    for (double v : x) sum += v;
    return x.empty() ? 0.0 : sum / double(x.size());
  };
  auto standardError = [&](const std::vector<double>& x) {
    if (x.size() < 2) return 0.0;
    const double m = mean(x);
    double ss = 0.0;
    for (double v : x) ss += (v - m) * (v - m);
    return std::sqrt(ss / double(x.size() - 1) / double(x.size()));
  };

  ChartTable t;
  t.name = "lightmap_samples";
  t.title = "Lightmap: samples per texel vs error vs bake time (cornell_box)";
  t.columns = {"variant", "samples", "relative_rms_error", "max_error_vs_raw", "rms_error",
               "mean_ratio", "mean_ratio_stderr", "variance_ratio", "bake_seconds",
               "light_seconds", "rays", "texels", "seeds", "reference_samples"};
  std::vector<double> xs, ys;
  for (size_t v = 0; v < denoised.size(); ++v)
    for (size_t k = 0; k < samples.size(); ++k) {
      const Cell& c = cells[v * samples.size() + k];
      const Cell& raw = cells[k];  // variant 0, the same count and seeds
      double worst = 0.0;
      for (size_t i = 0; i < c.relative.size(); ++i)
        worst = std::max(worst, raw.relative[i] > 0.0 ? c.relative[i] / raw.relative[i] : 0.0);
      const double rel = mean(c.relative);
      if (!denoised[v]) {
        xs.push_back(samples[k]);
        ys.push_back(rel);
      }
      t.addRow({denoised[v] ? "denoised" : "raw", std::to_string(samples[k]), num(rel),
                num(worst), num(mean(c.rms)), num(mean(c.ratio)), num(standardError(c.ratio)),
                num(c.lumDiff2 > 0.0 ? c.variance / c.lumDiff2 : 0.0), num(median(c.wall)),
                num(median(c.light)), std::to_string(c.rays), std::to_string(c.texels),
                std::to_string(c.relative.size()), std::to_string(referenceSamples)});
    }
  const double slope = logLogSlope(xs, ys);

  t.notes = commonNotes(o, o.threads);
  t.notes.push_back("chart 1: lightmap samples per texel vs relative error vs bake time");
  t.notes.push_back("scene: " + path + " (emissive ceiling light)");
  t.notes.push_back("settings: resolution " + num(s.resolution) +
                    " texels/unit, maxSize 256, 3 bounces, supersampling 1, stitching off; "
                    "variant raw = denoiser off, denoised = kiln's edge-aware denoiser on");
  t.notes.push_back("baseline: a reference bake of the same settings (denoiser off) with " +
                    std::to_string(referenceSamples) + " samples/texel and an independent seed (" +
                    num(refSeconds) + " s)");
  t.notes.push_back("seeds: each count is baked with seeds " + std::to_string(o.seed) +
                    ", " + std::to_string(o.seed + 1) + ", ... (at least " +
                    std::to_string(minSeeds) + ", " + std::to_string(pathsPerCount) +
                    " / samples at low counts); raw and denoised rows of a count share them");
  t.notes.push_back("relative_rms_error = sqrt(sum (x - ref)^2 / sum ref^2) over RGB of the "
                    "texels valid in both, mean over the seeds; max_error_vs_raw = the largest "
                    "over the seeds of a seed's relative error / the raw bake's of the same seed "
                    "(1 for raw rows; <= 1: the denoiser never added error); rms_error in "
                    "lightmap units (E / pi); mean_ratio = sum x / sum ref over the same texels, "
                    "mean over the seeds, and mean_ratio_stderr its standard error (the spread "
                    "over seeds / sqrt(seeds)); variance_ratio = sum of the baker's per-texel "
                    "luminance variance (what the denoiser is given) / sum of the squared "
                    "luminance error, over the same texels and all seeds (1 = calibrated; the "
                    "reference's own noise adds about 1/16 of the 1024-sample variance)");
  t.notes.push_back("timing: bake_seconds = wall time of bakeLightmaps (all stages), "
                    "light_seconds = its light stage; median over the seeds' bakes, "
                    "interleaved (each round bakes every variant and count once)");
  t.notes.push_back("fitted log-log slope of raw error vs samples: " + num(slope) +
                    " (Monte Carlo: -0.5)");

  const double e0 = ys.empty() ? 1.0 : ys.front();
  const double n0 = xs.empty() ? 1.0 : xs.front();
  t.plot =
      "set logscale xy 2\n"
      "set logscale y2 10\n"
      "set format y '%g'\nset format y2 '%g'\n"
      "set xlabel 'samples per texel'\n"
      "set ylabel 'relative RMS error vs reference'\n"
      "set y2label 'bake time (s)'\n"
      "set ytics nomirror\nset y2tics\n"
      "set key top right\n"
      "plot @CSV@ using 'samples':(strcol('variant') eq 'raw' ? column('relative_rms_error') : "
      "NaN) with linespoints lw 2 pt 7 title 'error, denoiser off', \\\n"
      "  '' using 'samples':(strcol('variant') eq 'denoised' ? column('relative_rms_error') : "
      "NaN) with linespoints lw 2 pt 5 title 'error, denoised', \\\n"
      "  '' using 'samples':(strcol('variant') eq 'raw' ? " + num(e0) + " * sqrt(" + num(n0) +
      " / column('samples')) : NaN) with lines dt 2 lc rgb 'gray40' title '1/sqrt(N) guide', \\\n"
      "  '' using 'samples':(strcol('variant') eq 'raw' ? column('bake_seconds') : NaN) axes "
      "x1y2 with linespoints dt 3 pt 6 lc rgb 'dark-orange' title 'bake time (right axis)'\n";
  return t;
}

}  // namespace kiln::chart

namespace kiln::chart {

// Chart 7: bake time vs error with a fixed count per texel, with adaptive sampling
// (errorTarget), with a bounce cache (final gather) and with the cache's Neyman allocation,
// all denoised, against the same kind of reference as chart 1.
Result<ChartTable> lightmapAdaptiveChart(const ChartOptions& o) {
  const std::string path = o.scenesDir + "/cornell_box.gltf";
  Result<Scene> scene = loadScene(path);
  if (!scene) return Error{scene.error()};
  LightmapBakeSettings s = cornellChartSettings(o);
  const std::vector<int> counts =
      o.quick ? std::vector<int>{16, 64} : std::vector<int>{16, 64, 256, 1024};
  const std::vector<float> targets =
      o.quick ? std::vector<float>{0.1f, 0.05f} : std::vector<float>{0.2f, 0.1f, 0.05f, 0.025f};
  const int cap = 4096;
  const int referenceSamples = o.quick ? 1024 : 16384;
  const int repeats = o.quick ? 1 : 3;
  Progress progress("chart adaptive",
                    1 + (3 * counts.size() + targets.size()) * size_t(repeats),
                    "bakes", o.progress);
  auto timedBake = [&](const LightmapBakeSettings& settings, double* seconds) {
    return timedLightmapBake(*scene, path, settings, o.cancel, progress, seconds);
  };
  double refSeconds = 0.0;
  Result<LightmapBakeResult> reference =
      timedBake(referenceSettings(s, referenceSamples, o.seed), &refSeconds);
  if (!reference) return Error{reference.error()};

  // kind: "fixed" (full paths), "adaptive" (errorTarget), "gather" (a bounce cache of
  // kGatherCache paths, fixed counts), "gather adaptive" (the same, Neyman allocation).
  constexpr int kGatherCache = 8;
  struct Variant {
    const char* kind;
    float target;
    int samples;
  };
  std::vector<Variant> variants;
  for (int c : counts) variants.push_back({"fixed", 0.0f, c});
  for (float e : targets) variants.push_back({"adaptive", e, cap});
  for (int c : counts) variants.push_back({"gather", 0.0f, c});
  for (int c : counts) variants.push_back({"gather adaptive", 0.0f, c});
  struct Cell {
    std::vector<double> wall;
    ErrorSums error;
    uint64_t rays = 0;
    double meanSamples = 0.0;
  };
  std::vector<Cell> cells(variants.size());
  for (int r = 0; r < repeats; ++r)
    for (size_t v = 0; v < variants.size(); ++v) {
      LightmapBakeSettings settings = s;
      settings.samplesPerTexel = variants[v].samples;
      settings.errorTarget = variants[v].target;
      const std::string kind = variants[v].kind;
      settings.bounceCacheSamples = kind.rfind("gather", 0) == 0 ? kGatherCache : 0;
      settings.adaptiveSamples = kind == "gather adaptive";
      double wall = 0.0;
      Result<LightmapBakeResult> bake = timedBake(settings, &wall);
      if (!bake) return Error{bake.error()};
      cells[v].wall.push_back(wall);
      if (r == 0) {
        cells[v].error = compareBakes(*bake, *reference);
        cells[v].rays = bake->stats.rays;
        cells[v].meanSamples = bake->stats.meanSamples;
      }
    }
  progress.finish();

  ChartTable t;
  t.name = "lightmap_adaptive";
  t.title = "Lightmap: bake time vs error, fixed, adaptive and gather (cornell_box, denoised)";
  t.columns = {"variant", "error_target", "mean_samples", "relative_rms_error", "mean_ratio",
               "bake_seconds", "rays", "repeats", "reference_samples"};
  for (size_t v = 0; v < variants.size(); ++v) {
    const Cell& c = cells[v];
    t.addRow({variants[v].kind, num(variants[v].target),
              num(c.meanSamples), num(c.error.relative()), num(c.error.ratio()),
              num(median(c.wall)), std::to_string(c.rays), std::to_string(repeats),
              std::to_string(referenceSamples)});
  }
  t.notes = commonNotes(o, o.threads);
  t.notes.push_back("chart 7: lightmap bake time vs error, fixed samples per texel vs adaptive "
                    "sampling (errorTarget, cap " + std::to_string(cap) + "), denoiser on; "
                    "gather = a bounce cache of " + std::to_string(kGatherCache) +
                    " paths per texel read at the paths' first hit (--bounce-cache), fixed "
                    "counts; gather adaptive = the same total of paths by Neyman allocation "
                    "from the cache's spread (--adaptive)");
  t.notes.push_back("scene: " + path + "; settings as chart 1 (resolution " + num(s.resolution) +
                    ", 3 bounces, supersampling 1, stitching off)");
  t.notes.push_back("baseline: a " + std::to_string(referenceSamples) +
                    "-sample bake with the denoiser off and an independent seed (" +
                    num(refSeconds) + " s); error as chart 1");
  t.plot =
      "set logscale xy\n"
      "set format y '%g'\n"
      "set xlabel 'bake time (s)'\n"
      "set ylabel 'relative RMS error vs reference'\n"
      "set key top right\n"
      "plot @CSV@ using 'bake_seconds':(strcol('variant') eq 'fixed' ? "
      "column('relative_rms_error') : NaN) with linespoints lw 2 pt 7 title 'fixed samples', "
      "\\\n  '' using 'bake_seconds':(strcol('variant') eq 'adaptive' ? "
      "column('relative_rms_error') : NaN) with linespoints lw 2 pt 5 title 'adaptive', "
      "\\\n  '' using 'bake_seconds':(strcol('variant') eq 'gather' ? "
      "column('relative_rms_error') : NaN) with linespoints lw 2 pt 9 title 'gather (bounce "
      "cache)', \\\n  '' using 'bake_seconds':(strcol('variant') eq 'gather adaptive' ? "
      "column('relative_rms_error') : NaN) with linespoints lw 2 pt 11 title 'gather, "
      "adaptive'\n";
  return t;
}

}  // namespace kiln::chart
