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

void setup_catalog(CLI::App& app);
void setup_analyze(CLI::App& app);
void setup_bench(CLI::App& app);

}  // namespace lensopt::cli
