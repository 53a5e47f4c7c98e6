// chart_sh.cpp: chart 3, SH irradiance against the exact irradiance: L1, raw L2, L2 deringed
// by the old window and by the fit the bake uses, and a fixed Hanning window. Cases: the HDR
// environment maps of ../shared/scenes/envmaps (brute-force cosine integration of every
// pixel), the same maps with a sun added (a delta whose L2 series rings below zero), and the
// 20 points of the Cycles probe reference (../shared/reference/cornell_box; chart_measure.h,
// docs/charts.md).
#include <algorithm>
#include <cmath>
#include <filesystem>

#include "src/image.h"
#include "src/parallel.h"
#include "src/progress.h"
#include "src/sh_projection.h"
#include "tools/chart/chart_measure.h"
#include "tools/chart/probe_reference.h"

namespace kiln::chart {
namespace {

// Sun irradiance (white, on a surface facing it) added to each map, in multiples of the map's
// own mean irradiance (pi x mean radiance): an outdoor sun gives 5-10x the sky's light.
constexpr double kSunOverSky = 8.0;

// One probe of a case: its raw L2 radiance SH and the exact irradiance at some normals.
struct CaseProbe {
  ShL2Rgb l2;
  std::vector<vec3> normals;
  std::vector<glm::dvec3> exact;
};

struct ShCase {
  std::string name;
  std::vector<CaseProbe> probes;
};

// The SH forms charted, in column order.
enum Method { kL1, kL2, kWindow, kFit, kHanning, kMethodCount };
constexpr const char* kMethodNames[kMethodCount] = {"L1", "L2", "L2 window", "L2 fit",
                                                    "L2 Hanning"};

// Brute force: E(n) = sum over pixels of L max(0, n . d) dOmega (pixel-centre directions,
// exact pixel solid angles), in double, at every normal.
Result<std::vector<glm::dvec3>> bruteForceIrradiance(const Image& map,
                                                     const std::vector<vec3>& normals,
                                                     const ChartOptions& o) {
  std::vector<vec3> dirs;
  std::vector<glm::dvec3> weighted;
  for (int y = 0; y < map.height; ++y) {
    const double dOmega = equirectPixelSolidAngle(y, map.width, map.height);
    for (int x = 0; x < map.width; ++x) {
      dirs.push_back(equirectDirection((x + 0.5f) / map.width, (y + 0.5f) / map.height));
      weighted.push_back(glm::dvec3(map.rgb(x, y)) * dOmega);
    }
  }
  std::vector<glm::dvec3> exact(normals.size());
  ParallelOptions po;
  po.threads = o.threads;
  po.grain = 8;
  po.cancel = o.cancel;
  if (!parallelFor(
          normals.size(),
          [&](size_t begin, size_t end) {
            for (size_t k = begin; k < end; ++k) {
              glm::dvec3 e(0.0);
              for (size_t p = 0; p < dirs.size(); ++p) {
                const double c = double(glm::dot(normals[k], dirs[p]));
                if (c > 0.0) e += weighted[p] * c;
              }
              exact[k] = e;
            }
          },
          po))
    return Error{"cancelled"};
  return exact;
}

// The brightest pixel's direction (the map's own sun, where there is one).
vec3 brightestDirection(const Image& map) {
  float best = -1.0f;
  vec3 dir(0.0f, 1.0f, 0.0f);
  for (int y = 0; y < map.height; ++y)
    for (int x = 0; x < map.width; ++x) {
      const vec3 c = map.rgb(x, y);
      if (c.x + c.y + c.z > best) {
        best = c.x + c.y + c.z;
        dir = equirectDirection((x + 0.5f) / map.width, (y + 0.5f) / map.height);
      }
    }
  return dir;
}

// "none needed", or how many probes a deringing changed (and the window's width for one).
std::string deringNote(const std::string& what, int changed, size_t probes, float width) {
  if (changed == 0) return "none needed";
  if (probes == 1) return what + (width > 0.0f ? " width " + num(width) : "");
  return what + " on " + std::to_string(changed) + " of " + std::to_string(probes) + " probes";
}

}  // namespace

Result<ChartTable> shIrradianceChart(const ChartOptions& o) {
  ChartTable t;
  t.name = "sh_irradiance";
  t.title = "SH irradiance vs exact: L1, L2, L2 deringed by window (old) and by fit (bake)";
  const std::string dir = o.sharedDir + "/scenes/envmaps";
  const std::string refPath = o.sharedDir + "/reference/cornell_box/probes.json";
  std::vector<std::string> maps;
  std::error_code ec;
  if (std::filesystem::is_directory(dir, ec))
    for (const auto& entry : std::filesystem::directory_iterator(dir, ec))
      if (entry.path().extension() == ".hdr") maps.push_back(entry.path().string());
  std::sort(maps.begin(), maps.end());
  if (maps.empty()) {
    t.skipped = dir + " has no .hdr maps (../shared is absent): chart 3 skipped";
    return t;
  }

  const int normalCount = o.quick ? 256 : 4096;
  const std::vector<vec3> normals = fibonacciSphere(normalCount);
  std::vector<ShCase> cases;
  Progress progress("chart sh", maps.size(), "maps", o.progress);
  std::vector<std::string> sizes;
  for (const std::string& path : maps) {
    if (o.cancel && o.cancel->load()) return Error{"cancelled"};
    Result<Image> img = readHdrImage(path);
    if (!img) return Error{img.error()};
    const Image& map = *img;
    const std::string name = std::filesystem::path(path).stem().string();
    sizes.push_back(name + " " + std::to_string(map.width) + "x" + std::to_string(map.height));
    Result<std::vector<glm::dvec3>> exact = bruteForceIrradiance(map, normals, o);
    if (!exact) return Error{exact.error()};
    CaseProbe plain{projectEquirect(map), normals, *exact};
    // + a sun from the brightest pixel's direction: radiance E_s delta(w - s), SH c_i += E_s
    // Y_i(s) exactly, irradiance E_s max(0, n.s) exactly.
    const vec3 s = brightestDirection(map);
    const double meanE = kPi * double(glm::dot(plain.l2.c[0], vec3(1.0f / 3.0f))) * 0.282095;
    const float sun = float(kSunOverSky * meanE);
    CaseProbe withSun = plain;
    withSun.l2.addSample(s, vec3(sun), 1.0f);
    for (size_t k = 0; k < normals.size(); ++k)
      withSun.exact[k] += double(sun) * std::max(0.0, double(glm::dot(normals[k], s)));
    cases.push_back({name, {plain}});
    cases.push_back({name + " + sun", {withSun}});
    progress.advance();
  }
  progress.finish();
  // The Cycles points: each its own L2 projection (of a panorama), exact E at 6 axes.
  std::vector<ProbeReferencePoint> reference;
  if (std::filesystem::exists(refPath)) {
    Result<std::vector<ProbeReferencePoint>> loaded = loadProbeReference(refPath);
    if (!loaded) return Error{loaded.error()};
    reference = std::move(loaded).value();
  }
  if (!reference.empty()) {
    ShCase cornell{"Cornell (Cycles)", {}};
    for (const ProbeReferencePoint& p : reference)
      cornell.probes.push_back(
          {p.sh, std::vector<vec3>(kReferenceAxes.begin(), kReferenceAxes.end()),
           std::vector<glm::dvec3>(p.exact.begin(), p.exact.end())});
    cases.push_back(cornell);
  }

  t.columns = {"case", "case_index", "method", "method_index", "deringing", "avg_rel_error",
               "median_rel_error", "p90_rel_error", "max_rel_error", "avg_error_over_max",
               "max_error_over_max", "rms_error_over_max", "min_irradiance_over_max"};
  // A fixed window for every case as well: Hanning of width 3 bands (w = 1, 0.75, 0.25), the
  // kind of window a renderer applies without looking (Sloan 2008), so that the chart shows
  // what windowing costs even where no deringing is needed.
  const std::array<float, 3> hanningFactors = shWindowFactors(ShWindowKind::kHanning, 3.0f);
  for (size_t c = 0; c < cases.size(); ++c) {
    const ShCase& sc = cases[c];
    // Per probe, the five forms (L1 as its L2 embedding: bands 0-1, band 2 zero).
    std::vector<std::array<ShL2Rgb, kMethodCount>> forms;
    int windowed = 0, fitted = 0;
    float width = 0.0f;
    for (const CaseProbe& p : sc.probes) {
      const WindowDeringResult w = windowDeringSh(p.l2);
      const DeringResult f = deringSh(p.l2);
      windowed += w.changed;
      fitted += f.changed;
      if (w.changed) width = w.width;
      ShL2Rgb l1 = p.l2;
      for (int i = kShL1Count; i < kShL2Count; ++i) l1.c[i] = vec3(0.0f);
      forms.push_back({l1, p.l2, w.sh, f.sh, windowSh(p.l2, hanningFactors)});
    }
    glm::dvec3 eMax(0.0);
    for (const CaseProbe& p : sc.probes)
      for (const glm::dvec3& e : p.exact) eMax = glm::max(eMax, e);
    for (int m = 0; m < kMethodCount; ++m) {
      std::vector<double> rel;
      double sumNorm = 0, maxNorm = 0, sumSq = 0, minE = kInfinity;
      for (size_t q = 0; q < sc.probes.size(); ++q) {
        const CaseProbe& p = sc.probes[q];
        const ShL2Rgb& sh = forms[q][size_t(m)];
        for (size_t i = 0; i < p.normals.size(); ++i) {
          const vec3 approx = m == kL1 ? reduceToL1(sh).irradiance(p.normals[i])
                                       : sh.irradiance(p.normals[i]);
          for (int ch = 0; ch < 3; ++ch) {
            const double err = std::abs(double(approx[ch]) - p.exact[i][ch]);
            rel.push_back(p.exact[i][ch] > 0.0 ? err / p.exact[i][ch] : 0.0);
            sumNorm += err / eMax[ch];
            maxNorm = std::max(maxNorm, err / eMax[ch]);
            sumSq += (err / eMax[ch]) * (err / eMax[ch]);
            minE = std::min(minE, double(approx[ch]) / eMax[ch]);
          }
        }
        // The exact minimum over the whole sphere for the L2 forms (sh_projection.h), which a
        // set of normals only bounds from above.
        if (m != kL1) {
          const vec3 mn = minIrradiance(sh);
          for (int ch = 0; ch < 3; ++ch) minE = std::min(minE, double(mn[ch]) / eMax[ch]);
        }
      }
      double sumRel = 0, maxRel = 0;
      for (double r : rel) sumRel += r, maxRel = std::max(maxRel, r);
      const double count = double(rel.size());
      std::string note = "none";
      if (m == kWindow) note = deringNote("sinc4", windowed, sc.probes.size(), width);
      if (m == kFit) note = deringNote("fit", fitted, sc.probes.size(), 0.0f);
      if (m == kHanning)
        note = "hanning width 3 (" + num(hanningFactors[1]) + ", " + num(hanningFactors[2]) + ")";
      t.addRow({sc.name, std::to_string(c), kMethodNames[m], std::to_string(m), note,
                num(sumRel / count), num(quantile(rel, 0.5)), num(quantile(rel, 0.9)),
                num(maxRel), num(sumNorm / count), num(maxNorm), num(std::sqrt(sumSq / count)),
                num(minE)});
    }
  }

  std::string sizeList;
  for (const std::string& s : sizes) sizeList += (sizeList.empty() ? "" : ", ") + s;
  t.notes = commonNotes(o, o.threads);
  t.notes.push_back("chart 3: SH irradiance against the exact irradiance; L1, L2, L2 deringed "
                    "by the old window and by the bake's fit, a fixed Hanning window");
  t.notes.push_back("maps: " + dir + " (" + sizeList + "); '+ sun': a white sun of " +
                    num(kSunOverSky) + "x the map's mean irradiance from its brightest pixel, "
                    "an exact delta in the SH and E_s max(0, n.s) in the exact irradiance");
  t.notes.push_back("Cornell (Cycles): " + refPath + ", 20 points, each its own L2 (Cycles' "
                    "projection of a panorama) against the exact irradiance at the 6 axes");
  t.notes.push_back("SH: projectEquirect (exact per-pixel basis integrals), irradiance by "
                    "Ramamoorthi-Hanrahan (A0 = pi, A1 = 2pi/3, A2 = pi/4); L1 = bands 0-1; "
                    "L2 window = windowDeringSh sinc^4 (the weakest window making E >= 0, the "
                    "bake's deringing before issue 13); L2 fit = deringSh (the nearest SH in "
                    "irradiance with E >= 0, c0 kept: the bake's deringing); both leave an SH "
                    "whose E is already >= 0 unchanged; L2 Hanning = a fixed Hanning window of "
                    "width 3");
  t.notes.push_back("baseline for maps: brute-force irradiance E(n) = sum over all pixels of L "
                    "max(0, n.d) dOmega at " + std::to_string(normalCount) +
                    " Fibonacci-sphere normals, per RGB channel");
  t.notes.push_back("errors per normal and channel: rel = |E_sh - E| / E (median, p90 and max "
                    "over normals and channels); over_max = |E_sh - E| / (the channel's "
                    "largest E in the case); min_irradiance_over_max = smallest E_sh / max E "
                    "(exact minimum over the sphere for the L2 forms; negative = the SH rings "
                    "below zero)");

  std::string caseTics;
  for (size_t c = 0; c < cases.size(); ++c)
    caseTics += (c ? ", '" : "'") + cases[c].name + "' " + std::to_string(c);
  t.width = 1100;
  t.height = 850;
  // Two panels on the same cases: the relative error per normal (median as boxes, p90 as
  // crosses), and the RMS error over the sphere relative to the largest E (the L2 norm that
  // the raw projection minimises and the fit stays nearest to).
  auto bars = [](const std::string& column, const std::string& what) {
    return "plot for [k=0:4] @CSV@ using (column('case_index') + 0.16 * (k - 2)):"
           "(column('method_index') == k ? column('" + column + "') : NaN) with boxes lc k+1 "
           "title word('L1 L2 L2-window L2-fit L2-Hanning', k+1).' (" + what + ")'";
  };
  t.plot =
      "set multiplot layout 2,1 title '" + t.title + "' noenhanced\n"
      "unset title\n"
      "set style fill solid 0.8 border -1\n"
      "set boxwidth 0.15\n"
      "set xrange [-0.5:" + num(double(cases.size()) - 0.5) + "]\n"
      "set logscale y\n"
      "set format y '%g'\n"
      "set xtics scale 0 (" + caseTics + ")\n"
      "set key outside right font ',8'\n"
      "set ylabel 'relative error |E_{SH} - E| / E'\n" +
      bars("median_rel_error", "median") + ", \\\n"
      "  for [k=0:4] @CSV@ using (column('case_index') + 0.16 * (k - 2)):"
      "(column('method_index') == k ? column('p90_rel_error') : NaN) with points pt 2 ps 1.5 "
      "lw 2 lc k+1 title word('L1 L2 L2-window L2-fit L2-Hanning', k+1).' (p90)'\n"
      "set ylabel 'RMS error over the sphere / max E'\n" +
      bars("rms_error_over_max", "RMS") + "\n"
      "unset multiplot\n";
  return t;
}

}  // namespace kiln::chart
