// Native TOML lens files (toml++), and read_lens / write_lens, which pick the format by the file's
// extension.
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
#include "lensopt/core/atomic_file.h"
#include "lensopt/core/error.h"
#include "lensopt/formats/zmx.h"
#include "lensopt/glass/glass.h"
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

constexpr std::array<std::string_view, 4> kTopLevelKeys = {"lens", "specs", "system", "surfaces"};
constexpr std::array<std::string_view, 12> kSystemKeys = {"mode",
                                                          "primary_wavelength_nm",
                                                          "wavelength_weights",
                                                          "aperture",
                                                          "aperture_value",
                                                          "field_type",
                                                          "fields",
                                                          "field_weights",
                                                          "vdy",
                                                          "vcx",
                                                          "vcy",
                                                          "object_distance_mm"};
constexpr std::array<std::string_view, 4> kApertureNames = {"f-number", "epd", "object-na",
                                                            "float-by-stop"};
constexpr std::array<std::string_view, 4> kFieldTypeNames = {
    "angle", "object-height", "paraxial-image-height", "real-image-height"};
constexpr std::array<std::string_view, 2> kLensKeys = {"name", "catalog"};
constexpr std::array<std::string_view, 6> kSpecsKeys = {
    "f_number", "half_field_deg", "sensor_diagonal_mm", "wavelengths_nm", "channels", "dispersion"};
constexpr std::array<std::string_view, 9> kSurfaceKeys = {
    "radius_mm", "curvature_per_mm", "thickness_mm", "material", "stop", "semi_diameter_mm",
    "conic",     "asphere",          "asphere_r2"};
constexpr std::array<std::string_view, 2> kModelGlassKeys = {"nd", "vd"};
constexpr std::array<char, 3> kChannelLetters = {'R', 'G', 'B'};

// Ulps either side of fl(1/c) searched for a radius R with fl(1/R) == c. The exact 1/c is within
// 1/2 ulp of fl(1/c), and any such R within about 1 ulp of the exact 1/c.
constexpr int kRadiusSearchUlps = 4;

std::string lower(std::string_view text) {
  std::string out(text);
  for (char& ch : out) ch = static_cast<char>(std::tolower(static_cast<unsigned char>(ch)));
  return out;
}

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
    std::string text = lower(s->get());
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
    const std::string model = lower(reader.string(*e.node, "dispersion"));
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
    const std::string value = lower(reader.string(node, what));
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
    const std::string mode = lower(reader.string(*e.node, "mode"));
    if (mode == "paper") {
      specs.mode = SpecMode::kPaper;
    } else if (mode != "as-written") {
      reader.fail(*e.node, fmt::format("mode = \"{}\" must be \"paper\" or \"as-written\"", mode));
    }
  }
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
    for (double w : specs.wavelength_weights)
      if (!(w >= 0.0)) reader.fail(*e.node, "wavelength weights must be >= 0");
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
  per_field("field_weights", [&](FieldPoint& f, double v, const toml::node& n) {
    if (!(v >= 0.0)) reader.fail(n, "field weights must be >= 0");
    f.weight = v;
  });
  per_field("vdy", [](FieldPoint& f, double v, const toml::node&) { f.vignetting.vdy = v; });
  per_field("vcx", [&](FieldPoint& f, double v, const toml::node& n) {
    if (!(v < 1.0)) reader.fail(n, "vcx must be < 1");
    f.vignetting.vcx = v;
  });
  per_field("vcy", [&](FieldPoint& f, double v, const toml::node& n) {
    if (!(v < 1.0)) reader.fail(n, "vcy must be < 1");
    f.vignetting.vcy = v;
  });
}

Material read_material(const TomlReader& reader, const toml::node& node, int surface_number,
                       const Lens& lens, const Catalog* catalog) {
  if (const auto* s = node.as_string()) {
    const std::string& name = s->get();
    if (lower(name) == "air") return Material::air();
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
    return Material::model(nd_value, vd_value);
  }
  reader.fail(node, fmt::format("surface {}: material must be a glass name, \"air\" or "
                                "{{ nd = ..., vd = ... }}, not {}",
                                surface_number, type_phrase(node)));
}

