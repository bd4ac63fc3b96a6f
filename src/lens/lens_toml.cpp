// Native TOML lens files (toml++): the reader. The writer is lens_toml_write.cpp; reading and
// writing by extension is formats/lens_file.h.
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
#include <array>
#include <cctype>
#include <cmath>
#include <limits>
#include <optional>
#include <sstream>
#include <vector>

#include "lens_io_detail.h"
#include "lens_toml_detail.h"
#include "lensopt/core/atomic_file.h"
#include "lensopt/core/error.h"
#include "lensopt/core/text.h"
#include "lensopt/glass/glass.h"
#include "lensopt/lens/input_limits.h"
#include "lensopt/lens/lens_io.h"
#include "lensopt/lens/validate.h"

static_assert(TOML_EXCEPTIONS, "lens_toml.cpp expects toml++ to report errors by exception");

namespace lensopt {

namespace detail {

std::string closest_key(std::string_view key, std::span<const std::string_view> known_keys) {
  std::string best;
  std::size_t best_distance = std::numeric_limits<std::size_t>::max();
  for (std::string_view known : known_keys) {
    const std::size_t d = edit_distance(key, known);
    if (d < best_distance && (d <= 2 || 3 * d <= known.size())) {
      best = known;
      best_distance = d;
    }
  }
  return best;
}

std::string did_you_mean(std::string_view key, std::span<const std::string_view> known_keys) {
  const std::string best = closest_key(key, known_keys);
  return best.empty() ? std::string() : fmt::format(" (did you mean '{}'?)", best);
}

}  // namespace detail

namespace {

using detail::kApertureNames;
using detail::kChannelLetters;
using detail::kFieldTypeNames;

constexpr std::array<std::string_view, 4> kTopLevelKeys = {"lens", "specs", "system", "surfaces"};
constexpr std::array<std::string_view, 16> kSystemKeys = {"mode",
                                                          "afocal",
                                                          "primary_wavelength_nm",
                                                          "wavelength_weights",
                                                          "aperture",
                                                          "aperture_value",
                                                          "field_type",
                                                          "fields",
                                                          "fields_x",
                                                          "field_weights",
                                                          "vdx",
                                                          "vdy",
                                                          "vcx",
                                                          "vcy",
                                                          "van_deg",
                                                          "object_distance_mm"};
constexpr std::array<std::string_view, 2> kLensKeys = {"name", "catalog"};
constexpr std::array<std::string_view, 6> kSpecsKeys = {
    "f_number", "half_field_deg", "sensor_diagonal_mm", "wavelengths_nm", "channels", "dispersion"};
constexpr std::array<std::string_view, 17> kSurfaceKeys = {"radius_mm",
                                                           "curvature_per_mm",
                                                           "thickness_mm",
                                                           "material",
                                                           "stop",
                                                           "semi_diameter_mm",
                                                           "conic",
                                                           "asphere",
                                                           "asphere_r2",
                                                           "coordinate_break",
                                                           "decenter_tilt",
                                                           "obscuration_mm",
                                                           "aperture_decenter_mm",
                                                           "vary",
                                                           "pickup_curvature",
                                                           "pickup_thickness",
                                                           "solve"};
// Solves and variables of a surface (lens.h VaryFlags, Pickup, ThicknessSolve).
constexpr std::array<std::string_view, 4> kVaryNames = {"radius", "thickness", "conic", "glass"};
constexpr std::array<std::string_view, 3> kPickupKeys = {"surface", "scale", "offset_mm"};
constexpr std::array<std::string_view, 2> kSolveKeys = {"thickness", "height_mm"};
// A coordinate_break or decenter_tilt table (lens.h Placement).
constexpr std::array<std::string_view, 7> kPlacementKeys = {
    "decenter_x_mm", "decenter_y_mm", "tilt_x_deg",   "tilt_y_deg",
    "tilt_z_deg",    "order",         "restore_frame"};
constexpr std::array<std::string_view, 4> kModelGlassKeys = {"nd", "vd", "model", "dpgf"};
constexpr std::array<std::string_view, 2> kCatalogGlassKeys = {"glass", "catalog"};

std::string_view type_phrase(const toml::node& node) {
  switch (node.type()) {
    case toml::node_type::table:
      return "a table";
    case toml::node_type::array:
      return "an array";
    case toml::node_type::string:
      return "a string";
    case toml::node_type::integer:
      return "an integer";
    case toml::node_type::floating_point:
      return "a floating-point number";
    case toml::node_type::boolean:
      return "a boolean";
    case toml::node_type::date:
    case toml::node_type::time:
    case toml::node_type::date_time:
      return "a date/time";
    default:
      return "nothing";
  }
}

// A key of a table with its value, both with source positions.
struct Entry {
  const toml::key* key = nullptr;
  const toml::node* node = nullptr;
  explicit operator bool() const { return node != nullptr; }
};

Entry entry(const toml::table& table, std::string_view name) {
  const auto it = table.find(name);
  if (it == table.end()) return {};
  return {&it->first, &it->second};
}

// Turns toml++ nodes into lens values, throwing Error at the node's file:line:column.
class TomlReader {
 public:
  explicit TomlReader(std::string file) : file_(std::move(file)) {}

