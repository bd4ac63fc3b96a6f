// A lens whose glasses come from several catalogs (issue 31, item 5): written as .zmx with every
// GCAT it needs and as TOML with each foreign glass's catalog, and read back to the same glasses
// and the same figures.
#include <doctest/doctest.h>

#include <string>
#include <vector>

#include "lensopt/analysis/analyze.h"
#include "lensopt/core/error.h"
#include "lensopt/formats/zmx.h"
#include "lensopt/glass/glass.h"
#include "lensopt/lens/lens_io.h"
#include "lensopt/lens/trace_lens.h"
#include "lensopt/paraxial/paraxial.h"

namespace lensopt::test_zmx_multi_catalog {
namespace {

// A cemented doublet: N-BK7 from SCHOTT and S-TIH6 from OHARA, two fields, F, d, C.
const char* kTwoCatalogs =
    "MODE SEQ\nUNIT MM X W X CM MR CPMM\nENPD 10\nGCAT SCHOTT OHARA\n"
    "FTYP 0 0 2 3 0 0 0\nXFLN 0 0\nYFLN 0 5\n"
    "WAVM 1 0.4861327 1\nWAVM 2 0.5875618 1\nWAVM 3 0.6562725 1\nPWAV 2\n"
    "SURF 0\n  TYPE STANDARD\n  CURV 0\n  DISZ INFINITY\n"
    "SURF 1\n  STOP\n  TYPE STANDARD\n  CURV 0.016\n  DISZ 4\n  GLAS N-BK7 0 0\n"
    "SURF 2\n  TYPE STANDARD\n  CURV -0.022\n  DISZ 2.5\n  GLAS S-TIH6 0 0\n"
    "SURF 3\n  TYPE STANDARD\n  CURV -0.0078\n  DISZ 97\n"
    "SURF 4\n  TYPE STANDARD\n  CURV 0\n  DISZ 0\n";

std::vector<const Glass*> glasses_of(const Lens& lens) {
  std::vector<const Glass*> out;
  for (const Surface& s : lens.surfaces)
    if (!s.material.is_air()) out.push_back(s.material.glass.get());
  return out;
}

// The same catalog glass: its catalog, name and formula data.
bool same_glass(const Glass* a, const Glass* b) {
  return a != nullptr && b != nullptr && a->catalog == b->catalog && a->name == b->name &&
         a->nd == b->nd && a->vd == b->vd && a->formula == b->formula &&
         a->coefficients == b->coefficients;
}

bool any_has(const std::vector<std::string>& warnings, const std::string& text) {
  for (const std::string& w : warnings)
    if (w.find(text) != std::string::npos) return true;
  return false;
}

// The figures compared: paraxial EFL and BFL at every wavelength, and analyze's RMS spots.
std::vector<double> figures(const Lens& lens) {
  std::vector<double> out;
  const TraceLens<double> tl = make_trace_lens(lens);
  for (const double nm : lens.specs.wavelengths_nm) {
    const ParaxialData<double> par = paraxial_data(tl, nm);
    out.push_back(par.efl_mm);
    out.push_back(par.bfl_mm);
  }
  AnalyzeOptions options;
  options.trace.rings = 8;
  const AnalysisReport r = analyze_lens(lens, options);
  for (const FieldReport& f : r.fields) out.push_back(f.rms_spot_um.value_or(-1.0));
  return out;
}

}  // namespace

TEST_CASE("zmx multi-catalog: written with every GCAT needed, read back to the same figures") {
  const ZmxImport in = parse_zmx(kTwoCatalogs, "two.zmx");
  const std::vector<const Glass*> glasses = glasses_of(in.lens);
  REQUIRE(glasses.size() == 2);
  REQUIRE(glasses[0]);
  REQUIRE(glasses[1]);
  CHECK(glasses[0]->catalog == "SCHOTT");
  CHECK(glasses[1]->catalog == "OHARA");
  // Reading it says nothing about the two catalogs any more (TOML keeps both now).
  CHECK_FALSE(any_has(in.warnings, "catalogs ("));
  const std::vector<double> original = figures(in.lens);

  SUBCASE(".zmx") {
    const std::string text = format_zmx(in.lens);
    CHECK(text.find("GCAT SCHOTT OHARA\r\n") != std::string::npos);  // was "GCAT SCHOTT"
    const ZmxImport back = parse_zmx(text, "back.zmx");
    CHECK_FALSE(any_has(back.warnings, "none of the file's catalogs"));
    const std::vector<const Glass*> back_glasses = glasses_of(back.lens);
    REQUIRE(back_glasses.size() == 2);
    CHECK(same_glass(back_glasses[0], glasses[0]));
    CHECK(same_glass(back_glasses[1], glasses[1]));
    CHECK(figures(back.lens) == original);
  }
  SUBCASE("TOML") {
    const std::string text = format_lens_toml(in.lens);
    CHECK(text.find("material = { glass = \"S-TIH6\", catalog = \"OHARA\" }") != std::string::npos);
    const Lens back = parse_lens_toml(text, "back.toml");
    const std::vector<const Glass*> back_glasses = glasses_of(back);
    REQUIRE(back_glasses.size() == 2);
    CHECK(same_glass(back_glasses[0], glasses[0]));
    CHECK(same_glass(back_glasses[1], glasses[1]));
    CHECK(figures(back) == original);
    // And on to .zmx again: the same GCAT.
    CHECK(format_zmx(back).find("GCAT SCHOTT OHARA\r\n") != std::string::npos);
  }
}

TEST_CASE("zmx multi-catalog: a TOML material names its glass's catalog, with clear errors") {
  const std::string head =
      "[lens]\nname = \"t\"\ncatalog = \"SCHOTT\"\n[specs]\nf_number = 8\nhalf_field_deg = 5\n"
      "sensor_diagonal_mm = 17.5\n[[surfaces]]\nradius_mm = \"inf\"\nthickness_mm = 0\n"
      "stop = true\n[[surfaces]]\nradius_mm = 62.5\nthickness_mm = 4\n"
      "material = \"N-BK7\"\n[[surfaces]]\nradius_mm = -45.45\nthickness_mm = 2.5\n";
  const std::string tail = "\n[[surfaces]]\nradius_mm = -128.2\nthickness_mm = 97\n";
  const Lens ok =
      parse_lens_toml(head + "material = { glass = \"S-TIH6\", catalog = \"OHARA\" }" + tail, "t");
  REQUIRE(ok.surfaces[2].material.glass);
  CHECK(ok.surfaces[2].material.glass->catalog == "OHARA");
  CHECK(ok.surfaces[2].material.glass->name == "S-TIH6");
  auto error_of = [&](const std::string& material) {
    try {
      parse_lens_toml(head + material + tail, "t.toml");
    } catch (const Error& error) {
      return std::string(error.what());
    }
    return std::string();
  };
  const std::string unknown = error_of("material = { glass = \"S-TIH66\", catalog = \"OHARA\" }");
  CHECK(unknown.find("t.toml:19") != std::string::npos);
  CHECK(unknown.find("unknown glass 'S-TIH66' in catalog 'OHARA'") != std::string::npos);
  const std::string no_catalog = error_of("material = { glass = \"N-SF5\", catalog = \"NOPE\" }");
  CHECK(no_catalog.find("cannot load catalog 'NOPE'") != std::string::npos);
  const std::string extra = error_of("material = { glass = \"N-SF5\", nd = 1.6 }");
  CHECK(extra.find("nd") != std::string::npos);
}

}  // namespace lensopt::test_zmx_multi_catalog
