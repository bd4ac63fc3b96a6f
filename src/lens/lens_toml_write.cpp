// Native TOML lens files: the writer (format_lens_toml, write_lens_toml); the reader is
// lens_toml.cpp.
//
// Exact numbers. Every double is written with fmt "{}", the shortest decimal that reads back to
// the same double, and toml++ reads decimals correctly rounded, so thicknesses, indices and specs
// survive format -> parse bit for bit. A curvature c written as a radius R needs fl(1 / R) == c,
// and R = fl(1 / c) does not always give that: fl(1 / fl(1 / c)) differs from c for some c. So the
// writer looks at the doubles within a few ulps of fl(1 / c), keeps those R with fl(1 / R) == c
// and writes the one with the shortest decimal (a radius the file gave, such as 9.1, is found
// again). When no R exists (the doubles near 1/c are spaced more coarsely, relative to their size,
// than those near c, so some c are no reciprocal of any double) it writes curvature_per_mm.
// Either way parse(format(l)) has l's doubles, and format(parse(format(l))) == format(l).
#include <fmt/format.h>
#include <toml++/toml.h>

#include <algorithm>
#include <cctype>
#include <cmath>
#include <limits>
#include <optional>
#include <sstream>
#include <string>
#include <vector>

#include "lens_toml_detail.h"
#include "lensopt/core/atomic_file.h"
#include "lensopt/core/error.h"
#include "lensopt/glass/glass.h"
#include "lensopt/lens/lens_io.h"

namespace lensopt {
namespace {

using detail::kApertureNames;
using detail::kChannelLetters;
using detail::kFieldTypeNames;

// Ulps either side of fl(1/c) searched for a radius R with fl(1/R) == c. The exact 1/c is within
// 1/2 ulp of fl(1/c), and any such R within about 1 ulp of the exact 1/c.
constexpr int kRadiusSearchUlps = 4;

// The shortest decimal that reads back as x, always with a '.' or an exponent so TOML reads a
// float ("3.0", not "3"); "inf", "-inf", "nan" as TOML spells them.
std::string number_text(double x) {
  std::string text = fmt::format("{}", x);
  if (text.find_first_of(".eEn") == std::string::npos) text += ".0";
  return text;
}

// A radius R with fl(1 / R) == c, the one with the shortest decimal near fl(1 / c); +-inf for a
// flat surface (the sign of a zero curvature kept); nullopt when no double R has fl(1/R) == c.
std::optional<double> exact_radius_mm(double curvature_per_mm) {
  const double inf = std::numeric_limits<double>::infinity();
  if (curvature_per_mm == 0.0) return std::signbit(curvature_per_mm) ? -inf : inf;
  const double nearest = 1.0 / curvature_per_mm;
  if (!std::isfinite(nearest)) return std::nullopt;
  std::optional<double> best;
  std::size_t best_length = 0;
  double radius_mm = nearest;
  for (int i = 0; i < kRadiusSearchUlps; ++i) radius_mm = std::nextafter(radius_mm, -inf);
  for (int i = 0; i <= 2 * kRadiusSearchUlps; ++i, radius_mm = std::nextafter(radius_mm, inf)) {
    if (1.0 / radius_mm != curvature_per_mm) continue;
    const std::size_t length = fmt::formatted_size("{}", radius_mm);
    if (!best || length < best_length ||
        (length == best_length && std::abs(radius_mm - nearest) < std::abs(*best - nearest))) {
      best = radius_mm;
      best_length = length;
    }
  }
  return best;
}

// A TOML basic string: quotes, backslashes and control characters escaped.
std::string toml_string(std::string_view text) {
  std::string out = "\"";
  for (const char ch : text) {
    const auto byte = static_cast<unsigned char>(ch);
    if (ch == '"' || ch == '\\') {
      out += '\\';
      out += ch;
    } else if (ch == '\n') {
      out += "\\n";
    } else if (ch == '\t') {
      out += "\\t";
    } else if (byte < 0x20 || byte == 0x7f) {
      out += fmt::format("\\u{:04X}", static_cast<unsigned>(byte));
    } else {
      out += ch;
    }
  }
  out += '"';
  return out;
}

// TOML text of the tables a lens file carries for other modules ([optimize], ...), from toml++'s
// parsed tree. toml++'s own formatter writes floats with 17 significant digits (0.1 becomes
// 0.10000000000000001); this writes them as the shortest exact decimal, like the lens itself.
// Keys come in toml++'s (sorted) order; inline tables stay inline; dates print as toml++ does.
class ExtraTomlWriter {
 public:
  std::string write(const toml::table& root) {
    out_.clear();
    write_table_body(root, "", false);
    return out_;
  }

