// chart_sh.cpp: chart 3, L1 vs L2 vs windowed L2 irradiance error on the HDR environment maps
// of ../shared/scenes/envmaps, against brute-force cosine integration of every pixel
// (chart_measure.h, docs/charts.md).
#include <algorithm>
#include <cmath>
#include <filesystem>

#include "src/image.h"
#include "src/parallel.h"
#include "src/progress.h"
#include "src/sh_projection.h"
#include "tools/chart/chart_measure.h"

namespace kiln::chart {
namespace {

struct Method {
  std::string name;
  std::string window;  // what window was applied
  std::function<vec3(vec3)> irradiance;
};

}  // namespace

Result<ChartTable> shIrradianceChart(const ChartOptions& o) {
  ChartTable t;
  t.name = "sh_irradiance";
  t.title = "SH irradiance: L1 vs L2 vs windowed L2, error vs brute-force integration";
  const std::string dir = o.sharedDir + "/scenes/envmaps";
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
  t.columns = {"map", "map_index", "method", "method_index", "window", "avg_rel_error",
               "max_rel_error", "avg_error_over_max", "max_error_over_max", "rms_error_over_max",
               "min_irradiance_over_max"};
  Progress progress("chart sh", maps.size(), "maps", o.progress);
  std::vector<std::string> sizes;
  for (size_t m = 0; m < maps.size(); ++m) {
    if (o.cancel && o.cancel->load()) return Error{"cancelled"};
    Result<Image> img = readHdrImage(maps[m]);
    if (!img) return Error{img.error()};
    const Image& map = *img;
    const std::string name = std::filesystem::path(maps[m]).stem().string();
    sizes.push_back(name + " " + std::to_string(map.width) + "x" + std::to_string(map.height));

    // Brute force: E(n) = sum over pixels of L max(0, n . d) dOmega (pixel-centre directions,
    // exact pixel solid angles), in double.
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
    glm::dvec3 eMax(0.0);
    for (const glm::dvec3& e : exact) eMax = glm::max(eMax, e);

    const ShL2Rgb l2 = projectEquirect(map);
    const ShL1Rgb l1 = reduceToL1(l2);
    const WindowDeringResult dering = windowDeringSh(l2, ShWindowKind::kSinc4);
    // A fixed window for every map as well: Hanning of width 3 bands (w = 1, 0.75, 0.25), the
    // kind of window a renderer applies without looking (Sloan 2008), so that the chart shows
    // what windowing costs even on maps that need no deringing.
    const std::array<float, 3> hanningFactors = shWindowFactors(ShWindowKind::kHanning, 3.0f);
    const ShL2Rgb hanning = windowSh(l2, hanningFactors);
    std::vector<Method> methods = {
        {"L1", "none", [&](vec3 n) { return l1.irradiance(n); }},
        {"L2", "none", [&](vec3 n) { return l2.irradiance(n); }},
        {"L2 deringed", dering.changed ? "sinc4 width " + num(dering.width) : "none needed",
         [&](vec3 n) { return dering.sh.irradiance(n); }},
        {"L2 Hanning", "hanning width 3 (" + num(hanningFactors[1]) + ", " +
                           num(hanningFactors[2]) + ")",
         [&](vec3 n) { return hanning.irradiance(n); }},
    };
    for (size_t k = 0; k < methods.size(); ++k) {
      double sumRel = 0, maxRel = 0, sumNorm = 0, maxNorm = 0, sumSq = 0, minE = kInfinity;
      int count = 0;
      for (size_t i = 0; i < normals.size(); ++i) {
        const vec3 approx = methods[k].irradiance(normals[i]);
        for (int c = 0; c < 3; ++c) {
          const double err = std::abs(double(approx[c]) - exact[i][c]);
          const double rel = exact[i][c] > 0.0 ? err / exact[i][c] : 0.0;
          sumRel += rel;
          maxRel = std::max(maxRel, rel);
          sumNorm += err / eMax[c];
          maxNorm = std::max(maxNorm, err / eMax[c]);
          sumSq += (err / eMax[c]) * (err / eMax[c]);
          minE = std::min(minE, double(approx[c]) / eMax[c]);
          ++count;
        }
      }
      // The exact minimum over the whole sphere for the L2 forms (sh_projection.h), which a
      // dense set of normals only bounds from above.
      if (k >= 1) {
        const ShL2Rgb& sh = k == 1 ? l2 : (k == 2 ? dering.sh : hanning);
        const vec3 mn = minIrradiance(sh);
        for (int c = 0; c < 3; ++c) minE = std::min(minE, double(mn[c]) / eMax[c]);
      }
      t.addRow({name, std::to_string(m), methods[k].name, std::to_string(k), methods[k].window,
                num(sumRel / count), num(maxRel), num(sumNorm / count), num(maxNorm),
                num(std::sqrt(sumSq / count)), num(minE)});
    }
    progress.advance();
  }
  progress.finish();

  std::string sizeList;
  for (const std::string& s : sizes) sizeList += (sizeList.empty() ? "" : ", ") + s;
  t.notes = commonNotes(o, o.threads);
  t.notes.push_back("chart 3: L1 vs L2 vs windowed L2 irradiance error on HDR environment maps");
  t.notes.push_back("maps: " + dir + " (" + sizeList + ")");
  t.notes.push_back("SH: projectEquirect (exact per-pixel basis integrals), irradiance by "
                    "Ramamoorthi-Hanrahan (A0 = pi, A1 = 2pi/3, A2 = pi/4); L1 = bands 0-1; "
                    "L2 deringed = windowDeringSh sinc^4 (the weakest window making E >= 0; the L2 "
                    "itself when E is already >= 0); L2 Hanning = a fixed Hanning window of "
                    "width 3");
  t.notes.push_back("baseline: brute-force irradiance E(n) = sum over all pixels of L max(0, "
                    "n.d) dOmega at " + std::to_string(normalCount) +
                    " Fibonacci-sphere normals, per RGB channel");
  t.notes.push_back("errors per normal and channel: rel = |E_sh - E| / E; over_max = |E_sh - "
                    "E| / (the channel's largest E over all normals); min_irradiance_over_max = "
                    "smallest E_sh / max E (exact minimum over the sphere for the L2 forms; "
                    "negative = the SH rings below zero)");

  std::string mapTics;
  for (size_t m = 0; m < maps.size(); ++m)
    mapTics += (m ? ", '" : "'") + std::filesystem::path(maps[m]).stem().string() + "' " +
               std::to_string(m);
  t.plot =
      "set style fill solid 0.8 border -1\n"
      "set boxwidth 0.18\n"
      "set xrange [-0.5:" + num(double(maps.size()) - 0.5) + "]\n"
      "set logscale y\n"
      "set ylabel 'relative irradiance error |E_{SH} - E| / E'\n"
      "set key below horizontal maxrows 2\n"
      "set format y '%g'\n"
      "set xtics scale 0 (" + mapTics + ")\n"
      "plot for [k=0:3] @CSV@ using (column('map_index') + 0.2 * (k - 1.5)):"
      "(column('method_index') == k ? column('avg_rel_error') : NaN) with boxes lc k+1 title "
      "word('L1 L2 L2-deringed L2-Hanning', k+1).' (average)', \\\n"
      "  for [k=0:3] @CSV@ using (column('map_index') + 0.2 * (k - 1.5)):"
      "(column('method_index') == k ? column('max_rel_error') : NaN) with points pt 2 ps 1.5 "
      "lw 2 lc k+1 title word('L1 L2 L2-deringed L2-Hanning', k+1).' (max)'\n";
  return t;
}

}  // namespace kiln::chart
