// The lensopt subcommands. Each lives in its own file (cmd_<name>.cpp) with an options struct,
// a setup function that binds CLI11 options and a run function; main.cpp only registers them.
#pragma once

#include <CLI/CLI.hpp>
#include <cmath>
#include <functional>
#include <string>
#include <vector>

namespace lensopt::cli {

// Thrown by a run function to end the program with a given exit code after its output
// (e.g. `analyze --strict` with failing rays).
struct ExitCode {
  int code;
};

// CLI11 check of a number option that must be finite: "nan" and "inf" parse as doubles, NaN is
// the commands' "not given" (a NaN typed in was ignored without a word), and CLI::Range and
// CLI::PositiveNumber let NaN through (every comparison with it is false).
inline const CLI::Validator kFinite(
    [](std::string& text) -> std::string {
      double value = 0;
      if (!CLI::detail::lexical_cast(text, value)) return "not a number: " + text;
      return std::isfinite(value) ? std::string() : "must be a finite number, not " + text;
    },
    "FINITE");

// What `optimize` passes to its --joint mode (cmd_optimize_joint.cpp): the options the two modes
// share. NaN / -1: not given.
struct OptimizeShared {
  std::string lens_path, output_path;
  bool in_place = false, json = false, quiet = false;
  int threads = -1;
  double weight_ray_path = NAN, weight_ray_angle = NAN, weight_glass = NAN;
  std::vector<std::string> freeze;
};
// Binds the joint options to `optimize` and returns the joint run.
std::function<void(const OptimizeShared&)> setup_optimize_joint(CLI::App& optimize);

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