Surface read_surface(const TomlReader& reader, const toml::table& table, int surface_number,
                     const Lens& lens, const Catalog* catalog) {
  reader.check_keys(table, kSurfaceKeys, fmt::format("surface {}", surface_number));
  Surface surface;
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
  if (const Entry e = entry(table, "material"))
    surface.material = read_material(reader, *e.node, surface_number, lens, catalog);
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
  return surface;
}

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

std::string lower_extension(const std::filesystem::path& path) {
  return lower(path.extension().string());
}

}  // namespace

Lens parse_lens_toml(std::string_view text, const std::string& source_name) {
  const TomlReader reader(source_name);
  toml::table root;
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
    lens.extra_toml = ExtraTomlWriter().write(extra);
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
  if (const toml::node* node = root.get("system"))
    read_system(reader, reader.table(*node, "[system]"), lens.specs);

  const toml::node* surfaces_node = root.get("surfaces");
  if (surfaces_node == nullptr) reader.fail_file("no [[surfaces]]: a lens needs at least two");
  const toml::array& surfaces = reader.array(*surfaces_node, "surfaces");
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
      std::vector<double> values, weights, vdy, vcx, vcy;
      bool weighted = false, vignetted = false;
      for (const FieldPoint& f : specs.fields) {
        values.push_back(f.value);
        weights.push_back(f.weight);
        vdy.push_back(f.vignetting.vdy);
        vcx.push_back(f.vignetting.vcx);
        vcy.push_back(f.vignetting.vcy);
        weighted = weighted || f.weight != 1.0;
        vignetted = vignetted || f.vignetting.any();
      }
      line("fields", list(values));
      if (weighted) line("field_weights", list(weights));
      if (vignetted) {
        line("vdy", list(vdy));
        line("vcx", list(vcx));
        line("vcy", list(vcy));
      }
    }
  }

  for (const Surface& surface : lens.surfaces) {
    out += "\n[[surfaces]]\n";
    const std::optional<double> radius_mm =
        surface.written_as_radius ? exact_radius_mm(surface.curvature_per_mm) : std::nullopt;
    if (radius_mm) {
      line("radius_mm", number_text(*radius_mm));
    } else {
      line("curvature_per_mm", number_text(surface.curvature_per_mm));
    }
    line("thickness_mm", number_text(surface.thickness_mm));
    switch (surface.material.kind) {
      case Material::Kind::kAir:
        break;
      case Material::Kind::kCatalog:
        line("material", toml_string(surface.material.glass_name));
        break;
      case Material::Kind::kModel:
        line("material", fmt::format("{{ nd = {}, vd = {} }}", number_text(surface.material.nd),
                                     number_text(surface.material.vd)));
        break;
    }
    if (surface.is_stop) line("stop", "true");
    if (surface.semi_diameter_mm != 0.0)
      line("semi_diameter_mm", number_text(surface.semi_diameter_mm));
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
  }

  if (!lens.extra_toml.empty()) {
    out += "\n";
    out += lens.extra_toml;
    if (out.back() != '\n') out += '\n';
  }
  return out;
}

Lens read_lens(const std::filesystem::path& path) {
  const std::string extension = lower_extension(path);
  if (extension == ".toml") return parse_lens_toml(read_file(path), path.string());
  if (extension == ".yml" || extension == ".yaml")
    return parse_lens_yaml(read_file(path), path.string());
  if (extension == ".zmx") {
    // Zemax import (src/formats/zmx.cpp); its warnings (ignored lines) go to stderr.
    ZmxImport imported = read_zmx(path);
    for (const std::string& warning : imported.warnings)
      fmt::print(stderr, "lensopt: warning: {}\n", warning);
    return std::move(imported.lens);
  }
  throw Error(SourceLocation{path.string()},
              fmt::format("unknown lens file type '{}'; lensopt reads .toml, the paper's "
                          ".yml/.yaml and Zemax .zmx",
                          path.extension().string()));
}

void write_lens(const Lens& lens, const std::filesystem::path& path) {
  const std::string extension = lower_extension(path);
  if (extension == ".zmx") return write_zmx(lens, path);
  if (extension != ".toml")
    throw Error(SourceLocation{path.string()},
                fmt::format("cannot write a lens as '{}'; lensopt writes lenses as .toml or "
                            "Zemax .zmx",
                            path.extension().string()));
  write_file_atomic(path, format_lens_toml(lens));
}

}  // namespace lensopt
