// Negative lenses (issue 31, item 3): three Thorlabs diverging lenses as vendors ship them
// (tests/data/zmx-real, sources in its README) import, and their paraxial data match a y-nu trace
// written here from the files' own lines; analyze measures the spot on the virtual image.
#include <doctest/doctest.h>
#include <fmt/format.h>

#include <cmath>
#include <fstream>
#include <sstream>
#include <string>
#include <vector>

#include "lensopt/analysis/analyze.h"
#include "lensopt/analysis/forms_image.h"
#include "lensopt/core/constants.h"
#include "lensopt/formats/zmx.h"
#include "lensopt/glass/glass.h"
#include "lensopt/lens/trace_lens.h"
#include "lensopt/paraxial/paraxial.h"
#include "lensopt/render/render.h"
#include "test_support.h"

namespace lensopt::test_zmx_negative {
namespace {

struct Independent {
  double efl_mm, bfl_mm;
};

// The paraxial EFL and BFL of a .zmx file computed here, not by lensopt's reader or paraxial
// code: its SURF / CURV / DISZ / GLAS lines (surface 0 the object, the last one the image), each
// GLAS index from SCHOTT's Sellmeier 1 coefficients written out,
//   n^2 = 1 + sum_i B_i l^2 / (l^2 - C_i)   (l in um),
// and a y-nu trace of the ray (y, w) = (1, 0): w' = w - y c (n' - n), y' = y + t w' / n';
// EFL = -1 / w and BFL = -y / w after the last lens surface.
Independent independent_paraxial(const std::filesystem::path& path, double wavelength_um) {
  std::ifstream file(path, std::ios::binary);
  std::stringstream raw;
  raw << file.rdbuf();
  std::istringstream text(raw.str());
  struct Surf {
    double c = 0, t = 0;
    std::string glass;
  };
  std::vector<Surf> surfaces;
  std::string line;
  while (std::getline(text, line)) {
    std::istringstream words(line);
    std::string key;
    words >> key;
    if (key == "SURF") surfaces.emplace_back();
    if (surfaces.empty()) continue;
    if (key == "CURV") words >> surfaces.back().c;
    if (key == "DISZ") {
      std::string t;
      words >> t;
      surfaces.back().t = t == "INFINITY" ? 0.0 : std::stod(t);
    }
    if (key == "GLAS") words >> surfaces.back().glass;
  }
  REQUIRE(surfaces.size() >= 4);
  const auto schott = load_catalog("SCHOTT");
  const double l2 = wavelength_um * wavelength_um;
  auto index = [&](const std::string& name) {
    if (name.empty()) return 1.0;
    const Glass& g = schott->at(name);
    REQUIRE(g.formula == DispersionFormula::kSellmeier1);
    const std::vector<double>& k = g.coefficients;
    return std::sqrt(1.0 + k[0] * l2 / (l2 - k[1]) + k[2] * l2 / (l2 - k[3]) +
                     k[4] * l2 / (l2 - k[5]));
  };
  double y = 1.0, w = 0.0, n = 1.0;
  for (std::size_t k = 1; k + 1 < surfaces.size(); ++k) {
    if (k > 1) y = y + surfaces[k - 1].t * w / n;
    const double n_after = index(surfaces[k].glass);
    w = w - y * surfaces[k].c * (n_after - n);
    n = n_after;
  }
  return {-1.0 / w, -y / w};
}

}  // namespace

TEST_CASE("zmx negative: three Thorlabs diverging lenses import and analyse; EFL and BFL match") {
  // Thorlabs' EFL (the part number's focal length), for orientation only: the test holds
  // lensopt to the independent trace.
  const struct {
    const char* file;
    double nominal_efl_mm;
  } cases[] = {{"thorlabs_LC1715-A.zmx", -50.0},
               {"thorlabs_LD1464-A.zmx", -50.0},
               {"thorlabs_ACN254-100-A.zmx", -100.0}};
  for (const auto& c : cases) {
    CAPTURE(c.file);
    const auto path = test::source_dir() / "tests" / "data" / "zmx-real" / c.file;
    const ZmxImport in = read_zmx(path);  // refused before: "needs a positive focal length"
    const Independent ref = independent_paraxial(path, 0.5876);  // PWAV 2: 0.5876 um
    const TraceLens<double> tl = make_trace_lens(in.lens);
    REQUIRE(tl.reference_nm() == doctest::Approx(587.6));
    const ParaxialData<double> par = paraxial_data(tl, tl.reference_nm());
    MESSAGE(std::string(c.file), ": EFL ", par.efl_mm, " mm, BFL ", par.bfl_mm,
            " mm; relative to the independent trace: EFL ",
            std::abs(par.efl_mm - ref.efl_mm) / std::abs(ref.efl_mm), ", BFL ",
            std::abs(par.bfl_mm - ref.bfl_mm) / std::abs(ref.efl_mm));
    CHECK(par.efl_mm < 0.0);
    CHECK(std::abs(par.efl_mm - ref.efl_mm) <= 1e-9 * std::abs(ref.efl_mm));
    CHECK(std::abs(par.bfl_mm - ref.bfl_mm) <= 1e-9 * std::abs(ref.efl_mm));
    CHECK(std::abs(par.efl_mm - c.nominal_efl_mm) < 0.01 * std::abs(c.nominal_efl_mm));
    // The summary specs use |EFL|: a positive F-number.
    CHECK(in.lens.specs.f_number ==
          doctest::Approx(std::abs(par.efl_mm) / in.lens.specs.aperture_value).epsilon(1e-12));

    // analyze: the virtual image the file's negative DISZ places at the paraxial focus.
    AnalyzeOptions options;
    const AnalysisReport r = analyze_lens(in.lens, options);
    CHECK_NOTHROW(check_forms_image(r));
    CHECK(r.efl_mm == doctest::Approx(par.efl_mm).epsilon(1e-14));
    CHECK(r.f_number < 0.0);  // EFL / EPD, signed as OpticStudio's image-space F/#
    CHECK(r.virtual_image);
    CHECK(r.image_distance_mm < 0.0);
    REQUIRE(r.mean_rms_spot_um);
    CHECK(std::isfinite(*r.mean_rms_spot_um));
    CHECK(r.ray_failures == 0);
    // The spot is measured on the virtual image: moving the image plane 5 mm away from the
    // paraxial focus (either way) makes it larger.
    for (const double shift : {-5.0, 5.0}) {
      Lens moved = in.lens;
      moved.surfaces.back().thickness_mm += shift;
      const AnalysisReport rm = analyze_lens(moved, options);
      REQUIRE(rm.mean_rms_spot_um);
      CHECK(*rm.mean_rms_spot_um > *r.mean_rms_spot_um);
    }
    const std::string text = format_report_text(r);
    CHECK(text.find("virtual") != std::string::npos);
  }
}

TEST_CASE("zmx negative: an afocal lens without the flag imports in afocal mode, with a warning") {
  // Two plano-convex model-glass elements (nd exact at the primary 587.5618 nm) spaced so that
  // the ray (y, w) = (1, 0) leaves parallel: after surface 1 w = -c (n - 1); surface 4 (-c)
  // gives w' = w - y4 c (n - 1) = 0 for y4 = -1, and y4 = 1 + 2 t w / n + d w, so
  // d = (-2 - 2 t w / n) / w.
  const double n = 1.5168, c = 0.02, t = 5.0;
  const double w = -c * (n - 1.0);
  const double d = (-2.0 - 2.0 * t * w / n) / w;
  const std::string text = fmt::format(
      "MODE SEQ\nUNIT MM X W X CM MR CPMM\nENPD 10\nFTYP 0 0 1 1 0 0 0\nXFLN 0\nYFLN 0\n"
      "WAVM 1 0.5875618 1\nPWAV 1\n"
      "SURF 0\n  CURV 0\n  DISZ INFINITY\n"
      "SURF 1\n  STOP\n  CURV {c:.17g}\n  DISZ {t:.17g}\n  GLAS ___BLANK 1 0 {n:.17g} 64.17\n"
      "SURF 2\n  CURV 0\n  DISZ {d:.17g}\n"
      "SURF 3\n  CURV 0\n  DISZ {t:.17g}\n  GLAS ___BLANK 1 0 {n:.17g} 64.17\n"
      "SURF 4\n  CURV {mc:.17g}\n  DISZ 50\n"
      "SURF 5\n  CURV 0\n  DISZ 0\n",
      fmt::arg("c", c), fmt::arg("t", t), fmt::arg("n", n), fmt::arg("d", d), fmt::arg("mc", -c));
  // It used to be refused; now it reads in afocal mode (analysis/afocal.h), the FTYP line's
  // warning saying the file did not set Afocal Image Space.
  const ZmxImport imported = parse_zmx(text, "telescope.zmx");
  CHECK(imported.lens.specs.afocal);
  int afocal_warnings = 0;
  for (const std::string& w : imported.warnings)
    if (w.find("Afocal Image Space") != std::string::npos) {
      ++afocal_warnings;
      CHECK(w.find("telescope.zmx:4") != std::string::npos);  // the FTYP line
    }
  CHECK(afocal_warnings == 1);
}

TEST_CASE("zmx negative: off-axis fields of a diverging lens; render refuses with the reason") {
  const auto path = test::source_dir() / "tests" / "data" / "zmx-real" / "thorlabs_LD1464-A.zmx";
  Lens lens = read_zmx(path).lens;
  lens.specs.fields = {{0.0, 1.0, {}}, {3.0, 1.0, {}}, {6.0, 1.0, {}}};
  lens.specs.half_field_deg = 6.0;
  AnalyzeOptions options;
  options.trace.rings = 8;
  const AnalysisReport r = analyze_lens(lens, options);
  CHECK_NOTHROW(check_forms_image(r));
  REQUIRE(r.fields.size() == 3);
  // The virtual image is upright: the chief ray's image lies on the other side of the axis
  // from a converging lens's (negative y), at the paraxial height EFL tan(theta) there.
  const TraceLens<double> tl = make_trace_lens(lens);
  const ParaxialData<double> par = paraxial_data(tl, tl.reference_nm());
  for (const FieldReport& f : r.fields) {
    CAPTURE(f.field_deg);
    CHECK(std::isfinite(f.distortion_percent));
    REQUIRE(f.rms_spot_um);
    CHECK(std::isfinite(*f.rms_spot_um));
    if (f.field_deg == 0.0) continue;
    CHECK(f.reference_y_mm < 0.0);
    CHECK(f.centroid_y_mm < 0.0);
    // The paraxial chief ray on the written (virtual) image plane: for a thin system seen from
    // the image side, y = (EFL - BFL + t_K) tan theta with the chief ray through the front
    // vertex (z_EP = 0: the stop is at surface 1); here from the y-nu trace of the lens.
    REQUIRE(par.entrance_pupil_z_mm == doctest::Approx(0.0));
    const double t = std::tan(f.field_deg * kPi / 180.0);
    CHECK(f.reference_y_mm ==
          doctest::Approx(paraxial_image_height(tl, 0.0, t, tl.reference_nm())).epsilon(1e-12));
  }
  CHECK(r.angular_magnification > 0.0);
  try {
    build_imaging_model(lens, options.trace, PsfOptions{});
    FAIL("a diverging lens was rendered");
  } catch (const Error& error) {
    const std::string what = error.what();
    CHECK(what.find("diverges") != std::string::npos);
    CHECK(what.find("thorlabs_LD1464-A.zmx") != std::string::npos);
  }
}

}  // namespace lensopt::test_zmx_negative
