// Sag and slope bounds of the surface profiles (include/lensopt/optimize/profile_bounds.h).
#include "lensopt/optimize/profile_bounds.h"

#include <algorithm>
#include <cmath>

#include "lensopt/paraxial/paraxial.h"

namespace lensopt {

std::vector<double> paraxial_clear_semi_apertures_mm(const TraceLens<double>& lens,
                                                     const Specs& specs) {
  return paraxial_clear_semi_apertures(lens, specs);
}

void profile_extremes(const TraceLens<double>& lens, const std::vector<double>& heights_mm,
                      double& max_slope_deg, double& min_q2) {
  max_slope_deg = 0.0;
  min_q2 = 1.0;
  for (int k = 0; k < lens.surface_count(); ++k) {
    if (!lens.has_profiles() || lens.profile[k] == kProfileSphere) continue;
    const double c = lens.curvature_per_mm[k];
    const double* a = lens.asphere.data() + static_cast<std::size_t>(k) * kAsphereTerms;
    for (int j = 1; j <= kProfileBoundRadii; ++j) {
      const double r = heights_mm[k] * j / kProfileBoundRadii;
      const double rho = r * r;
      const double q2 = profile_q2(c, 1.0 + lens.conic[k], rho);
      min_q2 = std::min(min_q2, q2);
      if (!(q2 > 0.0)) {
        max_slope_deg = 90.0;  // outside the domain: a vertical (or no) surface
        continue;
      }
      // S' (lens/profile_sag.h), inside the domain.
      const double slope = std::abs(2.0 * r * profile_slope_at_q(c, a, rho, std::sqrt(q2)));
      max_slope_deg = std::max(max_slope_deg, std::atan(slope) * 180.0 / kPi);
    }
  }
}

}  // namespace lensopt
