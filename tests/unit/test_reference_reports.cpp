// The designer's reports against independent calculations: the encircled energy of an
// aberration-free lens against the Airy pattern's closed form 1 - J0^2 - J1^2 (diffraction) and a
// defocused one against the uniform blur disk's (r / R)^2 (geometric); the chromatic focal shift
// of a thin singlet against the thin-lens hand computation (f(F) - f(C) = -f / V to first order);
// real-ray lateral colour against exact paraxial colour at a small field.
#include <doctest/doctest.h>

#include <cmath>
#include <string>
#include <vector>

#include "lensopt/analysis/chromatic.h"
#include "lensopt/analysis/encircled_energy.h"
#include "lensopt/analysis/seidel.h"
#include "lensopt/core/error.h"
#include "lensopt/lens/lens_io.h"
#include "lensopt/paraxial/paraxial.h"
#include "test_support.h"

namespace test_reference_reports {

using namespace lensopt;

namespace {

// f = 100 mm f/40 plano-convex singlet (as tests/unit/test_wave.cpp): aberration-free to a
// thousandth of a wave on axis; one wavelength given twice.
Lens slow_singlet(double image_distance_mm = 97.36) {
  const std::string text = R"(
[lens]
name = "slow-singlet"
[specs]
f_number = 40.0
half_field_deg = 0.5
sensor_diagonal_mm = 1.7453292519943295
wavelengths_nm = [587.56, 587.56]
channels = ["G", "G"]
dispersion = "abbe"
[[surfaces]]
radius_mm = inf
thickness_mm = 1.0
stop = true
[[surfaces]]
radius_mm = 51.68
thickness_mm = 4.0
material = { nd = 1.5168, vd = 64.17 }
[[surfaces]]
radius_mm = inf
thickness_mm = )" + std::to_string(image_distance_mm) +
                           "\n";
  return parse_lens_toml(text, "slow-singlet");
}

TraceSystem<double> prepare(const Lens& lens, int fields = 2, int rings = 32) {
  TraceOptions options;
  options.fields = fields;
  options.rings = rings;
  return prepare_system(make_trace_lens(lens), lens.specs, options);
}

// A thin singlet (1 um of glass) of paraxial curvatures c1, c2 with its stop `stop_mm` in front,
// F, d, C wavelengths, entrance pupil 10 mm, fields 0 and `field_deg`.
Lens thin_singlet(double stop_mm, double c1, double c2, double vd, double field_deg,
                  double image_mm) {
  Lens lens;
  lens.name = "thin singlet";
  lens.specs.mode = SpecMode::kAsWritten;
  lens.specs.aperture_type = ApertureType::kEntrancePupilDiameter;
  lens.specs.aperture_value = 10.0;
  lens.specs.wavelengths_nm = {486.1327, 587.5618, 656.2725};
  lens.specs.wavelength_channels = {2, 1, 0};
  lens.specs.primary_wavelength_nm = 587.5618;
  lens.specs.fields = {{0.0, 1.0, {}}, {field_deg, 1.0, {}}};
  Surface stop;
  stop.is_stop = true;
  stop.thickness_mm = stop_mm;
  Surface front;
  front.curvature_per_mm = c1;
  front.thickness_mm = 1e-3;
  front.material = Material::model(1.5168, vd);
  Surface back;
  back.curvature_per_mm = c2;
  back.thickness_mm = image_mm;
  lens.surfaces = {stop, front, back};
  return lens;
}

}  // namespace

