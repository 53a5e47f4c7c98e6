// chart_table.h: one chart of `kiln chart` as data: the measured table (written as CSV whose
// first lines are '#' comments saying how it was measured) and the gnuplot commands that draw
// it as a PNG. Also the small helpers the measurements share (timing medians, the machine
// description, number formatting). Library kiln_chart (tools/chart), docs/charts.md.
#pragma once

#include <string>
#include <vector>

#include "kiln/result.h"

namespace kiln::chart {

struct ChartTable {
  std::string name;                // file stem: DIR/<name>.csv and DIR/<name>.png
  std::string title;               // the plot's title
  std::vector<std::string> notes;  // '#' comment lines (without the '# '): how it was measured
  std::vector<std::string> columns;
  std::vector<std::vector<std::string>> rows;  // each columns.size() cells
  // gnuplot commands after the common preamble (terminal, output, CSV separator and column
  // headers); "@CSV@" stands for the quoted CSV path.
  std::string plot;
  int width = 800, height = 500;  // the PNG's size in pixels
  // Non-empty: the chart could not be measured here (e.g. ../shared is absent); nothing is
  // written and this says why.
  std::string skipped;

  void addRow(std::vector<std::string> cells) { rows.push_back(std::move(cells)); }
  // Index of a column, -1 when absent.
  int column(const std::string& name) const;
};

// "%.6g" (locale-independent), "nan"/"inf" spelled as gnuplot and strtod read them.
std::string num(double v);

// The CSV text of a table: "# note" lines, the header line, the rows. Cells holding a comma
// or a quote are quoted.
std::string chartCsv(const ChartTable& table);

// Writes DIR/<name>.csv (temporary file, then rename).
Status writeChartCsv(const std::string& dir, const ChartTable& table);

// The gnuplot executable on PATH, "" when there is none.
std::string findGnuplot();

// Draws DIR/<name>.png from DIR/<name>.csv with gnuplot (size in pixels), through a temporary
// script and image that are removed or renamed. Errors carry gnuplot's own message.
Status renderChartPng(const std::string& gnuplot, const std::string& dir, const ChartTable& table,
                      int width = 800, int height = 500);

// "N hardware threads, <CPU model from /proc/cpuinfo>".
std::string machineDescription();

// Median of the values (the mean of the two middle ones for an even count); 0 when empty.
double median(std::vector<double> v);
// Quantile f in [0, 1] of the values, interpolated linearly between order statistics (f = 0.5
// is the median above); 0 when empty.
double quantile(std::vector<double> v, double f);

// Least-squares slope of log(y) against log(x) over the pairs with x, y > 0 (0 when fewer
// than two).
double logLogSlope(const std::vector<double>& x, const std::vector<double>& y);

}  // namespace kiln::chart
