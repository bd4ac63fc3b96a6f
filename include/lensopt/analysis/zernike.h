// Zernike fits of a wavefront (analysis/wavefront.h), in the Fringe and the Standard (Noll)
// orderings, coefficients in waves.
//
// Polar pupil coordinates: x_p = rho cos theta, y_p = rho sin theta (normalized pupil, theta
// from the +x axis towards +y). The radial polynomial of order n and azimuthal order m >= 0
// (n - m even):
//   R_n^m(rho) = sum_{k=0}^{(n-m)/2} (-1)^k (n-k)! / (k! ((n+m)/2-k)! ((n-m)/2-k)!) rho^(n-2k)
// and the term is R_n^m(rho) times 1 (m = 0), cos(m theta) or sin(m theta).
//   * Standard (Noll 1976, OpticStudio's "Zernike Standard"): normalized to unit RMS over the
//     disk, N = sqrt(n + 1) (m = 0) or sqrt(2 (n + 1)); index j = 1, 2, ... by n ascending,
//     then |m| ascending; for m > 0 the pair (j, j + 1) takes cos on the even index and sin on
//     the odd one (Z2 = 2 rho cos, Z3 = 2 rho sin, Z4 = sqrt(3)(2 rho^2 - 1), Z11 = sqrt(5)(6 rho^4
//     - 6 rho^2 + 1), ...).
//   * Fringe (University of Arizona, OpticStudio's "Zernike Fringe"): unnormalized (peak 1 at
//     the edge); grouped by g = (n + m)/2 = 0, 1, 2, ..., within a group m descending from g
//     (n = 2g - m), cos before sin (Z1 = 1, Z2 = rho cos, Z3 = rho sin, Z4 = 2 rho^2 - 1,
//     Z5 = rho^2 cos 2theta, ..., Z9 = 6 rho^4 - 6 rho^2 + 1, ..., Z36 = R_10^0), and the set
//     ends with Z37 = R_12^0: at most 37 terms.
// Fit: weighted least squares over the samples that arrived (vignetted and failed rays
// excluded), weights = the grid cells' area fractions:
//   min_c sum_i a_i (W_i - sum_j c_j Z_j(x_i, y_i))^2
// solved by a column-pivoted QR of the sqrt(a)-scaled design matrix (the sampled Zernikes are not
// exactly orthogonal on a grid; least squares needs no orthogonality). The raw W is fitted, so
// piston and tilt appear as Z1..Z3. residual_rms_waves is sqrt(sum a r^2 / sum a) of the misfit.
#pragma once

#include <string>
#include <vector>

#include "lensopt/analysis/wavefront.h"

namespace lensopt {

enum class ZernikeOrdering { kFringe, kStandard };

// The largest number of terms a fit takes (Standard: n <= 20; Fringe: 37).
inline constexpr int kMaxZernikeTerms = 231;

struct ZernikeTerm {
  int n = 0;          // radial order
  int m = 0;          // azimuthal order, >= 0
  bool sine = false;  // sin(m theta) (else cos, or 1 for m = 0)
};

// Term j (1-based) of an ordering; throws Error for j outside [1, kMaxZernikeTerms] (Standard)
// or [1, 37] (Fringe).
ZernikeTerm zernike_term(ZernikeOrdering ordering, int j);

// Z_j at the pupil point (x, y), with the ordering's normalization.
double zernike_value(ZernikeOrdering ordering, int j, double x, double y);

// "fringe" / "standard".
std::string zernike_ordering_name(ZernikeOrdering ordering);
// Parses "fringe" or "standard"; throws Error otherwise.
ZernikeOrdering parse_zernike_ordering(const std::string& name);

struct ZernikeFit {
  ZernikeOrdering ordering = ZernikeOrdering::kFringe;
  std::vector<double> coefficients_waves;  // c_1 .. c_terms
  double residual_rms_waves = 0;           // misfit
  int samples = 0;                         // samples fitted
};

// Fits `terms` Zernikes to the values w at pupil points (x, y) with weights a (samples with
// a <= 0 are left out). Throws Error for terms outside [1, kMaxZernikeTerms] or fewer samples
// than terms.
ZernikeFit fit_zernike(const std::vector<double>& x, const std::vector<double>& y,
                       const std::vector<double>& w, const std::vector<double>& a, int terms,
                       ZernikeOrdering ordering);

// The fit of a wavefront on its grid (the samples that arrived).
ZernikeFit fit_zernike(const Wavefront<double>& wavefront, const PupilGrid& grid, int terms,
                       ZernikeOrdering ordering);

}  // namespace lensopt
