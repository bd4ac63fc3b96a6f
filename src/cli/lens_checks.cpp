// Checks of a lens that every command shares (commands.h).
#include "lens_checks.h"

#include <fmt/core.h>

#include <string>

#include "lensopt/analysis/afocal.h"
#include "lensopt/analysis/apertures.h"
#include "lensopt/core/error.h"
#include "lensopt/lens/validate.h"

namespace lensopt::cli {

void check_lens_warnings(const Lens& lens, const char* command, bool strict) {
  // An afocal lens is measured in angle (analysis/afocal.h): analyze, plot (its spot in angle),
  // convert and optimize (its angular spot, optimize/design_loss.h) take it; the commands that
  // measure an image plane refuse it, saying why.
  const std::string name(command);
  if (name != "analyze" && name != "plot" && name != "convert" && name != "optimize")
    refuse_afocal(lens, name,
                  name == "tolerance"
                      ? "tolerancing measures the change of the image-plane spot and MTF, and an "
                        "afocal tolerance criterion (angular spot, plane-wave wavefront) is not "
                        "implemented"
                      : "");
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
