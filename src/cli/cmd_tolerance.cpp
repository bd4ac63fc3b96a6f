// Placeholder registration until the `tolerance` command lands; it says so when run.
#include "commands.h"
#include "lensopt/core/error.h"

namespace lensopt::cli {
void setup_tolerance(CLI::App& app) {
  CLI::App* sub = app.add_subcommand("tolerance", "Monte-Carlo tolerancing (not built yet)");
  sub->allow_extras();
  sub->callback([] { throw Error("'tolerance' is not implemented in this build yet"); });
}
}  // namespace lensopt::cli
