// Zernike orderings and least-squares fits (analysis/zernike.h).
#include "lensopt/analysis/zernike.h"

#include <fmt/format.h>

#include <Eigen/Dense>
#include <cmath>

#include "lensopt/core/error.h"

namespace lensopt {
namespace {

// The Fringe set has 37 terms: Z1..Z36 by the grouping rule, then Z37 = R_12^0.
constexpr int kFringeTerms = 37;

int max_terms(ZernikeOrdering ordering) {
  return ordering == ZernikeOrdering::kFringe ? kFringeTerms : kMaxZernikeTerms;
}

void check_index(ZernikeOrdering ordering, int j) {
  if (j < 1 || j > max_terms(ordering))
    throw Error(fmt::format("Zernike {} term {} must be in [1, {}]",
                            zernike_ordering_name(ordering), j, max_terms(ordering)));
}

double factorial(int k) {
  double f = 1;
  for (int i = 2; i <= k; ++i) f *= i;
  return f;
}

double radial(int n, int m, double rho) {
  double sum = 0;
  for (int k = 0; k <= (n - m) / 2; ++k) {
    const double c = ((k % 2) ? -1.0 : 1.0) * factorial(n - k) /
                     (factorial(k) * factorial((n + m) / 2 - k) * factorial((n - m) / 2 - k));
    sum += c * std::pow(rho, n - 2 * k);
  }
  return sum;
}

}  // namespace

ZernikeTerm zernike_term(ZernikeOrdering ordering, int j) {
  check_index(ordering, j);
  if (ordering == ZernikeOrdering::kFringe && j == kFringeTerms) return {12, 0, false};
  int index = 0;
  if (ordering == ZernikeOrdering::kStandard) {
    for (int n = 0;; ++n) {
      for (int m = n % 2; m <= n; m += 2) {
        if (m == 0) {
          if (++index == j) return {n, 0, false};
        } else {
          // The pair (index + 1, index + 2): cos on the even index, sin on the odd one.
          for (int k = 1; k <= 2; ++k)
            if (index + k == j) return {n, m, (j % 2) == 1};
          index += 2;
        }
      }
    }
  }
  for (int g = 0;; ++g) {
    for (int m = g; m >= 0; --m) {
      const int n = 2 * g - m;
      if (m == 0) {
        if (++index == j) return {n, 0, false};
      } else {
        if (++index == j) return {n, m, false};
        if (++index == j) return {n, m, true};
      }
    }
  }
}

double zernike_value(ZernikeOrdering ordering, int j, double x, double y) {
  const ZernikeTerm t = zernike_term(ordering, j);
  const double rho = std::sqrt(x * x + y * y);
  const double theta = std::atan2(y, x);
  double v = radial(t.n, t.m, rho);
  if (t.m > 0) v *= t.sine ? std::sin(t.m * theta) : std::cos(t.m * theta);
  if (ordering == ZernikeOrdering::kStandard)
    v *= t.m == 0 ? std::sqrt(t.n + 1.0) : std::sqrt(2.0 * (t.n + 1.0));
  return v;
}

std::string zernike_ordering_name(ZernikeOrdering ordering) {
  return ordering == ZernikeOrdering::kStandard ? "standard" : "fringe";
}

ZernikeOrdering parse_zernike_ordering(const std::string& name) {
  if (name == "fringe") return ZernikeOrdering::kFringe;
  if (name == "standard" || name == "noll") return ZernikeOrdering::kStandard;
  throw Error(fmt::format("Zernike ordering '{}' must be fringe or standard", name));
}

ZernikeFit fit_zernike(const std::vector<double>& x, const std::vector<double>& y,
                       const std::vector<double>& w, const std::vector<double>& a, int terms,
                       ZernikeOrdering ordering) {
  check_index(ordering, terms);
  std::vector<std::size_t> used;
  for (std::size_t i = 0; i < w.size(); ++i)
    if (a[i] > 0.0 && std::isfinite(w[i])) used.push_back(i);
  if (static_cast<int>(used.size()) < terms)
    throw Error(fmt::format("a Zernike fit of {} terms needs at least as many pupil samples ({})",
                            terms, used.size()));
  // The terms' (n, m, sin) once, then the design matrix scaled by sqrt(a).
  std::vector<ZernikeTerm> t(terms);
  for (int j = 0; j < terms; ++j) t[j] = zernike_term(ordering, j + 1);
  const Eigen::Index rows = static_cast<Eigen::Index>(used.size());
  Eigen::MatrixXd design(rows, terms);
  Eigen::VectorXd rhs(rows);
  double weight_sum = 0;
  for (Eigen::Index r = 0; r < rows; ++r) {
    const std::size_t i = used[r];
    const double s = std::sqrt(a[i]);
    const double rho = std::sqrt(x[i] * x[i] + y[i] * y[i]);
    const double theta = std::atan2(y[i], x[i]);
    for (int j = 0; j < terms; ++j) {
      double v = radial(t[j].n, t[j].m, rho);
      if (t[j].m > 0) v *= t[j].sine ? std::sin(t[j].m * theta) : std::cos(t[j].m * theta);
      if (ordering == ZernikeOrdering::kStandard)
        v *= t[j].m == 0 ? std::sqrt(t[j].n + 1.0) : std::sqrt(2.0 * (t[j].n + 1.0));
      design(r, j) = s * v;
    }
    rhs(r) = s * w[i];
    weight_sum += a[i];
  }
  const Eigen::VectorXd c = design.colPivHouseholderQr().solve(rhs);
  ZernikeFit fit;
  fit.ordering = ordering;
  fit.samples = static_cast<int>(rows);
  fit.coefficients_waves.assign(c.data(), c.data() + terms);
  const double misfit = (design * c - rhs).squaredNorm();
  fit.residual_rms_waves = std::sqrt(misfit / weight_sum);
  return fit;
}

ZernikeFit fit_zernike(const Wavefront<double>& wf, const PupilGrid& grid, int terms,
                       ZernikeOrdering ordering) {
  if (grid.mirrored) throw Error("a Zernike fit needs the full pupil grid, not a half grid");
  std::vector<double> a(grid.size(), 0.0);
  for (std::size_t i = 0; i < grid.size(); ++i)
    if (wf.ok[i]) a[i] = grid.weight[i];
  return fit_zernike(grid.samples.x, grid.samples.y, wf.opd_waves, a, terms, ordering);
}

}  // namespace lensopt
