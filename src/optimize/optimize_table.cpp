#include "optimize/optimize_table.h"

#include <fmt/format.h>

#include <cmath>
#include <cstdint>
#include <filesystem>
#include <fstream>
#include <optional>
#include <sstream>

namespace lensopt {

GlassSearch parse_glass_search(const std::string& name, const SourceLocation& where) {
  if (name == "none") return GlassSearch::kNone;
  if (name == "snap") return GlassSearch::kSnap;
  if (name == "neighbours" || name == "neighbors") return GlassSearch::kNeighbours;
  throw Error(where, fmt::format("glass_search = '{}' must be none, snap or neighbours", name));
}

std::string glass_search_name(GlassSearch search) {
  switch (search) {
    case GlassSearch::kNone:
      return "none";
    case GlassSearch::kSnap:
      return "snap";
    case GlassSearch::kNeighbours:
      return "neighbours";
  }
  return "?";
}

DesignMerit parse_merit(const std::string& name, const SourceLocation& where) {
  if (name == "spot") return DesignMerit::kSpot;
  if (name == "wavefront") return DesignMerit::kWavefront;
  throw Error(where, fmt::format("merit = '{}' must be spot or wavefront", name));
}

BoundsMode parse_bounds_mode(const std::string& name, const SourceLocation& where) {
  if (name == "auto") return BoundsMode::kAuto;
  if (name == "lens") return BoundsMode::kLens;
  if (name == "paper") return BoundsMode::kPaper;
  throw Error(where, fmt::format("bounds = '{}' must be auto, lens or paper", name));
}

const char* optimize_table_keys() {
  return "glass_search, constraints, rings, fields, max_iterations, max_rounds, glass_neighbours, "
         "weight_ray_path, weight_ray_angle, weight_glass, min_air_mm, min_glass_mm, "
         "max_glass_mm, min_image_clearance_mm, min_virtual_image_mm, max_virtual_image_mm, "
         "max_ray_angle_deg, max_surface_slope_deg, "
         "weight_profile, soft_start, freeze, vary, merit, wavefront_pupil_samples, focus_only, "
         "targets ([[optimize.targets]])";
}

namespace {

SourceLocation location_of(const toml::node& node, const SourceLocation& fallback) {
  const auto& src = node.source();
  if (src.begin.line == 0) return fallback;
  return SourceLocation{fallback.file, static_cast<int>(src.begin.line),
                        static_cast<int>(src.begin.column)};
}

// One [[optimize.targets]] entry (optimize/targets.h): a quantity key with a number (equality)
// or a string with the relation ("<= 1", ">= 0.6", "= 100"), or target = "NAME <= V"; weight and
// field optional.
DesignTarget parse_target_table(const toml::table& table, const SourceLocation& where) {
  std::optional<DesignTarget> target;
  double weight = 1.0;
  int field = 0;
  double frequency_cpmm = 0.0;
  std::optional<MtfOrientation> orientation;
  auto once = [&](const SourceLocation& at) {
    if (target)
      throw Error(at,
                  "[[optimize.targets]]: one quantity per entry (start another "
                  "[[optimize.targets]] for the next)");
  };
  for (const auto& [key, node] : table) {
    const std::string k(key.str());
    const SourceLocation at = location_of(node, where);
    if (k == "weight") {
      const auto v = node.value<double>();
      if (!v) throw Error(at, "[[optimize.targets]] weight must be a number");
      weight = *v;
    } else if (k == "field") {
      const auto v = node.value<int64_t>();
      if (!v || *v < 1) throw Error(at, "[[optimize.targets]] field must be an integer >= 1");
      field = static_cast<int>(*v);
    } else if (k == "frequency_cpmm") {
      const auto v = node.value<double>();
      if (!v) throw Error(at, "[[optimize.targets]] frequency_cpmm must be a number (cycles/mm)");
      frequency_cpmm = *v;
    } else if (k == "orientation") {
      const auto v = node.value<std::string>();
      if (!v)
        throw Error(at,
                    "[[optimize.targets]] orientation must be \"tangential\", \"sagittal\" "
                    "or \"average\"");
      orientation = parse_mtf_orientation(*v, at);
    } else if (k == "target") {
      const auto v = node.value<std::string>();
      if (!v) throw Error(at, "[[optimize.targets]] target must be a string (\"efl_mm = 100\")");
      once(at);
      target = parse_target(*v, at, false);
    } else {
      once(at);
      const TargetQuantity q = parse_target_quantity(k, at);
      if (const auto number = node.value<double>()) {
        DesignTarget t;
        t.quantity = q;
        t.value = *number;
        target = t;
      } else if (const auto text = node.value<std::string>()) {
        // "<= 1": the relation and value of this quantity.
        const std::string trimmed = *text;
        const std::size_t first = trimmed.find_first_not_of(" \t");
        const bool relation =
            first != std::string::npos &&
            (trimmed[first] == '<' || trimmed[first] == '>' || trimmed[first] == '=');
        target = parse_target(relation ? k + trimmed : k + "=" + trimmed, at, false);
      } else {
        throw Error(at, fmt::format("[[optimize.targets]] {} must be a number (= target) or a "
                                    "string with its relation (\"<= 1\", \">= 0.6\")",
                                    k));
      }
    }
  }
  if (!target)
    throw Error(where, fmt::format("[[optimize.targets]]: no quantity; write one of {} (e.g. "
                                   "efl_mm = 100, distortion_percent = \"<= 1\")",
                                   target_quantity_names()));
  target->weight = weight;
  target->field = field;
  if (frequency_cpmm != 0.0) target->frequency_cpmm = frequency_cpmm;
  if (orientation) target->orientation = *orientation;
  target->where =
      where.line > 0 ? fmt::format("{}:{}:{}", where.file, where.line, where.column) : where.file;
  validate_target(*target, where);
  return *target;
}

}  // namespace

bool apply_optimize_key(const std::string& key, const toml::node& node, const SourceLocation& where,
                        OptimizeOptions& options) {
  auto number = [&] {
    const auto v = node.value<double>();
    if (!v) throw Error(where, fmt::format("[optimize] {} must be a number", key));
    return *v;
  };
  auto integer = [&] {
    const auto v = node.value<int64_t>();
    if (!v) throw Error(where, fmt::format("[optimize] {} must be an integer", key));
    return static_cast<int>(*v);
  };
  auto text = [&] {
    const auto v = node.value<std::string>();
    if (!v) throw Error(where, fmt::format("[optimize] {} must be a string", key));
    return *v;
  };
  DesignLossOptions& loss = options.loss;
  if (key == "weight_ray_path")
    loss.weight_ray_path = number();
  else if (key == "weight_ray_angle")
    loss.weight_ray_angle = number();
  else if (key == "weight_glass")
    loss.weight_glass = number();
  else if (key == "min_air_mm")
    loss.min_air_mm = number();
  else if (key == "min_glass_mm")
    loss.min_glass_mm = number();
  else if (key == "max_glass_mm")
    loss.max_glass_mm = number();
  else if (key == "min_image_clearance_mm")
    loss.min_image_clearance_mm = number();
  else if (key == "min_virtual_image_mm")
    loss.min_virtual_image_mm = number();
  else if (key == "max_virtual_image_mm")
    loss.max_virtual_image_mm = number();
  else if (key == "max_ray_angle_deg")
    loss.max_ray_angle_deg = number();
  else if (key == "max_surface_slope_deg")
    loss.max_surface_slope_deg = number();
  else if (key == "weight_profile")
    loss.weight_profile = number();
  else if (key == "rings")
    options.sampling.rings = integer();
  else if (key == "fields")
    options.sampling.fields = integer();
  else if (key == "max_iterations")
    options.max_iterations = integer();
  else if (key == "max_rounds")
    options.max_rounds = integer();
  else if (key == "glass_neighbours")
    options.glass_neighbours = integer();
  else if (key == "glass_search")
    options.glass_search = parse_glass_search(text(), where);
  else if (key == "soft_start") {
    const auto v = node.value<bool>();
    if (!v) throw Error(where, "[optimize] soft_start must be true or false");
    options.soft_start = *v;
  } else if (key == "constraints") {
    const std::string v = text();
    if (v != "strict" && v != "paper")
      throw Error(where,
                  fmt::format("[optimize] constraints = '{}' must be \"strict\" or \"paper\"", v));
    loss.paper_penalties = v == "paper";
  } else if (key == "merit") {
    loss.merit = parse_merit(text(), where);
  } else if (key == "wavefront_pupil_samples") {
    loss.wavefront_pupil_samples = integer();
    if (loss.wavefront_pupil_samples < 4 || loss.wavefront_pupil_samples > 256)
      throw Error(where, fmt::format("[optimize] wavefront_pupil_samples = {} must be in [4, 256]",
                                     loss.wavefront_pupil_samples));
  } else if (key == "freeze") {
    const toml::array* items = node.as_array();
    if (!items) throw Error(where, "[optimize] freeze must be an array of variable names");
    options.freeze.clear();
    for (const auto& item : *items) {
      const auto v = item.value<std::string>();
      if (!v) throw Error(where, "[optimize] freeze entries must be strings");
      options.freeze.push_back(*v);
    }
  } else if (key == "targets") {
    const toml::array* items = node.as_array();
    if (!items)
      throw Error(where, "[optimize] targets must be an array of tables ([[optimize.targets]])");
    options.targets.clear();
    for (const auto& item : *items) {
      const toml::table* table = item.as_table();
      const SourceLocation at = location_of(item, where);
      if (!table)
        throw Error(at, "[optimize] targets entries must be tables ([[optimize.targets]])");
      options.targets.push_back(parse_target_table(*table, at));
    }
  } else if (key == "focus_only") {
    const auto v = node.value<bool>();
    if (!v) throw Error(where, "[optimize] focus_only must be true or false");
    options.focus_only = *v;
  } else if (key == "vary") {
    const toml::array* items = node.as_array();
    if (!items)
      throw Error(where,
                  "[optimize] vary must be an array of profile variables (\"k3\", \"a4_3\")");
    options.vary.clear();
    for (const auto& item : *items) {
      const auto v = item.value<std::string>();
      if (!v) throw Error(where, "[optimize] vary entries must be strings");
      options.vary.push_back(*v);
    }
  } else {
    return false;
  }
  return true;
}

}  // namespace lensopt

