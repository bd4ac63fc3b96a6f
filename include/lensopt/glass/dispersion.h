// Model glasses: an index from (nd, vd) alone, templated so glass variables (nd, vd) carry
// derivatives through the tracer. Two models:
//
// The paper's two-parameter model (abbe_index; the paper's lenses and every TOML/YAML model
// glass):
//   n(l) = A + B / l^2,  B = (nd - 1) / (vd (lF^-2 - lC^-2)),  A = nd - B / ld^2,
// with lC = 656.3 nm, ld = 587.6 nm, lF = 486.1 nm (paper, "Glass Variables").
//
// OpticStudio's model glass (zemax_model_index; a .zmx model glass, `GLAS ___BLANK 1 0 nd vd
// dPgF`): OpticStudio idealizes the dispersion at the helium d line, 587.5618 nm, from nd, vd
// and the partial-dispersion deviation dPgF (OpticStudio manual, "Material Solves: Model"); its
// exact formula is not published. lensopt's model honours every stated parameter exactly with the
// Fraunhofer lines d = 587.5618, F = 486.1327, C = 656.2725, g = 435.8343 nm:
//   n(ld) = nd exactly,  nF - nC = (nd - 1) / vd,
//   (ng - nF) / (nF - nC) = PgF = 0.6438 - 0.001682 vd + dPgF   (the normal line)
// by n(l) = nd + B (x - xd) + C (x^2 - xd^2), x = 1 / l^2 (l in um): the two linear conditions
// on F - C and g - F give B and C. Outside the visible the model is, as OpticStudio warns, only
// an extrapolation.
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

// Which model a model glass (nd, vd) follows; TraceLens::is_glass holds it per medium (0 = air).
enum class ModelGlass : char {
  kPaper = 1,  // abbe_index, anchored at 587.6 nm (the paper's lenses, TOML and YAML)
  kZemax = 2,  // zemax_model_index, nd exact at 587.5618 nm (model glasses of a .zmx file)
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

// The Fraunhofer lines of OpticStudio's model glass (nm).
inline constexpr double kHeliumD_nm = 587.5618;
inline constexpr double kHydrogenF_nm = 486.1327;
inline constexpr double kHydrogenC_nm = 656.2725;
inline constexpr double kMercuryG_nm = 435.8343;
// Normal line of the relative partial dispersion: PgF = kNormalLineA + kNormalLineB vd.
inline constexpr double kNormalLineA = 0.6438;
inline constexpr double kNormalLineB = -0.001682;

// OpticStudio's model glass (see the header): n(587.5618 nm) = nd exactly.
template <typename T>
T zemax_model_index(const T& nd, const T& vd, const T& dpgf, double wavelength_nm) {
  const auto x_of = [](double nm) {
    const double um = nm / 1000.0;
    return 1.0 / (um * um);
  };
  const double xd = x_of(kHeliumD_nm), xf = x_of(kHydrogenF_nm), xc = x_of(kHydrogenC_nm);
  const double xg = x_of(kMercuryG_nm), x = x_of(wavelength_nm);
  // B (xF - xC) + C (xF^2 - xC^2) = D,  B (xg - xF) + C (xg^2 - xF^2) = P D,  D = (nd - 1) / vd.
  const double a11 = xf - xc, a12 = xf * xf - xc * xc;
  const double a21 = xg - xf, a22 = xg * xg - xf * xf;
  const double det = a11 * a22 - a12 * a21;
  const T d = (nd - K<T>(1.0)) / vd;
  const T p = K<T>(kNormalLineA) + K<T>(kNormalLineB) * vd + dpgf;
  const T b = d * (K<T>(a22) - p * K<T>(a12)) * K<T>(1.0 / det);
  const T c = d * (p * K<T>(a11) - K<T>(a21)) * K<T>(1.0 / det);
  return nd + b * K<T>(x - xd) + c * K<T>(x * x - xd * xd);
}

}  // namespace lensopt
