// The search's options, its TOML description, the candidate list, its fingerprint and shards.
#include <fmt/core.h>
#include <fnmatch.h>
#include <toml++/toml.h>

#include <algorithm>
#include <cmath>
#include <functional>
#include <map>
#include <nlohmann/json.hpp>
#include <optional>
#include <set>

#include "lensopt/core/atomic_file.h"
#include "lensopt/core/constants.h"
#include "lensopt/core/error.h"
#include "lensopt/formats/lens_file.h"
#include "lensopt/lens/input_limits.h"
#include "lensopt/lens/lens_io.h"
#include "lensopt/lens/validate.h"
#include "lensopt/search/search.h"
#include "optimize/optimize_table.h"
#include "search_detail.h"

namespace lensopt {
namespace {

SourceLocation where_of(const std::filesystem::path& path, const toml::node& node) {
  return SourceLocation{path.string(), static_cast<int>(node.source().begin.line),
                        static_cast<int>(node.source().begin.column)};
}

toml::table parse_toml_file(const std::filesystem::path& path) {
  const std::string text = read_file(path);
  check_toml_nesting(text, path.string());  // before toml++ recurses (lens/input_limits.h)
  try {
    return toml::parse(text, path.string());
  } catch (const toml::parse_error& e) {
    throw Error(SourceLocation{path.string(), static_cast<int>(e.source().begin.line),
                               static_cast<int>(e.source().begin.column)},
                std::string(e.description()));
  }
}

// Lens files named by a path whose file name may hold the wildcards * ? [...], sorted.
std::vector<std::filesystem::path> expand_lens_path(const std::string& pattern) {
  const std::filesystem::path p(pattern);
  const std::string name = p.filename().string();
  if (name.find_first_of("*?[") == std::string::npos) {
    if (!std::filesystem::exists(p)) throw Error(SourceLocation{pattern}, "no such lens file");
    return {p};
  }
  const std::filesystem::path dir = p.has_parent_path() ? p.parent_path() : ".";
  std::vector<std::filesystem::path> out;
  std::error_code ec;
  for (const auto& entry : std::filesystem::directory_iterator(dir, ec)) {
    if (!entry.is_regular_file()) continue;
    const std::string file = entry.path().filename().string();
    if (fnmatch(name.c_str(), file.c_str(), 0) == 0) out.push_back(p.parent_path() / file);
  }
  if (ec) throw Error(SourceLocation{dir.string()}, "cannot list the folder: " + ec.message());
  if (out.empty()) throw Error(SourceLocation{pattern}, "no lens file matches");
  std::sort(out.begin(), out.end());
  return out;
}

// The search's specs on a candidate: all of them on a generated start (`own_specs` false), only
// the explicitly given ones on a start read from a lens file.
void apply_specs(Lens& lens, const SearchOptions& options, bool own_specs) {
  if (!own_specs || options.f_number_given) lens.specs.f_number = options.f_number;
  if (!own_specs || options.half_field_given) lens.specs.half_field_deg = options.half_field_deg;
  if (!own_specs || options.sensor_diagonal_given)
    lens.specs.sensor_diagonal_mm = options.sensor_diagonal_mm;
}

}  // namespace

SearchOptions::SearchOptions() {
  optimize.verbose = false;
  optimize.glass_search = GlassSearch::kNone;
}

void SearchOptions::validate() const {
  if (starts.empty())
    throw Error("the search has no starting lens: give lens files or generated element counts");
  for (const StartGroup& g : starts) {
    if (g.lens_files.empty() && g.generate.empty())
      throw Error("a start group has neither lens files nor generated element counts");
    for (int n : g.generate)
      if (n < 1 || n > 4)
        throw Error(fmt::format("generate = {}: generated starts have 1 to 4 elements", n));
    if (g.glass_seeds < 1 || g.glass_seeds > 1000)
      throw Error(fmt::format("glass_seeds = {} must be in [1, 1000]", g.glass_seeds));
    if (!g.stops.front && !g.stops.between && !g.stops.rear)
      throw Error("stops: give at least one stop position");
  }
  // A requested F-number: below F/0.5 no lens in air can meet it (lens/validate.h).
  if (!(f_number >= kMinFNumber && f_number <= kMaxFNumber))
    throw Error(
        fmt::format("f_number = {} must be in [{:g}, {:g}]", f_number, kMinFNumber, kMaxFNumber));
  if (!(half_field_deg > 0.0 && half_field_deg < 90.0))
    throw Error(fmt::format("half_field_deg = {} must be in (0, 90)", half_field_deg));
  if (!(sensor_diagonal_mm > 0.0) || !std::isfinite(sensor_diagonal_mm))
    throw Error(fmt::format("sensor_diagonal_mm = {} must be > 0", sensor_diagonal_mm));
  if (top_k < 0) throw Error(fmt::format("top = {} must be >= 0", top_k));
  if (jobs < 0) throw Error(fmt::format("jobs = {} must be >= 0", jobs));
  if (optimizer_threads < 0)
    throw Error(fmt::format("threads = {} must be >= 0", optimizer_threads));
  if (shard_count < 1 || shard_index < 1 || shard_index > shard_count)
    throw Error(fmt::format("shard {}/{}: need 1 <= I <= N", shard_index, shard_count));
  optimize.validate();
}

bool is_search_description(const std::filesystem::path& path) {
  if (path.extension() != ".toml") return false;
  const toml::table file = parse_toml_file(path);
  return file["search"].as_table() != nullptr;
}

namespace {

// Reads a search description's tables into SearchOptions, each value checked for its type with
// an Error at its file:line:column.
class DescriptionReader {
 public:
  explicit DescriptionReader(const std::filesystem::path& path)
      : path_(path), base_(path.parent_path()) {}

