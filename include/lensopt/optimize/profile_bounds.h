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
#include <type_traits>
#include <vector>

#include "lensopt/core/scalar.h"
#include "lensopt/lens/lens.h"
#include "lensopt/lens/profile_sag.h"
#include "lensopt/lens/trace_lens.h"
#include "lensopt/paraxial/paraxial.h"
#include "lensopt/trace/system.h"

namespace lensopt {

inline constexpr int kProfileBoundRadii = 8;
inline constexpr double kProfileMinDomain = 1e-3;

// Paraxial clear semi-aperture (mm) of every surface of `lens` for its specs (paper sampling:
// entrance-pupil radius f / (2 N), the largest field; paraxial.h); 0 where it cannot be computed.
template <typename T>
std::vector<T> paraxial_clear_semi_apertures(const TraceLens<T>& lens, const Specs& specs) {
  std::vector<T> out = paraxial_clear_semi_apertures_or_nonfinite(lens, specs);
  for (T& h : out)
    if (!std::isfinite(value_of(h))) h = K<T>(0.0);  // not computable: 0
  return out;
}
std::vector<double> paraxial_clear_semi_apertures_mm(const TraceLens<double>& lens,
                                                     const Specs& specs);

// Number of profile-bound residuals of a lens: 2 kProfileBoundRadii per non-spherical surface.
template <typename T>
int profile_bound_count(const TraceLens<T>& lens) {
  int count = 0;
  for (std::uint8_t kind : lens.profile) count += kind != kProfileSphere ? 1 : 0;
  return 2 * kProfileBoundRadii * count;
}

// The residuals of the header into `residuals` (profile_bound_count of them), weight w; the
// heights (H = double: constants, as LM holds them per round; H = T: differentiated).
template <typename T, typename H>
void profile_bound_residuals(const TraceLens<T>& lens, const std::vector<H>& heights_mm,
                             double max_slope_deg, double weight, T* residuals) {
  using std::abs;
  using std::sqrt;
  const T root_w = K<T>(std::sqrt(weight));
  const T tan_max = K<T>(std::tan(max_slope_deg * kPi / 180.0));
  const T zero = K<T>(0.0);
  const T floor = K<T>(kProfileMinDomain);
  auto to_t = [](const H& v) -> T {
    if constexpr (std::is_same_v<H, T>) {
      return v;
    } else {
      return K<T>(v);
    }
  };
  int out = 0;
  for (int k = 0; k < lens.surface_count(); ++k) {
    if (!lens.has_profiles() || lens.profile[k] == kProfileSphere) continue;
    const T& c = lens.curvature_per_mm[k];
    const T one_plus_k = K<T>(1.0) + lens.conic[k];
    const T* a = lens.asphere.data() + static_cast<std::size_t>(k) * kAsphereTerms;
    for (int j = 1; j <= kProfileBoundRadii; ++j) {
      const H r = heights_mm[k] * K<H>(static_cast<double>(j)) / K<H>(kProfileBoundRadii);
      const T rho = to_t(r * r);
      const T q2 = profile_q2(c, one_plus_k, rho);
      // S' (lens/profile_sag.h) with q^2 held at the floor where the domain bound is violated
      // (see header).
      const T q = sqrt(q2 > floor ? q2 : floor);
      const T slope = abs(to_t(K<H>(2.0) * r) * profile_slope_at_q(c, a, rho, q));
      const T over = slope - tan_max;
      residuals[out++] = root_w * (over > zero ? over : zero);
      const T short_of = floor - q2;
      residuals[out++] = root_w * (short_of > zero ? short_of : zero);
    }
  }
}

// The profile bounds as a term of the design loss (design_loss.h, the gradient optimizers'):
//   l_PB = sum of the squared residuals of the header at weight 1,
// with the clear semi-apertures computed on T from the lens itself, so that l_PB is one smooth
// function of the variables and its gradient exact (LM holds the heights per round instead).
template <typename T>
T profile_bound_loss(const TraceLens<T>& lens, const Specs& specs, double max_slope_deg) {
  const int count = profile_bound_count(lens);
  T sum = K<T>(0.0);
  if (count == 0) return sum;
  const std::vector<T> heights = paraxial_clear_semi_apertures(lens, specs);
  std::vector<T> r(count);
  profile_bound_residuals(lens, heights, max_slope_deg, 1.0, r.data());
  for (const T& v : r) sum = sum + v * v;
  return sum;
}

// The steepest profile slope (deg, atan |dz/dr|) over the non-spherical surfaces at the radii of
// the header, and the smallest q^2 there (1 when the lens has no profiles).
void profile_extremes(const TraceLens<double>& lens, const std::vector<double>& heights_mm,
                      double& max_slope_deg, double& min_q2);

}  // namespace lensopt
