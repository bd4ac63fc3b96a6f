// Zemax AGF glass catalog reader.
//
// An AGF file is a list of lines "KEY field field ...", fields separated by blanks:
//   CC comment
//   NM name formula MIL nd vd [exclude [status [melt_frequency]]]   starts a glass
//   GC comment (kept: the glass's comment), ED thermal/chemical data, TD thermal dispersion, OD
//   other data (not kept) CD c0 c1 ... c9                  dispersion coefficients of the glass's
//   formula LD min_um max_um                 wavelength range of the formula IT wavelength_um
//   transmission thickness_mm   one internal-transmission sample
// Vendors write numbers as integers or floats ("2", "2.00000E+00", "1.06000E+000").
#include <fmt/format.h>

#include <cctype>
#include <charconv>
#include <cmath>
#include <cstdint>
#include <fstream>
#include <optional>
#include <sstream>
#include <unordered_map>

#include "lensopt/core/error.h"
#include "lensopt/core/text.h"
#include "lensopt/glass/glass.h"

namespace lensopt {
namespace {

// Coefficients each formula uses (CD c0..c(n-1)); a CD line with fewer is malformed.
int coefficients_needed(DispersionFormula formula) {
  switch (formula) {
    case DispersionFormula::kSchott:
    case DispersionFormula::kSellmeier1:
    case DispersionFormula::kHerzberger:
      return 6;
    case DispersionFormula::kSellmeier2:
    case DispersionFormula::kSellmeier4:
      return 5;
    case DispersionFormula::kConrady:
      return 3;
    case DispersionFormula::kSellmeier3:
    case DispersionFormula::kExtended1:
    case DispersionFormula::kExtended2:
      return 8;
    case DispersionFormula::kHandbook1:
    case DispersionFormula::kHandbook2:
      return 4;
    case DispersionFormula::kSellmeier5:
      return 10;
    case DispersionFormula::kExtended3:
      return 9;
    // The database's formulas take any count: at least C1 (and the pairs glass/formulas.h sums).
    case DispersionFormula::kRiiSellmeier:
    case DispersionFormula::kRiiSellmeier2:
    case DispersionFormula::kRiiPolynomial:
    case DispersionFormula::kRiiInfo:
    case DispersionFormula::kRiiCauchy:
    case DispersionFormula::kRiiGases:
      return 1;
    case DispersionFormula::kRiiHerzberger:
      return 6;
    case DispersionFormula::kRiiRetro:
      return 4;
    case DispersionFormula::kRiiExotic:
      return 6;
    case DispersionFormula::kTable:
      return 4;  // two samples (l, n)
  }
  return 0;
}

bool is_known_formula(int id) {
  return (id >= 1 && id <= 13) || (id >= 101 && id <= 109) || id == 120;
}

// The formulas of the refractiveindex.info database and the table keep the CD line's own count.
bool keeps_coefficient_count(DispersionFormula formula) {
  return static_cast<int>(formula) > 100;
}

// Blank-separated fields of a line (spaces, tabs), and the 1-based column each starts at.
void split_fields(std::string_view line, std::vector<std::string_view>& fields,
                  std::vector<int>& columns) {
  fields.clear();
  columns.clear();
  std::size_t i = 0;
  const auto is_blank = [](char ch) { return ch == ' ' || ch == '\t' || ch == '\r' || ch == '\f'; };
  while (i < line.size()) {
    while (i < line.size() && is_blank(line[i])) ++i;
    const std::size_t start = i;
    while (i < line.size() && !is_blank(line[i])) ++i;
    if (i > start) {
      fields.push_back(line.substr(start, i - start));
      columns.push_back(static_cast<int>(start) + 1);
    }
  }
}

std::optional<double> to_double(std::string_view text) {
  // from_chars takes no leading '+'; AGF writers do not use one, but accept it.
  if (!text.empty() && text.front() == '+') text.remove_prefix(1);
  double value = 0.0;
  const auto [end, ec] = std::from_chars(text.data(), text.data() + text.size(), value);
  if (ec != std::errc() || end != text.data() + text.size() || !std::isfinite(value)) {
    return std::nullopt;
  }
  return value;
}

// Reads AGF lines into a Catalog; one instance per file.
class AgfReader {
 public:
  AgfReader(std::string source_name, Catalog& catalog)
      : source_name_(std::move(source_name)), catalog_(catalog) {}

