// A diverging lens's virtual image in the optimizer (optimize/virtual_image.h).
#include "lensopt/optimize/virtual_image.h"

#include <fmt/format.h>

#include <cmath>
#include <limits>

#include "lensopt/analysis/analyze.h"
#include "lensopt/optimize/optimizer.h"
#include "lensopt/optimize/variables.h"

namespace lensopt {
namespace {

// The start's image-space travel extremes (min, max dz) over every ray at full sampling.
bool image_travel(const Lens& lens, double& min_dz, double& max_dz) {
  const LensParameterization param(lens, GlassSpace(*load_catalog(glass_catalog_for(lens))));
  const std::vector<double> x = param.from_lens(lens);
  DesignExtremes ext;
  DesignLossOptions loss;
  evaluate_design<double>(param, x.data(), GlassMode::kContinuous, {}, AnalyzeOptions{}.trace, loss,
                          nullptr, nullptr, nullptr, &ext);
  if (ext.min_travel_mm.empty()) return false;
  min_dz = ext.min_travel_mm.back();
  max_dz = ext.max_travel_mm.back();
  return std::isfinite(min_dz) && std::isfinite(max_dz);
}

}  // namespace

DesignLossOptions with_virtual_image_bounds(const Lens& start, DesignLossOptions loss,
                                            std::string* why) {
  if (loss.virtual_image() || start.specs.mode != SpecMode::kAsWritten || start.specs.afocal)
    return loss;
  const double f = design_focal_length_mm(start);
  if (!(std::isfinite(f) && f < 0.0)) return loss;
  double min_dz = 0.0, max_dz = 0.0;
  if (!image_travel(start, min_dz, max_dz) || !(min_dz < 0.0)) return loss;
  const double nearest = -max_dz, farthest = -min_dz;
  loss.min_virtual_image_mm = nearest > 0.0 ? 0.5 * nearest : 0.0;
  loss.max_virtual_image_mm = 2.0 * farthest;
  if (why)
    *why = fmt::format(
        "image: virtual (EFL {:.6g} mm), measured {:.6g} mm before the last surface; its "
        "distance is held within [{:.6g}, {:.6g}] mm (0.5x the start's nearest ray, 2x its "
        "farthest; the image clearance does not apply)",
        f, -start.surfaces.back().thickness_mm, loss.min_virtual_image_mm,
        loss.max_virtual_image_mm);
  return loss;
}

}  // namespace lensopt
