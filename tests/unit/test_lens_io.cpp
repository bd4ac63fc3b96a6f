// Lens formats: the native TOML round trip is exact (every double bit for bit, and format is a
// fixed point), the project's TOML lenses are the paper's YAML prescriptions, other tables
// survive, and bad input names file:line and the problem.
#include <doctest/doctest.h>
#include <toml++/toml.h>

#include <bit>
#include <cmath>
#include <cstdint>
#include <filesystem>
#include <fstream>
#include <random>
#include <string>
#include <vector>

#include "error_checks.h"
#include "lens_checks.h"
#include "lensopt/core/atomic_file.h"
#include "lensopt/core/error.h"
#include "lensopt/formats/lens_file.h"
#include "lensopt/glass/glass.h"
#include "lensopt/lens/lens_io.h"
#include "test_support.h"

namespace test_lens_io {

using namespace lensopt;
using lensopt::test::bits;

namespace {

using lensopt::test::check_contains;
using lensopt::test::error_of;

// format -> parse gives the same lens, and format(parse(format(l))) == format(l).
void check_round_trip(const Lens& lens, const std::string& source_name) {
  const std::string text = format_lens_toml(lens);
  const Lens again = parse_lens_toml(text, source_name);
  test::check_identical_lenses(lens, again);
  CHECK(format_lens_toml(again) == text);
}

std::string toml_error(const std::string& text) {
  return error_of([&] { parse_lens_toml(text, "bad.toml"); });
}

std::string yaml_error(const std::string& text) {
  return error_of([&] { parse_lens_yaml(text, "bad.yml"); });
}

std::vector<std::filesystem::path> project_lenses() {
  std::vector<std::filesystem::path> paths;
  for (const auto& item : std::filesystem::directory_iterator(test::source_dir() / "lenses"))
    if (item.path().extension() == ".toml") paths.push_back(item.path());
  std::sort(paths.begin(), paths.end());
  return paths;
}

// A valid lens without catalog glasses: stop, then a model-glass singlet.
const char* const kGoodToml = R"([lens]
name = "good"

[[surfaces]]
radius_mm = inf
thickness_mm = 2.0
stop = true

[[surfaces]]
radius_mm = 20.0
thickness_mm = 3.0
material = { nd = 1.7, vd = 50.0 }

[[surfaces]]
radius_mm = -30.0
thickness_mm = 15.0
)";

}  // namespace

TEST_CASE("lens io: every lenses/*.toml round-trips exactly through format_lens_toml") {
  const auto paths = project_lenses();
  CHECK(paths.size() >= 4);
  for (const auto& path : paths) {
    CAPTURE(path.string());
    const Lens lens = read_lens(path);
    CHECK(lens.source_path == path.string());
    CHECK(lens.catalog_name == "ohara");
    check_round_trip(lens, path.string());
    // The file's own doubles come back too: parsing the file twice is deterministic and the
    // formatted text parses to the same lens as the file.
    test::check_identical_lenses(lens, parse_lens_toml(format_lens_toml(lens), path.string()));
  }
}

