// Placeholder registration until the `optimize` command lands; it says so when run.
#include "commands.h"
#include "lensopt/core/error.h"

namespace lensopt::cli {
void setup_optimize(CLI::App& app) {
  CLI::App* sub = app.add_subcommand("optimize", "spot-size optimization (not built yet)");
  sub->allow_extras();
  sub->callback([] { throw Error("'optimize' is not implemented in this build yet"); });
}
}  // namespace lensopt::cli
