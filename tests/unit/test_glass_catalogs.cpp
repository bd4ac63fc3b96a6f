// The catalogs made from the refractiveindex.info database (tools/make-rii-catalogs.py), the
// database's formulas, OpticStudio's model glass and the Zemax catalog names.
#include <ceres/jet.h>
#include <doctest/doctest.h>

#include <cmath>
#include <fstream>
#include <map>
#include <set>
#include <sstream>
#include <string>

#include "lensopt/core/error.h"
#include "lensopt/glass/dispersion.h"
#include "lensopt/glass/formulas.h"
#include "lensopt/glass/glass.h"
#include "test_support.h"

namespace lensopt::test_glass_catalogs {
namespace {

constexpr double kD_nm = 587.5618, kF_nm = 486.1327, kC_nm = 656.2725, kG_nm = 435.8343;

double abbe_number(const Glass& g) {
  return (g.index(kD_nm) - 1.0) / (g.index(kF_nm) - g.index(kC_nm));
}

// "    nd: 1.883000" -> 1.883 from a database YAML (the PROPERTIES / SPECS block); nullopt if none.
std::optional<double> yaml_number(const std::string& text, const std::string& key) {
  std::istringstream in(text);
  std::string line;
  while (std::getline(in, line)) {
    const std::size_t start = line.find_first_not_of(' ');
    if (start == std::string::npos || start < 2) continue;
    if (line.compare(start, key.size() + 1, key + ":") != 0) continue;
    return std::stod(line.substr(start + key.size() + 1));
  }
  return std::nullopt;
}

std::string read_text(const std::filesystem::path& path) {
  std::ifstream in(path, std::ios::binary);
  std::ostringstream out;
  out << in.rdbuf();
  return out.str();
}

// Sumita glasses whose database formula (a transcription of Sumita's Zemax catalog 2017-02-02)
// misses Sumita's own nd / vd (5 decimals / 1 decimal) by more than 1e-5 / 0.05: the vendor's
// catalog disagrees with itself, as OpticStudio with the same catalog would. They are checked at
// 4e-5 / 0.25 instead, and the test fails if one of them comes within the strict bounds (then it
// leaves this list).
const std::set<std::string> kSumitaSelfInconsistent = {
    "K-BaSF4",    "K-BaSF5",     "K-CD45(M)",  "K-CSK120(M)", "K-CSK120",    "K-CaFK95(M)",
    "K-CaFK95",   "K-FIR97UV",   "K-GFK68",    "K-LaF2",      "K-LaFK50(M)", "K-LaFK50T(M)",
    "K-LaFK58",   "K-LaFK60(M)", "K-LaK14",    "K-LaKn2",     "K-LaKn4",     "K-LaKn5",
    "K-LaSFn14",  "K-LaSFn17",   "K-LaSFn21",  "K-PBK40(M)",  "K-PBK50(M)",  "K-PBK50",
    "K-PFK80(M)", "K-PFK80",     "K-PFK85(M)", "K-PG325(M)",  "K-PG375(M)",  "K-PMK30(M)",
    "K-PMK30",    "K-PSFn1(M)",  "K-PSFn1",    "K-PSFn2(M)",  "K-PSFn2",     "K-PSFn214(M)",
    "K-PSFn3(M)", "K-PSFn3",     "K-PSK100",   "K-PSK11",     "K-SFLD11",    "K-SK15",
    "K-SK5",      "K-SKLD120",   "K-SSK1",     "K-VC179(M)",  "K-VC181(M)",  "K-VC89(M)",
    "K-VC89",     "K-VC91"};

}  // namespace

TEST_CASE("glass: OpticStudio's model glass: nd exact at 587.5618 nm, vd and PgF as stated") {
  for (const auto& [nd, vd, dpgf] : std::vector<std::tuple<double, double, double>>{
           {1.62041, 60.32, 0.0}, {1.80518, 25.36, 0.0136}, {1.5168, 64.17, -0.0009}}) {
    CAPTURE(nd);
    // Exactly nd (bit for bit), as OpticStudio's model glass; the paper's model is anchored at
    // 587.6 nm and misses it (the defect: EFL errors of 1e-7 to 7e-6 on patent lenses).
    CHECK(zemax_model_index(nd, vd, dpgf, kD_nm) == nd);
    CHECK(abbe_index(nd, vd, kD_nm) != nd);
    const double n_f = zemax_model_index(nd, vd, dpgf, kF_nm);
    const double n_c = zemax_model_index(nd, vd, dpgf, kC_nm);
    const double n_g = zemax_model_index(nd, vd, dpgf, kG_nm);
    CHECK(std::abs((nd - 1.0) / (n_f - n_c) - vd) < 1e-10 * vd);
    CHECK(std::abs((n_g - n_f) / (n_f - n_c) - (0.6438 - 0.001682 * vd + dpgf)) < 1e-10);
  }
  // Jets: d n / d nd at 587.5618 nm is 1 and d n / d vd is 0 (nd does not depend on vd there).
  using J = ceres::Jet<double, 2>;
  const J nd(1.62041, 0), vd(60.32, 1);
  const J n = zemax_model_index(nd, vd, K<J>(0.0), kD_nm);
  CHECK(n.v[0] == 1.0);
  CHECK(n.v[1] == 0.0);
  // Against finite differences at 486.1327 nm.
  const J nf = zemax_model_index(nd, vd, K<J>(0.0), kF_nm);
  const double h = 1e-6;
  const double fd_nd = (zemax_model_index(1.62041 + h, 60.32, 0.0, kF_nm) -
                        zemax_model_index(1.62041 - h, 60.32, 0.0, kF_nm)) /
                       (2 * h);
  const double fd_vd = (zemax_model_index(1.62041, 60.32 + h, 0.0, kF_nm) -
                        zemax_model_index(1.62041, 60.32 - h, 0.0, kF_nm)) /
                       (2 * h);
  CHECK(std::abs(nf.v[0] - fd_nd) < 1e-8);
  CHECK(std::abs(nf.v[1] - fd_vd) < 1e-8);
}

TEST_CASE("glass: the database's formulas, templated, equal their stated forms") {
  // Formula 1 (Sellmeier, C squared): Malitson's fused silica at 587.5618 nm, n = 1.458464 in
  // lensopt's MISC catalog; the template on a Jet gives the same value and dn/dl by FD.
  const std::vector<double> silica = {0,         0.6961663, 0.0684043, 0.4079426,
                                      0.1162414, 0.8974794, 9.896161};
  const double l = 0.5875618;
  const double n = formula_index(DispersionFormula::kRiiSellmeier, silica, l);
  double sum = 0;
  for (int i = 1; i + 1 < 7; i += 2)
    sum += silica[i] * l * l / (l * l - silica[i + 1] * silica[i + 1]);
  CHECK(n == doctest::Approx(std::sqrt(1 + sum)).epsilon(1e-15));
  CHECK(std::abs(n - 1.458464) < 1e-6);
  using J = ceres::Jet<double, 1>;
  const J nj = formula_index(DispersionFormula::kRiiSellmeier, silica, J(l, 0));
  CHECK(nj.a == n);
  const double h = 1e-7;
  const double fd = (formula_index(DispersionFormula::kRiiSellmeier, silica, l + h) -
                     formula_index(DispersionFormula::kRiiSellmeier, silica, l - h)) /
                    (2 * h);
  CHECK(std::abs(nj.v[0] - fd) < 1e-7);
  // Formula 4 (ZnS, Debenham): n^2 = C1 + C2 l^C3/(l^2 - C4^C5) + C6 l^C7/(l^2 - C8^C9).
  const std::vector<double> zns = {8.393, 0.14383, 0, 0.2421, 2, 4430.99, 0, 36.71, 2};
  const double l2 = 1.0;
  CHECK(formula_index(DispersionFormula::kRiiInfo, zns, 1.0) ==
        doctest::Approx(
            std::sqrt(8.393 + 0.14383 / (l2 - 0.2421 * 0.2421) + 4430.99 / (l2 - 36.71 * 36.71)))
            .epsilon(1e-15));
  // Formula 5 (Cauchy) and 3 (polynomial), and a table: its samples exactly, a cubic between.
  const std::vector<double> cauchy = {1.5, 0.004, -2, 0.0001, -4};
  CHECK(formula_index(DispersionFormula::kRiiCauchy, cauchy, 0.5) ==
        doctest::Approx(1.5 + 0.004 / 0.25 + 0.0001 / 0.0625).epsilon(1e-15));
  const std::vector<double> table = {0.4, 1.53, 0.5, 1.52, 0.6, 1.515, 0.7, 1.512, 0.8, 1.510};
  CHECK(formula_index(DispersionFormula::kTable, table, 0.6) == 1.515);
  const double mid = formula_index(DispersionFormula::kTable, table, 0.55);
  CHECK(mid < 1.52);
  CHECK(mid > 1.515);
}

TEST_CASE("glass: every glass of the database catalogs gives its vendor's nd and vd") {
  std::size_t checked = 0;
  for (const std::string& name : database_catalog_names()) {
    CAPTURE(name);
    const auto catalog = load_catalog(name);
    CHECK(catalog->name == name);
    CHECK(catalog->warnings.empty());
    REQUIRE_FALSE(catalog->glasses.empty());
    for (const Glass& g : catalog->glasses) {
      CAPTURE(g.name);
      REQUIRE(g.formula_supported);
      CHECK(g.comment.rfind("source: ", 0) == 0);
      CHECK(g.max_wavelength_um > g.min_wavelength_um);
      if (g.nd == 0.0) {
        // An infrared material: no nd or vd (its range excludes the visible).
        CHECK_FALSE((g.min_wavelength_um <= kF_nm / 1000 && g.max_wavelength_um >= kC_nm / 1000));
        continue;
      }
      const bool loose = name == "SUMITA" && kSumitaSelfInconsistent.count(g.name) > 0;
      const double nd_error = std::abs(g.index(kD_nm) - g.nd);
      const double vd_error = std::abs(abbe_number(g) - g.vd);
      if (loose) {
        CHECK(nd_error < 4e-5);
        CHECK(vd_error < 0.25);
        CHECK((nd_error > 1e-5 || vd_error > 0.05));
      } else {
        CHECK(nd_error < 1e-5);
        CHECK(vd_error < 0.05);
      }
      ++checked;
    }
  }
  CHECK(checked > 600);
}

TEST_CASE("glass: the database catalogs' nd and vd are the vendor's published figures") {
  LENSOPT_REQUIRE_SHARED(shared);
  const std::filesystem::path rii = shared / "data" / "rii";
  std::size_t compared = 0;
  for (const std::string& name : database_catalog_names()) {
    const auto catalog = load_catalog(name);
    for (const Glass& g : catalog->glasses) {
      CAPTURE(g.name);
      // "source: <path> (sha256 ...); reference"
      const std::string path = g.comment.substr(8, g.comment.find(' ', 8) - 8);
      const std::string text = read_text(rii / path);
      REQUIRE_FALSE(text.empty());
      const auto nd = yaml_number(text, "nd");
      const auto vd = yaml_number(text, "Vd");
      if (!nd || !vd) continue;  // no published figures: the NM line holds computed ones
      CHECK(g.nd == *nd);
      CHECK(g.vd == *vd);
      ++compared;
    }
  }
  CHECK(compared > 500);
}

TEST_CASE("glass: crystals against a second source at three wavelengths") {
  // Crystran's handbook tables (specs/crystran in the data, 4 or 5 decimals, other samples and
  // temperatures) against the formulas lensopt ships (Malitson's CaF2, BaF2 and fused silica):
  // agreement within the tables' last digit and the spread between samples.
  const auto infrared = load_catalog("INFRARED");
  struct Point {
    const char* glass;
    double um, n, tolerance;
  };
  for (const Point& p : std::vector<Point>{{"CAF2", 0.486, 1.4370, 1e-4},
                                           {"CAF2", 0.588, 1.4339, 1e-4},
                                           {"CAF2", 2.058, 1.4236, 1e-4},
                                           {"BAF2", 0.5461, 1.4759, 1e-4},
                                           {"BAF2", 0.5893, 1.4744, 1e-4},
                                           {"BAF2", 5.138, 1.4501, 1e-4},
                                           {"F_SILICA", 0.40, 1.47012, 1e-5},
                                           {"F_SILICA", 0.60, 1.45804, 1e-5},
                                           {"F_SILICA", 1.00, 1.45042, 1e-5}}) {
    CAPTURE(p.glass);
    CAPTURE(p.um);
    CHECK(std::abs(infrared->at(p.glass).index(p.um * 1000) - p.n) < p.tolerance);
  }
  // Nikon's CaF2 (HIKARI NICF-V, its data sheet's nd) against Malitson's CaF2 at the d line.
  CHECK(std::abs(load_catalog("HIKARI")->at("NICF-V").nd - infrared->at("CAF2").index(kD_nm)) <
        3e-5);
}

TEST_CASE("agf: lensopt's formula ids, tables and GC comments") {
  const Catalog c = parse_agf(
      "NM T 120 0 1.5 60 0 0\nGC source: made up\nGC second line\n"
      "CD 0.4 1.53 0.5 1.52 0.6 1.515 0.7 1.512\nLD 0.4 0.7\n"
      "NM S 101 0 1.458464 67.8 0 0\n"
      "CD 0 0.6961663 0.0684043 0.4079426 0.1162414 0.8974794 9.896161\nLD 0.21 6.7\n",
      "made.agf");
  REQUIRE(c.glasses.size() == 2);
  CHECK(c.warnings.empty());
  CHECK(c.glasses[0].formula == DispersionFormula::kTable);
  CHECK(c.glasses[0].comment == "source: made up second line");
  CHECK(c.glasses[0].coefficients.size() == 8);  // the table's own count, not padded to 10
  CHECK(c.glasses[0].index(500.0) == 1.52);
  CHECK(c.glasses[1].coefficients.size() == 7);
  CHECK(std::abs(c.glasses[1].index(587.5618) - 1.458464) < 1e-6);
  CHECK(formula_name(DispersionFormula::kRiiSellmeier) == "RII Sellmeier");
  // A table out of wavelength order, or with an odd count, is an error naming file and line.
  CHECK_THROWS_WITH_AS(parse_agf("NM T 120 0 1.5 60 0 0\nCD 0.5 1.52 0.4 1.53\n", "bad.agf"),
                       doctest::Contains("bad.agf:2"), Error);
  CHECK_THROWS_WITH_AS(parse_agf("NM T 120 0 1.5 60 0 0\nCD 0.4 1.53 0.5 1.52 0.6\n", "odd.agf"),
                       doctest::Contains("(wavelength, index) pairs"), Error);
}

TEST_CASE("glass: Zemax catalog names find the shipped catalogs") {
  CHECK(zemax_catalog_alias("NIKON-HIKARI") == "HIKARI");
  CHECK(zemax_catalog_alias("nikon") == "HIKARI");
  CHECK(zemax_catalog_alias("SUMITA_AUG2011") == "SUMITA");
  CHECK(zemax_catalog_alias("SCHOTT_2017") == "SCHOTT");
  CHECK(zemax_catalog_alias("MY_GLASSES") == "MY_GLASSES");
  CHECK(load_catalog("NIKON-HIKARI")->find("J-LASF08A") != nullptr);
  CHECK(load_catalog("SUMITA_AUG2011")->find("K-SSK1") != nullptr);
  for (const char* g : {"GERMANIUM", "ZNSE", "SILICON", "CAF2"})
    CHECK(load_catalog("INFRARED")->find(g) != nullptr);
  for (const char* g : {"F_SILICA", "CAF2", "SAPPHIRE"})
    CHECK(load_catalog("MISC")->find(g) != nullptr);
  // Corning 7980 (C79-80) is fused silica: Malitson's formula, as MISC's F_SILICA.
  CHECK(load_catalog("CORNING")->at("C79-80").index(kD_nm) ==
        load_catalog("MISC")->at("F_SILICA").index(kD_nm));
  // LZOS's tabulated glasses (named LZ_<name> as in OpticStudio) give their table at the d line
  // (0.58756 um) within the table's interpolation to 587.5618 nm.
  const Glass& k8 = load_catalog("LZOS")->at("LZ_K8");
  CHECK(std::abs(k8.index(kD_nm) - 1.516373) < 1e-6);
}

}  // namespace lensopt::test_glass_catalogs