TEST_CASE("lens io: lenses/X.toml are the paper's released YAML prescriptions") {
  LENSOPT_REQUIRE_SHARED(shared);
  // The YAML's nd and v are float32 copies of figures computed from the glass formula, so they
  // agree with the catalog's rounded nd (5 decimals) and vd (2 decimals) to about their rounding.
  // The Tessar's indices differ more (up to 1.0e-4 in nd): its glasses are not exact catalog
  // figures, and its TOML uses the nearest catalog glass.
  struct Pair {
    const char* toml;
    const char* yaml;
    double nd_tolerance;
    double vd_tolerance;
  };
  const Pair pairs[] = {{"doublet", "baseline_doublet.yml", 1e-5, 5e-3},
                        {"cooke", "baseline_cooke.yml", 1e-5, 5e-3},
                        {"tessar", "baseline_tessar.yml", 1.5e-4, 6e-3},
                        {"singlet", "singlet_lens.yml", 1e-5, 5e-3}};
  const auto catalog = load_catalog("ohara");
  for (const Pair& pair : pairs) {
    CAPTURE(pair.toml);
    const Lens toml = read_lens(test::source_dir() / "lenses" / (std::string(pair.toml) + ".toml"));
    const Lens yaml = read_lens(shared / "data" / "reference-lenses" / pair.yaml);
    CHECK(toml.specs.f_number == yaml.specs.f_number);
    CHECK(toml.specs.half_field_deg == yaml.specs.half_field_deg);
    CHECK(toml.specs.sensor_diagonal_mm == yaml.specs.sensor_diagonal_mm);
    CHECK(toml.specs.wavelengths_nm == yaml.specs.wavelengths_nm);
    REQUIRE(toml.surfaces.size() == yaml.surfaces.size());
    for (std::size_t i = 0; i < toml.surfaces.size(); ++i) {
      CAPTURE(i);
      const Surface& s = toml.surfaces[i];
      const Surface& y = yaml.surfaces[i];
      CHECK(s.written_as_radius);
      CHECK(std::abs(s.curvature_per_mm - y.curvature_per_mm) <=
            1e-15 * std::abs(y.curvature_per_mm));
      CHECK(bits(s.thickness_mm) == bits(y.thickness_mm));
      CHECK(s.is_stop == y.is_stop);
      CHECK(s.material.is_air() == y.material.is_air());
      if (y.material.is_air()) continue;
      CHECK(s.material.kind == Material::Kind::kCatalog);
      CHECK(std::abs(s.material.nd - y.material.nd) <= pair.nd_tolerance);
      CHECK(std::abs(s.material.vd - y.material.vd) <= pair.vd_tolerance);
      // No other catalog glass is nearer to the YAML's (nd, v), in units of 1e-3 and 0.1.
      auto distance2 = [&](const Glass& g) {
        const double dn = (g.nd - y.material.nd) / 1e-3;
        const double dv = (g.vd - y.material.vd) / 0.1;
        return dn * dn + dv * dv;
      };
      const Glass& chosen = catalog->at(s.material.glass_name);
      for (const Glass& g : catalog->glasses) CHECK(distance2(chosen) <= distance2(g));
    }
  }
}

TEST_CASE("yaml: the paper's lenses read as is") {
  LENSOPT_REQUIRE_SHARED(shared);
  const auto path = shared / "data" / "reference-lenses" / "baseline_cooke.yml";
  const Lens lens = read_lens(path);
  CHECK(lens.name == "baseline_cooke");
  CHECK(lens.source_path == path.string());
  CHECK(lens.catalog_name.empty());
  REQUIRE(lens.surfaces.size() == 7);
  CHECK(lens.stop_index() == 4);
  CHECK(lens.element_count() == 3);
  CHECK(lens.specs.f_number == 2.0);
  CHECK(lens.specs.half_field_deg == 25.0);
  CHECK(lens.specs.sensor_diagonal_mm == 16.0);
  CHECK(lens.specs.wavelengths_nm == paper_wavelengths_nm());
  CHECK(lens.specs.dispersion == DispersionModel::kAbbe);
  CHECK(lens.surfaces[0].curvature_per_mm == 0.10994608700275421);
  CHECK(!lens.surfaces[0].written_as_radius);
  CHECK(lens.surfaces[6].thickness_mm == 13.061942100524902);
  CHECK(lens.surfaces[2].material.kind == Material::Kind::kModel);
  CHECK(lens.surfaces[2].material.nd == 1.6258817911148071);
  CHECK(lens.surfaces[2].material.vd == 35.69896697998047);
  CHECK(lens.surfaces[3].material.is_air());

  // Every released file reads, and its TOML form round-trips exactly.
  for (const char* name :
       {"baseline_doublet.yml", "baseline_cooke.yml", "baseline_tessar.yml", "singlet_lens.yml"}) {
    CAPTURE(name);
    const Lens yaml = read_lens(shared / "data" / "reference-lenses" / name);
    check_round_trip(yaml, "from_yaml.toml");
  }
  const Lens tessar = read_lens(shared / "data" / "reference-lenses" / "baseline_tessar.yml");
  CHECK(tessar.element_count() == 4);
  CHECK(tessar.surfaces[5].material.nd == 1.7638611793518066);
  CHECK(tessar.surfaces[6].material.nd == 1.9166003465652466);
}

