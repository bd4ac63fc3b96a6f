// The lensopt subcommands. Each lives in its own file (cmd_<name>.cpp) with an options struct,
// a setup function that binds CLI11 options and a run function; main.cpp only registers them.
#pragma once

#include <CLI/CLI.hpp>

namespace lensopt::cli {

// Thrown by a run function to end the program with a given exit code after its output
// (e.g. `analyze --strict` with failing rays).
struct ExitCode {
  int code;
};

void setup_catalog(CLI::App& app);    // cmd_catalog.cpp
void setup_analyze(CLI::App& app);    // cmd_analyze.cpp
void setup_bench(CLI::App& app);      // cmd_bench.cpp
void setup_optimize(CLI::App& app);   // cmd_optimize.cpp
void setup_render(CLI::App& app);     // cmd_render.cpp
void setup_export(CLI::App& app);     // cmd_export.cpp
void setup_chart(CLI::App& app);      // cmd_chart.cpp
void setup_tolerance(CLI::App& app);  // cmd_tolerance.cpp
void setup_search(CLI::App& app);     // cmd_search.cpp
void setup_plot(CLI::App& app);       // cmd_plot.cpp
void setup_convert(CLI::App& app);    // cmd_convert.cpp

}  // namespace lensopt::cli
