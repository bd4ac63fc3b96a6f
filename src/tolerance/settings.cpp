// Tolerances, options and the [tolerance] table of a lens TOML.
#include <fmt/format.h>
#include <toml++/toml.h>

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <limits>
#include <sstream>

#include "lensopt/core/error.h"
#include "lensopt/tolerance/tolerance.h"

namespace lensopt {

std::string to_string(ToleranceDistribution distribution) {
  return distribution == ToleranceDistribution::kUniform ? "uniform" : "normal";
}

std::string to_string(FocusCompensator compensator) {
  switch (compensator) {
    case FocusCompensator::kParaxial:
      return "paraxial";
    case FocusCompensator::kBestRms:
      return "best-rms";
    case FocusCompensator::kNone:
      return "none";
  }
  return "?";
}

ToleranceDistribution parse_tolerance_distribution(const std::string& text) {
  if (text == "uniform") return ToleranceDistribution::kUniform;
  if (text == "normal") return ToleranceDistribution::kNormal;
  throw Error(
      fmt::format("unknown tolerance distribution '{}' (expected uniform or normal)", text));
}

FocusCompensator parse_focus_compensator(const std::string& text) {
  if (text == "paraxial") return FocusCompensator::kParaxial;
  if (text == "best-rms") return FocusCompensator::kBestRms;
  if (text == "none") return FocusCompensator::kNone;
  throw Error(fmt::format("unknown compensator '{}' (expected paraxial, best-rms or none)", text));
}

std::string to_string(SpotReference reference) {
  return reference == SpotReference::kCentroid ? "centroid" : "nominal";
}

SpotReference parse_spot_reference(const std::string& text) {
  if (text == "centroid") return SpotReference::kCentroid;
  if (text == "nominal") return SpotReference::kNominal;
  throw Error(fmt::format(
      "unknown spot reference '{}' (expected centroid: each field about its own centroid, or "
      "nominal: about the nominal lens's image point of the field)",
      text));
}

CompensatorList parse_compensators(const std::string& text) {
  CompensatorList out;
  const char* expected =
      "expected a comma-separated list of paraxial, best-rms or none (the focus), image-shift, "
      "decenter:element=K";
  std::size_t start = 0;
  bool any = false;
  while (start <= text.size()) {
    const std::size_t comma = std::min(text.find(',', start), text.size());
    std::string item = text.substr(start, comma - start);
    start = comma + 1;
    const std::size_t a = item.find_first_not_of(" \t");
    const std::size_t b = item.find_last_not_of(" \t");
    item = a == std::string::npos ? std::string() : item.substr(a, b - a + 1);
    if (item.empty())
      throw Error(fmt::format("compensator '{}': an empty item ({})", text, expected));
    any = true;
    if (item == "paraxial" || item == "best-rms" || item == "none") {
      if (out.focus)
        throw Error(fmt::format("compensator '{}': two focus compensators ({} and {})", text,
                                to_string(*out.focus), item));
      out.focus = parse_focus_compensator(item);
    } else if (item == "image-shift") {
      if (out.image_shift)
        throw Error(fmt::format("compensator '{}': image-shift given twice", text));
      out.image_shift = true;
    } else if (item.rfind("decenter:", 0) == 0) {
      const std::string spec = item.substr(9);
      const std::string key = "element=";
      if (spec.rfind(key, 0) != 0)
        throw Error(
            fmt::format("compensator '{}': '{}' must be decenter:element=K (K the group "
                        "of glasses, as in the rows tedx<K>)",
                        text, item));
      const std::string number = spec.substr(key.size());
      std::size_t used = 0;
      int k = 0;
      try {
        k = std::stoi(number, &used);
      } catch (const std::exception&) {
        used = 0;
      }
      if (used == 0 || used != number.size() || k < 1)
        throw Error(
            fmt::format("compensator '{}': element '{}' must be a group number >= 1 (as "
                        "in the rows tedx<K>)",
                        text, number));
      for (int e : out.decenter_elements)
        if (e == k)
          throw Error(fmt::format("compensator '{}': decenter:element={} given twice", text, k));
      out.decenter_elements.push_back(k);
    } else {
      throw Error(fmt::format("unknown compensator '{}' ({})", item, expected));
    }
  }
  if (!any) throw Error(fmt::format("compensator '{}': no compensator ({})", text, expected));
  return out;
}

void ToleranceOptions::apply(const CompensatorList& list) {
  if (list.focus) compensator = *list.focus;
  image_shift = list.image_shift;
  decenter_compensators = list.decenter_elements;
}

std::string ToleranceOptions::compensators_text() const {
  std::string out = fmt::format("{} focus", to_string(compensator));
  if (image_shift) out += ", image shift";
  for (int k : decenter_compensators) out += fmt::format(", decenter of group {}", k);
  return out;
}

const std::vector<std::string>& tolerance_names() {
  static const std::vector<std::string> names = {"curvature_pct",
                                                 "glass_thickness_mm",
                                                 "air_thickness_mm",
                                                 "nd",
                                                 "vd_pct",
                                                 "asphere_sag_um",
                                                 "decenter_mm",
                                                 "tilt_arcmin",
                                                 "surface_decenter_mm",
                                                 "surface_tilt_arcmin"};
  return names;
}

namespace {

void check_tolerance(const char* name, double value) {
  if (!std::isfinite(value))
    throw Error(fmt::format("tolerance {} = {} is not a finite number", name, value));
  if (value < 0)
    throw Error(
        fmt::format("tolerance {} = {} is negative (tolerances are +- limits, >= 0)", name, value));
}

}  // namespace

void Tolerances::validate() const {
  check_tolerance("curvature_pct", curvature_pct);
  check_tolerance("glass_thickness_mm", glass_thickness_mm);
  check_tolerance("air_thickness_mm", air_thickness_mm);
  check_tolerance("nd", nd);
  check_tolerance("vd_pct", vd_pct);
  check_tolerance("asphere_sag_um", asphere_sag_um);
  check_tolerance("decenter_mm", decenter_mm);
  check_tolerance("tilt_arcmin", tilt_arcmin);
  if (tilt_arcmin > 600)
    throw Error(
        fmt::format("tolerance tilt_arcmin = {} must be at most 600 (10 deg)", tilt_arcmin));
  check_tolerance("surface_decenter_mm", surface_decenter_mm);
  check_tolerance("surface_tilt_arcmin", surface_tilt_arcmin);
  if (surface_tilt_arcmin > 600)
    throw Error(fmt::format("tolerance surface_tilt_arcmin = {} must be at most 600 (10 deg)",
                            surface_tilt_arcmin));
  if (curvature_pct >= 100)
    throw Error(fmt::format("tolerance curvature_pct = {} must be below 100 %", curvature_pct));
  if (vd_pct >= 100) throw Error(fmt::format("tolerance vd_pct = {} must be below 100 %", vd_pct));
}

Tolerances Tolerances::times(double factor) const {
  return {curvature_pct * factor,
          glass_thickness_mm * factor,
          air_thickness_mm * factor,
          nd * factor,
          vd_pct * factor,
          asphere_sag_um * factor,
          decenter_mm * factor,
          tilt_arcmin * factor,
          surface_decenter_mm * factor,
          surface_tilt_arcmin * factor};
}

void ToleranceSettings::apply_to(Tolerances& t) const {
  if (curvature_pct) t.curvature_pct = *curvature_pct;
  if (glass_thickness_mm) t.glass_thickness_mm = *glass_thickness_mm;
  if (air_thickness_mm) t.air_thickness_mm = *air_thickness_mm;
  if (nd) t.nd = *nd;
  if (vd_pct) t.vd_pct = *vd_pct;
  if (asphere_sag_um) t.asphere_sag_um = *asphere_sag_um;
  if (decenter_mm) t.decenter_mm = *decenter_mm;
  if (tilt_arcmin) t.tilt_arcmin = *tilt_arcmin;
  if (surface_decenter_mm) t.surface_decenter_mm = *surface_decenter_mm;
  if (surface_tilt_arcmin) t.surface_tilt_arcmin = *surface_tilt_arcmin;
}

void ToleranceOptions::validate() const {
  tolerances.validate();
  if (trials < 1 || trials > 100000000)
    throw Error(fmt::format("trials = {} must be in [1, 100000000]", trials));
  if (jobs < 0) throw Error(fmt::format("jobs = {} must be >= 0", jobs));
  if (rings < 1 || rings > 256) throw Error(fmt::format("rings = {} must be in [1, 256]", rings));
  if (fields < 1 || fields > 1000)
    throw Error(fmt::format("fields = {} must be in [1, 1000]", fields));
  if (max_spot_um && !(std::isfinite(*max_spot_um) && *max_spot_um > 0))
    throw Error(fmt::format("max_spot_um = {} must be a positive number", *max_spot_um));
  if (inverse_drop_um && !(std::isfinite(*inverse_drop_um) && *inverse_drop_um > 0))
    throw Error(fmt::format("inverse_drop_um = {} must be a positive number (um of mean RMS spot)",
                            *inverse_drop_um));
  if (image_shift && spot_reference == SpotReference::kCentroid)
    throw Error(
        "the image-shift compensator changes nothing while each field's spot is taken about its "
        "own centroid (spot_reference = centroid): set spot_reference = nominal (--spot-reference "
        "nominal) to measure the spots on the detector, about the nominal image points");
  for (std::size_t i = 0; i < decenter_compensators.size(); ++i) {
    if (decenter_compensators[i] < 1)
      throw Error(fmt::format("compensator decenter:element={} must name a group >= 1",
                              decenter_compensators[i]));
    for (std::size_t j = 0; j < i; ++j)
      if (decenter_compensators[j] == decenter_compensators[i])
        throw Error(fmt::format("compensator decenter:element={} is given twice",
                                decenter_compensators[i]));
  }
}

ToleranceSettings parse_tolerance_table(std::string_view toml_text,
                                        const std::string& source_name) {
  toml::table doc;
  try {
    doc = toml::parse(toml_text, source_name);
  } catch (const toml::parse_error& e) {
    const auto& where = e.source().begin;
    throw Error(
        SourceLocation{source_name, static_cast<int>(where.line), static_cast<int>(where.column)},
        std::string(e.description()));
  }
  ToleranceSettings out;
  const toml::node* node = doc.get("tolerance");
  if (node == nullptr) return out;
  auto location = [&](const toml::source_region& region) {
    return SourceLocation{source_name, static_cast<int>(region.begin.line),
                          static_cast<int>(region.begin.column)};
  };
  const toml::table* table = node->as_table();
  if (table == nullptr) throw Error(location(node->source()), "[tolerance] must be a table");

  for (auto&& [key, node_value] : *table) {
    // A reference of its own: lambdas may not capture a structured binding before C++20's
    // P1091 (clang 14, used by tools/tsan-python.sh, refuses it).
    const toml::node& value = node_value;
    const std::string name(key.str());
    const SourceLocation where =
        location(key.source().begin.line > 0 ? key.source() : value.source());
    auto number = [&]() -> double {
      const std::optional<double> v = value.value<double>();
      if (!v || !(value.is_integer() || value.is_floating_point()))
        throw Error(where, fmt::format("[tolerance] {} must be a number", name));
      return *v;
    };
    auto tolerance = [&]() -> double {
      const double v = number();
      if (!std::isfinite(v))
        throw Error(where, fmt::format("[tolerance] {} = {} is not a finite number", name, v));
      if (v < 0)
        throw Error(where, fmt::format("[tolerance] {} = {} is negative (tolerances are +- "
                                       "limits, >= 0)",
                                       name, v));
      if ((name == "curvature_pct" || name == "vd_pct") && v >= 100)
        throw Error(where, fmt::format("[tolerance] {} = {} must be below 100 %", name, v));
      return v;
    };
    auto text = [&]() -> std::string {
      const std::optional<std::string> v = value.value<std::string>();
      if (!v) throw Error(where, fmt::format("[tolerance] {} must be a string", name));
      return *v;
    };
    auto integer = [&](std::int64_t lo, std::int64_t hi) -> std::int64_t {
      const std::optional<std::int64_t> v = value.value<std::int64_t>();
      if (!v || !value.is_integer())
        throw Error(where, fmt::format("[tolerance] {} must be an integer", name));
      if (*v < lo || *v > hi)
        throw Error(where,
                    fmt::format("[tolerance] {} = {} must be in [{}, {}]", name, *v, lo, hi));
      return *v;
    };
    try {
      if (name == "curvature_pct") {
        out.curvature_pct = tolerance();
      } else if (name == "glass_thickness_mm") {
        out.glass_thickness_mm = tolerance();
      } else if (name == "air_thickness_mm") {
        out.air_thickness_mm = tolerance();
      } else if (name == "nd") {
        out.nd = tolerance();
      } else if (name == "vd_pct") {
        out.vd_pct = tolerance();
      } else if (name == "asphere_sag_um") {
        out.asphere_sag_um = tolerance();
      } else if (name == "decenter_mm") {
        out.decenter_mm = tolerance();
      } else if (name == "tilt_arcmin") {
        out.tilt_arcmin = tolerance();
      } else if (name == "surface_decenter_mm") {
        out.surface_decenter_mm = tolerance();
      } else if (name == "surface_tilt_arcmin") {
        out.surface_tilt_arcmin = tolerance();
      } else if (name == "inverse_drop_um") {
        const double v = number();
        if (!(std::isfinite(v) && v > 0))
          throw Error(where, fmt::format("[tolerance] inverse_drop_um = {} must be positive", v));
        out.inverse_drop_um = v;
      } else if (name == "distribution") {
        out.distribution = parse_tolerance_distribution(text());
      } else if (name == "compensator") {
        // A string ("best-rms", "best-rms, decenter:element=2") or an array of such strings.
        if (const toml::array* items = value.as_array()) {
          std::string joined;
          for (const toml::node& item : *items) {
            const std::optional<std::string> v = item.value<std::string>();
            if (!v)
              throw Error(where, "[tolerance] compensator must be a string or an array of strings");
            joined += (joined.empty() ? "" : ",") + *v;
          }
          out.compensators = parse_compensators(joined);
        } else {
          out.compensators = parse_compensators(text());
        }
        if (out.compensators->focus) out.compensator = out.compensators->focus;
      } else if (name == "spot_reference") {
        out.spot_reference = parse_spot_reference(text());
      } else if (name == "max_spot_um") {
        const double v = number();
        if (!(std::isfinite(v) && v > 0))
          throw Error(where, fmt::format("[tolerance] max_spot_um = {} must be positive", v));
        out.max_spot_um = v;
      } else if (name == "trials") {
        out.trials = static_cast<int>(integer(1, 100000000));
      } else if (name == "seed") {
        out.seed = static_cast<std::uint64_t>(integer(0, std::numeric_limits<std::int64_t>::max()));
      } else {
        throw Error(where,
                    fmt::format("unknown key '{}' in [tolerance] (known: curvature_pct, "
                                "glass_thickness_mm, air_thickness_mm, nd, vd_pct, asphere_sag_um, "
                                "decenter_mm, tilt_arcmin, surface_decenter_mm, "
                                "surface_tilt_arcmin, inverse_drop_um, "
                                "distribution, compensator, spot_reference, max_spot_um, trials, "
                                "seed)",
                                name));
      }
    } catch (const Error& e) {
      if (e.where().line > 0) throw;
      throw Error(where, fmt::format("[tolerance] {}: {}", name, e.message()));
    }
  }
  return out;
}

ToleranceSettings tolerance_settings_of(const Lens& lens) {
  // The source file gives exact line numbers; extra_toml is the fallback (e.g. a lens built in
  // memory, or a source file that moved).
  const std::filesystem::path path = lens.source_path;
  if (!lens.source_path.empty() && path.extension() == ".toml") {
    std::ifstream in(path, std::ios::binary);
    if (in) {
      std::ostringstream text;
      text << in.rdbuf();
      return parse_tolerance_table(text.str(), lens.source_path);
    }
  }
  if (lens.extra_toml.empty()) return {};
  const std::string name = lens.source_path.empty()
                               ? std::string("[tolerance] table")
                               : fmt::format("{} (tables after the lens)", lens.source_path);
  return parse_tolerance_table(lens.extra_toml, name);
}

ToleranceOptions tolerance_options_for(const Lens& lens) {
  const ToleranceSettings table = tolerance_settings_of(lens);
  ToleranceOptions options;
  table.apply_to(options.tolerances);
  if (table.distribution) options.distribution = *table.distribution;
  if (table.compensators) options.apply(*table.compensators);
  if (table.spot_reference) options.spot_reference = *table.spot_reference;
  options.max_spot_um = table.max_spot_um;
  if (table.inverse_drop_um) options.inverse_drop_um = table.inverse_drop_um;
  if (table.trials) options.trials = *table.trials;
  if (table.seed) options.seed = *table.seed;
  return options;
}

}  // namespace lensopt