TEST_CASE("yaml: plain scalars as well as one-element lists") {
  const Lens lens = parse_lens_yaml(R"(stop_idx: 0
sequence: AGA
hfov: 20
f_number: 2.8
c: [0.0, 0.02, -0.04]
t: [5, 3.0, 15.0]
nd: 1.9
v: 31.6
)",
                                    "dir/scalar_lens.yml");
  CHECK(lens.name == "scalar_lens");
  CHECK(lens.specs.half_field_deg == 20.0);
  CHECK(lens.specs.f_number == 2.8);
  REQUIRE(lens.surfaces.size() == 3);
  CHECK(lens.surfaces[0].is_stop);
  CHECK(lens.surfaces[0].thickness_mm == 5.0);
  CHECK(lens.surfaces[1].material.nd == 1.9);
  CHECK(lens.surfaces[1].material.vd == 31.6);
  CHECK(lens.surfaces[2].material.is_air());
}

TEST_CASE("toml: numbers, radii and flat surfaces in every accepted spelling") {
  const Lens lens = parse_lens_toml(R"([lens]
name = "spellings"

[specs]
f_number = 4
half_field_deg = 10.5
sensor_diagonal_mm = 8
wavelengths_nm = [450, 550.5, 650]
channels = ["B", "g", "R"]
dispersion = "Catalog"

[[surfaces]]
radius_mm = "Infinity"
thickness_mm = 2
stop = true

[[surfaces]]
radius_mm = 9.1
thickness_mm = 3.0
material = { nd = 1.5168, vd = 64.17 }
semi_diameter_mm = 4.5

[[surfaces]]
curvature_per_mm = -0.0125
thickness_mm = 1.0
material = "air"

[[surfaces]]
radius_mm = -inf
thickness_mm = 20.0
)",
                                    "spellings.toml");
  CHECK(lens.specs.f_number == 4.0);
  CHECK(lens.specs.wavelengths_nm == std::vector<double>{450.0, 550.5, 650.0});
  CHECK(lens.specs.wavelength_channels == std::vector<int>{2, 1, 0});
  CHECK(lens.specs.dispersion == DispersionModel::kCatalog);
  REQUIRE(lens.surfaces.size() == 4);
  CHECK(lens.surfaces[0].curvature_per_mm == 0.0);
  CHECK(lens.surfaces[0].thickness_mm == 2.0);
  CHECK(lens.surfaces[1].curvature_per_mm == 1.0 / 9.1);
  CHECK(lens.surfaces[1].written_as_radius);
  CHECK(lens.surfaces[1].semi_diameter_mm == 4.5);
  CHECK(lens.surfaces[2].curvature_per_mm == -0.0125);
  CHECK(!lens.surfaces[2].written_as_radius);
  CHECK(lens.surfaces[2].material.is_air());
  CHECK(std::signbit(lens.surfaces[3].curvature_per_mm));

  const std::string text = format_lens_toml(lens);
  check_contains(text, "radius_mm = inf\n");
  check_contains(text, "radius_mm = 9.1\n");  // the radius as the file wrote it
  check_contains(text, "curvature_per_mm = -0.0125\n");
  check_contains(text, "radius_mm = -inf\n");
  check_contains(text, "thickness_mm = 2.0\n");  // a float, not the integer 2
  check_contains(text, "channels = [\"B\", \"G\", \"R\"]\n");
  check_contains(text, "dispersion = \"catalog\"\n");
  check_round_trip(lens, "spellings.toml");
}

