// .zmx glasses: OpticStudio's model glass (issue 29), the Zemax catalog names of the catalogs
// made from the refractiveindex.info database, a glass found outside the file's catalogs, and a
// real file that names them (issue 30).
#include <doctest/doctest.h>

#include <cmath>
#include <fstream>
#include <sstream>
#include <string>

#include "lensopt/core/error.h"
#include "lensopt/formats/lens_file.h"
#include "lensopt/formats/zmx.h"
#include "lensopt/glass/dispersion.h"
#include "lensopt/glass/glass.h"
#include "lensopt/lens/lens_io.h"
#include "lensopt/lens/trace_lens.h"
#include "lensopt/lens/validate.h"
#include "lensopt/paraxial/paraxial.h"
#include "test_support.h"

namespace lensopt::test_zmx_glasses {
namespace {

constexpr double kD_nm = 587.5618;

// A singlet at f/4 with the given GLAS line on surface 1, GCAT as given.
std::string singlet_zmx(const std::string& gcat, const std::string& glas,
                        const std::string& waves =
                            "WAVM 1 0.4861327 1\nWAVM 2 0.5875618 1\n"
                            "WAVM 3 0.6562725 1\nPWAV 2\n") {
  return "VERS 190513 80 123457\nMODE SEQ\nNAME singlet\nUNIT MM X W X CM MR CPMM\nENPD 10\n" +
         (gcat.empty() ? std::string() : "GCAT " + gcat + "\n") +
         "FTYP 0 0 1 3 0 0 0\nXFLN 0\nYFLN 0\n" + waves +
         "SURF 0\n  TYPE STANDARD\n  CURV 0\n  DISZ INFINITY\n"
         "SURF 1\n  STOP\n  TYPE STANDARD\n  CURV 0.02\n  DISZ 5\n  " +
         glas +
         "\n"
         "SURF 2\n  TYPE STANDARD\n  CURV -0.005\n  DISZ 45\n"
         "SURF 3\n  TYPE STANDARD\n  CURV 0\n  DISZ 0\n";
}

int first_glass(const Lens& lens) {
  for (std::size_t k = 0; k < lens.surfaces.size(); ++k)
    if (!lens.surfaces[k].material.is_air()) return static_cast<int>(k);
  return -1;
}

bool any_warning_has(const std::vector<std::string>& warnings, const std::string& text) {
  for (const std::string& w : warnings)
    if (w.find(text) != std::string::npos) return true;
  return false;
}

}  // namespace

TEST_CASE("zmx: a model glass's index at 587.5618 nm is its nd exactly (OpticStudio's model)") {
  // Fails on the old code: the paper's Abbe model, anchored at 587.6 nm, gave n(587.5618) =
  // nd + 1.97e-4 (nd - 1) / vd, 6.3e-6 above nd for this glass.
  for (const std::string& glas : {std::string("GLAS ___BLANK 1 0 1.80518 25.36 0 0 0 0 0 0"),
                                  std::string("GLAS ___BLANK 1 0 1.80518 25.36")}) {
    CAPTURE(glas);
    const ZmxImport in = parse_zmx(singlet_zmx("SCHOTT", glas), "model.zmx");
    const int k = first_glass(in.lens);
    REQUIRE(k >= 0);
    const Material& m = in.lens.surfaces[k].material;
    CHECK(m.kind == Material::Kind::kModel);
    CHECK(m.model_glass == ModelGlass::kZemax);
    const TraceLens<double> tl = make_trace_lens(in.lens);
    CHECK(tl.index_at_nm(k, kD_nm) == 1.80518);
    // vd as stated, with OpticStudio's F and C lines.
    const double n_f = tl.index_at_nm(k, 486.1327), n_c = tl.index_at_nm(k, 656.2725);
    CHECK(std::abs(0.80518 / (n_f - n_c) - 25.36) < 1e-9);
    // The paraxial EFL at d is the thick-lens formula with n = nd exactly.
    const double n = 1.80518, c1 = 0.02, c2 = -0.005, t = 5.0;
    const double power = (n - 1) * (c1 - c2) + (n - 1) * (n - 1) * t * c1 * c2 / n;
    CHECK(std::abs(paraxial_data(tl, kD_nm).efl_mm - 1.0 / power) < 1e-12 / power);
  }
  // dPgF is the seventh field; the TOML lens keeps the model and dPgF.
  const ZmxImport in =
      parse_zmx(singlet_zmx("", "GLAS ___BLANK 1 0 1.80518 25.36 0.0136 0 0 0 0 0"), "m.zmx");
  const Material& m = in.lens.surfaces[first_glass(in.lens)].material;
  CHECK(m.dpgf == 0.0136);
  const std::string toml = format_lens_toml(in.lens);
  CHECK(toml.find("model = \"opticstudio\", dpgf = 0.0136") != std::string::npos);
  const Lens back = parse_lens_toml(toml, "back.toml");
  const Material& mb = back.surfaces[first_glass(back)].material;
  CHECK(mb.model_glass == ModelGlass::kZemax);
  CHECK(mb.dpgf == 0.0136);
  CHECK(make_trace_lens(back).index_at_nm(first_glass(back), 435.8343) ==
        make_trace_lens(in.lens).index_at_nm(first_glass(in.lens), 435.8343));
}

TEST_CASE("zmx: a lens lensopt writes keeps its model glasses' model when read back") {
  // The paper's model glass: the written file notes it, and lensopt reads it back so.
  Lens paper = read_lens(test::source_dir() / "lenses" / "doublet.toml");
  paper.surfaces[0].material = Material::model(1.7234567890123, 41.123456789);
  const std::string zmx = format_zmx(paper);
  CHECK(zmx.find("NOTE 0 lensopt model_glass paper") != std::string::npos);
  const Lens back = parse_zmx(zmx, "paper.zmx").lens;
  CHECK(back.surfaces[0].material.model_glass == ModelGlass::kPaper);
  CHECK(make_trace_lens(back).index_at_nm(0, kD_nm) ==
        make_trace_lens(paper).index_at_nm(0, kD_nm));
  // OpticStudio's (a .zmx import): no note, dPgF on the GLAS line.
  const ZmxImport in =
      parse_zmx(singlet_zmx("", "GLAS ___BLANK 1 0 1.80518 25.36 0.0136 0 0 0 0 0"), "m.zmx");
  const std::string again = format_zmx(in.lens);
  CHECK(again.find("lensopt model_glass") == std::string::npos);
  const Lens zemax = parse_zmx(again, "again.zmx").lens;
  const Material& m = zemax.surfaces[first_glass(zemax)].material;
  CHECK(m.model_glass == ModelGlass::kZemax);
  CHECK(m.dpgf == 0.0136);
}

TEST_CASE("zmx: the paper's lenses keep the paper's model glass") {
  const Lens lens = read_lens(test::source_dir() / "lenses" / "doublet.toml");
  for (const Surface& s : lens.surfaces)
    if (s.material.kind == Material::Kind::kModel)
      CHECK(s.material.model_glass == ModelGlass::kPaper);
  const TraceLens<double> tl = make_trace_lens(lens);
  for (int k = 0; k < tl.surface_count(); ++k)
    if (tl.is_glass[k]) CHECK(tl.is_glass[k] == static_cast<char>(ModelGlass::kPaper));
}

TEST_CASE("zmx: Zemax catalog names find the database catalogs") {
  // GCAT NIKON-HIKARI finds J-LASF08A; GCAT INFRARED finds GERMANIUM at 10 um.
  const ZmxImport hikari =
      parse_zmx(singlet_zmx("NIKON-HIKARI", "GLAS J-LASF08A 0 0 1.883 40.69"), "h.zmx");
  const Material& m = hikari.lens.surfaces[first_glass(hikari.lens)].material;
  REQUIRE(m.kind == Material::Kind::kCatalog);
  CHECK(m.glass->catalog == "HIKARI");
  CHECK(std::abs(m.glass->index(kD_nm) - 1.883) < 1e-5);
  CHECK_FALSE(any_warning_has(hikari.warnings, "none of the file's catalogs"));
  const ZmxImport ge = parse_zmx(
      singlet_zmx("SCHOTT INFRARED", "GLAS GERMANIUM 0 0 4 0", "WAVM 1 10 1\nPWAV 1\n"), "g.zmx");
  CHECK(ge.lens.surfaces[first_glass(ge.lens)].material.glass->catalog == "INFRARED");
}

TEST_CASE("zmx: a glass outside the file's catalogs is used with a warning naming its catalog") {
  const ZmxImport in = parse_zmx(singlet_zmx("SCHOTT", "GLAS J-LASF08A 0 0 1.883 40.69"), "x.zmx");
  const Material& m = in.lens.surfaces[first_glass(in.lens)].material;
  REQUIRE(m.kind == Material::Kind::kCatalog);
  CHECK(m.glass->catalog == "HIKARI");
  CHECK(any_warning_has(in.warnings, "glass 'J-LASF08A' is in none of the file's catalogs"));
  CHECK(any_warning_has(in.warnings, "HIKARI"));
  // A name in no shipped catalog still fails, naming the catalogs searched.
  CHECK_THROWS_WITH_AS(parse_zmx(singlet_zmx("SCHOTT", "GLAS NO-SUCH-GLASS 0 0 1.6 40"), "y.zmx"),
                       doctest::Contains("unknown glass 'NO-SUCH-GLASS'"), Error);
}

TEST_CASE("zmx: a wavelength outside a glass's range is warned once, naming glass and file") {
  const ZmxImport in = parse_zmx(
      singlet_zmx("INFRARED", "GLAS CAF2 0 0 1.43 95", "WAVM 1 0.5875618 1\nWAVM 2 11 1\nPWAV 1\n"),
      "range.zmx");
  const auto warnings = glass_range_warnings(in.lens);
  REQUIRE(warnings.size() == 1);
  CHECK(warnings[0].find("range.zmx") != std::string::npos);
  CHECK(warnings[0].find("glass CAF2 (catalog INFRARED") != std::string::npos);
  CHECK(warnings[0].find("11000 nm") != std::string::npos);
}

namespace {

// The file's text as ASCII: UTF-16 LE (with a BOM) keeps every other byte.
std::string ascii_text(const std::filesystem::path& path) {
  std::ifstream file(path, std::ios::binary);
  std::ostringstream bytes;
  bytes << file.rdbuf();
  const std::string raw = bytes.str();
  if (raw.size() < 2 || static_cast<unsigned char>(raw[0]) != 0xFF ||
      static_cast<unsigned char>(raw[1]) != 0xFE)
    return raw;
  std::string out;
  for (std::size_t i = 2; i < raw.size(); i += 2) out += raw[i];
  return out;
}

// An independent paraxial EFL of a .zmx file: its own CURV / DISZ / GLAS lines (read here, not by
// lensopt's reader), the index of each GLAS name from `index_of`, and a y-nu trace:
//   w' = w - y c (n' - n),  y' = y + t w / n',  EFL = -1 / w at the image for y = 1, w = 0.
template <typename IndexOf>
double independent_efl(const std::filesystem::path& path, IndexOf index_of) {
  std::istringstream text(ascii_text(path));
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
  REQUIRE(surfaces.size() > 3);
  double y = 1.0, w = 0.0, n = 1.0;
  for (std::size_t k = 1; k + 1 < surfaces.size(); ++k) {
    const double n_after = surfaces[k].glass.empty() ? 1.0 : index_of(surfaces[k].glass);
    w = w - y * surfaces[k].c * (n_after - n);
    n = n_after;
    if (k + 2 < surfaces.size()) y = y + surfaces[k].t * w / n;
  }
  return -1.0 / w;
}

}  // namespace

TEST_CASE("zmx real: US 5831776 (ray-optics) with GCAT SCHOTT MISC: fused silica at 248 nm") {
  const auto path =
      test::source_dir() / "tests" / "data" / "zmx-real" / "rayoptics_US05831776-1.zmx";
  const ZmxImport in = read_zmx(path);
  CHECK_FALSE(any_warning_has(in.warnings, "not found"));
  // SILICA is MISC's fused silica (Malitson).
  int glasses = 0;
  for (const Surface& s : in.lens.surfaces) {
    if (s.material.is_air()) continue;
    ++glasses;
    REQUIRE(s.material.kind == Material::Kind::kCatalog);
    CHECK(s.material.glass->catalog == "MISC");
    CHECK(s.material.glass->name == "SILICA");
  }
  CHECK(glasses > 5);
  // Independent: Malitson's fused-silica formula as the data gives it (refractiveindex.info
  // main/SiO2/nk/Malitson.yml, formula 1: n^2 = 1 + sum B l^2 / (l^2 - C^2)), written out here.
  const double l = 0.248, l2 = l * l;
  const double b[3] = {0.6961663, 0.4079426, 0.8974794}, c[3] = {0.0684043, 0.1162414, 9.896161};
  double n2 = 1.0;
  for (int i = 0; i < 3; ++i) n2 += b[i] * l2 / (l2 - c[i] * c[i]);
  const double n_silica = std::sqrt(n2);
  const double efl = independent_efl(path, [&](const std::string& glass) {
    REQUIRE(glass == "SILICA");
    return n_silica;
  });
  const double lensopt_efl = paraxial_data(make_trace_lens(in.lens), 248.0).efl_mm;
  MESSAGE("US 5831776: EFL ", lensopt_efl, " mm, independent ", efl, " mm");
  CHECK(std::abs(lensopt_efl - efl) < 1e-12 * std::abs(efl));
}

TEST_CASE("zmx real: Edmund 55278 (ray-optics) with GCAT SCHOTT INFRARED MISC") {
  const auto path = test::source_dir() / "tests" / "data" / "zmx-real" / "rayoptics_zmax_55278.zmx";
  const ZmxImport in = read_zmx(path);
  // INFRARED and MISC are found now (they were "not found" before); SF5 and BK7 come from
  // SCHOTT, the first catalog, as in OpticStudio.
  CHECK_FALSE(any_warning_has(in.warnings, "not found"));
  for (const Surface& s : in.lens.surfaces)
    if (!s.material.is_air()) CHECK(s.material.glass->catalog == "SCHOTT");
  // Independent: the Sellmeier 1 formula written out here with SCHOTT's coefficients (the same
  // formula data), at the primary wavelength 587.6 nm.
  const auto schott = load_catalog("SCHOTT");
  const double l = 0.5876, l2 = l * l;
  const double efl = independent_efl(path, [&](const std::string& name) {
    const Glass& g = schott->at(name);
    REQUIRE(g.formula == DispersionFormula::kSellmeier1);
    const std::vector<double>& k = g.coefficients;
    return std::sqrt(1.0 + k[0] * l2 / (l2 - k[1]) + k[2] * l2 / (l2 - k[3]) +
                     k[4] * l2 / (l2 - k[5]));
  });
  const TraceLens<double> tl = make_trace_lens(in.lens);
  const double lensopt_efl = paraxial_data(tl, tl.reference_nm()).efl_mm;
  MESSAGE("Edmund 55278: EFL ", lensopt_efl, " mm, independent ", efl, " mm");
  CHECK(std::abs(lensopt_efl - efl) < 1e-12 * std::abs(efl));
}

}  // namespace lensopt::test_zmx_glasses
