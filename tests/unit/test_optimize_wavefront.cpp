// The optimizer's wavefront merit (optimize/design_loss.h, DesignMerit::kWavefront): its value
// is the analysis's mean RMS wavefront (analysis/wavefront.h) of the same system, its residuals'
// sum of squares is the reweighted merit, its Jet derivatives with respect to every optimizer
// variable (curvatures, spacings, defocus, continuous glasses, conic and asphere terms) match
// central finite differences within 1e-6 relative, and a short run lowers the RMS wavefront.
#include <ceres/jet.h>
#include <doctest/doctest.h>

#include <algorithm>
#include <cmath>
#include <limits>
#include <string>
#include <utility>
#include <vector>

#include "lensopt/analysis/wavefront.h"
#include "lensopt/core/error.h"
#include "lensopt/formats/lens_file.h"
#include "lensopt/lens/lens_io.h"
#include "lensopt/optimize/optimizer.h"
#include "test_support.h"

namespace test_optimize_wavefront {

using namespace lensopt;

namespace {

TraceOptions wave_sampling() {
  TraceOptions t;
  t.rings = 4;
  t.fields = 3;
  return t;
}

DesignLossOptions wave_loss() {
  DesignLossOptions o;
  o.merit = DesignMerit::kWavefront;
  o.wavefront_pupil_samples = 10;
  return o;
}

int residuals_of(const LensParameterization& param, const TraceOptions& sampling,
                 const DesignLossOptions& loss) {
  const Lens& lens = param.structure();
  int glasses = 0;
  for (const LensVariable& v : param.variables()) glasses += v.kind == LensVariable::Kind::kGlass0;
  // The design loss's sampling: the paper's fields, or a lens's own (design_sampling.h).
  const DesignSampling sampled = design_sampling(lens, sampling);
  return design_residual_count(loss, sampled.spot_fields,
                               static_cast<int>(sampled.setup.field_values.size()),
                               static_cast<int>(lens.specs.wavelengths_nm.size()),
                               static_cast<int>(paper_pupil_samples(sampling.rings).size()),
                               static_cast<int>(lens.surfaces.size()), glasses);
}

// Jet derivatives of the mean RMS wavefront against central differences for every variable of
// `param`, continuous glasses, within 1e-6 relative. `moved`: variables moved off the start by an
// amount (name, dx).
//
// The differences. The merit is an RMS of optical path differences of ~f = 100 mm paths, so its
// value carries rounding noise eps_f of a few 1e-12 waves (measured on the AC254: 3e-12, the
// scatter about the tangent over steps of 1e-12; one ulp of 100 mm is 3e-11 waves at 486 nm). A
// Richardson-extrapolated central difference R(h) = (4 D(h/2) - D(h)) / 3 errs by truncation
// ~ h^4 plus rounding ~ 2 eps_f / (h |f'|), so no one step serves every variable: on the AC254
// the old fixed step 2e-5 gave s1 (the lens moved against the stop in collimated space, f' =
// 0.017 waves per f) 3e-5 relative and g2.1 2e-6, both rounding (the error grew as 1/h below
// h = 1e-4, and at h = 1e-3 ... 1e-2 every variable but the steep defocus and a4_4 agreed with
// its Jet within 1.1e-7), while the Cooke's s5 (f' = 0.031 near a minimum) needs h <= 1e-3
// against truncation (measured 2026-11-25; with the steps below every variable of both lenses
// agrees within 6e-8). So, as Ridders' method does, R is taken on the steps h_k = h_0 / 2^k, k =
// 0..9 (h_0 = 1e-2 of the variable's scale, or less where the merit would move by more than 1e-2
// waves), and the estimate is the one where two successive steps agree best; that agreement is
// its error estimate, checked to be well below the tolerance (the check means something).
void check_wavefront_derivatives(const LensParameterization& param,
                                 const std::vector<std::pair<std::string, double>>& moved = {}) {
  constexpr int kWidth = 24;
  REQUIRE(param.size() <= kWidth);
  std::vector<double> x = param.from_lens(param.structure());
  for (const auto& [name, dx] : moved)
    for (int i = 0; i < param.size(); ++i)
      if (param.variables()[i].name == name) x[i] += dx;
  const TraceOptions sampling = wave_sampling();
  const DesignLossOptions loss = wave_loss();
  auto merit = [&](const std::vector<double>& xs) {
    DesignLoss<double> l;
    evaluate_design<double>(param, xs.data(), GlassMode::kContinuous, {}, sampling, loss, nullptr,
                            nullptr, &l);
    return l.wavefront_waves;
  };
  using J = ceres::Jet<double, kWidth>;
  std::vector<J> xj(param.size());
  for (int i = 0; i < param.size(); ++i) xj[i] = J(x[i], i);
  DesignLoss<J> lj;
  evaluate_design<J>(param, xj.data(), GlassMode::kContinuous, {}, sampling, loss, nullptr, nullptr,
                     &lj);
  CHECK(lj.wavefront_waves.a == doctest::Approx(merit(x)).epsilon(1e-11));
  CHECK(lj.wavefront_waves.a > 0.0);
  MESSAGE(param.structure().name, ": mean RMS wavefront ", lj.wavefront_waves.a, " waves, ",
          param.size(), " variables");
  double worst = 0;
  for (int i = 0; i < param.size(); ++i) {
    auto central = [&](double h) {
      std::vector<double> plus = x, minus = x;
      plus[i] += h;
      minus[i] -= h;
      return (merit(plus) - merit(minus)) / (2 * h);
    };
    const double jet = lj.wavefront_waves.v[i];
    double h = 1e-2 * std::max(1.0, std::abs(x[i]));
    if (std::abs(jet) * h > 1e-2) h = 1e-2 / std::abs(jet);
    constexpr int kSteps = 10;
    double d[kSteps + 1], r[kSteps];
    for (int k = 0; k <= kSteps; ++k) d[k] = central(h / (1 << k));
    for (int k = 0; k < kSteps; ++k) r[k] = (4 * d[k + 1] - d[k]) / 3;
    int best = 0;
    for (int k = 1; k + 1 < kSteps; ++k)
      if (std::abs(r[k + 1] - r[k]) < std::abs(r[best + 1] - r[best])) best = k;
    const double fd = r[best + 1];
    const double fd_error = std::abs(r[best + 1] - r[best]);
    const double scale = std::max(std::abs(fd), 1e-3);
    INFO("d/d", param.variables()[i].name, ": jet ", jet, " fd ", fd, " (+- ", fd_error,
         ") at h = ", h / (2 << best));
    CHECK(fd_error <= 2e-7 * scale);
    CHECK(std::abs(jet - fd) <= 1e-6 * scale);
    worst = std::max(worst, std::abs(jet - fd) / scale);
  }
  MESSAGE(param.structure().name, ": largest |jet - fd| / |fd| ", worst);
}

}  // namespace

TEST_CASE("optimize wavefront: the merit is the analysis's RMS wavefront; residuals sum to it") {
  const Lens lens = read_lens(test::source_dir() / "lenses/cooke.toml");
  const LensParameterization param(lens, GlassSpace(*load_catalog("ohara")));
  const std::vector<double> x = param.from_lens(lens);
  const std::vector<int> glasses = param.nearest_glasses(x.data());
  const TraceOptions sampling = wave_sampling();
  DesignLossOptions loss = wave_loss();
  loss.weight_ray_path = loss.weight_ray_angle = loss.weight_glass = 0;  // the merit alone
  DesignLoss<double> l;
  evaluate_design<double>(param, x.data(), GlassMode::kFixed, glasses, sampling, loss, nullptr,
                          nullptr, &l);
  REQUIRE(l.field_wavefront_waves.size() == 3);
  CHECK(l.merit_value() == l.wavefront_waves);

  // The same system as evaluate_design builds (paper mode, the forward map's lens), analysed.
  TraceOptions topt = sampling;
  topt.scale_to_spec = false;
  Specs specs = lens.specs;
  specs.mode = SpecMode::kPaper;
  const TraceSystem<double> sys =
      prepare_system(param.to_trace_lens(x.data(), GlassMode::kFixed, glasses), specs, topt);
  // The merit's half quadrature against the full one (both halves traced): the mirror is exact.
  const int n = loss.wavefront_pupil_samples;
  const double analysed = mean_rms_wavefront(
      sys,
      make_pupil_quadrature(wavefront_merit_rings(n), wavefront_merit_half_azimuths(n), false));
  CHECK(l.wavefront_waves == doctest::Approx(analysed).epsilon(1e-12));
  // ... and near the analysis's square grid at fine sampling (the same wavefront, the same
  // integral; measured 3e-5 relative, the 256 x 256 grid's own rim error being of that order).
  const double fine = mean_rms_wavefront(sys, make_pupil_grid(256));
  MESSAGE("Cooke start, 3 fields: merit ", l.wavefront_waves, " waves, 256 x 256 grid ", fine);
  CHECK(l.wavefront_waves == doctest::Approx(fine).epsilon(2e-4));

  // Sum of squares at the reweighting point a_h = 1 / (F W_h) is the mean RMS wavefront.
  std::vector<double> weights;
  for (double w : l.field_wavefront_waves) weights.push_back(1.0 / (3 * w));
  std::vector<double> r(residuals_of(param, sampling, loss));
  evaluate_design<double>(param, x.data(), GlassMode::kFixed, glasses, sampling, loss, &weights,
                          r.data(), nullptr);
  double sum = 0;
  for (double v : r) sum += v * v;
  CHECK(sum == doctest::Approx(l.wavefront_waves).epsilon(1e-12));
  // In mm (the optimizer's unit): the sum of squares and l_lens scale by the unit, the merit not.
  DesignLossOptions in_mm = loss;
  in_mm.wavefront_unit_mm = 0.0115;
  std::vector<double> r_mm(r.size());
  DesignLoss<double> l_mm;
  evaluate_design<double>(param, x.data(), GlassMode::kFixed, glasses, sampling, in_mm, &weights,
                          r_mm.data(), &l_mm);
  double sum_mm = 0;
  for (double v : r_mm) sum_mm += v * v;
  CHECK(sum_mm == doctest::Approx(0.0115 * l.wavefront_waves).epsilon(1e-12));
  CHECK(l_mm.wavefront_waves == l.wavefront_waves);
  CHECK(l_mm.total == doctest::Approx(0.0115 * l.wavefront_waves).epsilon(1e-12));
  // ... and its gradient is twice the merit's (Jets on both sides).
  using J = ceres::Jet<double, 24>;
  REQUIRE(param.size() <= 24);
  std::vector<J> xj(param.size());
  for (int i = 0; i < param.size(); ++i) xj[i] = J(x[i], i);
  std::vector<J> rj(r.size());
  DesignLoss<J> lj;
  evaluate_design<J>(param, xj.data(), GlassMode::kFixed, glasses, sampling, loss, &weights,
                     rj.data(), &lj);
  J sum_j = J(0.0);
  for (const J& v : rj) sum_j += v * v;
  for (int i = 0; i < param.size(); ++i) {
    if (param.variables()[i].group == "glasses") continue;
    INFO("variable ", param.variables()[i].name);
    CHECK(sum_j.v[i] == doctest::Approx(2 * lj.wavefront_waves.v[i]).epsilon(1e-9));
  }
}

TEST_CASE("optimize wavefront: RMS wavefront derivatives match finite differences (Cooke)") {
  const Lens lens = read_lens(test::source_dir() / "lenses/cooke.toml");
  check_wavefront_derivatives(LensParameterization(lens, GlassSpace(*load_catalog("ohara"))));
}

TEST_CASE(
    "optimize wavefront: RMS wavefront derivatives match finite differences (AC254 + k, a4)") {
  // Not one of the paper's lenses: a Zemax import, with a conic and an asphere term as variables.
  const Lens lens = read_lens(test::source_dir() / "lenses/zmx/achromat_ac254_100.zmx");
  const LensParameterization param(lens, GlassSpace(*load_catalog("ohara")), {"k2", "a4_4"});
  bool conic = false, asphere = false;
  for (const LensVariable& v : param.variables()) {
    conic |= v.kind == LensVariable::Kind::kConic;
    asphere |= v.kind == LensVariable::Kind::kAsphere;
  }
  REQUIRE(conic);
  REQUIRE(asphere);
  // s1 (the stop, inserted flat at the first surface's vertex, to that surface) is a weak
  // variable: see the step of check_wavefront_derivatives.
  check_wavefront_derivatives(param);
}

TEST_CASE("optimize wavefront: a short --merit wavefront run lowers the RMS wavefront") {
  const Lens lens = read_lens(test::source_dir() / "lenses/zmx/achromat_ac254_100.zmx");
  OptimizeOptions options;
  options.sampling = wave_sampling();
  options.loss = bounds_for(lens, options.loss, BoundsMode::kAuto);
  options.loss.merit = DesignMerit::kWavefront;
  options.loss.wavefront_pupil_samples = 10;
  options.max_iterations = 10;
  options.max_rounds = 1;
  options.verbose = false;
  const OptimizeResult result = optimize_lens(lens, options);
  MESSAGE("AC254: RMS wavefront ", result.start_wavefront_waves, " -> ",
          result.final_wavefront_waves, " waves; spot ", result.start_spot_um, " -> ",
          result.final_spot_um, " um");
  CHECK(result.start_wavefront_waves > 0.0);
  CHECK(!result.kept_start);
  CHECK(result.final_wavefront_waves < 0.9 * result.start_wavefront_waves);
  CHECK(std::isfinite(result.final_spot_um));
}

TEST_CASE("optimize wavefront: bad merit options are rejected") {
  DesignLossOptions loss;
  loss.wavefront_pupil_samples = 2;
  CHECK_THROWS_WITH_AS(loss.validate(), doctest::Contains("wavefront_pupil_samples"), Error);
  DesignLossOptions unit;
  unit.wavefront_unit_mm = -1.0;
  CHECK_THROWS_WITH_AS(unit.validate(), doctest::Contains("wavefront_unit_mm"), Error);
}

}  // namespace test_optimize_wavefront
