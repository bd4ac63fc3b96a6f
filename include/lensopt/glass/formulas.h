// The dispersion formulas, templated on the scalar (double or a ceres::Jet) so a wavelength or a
// coefficient can carry derivatives. Wavelength l in micrometres (in air); c[0..] the coefficients
// in file order; the index is relative to air.
//
// Zemax AGF formulas (ids 1..13): see glass.h and src/glass/glass.cpp.
//
// The refractiveindex.info database's formulas (ids 101..109 = its "formula 1..9"), coefficients
// C1, C2, ... = c[0], c[1], ... exactly as the database's YAML lists them (any count):
//   101 Sellmeier:   n^2 = 1 + C1 + sum_{i=2,4,..} C_i l^2 / (l^2 - C_{i+1}^2)
//   102 Sellmeier-2: n^2 = 1 + C1 + sum_{i=2,4,..} C_i l^2 / (l^2 - C_{i+1})
//   103 Polynomial:  n^2 = C1 + sum_{i=2,4,..} C_i l^C_{i+1}
//   104 RefractiveIndex.INFO:
//                    n^2 = C1 + C2 l^C3 / (l^2 - C4^C5) + C6 l^C7 / (l^2 - C8^C9)
//                          + sum_{i=10,12,..} C_i l^C_{i+1}
//   105 Cauchy:      n = C1 + sum_{i=2,4,..} C_i l^C_{i+1}
//   106 Gases:       n = 1 + C1 + sum_{i=2,4,..} C_i / (C_{i+1} - l^-2)
//   107 Herzberger:  n = C1 + C2 L + C3 L^2 + C4 l^2 + C5 l^4 + C6 l^6,  L = 1 / (l^2 - 0.028)
//   108 Retro:       (n^2 - 1) / (n^2 + 2) = C1 + C2 l^2 / (l^2 - C3) + C4 l^2
//   109 Exotic:      n^2 = C1 + C2 / (l^2 - C3) + C4 (l - C5) / ((l - C5)^2 + C6)
// (refractiveindex.info database, doc/Dispersion formulas.pdf). A term whose coefficients the
// data does not give is absent.
//
// 120 Table: tabulated n, c = (l_1, n_1, l_2, n_2, ...) with l ascending; n between two samples
// by the cubic through the four nearest samples (Lagrange; the two nearest at the ends), so n at a
// sample is the sample itself; outside the table the end cubic extrapolates (the range check
// warns).
#pragma once

#include <cmath>
#include <cstddef>
#include <limits>
#include <vector>

#include "lensopt/core/scalar.h"
#include "lensopt/glass/glass.h"

