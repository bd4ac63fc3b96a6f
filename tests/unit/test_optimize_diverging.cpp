// Diverging and afocal lenses in optimize and render (issue 31, item 3): a diverging lens is
// optimized on its virtual image (optimize/virtual_image.h): variables normalized by |f|, the last
// curvature solved for EFL = -|f|, the merit measured on the image plane before the last surface
// (rays traced back to it), the image bounded as a virtual one; its exact gradients (Jets and the
// adjoint) against central finite differences; real Thorlabs negative lenses optimized with
// efl_mm = -50, and analyze of the result gives optimize's figures. render refuses an afocal lens
// (optimize measures it in angle: test_optimize_afocal.cpp).
#include <ceres/jet.h>
#include <doctest/doctest.h>
#include <fmt/format.h>

#include <cmath>
#include <string>

#include "error_checks.h"
#include "lensopt/analysis/analyze.h"
#include "lensopt/formats/lens_file.h"
#include "lensopt/formats/zmx.h"
#include "lensopt/glass/glass.h"
#include "lensopt/joint/imaging.h"
#include "lensopt/lens/lens_io.h"
#include "lensopt/optimize/design_gradient.h"
#include "lensopt/optimize/optimizer.h"
#include "lensopt/optimize/targets.h"
#include "lensopt/optimize/variables.h"
#include "lensopt/optimize/virtual_image.h"
#include "lensopt/paraxial/paraxial.h"
#include "lensopt/render/render.h"
#include "test_support.h"