 private:
  static std::string key_text(std::string_view key) {
    const bool bare = !key.empty() && std::all_of(key.begin(), key.end(), [](char ch) {
      return std::isalnum(static_cast<unsigned char>(ch)) || ch == '_' || ch == '-';
    });
    return bare ? std::string(key) : toml_string(key);
  }

  // A table written under a [header] rather than inline.
  static bool is_header_table(const toml::node& node) {
    const toml::table* table = node.as_table();
    return table != nullptr && !table->is_inline();
  }
  static bool is_header_array(const toml::node& node) {
    return node.is_array_of_tables() &&
           std::all_of(node.as_array()->begin(), node.as_array()->end(),
                       [](const toml::node& item) { return is_header_table(item); });
  }

  void write_value(const toml::node& node) {
    if (const auto* v = node.as_floating_point()) {
      out_ += number_text(v->get());
    } else if (const auto* v = node.as_integer()) {
      out_ += fmt::format("{}", v->get());
    } else if (const auto* v = node.as_string()) {
      out_ += toml_string(v->get());
    } else if (const auto* v = node.as_boolean()) {
      out_ += v->get() ? "true" : "false";
    } else if (const auto* array = node.as_array()) {
      out_ += '[';
      for (std::size_t i = 0; i < array->size(); ++i) {
        if (i > 0) out_ += ", ";
        write_value((*array)[i]);
      }
      out_ += ']';
    } else if (const auto* table = node.as_table()) {
      out_ += '{';
      bool first = true;
      for (auto&& [key, value] : *table) {
        out_ += first ? " " : ", ";
        first = false;
        out_ += key_text(key.str()) + " = ";
        write_value(value);
      }
      out_ += first ? "}" : " }";
    } else {
      // Date, time, date-time: toml++ prints them as TOML spells them.
      std::ostringstream text;
      if (const auto* v = node.as_date()) text << *v;
      if (const auto* v = node.as_time()) text << *v;
      if (const auto* v = node.as_date_time()) text << *v;
      out_ += text.str();
    }
  }

  // The key/values of `table` (under `path`; "" is the root, where everything is a table or an
  // array of tables, written under headers so nothing attaches to the lens's last table), then
  // its sub-tables and arrays of tables.
  void write_table_body(const toml::table& table, const std::string& path, bool array_element) {
    const bool root = path.empty();
    auto is_child_table = [root](const toml::node& node) {
      return node.is_table() && (root || is_header_table(node));
    };
    auto is_child_array = [root](const toml::node& node) {
      return node.is_array_of_tables() && (root || is_header_array(node));
    };
    bool has_values = false;
    bool has_children = false;
    for (auto&& [key, value] : table) {
      const bool child = is_child_table(value) || is_child_array(value);
      has_children = has_children || child;
      has_values = has_values || !child;
    }
    if (!root && (array_element || has_values || !has_children)) {
      if (!out_.empty()) out_ += '\n';
      out_ += array_element ? fmt::format("[[{}]]\n", path) : fmt::format("[{}]\n", path);
    }
    for (auto&& [key, value] : table) {
      if (is_child_table(value) || is_child_array(value)) continue;
      out_ += key_text(key.str()) + " = ";
      write_value(value);
      out_ += '\n';
    }
    for (auto&& [key, value] : table) {
      const std::string child_path = root ? key_text(key.str()) : path + "." + key_text(key.str());
      if (is_child_table(value)) {
        write_table_body(*value.as_table(), child_path, false);
      } else if (is_child_array(value)) {
        for (const toml::node& item : *value.as_array())
          write_table_body(*item.as_table(), child_path, true);
      }
    }
  }