  // Only [search], [specs] and [optimize], each a table.
  void check_tables(const toml::table& file) const {
    for (const auto& [key, node] : file) {
      const std::string k(key.str());
      if (k != "search" && k != "specs" && k != "optimize")
        throw Error(where_of(path_, node),
                    fmt::format("unknown table [{}]; known: [search], [specs], [optimize]", k));
      if (!node.is_table())
        throw Error(where_of(path_, node), fmt::format("'{}' must be a table", k));
    }
  }

  // Start keys, in [search] (the defaults, and a group of their own when they name lenses) and
  // in each [[search.starts]] table (a group inheriting the defaults' variations); with
  // [search]'s own keys (catalog, top).
  void read_starts(const toml::table& file, SearchOptions& options) const {
    StartGroup defaults;
    const toml::array* start_tables = nullptr;
    for_each(
        file, "search", [&](const std::string& k, const toml::node& n, const SourceLocation& w) {
          if (group_key(defaults, k, n, w)) return;
          if (k == "catalog") {
            options.catalog = string(k, n, w);
          } else if (k == "top") {
            options.top_k = integer(k, n, w);
          } else if (k == "starts") {
            start_tables = n.as_array();
            if (!start_tables || !start_tables->is_array_of_tables())
              throw Error(w, "starts must be an array of tables: [[search.starts]]");
          } else {
            throw Error(
                w, fmt::format("unknown key '{}' in [search]; known: lenses, generate, vary_stop, "
                               "vary_cement, stops, glass_seeds, catalog, top, starts",
                               k));
          }
        });
    if (!defaults.lens_files.empty() || !defaults.generate.empty())
      options.starts.push_back(defaults);
    if (!start_tables) return;
    for (const auto& item : *start_tables) {
      StartGroup g = defaults;
      g.lens_files.clear();
      g.generate.clear();
      for (const auto& [key, node] : *item.as_table()) {
        const std::string k(key.str());
        if (!group_key(g, k, node, where_of(path_, node)))
          throw Error(where_of(path_, node),
                      fmt::format("unknown key '{}' in [[search.starts]]; known: lenses, generate, "
                                  "vary_stop, vary_cement, stops, glass_seeds",
                                  k));
      }
      if (g.lens_files.empty() && g.generate.empty())
        throw Error(where_of(path_, item), "[[search.starts]] needs lenses or generate");
      options.starts.push_back(g);
    }
  }

