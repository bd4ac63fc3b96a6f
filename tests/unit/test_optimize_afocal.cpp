// optimize on an afocal lens (issue 31, item 3; optimize/design_loss.h "Afocal merit",
// optimize/variables.h, paraxial/afocal.h): the merit is the RMS angular spot, the one
// implementation analyze runs (analysis/angular_spot.h), so the optimizer's merit equals analyze's
// figure on the same lens; its Jet derivatives match central differences; the last curvature
// holds the angular magnification (the lens's own, or a requested one applied to the start); the
// shipped Keplerian telescope (two plano-convex singlets, spherical aberration and colour)
// improves and analyze of the result gives optimize's figure.
#include <ceres/jet.h>
#include <doctest/doctest.h>
#include <fmt/format.h>

#include <cmath>
#include <string>
#include <vector>

#include "error_checks.h"
#include "lensopt/analysis/afocal.h"
#include "lensopt/analysis/analyze.h"
#include "lensopt/formats/lens_file.h"
#include "lensopt/glass/glass.h"
#include "lensopt/lens/lens_io.h"
#include "lensopt/optimize/design_gradient.h"
#include "lensopt/optimize/optimizer.h"
#include "lensopt/optimize/targets.h"
#include "lensopt/optimize/variables.h"
#include "lensopt/paraxial/afocal.h"
#include "test_support.h"

