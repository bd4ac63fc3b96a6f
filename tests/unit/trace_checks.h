// Trace and gradient checks shared by the unit tests: a quick sampling, the mean RMS spot of a
// lens, the worst relative difference of two gradients, and central differences of the mean spot.
#pragma once

#include <algorithm>
#include <cmath>
#include <vector>

#include "lensopt/analysis/spot.h"
#include "lensopt/lens/lens.h"
#include "lensopt/lens/trace_lens.h"
#include "lensopt/trace/system.h"

namespace lensopt::test {

// A small sampling for tests: `rings` pupil rings, 5 fields, one thread.
inline TraceOptions quick(int rings = 8) {
  TraceOptions t;
  t.rings = rings;
  t.fields = 5;
  t.threads = 1;
  return t;
}

// The mean RMS spot (mm) of a lens at `options`.
inline double mean_spot(const Lens& lens, const TraceOptions& options) {
  const TraceSystem<double> sys = prepare_system(make_trace_lens(lens), lens.specs, options);
  return evaluate_spots(sys, options.threads).mean_rms_spot_mm;
}

// Worst relative difference of two gradients, each entry relative to the larger of its own size
// and 1e-6 of b's largest entry (an entry that is zero up to rounding).
inline double worst_relative(const std::vector<double>& a, const std::vector<double>& b) {
  double largest = 0;
  for (double d : b) largest = std::max(largest, std::abs(d));
  double worst = 0;
  for (std::size_t i = 0; i < a.size(); ++i) {
    const double denominator = std::max(std::abs(b[i]), 1e-6 * largest);
    worst = std::max(worst, std::abs(a[i] - b[i]) / denominator);
  }
  return worst;
}

// d(mean spot)/d(variable) by central differences, Richardson-extrapolated:
//   D(h) = (f(x + h) - f(x - h)) / (2 h),  (4 D(h / 2) - D(h)) / 3 = f' + O(h^4),
// with h = 2e-5 times a scale per kind (curvature_scale for curvatures, 40 for vd, 1 otherwise).
inline std::vector<double> mean_spot_central_differences(
    const Lens& lens, const std::vector<PrescriptionVariable>& variables,
    const TraceOptions& options, double curvature_scale) {
  std::vector<double> fd(variables.size());
  for (std::size_t i = 0; i < variables.size(); ++i) {
    const double x0 = variable_value(lens, variables[i]);
    double scale = 1.0;
    if (variables[i].kind == PrescriptionVariable::Kind::kCurvature) scale = curvature_scale;
    if (variables[i].kind == PrescriptionVariable::Kind::kVd) scale = 40.0;
    auto central = [&](double h) {
      Lens plus = lens, minus = lens;
      set_variable_value(plus, variables[i], x0 + h);
      set_variable_value(minus, variables[i], x0 - h);
      return (mean_spot(plus, options) - mean_spot(minus, options)) / (2 * h);
    };
    const double h = 2e-5 * scale;
    fd[i] = (4 * central(h / 2) - central(h)) / 3;
  }
  return fd;
}

}  // namespace lensopt::test
