// Compensators beyond focus (issue 32, tolerance.h "Compensators beyond focus"): a chosen group's
// decenter (OpticStudio's TEDX/TEDY as compensators) and the lateral image shift with the spot
// taken about the nominal image points; their parsing ([tolerance] table, --compensator).
#include <doctest/doctest.h>
#include <fmt/format.h>

#include <cmath>
#include <string>
#include <utility>
#include <vector>

#include "lensopt/core/error.h"
#include "lensopt/formats/lens_file.h"
#include "lensopt/lens/lens.h"
#include "lensopt/tolerance/tolerance.h"
#include "test_support.h"

namespace test_tolerance_compensators {

using namespace lensopt;

namespace {

Lens tessar() {
  return read_lens(test::source_dir() / "lenses" / "tessar.toml");
}

ToleranceOptions small_options() {
  ToleranceOptions o;
  o.rings = 6;
  o.fields = 3;
  o.trials = 1;
  o.jobs = 2;
  return o;
}

int parameter_index(const ToleranceModel& model, const std::string& name) {
  const std::vector<ToleranceParameter>& params = model.parameters();
  for (std::size_t i = 0; i < params.size(); ++i)
    if (params[i].name == name) return static_cast<int>(i);
  FAIL("no parameter ", name);
  return -1;
}

}  // namespace

TEST_CASE("tolerance compensators: the list, the table and their errors") {
  const CompensatorList a = parse_compensators("best-rms, image-shift,decenter:element=2");
  REQUIRE(a.focus);
  CHECK(*a.focus == FocusCompensator::kBestRms);
  CHECK(a.image_shift);
  CHECK(a.decenter_elements == std::vector<int>{2});
  const CompensatorList b = parse_compensators("decenter:element=3,decenter:element=1");
  CHECK_FALSE(b.focus);
  CHECK(b.decenter_elements == std::vector<int>{3, 1});
  CHECK_THROWS_WITH_AS(parse_compensators("decenter:element=0"),
                       doctest::Contains("must be a group number >= 1"), Error);
  CHECK_THROWS_WITH_AS(parse_compensators("decenter:group=2"),
                       doctest::Contains("must be decenter:element=K"), Error);
  CHECK_THROWS_WITH_AS(parse_compensators("paraxial,none"),
                       doctest::Contains("two focus compensators"), Error);
  CHECK_THROWS_WITH_AS(parse_compensators("tilt:element=2"),
                       doctest::Contains("unknown compensator 'tilt:element=2'"), Error);
  CHECK_THROWS_WITH_AS(parse_compensators("decenter:element=2,decenter:element=2"),
                       doctest::Contains("given twice"), Error);
  // The [tolerance] table: a string list or an array, and the spot reference.
  const ToleranceSettings t = parse_tolerance_table(
      "[tolerance]\ncompensator = [\"best-rms\", \"decenter:element=2\"]\n"
      "spot_reference = \"nominal\"\n",
      "x.toml");
  REQUIRE(t.compensator);
  CHECK(*t.compensator == FocusCompensator::kBestRms);
  REQUIRE(t.compensators);
  CHECK(t.compensators->decenter_elements == std::vector<int>{2});
  REQUIRE(t.spot_reference);
  CHECK(*t.spot_reference == SpotReference::kNominal);
  CHECK_THROWS_WITH_AS(
      parse_tolerance_table("[tolerance]\ncompensator = \"image-shift,decenter:element=x\"\n",
                            "x.toml"),
      doctest::Contains("x.toml:2"), Error);
  // The image shift moves nothing about the centroids: refused with that reference.
  ToleranceOptions o;
  o.image_shift = true;
  CHECK_THROWS_WITH_AS(o.validate(), doctest::Contains("spot_reference = nominal"), Error);
  o.spot_reference = SpotReference::kNominal;
  CHECK_NOTHROW(o.validate());
  // A group the lens does not have.
  ToleranceOptions g = small_options();
  g.decenter_compensators = {4};
  CHECK_THROWS_WITH_AS(ToleranceModel(tessar(), g),
                       doctest::Contains("the lens has 3 groups of glasses (rows tedx1..tedx3)"),
                       Error);
}

namespace {

// A pure decenter (x, y) of group `group`, compensated by that group's own decenter: the trial
// is the nominal moved by (x, y) + c, so its compensated merit is the compensated nominal's,
// reached at c = c_0 - (x, y). Returns the uncompensated nominal's mean spot.
double check_own_decenter(const Lens& lens, ToleranceOptions o, int group,
                          const std::vector<std::pair<double, double>>& moves) {
  o.tolerances = Tolerances::zero();
  o.tolerances.decenter_mm = 0.02;
  const ToleranceModel plain(lens, o);
  o.decenter_compensators = {group};
  const ToleranceModel compensated(lens, o);
  const int dx = parameter_index(compensated, fmt::format("tedx{}", group));
  const int dy = parameter_index(compensated, fmt::format("tedy{}", group));
  const std::vector<double> zero(compensated.parameters().size(), 0.0);
  const TrialResult nominal = plain.evaluate(zero);
  const TrialResult best = compensated.evaluate(zero);
  REQUIRE(nominal.valid);
  REQUIRE(best.valid);
  REQUIRE(best.compensation.size() == 2);
  MESSAGE(lens.name, ": nominal ", nominal.mean_spot_um, " um, compensated nominal ",
          best.mean_spot_um, " um at group ", group, " moved (", best.compensation[0], ", ",
          best.compensation[1], ") mm");
  CHECK(best.mean_spot_um <= nominal.mean_spot_um);
  for (const auto& [x, y] : moves) {
    std::vector<double> d = zero;
    d[static_cast<std::size_t>(dx)] = x;
    d[static_cast<std::size_t>(dy)] = y;
    const TrialResult before = plain.evaluate(d);
    const TrialResult after = compensated.evaluate(d);
    REQUIRE(before.valid);
    REQUIRE(after.valid);
    MESSAGE("group ", group, " decentred by (", x, ", ", y, ") mm: mean spot ", before.mean_spot_um,
            " um, compensated ", after.mean_spot_um, " um; compensator moves (",
            after.compensation[0], ", ", after.compensation[1], ") mm");
    // The decenter costs something (else the check proves nothing) ...
    CHECK(before.mean_spot_um > nominal.mean_spot_um * (1.0 + 1e-3));
    // ... and the compensator takes it back to the compensated nominal, to 1e-9.
    CHECK(std::abs(after.mean_spot_um - best.mean_spot_um) <= 1e-9 * best.mean_spot_um);
    REQUIRE(after.compensation.size() == 2);
    CHECK(std::abs(after.compensation[0] - (best.compensation[0] - x)) <= 1e-6);
    CHECK(std::abs(after.compensation[1] - (best.compensation[1] - y)) <= 1e-6);
    CHECK(after.perturbations == d);
  }
  return nominal.mean_spot_um;
}

}  // namespace

TEST_CASE("tolerance compensators: a group's own decenter undoes its decenter exactly") {
  // Fields on +y and -y, +x and -x: the merit is even in the decenter (to the pupil sampling),
  // the nominal is its minimum, and the compensated pure decenter returns the nominal merit.
  Lens cooke = read_lens(test::source_dir() / "lenses" / "zmx" / "cooke_triplet_50.zmx");
  auto field_at = [](double x, double y) {
    FieldPoint f;
    f.x = x;
    f.value = y;
    return f;
  };
  cooke.specs.fields = {field_at(0, 0), field_at(0, 14), field_at(0, -14), field_at(14, 0),
                        field_at(-14, 0)};
  ToleranceOptions o = small_options();
  o.fields = 5;
  {
    ToleranceOptions plain = o;
    plain.tolerances = Tolerances::zero();
    plain.tolerances.decenter_mm = 0.02;
    const ToleranceModel model(cooke, plain);
    const TrialResult nominal = model.evaluate(std::vector<double>(model.parameters().size(), 0));
    plain.decenter_compensators = {2};
    const ToleranceModel compensated(cooke, plain);
    const TrialResult best =
        compensated.evaluate(std::vector<double>(model.parameters().size(), 0));
    // Even to the sampling: the full pupil is mirror-symmetric in x (the compensator does not
    // move in x), but the ring pattern's alternating radii are not in y, which leaves the
    // nominal 4e-6 of its merit above the minimum (a y move of 0.3 um).
    REQUIRE(best.compensation.size() == 2);
    CHECK(std::abs(best.compensation[0]) <= 1e-6);
    CHECK(std::abs(best.compensation[1]) <= 1e-3);
    CHECK(best.mean_spot_um <= nominal.mean_spot_um);
    CHECK(nominal.mean_spot_um - best.mean_spot_um <= 1e-5 * nominal.mean_spot_um);
  }
  check_own_decenter(cooke, o, 2, {{0.0, 0.02}, {-0.015, 0.01}});
  // The Tessar at its paper fields 0..hfov, all on +y: a y decenter of group 2 trades coma
  // between the fields, so the compensated nominal lies a little below the nominal; a pure
  // decenter still comes back to it.
  check_own_decenter(tessar(), small_options(), 2, {{0.0, 0.02}, {-0.015, 0.01}});
}

TEST_CASE("tolerance compensators: the image shift re-registers the image on the detector") {
  const Lens lens = tessar();
  ToleranceOptions o = small_options();
  o.tolerances = Tolerances::zero();
  o.tolerances.decenter_mm = 0.02;
  const ToleranceModel centroid(lens, o);
  o.spot_reference = SpotReference::kNominal;
  const ToleranceModel detector(lens, o);
  o.image_shift = true;
  const ToleranceModel shifted(lens, o);
  ToleranceOptions one = o;
  one.fields = 1;  // on axis only: one shift can re-register it exactly
  const ToleranceModel shifted_axis(lens, one);
  one.image_shift = false;
  const ToleranceModel detector_axis(lens, one);
  one.spot_reference = SpotReference::kCentroid;
  const ToleranceModel centroid_axis(lens, one);

  std::vector<double> d(centroid.parameters().size(), 0.0);
  // The nominal is the same about its centroids and about its own image points.
  const TrialResult n0 = centroid.evaluate(d), n1 = detector.evaluate(d), n2 = shifted.evaluate(d);
  CHECK(n1.mean_spot_um == doctest::Approx(n0.mean_spot_um).epsilon(1e-12));
  CHECK(n2.mean_spot_um == doctest::Approx(n0.mean_spot_um).epsilon(1e-12));
  // Group 1 decentred: the image moves (boresight) and its coma differs from field to field.
  d[static_cast<std::size_t>(parameter_index(centroid, "tedy1"))] = 0.02;
  d[static_cast<std::size_t>(parameter_index(centroid, "tedx1"))] = -0.01;
  const TrialResult c = centroid.evaluate(d), n = detector.evaluate(d), s = shifted.evaluate(d);
  MESSAGE("tedx1 -0.01, tedy1 0.02 mm: about the centroids ", c.mean_spot_um,
          " um; about the nominal image points ", n.mean_spot_um, " um; with the image shift ",
          s.mean_spot_um, " um (shift ", s.compensation[0], ", ", s.compensation[1], " mm)");
  // About fixed points the displacement adds to the blur; a common shift takes most of it back,
  // never all of it with three fields (the displacement differs between fields).
  CHECK(n.mean_spot_um > c.mean_spot_um * 1.01);
  CHECK(s.mean_spot_um < n.mean_spot_um);
  CHECK(s.mean_spot_um > c.mean_spot_um);
  // The shift is the minimum: moving it either way by 0.1 um costs.
  REQUIRE(s.compensation.size() == 2);
  CHECK(std::abs(s.compensation[0]) > 1e-4);
  CHECK(std::abs(s.compensation[1]) > 1e-4);
  // On axis alone one shift re-registers the image exactly: S^2 = RMS^2 + |c - q - s|^2 with
  // s = c - q, the centroid-referenced spot.
  const TrialResult ca = centroid_axis.evaluate(d), na = detector_axis.evaluate(d),
                    sa = shifted_axis.evaluate(d);
  MESSAGE("on axis: centroid ", ca.mean_spot_um, " um, nominal point ", na.mean_spot_um,
          " um, shifted ", sa.mean_spot_um, " um");
  CHECK(na.mean_spot_um > ca.mean_spot_um * 1.01);
  CHECK(std::abs(sa.mean_spot_um - ca.mean_spot_um) <= 1e-9 * ca.mean_spot_um);
  // The shift moved the image by the centroid's displacement: (c - q) of the nominal.
  const TrialResult nominal_axis = centroid_axis.evaluate(std::vector<double>(d.size(), 0.0));
  CHECK(sa.compensation[0] ==
        doctest::Approx(ca.centroid_x_mm[0] - nominal_axis.centroid_x_mm[0]).epsilon(1e-9));
  CHECK(sa.compensation[1] ==
        doctest::Approx(ca.centroid_y_mm[0] - nominal_axis.centroid_y_mm[0]).epsilon(1e-9));
  // With the best-rms focus the focus and the shift are solved together: no worse than the
  // focus alone about the same points.
  ToleranceOptions best = o;
  best.compensator = FocusCompensator::kBestRms;
  const ToleranceModel best_shift(lens, best);
  best.image_shift = false;
  const ToleranceModel best_alone(lens, best);
  CHECK(best_shift.evaluate(d).mean_spot_um <= best_alone.evaluate(d).mean_spot_um);
  CHECK(best_shift.evaluate(d).mean_spot_um <= s.mean_spot_um);
}

TEST_CASE("tolerance compensators: the Tessar's table and yield with a decentred group") {
  const Lens lens = tessar();
  ToleranceOptions o = small_options();
  o.trials = 60;
  o.seed = 3;
  o.sensitivity = true;
  const ToleranceReport plain_first = run_tolerance(lens, [&] {
    ToleranceOptions p = o;
    p.trials = 1;
    p.sensitivity = false;
    return p;
  }());
  // A yield limit between the nominal and the typical trial.
  o.max_spot_um = plain_first.nominal.mean_spot_um * 1.10;
  const ToleranceReport plain = run_tolerance(lens, o);
  o.decenter_compensators = {2};
  const ToleranceReport compensated = run_tolerance(lens, o);
  REQUIRE(plain.yield);
  REQUIRE(compensated.yield);
  MESSAGE("Tessar, ", o.trials, " trials (6 rings, 3 fields), yield at ", *o.max_spot_um,
          " um: ", 100.0 * *plain.yield, " % uncompensated, ", 100.0 * *compensated.yield,
          " % with group 2's decenter; mean spot ", plain.spot.mean, " -> ", compensated.spot.mean,
          " um, p90 ", plain.spot.p90, " -> ", compensated.spot.p90);
  // The same draws (a compensator is no parameter), each trial no worse compensated.
  REQUIRE(plain.trials.size() == compensated.trials.size());
  for (std::size_t i = 0; i < plain.trials.size(); ++i) {
    CHECK(plain.trials[i].perturbations == compensated.trials[i].perturbations);
    if (plain.trials[i].valid && compensated.trials[i].valid)
      CHECK(compensated.trials[i].mean_spot_um <= plain.trials[i].mean_spot_um);
  }
  CHECK(*compensated.yield >= *plain.yield);
  CHECK(compensated.spot.mean < plain.spot.mean);
  // In the sensitivity table group 2's own decenters now cost nothing.
  for (const SensitivityRow& row : compensated.sensitivity) {
    const ToleranceParameter& p = compensated.parameters[static_cast<std::size_t>(row.parameter)];
    if (p.name != "tedx2" && p.name != "tedy2") continue;
    INFO(p.name, ": ", row.plus_um, ", ", row.minus_um, " um");
    CHECK(std::abs(row.plus_um) <= 1e-6);
    CHECK(std::abs(row.minus_um) <= 1e-6);
  }
  // The CSV and the JSON carry the compensator moves.
  const std::string csv = format_trials_csv(compensated);
  CHECK(csv.find(",comp_dx2_mm,comp_dy2_mm\n") != std::string::npos);
  CHECK(format_tolerance_json(compensated).find("\"comp_dy2_mm\"") != std::string::npos);
  CHECK(format_trials_csv(plain).find("comp_") == std::string::npos);
  CHECK(format_tolerance_text(compensated).find("decenter x, y of group 2") != std::string::npos);
}

}  // namespace test_tolerance_compensators
