// Zemax .zmx import and export: TOML -> ZMX -> TOML is exact for the baselines; UTF-16 and ASCII,
// CRLF and LF read the same; the hand-written textbook files have their stated focal lengths;
// aspheres, coordinate breaks and unknown glasses are errors at their line; other lines warnings.
#include <doctest/doctest.h>
#include <fmt/format.h>

#include <bit>
#include <cmath>
#include <cstdint>
#include <filesystem>
#include <random>
#include <string>
#include <vector>

#include "lens_checks.h"
#include "lensopt/analysis/analyze.h"
#include "lensopt/core/atomic_file.h"
#include "lensopt/core/error.h"
#include "lensopt/core/text.h"
#include "lensopt/formats/lens_file.h"
#include "lensopt/formats/zmx.h"
#include "lensopt/glass/dispersion.h"
#include "lensopt/lens/lens_io.h"
#include "lensopt/lens/trace_lens.h"
#include "lensopt/paraxial/paraxial.h"
#include "test_support.h"

namespace test_zmx {

using namespace lensopt;
using lensopt::test::bits;

namespace {

std::string to_lf(const std::string& text) {
  std::string out;
  for (char ch : text)
    if (ch != '\r') out += ch;
  return out;
}

// ASCII text as UTF-16 LE with a BOM, as OpticStudio writes .zmx files.
std::string to_utf16le(const std::string& text) {
  std::string out = "\xFF\xFE";
  for (char ch : text) {
    out += ch;
    out += '\0';
  }
  return out;
}

// A minimal valid file with `surface_lines` as the body of SURF 1 (f/4 singlet-like system).
std::string small_zmx(const std::string& header_extra, const std::string& surface_lines) {
  return "VERS 190513 80 123457 L123457\n"
         "MODE SEQ\n"
         "NAME small\n"
         "UNIT MM X W X CM MR CPMM\n"
         "FNUM 4 0\n" +
         header_extra +
         "FTYP 0 0 2 2 0 0 0\n"
         "XFLN 0 0\n"
         "YFLN 0 10\n"
         "WAVM 1 0.4861327 1\n"
         "WAVM 2 0.6562725 1\n"
         "SURF 0\n"
         "  TYPE STANDARD\n"
         "  CURV 0\n"
         "  DISZ INFINITY\n"
         "SURF 1\n"
         "  TYPE STANDARD\n"
         "  CURV 0\n"
         "  DISZ 2\n"
         "  STOP\n"
         "SURF 2\n" +
         surface_lines +
         "SURF 3\n"
         "  TYPE STANDARD\n"
         "  CURV -0.02\n"
         "  DISZ 45\n"
         "SURF 4\n"
         "  TYPE STANDARD\n"
         "  CURV 0\n"
         "  DISZ 0\n";
}

// Line (1-based) of the first line of `text` containing `needle`.
int line_of(const std::string& text, const std::string& needle) {
  const std::size_t at = text.find(needle);
  REQUIRE(at != std::string::npos);
  int line = 1;
  for (std::size_t i = 0; i < at; ++i) line += text[i] == '\n' ? 1 : 0;
  return line;
}

Error error_of(const std::string& text) {
  try {
    parse_zmx(text, "bad.zmx");
  } catch (const Error& error) {
    return error;
  }
  FAIL("no error for a bad .zmx");
  return Error("unreachable");
}

double paraxial_efl_mm(const Lens& lens) {
  return paraxial_data(make_trace_lens(lens), lens.specs.primary_wavelength_nm).efl_mm;
}

}  // namespace

TEST_CASE("zmx: TOML -> ZMX -> TOML is exact for the baselines") {
  for (const char* name : {"doublet", "cooke", "tessar"}) {
    CAPTURE(name);
    const auto toml_path = test::source_dir() / "lenses" / (std::string(name) + ".toml");
    const Lens lens = read_lens(toml_path);
    const std::string zmx = format_zmx(lens);
    CHECK(zmx.find("TYPE STANDARD") != std::string::npos);
    CHECK(zmx.find("GCAT OHARA") != std::string::npos);
    CHECK(zmx.find("FNUM 2 0") != std::string::npos);
    const ZmxImport imported = parse_zmx(zmx, std::string(name) + ".zmx");
    test::check_identical_lenses(lens, imported.lens);
    CHECK(imported.lens.source_path == std::string(name) + ".zmx");
    // And on to TOML: the same text as the original lens gives.
    CHECK(format_lens_toml(imported.lens) == format_lens_toml(lens));
    const Lens again = parse_lens_toml(format_lens_toml(imported.lens), "again.toml");
    test::check_identical_lenses(lens, again);
    // ZMX is a fixed point as well.
    CHECK(format_zmx(imported.lens) == zmx);
  }
}

TEST_CASE("zmx: model glasses, semi-diameters and extra tables survive") {
  Lens lens = read_lens(test::source_dir() / "lenses" / "doublet.toml");
  lens.surfaces[0].material = Material::model(1.7234567890123, 41.123456789);
  lens.surfaces[0].semi_diameter_mm = 5.123456789;
  lens.surfaces[1].curvature_per_mm = 0.1 / 3.0;  // no short decimal
  lens.specs.wavelengths_nm = {450.1, 550.3, 650.7};
  lens.specs.wavelength_channels = {2, 1, 0};
  lens.extra_toml = "[optimize]\nsteps = 10\n";
  const std::string zmx = format_zmx(lens);
  CHECK(zmx.find("GLAS ___BLANK 1 0 1.7234567890123 41.123456789") != std::string::npos);
  CHECK(zmx.find("DIAM 5.123456789") != std::string::npos);
  const ZmxImport imported = parse_zmx(zmx, "model.zmx");
  test::check_identical_lenses(lens, imported.lens);
}

TEST_CASE("zmx: UTF-16 LE and ASCII, CRLF and LF read the same") {
  const Lens lens = read_lens(test::source_dir() / "lenses" / "tessar.toml");
  const std::string crlf = format_zmx(lens);
  REQUIRE(crlf.find("\r\n") != std::string::npos);
  const std::string lf = to_lf(crlf);
  for (const std::string& bytes : {crlf, lf, to_utf16le(crlf), to_utf16le(lf)}) {
    const ZmxImport imported = parse_zmx(bytes, "tessar.zmx");
    test::check_identical_lenses(lens, imported.lens);
  }
  CHECK(decode_text(to_utf16le("GLAS")) == "GLAS");
}

TEST_CASE("zmx: textbook designs import and analyse to their stated focal lengths") {
  struct Case {
    const char* file;
    double stated_efl_mm;
    double precision_mm;  // of the source's figure
  };
  // AC254-100-A: 100.1 mm stated to 0.1 mm; the Cooke triplet 50 mm; the double Gauss nominally
  // 100 mm (its paraxial EFL is 99.50 mm, within the half-unit of the nominal figure).
  for (const Case& c :
       {Case{"achromat_ac254_100.zmx", 100.1, 0.05}, Case{"cooke_triplet_50.zmx", 50.0, 0.05},
        Case{"double_gauss_100.zmx", 100.0, 0.5}}) {
    CAPTURE(c.file);
    const ZmxImport imported = read_zmx(test::source_dir() / "lenses" / "zmx" / c.file);
    const Lens& lens = imported.lens;
    const double efl_mm = paraxial_efl_mm(lens);
    MESSAGE(std::string(c.file) << ": paraxial EFL " << efl_mm << " mm (stated " << c.stated_efl_mm
                                << ")");
    CHECK(std::abs(efl_mm - c.stated_efl_mm) <= c.precision_mm);
    CHECK(lens.stop_index() >= 0);
    CHECK(lens.specs.wavelengths_nm.size() == 3);
    // The spec focal length is the lens's own, so analysis needs no scaling either way.
    CHECK(lens.specs.focal_length_mm() == doctest::Approx(efl_mm).epsilon(1e-12));
    AnalyzeOptions options;
    options.trace.scale_to_spec = false;
    options.trace.rings = 4;
    options.trace.fields = 3;
    options.trace.threads = 1;
    const AnalysisReport report = analyze_lens(lens, options);
    CHECK(report.efl_mm == doctest::Approx(efl_mm).epsilon(1e-9));
    CHECK(report.ray_failures == 0);
    REQUIRE(report.mean_rms_spot_um.has_value());
    CHECK(*report.mean_rms_spot_um > 0.0);
  }
  // The triplet's stop is on a curved surface: a flat stop is inserted before it, with a warning.
  const ZmxImport cooke = read_zmx(test::source_dir() / "lenses" / "zmx" / "cooke_triplet_50.zmx");
  CHECK(cooke.lens.surfaces.size() == 7);
  CHECK(cooke.lens.stop_index() == 3);
  CHECK(cooke.lens.specs.f_number == doctest::Approx(paraxial_efl_mm(cooke.lens) / 10.0));
  bool stop_warning = false;
  for (const std::string& w : cooke.warnings)
    stop_warning = stop_warning || w.find("flat stop surface is inserted") != std::string::npos;
  CHECK(stop_warning);
}

TEST_CASE(
    "zmx: conics and even aspheres round-trip exactly; other types are errors naming the line") {
  // TOML -> ZMX -> TOML keeps every profile number bit for bit.
  Lens lens = read_lens(test::source_dir() / "lenses" / "doublet.toml");
  lens.surfaces[0].conic = -0.637;
  lens.surfaces[0].asphere_r2_per_mm = 1.0 / 3.0;
  lens.surfaces[0].asphere = {1.0 / 7.0 * 1e-4, -2e-7, 3.3e-9, 0.0, 1.0 / 9.0 * 1e-14, 0.0, 5e-19};
  lens.surfaces[1].conic = 2.5;  // a conic on a STANDARD surface
  lens.surfaces[3].asphere[1] = -1e-6;
  const Lens back = parse_zmx(format_zmx(lens), "round.zmx").lens;
  test::check_identical_lenses(lens, back);
  const Lens toml = parse_lens_toml(format_lens_toml(back), "round.toml");
  test::check_identical_lenses(lens, toml);
  {
    // EVENASPH has PARM 1..8; a ninth term is refused, naming it.
    const std::string text = small_zmx(
        "", "  TYPE EVENASPH\n  CURV 0.02\n  PARM 9 1e-20\n  DISZ 3\n  GLAS ___BLANK 1 0 1.5 60\n");
    const Error e = error_of(text);
    CHECK(e.where().file == "bad.zmx");
    CHECK(e.where().line == line_of(text, "PARM 9"));
    CHECK(std::string(e.what()).find("PARM 9") != std::string::npos);
  }
  {
    const std::string text = small_zmx("", "  TYPE TOROIDAL\n  CURV 0.02\n  DISZ 3\n");
    const Error e = error_of(text);
    CHECK(e.where().line == line_of(text, "TYPE TOROIDAL"));
    CHECK(std::string(e.what()).find("TOROIDAL") != std::string::npos);
  }
  {
    // COORDBRK imports (issue 32, test_zmx_geometry3d.cpp); a parameter it does not have is an
    // error naming its line.
    const std::string text = small_zmx("", "  TYPE COORDBRK\n  PARM 7 1\n  DISZ 0\n");
    const Error e = error_of(text);
    CHECK(e.where().line == line_of(text, "PARM 7"));
    CHECK(std::string(e.what()).find("COORDBRK") != std::string::npos);
  }
  {
    // A conic and an even asphere import (in the file's units: CM here).
    std::string text =
        small_zmx("",
                  "  TYPE EVENASPH\n  CURV 0.02\n  DISZ 3\n  CONI -1.5\n  PARM 1 0.001\n"
                  "  PARM 2 2e-5\n  PARM 8 -3e-17\n  GLAS ___BLANK 1 0 1.5 60\n");
    const Lens mm = parse_zmx(text, "a.zmx").lens;
    CHECK(mm.surfaces[1].conic == -1.5);
    CHECK(mm.surfaces[1].asphere_r2_per_mm == 0.001);
    CHECK(mm.surfaces[1].asphere[0] == 2e-5);
    CHECK(mm.surfaces[1].asphere[6] == -3e-17);
    text.replace(text.find("UNIT MM"), 7, "UNIT CM");
    const Lens cm = parse_zmx(text, "a.zmx").lens;
    CHECK(cm.surfaces[1].conic == -1.5);
    CHECK(cm.surfaces[1].asphere_r2_per_mm == doctest::Approx(0.0001).epsilon(1e-15));
    CHECK(cm.surfaces[1].asphere[0] == doctest::Approx(2e-8).epsilon(1e-15));
    CHECK(cm.surfaces[1].sag_mm(30.0) == doctest::Approx(10.0 * mm.surfaces[1].sag_mm(3.0)));
  }
  {
    // A glass in no shipped catalog: an error naming the glass, the catalogs searched and the
    // closest names.
    const std::string text =
        small_zmx("GCAT OHARA\n", "  TYPE STANDARD\n  CURV 0.02\n  DISZ 3\n  GLAS N-BK77 0 0\n");
    const Error e = error_of(text);
    const std::string message = e.what();
    CHECK(e.where().line == line_of(text, "GLAS N-BK77"));
    CHECK(e.where().column == 8);
    CHECK(message.find("N-BK77") != std::string::npos);
    CHECK(message.find("OHARA") != std::string::npos);
    CHECK(message.find("closest") != std::string::npos);
  }
  {
    // A glass outside the file's catalogs but in a shipped one (issue 30): used, with a warning
    // naming the catalog it came from.
    const std::string text =
        small_zmx("GCAT OHARA\n", "  TYPE STANDARD\n  CURV 0.02\n  DISZ 3\n  GLAS N-BK7 0 0\n");
    const ZmxImport imported = parse_zmx(text, "outside.zmx");
    CHECK(imported.lens.surfaces[1].material.glass->catalog == "SCHOTT");
    bool warned = false;
    for (const std::string& w : imported.warnings)
      warned = warned ||
               (w.find("'N-BK7' is in none of the file's catalogs (OHARA)") != std::string::npos &&
                w.find("SCHOTT") != std::string::npos);
    CHECK(warned);
  }
  {
    // A catalog that does not exist is named too.
    const std::string text =
        small_zmx("GCAT NOSUCHVENDOR\n", "  TYPE STANDARD\n  CURV 0.02\n  DISZ 3\n  GLAS XYZ-1\n");
    const std::string message = error_of(text).what();
    CHECK(message.find("XYZ-1") != std::string::npos);
    CHECK(message.find("NOSUCHVENDOR") != std::string::npos);
  }
  {
    // Field types 0..3 are read (test_system_model.cpp); another is an error at its line.
    const std::string text = small_zmx("FTYP 7 0 2 2 0 0 0\n", "  TYPE STANDARD\n  CURV 0\n");
    const Error e = error_of(text);
    CHECK(e.where().line == line_of(text, "FTYP 7"));
  }
}

TEST_CASE("zmx: a file without GCAT takes its glasses from SCHOTT, OpticStudio's default") {
  // As optiland's test file lens_floa.zmx (tests/data/zmx-real): GLAS N-BK7 and no GCAT line.
  const std::string text =
      small_zmx("", "  TYPE STANDARD\n  CURV 0.02\n  DISZ 3\n  GLAS N-BK7 1 0 1.5168 64.17\n");
  const ZmxImport imported = parse_zmx(text, "nogcat.zmx");
  const Lens& lens = imported.lens;
  REQUIRE(lens.surfaces.size() == 3);
  REQUIRE(lens.surfaces[1].material.glass != nullptr);
  CHECK(lens.surfaces[1].material.kind == Material::Kind::kCatalog);
  CHECK(lens.surfaces[1].material.glass->catalog == "SCHOTT");
  CHECK(lens.surfaces[1].material.glass_name == "N-BK7");
  CHECK(lens.catalog_name == "SCHOTT");
  bool warned = false;
  for (const std::string& w : imported.warnings)
    warned = warned || w.find("no GCAT line: its glasses come from SCHOTT") != std::string::npos;
  CHECK(warned);
  // A glass in no shipped catalog is an error naming the catalog searched (S-BSL7, Ohara's, is
  // used with a warning: test_zmx_glasses.cpp).
  const std::string message =
      error_of(small_zmx("", "  TYPE STANDARD\n  CURV 0.02\n  DISZ 3\n  GLAS S-BSL77 0 0\n"))
          .what();
  CHECK(message.find("unknown glass 'S-BSL77'") != std::string::npos);
  CHECK(message.find("SCHOTT (") != std::string::npos);
}

TEST_CASE("zmx: catalog glasses resolve through GCAT; unknown lines are warnings with lines") {
  const std::string text =
      small_zmx("GCAT OHARA\nFOOB 1 2 3\nPFIL 0 0 0\n",
                "  TYPE STANDARD\n  CURV 0.02\n  DISZ 3\n  GLAS S-BSL7 0 0 1.5 60\n  CLAP 0 5\n"
                "  COMM front\n");
  const ZmxImport imported = parse_zmx(text, "small.zmx");
  const Lens& lens = imported.lens;
  REQUIRE(lens.surfaces.size() == 3);
  CHECK(lens.surfaces[1].material.kind == Material::Kind::kCatalog);
  CHECK(lens.surfaces[1].material.glass_name == "S-BSL7");
  CHECK(lens.catalog_name == "OHARA");
  CHECK(lens.specs.f_number == 4.0);
  CHECK(lens.specs.half_field_deg == 10.0);
  CHECK(lens.specs.dispersion == DispersionModel::kCatalog);
  CHECK(lens.specs.wavelength_channels == std::vector<int>{2, 0});
  auto has = [&](const std::string& needle) {
    for (const std::string& w : imported.warnings)
      if (w.find(needle) != std::string::npos) return true;
    return false;
  };
  CHECK(has(fmt::format("small.zmx:{}: unknown line 'FOOB 1 2 3'", line_of(text, "FOOB"))));
  // CLAP rmin rmax is a circular clear aperture (issue 32): read, not a warning.
  CHECK_FALSE(has(fmt::format("small.zmx:{}:", line_of(text, "CLAP"))));
  CHECK(lens.surfaces[1].semi_diameter_mm > 0.0);
  CHECK(has(fmt::format("PFIL (line {})", line_of(text, "PFIL"))));
  CHECK(has("colour channels assigned by wavelength"));
  // The imported lens writes as TOML that reads back (the catalog name loads).
  const Lens toml = parse_lens_toml(format_lens_toml(lens), "small.toml");
  CHECK(toml.surfaces[1].material.glass_name == "S-BSL7");
}

TEST_CASE("zmx: ENPD gives f/# = EFL / ENPD; units convert to mm") {
  std::string text = small_zmx("",
                               "  TYPE STANDARD\n  CURV 0.02\n  DISZ 3\n  GLAS ___BLANK 1 0 "
                               "1.5 60\n");
  text.replace(text.find("FNUM 4 0"), 8, "ENPD 12.5");
  const Lens lens = parse_zmx(text, "enpd.zmx").lens;
  CHECK(lens.specs.f_number == doctest::Approx(paraxial_efl_mm(lens) / 12.5).epsilon(1e-12));
  std::string cm = text;
  cm.replace(cm.find("UNIT MM"), 7, "UNIT CM");
  const Lens in_cm = parse_zmx(cm, "cm.zmx").lens;
  CHECK(in_cm.surfaces[1].thickness_mm == doctest::Approx(30.0));
  CHECK(paraxial_efl_mm(in_cm) == doctest::Approx(10.0 * paraxial_efl_mm(lens)));
  CHECK(in_cm.specs.f_number == doctest::Approx(lens.specs.f_number));
}

TEST_CASE("zmx: read_lens and write_lens dispatch on .zmx") {
  const auto dir = std::filesystem::temp_directory_path() /
                   ("lensopt_zmx_" + std::to_string(std::random_device{}()));
  std::filesystem::create_directories(dir);
  const Lens lens = read_lens(test::source_dir() / "lenses" / "cooke.toml");
  write_lens(lens, dir / "cooke.zmx");
  const Lens back = read_lens(dir / "cooke.zmx");
  CHECK(back.source_path == (dir / "cooke.zmx").string());
  test::check_identical_lenses(lens, back);
  std::filesystem::remove_all(dir);
}

}  // namespace test_zmx
