// Hostile lens input (issue 34): nesting and dotted keys that overflowed toml++'s recursion, YAML
// alias bombs, lenses of absurd size, and weights or apertures that were accepted silently. Each
// is refused before the costly work with file:line and the limit; real files still read.
#include <doctest/doctest.h>

#include <chrono>
#include <string>

#include "error_checks.h"
#include "lensopt/core/atomic_file.h"
#include "lensopt/core/error.h"
#include "lensopt/lens/input_limits.h"
#include "lensopt/lens/lens_io.h"
#include "test_support.h"

namespace test_lens_limits {

using namespace lensopt;

namespace {

using lensopt::test::check_contains;
using lensopt::test::error_of;

std::string toml_error(const std::string& text) {
  return error_of([&] { parse_lens_toml(text, "bad.toml"); });
}

std::string yaml_error(const std::string& text) {
  return error_of([&] { parse_lens_yaml(text, "bad.yml"); });
}

std::string repeat(const std::string& part, int n, const std::string& separator) {
  std::string out;
  for (int i = 0; i < n; ++i) {
    if (i > 0) out += separator;
    out += part;
  }
  return out;
}

std::string doublet_text() {
  return read_file(test::source_dir() / "lenses" / "doublet.toml");
}

// The doublet with a [system] table (its [specs] f_number = 2.0 kept unless `drop_f_number`).
std::string with_system(const std::string& system, bool drop_f_number = false) {
  std::string text = doublet_text();
  if (drop_f_number) {
    const std::size_t at = text.find("f_number = 2.0\n");
    REQUIRE(at != std::string::npos);
    text.erase(at, std::string("f_number = 2.0\n").size());
  }
  const std::size_t surfaces = text.find("[[surfaces]]");
  REQUIRE(surfaces != std::string::npos);
  return text.substr(0, surfaces) + "[system]\n" + system + "\n\n" + text.substr(surfaces);
}

}  // namespace

TEST_CASE("lens limits: deep TOML keys and nesting are refused before toml++ recurses") {
  // 40,000 dotted parts overflowed the 8 MB stack inside toml++ (SIGSEGV), in a table header, a
  // dotted key, quoted parts, or an inline table's key.
  const std::string parts = repeat("a", 40000, ".");
  for (const std::string& text :
       {"[" + parts + "]\nx = 1\n", parts + " = 1\n", "x = { " + parts + " = 1 }\n",
        "# a comment\n\n" + repeat("\"a\"", 40000, ".") + " = 1\n"}) {
    const std::string e = toml_error(text);
    check_contains(e, "dotted key of more than 100 parts");
    check_contains(e, "bad.toml:");
  }
  // The line and column of the first dot too many.
  check_contains(toml_error("\n\n[" + parts + "]\n"), "bad.toml:3:");
  // Arrays and inline tables 150 deep (toml++ itself stops at 256).
  const std::string e = toml_error("x = " + std::string(150, '[') + std::string(150, ']') + "\n");
  check_contains(e, "bad.toml:1:");
  check_contains(e, "nest more than 100 levels");
  check_contains(toml_error("x = " + repeat("{a = ", 120, "") + "1" + std::string(120, '}')),
                 "nest more than 100 levels");
  // At the limits: a key of 100 parts (with its table's name) and 100 levels of arrays read.
  const Lens at_limit =
      parse_lens_toml(doublet_text() + "\n[extra]\n" + repeat("a", 99, ".") +
                          " = 1\nx = " + std::string(99, '[') + std::string(99, ']') + "\n",
                      "ok.toml");
  check_contains(at_limit.extra_toml, "[extra");
}

TEST_CASE("lens limits: strings and comments never count towards the TOML limits") {
  // Dots and brackets inside comments, basic, literal and multi-line strings (with escaped and
  // extra closing quotes) are text, not structure: the lens reads.
  const std::string dots = std::string(300, '.');
  const std::string brackets = std::string(300, '[');
  std::string text = doublet_text();
  const std::size_t lens = text.find("[lens]\n");
  REQUIRE(lens != std::string::npos);
  text.insert(lens, "# " + dots + brackets + "\n");
  text += "\n[notes]\nbasic = \"" + dots + brackets + "\\\"" + dots + "\"\nliteral = '" + dots +
          brackets + "'\nmulti = \"\"\"\n" + brackets + "\\\"\"\"" + dots + "\n\"\"\"\"\"\n" +
          "raw = '''\n" + dots + brackets + "\n'''''\nafter = 1.5\n";
  const Lens l = parse_lens_toml(text, "ok.toml");
  CHECK(l.surfaces.size() >= 2);
  check_contains(l.extra_toml, "after = 1.5");
}

TEST_CASE("lens limits: YAML alias bombs are refused from the parser's events, quickly") {
  // 9 levels of 10 aliases: 10^9 nodes when expanded; the duplicate-key walk took ~45 s.
  std::string bomb = "a0: &a0 [x, x, x, x, x, x, x, x, x, x]\n";
  for (int i = 1; i <= 9; ++i)
    bomb += "a" + std::to_string(i) + ": &a" + std::to_string(i) + " [" +
            repeat("*a" + std::to_string(i - 1), 10, ", ") + "]\n";
  const auto t0 = std::chrono::steady_clock::now();
  const std::string e = yaml_error(bomb);
  const double seconds =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  check_contains(e, "expands to more than 100000 nodes");
  check_contains(e, "bad.yml:5:");  // a4's aliases pass 10^5 expanded nodes
  CHECK(seconds < 2.0);
  // Many aliases of a small anchor.
  check_contains(yaml_error("a: &a 1\nb: [" + repeat("*a", 1001, ", ") + "]\n"),
                 "more than 1000 aliases");
  // Deep flow nesting.
  check_contains(yaml_error("a: " + std::string(150, '[') + std::string(150, ']') + "\n"),
                 "nest more than 100 levels");
  // The paper's YAML still reads.
  const std::string ok =
      "stop_idx: [2]\nsequence: [GAAGA]\nhfov: [25]\nf_number: [2]\n"
      "c: [0.06, 0.04, 0, -0.02, -0.05]\nt: [1.6, 5.6, 6.9, 2.9, 12]\nnd: [1.68, 1.89]\n"
      "v: [55, 37]\n";
  CHECK(parse_lens_yaml(ok, "ok.yml").surfaces.size() == 5);
}

TEST_CASE("lens limits: a lens of more than 1000 surfaces, fields or wavelengths is refused") {
  const std::string head = "[lens]\nname = \"big\"\n\n";
  std::string text = head;
  for (int i = 0; i < 1001; ++i)
    text += "[[surfaces]]\nradius_mm = inf\nthickness_mm = 1\n" +
            std::string(i == 0 ? "stop = true\n" : "") + "\n";
  const std::string e = toml_error(text);
  check_contains(e, "the lens has 1001 surfaces; lensopt reads at most 1000");
  check_contains(e, "bad.toml:4005:");  // the 1001st surface: 3 lines, 5 for the stop, 4 each
  check_contains(toml_error(with_system("fields = [" + repeat("1", 1001, ", ") + "]")),
                 "fields has 1001 fields; lensopt reads at most 1000");
  std::string wavelengths = doublet_text();
  wavelengths.replace(wavelengths.find("f_number = 2.0\n"), 0,
                      "wavelengths_nm = [" + repeat("550", 1001, ", ") + "]\n");
  check_contains(toml_error(wavelengths), "wavelengths_nm has 1001 wavelengths");
  std::string yaml = "stop_idx: [0]\nsequence: [" + std::string(1001, 'A') + "]\nhfov: [25]\n";
  check_contains(yaml_error(yaml), "sequence has 1001 surfaces; lensopt reads at most 1000");
}

TEST_CASE("lens limits: weights and apertures are validated where they are written") {
  // field_weights = [0, 0, 0] gave analyze --json "mean_rms_spot_um": null at exit 0.
  std::string e = toml_error(with_system("fields = [0, 10, 20]\nfield_weights = [0, 0, 0]"));
  check_contains(e, "bad.toml:");
  check_contains(e, "every field weight is 0");
  e = toml_error(with_system("fields = [0, 10, 20]\nfield_weights = [1, -1, 0]"));
  check_contains(e, "field weight -1 must be >= 0");
  // wavelength_weights = [0, ...] passed every command but plot.
  const std::string zeros = repeat("0", 15, ", ");
  e = toml_error(with_system("wavelength_weights = [" + zeros + "]"));
  check_contains(e, "every wavelength weight is 0");
  check_contains(e, "bad.toml:");
  // aperture = "f-number" without [specs] f_number was traced at F/2 without a word.
  e = toml_error(with_system("aperture = \"f-number\"", true));
  check_contains(e, "aperture = \"f-number\" needs [specs] f_number");
  e = toml_error(with_system("mode = \"as-written\"", true));
  check_contains(e, "[system] gives no aperture");
  // With the F-number, or another aperture, the lens reads; one positive weight is enough.
  CHECK(parse_lens_toml(with_system("aperture = \"f-number\""), "ok.toml").specs.f_number == 2.0);
  CHECK(parse_lens_toml(with_system("aperture = \"epd\"\naperture_value = 8", true), "ok.toml")
            .specs.aperture_value == 8.0);
  const Lens weighted =
      parse_lens_toml(with_system("fields = [0, 10, 20]\nfield_weights = [0, 0, 1]"), "ok.toml");
  CHECK(weighted.specs.fields[2].weight == 1.0);
  // validate_lens, for lenses built in code (Python), refuses them too.
  Lens l = weighted;
  for (FieldPoint& f : l.specs.fields) f.weight = 0.0;
  check_contains(error_of([&] { l.validate(); }), "every field weight is 0");
}

}  // namespace test_lens_limits
