// Checks of a lens that every command shares (commands.h).
#include "lens_checks.h"

#include <fmt/core.h>

#include "lensopt/analysis/apertures.h"
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
  for (const SurfaceCrossing& x : crossing_surfaces(lens))
    fmt::print(stderr,
               "lensopt {}: warning: {}: surfaces {} and {} cross: the gap between them is "
               "{:.4g} mm at height {:.4g} mm, inside the rays' clear aperture (elements through "
               "each other, or a negative edge thickness); no lens can be made so\n",
               command, lens.source_path, x.first + 1, x.second + 1, x.gap_mm, x.height_mm);
}

}  // namespace lensopt::cli
