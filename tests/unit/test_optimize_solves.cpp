// Solves and variables in the optimizer (issue 31 item 2; optimize/variables.h choose_variables,
// the forward map's pickups and solves): pickups held through optimize and their exact Jacobians
// against central finite differences and the chain rule, which variables the vary flags and
// the explicit lists free (and the report saying why), and the focus solve re-evaluated after
// every step.
#include <ceres/jet.h>
#include <doctest/doctest.h>

#include <algorithm>
#include <cmath>
#include <string>

#include "lensopt/analysis/analyze.h"
#include "lensopt/core/error.h"
#include "lensopt/formats/lens_file.h"
#include "lensopt/lens/lens_io.h"
#include "lensopt/optimize/optimizer.h"
#include "lensopt/optimize/targets.h"
#include "lensopt/paraxial/paraxial.h"
#include "lensopt/paraxial/solves.h"
#include "test_support.h"

namespace test_optimize_solves {

using namespace lensopt;

namespace {

double paraxial_efl(const Lens& lens) {
  const TraceLens<double> t = make_trace_lens(lens);
  return paraxial_data(t, t.reference_nm()).efl_mm;
}

OptimizeOptions quick_options(const Lens& lens) {
  OptimizeOptions o;
  o.sampling.rings = 6;
  o.sampling.fields = 5;
  o.glass_search = GlassSearch::kNone;
  o.max_iterations = 15;
  o.max_rounds = 2;
  o.verbose = false;
  o.loss = bounds_for(lens, o.loss, BoundsMode::kAuto);
  return o;
}

bool log_has(const std::vector<std::string>& log, const std::string& text) {
  for (const std::string& line : log)
    if (line.find(text) != std::string::npos) return true;
  return false;
}

}  // namespace

TEST_CASE(
    "optimize solves: a symmetric element's picked-up curvature stays symmetric under optimize") {
  // The Cooke triplet's negative element made symmetric: c4 = -1 x c3.
  Lens lens = read_lens(test::source_dir() / "lenses" / "cooke.toml");
  lens.surfaces[3].curvature_pickup = {2, -1.0, 0.0};
  lens = with_solves(lens);
  REQUIRE(lens.surfaces[3].curvature_per_mm == -lens.surfaces[2].curvature_per_mm);
  const OptimizeResult r = optimize_lens(lens, quick_options(lens));
  MESSAGE("cooke, c4 = -c3: spot ", r.start_spot_um, " -> ", r.final_spot_um, " um; c3 ",
          r.lens.surfaces[2].curvature_per_mm, " c4 ", r.lens.surfaces[3].curvature_per_mm);
  CHECK_FALSE(r.kept_start);
  CHECK(r.final_spot_um < r.start_spot_um);
  CHECK(r.lens.surfaces[2].curvature_per_mm != lens.surfaces[2].curvature_per_mm);
  CHECK(r.lens.surfaces[3].curvature_per_mm == -r.lens.surfaces[2].curvature_per_mm);
  CHECK(r.lens.surfaces[3].curvature_pickup.active());  // kept for the written file
  CHECK(log_has(r.log, "picked up: c4 = -1 x c3"));
}

TEST_CASE("optimize solves: Jacobians through pickups match central finite differences") {
  // The Cooke with c4 = -1 x c3, t5 (the stop's air space) = 1 x t2 + 0.5 mm and the image at
  // the paraxial focus (a marginal-ray-height solve): the spot of a field and the total track as
  // residual targets, their exact (Jet) derivatives by every curvature and spacing against
  // central differences.
  Lens lens = read_lens(test::source_dir() / "lenses" / "cooke.toml");
  lens.surfaces[3].curvature_pickup = {2, -1.0, 0.0};
  lens.surfaces[4].thickness_pickup = {1, 1.0, 0.5};
  lens.surfaces.back().thickness_solve.kind = ThicknessSolve::Kind::kMarginalHeight;
  lens = with_solves(lens);
  const LensParameterization param(lens, GlassSpace(*load_catalog(glass_catalog_for(lens))));
  const std::vector<double> x = param.from_lens(lens);
  const std::vector<int> glasses = param.nearest_glasses(x.data());
  TraceOptions sampling;
  sampling.rings = 6;
  sampling.fields = 5;
  TargetSampling ts;
  auto target = [](TargetQuantity q, int field) {
    DesignTarget t;
    t.quantity = q;
    t.value = 0.0;
    t.field = field;
    return t;
  };
  const std::vector<DesignTarget> targets = {target(TargetQuantity::kRmsSpotUm, 2),
                                             target(TargetQuantity::kTotalTrackMm, 0)};
  const int count = 2;
  auto residuals = [&](const std::vector<double>& xs) {
    std::vector<double> r(count);
    REQUIRE(evaluate_targets<double>(param, xs.data(), GlassMode::kFixed, glasses, sampling,
                                     targets, ts, 1.0, 0.01, r.data()));
    return r;
  };
  using J = ceres::Jet<double, 24>;
  REQUIRE(param.size() <= 24);
  std::vector<J> xj(param.size());
  for (int i = 0; i < param.size(); ++i) xj[i] = J(x[i], i);
  std::vector<J> rj(count);
  REQUIRE(evaluate_targets<J>(param, xj.data(), GlassMode::kFixed, glasses, sampling, targets, ts,
                              1.0, 0.01, rj.data()));
  int checked = 0;
  for (int i = 0; i < param.size(); ++i) {
    const LensVariable& v = param.variables()[i];
    if (v.group == "glasses") continue;
    if (v.name == "c4" || v.name == "s5" || v.name == "defocus") {
      // Picked up: the variable itself has no effect.
      for (int row = 0; row < count; ++row) CHECK(rj[row].v[i] == 0.0);
      continue;
    }
    const double h = 1e-6 * std::max(1.0, std::abs(x[i]));
    std::vector<double> plus = x, minus = x;
    plus[i] += h;
    minus[i] -= h;
    const std::vector<double> rp = residuals(plus), rm = residuals(minus);
    for (int row = 0; row < count; ++row) {
      const double fd = (rp[row] - rm[row]) / (2 * h);
      INFO("variable ", v.name, " row ", row, ": jet ", rj[row].v[i], " fd ", fd);
      CHECK(std::abs(rj[row].v[i] - fd) <= 1e-6 * std::max(std::abs(fd), 1.0));
      ++checked;
    }
  }
  CHECK(checked >= 16);  // the free curvatures and spacings by 2 targets
  // Through the pickups, by the chain rule against the same lens without them (the same
  // values, c4 and s5 then free): d/dc3 = d/dc3 - d/dc4 and d/ds2 = d/ds2 + d/ds5.
  Lens free = lens;
  free.surfaces[3].curvature_pickup = {};
  free.surfaces[4].thickness_pickup = {};
  const LensParameterization plain(free, GlassSpace(*load_catalog(glass_catalog_for(free))));
  REQUIRE(plain.size() == param.size());
  std::vector<J> rf(count);
  REQUIRE(evaluate_targets<J>(plain, xj.data(), GlassMode::kFixed, glasses, sampling, targets, ts,
                              1.0, 0.01, rf.data()));
  const int c3 = param.select({"c3"}).front(), c4 = param.select({"c4"}).front();
  const int s2 = param.select({"s2"}).front(), s5 = param.select({"s5"}).front();
  for (int row = 0; row < count; ++row) {
    CHECK(rf[row].a == doctest::Approx(rj[row].a).epsilon(1e-12));
    CHECK(rj[row].v[c3] == doctest::Approx(rf[row].v[c3] - rf[row].v[c4]).epsilon(1e-9));
    CHECK(rj[row].v[s2] == doctest::Approx(rf[row].v[s2] + rf[row].v[s5]).epsilon(1e-9));
  }
  CHECK(std::abs(rf[0].v[c4]) > 1e-3 * std::abs(rf[0].v[c3]));  // the pickup matters
}

TEST_CASE("optimize solves: vary flags free their variables; explicit lists override the file") {
  Lens lens = read_lens(test::source_dir() / "lenses" / "cooke.toml");
  lens.surfaces[0].vary.radius = true;
  lens.surfaces[2].vary.radius = true;
  lens.surfaces[1].vary.thickness = true;
  lens.surfaces.back().vary.thickness = true;  // the defocus
  const LensParameterization param(lens, GlassSpace(*load_catalog(glass_catalog_for(lens))));
  auto held_names = [&](const VariableChoice& c) {
    std::vector<std::string> names;
    for (int i : c.held) names.push_back(param.variables()[i].name);
    return names;
  };
  auto has = [](const std::vector<std::string>& names, const std::string& n) {
    return std::find(names.begin(), names.end(), n) != names.end();
  };
  SUBCASE("the file's flags alone") {
    const VariableChoice c = choose_variables(param, {}, {}, false);
    const std::vector<std::string> held = held_names(c);
    for (const char* free_name : {"c1", "c3", "s2", "defocus"}) CHECK_FALSE(has(held, free_name));
    for (const char* held_name : {"c2", "c4", "c6", "s1", "s3", "g1.0", "g1.1"})
      CHECK(has(held, held_name));
    CHECK(log_has(c.report, "variables free (vary flags in the lens file): c1, c3, s2, defocus"));
    CHECK(log_has(c.report, "held (not flagged in the lens file"));
  }
  SUBCASE("--freeze holds a flagged variable; --vary frees an unflagged one") {
    const VariableChoice c = choose_variables(param, {"c1"}, {"s3"}, false);
    const std::vector<std::string> held = held_names(c);
    CHECK(has(held, "c1"));
    CHECK_FALSE(has(held, "s3"));
    CHECK(log_has(c.report, "held (named in freeze: --freeze / [optimize] freeze): c1"));
    CHECK(log_has(c.report, "free (named in vary: --vary / [optimize] vary): s3"));
  }
  SUBCASE("a name in both lists is an error") {
    CHECK_THROWS_WITH_AS(choose_variables(param, {"c1"}, {"c1"}, false),
                         doctest::Contains("both held (freeze) and freed (vary)"), Error);
  }
  SUBCASE("without flags every variable is free") {
    Lens plain = read_lens(test::source_dir() / "lenses" / "cooke.toml");
    const LensParameterization p(plain, GlassSpace(*load_catalog(glass_catalog_for(plain))));
    const VariableChoice c = choose_variables(p, {}, {}, false);
    CHECK(c.held.empty());
    CHECK(log_has(c.report, "no vary flags in the lens file: every variable"));
  }
  SUBCASE("optimize changes only the flagged values (and the focal-length solve)") {
    // A start the flagged values can improve: c1 and s2 off the baseline's.
    lens.surfaces[0].curvature_per_mm *= 1.05;
    lens.surfaces[1].thickness_mm *= 1.5;
    const OptimizeResult r = optimize_lens(lens, quick_options(lens));
    MESSAGE("cooke with vary flags: spot ", r.start_spot_um, " -> ", r.final_spot_um, " um");
    CHECK_FALSE(r.kept_start);
    const Lens start = scaled(lens, lens_spec_scale(lens));
    const std::size_t last = lens.surfaces.size() - 1;
    for (std::size_t k = 0; k < last; ++k) {
      INFO("surface ", k + 1);
      if (k != 0 && k != 2)
        CHECK(r.lens.surfaces[k].curvature_per_mm ==
              doctest::Approx(start.surfaces[k].curvature_per_mm).epsilon(1e-12));
      if (k != 1)
        CHECK(r.lens.surfaces[k].thickness_mm ==
              doctest::Approx(start.surfaces[k].thickness_mm).epsilon(1e-12));
      CHECK(r.lens.surfaces[k].material.label() == start.surfaces[k].material.label());
    }
    CHECK(log_has(r.log, "c7 is solved for the focal length"));
  }
}

TEST_CASE(
    "optimize solves: a picked-up or solved value cannot be varied; the last curvature not picked "
    "up") {
  Lens lens = read_lens(test::source_dir() / "lenses" / "cooke.toml");
  lens.surfaces[3].curvature_pickup = {2, -1.0, 0.0};
  lens.surfaces.back().thickness_solve.kind = ThicknessSolve::Kind::kMarginalHeight;
  const LensParameterization param(lens, GlassSpace(*load_catalog(glass_catalog_for(lens))));
  CHECK_THROWS_WITH_AS(choose_variables(param, {}, {"c4"}, false),
                       doctest::Contains("picked up: c4 = -1 x c3"), Error);
  CHECK_THROWS_WITH_AS(choose_variables(param, {}, {}, true),
                       doctest::Contains("--focus-only: the image distance is not a variable"),
                       Error);
  const VariableChoice c = choose_variables(param, {}, {}, false);
  CHECK(log_has(c.report, "solved: t7 (defocus) by the marginal ray height 0 mm"));
  Lens last = read_lens(test::source_dir() / "lenses" / "cooke.toml");
  last.surfaces.back().curvature_pickup = {5, -1.0, 0.0};
  CHECK_THROWS_WITH_AS(
      LensParameterization(last, GlassSpace(*load_catalog(glass_catalog_for(last)))),
      doctest::Contains("solves the last curvature for the focal length"), Error);
}

TEST_CASE(
    "optimize solves: optimize with a marginal-height solve keeps the image at the paraxial "
    "focus") {
  Lens lens = read_lens(test::source_dir() / "tests" / "data" / "achromat_ac254_100_300mm.toml");
  lens.surfaces.back().thickness_solve.kind = ThicknessSolve::Kind::kMarginalHeight;
  lens.surfaces[1].curvature_per_mm = 1.0 / 50.0;  // off the design: the bending has work to do
  const OptimizeResult r = optimize_lens(lens, quick_options(lens));
  MESSAGE("achromat at 300 mm with the focus solve: spot ", r.start_spot_um, " -> ",
          r.final_spot_um, " um");
  CHECK_FALSE(r.kept_start);
  CHECK(r.final_spot_um < r.start_spot_um);
  // The result's last thickness is its own paraxial image distance (re-solved after every step).
  Lens check = r.lens;
  const double written = check.surfaces.back().thickness_mm;
  check = with_solves(check);
  CHECK(std::abs(check.surfaces.back().thickness_mm - written) <= 1e-9 * written);
  CHECK(std::abs(paraxial_efl(r.lens) - paraxial_efl(with_solves(lens))) <= 1e-6);
}

}  // namespace test_optimize_solves
