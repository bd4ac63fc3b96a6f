// The paper's two-parameter dispersion model, templated so glass variables (nd, vd) carry
// derivatives through the tracer:
//   n(l) = A + B / l^2,  B = (nd - 1) / (vd (lF^-2 - lC^-2)),  A = nd - B / ld^2,
// with lC = 656.3 nm, ld = 587.6 nm, lF = 486.1 nm (paper, "Glass Variables").
#pragma once

#include "lensopt/core/scalar.h"

namespace lensopt {

inline constexpr double kWavelengthC_nm = 656.3;
inline constexpr double kWavelengthD_nm = 587.6;
inline constexpr double kWavelengthF_nm = 486.1;

// Which dispersion the tracer uses for glasses.
enum class DispersionModel {
  kAbbe,     // the paper's A + B / l^2 from nd and vd (default; reproduces the paper)
  kCatalog,  // the catalog glass's own formula (model glasses fall back to kAbbe)
};

// Refractive index at `wavelength_nm` from nd and vd by the paper's model.
template <typename T>
T abbe_index(const T& nd, const T& vd, double wavelength_nm) {
  const double inv_c2 = 1.0 / (kWavelengthC_nm * kWavelengthC_nm);
  const double inv_f2 = 1.0 / (kWavelengthF_nm * kWavelengthF_nm);
  const double inv_d2 = 1.0 / (kWavelengthD_nm * kWavelengthD_nm);
  const double inv_l2 = 1.0 / (wavelength_nm * wavelength_nm);
  const T b = (nd - K<T>(1.0)) / (vd * K<T>(inv_f2 - inv_c2));
  // n = nd + B (l^-2 - ld^-2)
  return nd + b * K<T>(inv_l2 - inv_d2);
}

}  // namespace lensopt
