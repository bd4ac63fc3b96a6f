// Placeholder registration until the `convert` command lands; it says so when run.
#include "commands.h"
#include "lensopt/core/error.h"

namespace lensopt::cli {
void setup_convert(CLI::App& app) {
  CLI::App* sub = app.add_subcommand("convert", "convert lens formats (not built yet)");
  sub->allow_extras();
  sub->callback([] { throw Error("'convert' is not implemented in this build yet"); });
}
}  // namespace lensopt::cli
