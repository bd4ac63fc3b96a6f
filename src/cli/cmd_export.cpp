// Placeholder registration until the `export` command lands; it says so when run.
#include "commands.h"
#include "lensopt/core/error.h"

namespace lensopt::cli {
void setup_export(CLI::App& app) {
  CLI::App* sub = app.add_subcommand("export", "export PSF grids and maps (not built yet)");
  sub->allow_extras();
  sub->callback([] { throw Error("'export' is not implemented in this build yet"); });
}
}  // namespace lensopt::cli
