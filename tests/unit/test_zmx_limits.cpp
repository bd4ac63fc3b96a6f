// Hostile .zmx input (issue 34): surface, field and wavelength counts no lens reaches, and
// weights that left nothing to trace, are refused at their line.
#include <doctest/doctest.h>

#include <algorithm>
#include <string>

#include "error_checks.h"
#include "lensopt/core/error.h"
#include "lensopt/formats/lens_file.h"
#include "lensopt/formats/zmx.h"
#include "test_support.h"

namespace test_zmx_limits {

using namespace lensopt;

namespace {

using lensopt::test::check_contains;

std::string zmx_error(const std::string& text) {
  return lensopt::test::error_of([&] { parse_zmx(text, "bad.zmx"); });
}

// The doublet as .zmx (CRLF), with the line that starts with `key` replaced by `line`.
std::string doublet_zmx(const std::string& key = "", const std::string& line = "") {
  std::string text = format_zmx(read_lens(test::source_dir() / "lenses" / "doublet.toml"));
  if (key.empty()) return text;
  const std::size_t at = text.find("\r\n" + key + " ");
  REQUIRE(at != std::string::npos);
  const std::size_t end = text.find("\r\n", at + 2);
  return text.substr(0, at + 2) + line + text.substr(end);
}

// The 1-based line of the first line starting with `key`.
int line_of(const std::string& text, const std::string& key) {
  const std::size_t at = text.find("\r\n" + key + " ");
  int line = 2;
  for (std::size_t i = 0; i < at; ++i) line += text[i] == '\n';
  return line;
}

}  // namespace

TEST_CASE("zmx limits: weights that leave nothing to trace are refused at their line") {
  CHECK(parse_zmx(doublet_zmx(), "ok.zmx").lens.surfaces.size() >= 2);
  // FWGN 0 0 0 was accepted: analyze --json then printed null spots at exit 0.
  std::string text = doublet_zmx("FWGN", "FWGN 0 0 0");
  std::string e = zmx_error(text);
  check_contains(e, "bad.zmx:" + std::to_string(line_of(text, "FWGN")) + ":");
  check_contains(e, "every active field has weight 0");
  check_contains(zmx_error(doublet_zmx("FWGN", "FWGN 1 -1 1")), "field weight -1 must be >= 0");
  // WAVM weights all 0 (each WAVM line of the doublet's 15).
  text = doublet_zmx();
  for (int i = 1; i <= 15; ++i) {
    const std::string key = "WAVM " + std::to_string(i) + " ";
    const std::size_t at = text.find("\r\n" + key);
    const std::size_t end = text.find("\r\n", at + 2);
    text.replace(end - 2, 2, " 0");  // the weight "1" -> "0"
  }
  e = zmx_error(text);
  check_contains(e, "every active wavelength has weight 0");
  check_contains(e, "bad.zmx:" + std::to_string(line_of(text, "WAVM")) + ":");
}

TEST_CASE("zmx limits: more than 1000 surfaces, fields or wavelengths are refused") {
  // 100,000 surfaces made analyze run for minutes; the first SURF beyond the limit is named.
  std::string text = doublet_zmx();
  text = text.substr(0, text.find("SURF 0\r\n"));
  const int before = static_cast<int>(std::count(text.begin(), text.end(), '\n'));
  for (int i = 0; i < 1200; ++i)
    text += "SURF " + std::to_string(i) + "\r\n  CURV 0\r\n  DISZ 1\r\n";
  std::string e = zmx_error(text);
  check_contains(e, "SURF 1002: lensopt reads at most 1000 lens surfaces");
  check_contains(e, "bad.zmx:" + std::to_string(before + 1 + 3 * 1002) + ":");
  std::string values;
  for (int i = 0; i < 1001; ++i) values += " 1";
  check_contains(zmx_error(doublet_zmx("YFLN", "YFLN" + values)),
                 "YFLN has 1001 fields; lensopt reads at most 1000");
  check_contains(zmx_error(doublet_zmx("FWGN", "FWGN" + values)), "FWGN has 1001 fields");
  check_contains(zmx_error(doublet_zmx("PWAV", "WAVM 1001 0.55 1")),
                 "wavelength number 1001 is out of range");
}

}  // namespace test_zmx_limits
