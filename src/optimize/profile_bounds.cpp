// Sag and slope bounds of the surface profiles (include/lensopt/optimize/profile_bounds.h).
#include "lensopt/optimize/profile_bounds.h"

#include <algorithm>
#include <cmath>

#include "lensopt/core/constants.h"
#include "lensopt/paraxial/afocal.h"
#include "lensopt/paraxial/paraxial.h"

namespace lensopt {

std::vector<double> paraxial_clear_semi_apertures_mm(const TraceLens<double>& lens,
                                                     const Specs& specs) {
  if (!specs.afocal) return paraxial_clear_semi_apertures(lens, specs);
  // An afocal lens has no EFL for r_EP = f / (2 N): the marginal ray from the written entrance
  // pupil's rim (collimated, or from the axial object point), the chief ray through the pupil's
  // centre at the largest field angle (paraxial/afocal.h's entrance pupil). 0 where the lens does
  // not give them (an aperture by object NA or stop, fields by object height).
  const int k_count = lens.surface_count();
  std::vector<double> out(k_count, 0.0);
  if (specs.aperture_type != ApertureType::kEntrancePupilDiameter ||
      specs.field_type != FieldType::kAngle || !(specs.aperture_value > 0.0))
    return out;
  const double nm = lens.reference_nm();
  const double r_ep = 0.5 * specs.aperture_value;
  const double z_ep = paraxial_entrance_pupil_z_mm(lens, nm);
  const double tan_field = std::tan(specs.max_field_value() * kPi / 180.0);
  ParaxialRay<double> marginal{r_ep, 0.0};
  if (!specs.object_at_infinity()) {
    const double u0 = r_ep / (specs.object_distance_mm + z_ep);
    marginal = ParaxialRay<double>{u0 * specs.object_distance_mm, u0};
  }
  for (int k = 0; k < k_count; ++k) {
    const double h =
        std::abs(paraxial_trace(lens, marginal, k + 1, nm).y) +
        std::abs(
            paraxial_trace(lens, ParaxialRay<double>{-z_ep * tan_field, tan_field}, k + 1, nm).y);
    out[k] = std::isfinite(h) ? h : 0.0;
  }
  return out;
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
