// Tolerancing a lens at fields off +y (issue 32): with element decenters toleranced the trials are
// not rotationally symmetric, so a field on -y and one on x are traced where they are written
// (their azimuths), not as the mirror of the +y field.
#include <doctest/doctest.h>

#include <cmath>
#include <string>

#include "lensopt/formats/lens_file.h"
#include "lensopt/lens/lens.h"
#include "lensopt/tolerance/tolerance.h"
#include "test_support.h"

namespace test_tolerance_fields {

using namespace lensopt;

TEST_CASE("tolerance fields: a decentred trial sees the +y, -y and x fields apart") {
  Lens lens = read_lens(test::source_dir() / "lenses" / "zmx" / "cooke_triplet_50.zmx");
  REQUIRE(lens.specs.mode == SpecMode::kAsWritten);
  auto field_at = [](double x, double y) {
    FieldPoint f;
    f.x = x;
    f.value = y;
    return f;
  };
  lens.specs.fields = {field_at(0, 0), field_at(0, 10), field_at(0, -10), field_at(10, 0)};
  ToleranceOptions o;
  o.tolerances = Tolerances::zero();
  o.tolerances.decenter_mm = 0.05;
  o.rings = 8;
  o.trials = 1;
  const ToleranceModel model(lens, o);
  // Four fields: on a symmetric lens +y and -y would be one (lens_setup), but not here.
  REQUIRE(model.fields_deg().size() == 4);
  const std::vector<ToleranceParameter>& params = model.parameters();
  std::vector<double> d(params.size(), 0.0);
  int tedy2 = -1;
  for (std::size_t i = 0; i < params.size(); ++i)
    if (params[i].name == "tedy2") tedy2 = static_cast<int>(i);
  REQUIRE(tedy2 >= 0);
  const TrialResult nominal = model.evaluate(d);
  REQUIRE(nominal.valid);
  // The nominal is symmetric: the three 10 deg fields agree (traced in their own frames).
  for (int h : {2, 3}) {
    INFO("field ", h + 1, ": ", nominal.rms_spot_um[h], " against ", nominal.rms_spot_um[1]);
    CHECK(std::abs(nominal.rms_spot_um[h] - nominal.rms_spot_um[1]) <=
          1e-9 * nominal.rms_spot_um[1]);
  }
  // The middle element 0.05 mm up: coma of opposite signs at +y and -y, and another spot at x.
  d[tedy2] = 0.05;
  const TrialResult r = model.evaluate(d);
  REQUIRE(r.valid);
  MESSAGE("tedy2 0.05 mm: spots ", r.rms_spot_um[0], ", ", r.rms_spot_um[1], ", ", r.rms_spot_um[2],
          ", ", r.rms_spot_um[3], " um (nominal ", nominal.rms_spot_um[1], " um at 10 deg)");
  CHECK(std::abs(r.rms_spot_um[1] - r.rms_spot_um[2]) > 1e-3 * r.rms_spot_um[1]);
  CHECK(std::abs(r.rms_spot_um[1] - r.rms_spot_um[3]) > 1e-3 * r.rms_spot_um[1]);
  CHECK(std::abs(r.rms_spot_um[2] - r.rms_spot_um[3]) > 1e-3 * r.rms_spot_um[2]);
}

TEST_CASE("tolerance fields: the summary counts the full pupil of a decentred trial") {
  // With decenters or tilts toleranced every trial is traced on the full pupil (the nominal
  // carries zero placements): 2 R^2 rays per field and wavelength, which the summary states
  // (it said R^2, the half pupil).
  const Lens lens = read_lens(test::source_dir() / "lenses" / "tessar.toml");
  ToleranceOptions o;
  o.rings = 6;
  o.trials = 1;
  const ToleranceModel placed(lens, o);
  CHECK(placed.rays_per_field_wavelength() == 72);
  o.tolerances.decenter_mm = 0.0;
  o.tolerances.tilt_arcmin = 0.0;
  o.tolerances.surface_tilt_arcmin = 0.0;
  const ToleranceModel symmetric(lens, o);
  CHECK(symmetric.rays_per_field_wavelength() == 36);
}

}  // namespace test_tolerance_fields
