// Real .zmx files from other open projects (tests/data/zmx-real, sources in its README): every
// spherical refractive file imports with the shipped glass catalogs and agrees with the
// independent reference values of reference.json to the precision they carry; files with
// features lensopt does not model give one line naming the feature and file:line.
#include <doctest/doctest.h>
#include <fmt/format.h>

#include <cmath>
#include <filesystem>
#include <fstream>
#include <map>
#include <nlohmann/json.hpp>
#include <regex>
#include <string>
#include <vector>

#include "lensopt/analysis/analyze.h"
#include "lensopt/analysis/apertures.h"
#include "lensopt/core/error.h"
#include "lensopt/formats/zmx.h"
#include "lensopt/glass/dispersion.h"
#include "lensopt/lens/lens.h"
#include "lensopt/lens/trace_lens.h"
#include "lensopt/lens/validate.h"
#include "lensopt/paraxial/paraxial.h"
#include "test_support.h"

namespace test_zmx_real {

using namespace lensopt;

namespace {

std::filesystem::path real_dir() {
  return test::source_dir() / "tests" / "data" / "zmx-real";
}

enum class Expect {
  kImports,      // spherical refractive, everything it uses is supported: must import
  kUnsupported,  // a feature lensopt does not model: one clear line naming it and file:line
  kPending,      // imports once system-model / asphere work lands; until then a one-line error
  kGeometry,     // mirrors / coordinate breaks: imports, traced in test_zmx_geometry3d.cpp
};

struct RealFile {
  const char* file;
  Expect expect;
  const char* feature;  // kUnsupported: a word the message must contain; kPending: why
  int line;             // kUnsupported: the line the message must name
};

// Every file of the folder, with what it is expected to do.
const std::vector<RealFile>& real_files() {
  static const std::vector<RealFile> files = {
      {"optiland_lens1.zmx", Expect::kImports, "", 0},
      {"thorlabs_AC254-100-A.zmx", Expect::kImports, "", 0},
      {"thorlabs_AC254-125-A.zmx", Expect::kImports, "", 0},
      {"rayoptics_US00583336-2-scaled.zmx", Expect::kImports, "", 0},
      {"optiland_lens_floa.zmx", Expect::kImports, "", 0},
      {"optiland_thorlabs_AL1815-C_iso_8859_1.zmx", Expect::kImports, "", 0},
      {"rayoptics_US05831776-1.zmx", Expect::kImports, "", 0},
      {"rayoptics_zmax_55278.zmx", Expect::kImports, "", 0},
      // Negative lenses (issue 31): refused before ("needs a positive focal length").
      {"thorlabs_LC1715-A.zmx", Expect::kImports, "", 0},
      {"thorlabs_LD1464-A.zmx", Expect::kImports, "", 0},
      {"thorlabs_ACN254-100-A.zmx", Expect::kImports, "", 0},
      {"rayoptics_HoO-V2C18Ex03.zmx", Expect::kGeometry, "", 0},
      {"rayoptics_zmax_37992.zmx", Expect::kGeometry, "", 0},
  };
  return files;
}

std::string import_error(const std::filesystem::path& path) {
  try {
    read_zmx(path);
  } catch (const Error& error) {
    return error.what();
  }
  return {};
}

}  // namespace

TEST_CASE("zmx-real: the folder's files are all listed, with their expected outcome") {
  std::vector<std::string> on_disk;
  for (const auto& entry : std::filesystem::directory_iterator(real_dir())) {
    std::string extension = entry.path().extension().string();
    for (char& ch : extension) ch = static_cast<char>(std::tolower(static_cast<unsigned char>(ch)));
    if (extension == ".zmx") on_disk.push_back(entry.path().filename().string());
  }
  CHECK(on_disk.size() == real_files().size());
  for (const std::string& name : on_disk) {
    bool listed = false;
    for (const RealFile& f : real_files()) listed = listed || name == f.file;
    CAPTURE(name);
    CHECK(listed);
  }
}

TEST_CASE("zmx-real: spherical refractive files import with the shipped catalogs") {
  std::map<std::string, nlohmann::json> references;
  {
    std::ifstream in(real_dir() / "reference.json");
    REQUIRE(in);
    const nlohmann::json doc = nlohmann::json::parse(in);
    for (const auto& entry : doc.at("lenses"))
      references[entry.at("file").get<std::string>()] = entry;
  }
  int imported = 0;
  int compared = 0;
  for (const RealFile& f : real_files()) {
    if (f.expect != Expect::kImports) continue;
    CAPTURE(f.file);
    const auto path = real_dir() / f.file;
    ZmxImport result;
    REQUIRE_NOTHROW(result = read_zmx(path));
    ++imported;
    const Lens& lens = result.lens;
    // Every glass of these files is a catalog glass, resolved from the shipped catalogs:
    // Schott's, but the Thorlabs asphere's Ohara S-LAH64 and US 5831776's fused silica (MISC).
    const std::string name = f.file;
    const std::string vendor = name.find("AL1815") != std::string::npos       ? "OHARA"
                               : name.find("US05831776") != std::string::npos ? "MISC"
                                                                              : "SCHOTT";
    for (const Surface& s : lens.surfaces) {
      if (s.material.is_air()) continue;
      CHECK(s.material.kind == Material::Kind::kCatalog);
      REQUIRE(s.material.glass != nullptr);
      CHECK(s.material.glass->catalog == vendor);
    }
    // At the file's primary wavelength, one the traced lens holds (TraceLens::index_at_nm has no
    // catalog index at any other wavelength).
    const auto paraxial = paraxial_data(make_trace_lens(lens), lens.specs.primary_wavelength_nm);
    CHECK(std::isfinite(paraxial.efl_mm));
    CHECK(std::isfinite(paraxial.bfl_mm));
    MESSAGE(fmt::format("{}: EFL {:.6f} mm, BFL {:.6f} mm, entrance pupil at {:.6f} mm ({} nm)",
                        f.file, paraxial.efl_mm, paraxial.bfl_mm, paraxial.entrance_pupil_z_mm,
                        lens.specs.primary_wavelength_nm));
    if (const auto it = references.find(f.file); it != references.end()) {
      const nlohmann::json& ref = it->second;
      const double tolerance = ref.at("tolerance_mm").get<double>();
      CAPTURE(ref.at("source").get<std::string>());
      CHECK(std::abs(paraxial.efl_mm - ref.at("efl_mm").get<double>()) <= tolerance);
      CHECK(std::abs(paraxial.bfl_mm - ref.at("bfl_mm").get<double>()) <= tolerance);
      ++compared;
    }
  }
  CHECK(imported == 11);
  CHECK(compared == 2);
}

TEST_CASE("zmx-real: lens_floa's FLOA stop gives a paraxial F/0.499: it imports with a warning") {
  // Its stop (semi-diameter 8.5 mm, 10 mm behind a 20 mm singlet) is imaged into an entrance
  // pupil of 40.47 mm: EFL / EPD = 20.2107 / 40.4730 = 0.49936, below the F/0.5 of an image-space
  // NA of 1. OpticStudio and optiland load the file (their outer rays miss a surface); lensopt
  // imports it as written and says so, naming the file and the F-number.
  const auto path = real_dir() / "optiland_lens_floa.zmx";
  ZmxImport result;
  REQUIRE_NOTHROW(result = read_zmx(path));
  const Lens& lens = result.lens;
  CHECK(lens.specs.aperture_type == ApertureType::kFloatByStop);
  CHECK(lens.specs.f_number == doctest::Approx(0.49936).epsilon(1e-5));
  const std::vector<std::string> warnings = f_number_warnings(lens);
  REQUIRE(warnings.size() == 1);
  CAPTURE(warnings[0]);
  CHECK(warnings[0].find("optiland_lens_floa.zmx") != std::string::npos);
  CHECK(warnings[0].find("0.49936") != std::string::npos);
  CHECK(warnings[0].find('\n') == std::string::npos);
  // The same F-number is refused where it is a request: the paper's spec mode.
  Lens paper = lens;
  paper.specs.mode = SpecMode::kPaper;
  paper.specs.half_field_deg = 10.0;
  CHECK(f_number_warnings(paper).empty());
  CHECK_THROWS_WITH(validate_lens(paper), doctest::Contains("f_number = 0.49936"));
  // A lens as written keeps a sanity bound: an entrance pupil of more than ten focal lengths.
  Lens nonsense = lens;
  nonsense.specs.f_number = 0.5 * kMinParaxialFNumber;
  CHECK_THROWS_WITH(validate_lens(nonsense), doctest::Contains("must be in [0.05, 1000]"));
  // At F/0.5 and above nothing is said.
  Lens slower = lens;
  slower.specs.f_number = kMinFNumber;
  CHECK(f_number_warnings(slower).empty());

  // analyze counts the rays that miss a surface (the aimed pupil reaches beyond the 9.68 mm rim
  // where the singlet's surfaces meet: they miss surface 2), and the relative illumination,
  // whose edge rays fail, is unavailable: n/a in the text, null in the JSON, never 0 or NaN.
  const AnalysisReport r = analyze_lens(lens, AnalyzeOptions{});
  REQUIRE(r.fields.size() == 1);
  CHECK(r.ray_failures > 0);
  CHECK(r.ray_failures < r.fields[0].traced_rays + r.ray_failures);  // some rays arrive
  REQUIRE(r.failures_by_surface.size() >= 2);
  CHECK(r.failures_by_surface[1] == r.ray_failures);
  CHECK(r.fields[0].failed_rays == r.ray_failures);
  CHECK_FALSE(r.fields[0].relative_illumination);
  REQUIRE(r.fields[0].rms_spot_um);
  CHECK(std::isfinite(*r.fields[0].rms_spot_um));
  const std::string text = format_report_text(r), json = format_report_json(r);
  CHECK(text.find("n/a") != std::string::npos);
  CHECK(json.find("\"relative_illumination\": [\n    null") != std::string::npos);
  // Its automatic semi-diameters: surface 1 has one (the marginal rays reach it), surface 2,
  // which they miss, has none, and the .zmx writer writes no DIAM for it (not "DIAM 0 0").
  const std::vector<double> automatic = automatic_semi_diameters(lens);
  REQUIRE(automatic.size() >= 2);
  CHECK(automatic[0] > 0.0);
  CHECK(std::isnan(automatic[1]));
  CHECK(format_zmx(lens).find("DIAM 0 0") == std::string::npos);
  for (const std::string& out : {text, json}) {
    CHECK_FALSE(std::regex_search(out, std::regex("\\b(nan|inf)\\b")));  // not "infinity"
  }
}

TEST_CASE("zmx-real: unsupported features are one line naming the feature and file:line") {
  for (const RealFile& f : real_files()) {
    if (f.expect != Expect::kUnsupported) continue;
    CAPTURE(f.file);
    const std::string what = import_error(real_dir() / f.file);
    CAPTURE(what);
    REQUIRE_FALSE(what.empty());
    CHECK(what.find('\n') == std::string::npos);
    CHECK(what.find(fmt::format("{}:{}:", f.file, f.line)) != std::string::npos);
    CHECK(what.find(f.feature) != std::string::npos);
  }
}

TEST_CASE("zmx-real: files waiting for other work either import or fail on one line") {
  for (const RealFile& f : real_files()) {
    if (f.expect != Expect::kPending) continue;
    CAPTURE(f.file);
    const std::string what = import_error(real_dir() / f.file);
    if (what.empty()) {
      MESSAGE(fmt::format("{}: imports now (was waiting for {})", f.file, f.feature));
      continue;
    }
    MESSAGE(fmt::format("{}: not imported yet, needs {}: {}", f.file, f.feature, what));
    CHECK(what.find('\n') == std::string::npos);
    CHECK(what.find(std::string(f.file) + ":") != std::string::npos);
  }
}

namespace {

// A small two-glass doublet whose glasses come from two vendors' catalogs.
std::string two_vendor_zmx(const std::string& gcat, const std::string& glass1,
                           const std::string& glass2) {
  return "MODE SEQ\nUNIT MM X W X CM MR CPMM\nENPD 10\n" + gcat +
         "FTYP 0 0 2 3 0 0 0\nXFLN 0 0\nYFLN 0 5\n"
         "WAVM 1 0.4861327 1\nWAVM 2 0.5875618 1\nWAVM 3 0.6562725 1\n"
         "SURF 0\n  TYPE STANDARD\n  CURV 0\n  DISZ INFINITY\n"
         "SURF 1\n  STOP\n  TYPE STANDARD\n  CURV 0.016\n  DISZ 4\n  " +
         glass1 +
         "\n"
         "SURF 2\n  TYPE STANDARD\n  CURV -0.022\n  DISZ 2.5\n  " +
         glass2 +
         "\n"
         "SURF 3\n  TYPE STANDARD\n  CURV -0.0078\n  DISZ 97\n"
         "SURF 4\n  TYPE STANDARD\n  CURV 0\n  DISZ 0\n";
}

// The materials of the glass spaces, in order (a stop inserted at a curved vertex is air).
std::vector<Material> glasses_of(const Lens& lens) {
  std::vector<Material> out;
  for (const Surface& s : lens.surfaces)
    if (!s.material.is_air()) out.push_back(s.material);
  return out;
}

std::string zmx_error(const std::string& text) {
  try {
    parse_zmx(text, "two.zmx");
  } catch (const Error& error) {
    return error.what();
  }
  return {};
}

}  // namespace

TEST_CASE("zmx catalogs: GCAT SCHOTT OHARA resolves out of the box") {
  const ZmxImport imported = parse_zmx(
      two_vendor_zmx("GCAT SCHOTT OHARA\n", "GLAS N-BK7 0 0 1.5168 64.17", "GLAS S-TIH6 0 0"),
      "two.zmx");
  const std::vector<Material> glasses = glasses_of(imported.lens);
  REQUIRE(glasses.size() == 2);
  REQUIRE(glasses[0].glass != nullptr);
  REQUIRE(glasses[1].glass != nullptr);
  CHECK(glasses[0].glass->catalog == "SCHOTT");
  CHECK(glasses[1].glass->catalog == "OHARA");
  CHECK(imported.lens.specs.dispersion == DispersionModel::kCatalog);
  // Model glasses stay model glasses, whatever the catalogs.
  const ZmxImport model =
      parse_zmx(two_vendor_zmx("GCAT SCHOTT OHARA\n", "GLAS ___BLANK 1 0 1.5168 64.17",
                               "GLAS ___BLANK 1 0 1.80518 25.43"),
                "model.zmx");
  const std::vector<Material> models = glasses_of(model.lens);
  REQUIRE(models.size() == 2);
  CHECK(models[0].kind == Material::Kind::kModel);
  CHECK(models[0].nd == 1.5168);
  CHECK(models[1].kind == Material::Kind::kModel);
  CHECK(models[1].vd == 25.43);
  // HOYA and CDGM ship as well.
  const ZmxImport asian = parse_zmx(
      two_vendor_zmx("GCAT HOYA CDGM\n", "GLAS BSC7 0 0", "GLAS H-ZF13 0 0"), "asian.zmx");
  const std::vector<Material> vendors = glasses_of(asian.lens);
  REQUIRE(vendors.size() == 2);
  REQUIRE(vendors[0].glass != nullptr);
  REQUIRE(vendors[1].glass != nullptr);
  CHECK(vendors[0].glass->catalog == "HOYA");
  CHECK(vendors[1].glass->catalog == "CDGM");
}

TEST_CASE("zmx catalogs: an unknown glass names the catalogs and the nearest glasses") {
  const std::string text =
      two_vendor_zmx("GCAT SCHOTT OHARA\n", "GLAS N-BK77 0 0 1.5168 64.17", "GLAS SF5 0 0");
  const std::string what = zmx_error(text);
  CAPTURE(what);
  REQUIRE_FALSE(what.empty());
  CHECK(what.find('\n') == std::string::npos);
  CHECK(what.find("two.zmx:") != std::string::npos);
  CHECK(what.find("unknown glass 'N-BK77'") != std::string::npos);
  CHECK(what.find("SCHOTT (") != std::string::npos);  // catalogs searched, with their files
  CHECK(what.find("OHARA (") != std::string::npos);
  CHECK(what.find("closest by name: N-BK7") != std::string::npos);
  // By (nd, vd) from the GLAS line: N-BK7 itself is the nearest on the glass map.
  CHECK(what.find("nearest to nd = 1.5168, vd = 64.17: SCHOTT N-BK7 (1.5168, 64.17)") !=
        std::string::npos);
  // Without nd and vd on the line there is no map suggestion, still the names.
  const std::string bare =
      zmx_error(two_vendor_zmx("GCAT SCHOTT\n", "GLAS N-BK77 0 0", "GLAS SF5 0 0"));
  CHECK(bare.find("closest by name") != std::string::npos);
  CHECK(bare.find("nearest to nd") == std::string::npos);
}

}  // namespace test_zmx_real
