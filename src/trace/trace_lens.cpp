#include "lensopt/trace/trace_lens.h"

#include <fmt/format.h>

#include <cmath>

#include "lensopt/core/error.h"

namespace lensopt {

std::string PrescriptionVariable::name() const {
  switch (kind) {
    case Kind::kCurvature:
      return fmt::format("c{}", surface + 1);
    case Kind::kThickness:
      return fmt::format("t{}", surface + 1);
    case Kind::kNd:
      return fmt::format("nd{}", surface + 1);
    case Kind::kVd:
      return fmt::format("vd{}", surface + 1);
  }
  return "?";
}

std::vector<PrescriptionVariable> all_prescription_variables(const Lens& lens) {
  using Kind = PrescriptionVariable::Kind;
  std::vector<PrescriptionVariable> out;
  const int k_count = static_cast<int>(lens.surfaces.size());
  for (int k = 0; k < k_count; ++k)
    if (!lens.surfaces[k].is_stop) out.push_back({Kind::kCurvature, k});
  for (int k = 0; k < k_count; ++k) out.push_back({Kind::kThickness, k});
  for (int k = 0; k < k_count; ++k)
    if (!lens.surfaces[k].material.is_air()) out.push_back({Kind::kNd, k});
  for (int k = 0; k < k_count; ++k)
    if (!lens.surfaces[k].material.is_air()) out.push_back({Kind::kVd, k});
  return out;
}

double variable_value(const Lens& lens, const PrescriptionVariable& v) {
  const Surface& s = lens.surfaces.at(v.surface);
  switch (v.kind) {
    case PrescriptionVariable::Kind::kCurvature:
      return s.curvature_per_mm;
    case PrescriptionVariable::Kind::kThickness:
      return s.thickness_mm;
    case PrescriptionVariable::Kind::kNd:
      return s.material.nd;
    case PrescriptionVariable::Kind::kVd:
      return s.material.vd;
  }
  return 0.0;
}

void set_variable_value(Lens& lens, const PrescriptionVariable& v, double value) {
  Surface& s = lens.surfaces.at(v.surface);
  switch (v.kind) {
    case PrescriptionVariable::Kind::kCurvature:
      s.curvature_per_mm = value;
      break;
    case PrescriptionVariable::Kind::kThickness:
      s.thickness_mm = value;
      break;
    case PrescriptionVariable::Kind::kNd:
      s.material.nd = value;
      break;
    case PrescriptionVariable::Kind::kVd:
      s.material.vd = value;
      break;
  }
}

std::vector<double> trace_wavelengths_nm(const Specs& specs) {
  std::vector<double> out = specs.wavelengths_nm;
  out.push_back(specs.primary_wavelength_nm);  // reference wavelength, last
  return out;
}

std::vector<double> catalog_offsets(const Glass& glass, double nd, double vd,
                                    const std::vector<double>& wavelengths_nm,
                                    const std::string& what) {
  if (!glass.formula_supported)
    throw Error(
        fmt::format("{}: glass {} uses an unsupported dispersion formula; use "
                    "dispersion = \"abbe\"",
                    what, glass.name));
  std::vector<double> out(wavelengths_nm.size());
  for (std::size_t w = 0; w < wavelengths_nm.size(); ++w)
    out[w] = glass.index(wavelengths_nm[w]) - abbe_index(nd, vd, wavelengths_nm[w]);
  return out;
}

TraceLens<double> make_trace_lens(const Lens& lens) {
  lens.validate();
  TraceLens<double> out;
  const int k_count = static_cast<int>(lens.surfaces.size());
  out.wavelengths_nm = trace_wavelengths_nm(lens.specs);
  out.stop = lens.stop_index();
  for (const Surface& s : lens.surfaces) {
    out.curvature_per_mm.push_back(s.curvature_per_mm);
    out.thickness_mm.push_back(s.thickness_mm);
    const bool glass = !s.material.is_air();
    out.is_glass.push_back(glass ? 1 : 0);
    out.nd.push_back(glass ? s.material.nd : 1.0);
    out.vd.push_back(glass ? s.material.vd : 0.0);
  }
  bool clips = false;
  for (const Surface& s : lens.surfaces) clips = clips || s.semi_diameter_mm > 0.0;
  // The stop's semi-diameter sets the pupil (float by stop size); it does not clip the aimed rays.
  // A clear aperture passes rays up to 1e-9 beyond its edge, so a pupil-edge ray that lies on it
  // (x^2 + y^2 = r^2 up to rounding) is not vignetted.
  constexpr double kEdgeTolerance = 1.0 + 1e-9;
  if (clips)
    for (const Surface& s : lens.surfaces)
      out.semi_diameter_mm.push_back(s.is_stop ? 0.0 : s.semi_diameter_mm * kEdgeTolerance);
  if (lens.specs.dispersion == DispersionModel::kCatalog) {
    out.catalog_offset.assign(k_count, std::vector<double>(out.wavelengths_nm.size(), 0.0));
    for (int k = 0; k < k_count; ++k) {
      const Material& m = lens.surfaces[k].material;
      if (m.kind != Material::Kind::kCatalog || !m.glass) continue;
      try {
        out.catalog_offset[k] = catalog_offsets(*m.glass, m.nd, m.vd, out.wavelengths_nm,
                                                fmt::format("surface {}", k + 1));
      } catch (const Error& e) {
        throw Error(SourceLocation{lens.source_path}, e.message());
      }
    }
  }
  return out;
}

}  // namespace lensopt
