// Glass dispersion (the AGF formulas) and internal transmission.
//
// Every formula takes the wavelength l in micrometres (in air) and the CD coefficients c0..c9 in
// file order, and gives the index relative to air:
//    1 Schott:      n^2 = c0 + c1 l^2 + c2 l^-2 + c3 l^-4 + c4 l^-6 + c5 l^-8
//    2 Sellmeier 1: n^2 - 1 = c0 l^2/(l^2 - c1) + c2 l^2/(l^2 - c3) + c4 l^2/(l^2 - c5)
//    3 Herzberger:  n = c0 + c1 L + c2 L^2 + c3 l^2 + c4 l^4 + c5 l^6,  L = 1/(l^2 - 0.028)
//    4 Sellmeier 2: n^2 - 1 = c0 + c1 l^2/(l^2 - c2^2) + c3/(l^2 - c4^2)
//    5 Conrady:     n = c0 + c1/l + c2/l^3.5
//    6 Sellmeier 3: n^2 - 1 = sum_{k=0..3} c(2k) l^2/(l^2 - c(2k+1))
//    7 Handbook of Optics 1: n^2 = c0 + c1/(l^2 - c2) - c3 l^2
//    8 Handbook of Optics 2: n^2 = c0 + c1 l^2/(l^2 - c2) - c3 l^2
//    9 Sellmeier 4: n^2 = c0 + c1 l^2/(l^2 - c2) + c3 l^2/(l^2 - c4)
//   10 Extended:    n^2 = c0 + c1 l^2 + c2 l^-2 + c3 l^-4 + c4 l^-6 + c5 l^-8 + c6 l^-10
//                         + c7 l^-12
//   11 Sellmeier 5: n^2 - 1 = sum_{k=0..4} c(2k) l^2/(l^2 - c(2k+1))
//   12 Extended 2:  n^2 = c0 + c1 l^2 + c2 l^-2 + c3 l^-4 + c4 l^-6 + c5 l^-8 + c6 l^4 + c7 l^6
//   13 Extended 3:  n^2 = c0 + c1 l^2 + c2 l^4 + c3 l^-2 + c4 l^-4 + c5 l^-6 + c6 l^-8
//                         + c7 l^-10 + c8 l^-12
// (Zemax OpticStudio manual, "The Glass Dispersion Formulas"). lensopt's catalogs made from the
// refractiveindex.info database add its formulas (ids 101..109) and tabulated data (120); all are
// evaluated by the one template formula_index (glass/formulas.h), double here.
#include "lensopt/glass/glass.h"

#include <fmt/format.h>

#include <algorithm>
#include <cmath>
#include <limits>

#include "lensopt/glass/formulas.h"
#include "lensopt/glass/glass_range.h"