  void read_line(std::string_view line, int line_number) {
    line_number_ = line_number;
    split_fields(line, fields_, column_of_field_);
    if (fields_.empty()) return;
    const std::string_view key = fields_[0];
    if (key == "NM") {
      read_name_line();
    } else if (key == "CD") {
      read_coefficients_line();
    } else if (key == "LD") {
      read_range_line();
    } else if (key == "IT") {
      read_transmission_line();
    } else if (key == "GC" && !catalog_.glasses.empty()) {
      // The glass's comment (lensopt's catalogs: the data's source), lines joined by a blank.
      std::string& comment = catalog_.glasses.back().comment;
      const std::size_t start = line.find("GC") + 2;
      std::string_view text = line.substr(std::min(start, line.size()));
      while (!text.empty() && (text.front() == ' ' || text.front() == '\t')) text.remove_prefix(1);
      while (!text.empty() && (text.back() == ' ' || text.back() == '\r')) text.remove_suffix(1);
      if (!text.empty()) {
        if (!comment.empty()) comment += ' ';
        comment += text;
      }
    }
    // CC, ED, TD, OD and keys this reader does not know carry nothing the catalog keeps.
  }

  // Checks the last glass once the file is read.
  void finish() { finish_glass(); }

 private:
  [[noreturn]] void fail(const std::string& message, int column = 0) const {
    throw Error(SourceLocation{source_name_, line_number_, column}, message);
  }

  double number(std::size_t i, std::string_view what) const {
    if (i >= fields_.size()) fail(fmt::format("{} line: missing {}", fields_[0], what));
    const auto value = to_double(fields_[i]);
    if (!value) {
      fail(fmt::format("{} line: {} '{}' is not a number", fields_[0], what, fields_[i]),
           column_of_field_[i]);
    }
    return *value;
  }

  // A field that must hold an integer, written as "2" or "2.00000E+00".
  int integer(std::size_t i, std::string_view what) const {
    const double value = number(i, what);
    if (value != std::round(value) || std::abs(value) > 1e6) {
      fail(fmt::format("{} line: {} '{}' is not an integer", fields_[0], what, fields_[i]),
           column_of_field_[i]);
    }
    return static_cast<int>(value);
  }

  Glass& current_glass(std::string_view key) const {
    if (catalog_.glasses.empty()) fail(fmt::format("{} line before any NM (glass name) line", key));
    return catalog_.glasses.back();
  }

  void warn(const std::string& message) {
    catalog_.warnings.push_back(
        fmt::format("{}: {}", SourceLocation{source_name_, line_number_, 0}.to_string(), message));
  }

  void read_name_line() {
    finish_glass();
    // NM name formula MIL nd vd: six fields at least.
    if (fields_.size() < 6) {
      fail(
          fmt::format("NM line: expected 'NM name formula MIL nd vd [exclude status]', got {} "
                      "field(s)",
                      fields_.size()));
    }
    Glass glass;
    glass.name = std::string(fields_[1]);
    glass.catalog = catalog_.name;
    glass.source_line = line_number_;
    const int formula_id = integer(2, "formula id");
    glass.formula = static_cast<DispersionFormula>(formula_id);
    glass.formula_supported = is_known_formula(formula_id);
    // fields_[3] is the MIL code (nd and vd digits, sometimes a placeholder such as 1): unused.
    glass.nd = number(4, "nd");
    glass.vd = number(5, "vd");
    if (fields_.size() > 6) number(6, "exclude flag");
    if (fields_.size() > 7) {
      const int status = integer(7, "status");
      glass.status = static_cast<GlassStatus>(status);
      if (status < 0 || status > 4) {
        warn(fmt::format("glass {}: unknown status code {}", glass.name, status));
      }
    }
    // fields_[8], the melt frequency, is not kept (some files write '-').
    if (!glass.formula_supported) {
      warn(fmt::format("glass {}: unsupported dispersion formula {}; its index is not computed",
                       glass.name, formula_id));
    }
    // Look-up is case-insensitive and takes the first of equal names: say so when that hides one.
    std::string key;
    for (const char ch : glass.name)
      key += static_cast<char>(std::tolower(static_cast<unsigned char>(ch)));
    if (const auto [it, inserted] = first_line_by_name_.emplace(key, line_number_); !inserted) {
      warn(fmt::format("glass {} is listed again (first at line {}); look-up finds the first",
                       glass.name, it->second));
    }
    catalog_.glasses.push_back(std::move(glass));
    has_coefficients_ = false;
  }

