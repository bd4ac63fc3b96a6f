// Checks of a lens that every command shares (commands.h).
#include "lens_checks.h"

#include <fmt/core.h>

#include "lensopt/core/error.h"
#include "lensopt/lens/validate.h"

namespace lensopt::cli {

void check_glass_ranges(const Lens& lens, const char* command, bool strict) {
  const std::vector<std::string> warnings = glass_range_warnings(lens);
  if (warnings.empty()) return;
  if (strict)
    throw Error(SourceLocation{lens.source_path}, warnings.front() + " (refused with --strict)");
  for (const std::string& w : warnings) fmt::print(stderr, "lensopt {}: warning: {}\n", command, w);
}

}  // namespace lensopt::cli