namespace lensopt {

void apply_optimize_table(const Lens& lens, OptimizeOptions& options) {
  // The source file gives exact line numbers; extra_toml (the tables after the lens) is the
  // fallback for a lens built in memory or parsed from text.
  std::string text, name;
  const std::filesystem::path path = lens.source_path;
  if (!lens.source_path.empty() && path.extension() == ".toml") {
    std::ifstream in(path, std::ios::binary);
    if (in) {
      std::ostringstream buffer;
      buffer << in.rdbuf();
      text = buffer.str();
      name = lens.source_path;
    }
  }
  if (name.empty()) {
    if (lens.extra_toml.empty()) return;
    text = lens.extra_toml;
    name = lens.source_path.empty() ? std::string("[optimize] table")
                                    : fmt::format("{} (tables after the lens)", lens.source_path);
  }
  toml::table file;
  try {
    file = toml::parse(text, name);
  } catch (const toml::parse_error& e) {
    throw Error(SourceLocation{name, static_cast<int>(e.source().begin.line),
                               static_cast<int>(e.source().begin.column)},
                std::string(e.description()));
  }
  const toml::table* table = file["optimize"].as_table();
  if (!table) return;
  for (const auto& [key, node] : *table) {
    const SourceLocation where{name, static_cast<int>(node.source().begin.line),
                               static_cast<int>(node.source().begin.column)};
    const std::string k(key.str());
    if (!apply_optimize_key(k, node, where, options))
      throw Error(where, fmt::format("unknown key '{}' in [optimize]; known: {}", k,
                                     optimize_table_keys()));
  }
}

ResolvedOptimizeOptions resolve_optimize_options(const Lens& lens,
                                                 const OptimizeOverrides& overrides) {
  ResolvedOptimizeOptions r;
  OptimizeOptions& o = r.options;
  // The targets: the table's, each replaced by the caller's of the same quantity and field.
  OptimizeOptions table_only;
  apply_optimize_table(lens, table_only);
  std::vector<DesignTarget> targets;
  for (const DesignTarget& t : table_only.targets) {
    bool replaced = false;
    for (const DesignTarget& u : overrides.targets) replaced = replaced || same_target(u, t);
    if (!replaced) targets.push_back(t);
  }
  for (const DesignTarget& t : overrides.targets) {
    validate_target(t, SourceLocation{t.where});
    targets.push_back(t);
  }
  // Bounds first (the paper's for the paper's lenses, else from the lens itself with its solved
  // targets applied: a start scaled to another focal length has other extremes), then the lens
  // file's [optimize] table, then the caller's values.
  o.loss = bounds_for(apply_target_solves(lens, targets_with_defaults(lens, targets)), o.loss,
                      overrides.bounds);
  r.paper_bounds = overrides.bounds == BoundsMode::kPaper ||
                   (overrides.bounds == BoundsMode::kAuto && is_paper_lens(lens));
  apply_optimize_table(lens, o);
  auto set = [](const auto& value, auto& target) {
    if (value) target = *value;
  };
  set(overrides.paper_penalties, o.loss.paper_penalties);
  set(overrides.merit, o.loss.merit);
  set(overrides.wavefront_pupil_samples, o.loss.wavefront_pupil_samples);
  set(overrides.glass_search, o.glass_search);
  for (const std::string& f : overrides.freeze) o.freeze.push_back(f);
  set(overrides.vary, o.vary);
  set(overrides.soft_start, o.soft_start);
  set(overrides.rings, o.sampling.rings);
  set(overrides.fields, o.sampling.fields);
  set(overrides.threads, o.sampling.threads);
  set(overrides.max_iterations, o.max_iterations);
  set(overrides.max_rounds, o.max_rounds);
  set(overrides.glass_neighbours, o.glass_neighbours);
  set(overrides.weight_ray_path, o.loss.weight_ray_path);
  set(overrides.weight_ray_angle, o.loss.weight_ray_angle);
  set(overrides.weight_glass, o.loss.weight_glass);
  set(overrides.min_air_mm, o.loss.min_air_mm);
  set(overrides.min_glass_mm, o.loss.min_glass_mm);
  set(overrides.max_glass_mm, o.loss.max_glass_mm);
  set(overrides.min_image_clearance_mm, o.loss.min_image_clearance_mm);
  set(overrides.max_ray_angle_deg, o.loss.max_ray_angle_deg);
  if (overrides.min_virtual_image_mm || overrides.max_virtual_image_mm) {
    // Bounds of a virtual image (a diverging lens, virtual_image.h): the derived ones are set
    // (bounds_for); a lens with a real image, or none, has no virtual image to bound.
    const std::string where = lens.source_path.empty() ? lens.name : lens.source_path;
    if (lens.specs.afocal || !o.loss.virtual_image())
      throw Error(SourceLocation{where},
                  lens.specs.afocal
                      ? std::string("min/max_virtual_image_mm: the lens is afocal (image at "
                                    "infinity); it has no virtual image to bound")
                      : fmt::format("min/max_virtual_image_mm: the lens forms a real image "
                                    "(EFL {:.6g} mm); the virtual-image bounds apply to a "
                                    "diverging lens (its image before the last surface); bound "
                                    "a real image with min_image_clearance_mm",
                                    design_focal_length_mm(lens)));
    set(overrides.min_virtual_image_mm, o.loss.min_virtual_image_mm);
    set(overrides.max_virtual_image_mm, o.loss.max_virtual_image_mm);
  }
  set(overrides.verbose, o.verbose);
  set(overrides.focus_only, o.focus_only);
  o.targets = targets;
  o.validate();
  return r;
}

}  // namespace lensopt
