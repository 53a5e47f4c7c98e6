// chart_measure.h: the measurements behind `kiln chart` (docs/charts.md), one function per
// chart, each returning the table and the gnuplot commands that draw it (chart_table.h).
//
//   1. lightmapSamplesChart: lightmap samples per texel vs relative error vs bake time;
//   2. probePlacementChart: probe count vs interpolation error for automatic placement, a
//      uniform grid and Godot-style octree corners;
//   3. shIrradianceChart: L1, L2 and deringed L2 (window, fit) against the exact irradiance
//      on HDR environment maps, the same with a sun, and the Cycles Cornell box points;
//   4. tetrahedralizationChart: TetGen vs CGAL tetrahedralization time;
//   5. probeLookupChart: lookups per second, hinted walk / unhinted / CGAL locate / brute force;
//   6. probeVisibilityChart: light leaking through a wall vs the size of the probes'
//      visibility maps (resolution 0 = plain blending to 32 x 32).
//
// Accuracy numbers are deterministic (keyed randomness, parallelFor); timings are medians of
// repeats interleaved between the variants of a chart in the same run, on this machine.
// Errors: scenes that do not load, bakes that fail, "cancelled" when *cancel becomes true.
#pragma once

#include <atomic>
#include <cstdint>
#include <string>

#include "kiln/result.h"
#include "tools/chart/chart_table.h"

namespace kiln::chart {

struct ChartOptions {
  bool quick = false;       // small sizes (seconds), for tests
  std::string scenesDir;    // tools/scenes (cornell_box.gltf, two_rooms.gltf)
  std::string sharedDir;    // ../shared (scenes/envmaps/*.hdr); may be absent
  uint64_t seed = 0;        // keys every random number
  int threads = 0;          // bakes and error measurement (0 = all cores); lookups: 1
  bool progress = true;     // progress lines on stderr
  const std::atomic<bool>* cancel = nullptr;
  std::string command;      // how the charts were made, recorded in the CSVs
};

Result<ChartTable> lightmapSamplesChart(const ChartOptions& options);
Result<ChartTable> probePlacementChart(const ChartOptions& options);
Result<ChartTable> shIrradianceChart(const ChartOptions& options);
Result<ChartTable> tetrahedralizationChart(const ChartOptions& options);
Result<ChartTable> probeLookupChart(const ChartOptions& options);
Result<ChartTable> probeVisibilityChart(const ChartOptions& options);
// Chart 7 (chart_lightmap.cpp): bake time vs error, fixed samples vs adaptive sampling.
Result<ChartTable> lightmapAdaptiveChart(const ChartOptions& options);

// Notes every chart's CSV starts with: the command, the machine, threads, seed.
std::vector<std::string> commonNotes(const ChartOptions& options, int threadsUsed);

}  // namespace kiln::chart
