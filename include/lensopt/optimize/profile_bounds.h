// Sag and slope bounds of the surface profiles during optimization (issue 16): an asphere must
// stay a surface that can be made and traced, whatever its terms do between the rays.
//
// For every non-spherical surface k (TraceLens::profile not a sphere) with clear semi-aperture
// h_k (mm) and the radii r_j = h_k j / kProfileBoundRadii, j = 1..kProfileBoundRadii:
//   domain  q^2(r_j) = 1 - (1 + k) c^2 r_j^2 >= kProfileMinDomain   (the conic's square root stays
//           real, with a margin, up to the rim);
//   slope   |dz/dr|(r_j) = 2 r_j |S'(r_j^2)| <= tan(theta_max),  S' = c / (2 q) + P'(rho)
//           (trace/profile.h), theta_max = DesignLossOptions::max_surface_slope_deg (60 deg):
//           the surface normal tilts at most theta_max from the axis.
// As least-squares residuals (LM), two per (surface, radius): sqrt(w) max(|dz/dr| - tan theta_max,
// 0) and sqrt(w) max(kProfileMinDomain - q^2, 0), w = DesignLossOptions::weight_profile; where
// q^2 < kProfileMinDomain the slope is evaluated at q^2 = kProfileMinDomain (finite; the domain
// residual is the one that acts there). The clear semi-aperture is the paraxial estimate
// |y_marginal| + |y_chief| (marginal ray at the entrance-pupil edge, chief ray at the largest
// field), computed in double at the start of each LM round: the heights the rays reach.
#pragma once

#include <cmath>
#include <vector>

#include "lensopt/core/scalar.h"
#include "lensopt/lens/lens.h"
#include "lensopt/lens/trace_lens.h"
#include "lensopt/trace/system.h"

namespace lensopt {

inline constexpr int kProfileBoundRadii = 8;
inline constexpr double kProfileMinDomain = 1e-3;

// Paraxial clear semi-aperture (mm) of every surface of `lens` for its specs (paper sampling:
// entrance-pupil radius f / (2 N), the largest field); 0 where it cannot be computed.
std::vector<double> paraxial_clear_semi_apertures_mm(const TraceLens<double>& lens,
                                                     const Specs& specs);

// Number of profile-bound residuals of a lens: 2 kProfileBoundRadii per non-spherical surface.
template <typename T>
int profile_bound_count(const TraceLens<T>& lens) {
  int count = 0;
  for (std::uint8_t kind : lens.profile) count += kind != kProfileSphere ? 1 : 0;
  return 2 * kProfileBoundRadii * count;
}

// The residuals of the header into `residuals` (profile_bound_count of them), weight w.
template <typename T>
void profile_bound_residuals(const TraceLens<T>& lens, const std::vector<double>& heights_mm,
                             double max_slope_deg, double weight, T* residuals) {
  using std::abs;
  using std::sqrt;
  const T root_w = K<T>(std::sqrt(weight));
  const T tan_max = K<T>(std::tan(max_slope_deg * kPi / 180.0));
  const T zero = K<T>(0.0);
  const T floor = K<T>(kProfileMinDomain);
  int out = 0;
  for (int k = 0; k < lens.surface_count(); ++k) {
    if (!lens.has_profiles() || lens.profile[k] == kProfileSphere) continue;
    const T& c = lens.curvature_per_mm[k];
    const T one_plus_k = K<T>(1.0) + lens.conic[k];
    const T* a = lens.asphere.data() + static_cast<std::size_t>(k) * kAsphereTerms;
    for (int j = 1; j <= kProfileBoundRadii; ++j) {
      const double r = heights_mm[k] * j / kProfileBoundRadii;
      const T rho = K<T>(r * r);
      const T q2 = K<T>(1.0) - one_plus_k * c * c * rho;
      // S' with q^2 held at the floor where the domain bound is violated (see header).
      const T q = sqrt(q2 > floor ? q2 : floor);
      T dp = a[7] * K<T>(8.0);
      for (int i = 6; i >= 0; --i) dp = a[i] * K<T>(i + 1.0) + K<T>(r * r) * dp;
      const T slope = abs(K<T>(2.0 * r) * (c / (K<T>(2.0) * q) + dp));
      const T over = slope - tan_max;
      residuals[out++] = root_w * (over > zero ? over : zero);
      const T short_of = floor - q2;
      residuals[out++] = root_w * (short_of > zero ? short_of : zero);
    }
  }
}

// The steepest profile slope (deg, atan |dz/dr|) over the non-spherical surfaces at the radii of
// the header, and the smallest q^2 there (1 when the lens has no profiles).
void profile_extremes(const TraceLens<double>& lens, const std::vector<double>& heights_mm,
                      double& max_slope_deg, double& min_q2);

}  // namespace lensopt