TEST_CASE(
    "reports: diffraction encircled energy of an aberration-free lens is the Airy pattern's") {
  const Lens lens = slow_singlet();
  const TraceSystem<double> sys = prepare(lens);
  EncircledEnergyOptions options;
  options.field_indices = {0};
  options.wave.pupil_samples = 128;
  // Refocus on the paraxial focus (the written image plane is 2.9 um short of it).
  options.wave.focus_shift_mm = sys.bfl_mm - sys.lens.thickness_mm.back();
  const double lambda_mm = 587.56e-6, f_number = 40.0;
  const double airy_um = 1.22 * lambda_mm * 1e3 * f_number;
  options.max_radius_um = 5.0 * airy_um;
  options.radii = 201;
  const EncircledEnergy ee = encircled_energy(sys, options);
  REQUIRE(ee.fields.size() == 1);
  const FieldEncircledEnergy& f = ee.fields[0];
  CHECK(ee.airy_radius_um == doctest::Approx(airy_um).epsilon(3e-3));
  CHECK(ee.warnings.empty());
  // Closed form (Rayleigh): EE(r) = 1 - J0(v)^2 - J1(v)^2, v = pi r / (lambda N).
  double worst = 0;
  for (std::size_t i = 0; i < ee.radius_um.size(); ++i) {
    const double v = kPi * ee.radius_um[i] * 1e-3 / (lambda_mm * f_number);
    const double j0 = std::cyl_bessel_j(0.0, v), j1 = std::cyl_bessel_j(1.0, v);
    worst = std::max(worst, std::abs(f.diffraction[i] - (1.0 - j0 * j0 - j1 * j1)));
  }
  MESSAGE("largest |EE - (1 - J0^2 - J1^2)| over 0..5 Airy radii: " << worst);
  CHECK(worst < 2e-3);
  // 50 % at the root of 1 - J0(v)^2 - J1(v)^2 = 1/2 (bisection here: v = 1.6802); the first dark
  // ring (v = 3.8317, the first zero of J1) holds 1 - J0^2 = 83.8 %.
  REQUIRE(f.diffraction_r50_um);
  double lo = 0.5, hi = 3.0;
  for (int i = 0; i < 60; ++i) {
    const double mid = 0.5 * (lo + hi);
    const double j0 = std::cyl_bessel_j(0.0, mid), j1 = std::cyl_bessel_j(1.0, mid);
    (1.0 - j0 * j0 - j1 * j1 > 0.5 ? hi : lo) = mid;
  }
  const double v50 = kPi * *f.diffraction_r50_um * 1e-3 / (lambda_mm * f_number);
  CHECK(v50 == doctest::Approx(lo).epsilon(3e-3));
  const double v_ring = 3.8317;  // the first zero of J1
  const double r_ring_um = v_ring * lambda_mm * 1e3 * f_number / kPi;
  std::vector<double> at_ring = psf_encircled_energy(
      [&] {
        WaveOptions wo = options.wave;
        wo.keep_psf = true;
        return analyze_wave(sys, wo, {}, {0}).fields[0].mono[0];
      }(),
      {r_ring_um}, 0.0, 0.0);
  CHECK(at_ring[0] ==
        doctest::Approx(1.0 - std::pow(std::cyl_bessel_j(0.0, v_ring), 2)).epsilon(2e-3));
}

TEST_CASE("reports: geometric encircled energy of a defocused perfect lens is (r / R)^2") {
  // The slow singlet's image plane 4 mm beyond its focus: the rays of its (aberration-free) pupil
  // fill a disk of radius R = 4 mm / (2 N) uniformly, so EE(r) = (r / R)^2 for r <= R.
  const Lens focused = slow_singlet();
  const TraceSystem<double> at_focus = prepare(focused);
  const double defocus_mm = 4.0;
  const Lens lens = slow_singlet(at_focus.bfl_mm + defocus_mm);
  const TraceSystem<double> sys = prepare(lens, 2, 32);
  EncircledEnergyOptions options;
  options.field_indices = {0};
  options.diffraction = false;
  options.radii = 101;
  const EncircledEnergy ee = encircled_energy(sys, options);
  const FieldEncircledEnergy& f = ee.fields[0];
  // The marginal ray's slope: u' = -r_EP / f, R = defocus * r_EP / f (paraxially; the real ray
  // differs by O(u'^2) ~ 1e-4).
  const double blur_um = defocus_mm * 1e3 * (0.5 * sys.epd_mm) / sys.efl_mm;
  CHECK(ee.radius_um.back() == doctest::Approx(1.05 * blur_um).epsilon(5e-3));
  double worst = 0;
  for (std::size_t i = 0; i < ee.radius_um.size(); ++i) {
    const double r = ee.radius_um[i];
    const double expected = r >= blur_um ? 1.0 : (r / blur_um) * (r / blur_um);
    worst = std::max(worst, std::abs(f.geometric[i] - expected));
  }
  MESSAGE("largest |EE_geo - (r/R)^2|: " << worst << " (R = " << blur_um << " um)");
  // The R = 32 rings of the paper's sampling (trace/system.h: ring i holds 2i + 1 of the R^2
  // rays, spread over the radii [2i, 2i + 1] / (2R - 1)) quantize the disk: the curve steps by
  // at most one ring's share, (2R - 1) / R^2 < 2 / R.
  CHECK(worst < 2.0 / 32.0);
  CHECK(f.geometric.back() == 1.0);
  REQUIRE(f.geometric_r50_um);
  CHECK(*f.geometric_r50_um == doctest::Approx(blur_um * std::sqrt(0.5)).epsilon(0.02));
}

