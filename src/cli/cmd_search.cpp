// Placeholder registration until the `search` command lands; it says so when run.
#include "commands.h"
#include "lensopt/core/error.h"

namespace lensopt::cli {
void setup_search(CLI::App& app) {
  CLI::App* sub = app.add_subcommand("search", "batch baseline search (not built yet)");
  sub->allow_extras();
  sub->callback([] { throw Error("'search' is not implemented in this build yet"); });
}
}  // namespace lensopt::cli
