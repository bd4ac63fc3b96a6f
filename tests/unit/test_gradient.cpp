// Every derivative of the mean RMS spot (Jets through scaling, pupil, ray aiming, trace and spot)
// against central finite differences with Richardson extrapolation, on the three baselines,
// at a flat surface and on axis.
#include <doctest/doctest.h>

#include <cmath>

#include "lensopt/analysis/gradient.h"
#include "lensopt/formats/lens_file.h"
#include "lensopt/lens/lens_io.h"
#include "test_support.h"

namespace test_gradient {

using namespace lensopt;

namespace {

double mean_spot(const Lens& lens, const TraceOptions& options) {
  const TraceSystem<double> sys = prepare_system(make_trace_lens(lens), lens.specs, options);
  return evaluate_spots(sys, options.threads).mean_rms_spot_mm;
}

// Central difference with one Richardson step: (4 D(h/2) - D(h)) / 3, error O(h^4).
double finite_difference(const Lens& lens, const PrescriptionVariable& v,
                         const TraceOptions& options) {
  const double x0 = variable_value(lens, v);
  double scale = 1.0;
  switch (v.kind) {
    case PrescriptionVariable::Kind::kCurvature:
      scale = 0.05;
      break;
    case PrescriptionVariable::Kind::kThickness:
      scale = 1.0;
      break;
    case PrescriptionVariable::Kind::kNd:
      scale = 1.0;
      break;
    case PrescriptionVariable::Kind::kVd:
      scale = 40.0;
      break;
    default:
      scale = 1.0;
      break;
  }
  auto central = [&](double h) {
    Lens plus = lens, minus = lens;
    set_variable_value(plus, v, x0 + h);
    set_variable_value(minus, v, x0 - h);
    return (mean_spot(plus, options) - mean_spot(minus, options)) / (2 * h);
  };
  // The per-field RMS is hyperbola-like near its minimum, so the spot is strongly curved in some
  // variables (the Tessar's indices most): small steps, with Richardson removing the O(h^2) term.
  const double h = 2e-5 * scale;
  return (4 * central(h / 2) - central(h)) / 3;
}

// Checks every variable; returns the worst relative error. A derivative's error is relative to
// its own size, floored at 1e-3 of the gradient's largest (variable-scaled) entry so that a
// derivative that is zero up to rounding is not held to a relative bound.
double check_gradient(const Lens& lens, const TraceOptions& options) {
  const std::vector<PrescriptionVariable> variables = all_prescription_variables(lens);
  const SpotGradient g =
      mean_spot_gradient<8>(make_trace_lens(lens), lens.specs, variables, options);
  CHECK(g.mean_rms_spot_mm == doctest::Approx(mean_spot(lens, options)).epsilon(1e-12));
  double largest = 0;
  for (double d : g.gradient) largest = std::max(largest, std::abs(d));
  double worst = 0;
  for (std::size_t i = 0; i < variables.size(); ++i) {
    const double fd = finite_difference(lens, variables[i], options);
    const double denominator = std::max(std::abs(g.gradient[i]), 1e-6 * largest);
    const double error = std::abs(g.gradient[i] - fd) / denominator;
    INFO(lens.name, " d/d", variables[i].name(), ": jet ", g.gradient[i], " fd ", fd);
    CHECK(error < 1e-5);
    worst = std::max(worst, error);
  }
  return worst;
}

}  // namespace

TEST_CASE("gradient: Jet derivatives of the mean spot match finite differences (baselines)") {
  for (const char* name : {"doublet", "cooke", "tessar"}) {
    const Lens lens = read_lens(test::source_dir() / "lenses" / (std::string(name) + ".toml"));
    TraceOptions options;  // full paper sampling, ray aiming on, scaled to the spec
    const double worst = check_gradient(lens, options);
    MESSAGE(name, ": ", all_prescription_variables(lens).size(),
            " variables, worst relative error ", worst);
  }
}

TEST_CASE("gradient: without scaling and without ray aiming") {
  const Lens lens = read_lens(test::source_dir() / "lenses" / "cooke.toml");
  TraceOptions options;
  options.rings = 12;
  options.fields = 7;
  options.scale_to_spec = false;
  check_gradient(lens, options);
  options.ray_aiming = false;
  check_gradient(lens, options);
}

TEST_CASE("gradient: at a flat refracting surface and on axis") {
  // Flatten the front surface of the Doublet's second element (c = 0 exactly) and differentiate
  // there: the intersection's F / (G + sqrt(zeta)) form keeps the derivative finite.
  Lens lens = read_lens(test::source_dir() / "lenses" / "doublet.toml");
  int flat = -1;
  for (std::size_t k = 0; k < lens.surfaces.size(); ++k) {
    if (!lens.surfaces[k].is_stop && k > 0 && flat < 0 && k + 1 < lens.surfaces.size() &&
        !lens.surfaces[k].material.is_air()) {
      flat = static_cast<int>(k);
    }
  }
  REQUIRE(flat >= 0);
  lens.surfaces[flat].curvature_per_mm = 0.0;
  TraceOptions options;
  options.rings = 16;
  options.fields = 5;
  check_gradient(lens, options);
  // On axis only: one field at 0 deg (no ray aiming applies there).
  options.fields = 1;
  check_gradient(lens, options);
}

}  // namespace test_gradient