TEST_CASE("toml: radius_mm = 1/c round-trips bit for bit for random curvatures") {
  // Curvatures log-uniform in 1e-4..1 /mm of both signs, written as radii: parse(format(l)) has
  // the same doubles (radius when some R has fl(1/R) == c, else curvature), and format is a
  // fixed point.
  std::mt19937_64 rng(20230617);
  std::uniform_real_distribution<double> log10_curvature(-4.0, 0.0);
  // 2 x 999 random surfaces: two lenses within the reader's 1000-surface limit.
  for (int batch = 0; batch < 2; ++batch) {
    Lens lens = parse_lens_toml(kGoodToml, "random.toml");
    const Surface glass_surface = lens.surfaces[1];
    lens.surfaces.resize(1);
    for (int i = 0; i < 999; ++i) {
      Surface s = glass_surface;
      s.curvature_per_mm = (i % 2 ? -1.0 : 1.0) * std::pow(10.0, log10_curvature(rng));
      s.thickness_mm = std::pow(10.0, log10_curvature(rng) + 1.0);
      s.material = i % 2 ? Material::air() : Material::model(1.5 + 0.001 * i, 20.0 + 0.01 * i);
      lens.surfaces.push_back(s);
    }
    lens.surfaces.back().material = Material::air();
    const std::string text = format_lens_toml(lens);
    const Lens again = parse_lens_toml(text, "random.toml");
    REQUIRE(again.surfaces.size() == lens.surfaces.size());
    int as_radius = 0;
    for (std::size_t i = 0; i < lens.surfaces.size(); ++i) {
      CHECK(bits(again.surfaces[i].curvature_per_mm) == bits(lens.surfaces[i].curvature_per_mm));
      CHECK(bits(again.surfaces[i].thickness_mm) == bits(lens.surfaces[i].thickness_mm));
      CHECK(bits(again.surfaces[i].material.nd) == bits(lens.surfaces[i].material.nd));
      as_radius += again.surfaces[i].written_as_radius ? 1 : 0;
    }
    MESSAGE(as_radius, " of ", lens.surfaces.size(), " curvatures written as an exact radius");
    CHECK(as_radius > static_cast<int>(lens.surfaces.size()) / 2);
    CHECK(format_lens_toml(again) == text);
  }
}

TEST_CASE("toml: extra tables survive a round trip") {
  // Top-level inline tables must come before the first header.
  const std::string text =
      "inline_top = { a = 1 }\nlisted = [{ b = 2 }, { b = 3 }]\n" + std::string(kGoodToml) + R"(
[optimize]
steps = 200
tolerance = 1e-10
weights = [0.1, 0.2, 0.7]
method = "lm \"fast\""
phase.first = { iterations = 5, damping = 0.5 }
when = 2023-06-17T10:00:00Z
"odd key" = true

[tolerance.monte_carlo]
trials = 500
seed = 7

[[search.runs]]
seed = 1

[[search.runs]]
seed = 2
[search.runs.start]
scale = 1.5

[empty]
)";
  const Lens lens = parse_lens_toml(text, "extra.toml");
  check_contains(lens.extra_toml, "[optimize]");
  check_contains(lens.extra_toml, "[tolerance.monte_carlo]");
  check_contains(lens.extra_toml, "[[search.runs]]");
  check_contains(lens.extra_toml, "weights = [0.1, 0.2, 0.7]\n");  // shortest exact decimals
  check_contains(lens.extra_toml, "tolerance = 1e-10\n");
  const std::string formatted = format_lens_toml(lens);
  check_round_trip(lens, "extra.toml");

  // The values themselves are intact, doubles exact, and nothing joined the lens's last surface.
  const Lens again = parse_lens_toml(formatted, "extra.toml");
  CHECK(again.surfaces.size() == 3);
  const toml::table extra = toml::parse(again.extra_toml);
  CHECK(extra["optimize"]["steps"].value<std::int64_t>() == 200);
  CHECK(extra["optimize"]["tolerance"].value<double>() == 1e-10);
  CHECK(extra["optimize"]["weights"][0].value<double>() == 0.1);
  CHECK(extra["optimize"]["weights"][2].value<double>() == 0.7);
  CHECK(extra["optimize"]["method"].value<std::string>() == "lm \"fast\"");
  CHECK(extra["optimize"]["phase"]["first"]["damping"].value<double>() == 0.5);
  CHECK(extra["optimize"]["odd key"].value<bool>() == true);
  REQUIRE(extra["optimize"]["when"].as_date_time() != nullptr);
  CHECK(extra["optimize"]["when"].as_date_time()->get().date.year == 2023);
  CHECK(extra["tolerance"]["monte_carlo"]["trials"].value<std::int64_t>() == 500);
  REQUIRE(extra["search"]["runs"].as_array() != nullptr);
  CHECK(extra["search"]["runs"].as_array()->size() == 2);
  CHECK(extra["search"]["runs"][1]["seed"].value<std::int64_t>() == 2);
  CHECK(extra["search"]["runs"][1]["start"]["scale"].value<double>() == 1.5);
  CHECK(extra["empty"].as_table() != nullptr);
  CHECK(extra["inline_top"]["a"].value<std::int64_t>() == 1);
  CHECK(extra["listed"][1]["b"].value<std::int64_t>() == 3);
}

