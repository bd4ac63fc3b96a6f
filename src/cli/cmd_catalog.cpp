// Placeholder registration; the glass-catalog work replaces this file.
#include "commands.h"

namespace lensopt::cli {
void setup_catalog(CLI::App& app) { app.add_subcommand("catalog", "list a glass catalog"); }
}  // namespace lensopt::cli
