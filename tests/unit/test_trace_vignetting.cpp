// OpticStudio's vignetting factors VDX and VAN (issue 14): the decentre across the field and the
// angle that turns the compressed pupil ellipse. A field with either set breaks the mirror
// symmetry about the meridional plane, so the system traces the full pupil; these tests check
// the pupil points by hand, the full-pupil spot, centroid and PSF, the .zmx frame turns, and that
// the derivatives (adjoint, Jets, design loss) stay exact.
#include <doctest/doctest.h>

#include <cmath>
#include <string>

#include "lensopt/analysis/field_maps.h"
#include "lensopt/analysis/spot.h"
#include "lensopt/analysis/spot_adjoint.h"
#include "lensopt/analysis/wavefront.h"
#include "lensopt/core/error.h"
#include "lensopt/formats/lens_file.h"
#include "lensopt/formats/zmx.h"
#include "lensopt/glass/glass.h"
#include "lensopt/lens/lens_io.h"
#include "lensopt/optimize/design_gradient.h"
#include "lensopt/optimize/design_sampling.h"
#include "lensopt/optimize/optimizer.h"
#include "lensopt/render/psf.h"
#include "test_support.h"
#include "trace_checks.h"

namespace test_trace_vignetting {

using namespace lensopt;

namespace {

constexpr double kPiValue = 3.14159265358979323846;

// A 50 mm doublet (.zmx text, model glasses, F d C) with the given field and vignetting lines.
std::string doublet_zmx(const std::string& field_lines) {
  return "VERS 190513 80 123457 L123457\nMODE SEQ\nNAME vignetted doublet\n"
         "UNIT MM X W X CM MR CPMM\nENPD 10\n" +
         field_lines +
         "WAVM 1 0.4861327 1\nWAVM 2 0.5875618 1\nWAVM 3 0.6562725 1\nPWAV 2\n"
         "SURF 0\n  TYPE STANDARD\n  CURV 0\n  DISZ INFINITY\n"
         "SURF 1\n  TYPE STANDARD\n  CURV 0\n  DISZ 2\n  STOP\n"
         "SURF 2\n  TYPE STANDARD\n  CURV 0.03\n  DISZ 5\n  GLAS ___BLANK 1 0 1.6 60 0 0 0 0 0 0\n"
         "SURF 3\n  TYPE STANDARD\n  CURV -0.035\n  DISZ 2\n  GLAS ___BLANK 1 0 1.7 30 0 0 0 0 0 "
         "0\n"
         "SURF 4\n  TYPE STANDARD\n  CURV -0.004\n  DISZ 45\n"
         "SURF 5\n  TYPE STANDARD\n  CURV 0\n  DISZ 0\n";
}

using test::quick;

// OpticStudio's definition written out: compress, turn by VAN (counterclockwise), decentre.
void by_hand(double vdx, double vdy, double vcx, double vcy, double van_deg, double px, double py,
             double& qx, double& qy) {
  const double a = van_deg * kPiValue / 180.0;
  const double u = (1 - vcx) * px, t = (1 - vcy) * py;
  qx = vdx + std::cos(a) * u - std::sin(a) * t;
  qy = vdy + std::sin(a) * u + std::cos(a) * t;
}

using test::worst_relative;  // the 1e-9 check of test_spot_adjoint.cpp

using test::mean_spot;

// The AC254-100 achromat (.zmx) with three fields, the outer two vignetted with VDX and VAN.
Lens vignetted_achromat() {
  Lens lens = read_zmx(test::source_dir() / "lenses" / "zmx" / "achromat_ac254_100.zmx").lens;
  const double largest = lens.specs.fields.back().value;
  lens.specs.fields.clear();
  lens.specs.fields.push_back({0.0, 1.0, {}});
  lens.specs.fields.push_back({0.6 * largest, 1.0, {0.08, 0.03, 0.1, 0.25, 20.0}});
  lens.specs.fields.push_back({largest, 2.0, {-0.05, 0.06, 0.3, 0.1, -35.0}});
  return lens;
}

}  // namespace

TEST_CASE("vignetting: VDX decentres the pupil across the field by VDX pupil radii") {
  // Ray aiming off: the aimed map is the identity, so a ray of normalized pupil point (px, py)
  // starts at R (px', py'), R = EPD / 2 = 5 mm. With VDX = 0.2 alone the bundle is the unvignetted
  // one shifted by 0.2 R = 1 mm in x: its chief ray (0, 0) starts at (1 mm, 0) and the bundle's
  // mean x on the entrance pupil is 1 mm (the full pupil is mirror-symmetric in px).
  const ZmxImport imp =
      parse_zmx(doublet_zmx("FTYP 0 0 2 3 0 0 0\nXFLN 0 0\nYFLN 0 5\nVDXN 0 0.2\n"), "vdx.zmx");
  TraceOptions t = quick();
  t.ray_aiming = false;
  const TraceSystem<double> sys = prepare_lens_system(imp.lens, t);
  REQUIRE(sys.full_pupil);
  const PupilSamples half = paper_pupil_samples(t.rings);
  REQUIRE(sys.pupil.size() == 2 * half.size());
  RayBundle<double> rays;
  start_rays(sys, 1, 0, rays);
  double mean_x = 0.0;
  for (std::size_t i = 0; i < rays.size(); ++i) {
    const double px = i < half.size() ? half.x[i] : -half.x[i - half.size()];
    const double py = half.y[i % half.size()];
    CHECK(rays.x[i] == doctest::Approx(5.0 * (0.2 + px)).epsilon(1e-14));
    CHECK(rays.y[i] == doctest::Approx(5.0 * py).epsilon(1e-14));
    mean_x += rays.x[i] / static_cast<double>(rays.size());
  }
  CHECK(mean_x == doctest::Approx(1.0).epsilon(1e-13));
  PupilSamples chief;
  chief.x = {0.0};
  chief.y = {0.0};
  start_rays(sys, 1, 0, rays, &chief);
  CHECK(rays.x[0] == doctest::Approx(1.0).epsilon(1e-15));
  CHECK(rays.y[0] == 0.0);
  // The on-axis field (no factors) keeps the unshifted pupil, now traced in full.
  start_rays(sys, 0, 0, rays);
  for (std::size_t i = 0; i < rays.size(); ++i)
    CHECK(rays.x[i] == doctest::Approx(5.0 * sys.pupil.x[i]).epsilon(1e-14));
}

TEST_CASE("vignetting: VAN turns the compressed pupil; its second moments are the ellipse's") {
  // VCX = 0.5, VCY = 0.2, VAN = 30 deg, VDX = 0.1, VDY = -0.05, ray aiming off. By hand, the
  // uniform unit disc has E[px^2] = E[py^2] = 1/4, E[px py] = 0; after the compression C =
  // diag(u, t) (u = 0.5, t = 0.8) and the turn R(a) the covariance is R C (I / 4) C R^T:
  //   cxx = (c^2 u^2 + s^2 t^2) / 4,  cyy = (s^2 u^2 + c^2 t^2) / 4,  cxy = c s (u^2 - t^2) / 4,
  // centred on (VDX, VDY); the major axis (along the compressed y) points at VAN + 90 deg.
  const ZmxImport imp =
      parse_zmx(doublet_zmx("FTYP 0 0 2 3 0 0 0\nXFLN 0 0\nYFLN 0 5\nVDXN 0 0.1\nVDYN 0 -0.05\n"
                            "VCXN 0 0.5\nVCYN 0 0.2\nVANN 0 30\n"),
                "van.zmx");
  TraceOptions t = quick(32);
  t.ray_aiming = false;
  const TraceSystem<double> sys = prepare_lens_system(imp.lens, t);
  RayBundle<double> rays;
  start_rays(sys, 1, 1, rays);
  const double n = static_cast<double>(rays.size());
  double mx = 0, my = 0;
  for (std::size_t i = 0; i < rays.size(); ++i) {
    mx += rays.x[i] / 5.0 / n;
    my += rays.y[i] / 5.0 / n;
  }
  double sxx = 0, syy = 0, sxy = 0;
  for (std::size_t i = 0; i < rays.size(); ++i) {
    const double dx = rays.x[i] / 5.0 - mx, dy = rays.y[i] / 5.0 - my;
    sxx += dx * dx / n;
    syy += dy * dy / n;
    sxy += dx * dy / n;
  }
  // The samples' own moments mapped exactly: the same transform of the sample pattern's
  // covariance (the pattern is nearly, not exactly, uniform).
  double pxx = 0, pyy = 0, pxy = 0, pmy = 0;
  for (std::size_t i = 0; i < sys.pupil.size(); ++i) pmy += sys.pupil.y[i] / n;
  for (std::size_t i = 0; i < sys.pupil.size(); ++i) {
    const double dy = sys.pupil.y[i] - pmy;
    pxx += sys.pupil.x[i] * sys.pupil.x[i] / n;
    pyy += dy * dy / n;
    pxy += sys.pupil.x[i] * dy / n;
  }
  const double a = 30.0 * kPiValue / 180.0, c = std::cos(a), s = std::sin(a);
  const double u = 0.5, tt = 0.8;
  // A = R C = [[c u, -s t], [s u, c t]]; A P A^T with P the pattern's covariance.
  const double a11 = c * u, a12 = -s * tt, a21 = s * u, a22 = c * tt;
  const double exx = a11 * a11 * pxx + 2 * a11 * a12 * pxy + a12 * a12 * pyy;
  const double eyy = a21 * a21 * pxx + 2 * a21 * a22 * pxy + a22 * a22 * pyy;
  const double exy = a11 * a21 * pxx + (a11 * a22 + a12 * a21) * pxy + a12 * a22 * pyy;
  CHECK(sxx == doctest::Approx(exx).epsilon(1e-12));
  CHECK(syy == doctest::Approx(eyy).epsilon(1e-12));
  CHECK(sxy == doctest::Approx(exy).epsilon(1e-12));
  // Against the ideal ellipse (a uniform disc): the pattern's sampling error only (its own
  // second moments are 0.9-1.0 % above the disc's at 32 rings).
  const double ixx = (c * c * u * u + s * s * tt * tt) / 4;
  const double iyy = (s * s * u * u + c * c * tt * tt) / 4;
  const double ixy = c * s * (u * u - tt * tt) / 4;
  MESSAGE("second moments: sampled ", sxx, " ", syy, " ", sxy, "; ellipse ", ixx, " ", iyy, " ",
          ixy);
  CHECK(sxx == doctest::Approx(ixx).epsilon(0.01));
  CHECK(syy == doctest::Approx(iyy).epsilon(0.01));
  CHECK(sxy == doctest::Approx(ixy).epsilon(0.01));
  CHECK(mx == doctest::Approx(0.1 + (a11 * 0 + a12 * pmy)).epsilon(1e-12));
  CHECK(std::abs(mx - 0.1) < 2e-3);
  CHECK(std::abs(my + 0.05) < 2e-3);
  // The major axis: at VAN + 90 deg (mod 180), i.e. -60 deg.
  const double major_deg = 0.5 * std::atan2(2 * sxy, sxx - syy) * 180.0 / kPiValue;
  CHECK(major_deg == doctest::Approx(-60.0).epsilon(0.01));
  // The projected pupil area (relative illumination) does not depend on VAN on axis (the map to
  // direction cosines is rotationally symmetric there): the same field turned by 0 and 30 deg.
  Lens turned = imp.lens, straight = imp.lens;
  turned.specs.fields[0].vignetting = {0.0, 0.0, 0.5, 0.2, 30.0};
  straight.specs.fields[0].vignetting = {0.0, 0.0, 0.5, 0.2, 0.0};
  double area_turned = 0, area_straight = 0;
  REQUIRE(projected_pupil_area(prepare_lens_system(turned, t), 0, area_turned));
  REQUIRE(projected_pupil_area(prepare_lens_system(straight, t), 0, area_straight));
  CHECK(area_turned == doctest::Approx(area_straight).epsilon(1e-12));
}

TEST_CASE("vignetting: a .zmx with VDX and VAN imports and its rays follow the definition") {
  // Fields on +y, -y, +x and off the axes, aiming on. lensopt turns each into the +y frame
  // (lens.h): -y mirrors (VDY, VAN change sign), +x turns a quarter turn (VDY' = VDX, VDX' =
  // -VDY, VCX and VCY swap, VAN stays), a field at azimuth phi turns by b = 90 deg - phi (D' =
  // R(b) D, VAN' = VAN + b). The reader no longer warns: the factors are traced.
  const ZmxImport imp = parse_zmx(
      doublet_zmx("FTYP 0 0 5 3 0 0 0\nXFLN 0 0 0 3 2\nYFLN 0 3 -3 0 2\n"
                  "VDXN 0 0.04 0.05 0.06 0.07\nVDYN 0 0.01 0.02 0.03 0\n"
                  "VCXN 0 0.1 0.2 0.3 0.1\nVCYN 0 0.15 0.25 0.35 0.3\nVANN 0 10 -20 30 5\n"),
      "turns.zmx");
  for (const std::string& w : imp.warnings) {
    CHECK(w.find("VDXN") == std::string::npos);
    CHECK(w.find("VANN") == std::string::npos);
    CHECK(w.find("off the x and y axes") == std::string::npos);
  }
  const std::vector<FieldPoint>& f = imp.lens.specs.fields;
  REQUIRE(f.size() == 5);
  CHECK(f[1].vignetting.vdx == 0.04);
  CHECK(f[1].vignetting.van_deg == 10.0);
  CHECK(f[2].vignetting.vdx == 0.05);  // -y
  CHECK(f[2].vignetting.vdy == -0.02);
  CHECK(f[2].vignetting.van_deg == 20.0);
  CHECK(f[3].vignetting.vdx == -0.03);  // +x
  CHECK(f[3].vignetting.vdy == 0.06);
  CHECK(f[3].vignetting.vcx == 0.35);
  CHECK(f[3].vignetting.vcy == 0.3);
  CHECK(f[3].vignetting.van_deg == 30.0);
  // (2, 2): azimuth 45 deg, b = 45 deg: D' = R(45) (0.07, 0), VAN' = 50.
  // The field keeps its x and y (issue 32: fields off the y axis); its radius is sqrt(8).
  CHECK(f[4].x == 2.0);
  CHECK(f[4].value == 2.0);
  CHECK(f[4].radius() == doctest::Approx(std::sqrt(8.0)).epsilon(1e-15));
  CHECK(f[4].vignetting.vdx == doctest::Approx(0.07 * std::sqrt(0.5)).epsilon(1e-14));
  CHECK(f[4].vignetting.vdy == doctest::Approx(0.07 * std::sqrt(0.5)).epsilon(1e-14));
  CHECK(f[4].vignetting.vcx == 0.1);
  CHECK(f[4].vignetting.vcy == 0.3);
  CHECK(f[4].vignetting.van_deg == doctest::Approx(50.0).epsilon(1e-14));
  // Frame turns keep the pupil: the (2, 2) field's pupil ellipse turned back by -45 deg is
  // OpticStudio's. Its +x edge point (1, 0) is at D + R(5) C (1, 0) in OpticStudio's frame.
  {
    double qx = 0, qy = 0, ox = 0, oy = 0;
    f[4].vignetting.pupil_point(1.0, 0.0, qx, qy);
    by_hand(0.07, 0.0, 0.1, 0.3, 5.0, 1.0, 0.0, ox, oy);
    const double b = -45.0 * kPiValue / 180.0;
    CHECK(std::cos(b) * qx - std::sin(b) * qy == doctest::Approx(ox).epsilon(1e-14));
    CHECK(std::sin(b) * qx + std::cos(b) * qy == doctest::Approx(oy).epsilon(1e-14));
  }
  // The rays: start points x = R scale_x px', y = R (offset_y + scale_y py') with (px', py') by
  // hand, aimed map of the field; then at the image they are the rays started there.
  const TraceSystem<double> sys = prepare_lens_system(imp.lens, quick());
  REQUIRE(sys.full_pupil);
  PupilSamples probe;
  probe.x = {0.0, 1.0, -1.0, 0.0, 0.0, 0.6};
  probe.y = {0.0, 0.0, 0.0, 1.0, -1.0, -0.7};
  const double r_ep = sys.epd_mm / 2;
  // The system's fields are sorted by value (stable): 2 sqrt(2) (f[4]), then 3 (f[1], f[2], f[3]).
  REQUIRE(sys.fields_deg.size() == 5);
  const int order[5] = {0, 4, 1, 2, 3};
  for (int h = 1; h < 5; ++h) {
    CAPTURE(h);
    const VignettingFactors& v = sys.vignetting[h];
    CHECK(v.vdx == f[order[h]].vignetting.vdx);
    CHECK(v.van_deg == f[order[h]].vignetting.van_deg);
    const int w = 1;
    const PupilMap<double>& map = sys.pupil_map(h, w);
    RayBundle<double> rays;
    start_rays(sys, h, w, rays, &probe);
    for (std::size_t i = 0; i < probe.size(); ++i) {
      double qx = 0, qy = 0;
      by_hand(v.vdx, v.vdy, v.vcx, v.vcy, v.van_deg, probe.x[i], probe.y[i], qx, qy);
      CHECK(rays.x[i] == doctest::Approx(r_ep * map.scale_x * qx).epsilon(1e-14));
      CHECK(rays.y[i] == doctest::Approx(r_ep * (map.offset_y + map.scale_y * qy)).epsilon(1e-14));
    }
  }
  // Written back (TOML and .zmx) in the +y frame: the same factors.
  for (const Lens& back : {parse_zmx(format_zmx(imp.lens), "back.zmx").lens,
                           parse_lens_toml(format_lens_toml(imp.lens), "back.toml")}) {
    REQUIRE(back.specs.fields.size() == 5);
    for (std::size_t i = 0; i < 5; ++i) {
      CHECK(back.specs.fields[i].vignetting.vdx == f[i].vignetting.vdx);
      CHECK(back.specs.fields[i].vignetting.van_deg == f[i].vignetting.van_deg);
    }
  }
}

TEST_CASE(
    "vignetting: the full-pupil spot has its own x centroid; symmetric fields are unchanged") {
  const Lens lens = vignetted_achromat();
  TraceOptions t = quick(12);
  const TraceSystem<double> sys = prepare_lens_system(lens, t);
  REQUIRE(sys.full_pupil);
  const SpotResult<double> spots = evaluate_spots(sys, 1);
  // By hand from the traced rays: S_h^2 = E[(y - ybar)^2] + E[(x - xbar)^2] (equal weights).
  RayBundle<double> rays;
  for (int h = 0; h < 3; ++h) {
    CAPTURE(h);
    std::vector<double> xs, ys;
    for (int w = 0; w < sys.wavelength_count; ++w) {
      start_rays(sys, h, w, rays);
      trace_bundle(sys.lens, w, sys.lens.surface_count(), true, rays,
                   static_cast<RayRecord<double>*>(nullptr));
      for (std::size_t i = 0; i < rays.size(); ++i)
        if (rays.status[i] == kRayOk) {
          xs.push_back(rays.x[i]);
          ys.push_back(rays.y[i]);
        }
    }
    double mx = 0, my = 0;
    for (std::size_t i = 0; i < xs.size(); ++i) {
      mx += xs[i] / xs.size();
      my += ys[i] / ys.size();
    }
    double s2 = 0;
    for (std::size_t i = 0; i < xs.size(); ++i)
      s2 += ((xs[i] - mx) * (xs[i] - mx) + (ys[i] - my) * (ys[i] - my)) / xs.size();
    CHECK(spots.centroid_x_mm[h] == doctest::Approx(mx).epsilon(1e-9).scale(1e-6));
    CHECK(spots.rms_spot_mm[h] == doctest::Approx(std::sqrt(s2)).epsilon(1e-10));
    MESSAGE("field ", h, ": x centroid ", mx * 1000, " um");
    if (h > 0) CHECK(std::abs(mx) > 1e-7);  // VDX and VAN move the spot across the field
  }
  // The on-axis field (no factors) on the full pupil equals the mirrored half pupil of the lens
  // without the two vignetted fields, to rounding; and that lens traces the half pupil.
  Lens symmetric = lens;
  symmetric.specs.fields.resize(1);
  const TraceSystem<double> half = prepare_lens_system(symmetric, t);
  CHECK(!half.full_pupil);
  CHECK(half.pupil.size() * 2 == sys.pupil.size());
  const SpotResult<double> half_spots = evaluate_spots(half, 1);
  CHECK(half_spots.rms_spot_mm[0] == doctest::Approx(spots.rms_spot_mm[0]).epsilon(1e-12));
  CHECK(half_spots.centroid_x_mm[0] == 0.0);
  // The through-focus moments (tolerancing) at tau = 0 are the same spot, and their variance
  // polynomial is the spot of the rays moved along their slopes.
  const double tau = 0.05;
  for (int h = 1; h < 3; ++h) {
    ThroughFocusSpot moments;
    moments.spot.full_pupil = true;
    std::vector<double> xs, ys;
    for (int w = 0; w < sys.wavelength_count; ++w) {
      start_rays(sys, h, w, rays);
      trace_bundle(sys.lens, w, sys.lens.surface_count(), true, rays,
                   static_cast<RayRecord<double>*>(nullptr));
      moments.add(rays);
      for (std::size_t i = 0; i < rays.size(); ++i)
        if (rays.status[i] == kRayOk) {
          xs.push_back(rays.x[i] + tau * rays.l[i] / rays.n[i]);
          ys.push_back(rays.y[i] + tau * rays.m[i] / rays.n[i]);
        }
    }
    CHECK(moments.rms(0.0) == spots.rms_spot_mm[h] * 1.0);
    double mx = 0, my = 0, s2 = 0;
    for (std::size_t i = 0; i < xs.size(); ++i) {
      mx += xs[i] / xs.size();
      my += ys[i] / ys.size();
    }
    for (std::size_t i = 0; i < xs.size(); ++i)
      s2 += ((xs[i] - mx) * (xs[i] - mx) + (ys[i] - my) * (ys[i] - my)) / xs.size();
    CHECK(moments.rms(tau) == doctest::Approx(std::sqrt(s2)).epsilon(1e-9));
  }
  // PSFs: every traced ray once (no mirror), all energy inside a wide grid; the on-axis PSF
  // equals the half-pupil system's.
  PsfOptions wide;
  wide.grid_size = 129;
  RayBundle<double> scratch;
  const FieldPsf<double> psf = field_psf(sys, 2, {0}, wide, scratch);
  CHECK(psf.traced_rays[0] == static_cast<int>(sys.pupil.size()));
  CHECK(psf.energy_share[0] == doctest::Approx(1.0).epsilon(1e-3));
  const FieldPsf<double> full0 = field_psf(sys, 0, {0}, wide, scratch);
  const FieldPsf<double> half0 = field_psf(half, 0, {0}, wide, scratch);
  CHECK(full0.energy_share[0] == doctest::Approx(half0.energy_share[0]).epsilon(1e-12));
  double worst = 0;
  for (std::size_t i = 0; i < full0.psf[0].size(); ++i)
    worst = std::max(worst, std::abs(full0.psf[0][i] - half0.psf[0][i]));
  CHECK(worst < 1e-12);
  // The wavefront: a half grid on a full-pupil system is refused.
  const ReferenceSphere<double> sphere = reference_sphere(sys, 1);
  RayRecord<double> record;
  CHECK_THROWS_AS(compute_wavefront(sys, 1, 0, make_half_pupil_grid(16), sphere, 0.0, rays, record),
                  Error);
  const Wavefront<double> wf =
      compute_wavefront(sys, 1, 0, make_pupil_grid(16), sphere, 0.0, rays, record);
  CHECK(std::isfinite(wf.rms_waves));
}

TEST_CASE("vignetting: gradients with VDX and VAN stay exact (adjoint, Jets, finite differences)") {
  const Lens lens = vignetted_achromat();
  const std::vector<PrescriptionVariable> variables = all_prescription_variables(lens);
  const TraceLens<double> trace_lens = make_trace_lens(lens);
  for (bool aiming : {true, false}) {
    CAPTURE(aiming);
    TraceOptions options = quick(10);
    options.ray_aiming = aiming;
    const SpotGradient jets = mean_spot_gradient_auto(trace_lens, lens.specs, variables, options);
    const SpotGradient adjoint =
        mean_spot_gradient_adjoint<8>(trace_lens, lens.specs, variables, options);
    CHECK(adjoint.mean_rms_spot_mm == doctest::Approx(mean_spot(lens, options)).epsilon(1e-12));
    CHECK(worst_relative(adjoint.gradient, jets.gradient) < 1e-9);
    // Central differences (Richardson-extrapolated) of every variable.
    const std::vector<double> fd =
        test::mean_spot_central_differences(lens, variables, options, 0.01);
    const double worst = worst_relative(adjoint.gradient, fd);
    INFO("worst relative error against finite differences ", worst);
    CHECK(worst < 1e-5);
  }
  // The design loss l_lens (LM's merit, the optimizer's adjoint gradient) against its Jets.
  const LensParameterization param(lens, GlassSpace(*load_catalog("ohara")));
  TraceOptions sampling;
  sampling.rings = 6;
  sampling.fields = 3;
  const std::vector<double> x = param.from_lens(lens);
  DesignLossOptions loss;
  loss.max_ray_angle_deg = 20.0;  // an active angle hinge
  const DesignValueGradient a =
      design_loss_gradient(param, x, GlassMode::kQuantized, {}, sampling, loss);
  const DesignValueGradient j =
      design_loss_gradient_jets(param, x, GlassMode::kQuantized, {}, sampling, loss);
  CHECK(a.loss.total == doctest::Approx(j.loss.total).epsilon(1e-12));
  CHECK(a.loss.spot_mm == doctest::Approx(j.loss.spot_mm).epsilon(1e-12));
  CHECK(worst_relative(a.gradient, j.gradient) < 1e-9);
  // The least-squares residuals: one block of 2 x (full pupil rays) per spot field and
  // wavelength, whose sum of squares is sum_h a_h S_h^2 (a_h = phi_h / sum phi, no failed rays;
  // design_loss.h), S_h about both centroids.
  TraceOptions unscaled = sampling;
  unscaled.scale_to_spec = false;
  const DesignSampling sampled = design_sampling(param.structure(), unscaled);
  REQUIRE(needs_full_pupil(sampled.setup.vignetting));
  const int wl = static_cast<int>(lens.specs.wavelengths_nm.size());
  const int rays = 2 * static_cast<int>(paper_pupil_samples(sampling.rings).size());
  int glasses = 0;
  for (const LensVariable& v : param.variables()) glasses += v.kind == LensVariable::Kind::kGlass0;
  const int count = design_residual_count(
      loss, sampled.spot_fields, static_cast<int>(sampled.setup.field_values.size()), wl, rays,
      static_cast<int>(lens.surfaces.size()), glasses, true);
  std::vector<double> residuals(count, 0.0);
  DesignLoss<double> l;
  REQUIRE(evaluate_design<double>(param, x.data(), GlassMode::kQuantized, {}, sampling, loss,
                                  nullptr, residuals.data(), &l));
  CHECK(l.spot_mm == doctest::Approx(j.loss.spot_mm).epsilon(1e-12));
  REQUIRE(l.failed_rays == 0);
  double sum_squares = 0.0, expected = 0.0, phi_sum = 0.0;
  const int spot_residuals = sampled.spot_fields * wl * rays * 2;
  for (int i = 0; i < spot_residuals; ++i) sum_squares += residuals[i] * residuals[i];
  for (double p : l.field_weights) phi_sum += p;
  for (int h = 0; h < sampled.spot_fields; ++h)
    expected += l.field_weights[h] / phi_sum * l.field_rms_mm[h] * l.field_rms_mm[h];
  CHECK(sum_squares == doctest::Approx(expected).epsilon(1e-12));
}

}  // namespace test_trace_vignetting
