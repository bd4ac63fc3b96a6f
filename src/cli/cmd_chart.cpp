// Placeholder registration until the `chart` command lands; it says so when run.
#include "commands.h"
#include "lensopt/core/error.h"

namespace lensopt::cli {
void setup_chart(CLI::App& app) {
  CLI::App* sub = app.add_subcommand("chart", "generate a test chart (not built yet)");
  sub->allow_extras();
  sub->callback([] { throw Error("'chart' is not implemented in this build yet"); });
}
}  // namespace lensopt::cli
