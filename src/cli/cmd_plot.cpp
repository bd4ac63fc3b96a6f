// Placeholder registration until the `plot` command lands; it says so when run.
#include "commands.h"
#include "lensopt/core/error.h"

namespace lensopt::cli {
void setup_plot(CLI::App& app) {
  CLI::App* sub = app.add_subcommand("plot", "plots (not built yet)");
  sub->allow_extras();
  sub->callback([] { throw Error("'plot' is not implemented in this build yet"); });
}
}  // namespace lensopt::cli
