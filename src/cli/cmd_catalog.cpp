// lensopt catalog FILE: list a glass catalog's glasses with their indices at chosen wavelengths;
// FILE "all" lists every shipped catalog. --name, --nd and --vd select glasses (a name part, nd and
// vd windows); --plot FILE draws the selected glasses on the glass map (nd against vd).
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
#include "lensopt/core/error.h"
#include "lensopt/core/text.h"
#include "lensopt/glass/dispersion.h"
#include "lensopt/glass/glass.h"
#include "lensopt/glass/glass_range.h"
#include "lensopt/plot/glass_map.h"

namespace lensopt::cli {
namespace {

struct CatalogCommand {
  std::string catalog;  // path or catalog name; "all": every shipped catalog
  bool json = false;
  std::vector<double> wavelengths_nm{kHeliumD_nm};
  std::string name_part;          // --name: glasses whose name contains it (case-insensitive)
  std::vector<double> nd_window;  // --nd LO,HI
  std::vector<double> vd_window;  // --vd LO,HI
  std::string plot_path;          // --plot: the glass map of the listed glasses
};

// The glasses of a catalog that the filters select, as a catalog of their own.
Catalog selected(const Catalog& catalog, const CatalogCommand& cmd) {
  Catalog out;
  out.name = catalog.name;
  out.path = catalog.path;
  const std::string part = to_lower(cmd.name_part);
  for (const Glass& g : catalog.glasses) {
    if (!part.empty() && to_lower(g.name).find(part) == std::string::npos) continue;
    if (cmd.nd_window.size() == 2 && !(g.nd >= cmd.nd_window[0] && g.nd <= cmd.nd_window[1]))
      continue;
    if (cmd.vd_window.size() == 2 && !(g.vd >= cmd.vd_window[0] && g.vd <= cmd.vd_window[1]))
      continue;
    out.glasses.push_back(g);
  }
  return out;
}

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
  for (const auto* window : {&cmd.nd_window, &cmd.vd_window})
    if (!window->empty() && (window->size() != 2 || !((*window)[0] <= (*window)[1])))
      throw lensopt::Error("--nd and --vd take a window LO,HI with LO <= HI");
  if (cmd.json && cmd.catalog == "all")
    throw lensopt::Error("--json lists one catalog (one JSON array); name it instead of all");
  std::vector<std::shared_ptr<const Catalog>> catalogs;
  if (cmd.catalog == "all") {
    for (const std::string& name : all_shipped_catalog_names())
      catalogs.push_back(load_catalog(name));
  } else {
    catalogs.push_back(load_catalog(cmd.catalog));
  }
  std::vector<std::shared_ptr<const Catalog>> shown;
  for (const auto& catalog : catalogs) {
    for (const auto& warning : catalog->warnings)
      fmt::print(stderr, "lensopt catalog: warning: {}\n", warning);
    shown.push_back(std::make_shared<const Catalog>(selected(*catalog, cmd)));
  }
  for (const auto& catalog : shown) {
    print_notes(*catalog, cmd.wavelengths_nm);
    if (cmd.json) {
      print_json(*catalog, cmd.wavelengths_nm);
    } else {
      print_table(*catalog, cmd.wavelengths_nm);
    }
  }
  if (!cmd.plot_path.empty()) {
    plot::GlassMapOptions options;
    options.title = cmd.catalog == "all" ? "Glass map: the shipped catalogs"
                                         : fmt::format("Glass map: {}", catalogs.front()->name);
    std::size_t total = 0;
    for (const auto& catalog : shown) total += catalog->glasses.size();
    options.label_glasses = total <= 40;
    const int drawn = plot::write_glass_map(cmd.plot_path, shown, {}, options);
    fmt::print(stderr, "lensopt catalog: glass map of {} glasses written to {}\n", drawn,
               cmd.plot_path);
  }
}

}  // namespace

void setup_catalog(CLI::App& app) {
  auto cmd = std::make_shared<CatalogCommand>();
  CLI::App* sub = app.add_subcommand(
      "catalog", "List a glass catalog (AGF file or name such as 'ohara'): nd, vd, indices");
  sub->add_option("FILE", cmd->catalog,
                  "AGF file, a catalog name (ohara, X for X.agf, Zemax names such as NIKON-HIKARI, "
                  "INFRARED, MISC), or all (every shipped catalog)")
      ->required();
  sub->add_option("--name", cmd->name_part, "only glasses whose name contains this (any case)");
  sub->add_option("--nd", cmd->nd_window, "only glasses with nd in LO,HI")->delimiter(',');
  sub->add_option("--vd", cmd->vd_window, "only glasses with vd in LO,HI")->delimiter(',');
  sub->add_option("--plot", cmd->plot_path,
                  "also draw the listed glasses on the glass map (nd against vd), .svg or .png");
  sub->add_flag("--json", cmd->json, "one JSON array on stdout (warnings on stderr)");
  sub->add_option("--wavelengths-nm", cmd->wavelengths_nm,
                  "wavelengths in nm, comma-separated (default 587.5618)")
      ->delimiter(',')
      ->check(CLI::Range(1.0, 1.0e6));
  sub->callback([cmd] { run_catalog(*cmd); });
}

}  // namespace lensopt::cli