  std::string out_;
};
}  // namespace

namespace detail {

std::string format_extra_toml(const toml::table& root) {
  return ExtraTomlWriter().write(root);
}

}  // namespace detail

std::string format_lens_toml(const Lens& lens) {
  std::string out;
  auto line = [&out](std::string_view key, const std::string& value) {
    out += fmt::format("{} = {}\n", key, value);
  };

  out += "[lens]\n";
  if (!lens.name.empty()) line("name", toml_string(lens.name));
  if (!lens.catalog_name.empty()) line("catalog", toml_string(lens.catalog_name));

  const Specs& specs = lens.specs;
  out += "\n[specs]\n";
  line("f_number", number_text(specs.f_number));
  line("half_field_deg", number_text(specs.half_field_deg));
  line("sensor_diagonal_mm", number_text(specs.sensor_diagonal_mm));
  if (specs.wavelengths_nm == paper_wavelengths_nm() &&
      specs.wavelength_channels == paper_wavelength_channels()) {
    out += "# wavelengths: the paper's 15 (R, G, B, five each)\n";
  } else {
    std::vector<std::string> wavelengths;
    for (double w : specs.wavelengths_nm) wavelengths.push_back(number_text(w));
    std::vector<std::string> channels;
    for (int channel : specs.wavelength_channels) {
      if (channel < 0 || channel >= static_cast<int>(kChannelLetters.size()))
        throw Error(fmt::format("lens '{}': wavelength channel {} is not R (0), G (1) or B (2)",
                                lens.name, channel));
      channels.push_back(fmt::format("\"{}\"", kChannelLetters[channel]));
    }
    line("wavelengths_nm", fmt::format("[{}]", fmt::join(wavelengths, ", ")));
    line("channels", fmt::format("[{}]", fmt::join(channels, ", ")));
  }
  line("dispersion", specs.dispersion == DispersionModel::kCatalog ? "\"catalog\"" : "\"abbe\"");

  // [system]: written for a lens traced as written, or with system data beyond the paper's.
  const bool default_system =
      specs.mode == SpecMode::kPaper && specs.primary_wavelength_nm == kWavelengthD_nm &&
      specs.wavelength_weights.empty() && specs.fields.empty() && specs.object_at_infinity();
  if (!default_system) {
    out += "\n[system]\n";
    line("mode", specs.mode == SpecMode::kPaper ? "\"paper\"" : "\"as-written\"");
    if (specs.afocal) line("afocal", "true");
    line("primary_wavelength_nm", number_text(specs.primary_wavelength_nm));
    auto list = [](const std::vector<double>& v) {
      std::vector<std::string> t;
      for (double x : v) t.push_back(number_text(x));
      return fmt::format("[{}]", fmt::join(t, ", "));
    };
    if (!specs.wavelength_weights.empty())
      line("wavelength_weights", list(specs.wavelength_weights));
    line("aperture", fmt::format("\"{}\"", kApertureNames[static_cast<int>(specs.aperture_type)]));
    if (specs.aperture_type == ApertureType::kEntrancePupilDiameter ||
        specs.aperture_type == ApertureType::kObjectNA)
      line("aperture_value", number_text(specs.aperture_value));
    if (!specs.object_at_infinity())
      line("object_distance_mm", number_text(specs.object_distance_mm));
    if (!specs.fields.empty()) {
      line("field_type",
           fmt::format("\"{}\"", kFieldTypeNames[static_cast<int>(specs.field_type)]));
      std::vector<double> values, xs, weights, vdx, vdy, vcx, vcy, van;
      bool weighted = false, vignetted = false, asymmetric = false, off_y = false;
      for (const FieldPoint& f : specs.fields) {
        values.push_back(f.value);
        xs.push_back(f.x);
        off_y = off_y || f.x != 0.0;
        weights.push_back(f.weight);
        vdx.push_back(f.vignetting.vdx);
        vdy.push_back(f.vignetting.vdy);
        vcx.push_back(f.vignetting.vcx);
        vcy.push_back(f.vignetting.vcy);
        van.push_back(f.vignetting.van_deg);
        weighted = weighted || f.weight != 1.0;
        vignetted = vignetted || f.vignetting.any();
        asymmetric = asymmetric || f.vignetting.asymmetric();
      }
      line("fields", list(values));
      if (off_y) line("fields_x", list(xs));
      if (weighted) line("field_weights", list(weights));
      if (vignetted) {
        if (asymmetric) line("vdx", list(vdx));
        line("vdy", list(vdy));
        line("vcx", list(vcx));
        line("vcy", list(vcy));
        if (asymmetric) line("van_deg", list(van));
      }
    }
  }

  // Whether a glass is the one the lens's catalog gives for its name (the same figures).
  std::shared_ptr<const Catalog> lens_catalog;
  if (!lens.catalog_name.empty()) {
    try {
      lens_catalog = load_catalog(lens.catalog_name);
    } catch (const Error&) {
      lens_catalog = nullptr;
    }
  }
  auto in_lens_catalog = [&](const Glass& glass) {
    const Glass* found = lens_catalog ? lens_catalog->find(glass.name) : nullptr;
    return found != nullptr && found->catalog == glass.catalog && found->nd == glass.nd &&
           found->vd == glass.vd && found->coefficients == glass.coefficients;
  };
  auto placement_text = [&](const Surface& s) {
    const Placement& p = s.placement;
    std::vector<std::string> items;
    auto item = [&](const char* key, double v) {
      if (v != 0.0) items.push_back(fmt::format("{} = {}", key, number_text(v)));
    };
    item("decenter_x_mm", p.decenter_x_mm);
    item("decenter_y_mm", p.decenter_y_mm);
    item("tilt_x_deg", p.tilt_x_deg);
    item("tilt_y_deg", p.tilt_y_deg);
    item("tilt_z_deg", p.tilt_z_deg);
    if (p.tilt_first) items.push_back("order = \"tilt-first\"");
    if (s.restore_frame) items.push_back("restore_frame = true");
    return items.empty() ? std::string("{}") : fmt::format("{{ {} }}", fmt::join(items, ", "));
  };
  for (const Surface& surface : lens.surfaces) {
    out += "\n[[surfaces]]\n";
    if (surface.coordinate_break) {
      line("coordinate_break", placement_text(surface));
      line("thickness_mm", number_text(surface.thickness_mm));
      continue;
    }
    if (surface.placement.any() || surface.restore_frame)
      line("decenter_tilt", placement_text(surface));
    const std::optional<double> radius_mm =
        surface.written_as_radius ? exact_radius_mm(surface.curvature_per_mm) : std::nullopt;
    if (radius_mm) {
      line("radius_mm", number_text(*radius_mm));
    } else {
      line("curvature_per_mm", number_text(surface.curvature_per_mm));
    }
    line("thickness_mm", number_text(surface.thickness_mm));
    if (surface.mirror) {
      line("material", "\"mirror\"");
    } else
      switch (surface.material.kind) {
        case Material::Kind::kAir:
          break;
        case Material::Kind::kCatalog:
          // A glass of another catalog than the lens's names its catalog.
          if (surface.material.glass && !in_lens_catalog(*surface.material.glass)) {
            line("material", fmt::format("{{ glass = {}, catalog = {} }}",
                                         toml_string(surface.material.glass_name),
                                         toml_string(surface.material.glass->catalog)));
          } else {
            line("material", toml_string(surface.material.glass_name));
          }
          break;
        case Material::Kind::kModel:
          if (surface.material.model_glass == ModelGlass::kZemax) {
            line("material",
                 fmt::format("{{ nd = {}, vd = {}, model = \"opticstudio\"{} }}",
                             number_text(surface.material.nd), number_text(surface.material.vd),
                             surface.material.dpgf == 0.0
                                 ? std::string()
                                 : fmt::format(", dpgf = {}", number_text(surface.material.dpgf))));
          } else {
            line("material", fmt::format("{{ nd = {}, vd = {} }}", number_text(surface.material.nd),
                                         number_text(surface.material.vd)));
          }
          break;
      }
    if (surface.is_stop) line("stop", "true");
    if (surface.semi_diameter_mm != 0.0)
      line("semi_diameter_mm", number_text(surface.semi_diameter_mm));
    if (surface.obscuration_mm != 0.0) line("obscuration_mm", number_text(surface.obscuration_mm));
    if (surface.aperture_decenter_x_mm != 0.0 || surface.aperture_decenter_y_mm != 0.0)
      line("aperture_decenter_mm",
           fmt::format("[{}, {}]", number_text(surface.aperture_decenter_x_mm),
                       number_text(surface.aperture_decenter_y_mm)));
    if (surface.conic != 0.0) line("conic", number_text(surface.conic));
    if (surface.asphere_r2_per_mm != 0.0)
      line("asphere_r2", number_text(surface.asphere_r2_per_mm));
    int terms = kAsphereOrders;
    while (terms > 0 && surface.asphere[terms - 1] == 0.0) --terms;
    if (terms > 0) {
      std::vector<std::string> values;
      for (int j = 0; j < terms; ++j) values.push_back(number_text(surface.asphere[j]));
      line("asphere", fmt::format("[{}]", fmt::join(values, ", ")));
    }
    // Solves and variables (lens.h), 1-based surfaces.
    if (surface.vary.any()) {
      std::vector<std::string> names;
      if (surface.vary.radius) names.emplace_back("\"radius\"");
      if (surface.vary.thickness) names.emplace_back("\"thickness\"");
      if (surface.vary.conic) names.emplace_back("\"conic\"");
      if (surface.vary.glass) names.emplace_back("\"glass\"");
      line("vary", fmt::format("[{}]", fmt::join(names, ", ")));
    }
    if (surface.curvature_pickup.active())
      line("pickup_curvature",
           fmt::format("{{ surface = {}, scale = {} }}", surface.curvature_pickup.source + 1,
                       number_text(surface.curvature_pickup.scale)));
    if (surface.thickness_pickup.active())
      line("pickup_thickness", fmt::format("{{ surface = {}, scale = {}, offset_mm = {} }}",
                                           surface.thickness_pickup.source + 1,
                                           number_text(surface.thickness_pickup.scale),
                                           number_text(surface.thickness_pickup.offset_mm)));
    if (surface.thickness_solve.kind == ThicknessSolve::Kind::kMarginalHeight)
      line("solve", fmt::format("{{ thickness = \"marginal_height\", height_mm = {} }}",
                                number_text(surface.thickness_solve.height_mm)));
  }

  if (!lens.extra_toml.empty()) {
    out += "\n";
    out += lens.extra_toml;
    if (out.back() != '\n') out += '\n';
  }
  return out;
}

void write_lens_toml(const Lens& lens, const std::filesystem::path& path) {
  write_file_atomic(path, format_lens_toml(lens));
}
}  // namespace lensopt