  // [specs]: the spec overrides; focal_length_mm gives the sensor d = 2 f tan(hfov).
  void read_specs(const toml::table& file, SearchOptions& options) const {
    for_each(file, "specs",
             [&](const std::string& k, const toml::node& n, const SourceLocation& w) {
               if (k == "f_number") {
                 options.f_number = number(k, n, w);
                 options.f_number_given = true;
               } else if (k == "half_field_deg") {
                 options.half_field_deg = number(k, n, w);
                 options.half_field_given = true;
               } else if (k == "sensor_diagonal_mm") {
                 options.sensor_diagonal_mm = number(k, n, w);
                 options.sensor_diagonal_given = true;
               } else if (k == "focal_length_mm") {
                 options.sensor_diagonal_given = true;
                 // d = 2 f tan(hfov), with the half field given in this table or the default.
                 const double f = number(k, n, w);
                 const toml::table* specs = file["specs"].as_table();
                 double hfov = options.half_field_deg;
                 if (const auto h = (*specs)["half_field_deg"].value<double>()) hfov = *h;
                 options.sensor_diagonal_mm = 2.0 * f * std::tan(hfov * kPi / 180.0);
               } else {
                 throw Error(
                     w, fmt::format("unknown key '{}' in [specs]; known: f_number, half_field_deg, "
                                    "sensor_diagonal_mm, focal_length_mm",
                                    k));
               }
             });
  }

  // [optimize]: optimize's own keys (optimize_table.h), plus constraints = "paper+strict".
  void read_optimize(const toml::table& file, SearchOptions& options) const {
    for_each(file, "optimize",
             [&](const std::string& k, const toml::node& n, const SourceLocation& w) {
               // "paper+strict" is the search's own: two optimizations per candidate.
               if (k == "constraints" &&
                   n.value<std::string>() == std::optional<std::string>("paper+strict")) {
                 options.optimize.loss.paper_penalties = false;
                 options.paper_then_strict = true;
                 return;
               }
               if (k == "constraints") options.paper_then_strict = false;
               if (!apply_optimize_key(k, n, w, options.optimize))
                 throw Error(w, fmt::format("unknown key '{}' in [optimize]; known: {}", k,
                                            optimize_table_keys()));
             });
  }

 private:
  template <typename Handle>
  void for_each(const toml::table& file, const char* table_name, Handle&& handle) const {
    const toml::table* table = file[table_name].as_table();
    if (!table) return;
    for (const auto& [key, node] : *table)
      handle(std::string(key.str()), node, where_of(path_, node));
  }
  static double number(const std::string& k, const toml::node& n, const SourceLocation& w) {
    const auto v = n.value<double>();
    if (!v) throw Error(w, fmt::format("{} must be a number", k));
    return *v;
  }
  static int integer(const std::string& k, const toml::node& n, const SourceLocation& w) {
    const auto v = n.value<int64_t>();
    if (!v || !n.is_integer()) throw Error(w, fmt::format("{} must be an integer", k));
    return static_cast<int>(*v);
  }
  static bool boolean(const std::string& k, const toml::node& n, const SourceLocation& w) {
    const auto v = n.value<bool>();
    if (!v) throw Error(w, fmt::format("{} must be true or false", k));
    return *v;
  }
  static std::string string(const std::string& k, const toml::node& n, const SourceLocation& w) {
    const auto v = n.value<std::string>();
    if (!v) throw Error(w, fmt::format("{} must be a string", k));
    return *v;
  }
  std::vector<std::string> strings(const std::string& k, const toml::node& n,
                                   const SourceLocation& w) const {
    const toml::array* arr = n.as_array();
    if (!arr) throw Error(w, fmt::format("{} must be an array of strings", k));
    std::vector<std::string> out;
    for (const auto& item : *arr) out.push_back(string(k, item, where_of(path_, item)));
    return out;
  }

