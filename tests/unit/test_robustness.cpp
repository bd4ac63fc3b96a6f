// Issue 15: nothing lost, nothing silently wrong. The output layer (atomic, verified writes,
// outputs over inputs refused, stale temporaries), render resume, text decoding (UTF-16 /
// UTF-8 / Latin-1), physical validation of lenses, PSF size checks, glass ranges, duplicate keys,
// and a seeded in-process fuzz of the four readers.
#include <doctest/doctest.h>
#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <filesystem>
#include <fstream>
#include <functional>
#include <iterator>
#include <limits>
#include <nlohmann/json.hpp>
#include <random>
#include <string>

#include "lensopt/analysis/forms_image.h"
#include "lensopt/core/atomic_file.h"
#include "lensopt/core/error.h"
#include "lensopt/core/output_checks.h"
#include "lensopt/core/text.h"
#include "lensopt/formats/lens_file.h"
#include "lensopt/formats/zmx.h"
#include "lensopt/glass/glass.h"
#include "lensopt/glass/glass_range.h"
#include "lensopt/lens/lens_io.h"
#include "lensopt/lens/validate.h"
#include "lensopt/render/psf_resample.h"
#include "test_support.h"

namespace test_robustness {

using namespace lensopt;
namespace fs = std::filesystem;

namespace {

struct Scratch {
  fs::path path;
  Scratch() {
    static std::atomic<int> counter{0};
    path = fs::temp_directory_path() /
           ("lensopt-test-robust-" + std::to_string(::getpid()) + "-" + std::to_string(counter++));
    fs::remove_all(path);
    fs::create_directories(path);
  }
  ~Scratch() {
    std::error_code ec;
    fs::remove_all(path, ec);
  }
};

std::string doublet_toml() {
  return read_file(test::source_dir() / "lenses" / "doublet.toml");
}

// doublet.toml with one line replaced (the first line that starts with `key`).
std::string with_line(const std::string& key, const std::string& line, int occurrence = 0) {
  std::string text = doublet_toml();
  std::size_t at = 0;
  for (int k = 0; k <= occurrence; ++k) {
    at = text.find("\n" + key, at + 1);
    REQUIRE(at != std::string::npos);
  }
  const std::size_t end = text.find('\n', at + 1);
  return text.substr(0, at + 1) + line + text.substr(end);
}

std::string error_of(const std::function<void()>& f) {
  try {
    f();
  } catch (const Error& e) {
    return e.what();
  }
  return "";
}

std::vector<std::string> names_in(const fs::path& dir) {
  std::vector<std::string> out;
  for (const auto& e : fs::directory_iterator(dir)) out.push_back(e.path().filename().string());
  std::sort(out.begin(), out.end());
  return out;
}

}  // namespace

TEST_CASE("output layer: atomic writes, verified, nothing left behind") {
  Scratch s;
  write_file_atomic(s.path / "a.txt", "hello");
  CHECK(read_file(s.path / "a.txt") == "hello");
  // A missing folder: an Error naming the file, and nothing written.
  const std::string e1 = error_of([&] { write_file_atomic(s.path / "no" / "b.txt", "x"); });
  CHECK(e1.find("b.txt") != std::string::npos);
  CHECK(e1.find("does not exist") != std::string::npos);
  // A writer that produces nothing is an error, never a 0-byte file under the final name.
  const std::string e2 = error_of([&] {
    write_file_atomic_with(s.path / "c.png", [](const fs::path& temp) { std::ofstream{temp}; });
  });
  CHECK(e2.find("c.png") != std::string::npos);
  CHECK(e2.find("empty") != std::string::npos);
  // A writer that throws leaves the previous file intact and no temporary.
  write_file_atomic(s.path / "d.txt", "old");
  CHECK_THROWS_AS(write_file_atomic_with(s.path / "d.txt",
                                         [](const fs::path& temp) {
                                           std::ofstream(temp) << "partial";
                                           throw Error("encoder failed");
                                         }),
                  Error);
  CHECK(read_file(s.path / "d.txt") == "old");
  CHECK(names_in(s.path) == std::vector<std::string>{"a.txt", "d.txt"});
}

TEST_CASE("output layer: outputs over inputs and unwritable places are refused before work") {
  Scratch s;
  write_file_atomic(s.path / "lens.toml", doublet_toml());
  fs::create_directories(s.path / "sub");
  CHECK(same_file(s.path / "lens.toml", s.path / "sub" / ".." / "lens.toml"));
  CHECK_FALSE(same_file(s.path / "lens.toml", s.path / "other.toml"));
  const std::string e1 =
      error_of([&] { check_output_file(s.path / "sub/../lens.toml", {s.path / "lens.toml"}); });
  CHECK(e1.find("refusing to write an output over an input") != std::string::npos);
  CHECK(error_of([&] { check_output_file(s.path / "missing" / "x.csv"); }).find("does not exist") !=
        std::string::npos);
  CHECK(error_of([&] { check_output_file(s.path / "sub"); }).find("is a directory") !=
        std::string::npos);
  CHECK(error_of([&] {
          check_output_dir(s.path / "sub", {s.path / "sub/"});
        }).find("refusing to write into an input") != std::string::npos);
  CHECK_NOTHROW(check_output_file(s.path / "out.csv", {s.path / "lens.toml"}));
  CHECK_NOTHROW(check_output_dir(s.path / "new" / "dir", {s.path / "lens.toml"}));
  CHECK(fs::is_directory(s.path / "new" / "dir"));
}

TEST_CASE("output layer: stale temporaries of dead processes are removed") {
  Scratch s;
  long pid = 0;
  CHECK(is_temp_file_name(".img.tmp123-4.png", &pid));
  CHECK(pid == 123);
  CHECK(is_temp_file_name(".render_metrics.tmp77-0.csv"));
  CHECK_FALSE(is_temp_file_name("img.png"));
  CHECK_FALSE(is_temp_file_name(".hidden.png"));
  fs::create_directories(s.path / "a");
  // A pid above the kernel's limit is never alive; our own pid is.
  std::ofstream(s.path / "a" / ".img.tmp2147480000-0.png") << "partial";
  const std::string mine = ".img.tmp" + std::to_string(::getpid()) + "-0.png";
  std::ofstream(s.path / "a" / mine) << "in flight";
  std::ofstream(s.path / "a" / "img.png") << "kept";
  CHECK(remove_stale_temp_files(s.path) == 1);
  CHECK(names_in(s.path / "a") == std::vector<std::string>{mine, "img.png"});
}

TEST_CASE("text: UTF-16, UTF-8 and ISO-8859-1 are told apart") {
  CHECK(is_valid_utf8("caf\xc3\xa9"));
  CHECK_FALSE(is_valid_utf8("caf\xe9"));
  CHECK_FALSE(is_valid_utf8("\xc0\xaf"));          // overlong
  CHECK_FALSE(is_valid_utf8("\xed\xa0\x80"));      // a surrogate
  CHECK(decode_text("caf\xe9") == "caf\xc3\xa9");  // Latin-1 -> UTF-8
  CHECK(decode_text("caf\xc3\xa9") == "caf\xc3\xa9");
  CHECK(decode_text(std::string("\xff\xfe"
                                "c\0\xe9\0",
                                6)) == "c\xc3\xa9");
  CHECK(decode_text("\xef\xbb\xbfx\xe9") == "x\xc3\xa9");  // a BOM, then not UTF-8: Latin-1
}

TEST_CASE("text: a Latin-1 .zmx NAME and AGF glass name give valid UTF-8 and JSON") {
  Lens lens = read_lens(test::source_dir() / "lenses" / "doublet.toml");
  std::string zmx = format_zmx(lens);
  const std::size_t at = zmx.find("NAME ");
  REQUIRE(at != std::string::npos);
  zmx.replace(at, zmx.find('\n', at) - at, "NAME Objectif de d\xe9monstration");
  const ZmxImport imported = parse_zmx(zmx, "latin1.zmx");
  CHECK(imported.lens.name == "Objectif de d\xc3\xa9monstration");
  CHECK_NOTHROW(nlohmann::json(imported.lens.name).dump());

  std::string agf = read_file(test::source_dir() / "catalogs" / "ohara65.agf");
  const std::size_t nm = agf.find("NM S-BAH10");
  REQUIRE(nm != std::string::npos);
  agf.replace(nm, 10, "NM S-BAH10\xf6");
  const Catalog catalog = parse_agf(agf, "latin1.agf");
  REQUIRE(catalog.find("S-BAH10\xc3\xb6") != nullptr);
  nlohmann::json j = nlohmann::json::array();
  for (const Glass& g : catalog.glasses) j.push_back(g.name);
  CHECK_NOTHROW(j.dump());
}

TEST_CASE("validation: degenerate lenses are refused with file:line") {
  auto fails = [](const std::string& text) {
    return error_of([&] { parse_lens_toml(text, "bad.toml"); });
  };
  const std::string hfov0 = fails(with_line("half_field_deg", "half_field_deg = 0.0"));
  CHECK(hfov0.find("bad.toml:16") != std::string::npos);
  CHECK(hfov0.find("half_field_deg") != std::string::npos);
  CHECK(fails(with_line("f_number", "f_number = 1e-320")).find("f_number") != std::string::npos);
  CHECK(fails(with_line("sensor_diagonal_mm", "sensor_diagonal_mm = 1e-320"))
            .find("sensor_diagonal_mm") != std::string::npos);
  CHECK(fails(with_line("sensor_diagonal_mm", "sensor_diagonal_mm = 1e-9"))
            .find("sensor_diagonal_mm") != std::string::npos);
  // The last thickness of 1e308: more than 1e4 lens lengths.
  const std::string far = fails(with_line("thickness_mm", "thickness_mm = 1e308", 4));
  CHECK(far.find("surface 5") != std::string::npos);
  CHECK(far.find("bad.toml:") != std::string::npos);
  const std::string tiny_r = fails(with_line("radius_mm", "radius_mm = 1e-6"));
  CHECK(tiny_r.find("surface 1") != std::string::npos);
  CHECK(tiny_r.find("radius") != std::string::npos);
  // Model glasses: nd = 1e300, vd = 1e-320.
  std::string model = with_line("material", "material = { nd = 1e300, vd = 50.0 }");
  CHECK(fails(model).find("nd") != std::string::npos);
  model = with_line("material", "material = { nd = 1.6, vd = 1e-320 }");
  CHECK(fails(model).find("vd") != std::string::npos);
  // The reference doublet still reads.
  CHECK_NOTHROW(parse_lens_toml(doublet_toml(), "doublet.toml"));
}

TEST_CASE("validation: a .zmx without field lines is refused, not analyzed into nulls") {
  Lens lens = read_lens(test::source_dir() / "lenses" / "doublet.toml");
  std::string zmx = format_zmx(lens);
  std::string kept;
  std::size_t start = 0;
  while (start < zmx.size()) {
    const std::size_t end = zmx.find('\n', start);
    const std::string line = zmx.substr(start, end - start);
    if (line.rfind("XFLN", 0) != 0 && line.rfind("YFLN", 0) != 0) kept += line + "\n";
    if (end == std::string::npos) break;
    start = end + 1;
  }
  const std::string e = error_of([&] { parse_zmx(kept, "nofield.zmx"); });
  CHECK(e.find("field of view") != std::string::npos);  // the paper mode needs one
}

TEST_CASE("analysis: a report without an image is an error") {
  AnalysisReport r;
  r.lens_name = "x";
  r.source_path = "x.toml";
  r.efl_mm = std::numeric_limits<double>::infinity();
  r.epd_mm = 1;
  r.scale = 1;
  r.stop_radius_mm = 1;
  const std::string e = error_of([&] { check_forms_image(r); });
  CHECK(e.find("does not form an image") != std::string::npos);
  CHECK(e.find("no field") != std::string::npos);
  CHECK(e.find("focal length") != std::string::npos);
  CHECK(e.find("afocal") != std::string::npos);  // an infinite EFL: afocal, said so (issue 31)
}

TEST_CASE("render: a PSF wider than the supported kernel is an error naming the sizes") {
  PsfOptions options;
  std::vector<double> grid(static_cast<std::size_t>(options.grid_size) * options.grid_size, 0.0);
  grid.front() = 1.0;  // a corner bin: the widest reach
  // A sensor diagonal of 1e-9 mm over a 1000 px image: pitch 1e-9 um.
  const std::string e = error_of([&] { psf_kernel_radius(grid, options, 0.0, 1e-9); });
  CHECK(e.find("pixels wide") != std::string::npos);
  CHECK(e.find("sensor diagonal is too small") != std::string::npos);
  CHECK(psf_kernel_radius(grid, options, 0.0, options.bin_um) < kMaxPsfKernelRadiusPx);
}

TEST_CASE("glass ranges: a wavelength outside LD is reported once per glass, with a reason") {
  Lens lens = read_lens(test::source_dir() / "lenses" / "doublet.toml");
  CHECK(glass_range_warnings(lens).empty());
  lens.specs.wavelengths_nm = {250.0, 587.6, 15000.0};
  lens.specs.wavelength_channels = {2, 1, 0};
  const std::vector<std::string> w = glass_range_warnings(lens);
  REQUIRE(w.size() == 2);  // two glasses, one message each
  CHECK(w[0].find("250, 15000 nm outside") != std::string::npos);
  const Glass& g = *lens.surfaces[0].material.glass;
  CHECK_FALSE(glass_in_range(g, 250.0));
  CHECK(glass_in_range(g, 587.6));
  CHECK(missing_index_reason(g, 587.6).empty());
  Glass unsupported = g;
  unsupported.formula_supported = false;
  CHECK(missing_index_reason(unsupported, 587.6).find("unsupported") != std::string::npos);
}

TEST_CASE("duplicate keys: YAML and TOML name both lines") {
  const std::string yaml =
      "stop_idx: [2]\nsequence: [GAAGA]\nhfov: [25]\nf_number: [2.]\n"
      "c: [ 0.0598, 0.0436, 0.0, 0.0226, -0.0437 ]\n"
      "t: [ 1.61, 5.60, 6.90, 2.89, 12.04 ]\nnd: [1.678, 1.892]\nv: [55.34, 37.13]\n"
      "hfov: [30]\n";
  const std::string e = error_of([&] { parse_lens_yaml(yaml, "dup.yml"); });
  CHECK(e.find("dup.yml:9") != std::string::npos);
  CHECK(e.find("duplicate key 'hfov'") != std::string::npos);
  CHECK(e.find("line 3") != std::string::npos);
  std::string toml = doublet_toml();
  toml.insert(toml.find("half_field_deg"), "f_number = 4.0\n");
  const std::string t = error_of([&] { parse_lens_toml(toml, "dup.toml"); });
  CHECK(t.find("dup.toml:") != std::string::npos);
  CHECK(t.find("f_number") != std::string::npos);
}

TEST_CASE("fuzz: mutated TOML, YAML, .zmx and AGF inputs give a lens or an Error") {
  // Seeded and bounded; tests/e2e/fuzz.sh runs the command line, tools/fuzz-sanitize.sh both
  // under ASan + UBSan.
  const Lens doublet = read_lens(test::source_dir() / "lenses" / "doublet.toml");
  const std::string seeds[4] = {
      doublet_toml(), format_zmx(doublet),
      "stop_idx: [2]\nsequence: [GAAGA]\nhfov: [25]\nf_number: [2.]\n"
      "c: [ 0.0598, 0.0436, 0.0, 0.0226, -0.0437 ]\n"
      "t: [ 1.61, 5.60, 6.90, 2.89, 12.04 ]\nnd: [1.678, 1.892]\nv: [55.34, 37.13]\n",
      read_file(test::source_dir() / "catalogs" / "ohara65.agf").substr(0, 6000)};
  const char* junk[] = {"\xe9",
                        "\xff\xfe",
                        "1e308",
                        "-1e308",
                        "1e-320",
                        "nan",
                        "inf",
                        "0",
                        "-",
                        "[",
                        "]",
                        "=",
                        "\n",
                        "\"",
                        ":",
                        "SURF 2\n",
                        "NM X 2 0 1.5 60\n",
                        "e9"};
  std::mt19937 rng(15);
  int lenses = 0, errors = 0;
  for (int round = 0; round < 400; ++round) {
    const int kind = round % 4;
    std::string data = seeds[kind];
    const int edits = 1 + static_cast<int>(rng() % 4);
    for (int k = 0; k < edits && !data.empty(); ++k) {
      const std::size_t pos = rng() % data.size();
      switch (rng() % 3) {
        case 0:
          data.insert(pos, junk[rng() % std::size(junk)]);
          break;
        case 1:
          data.erase(pos, 1 + rng() % 30);
          break;
        default:
          data[pos] = static_cast<char>(rng() % 256);
      }
    }
    try {
      switch (kind) {
        case 0:
          parse_lens_toml(data, "fuzz.toml");
          break;
        case 1:
          parse_zmx(data, "fuzz.zmx");
          break;
        case 2:
          parse_lens_yaml(data, "fuzz.yml");
          break;
        default: {
          const Catalog c = parse_agf(data, "fuzz.agf");
          for (const Glass& g : c.glasses) {
            CHECK(is_valid_utf8(g.name));
            (void)g.index(587.6);
          }
        }
      }
      ++lenses;
    } catch (const Error&) {
      ++errors;
    }  // anything else escapes and fails the test
  }
  CHECK(lenses + errors == 400);
  CHECK(errors > 0);
  CHECK(lenses > 0);
}

}  // namespace test_robustness
