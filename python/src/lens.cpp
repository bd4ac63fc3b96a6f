// Lenses in Python: Material, Surface, Specs, Lens (edited in place), reading and writing every
// format the core knows (.toml, the paper's .yml, Zemax .zmx), glass catalogs.
#include <pybind11/stl_bind.h>

#include <array>
#include <cmath>
#include <limits>

#include "bindings.h"
#include "lensopt/core/error.h"
#include "lensopt/formats/lens_file.h"
#include "lensopt/formats/zmx.h"
#include "lensopt/glass/glass.h"
#include "lensopt/lens/lens_io.h"
#include "lensopt/lens/validate.h"
#include "lensopt/paraxial/solves.h"

PYBIND11_MAKE_OPAQUE(std::vector<lensopt::Surface>)

namespace lensopt::python {
namespace {

std::string kind_name(Material::Kind k) {
  switch (k) {
    case Material::Kind::kAir:
      return "air";
    case Material::Kind::kCatalog:
      return "catalog";
    case Material::Kind::kModel:
      return "model";
  }
  return "air";
}

DispersionModel parse_dispersion(const std::string& s) {
  if (s == "abbe") return DispersionModel::kAbbe;
  if (s == "catalog") return DispersionModel::kCatalog;
  throw Error("dispersion must be 'abbe' or 'catalog', not '" + s + "'");
}

constexpr std::array<const char*, 4> kApertures = {"f-number", "epd", "object-na", "float-by-stop"};
constexpr std::array<const char*, 4> kFieldTypes = {"angle", "object-height",
                                                    "paraxial-image-height", "real-image-height"};

template <std::size_t N>
int name_index(const std::string& value, const std::array<const char*, N>& names,
               const char* what) {
  std::string all;
  for (std::size_t i = 0; i < N; ++i) {
    if (value == names[i]) return static_cast<int>(i);
    all += (i ? ", '" : "'") + std::string(names[i]) + "'";
  }
  throw Error(std::string(what) + " must be one of " + all + ", not '" + value + "'");
}

// A placement number as the TOML reader takes it: finite (lens_toml.cpp read_placement).
// A pickup from Python: None, or a dict {'surface': n (1-based), 'scale': k, 'offset_mm': o}.
Pickup pickup_of(const py::object& value, bool thickness) {
  Pickup p;
  if (value.is_none()) return p;
  const py::dict d = value.cast<py::dict>();
  bool has_surface = false;
  for (const auto& [key, v] : d) {
    const std::string k = key.cast<std::string>();
    if (k == "surface") {
      const int n = v.cast<int>();
      if (n < 1) throw Error("a pickup's surface is 1-based: " + std::to_string(n));
      p.source = n - 1;
      has_surface = true;
    } else if (k == "scale") {
      p.scale = v.cast<double>();
    } else if (k == "offset_mm" && thickness) {
      p.offset_mm = v.cast<double>();
    } else {
      throw Error("unknown pickup key '" + k + "'; known: surface, scale" +
                  (thickness ? ", offset_mm" : " (a curvature pickup has no offset)"));
    }
  }
  if (!has_surface) throw Error("a pickup needs 'surface' (the 1-based source surface)");
  if (!std::isfinite(p.scale) || !std::isfinite(p.offset_mm))
    throw Error("a pickup's scale and offset must be finite");
  return p;
}

double finite_placement(double v, const char* what) {
  if (!std::isfinite(v))
    throw Error(std::string(what) + " = " + std::to_string(v) + " is not finite");
  return v;
}

// The order flag by its TOML name.
bool tilt_first_of(const std::string& order) {
  if (order == "tilt-first") return true;
  if (order == "decenter-first") return false;
  throw Error("order = \"" + order +
              "\" must be \"decenter-first\" (OpticStudio's order 0) or \"tilt-first\" (order 1)");
}

// System data of the as-written mode: refused on the paper's mode, which would not trace it.
void require_as_written(const Specs& s, const char* what) {
  if (s.mode != SpecMode::kAsWritten)
    throw Error(std::string(what) +
                " is system data of a lens traced as written; this lens is in the paper's spec "
                "mode (f_number, half_field_deg, sensor_diagonal_mm): set specs.mode = "
                "'as-written' first");
}

std::string lower_extension(const std::string& path) {
  std::string e = std::filesystem::path(path).extension().string();
  for (char& c : e) c = static_cast<char>(std::tolower(static_cast<unsigned char>(c)));
  return e;
}

}  // namespace

void bind_lens(py::module_& m) {
  py::class_<Material>(
      m, "Material", "The medium after a surface: air, a catalog glass or a model glass (nd, vd).")
      .def(py::init<>(), "Air.")
      .def_property_readonly(
          "kind", [](const Material& x) { return kind_name(x.kind); },
          "'air', 'catalog' or 'model'")
      .def_readonly("glass_name", &Material::glass_name, "catalog glass name ('' unless catalog)")
      .def_readonly("nd", &Material::nd, "d-line index")
      .def_readonly("vd", &Material::vd, "Abbe number (0 for air)")
      .def("is_air", &Material::is_air)
      .def_property_readonly("label", &Material::label, "'air', the glass name or 'model(nd, vd)'")
      .def_static("air", &Material::air, "Air.")
      .def_static("model", &Material::model, py::arg("nd"), py::arg("vd"),
                  "A model glass of index nd and Abbe number vd.")
      .def_static(
          "catalog",
          [](const std::string& name, const std::string& catalog) {
            const auto cat = load_catalog(catalog);
            return Material::from_catalog(cat->at(name));
          },
          py::arg("name"), py::arg("catalog") = "ohara",
          "A catalog glass by name; raises LensoptError naming the closest names if unknown.")
      .def("__repr__", [](const Material& x) { return "<Material " + x.label() + ">"; });

  py::class_<Surface>(m, "Surface", "One refracting (or stop) surface; lengths in mm.")
      .def(py::init([](double radius_mm, double thickness_mm, const Material& material, bool stop,
                       double semi_diameter_mm) {
             Surface s;
             s.curvature_per_mm = std::isinf(radius_mm) || radius_mm == 0 ? 0.0 : 1.0 / radius_mm;
             s.thickness_mm = thickness_mm;
             s.material = material;
             s.is_stop = stop;
             s.semi_diameter_mm = semi_diameter_mm;
             return s;
           }),
           py::arg("radius_mm") = std::numeric_limits<double>::infinity(),
           py::arg("thickness_mm") = 0.0, py::arg("material") = Material::air(),
           py::arg("stop") = false, py::arg("semi_diameter_mm") = 0.0)
      .def_readwrite("curvature_per_mm", &Surface::curvature_per_mm, "c = 1/R (0: flat)")
      .def_property(
          "radius_mm",
          [](const Surface& s) {
            return s.curvature_per_mm == 0 ? std::numeric_limits<double>::infinity()
                                           : 1.0 / s.curvature_per_mm;
          },
          [](Surface& s, double r) {
            s.curvature_per_mm = std::isinf(r) || r == 0 ? 0.0 : 1.0 / r;
            s.written_as_radius = true;
          },
          "R = 1/c (inf: flat)")
      .def_readwrite("thickness_mm", &Surface::thickness_mm, "axial distance to the next surface")
      .def_readwrite("material", &Surface::material, "medium from this surface to the next")
      .def_readwrite("is_stop", &Surface::is_stop, "the aperture stop (must be flat)")
      .def_readwrite("semi_diameter_mm", &Surface::semi_diameter_mm, "0: not set")
      // 3D placement (issue 32), with the TOML reader's checks (lens_toml.cpp read_placement):
      // finite numbers, order 'decenter-first' or 'tilt-first', restore_frame not on a
      // coordinate break, obscuration >= 0.
      .def_property(
          "decenter_x_mm", [](const Surface& s) { return s.placement.decenter_x_mm; },
          [](Surface& s, double v) {
            s.placement.decenter_x_mm = finite_placement(v, "decenter_x_mm");
          },
          "decenter along x (mm): the surface (or, for a coordinate break, the frame after it)")
      .def_property(
          "decenter_y_mm", [](const Surface& s) { return s.placement.decenter_y_mm; },
          [](Surface& s, double v) {
            s.placement.decenter_y_mm = finite_placement(v, "decenter_y_mm");
          },
          "decenter along y (mm)")
      .def_property(
          "tilt_x_deg", [](const Surface& s) { return s.placement.tilt_x_deg; },
          [](Surface& s, double v) { s.placement.tilt_x_deg = finite_placement(v, "tilt_x_deg"); },
          "tilt about x (deg), OpticStudio's sense")
      .def_property(
          "tilt_y_deg", [](const Surface& s) { return s.placement.tilt_y_deg; },
          [](Surface& s, double v) { s.placement.tilt_y_deg = finite_placement(v, "tilt_y_deg"); },
          "tilt about y (deg)")
      .def_property(
          "tilt_z_deg", [](const Surface& s) { return s.placement.tilt_z_deg; },
          [](Surface& s, double v) { s.placement.tilt_z_deg = finite_placement(v, "tilt_z_deg"); },
          "tilt about z (deg)")
      .def_property(
          "order",
          [](const Surface& s) {
            return std::string(s.placement.tilt_first ? "tilt-first" : "decenter-first");
          },
          [](Surface& s, const std::string& order) {
            s.placement.tilt_first = tilt_first_of(order);
          },
          "'decenter-first' (OpticStudio's order 0, default) or 'tilt-first' (order 1)")
      .def_property(
          "restore_frame", [](const Surface& s) { return s.restore_frame; },
          [](Surface& s, bool v) {
            if (v && s.coordinate_break)
              throw Error(
                  "restore_frame belongs to a surface's decenter_tilt (a coordinate break moves "
                  "the frame of everything after it)");
            s.restore_frame = v;
          },
          "the frame after the surface is the one before it (OpticStudio's 'reverse this "
          "surface')")
      .def_readonly("coordinate_break", &Surface::coordinate_break,
                    "a dummy surface that only moves the frame (Lens.add_coordinate_break)")
      .def_readwrite("mirror", &Surface::mirror, "a reflecting surface (GLAS MIRROR)")
      .def_property(
          "obscuration_mm", [](const Surface& s) { return s.obscuration_mm; },
          [](Surface& s, double v) {
            if (!std::isfinite(v) || !(v >= 0.0))
              throw Error("obscuration_mm = " + std::to_string(v) + " must be >= 0");
            s.obscuration_mm = v;
          },
          "central obscuration radius (mm, 0: none)")
      // Solves and variables (lens.h; issue 31): as the TOML keys, surfaces 1-based.
      .def_property(
          "vary",
          [](const Surface& s) {
            std::vector<std::string> names;
            if (s.vary.radius) names.emplace_back("radius");
            if (s.vary.thickness) names.emplace_back("thickness");
            if (s.vary.conic) names.emplace_back("conic");
            if (s.vary.glass) names.emplace_back("glass");
            return names;
          },
          [](Surface& s, const std::vector<std::string>& names) {
            VaryFlags f;
            for (const std::string& name : names) {
              if (name == "radius")
                f.radius = true;
              else if (name == "thickness")
                f.thickness = true;
              else if (name == "conic")
                f.conic = true;
              else if (name == "glass")
                f.glass = true;
              else
                throw Error("unknown vary entry '" + name +
                            "'; known: radius, thickness, conic, glass");
            }
            s.vary = f;
          },
          "values the optimizer may change: a list of 'radius', 'thickness', 'conic', 'glass' "
          "(TOML vary); when any surface has one, only flagged values are free")
      .def_property(
          "pickup_curvature",
          [](const Surface& s) -> py::object {
            if (!s.curvature_pickup.active()) return py::none();
            return py::dict(py::arg("surface") = s.curvature_pickup.source + 1,
                            py::arg("scale") = s.curvature_pickup.scale);
          },
          [](Surface& s, const py::object& value) { s.curvature_pickup = pickup_of(value, false); },
          "None or {'surface': n (1-based, earlier), 'scale': k}: c = k * c_n (TOML "
          "pickup_curvature); Lens.apply_solves() evaluates it")
      .def_property(
          "pickup_thickness",
          [](const Surface& s) -> py::object {
            if (!s.thickness_pickup.active()) return py::none();
            return py::dict(py::arg("surface") = s.thickness_pickup.source + 1,
                            py::arg("scale") = s.thickness_pickup.scale,
                            py::arg("offset_mm") = s.thickness_pickup.offset_mm);
          },
          [](Surface& s, const py::object& value) { s.thickness_pickup = pickup_of(value, true); },
          "None or {'surface': n, 'scale': k, 'offset_mm': o}: t = k * t_n + o")
      .def_property(
          "solve",
          [](const Surface& s) -> py::object {
            if (!s.thickness_solve.active()) return py::none();
            return py::dict(py::arg("thickness") = "marginal_height",
                            py::arg("height_mm") = s.thickness_solve.height_mm);
          },
          [](Surface& s, const py::object& value) {
            ThicknessSolve solve;
            if (!value.is_none()) {
              const py::dict d = value.cast<py::dict>();
              for (const auto& [key, v] : d) {
                const std::string k = key.cast<std::string>();
                if (k == "thickness") {
                  if (v.cast<std::string>() != "marginal_height")
                    throw Error("unknown thickness solve '" + v.cast<std::string>() +
                                "'; known: marginal_height");
                  solve.kind = ThicknessSolve::Kind::kMarginalHeight;
                } else if (k == "height_mm") {
                  solve.height_mm = v.cast<double>();
                } else {
                  throw Error("unknown solve key '" + k + "'; known: thickness, height_mm");
                }
              }
              if (!solve.active()) throw Error("a solve needs 'thickness': 'marginal_height'");
            }
            s.thickness_solve = solve;
          },
          "None or {'thickness': 'marginal_height', 'height_mm': h}: the thickness that brings "
          "the paraxial marginal ray to height h on the next surface (h = 0 on the last: the "
          "paraxial focus)")
      .def("__repr__", [](const Surface& s) {
        return "<Surface c=" + std::to_string(s.curvature_per_mm) +
               "/mm t=" + std::to_string(s.thickness_mm) + "mm " + s.material.label() +
               (s.is_stop ? " stop" : "") + ">";
      });

  py::bind_vector<std::vector<Surface>>(m, "SurfaceList",
                                        "The lens's surfaces, edited in place (a list).");

  py::class_<FieldPoint>(m, "FieldPoint",
                         "One field as written: value (its y, deg or mm), weight and x (0 on the "
                         "y axis; OpticStudio's XFLN).")
      .def(py::init([](double value, double weight, double x) {
             FieldPoint f;
             f.value = value;
             f.weight = weight;
             f.x = x;
             return f;
           }),
           py::arg("value"), py::arg("weight") = 1.0, py::arg("x") = 0.0)
      .def_readwrite("value", &FieldPoint::value, "y: deg or mm, as Specs.field_type says")
      .def_readwrite("x", &FieldPoint::x, "x: deg or mm (0 on the y axis)")
      .def_property_readonly("radius", &FieldPoint::radius, "sqrt(x^2 + value^2)")
      .def_property_readonly("azimuth_deg", &FieldPoint::azimuth_deg,
                             "from +y towards +x; 0 on the y axis")
      .def_readwrite("weight", &FieldPoint::weight)
      .def("__repr__", [](const FieldPoint& f) {
        return "<FieldPoint " + std::to_string(f.value) + " weight " + std::to_string(f.weight) +
               ">";
      });

  // System data: what traces a lens is its mode's (trace/system.h specs_setup). A value that
  // the lens's mode would not use raises instead of being kept silently.
  py::class_<Specs>(
      m, "Specs",
      "First-order specifications and system data. mode 'paper' (the paper's: f_number, "
      "half_field_deg, sensor_diagonal_mm; the prescription is scaled to the spec focal length) "
      "or 'as-written' (a .zmx or a TOML [system]: aperture, fields, object distance as "
      "written). Setting a value the lens's mode does not use raises LensoptError.")
      .def(py::init<>(), "The paper's defaults: f/2, 25 deg, 16 mm, 15 wavelengths.")
      .def_property(
          "mode",
          [](const Specs& s) { return s.mode == SpecMode::kPaper ? "paper" : "as-written"; },
          [](Specs& s, const std::string& v) {
            if (v == "paper")
              s.mode = SpecMode::kPaper;
            else if (v == "as-written")
              s.mode = SpecMode::kAsWritten;
            else
              throw Error("mode must be 'paper' or 'as-written', not '" + v + "'");
          },
          "'paper' or 'as-written'")
      .def_property(
          "f_number", [](const Specs& s) { return s.f_number; },
          [](Specs& s, double v) {
            s.f_number = v;
            // A lens traced as written takes it as its aperture (image-space F/#), as
            // OpticStudio's aperture type "Image Space F/#".
            if (s.mode == SpecMode::kAsWritten) {
              s.aperture_type = ApertureType::kFNumber;
              s.aperture_value = 0.0;
            }
          },
          "Image-space F-number EFL / EPD. Setting it on a lens traced as written makes it the "
          "aperture (aperture = 'f-number').")
      .def_property(
          "half_field_deg", [](const Specs& s) { return s.half_field_deg; },
          [](Specs& s, double v) {
            if (s.mode == SpecMode::kAsWritten && !s.fields.empty())
              throw Error(
                  "half_field_deg is not traced on a lens whose fields are written (a .zmx or a "
                  "TOML [system] fields): set specs.fields (a list of FieldPoint or numbers)");
            s.half_field_deg = v;
          },
          "The paper's half field of view (deg); a lens as written with fields uses those.")
      .def_readwrite("sensor_diagonal_mm", &Specs::sensor_diagonal_mm)
      .def_property(
          "wavelengths_nm", [](const Specs& s) { return s.wavelengths_nm; },
          [](Specs& s, const std::vector<double>& v) {
            // New wavelengths keep their channels and weights only when the count is the same.
            if (v.size() != s.wavelengths_nm.size()) {
              s.wavelength_channels = default_wavelength_channels(v);
              s.wavelength_weights.clear();
            }
            s.wavelengths_nm = v;
          },
          "Wavelengths (nm). A list of another length resets the channels (by band) and the "
          "weights (equal).")
      .def_readwrite("wavelength_channels", &Specs::wavelength_channels,
                     "0 = R, 1 = G, 2 = B, one per wavelength")
      .def_readwrite("wavelength_weights", &Specs::wavelength_weights,
                     "one per wavelength, or empty: equal")
      .def_readwrite("primary_wavelength_nm", &Specs::primary_wavelength_nm,
                     "the paraxial reference wavelength (nm)")
      .def_property(
          "aperture",
          [](const Specs& s) { return std::string(kApertures[static_cast<int>(s.aperture_type)]); },
          [](Specs& s, const std::string& v) {
            require_as_written(s, "aperture");
            s.aperture_type = static_cast<ApertureType>(name_index(v, kApertures, "aperture"));
          },
          "'f-number' (f_number), 'epd' or 'object-na' (aperture_value), 'float-by-stop' (the "
          "stop's semi-diameter); a lens traced as written only")
      .def_property(
          "aperture_value", [](const Specs& s) { return s.aperture_value; },
          [](Specs& s, double v) {
            require_as_written(s, "aperture_value");
            if (!(v > 0.0) || !std::isfinite(v))
              throw Error("aperture_value = " + std::to_string(v) + " must be > 0");
            s.aperture_value = v;
          },
          "EPD (mm) or object-space NA, as aperture says")
      .def_property(
          "field_type",
          [](const Specs& s) { return std::string(kFieldTypes[static_cast<int>(s.field_type)]); },
          [](Specs& s, const std::string& v) {
            require_as_written(s, "field_type");
            s.field_type = static_cast<FieldType>(name_index(v, kFieldTypes, "field_type"));
          },
          "'angle' (deg), 'object-height', 'paraxial-image-height' or 'real-image-height' (mm)")
      .def_property(
          "fields", [](const Specs& s) { return s.fields; },
          [](Specs& s, const py::iterable& values) {
            require_as_written(s, "fields");
            std::vector<FieldPoint> fields;
            for (const py::handle v : values) {
              if (py::isinstance<FieldPoint>(v)) {
                fields.push_back(v.cast<FieldPoint>());
              } else {
                FieldPoint f;
                f.value = v.cast<double>();
                fields.push_back(f);
              }
            }
            s.fields = std::move(fields);
            if (!s.fields.empty()) s.half_field_deg = s.max_field_value();
          },
          "The fields as written (a list of FieldPoint; assign a new list of FieldPoint or "
          "numbers to change them: the getter returns a copy).")
      .def_property(
          "object_distance_mm", [](const Specs& s) { return s.object_distance_mm; },
          [](Specs& s, double v) {
            require_as_written(s, "object_distance_mm");
            if (!(v > 0.0))
              throw Error("object_distance_mm = " + std::to_string(v) +
                          " must be > 0 (math.inf: at infinity)");
            s.object_distance_mm = v;
          },
          "Object to the first surface (mm); math.inf: at infinity")
      .def_property(
          "dispersion",
          [](const Specs& s) {
            return s.dispersion == DispersionModel::kAbbe ? "abbe" : "catalog";
          },
          [](Specs& s, const std::string& v) { s.dispersion = parse_dispersion(v); },
          "'abbe' (the paper's) or 'catalog'")
      .def("focal_length_mm", &Specs::focal_length_mm, "f = d / (2 tan(hfov))");

  py::class_<Lens>(m, "Lens", "A lens prescription with its specs (edit it in place).")
      .def(py::init<>())
      .def_readwrite("name", &Lens::name)
      .def_readwrite("catalog_name", &Lens::catalog_name, "catalog of its glass names ('ohara')")
      .def_readwrite("specs", &Lens::specs)
      .def_readwrite("surfaces", &Lens::surfaces)
      .def_readwrite("source_path", &Lens::source_path, "file it was read from")
      .def_readwrite("extra_toml", &Lens::extra_toml, "other TOML tables, verbatim")
      .def("stop_index", &Lens::stop_index, "index of the stop surface (-1: none)")
      .def("element_count", &Lens::element_count)
      .def("track_length_mm", &Lens::track_length_mm, "first to last vertex")
      .def("total_track_mm", &Lens::total_track_mm, "first vertex to image")
      .def("validate", &Lens::validate, "Raises LensoptError if the lens cannot be traced.")
      .def(
          "apply_solves",
          [](Lens& lens) {
            lens.validate();
            lens = with_solves(lens);
          },
          "Evaluates the pickups and marginal-ray-height solves in place (reading a file, "
          "analyze and optimize do it too).")
      .def(
          "add_coordinate_break",
          [](Lens& lens, int index, double thickness_mm, double decenter_x_mm, double decenter_y_mm,
             double tilt_x_deg, double tilt_y_deg, double tilt_z_deg, const std::string& order) {
            const int count = static_cast<int>(lens.surfaces.size());
            if (index < 0 || index > count)
              throw Error("add_coordinate_break: index " + std::to_string(index) +
                          " must be in 0.." + std::to_string(count) +
                          " (the break goes before surfaces[index]; " + std::to_string(count) +
                          ": after the last)");
            Surface s;
            s.coordinate_break = true;
            // The medium before it continues (as the TOML reader does).
            s.material = index == 0 ? Material::air()
                                    : lens.surfaces[static_cast<std::size_t>(index - 1)].material;
            s.thickness_mm = finite_placement(thickness_mm, "thickness_mm");
            s.placement.decenter_x_mm = finite_placement(decenter_x_mm, "decenter_x_mm");
            s.placement.decenter_y_mm = finite_placement(decenter_y_mm, "decenter_y_mm");
            s.placement.tilt_x_deg = finite_placement(tilt_x_deg, "tilt_x_deg");
            s.placement.tilt_y_deg = finite_placement(tilt_y_deg, "tilt_y_deg");
            s.placement.tilt_z_deg = finite_placement(tilt_z_deg, "tilt_z_deg");
            s.placement.tilt_first = tilt_first_of(order);
            lens.surfaces.insert(lens.surfaces.begin() + index, s);
            return index;
          },
          py::arg("index"), py::kw_only(), py::arg("thickness_mm") = 0.0,
          py::arg("decenter_x_mm") = 0.0, py::arg("decenter_y_mm") = 0.0,
          py::arg("tilt_x_deg") = 0.0, py::arg("tilt_y_deg") = 0.0, py::arg("tilt_z_deg") = 0.0,
          py::arg("order") = "decenter-first",
          "Inserts a coordinate break (TOML coordinate_break, .zmx COORDBRK) before "
          "surfaces[index]: it moves the frame of every surface after it; its thickness runs "
          "along the new z. Returns index.")
      .def("breaks_symmetry", &Lens::breaks_symmetry,
           "Some surface has a placement, is a coordinate break or has a decentred aperture.")
      .def(
          "scaled", [](const Lens& l, double s) { return scaled(l, s); }, py::arg("scale"),
          "The lens scaled uniformly (curvatures / s, lengths * s).")
      .def("to_toml", &format_lens_toml, "The native TOML text (lossless).")
      .def("to_zmx", &format_zmx, "The Zemax .zmx text.")
      .def("copy", [](const Lens& l) { return Lens(l); })
      .def("__copy__", [](const Lens& l) { return Lens(l); })
      .def("__deepcopy__", [](const Lens& l, py::dict) { return Lens(l); })
      .def(py::pickle(
          // The native TOML text is lossless (lens_io.h); the file it came from rides along.
          [](const Lens& l) { return py::make_tuple(format_lens_toml(l), l.source_path); },
          [](const py::tuple& t) {
            if (t.size() != 2) throw Error("a pickled Lens is (toml text, source path)");
            Lens l = parse_lens_toml(t[0].cast<std::string>(), "<pickled lens>");
            l.source_path = t[1].cast<std::string>();
            return l;
          }))
      .def("__repr__", [](const Lens& l) {
        return "<Lens '" + l.name + "', " + std::to_string(l.surfaces.size()) + " surfaces>";
      });

  m.def(
      "load_lens",
      [](const std::filesystem::path& path) {
        require_file(path);
        std::vector<std::string> warnings;
        Lens lens;
        if (lower_extension(path.string()) == ".zmx") {
          ZmxImport imported = read_zmx(path);
          warnings = std::move(imported.warnings);
          lens = std::move(imported.lens);
        } else {
          lens = read_lens(path);
        }
        for (std::string& w : f_number_warnings(lens)) warnings.push_back(std::move(w));
        if (!warnings.empty()) {
          py::object warn = py::module_::import("warnings").attr("warn");
          for (const std::string& w : warnings) warn(w);
        }
        return lens;
      },
      py::arg("path"),
      "Reads a lens (path: str or os.PathLike): .toml, the paper's .yml/.yaml or Zemax .zmx (its "
      "ignored lines and a paraxial F-number below 0.5 become Python warnings). Raises "
      "FileNotFoundError for a missing file, LensoptError with file:line:column for bad input.");
  m.def(
      "parse_lens",
      [](const std::string& text, const std::string& format, const std::string& source_name) {
        if (format == "toml") return parse_lens_toml(text, source_name);
        if (format == "yml" || format == "yaml") return parse_lens_yaml(text, source_name);
        if (format == "zmx") return parse_zmx(text, source_name).lens;
        throw Error("format must be 'toml', 'yml' or 'zmx', not '" + format + "'");
      },
      py::arg("text"), py::arg("format") = "toml", py::arg("source_name") = "<string>",
      "Parses lens text of a format ('toml', 'yml', 'zmx').");
  m.def(
      "save_lens",
      [](const Lens& lens, const std::filesystem::path& path) { write_lens(lens, path); },
      py::arg("lens"), py::arg("path"),
      "Writes a lens atomically (path: str or os.PathLike), by extension: .toml or Zemax .zmx.");
  m.def(
      "catalog_glasses",
      [](const std::string& name) {
        const auto cat = load_catalog(name);
        py::list out;
        for (const Glass& g : cat->glasses) out.append(py::make_tuple(g.name, g.nd, g.vd));
        return out;
      },
      py::arg("catalog") = "ohara", "(name, nd, vd) of every glass of a catalog.");
  m.def(
      "glass_index",
      [](const std::string& glass, double wavelength_nm, const std::string& catalog) {
        return load_catalog(catalog)->at(glass).index(wavelength_nm);
      },
      py::arg("glass"), py::arg("wavelength_nm"), py::arg("catalog") = "ohara",
      "Refractive index of a catalog glass from its own dispersion formula.");
}

}  // namespace lensopt::python