namespace lensopt::test_optimize_afocal {
namespace {

using test::check_contains;
using test::error_of;

// The shipped 4x Keplerian telescope (tests/data/afocal/README.md), its clear apertures kept.
Lens keplerian() {
  return read_lens(test::source_dir() / "tests" / "data" / "afocal" / "keplerian_telescope.zmx");
}

double magnification(const Lens& lens) {
  const TraceLens<double> traced = make_trace_lens(lens);
  return paraxial_angular_magnification(traced, traced.reference_nm());
}

// The RMS exit angle (mrad) a residual power P (diopters) alone gives a uniform exit beam of
// radius r (mm): P r / sqrt(2) / 1000 rad.
double residual_spread_mrad(const AfocalReport& r) {
  const double radius_mm = 0.5 * r.first_order.exit_pupil_diameter_mm;
  return std::abs(r.first_order.residual_power_diopters) * radius_mm / std::sqrt(2.0);
}

LensParameterization parameterization(const Lens& lens) {
  return LensParameterization(lens, GlassSpace(*load_catalog(glass_catalog_for(lens))));
}

TEST_CASE("optimize afocal: the merit is analyze's RMS angular spot on the same lens") {
  const Lens start = keplerian();
  REQUIRE(start.specs.afocal);
  const LensParameterization param = parameterization(start);
  CHECK(param.afocal());
  CHECK(param.angular_magnification() == doctest::Approx(-4.0).epsilon(1e-9));
  const std::vector<double> x = param.from_lens(start);
  // The lens of the variables, written out (the lens the merit traces), and analyzed.
  const Lens same = param.to_lens(x.data(), GlassMode::kContinuous);
  const TraceOptions trace = AnalyzeOptions{}.trace;
  DesignLoss<double> loss;
  REQUIRE(evaluate_design<double>(param, x.data(), GlassMode::kContinuous, {}, trace,
                                  DesignLossOptions{}, nullptr, nullptr, &loss));
  CHECK(loss.afocal);
  AfocalOptions afocal;
  afocal.wavefront = false;
  const AfocalReport report = analyze_afocal_lens(same, trace, afocal);
  REQUIRE(report.fields.size() == loss.field_angular_spot_rad.size());
  REQUIRE(report.mean_rms_angular_spot_mrad);
  for (std::size_t h = 0; h < report.fields.size(); ++h) {
    REQUIRE(report.fields[h].rms_angular_spot_mrad);
    const double analyze_mrad = *report.fields[h].rms_angular_spot_mrad;
    const double merit_mrad = 1e3 * loss.field_angular_spot_rad[h];
    INFO("field ", h, ": analyze ", analyze_mrad, " mrad, merit ", merit_mrad, " mrad");
    CHECK(analyze_mrad > 0.0);
    CHECK(std::abs(merit_mrad - analyze_mrad) <= 1e-12 * analyze_mrad);
  }
  const double mean = *report.mean_rms_angular_spot_mrad;
  CHECK(std::abs(1e3 * loss.angular_spot_rad - mean) <= 1e-12 * mean);
  // The merit in mm is L times the angle, L the vertex length (design_loss.h).
  CHECK(param.length_unit_mm() == doctest::Approx(4.0 + 119.72573839662448 + 4.0).epsilon(1e-12));
  CHECK(loss.spot_mm == doctest::Approx(param.length_unit_mm() * loss.angular_spot_rad));
  // The least-squares residuals sum (squared) to the merit at the reweighted point: with
  // a_h = phi_h / (Phi L A_h) the sum of squares is L * mean A (design_loss.h).
  std::vector<double> a(loss.field_rms_mm.size());
  for (std::size_t h = 0; h < a.size(); ++h) a[h] = 1.0 / (a.size() * loss.field_rms_mm[h]);
  const int n = static_cast<int>(param.structure().surfaces.size());
  const DesignSampling sampled = design_sampling(param.structure(), trace);
  const int rays = static_cast<int>(paper_pupil_samples(trace.rings).size());
  const int spot_rows = sampled.spot_fields * 3 * rays * 2;  // 3 wavelengths
  std::vector<double> r(
      design_residual_count(sampled.spot_fields,
                            static_cast<int>(sampled.setup.field_values.size()), 3, rays, n, 2),
      0.0);
  DesignLoss<double> again;
  REQUIRE(evaluate_design<double>(param, x.data(), GlassMode::kContinuous, {}, trace,
                                  DesignLossOptions{}, &a, r.data(), &again));
  double sum = 0.0;
  for (int i = 0; i < spot_rows; ++i) sum += r[i] * r[i];
  CHECK(sum == doctest::Approx(loss.spot_mm).epsilon(1e-9));
  CHECK(n == 5);
}

TEST_CASE("optimize afocal: Jet derivatives of the angular spot match central differences") {
  const Lens start = keplerian();
  const LensParameterization param = parameterization(start);
  constexpr int kWidth = 16;
  REQUIRE(param.size() <= kWidth);
  std::vector<double> x = param.from_lens(start);
  TraceOptions sampling;
  sampling.rings = 4;
  auto merit = [&](const std::vector<double>& xs) {
    DesignLoss<double> l;
    evaluate_design<double>(param, xs.data(), GlassMode::kContinuous, {}, sampling,
                            DesignLossOptions{}, nullptr, nullptr, &l);
    return l.angular_spot_rad;
  };
  auto held_m = [&](const auto* xs) {
    using T = std::remove_cv_t<std::remove_pointer_t<decltype(xs)>>;
    const TraceLens<T> tl = param.to_trace_lens(xs, GlassMode::kContinuous);
    return paraxial_angular_magnification(tl, tl.reference_nm());
  };
  using J = ceres::Jet<double, kWidth>;
  std::vector<J> xj(param.size());
  for (int i = 0; i < param.size(); ++i) xj[i] = J(x[i], i);
  DesignLoss<J> lj;
  REQUIRE(evaluate_design<J>(param, xj.data(), GlassMode::kContinuous, {}, sampling,
                             DesignLossOptions{}, nullptr, nullptr, &lj));
  CHECK(lj.angular_spot_rad.a == doctest::Approx(merit(x)).epsilon(1e-12));
  // The angular magnification is held by the solve: M = -4 and dM/dx = 0 for every variable.
  const J mj = held_m(xj.data());
  CHECK(mj.a == doctest::Approx(-4.0).epsilon(1e-9));
  for (int i = 0; i < param.size(); ++i) CHECK(std::abs(mj.v[i]) <= 1e-10);
  int checked = 0;
  for (int i = 0; i < param.size(); ++i) {
    const double jet = lj.angular_spot_rad.v[i];
    auto central = [&](double h) {
      std::vector<double> plus = x, minus = x;
      plus[i] += h;
      minus[i] -= h;
      return (merit(plus) - merit(minus)) / (2 * h);
    };
    // Ridders-style: Richardson on halving steps, the pair that agrees best (as
    // test_optimize_wavefront.cpp); a variable without effect (held ones too) has jet 0.
    double h = 1e-3 * std::max(1.0, std::abs(x[i]));
    constexpr int kSteps = 10;
    double d[kSteps + 1], rr[kSteps];
    for (int k = 0; k <= kSteps; ++k) d[k] = central(h / (1 << k));
    for (int k = 0; k < kSteps; ++k) rr[k] = (4 * d[k + 1] - d[k]) / 3;
    int best = 0;
    for (int k = 1; k + 1 < kSteps; ++k)
      if (std::abs(rr[k + 1] - rr[k]) < std::abs(rr[best + 1] - rr[best])) best = k;
    const double fd = rr[best + 1];
    const double scale = std::max(std::abs(fd), 1e-6);
    INFO("d/d", param.variables()[i].name, ": jet ", jet, " fd ", fd);
    CHECK(std::abs(jet - fd) <= 1e-6 * scale);
    if (std::abs(fd) > 1e-6) ++checked;
  }
  CHECK(checked >= 4);  // the curvatures and spacings move the angular spot
}

TEST_CASE("optimize afocal: the Keplerian telescope improves, holds or reaches its magnification") {
  const Lens start = keplerian();
  OptimizeOverrides overrides;
  overrides.verbose = false;
  SUBCASE("its own magnification held (no target given)") {
    const OptimizeOptions options = resolve_optimize_options(start, overrides).options;
    const OptimizeResult result = optimize_lens(start, options);
    REQUIRE(result.afocal);
    MESSAGE("Keplerian 4x: mean RMS angular spot ", result.start_angular_spot_mrad, " -> ",
            result.final_angular_spot_mrad, " mrad; ", result.iterations, " iterations");
    CHECK_FALSE(result.kept_start);
    CHECK(result.final_angular_spot_mrad < 0.5 * result.start_angular_spot_mrad);
    CHECK(result.final_constraints.all_pass());
    CHECK(result.final_targets.all_pass());
    REQUIRE(!result.final_targets.rows.empty());
    CHECK(result.final_targets.rows[0].target.quantity == TargetQuantity::kAngularMagnification);
    CHECK(result.final_targets.rows[0].target.is_default);
    CHECK(std::abs(magnification(result.lens) - magnification(start)) <= 1e-6);
    // analyze of the result gives optimize's figure.
    AfocalOptions afocal;
    afocal.wavefront = false;
    const AfocalReport report = analyze_afocal_lens(result.lens, AnalyzeOptions{}.trace, afocal);
    REQUIRE(report.mean_rms_angular_spot_mrad);
    CHECK(*report.mean_rms_angular_spot_mrad ==
          doctest::Approx(result.final_angular_spot_mrad).epsilon(1e-12));
    CHECK(report.first_order.angular_magnification == doctest::Approx(-4.0).epsilon(1e-6));
    // Still afocal: the residual power P the merit leaves balances the spherical aberration and
    // colour; as a pure defocus it would spread the exit beam (radius r = D_XP / 2) over an RMS
    // angle P r / sqrt(2), which stays below the final angular spot (measured: 0.212 diopters,
    // 0.38 mrad against 1.41 mrad).
    MESSAGE("residual power after: ", report.first_order.residual_power_diopters, " diopters");
    CHECK(residual_spread_mrad(report) < *report.mean_rms_angular_spot_mrad);
  }
  SUBCASE("a requested magnification is reached") {
    overrides.targets.push_back(
        parse_target("angular_magnification=-5", SourceLocation{"--target"}));
    const OptimizeOptions options = resolve_optimize_options(start, overrides).options;
    const OptimizeResult result = optimize_lens(start, options);
    MESSAGE("Keplerian to 5x: mean RMS angular spot ", result.start_angular_spot_mrad, " -> ",
            result.final_angular_spot_mrad, " mrad; ", result.iterations, " iterations");
    CHECK_FALSE(result.kept_start);
    CHECK(std::abs(magnification(result.lens) - (-5.0)) <= 1e-6);
    CHECK(result.final_targets.all_pass());
    CHECK(result.final_constraints.all_pass());
    CHECK_FALSE(result.start_targets.all_pass());  // the start is 4x
    AfocalOptions afocal;
    afocal.wavefront = false;
    const AfocalReport report = analyze_afocal_lens(result.lens, AnalyzeOptions{}.trace, afocal);
    REQUIRE(report.mean_rms_angular_spot_mrad);
    CHECK(*report.mean_rms_angular_spot_mrad ==
          doctest::Approx(result.final_angular_spot_mrad).epsilon(1e-12));
    MESSAGE("residual power after: ", report.first_order.residual_power_diopters, " diopters");
    CHECK(residual_spread_mrad(report) < *report.mean_rms_angular_spot_mrad);
  }
}

TEST_CASE("optimize afocal: what does not apply to an afocal lens is refused, saying why") {
  const Lens start = keplerian();
  auto targets_error = [&](const char* text) {
    return error_of(
        [&] { targets_with_defaults(start, {parse_target(text, SourceLocation{"--target"})}); });
  };
  check_contains(targets_error("efl_mm=100"), "has no focal length");
  check_contains(targets_error("f_number=4"), "angular_magnification");
  check_contains(targets_error("rms_spot_um<=5"), "measured on an image plane");
  // total_track_mm is a target of an afocal lens.
  CHECK(targets_with_defaults(start, {parse_target("total_track_mm<=200", SourceLocation{"t"})})
            .size() == 2);
  const LensParameterization param = parameterization(start);
  check_contains(error_of([&] { choose_variables(param, {}, {}, true); }),
                 "an afocal lens has no image distance to refocus");
  // The last thickness is not a variable of an afocal lens (it does not move the exit rays).
  const VariableChoice choice = choose_variables(param, {}, {}, false);
  bool defocus_held = false;
  for (int i : choice.held)
    defocus_held = defocus_held || param.variables()[i].kind == LensVariable::Kind::kDefocus;
  CHECK(defocus_held);
  OptimizeOptions wave;
  wave.loss.merit = DesignMerit::kWavefront;
  wave.verbose = false;
  check_contains(error_of([&] { optimize_lens(start, wave); }),
                 "wavefront merit of an afocal lens");
  // A focusing lens has no angular magnification target.
  const Lens doublet = read_lens(test::source_dir() / "lenses" / "doublet.toml");
  check_contains(error_of([&] {
                   Lens l = doublet;
                   l.specs.mode = SpecMode::kAsWritten;
                   targets_with_defaults(
                       l, {parse_target("angular_magnification=-4", SourceLocation{"--target"})});
                 }),
                 "target of an afocal lens");
}

}  // namespace
}  // namespace lensopt::test_optimize_afocal
