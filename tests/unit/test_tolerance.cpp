// Monte-Carlo tolerancing: exactness at zero tolerance, reproducibility across threads, spread
// growing with the tolerances, the compensators, the Tessar's sensitivity ranking, bad input.
// Reduced sampling (few rings and fields) keeps these fast.
#include <doctest/doctest.h>
#include <fmt/format.h>

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <functional>
#include <string>

#include "lensopt/analysis/analyze.h"
#include "lensopt/analysis/spot.h"
#include "lensopt/core/atomic_file.h"
#include "lensopt/core/error.h"
#include "lensopt/formats/lens_file.h"
#include "lensopt/lens/lens_io.h"
#include "lensopt/paraxial/paraxial.h"
#include "lensopt/tolerance/tolerance.h"
#include "test_support.h"

namespace test_tolerance {

using namespace lensopt;

namespace {

Lens tessar() {
  return read_lens(test::source_dir() / "lenses" / "tessar.toml");
}

ToleranceOptions small_options(int trials) {
  ToleranceOptions o;
  o.trials = trials;
  o.rings = 6;
  o.fields = 4;
  o.jobs = 1;
  o.sensitivity = false;
  return o;
}

bool same_trial(const TrialResult& a, const TrialResult& b) {
  return a.valid == b.valid && a.mean_spot_um == b.mean_spot_um && a.rms_spot_um == b.rms_spot_um &&
         a.efl_mm == b.efl_mm && a.max_abs_distortion_pct == b.max_abs_distortion_pct &&
         a.ray_failures == b.ray_failures && a.image_distance_mm == b.image_distance_mm;
}

std::string error_of(const std::function<void()>& f) {
  try {
    f();
  } catch (const Error& e) {
    return e.what();
  }
  return "";
}

}  // namespace

TEST_CASE("tolerance: with every tolerance zero every trial equals the nominal exactly") {
  const Lens lens = tessar();
  for (FocusCompensator c :
       {FocusCompensator::kParaxial, FocusCompensator::kBestRms, FocusCompensator::kNone}) {
    for (ToleranceDistribution d :
         {ToleranceDistribution::kUniform, ToleranceDistribution::kNormal}) {
      ToleranceOptions o = small_options(6);
      o.tolerances = Tolerances::zero();
      o.compensator = c;
      o.distribution = d;
      o.jobs = 2;
      const ToleranceReport r = run_tolerance(lens, o);
      REQUIRE(r.trials.size() == 6);
      for (const TrialResult& t : r.trials) {
        CHECK(same_trial(t, r.nominal));
        for (double p : t.perturbations) CHECK(p == 0.0);
      }
      CHECK(r.spot.std == 0.0);
      CHECK(r.spot.worst == r.nominal.mean_spot_um);
    }
  }
}

TEST_CASE("tolerance: the nominal matches analyze at the same sampling") {
  const Lens lens = tessar();
  const ToleranceReport r = run_tolerance(lens, small_options(1));
  AnalyzeOptions a;
  a.trace.rings = 6;
  a.trace.fields = 4;
  const AnalysisReport report = analyze_lens(lens, a);
  REQUIRE(report.mean_rms_spot_um.has_value());
  CHECK(r.nominal.mean_spot_um == doctest::Approx(*report.mean_rms_spot_um).epsilon(1e-9));
  CHECK(r.nominal.efl_mm == doctest::Approx(lens.specs.focal_length_mm()).epsilon(1e-12));
  CHECK(r.scale == doctest::Approx(report.scale).epsilon(1e-15));
  double max_distortion = 0;
  for (const FieldReport& f : report.fields)
    max_distortion = std::max(max_distortion, std::abs(f.distortion_percent));
  CHECK(r.nominal.max_abs_distortion_pct == doctest::Approx(max_distortion).epsilon(1e-6));
  CHECK(r.nominal.ray_failures == report.ray_failures);
  // The paraxial solve reproduces the nominal image distance.
  CHECK(r.nominal.image_distance_mm ==
        doctest::Approx(lens.surfaces.back().thickness_mm * r.scale).epsilon(1e-14));
}

TEST_CASE("tolerance: the same seed gives an identical per-trial CSV with jobs 1 and jobs 2") {
  const Lens lens = tessar();
  ToleranceOptions o = small_options(24);
  o.seed = 12345;
  o.jobs = 1;
  const std::string csv1 = format_trials_csv(run_tolerance(lens, o));
  o.jobs = 2;
  const std::string csv2 = format_trials_csv(run_tolerance(lens, o));
  CHECK(csv1 == csv2);
  CHECK(std::count(csv1.begin(), csv1.end(), '\n') == 25);
  o.seed = 12346;
  const std::string csv3 = format_trials_csv(run_tolerance(lens, o));
  CHECK(csv3 != csv1);
  // A trial depends on (seed, index) only: more trials keep the first ones.
  o.seed = 12345;
  o.trials = 30;
  const std::string csv4 = format_trials_csv(run_tolerance(lens, o));
  CHECK(csv4.substr(0, csv1.size()) == csv1);
}

TEST_CASE("tolerance: draws stay within the limits with the stated distributions") {
  const Lens lens = tessar();
  for (ToleranceDistribution d :
       {ToleranceDistribution::kUniform, ToleranceDistribution::kNormal}) {
    ToleranceOptions o = small_options(1);
    o.distribution = d;
    const ToleranceModel model(lens, o);
    const auto& params = model.parameters();
    std::size_t nd_index = params.size();
    for (std::size_t i = 0; i < params.size(); ++i)
      if (params[i].kind == ToleranceParameter::Kind::kNd) nd_index = std::min(nd_index, i);
    REQUIRE(nd_index < params.size());
    const int n = 20000;
    double sum = 0, sum2 = 0, largest = 0;
    bool within = true;
    for (int i = 0; i < n; ++i) {
      const std::vector<double> p = model.draw(i);
      for (std::size_t j = 0; j < p.size(); ++j)
        within = within && std::abs(p[j]) <= params[j].limit;
      const double u = p[nd_index] / 5e-4;
      sum += u;
      sum2 += u * u;
      largest = std::max(largest, std::abs(u));
    }
    CHECK(within);
    const double mean = sum / n;
    const double sd = std::sqrt(sum2 / n - mean * mean);
    CHECK(std::abs(mean) < 0.02);
    if (d == ToleranceDistribution::kUniform) {
      CHECK(sd == doctest::Approx(1.0 / std::sqrt(3.0)).epsilon(0.02));  // U[-1, 1]
      CHECK(largest > 0.999);
    } else {
      // sigma 1/2 truncated at 2 sigma: sd = 0.5 * sqrt(1 - 4 phi(2) / (2 Phi(2) - 1)) = 0.4399
      CHECK(sd == doctest::Approx(0.4399).epsilon(0.02));
    }
  }
}

TEST_CASE("tolerance: doubling every tolerance increases the spread of the mean spot") {
  const Lens lens = tessar();
  ToleranceOptions o = small_options(120);
  o.jobs = 2;
  const ToleranceReport single = run_tolerance(lens, o);
  o.tolerances = o.tolerances.times(2.0);
  const ToleranceReport doubled = run_tolerance(lens, o);
  MESSAGE("std of the mean spot: ", single.spot.std, " um, doubled tolerances: ", doubled.spot.std,
          " um");
  CHECK(single.spot.std > 0.0);
  CHECK(doubled.spot.std > 1.5 * single.spot.std);
  CHECK(doubled.spot.p90 > single.spot.p90);
  CHECK(doubled.efl_std_mm > 1.5 * single.efl_std_mm);
}

TEST_CASE("tolerance: the paraxial compensator removes a thickness error's defocus") {
  const Lens lens = tessar();
  ToleranceOptions o = small_options(1);
  o.tolerances = Tolerances::zero();
  o.tolerances.glass_thickness_mm = 0.05;
  o.tolerances.air_thickness_mm = 0.05;
  ToleranceOptions none = o;
  none.compensator = FocusCompensator::kNone;
  ToleranceOptions best = o;
  best.compensator = FocusCompensator::kBestRms;
  const ToleranceModel paraxial_model(lens, o), none_model(lens, none), best_model(lens, best);
  const auto& params = paraxial_model.parameters();
  const std::vector<double> zero(params.size(), 0.0);
  const TrialResult nominal = paraxial_model.evaluate(zero);
  const TrialResult nominal_none = none_model.evaluate(zero);
  const TrialResult nominal_best = best_model.evaluate(zero);
  CHECK(nominal_best.mean_spot_um <= nominal.mean_spot_um);
  int checked = 0, defocus_dominated = 0;
  for (std::size_t i = 0; i < params.size(); ++i) {
    if (params[i].kind != ToleranceParameter::Kind::kThickness || params[i].limit == 0) continue;
    for (double sign : {1.0, -1.0}) {
      std::vector<double> d(params.size(), 0.0);
      d[i] = sign * params[i].limit;
      const TrialResult with = paraxial_model.evaluate(d);
      const TrialResult without = none_model.evaluate(d);
      const TrialResult refocused = best_model.evaluate(d);
      // The compensated image distance is the perturbed paraxial focus plus the nominal defocus.
      TraceLens<double> tl = make_trace_lens(paraxial_model.scaled_lens());
      const double bfl0 = paraxial_data(tl, kWavelengthD_nm).bfl_mm;
      tl.thickness_mm[params[i].surface] += d[i];
      const double shift = paraxial_data(tl, kWavelengthD_nm).bfl_mm - bfl0;
      CHECK(with.image_distance_mm - nominal.image_distance_mm ==
            doctest::Approx(shift).epsilon(1e-9));
      CHECK(without.image_distance_mm == nominal_none.image_distance_mm);
      const double error_none = without.mean_spot_um - nominal_none.mean_spot_um;
      const double error_paraxial = with.mean_spot_um - nominal.mean_spot_um;
      MESSAGE(params[i].name, sign > 0 ? "+" : "-", ": BFL shift ", shift,
              " mm; spot change without compensator ", error_none, " um, paraxial ", error_paraxial,
              " um, best-rms ", refocused.mean_spot_um - nominal_best.mean_spot_um, " um");
      // Where the error is mostly a focus shift (> 0.05 mm; the front elements), the paraxial
      // solve removes most of it (about 90 % or more): what is left is the aberration change.
      if (std::abs(shift) > 0.05) {
        CHECK(error_none > 3.0);
        CHECK(std::abs(error_paraxial) < 0.15 * error_none);
        ++defocus_dominated;
      }
      // Best-RMS refocus is never worse than the paraxial solve.
      CHECK(refocused.mean_spot_um <= with.mean_spot_um);
      ++checked;
    }
  }
  CHECK(checked == 12);  // 4 glass thicknesses and 2 airspaces of the Tessar, at + and -
  CHECK(defocus_dominated >= 4);
}

TEST_CASE("tolerance: the Tessar's sensitivity ranking is physically sensible") {
  const Lens lens = tessar();
  ToleranceOptions o;  // the default tolerances and tolerancing sampling (16 rings, 11 fields)
  o.trials = 1;
  o.jobs = 2;
  // The ranking of the prescription's own numbers; element decenters and tilts are ranked in
  // test_tolerance_placement.cpp.
  o.tolerances.decenter_mm = 0.0;
  o.tolerances.tilt_arcmin = 0.0;
  o.tolerances.surface_tilt_arcmin = 0.0;
  const ToleranceReport r = run_tolerance(lens, o);
  REQUIRE(r.sensitivity.size() == 19);  // 7 curvatures, 4 glass thicknesses, 4 nd, 4 vd
  std::string ranking;
  for (const SensitivityRow& s : r.sensitivity)
    ranking += r.parameters[s.parameter].name + fmt::format("({:.3f}) ", s.score_um);
  MESSAGE("Tessar sensitivity ranking (um): ", ranking);
  for (std::size_t i = 1; i < r.sensitivity.size(); ++i)
    CHECK(r.sensitivity[i - 1].score_um >= r.sensitivity[i].score_um);
  std::vector<std::string> order;
  for (const SensitivityRow& s : r.sensitivity) order.push_back(r.parameters[s.parameter].name);
  auto rank_of = [&](const std::string& name) {
    return static_cast<int>(std::find(order.begin(), order.end(), name) - order.begin());
  };
  // Glass thickness first: +-0.05 mm is 5 % of the 1.0 mm negative element (t3) and 2 % of the
  // 2.6 mm front element (t1) in a lens of 10 mm track (the supplement: "sensitive to changes in
  // glass thickness due to their small total track length").
  CHECK(rank_of("t3") < 3);
  CHECK(rank_of("t1") < 3);
  // A relative curvature error changes a surface's power (n' - n) c in proportion, so the
  // curvature rows follow the surface powers: the three strongest, surface 1 (0.091 /mm),
  // surface 4 (0.084) and surface 8 (0.071), lead; the cemented interface 7 is the most strongly
  // curved surface (R -6.9 mm) but has little power (n' - n = 0.15) and ranks below them.
  std::vector<std::string> curvatures;
  for (const std::string& name : order)
    if (name[0] == 'c') curvatures.push_back(name);
  REQUIRE(curvatures.size() == 7);
  std::vector<std::string> top3(curvatures.begin(), curvatures.begin() + 3);
  std::sort(top3.begin(), top3.end());
  CHECK(top3 == std::vector<std::string>{"c1", "c4", "c8"});
  CHECK(rank_of("c7") > rank_of("c8"));
  // An index error mostly moves the focus, which the paraxial solve removes: without the
  // compensator the same nd errors are far larger.
  ToleranceOptions none = o;
  none.compensator = FocusCompensator::kNone;
  const ToleranceReport rn = run_tolerance(lens, none);
  for (const SensitivityRow& s : r.sensitivity) {
    const ToleranceParameter& p = r.parameters[s.parameter];
    if (p.kind != ToleranceParameter::Kind::kNd) continue;
    for (const SensitivityRow& t : rn.sensitivity)
      if (t.parameter == s.parameter) CHECK(t.score_um > 2.0 * s.score_um);
  }
}

TEST_CASE("tolerance: statistics use interpolated percentiles") {
  std::vector<double> v;
  for (int i = 101; i >= 1; --i) v.push_back(i);
  const SpotStatistics s = spot_statistics(v);
  CHECK(s.count == 101);
  CHECK(s.mean == doctest::Approx(51));
  CHECK(s.p50 == doctest::Approx(51));
  CHECK(s.p90 == doctest::Approx(91));
  CHECK(s.p99 == doctest::Approx(100));
  CHECK(s.worst == 101);
  CHECK(s.best == 1);
  CHECK(s.std == doctest::Approx(std::sqrt(101.0 * 102.0 / 12.0)));
}

TEST_CASE("tolerance: yield counts trials at or below the limit") {
  const Lens lens = tessar();
  ToleranceOptions o = small_options(40);
  o.jobs = 2;
  const ToleranceReport probe = run_tolerance(lens, o);
  o.max_spot_um = probe.spot.p50;
  const ToleranceReport r = run_tolerance(lens, o);
  REQUIRE(r.yield.has_value());
  CHECK(*r.yield == doctest::Approx(0.5).epsilon(0.06));
  const std::string svg = format_tolerance_histogram_svg(r);
  CHECK(svg.find("<svg") != std::string::npos);
  CHECK(svg.find("max spot") != std::string::npos);
  const std::string json = format_tolerance_json(r);
  CHECK(json.find("\"yield\"") != std::string::npos);
  CHECK(json.find("NaN") == std::string::npos);
}

TEST_CASE("tolerance: negative or unknown tolerances are errors naming them") {
  Tolerances t;
  t.nd = -1e-4;
  CHECK(error_of([&] { t.validate(); }).find("nd") != std::string::npos);
  t = Tolerances{};
  t.glass_thickness_mm = -0.05;
  CHECK(error_of([&] { t.validate(); }).find("glass_thickness_mm") != std::string::npos);
  t = Tolerances{};
  t.curvature_pct = std::nan("");
  CHECK(error_of([&] { t.validate(); }).find("curvature_pct") != std::string::npos);

  const std::string unknown = error_of([] {
    parse_tolerance_table("[lens]\nname = \"x\"\n\n[tolerance]\nnd = 5e-4\nwedge_deg = 0.1\n",
                          "lens.toml");
  });
  CHECK(unknown.find("lens.toml:6:") != std::string::npos);
  CHECK(unknown.find("wedge_deg") != std::string::npos);
  const std::string negative = error_of(
      [] { parse_tolerance_table("[tolerance]\ncurvature_pct = 0.2\nvd_pct = -0.5\n", "a.toml"); });
  CHECK(negative.find("a.toml:3:") != std::string::npos);
  CHECK(negative.find("vd_pct") != std::string::npos);
  CHECK(negative.find("negative") != std::string::npos);
  const std::string type =
      error_of([] { parse_tolerance_table("[tolerance]\nnd = \"small\"\n", "b.toml"); });
  CHECK(type.find("b.toml:2:") != std::string::npos);
  CHECK(type.find("nd") != std::string::npos);
  const std::string compensator =
      error_of([] { parse_tolerance_table("[tolerance]\ncompensator = \"magic\"\n", "c.toml"); });
  CHECK(compensator.find("c.toml:2:") != std::string::npos);
  CHECK(compensator.find("magic") != std::string::npos);

  ToleranceOptions o;
  o.tolerances.air_thickness_mm = -1;
  CHECK(error_of([&] { run_tolerance(tessar(), o); }).find("air_thickness_mm") !=
        std::string::npos);
}

TEST_CASE("tolerance: the [tolerance] table of a lens file is read with file:line errors") {
  const std::string text = read_file(test::source_dir() / "lenses" / "tessar.toml");
  const std::filesystem::path dir = test::temp_root() / "tolerance";
  std::filesystem::create_directories(dir);
  const std::filesystem::path good = dir / "tessar_tol.toml";
  {
    std::ofstream out(good);
    out << text << "\n[tolerance]\ncurvature_pct = 0.1\nnd = 1e-3\ncompensator = \"best-rms\"\n"
        << "distribution = \"normal\"\nmax_spot_um = 20\ntrials = 50\nseed = 7\n";
  }
  const Lens lens = read_lens(good);
  const ToleranceSettings s = tolerance_settings_of(lens);
  REQUIRE(s.curvature_pct.has_value());
  CHECK(*s.curvature_pct == 0.1);
  CHECK(*s.nd == 1e-3);
  CHECK(!s.vd_pct.has_value());
  CHECK(*s.compensator == FocusCompensator::kBestRms);
  CHECK(*s.distribution == ToleranceDistribution::kNormal);
  CHECK(*s.max_spot_um == 20);
  CHECK(*s.trials == 50);
  CHECK(*s.seed == 7);
  Tolerances t;
  s.apply_to(t);
  CHECK(t.curvature_pct == 0.1);
  CHECK(t.vd_pct == 0.5);

  const std::filesystem::path bad = dir / "tessar_bad.toml";
  {
    std::ofstream out(bad);
    out << text << "\n[tolerance]\nglass_thickness_mm = -0.05\n";
  }
  const int line = static_cast<int>(std::count(text.begin(), text.end(), '\n')) + 3;
  const std::string message = error_of([&] { tolerance_settings_of(read_lens(bad)); });
  CHECK(message.find(fmt::format("tessar_bad.toml:{}:", line)) != std::string::npos);
  CHECK(message.find("glass_thickness_mm") != std::string::npos);
  std::filesystem::remove_all(dir);
}

TEST_CASE("tolerance: the halves of a cemented pair are distinct elements") {
  Lens lens = read_lens(test::source_dir() / "lenses" / "doublet.toml");
  // Cement a second glass to the first element: surfaces 1-2 S-LAL12, 2-3 S-LAH92.
  lens.surfaces[1].material = lens.surfaces[3].material;
  Tolerances tol;
  const auto params = tolerance_parameters(lens, tol);
  std::string t1, t2;
  for (const ToleranceParameter& p : params) {
    if (p.name == "t1") t1 = p.description;
    if (p.name == "t2") t2 = p.description;
  }
  CAPTURE(t1);
  CAPTURE(t2);
  CHECK(t1.find("element 1 ") != std::string::npos);
  CHECK(t2.find("element 2 ") != std::string::npos);
}

TEST_CASE("tolerance: a trial whose elements intersect is a failure, not a yield") {
  Lens lens = read_lens(test::source_dir() / "lenses" / "doublet.toml");
  REQUIRE(lens.surfaces[2].is_stop);
  // 0.01 mm from the stop to the convex second element, airspaces toleranced +-0.05 mm: the
  // element crosses the stop plane in about 40 % of the trials.
  lens.surfaces[2].thickness_mm = 0.01;
  ToleranceOptions o = small_options(60);
  o.max_spot_um = 1e9;  // every traced trial is within the spot limit
  o.tolerances.air_thickness_mm = 0.05;
  const ToleranceReport r = run_tolerance(lens, o);
  CHECK_FALSE(r.nominal.collision);
  CHECK(r.nominal.min_edge_gap_mm >= 0.0);
  int collisions = 0;
  for (const TrialResult& t : r.trials) {
    collisions += t.collision ? 1 : 0;
    if (t.collision) CHECK(t.min_edge_gap_mm < 0.0);
  }
  MESSAGE("trials with intersecting elements: " << collisions << " of " << r.trials.size());
  CHECK(collisions > 5);
  CHECK(collisions < 55);
  CHECK(r.trials_with_collisions == collisions);
  REQUIRE(r.yield.has_value());
  CHECK(*r.yield == doctest::Approx(1.0 - static_cast<double>(collisions) / 60.0));
  CHECK(format_tolerance_text(r, 0).find("intersecting elements") != std::string::npos);
  CHECK(format_trials_csv(r).find("elements_intersect") != std::string::npos);
  // Airspaces held: nothing intersects and every trial is a yield.
  o.tolerances.air_thickness_mm = 0.0;
  const ToleranceReport held = run_tolerance(lens, o);
  CHECK(held.trials_with_collisions == 0);
  CHECK(*held.yield == 1.0);
}

TEST_CASE("tolerance: through-focus moments equal the per-ray sums, failed rays left out") {
  // ThroughFocusSpot::add divides the slopes in a vectorized pass; the sums must equal the
  // scalar loop's bit for bit, in the same order, skipping failed rays.
  RayBundle<double> rays;
  rays.resize(41);
  for (std::size_t i = 0; i < rays.size(); ++i) {
    const double u = static_cast<double>(i) / rays.size();
    rays.x[i] = 0.01 * std::sin(7.0 * u);
    rays.y[i] = 3.0 + 0.02 * std::cos(5.0 * u);
    rays.l[i] = 0.05 * u;
    rays.m[i] = 0.3 - 0.1 * u;
    rays.n[i] = std::sqrt(1.0 - rays.l[i] * rays.l[i] - rays.m[i] * rays.m[i]);
  }
  rays.status[0] = kRayVignetted;  // the first arrived ray (1) becomes the reference
  rays.status[17] = kRayMissedSurface;
  ThroughFocusSpot moments;
  std::vector<double> scratch;
  moments.add(rays, scratch);
  moments.add(rays);  // the overload without a scratch buffer: a second wavelength
  double y0 = 0, sy0 = 0, sum_dy = 0, sum_dy2 = 0, sum_x2 = 0, sum_ds = 0, sum_dyds = 0;
  double sum_ds2 = 0, sum_xsx = 0, sum_sx2 = 0;
  int count = 0;
  for (int pass = 0; pass < 2; ++pass) {
    for (std::size_t i = 0; i < rays.size(); ++i) {
      if (rays.status[i] != kRayOk) continue;
      const double sy = rays.m[i] / rays.n[i];
      const double sx = rays.l[i] / rays.n[i];
      if (count == 0) y0 = rays.y[i], sy0 = sy;
      const double dy = rays.y[i] - y0;
      const double ds = sy - sy0;
      sum_dy += dy;
      sum_dy2 += dy * dy;
      sum_x2 += rays.x[i] * rays.x[i];
      sum_ds += ds;
      sum_dyds += dy * ds;
      sum_ds2 += ds * ds;
      sum_xsx += rays.x[i] * sx;
      sum_sx2 += sx * sx;
      ++count;
    }
  }
  CHECK(moments.count() == 2 * 39);
  CHECK(count == 2 * 39);
  CHECK(moments.spot.y0 == rays.y[1]);
  CHECK(moments.sy0 == rays.m[1] / rays.n[1]);
  CHECK(moments.spot.sum_dy == sum_dy);
  CHECK(moments.spot.sum_dy2 == sum_dy2);
  CHECK(moments.spot.sum_x2 == sum_x2);
  CHECK(moments.sum_ds == sum_ds);
  CHECK(moments.sum_dyds == sum_dyds);
  CHECK(moments.sum_ds2 == sum_ds2);
  CHECK(moments.sum_xsx == sum_xsx);
  CHECK(moments.sum_sx2 == sum_sx2);
  CHECK(moments.rms(0.0) > 0.0);
}

}  // namespace test_tolerance
