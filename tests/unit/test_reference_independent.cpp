// lensopt against numbers computed by independent tools (tests/data/independent, sources and
// precision in its README): optiland's paraxial data of 11 of its sample lenses (same vendor
// glass data), its float-by-stop entrance pupil, sag / intersection / normal of spheres, conics
// and even aspheres, real-ray distortion, a ray-fan intercept and the sampled MTF of the Cooke
// triplet; OpticStudio's first-order data and on-axis spot radii of a singlet. Each comparison
// is held to the precision the reference carries and states the difference achieved.
#include <doctest/doctest.h>
#include <fmt/format.h>

#include <algorithm>
#include <cmath>
#include <complex>
#include <fstream>
#include <nlohmann/json.hpp>
#include <string>

#include "lensopt/analysis/wave.h"
#include "lensopt/analysis/wavefront.h"
#include "lensopt/analysis/zernike.h"
#include "lensopt/core/constants.h"
#include "lensopt/formats/lens_file.h"
#include "lensopt/lens/lens.h"
#include "lensopt/lens/trace_lens.h"
#include "lensopt/paraxial/paraxial.h"
#include "lensopt/trace/kernel.h"
#include "lensopt/trace/profile.h"
#include "lensopt/trace/system.h"
#include "test_support.h"

namespace test_reference_independent {

using namespace lensopt;

namespace {

std::filesystem::path independent_dir() {
  return test::source_dir() / "tests" / "data" / "independent";
}

nlohmann::json read_json(const std::filesystem::path& path) {
  std::ifstream in(path);
  REQUIRE(in);
  return nlohmann::json::parse(in);
}

// Paraxial first-order data of a lens as optiland defines them (tests/test_paraxial.py): EFL,
// back focal point and exit pupil from the image surface, entrance pupil from the first surface,
// pupil diameters and the image-space F-number.
struct FirstOrder {
  double efl = 0, f2_from_image = 0, epl = 0, epd = 0, xpl_from_image = 0, xpd = 0, fno = 0;
  double t_last = 0;  // the prescription's last thickness (vertex to image surface)
};

// Adds `offset` to the index of every surface of glass `glass` at `wavelength_nm` (a stand-in for
// another data set of that glass; see the Cooke triplet below).
void offset_glass_index(const Lens& lens, TraceLens<double>& tl, const std::string& glass,
                        double wavelength_nm, double offset) {
  REQUIRE(tl.catalog_offset.size() == lens.surfaces.size());
  for (std::size_t k = 0; k < lens.surfaces.size(); ++k) {
    const Material& material = lens.surfaces[k].material;
    if (material.glass == nullptr || material.glass->name != glass) continue;
    for (std::size_t w = 0; w < tl.wavelengths_nm.size(); ++w)
      if (tl.wavelengths_nm[w] == wavelength_nm) tl.catalog_offset[k][w] += offset;
  }
}

TraceSystem<double> prepare(const Lens& lens, double sk16_offset_550 = 0.0) {
  TraceOptions options;
  options.rings = 4;
  TraceLens<double> tl = make_trace_lens(lens);
  if (sk16_offset_550 != 0.0) offset_glass_index(lens, tl, "SK16", 550.0, sk16_offset_550);
  return prepare_system(tl, lens_setup(lens, options), options);
}

FirstOrder first_order(const Lens& lens, double sk16_offset_550 = 0.0) {
  const TraceSystem<double> sys = prepare(lens, sk16_offset_550);
  const TraceLens<double>& tl = sys.lens;
  const double wavelength = tl.wavelengths_nm.back();  // the primary
  FirstOrder out;
  out.t_last = tl.thickness_mm.back();
  out.efl = sys.efl_mm;
  out.f2_from_image = sys.bfl_mm - out.t_last;
  out.epl = sys.entrance_pupil_z_mm;
  out.epd = sys.epd_mm;
  out.fno = sys.efl_mm / sys.epd_mm;
  out.xpl_from_image = exit_pupil_from_image_mm(tl, wavelength);
  // Exit pupil diameter: the axial marginal ray (height EPD / 2) at the exit pupil plane.
  const ParaxialRay<double> marginal = paraxial_trace(
      tl, ParaxialRay<double>{sys.epd_mm / 2.0, 0.0}, tl.surface_count(), wavelength);
  const double z_xp = out.xpl_from_image + out.t_last;  // from the last vertex
  out.xpd = 2.0 * std::abs(marginal.y + z_xp * marginal.w);
  return out;
}

// The Cooke triplet's "SK16": optiland resolves the name without a vendor in its
// refractiveindex.info database to data that are not Schott's SK16 of SCHOTT_202002.AGF. The
// index offset at 550 nm that gives optiland's EFL (secant iterations): every other value of
// the lens is then a check of the rest of the computation.
double cooke_sk16_offset(const Lens& lens, double efl_reference) {
  double a = 0.0, b = 1e-6;
  double fa = first_order(lens, a).efl - efl_reference;
  double fb = first_order(lens, b).efl - efl_reference;
  for (int i = 0; i < 8 && fb != 0.0 && fb != fa; ++i) {
    const double c = b - fb * (b - a) / (fb - fa);
    a = b;
    fa = fb;
    b = c;
    fb = first_order(lens, b).efl - efl_reference;
  }
  return b;
}

// |a - b| / |b| (or |a - b| when b = 0).
double relative(double a, double b) {
  return b == 0.0 ? std::abs(a - b) : std::abs(a - b) / std::abs(b);
}

}  // namespace

TEST_CASE("independent: optiland's paraxial data of its sample lenses (same vendor glass data)") {
  const nlohmann::json doc = read_json(independent_dir() / "optiland_paraxial.json");
  const double bound = doc.at("relative_bound").get<double>();
  int lenses = 0, values = 0;
  double worst = 0.0;
  for (const nlohmann::json& ref : doc.at("lenses")) {
    const std::string name = ref.at("name").get<std::string>();
    CAPTURE(name);
    const Lens lens = read_lens(independent_dir() / ("optiland_" + name + ".toml"));
    const bool fitted = ref.value("fit_sk16_index_to_efl", false);
    const double offset = fitted ? cooke_sk16_offset(lens, ref.at("f2").get<double>()) : 0.0;
    if (fitted) {
      MESSAGE(
          fmt::format("{}: as written (Schott SK16) EFL differs by {:.3e} relative; SK16 "
                      "index offset at 550 nm fitted to optiland's EFL: {:.4e}",
                      name, relative(first_order(lens).efl, ref.at("f2").get<double>()), offset));
      CHECK(std::abs(offset) < 2e-6);  // a glass-data difference, not a different glass
    }
    const FirstOrder got = first_order(lens, offset);
    const bool solved = ref.value("image_solve", false);
    // optiland's image_solve moved its image surface to the paraxial focus: positions from the
    // image surface are then compared from the focus (F2 = 0 there).
    const double f2_ref = ref.at("F2").get<double>();
    const double to_focus = solved ? -got.f2_from_image : 0.0;  // lensopt's focus from its image
    struct Item {
      const char* what;
      double lensopt, reference, scale;
    };
    const double efl_ref = ref.at("f2").get<double>();
    std::vector<Item> items = {
        {"EPL", got.epl, ref.at("EPL").get<double>(), efl_ref},
        {"EPD", got.epd, ref.at("EPD").get<double>(), ref.at("EPD").get<double>()},
        {"XPL", got.xpl_from_image + to_focus, ref.at("XPL").get<double>() - (solved ? f2_ref : 0),
         efl_ref},
        {"XPD", got.xpd, ref.at("XPD").get<double>(), ref.at("XPD").get<double>()},
    };
    if (!solved) items.push_back({"F2", got.f2_from_image, f2_ref, efl_ref});
    if (!fitted) {  // consumed by the fit
      items.push_back({"EFL", got.efl, efl_ref, efl_ref});
      items.push_back({"FNO", got.fno, ref.at("FNO").get<double>(), ref.at("FNO").get<double>()});
    }
    std::string line = fmt::format("{}:", name);
    for (const Item& item : items) {
      // Lengths relative to the focal length (positions) or to themselves (sizes, F-number).
      const double d = std::abs(item.lensopt - item.reference) / std::abs(item.scale);
      worst = std::max(worst, d);
      line += fmt::format(" {} {:.3e}", item.what, d);
      CAPTURE(item.what);
      CAPTURE(item.lensopt);
      CAPTURE(item.reference);
      CHECK(d <= bound);
      ++values;
    }
    MESSAGE(line);
    ++lenses;
  }
  MESSAGE(fmt::format("{} lenses, {} values: largest difference {:.3e} (relative)", lenses, values,
                      worst));
  CHECK(lenses == static_cast<int>(doc.at("lenses").size()));
}

TEST_CASE("independent: optiland's float-by-stop entrance pupil of the Cooke triplet") {
  // optiland's float_by_stop_size value is the stop's diameter (7.6 mm: semi-diameter 3.8 mm).
  const nlohmann::json doc = read_json(independent_dir() / "optiland_paraxial.json");
  const nlohmann::json& ref = doc.at("float_by_stop");
  Lens lens =
      read_lens(independent_dir() / ("optiland_" + ref.at("name").get<std::string>() + ".toml"));
  double efl_reference = 0.0;
  for (const nlohmann::json& l : doc.at("lenses"))
    if (l.at("name") == ref.at("name")) efl_reference = l.at("f2").get<double>();
  REQUIRE(efl_reference > 0.0);
  const double offset = cooke_sk16_offset(lens, efl_reference);
  lens.specs.aperture_type = ApertureType::kFloatByStop;
  lens.surfaces[lens.stop_index()].semi_diameter_mm =
      ref.at("stop_diameter_mm").get<double>() / 2.0;
  const double epd_ref = ref.at("EPD").get<double>();
  const double as_written = relative(first_order(lens).epd, epd_ref);
  const FirstOrder got = first_order(lens, offset);
  const double d = relative(got.epd, epd_ref);
  MESSAGE(
      fmt::format("float-by-stop EPD: lensopt {:.15f}, optiland {:.15f}, relative {:.3e} "
                  "(with Schott's SK16 as written: {:.3e})",
                  got.epd, epd_ref, d, as_written));
  CHECK(d <= doc.at("relative_bound").get<double>());
}

TEST_CASE("independent: optiland's sag, intersection distance and normal of conics and aspheres") {
  const nlohmann::json doc = read_json(independent_dir() / "optiland_geometry.json");
  const double closed_form_bound = doc.at("closed_form_relative_bound").get<double>();
  const double newton_bound = doc.at("newton_distance_bound_mm").get<double>();
  int values = 0;
  double worst_closed = 0.0, worst_newton = 0.0;
  for (const nlohmann::json& s : doc.at("surfaces")) {
    const std::string label = s.at("label").get<std::string>();
    CAPTURE(label);
    const double radius = s.at("radius_mm").get<double>();
    Surface surface;
    surface.curvature_per_mm = 1.0 / radius;
    surface.conic = s.value("conic", 0.0);
    // optiland's EvenAsphere coefficients start at r^2: [a2, a4, a6, ...].
    const std::vector<double> coefficients = s.value("coefficients", std::vector<double>{});
    double a[8] = {0, 0, 0, 0, 0, 0, 0, 0};
    for (std::size_t i = 0; i < coefficients.size(); ++i) a[i] = coefficients[i];
    surface.asphere_r2_per_mm = a[0];
    for (int i = 0; i < kAsphereOrders; ++i) surface.asphere[i] = a[i + 1];
    const double c = surface.curvature_per_mm, one_plus_k = 1.0 + surface.conic;
    const bool aspheric = surface.has_asphere();

    for (const nlohmann::json& p : s.value("sag", nlohmann::json::array())) {
      const double x = p.at(0).get<double>(), y = p.at(1).get<double>();
      const double ref = p.at(2).get<double>();
      const double got = surface.sag_mm(std::hypot(x, y));
      const double d = relative(got, ref);
      worst_closed = std::max(worst_closed, d);
      CAPTURE(x);
      CAPTURE(y);
      CHECK(d <= closed_form_bound);
      ++values;
    }
    for (const nlohmann::json& r : s.value("distance", nlohmann::json::array())) {
      // A ray from (x0, y0, z0) along (l, m, n) to the surface: lensopt starts on the vertex
      // plane, s0 = -z0 / n along the ray, then the profile's intersection path s.
      const double x0 = r.at("origin").at(0).get<double>();
      const double y0 = r.at("origin").at(1).get<double>();
      const double z0 = r.at("origin").at(2).get<double>();
      double l = r.at("direction").at(0).get<double>();
      double m = r.at("direction").at(1).get<double>();
      const double n = std::sqrt(1.0 - l * l - m * m);
      const double ref = r.at("distance_mm").get<double>();
      const double s0 = -z0 / n;
      const double x1 = x0 + s0 * l, y1 = y0 + s0 * m;
      CAPTURE(x0);
      CAPTURE(y0);
      double s = 0.0;
      if (aspheric) {
        REQUIRE(detail::asphere_newton(c, one_plus_k, a, x1, y1, l, m, n, s));
        // The vectorized stage the kernel runs first must agree.
        double s_chunk = 0.0;
        std::int32_t failure = -1;
        detail::asphere_intersect_chunk(c, one_plus_k, a, 1, &x1, &y1, &l, &m, &n, &s_chunk,
                                        &failure);
        CHECK(failure == kRayOk);
        CHECK(std::abs(s_chunk - s) <= newton_bound);
        const double d = std::abs(s0 + s - ref);
        worst_newton = std::max(worst_newton, d);
        CHECK(d <= newton_bound);
      } else {
        bool miss = true;
        s = detail::conic_intersection(c, one_plus_k, x1, y1, l, m, n, miss);
        REQUIRE_FALSE(miss);
        const double d = relative(s0 + s, ref);
        worst_closed = std::max(worst_closed, d);
        CHECK(d <= closed_form_bound);
      }
      ++values;
    }
    if (s.contains("normal")) {
      // optiland's normal at (x, y) points to -z; lensopt's (-2 x S', -2 y S', 1) / |.| to +z.
      const nlohmann::json& nr = s.at("normal");
      const double x = nr.at("at").at(0).get<double>(), y = nr.at("at").at(1).get<double>();
      double sag = 0, slope = 0;
      detail::asphere_sag(c, one_plus_k, a, x * x + y * y, sag, slope);
      const double gx = -2.0 * x * slope, gy = -2.0 * y * slope;
      const double norm = std::sqrt(gx * gx + gy * gy + 1.0);
      const double got[3] = {gx / norm, gy / norm, 1.0 / norm};
      for (int i = 0; i < 3; ++i) {
        const double ref = -nr.at("unit_normal").at(i).get<double>();
        const double d = relative(got[i], ref);
        worst_closed = std::max(worst_closed, d);
        CAPTURE(i);
        CHECK(d <= closed_form_bound);
        ++values;
      }
    }
  }
  MESSAGE(
      fmt::format("{} geometry values: closed forms within {:.3e} relative, asphere "
                  "intersection distances within {:.3e} mm",
                  values, worst_closed, worst_newton));
  CHECK(values == doc.at("value_count").get<int>());
}

TEST_CASE("independent: optiland's real-ray distortion of the triplet telescope objective") {
  // The stop is the first surface: the chief ray of field theta is the ray through its vertex,
  // so no pupil convention enters. Distortion (percent) = 100 (y - y_ref) / y_ref with
  // y_ref = const tan(theta) (f-tan) or const theta (f-theta), const = y / tan(theta) of a
  // chief ray at 1e-10 of the field, per wavelength, as optiland.analysis.Distortion defines it.
  const nlohmann::json doc = read_json(independent_dir() / "optiland_analysis.json");
  const nlohmann::json& ref = doc.at("distortion");
  const Lens lens =
      read_lens(independent_dir() / ("optiland_" + ref.at("lens").get<std::string>() + ".toml"));
  const TraceLens<double> tl = make_trace_lens(lens);
  const double theta = ref.at("field_deg").get<double>() * kPi / 180.0;
  const double tiny = 1e-10 * theta;
  const int k_count = tl.surface_count();
  double worst_tan = 0.0, worst_theta = 0.0;
  for (int w = 0; w < 3; ++w) {
    CAPTURE(tl.wavelengths_nm[w]);
    RayBundle<double> rays;
    rays.resize(2);
    const double angles[2] = {theta, tiny};
    for (int i = 0; i < 2; ++i) {
      rays.x[i] = rays.y[i] = rays.z[i] = 0.0;  // the vertex of the stop (surface 1)
      rays.l[i] = 0.0;
      rays.m[i] = std::sin(angles[i]);
      rays.n[i] = std::cos(angles[i]);
    }
    trace_bundle(tl, w, k_count, true, rays, static_cast<RayRecord<double>*>(nullptr));
    REQUIRE(rays.status[0] == kRayOk);
    REQUIRE(rays.status[1] == kRayOk);
    const double scale = rays.y[1] / std::tan(tiny);
    const double f_tan = 100.0 * (rays.y[0] - scale * std::tan(theta)) / (scale * std::tan(theta));
    const double f_theta = 100.0 * (rays.y[0] - scale * theta) / (scale * theta);
    const double d_tan = std::abs(f_tan - ref.at("f_tan_percent").at(w).get<double>());
    const double d_theta = std::abs(f_theta - ref.at("f_theta_percent").at(w).get<double>());
    MESSAGE(fmt::format("{} nm: f-tan {:.9f} % (optiland {}), f-theta {:.9f} % (optiland {})",
                        tl.wavelengths_nm[w], f_tan, ref.at("f_tan_percent").at(w).get<double>(),
                        f_theta, ref.at("f_theta_percent").at(w).get<double>()));
    worst_tan = std::max(worst_tan, d_tan);
    worst_theta = std::max(worst_theta, d_theta);
    CHECK(d_tan <= ref.at("f_tan_bound_percent").get<double>());
    CHECK(d_theta <= ref.at("f_theta_bound_percent").get<double>());
  }
  MESSAGE(fmt::format("distortion: f-tan within {:.2e} %, f-theta within {:.2e} % of optiland",
                      worst_tan, worst_theta));
}

TEST_CASE("independent: optiland's sampled MTF of the Cooke triplet on axis") {
  // optiland's SampledMTF (mtf/sampled.py): the pupil sampled on a uniform n x n grid over
  // [-1, 1]^2 (points with r <= 1), OTF(nu) = sum_p P(p) P*(p - delta) / N with
  // delta = |XPL| lambda nu / (XPD / 2) (paraxial exit pupil), P* from a 37-term Fringe fit and
  // 0 outside the pupil. Two comparisons:
  //  (a) lensopt's wavefront (its own 37-term Fringe fit, with optiland's SK16 index at 550 nm)
  //      through that formula reproduces optiland's numbers to the precision they are printed
  //      with (one unit of the last digit: they are cut, not rounded);
  //  (b) lensopt's own diffraction MTF (pupil autocorrelation on a 128 grid) differs from them by
  //      no more than the bias of optiland's n = 32 grid, measured here on the aberration-free
  //      pupil (grid overlap fraction against (2/pi)(phi - cos phi sin phi)), plus 1e-3.
  const nlohmann::json doc = read_json(independent_dir() / "optiland_analysis.json");
  const nlohmann::json& ref = doc.at("mtf");
  Lens lens =
      read_lens(independent_dir() / ("optiland_" + ref.at("lens").get<std::string>() + ".toml"));
  // Monochromatic at the reference wavelength (the primary, 550 nm, stays the paraxial one).
  const double wavelength_nm = ref.at("wavelength_nm").get<double>();
  lens.specs.wavelengths_nm = {wavelength_nm};
  lens.specs.wavelength_channels = default_wavelength_channels(lens.specs.wavelengths_nm);
  lens.specs.wavelength_weights.clear();
  // optiland's SK16 at 550 nm (see the paraxial test case).
  const nlohmann::json paraxial_doc = read_json(independent_dir() / "optiland_paraxial.json");
  double efl_reference = 0.0;
  for (const nlohmann::json& l : paraxial_doc.at("lenses"))
    if (l.at("name") == ref.at("lens")) efl_reference = l.at("f2").get<double>();
  REQUIRE(efl_reference > 0.0);
  const double sk16_offset = cooke_sk16_offset(lens, efl_reference);
  const TraceSystem<double> sys = prepare(lens, sk16_offset);
  REQUIRE(sys.fields_deg.front() == 0.0);
  std::vector<double> frequencies;
  for (const nlohmann::json& p : ref.at("points"))
    frequencies.push_back(p.at("frequency_cyc_mm").get<double>());
  WaveOptions wave;
  wave.pupil_samples = 128;
  wave.geometric = false;
  wave.threads = 1;
  wave.zernike_terms = 37;
  wave.zernike_ordering = ZernikeOrdering::kFringe;
  const WaveReport report = analyze_wave(sys, wave, frequencies, {0});
  REQUIRE(report.fields.size() == 1);
  const WaveField& field = report.fields.front();
  REQUIRE(field.mono.size() == 1);
  const std::vector<double>& zernike = field.mono.front().zernike_waves;
  REQUIRE(zernike.size() == 37);
  const FirstOrder paraxial = first_order(lens, sk16_offset);
  const int grid = ref.at("optiland_grid").get<int>();
  std::vector<double> gx, gy;
  for (int i = 0; i < grid; ++i)
    for (int j = 0; j < grid; ++j) {
      const double x = -1.0 + 2.0 * j / (grid - 1), y = -1.0 + 2.0 * i / (grid - 1);
      if (x * x + y * y <= 1.0) {
        gx.push_back(x);
        gy.push_back(y);
      }
    }
  auto w_fit = [&](double x, double y) {
    double w = 0.0;
    for (int j = 1; j <= 37; ++j)
      w += zernike[j - 1] * zernike_value(ZernikeOrdering::kFringe, j, x, y);
    return w;
  };
  const double printed = ref.at("printed_unit").get<double>();
  double worst_a = 0.0, worst_b = 0.0;
  for (std::size_t i = 0; i < frequencies.size(); ++i) {
    const nlohmann::json& p = ref.at("points").at(i);
    const bool tangential = p.at("orientation").get<std::string>() == "tangential";
    const double angle = p.at("angle_deg").get<double>() * kPi / 180.0;
    const double delta = std::abs(paraxial.xpl_from_image) * wavelength_nm * 1e-6 * frequencies[i] /
                         (paraxial.xpd / 2.0);
    const double dx = delta * std::cos(angle), dy = delta * std::sin(angle);
    std::complex<double> otf = 0.0;
    int overlap = 0;
    for (std::size_t k = 0; k < gx.size(); ++k) {
      const double sx = gx[k] - dx, sy = gy[k] - dy;
      if (sx * sx + sy * sy > 1.0) continue;
      ++overlap;
      otf += std::polar(1.0, 2.0 * kPi * (w_fit(gx[k], gy[k]) - w_fit(sx, sy)));
    }
    const double emulated = std::abs(otf) / static_cast<double>(gx.size());
    const double grid_bias =
        static_cast<double>(overlap) / gx.size() - diffraction_limited_mtf(delta / 2.0);
    const double got = tangential ? field.mtf_t[i] : field.mtf_s[i];
    const double expected = p.at("mtf").get<double>();
    const double d_a = std::abs(emulated - expected), d_b = std::abs(got - expected);
    worst_a = std::max(worst_a, d_a);
    worst_b = std::max(worst_b, d_b);
    MESSAGE(
        fmt::format("{:.4f} cyc/mm: optiland {:.5f}; lensopt's wavefront through optiland's "
                    "formula {:.5f} (diff {:.1e}); lensopt's MTF {} {:.5f} (diff {:.4f}, grid "
                    "bias of the n = {} reference {:+.4f})",
                    frequencies[i], expected, emulated, d_a, tangential ? "T" : "S", got, d_b, grid,
                    grid_bias));
    CHECK(d_a <= printed);
    CHECK(d_b <= std::abs(grid_bias) + 1e-3);
  }
  // The report names the wavelength whose chief ray centres the reference sphere: the primary.
  CHECK(report.reference_wavelength_nm == 550.0);
  CHECK(format_wave_text(report).find("about the 550 nm chief ray") != std::string::npos);
  MESSAGE(
      fmt::format("on-axis MTF: emulated within {:.1e}, lensopt's own within {:.4f} of optiland",
                  worst_a, worst_b));
}

TEST_CASE("independent: optiland's ray fan intercepts of the Cooke triplet") {
  // Real rays through the paraxial entrance pupil (no ray aiming, as optiland's RayFan traces
  // them): the ray of pupil point (px, py) and field theta crosses the entrance pupil plane
  // (z = EPL) at r_ep (px, py); its image intercept minus the chief ray's at the primary.
  const nlohmann::json doc = read_json(independent_dir() / "optiland_analysis.json");
  const nlohmann::json& ref = doc.at("ray_fan");
  const Lens lens =
      read_lens(independent_dir() / ("optiland_" + ref.at("lens").get<std::string>() + ".toml"));
  const nlohmann::json paraxial = read_json(independent_dir() / "optiland_paraxial.json");
  double efl_reference = 0.0;
  for (const nlohmann::json& l : paraxial.at("lenses"))
    if (l.at("name") == ref.at("lens")) efl_reference = l.at("f2").get<double>();
  REQUIRE(efl_reference > 0.0);
  const TraceSystem<double> sys = prepare(lens, cooke_sk16_offset(lens, efl_reference));
  const TraceLens<double>& tl = sys.lens;
  const int primary = static_cast<int>(tl.wavelengths_nm.size()) - 1;
  const double r_ep = sys.epd_mm / 2.0, z_ep = sys.entrance_pupil_z_mm;
  auto intercept = [&](double theta, int w, double px, double py, double& x, double& y) {
    RayBundle<double> rays;
    rays.resize(1);
    rays.l[0] = 0.0;
    rays.m[0] = std::sin(theta);
    rays.n[0] = std::cos(theta);
    rays.x[0] = r_ep * px;
    rays.y[0] = r_ep * py - z_ep * std::tan(theta);  // on the first vertex plane
    rays.z[0] = 0.0;
    trace_bundle(tl, w, tl.surface_count(), true, rays, static_cast<RayRecord<double>*>(nullptr));
    REQUIRE(rays.status[0] == kRayOk);
    x = rays.x[0];
    y = rays.y[0];
  };
  const double bound = ref.at("bound_mm").get<double>();
  for (const nlohmann::json& p : ref.at("points")) {
    const double theta = p.at("field_deg").get<double>() * kPi / 180.0;
    const double wavelength = p.at("wavelength_nm").get<double>();
    int w = -1;
    for (int i = 0; i < primary; ++i)
      if (tl.wavelengths_nm[i] == wavelength) w = i;
    REQUIRE(w >= 0);
    double x = 0, y = 0, x_chief = 0, y_chief = 0;
    intercept(theta, w, p.at("px").get<double>(), p.at("py").get<double>(), x, y);
    intercept(theta, primary, 0.0, 0.0, x_chief, y_chief);
    const bool along_x = p.at("axis").get<std::string>() == "x";
    const double got = along_x ? x - x_chief : y - y_chief;
    const double expected = p.at("value_mm").get<double>();
    MESSAGE(fmt::format("{} deg, {} nm, ({}, {}): lensopt {:.9f} mm, optiland {} mm, diff {:.2e}",
                        p.at("field_deg").get<double>(), wavelength, p.at("px").get<double>(),
                        p.at("py").get<double>(), got, expected, std::abs(got - expected)));
    if (p.at("check").get<bool>()) CHECK(std::abs(got - expected) <= bound);
  }
}

TEST_CASE("independent: OpticStudio's first-order data and on-axis spots of a singlet") {
  const nlohmann::json doc = read_json(independent_dir() / "opticstudio_singlet.json");
  const Lens lens = read_lens(independent_dir() / "optiland_singlet_stop_surf2.toml");
  const FirstOrder got = first_order(lens);
  const nlohmann::json& fo = doc.at("first_order");
  const std::pair<const char*, double> mine[] = {{"EFL", got.efl}, {"EPD", got.epd},
                                                 {"EPL", got.epl}, {"FNO", got.fno},
                                                 {"XPD", got.xpd}, {"XPL", got.xpl_from_image}};
  for (const auto& [what, value] : mine) {
    const double expected = fo.at(what).at(0).get<double>();
    // The displayed value is rounded: it carries half a unit of its last digit.
    const double half_unit = 0.5 * fo.at(what).at(1).get<double>();
    MESSAGE(fmt::format("{}: lensopt {:.9f}, OpticStudio {}, diff {:.2e}", what, value, expected,
                        std::abs(value - expected)));
    CAPTURE(what);
    CHECK(std::abs(value - expected) <= half_unit + 1e-12);
  }
  // Standard Spot, ray density 6: the centre ray and rings i = 1..6 at pupil radius i / 6 with 6 i
  // rays each (127 rays); on axis only the ring radii matter (rotational symmetry). RMS and
  // largest radius about the chief ray (the axis), each wavelength alone.
  const nlohmann::json& spot = doc.at("spot_on_axis");
  const int rings = spot.at("rings").get<int>();
  TraceOptions options;
  options.rings = 4;
  const TraceSystem<double> sys = prepare_lens_system(lens, options);
  const TraceLens<double>& tl = sys.lens;
  const double bound = spot.at("bound_mm").get<double>();
  for (int w = 0; w < 3; ++w) {
    REQUIRE(tl.wavelengths_nm[w] == spot.at("wavelengths_nm").at(w).get<double>());
    RayBundle<double> rays;
    rays.resize(static_cast<std::size_t>(rings) + 1);
    for (int i = 0; i <= rings; ++i) {
      rays.x[i] = 0.0;
      rays.y[i] = sys.epd_mm / 2.0 * i / rings;
      rays.z[i] = 0.0;
      rays.l[i] = rays.m[i] = 0.0;
      rays.n[i] = 1.0;
    }
    trace_bundle(tl, w, tl.surface_count(), true, rays, static_cast<RayRecord<double>*>(nullptr));
    double sum = 0.0, geo = 0.0;
    int count = 1;  // the centre ray lands on the axis
    for (int i = 1; i <= rings; ++i) {
      REQUIRE(rays.status[i] == kRayOk);
      sum += 6.0 * i * rays.y[i] * rays.y[i];
      count += 6 * i;
      geo = std::max(geo, std::abs(rays.y[i]));
    }
    const double rms = std::sqrt(sum / count);
    const double rms_ref = spot.at("rms_mm").at(w).get<double>();
    const double geo_ref = spot.at("geo_mm").at(w).get<double>();
    MESSAGE(fmt::format("{} nm: RMS {:.9f} mm (OpticStudio {}), GEO {:.9f} mm (OpticStudio {})",
                        tl.wavelengths_nm[w], rms, rms_ref, geo, geo_ref));
    CHECK(std::abs(rms - rms_ref) <= bound);
    CHECK(std::abs(geo - geo_ref) <= bound);
  }
}

namespace {

// Appends a wavelength to a lens's specs (its channel by band, weight 1 when weights are written).
void add_wavelength(Lens& lens, double wavelength_nm) {
  Specs& specs = lens.specs;
  specs.wavelengths_nm.push_back(wavelength_nm);
  specs.wavelength_channels = default_wavelength_channels(specs.wavelengths_nm);
  if (!specs.wavelength_weights.empty()) specs.wavelength_weights.push_back(1.0);
}

}  // namespace

TEST_CASE("independent: optiland run on real .zmx files, first order and real rays at 1e-9") {
  // tests/data/independent/optiland_run_rays.json (README there): optiland given the indices of
  // lensopt's glass data. Rays without aiming, through the paraxial entrance pupil of the primary
  // wavelength; the files' vignetting factors and clear apertures are not applied (optiland was
  // given neither).
  const nlohmann::json doc = read_json(independent_dir() / "optiland_run_rays.json");
  const double bound = doc.at("relative_bound").get<double>();
  int lenses = 0, paraxial_values = 0, intercepts = 0, missed = 0, surface_points = 0;
  double worst_paraxial = 0.0, worst_ray = 0.0, worst_direction = 0.0, worst_surfaces = 0.0;
  for (const nlohmann::json& ref : doc.at("lenses")) {
    const std::string name = ref.at("name").get<std::string>();
    CAPTURE(name);
    const std::filesystem::path path = test::source_dir() / ref.at("file").get<std::string>();
    Lens lens = read_lens(path);
    // The same index data as the reference: the run gave optiland the paper's model-glass
    // indices for GLAS ___BLANK (its conventions, README), which .zmx model glasses followed
    // then; they now follow OpticStudio's model glass (nd exact at 587.5618 nm, issue 29).
    for (Surface& s : lens.surfaces)
      if (s.material.kind == Material::Kind::kModel) s.material.model_glass = ModelGlass::kPaper;
    for (const nlohmann::json& um : ref.at("extra_wavelengths_um"))
      add_wavelength(lens, um.get<double>() * 1000.0);
    TraceOptions options;
    options.rings = 4;
    options.ray_aiming = false;
    TraceSystem<double> sys = prepare_lens_system(lens, options);
    REQUIRE(sys.scale == 1.0);
    // Pupil coordinates on the paraxial entrance pupil (no vignetting factors), and no clear
    // apertures (optiland was given none).
    sys.vignetting.assign(sys.vignetting.size(), VignettingFactors{});
    sys.lens.semi_diameter_mm.clear();
    const TraceLens<double>& tl = sys.lens;
    const double primary_nm = ref.at("primary_wavelength_um").get<double>() * 1000.0;
    REQUIRE(std::abs(tl.wavelengths_nm.back() - primary_nm) <= 1e-9 * primary_nm);
    auto wavelength_index = [&](double nm) {
      for (std::size_t i = 0; i < tl.wavelengths_nm.size(); ++i)
        if (std::abs(tl.wavelengths_nm[i] - nm) <= 1e-9 * nm) return static_cast<int>(i);
      FAIL("wavelength " << nm << " nm not in the traced lens");
      return -1;
    };
    double efl_primary = 0.0;
    for (const nlohmann::json& p : ref.at("paraxial"))
      if (p.at("wavelength_um").get<double>() * 1000.0 == primary_nm)
        efl_primary = p.at("EFL").get<double>();
    REQUIRE(efl_primary > 0.0);

    // Paraxial data at each wavelength: EFL and EPD relative to themselves, positions (BFL from
    // the last vertex, EPL from the first, XPL from the image) relative to the EFL.
    double lens_paraxial = 0.0;
    for (const nlohmann::json& p : ref.at("paraxial")) {
      // The lens's own value of the wavelength (index_at_nm looks it up exactly).
      const double nm =
          tl.wavelengths_nm[wavelength_index(p.at("wavelength_um").get<double>() * 1000.0)];
      const ParaxialData<double> par = paraxial_data(tl, nm);
      const double efl = p.at("EFL").get<double>();
      struct Item {
        const char* what;
        double lensopt, reference, scale;
      };
      std::vector<Item> items = {
          {"EFL", par.efl_mm, efl, efl},
          {"BFL", par.bfl_mm, p.at("BFL").get<double>(), efl},
          {"EPL", par.entrance_pupil_z_mm, p.at("EPL").get<double>(), efl},
          {"XPL", exit_pupil_from_image_mm(tl, nm), p.at("XPL_from_image").get<double>(), efl},
      };
      // The aperture is the primary wavelength's (an EPD from F/# or from the stop there).
      if (nm == tl.wavelengths_nm.back())
        items.push_back({"EPD", sys.epd_mm, p.at("EPD").get<double>(), p.at("EPD").get<double>()});
      for (const Item& item : items) {
        const double d = std::abs(item.lensopt - item.reference) / std::abs(item.scale);
        lens_paraxial = std::max(lens_paraxial, d);
        CAPTURE(nm);
        CAPTURE(item.what);
        CAPTURE(item.lensopt);
        CAPTURE(item.reference);
        CHECK(d <= bound);
        ++paraxial_values;
      }
    }

    // Image intercepts of the chief ray, the marginal rays (Px, Py) = (0, +-1), (1, 0) and the
    // zonal rays (0, +-0.5), (0.5, 0) at each field and wavelength, relative to the EFL at the
    // primary wavelength.
    double lens_ray = 0.0, lens_direction = 0.0, lens_surfaces = 0.0;
    for (const nlohmann::json& r : ref.at("rays")) {
      const double nm = r.at("wavelength_um").get<double>() * 1000.0;
      const double field = r.at("field_deg").get<double>();
      int h = -1;
      for (std::size_t i = 0; i < sys.fields_deg.size(); ++i)
        if (sys.fields_deg[i] == field) h = static_cast<int>(i);
      REQUIRE(h >= 0);
      const int w = wavelength_index(nm);
      PupilSamples pupil;
      pupil.x = {r.at("px").get<double>()};
      pupil.y = {r.at("py").get<double>()};
      RayBundle<double> rays;
      start_rays(sys, h, w, rays, &pupil);
      trace_bundle(tl, w, tl.surface_count(), true, rays, static_cast<RayRecord<double>*>(nullptr));
      CAPTURE(nm);
      CAPTURE(field);
      CAPTURE(pupil.x[0]);
      CAPTURE(pupil.y[0]);
      if (!r.at("traced").get<bool>()) {
        // The ray misses a surface in optiland (the marginal rays of a very fast lens): lensopt
        // must not return an intercept either.
        CHECK(rays.status[0] != kRayOk);
        ++missed;
        continue;
      }
      REQUIRE(rays.status[0] == kRayOk);
      const double d = std::max(std::abs(rays.x[0] - r.at("x").get<double>()),
                                std::abs(rays.y[0] - r.at("y").get<double>())) /
                       efl_primary;
      CAPTURE(rays.y[0]);
      CAPTURE(r.at("y").get<double>());
      CHECK(d <= bound);
      lens_ray = std::max(lens_ray, d);
      // Direction cosines in image space (dimensionless).
      const double dd = std::max({std::abs(rays.l[0] - r.at("L").get<double>()),
                                  std::abs(rays.m[0] - r.at("M").get<double>()),
                                  std::abs(rays.n[0] - r.at("N").get<double>())});
      CHECK(dd <= bound);
      lens_direction = std::max(lens_direction, dd);
      if (r.contains("surfaces_xy")) {
        // (x, y) on every surface of the file: lensopt's surface k + inserted, where a stop on a
        // curved surface became a flat stop surface before it (inserted from there on).
        const nlohmann::json& xy = r.at("surfaces_xy");
        const bool stop_inserted = tl.surface_count() == static_cast<int>(xy.size()) + 1;
        REQUIRE((stop_inserted || tl.surface_count() == static_cast<int>(xy.size())));
        for (int j = 0; j < static_cast<int>(xy.size()); ++j) {
          const int k = j + (stop_inserted && j >= tl.stop ? 1 : 0);
          RayBundle<double> at;
          start_rays(sys, h, w, at, &pupil);
          trace_bundle(tl, w, k + 1, false, at, static_cast<RayRecord<double>*>(nullptr));
          CAPTURE(k);
          REQUIRE(at.status[0] == kRayOk);
          const double ds = std::max(std::abs(at.x[0] - xy.at(j).at(0).get<double>()),
                                     std::abs(at.y[0] - xy.at(j).at(1).get<double>())) /
                            efl_primary;
          CHECK(ds <= bound);
          lens_surfaces = std::max(lens_surfaces, ds);
          ++surface_points;
        }
      }
      ++intercepts;
    }
    MESSAGE(
        fmt::format("{}: paraxial (EFL, BFL, EPL, XPL, EPD) within {:.2e} relative; image "
                    "intercepts within {:.2e} x EFL, directions within {:.2e}; on the "
                    "surfaces within {:.2e} x EFL ({} wavelengths, {} fields)",
                    name, lens_paraxial, lens_ray, lens_direction, lens_surfaces,
                    ref.at("wavelengths_um").size(), ref.at("fields_deg").size()));
    worst_paraxial = std::max(worst_paraxial, lens_paraxial);
    worst_ray = std::max(worst_ray, lens_ray);
    worst_direction = std::max(worst_direction, lens_direction);
    worst_surfaces = std::max(worst_surfaces, lens_surfaces);
    ++lenses;
  }
  MESSAGE(
      fmt::format("{} lenses: {} paraxial values within {:.2e}; {} rays: image intercepts "
                  "within {:.2e} x EFL, directions within {:.2e}; {} points on the surfaces "
                  "within {:.2e} x EFL; {} rays that miss a surface in both",
                  lenses, paraxial_values, worst_paraxial, intercepts, worst_ray, worst_direction,
                  surface_points, worst_surfaces, missed));
  CHECK(lenses == static_cast<int>(doc.at("lenses").size()));
}

}  // namespace test_reference_independent