  void read_coefficients_line() {
    Glass& glass = current_glass("CD");
    std::vector<double> coefficients;
    for (std::size_t i = 1; i < fields_.size(); ++i) {
      coefficients.push_back(number(i, fmt::format("coefficient c{}", i - 1)));
    }
    const auto needed = static_cast<std::size_t>(coefficients_needed(glass.formula));
    if (coefficients.empty() || coefficients.size() < needed) {
      fail(fmt::format("CD line: glass {} ({}) needs {} coefficients, the line has {}", glass.name,
                       formula_name(glass.formula), std::max<std::size_t>(needed, 1),
                       coefficients.size()));
    }
    if (glass.formula == DispersionFormula::kTable) {
      // (l, n) pairs, l ascending and positive, n positive.
      if (coefficients.size() % 2 != 0)
        fail(
            fmt::format("CD line: glass {} (table) needs (wavelength, index) pairs, the line has "
                        "{} numbers",
                        glass.name, coefficients.size()));
      for (std::size_t i = 0; i < coefficients.size(); i += 2) {
        if (!(coefficients[i] > 0.0) || !(coefficients[i + 1] > 0.0) ||
            (i > 0 && !(coefficients[i] > coefficients[i - 2])))
          fail(fmt::format("CD line: glass {} (table): sample {} ({} um, n {}) must have a "
                           "positive wavelength above the one before and a positive index",
                           glass.name, i / 2 + 1, coefficients[i], coefficients[i + 1]),
               column_of_field_[i + 1]);
      }
    }
    if (!keeps_coefficient_count(glass.formula) && coefficients.size() < 10)
      coefficients.resize(10, 0.0);
    glass.coefficients = std::move(coefficients);
    has_coefficients_ = true;
  }

  void read_range_line() {
    Glass& glass = current_glass("LD");
    glass.min_wavelength_um = number(1, "minimum wavelength (um)");
    glass.max_wavelength_um = number(2, "maximum wavelength (um)");
  }

  void read_transmission_line() {
    Glass& glass = current_glass("IT");
    TransmissionPoint point;
    point.wavelength_um = number(1, "wavelength (um)");
    const double second = number(2, "transmission");
    if (fields_.size() > 3) {
      point.transmission = second;
      point.thickness_mm = number(3, "thickness (mm)");
    } else if (second > 1.0) {
      // Two numbers, the second above 1: a thickness with the transmission field left blank,
      // as Schott writes below its measurable range. Blank = nothing measured = 0.
      point.transmission = 0.0;
      point.thickness_mm = second;
    } else {
      point.transmission = second;  // transmission with the thickness left out
    }
    glass.transmission.push_back(point);
  }

  // A glass without a CD line has no dispersion data: its index would be silently wrong.
  void finish_glass() {
    if (catalog_.glasses.empty() || has_coefficients_) return;
    Glass& glass = catalog_.glasses.back();
    if (!glass.formula_supported) return;
    glass.formula_supported = false;
    catalog_.warnings.push_back(
        fmt::format("{}: glass {}: no CD (dispersion coefficients) line; its index is not computed",
                    SourceLocation{source_name_, glass.source_line, 0}.to_string(), glass.name));
  }

  std::string source_name_;
  Catalog& catalog_;
  int line_number_ = 0;
  std::vector<std::string_view> fields_;
  std::vector<int> column_of_field_;
  bool has_coefficients_ = true;
  std::unordered_map<std::string, int> first_line_by_name_;  // lower-case name -> NM line
};

}  // namespace

Catalog parse_agf(std::string_view bytes, const std::string& source_name) {
  Catalog catalog;
  catalog.path = source_name;
  catalog.name = catalog_family_name(std::filesystem::path(source_name).stem().string());
  const std::string text = decode_text(bytes);
  AgfReader reader(source_name, catalog);
  // Lines end in LF, CRLF or a lone CR.
  int line_number = 0;
  std::size_t start = 0;
  while (start < text.size()) {
    std::size_t end = text.find_first_of("\r\n", start);
    if (end == std::string::npos) end = text.size();
    ++line_number;
    reader.read_line(std::string_view(text).substr(start, end - start), line_number);
    if (end < text.size() && text[end] == '\r' && end + 1 < text.size() && text[end + 1] == '\n') {
      ++end;
    }
    start = end + 1;
  }
  reader.finish();
  return catalog;
}

Catalog read_agf(const std::filesystem::path& path) {
  std::ifstream in(path, std::ios::binary);
  if (!in) throw Error(SourceLocation{path.string()}, "cannot open glass catalog");
  std::ostringstream contents;
  contents << in.rdbuf();
  if (in.bad()) throw Error(SourceLocation{path.string()}, "cannot read glass catalog");
  return parse_agf(contents.str(), path.string());
}

}  // namespace lensopt
