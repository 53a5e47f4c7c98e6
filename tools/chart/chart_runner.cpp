// chart_runner.cpp: `kiln chart`'s run over the six charts (chart_runner.h).
#include "tools/chart/chart_runner.h"

#include <algorithm>
#include <filesystem>
#include <functional>
#include <thread>

namespace kiln::chart {

const std::vector<std::string>& chartNames() {
  static const std::vector<std::string> names = {"lightmap",           "placement", "sh",
                                                 "tetrahedralization", "lookup",    "visibility",
                                                 "adaptive"};
  return names;
}

std::string defaultScenesDir() { return KILN_CHART_SCENES_DIR; }
std::string defaultSharedDir() { return KILN_CHART_SHARED_DIR; }

std::vector<std::string> commonNotes(const ChartOptions& o, int threadsUsed) {
  const unsigned hw = std::thread::hardware_concurrency();
  return {"made by: " + (o.command.empty() ? std::string("kiln chart") : o.command) +
              (o.quick ? " (--quick: small sizes)" : ""),
          "machine: " + machineDescription() + "; worker threads used: " +
              (threadsUsed > 0 ? std::to_string(threadsUsed)
                               : std::to_string(hw) + " (all cores)"),
          "seed: " + std::to_string(o.seed)};
}

Result<ChartRunReport> runCharts(const ChartOptions& options, const std::string& outDir,
                                 const std::vector<std::string>& only) {
  for (const std::string& n : only)
    if (std::find(chartNames().begin(), chartNames().end(), n) == chartNames().end())
      return Error{"unknown chart '" + n +
                   "' (expected lightmap, placement, sh, tetrahedralization, lookup, "
                   "visibility or adaptive)"};
  std::error_code ec;
  std::filesystem::create_directories(outDir, ec);
  if (ec || !std::filesystem::is_directory(outDir))
    return Error{outDir + ": cannot create the output directory" +
                 (ec ? ": " + ec.message() : std::string())};

  using Measure = std::function<Result<ChartTable>(const ChartOptions&)>;
  const std::vector<Measure> measures = {lightmapSamplesChart, probePlacementChart,
                                         shIrradianceChart,    tetrahedralizationChart,
                                         probeLookupChart,     probeVisibilityChart,
                                         lightmapAdaptiveChart};
  ChartRunReport report;
  report.gnuplot = findGnuplot();
  report.gnuplotMissing = report.gnuplot.empty();
  std::vector<ChartTable> tables;
  for (size_t i = 0; i < measures.size(); ++i) {
    if (!only.empty() && std::find(only.begin(), only.end(), chartNames()[i]) == only.end())
      continue;
    if (options.cancel && options.cancel->load()) return Error{"cancelled"};
    Result<ChartTable> table = measures[i](options);
    if (!table) return Error{"chart " + chartNames()[i] + ": " + table.error()};
    if (!table->skipped.empty()) {
      report.skipped.push_back(table->skipped);
      continue;
    }
    if (Status s = writeChartCsv(outDir, *table); !s) return Error{s.error()};
    report.written.push_back(outDir + "/" + table->name + ".csv");
    if (!report.gnuplotMissing) {
      if (Status s = renderChartPng(report.gnuplot, outDir, *table, table->width, table->height);
          !s)
        return Error{s.error()};
      report.written.push_back(outDir + "/" + table->name + ".png");
    }
  }
  return report;
}

}  // namespace kiln::chart
