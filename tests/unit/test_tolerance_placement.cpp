// Tolerancing by element decenter and tilt (issue 32): the parameters (TEDX, TEDY, TETX, TETY per
// group of glasses, defaults 0.02 mm and 1 arcmin), their [tolerance] keys, the closed-form image
// shift of a decentred singlet, and the Tessar's sensitivity table and yield with them.
#include <doctest/doctest.h>
#include <fmt/format.h>

#include <cmath>
#include <string>

#include "lensopt/core/error.h"
#include "lensopt/formats/lens_file.h"
#include "lensopt/lens/lens.h"
#include "lensopt/tolerance/tolerance.h"
#include "test_support.h"

namespace test_tolerance_placement {

using namespace lensopt;

namespace {

Lens tessar() {
  return read_lens(test::source_dir() / "lenses" / "tessar.toml");
}

}  // namespace

TEST_CASE("tolerance placement: one decenter and tilt pair per group of glasses") {
  const Lens lens = tessar();
  const Tolerances defaults;
  CHECK(defaults.decenter_mm == 0.02);
  CHECK(defaults.tilt_arcmin == 1.0);
  const std::vector<ToleranceParameter> params = tolerance_parameters(lens, defaults);
  // The Tessar: a front singlet, a negative singlet and a cemented doublet (one group).
  std::vector<std::string> names;
  for (const ToleranceParameter& p : params)
    if (p.kind == ToleranceParameter::Kind::kDecenterX ||
        p.kind == ToleranceParameter::Kind::kDecenterY ||
        p.kind == ToleranceParameter::Kind::kTiltX || p.kind == ToleranceParameter::Kind::kTiltY)
      names.push_back(p.name + "/" + p.limit_text + "/" + std::to_string(p.surface) + "-" +
                      std::to_string(p.last_surface));
  const std::vector<std::string> expected = {
      "tedx1/0.02 mm/0-1", "tedy1/0.02 mm/0-1", "tetx1/1 arcmin/0-1", "tety1/1 arcmin/0-1",
      "tedx2/0.02 mm/2-3", "tedy2/0.02 mm/2-3", "tetx2/1 arcmin/2-3", "tety2/1 arcmin/2-3",
      "tedx3/0.02 mm/5-7", "tedy3/0.02 mm/5-7", "tetx3/1 arcmin/5-7", "tety3/1 arcmin/5-7"};
  CHECK(names == expected);
  // The [tolerance] table keys.
  const ToleranceSettings t =
      parse_tolerance_table("[tolerance]\ndecenter_mm = 0.05\ntilt_arcmin = 2\n", "x.toml");
  REQUIRE(t.decenter_mm);
  CHECK(*t.decenter_mm == 0.05);
  REQUIRE(t.tilt_arcmin);
  CHECK(*t.tilt_arcmin == 2.0);
  CHECK_THROWS_AS(parse_tolerance_table("[tolerance]\ntilt_arcmin = -1\n", "x.toml"), Error);
}

TEST_CASE("tolerance placement: a decentred singlet moves its image linearly") {
  // A singlet behind its stop, fields 0 and 5 deg, traced as written, decentred by +-delta.
  Lens lens;
  lens.name = "singlet";
  lens.specs.mode = SpecMode::kAsWritten;
  lens.specs.aperture_type = ApertureType::kEntrancePupilDiameter;
  lens.specs.aperture_value = 4.0;
  lens.specs.fields = {FieldPoint{0.0}, FieldPoint{5.0}};
  lens.specs.wavelengths_nm = {587.6};
  lens.specs.wavelength_channels = {1};
  Surface stop, front, back;
  stop.is_stop = true;
  stop.thickness_mm = 0.5;
  front.curvature_per_mm = 1.0 / 100.0;
  front.thickness_mm = 2.0;
  front.material = Material::model(1.5, 60.0);
  back.curvature_per_mm = -1.0 / 100.0;
  back.thickness_mm = 99.0;
  lens.surfaces = {stop, front, back};
  ToleranceOptions o;
  o.tolerances = Tolerances::zero();
  o.tolerances.decenter_mm = 0.02;
  o.compensator = FocusCompensator::kParaxial;
  o.rings = 8;
  o.jobs = 1;
  const ToleranceModel model(lens, o);
  const std::vector<ToleranceParameter>& params = model.parameters();
  int tedy = -1;
  for (std::size_t i = 0; i < params.size(); ++i)
    if (params[i].name == "tedy1") tedy = static_cast<int>(i);
  REQUIRE(tedy >= 0);
  const double delta = 0.02;
  std::vector<double> d(params.size(), 0.0);
  const TrialResult nominal = model.evaluate(d);
  d[tedy] = delta;
  const TrialResult up = model.evaluate(d);
  d[tedy] = -delta;
  const TrialResult down = model.evaluate(d);
  REQUIRE(nominal.valid);
  REQUIRE(up.valid);
  REQUIRE(down.valid);
  // The nominal with zero placements (the 3D path, full pupil) is the symmetric nominal.
  ToleranceOptions symmetric = o;
  symmetric.tolerances.decenter_mm = 0.0;
  const ToleranceModel plain(lens, symmetric);
  const TrialResult n0 = plain.evaluate(std::vector<double>(plain.parameters().size(), 0.0));
  CHECK(nominal.mean_spot_um == doctest::Approx(n0.mean_spot_um).epsilon(1e-12));
  CHECK(nominal.max_abs_distortion_pct == doctest::Approx(n0.max_abs_distortion_pct).epsilon(1e-9));
  // A decenter moves the image of every field by delta, to first order: the distortion at the
  // last field moves by the same amount for +delta and -delta, in opposite directions (the
  // exact shift, delta, is checked on the traced rays in test_trace_geometry3d.cpp). |D0| is
  // above the change here, so |D(+delta)| - |D0| = |D0| - |D(-delta)|.
  const double rise = up.max_abs_distortion_pct - nominal.max_abs_distortion_pct;
  const double fall = nominal.max_abs_distortion_pct - down.max_abs_distortion_pct;
  MESSAGE(fmt::format("distortion at 5 deg: nominal {:.6f} %, +delta {:.6f} %, -delta {:.6f} %",
                      nominal.max_abs_distortion_pct, up.max_abs_distortion_pct,
                      down.max_abs_distortion_pct));
  CHECK(std::abs(rise) > 0.1);  // 0.02 mm on an image height of about 8.7 mm: 0.2 %
  CHECK(rise == doctest::Approx(fall).epsilon(1e-3));
  // The EFL does not change with a decenter; the spot hardly does (a decentred singlet's coma).
  CHECK(up.efl_mm == doctest::Approx(nominal.efl_mm).epsilon(1e-12));
}

TEST_CASE("tolerance placement: the Tessar with decenter and tilt tolerances") {
  const Lens lens = tessar();
  ToleranceOptions o;                      // the default tolerances, now with 0.02 mm and 1 arcmin
  o.tolerances.surface_tilt_arcmin = 0.0;  // the surfaces' wedge: test_tolerance_surface.cpp
  o.trials = 40;
  o.rings = 8;
  o.fields = 5;
  o.jobs = 2;
  o.max_spot_um = 20.0;
  const ToleranceReport r = run_tolerance(lens, o);
  REQUIRE(r.sensitivity.size() == 31);  // 19 as before + 3 groups x 4
  std::string table;
  for (std::size_t i = 0; i < r.sensitivity.size(); ++i)
    table += fmt::format("{}({:.3f}) ", r.parameters[r.sensitivity[i].parameter].name,
                         r.sensitivity[i].score_um);
  MESSAGE("Tessar sensitivity with decenters and tilts (um): ", table);
  // Every decenter and tilt row moves the spot (none is a no-op), and with zero decenter and
  // tilt tolerances the nominal is the one of the symmetric path (same mean spot to rounding).
  for (const SensitivityRow& s : r.sensitivity) {
    const ToleranceParameter& p = r.parameters[s.parameter];
    if (p.kind == ToleranceParameter::Kind::kDecenterX ||
        p.kind == ToleranceParameter::Kind::kTiltX)
      CHECK(s.score_um > 0.0);
  }
  ToleranceOptions off = o;
  off.tolerances.decenter_mm = 0.0;
  off.tolerances.tilt_arcmin = 0.0;
  off.trials = 1;
  off.sensitivity = false;
  const ToleranceReport r0 = run_tolerance(lens, off);
  CHECK(r.nominal.mean_spot_um == doctest::Approx(r0.nominal.mean_spot_um).epsilon(1e-12));
  MESSAGE(fmt::format("Tessar: nominal {:.4f} um, mean {:.4f} um, p90 {:.4f} um, yield {:.3f}",
                      r.nominal.mean_spot_um, r.spot.mean, r.spot.p90, r.yield.value_or(-1.0)));
  CHECK(r.spot.mean > r0.nominal.mean_spot_um);
}

}  // namespace test_tolerance_placement