namespace lensopt {
namespace {

constexpr double kNanometresPerMicrometre = 1000.0;
}  // namespace

std::string formula_name(DispersionFormula formula) {
  switch (formula) {
    case DispersionFormula::kSchott:
      return "Schott";
    case DispersionFormula::kSellmeier1:
      return "Sellmeier 1";
    case DispersionFormula::kHerzberger:
      return "Herzberger";
    case DispersionFormula::kSellmeier2:
      return "Sellmeier 2";
    case DispersionFormula::kConrady:
      return "Conrady";
    case DispersionFormula::kSellmeier3:
      return "Sellmeier 3";
    case DispersionFormula::kHandbook1:
      return "Handbook of Optics 1";
    case DispersionFormula::kHandbook2:
      return "Handbook of Optics 2";
    case DispersionFormula::kSellmeier4:
      return "Sellmeier 4";
    case DispersionFormula::kExtended1:
      return "Extended";
    case DispersionFormula::kSellmeier5:
      return "Sellmeier 5";
    case DispersionFormula::kExtended2:
      return "Extended 2";
    case DispersionFormula::kExtended3:
      return "Extended 3";
    case DispersionFormula::kRiiSellmeier:
      return "RII Sellmeier";
    case DispersionFormula::kRiiSellmeier2:
      return "RII Sellmeier-2";
    case DispersionFormula::kRiiPolynomial:
      return "RII polynomial";
    case DispersionFormula::kRiiInfo:
      return "RII RefractiveIndex.INFO";
    case DispersionFormula::kRiiCauchy:
      return "RII Cauchy";
    case DispersionFormula::kRiiGases:
      return "RII gases";
    case DispersionFormula::kRiiHerzberger:
      return "RII Herzberger";
    case DispersionFormula::kRiiRetro:
      return "RII retro";
    case DispersionFormula::kRiiExotic:
      return "RII exotic";
    case DispersionFormula::kTable:
      return "table";
  }
  return fmt::format("unknown ({})", static_cast<int>(formula));
}

std::string status_name(GlassStatus status) {
  switch (status) {
    case GlassStatus::kStandard:
      return "standard";
    case GlassStatus::kPreferred:
      return "preferred";
    case GlassStatus::kObsolete:
      return "obsolete";
    case GlassStatus::kSpecial:
      return "special";
    case GlassStatus::kMelt:
      return "melt";
  }
  return fmt::format("unknown ({})", static_cast<int>(status));
}

bool glass_in_range(const Glass& glass, double wavelength_nm) {
  const double min_wavelength_um = glass.min_wavelength_um;
  const double max_wavelength_um = glass.max_wavelength_um;
  if (!(max_wavelength_um > min_wavelength_um) || !(max_wavelength_um > 0)) return true;
  const double l_um = wavelength_nm / kNanometresPerMicrometre;
  // A relative slack of 1e-9 keeps the range's own end points inside.
  return l_um >= min_wavelength_um * (1 - 1e-9) && l_um <= max_wavelength_um * (1 + 1e-9);
}

std::string missing_index_reason(const Glass& glass, double wavelength_nm) {
  if (!glass.formula_supported)
    return fmt::format("unsupported dispersion formula {}", formula_name(glass.formula));
  const double n = glass.index(wavelength_nm);
  if (std::isfinite(n) && n > 0) return "";
  const std::string range =
      glass_in_range(glass, wavelength_nm)
          ? std::string()
          : fmt::format(" ({} nm is outside the formula's range {}-{} nm)", wavelength_nm,
                        glass.min_wavelength_um * kNanometresPerMicrometre,
                        glass.max_wavelength_um * kNanometresPerMicrometre);
  return fmt::format("the {} formula gives no real index at {} nm{}", formula_name(glass.formula),
                     wavelength_nm, range);
}

double Glass::index(double wavelength_nm) const {
  if (!formula_supported) return std::numeric_limits<double>::quiet_NaN();
  return formula_index(formula, coefficients, wavelength_nm / kNanometresPerMicrometre);
}

bool Glass::transmits(double wavelength_nm) const {
  if (transmission.empty()) return true;
  const double l_um = wavelength_nm / kNanometresPerMicrometre;
  // The IT table in wavelength order (files list it ascending; sort a copy if one does not).
  const std::vector<TransmissionPoint>* table = &transmission;
  std::vector<TransmissionPoint> sorted;
  const auto by_wavelength = [](const TransmissionPoint& a, const TransmissionPoint& b) {
    return a.wavelength_um < b.wavelength_um;
  };
  if (!std::is_sorted(transmission.begin(), transmission.end(), by_wavelength)) {
    sorted = transmission;
    std::stable_sort(sorted.begin(), sorted.end(), by_wavelength);
    table = &sorted;
  }
  const auto& points = *table;
  if (l_um < points.front().wavelength_um || l_um > points.back().wavelength_um) return true;
  // First sample at or beyond l; interpolate between it and the one before:
  //   t(l) = t0 + (t1 - t0) (l - l0)/(l1 - l0).
  const auto upper = std::lower_bound(
      points.begin(), points.end(), l_um,
      [](const TransmissionPoint& p, double value) { return p.wavelength_um < value; });
  if (upper->wavelength_um == l_um || upper == points.begin()) return upper->transmission > 0.0;
  const auto lower = upper - 1;
  const double span_um = upper->wavelength_um - lower->wavelength_um;
  const double fraction = (l_um - lower->wavelength_um) / span_um;
  const double t = lower->transmission + (upper->transmission - lower->transmission) * fraction;
  return t > 0.0;
}

}  // namespace lensopt