TEST_CASE("lens io: write_lens writes atomically what format_lens_toml gives, read_lens reads it") {
  const auto dir = std::filesystem::temp_directory_path() /
                   ("lensopt-lens-io-" + std::to_string(std::random_device{}()));
  std::filesystem::create_directories(dir);
  const Lens lens = parse_lens_toml(kGoodToml, "good.toml");
  write_lens(lens, dir / "out.toml");
  CHECK(read_file(dir / "out.toml") == format_lens_toml(lens));
  const Lens back = read_lens(dir / "out.toml");
  CHECK(back.source_path == (dir / "out.toml").string());
  CHECK(format_lens_toml(back) == format_lens_toml(lens));
  check_contains(error_of([&] { write_lens(lens, dir / "out.yml"); }), "out.yml");
  CHECK(!std::filesystem::exists(dir / "out.yml"));
  std::filesystem::remove_all(dir);
}

TEST_CASE("lens io: read_lens dispatches by extension") {
  const std::string zmx = error_of([] { read_lens("some/lens.zmx"); });
  check_contains(zmx, "some/lens.zmx");  // dispatched to the .zmx reader: it cannot read the file
  check_contains(zmx, "cannot read");
  const std::string unknown = error_of([] { read_lens("some/lens.json"); });
  check_contains(unknown, "some/lens.json");
  check_contains(unknown, "'.json'");
  check_contains(error_of([] { read_lens("no/such/lens.toml"); }), "no/such/lens.toml");
}

