// chart_command.cpp: `kiln chart --out DIR [--quick]`: speed-against-accuracy charts (CSV +
// gnuplot PNG per chart). Thin over tools/chart (chart_runner.h); what each chart measures
// and how: docs/charts.md.
#include <iostream>
#include <memory>

#include "src/progress.h"
#include "tools/chart/chart_runner.h"
#include "tools/kiln/cli_common.h"

namespace kiln::cli {
namespace {

struct ChartCommandOptions {
  std::string out;
  bool quick = false;
  std::vector<std::string> only;
  std::string scenes = chart::defaultScenesDir();
  std::string shared = chart::defaultSharedDir();
  uint64_t seed = 0;
  int threads = 0;
  bool quiet = false;
};

int runChart(const ChartCommandOptions& o) {
  chart::ChartOptions options;
  options.quick = o.quick;
  options.scenesDir = o.scenes;
  options.sharedDir = o.shared;
  options.seed = o.seed;
  options.threads = o.threads;
  options.progress = !o.quiet;
  options.command = "kiln chart --out " + o.out + (o.quick ? " --quick" : "");
  for (const std::string& n : o.only) options.command += " --only " + n;
  if (o.seed) options.command += " --seed " + std::to_string(o.seed);
  // Before any work: a bad --out fails now, not after minutes of measuring.
  if (int code = checkOutputDirectory("--out", o.out)) return code;
  installInterruptHandler();
  options.cancel = &cancelFlag();
  Result<chart::ChartRunReport> report = chart::runCharts(options, o.out, o.only);
  if (cancelFlag().load()) return reportInterrupted("charts not finished");
  if (!report) {
    printError(report.error());
    return kExitBadInput;
  }
  for (const std::string& s : report->skipped) printWarning(s);
  if (!o.quiet)
    for (const std::string& f : report->written) std::cerr << "kiln: wrote " << f << "\n";
  if (report->gnuplotMissing) {
    printError("gnuplot not found on PATH: the CSVs are in " + o.out +
               " but no PNG was drawn; install the Debian package gnuplot-nox "
               "(tools/install_deps.sh)");
    return kExitBadInput;
  }
  return kExitOk;
}

}  // namespace

void registerChartCommand(CLI::App& app) {
  auto o = std::make_shared<ChartCommandOptions>();
  CLI::App* c = app.add_subcommand(
      "chart",
      "Speed-against-accuracy charts (CSV + gnuplot PNG each): lightmap samples vs error vs "
      "time, probe placement, L1/L2 SH irradiance, TetGen vs CGAL, lookup throughput, probe "
      "visibility leak vs map size");
  c->add_option("--out,-o", o->out, "Output directory (created; files replaced atomically)")
      ->required();
  c->add_flag("--quick", o->quick, "Small sizes (seconds): for tests and a first look");
  c->add_option("--only", o->only,
                "Only these charts (repeatable): lightmap, placement, sh, tetrahedralization, "
                "lookup, visibility")
      ->check(CLI::IsMember(chart::chartNames()));
  c->add_option("--scenes", o->scenes, "Directory of cornell_box.gltf and two_rooms.gltf")
      ->capture_default_str();
  c->add_option("--shared", o->shared, "The shared data directory (scenes/envmaps/*.hdr)")
      ->capture_default_str();
  c->add_option("--seed", o->seed, "Seed of every random number")->capture_default_str();
  c->add_option("--threads", o->threads,
                "Worker threads for bakes and error measurement (0 = all cores); lookups and "
                "tetrahedralization are timed on one thread")
      ->check(CLI::NonNegativeNumber);
  c->add_flag("--quiet,-q", o->quiet, "No progress on stderr");
  c->callback(commandCallback([o]() { return runChart(*o); }));
}

}  // namespace kiln::cli