  // One start key of a group; false for a key that is not one.
  bool group_key(StartGroup& g, const std::string& k, const toml::node& n,
                 const SourceLocation& w) const {
    if (k == "lenses") {
      for (const std::string& s : strings(k, n, w)) {
        const std::filesystem::path p(s);
        g.lens_files.push_back(p.is_absolute() ? s : (base_ / p).lexically_normal().string());
      }
    } else if (k == "generate") {
      const toml::array* arr = n.as_array();
      if (!arr) throw Error(w, "generate must be an array of element counts, e.g. [2, 3]");
      for (const auto& item : *arr) g.generate.push_back(integer(k, item, where_of(path_, item)));
    } else if (k == "vary_stop") {
      g.vary_stop = boolean(k, n, w);
    } else if (k == "vary_cement") {
      g.vary_cement = boolean(k, n, w);
    } else if (k == "stops") {
      g.stops = StopPlaces{false, false, false};
      for (const std::string& s : strings(k, n, w)) {
        if (s == "front")
          g.stops.front = true;
        else if (s == "between")
          g.stops.between = true;
        else if (s == "rear")
          g.stops.rear = true;
        else
          throw Error(w, fmt::format("stops: '{}' must be front, between or rear", s));
      }
    } else if (k == "glass_seeds") {
      g.glass_seeds = integer(k, n, w);
    } else {
      return false;
    }
    return true;
  }

