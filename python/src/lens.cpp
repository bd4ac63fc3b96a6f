// Lenses in Python: Material, Surface, Specs, Lens (edited in place), reading and writing every
// format the core knows (.toml, the paper's .yml, Zemax .zmx), glass catalogs.
#include <pybind11/stl_bind.h>

#include <cmath>
#include <limits>

#include "bindings.h"
#include "lensopt/core/error.h"
#include "lensopt/formats/lens_file.h"
#include "lensopt/formats/zmx.h"
#include "lensopt/glass/glass.h"
#include "lensopt/lens/lens_io.h"
#include "lensopt/lens/validate.h"

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
      .def("__repr__", [](const Surface& s) {
        return "<Surface c=" + std::to_string(s.curvature_per_mm) +
               "/mm t=" + std::to_string(s.thickness_mm) + "mm " + s.material.label() +
               (s.is_stop ? " stop" : "") + ">";
      });

  py::bind_vector<std::vector<Surface>>(m, "SurfaceList",
                                        "The lens's surfaces, edited in place (a list).");

  py::class_<Specs>(m, "Specs", "First-order specifications and wavelength sampling.")
      .def(py::init<>(), "The paper's defaults: f/2, 25 deg, 16 mm, 15 wavelengths.")
      .def_readwrite("f_number", &Specs::f_number)
      .def_readwrite("half_field_deg", &Specs::half_field_deg)
      .def_readwrite("sensor_diagonal_mm", &Specs::sensor_diagonal_mm)
      .def_readwrite("wavelengths_nm", &Specs::wavelengths_nm)
      .def_readwrite("wavelength_channels", &Specs::wavelength_channels,
                     "0 = R, 1 = G, 2 = B, one per wavelength")
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
          "scaled", [](const Lens& l, double s) { return scaled(l, s); }, py::arg("scale"),
          "The lens scaled uniformly (curvatures / s, lengths * s).")
      .def("to_toml", &format_lens_toml, "The native TOML text (lossless).")
      .def("to_zmx", &format_zmx, "The Zemax .zmx text.")
      .def("copy", [](const Lens& l) { return Lens(l); })
      .def("__copy__", [](const Lens& l) { return Lens(l); })
      .def("__deepcopy__", [](const Lens& l, py::dict) { return Lens(l); })
      .def("__repr__", [](const Lens& l) {
        return "<Lens '" + l.name + "', " + std::to_string(l.surfaces.size()) + " surfaces>";
      });

  m.def(
      "load_lens",
      [](const std::string& path) {
        std::vector<std::string> warnings;
        Lens lens;
        if (lower_extension(path) == ".zmx") {
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
      "Reads a lens: .toml, the paper's .yml/.yaml or Zemax .zmx (its ignored lines and a "
      "paraxial F-number below 0.5 become Python warnings). Raises LensoptError with "
      "file:line:column.");
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
      "save_lens", [](const Lens& lens, const std::string& path) { write_lens(lens, path); },
      py::arg("lens"), py::arg("path"),
      "Writes a lens atomically, by extension: .toml or Zemax .zmx.");
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
