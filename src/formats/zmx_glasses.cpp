// The .zmx reader's glasses: the GCAT catalogs loaded in order, and each surface's GLAS resolved
// against them or as a model glass (zmx_parser.h).
#include <fmt/format.h>

#include <algorithm>
#include <charconv>
#include <cmath>
#include <filesystem>
#include <set>

#include "zmx_parser.h"

namespace lensopt::zmx_detail {

std::vector<CatalogEntry> ZmxParser::load_catalogs() {
  std::vector<CatalogEntry> out;
  std::set<std::string> paths;
  auto add = [&](CatalogEntry entry) {
    if (entry.catalog && !paths.insert(entry.catalog->path).second) return;
    out.push_back(std::move(entry));
  };
  auto try_load = [&](const std::string& requested, const std::string& name) -> bool {
    try {
      add({requested, name, load_catalog(name), ""});
      return true;
    } catch (const Error& error) {
      return false;
    }
  };
  std::vector<std::string> names;
  if (note_catalog_) names.push_back(*note_catalog_);
  for (const auto& [name, line] : gcat_) names.push_back(name);
  // No GCAT line (and no lensopt note): OpticStudio's default glass catalog, SCHOTT.
  if (names.empty()) names.push_back("SCHOTT");
  for (const std::string& name : names) {
    bool found = try_load(name, name);
    // OpticStudio names catalogs by family ("SCHOTT"); vendor files are often dated
    // ("SCHOTT_202002.AGF"): take those in the search path as well.
    for (const auto& folder : catalog_search_path()) {
      std::error_code ec;
      std::filesystem::directory_iterator it(folder, ec);
      if (ec) continue;
      std::vector<std::filesystem::path> matches;
      for (const auto& entry : it) {
        const std::string stem = upper(entry.path().stem().string());
        if (upper(entry.path().extension().string()) != ".AGF") continue;
        const std::string wanted = upper(name);
        if (stem == wanted || stem.rfind(wanted + "_", 0) == 0) matches.push_back(entry.path());
      }
      std::sort(matches.begin(), matches.end());
      for (const auto& path : matches) found = try_load(name, path.stem().string()) || found;
    }
    if (!found) {
      std::vector<std::string> folders;
      for (const auto& folder : catalog_search_path()) folders.push_back(folder.string());
      add({name, "", nullptr,
           fmt::format("not found in {}", folders.empty()
                                              ? "(no folders)"
                                              : fmt::format("{}", fmt::join(folders, ", ")))});
    }
  }
  return out;
}

Material ZmxParser::resolve_glass(const RawSurface& raw, std::vector<CatalogEntry>& catalogs,
                                  std::vector<std::string>& used_catalogs,
                                  DispersionModel dispersion) {
  if (raw.glass.empty()) return Material::air();
  // OpticStudio's model glass: n(587.5618 nm) = nd exactly (glass/dispersion.h); the paper's
  // in a file lensopt wrote from a lens with the paper's model glasses (its note says so).
  if (raw.model_glass)
    return note_model_glass_paper_
               ? Material::model(raw.model_nd, raw.model_vd)
               : Material::zemax_model(raw.model_nd, raw.model_vd, raw.model_dpgf);
  for (const CatalogEntry& entry : catalogs) {
    if (!entry.catalog) continue;
    const Glass* glass = entry.catalog->find(raw.glass);
    if (glass == nullptr) continue;
    if (dispersion == DispersionModel::kCatalog && !glass->formula_supported)
      fail_at(raw.glas_line, raw.glas_column,
              fmt::format("glass '{}' (catalog {}) uses dispersion formula {}, which lensopt "
                          "cannot evaluate",
                          glass->name, entry.catalog->name, formula_name(glass->formula)));
    if (std::find(used_catalogs.begin(), used_catalogs.end(), entry.load_name) ==
        used_catalogs.end())
      used_catalogs.push_back(entry.load_name);
    return Material::from_catalog(*glass);
  }
  // Not in the file's catalogs: a shipped catalog that holds the glass (vendors first, then the
  // database's, shipped order). OpticStudio would refuse the file; lensopt uses the glass and says
  // where it came from, so a file whose GCAT names a catalog lensopt does not ship still imports.
  for (const std::string& name : all_shipped_catalog_names()) {
    std::shared_ptr<const Catalog> catalog;
    try {
      catalog = load_catalog(name);
    } catch (const Error&) {
      continue;
    }
    const bool searched_already =
        std::any_of(catalogs.begin(), catalogs.end(), [&](const CatalogEntry& entry) {
          return entry.catalog && entry.catalog->path == catalog->path;
        });
    if (searched_already) continue;
    const Glass* glass = catalog->find(raw.glass);
    if (glass == nullptr) continue;
    if (dispersion == DispersionModel::kCatalog && !glass->formula_supported) continue;
    std::vector<std::string> requested;
    for (const CatalogEntry& entry : catalogs) requested.push_back(entry.requested);
    warn(raw.glas_line,
         fmt::format("surface {}: glass '{}' is in none of the file's catalogs ({}); lensopt uses "
                     "{} from its shipped catalog {} ({}), where OpticStudio would refuse the file",
                     raw.number, raw.glass,
                     requested.empty() ? std::string("none")
                                       : fmt::format("{}", fmt::join(requested, ", ")),
                     glass->name, catalog->name, catalog->path));
    if (std::find(used_catalogs.begin(), used_catalogs.end(), catalog->name) == used_catalogs.end())
      used_catalogs.push_back(catalog->name);
    return Material::from_catalog(*glass);
  }
  std::vector<std::string> searched;
  // Nearest glasses over all catalogs searched: by name (edit distance) and, when the GLAS line
  // carries the glass's nd and vd, on the glass map.
  std::vector<std::pair<std::size_t, std::string>> by_name;  // (rank in its catalog, name)
  std::vector<std::pair<double, std::string>> by_index;      // (map distance, "NAME (nd, vd)")
  for (const CatalogEntry& entry : catalogs) {
    if (entry.catalog) {
      searched.push_back(fmt::format("{} ({})", entry.requested, entry.catalog->path));
      const auto names = entry.catalog->closest_names(raw.glass, 3);
      for (std::size_t k = 0; k < names.size(); ++k) by_name.emplace_back(k, names[k]);
      if (raw.model_nd > 0.0)
        for (const Glass* g : entry.catalog->closest_by_index(raw.model_nd, raw.model_vd, 3)) {
          const double dn = 100.0 * (g->nd - raw.model_nd);
          const double dv = g->vd - raw.model_vd;
          by_index.emplace_back(
              std::sqrt(dn * dn + dv * dv),
              fmt::format("{} {} ({}, {})", entry.catalog->name, g->name, g->nd, g->vd));
        }
    } else {
      searched.push_back(fmt::format("{} ({})", entry.requested, entry.failure));
    }
  }
  std::stable_sort(by_name.begin(), by_name.end(),
                   [](const auto& a, const auto& b) { return a.first < b.first; });
  std::stable_sort(by_index.begin(), by_index.end(),
                   [](const auto& a, const auto& b) { return a.first < b.first; });
  std::vector<std::string> closest;
  for (std::size_t k = 0; k < by_name.size() && k < 3; ++k) closest.push_back(by_name[k].second);
  std::vector<std::string> nearest;
  for (std::size_t k = 0; k < by_index.size() && k < 3; ++k) nearest.push_back(by_index[k].second);
  fail_at(
      raw.glas_line, raw.glas_column,
      fmt::format("surface {}: unknown glass '{}': not in the catalogs searched: {}{}{}",
                  raw.number, raw.glass,
                  searched.empty() ? std::string("none (the file has no GCAT line)")
                                   : fmt::format("{}", fmt::join(searched, "; ")),
                  closest.empty() ? std::string()
                                  : fmt::format("; closest by name: {}", fmt::join(closest, ", ")),
                  nearest.empty() ? std::string()
                                  : fmt::format("; nearest to nd = {}, vd = {}: {}", raw.model_nd,
                                                raw.model_vd, fmt::join(nearest, ", "))));
}

}  // namespace lensopt::zmx_detail
