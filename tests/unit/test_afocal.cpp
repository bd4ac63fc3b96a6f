// Afocal image space (issue 31, item 3; analysis/afocal.h): telescopes and beam expanders read
// from TOML and .zmx, their angular magnification and exit pupil against the thick-lens closed
// forms written here, and a perfect afocal pair (confocal paraboloids) with no angular spot and
// no wavefront error.
#include <doctest/doctest.h>
#include <fmt/format.h>

#include <cmath>
#include <nlohmann/json.hpp>
#include <string>

#include "error_checks.h"
#include "lensopt/analysis/afocal.h"
#include "lensopt/analysis/analyze.h"
#include "lensopt/analysis/forms_image.h"
#include "lensopt/core/error.h"
#include "lensopt/formats/zmx.h"
#include "lensopt/lens/lens_io.h"
#include "lensopt/lens/trace_lens.h"

namespace lensopt::test_afocal {
namespace {

using test::check_contains;
using test::error_of;

constexpr double kPrimaryNm = 587.5618;

// The model glass's index at the primary wavelength (the input of the closed forms).
double model_index() {
  const Lens probe = parse_lens_toml(
      "[system]\nmode = \"as-written\"\nafocal = false\naperture = \"epd\"\naperture_value = 10\n"
      "primary_wavelength_nm = 587.5618\n[specs]\nwavelengths_nm = [587.5618]\n"
      "[[surfaces]]\nradius_mm = inf\nthickness_mm = 0\nstop = true\n"
      "[[surfaces]]\nradius_mm = 50\nthickness_mm = 4\nmaterial = { nd = 1.5168, vd = 64.17 }\n"
      "[[surfaces]]\nradius_mm = inf\nthickness_mm = 50\n",
      "probe.toml");
  const TraceLens<double> tl = make_trace_lens(probe);
  return tl.index_at_nm(1, kPrimaryNm);
}

// Two singlets of focal lengths f1 and f2 (plano, the curved side outwards: the first lens
// curved in front, the second behind), thickness t each, with a flat stop at the first vertex,
// spaced so that their principal planes are f1 + f2 apart: afocal. For a lens whose other side
// is flat the principal plane on the curved side lies at its vertex and the other one t / n
// inside the flat face, so the air gap is f1 + f2 - t / n - t / n.
struct TwoLens {
  double f1, f2, t, n, gap;
  std::string toml;
};
TwoLens two_lens_telescope(double f1, double f2, double epd, const std::string& fields) {
  TwoLens s{f1, f2, 4.0, model_index(), 0, ""};
  s.gap = f1 + f2 - 2.0 * s.t / s.n;
  const double c1 = 1.0 / ((s.n - 1.0) * f1), c2 = -1.0 / ((s.n - 1.0) * f2);
  s.toml = fmt::format(
      "[lens]\nname = \"telescope\"\n"
      "[system]\nmode = \"as-written\"\nafocal = true\naperture = \"epd\"\naperture_value = {}\n"
      "primary_wavelength_nm = 587.5618\nfields = [{}]\n"
      "[specs]\nwavelengths_nm = [486.1327, 587.5618, 656.2725]\n"
      "[[surfaces]]\nradius_mm = inf\nthickness_mm = 0\nstop = true\n"
      "[[surfaces]]\ncurvature_per_mm = {:.17g}\nthickness_mm = {:.17g}\n"
      "material = {{ nd = 1.5168, vd = 64.17 }}\n"
      "[[surfaces]]\nradius_mm = inf\nthickness_mm = {:.17g}\n"
      "[[surfaces]]\nradius_mm = inf\nthickness_mm = {:.17g}\n"
      "material = {{ nd = 1.5168, vd = 64.17 }}\n"
      "[[surfaces]]\ncurvature_per_mm = {:.17g}\nthickness_mm = 40\n",
      epd, fields, c1, s.t, s.gap, s.t, c2);
  return s;
}

// An independent meridional real-ray trace through two_lens_telescope's four faces, glass index
// n_glass: the ray starts at (y, z = 0) on the stop plane with direction (m, n), optical path 0.
// On a sphere of curvature c with its vertex at z_k, the ray (y, z) + s (m, n) meets
// c (y^2 + z'^2) - 2 z' = 0 (z' = z - z_k) at s = C / (B + sqrt(B^2 - c C)),
// B = n - c (y m + z' n), C = c (y^2 + z'^2) - 2 z'; the unit normal there is (-c y, 1 - c z');
// refraction D' = mu D + (sqrt(1 - mu^2 (1 - cos^2)) - mu cos) N, mu = n1 / n2, cos = D . N.
struct MeridionalRay {
  double y, z, m, n, path_mm;
};
MeridionalRay trace_meridional(const TwoLens& k, double n_glass, double y, double m, double n) {
  const double c1 = 1.0 / ((k.n - 1.0) * k.f1), c2 = -1.0 / ((k.n - 1.0) * k.f2);
  struct Face {
    double z, c, n_after;
  };
  const Face faces[] = {{0.0, c1, n_glass},
                        {k.t, 0.0, 1.0},
                        {k.t + k.gap, 0.0, n_glass},
                        {2.0 * k.t + k.gap, c2, 1.0}};
  MeridionalRay r{y, 0.0, m, n, 0.0};
  double n_before = 1.0;
  for (const Face& face : faces) {
    const double zl = r.z - face.z;
    const double b = r.n - face.c * (r.y * r.m + zl * r.n);
    const double c = face.c * (r.y * r.y + zl * zl) - 2.0 * zl;
    const double s = c / (b + std::sqrt(b * b - face.c * c));
    r.y += s * r.m;
    r.z += s * r.n;
    r.path_mm += n_before * s;
    const double ny = -face.c * r.y, nz = 1.0 - face.c * (r.z - face.z);
    const double mu = n_before / face.n_after;
    const double cos_i = r.m * ny + r.n * nz;
    const double g = std::sqrt(1.0 - mu * mu * (1.0 - cos_i * cos_i)) - mu * cos_i;
    r.m = mu * r.m + g * ny;
    r.n = mu * r.n + g * nz;
    n_before = face.n_after;
  }
  return r;
}

// The chief ray at the primary wavelength (the stop is the first vertex: it starts at the origin
// at the field angle u): its output slope m / n.
double meridional_chief_tan_out(const TwoLens& k, double u) {
  const MeridionalRay r = trace_meridional(k, k.n, 0.0, std::sin(u), std::cos(u));
  return r.m / r.n;
}

TEST_CASE("afocal: a Keplerian telescope f1 = 100, f2 = 25 has M = -4 and its exit pupil") {
  const TwoLens k = two_lens_telescope(100.0, 25.0, 20.0, "0, 0.5, 1");
  const Lens lens = parse_lens_toml(k.toml, "keplerian.toml");
  REQUIRE(lens.specs.afocal);
  AfocalOptions options;
  options.pupil_samples = 32;
  TraceOptions trace;
  trace.rings = 8;
  const AfocalReport r = analyze_afocal_lens(lens, trace, options);
  // Closed forms (thick lenses, principal planes as above): M = -f1 / f2; the entrance pupil (at
  // the first lens's front principal plane) is imaged by lens 2 from f1 + f2 before its front
  // principal plane to s' = f2 (f1 + f2) / f1 behind its rear one, the last vertex; its diameter
  // is EPD / |M|.
  const double m_closed = -k.f1 / k.f2;
  CHECK(r.first_order.angular_magnification == doctest::Approx(m_closed).epsilon(1e-9));
  CHECK(std::abs(r.first_order.angular_magnification + 4.0) < 1e-9);
  const double z_xp = k.f2 * (k.f1 + k.f2) / k.f1;
  CHECK(r.first_order.exit_pupil_z_mm == doctest::Approx(z_xp).epsilon(1e-9));
  CHECK(r.first_order.exit_pupil_diameter_mm == doctest::Approx(20.0 / 4.0).epsilon(1e-9));
  CHECK(std::abs(r.first_order.residual_power_diopters) < 1e-12);
  CHECK(r.first_order.entrance_pupil_z_mm == doctest::Approx(0.0));
  REQUIRE(r.fields.size() == 3);
  for (const AfocalField& f : r.fields) {
    CAPTURE(f.field_deg);
    REQUIRE(f.chief_ok);
    REQUIRE(f.rms_angular_spot_mrad);
    REQUIRE(f.rms_wavefront_waves);
    REQUIRE(f.strehl);
    CHECK(std::isfinite(*f.rms_angular_spot_mrad));
    CHECK(*f.rms_angular_spot_mrad > 0.0);  // two plano-convex singlets: not perfect
    CHECK(*f.strehl > 0.0);
    CHECK(*f.strehl <= 1.0);
    // Inverted: the output chief ray is on the other side, about 4 times steeper.
    if (f.field_deg > 0) {
      CHECK(f.output_chief_angle_deg < 0.0);
      CHECK(f.paraxial_output_angle_deg ==
            doctest::Approx(std::atan(-4.0 * std::tan(f.field_deg * M_PI / 180.0)) * 180.0 / M_PI)
                .epsilon(1e-9));
      // The real chief ray, traced by hand in the meridional plane (the stop is the first vertex,
      // so it starts at the origin at the field angle): its output slope against M tan u.
      const double u = f.field_deg * M_PI / 180.0;
      const double tan_out = meridional_chief_tan_out(k, u);
      MESSAGE("Keplerian angular distortion at ", f.field_deg,
              " deg: ", f.angular_distortion_percent, " %");
      CHECK(std::tan(f.output_chief_angle_deg * M_PI / 180.0) ==
            doctest::Approx(tan_out).epsilon(1e-12));
      const double m_tan = r.first_order.angular_magnification * std::tan(u);
      CHECK(f.angular_distortion_percent ==
            doctest::Approx(100.0 * (tan_out - m_tan) / m_tan).epsilon(1e-9));
      CHECK(std::abs(f.angular_distortion_percent) > 0.0);
    } else {
      CHECK(f.angular_distortion_percent == 0.0);
      CHECK(f.output_chief_angle_deg == doctest::Approx(0.0).epsilon(1e-12));
    }
  }
  // The JSON has the units in its keys and no NaN.
  const nlohmann::json j = nlohmann::json::parse(format_afocal_json(r));
  CHECK(j["angular_magnification"].get<double>() == doctest::Approx(-4.0));
  CHECK(j["fields"][1].contains("rms_angular_spot_mrad"));
  CHECK(j["fields"][1].contains("rms_wavefront_waves"));
  CHECK(!j.contains("efl_mm"));
  const std::string text = format_afocal_text(r);
  CHECK(text.find("angular magnification") != std::string::npos);
  CHECK(text.find("mrad") != std::string::npos);
}

TEST_CASE("afocal: the angular spot agrees with the spread of the exit directions") {
  // The angular spot is the RMS angle of the exit rays about their centroid direction: on axis,
  // the half-pupil rays and their mirrors are spread symmetrically about +z, and the RMS of their
  // angles from +z (computed here from the kept points) is the reported RMS.
  const TwoLens k = two_lens_telescope(100.0, 25.0, 20.0, "0");
  const Lens lens = parse_lens_toml(k.toml, "keplerian.toml");
  TraceOptions trace;
  trace.rings = 6;
  const TraceSystem<double> sys = prepare_lens_system(lens, trace);
  AfocalOptions options;
  options.wavefront = false;
  options.keep_points = true;
  options.wavelength_weights = {1.0, 1.0, 1.0};
  const AfocalReport r = analyze_afocal(sys, options);
  REQUIRE(r.fields.size() == 1);
  const AngularSpot& s = r.fields[0].spot;
  REQUIRE(s.x_mrad.size() == 2 * static_cast<std::size_t>(s.count));
  double sum = 0;
  for (std::size_t i = 0; i < s.x_mrad.size(); ++i)
    sum += s.x_mrad[i] * s.x_mrad[i] + s.y_mrad[i] * s.y_mrad[i];
  CHECK(std::sqrt(sum / s.x_mrad.size()) == doctest::Approx(*r.fields[0].rms_angular_spot_mrad));
  CHECK(s.centroid_n == doctest::Approx(1.0).epsilon(1e-12));
}

// The on-axis wavefront of two_lens_telescope at one wavelength, by trace_meridional with the
// glass index at that wavelength: the ray at pupil height h starts
// on the stop plane (z = 0, OPL 0) along the axis; its optical path is summed face by face and
// continued (backwards when negative) to the reference plane z = z_plane normal to the axis.
// W(rho) = (OPL(h) - OPL(0)) / lambda; the RMS about the disk's mean (piston; an axial pencil has
// no tilt) by the midpoint rule in rho^2 (equal areas), `rings` rings.
double axial_rms_waves(const TwoLens& k, double n_glass, double wavelength_nm, double z_plane,
                       double pupil_radius_mm, int rings) {
  auto opl = [&](double h) {
    const MeridionalRay r = trace_meridional(k, n_glass, h, 0.0, 1.0);
    return r.path_mm + (z_plane - r.z) / r.n;
  };
  const double lambda_mm = wavelength_nm * 1e-6, o0 = opl(0.0);
  double sum = 0, sum_sq = 0;
  for (int i = 0; i < rings; ++i) {
    const double rho = std::sqrt((i + 0.5) / rings);
    const double w = (opl(rho * pupil_radius_mm) - o0) / lambda_mm;
    sum += w;
    sum_sq += w * w;
  }
  const double mean = sum / rings;
  return std::sqrt(sum_sq / rings - mean * mean);
}

TEST_CASE("afocal: a Galilean beam expander (f1 = -25, f2 = 100) expands the beam 4 times") {
  const TwoLens g = two_lens_telescope(-25.0, 100.0, 5.0, "0, 0.5");
  const Lens lens = parse_lens_toml(g.toml, "galilean.toml");
  AfocalOptions options;
  options.pupil_samples = 32;
  TraceOptions trace;
  trace.rings = 8;
  const AfocalReport r = analyze_afocal_lens(lens, trace, options);
  // M = -f1 / f2 = +0.25 (erect); the entrance pupil is imaged by lens 2 from f1 + f2 = 75 mm
  // before it to 1 / (1 / f2 - 1 / (f1 + f2)) = -300 mm: a virtual exit pupil before the last
  // vertex, 4 times the entrance pupil.
  CHECK(r.first_order.angular_magnification == doctest::Approx(0.25).epsilon(1e-9));
  const double z_xp = 1.0 / (1.0 / g.f2 - 1.0 / (g.f1 + g.f2));
  CHECK(z_xp == doctest::Approx(-300.0));
  CHECK(r.first_order.exit_pupil_z_mm == doctest::Approx(z_xp).epsilon(1e-9));
  CHECK(r.first_order.exit_pupil_diameter_mm == doctest::Approx(20.0).epsilon(1e-9));
  REQUIRE(r.fields.size() == 2);
  CHECK(r.fields[1].output_chief_angle_deg > 0.0);
  CHECK(r.fields[1].output_chief_angle_deg < 0.5);
  REQUIRE(r.fields[0].rms_wavefront_waves);
  MESSAGE("Galilean on-axis RMS wavefront ", *r.fields[0].rms_wavefront_waves, " waves");
  // Against the independent trace: the three wavelengths (equal weights) each against the plane
  // through the exit pupil at the primary wavelength (z_xp before the last vertex), RMS of the
  // three RMS values. A finer pupil grid, so the sampling of the disk is not what is compared.
  const double nm[3] = {486.1327, 587.5618, 656.2725};
  const Lens probe = parse_lens_toml(
      "[system]\nmode = \"as-written\"\naperture = \"epd\"\naperture_value = 10\n"
      "primary_wavelength_nm = 587.5618\n[specs]\nwavelengths_nm = [486.1327, 587.5618, "
      "656.2725]\n[[surfaces]]\nradius_mm = inf\nthickness_mm = 0\nstop = true\n"
      "[[surfaces]]\nradius_mm = 50\nthickness_mm = 4\nmaterial = { nd = 1.5168, vd = 64.17 }\n"
      "[[surfaces]]\nradius_mm = inf\nthickness_mm = 50\n",
      "probe.toml");
  const TraceLens<double> probe_lens = make_trace_lens(probe);
  const double z_plane = 2.0 * g.t + g.gap + z_xp;
  double sum_sq = 0;
  for (const double w : nm) {
    const double rms = axial_rms_waves(g, probe_lens.index_at_nm(1, w), w, z_plane, 2.5, 20000);
    MESSAGE("independent on-axis RMS at ", w, " nm: ", rms, " waves");
    sum_sq += rms * rms;
  }
  AfocalOptions fine = options;
  fine.pupil_samples = 256;
  const AfocalReport r_fine = analyze_afocal_lens(lens, trace, fine);
  REQUIRE(r_fine.fields[0].rms_wavefront_waves);
  MESSAGE("Galilean on-axis RMS, 256-sample grid: ", *r_fine.fields[0].rms_wavefront_waves,
          " waves; independent: ", std::sqrt(sum_sq / 3.0));
  CHECK(*r_fine.fields[0].rms_wavefront_waves ==
        doctest::Approx(std::sqrt(sum_sq / 3.0)).epsilon(5e-4));
}

TEST_CASE("afocal: confocal paraboloids (a Mersenne pair) have no angular spot or wavefront") {
  // Primary concave paraboloid f = 100 (R = -200, k = -1) with the stop on it, the secondary
  // convex paraboloid f = -25 (R = -50, k = -1) 75 mm before it: both foci at 100 mm before the
  // primary, so the axial beam leaves collimated and every ray exactly parallel. M = 4.
  const std::string toml =
      "[lens]\nname = \"mersenne\"\n"
      "[system]\nmode = \"as-written\"\nafocal = true\naperture = \"epd\"\naperture_value = 40\n"
      "primary_wavelength_nm = 587.5618\nfields = [0, 0.05]\n"
      "[specs]\nwavelengths_nm = [587.5618]\n"
      "[[surfaces]]\nradius_mm = inf\nthickness_mm = 0\nstop = true\n"
      "[[surfaces]]\nradius_mm = -200\nconic = -1\nthickness_mm = -75\nmaterial = \"mirror\"\n"
      "[[surfaces]]\nradius_mm = -50\nconic = -1\nthickness_mm = 100\nmaterial = \"mirror\"\n";
  const Lens lens = parse_lens_toml(toml, "mersenne.toml");
  AfocalOptions options;
  options.pupil_samples = 48;
  options.zernike_terms = 9;
  TraceOptions trace;
  trace.rings = 10;
  const AfocalReport r = analyze_afocal_lens(lens, trace, options);
  CHECK(std::abs(r.first_order.angular_magnification) == doctest::Approx(4.0).epsilon(1e-12));
  CHECK(std::abs(r.first_order.residual_power_diopters) < 1e-12);
  CHECK(r.first_order.exit_pupil_diameter_mm == doctest::Approx(10.0).epsilon(1e-9));
  REQUIRE(r.fields.size() == 2);
  const AfocalField& axis = r.fields[0];
  REQUIRE(axis.rms_angular_spot_mrad);
  REQUIRE(axis.rms_wavefront_waves);
  REQUIRE(axis.strehl);
  CHECK(*axis.rms_angular_spot_mrad < 1e-9);
  CHECK(*axis.rms_wavefront_waves < 1e-7);
  CHECK(*axis.strehl == doctest::Approx(1.0).epsilon(1e-9));
  for (double z : axis.zernike_waves) CHECK(std::abs(z) < 1e-6);
  // Slightly off axis the pair stays nearly perfect (a small field aberration only).
  const AfocalField& off = r.fields[1];
  REQUIRE(off.rms_wavefront_waves);
  MESSAGE("Mersenne at 0.05 deg: RMS angular spot ", *off.rms_angular_spot_mrad,
          " mrad, RMS wavefront ", *off.rms_wavefront_waves, " waves, angular distortion ",
          off.angular_distortion_percent, " %");
  CHECK(*off.rms_wavefront_waves < 0.05);
}

TEST_CASE("afocal: the TOML flag round-trips and an afocal lens needs a non-EFL aperture") {
  const TwoLens k = two_lens_telescope(100.0, 25.0, 20.0, "0, 1");
  const Lens lens = parse_lens_toml(k.toml, "keplerian.toml");
  const std::string written = format_lens_toml(lens);
  CHECK(written.find("afocal = true") != std::string::npos);
  CHECK(parse_lens_toml(written, "again.toml").specs.afocal);
  // An F-number needs a focal length.
  std::string f_number = k.toml;
  f_number.replace(f_number.find("aperture = \"epd\""), 16, "aperture = \"f-number\"");
  f_number.replace(f_number.find("[specs]\n"), 8, "[specs]\nf_number = 4\n");
  check_contains(error_of([&] { parse_lens_toml(f_number, "f.toml"); }), "no F-number");
  // The paper's spec mode scales to a focal length.
  std::string paper = k.toml;
  paper.replace(paper.find("mode = \"as-written\""), 19, "mode = \"paper\"");
  check_contains(error_of([&] { parse_lens_toml(paper, "p.toml"); }), "as-written");
  // The image-plane analysis still refuses it, saying afocal and the angular magnification.
  Lens plain = lens;
  plain.specs.afocal = false;
  AnalyzeOptions options;
  options.trace.rings = 4;
  check_contains(error_of([&] { check_forms_image(analyze_lens(plain, options)); }), "afocal");
  // And analyze_afocal_lens needs the flag.
  check_contains(error_of([&] { analyze_afocal_lens(plain, TraceOptions{}, AfocalOptions{}); }),
                 "not in afocal mode");
}

std::string telescope_zmx(const TwoLens& k, int afocal_flag, const std::string& aperture) {
  return fmt::format(
      "VERS 190513 0 000000 0\nMODE SEQ\nNAME Keplerian telescope\nUNIT MM X W X CM MR CPMM\n"
      "{}\nFTYP 0 0 2 1 0 0 {}\nXFLN 0 0\nYFLN 0 1\nFWGN 1 1\nWAVM 1 0.5875618 1\nPWAV 1\n"
      "SURF 0\n  CURV 0\n  DISZ INFINITY\n"
      "SURF 1\n  STOP\n  CURV 0\n  DISZ 0\n"
      "SURF 2\n  CURV {:.17g}\n  DISZ {:.17g}\n  GLAS ___BLANK 1 0 1.5168 64.17\n"
      "SURF 3\n  CURV 0\n  DISZ {:.17g}\n"
      "SURF 4\n  CURV 0\n  DISZ {:.17g}\n  GLAS ___BLANK 1 0 1.5168 64.17\n"
      "SURF 5\n  CURV {:.17g}\n  DISZ 40\n"
      "SURF 6\n  CURV 0\n  DISZ 0\n",
      aperture, afocal_flag, 1.0 / ((k.n - 1.0) * k.f1), k.t, k.gap, k.t,
      -1.0 / ((k.n - 1.0) * k.f2));
}

TEST_CASE("afocal: a .zmx with Afocal Image Space (FTYP's seventh value) imports and writes back") {
  // ___BLANK model glass: nd exact at 587.5618 nm, the closed form's n is 1.5168 itself.
  TwoLens k{100.0, 25.0, 4.0, 1.5168, 0, ""};
  k.gap = k.f1 + k.f2 - 2.0 * k.t / k.n;
  const ZmxImport imported = parse_zmx(telescope_zmx(k, 1, "ENPD 20"), "telescope.zmx");
  for (const std::string& w : imported.warnings) CHECK(w.find("afocal") == std::string::npos);
  REQUIRE(imported.lens.specs.afocal);
  TraceOptions trace;
  trace.rings = 6;
  AfocalOptions options;
  options.pupil_samples = 16;
  const AfocalReport r = analyze_afocal_lens(imported.lens, trace, options);
  CHECK(r.first_order.angular_magnification == doctest::Approx(-4.0).epsilon(1e-9));
  CHECK(r.first_order.exit_pupil_z_mm == doctest::Approx(31.25).epsilon(1e-9));
  // Written back: the flag is kept.
  const std::string written = format_zmx(imported.lens);
  const ZmxImport again = parse_zmx(written, "again.zmx");
  CHECK(again.lens.specs.afocal);
  // Without the flag the paraxial EFL (infinite) says afocal: read so, with a warning.
  const ZmxImport inferred = parse_zmx(telescope_zmx(k, 0, "ENPD 20"), "inferred.zmx");
  CHECK(inferred.lens.specs.afocal);
  int afocal_warnings = 0;
  for (const std::string& w : inferred.warnings)
    afocal_warnings += w.find("Afocal Image Space") != std::string::npos;
  CHECK(afocal_warnings == 1);
  // A flag value other than 0 or 1, and an F-number aperture, are errors naming the line.
  check_contains(error_of([&] { parse_zmx(telescope_zmx(k, 2, "ENPD 20"), "bad.zmx"); }),
                 "bad.zmx:6");
  check_contains(error_of([&] { parse_zmx(telescope_zmx(k, 1, "FNUM 4 0"), "fnum.zmx"); }),
                 "no F-number");
}

}  // namespace
}  // namespace lensopt::test_afocal
