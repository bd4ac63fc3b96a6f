// Placeholder registration until the `render` command lands; it says so when run.
#include "commands.h"
#include "lensopt/core/error.h"

namespace lensopt::cli {
void setup_render(CLI::App& app) {
  CLI::App* sub = app.add_subcommand("render", "render aberrated images (not built yet)");
  sub->allow_extras();
  sub->callback([] { throw Error("'render' is not implemented in this build yet"); });
}
}  // namespace lensopt::cli
