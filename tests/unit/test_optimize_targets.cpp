// The designer's targets (optimize/targets.h): parsing (--target text, [[optimize.targets]] with
// file:line), the residuals' exact Jacobians against central finite differences, the solved
// targets (efl_mm, f_number) and the target table on real lenses; --focus-only; the clear
// apertures and the lens-derived bounds that never fall back in silence.
#include <ceres/jet.h>
#include <doctest/doctest.h>

#include <cmath>
#include <fstream>
#include <limits>

#include "lensopt/analysis/analyze.h"
#include "lensopt/core/error.h"
#include "lensopt/formats/lens_file.h"
#include "lensopt/lens/lens_io.h"
#include "lensopt/optimize/optimizer.h"
#include "lensopt/optimize/targets.h"
#include "lensopt/paraxial/paraxial.h"
#include "test_support.h"

namespace test_optimize_targets {

using namespace lensopt;

namespace {

// The 100 mm achromat (AC254-100) at a 300 mm object, object heights 0, 6, 12 mm: the lens of
// issue 31.
Lens achromat_at_300mm() {
  Lens lens = read_lens(test::source_dir() / "lenses" / "zmx" / "achromat_ac254_100.zmx");
  lens.specs.object_distance_mm = 300.0;
  lens.specs.field_type = FieldType::kObjectHeight;
  lens.specs.fields = {{0.0, 1.0, {}}, {6.0, 1.0, {}}, {12.0, 1.0, {}}};
  return lens;
}

double paraxial_efl(const Lens& lens) {
  const TraceLens<double> t = make_trace_lens(lens);
  return paraxial_data(t, t.reference_nm()).efl_mm;
}

TraceOptions small_sampling() {
  TraceOptions t;
  t.rings = 6;
  t.fields = 5;
  return t;
}

OptimizeOptions quick_options(const Lens& lens) {
  OptimizeOptions o;
  o.sampling = small_sampling();
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

}  // namespace

TEST_CASE("optimize targets: --target text and its errors") {
  const SourceLocation where{"--target"};
  DesignTarget t = parse_target("efl_mm=100", where);
  CHECK(t.quantity == TargetQuantity::kEflMm);
  CHECK(t.relation == TargetRelation::kEqual);
  CHECK(t.value == 100.0);
  t = parse_target(" distortion_percent <= 1 ", where);
  CHECK(t.quantity == TargetQuantity::kDistortionPercent);
  CHECK(t.relation == TargetRelation::kAtMost);
  CHECK(t.value == 1.0);
  t = parse_target("rms_spot_um<=5,field=2,weight=3", where);
  CHECK(t.relation == TargetRelation::kAtMost);
  CHECK(t.field == 2);
  CHECK(t.weight == 3.0);
  t = parse_target("relative_illumination>=0.6", where);
  CHECK(t.relation == TargetRelation::kAtLeast);
  CHECK(target_text(parse_target("rms_spot_um<=5,field=2,weight=3", where)) ==
        "rms_spot_um[field 2] <= 5 (weight 3)");
  auto fails = [&](const char* text, const char* part) {
    INFO(text);
    try {
      parse_target(text, where);
      FAIL("accepted");
    } catch (const Error& e) {
      CHECK(std::string(e.what()).find(part) != std::string::npos);
    }
  };
  fails("focal=100", "unknown target quantity 'focal'");
  fails("efl_mm<100", "the relation must be =, <= or >=");
  fails("efl_mm=abc", "is not a finite number");
  fails("efl_mm=0", "must be nonzero");  // -5 is a diverging lens: test_optimize_diverging.cpp
  fails("total_track_mm<=130,field=2", "a whole-lens quantity has no field");
  fails("rms_spot_um<=5,colour=red", "must be weight=W, field=N, or for mtf freq=NU");
  fails("rms_spot_um<=5,weight=0", "weight = 0 must be");
  fails("efl_mm", "write NAME=VALUE");
}

TEST_CASE("optimize targets: [[optimize.targets]] reads back from TOML with file:line errors") {
  const Lens base = read_lens(test::source_dir() / "lenses" / "doublet.toml");
  const std::string lens_text = format_lens_toml(base);
  const std::string table =
      "\n[[optimize.targets]]\nefl_mm = 50\n\n"
      "[[optimize.targets]]\ndistortion_percent = \"<= 1\"\nweight = 2\n\n"
      "[[optimize.targets]]\ntarget = \"relative_illumination >= 0.5\"\n\n"
      "[[optimize.targets]]\nrms_spot_um = \"<= 20\"\nfield = 1\n";
  const std::filesystem::path path = test::temp_root() / "targets.toml";
  {
    std::ofstream out(path);
    out << lens_text << table;
  }
  const Lens lens = read_lens(path);
  OptimizeOverrides none;
  const ResolvedOptimizeOptions r = resolve_optimize_options(lens, none);
  REQUIRE(r.options.targets.size() == 4);
  CHECK(r.options.targets[0].quantity == TargetQuantity::kEflMm);
  CHECK(r.options.targets[0].value == 50.0);
  CHECK(r.options.targets[1].relation == TargetRelation::kAtMost);
  CHECK(r.options.targets[1].weight == 2.0);
  CHECK(r.options.targets[2].quantity == TargetQuantity::kRelativeIllumination);
  CHECK(r.options.targets[2].relation == TargetRelation::kAtLeast);
  CHECK(r.options.targets[3].field == 1);
  // A --target of the same quantity and field replaces the table's; others are added.
  OptimizeOverrides cli;
  cli.targets = {parse_target("efl_mm=60", SourceLocation{"--target"}),
                 parse_target("total_track_mm<=90", SourceLocation{"--target"})};
  const ResolvedOptimizeOptions c = resolve_optimize_options(lens, cli);
  REQUIRE(c.options.targets.size() == 5);
  int efl = 0;
  for (const DesignTarget& t : c.options.targets)
    if (t.quantity == TargetQuantity::kEflMm) {
      ++efl;
      CHECK(t.value == 60.0);
    }
  CHECK(efl == 1);
  // A bad entry names the file and line.
  const std::filesystem::path bad = test::temp_root() / "bad-targets.toml";
  {
    std::ofstream out(bad);
    out << lens_text << "\n[[optimize.targets]]\nefl_mm = 50\n\n[[optimize.targets]]\n"
        << "distortion = \"<= 1\"\n";
  }
  const Lens bad_lens = read_lens(bad);
  try {
    resolve_optimize_options(bad_lens, none);
    FAIL("accepted");
  } catch (const Error& e) {
    const std::string m = e.what();
    INFO(m);
    CHECK(m.find("bad-targets.toml:") != std::string::npos);
    CHECK(m.find("unknown target quantity 'distortion'") != std::string::npos);
  }
}

TEST_CASE("optimize targets: residual Jacobians match central finite differences") {
  // Every residual quantity on the achromat at a finite object, at fields where each is smooth
  // (equalities, so the residual is q - t and never a flat hinge).
  const Lens lens = achromat_at_300mm();
  const LensParameterization param(lens, GlassSpace(*load_catalog(glass_catalog_for(lens))));
  const std::vector<double> x = param.from_lens(lens);
  const std::vector<int> glasses = param.nearest_glasses(x.data());
  const TraceOptions sampling = small_sampling();
  TargetSampling ts;
  ts.wavefront_grid = make_pupil_quadrature(4, 8, true);
  auto target = [](TargetQuantity q, int field) {
    DesignTarget t;
    t.quantity = q;
    t.value = 0.0;
    t.field = field;
    return t;
  };
  const std::vector<DesignTarget> targets = {
      target(TargetQuantity::kTotalTrackMm, 0),
      target(TargetQuantity::kBflMm, 0),
      target(TargetQuantity::kDistortionPercent, 3),
      target(TargetQuantity::kRelativeIllumination, 3),
      target(TargetQuantity::kRmsSpotUm, 2),
      target(TargetQuantity::kRmsWavefrontWaves, 3),
      target(TargetQuantity::kEflMm, 0),  // solved: no residual
  };
  const int count = target_residual_count(targets, 3);
  REQUIRE(count == 6);
  const double wave_unit = 0.01;
  auto residuals = [&](const std::vector<double>& xs) {
    std::vector<double> r(count);
    REQUIRE(evaluate_targets<double>(param, xs.data(), GlassMode::kFixed, glasses, sampling,
                                     targets, ts, 1.0, wave_unit, r.data()));
    return r;
  };
  using J = ceres::Jet<double, 16>;
  REQUIRE(param.size() <= 16);
  std::vector<J> xj(param.size());
  for (int i = 0; i < param.size(); ++i) xj[i] = J(x[i], i);
  std::vector<J> rj(count);
  TargetValues<J> values;
  REQUIRE(evaluate_targets<J>(param, xj.data(), GlassMode::kFixed, glasses, sampling, targets, ts,
                              1.0, wave_unit, rj.data(), &values));
  const std::vector<double> r0 = residuals(x);
  for (int row = 0; row < count; ++row) CHECK(rj[row].a == doctest::Approx(r0[row]).epsilon(1e-12));
  // The values are the quantities themselves: EFL the held focal length, the track the sum.
  CHECK(values.value[6].a == doctest::Approx(param.focal_length_mm()).epsilon(1e-12));
  for (int i = 0; i < param.size(); ++i) CHECK(std::abs(values.value[6].v[i]) < 1e-9);
  for (int row = 0; row < count; ++row) CHECK(std::abs(r0[row]) > 0.0);
  for (int i = 0; i < param.size(); ++i) {
    const LensVariable& v = param.variables()[i];
    if (v.group == "glasses") continue;  // fixed glasses: no derivative
    const double h = 1e-6 * std::max(1.0, std::abs(x[i]));
    std::vector<double> plus = x, minus = x;
    plus[i] += h;
    minus[i] -= h;
    const std::vector<double> rp = residuals(plus), rm = residuals(minus);
    for (int row = 0; row < count; ++row) {
      const double fd = (rp[row] - rm[row]) / (2 * h);
      INFO("variable ", v.name, ", target ", target_quantity_name(targets[row].quantity), ": jet ",
           rj[row].v[i], " fd ", fd);
      CHECK(std::abs(rj[row].v[i] - fd) <= 2e-5 * std::max(std::abs(fd), 1e-3));
    }
  }
}

TEST_CASE("optimize targets: the achromat at a finite object keeps its EFL, or reaches a target") {
  const Lens lens = achromat_at_300mm();
  const double efl = paraxial_efl(lens);
  REQUIRE(efl > 99.0);
  SUBCASE("no target: the lens's own focal length is the default target, held to 1e-6") {
    const OptimizeResult r = optimize_lens(lens, quick_options(lens));
    const TargetRow* row = row_of(r.final_targets, TargetQuantity::kEflMm);
    REQUIRE(row);
    CHECK(row->target.is_default);
    CHECK(row->pass);
    CHECK(std::abs(paraxial_efl(r.lens) - efl) <= 1e-6);
    CHECK(r.final_spot_um < r.start_spot_um);
  }
  SUBCASE("efl_mm = 90: reached to 1e-6 while the spot improves") {
    OptimizeOptions o = quick_options(lens);
    o.targets = {parse_target("efl_mm=90", SourceLocation{"--target"})};
    const OptimizeResult r = optimize_lens(lens, o);
    MESSAGE("achromat efl 90: spot ", r.start_spot_um, " -> ", r.final_spot_um, " um; EFL ",
            paraxial_efl(r.lens));
    CHECK(std::abs(paraxial_efl(r.lens) - 90.0) <= 1e-6);
    const TargetRow* before = row_of(r.start_targets, TargetQuantity::kEflMm);
    const TargetRow* after = row_of(r.final_targets, TargetQuantity::kEflMm);
    REQUIRE(before);
    REQUIRE(after);
    CHECK(before->value == doctest::Approx(efl).epsilon(1e-12));
    CHECK_FALSE(before->pass);
    CHECK(after->pass);
    CHECK_FALSE(r.kept_start);
    // Better than the start scaled to 90 mm (the optimizer's start) and than the lens as given.
    CHECK(r.final_spot_um < r.start_spot_um);
    const AnalysisReport given = analyze_lens(lens, AnalyzeOptions{});
    CHECK(r.final_spot_um < *given.mean_rms_spot_um);
    CHECK(r.final_constraints.all_pass());
  }
}

TEST_CASE("optimize targets: --focus-only refocuses a lens at a finite object") {
  Lens lens = achromat_at_300mm();
  // Out of focus: the paraxial image of the 300 mm object lies ~50 mm behind the written 97.1 mm.
  OptimizeOptions o = quick_options(lens);
  o.focus_only = true;
  const OptimizeResult r = optimize_lens(lens, o);
  MESSAGE("focus only: spot ", r.start_spot_um, " -> ", r.final_spot_um, " um, ", r.iterations,
          " iterations");
  CHECK(r.iterations > 0);
  CHECK(r.final_spot_um < 0.5 * r.start_spot_um);
  const std::size_t k = lens.surfaces.size();
  for (std::size_t i = 0; i + 1 < k; ++i) {
    INFO("surface ", i + 1);
    CHECK(r.lens.surfaces[i].curvature_per_mm ==
          doctest::Approx(lens.surfaces[i].curvature_per_mm).epsilon(1e-9));
    CHECK(r.lens.surfaces[i].thickness_mm ==
          doctest::Approx(lens.surfaces[i].thickness_mm).epsilon(1e-9));
    CHECK(r.lens.surfaces[i].material.label() == lens.surfaces[i].material.label());
  }
  CHECK(r.lens.surfaces[k - 1].thickness_mm > lens.surfaces[k - 1].thickness_mm + 20.0);
}

TEST_CASE("optimize targets: clear apertures that vignet the start are refused with what to do") {
  Lens lens = achromat_at_300mm();
  REQUIRE(lens.surfaces[0].is_stop);  // the flat stop the .zmx reader inserts; surface 2 is R1
  lens.surfaces[1].semi_diameter_mm = 4.0;  // the 20 mm pupil: most rays clipped
  try {
    optimize_lens(lens, quick_options(lens));
    FAIL("accepted");
  } catch (const Error& e) {
    const std::string m = e.what();
    INFO(m);
    CHECK(m.find("vignet") != std::string::npos);
    CHECK(m.find("surface 2 (semi_diameter_mm = 4") != std::string::npos);
    CHECK(m.find("Remove semi_diameter_mm") != std::string::npos);
  }
  // Apertures that clip nothing are kept on the result (no longer dropped) and checked.
  lens.surfaces[1].semi_diameter_mm = 12.7;
  OptimizeOptions o = quick_options(lens);
  o.max_rounds = 1;
  const OptimizeResult r = optimize_lens(lens, o);
  CHECK(r.lens.surfaces[1].semi_diameter_mm == 12.7);
  bool row = false;
  for (const ConstraintReport::Row& c : r.final_constraints.rows)
    row = row || c.name == "rays vignetted by clear apertures";
  CHECK(row);
}

TEST_CASE("optimize targets: lens-derived bounds of a start with failing rays are its own") {
  // R1 = 8 mm under a 20 mm pupil: the rays above 8 mm miss surface 2 (and the glass travel of
  // the rest runs negative). Before, any failed ray made the bounds the paper's scaled by f / 50
  // without a word (max glass 3 s = 0.91 mm against the start's 4.6 mm); now they come from the
  // rays that trace, by the formulas of optimizer.h.
  Lens lens = achromat_at_300mm();
  lens.surfaces[1].curvature_per_mm = 1.0 / 8.0;
  const DesignLossOptions paper;
  const ConstraintReport start = check_constraints(lens, paper, AnalyzeOptions{}.trace);
  REQUIRE(start.ray_failures > 0);
  const double s = design_focal_length_mm(lens) / 50.0;
  const DesignLossOptions derived = lens_derived_bounds(lens, paper);
  double thinnest = std::numeric_limits<double>::infinity(), thickest = 0.0;
  for (const ConstraintReport::Row& r : start.rows) {
    if (r.name.rfind("glass", 0) != 0) continue;
    if (r.is_lower) thinnest = std::min(thinnest, r.value);
    if (!r.is_lower) thickest = std::max(thickest, r.value);
  }
  MESSAGE("failing start: glass ", derived.min_glass_mm, "..", derived.max_glass_mm,
          " mm (s * paper ", s * paper.min_glass_mm, "..", s * paper.max_glass_mm, "; traced rays ",
          thinnest, "..", thickest, ")");
  CHECK(derived.max_glass_mm == doctest::Approx(std::max(s * paper.max_glass_mm, 1.5 * thickest)));
  CHECK(derived.max_glass_mm > s * paper.max_glass_mm);
  CHECK(derived.min_glass_mm ==
        doctest::Approx(std::min(s * paper.min_glass_mm, std::max(0.0, 0.5 * thinnest))));
}

}  // namespace test_optimize_targets