  SourceLocation at(const toml::source_region& region) const {
    return {file_, static_cast<int>(region.begin.line), static_cast<int>(region.begin.column)};
  }
  [[noreturn]] void fail(const toml::source_region& region, const std::string& message) const {
    throw Error(at(region), message);
  }
  [[noreturn]] void fail(const toml::node& node, const std::string& message) const {
    fail(node.source(), message);
  }
  [[noreturn]] void fail(const Entry& e, const std::string& message) const {
    fail(e.key->source(), message);
  }
  [[noreturn]] void fail_file(const std::string& message) const {
    throw Error(SourceLocation{file_}, message);
  }

  // Every key of `table` must be one of `known`; `where` names the table ("[specs]").
  void check_keys(const toml::table& table, std::span<const std::string_view> known,
                  std::string_view where) const {
    for (auto&& [key, node] : table) {
      if (std::find(known.begin(), known.end(), key.str()) != known.end()) continue;
      fail(key.source(), fmt::format("unknown key '{}' in {}{}", key.str(), where,
                                     detail::did_you_mean(key.str(), known)));
    }
  }

  double number(const toml::node& node, std::string_view what) const {
    if (const auto* v = node.as_floating_point()) return v->get();
    if (const auto* v = node.as_integer()) return static_cast<double>(v->get());
    fail(node, fmt::format("{} must be a number, not {}", what, type_phrase(node)));
  }

  double finite_number(const toml::node& node, std::string_view what) const {
    const double x = number(node, what);
    if (!std::isfinite(x)) fail(node, fmt::format("{} = {} must be finite", what, x));
    return x;
  }

  std::string string(const toml::node& node, std::string_view what) const {
    if (const auto* v = node.as_string()) return v->get();
    fail(node, fmt::format("{} must be a string, not {}", what, type_phrase(node)));
  }

  bool boolean(const toml::node& node, std::string_view what) const {
    if (const auto* v = node.as_boolean()) return v->get();
    fail(node, fmt::format("{} must be true or false, not {}", what, type_phrase(node)));
  }

  const toml::table& table(const toml::node& node, std::string_view what) const {
    if (const auto* t = node.as_table()) return *t;
    fail(node, fmt::format("{} must be a table, not {}", what, type_phrase(node)));
  }

  const toml::array& array(const toml::node& node, std::string_view what) const {
    if (const auto* a = node.as_array()) return *a;
    fail(node, fmt::format("{} must be an array, not {}", what, type_phrase(node)));
  }

  const std::string& file() const { return file_; }