  std::filesystem::path path_;
  std::filesystem::path base_;  // relative lens paths are relative to the description's folder
};

}  // namespace

void read_search_description(const std::filesystem::path& path, SearchOptions& options) {
  const toml::table file = parse_toml_file(path);
  const DescriptionReader reader(path);
  reader.check_tables(file);
  reader.read_starts(file, options);
  reader.read_specs(file, options);
  reader.read_optimize(file, options);
}

std::vector<SearchCandidate> make_candidates(const SearchOptions& options) {
  std::vector<SearchCandidate> out;
  std::set<std::string> labels;
  auto unique_label = [&](std::string label) {
    if (labels.insert(label).second) return label;
    for (int i = 2;; ++i) {
      const std::string l = fmt::format("{}-{}", label, i);
      if (labels.insert(l).second) return l;
    }
  };
  auto push = [&](const std::string& source, const std::string& layout, int seed, bool own_specs,
                  const std::function<Lens()>& build) {
    SearchCandidate c;
    c.index = static_cast<int>(out.size());
    c.source = source;
    c.layout = layout;
    c.glass_seed = seed;
    c.from_lens_file = own_specs;
    c.id = fmt::format("{}:{}:g{}", source, layout, seed);
    try {
      c.start = build();
      c.start.name = c.id;
      apply_specs(c.start, options, own_specs);
      c.start.validate();
    } catch (const Error& e) {
      c.error = e.message();
    }
    out.push_back(std::move(c));
  };

  for (const StartGroup& g : options.starts) {
    for (const std::string& pattern : g.lens_files) {
      for (const std::filesystem::path& path : expand_lens_path(pattern)) {
        const Lens lens = read_lens(path);  // an unreadable file is bad input: it throws
        const std::string label = unique_label(path.stem().string());
        std::optional<LensForm> form;
        std::string form_error;
        try {
          form = decompose_lens(lens);
        } catch (const Error& e) {
          form_error = e.message();
        }
        if (!form) {
          // Only the lens as given; seeds and layouts need its elements.
          for (int seed = 0; seed < g.glass_seeds; ++seed) {
            push(label, "as-given", seed, true, [&]() -> Lens {
              if (seed == 0) return lens;
              throw Error("glass seeds need a lens of elements and one stop in air: " + form_error);
            });
          }
          continue;
        }
        const std::string catalog_name =
            lens.catalog_name.empty() ? options.catalog : lens.catalog_name;
        const double defocus_mm = detail::lens_defocus_mm(lens);
        for (const LensLayout& layout :
             layout_variants(form->layout, g.vary_stop, g.vary_cement, g.stops)) {
          for (int seed = 0; seed < g.glass_seeds; ++seed) {
            push(label, layout.code(), seed, true, [&]() -> Lens {
              if (seed == 0 && layout == form->layout) return lens;
              LensForm f = with_layout(*form, layout);
              seed_glasses(f, seed, *load_catalog(catalog_name));
              Lens l = compose_lens(f, lens);
              if (l.catalog_name.empty() && seed > 0) l.catalog_name = catalog_name;
              l.surfaces.back().thickness_mm = detail::rebuilt_image_mm(l, defocus_mm);
              return l;
            });
          }
        }
      }
    }
    for (int n : g.generate) {
      const std::string label = unique_label(fmt::format("gen{}", n));
      Lens like;
      like.catalog_name = options.catalog;
      like.source_path = label;
      apply_specs(like, options, false);
      const double f = like.specs.focal_length_mm();
      for (const LensLayout& layout :
           layout_variants(default_layout(n), g.vary_stop, g.vary_cement, g.stops)) {
        for (int seed = 0; seed < g.glass_seeds; ++seed) {
          push(label, layout.code(), seed, false, [&]() -> Lens {
            const std::shared_ptr<const Catalog> catalog = load_catalog(options.catalog);
            LensForm form = generated_form(layout, *catalog, f);
            seed_glasses(form, seed, *catalog);
            Lens l = compose_lens(form, like);
            l.surfaces.back().thickness_mm = detail::rebuilt_image_mm(l, 0.0);
            return l;
          });
        }
      }
    }
  }
  return out;
}

namespace detail {

uint64_t fnv1a64(const std::string& text, uint64_t hash) {
  for (unsigned char c : text) {
    hash ^= c;
    hash *= 1099511628211ull;
  }
  return hash;
}

nlohmann::json optimize_settings_json(const OptimizeOptions& o, bool paper_then_strict) {
  return {{"glass_search", glass_search_name(o.glass_search)},
          {"glass_neighbours", o.glass_neighbours},
          {"constraints", paper_then_strict        ? "paper+strict"
                          : o.loss.paper_penalties ? "paper"
                                                   : "strict"},
          {"rings", o.sampling.rings},
          {"fields", o.sampling.fields},
          {"ray_aiming", o.sampling.ray_aiming},
          {"scale_to_spec", o.sampling.scale_to_spec},
          {"max_iterations", o.max_iterations},
          {"max_rounds", o.max_rounds},
          {"soft_start", o.soft_start},
          {"freeze", o.freeze},
          {"weight_spot", o.loss.weight_spot},
          {"weight_ray_path", o.loss.weight_ray_path},
          {"weight_ray_angle", o.loss.weight_ray_angle},
          {"weight_glass", o.loss.weight_glass},
          {"min_air_mm", o.loss.min_air_mm},
          {"min_glass_mm", o.loss.min_glass_mm},
          {"max_glass_mm", o.loss.max_glass_mm},
          {"min_image_clearance_mm", o.loss.min_image_clearance_mm},
          {"max_ray_angle_deg", o.loss.max_ray_angle_deg}};
}

}  // namespace detail

std::string search_fingerprint(const std::vector<SearchCandidate>& candidates,
                               const SearchOptions& options) {
  uint64_t h =
      detail::fnv1a64(detail::optimize_settings_json(options.optimize, options.paper_then_strict)
                          .dump(-1, ' ', false, nlohmann::json::error_handler_t::replace));
  for (const SearchCandidate& c : candidates) {
    h = detail::fnv1a64(c.id + "\n", h);
    h = detail::fnv1a64(c.error.empty() ? format_lens_toml(c.start) : "error: " + c.error, h);
  }
  return fmt::format("{:016x}", h);
}

bool in_shard(int index, int shard_index, int shard_count) {
  return index % shard_count == shard_index - 1;
}

void parse_shard(const std::string& text, int& shard_index, int& shard_count) {
  const auto slash = text.find('/');
  try {
    if (slash == std::string::npos) throw std::invalid_argument("no slash");
    std::size_t used_i = 0, used_n = 0;
    const int i = std::stoi(text.substr(0, slash), &used_i);
    const int n = std::stoi(text.substr(slash + 1), &used_n);
    if (used_i != slash || used_n != text.size() - slash - 1 || n < 1 || i < 1 || i > n)
      throw std::invalid_argument("range");
    shard_index = i;
    shard_count = n;
  } catch (const std::logic_error&) {
    throw Error(SourceLocation{"--shard"},
                fmt::format("'{}' must be I/N with 1 <= I <= N, e.g. 2/8", text));
  }
}

std::string candidate_list_text(const std::vector<SearchCandidate>& candidates,
                                const SearchOptions& options) {
  std::string out = "index  shard  id  status\n";
  for (const SearchCandidate& c : candidates) {
    const int shard = c.index % options.shard_count + 1;
    out += fmt::format("{:5d}  {}/{}  {}  {}\n", c.index, shard, options.shard_count, c.id,
                       c.error.empty() ? "ok" : "error: " + c.error);
  }
  return out;
}

}  // namespace lensopt
