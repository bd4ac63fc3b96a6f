// Glass catalogs: every AGF dispersion formula against values worked out independently from its
// equation (and published catalog indices), the AGF reader's encodings and errors, catalog
// look-up, the built-in Ohara catalog, and every glass of the vendor files in ../shared.
#include <doctest/doctest.h>
#include <unistd.h>

#include <algorithm>
#include <cmath>
#include <cstdlib>
#include <fstream>
#include <map>
#include <sstream>
#include <string>

#include "lensopt/core/error.h"
#include "lensopt/glass/glass.h"
#include "test_support.h"

namespace test_glass {

using namespace lensopt;

namespace {

constexpr double kD_nm = 587.5618;  // helium d line
constexpr double kF_nm = 486.1327;  // hydrogen F line
constexpr double kC_nm = 656.2725;  // hydrogen C line

// Schott N-BK7, Sellmeier 1 (B1 C1 B2 C2 B3 C3, C in um^2), from Schott's data sheet.
constexpr const char* kBk7Sellmeier =
    "1.03961212 6.00069867E-03 2.31792344E-01 2.00179144E-02 1.01046945 1.03560653E+02";
// Schott BK7 in the older Schott power series (A0..A5), from Schott's pre-1992 catalog.
constexpr const char* kBk7Schott =
    "2.2718929 -1.0108077E-2 1.0592509E-2 2.0816965E-4 -7.6472538E-6 4.9240991E-7";

// A one-glass AGF text.
std::string one_glass(int formula, const std::string& coefficients, double nd = 1.5,
                      double vd = 60.0) {
  std::ostringstream out;
  out << "CC test glass\n";
  out << "NM G " << formula << " 500600 " << nd << " " << vd << " 0 0 1\n";
  out << "CD " << coefficients << "\n";
  out << "LD 0.3 2.5\n";
  return out.str();
}

Glass parse_one(int formula, const std::string& coefficients) {
  const Catalog catalog = parse_agf(one_glass(formula, coefficients), "inline.agf");
  REQUIRE(catalog.glasses.size() == 1);
  REQUIRE(catalog.warnings.empty());
  return catalog.glasses.front();
}

// The what() of the Error that parsing `text` throws ("" if none is thrown).
std::string parse_error(const std::string& text, const std::string& name = "bad.agf") {
  try {
    parse_agf(text, name);
  } catch (const Error& e) {
    return e.what();
  }
  return "";
}

// ASCII text as UTF-16 LE with a BOM (and any extra code units appended after it).
std::string to_utf16le(const std::string& ascii) {
  std::string bytes = "\xFF\xFE";
  for (const char ch : ascii) {
    bytes += ch;
    bytes += '\0';
  }
  return bytes;
}

std::string read_file(const std::filesystem::path& path) {
  std::ifstream in(path, std::ios::binary);
  std::ostringstream out;
  out << in.rdbuf();
  return out.str();
}

}  // namespace

TEST_CASE("glass: Sellmeier 1 gives N-BK7's published indices") {
  const Glass bk7 = parse_one(2, kBk7Sellmeier);
  CHECK(bk7.formula == DispersionFormula::kSellmeier1);
  // Schott data sheet: nd = 1.51680, nF = 1.52238, nC = 1.51432.
  CHECK(std::abs(bk7.index(kD_nm) - 1.51680) < 5e-6);
  CHECK(std::abs(bk7.index(kF_nm) - 1.52238) < 1e-5);
  CHECK(std::abs(bk7.index(kC_nm) - 1.51432) < 1e-5);
}

TEST_CASE("glass: Sellmeier 1 gives fused silica's index (Malitson 1965)") {
  // Malitson: B = 0.6961663, 0.4079426, 0.8974794; resonances 0.0684043, 0.1162414, 9.896161 um
  // (C = their squares). n(587.6 nm) = 1.4585.
  const Glass silica = parse_one(
      2, "0.6961663 0.00467914825849 0.4079426 0.01351206307396 0.8974794 97.93400253792");
  CHECK(std::abs(silica.index(kD_nm) - 1.458464) < 1e-6);
}

TEST_CASE("glass: Schott power series gives BK7's published indices") {
  const Glass bk7 = parse_one(1, kBk7Schott);
  CHECK(std::abs(bk7.index(kD_nm) - 1.51680) < 1e-5);
  CHECK(std::abs(bk7.index(kF_nm) - 1.52238) < 2e-5);
  CHECK(std::abs(bk7.index(kC_nm) - 1.51432) < 2e-5);
}

TEST_CASE("glass: every AGF formula against its equation worked out by hand") {
  // Expected values evaluated from each formula's equation in 40-digit decimal arithmetic,
  // lambda in um, at 486.1327 nm and 1014.0 nm.
  struct Case {
    int formula;
    const char* coefficients;
    double n_486;
    double n_1014;
  };
  const Case cases[] = {
      // 3 Herzberger: n = c0 + c1 L + c2 L^2 + c3 l^2 + c4 l^4 + c5 l^6, L = 1/(l^2 - 0.028)
      {3, "1.5 0.004 0.0001 -0.002 0.0001 -1e-5", 1.521037755092, 1.502137633712},
      // 4 Sellmeier 2: n^2 - 1 = c0 + c1 l^2/(l^2 - c2^2) + c3/(l^2 - c4^2)
      {4, "0.2 0.9 0.1 0.005 0.15", 1.470764913575, 1.453895059453},
      // 5 Conrady: n = c0 + c1/l + c2/l^3.5
      {5, "1.5 0.01 0.0005", 1.526812577054, 1.510338185322},
      // 6 Sellmeier 3: N-BK7's three terms and a fourth (0.01, 0.05)
      {6, "1.03961212 0.00600069867 0.231792344 0.0200179144 1.01046945 103.560653 0.01 0.05",
       1.526536291959, 1.510790494888},
      // 7 Handbook of Optics 1: n^2 = c0 + c1/(l^2 - c2) - c3 l^2
      {7, "2.2 0.01 0.02 0.01", 1.497953100641, 1.483117239561},
      // 8 Handbook of Optics 2: n^2 = c0 + c1 l^2/(l^2 - c2) - c3 l^2
      {8, "1.2 1.05 0.0061 0.009", 1.508540249715, 1.499003926162},
      // 9 Sellmeier 4: n^2 = c0 + c1 l^2/(l^2 - c2) + c3 l^2/(l^2 - c4)
      {9, "1.1 1.2 0.01 0.3 100", 1.533724369973, 1.519430458110},
      // 10 Extended: BK7's Schott series plus c6 l^-10 + c7 l^-12
      {10, "2.2718929 -1.0108077E-2 1.0592509E-2 2.0816965E-4 -7.6472538E-6 4.9240991E-7 1e-8 1e-9",
       1.522383329820, 1.507312897994},
      // 11 Sellmeier 5: N-BK7's three terms and two more
      {11,
       "1.03961212 0.00600069867 0.231792344 0.0200179144 1.01046945 103.560653 0.01 0.05 "
       "0.002 0.07",
       1.527466783991, 1.511500587939},
      // 12 Extended 2: BK7's Schott series plus c6 l^4 + c7 l^6
      {12,
       "2.2718929 -1.0108077E-2 1.0592509E-2 2.0816965E-4 -7.6472538E-6 4.9240991E-7 1e-4 -1e-5",
       1.522378779899, 1.507344357357},
      // 13 Extended 3: n^2 = c0 + c1 l^2 + c2 l^4 + c3 l^-2 + ... + c8 l^-12
      {13, "2.27 -0.0101 1e-4 0.0106 2.08e-4 -7.6e-6 4.9e-7 1e-8 1e-9", 1.521774314575,
       1.506725078545},
  };
  for (const Case& c : cases) {
    CAPTURE(c.formula);
    const Glass glass = parse_one(c.formula, c.coefficients);
    CHECK(static_cast<int>(glass.formula) == c.formula);
    CHECK(glass.formula_supported);
    CHECK(std::abs(glass.index(kF_nm) - c.n_486) < 1e-11);
    CHECK(std::abs(glass.index(1014.0) - c.n_1014) < 1e-11);
  }
}

TEST_CASE("glass: formulas that contain Sellmeier 1 or Schott reduce to them") {
  const double nd_sellmeier = parse_one(2, kBk7Sellmeier).index(kD_nm);
  const double nd_schott = parse_one(1, kBk7Schott).index(kD_nm);
  // Sellmeier 3 and 5 with their extra terms zero.
  CHECK(parse_one(6, std::string(kBk7Sellmeier) + " 0 0").index(kD_nm) ==
        doctest::Approx(nd_sellmeier).epsilon(1e-14));
  CHECK(parse_one(11, std::string(kBk7Sellmeier) + " 0 0 0 0").index(kD_nm) ==
        doctest::Approx(nd_sellmeier).epsilon(1e-14));
  // Extended and Extended 2 with c6 = c7 = 0; Extended 3 with the series reordered
  // (c0, c1, 0, c2..c5).
  CHECK(parse_one(10, std::string(kBk7Schott) + " 0 0").index(kD_nm) ==
        doctest::Approx(nd_schott).epsilon(1e-14));
  CHECK(parse_one(12, std::string(kBk7Schott) + " 0 0").index(kD_nm) ==
        doctest::Approx(nd_schott).epsilon(1e-14));
  CHECK(parse_one(13,
                  "2.2718929 -1.0108077E-2 0 1.0592509E-2 2.0816965E-4 -7.6472538E-6 "
                  "4.9240991E-7 0 0")
            .index(kD_nm) == doctest::Approx(nd_schott).epsilon(1e-14));
  // Handbook of Optics 2 with c0 = 1, c3 = 0 is a one-term Sellmeier; Sellmeier 4 with c0 = 1
  // a two-term one.
  const double l2 = 0.5875618 * 0.5875618;
  CHECK(parse_one(8, "1 1.03961212 0.00600069867 0").index(kD_nm) ==
        doctest::Approx(std::sqrt(1 + 1.03961212 * l2 / (l2 - 0.00600069867))).epsilon(1e-14));
  CHECK(parse_one(9, "1 1.03961212 0.00600069867 1.01046945 103.560653").index(kD_nm) ==
        doctest::Approx(
            parse_one(2, "1.03961212 0.00600069867 0 0 1.01046945 103.560653").index(kD_nm))
            .epsilon(1e-14));
}

TEST_CASE("glass: formula and status names") {
  CHECK(formula_name(DispersionFormula::kSchott) == "Schott");
  CHECK(formula_name(DispersionFormula::kSellmeier1) == "Sellmeier 1");
  CHECK(formula_name(DispersionFormula::kHandbook2) == "Handbook of Optics 2");
  CHECK(formula_name(DispersionFormula::kExtended3) == "Extended 3");
  CHECK(formula_name(static_cast<DispersionFormula>(14)) == "unknown (14)");
  CHECK(status_name(GlassStatus::kPreferred) == "preferred");
  CHECK(status_name(GlassStatus::kObsolete) == "obsolete");
  CHECK(status_name(static_cast<GlassStatus>(9)) == "unknown (9)");
}

TEST_CASE("agf: an unknown formula is reported, never computed") {
  const std::string text = "NM GOOD 2 1 1.5 60 0 0\nCD " + std::string(kBk7Sellmeier) +
                           "\nNM ODD 14 1 1.6 40 0 0\nCD 1 2 3 4 5 6\nLD 0.4 0.7\n";
  const Catalog catalog = parse_agf(text, "some/dir/odd.agf");
  REQUIRE(catalog.glasses.size() == 2);
  const Glass& odd = catalog.glasses[1];
  CHECK_FALSE(odd.formula_supported);
  CHECK(std::isnan(odd.index(kD_nm)));
  CHECK(odd.source_line == 3);
  REQUIRE(catalog.warnings.size() == 1);
  CHECK(catalog.warnings[0].find("some/dir/odd.agf:3") != std::string::npos);
  CHECK(catalog.warnings[0].find("ODD") != std::string::npos);
  CHECK(catalog.warnings[0].find("14") != std::string::npos);
  CHECK(catalog.glasses[0].formula_supported);
}

TEST_CASE("agf: a glass without a CD line is flagged unsupported") {
  const Catalog catalog = parse_agf("NM BARE 2 1 1.5 60 0 0\nLD 0.4 0.7\n", "bare.agf");
  REQUIRE(catalog.glasses.size() == 1);
  CHECK_FALSE(catalog.glasses[0].formula_supported);
  REQUIRE(catalog.warnings.size() == 1);
  CHECK(catalog.warnings[0].find("bare.agf:1") != std::string::npos);
}

TEST_CASE("agf: a glass name listed twice is reported") {
  const std::string cd = "CD " + std::string(kBk7Sellmeier) + "\n";
  const Catalog catalog =
      parse_agf("NM TWIN 2 1 1.5 60 0 0\n" + cd + "NM twin 2 1 1.6 40 0 0\n" + cd, "dup.agf");
  REQUIRE(catalog.glasses.size() == 2);
  CHECK(catalog.find("Twin")->nd == 1.5);
  REQUIRE(catalog.warnings.size() == 1);
  CHECK(catalog.warnings[0].find("dup.agf:3") != std::string::npos);
}

TEST_CASE("agf: fields of the NM, LD and IT lines") {
  const std::string text =
      "CC a comment\n"
      "NM N-BK7 2.00000E+00 517642.251 1.51680E+00 6.41700E+01 0.00000E+00 1.00000E+00 -\n"
      "GC some text\n"
      "ED 7.1 8.3 2.51 -0.0009 0\n"
      "CD " +
      std::string(kBk7Sellmeier) +
      "\n"
      "TD 1 2 3 4 5 6 20\n"
      "OD 1 2 3 4 5 6\n"
      "ZZ a key this reader does not know\n"
      "LD 3.00000E-01 2.50000E+00\n"
      "IT 3.00000E-01  2.50000E+01\n"
      "IT 3.20000E-01 2.00000E-02 2.50000E+01\n"
      "IT 3.50000E-01 5.50000E-01 2.50000E+01\n";
  const Catalog catalog = parse_agf(text, "/tmp/x/SCHOTT_TEST.AGF");
  CHECK(catalog.name == "SCHOTT_TEST");
  CHECK(catalog.path == "/tmp/x/SCHOTT_TEST.AGF");
  CHECK(catalog.warnings.empty());
  REQUIRE(catalog.glasses.size() == 1);
  const Glass& g = catalog.glasses[0];
  CHECK(g.name == "N-BK7");
  CHECK(g.catalog == "SCHOTT_TEST");
  CHECK(g.formula == DispersionFormula::kSellmeier1);  // written as a float
  CHECK(g.status == GlassStatus::kPreferred);
  CHECK(g.nd == 1.5168);
  CHECK(g.vd == 64.17);
  CHECK(g.source_line == 2);
  CHECK(g.coefficients.size() == 10);
  CHECK(g.min_wavelength_um == 0.3);
  CHECK(g.max_wavelength_um == 2.5);
  REQUIRE(g.transmission.size() == 3);
  // Schott leaves the transmission field blank below its measurable range.
  CHECK(g.transmission[0].transmission == 0.0);
  CHECK(g.transmission[0].thickness_mm == 25.0);
  CHECK(g.transmission[1].transmission == 0.02);
  CHECK(std::abs(g.index(kD_nm) - 1.5168) < 5e-6);
}

TEST_CASE("glass: transmission from the IT table") {
  Glass g;
  CHECK(g.transmits(300.0));  // no IT data
  g.transmission = {{0.30, 0.0, 10}, {0.32, 0.0, 10}, {0.34, 0.5, 10}, {0.40, 0.99, 10}};
  CHECK(g.transmits(250.0));  // outside the table
  CHECK(g.transmits(450.0));
  CHECK_FALSE(g.transmits(300.0));
  CHECK_FALSE(g.transmits(310.0));  // between two zeros
  CHECK_FALSE(g.transmits(320.0));
  CHECK(g.transmits(321.0));  // 0.025 interpolated
  CHECK(g.transmits(340.0));
  // Unsorted tables are read in wavelength order.
  g.transmission = {{0.40, 0.99, 10}, {0.30, 0.0, 10}, {0.32, 0.0, 10}, {0.34, 0.5, 10}};
  CHECK_FALSE(g.transmits(310.0));
  CHECK(g.transmits(330.0));
}

TEST_CASE("agf: UTF-16 LE with a BOM and CRLF line ends") {
  const std::string lf_text = one_glass(2, kBk7Sellmeier, 1.5168, 64.17);
  std::string crlf_text;
  for (const char ch : lf_text) {
    if (ch == '\n') crlf_text += '\r';
    crlf_text += ch;
  }
  const Catalog from_lf = parse_agf(lf_text, "a.agf");
  const Catalog from_crlf = parse_agf(crlf_text, "a.agf");
  // A UTF-16 comment with non-ASCII text: U+00B5 (micro sign) and U+1F600 (a surrogate pair).
  std::string utf16 = to_utf16le("CC ");
  utf16 += std::string("\xB5\x00\x3D\xD8\x00\xDE\r\x00\n\x00", 10);
  utf16 += to_utf16le(crlf_text).substr(2);
  const Catalog from_utf16 = parse_agf(utf16, "a.agf");
  for (const Catalog* catalog : {&from_lf, &from_crlf, &from_utf16}) {
    REQUIRE(catalog->glasses.size() == 1);
    const Glass& g = catalog->glasses[0];
    CHECK(g.name == "G");
    CHECK(g.nd == 1.5168);
    CHECK(g.vd == 64.17);
    CHECK(g.coefficients == from_lf.glasses[0].coefficients);
    CHECK(g.max_wavelength_um == 2.5);
  }
  CHECK(from_crlf.glasses[0].source_line == 2);
  CHECK(from_utf16.glasses[0].source_line == 3);
  // A UTF-8 BOM is dropped.
  CHECK(parse_agf("\xEF\xBB\xBF" + lf_text, "a.agf").glasses.size() == 1);
}

TEST_CASE("agf: malformed lines are errors naming file and line") {
  const std::string nm = "NM G 2 1 1.5 60 0 0\n";
  // A bad number on a CD line.
  std::string what = parse_error("CC x\n" + nm + "CD 1.0 0.006 abc 0.02 1.0 103\n");
  CHECK(what.find("bad.agf:3") != std::string::npos);
  CHECK(what.find("abc") != std::string::npos);
  // Too few CD coefficients for the formula.
  what = parse_error(nm + "CD 1.0 0.006 0.2\n");
  CHECK(what.find("bad.agf:2") != std::string::npos);
  CHECK(what.find("needs 6") != std::string::npos);
  // NM with too few fields, or a bad nd, or a fractional formula id.
  CHECK(parse_error("NM G 2 1 1.5\n").find("bad.agf:1") != std::string::npos);
  CHECK(parse_error("NM G 2 1 1.5x 60\n").find("nd") != std::string::npos);
  CHECK(parse_error("NM G 2.5 1 1.5 60\n").find("formula") != std::string::npos);
  // LD and IT with bad or missing numbers.
  CHECK(parse_error(nm + "CD " + kBk7Sellmeier + "\nLD 0.3\n").find("bad.agf:3") !=
        std::string::npos);
  CHECK(parse_error(nm + "CD " + kBk7Sellmeier + "\nIT 0.3 x 10\n").find("bad.agf:3") !=
        std::string::npos);
  CHECK(parse_error(nm + "CD " + kBk7Sellmeier + "\nIT 0.3\n").find("bad.agf:3") !=
        std::string::npos);
  // Data lines before any NM line.
  CHECK(parse_error("CC x\nCD 1 2 3 4 5 6\n").find("bad.agf:2") != std::string::npos);
  CHECK(parse_error("LD 0.3 2.5\n").find("before any NM") != std::string::npos);
  CHECK(parse_error("IT 0.3 0.5 10\n").find("bad.agf:1") != std::string::npos);
}

TEST_CASE("catalog: find, at and closest names") {
  const std::string text = "NM N-BK7 2 1 1.5168 64.17 0 1\nCD " + std::string(kBk7Sellmeier) +
                           "\nNM N-BK10 2 1 1.49782 66.95 0 0\nCD " + kBk7Sellmeier +
                           "\nNM N-SF6 2 1 1.80518 25.36 0 0\nCD " + kBk7Sellmeier +
                           "\nNM F2 2 1 1.62004 36.37 0 1\nCD " + kBk7Sellmeier + "\n";
  const Catalog catalog = parse_agf(text, "/somewhere/MYCAT.agf");
  REQUIRE(catalog.find("n-bk7") != nullptr);
  CHECK(catalog.find("n-bk7")->name == "N-BK7");
  CHECK(catalog.find("N-BK8") == nullptr);
  CHECK(&catalog.at("N-SF6") == &catalog.glasses[2]);
  CHECK(catalog.closest_names("n-bk8", 2) == std::vector<std::string>{"N-BK7", "N-BK10"});
  CHECK(catalog.closest_names("f2", 1) == std::vector<std::string>{"F2"});
  CHECK(catalog.closest_names("x", 10).size() == 4);
  std::string what;
  try {
    catalog.at("N-BK8");
  } catch (const Error& e) {
    what = e.what();
  }
  CHECK(what.find("unknown glass 'N-BK8' in catalog MYCAT") != std::string::npos);
  CHECK(what.find("closest: N-BK7, N-BK10, ") != std::string::npos);
}

TEST_CASE("catalog: the built-in Ohara catalog") {
  const auto ohara = load_catalog("ohara");
  REQUIRE(ohara != nullptr);
  CHECK(ohara->name == "ohara65");
  CHECK(ohara->glasses.size() == 65);
  CHECK(ohara->warnings.empty());
  CHECK(load_catalog("ohara") == ohara);  // cached
  // Only the lower-case "ohara" is the paper's subset: "OHARA" is Ohara's complete catalog.
  CHECK(load_catalog("OHARA") != ohara);
  CHECK(load_catalog("OHARA")->name == "OHARA");
  CHECK(load_catalog(ohara->path) == ohara);
  double worst = 0.0;
  for (const Glass& g : ohara->glasses) {
    CAPTURE(g.name);
    CHECK(g.formula == DispersionFormula::kSellmeier1);
    CHECK(g.formula_supported);
    CHECK(g.transmits(kD_nm));
    const double deviation = std::abs(g.index(kD_nm) - g.nd);
    CHECK(deviation < 2e-5);
    worst = std::max(worst, deviation);
  }
  MESSAGE("ohara65: worst |n(587.5618 nm) - nd| = " << worst);
  CHECK(ohara->at("s-bah10").name == "S-BAH10");
}

TEST_CASE("catalog: the built-in Ohara catalog matches the paper's table") {
  LENSOPT_REQUIRE_SHARED(shared);
  const auto ohara = load_catalog("ohara");
  std::ifstream csv(shared / "data" / "ohara65.csv");
  REQUIRE(csv.good());
  std::string line;
  std::getline(csv, line);  // header: name,nd,vd,B1,B2,B3,C1,C2,C3
  int rows = 0;
  while (std::getline(csv, line)) {
    if (line.empty()) continue;
    std::vector<std::string> cells;
    std::stringstream row(line);
    for (std::string cell; std::getline(row, cell, ',');) cells.push_back(cell);
    REQUIRE(cells.size() == 9);
    ++rows;
    const Glass* g = ohara->find(cells[0]);
    REQUIRE_MESSAGE(g != nullptr, cells[0]);
    CAPTURE(g->name);
    CHECK(g->nd == std::stod(cells[1]));
    CHECK(g->vd == std::stod(cells[2]));
    // AGF order B1 C1 B2 C2 B3 C3.
    for (int k = 0; k < 3; ++k) {
      CHECK(g->coefficients[2 * k] == std::stod(cells[3 + k]));
      CHECK(g->coefficients[2 * k + 1] == std::stod(cells[6 + k]));
    }
  }
  CHECK(rows == 65);
}

TEST_CASE("catalog: search path and errors") {
  const auto folders = catalog_search_path();
  const auto built_in = (test::source_dir() / "catalogs").lexically_normal();
  CHECK(std::find(folders.begin(), folders.end(), built_in) != folders.end());
  // A folder named in LENSOPT_CATALOG_PATH comes first; names are case-insensitive.
  const auto dir = std::filesystem::temp_directory_path() /
                   ("lensopt_test_catalogs_" + std::to_string(::getpid()));
  std::filesystem::create_directories(dir);
  {
    std::ofstream out(dir / "MyGlasses.AGF", std::ios::binary);
    out << one_glass(2, kBk7Sellmeier, 1.5168, 64.17);
  }
  const char* old = std::getenv("LENSOPT_CATALOG_PATH");
  const std::string saved = old ? old : "";
  ::setenv("LENSOPT_CATALOG_PATH", ("/nonexistent:" + dir.string()).c_str(), 1);
  CHECK(catalog_search_path().at(0) == std::filesystem::path("/nonexistent"));
  CHECK(catalog_search_path().at(1) == dir.lexically_normal());
  const auto mine = load_catalog("myglasses");
  CHECK(mine->name == "MyGlasses");
  CHECK(mine->glasses.size() == 1);
  std::string what;
  try {
    load_catalog("no_such_catalog");
  } catch (const Error& e) {
    what = e.what();
  }
  CHECK(what.find("no_such_catalog") != std::string::npos);
  CHECK(what.find(dir.string()) != std::string::npos);
  CHECK(what.find(built_in.string()) != std::string::npos);
  if (old) {
    ::setenv("LENSOPT_CATALOG_PATH", saved.c_str(), 1);
  } else {
    ::unsetenv("LENSOPT_CATALOG_PATH");
  }
  std::filesystem::remove_all(dir);
  CHECK_THROWS_AS(load_catalog("/no/such/dir/x.agf"), Error);
  CHECK_THROWS_AS(read_agf("/no/such/dir/x.agf"), Error);
}

TEST_CASE("agf: every glass of the vendor catalogs in ../shared") {
  LENSOPT_REQUIRE_SHARED(shared);
  // Published indices (vendor data sheets) of a few glasses, beyond the files' own nd.
  const std::map<std::string, std::map<std::string, double>> published = {
      {"SCHOTT", {{"N-BK7", 1.51680}, {"N-SF6", 1.80518}, {"F2", 1.62004}}},
      {"OHARA", {{"S-BAH10", 1.67003}, {"S-LAH65V", 1.80400}}},
  };
  for (const char* file : {"OHARA_20200623.AGF", "SCHOTT_202002.AGF"}) {
    const auto path = shared / "data" / "agf" / file;
    const Catalog catalog = read_agf(path);
    CAPTURE(catalog.name);
    CHECK_FALSE(catalog.glasses.empty());
    int checked = 0;
    int unsupported = 0;
    int opaque = 0;
    double worst = 0.0;
    std::string worst_name;
    for (const Glass& g : catalog.glasses) {
      if (!g.formula_supported) {
        ++unsupported;
        continue;
      }
      if (!g.transmits(kD_nm)) {
        ++opaque;
        continue;
      }
      CAPTURE(g.name);
      const double deviation = std::abs(g.index(kD_nm) - g.nd);
      CHECK(deviation < 2e-5);
      if (deviation > worst) {
        worst = deviation;
        worst_name = g.name;
      }
      ++checked;
    }
    MESSAGE(catalog.name << ": " << catalog.glasses.size() << " glasses, " << checked
                         << " checked against their nd, worst |n - nd| = " << worst << " ("
                         << worst_name << "); " << unsupported << " with an unsupported formula, "
                         << opaque << " not transmitting at 587.5618 nm; "
                         << catalog.warnings.size() << " warnings");
    CHECK(checked + unsupported + opaque == static_cast<int>(catalog.glasses.size()));
    for (const auto& [name, nd] : published.at(catalog.name)) {
      CAPTURE(name);
      CHECK(std::abs(catalog.at(name).index(kD_nm) - nd) < 1e-5);
    }
  }
  // The Schott file's N-BK7 at F and C (Schott data sheet: 1.52238, 1.51432).
  const Catalog schott = read_agf(shared / "data" / "agf" / "SCHOTT_202002.AGF");
  CHECK(std::abs(schott.at("N-BK7").index(kF_nm) - 1.52238) < 1e-5);
  CHECK(std::abs(schott.at("N-BK7").index(kC_nm) - 1.51432) < 1e-5);
  CHECK(schott.at("B270").formula == DispersionFormula::kSchott);
  // The Ohara file really is UTF-16 LE with a BOM, so the decoder ran on a vendor file.
  const std::string bytes = read_file(shared / "data" / "agf" / "OHARA_20200623.AGF");
  CHECK(static_cast<unsigned char>(bytes[0]) == 0xFF);
}

TEST_CASE("catalog: vendor file names are catalogs of the vendor family") {
  CHECK(catalog_family_name("SCHOTT_202002") == "SCHOTT");
  CHECK(catalog_family_name("OHARA_20200623") == "OHARA");
  CHECK(catalog_family_name("SCHOTT") == "SCHOTT");
  CHECK(catalog_family_name("ohara65") == "ohara65");
  CHECK(catalog_family_name("MY_GLASSES") == "MY_GLASSES");
  CHECK(catalog_family_name("_2020") == "_2020");
  CHECK(catalog_family_name("X_") == "X_");
  // A dated vendor file in a LENSOPT_CATALOG_PATH folder is found by its family name, the newest
  // date first, and comes before the shipped catalog of that name.
  const auto dir = std::filesystem::temp_directory_path() /
                   ("lensopt_test_vendor_" + std::to_string(::getpid()));
  std::filesystem::create_directories(dir);
  for (const char* file : {"ACME_201901.AGF", "ACME_202002.AGF"}) {
    std::ofstream out(dir / file, std::ios::binary);
    out << one_glass(2, kBk7Sellmeier, 1.5168, 64.17);
  }
  const char* old = std::getenv("LENSOPT_CATALOG_PATH");
  const std::string saved = old ? old : "";
  ::setenv("LENSOPT_CATALOG_PATH", dir.string().c_str(), 1);
  const auto acme = load_catalog("ACME");
  CHECK(acme->name == "ACME");
  CHECK(std::filesystem::path(acme->path).filename() == "ACME_202002.AGF");
  CHECK(acme->glasses.at(0).catalog == "ACME");
  CHECK(load_catalog("acme") == acme);
  CHECK(load_catalog("ACME_201901")->path != acme->path);  // a dated name is that file
  if (old) {
    ::setenv("LENSOPT_CATALOG_PATH", saved.c_str(), 1);
  } else {
    ::unsetenv("LENSOPT_CATALOG_PATH");
  }
  std::filesystem::remove_all(dir);
}

TEST_CASE("catalog: the shipped vendor catalogs (no ../shared needed)") {
  // Published d-line indices from the vendors' data sheets, computed from the shipped formulas.
  const std::map<std::string, std::map<std::string, double>> published = {
      {"SCHOTT",
       {{"N-BK7", 1.51680},
        {"N-SF6", 1.80518},
        {"F2", 1.62004},
        {"N-SK16", 1.62041},
        {"N-LAK9", 1.69100}}},
      {"OHARA",
       {{"S-BSL7", 1.51633}, {"S-TIH6", 1.80518}, {"S-LAH66", 1.77250}, {"S-FSL5", 1.48749}}},
      {"HOYA", {{"BSC7", 1.51680}, {"FD60", 1.80518}, {"TAF1", 1.77250}, {"FC5", 1.48749}}},
      {"CDGM", {{"H-K9L", 1.51680}, {"H-ZF13", 1.78472}, {"H-FK61", 1.49700}}},
  };
  const std::map<std::string, std::size_t> glass_counts = {
      {"SCHOTT", 356}, {"OHARA", 158}, {"HOYA", 398}, {"CDGM", 256}};
  CHECK(shipped_catalog_names() == std::vector<std::string>{"SCHOTT", "OHARA", "HOYA", "CDGM"});
  for (const std::string& name : shipped_catalog_names()) {
    CAPTURE(name);
    const auto catalog = load_catalog(name);
    CHECK(catalog->name == name);
    CHECK(std::filesystem::path(catalog->path).parent_path().lexically_normal() ==
          (test::source_dir() / "catalogs").lexically_normal());
    CHECK(catalog->glasses.size() == glass_counts.at(name));
    CHECK(catalog->warnings.empty());
    for (const auto& [glass, nd] : published.at(name)) {
      CAPTURE(glass);
      const Glass& g = catalog->at(glass);
      CHECK(g.catalog == name);
      CHECK(std::abs(g.index(kD_nm) - nd) < 1e-5);
      CHECK(std::abs(g.nd - nd) < 1e-5);
    }
    // The file is our normalized form: ASCII, our header first.
    const std::string bytes = read_file(catalog->path);
    CHECK(bytes.rfind("CC lensopt glass catalog " + name, 0) == 0);
    CHECK(std::all_of(bytes.begin(), bytes.end(),
                      [](char ch) { return static_cast<unsigned char>(ch) < 0x80; }));
  }
  // Nearest glasses on the glass map: N-BK7's own (nd, vd) finds N-BK7 first.
  const auto schott = load_catalog("SCHOTT");
  const auto near = schott->closest_by_index(1.5168, 64.17, 3);
  REQUIRE(near.size() == 3);
  CHECK(near[0]->name == "N-BK7");
}

TEST_CASE("catalog: the shipped catalogs hold every glass of the vendor files, unchanged") {
  LENSOPT_REQUIRE_SHARED(shared);
  for (const std::string& name : shipped_catalog_names()) {
    CAPTURE(name);
    std::filesystem::path vendor_file;
    for (const auto& entry : std::filesystem::directory_iterator(shared / "data" / "agf"))
      if (catalog_family_name(entry.path().stem().string()) == name) vendor_file = entry.path();
    REQUIRE_FALSE(vendor_file.empty());
    const Catalog vendor = read_agf(vendor_file);
    const auto shipped = load_catalog(name);
    REQUIRE(shipped->glasses.size() == vendor.glasses.size());
    for (std::size_t i = 0; i < vendor.glasses.size(); ++i) {
      const Glass& a = vendor.glasses[i];
      const Glass& b = shipped->glasses[i];
      CAPTURE(a.name);
      CHECK(a.name == b.name);
      CHECK(a.formula == b.formula);
      CHECK(a.nd == b.nd);
      CHECK(a.vd == b.vd);
      CHECK(a.status == b.status);
      CHECK(a.coefficients == b.coefficients);
      CHECK(a.min_wavelength_um == b.min_wavelength_um);
      CHECK(a.max_wavelength_um == b.max_wavelength_um);
      REQUIRE(a.transmission.size() == b.transmission.size());
      for (std::size_t k = 0; k < a.transmission.size(); ++k) {
        CHECK(a.transmission[k].wavelength_um == b.transmission[k].wavelength_um);
        CHECK(a.transmission[k].transmission == b.transmission[k].transmission);
        CHECK(a.transmission[k].thickness_mm == b.transmission[k].thickness_mm);
      }
      if (a.formula_supported && a.transmits(kD_nm)) CHECK(a.index(kD_nm) == b.index(kD_nm));
    }
  }
}

}  // namespace test_glass
