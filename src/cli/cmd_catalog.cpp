// lensopt catalog FILE: list a glass catalog's glasses with their indices at chosen wavelengths.
#include <fmt/core.h>
#include <fmt/ranges.h>

#include <algorithm>
#include <cmath>
#include <memory>
#include <nlohmann/json.hpp>
#include <optional>
#include <string>
#include <vector>

#include "commands.h"
#include "lensopt/glass/glass.h"
#include "lensopt/glass/glass_range.h"

namespace lensopt::cli {
namespace {

constexpr double kHeliumD_nm = 587.5618;  // the d line nd refers to

struct CatalogCommand {
  std::string catalog;  // path or catalog name
  bool json = false;
  std::vector<double> wavelengths_nm{kHeliumD_nm};
};

// The glass's indices at each wavelength; nullopt where the formula gives none (unsupported
// formula, or n^2 < 0 outside its range).
std::vector<std::optional<double>> indices(const Glass& glass, const std::vector<double>& wl_nm) {
  std::vector<std::optional<double>> n;
  for (const double wavelength_nm : wl_nm) {
    const double value = glass.index(wavelength_nm);  // NaN for an unsupported formula
    n.push_back(std::isfinite(value) ? std::optional<double>(value) : std::nullopt);
  }
  return n;
}

// Why a value is missing or extrapolated ("" when it is a plain catalog value).
std::string note_of(const Glass& glass, double wavelength_nm) {
  const std::string missing = missing_index_reason(glass, wavelength_nm);
  if (!missing.empty()) return missing;
  if (!glass_in_range(glass, wavelength_nm))
    return fmt::format("extrapolated: {} nm is outside the formula's range {}-{} nm (AGF LD line)",
                       wavelength_nm, glass.min_wavelength_um * 1000.0,
                       glass.max_wavelength_um * 1000.0);
  return "";
}

// One line on stderr per glass with a missing or extrapolated value.
void print_notes(const Catalog& catalog, const std::vector<double>& wavelengths_nm) {
  for (const Glass& glass : catalog.glasses) {
    std::vector<std::string> notes;
    for (const double w : wavelengths_nm) {
      const std::string note = note_of(glass, w);
      if (!note.empty()) notes.push_back(fmt::format("n({} nm): {}", w, note));
    }
    if (!notes.empty())
      fmt::print(stderr, "lensopt catalog: warning: {}: {}\n", glass.name, fmt::join(notes, "; "));
  }
}

std::string formula_label(const Glass& glass) {
  const std::string name = formula_name(glass.formula);
  return glass.formula_supported ? name : name + " (unsupported)";
}

void print_json(const Catalog& catalog, const std::vector<double>& wavelengths_nm) {
  auto list = nlohmann::ordered_json::array();
  for (const Glass& glass : catalog.glasses) {
    auto n = nlohmann::ordered_json::array();
    auto notes = nlohmann::ordered_json::array();
    for (const auto& value : indices(glass, wavelengths_nm)) {
      n.push_back(value ? nlohmann::ordered_json(*value) : nlohmann::ordered_json(nullptr));
    }
    bool any_note = false;
    for (const double w : wavelengths_nm) {
      const std::string note = note_of(glass, w);
      any_note |= !note.empty();
      notes.push_back(note.empty() ? nlohmann::ordered_json(nullptr)
                                   : nlohmann::ordered_json(note));
    }
    list.push_back(
        {{"name", glass.name},
         {"formula", formula_name(glass.formula)},
         {"supported", glass.formula_supported},
         {"status", status_name(glass.status)},
         {"nd", glass.nd},
         {"vd", glass.vd},
         {"n", std::move(n)},
         {"range_nm", glass.max_wavelength_um > glass.min_wavelength_um
                          ? nlohmann::ordered_json::array({glass.min_wavelength_um * 1000.0,
                                                           glass.max_wavelength_um * 1000.0})
                          : nlohmann::ordered_json(nullptr)}});
    if (any_note) list.back()["n_notes"] = std::move(notes);
  }
  fmt::print("{}\n", list.dump(2, ' ', false, nlohmann::json::error_handler_t::replace));
}

void print_table(const Catalog& catalog, const std::vector<double>& wavelengths_nm) {
  std::vector<std::string> header{"glass", "formula", "status", "nd", "vd"};
  for (const double wavelength_nm : wavelengths_nm) {
    header.push_back(fmt::format("n({} nm)", wavelength_nm));
  }
  std::vector<std::vector<std::string>> rows;
  for (const Glass& glass : catalog.glasses) {
    std::vector<std::string> row{glass.name, formula_label(glass), status_name(glass.status),
                                 fmt::format("{}", glass.nd), fmt::format("{}", glass.vd)};
    for (const auto& value : indices(glass, wavelengths_nm)) {
      row.push_back(value ? fmt::format("{:.6f}", *value) : std::string("-"));
    }
    for (std::size_t k = 0; k < wavelengths_nm.size(); ++k)
      if (row[5 + k] != "-" && !glass_in_range(glass, wavelengths_nm[k])) row[5 + k] += "*";
    rows.push_back(std::move(row));
  }
  std::vector<std::size_t> width(header.size());
  for (std::size_t k = 0; k < header.size(); ++k) {
    width[k] = header[k].size();
    for (const auto& row : rows) width[k] = std::max(width[k], row[k].size());
  }
  // Text columns left-aligned, numbers right-aligned.
  const auto print_row = [&](const std::vector<std::string>& row) {
    std::string line;
    for (std::size_t k = 0; k < row.size(); ++k) {
      if (k > 0) line += "  ";
      line +=
          k < 3 ? fmt::format("{:<{}}", row[k], width[k]) : fmt::format("{:>{}}", row[k], width[k]);
    }
    while (!line.empty() && line.back() == ' ') line.pop_back();
    fmt::print("{}\n", line);
  };
  fmt::print("catalog {} ({}): {} glasses\n", catalog.name, catalog.path, catalog.glasses.size());
  print_row(header);
  for (const auto& row : rows) print_row(row);
  bool starred = false;
  for (const auto& row : rows)
    for (std::size_t k = 5; k < row.size(); ++k) starred |= row[k].back() == '*';
  if (starred) fmt::print("* outside the glass's formula range (AGF LD line): extrapolated\n");
}

void run_catalog(const CatalogCommand& cmd) {
  const auto catalog = load_catalog(cmd.catalog);
  for (const auto& warning : catalog->warnings) {
    fmt::print(stderr, "lensopt catalog: warning: {}\n", warning);
  }
  print_notes(*catalog, cmd.wavelengths_nm);
  if (cmd.json) {
    print_json(*catalog, cmd.wavelengths_nm);
  } else {
    print_table(*catalog, cmd.wavelengths_nm);
  }
}

}  // namespace

void setup_catalog(CLI::App& app) {
  auto cmd = std::make_shared<CatalogCommand>();
  CLI::App* sub = app.add_subcommand(
      "catalog", "List a glass catalog (AGF file or name such as 'ohara'): nd, vd, indices");
  sub->add_option("FILE", cmd->catalog, "AGF file, or a catalog name (ohara, or X for X.agf)")
      ->required();
  sub->add_flag("--json", cmd->json, "one JSON array on stdout (warnings on stderr)");
  sub->add_option("--wavelengths-nm", cmd->wavelengths_nm,
                  "wavelengths in nm, comma-separated (default 587.5618)")
      ->delimiter(',')
      ->check(CLI::Range(1.0, 1.0e6));
  sub->callback([cmd] { run_catalog(*cmd); });
}

}  // namespace lensopt::cli
