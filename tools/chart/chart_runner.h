// chart_runner.h: `kiln chart`'s whole run: measure the selected charts (chart_measure.h),
// write DIR/<name>.csv for each, then draw DIR/<name>.png with gnuplot (chart_table.h).
#pragma once

#include <string>
#include <vector>

#include "kiln/result.h"
#include "tools/chart/chart_measure.h"

namespace kiln::chart {

// The charts by the names `--only` takes, in order: lightmap, placement, sh,
// tetrahedralization, lookup, visibility.
const std::vector<std::string>& chartNames();

struct ChartRunReport {
  std::vector<std::string> written;   // files written (CSV and PNG paths)
  std::vector<std::string> skipped;   // why a chart was skipped (e.g. no ../shared)
  std::string gnuplot;                // the gnuplot used, "" when missing
  bool gnuplotMissing = false;        // CSVs were written, PNGs were not
};

// Where the shipped scenes (tools/scenes) and ../shared are in the source tree this was built
// from (the defaults of `kiln chart --scenes / --shared`).
std::string defaultScenesDir();
std::string defaultSharedDir();

// Runs the charts named in `only` (all when empty) into `outDir` (created when missing). A
// chart that fails stops the run with its error (files of earlier charts stay written); a
// missing gnuplot is not an error here (report.gnuplotMissing: the caller decides).
Result<ChartRunReport> runCharts(const ChartOptions& options, const std::string& outDir,
                                 const std::vector<std::string>& only = {});

}  // namespace kiln::chart