 private:
  std::string file_;
};

// A radius value: a number (not 0), TOML's inf, or the strings "inf" / "infinity" (any case,
// optionally signed), all meaning a flat surface.
double read_radius_mm(const TomlReader& reader, const toml::node& node, std::string_view what) {
  if (const auto* s = node.as_string()) {
    std::string text = to_lower(s->get());
    double sign = 1.0;
    if (!text.empty() && (text.front() == '+' || text.front() == '-')) {
      sign = text.front() == '-' ? -1.0 : 1.0;
      text.erase(0, 1);
    }
    if (text == "inf" || text == "infinity") return sign * std::numeric_limits<double>::infinity();
    reader.fail(node,
                fmt::format("{} must be a number or \"inf\" (flat), not \"{}\"", what, s->get()));
  }
  const double radius_mm = reader.number(node, what);
  if (std::isnan(radius_mm)) reader.fail(node, fmt::format("{} is nan", what));
  if (radius_mm == 0.0)
    reader.fail(node, fmt::format("{} = 0 is not a surface; write {} = inf for a flat surface",
                                  what, what));
  if (!std::isfinite(1.0 / radius_mm))
    reader.fail(node, fmt::format("{} = {} is too small", what, radius_mm));
  return radius_mm;
}

Specs read_specs(const TomlReader& reader, const toml::table& table) {
  reader.check_keys(table, kSpecsKeys, "[specs]");
  Specs specs;
  if (const Entry e = entry(table, "f_number")) {
    specs.f_number = reader.finite_number(*e.node, "f_number");
    if (!(specs.f_number > 0.0))
      reader.fail(*e.node, fmt::format("f_number = {} must be > 0", specs.f_number));
  }
  if (const Entry e = entry(table, "half_field_deg")) {
    specs.half_field_deg = reader.finite_number(*e.node, "half_field_deg");
    if (!(specs.half_field_deg >= 0.0 && specs.half_field_deg < 89.0))
      reader.fail(*e.node,
                  fmt::format("half_field_deg = {} must be in [0, 89)", specs.half_field_deg));
  }
  if (const Entry e = entry(table, "sensor_diagonal_mm")) {
    specs.sensor_diagonal_mm = reader.finite_number(*e.node, "sensor_diagonal_mm");
    if (!(specs.sensor_diagonal_mm > 0.0))
      reader.fail(*e.node,
                  fmt::format("sensor_diagonal_mm = {} must be > 0", specs.sensor_diagonal_mm));
  }
  const Entry wavelengths = entry(table, "wavelengths_nm");
  const Entry channels = entry(table, "channels");
  if (channels && !wavelengths) reader.fail(channels, "channels is given without wavelengths_nm");
  if (wavelengths) {
    const toml::array& values = reader.array(*wavelengths.node, "wavelengths_nm");
    if (values.empty()) reader.fail(*wavelengths.node, "wavelengths_nm is empty");
    if (values.size() > kMaxWavelengths)
      reader.fail(values[kMaxWavelengths],
                  fmt::format("wavelengths_nm has {} wavelengths; lensopt reads at most {}",
                              values.size(), kMaxWavelengths));
    specs.wavelengths_nm.clear();
    for (const toml::node& value : values) {
      const double w = reader.finite_number(value, "a wavelength in wavelengths_nm");
      if (!(w > 200.0 && w < 20000.0))
        reader.fail(value, fmt::format("wavelength {} nm is out of range (200, 20000)", w));
      specs.wavelengths_nm.push_back(w);
    }
    specs.wavelength_channels = default_wavelength_channels(specs.wavelengths_nm);
  }
  if (wavelengths && channels) {
    const toml::array& letters = reader.array(*channels.node, "channels");
    if (letters.size() != specs.wavelengths_nm.size())
      reader.fail(*channels.node, fmt::format("channels has {} entries but wavelengths_nm has {}",
                                              letters.size(), specs.wavelengths_nm.size()));
    specs.wavelength_channels.clear();
    for (const toml::node& value : letters) {
      const std::string letter = reader.string(value, "a channel");
      const auto it = letter.size() == 1
                          ? std::find(kChannelLetters.begin(), kChannelLetters.end(),
                                      std::toupper(static_cast<unsigned char>(letter[0])))
                          : kChannelLetters.end();
      if (it == kChannelLetters.end())
        reader.fail(value, fmt::format("channel \"{}\" must be \"R\", \"G\" or \"B\"", letter));
      specs.wavelength_channels.push_back(static_cast<int>(it - kChannelLetters.begin()));
    }
  }
  if (const Entry e = entry(table, "dispersion")) {
    const std::string model = to_lower(reader.string(*e.node, "dispersion"));
    if (model == "abbe") {
      specs.dispersion = DispersionModel::kAbbe;
    } else if (model == "catalog") {
      specs.dispersion = DispersionModel::kCatalog;
    } else {
      reader.fail(*e.node, fmt::format("dispersion = \"{}\" must be \"abbe\" or \"catalog\"",
                                       reader.string(*e.node, "dispersion")));
    }
  }
  return specs;
}

// [system]: the lens's own system data (lens.h); its presence makes the mode "as-written".
void read_system(const TomlReader& reader, const toml::table& table, Specs& specs) {
  reader.check_keys(table, kSystemKeys, "[system]");
  specs.mode = SpecMode::kAsWritten;
  auto name_index = [&](const toml::node& node, const auto& names, std::string_view what) {
    const std::string value = to_lower(reader.string(node, what));
    for (std::size_t i = 0; i < names.size(); ++i)
      if (value == names[i]) return static_cast<int>(i);
    std::vector<std::string> quoted;
    for (const auto& n : names) quoted.push_back(fmt::format("\"{}\"", n));
    reader.fail(node,
                fmt::format("{} = \"{}\" must be one of {}", what, value, fmt::join(quoted, ", ")));
  };
  auto numbers = [&](const toml::node& node, std::string_view what) {
    std::vector<double> out;
    for (const toml::node& v : reader.array(node, what))
      out.push_back(reader.finite_number(v, what));
    return out;
  };
  if (const Entry e = entry(table, "mode")) {
    const std::string mode = to_lower(reader.string(*e.node, "mode"));
    if (mode == "paper") {
      specs.mode = SpecMode::kPaper;
    } else if (mode != "as-written") {
      reader.fail(*e.node, fmt::format("mode = \"{}\" must be \"paper\" or \"as-written\"", mode));
    }
  }
  if (const Entry e = entry(table, "afocal")) specs.afocal = reader.boolean(*e.node, "afocal");
  if (const Entry e = entry(table, "primary_wavelength_nm")) {
    specs.primary_wavelength_nm = reader.finite_number(*e.node, "primary_wavelength_nm");
    if (!(specs.primary_wavelength_nm > 200.0 && specs.primary_wavelength_nm < 20000.0))
      reader.fail(*e.node, "primary_wavelength_nm is out of range (200, 20000)");
  } else if (!specs.wavelengths_nm.empty() && specs.wavelengths_nm != paper_wavelengths_nm()) {
    // Without a primary: the wavelength nearest the d line.
    double best = specs.wavelengths_nm.front();
    for (double w : specs.wavelengths_nm)
      if (std::abs(w - kWavelengthD_nm) < std::abs(best - kWavelengthD_nm)) best = w;
    specs.primary_wavelength_nm = best;
  }
  if (const Entry e = entry(table, "wavelength_weights")) {
    specs.wavelength_weights = numbers(*e.node, "wavelength_weights");
    if (specs.wavelength_weights.size() != specs.wavelengths_nm.size())
      reader.fail(*e.node,
                  fmt::format("wavelength_weights has {} entries for {} wavelengths",
                              specs.wavelength_weights.size(), specs.wavelengths_nm.size()));
    const toml::array& written = *e.node->as_array();
    double sum = 0.0;
    for (std::size_t i = 0; i < written.size(); ++i) {
      const double w = specs.wavelength_weights[i];
      if (!(w >= 0.0)) reader.fail(written[i], fmt::format("wavelength weight {} must be >= 0", w));
      sum += w;
    }
    if (!(sum > 0.0))
      reader.fail(*e.node,
                  "every wavelength weight is 0: no wavelength would count; give at "
                  "least one a positive weight");
  }
  if (const Entry e = entry(table, "aperture"))
    specs.aperture_type =
        static_cast<ApertureType>(name_index(*e.node, kApertureNames, "aperture"));
  if (const Entry e = entry(table, "aperture_value")) {
    specs.aperture_value = reader.finite_number(*e.node, "aperture_value");
    if (!(specs.aperture_value > 0.0)) reader.fail(*e.node, "aperture_value must be > 0");
  } else if (specs.aperture_type == ApertureType::kEntrancePupilDiameter ||
             specs.aperture_type == ApertureType::kObjectNA) {
    reader.fail(table.source(), "[system] aperture needs aperture_value (EPD in mm, or the NA)");
  }
  if (const Entry e = entry(table, "field_type"))
    specs.field_type = static_cast<FieldType>(name_index(*e.node, kFieldTypeNames, "field_type"));
  if (const Entry e = entry(table, "object_distance_mm")) {
    specs.object_distance_mm = reader.number(*e.node, "object_distance_mm");
    if (!(specs.object_distance_mm > 0.0))
      reader.fail(*e.node, "object_distance_mm must be > 0 (inf: an object at infinity)");
  }
  if (const Entry e = entry(table, "fields")) {
    const toml::array& written = reader.array(*e.node, "fields");
    if (written.size() > kMaxFields)
      reader.fail(written[kMaxFields], fmt::format("fields has {} fields; lensopt reads at most {}",
                                                   written.size(), kMaxFields));
    const std::vector<double> values = numbers(*e.node, "fields");
    if (values.empty()) reader.fail(*e.node, "fields is empty");
    specs.fields.clear();
    for (double v : values) specs.fields.push_back({v, 1.0, {}});
    if (specs.field_type == FieldType::kAngle) {
      for (double v : values)
        if (!(std::abs(v) < 89.0))
          reader.fail(*e.node, fmt::format("field {} deg must be below 89", v));
      specs.half_field_deg = specs.max_field_value();
    }
  }
  auto per_field = [&](std::string_view key, auto assign) {
    if (const Entry e = entry(table, key)) {
      const std::vector<double> values = numbers(*e.node, key);
      if (values.size() != specs.fields.size())
        reader.fail(*e.node, fmt::format("{} has {} entries for {} fields", key, values.size(),
                                         specs.fields.size()));
      for (std::size_t i = 0; i < values.size(); ++i) assign(specs.fields[i], values[i], *e.node);
    }
  };
  if (const Entry e = entry(table, "field_weights")) {
    const std::vector<double> values = numbers(*e.node, "field_weights");
    if (values.size() != specs.fields.size())
      reader.fail(*e.node, fmt::format("field_weights has {} entries for {} fields", values.size(),
                                       specs.fields.size()));
    const toml::array& written = *e.node->as_array();
    double sum = 0.0;
    for (std::size_t i = 0; i < values.size(); ++i) {
      if (!(values[i] >= 0.0))
        reader.fail(written[i], fmt::format("field weight {} must be >= 0", values[i]));
      specs.fields[i].weight = values[i];
      sum += values[i];
    }
    if (!(sum > 0.0))
      reader.fail(*e.node,
                  "every field weight is 0: no field would count; give at least one "
                  "a positive weight");
  }
  // fields_x: the x value of each field (OpticStudio's XFLN); `fields` then holds the y values.
  per_field("fields_x", [&](FieldPoint& f, double v, const toml::node& n) {
    f.x = v;
    if (specs.field_type == FieldType::kAngle && !(f.radius() < 89.0))
      reader.fail(n, fmt::format("field (x, y) = ({:g}, {:g}) deg is {:g} deg off axis; it must be "
                                 "below 89",
                                 f.x, f.value, f.radius()));
  });
  if (entry(table, "fields_x") && specs.field_type == FieldType::kAngle)
    specs.half_field_deg = specs.max_field_value();
  per_field("vdx", [](FieldPoint& f, double v, const toml::node&) { f.vignetting.vdx = v; });
  per_field("vdy", [](FieldPoint& f, double v, const toml::node&) { f.vignetting.vdy = v; });
  per_field("vcx", [&](FieldPoint& f, double v, const toml::node& n) {
    if (!(v < 1.0)) reader.fail(n, "vcx must be < 1");
    f.vignetting.vcx = v;
  });
  per_field("vcy", [&](FieldPoint& f, double v, const toml::node& n) {
    if (!(v < 1.0)) reader.fail(n, "vcy must be < 1");
    f.vignetting.vcy = v;
  });
  per_field("van_deg",
            [](FieldPoint& f, double v, const toml::node&) { f.vignetting.van_deg = v; });
}

Material read_material(const TomlReader& reader, const toml::node& node, int surface_number,
                       const Lens& lens, const Catalog* catalog) {
  if (const auto* s = node.as_string()) {
    const std::string& name = s->get();
    if (to_lower(name) == "air") return Material::air();
    if (catalog == nullptr)
      reader.fail(node, fmt::format("surface {}: material \"{}\" names a catalog glass, but [lens] "
                                    "has no catalog (add catalog = \"ohara\")",
                                    surface_number, name));
    const Glass* glass = catalog->find(name);
    if (glass == nullptr)
      reader.fail(node, fmt::format("surface {}: unknown glass '{}' in catalog '{}'; closest: {}",
                                    surface_number, name, lens.catalog_name,
                                    fmt::join(catalog->closest_names(name, 3), ", ")));
    if (lens.specs.dispersion == DispersionModel::kCatalog && !glass->formula_supported)
      reader.fail(node, fmt::format("surface {}: glass '{}' uses dispersion formula {}, which "
                                    "lensopt cannot evaluate; use dispersion = \"abbe\"",
                                    surface_number, glass->name, formula_name(glass->formula)));
    return Material::from_catalog(*glass);
  }
  if (const auto* t = node.as_table(); t != nullptr && t->contains("glass")) {
    // A glass of another catalog: { glass = "S-TIH6", catalog = "OHARA" } (catalog: the lens's
    // when absent).
    reader.check_keys(*t, kCatalogGlassKeys,
                      fmt::format("the material of surface {}", surface_number));
    const Entry g = entry(*t, "glass");
    const std::string name = reader.string(*g.node, "glass");
    std::shared_ptr<const Catalog> own;
    const Catalog* from = catalog;
    std::string from_name = lens.catalog_name;
    if (const Entry c = entry(*t, "catalog")) {
      from_name = reader.string(*c.node, "catalog");
      try {
        own = load_catalog(from_name);
      } catch (const Error& error) {
        reader.fail(*c.node, fmt::format("surface {}: cannot load catalog '{}': {}", surface_number,
                                         from_name, error.message()));
      }
      from = own.get();
    }
    if (from == nullptr)
      reader.fail(node, fmt::format("surface {}: glass \"{}\" needs a catalog: add catalog = "
                                    "\"...\" to the material or to [lens]",
                                    surface_number, name));
    const Glass* glass = from->find(name);
    if (glass == nullptr)
      reader.fail(
          *g.node,
          fmt::format("surface {}: unknown glass '{}' in catalog '{}'; closest: {}", surface_number,
                      name, from_name, fmt::join(from->closest_names(name, 3), ", ")));
    if (lens.specs.dispersion == DispersionModel::kCatalog && !glass->formula_supported)
      reader.fail(*g.node, fmt::format("surface {}: glass '{}' uses dispersion formula {}, which "
                                       "lensopt cannot evaluate; use dispersion = \"abbe\"",
                                       surface_number, glass->name, formula_name(glass->formula)));
    return Material::from_catalog(*glass);
  }
  if (const auto* t = node.as_table()) {
    reader.check_keys(*t, kModelGlassKeys,
                      fmt::format("the material of surface {}", surface_number));
    const Entry nd = entry(*t, "nd");
    const Entry vd = entry(*t, "vd");
    if (!nd || !vd)
      reader.fail(node, fmt::format("surface {}: a model glass needs both nd and vd, as in "
                                    "{{ nd = 1.7, vd = 48 }}",
                                    surface_number));
    const double nd_value = reader.finite_number(*nd.node, "nd");
    const double vd_value = reader.finite_number(*vd.node, "vd");
    if (!(nd_value > 1.0))
      reader.fail(*nd.node,
                  fmt::format("surface {}: nd = {} must be > 1", surface_number, nd_value));
    if (!(vd_value > 0.0))
      reader.fail(*vd.node,
                  fmt::format("surface {}: vd = {} must be > 0", surface_number, vd_value));
    // model = "paper" (default: the paper's A + B / l^2 at 587.6 nm) or "opticstudio"
    // (OpticStudio's model glass, nd exact at 587.5618 nm, with dpgf; a .zmx import).
    std::string model = "paper";
    if (const Entry m = entry(*t, "model")) model = reader.string(*m.node, "model");
    const Entry dpgf = entry(*t, "dpgf");
    if (model == "opticstudio")
      return Material::zemax_model(nd_value, vd_value,
                                   dpgf ? reader.finite_number(*dpgf.node, "dpgf") : 0.0);
    if (model != "paper")
      reader.fail(*entry(*t, "model").node,
                  fmt::format("surface {}: model glass model = \"{}\" must be \"paper\" or "
                              "\"opticstudio\"",
                              surface_number, model));
    if (dpgf)
      reader.fail(*dpgf.node, fmt::format("surface {}: dpgf needs model = \"opticstudio\" (the "
                                          "paper's model glass has no partial dispersion term)",
                                          surface_number));
    return Material::model(nd_value, vd_value);
  }
  reader.fail(node, fmt::format("surface {}: material must be a glass name, \"air\" or "
                                "{{ nd = ..., vd = ... }}, not {}",
                                surface_number, type_phrase(node)));
}

// A coordinate_break = { ... } or decenter_tilt = { ... } table: decenters (mm), tilts (deg),
// order = "decenter-first" (OpticStudio's order 0, default) or "tilt-first" (order 1) and, for
// decenter_tilt, restore_frame.
void read_placement(const TomlReader& reader, const toml::node& node, int surface_number,
                    bool coordinate_break, Surface& surface) {
  const std::string what = fmt::format("surface {}: {}", surface_number,
                                       coordinate_break ? "coordinate_break" : "decenter_tilt");
  const toml::table& t = reader.table(node, what);
  reader.check_keys(t, kPlacementKeys, what);
  Placement& p = surface.placement;
  auto value = [&](std::string_view key, double& out) {
    if (const Entry e = entry(t, key))
      out = reader.finite_number(*e.node, fmt::format("{}.{}", what, key));
  };
  value("decenter_x_mm", p.decenter_x_mm);
  value("decenter_y_mm", p.decenter_y_mm);
  value("tilt_x_deg", p.tilt_x_deg);
  value("tilt_y_deg", p.tilt_y_deg);
  value("tilt_z_deg", p.tilt_z_deg);
  if (const Entry e = entry(t, "order")) {
    const std::string order = reader.string(*e.node, fmt::format("{}.order", what));
    if (order == "tilt-first")
      p.tilt_first = true;
    else if (order != "decenter-first")
      reader.fail(*e.node, fmt::format("{}.order = \"{}\" must be \"decenter-first\" "
                                       "(OpticStudio's order 0) or \"tilt-first\" (order 1)",
                                       what, order));
  }
  if (const Entry e = entry(t, "restore_frame")) {
    if (coordinate_break)
      reader.fail(e, fmt::format("{}: restore_frame belongs to decenter_tilt (a coordinate "
                                 "break moves the frame of everything after it)",
                                 what));
    surface.restore_frame = reader.boolean(*e.node, "restore_frame");
  }
}

// vary = ["radius", ...], pickup_curvature = { surface = 2, scale = -1 },
// pickup_thickness = { surface = 2, scale = 1, offset_mm = 0 },
// solve = { thickness = "marginal_height", height_mm = 0 } (lens.h; 1-based surfaces).
void read_solves(const TomlReader& reader, const toml::table& table, int surface_number,
                 Surface& surface) {
  const std::string where = fmt::format("surface {}", surface_number);
  if (const Entry e = entry(table, "vary")) {
    const toml::array& names = reader.array(*e.node, where + ": vary");
    for (const toml::node& node : names) {
      const std::string name = reader.string(node, where + ": vary entry");
      if (name == "radius")
        surface.vary.radius = true;
      else if (name == "thickness")
        surface.vary.thickness = true;
      else if (name == "conic")
        surface.vary.conic = true;
      else if (name == "glass")
        surface.vary.glass = true;
      else
        reader.fail(node, fmt::format("{}: unknown vary entry \"{}\"; known: radius, thickness, "
                                      "conic, glass{}",
                                      where, name, detail::did_you_mean(name, kVaryNames)));
    }
  }
  auto read_pickup = [&](const Entry& e, bool thickness) {
    const std::string what = fmt::format("{}: {}", where, e.key->str());
    const toml::table& t = reader.table(*e.node, what);
    reader.check_keys(t, kPickupKeys, what);
    Pickup p;
    const Entry source = entry(t, "surface");
    if (!source) reader.fail(*e.node, what + " needs surface = N (the 1-based source surface)");
    const double n = reader.finite_number(*source.node, what + " surface");
    if (n != std::floor(n) || n < 1 || n >= surface_number)
      reader.fail(*source.node, fmt::format("{} surface = {}: the source must be an earlier "
                                            "surface, 1 .. {}",
                                            what, n, surface_number - 1));
    p.source = static_cast<int>(n) - 1;
    if (const Entry s = entry(t, "scale")) p.scale = reader.finite_number(*s.node, what + " scale");
    if (const Entry o = entry(t, "offset_mm")) {
      if (!thickness)
        reader.fail(o, what + ": a curvature pickup has no offset (c = scale * c_source)");
      p.offset_mm = reader.finite_number(*o.node, what + " offset_mm");
    }
    return p;
  };
  if (const Entry e = entry(table, "pickup_curvature")) {
    if (surface.is_stop) reader.fail(e, where + ": the stop is flat; it has no curvature pickup");
    surface.curvature_pickup = read_pickup(e, false);
  }
  if (const Entry e = entry(table, "pickup_thickness"))
    surface.thickness_pickup = read_pickup(e, true);
  if (const Entry e = entry(table, "solve")) {
    const std::string what = where + ": solve";
    const toml::table& t = reader.table(*e.node, what);
    reader.check_keys(t, kSolveKeys, what);
    const Entry kind = entry(t, "thickness");
    if (!kind) reader.fail(*e.node, what + " needs thickness = \"marginal_height\"");
    const std::string name = reader.string(*kind.node, what + " thickness");
    if (name != "marginal_height")
      reader.fail(*kind.node, fmt::format("{}: unknown thickness solve \"{}\"; known: "
                                          "marginal_height",
                                          what, name));
    surface.thickness_solve.kind = ThicknessSolve::Kind::kMarginalHeight;
    if (const Entry h = entry(t, "height_mm"))
      surface.thickness_solve.height_mm = reader.finite_number(*h.node, what + " height_mm");
    if (surface.thickness_pickup.active())
      reader.fail(e, where + ": the thickness has both pickup_thickness and a solve");
  }
}

Surface read_surface(const TomlReader& reader, const toml::table& table, int surface_number,
                     const Lens& lens, const Catalog* catalog) {
  reader.check_keys(table, kSurfaceKeys, fmt::format("surface {}", surface_number));
  Surface surface;
  const Material before = lens.surfaces.empty() ? Material::air() : lens.surfaces.back().material;
  if (const Entry cb = entry(table, "coordinate_break")) {
    // A dummy surface: only its placement and thickness.
    for (std::string_view key :
         {"radius_mm", "curvature_per_mm", "material", "stop", "semi_diameter_mm", "conic",
          "asphere", "asphere_r2", "decenter_tilt", "obscuration_mm", "aperture_decenter_mm",
          "vary", "pickup_curvature", "pickup_thickness", "solve"})
      if (const Entry e = entry(table, key))
        reader.fail(e, fmt::format("surface {}: a coordinate break has only coordinate_break "
                                   "and thickness_mm, not {}",
                                   surface_number, key));
    surface.coordinate_break = true;
    surface.material = before;
    read_placement(reader, *cb.node, surface_number, true, surface);
    const Entry thickness = entry(table, "thickness_mm");
    if (!thickness)
      reader.fail(table.source(), fmt::format("surface {}: missing thickness_mm", surface_number));
    surface.thickness_mm = reader.finite_number(*thickness.node, "thickness_mm");
    return surface;
  }
  if (const Entry e = entry(table, "decenter_tilt"))
    read_placement(reader, *e.node, surface_number, false, surface);
  if (const Entry e = entry(table, "obscuration_mm")) {
    surface.obscuration_mm = reader.finite_number(*e.node, "obscuration_mm");
    if (!(surface.obscuration_mm >= 0.0))
      reader.fail(*e.node, fmt::format("obscuration_mm = {} must be >= 0", surface.obscuration_mm));
  }
  if (const Entry e = entry(table, "aperture_decenter_mm")) {
    const toml::array& xy = reader.array(*e.node, "aperture_decenter_mm");
    if (xy.size() != 2) reader.fail(*e.node, "aperture_decenter_mm must be [x, y] (mm)");
    surface.aperture_decenter_x_mm = reader.finite_number(xy[0], "aperture_decenter_mm x");
    surface.aperture_decenter_y_mm = reader.finite_number(xy[1], "aperture_decenter_mm y");
  }
  const Entry radius = entry(table, "radius_mm");
  const Entry curvature = entry(table, "curvature_per_mm");
  if (radius && curvature) {
    const bool radius_later = curvature.key->source().begin < radius.key->source().begin;
    reader.fail(
        radius_later ? radius : curvature,
        fmt::format("surface {}: give radius_mm or curvature_per_mm, not both", surface_number));
  }
  if (!radius && !curvature)
    reader.fail(table.source(), fmt::format("surface {}: missing radius_mm (or curvature_per_mm); "
                                            "write radius_mm = inf for a flat surface",
                                            surface_number));
  if (radius) {
    surface.curvature_per_mm = 1.0 / read_radius_mm(reader, *radius.node, "radius_mm");
    surface.written_as_radius = true;
  } else {
    surface.curvature_per_mm = reader.finite_number(*curvature.node, "curvature_per_mm");
    surface.written_as_radius = false;
  }
  const Entry thickness = entry(table, "thickness_mm");
  if (!thickness)
    reader.fail(table.source(), fmt::format("surface {}: missing thickness_mm", surface_number));
  surface.thickness_mm = reader.finite_number(*thickness.node, "thickness_mm");
  if (const Entry e = entry(table, "material")) {
    const auto* name = e.node->as_string();
    if (name && to_lower(name->get()) == "mirror") {
      // A reflecting surface: the medium before it continues, traversed backwards.
      surface.mirror = true;
      surface.material = before;
    } else {
      surface.material = read_material(reader, *e.node, surface_number, lens, catalog);
    }
  }
  if (const Entry e = entry(table, "stop")) {
    surface.is_stop = reader.boolean(*e.node, "stop");
    if (surface.is_stop && surface.curvature_per_mm != 0.0)
      reader.fail(
          e, fmt::format("surface {}: the stop must be flat, but its {}; write "
                         "radius_mm = inf, or put the stop on its own flat surface",
                         surface_number,
                         radius ? fmt::format("radius is {} mm", 1.0 / surface.curvature_per_mm)
                                : fmt::format("curvature is {} /mm", surface.curvature_per_mm)));
  }
  if (const Entry e = entry(table, "semi_diameter_mm")) {
    surface.semi_diameter_mm = reader.finite_number(*e.node, "semi_diameter_mm");
    if (surface.semi_diameter_mm < 0.0)
      reader.fail(*e.node,
                  fmt::format("semi_diameter_mm = {} must be >= 0", surface.semi_diameter_mm));
  }
  // Profile: conic constant, even-asphere terms a4, a6, ... (mm^(1-2i)) and the r^2 term.
  if (const Entry e = entry(table, "conic"))
    surface.conic = reader.finite_number(*e.node, fmt::format("surface {}: conic", surface_number));
  if (const Entry e = entry(table, "asphere_r2"))
    surface.asphere_r2_per_mm =
        reader.finite_number(*e.node, fmt::format("surface {}: asphere_r2", surface_number));
  if (const Entry e = entry(table, "asphere")) {
    const toml::array& terms =
        reader.array(*e.node, fmt::format("surface {}: asphere", surface_number));
    if (terms.size() > static_cast<std::size_t>(kAsphereOrders))
      reader.fail(*e.node, fmt::format("surface {}: asphere has {} terms; at most {} (a4 .. a16)",
                                       surface_number, terms.size(), kAsphereOrders));
    for (std::size_t j = 0; j < terms.size(); ++j)
      surface.asphere[j] = reader.finite_number(
          terms[j], fmt::format("surface {}: asphere a{}", surface_number, 2 * j + 4));
  }
  if (surface.is_stop && !surface.is_spherical())
    reader.fail(table.source(), fmt::format("surface {}: the stop must be flat, but it has a "
                                            "conic or asphere terms",
                                            surface_number));
  read_solves(reader, table, surface_number, surface);
  return surface;
}

}  // namespace

Lens parse_lens_toml(std::string_view text, const std::string& source_name) {
  const TomlReader reader(source_name);
  toml::table root;
  // Before toml++ recurses into it (lens/input_limits.h).
  check_toml_nesting(text, source_name);
  try {
    root = toml::parse(text, source_name);
  } catch (const toml::parse_error& e) {
    reader.fail(e.source(), fmt::format("TOML syntax error: {}", e.description()));
  }

  Lens lens;
  lens.source_path = source_name;
  lens.name = std::filesystem::path(source_name).stem().string();

  // Top level: [lens], [specs], [[surfaces]]; any other table is kept for other modules.
  toml::table extra;
  for (auto&& [key, node] : root) {
    if (std::find(kTopLevelKeys.begin(), kTopLevelKeys.end(), key.str()) != kTopLevelKeys.end())
      continue;
    if (node.is_table() || node.is_array_of_tables()) {
      extra.insert(key, node);
      continue;
    }
    reader.fail(key.source(),
                fmt::format("unknown top-level key '{}'{}; lens keys belong in [lens], [specs] or "
                            "[[surfaces]]",
                            key.str(), detail::did_you_mean(key.str(), kTopLevelKeys)));
  }
  if (!extra.empty()) {
    lens.extra_toml = detail::format_extra_toml(extra);
  }

  LensSourceLines lines;
  std::shared_ptr<const Catalog> catalog;
  if (const toml::node* node = root.get("lens")) {
    const toml::table& table = reader.table(*node, "[lens]");
    reader.check_keys(table, kLensKeys, "[lens]");
    if (const Entry e = entry(table, "name")) lens.name = reader.string(*e.node, "name");
    if (const Entry e = entry(table, "catalog")) {
      lens.catalog_name = reader.string(*e.node, "catalog");
      try {
        catalog = load_catalog(lens.catalog_name);
      } catch (const Error& error) {
        reader.fail(*e.node,
                    fmt::format("cannot load catalog '{}': {}", lens.catalog_name, error.what()));
      }
    }
  }

  if (const toml::node* node = root.get("specs")) {
    const toml::table& specs_table = reader.table(*node, "[specs]");
    lens.specs = read_specs(reader, specs_table);
    auto line_of = [&](std::string_view key) {
      const Entry e = entry(specs_table, key);
      return e ? static_cast<int>(e.node->source().begin.line) : 0;
    };
    lines.f_number = line_of("f_number");
    lines.half_field_deg = line_of("half_field_deg");
    lines.sensor_diagonal_mm = line_of("sensor_diagonal_mm");
  }
  if (const toml::node* node = root.get("system")) {
    const toml::table& system = reader.table(*node, "[system]");
    read_system(reader, system, lens.specs);
    // An F-number aperture of a lens traced as written takes [specs] f_number: without it the
    // default F/2 would be traced without a word.
    if (lens.specs.mode == SpecMode::kAsWritten &&
        lens.specs.aperture_type == ApertureType::kFNumber && lines.f_number == 0) {
      if (const Entry e = entry(system, "aperture"))
        reader.fail(*e.node,
                    "aperture = \"f-number\" needs [specs] f_number (the image-space "
                    "F-number to trace at)");
      reader.fail(system.source(),
                  "[system] gives no aperture: add aperture = \"f-number\" with [specs] "
                  "f_number, \"epd\" or \"object-na\" with aperture_value, or "
                  "\"float-by-stop\"");
    }
  }

  const toml::node* surfaces_node = root.get("surfaces");
  if (surfaces_node == nullptr) reader.fail_file("no [[surfaces]]: a lens needs at least two");
  const toml::array& surfaces = reader.array(*surfaces_node, "surfaces");
  if (surfaces.size() > kMaxSurfaces)
    reader.fail(surfaces[kMaxSurfaces],
                fmt::format("the lens has {} surfaces; lensopt reads at most {} (surface {} is "
                            "one too many)",
                            surfaces.size(), kMaxSurfaces, kMaxSurfaces + 1));
  for (std::size_t i = 0; i < surfaces.size(); ++i) {
    const int number = static_cast<int>(i) + 1;
    const toml::table& table = reader.table(surfaces[i], fmt::format("surface {}", number));
    lens.surfaces.push_back(read_surface(reader, table, number, lens, catalog.get()));
    lines.surfaces.push_back(static_cast<int>(table.source().begin.line));
  }

  // Whole-lens checks, placed at the surface they concern.
  if (surfaces.size() < 2)
    reader.fail(
        surfaces.empty() ? surfaces_node->source() : surfaces[0].source(),
        fmt::format("a lens needs at least two surfaces; this one has {}", surfaces.size()));
  int stop_count = 0;
  for (std::size_t i = 0; i < surfaces.size(); ++i) {
    if (!lens.surfaces[i].is_stop) continue;
    if (++stop_count > 1)
      reader.fail(entry(*surfaces[i].as_table(), "stop"),
                  fmt::format("surface {} is a second aperture stop; mark exactly one surface with "
                              "stop = true",
                              i + 1));
  }
  if (stop_count == 0)
    reader.fail(surfaces[0].source(),
                "no surface is the aperture stop; add stop = true to the "
                "flat surface where the stop is");
  if (!lens.surfaces.back().material.is_air()) {
    const Entry e = entry(*surfaces.back().as_table(), "material");
    reader.fail(e, fmt::format("surface {} (the last) must be followed by air, not {}",
                               surfaces.size(), lens.surfaces.back().material.label()));
  }

  validate_lens(lens, lines);
  return lens;
}

}  // namespace lensopt