namespace lensopt::test_optimize_diverging {
namespace {

using test::check_contains;
using test::error_of;

// A Thorlabs negative lens of tests/data/zmx-real with off-axis fields 0, 2, 4 deg.
Lens thorlabs(const char* file) {
  Lens lens = read_zmx(test::source_dir() / "tests" / "data" / "zmx-real" / file).lens;
  lens.specs.fields = {{0.0, 1.0, {}}, {2.0, 1.0, {}}, {4.0, 1.0, {}}};
  lens.specs.half_field_deg = 4.0;
  return lens;
}

// The LD1464-A bi-concave N-BK7 singlet (EFL about -50 mm).
Lens diverging() {
  return thorlabs("thorlabs_LD1464-A.zmx");
}

double paraxial_efl(const Lens& lens) {
  const TraceLens<double> t = make_trace_lens(lens);
  return paraxial_data(t, t.reference_nm()).efl_mm;
}

OptimizeOptions quick_options(const Lens& lens) {
  OptimizeOptions o;
  o.sampling.rings = 6;
  o.sampling.fields = 3;
  o.glass_search = GlassSearch::kNone;
  o.max_iterations = 15;
  o.max_rounds = 2;
  o.verbose = false;
  o.loss = bounds_for(lens, o.loss, BoundsMode::kAuto);
  return o;
}

const TargetRow* row_of(const TargetReport& report, TargetQuantity q) {
  for (const TargetRow& r : report.rows)
    if (r.target.quantity == q) return &r;
  return nullptr;
}

TEST_CASE("optimize diverging: the variables of a negative lens reproduce it, EFL = -|f| exact") {
  const Lens lens = diverging();
  const double efl = paraxial_efl(lens);
  REQUIRE(efl < -49.0);
  const LensParameterization param(lens, GlassSpace(*load_catalog(glass_catalog_for(lens))));
  CHECK(param.focal_length_mm() == efl);
  const std::vector<double> x = param.from_lens(lens);
  // Normalized by |f|: the first curvature is c1 |f| (negative for the concave front).
  CHECK(x[0] == doctest::Approx(lens.surfaces[1].curvature_per_mm * std::abs(efl)).epsilon(1e-14));
  // The catalog glass as make_trace_lens traces it (a fixed glass; a continuous one is a model).
  const std::vector<int> glasses = param.nearest_glasses(x.data());
  const TraceLens<double> traced = param.to_trace_lens(x.data(), GlassMode::kFixed, glasses);
  const TraceLens<double> written = make_trace_lens(lens);
  for (int k = 0; k < written.surface_count(); ++k) {
    INFO("surface ", k + 1);
    CHECK(traced.curvature_per_mm[k] ==
          doctest::Approx(written.curvature_per_mm[k]).epsilon(1e-12).scale(1e-15));
    CHECK(traced.thickness_mm[k] == doctest::Approx(written.thickness_mm[k]).epsilon(1e-12));
  }
  // The image as written is virtual: the last thickness is the (negative) paraxial BFL.
  CHECK(traced.thickness_mm.back() < 0.0);
  CHECK(paraxial_data(traced, traced.reference_nm()).efl_mm == doctest::Approx(efl).epsilon(1e-14));
  // Under a perturbation of the curvature the solve holds EFL = f exactly.
  std::vector<double> moved = x;
  moved[0] *= 1.3;
  const TraceLens<double> bent = param.to_trace_lens(moved.data(), GlassMode::kFixed, glasses);
  CHECK(std::abs(paraxial_data(bent, bent.reference_nm()).efl_mm - efl) <= 1e-12);
}

TEST_CASE("optimize diverging: efl_mm of the lens's own sign scales it; the other sign refused") {
  const SourceLocation where{"cli"};
  const DesignTarget t = parse_target("efl_mm=-50", where);
  CHECK(t.quantity == TargetQuantity::kEflMm);
  CHECK(t.value == -50.0);
  const Lens lens = thorlabs("thorlabs_ACN254-100-A.zmx");
  REQUIRE(paraxial_efl(lens) < -99.0);
  CHECK(paraxial_efl(apply_target_solves(lens, {t})) == doctest::Approx(-50.0).epsilon(1e-12));
  // Through zero, either way: refused with the reason.
  check_contains(error_of([&] { apply_target_solves(lens, {parse_target("efl_mm=50", where)}); }),
                 "through zero");
  const Lens doublet = read_lens(test::source_dir() / "lenses" / "doublet.toml");
  check_contains(error_of([&] { apply_target_solves(doublet, {t}); }), "through zero");
  // A diverging lens's F-number is signed: a target on it is refused, naming what to set.
  check_contains(error_of([&] { apply_target_solves(lens, {parse_target("f_number=5", where)}); }),
                 "epd");
  // The default target of an as-written diverging lens is its own (negative) focal length.
  const std::vector<DesignTarget> defaults = targets_with_defaults(lens, {});
  REQUIRE(defaults.size() == 1);
  CHECK(defaults[0].is_default);
  CHECK(defaults[0].value == paraxial_efl(lens));
}

TEST_CASE("optimize diverging: the virtual-image bounds as overrides (CLI and Python)") {
  const Lens lens = diverging();
  OptimizeOverrides both;
  both.verbose = false;
  both.min_virtual_image_mm = 20.0;
  both.max_virtual_image_mm = 90.0;
  const OptimizeOptions given = resolve_optimize_options(lens, both).options;
  CHECK(given.loss.min_virtual_image_mm == 20.0);
  CHECK(given.loss.max_virtual_image_mm == 90.0);
  // One of them: the other stays the start's derived bound.
  OptimizeOverrides none;
  none.verbose = false;
  const OptimizeOptions derived = resolve_optimize_options(lens, none).options;
  REQUIRE(derived.loss.virtual_image());
  OptimizeOverrides one;
  one.verbose = false;
  one.max_virtual_image_mm = 90.0;
  const OptimizeOptions partly = resolve_optimize_options(lens, one).options;
  CHECK(partly.loss.max_virtual_image_mm == 90.0);
  CHECK(partly.loss.min_virtual_image_mm == derived.loss.min_virtual_image_mm);
  // Bounds that cross are refused (validate), and so is a lens without a virtual image.
  OptimizeOverrides crossed = both;
  crossed.min_virtual_image_mm = 100.0;
  check_contains(error_of([&] { resolve_optimize_options(lens, crossed); }),
                 "below min_virtual_image_mm");
  const Lens doublet = read_lens(test::source_dir() / "lenses" / "doublet.toml");
  check_contains(error_of([&] { resolve_optimize_options(doublet, one); }), "real image");
  const Lens keplerian =
      read_lens(test::source_dir() / "tests" / "data" / "afocal" / "keplerian_telescope.zmx");
  check_contains(error_of([&] { resolve_optimize_options(keplerian, one); }), "afocal");
}

TEST_CASE("optimize diverging: the virtual image's bounds come from the start") {
  const Lens lens = diverging();
  const DesignLossOptions paper;
  std::string why;
  const DesignLossOptions loss = with_virtual_image_bounds(lens, paper, &why);
  REQUIRE(loss.virtual_image());
  check_contains(why, "virtual");
  const double bfl = -lens.surfaces.back().thickness_mm;  // as written: the paraxial image
  REQUIRE(bfl > 40.0);
  MESSAGE("LD1464-A virtual image: ", bfl, " mm before the last surface; bounds [",
          loss.min_virtual_image_mm, ", ", loss.max_virtual_image_mm, "] mm");
  // 0.5x the nearest ray's back travel, 2x the farthest: the start (rays near its BFL) inside.
  CHECK(loss.min_virtual_image_mm > 0.4 * bfl);
  // The back surface curves towards the image (R = +52 mm): every ray off the axis travels
  // further back than the vertex's BFL.
  CHECK(loss.min_virtual_image_mm >= 0.5 * bfl);
  CHECK(loss.min_virtual_image_mm < 0.51 * bfl);
  CHECK(loss.max_virtual_image_mm > 2.0 * bfl);
  CHECK(loss.max_virtual_image_mm < 2.2 * bfl);
  // bounds_for gives them in either mode; a converging lens gets none.
  CHECK(bounds_for(lens, paper, BoundsMode::kPaper).virtual_image());
  CHECK(bounds_for(lens, paper, BoundsMode::kLens).virtual_image());
  const Lens doublet = read_lens(test::source_dir() / "lenses" / "doublet.toml");
  CHECK_FALSE(with_virtual_image_bounds(doublet, paper).virtual_image());
  // The constraint report checks the virtual image's distance, not a real image's clearance, and
  // the start meets its own (lens-derived) bounds: the flat stop the .zmx reader puts 0 mm before
  // the concave front (rays travel back to its sag, -1.2 mm) is no air gap (glass_elements.h).
  const ConstraintReport report =
      check_constraints(lens, bounds_for(lens, paper, BoundsMode::kLens), AnalyzeOptions{}.trace);
  int rows = 0;
  for (const ConstraintReport::Row& r : report.rows) {
    INFO(r.name, " = ", r.value, " (bound ", r.bound, ")");
    CHECK(r.name.find("clearance") == std::string::npos);
    CHECK(r.pass);
    if (r.name.find("virtual image") != std::string::npos) {
      ++rows;
      CHECK(r.pass);
    }
  }
  CHECK(rows == 2);
  CHECK(report.all_pass());
}

// The adjoint and the Jets against central finite differences at a diverging start, with the
// virtual image's bound active (the farthest ray beyond the maximum), to 1e-6.
// The lenses as read: the flat stop the .zmx reader puts 0 mm before the concave stop surface
// bounds no air gap (glass_elements.h), so no ray sits on a hinge's kink there.
void check_gradient(const Lens& lens) {
  const LensParameterization param(lens, GlassSpace(*load_catalog(glass_catalog_for(lens))));
  const std::vector<double> x = param.from_lens(lens);
  TraceOptions sampling;
  sampling.rings = 4;
  sampling.fields = 3;
  DesignLossOptions loss = with_virtual_image_bounds(lens, DesignLossOptions{});
  REQUIRE(loss.virtual_image());
  DesignExtremes ext;
  evaluate_design<double>(param, x.data(), GlassMode::kContinuous, {}, sampling, loss, nullptr,
                          nullptr, nullptr, &ext);
  loss.max_virtual_image_mm = -ext.min_travel_mm.back() - 0.5;  // active: 0.5 mm too far
  loss.min_virtual_image_mm = 0.0;
  loss.min_glass_mm = 0.0;
  loss.min_air_mm = 0.0;
  loss.max_glass_mm = 100.0;
  const DesignValueGradient adj =
      design_loss_gradient(param, x, GlassMode::kContinuous, {}, sampling, loss);
  const DesignValueGradient jets =
      design_loss_gradient_jets(param, x, GlassMode::kContinuous, {}, sampling, loss);
  REQUIRE(adj.finite);
  REQUIRE(adj.loss.ray_path_mm > 0.0);  // the virtual image's bound is active
  REQUIRE(adj.loss.spot_mm > 0.0);
  auto total = [&](const std::vector<double>& at) {
    DesignLoss<double> l;
    evaluate_design<double>(param, at.data(), GlassMode::kContinuous, {}, sampling, loss, nullptr,
                            nullptr, &l);
    return l.total;
  };
  CHECK(adj.loss.total == doctest::Approx(total(x)).epsilon(1e-12));
  for (int i = 0; i < param.size(); ++i) {
    std::vector<double> p = x, m = x;
    const double step = 1e-6;
    p[i] += step;
    m[i] -= step;
    const double fd = (total(p) - total(m)) / (2 * step);
    INFO(lens.name, " variable ", param.variables()[i].name, ": adjoint ", adj.gradient[i],
         " jets ", jets.gradient[i], " fd ", fd);
    CHECK(adj.gradient[i] == doctest::Approx(jets.gradient[i]).epsilon(1e-9).scale(1e-9));
    CHECK(std::abs(jets.gradient[i] - fd) <= 1e-6 * std::max(1.0, std::abs(fd)));
  }
}

TEST_CASE("optimize diverging: adjoint and Jet gradients match central differences to 1e-6") {
  SUBCASE("LD1464-A singlet") {
    check_gradient(diverging());
  }
  SUBCASE("ACN254-100-A negative achromat") {
    check_gradient(thorlabs("thorlabs_ACN254-100-A.zmx"));
  }
}

TEST_CASE("optimize diverging: target residuals on the virtual image match finite differences") {
  const Lens lens = diverging();
  const LensParameterization param(lens, GlassSpace(*load_catalog(glass_catalog_for(lens))));
  const std::vector<double> x = param.from_lens(lens);
  const std::vector<int> glasses = param.nearest_glasses(x.data());
  TraceOptions sampling;
  sampling.rings = 6;
  sampling.fields = 3;
  TargetSampling ts;
  ts.wavefront_grid = make_pupil_quadrature(4, 8, true);
  std::vector<DesignTarget> targets;
  for (const char* text : {"rms_spot_um = 0, field = 3", "bfl_mm = 0", "total_track_mm = 0",
                           "distortion_percent = 0, field = 3"})
    targets.push_back(parse_target(text, SourceLocation{"test"}));
  const int count = target_residual_count(targets, 3);
  REQUIRE(count == 4);
  auto residuals = [&](const std::vector<double>& xs) {
    std::vector<double> r(count);
    REQUIRE(evaluate_targets<double>(param, xs.data(), GlassMode::kFixed, glasses, sampling,
                                     targets, ts, 1.0, 0.01, r.data()));
    return r;
  };
  using J = ceres::Jet<double, 8>;
  REQUIRE(param.size() <= 8);
  std::vector<J> xj(param.size());
  for (int i = 0; i < param.size(); ++i) xj[i] = J(x[i], i);
  std::vector<J> rj(count);
  TargetValues<J> values;
  REQUIRE(evaluate_targets<J>(param, xj.data(), GlassMode::kFixed, glasses, sampling, targets, ts,
                              1.0, 0.01, rj.data(), &values));
  // The BFL is the negative back distance of the virtual image.
  CHECK(values.value[1].a < -40.0);
  const std::vector<double> r0 = residuals(x);
  for (int i = 0; i < param.size(); ++i) {
    if (param.variables()[i].group == "glasses") continue;  // fixed glasses
    const double h = 1e-6 * std::max(1.0, std::abs(x[i]));
    std::vector<double> plus = x, minus = x;
    plus[i] += h;
    minus[i] -= h;
    const std::vector<double> rp = residuals(plus), rm = residuals(minus);
    for (int row = 0; row < count; ++row) {
      const double fd = (rp[row] - rm[row]) / (2 * h);
      INFO("variable ", param.variables()[i].name, ", target ", row, ": jet ", rj[row].v[i], " fd ",
           fd);
      CHECK(rj[row].a == doctest::Approx(r0[row]).epsilon(1e-12));
      CHECK(std::abs(rj[row].v[i] - fd) <= 1e-6 * std::max(1.0, std::abs(fd)));
    }
  }
}

// Optimizes a Thorlabs negative lens for minimum spot at efl_mm = -50 and checks the EFL, the
// spot at the virtual image, the constraints and that analyze gives optimize's figures.
void check_optimized(const Lens& lens) {
  OptimizeOptions o = quick_options(
      apply_target_solves(lens, {parse_target("efl_mm=-50", SourceLocation{"--target"})}));
  o.targets = {parse_target("efl_mm=-50", SourceLocation{"--target"})};
  REQUIRE(o.loss.virtual_image());
  const OptimizeResult r = optimize_lens(lens, o);
  const double efl = paraxial_efl(r.lens);
  MESSAGE(lens.name, ": EFL ", paraxial_efl(lens), " -> ", efl,
          " mm; RMS spot at the virtual "
          "image ",
          r.start_spot_um, " -> ", r.final_spot_um, " um; image ",
          r.lens.surfaces.back().thickness_mm, " mm");
  for (const std::string& line : r.log) MESSAGE("  ", line);
  CHECK(std::abs(efl + 50.0) <= 1e-6);
  const TargetRow* after = row_of(r.final_targets, TargetQuantity::kEflMm);
  REQUIRE(after);
  CHECK(after->pass);
  CHECK(std::isfinite(r.final_spot_um));
  CHECK(r.final_spot_um <= r.start_spot_um);
  CHECK(r.final_constraints.all_pass());
  CHECK(r.lens.surfaces.back().thickness_mm < 0.0);  // the image is still virtual
  // analyze of the result (written and read back) gives optimize's figures.
  const Lens back = parse_lens_toml(format_lens_toml(r.lens), "result.toml");
  const AnalysisReport a = analyze_lens(back, AnalyzeOptions{});
  REQUIRE(a.mean_rms_spot_um);
  CHECK(*a.mean_rms_spot_um == doctest::Approx(r.final_spot_um).epsilon(1e-12));
  CHECK(a.efl_mm == doctest::Approx(-50.0).epsilon(1e-8));
  CHECK(a.virtual_image);
  // And the design loss's own spot (the optimizer's merit code, on Jets in the optimizer) at the
  // analysis sampling equals analyze's, field by field.
  const LensParameterization param(back, GlassSpace(*load_catalog(glass_catalog_for(back))));
  const std::vector<double> x = param.from_lens(back);
  DesignLoss<double> l;
  REQUIRE(evaluate_design<double>(param, x.data(), GlassMode::kFixed,
                                  param.nearest_glasses(x.data()), AnalyzeOptions{}.trace, o.loss,
                                  nullptr, nullptr, &l));
  REQUIRE(l.field_rms_mm.size() == a.fields.size());
  for (std::size_t h = 0; h < a.fields.size(); ++h)
    CHECK(1000.0 * l.field_rms_mm[h] ==
          doctest::Approx(a.fields[h].rms_spot_um.value_or(-1.0)).epsilon(1e-9));
}

TEST_CASE("optimize diverging: Thorlabs negative lenses optimized at efl_mm = -50") {
  SUBCASE("LD1464-A bi-concave singlet") {
    check_optimized(diverging());
  }
  SUBCASE("ACN254-100-A negative achromat, scaled to -50 mm") {
    // Its 12.7 mm clear apertures vignet the 4 deg field once scaled to -50 mm: the optimizer
    // refuses a vignetted start (it traces unclipped pupils), so they are removed here.
    Lens lens = thorlabs("thorlabs_ACN254-100-A.zmx");
    for (Surface& s : lens.surfaces) s.semi_diameter_mm = 0.0;
    check_optimized(lens);
  }
}

TEST_CASE("render refuses an afocal lens, naming what measures it; optimize takes it") {
  const double n = 1.5168;
  const Lens lens = parse_lens_toml(
      fmt::format("[lens]\nname = \"keplerian\"\n[system]\nmode = \"as-written\"\nafocal = true\n"
                  "aperture = \"epd\"\naperture_value = 20\nprimary_wavelength_nm = 587.5618\n"
                  "fields = [0, 1]\n[specs]\nwavelengths_nm = [587.5618]\n"
                  "[[surfaces]]\nradius_mm = inf\nthickness_mm = 0\nstop = true\n"
                  "[[surfaces]]\ncurvature_per_mm = {:.17g}\nthickness_mm = 4\n"
                  "material = {{ nd = 1.5168, vd = 64.17, model = \"opticstudio\" }}\n"
                  "[[surfaces]]\nradius_mm = inf\nthickness_mm = {:.17g}\n"
                  "[[surfaces]]\nradius_mm = inf\nthickness_mm = 4\n"
                  "material = {{ nd = 1.5168, vd = 64.17, model = \"opticstudio\" }}\n"
                  "[[surfaces]]\ncurvature_per_mm = {:.17g}\nthickness_mm = 40\n",
                  1.0 / ((n - 1.0) * 100.0), 125.0 - 8.0 / n, -1.0 / ((n - 1.0) * 25.0)),
      "keplerian.toml");
  // optimize measures it in angle (test_optimize_afocal.cpp): its parameterization holds its
  // angular magnification M = -f1 / f2 = -4.
  const LensParameterization param(lens, GlassSpace(*load_catalog("schott")));
  CHECK(param.afocal());
  CHECK(param.angular_magnification() == doctest::Approx(-4.0).epsilon(1e-9));
  const std::string render = error_of([&] { build_imaging_model(lens, TraceOptions{}, {}); });
  check_contains(render, "render cannot take an afocal lens");
  check_contains(render, "plot --kind spot");
  // Joint image formation renders the image plane too (it used to fail later with "the paraxial
  // image heights do not increase with the field").
  const std::string joint = error_of([&] {
    DifferentiableImaging imaging(param, GlassMode::kQuantized, {}, DifferentiableImagingOptions{});
  });
  check_contains(joint, "joint image formation");
  check_contains(joint, "cannot take an afocal lens");
}

}  // namespace
}  // namespace lensopt::test_optimize_diverging