namespace lensopt {

namespace formula_detail {

// Herzberger's constant: L = 1/(l^2 - 0.028), l in um.
inline constexpr double kHerzbergerOffset_um2 = 0.028;

// C_i, 1-based as the database numbers them; 0 when the data does not give it.
inline double coefficient(const std::vector<double>& c, std::size_t i) {
  return i >= 1 && i <= c.size() ? c[i - 1] : 0.0;
}

// sum over i = first, first + 2, ... (while C_{i+1} exists) of term(C_i, C_{i+1}).
template <typename T, typename Term>
T pair_sum(const std::vector<double>& c, std::size_t first, Term term) {
  T sum = K<T>(0.0);
  for (std::size_t i = first; i + 1 <= c.size(); i += 2) sum = sum + term(c[i - 1], c[i]);
  return sum;
}

// Lagrange cubic through samples lo..lo+count-1 of a table (count 2..4), at l.
template <typename T>
T table_interpolate(const std::vector<double>& c, std::size_t lo, std::size_t count, const T& l) {
  T n = K<T>(0.0);
  for (std::size_t a = lo; a < lo + count; ++a) {
    T weight = K<T>(1.0);
    for (std::size_t b = lo; b < lo + count; ++b) {
      if (a == b) continue;
      const double la = c[2 * a], lb = c[2 * b];
      weight = weight * (l - K<T>(lb)) * K<T>(1.0 / (la - lb));
    }
    n = n + weight * K<T>(c[2 * a + 1]);
  }
  return n;
}

}  // namespace formula_detail

// Index by formula `formula` with coefficients c at wavelength l_um (um); NaN for an unknown id,
// or where the formula has no real value.
template <typename T>
T formula_index(DispersionFormula formula, const std::vector<double>& coefficients, const T& l_um) {
  using formula_detail::coefficient;
  using formula_detail::pair_sum;
  using std::pow;
  using std::sqrt;
  const T kNan = K<T>(std::numeric_limits<double>::quiet_NaN());
  const std::vector<double>& cv = coefficients;
  const auto c = [&](std::size_t i) { return coefficient(cv, i + 1); };  // c(0) = C1
  const T l2 = l_um * l_um;
  const T inv_l2 = K<T>(1.0) / l2;
  // sum_{k=1..count} a[k-1] x^k by Horner.
  const auto series = [](const double* a, int count, const T& x) {
    T sum = K<T>(0.0);
    for (int k = count - 1; k >= 0; --k) sum = (sum + K<T>(a[k])) * x;
    return sum;
  };
  const auto sellmeier = [&](int first, int terms) {  // sum c(2k) l^2 / (l^2 - c(2k+1))
    T sum = K<T>(0.0);
    for (int k = 0; k < terms; ++k)
      sum = sum + K<T>(c(first + 2 * k)) * l2 / (l2 - K<T>(c(first + 2 * k + 1)));
    return sum;
  };
  double a[10] = {};
  for (std::size_t i = 0; i < 10; ++i) a[i] = c(i);
  switch (formula) {
    case DispersionFormula::kSchott:
      return sqrt(K<T>(a[0]) + K<T>(a[1]) * l2 + series(a + 2, 4, inv_l2));
    case DispersionFormula::kSellmeier1:
      return sqrt(K<T>(1.0) + sellmeier(0, 3));
    case DispersionFormula::kHerzberger: {
      const T big_l = K<T>(1.0) / (l2 - K<T>(formula_detail::kHerzbergerOffset_um2));
      return K<T>(a[0]) + big_l * (K<T>(a[1]) + big_l * K<T>(a[2])) +
             l2 * (K<T>(a[3]) + l2 * (K<T>(a[4]) + l2 * K<T>(a[5])));
    }
    case DispersionFormula::kSellmeier2:
      return sqrt(K<T>(1.0 + a[0]) + K<T>(a[1]) * l2 / (l2 - K<T>(a[2] * a[2])) +
                  K<T>(a[3]) / (l2 - K<T>(a[4] * a[4])));
    case DispersionFormula::kConrady:
      return K<T>(a[0]) + K<T>(a[1]) / l_um + K<T>(a[2]) / pow(l_um, 3.5);
    case DispersionFormula::kSellmeier3:
      return sqrt(K<T>(1.0) + sellmeier(0, 4));
    case DispersionFormula::kHandbook1:
      return sqrt(K<T>(a[0]) + K<T>(a[1]) / (l2 - K<T>(a[2])) - K<T>(a[3]) * l2);
    case DispersionFormula::kHandbook2:
      return sqrt(K<T>(a[0]) + K<T>(a[1]) * l2 / (l2 - K<T>(a[2])) - K<T>(a[3]) * l2);
    case DispersionFormula::kSellmeier4:
      return sqrt(K<T>(a[0]) + sellmeier(1, 2));
    case DispersionFormula::kExtended1:
      return sqrt(K<T>(a[0]) + K<T>(a[1]) * l2 + series(a + 2, 6, inv_l2));
    case DispersionFormula::kSellmeier5:
      return sqrt(K<T>(1.0) + sellmeier(0, 5));
    case DispersionFormula::kExtended2:
      return sqrt(K<T>(a[0]) + l2 * (K<T>(a[1]) + l2 * (K<T>(a[6]) + l2 * K<T>(a[7]))) +
                  series(a + 2, 4, inv_l2));
    case DispersionFormula::kExtended3:
      return sqrt(K<T>(a[0]) + l2 * (K<T>(a[1]) + l2 * K<T>(a[2])) + series(a + 3, 6, inv_l2));
    case DispersionFormula::kRiiSellmeier:
      return sqrt(K<T>(1.0 + c(0)) + pair_sum<T>(cv, 2, [&](double b, double s) {
                    return K<T>(b) * l2 / (l2 - K<T>(s * s));
                  }));
    case DispersionFormula::kRiiSellmeier2:
      return sqrt(K<T>(1.0 + c(0)) + pair_sum<T>(cv, 2, [&](double b, double s) {
                    return K<T>(b) * l2 / (l2 - K<T>(s));
                  }));
    case DispersionFormula::kRiiPolynomial:
      return sqrt(K<T>(c(0)) +
                  pair_sum<T>(cv, 2, [&](double b, double e) { return K<T>(b) * pow(l_um, e); }));
    case DispersionFormula::kRiiInfo: {
      T n2 = K<T>(c(0));
      if (cv.size() >= 5)
        n2 = n2 + K<T>(c(1)) * pow(l_um, c(2)) / (l2 - K<T>(std::pow(c(3), c(4))));
      if (cv.size() >= 9)
        n2 = n2 + K<T>(c(5)) * pow(l_um, c(6)) / (l2 - K<T>(std::pow(c(7), c(8))));
      n2 = n2 + pair_sum<T>(cv, 10, [&](double b, double e) { return K<T>(b) * pow(l_um, e); });
      return sqrt(n2);
    }
    case DispersionFormula::kRiiCauchy:
      return K<T>(c(0)) +
             pair_sum<T>(cv, 2, [&](double b, double e) { return K<T>(b) * pow(l_um, e); });
    case DispersionFormula::kRiiGases:
      return K<T>(1.0 + c(0)) +
             pair_sum<T>(cv, 2, [&](double b, double s) { return K<T>(b) / (K<T>(s) - inv_l2); });
    case DispersionFormula::kRiiHerzberger: {
      const T big_l = K<T>(1.0) / (l2 - K<T>(formula_detail::kHerzbergerOffset_um2));
      return K<T>(c(0)) + K<T>(c(1)) * big_l + K<T>(c(2)) * big_l * big_l + K<T>(c(3)) * l2 +
             K<T>(c(4)) * l2 * l2 + K<T>(c(5)) * l2 * l2 * l2;
    }
    case DispersionFormula::kRiiRetro: {
      const T r = K<T>(c(0)) + K<T>(c(1)) * l2 / (l2 - K<T>(c(2))) + K<T>(c(3)) * l2;
      return sqrt((K<T>(1.0) + K<T>(2.0) * r) / (K<T>(1.0) - r));
    }
    case DispersionFormula::kRiiExotic: {
      const T d = l_um - K<T>(c(4));
      return sqrt(K<T>(c(0)) + K<T>(c(1)) / (l2 - K<T>(c(2))) +
                  K<T>(c(3)) * d / (d * d + K<T>(c(5))));
    }
    case DispersionFormula::kTable: {
      const std::size_t samples = cv.size() / 2;
      if (samples < 2) return kNan;
      // First sample at or beyond l (a binary search would do; tables are short).
      std::size_t upper = 0;
      const double l = value_of(l_um);
      while (upper < samples && cv[2 * upper] < l) ++upper;
      if (upper < samples && cv[2 * upper] == l) return K<T>(cv[2 * upper + 1]);
      if (samples < 4) return formula_detail::table_interpolate(cv, 0, samples, l_um);
      // The four samples around l: two each side where there are.
      std::size_t lo = upper >= 2 ? upper - 2 : 0;
      if (lo + 4 > samples) lo = samples - 4;
      return formula_detail::table_interpolate(cv, lo, 4, l_um);
    }
  }
  return kNan;
}

}  // namespace lensopt
