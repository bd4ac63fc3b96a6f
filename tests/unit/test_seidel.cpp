// First-order data and Seidel sums (analysis/seidel.h) against independent references: real rays
// traced at small aperture and field (third-order transverse aberrations are the limit of the
// real ones), a thin singlet's closed forms, the exit pupil of the wavefront code, and exact
// paraxial colour.
#include <doctest/doctest.h>

#include <cmath>
#include <string>
#include <vector>

#include "lensopt/analysis/seidel.h"
#include "lensopt/analysis/wavefront.h"
#include "lensopt/formats/lens_file.h"
#include "lensopt/trace/system.h"
#include "test_support.h"

namespace test_seidel {

using namespace lensopt;

namespace {

// Real transverse aberration (x, y) on the paraxial image plane of the ray at normalized pupil
// point (px, py) of the field fraction eta of the system's largest field, relative to eta times
// the paraxial image height.
struct RealRays {
  const TraceSystem<double>& sys;
  const SeidelReport& report;
  TraceLens<double> lens;  // semi-diameters cleared, image plane at the paraxial image
  int h_max = 0;
  RealRays(const TraceSystem<double>& s, const SeidelReport& r) : sys(s), report(r), lens(s.lens) {
    lens.semi_diameter_mm.clear();
    lens.thickness_mm.back() = r.first_order.image_distance_mm;
    for (int h = 0; h < static_cast<int>(sys.fields_deg.size()); ++h)
      if (std::abs(sys.fields_deg[h]) > std::abs(sys.fields_deg[h_max])) h_max = h;
  }
  void aberration(double px, double py, double eta, double& ex, double& ey) const {
    RayBundle<double> rays;
    rays.resize(1);
    const double r_ep = 0.5 * sys.epd_mm;
    const double tan_max = std::tan(sys.fields_deg[h_max] * kPi / 180.0);
    const double theta = std::atan(eta * tan_max);
    const double object_y = sys.object_at_infinity() ? 0.0 : eta * sys.field_object_y_mm[h_max];
    start_pupil_ray(rays, 0, px * r_ep, py * r_ep, sys.entrance_pupil_z_mm, sys.object_distance_mm,
                    std::sin(theta), std::cos(theta), object_y);
    const int w = sys.wavelength_count;  // the primary
    trace_bundle(lens, w, lens.surface_count(), true, rays,
                 static_cast<RayRecord<double>*>(nullptr));
    REQUIRE(rays.status[0] == kRayOk);
    ex = rays.x[0];
    ey = rays.y[0] - eta * report.first_order.paraxial_image_height_mm;
  }
};

// The third-order coefficient a of f(s) = a s^3 + b s^5 + ..., from s and 2 s.
double cubic_limit(double f1, double f2, double s) {
  const double e1 = f1 / (s * s * s), e2 = f2 / (8 * s * s * s);
  return (4.0 * e1 - e2) / 3.0;
}

void check_against_real_rays(const TraceSystem<double>& sys) {
  const SeidelReport r = seidel_report(sys);
  const RealRays rays(sys, r);
  const double w = r.marginal_final_w;
  const double s = 0.02;
  double x1, y1, x2, y2, xa, ya, xb, yb, x0, y0;
  // Spherical: the axial field, meridional rays.
  rays.aberration(0, s, 0, x1, y1);
  rays.aberration(0, 2 * s, 0, x2, y2);
  const double spherical = cubic_limit(y1, y2, s);
  // Distortion: the chief ray of a small field.
  rays.aberration(0, 0, s, x1, y1);
  rays.aberration(0, 0, 2 * s, x2, y2);
  const double distortion = cubic_limit(y1, y2, s);
  // Tangential coma and (3 S_III + S_IV): rays at +-rho of a field eta, rho = eta = s.
  auto tangential = [&](double t, double& even, double& odd) {
    rays.aberration(0, t, t, xa, ya);
    rays.aberration(0, -t, t, xb, yb);
    rays.aberration(0, 0, t, x0, y0);
    even = 0.5 * (ya + yb) - y0;
    odd = 0.5 * (ya - yb);
  };
  double even1, odd1, even2, odd2;
  tangential(s, even1, odd1);
  tangential(2 * s, even2, odd2);
  const double coma = cubic_limit(even1, even2, s);
  const double tangential_field = cubic_limit(odd1, odd2, s);
  // Sagittal: x of the ray at (rho, 0) of field eta.
  rays.aberration(s, 0, s, x1, y1);
  rays.aberration(2 * s, 0, 2 * s, x2, y2);
  const double sagittal_field = cubic_limit(x1, x2, s);
  const SurfaceSeidel& S = r.sums;
  const double scale =
      std::abs(S.s1) + std::abs(S.s2) + std::abs(S.s3) + std::abs(S.s4) + std::abs(S.s5);
  // Each measured coefficient against its third-order prediction, to 1e-3 of the largest sum
  // (the limit removes the fifth order; the seventh remains at (2 s)^4 ~ 3e-6 of it).
  const double tol = 1e-3 * scale / std::abs(2 * w);
  MESSAGE("sums S_I..S_V: " << S.s1 << ", " << S.s2 << ", " << S.s3 << ", " << S.s4 << ", "
                            << S.s5);
  CHECK(std::abs(spherical - S.s1 / (2 * w)) < tol);
  CHECK(std::abs(distortion - S.s5 / (2 * w)) < tol);
  CHECK(std::abs(coma - 3 * S.s2 / (2 * w)) < tol);
  CHECK(std::abs(tangential_field - (S.s1 + 3 * S.s3 + S.s4) / (2 * w)) < tol);
  CHECK(std::abs(sagittal_field - (S.s1 + S.s3 + S.s4) / (2 * w)) < tol);
  // The exit pupil two ways: the chief ray's axis crossing here, the stop imaged by the surfaces
  // after it in the wavefront code.
  const double z_xp = exit_pupil_from_image_mm(sys.lens, sys.lens.reference_nm());
  CHECK(std::abs(r.first_order.exit_pupil_z_mm - z_xp) < 1e-9 * std::max(1.0, std::abs(z_xp)));
  CHECK(r.first_order.efl_mm == doctest::Approx(sys.efl_mm).epsilon(1e-12));
}

}  // namespace

TEST_CASE("seidel: the sums are the small-aperture, small-field limits of real-ray aberrations") {
  const auto src = lensopt::test::source_dir();
  for (const std::string name : {"zmx/cooke_triplet_50.zmx", "zmx/double_gauss_100.zmx",
                                 "tessar.toml", "doublet-asphere.toml"}) {
    CAPTURE(name);
    const Lens lens = read_lens(src / "lenses" / name);
    TraceOptions t;
    t.rings = 2;
    t.ray_aiming = false;
    check_against_real_rays(prepare_lens_system(lens, t));
  }
  // A finite object (a 100 mm achromat at 300 mm).
  Lens achromat = read_lens(src / "lenses" / "zmx" / "achromat_ac254_100.zmx");
  achromat.specs.object_distance_mm = 300.0;
  achromat.specs.fields = {{0.0, 1.0, {}}, {3.0, 1.0, {}}};
  TraceOptions t;
  t.rings = 2;
  t.ray_aiming = false;
  const TraceSystem<double> sys = prepare_lens_system(achromat, t);
  check_against_real_rays(sys);
  const SeidelReport r = seidel_report(sys);
  CHECK(r.first_order.magnification < 0.0);  // a real, inverted image
}

TEST_CASE("seidel: a lens whose fields are all on axis still has an exit pupil") {
  // The chief ray of a 0 deg field has zero height and slope; the pupil's place does not depend
  // on the field, so it must be the one of the same lens with an off-axis field (it was 0/0).
  const auto src = lensopt::test::source_dir();
  Lens lens = read_lens(src / "lenses" / "zmx" / "cooke_triplet_50.zmx");
  TraceOptions t;
  t.rings = 2;
  const SeidelReport with_field = seidel_report(prepare_lens_system(lens, t));
  lens.specs.fields = {{0.0, 1.0, {}}};
  const SeidelReport on_axis = seidel_report(prepare_lens_system(lens, t));
  REQUIRE(std::isfinite(on_axis.first_order.exit_pupil_z_mm));
  REQUIRE(std::isfinite(on_axis.first_order.exit_pupil_diameter_mm));
  CHECK(on_axis.first_order.exit_pupil_z_mm ==
        doctest::Approx(with_field.first_order.exit_pupil_z_mm).epsilon(1e-12));
  CHECK(on_axis.first_order.exit_pupil_diameter_mm ==
        doctest::Approx(with_field.first_order.exit_pupil_diameter_mm).epsilon(1e-12));
}

TEST_CASE("seidel: a thin singlet at its stop against the closed forms") {
  // Welford's thin lens at the stop, object at infinity (shape B = (c1 + c2) / (c1 - c2),
  // conjugate C = -1 in these signs):
  //   S_I = (y^4 phi^3 / 4) [(n / (n - 1))^2 + (n + 2) / (n (n - 1)^2) (B + 2 (n^2 - 1) C /
  //         (n + 2))^2 - n C^2 / (n + 2)],  S_III = H^2 phi,  S_IV = H^2 phi / n,  S_V = 0.
  for (double bend : {-1.0, 0.0, 0.714, 1.0, 2.0}) {
    CAPTURE(bend);
    Lens lens;
    lens.name = "thin singlet";
    lens.specs.mode = SpecMode::kAsWritten;
    lens.specs.aperture_type = ApertureType::kEntrancePupilDiameter;
    lens.specs.aperture_value = 10.0;
    lens.specs.wavelengths_nm = {587.5618};
    lens.specs.wavelength_channels = {1};
    lens.specs.primary_wavelength_nm = 587.5618;
    lens.specs.fields = {{0.0, 1.0, {}}, {5.0, 1.0, {}}};
    const double n_glass = 1.5168, f = 100.0;
    // c1 - c2 = 1 / ((n - 1) f), c1 + c2 = B (c1 - c2).
    const double dc = 1.0 / ((n_glass - 1.0) * f);
    const double c1 = 0.5 * (bend + 1.0) * dc, c2 = 0.5 * (bend - 1.0) * dc;
    Surface stop;
    stop.is_stop = true;
    Surface front;
    front.curvature_per_mm = c1;
    front.thickness_mm = 1e-6;
    front.material = Material::model(n_glass, 64.17);
    Surface back;
    back.curvature_per_mm = c2;
    back.thickness_mm = 0.005;  // the sums do not depend on where the image plane is
    lens.surfaces = {stop, front, back};
    TraceOptions t;
    t.rings = 2;
    t.ray_aiming = false;
    const TraceSystem<double> sys = prepare_lens_system(lens, t);
    const SeidelReport r = seidel_report(sys);
    const double n = sys.lens.index_at_nm(1, sys.lens.reference_nm());
    const double phi = (n - 1.0) * (c1 - c2);
    const double y = 5.0, cc = -1.0;
    const double h = y * std::tan(5.0 * kPi / 180.0);
    const double k = 2.0 * (n * n - 1.0) * cc / (n + 2.0);
    const double s1 =
        y * y * y * y * phi * phi * phi / 4.0 *
        ((n / (n - 1)) * (n / (n - 1)) +
         (n + 2) / (n * (n - 1) * (n - 1)) * (bend + k) * (bend + k) - n * cc * cc / (n + 2));
    // The 1e-6 mm glass makes the lens thin to ~1e-8 of f.
    CHECK(r.sums.s1 == doctest::Approx(s1).epsilon(1e-6));
    CHECK(r.sums.s3 == doctest::Approx(h * h * phi).epsilon(1e-6));
    CHECK(r.sums.s4 == doctest::Approx(h * h * phi / n).epsilon(1e-6));
    // S_V of a thin lens at its stop is 0; the 1e-6 mm glass leaves ~1e-8 of S_III.
    CHECK(std::abs(r.sums.s5) < 1e-6 * std::abs(h * h * phi));
    CHECK(r.first_order.efl_mm == doctest::Approx(1.0 / phi).epsilon(1e-8));
  }
}

namespace {

// A thin singlet (f = 100 mm, n = 1.5168 at the primary) with its stop `stop_mm` in front and a
// glass of Abbe number `vd`, traced at F, d, C.
Lens thin_singlet(double stop_mm, double vd) {
  Lens lens;
  lens.name = "thin singlet";
  lens.specs.mode = SpecMode::kAsWritten;
  lens.specs.aperture_type = ApertureType::kEntrancePupilDiameter;
  lens.specs.aperture_value = 10.0;
  lens.specs.wavelengths_nm = {486.1327, 587.5618, 656.2725};
  lens.specs.wavelength_channels = {2, 1, 0};
  lens.specs.primary_wavelength_nm = 587.5618;
  lens.specs.fields = {{0.0, 1.0, {}}, {5.0, 1.0, {}}};
  Surface stop;
  stop.is_stop = true;
  stop.thickness_mm = stop_mm;
  Surface front;
  front.curvature_per_mm = 0.01;
  front.thickness_mm = 1e-3;
  front.material = Material::model(1.5168, vd);
  Surface back;
  back.curvature_per_mm = -0.0093;
  back.thickness_mm = 5.0;
  lens.surfaces = {stop, front, back};
  return lens;
}

}  // namespace

TEST_CASE("seidel: primary colour is the first-order limit of exact paraxial colour") {
  // To first order in dn: axial colour -C_I / (n' u'^2) and lateral colour C_II / w_K. The
  // exact paraxial colour differs by terms of relative order dn / (n - 1) (the index is not
  // linear in the power, and the primary is not midway between the band's ends): the bound is
  // three times that, 4.8 % for an ordinary glass (V = 64) and 1.5 % for V = 200.
  for (double vd : {64.17, 200.0}) {
    for (double stop_mm : {0.0, 20.0}) {
      CAPTURE(vd);
      CAPTURE(stop_mm);
      TraceOptions t;
      t.rings = 2;
      t.ray_aiming = false;
      const TraceSystem<double> sys = prepare_lens_system(thin_singlet(stop_mm, vd), t);
      const SeidelReport r = seidel_report(sys);
      const TraceLens<double>& tl = sys.lens;
      const double dn = tl.index_at_nm(1, 486.1327) - tl.index_at_nm(1, 656.2725);
      const double tol = 3.0 * dn / (tl.index_at_nm(1, 587.5618) - 1.0);
      const double w = r.marginal_final_w;
      const double axial = -r.sums.c1 / (w * w);
      const double lateral = r.sums.c2 / w;
      MESSAGE("axial " << axial << " vs " << r.axial_colour_mm << "; lateral " << lateral << " vs "
                       << r.lateral_colour_mm << " (bound " << tol << ")");
      CHECK(r.axial_colour_mm < 0.0);  // blue focuses nearer the lens
      CHECK(std::abs(axial - r.axial_colour_mm) <= tol * std::abs(r.axial_colour_mm));
      if (stop_mm == 0.0) {
        // A thin lens at its stop has no lateral colour (the 1 um glass leaves ~1e-8 mm).
        CHECK(std::abs(r.lateral_colour_mm) < 1e-6 * std::abs(r.axial_colour_mm));
        CHECK(std::abs(lateral) < 1e-6 * std::abs(r.axial_colour_mm));
      } else {
        CHECK(std::abs(lateral) > 1e-4);
        CHECK(std::abs(lateral - r.lateral_colour_mm) <= tol * std::abs(r.lateral_colour_mm));
      }
    }
  }
}

}  // namespace test_seidel
