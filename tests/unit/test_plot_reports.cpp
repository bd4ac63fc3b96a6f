// The report plots' data against independent calculations: the field curves of a thin singlet
// at its stop against the third-order closed forms (Seidel: S_III = H^2 phi, S_IV = H^2 phi / n),
// and the new plot kinds' data against the analysis functions analyze reports from.
#include <doctest/doctest.h>

#include <cmath>
#include <string>
#include <vector>

#include "lensopt/analysis/chromatic.h"
#include "lensopt/analysis/encircled_energy.h"
#include "lensopt/formats/lens_file.h"
#include "lensopt/plot/plot_data.h"
#include "lensopt/plot/report_charts.h"
#include "test_support.h"

namespace test_plot_reports {

using namespace lensopt;
using namespace lensopt::plot;

namespace {

// A thin singlet (20 um of glass: the lens file checks refuse an image 10^4 lens lengths away; f =
// 100 mm, shape `bend`) at its stop, one wavelength, EPD 10 mm, fields 0 and 3 deg, the image plane
// `image_mm` behind it.
Lens thin_singlet_at_stop(double bend, double image_mm) {
  Lens lens;
  lens.name = "thin singlet";
  lens.specs.mode = SpecMode::kAsWritten;
  lens.specs.aperture_type = ApertureType::kEntrancePupilDiameter;
  lens.specs.aperture_value = 10.0;
  lens.specs.wavelengths_nm = {587.5618};
  lens.specs.wavelength_channels = {1};
  lens.specs.primary_wavelength_nm = 587.5618;
  lens.specs.fields = {{0.0, 1.0, {}}, {3.0, 1.0, {}}};
  const double dc = 1.0 / (0.5168 * 100.0);
  Surface stop;
  stop.is_stop = true;
  Surface front;
  front.curvature_per_mm = 0.5 * (bend + 1.0) * dc;
  front.thickness_mm = 0.02;
  front.material = Material::model(1.5168, 64.17);
  Surface back;
  back.curvature_per_mm = 0.5 * (bend - 1.0) * dc;
  back.thickness_mm = image_mm;
  lens.surfaces = {stop, front, back};
  return lens;
}

}  // namespace

TEST_CASE("plot reports: field curves of a thin singlet at its stop are the Seidel closed forms") {
  // Third order, object at infinity, thin lens at its stop (phi = 1/f, H = y tan theta,
  // n' u' = -y phi): the sagittal and tangential foci lie behind the paraxial image plane by
  //   dz_S = -(S_III + S_IV) / (2 n' u'^2) = -f tan^2 theta (n + 1) / (2 n)
  //   dz_T = -(3 S_III + S_IV) / (2 n' u'^2) = -f tan^2 theta (3 n + 1) / (2 n)
  // whatever the bending; the Petzval surface between them at -f tan^2 theta / (2 n).
  for (double bend : {0.0, 1.0, -1.5}) {
    CAPTURE(bend);
    Lens lens = thin_singlet_at_stop(bend, 100.0);
    TraceOptions t;
    t.rings = 4;
    PlotContext probe = make_plot_context(lens, t);
    lens.surfaces.back().thickness_mm = probe.sys.bfl_mm;  // the paraxial focus
    const PlotContext ctx = make_plot_context(lens, t);
    const FieldCurveData d = compute_field_curves(ctx, 1e-3, 31);
    // One wavelength: every colour channel draws it (an empty channel borrows the nearest).
    REQUIRE(!d.focus.empty());
    for (const FocusCurve& curve : d.focus) CHECK(curve.wavelength_nm == 587.5618);
    const FocusCurve& c = d.focus[0];
    const double n = ctx.sys.lens.index_at_nm(1, 587.5618);
    const double f = ctx.sys.efl_mm;
    CHECK(f == doctest::Approx(100.0).epsilon(1e-4));
    // On axis: the paraxial focus, up to the close rays' (pupil 1e-3) spherical aberration,
    // 1.6e-6 mm at the strongest bending.
    CHECK(std::abs(c.tangential_mm[0]) < 1e-5);
    CHECK(std::abs(c.sagittal_mm[0]) < 1e-5);
    double worst_t = 0, worst_s = 0;
    for (std::size_t h = 1; h < d.field_deg.size(); ++h) {
      REQUIRE(c.valid[h]);
      const double t2 = std::pow(std::tan(d.field_deg[h] * kPi / 180.0), 2);
      const double dz_s = -f * t2 * (n + 1.0) / (2.0 * n);
      const double dz_t = -f * t2 * (3.0 * n + 1.0) / (2.0 * n);
      worst_s = std::max(worst_s, std::abs(c.sagittal_mm[h] / dz_s - 1.0));
      worst_t = std::max(worst_t, std::abs(c.tangential_mm[h] / dz_t - 1.0));
    }
    MESSAGE("largest relative error against the closed forms up to 3 deg: sagittal "
            << worst_s << ", tangential " << worst_t);
    // Fifth order: relative O(tan^2 theta) ~ 3e-3 at 3 deg.
    CHECK(worst_s < 1e-2);
    CHECK(worst_t < 1e-2);
  }
}

TEST_CASE("plot reports: the distortion curve is analyze's distortion at analyze's fields") {
  const auto src = lensopt::test::source_dir();
  for (const std::string name : {"lenses/tessar.toml", "lenses/zmx/double_gauss_100.zmx"}) {
    CAPTURE(name);
    const Lens lens = read_lens(src / name);
    TraceOptions t;
    t.rings = 8;
    const PlotContext ctx = make_plot_context(lens, t);
    const FieldCurveData d = compute_field_curves(ctx, 1e-3, 51);
    REQUIRE(d.sweep_distortion_percent.size() == d.field_deg.size());
    int shared = 0;
    for (std::size_t a = 0; a < ctx.report.fields.size(); ++a)
      for (std::size_t h = 0; h < d.field_deg.size(); ++h)
        if (std::abs(d.field_deg[h] - ctx.report.fields[a].field_deg) < 1e-12) {
          ++shared;
          CAPTURE(d.field_deg[h]);
          CHECK(d.sweep_distortion_percent[h] ==
                doctest::Approx(ctx.report.fields[a].distortion_percent).epsilon(1e-9).scale(1e-9));
        }
    MESSAGE(shared << " fields shared with analyze");
    CHECK(shared >= 2);  // at least the axis and the largest field
    CHECK(d.distortion_percent.size() == ctx.report.fields.size());
  }
}

TEST_CASE("plot reports: the Airy encircled energy reference is 1 - J0^2 - J1^2") {
  // v = pi r / (lambda N) and r_Airy = 1.22 lambda N: at the first dark ring (v = 3.8317) 83.8 %.
  CHECK(airy_encircled_energy(0.0, 10.0) == doctest::Approx(0.0));
  CHECK(airy_encircled_energy(10.0 * 3.8317 / (1.22 * kPi), 10.0) ==
        doctest::Approx(0.8378).epsilon(1e-3));
}

}  // namespace test_plot_reports