TEST_CASE("toml: errors name the file, the line and the problem") {
  SUBCASE("malformed TOML syntax") {
    const std::string e = toml_error(
        "[lens]\nname = \"x\"\n\n[[surfaces]]\nradius_mm = inf\n"
        "thickness_mm = = 2.0\n");
    check_contains(e, "bad.toml:6:");
    check_contains(e, "TOML syntax error");
  }
  SUBCASE("missing thickness_mm") {
    const std::string e = toml_error(R"([lens]
name = "x"

[[surfaces]]
radius_mm = inf
thickness_mm = 2.0
stop = true

[[surfaces]]
radius_mm = 20.0
material = { nd = 1.7, vd = 50.0 }

[[surfaces]]
radius_mm = -30.0
thickness_mm = 15.0
)");
    check_contains(e, "bad.toml:9:");
    check_contains(e, "surface 2: missing thickness_mm");
  }
  SUBCASE("both radius_mm and curvature_per_mm") {
    const std::string e = toml_error(R"([[surfaces]]
radius_mm = inf
thickness_mm = 2.0
stop = true

[[surfaces]]
radius_mm = 20.0
thickness_mm = 3.0
curvature_per_mm = 0.05
)");
    check_contains(e, "bad.toml:9:1:");
    check_contains(e, "surface 2: give radius_mm or curvature_per_mm, not both");
  }
  SUBCASE("unknown key, with a suggestion") {
    const std::string e = toml_error(R"([lens]
name = "x"

[[surfaces]]
radius_mm = inf
thicknes_mm = 2.0
)");
    check_contains(e, "bad.toml:6:1:");
    check_contains(e, "unknown key 'thicknes_mm' in surface 1");
    check_contains(e, "did you mean 'thickness_mm'?");
    const std::string specs = toml_error("[specs]\nf_number = 2.0\nhalf_field = 25.0\n");
    check_contains(specs, "bad.toml:3:1:");
    check_contains(specs, "unknown key 'half_field' in [specs] (did you mean 'half_field_deg'?)");
    const std::string top = toml_error("name = \"x\"\n");
    check_contains(top, "bad.toml:1:1:");
    check_contains(top, "unknown top-level key 'name'");
  }
  SUBCASE("unknown glass names the catalog and the closest glasses") {
    const std::string e = toml_error(R"([lens]
name = "x"
catalog = "ohara"

[[surfaces]]
radius_mm = inf
thickness_mm = 2.0
stop = true

[[surfaces]]
radius_mm = 20.0
thickness_mm = 3.0
material = "S-LAH97"

[[surfaces]]
radius_mm = -30.0
thickness_mm = 15.0
)");
    check_contains(e, "bad.toml:13:12:");
    check_contains(e, "unknown glass 'S-LAH97' in catalog 'ohara'");
    check_contains(e, "closest: ");
    check_contains(e, "S-LAH96");
  }
  SUBCASE("a glass name without a catalog") {
    const std::string e =
        toml_error("[[surfaces]]\nradius_mm = 20.0\nthickness_mm = 3.0\nmaterial = \"S-LAH96\"\n");
    check_contains(e, "bad.toml:4:");
    check_contains(e, "has no catalog");
  }
  SUBCASE("no stop") {
    std::string text = kGoodToml;
    text.replace(text.find("stop = true\n"), 12, "");
    const std::string e = toml_error(text);
    check_contains(e, "bad.toml:4:1:");
    check_contains(e, "no surface is the aperture stop");
  }
  SUBCASE("a curved stop") {
    const std::string e = toml_error(R"([[surfaces]]
radius_mm = 20.0
thickness_mm = 3.0
stop = true
)");
    check_contains(e, "bad.toml:4:1:");
    check_contains(e, "surface 1: the stop must be flat");
    check_contains(e, "radius is 20 mm");
  }
  SUBCASE("two stops") {
    const std::string e = toml_error(R"([[surfaces]]
radius_mm = inf
thickness_mm = 2.0
stop = true

[[surfaces]]
radius_mm = inf
thickness_mm = 2.0
stop = true

[[surfaces]]
radius_mm = 20.0
thickness_mm = 15.0
)");
    check_contains(e, "bad.toml:9:1:");
    check_contains(e, "surface 2 is a second aperture stop");
  }
  SUBCASE("wrong types and values") {
    std::string text = kGoodToml;
    text.replace(text.find("thickness_mm = 3.0"), 18, "thickness_mm = \"3\"");
    const std::string type = toml_error(text);
    check_contains(type, "bad.toml:11:16:");
    check_contains(type, "thickness_mm must be a number, not a string");

    text = kGoodToml;
    text.replace(text.find("radius_mm = 20.0"), 16, "radius_mm = 0");
    check_contains(toml_error(text), "bad.toml:10:13: radius_mm = 0 is not a surface");

    text = kGoodToml;
    text.replace(text.find("vd = 50.0"), 9, "v = 50.0");
    const std::string model = toml_error(text);
    check_contains(model, "bad.toml:12:");
    check_contains(model, "unknown key 'v' in the material of surface 2 (did you mean 'vd'?)");

    // Wavelengths without channels get them by band (< 500 nm B, < 600 nm G, else R).
    const Lens banded = parse_lens_toml(
        std::string("[specs]\nwavelengths_nm = [486.1, 587.6, 656.3]\n") + kGoodToml, "bands.toml");
    CHECK(banded.specs.wavelength_channels == std::vector<int>{2, 1, 0});

    const std::string channels = toml_error(
        std::string("[specs]\nwavelengths_nm = [500.0, 600.0]\nchannels = [\"G\", \"X\"]\n") +
        kGoodToml);
    check_contains(channels, "bad.toml:3:");
    check_contains(channels, "channel \"X\" must be \"R\", \"G\" or \"B\"");

    const std::string dispersion =
        toml_error(std::string("[specs]\ndispersion = \"sellmeier\"\n") + kGoodToml);
    check_contains(dispersion, "bad.toml:2:14:");
    check_contains(dispersion, "must be \"abbe\" or \"catalog\"");
  }
  SUBCASE("glass after the last surface") {
    std::string text = kGoodToml;
    text += "material = { nd = 1.5, vd = 60.0 }\n";
    const std::string e = toml_error(text);
    check_contains(e, "bad.toml:17:1:");
    check_contains(e, "must be followed by air");
  }
}

