// Real .zmx files with mirrors and coordinate breaks (tests/data/zmx-real, sources in its
// README): they import, and the chief and marginal real-ray image intercepts agree with an
// independent 3D reference trace written here (global coordinates, conic surfaces intersected
// as quadrics, reflection d - 2 (d.n) n, no lensopt code) within 1e-9 of the focal length.
// Also: COORDBRK / GLAS MIRROR / CLAP / OBSC / OBDC read and written, bad input named.
#include <doctest/doctest.h>
#include <fmt/format.h>

#include <array>
#include <cmath>
#include <filesystem>
#include <string>
#include <vector>

#include "lensopt/analysis/spot.h"
#include "lensopt/core/error.h"
#include "lensopt/formats/zmx.h"
#include "lensopt/lens/lens.h"
#include "lensopt/lens/trace_lens.h"
#include "lensopt/paraxial/paraxial.h"
#include "lensopt/trace/kernel.h"
#include "lensopt/trace/system.h"
#include "test_support.h"

namespace test_zmx_geometry3d {

using namespace lensopt;

namespace {

std::filesystem::path real_dir() {
  return test::source_dir() / "tests" / "data" / "zmx-real";
}

// ---- The independent reference: plain 3D vectors in one global frame. ----
struct V3 {
  double x = 0, y = 0, z = 0;
};
V3 operator+(V3 a, V3 b) {
  return {a.x + b.x, a.y + b.y, a.z + b.z};
}
V3 operator-(V3 a, V3 b) {
  return {a.x - b.x, a.y - b.y, a.z - b.z};
}
V3 operator*(double s, V3 a) {
  return {s * a.x, s * a.y, s * a.z};
}
double dot(V3 a, V3 b) {
  return a.x * b.x + a.y * b.y + a.z * b.z;
}

// A mirror: vertex `o`, local axes ex, ey, ez (orthonormal, global), curvature c, conic k.
struct RefMirror {
  V3 o, ex{1, 0, 0}, ey{0, 1, 0}, ez{0, 0, 1};
  double c = 0, k = 0;
};

// Reflects the ray (p, d) off the mirror: the intersection with the quadric
// c (x^2 + y^2) + (1 + k) c z^2 - 2 z = 0 on the branch through the vertex (where
// 1 - (1 + k) c z > 0), then d - 2 (d.n) n with n the unit normal there.
void reflect(const RefMirror& m, V3& p, V3& d) {
  const V3 q = p - m.o;
  const V3 lp{dot(q, m.ex), dot(q, m.ey), dot(q, m.ez)};
  const V3 ld{dot(d, m.ex), dot(d, m.ey), dot(d, m.ez)};
  const double e = (1 + m.k) * m.c;
  const double a = m.c * (ld.x * ld.x + ld.y * ld.y) + e * ld.z * ld.z;
  const double b = 2 * (m.c * (lp.x * ld.x + lp.y * ld.y) + e * lp.z * ld.z - ld.z);
  const double cc = m.c * (lp.x * lp.x + lp.y * lp.y) + e * lp.z * lp.z - 2 * lp.z;
  std::vector<double> roots;
  if (std::abs(a) < 1e-300) {
    roots.push_back(-cc / b);
  } else {
    const double disc = b * b - 4 * a * cc;
    REQUIRE(disc >= 0);
    const double qq = -0.5 * (b + std::copysign(std::sqrt(disc), b));
    roots.push_back(qq / a);
    roots.push_back(cc / qq);
  }
  bool found = false;
  double s = 0;
  for (double r : roots) {
    const double z = lp.z + r * ld.z;
    if (1 - e * z > 0 && (!found || std::abs(r) < std::abs(s))) {
      s = r;
      found = true;
    }
  }
  REQUIRE(found);
  const V3 h{lp.x + s * ld.x, lp.y + s * ld.y, lp.z + s * ld.z};
  V3 n{-m.c * h.x, -m.c * h.y, 1 - e * h.z};
  n = (1 / std::sqrt(dot(n, n))) * n;
  const V3 r = ld - (2 * dot(ld, n)) * n;
  p = m.o + (h.x * m.ex + h.y * m.ey + h.z * m.ez);
  d = r.x * m.ex + r.y * m.ey + r.z * m.ez;
}

// The intercept (x, y) of (p, d) with the plane through o with axes ex, ey, normal ez.
std::array<double, 2> intercept(V3 o, V3 ex, V3 ey, V3 ez, V3 p, V3 d) {
  const double s = dot(o - p, ez) / dot(d, ez);
  const V3 h = p + s * d - o;
  return {dot(h, ex), dot(h, ey)};
}

// lensopt's image intercepts of rays starting at z = 0 before surface 1.
std::vector<std::array<double, 2>> lensopt_intercepts(const TraceLens<double>& tl,
                                                      const std::vector<std::array<V3, 2>>& in) {
  RayBundle<double> rays;
  rays.resize(in.size());
  for (std::size_t i = 0; i < in.size(); ++i) {
    rays.x[i] = in[i][0].x;
    rays.y[i] = in[i][0].y;
    rays.z[i] = in[i][0].z;
    rays.l[i] = in[i][1].x;
    rays.m[i] = in[i][1].y;
    rays.n[i] = in[i][1].z;
  }
  const int w = static_cast<int>(tl.wavelengths_nm.size()) - 1;
  trace_bundle(tl, w, tl.surface_count(), true, rays, static_cast<RayRecord<double>*>(nullptr));
  std::vector<std::array<double, 2>> out;
  for (std::size_t i = 0; i < in.size(); ++i) {
    CAPTURE(i);
    REQUIRE(rays.status[i] == kRayOk);
    out.push_back({rays.x[i], rays.y[i]});
  }
  return out;
}

// Chief and marginal rays (pupil edge top, bottom, right) of a field (deg, in y and in x) for
// an entrance pupil of radius r at z = z_ep from surface 1, starting on the plane z = 0.
std::vector<std::array<V3, 2>> chief_and_marginal(double r, double z_ep, double field_y_deg,
                                                  double field_x_deg, V3 centre = {}) {
  const double tx = std::tan(field_x_deg * kPi / 180), ty = std::tan(field_y_deg * kPi / 180);
  const double norm = std::sqrt(1 + tx * tx + ty * ty);
  const V3 d{tx / norm, ty / norm, 1 / norm};
  std::vector<std::array<V3, 2>> out;
  for (const auto& p : std::vector<std::array<double, 2>>{{0, 0}, {0, 1}, {0, -1}, {1, 0}}) {
    // The point of the pupil plane, moved back along d to z = 0.
    const V3 at{centre.x + r * p[0], centre.y + r * p[1], z_ep};
    out.push_back({at - (z_ep / d.z) * d, d});
  }
  return out;
}

}  // namespace

TEST_CASE("zmx-geometry3d: Edmund's 90-degree off-axis parabola (coordinate break, tilted image)") {
  // rayoptics_zmax_37992.zmx: collimated 50.8 mm beam, stop 200 mm before a coordinate break
  // decentring by -190.6 mm in y, the parent paraboloid R = -190.6 mm (focal length 95.3 mm)
  // with its 25.4 mm aperture decentred to y = 190.6 (OBDC), focus at -95.3 mm, and the image
  // surface tilted 90 deg about x (SCBD) to face the beam leaving at 90 degrees.
  const ZmxImport result = read_zmx(real_dir() / "rayoptics_zmax_37992.zmx");
  const Lens& lens = result.lens;
  REQUIRE(lens.surfaces.size() == 4);  // stop, coordinate break, mirror, image tilt
  CHECK(lens.surfaces[1].coordinate_break);
  CHECK(lens.surfaces[1].placement.decenter_y_mm == -190.6);
  CHECK(lens.surfaces[2].mirror);
  CHECK(lens.surfaces[2].conic == -1.0);
  CHECK(lens.surfaces[2].aperture_decenter_y_mm == 190.6);
  CHECK(lens.surfaces[3].coordinate_break);
  CHECK(lens.surfaces[3].placement.tilt_x_deg == 90.0);
  const TraceLens<double> tl = make_trace_lens(lens);
  const ParaxialData<double> par = paraxial_data(tl, tl.reference_nm());
  const double f = 95.3;
  // The parent paraboloid's first-order data (placements are ignored paraxially); BFL from the
  // last surface, the image tilt's coordinate break at the focus: 0 (-95.3 from the mirror).
  CHECK(par.efl_mm == doctest::Approx(f).epsilon(1e-12));
  CHECK(std::abs(par.bfl_mm) < 1e-12 * f);
  CHECK(std::abs(paraxial_defocus_mm(tl, par)) < 1e-12 * f);

  // Reference geometry in the frame of surface 1.
  RefMirror m;
  m.o = {0, -190.6, 200};
  m.c = lens.surfaces[2].curvature_per_mm;
  m.k = -1;
  const double s90 = std::sin(90 * kPi / 180), c90 = std::cos(90 * kPi / 180);
  const V3 image_o = m.o + V3{0, 0, -f};
  const V3 ex{1, 0, 0}, ey{0, c90, s90}, ez{0, -s90, c90};
  int compared = 0;
  for (const auto& field :
       std::vector<std::array<double, 2>>{{0, 0}, {0.5, 0}, {0, 0.5}, {0.3, -0.4}}) {
    CAPTURE(field[0]);
    CAPTURE(field[1]);
    // Marginal rays at 0.9 of the pupil: off axis the full beam overfills the mirror's
    // decentred 25.4 mm aperture (and is vignetted there, as it should be).
    const auto rays = chief_and_marginal(0.9 * 25.4, 0.0, field[0], field[1]);
    const auto ours = lensopt_intercepts(tl, rays);
    for (std::size_t i = 0; i < rays.size(); ++i) {
      V3 p = rays[i][0], d = rays[i][1];
      reflect(m, p, d);
      const auto ref = intercept(image_o, ex, ey, ez, p, d);
      CAPTURE(i);
      CHECK(std::abs(ours[i][0] - ref[0]) < 1e-9 * f);
      CHECK(std::abs(ours[i][1] - ref[1]) < 1e-9 * f);
      ++compared;
    }
    if (field[0] == 0 && field[1] == 0)
      for (const auto& o : ours) CHECK(std::hypot(o[0], o[1]) < 1e-9);  // a perfect focus
  }
  CHECK(compared == 16);
  // The whole pipeline: full pupil (no mirror symmetry), an on-axis spot at the focus.
  TraceOptions options;
  options.rings = 8;
  options.threads = 1;
  const TraceSystem<double> sys = prepare_lens_system(lens, options);
  CHECK(sys.full_pupil);
  const auto spots = evaluate_spots(sys, 1);
  CHECK(spots.mean_rms_spot_mm < 1e-9);
}

TEST_CASE(
    "zmx-geometry3d: a two-mirror telescope (conic primary and secondary, stop on the primary)") {
  // rayoptics_HoO-V2C18Ex03.zmx: paraboloid primary R = -45.72 mm, hyperboloid secondary
  // (k = -3.236) 16 mm in front of it, image 24.035 mm behind the secondary; F/4, fields 0, 1 deg.
  const ZmxImport result = read_zmx(real_dir() / "rayoptics_HoO-V2C18Ex03.zmx");
  const Lens& lens = result.lens;
  const TraceLens<double> tl = make_trace_lens(lens);
  int mirrors = 0;
  for (const Surface& s : lens.surfaces) mirrors += s.mirror;
  CHECK(mirrors == 2);
  // Surfaces: dummy (16 mm), the inserted flat stop (0 mm), primary, secondary.
  REQUIRE(lens.surfaces.size() == 4);
  const Surface& primary = lens.surfaces[2];
  const Surface& secondary = lens.surfaces[3];
  // EFL by the two-mirror formula (reduced: powers -2 n c, reduced separation d / n'):
  // phi1 = -2 c1, phi2 = 2 c2, e = 16 (|d| / |n|), phi = phi1 + phi2 - e phi1 phi2.
  const double phi1 = -2 * primary.curvature_per_mm, phi2 = 2 * secondary.curvature_per_mm;
  const double e = -primary.thickness_mm;
  const double efl = 1 / (phi1 + phi2 - e * phi1 * phi2);
  const ParaxialData<double> par = paraxial_data(tl, tl.reference_nm());
  CHECK(par.efl_mm == doctest::Approx(efl).epsilon(1e-12));
  // The back focus: the image of infinity by the secondary, measured from it.
  const double f1 = 1 / phi1;              // primary focus, 22.86 mm in front of it
  const double s2 = f1 - e;                // the virtual object for the secondary, beyond it
  const double bfl = 1 / (phi2 + 1 / s2);  // Gaussian imaging 1/s' = phi + 1/s (reduced, n' = 1)
  CHECK(par.bfl_mm == doctest::Approx(bfl).epsilon(1e-12));

  RefMirror m1, m2;
  m1.o = {0, 0, lens.surfaces[0].thickness_mm};  // 16 mm
  m1.c = primary.curvature_per_mm;
  m1.k = primary.conic;
  m2.o = m1.o + V3{0, 0, primary.thickness_mm};  // back at z = 0
  m2.c = secondary.curvature_per_mm;
  m2.k = secondary.conic;
  const V3 image_o = m2.o + V3{0, 0, secondary.thickness_mm};
  const double r_ep = par.efl_mm / lens.specs.f_number / 2;
  int compared = 0;
  for (const auto& field :
       std::vector<std::array<double, 2>>{{0, 0}, {1, 0}, {0, 1}, {-0.6, 0.5}}) {
    CAPTURE(field[0]);
    CAPTURE(field[1]);
    // The entrance pupil is the stop, at the primary's vertex plane (z = 16).
    const auto rays = chief_and_marginal(r_ep, m1.o.z, field[0], field[1]);
    const auto ours = lensopt_intercepts(tl, rays);
    for (std::size_t i = 0; i < rays.size(); ++i) {
      V3 p = rays[i][0], d = rays[i][1];
      reflect(m1, p, d);
      reflect(m2, p, d);
      const auto ref = intercept(image_o, {1, 0, 0}, {0, 1, 0}, {0, 0, 1}, p, d);
      CAPTURE(i);
      CHECK(std::abs(ours[i][0] - ref[0]) < 1e-9 * efl);
      CHECK(std::abs(ours[i][1] - ref[1]) < 1e-9 * efl);
      ++compared;
    }
  }
  CHECK(compared == 16);
  // The written lens traces through the pipeline (centred mirrors: the half pupil).
  TraceOptions options;
  options.rings = 8;
  options.threads = 1;
  const TraceSystem<double> sys = prepare_lens_system(lens, options);
  CHECK_FALSE(sys.full_pupil);
  const auto spots = evaluate_spots(sys, 1);
  CHECK(std::isfinite(spots.mean_rms_spot_mm));
}

TEST_CASE("zmx-geometry3d: COORDBRK, MIRROR and apertures are written and read back") {
  const ZmxImport oap = read_zmx(real_dir() / "rayoptics_zmax_37992.zmx");
  const std::string text = format_zmx(oap.lens);
  CHECK(text.find("TYPE COORDBRK") != std::string::npos);
  CHECK(text.find("GLAS MIRROR") != std::string::npos);
  CHECK(text.find("OBDC 0 190.6") != std::string::npos);
  const ZmxImport again = parse_zmx(text, "again.zmx");
  REQUIRE(again.lens.surfaces.size() == oap.lens.surfaces.size());
  for (std::size_t k = 0; k < oap.lens.surfaces.size(); ++k) {
    const Surface& a = oap.lens.surfaces[k];
    const Surface& b = again.lens.surfaces[k];
    CAPTURE(k);
    CHECK(a.coordinate_break == b.coordinate_break);
    CHECK(a.mirror == b.mirror);
    CHECK(a.placement.decenter_y_mm == b.placement.decenter_y_mm);
    CHECK(a.placement.tilt_x_deg == b.placement.tilt_x_deg);
    CHECK(a.thickness_mm == b.thickness_mm);
    CHECK(a.semi_diameter_mm == b.semi_diameter_mm);
    CHECK(a.aperture_decenter_y_mm == b.aperture_decenter_y_mm);
  }
}

TEST_CASE("zmx-geometry3d: bad coordinate breaks and apertures are named with file and line") {
  const std::string head =
      "MODE SEQ\nUNIT MM X W X CM MR CPMM\nENPD 10\nFTYP 0 0 1 1 0 0 0\nXFLN 0\nYFLN 0\n"
      "WAVM 1 0.5876 1\nSURF 0\n  TYPE STANDARD\n  DISZ INFINITY\nSURF 1\n  STOP\n  TYPE "
      "STANDARD\n  DISZ 10\n";
  const std::string tail =
      "SURF 3\n  TYPE STANDARD\n  CURV -0.01\n  DISZ -50\n  GLAS MIRROR 0 0 1.5 40\nSURF 4\n  "
      "TYPE STANDARD\n  DISZ 0\n";
  // PARM 7 on a coordinate break.
  CHECK_THROWS_WITH_AS(
      parse_zmx(head + "SURF 2\n  TYPE COORDBRK\n  PARM 7 1\n  DISZ 0\n" + tail, "bad.zmx"),
      doctest::Contains("bad.zmx:17"), Error);
  // An annular obscuration.
  CHECK_THROWS_WITH_AS(
      parse_zmx(head + "SURF 2\n  TYPE STANDARD\n  DISZ 1\n  OBSC 2 5 0\n" + tail, "bad.zmx"),
      doctest::Contains("annular obscuration"), Error);
  // A field off +y in a lens without symmetry imports as (x, y) (traced in its own frame,
  // test_trace_field_xy.cpp; it was refused before fields had an x).
  std::string x_field = head + "SURF 2\n  TYPE COORDBRK\n  PARM 3 10\n  DISZ 0\n" + tail;
  x_field.replace(x_field.find("XFLN 0"), 6, "XFLN 1");
  const ZmxImport x_import = parse_zmx(x_field, "x.zmx");
  REQUIRE(x_import.lens.specs.fields.size() == 1);
  CHECK(x_import.lens.specs.fields[0].x == 1.0);
  CHECK(x_import.lens.specs.fields[0].value == 0.0);
  // And the good one imports: a tilted flat mirror behind a coordinate break.
  const ZmxImport good =
      parse_zmx(head + "SURF 2\n  TYPE COORDBRK\n  PARM 3 10\n  DISZ 0\n" + tail, "good.zmx");
  CHECK(good.lens.surfaces[1].coordinate_break);
  CHECK(good.lens.surfaces[1].placement.tilt_x_deg == 10.0);
  CHECK(good.lens.surfaces[2].mirror);
}

}  // namespace test_zmx_geometry3d
