// main.cpp: the `kiln` command line tool. Builds the CLI11 App, registers the subcommands
// (each in its own *_command.cpp, declared in cli_common.h), parses and maps every outcome to
// an exit code: 0 ok, 1 bad input, 2 bad usage.
#include <exception>
#include <iostream>
#include <string>

#include "src/distributed.h"
#include "tools/kiln/cli_common.h"

#ifndef KILN_VERSION
#define KILN_VERSION "0.1.0"  // keep in step with project(VERSION) in CMakeLists.txt
#endif

int main(int argc, char** argv) {
  using namespace kiln::cli;
  CLI::App app{"kiln: baked global illumination (lightmaps and light probes) for glTF 2.0 scenes",
               "kiln"};
  app.set_version_flag("--version", std::string("kiln ") + KILN_VERSION);
  app.require_subcommand(1);
  registerInfoCommand(app);
  registerBakeCommand(app);
  registerProbesCommand(app);
  registerRenderCommand(app);
  registerChartCommand(app);

  int code = kExitOk;
  try {
    app.parse(argc, argv);
  } catch (const CLI::Success& e) {  // --help, --help-all, --version
    code = app.exit(e);
  } catch (const CLI::RuntimeError& e) {
    code = e.get_exit_code();  // a subcommand's own failure, already reported
  } catch (const CLI::ParseError& e) {
    printError(std::string(e.what()) + " (run 'kiln --help' for usage)");
    code = kExitBadUsage;
  } catch (const std::exception& e) {
    // A bug or an exhausted resource: report it rather than abort. In a distributed bake
    // this rank alone may have failed: say which, and end the job.
    if (kiln::distributedActive())
      kiln::distributedAbort(std::string("unexpected failure: ") + e.what(), kExitBadInput);
    printError(std::string("unexpected failure: ") + e.what());
    code = kExitBadInput;
  }
  // A distributed bake (src/distributed.h) ends on every rank here.
  finishDistributedJob(code);
  return code;
}
