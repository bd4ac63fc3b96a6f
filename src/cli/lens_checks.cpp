// Checks of a lens that every command shares (commands.h).
#include "lens_checks.h"

#include <fmt/core.h>

#include "lensopt/core/error.h"
#include "lensopt/lens/validate.h"

namespace lensopt::cli {

void check_lens_warnings(const Lens& lens, const char* command, bool strict) {
  const std::vector<std::string> glass = glass_range_warnings(lens);
  if (strict && !glass.empty())
    throw Error(SourceLocation{lens.source_path}, glass.front() + " (refused with --strict)");
  for (const std::string& w : glass) fmt::print(stderr, "lensopt {}: warning: {}\n", command, w);
  for (const std::string& w : f_number_warnings(lens))
    fmt::print(stderr, "lensopt {}: warning: {}\n", command, w);
}

}  // namespace lensopt::cli