TEST_CASE("reports: chromatic focal shift of a thin singlet is the thin-lens hand computation") {
  // f(lambda) = 1 / ((n(lambda) - 1) (c1 - c2)) for a thin lens, so
  // f(F) - f(C) = (1 / (nF - 1) - 1 / (nC - 1)) / (c1 - c2) = -f (nF - nC) / ((nF - 1)(nC - 1)) /
  // (c1 - c2) ... and to first order in the dispersion -f / V, V = (nd - 1) / (nF - nC).
  for (double vd : {64.17, 36.37}) {
    CAPTURE(vd);
    const double c1 = 0.01, c2 = -0.0093;
    const Lens lens = thin_singlet(0.0, c1, c2, vd, 1.0, 5.0);
    TraceOptions t;
    t.rings = 2;
    const TraceSystem<double> sys = prepare_lens_system(lens, t);
    const ChromaticFocalShift s = chromatic_focal_shift(lens, sys);
    REQUIRE(s.wavelengths_nm.size() == 3);
    CHECK(s.wavelengths_nm[0] == 486.1327);
    CHECK(s.wavelengths_nm[2] == 656.2725);
    CHECK(s.shift_mm[1] == 0.0);  // the primary
    const double nF = sys.lens.index_at_nm(1, 486.1327), nd = sys.lens.index_at_nm(1, 587.5618),
                 nC = sys.lens.index_at_nm(1, 656.2725);
    const double k = c1 - c2;
    const double fF = 1.0 / ((nF - 1.0) * k), fd = 1.0 / ((nd - 1.0) * k),
                 fC = 1.0 / ((nC - 1.0) * k);
    // The 1 um glass moves the principal plane by ~1e-6 f: the thin lens to 1e-6.
    CHECK(s.shift_mm[0] == doctest::Approx(fF - fd).epsilon(1e-5));
    CHECK(s.shift_mm[2] == doctest::Approx(fC - fd).epsilon(1e-5));
    const double df = s.shift_mm[0] - s.shift_mm[2];
    const double v = (nd - 1.0) / (nF - nC);
    MESSAGE("f(F) - f(C) = " << df << " mm; -f / V = " << -fd / v << " mm");
    CHECK(df < 0.0);  // blue focuses nearer the lens
    // The exact thin-lens difference is -f / V (nd - 1)^2 / ((nF - 1)(nC - 1)); -f / V is its
    // first order in the dispersion, the next term of relative order dn / (nd - 1) = 1 / V
    // (0.6 % for V = 64, 1.1 % for V = 36 here).
    CHECK(df == doctest::Approx(-fd / v * (nd - 1.0) * (nd - 1.0) / ((nF - 1.0) * (nC - 1.0)))
                    .epsilon(1e-5));
    CHECK(std::abs(df / (-fd / v) - 1.0) < 1.0 / v);
    CHECK(s.max_range_mm == doctest::Approx(std::abs(df)));
    // The band: 11 samples from F to C include both ends.
    const ChromaticFocalShift band = chromatic_focal_shift(lens, sys, 486.1327, 656.2725, 11);
    CHECK(band.band);
    REQUIRE(band.shift_mm.size() == 11);
    CHECK(band.shift_mm.front() == doctest::Approx(s.shift_mm[0]).epsilon(1e-12));
    CHECK(band.shift_mm.back() == doctest::Approx(s.shift_mm[2]).epsilon(1e-12));
    // The diffraction-limited depth 4 lambda N^2 at f/10 (EPD 10 mm).
    CHECK(s.diffraction_depth_mm ==
          doctest::Approx(4.0 * 587.5618e-6 * (fd / 10.0) * (fd / 10.0)).epsilon(1e-4));
  }
  const Lens lens = thin_singlet(0.0, 0.01, -0.0093, 64.17, 1.0, 5.0);
  const TraceSystem<double> sys = prepare_lens_system(lens, TraceOptions{});
  CHECK_THROWS_AS(chromatic_focal_shift(lens, sys, 700.0, 400.0), Error);
}

TEST_CASE("reports: real-ray lateral colour tends to exact paraxial colour at a small field") {
  // A singlet with its stop 20 mm in front has lateral colour; at 0.5 deg the real chief rays'
  // height difference on the paraxial image plane equals the paraxial one (seidel.h) to third
  // order in the field, ~(0.5 deg)^2 relative.
  for (double vd : {64.17, 36.37}) {
    CAPTURE(vd);
    Lens lens = thin_singlet(20.0, 0.01, -0.0093, vd, 0.5, 90.0);
    TraceOptions t;
    t.rings = 2;
    TraceSystem<double> sys = prepare_lens_system(lens, t);
    const SeidelReport seidel = seidel_report(sys);
    lens.surfaces.back().thickness_mm = seidel.first_order.image_distance_mm;
    sys = prepare_lens_system(lens, t);
    const LateralColour lc = lateral_colour(sys);
    REQUIRE(lc.valid.size() == 2);
    CHECK(lc.valid[1]);
    CHECK(lc.short_nm == 486.1327);
    CHECK(lc.long_nm == 656.2725);
    CHECK(std::abs(lc.lateral_colour_um[0]) < 1e-9);  // on axis
    const double paraxial_um = seidel_report(sys).lateral_colour_mm * 1e3;
    MESSAGE("real " << lc.lateral_colour_um[1] << " um, paraxial " << paraxial_um << " um");
    CHECK(std::abs(paraxial_um) > 1e-2);
    CHECK(lc.lateral_colour_um[1] == doctest::Approx(paraxial_um).epsilon(2e-3));
    // Relative to the primary: the d line's own entry is 0 and short less long is the
    // difference of the F and C entries.
    CHECK(lc.relative_um[1][1] == 0.0);
    CHECK(lc.relative_um[1][0] - lc.relative_um[1][2] ==
          doctest::Approx(lc.lateral_colour_um[1]).epsilon(1e-9));
  }
}

}  // namespace test_reference_reports