TEST_CASE("yaml: errors name the file, the line and the problem") {
  const std::string good = R"(stop_idx: [2]
sequence: [GAAGA]
hfov: [25]
f_number: [2.]
c: [ 0.0598, 0.0436, 0.0, 0.0226, -0.0437 ]
t: [ 1.61, 5.60, 6.90, 2.89, 12.04 ]
nd: [1.678, 1.892]
v: [55.34, 37.13]
)";
  CHECK(parse_lens_yaml(good, "good.yml").surfaces.size() == 5);
  auto with = [&](const std::string& from, const std::string& to) {
    std::string text = good;
    text.replace(text.find(from), from.size(), to);
    return text;
  };
  SUBCASE("count mismatch") {
    const std::string t = yaml_error(with("2.89, 12.04", "12.04"));
    check_contains(t, "bad.yml:6:");
    check_contains(t, "t has 4 thicknesses but sequence 'GAAGA' has 5 surfaces");
    const std::string c = yaml_error(with("0.0598, ", ""));
    check_contains(c, "bad.yml:5:");
    check_contains(c, "c has 4 curvatures");
    const std::string nd = yaml_error(with("[1.678, 1.892]", "[1.678]"));
    check_contains(nd, "bad.yml:7:");
    check_contains(nd, "nd has 1 values but sequence 'GAAGA' has 2 glasses");
    const std::string v = yaml_error(with("[55.34, 37.13]", "[55.34, 37.13, 40.0]"));
    check_contains(v, "bad.yml:8:");
    check_contains(v, "v has 3 values");
  }
  SUBCASE("stop out of range or on a curved surface") {
    const std::string range = yaml_error(with("stop_idx: [2]", "stop_idx: [5]"));
    check_contains(range, "bad.yml:1:");
    check_contains(range, "stop_idx = 5 is out of range");
    const std::string curved = yaml_error(with("stop_idx: [2]", "stop_idx: [1]"));
    check_contains(curved, "bad.yml:1:");
    check_contains(curved, "stop_idx = 1 is a curved surface");
  }
  SUBCASE("missing keys and bad values") {
    const std::string missing = yaml_error(with("stop_idx: [2]", "stop_id: [2]"));
    check_contains(missing, "bad.yml:1:1:");
    check_contains(missing, "missing key 'stop_idx' (the file has 'stop_id' at line 1)");
    const std::string letter = yaml_error(with("[GAAGA]", "[GAXGA]"));
    check_contains(letter, "bad.yml:2:");
    check_contains(letter, "sequence letter 3 is 'X'");
    const std::string number = yaml_error(with("1.61,", "one,"));
    check_contains(number, "bad.yml:6:");
    check_contains(number, "t[0] must be a number, not 'one'");
    const std::string index = yaml_error(with("1.892", "0.9"));
    check_contains(index, "bad.yml:7:");
    check_contains(index, "nd[1] = 0.9 must be > 1");
  }
  SUBCASE("YAML syntax error") {
    const std::string e = yaml_error(with("hfov: [25]", "hfov: [25\n  bad: - x"));
    check_contains(e, "bad.yml:");
    check_contains(e, "YAML syntax error");
    const std::string e2 = yaml_error("stop_idx: [2]\nsequence: [GAAGA\nhfov: {a: [}\n");
    check_contains(e2, "bad.yml:3:");
    check_contains(e2, "YAML syntax error");
  }
}

}  // namespace test_lens_io
