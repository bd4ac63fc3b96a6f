// Glass look-up in a catalog, the catalog search path, and the cache of loaded catalogs.
#include <fmt/format.h>
#include <fmt/ranges.h>

#include <algorithm>
#include <cctype>
#include <cmath>
#include <cstdlib>
#include <map>
#include <memory>
#include <mutex>
#include <numeric>
#include <optional>
#include <system_error>

#include "lensopt/core/error.h"
#include "lensopt/core/text.h"
#include "lensopt/glass/glass.h"

namespace lensopt {
namespace {

// The built-in catalog that the name "ohara" stands for (catalogs/ohara65.agf).
constexpr std::string_view kOharaAlias = "ohara";
constexpr std::string_view kOharaFile = "ohara65.agf";

bool equals_ignoring_case(std::string_view a, std::string_view b) {
  return a.size() == b.size() && std::equal(a.begin(), a.end(), b.begin(), [](char x, char y) {
           return std::tolower(static_cast<unsigned char>(x)) ==
                  std::tolower(static_cast<unsigned char>(y));
         });
}

// Folder of the running executable (from /proc/self/exe), or empty when unknown.
std::filesystem::path executable_dir() {
  std::error_code ec;
  const auto exe = std::filesystem::read_symlink("/proc/self/exe", ec);
  if (ec) return {};
  return exe.parent_path();
}

// The .agf file in `dir` whose stem equals `stem` (case-insensitive), if any; else the vendor
// file of that family (stem "<stem>_<digits>", case-insensitive) with the largest date.
std::optional<std::filesystem::path> find_in_dir(const std::filesystem::path& dir,
                                                 std::string_view stem) {
  std::error_code ec;
  // The usual spellings first, then a case-insensitive scan of the folder.
  for (const char* extension : {".agf", ".AGF"}) {
    const auto candidate = dir / (std::string(stem) + extension);
    if (std::filesystem::is_regular_file(candidate, ec)) return candidate;
  }
  std::filesystem::directory_iterator it(dir, ec);
  if (ec) return std::nullopt;
  std::optional<std::filesystem::path> newest_of_family;
  std::string newest_stem;
  for (const auto& entry : it) {
    const auto& path = entry.path();
    if (!equals_ignoring_case(path.extension().string(), ".agf") || !entry.is_regular_file(ec))
      continue;
    const std::string file_stem = path.stem().string();
    if (equals_ignoring_case(file_stem, stem)) return path;
    if (file_stem != catalog_family_name(file_stem) &&
        equals_ignoring_case(catalog_family_name(file_stem), stem) &&
        (!newest_of_family || to_lower(file_stem) > newest_stem)) {
      newest_of_family = path;
      newest_stem = to_lower(file_stem);
    }
  }
  return newest_of_family;
}

struct CatalogCache {
  std::mutex mutex;
  std::map<std::string, std::shared_ptr<const Catalog>> by_path;
};

CatalogCache& catalog_cache() {
  static CatalogCache cache;
  return cache;
}

std::shared_ptr<const Catalog> load_cached(const std::filesystem::path& path) {
  std::error_code ec;
  auto key_path = std::filesystem::weakly_canonical(path, ec);
  if (ec) key_path = std::filesystem::absolute(path);
  const std::string key = key_path.string();
  CatalogCache& cache = catalog_cache();
  {
    const std::lock_guard<std::mutex> lock(cache.mutex);
    if (const auto it = cache.by_path.find(key); it != cache.by_path.end()) return it->second;
  }
  // Parse outside the lock; if another thread loaded the same file meanwhile, keep the first.
  auto catalog = std::make_shared<const Catalog>(read_agf(path));
  const std::lock_guard<std::mutex> lock(cache.mutex);
  return cache.by_path.emplace(key, std::move(catalog)).first->second;
}

}  // namespace

const Glass* Catalog::find(std::string_view glass_name) const {
  for (const Glass& glass : glasses) {
    if (equals_ignoring_case(glass.name, glass_name)) return &glass;
  }
  return nullptr;
}

const Glass& Catalog::at(std::string_view glass_name) const {
  if (const Glass* glass = find(glass_name)) return *glass;
  const auto closest = closest_names(glass_name, 3);
  std::string message = fmt::format("unknown glass '{}' in catalog {}", glass_name, name);
  if (!closest.empty()) message += fmt::format("; closest: {}", fmt::join(closest, ", "));
  throw Error(message);
}

std::vector<std::string> Catalog::closest_names(std::string_view glass_name,
                                                std::size_t count) const {
  const std::string wanted = to_lower(glass_name);
  std::vector<std::pair<std::size_t, std::size_t>> ranked;  // (distance, index in file)
  ranked.reserve(glasses.size());
  for (std::size_t i = 0; i < glasses.size(); ++i) {
    ranked.emplace_back(edit_distance(wanted, to_lower(glasses[i].name)), i);
  }
  // Best first; ties keep the file's order.
  std::sort(ranked.begin(), ranked.end());
  std::vector<std::string> names;
  for (std::size_t k = 0; k < ranked.size() && k < count; ++k) {
    names.push_back(glasses[ranked[k].second].name);
  }
  return names;
}

std::vector<const Glass*> Catalog::closest_by_index(double nd, double vd, std::size_t count) const {
  std::vector<std::pair<double, std::size_t>> ranked;  // (distance, index in file)
  for (std::size_t i = 0; i < glasses.size(); ++i) {
    if (!glasses[i].formula_supported) continue;
    const double dn = 100.0 * (glasses[i].nd - nd);
    const double dv = glasses[i].vd - vd;
    ranked.emplace_back(std::sqrt(dn * dn + dv * dv), i);
  }
  std::sort(ranked.begin(), ranked.end());
  std::vector<const Glass*> out;
  for (std::size_t k = 0; k < ranked.size() && k < count; ++k)
    out.push_back(&glasses[ranked[k].second]);
  return out;
}

std::string catalog_family_name(std::string_view stem) {
  // "<family>_<digits>" -> "<family>"; a stem that is all date, or has no such suffix, stays.
  const std::size_t underscore = stem.rfind('_');
  if (underscore == std::string_view::npos || underscore == 0 || underscore + 1 == stem.size())
    return std::string(stem);
  const std::string_view suffix = stem.substr(underscore + 1);
  const bool all_digits = std::all_of(suffix.begin(), suffix.end(), [](char ch) {
    return std::isdigit(static_cast<unsigned char>(ch)) != 0;
  });
  return all_digits ? std::string(stem.substr(0, underscore)) : std::string(stem);
}

const std::vector<std::string>& shipped_catalog_names() {
  static const std::vector<std::string> names = {"SCHOTT", "OHARA", "HOYA", "CDGM"};
  return names;
}

const std::vector<std::string>& database_catalog_names() {
  static const std::vector<std::string> names = {"HIKARI",  "SUMITA",   "LZOS", "LIGHTPATH",
                                                 "CORNING", "INFRARED", "MISC"};
  return names;
}

std::vector<std::string> all_shipped_catalog_names() {
  std::vector<std::string> names = shipped_catalog_names();
  for (const std::string& name : database_catalog_names()) names.push_back(name);
  return names;
}

std::string zemax_catalog_alias(std::string_view name) {
  const std::string upper_name = [&] {
    std::string out(name);
    for (char& ch : out) ch = static_cast<char>(std::toupper(static_cast<unsigned char>(ch)));
    return out;
  }();
  if (upper_name == "NIKON-HIKARI" || upper_name == "NIKON" || upper_name == "NIKON_HIKARI")
    return "HIKARI";
  const std::size_t underscore = upper_name.rfind('_');
  if (underscore != std::string::npos && underscore > 0) {
    const std::string suffix = upper_name.substr(underscore + 1);
    if (std::any_of(suffix.begin(), suffix.end(),
                    [](char ch) { return std::isdigit(static_cast<unsigned char>(ch)) != 0; }))
      return zemax_catalog_alias(upper_name.substr(0, underscore));
  }
  return std::string(name);
}

std::vector<std::filesystem::path> catalog_search_path() {
  std::vector<std::filesystem::path> folders;
  const auto add = [&](const std::filesystem::path& folder) {
    if (folder.empty()) return;
    const auto normal = folder.lexically_normal();
    if (std::find(folders.begin(), folders.end(), normal) == folders.end()) {
      folders.push_back(normal);
    }
  };
  if (const char* env = std::getenv("LENSOPT_CATALOG_PATH")) {
    std::string_view list(env);
    while (!list.empty()) {
      const std::size_t colon = list.find(':');
      add(std::filesystem::path(std::string(list.substr(0, colon))));
      if (colon == std::string_view::npos) break;
      list.remove_prefix(colon + 1);
    }
  }
  add(std::filesystem::path(LENSOPT_SOURCE_DIR) / "catalogs");
  if (const auto exe_dir = executable_dir(); !exe_dir.empty()) {
    add(exe_dir / ".." / "share" / "lensopt" / "catalogs");
    add(exe_dir / ".." / "catalogs");
  }
  return folders;
}

std::shared_ptr<const Catalog> load_catalog(std::string_view name_or_path) {
  if (name_or_path.empty()) throw Error("no glass catalog named (empty catalog name)");
  std::error_code ec;
  const std::filesystem::path as_path{std::string(name_or_path)};
  if (std::filesystem::is_regular_file(as_path, ec)) return load_cached(as_path);
  if (std::filesystem::is_directory(as_path, ec))
    throw Error(SourceLocation{as_path.string()}, "it is a directory, not a glass catalog (.agf)");
  // A name with a folder in it is a path that does not exist.
  if (as_path.has_parent_path()) {
    throw Error(SourceLocation{as_path.string()}, "glass catalog file not found");
  }
  // A name: "ohara" is the built-in ohara65.agf; any other name X is X.agf in the search path
  // (or X_<date>.agf). Only the lower-case spelling is the alias: "OHARA", as Zemax files name
  // it, is Ohara's complete catalog.
  const bool is_ohara = name_or_path == kOharaAlias;
  const std::string stem = is_ohara ? std::filesystem::path(kOharaFile).stem().string()
                                    : std::filesystem::path(as_path).stem().string();
  const auto folders = catalog_search_path();
  for (const auto& folder : folders) {
    if (const auto found = find_in_dir(folder, stem)) return load_cached(*found);
  }
  // A Zemax name for a shipped catalog ("NIKON-HIKARI" is HIKARI).
  if (!is_ohara) {
    const std::string alias = zemax_catalog_alias(stem);
    if (!equals_ignoring_case(alias, stem))
      for (const auto& folder : folders)
        if (const auto found = find_in_dir(folder, alias)) return load_cached(*found);
  }
  std::vector<std::string> searched;
  for (const auto& folder : folders) searched.push_back(folder.string());
  throw Error(
      fmt::format("glass catalog '{}' not found: looked for {}.agf (or {}_<date>.agf) in {} "
                  "(LENSOPT_CATALOG_PATH adds folders; shipped: ohara, {})",
                  name_or_path, stem, stem, fmt::join(searched, ", "),
                  fmt::join(all_shipped_catalog_names(), ", ")));
}

}  // namespace lensopt
