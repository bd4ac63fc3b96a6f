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

TraceLens<double> make_trace_lens(const Lens& lens) {
  lens.validate();
  TraceLens<double> out;
  const int k_count = static_cast<int>(lens.surfaces.size());
  out.wavelengths_nm = lens.specs.wavelengths_nm;
  out.wavelengths_nm.push_back(kWavelengthD_nm);  // reference wavelength, last
  out.stop = lens.stop_index();
  for (const Surface& s : lens.surfaces) {
    out.curvature_per_mm.push_back(s.curvature_per_mm);
    out.thickness_mm.push_back(s.thickness_mm);
    const bool glass = !s.material.is_air();
    out.is_glass.push_back(glass ? 1 : 0);
    out.nd.push_back(glass ? s.material.nd : 1.0);
    out.vd.push_back(glass ? s.material.vd : 0.0);
  }
  if (lens.specs.dispersion == DispersionModel::kCatalog) {
    out.catalog_offset.assign(k_count, std::vector<double>(out.wavelengths_nm.size(), 0.0));
    for (int k = 0; k < k_count; ++k) {
      const Material& m = lens.surfaces[k].material;
      if (m.kind != Material::Kind::kCatalog || !m.glass) continue;
      if (!m.glass->formula_supported) {
        throw Error(SourceLocation{lens.source_path},
                    fmt::format("surface {}: glass {} uses an unsupported dispersion formula; use "
                                "dispersion = \"abbe\"",
                                k + 1, m.glass_name));
      }
      for (std::size_t w = 0; w < out.wavelengths_nm.size(); ++w) {
        const double wl = out.wavelengths_nm[w];
        out.catalog_offset[k][w] = m.glass->index(wl) - abbe_index(m.nd, m.vd, wl);
      }
    }
  }
  return out;
}

}  // namespace lensopt
