// lensopt: design compound camera lenses with exact, differentiable ray tracing.
#include <fmt/core.h>

#include <CLI/CLI.hpp>

#include "commands.h"
#include "lensopt/core/error.h"
#include "lensopt/core/passive_threads.h"

int main(int argc, char** argv) {
  lensopt::use_passive_omp_wait(argv);
  CLI::App app{"lensopt: compound lens design with exact, differentiable ray tracing"};
  app.require_subcommand(1);
  app.set_version_flag("--version", "lensopt 0.1.0");
  lensopt::cli::setup_catalog(app);
  lensopt::cli::setup_analyze(app);
  lensopt::cli::setup_bench(app);
  lensopt::cli::setup_optimize(app);
  lensopt::cli::setup_render(app);
  lensopt::cli::setup_export(app);
  lensopt::cli::setup_chart(app);
  lensopt::cli::setup_tolerance(app);
  lensopt::cli::setup_search(app);
  lensopt::cli::setup_plot(app);
  lensopt::cli::setup_convert(app);
  try {
    app.parse(argc, argv);
  } catch (const CLI::ParseError& e) {
    return app.exit(e);
  } catch (const lensopt::cli::ExitCode& e) {
    return e.code;
  } catch (const lensopt::Error& e) {
    fmt::print(stderr, "lensopt: error: {}\n", e.what());
    return 1;
  } catch (const std::exception& e) {
    fmt::print(stderr, "lensopt: internal error: {}\n", e.what());
    return 2;
  }
  return 0;
}
