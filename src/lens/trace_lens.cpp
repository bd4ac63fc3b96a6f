#include "lensopt/lens/trace_lens.h"

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
    case Kind::kConic:
      return fmt::format("k{}", surface + 1);
    case Kind::kAsphere:
      return fmt::format("a{}_{}", 2 * term + 2, surface + 1);
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
  for (int k = 0; k < k_count; ++k) {
    const Surface& s = lens.surfaces[k];
    if (s.is_spherical()) continue;
    out.push_back({Kind::kConic, k});
    if (s.asphere_r2_per_mm != 0.0) out.push_back({Kind::kAsphere, k, 0});
    for (int j = 0; j < kAsphereOrders; ++j)
      if (s.asphere[j] != 0.0) out.push_back({Kind::kAsphere, k, j + 1});
  }
  return out;
}

bool parse_profile_variable(const std::string& name, PrescriptionVariable& out) {
  auto parse_int = [](const std::string& text, int& value) {
    if (text.empty() || text.size() > 3) return false;
    value = 0;
    for (char ch : text) {
      if (ch < '0' || ch > '9') return false;
      value = value * 10 + (ch - '0');
    }
    return true;
  };
  int surface = 0;
  if (name.size() >= 2 && name[0] == 'k' && parse_int(name.substr(1), surface) && surface >= 1) {
    out = {PrescriptionVariable::Kind::kConic, surface - 1, 0};
    return true;
  }
  const std::size_t bar = name.find('_');
  if (name.size() >= 4 && name[0] == 'a' && bar != std::string::npos) {
    int order = 0;
    if (!parse_int(name.substr(1, bar - 1), order) || !parse_int(name.substr(bar + 1), surface))
      return false;
    if (order < 2 || order > 16 || order % 2 != 0 || surface < 1) return false;
    out = {PrescriptionVariable::Kind::kAsphere, surface - 1, order / 2 - 1};
    return true;
  }
  return false;
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
    case PrescriptionVariable::Kind::kConic:
      return s.conic;
    case PrescriptionVariable::Kind::kAsphere:
      return v.term == 0 ? s.asphere_r2_per_mm : s.asphere.at(v.term - 1);
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
    case PrescriptionVariable::Kind::kConic:
      s.conic = value;
      break;
    case PrescriptionVariable::Kind::kAsphere:
      (v.term == 0 ? s.asphere_r2_per_mm : s.asphere.at(v.term - 1)) = value;
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
    out.is_glass.push_back(glass ? trace_glass_kind(s.material) : 0);
    out.nd.push_back(glass ? s.material.nd : 1.0);
    out.vd.push_back(glass ? s.material.vd : 0.0);
  }
  for (std::size_t k = 0; k < lens.surfaces.size(); ++k) {
    const Material& m = lens.surfaces[k].material;
    if (m.kind != Material::Kind::kModel || m.model_glass != ModelGlass::kZemax || m.dpgf == 0.0)
      continue;
    if (out.model_dpgf.empty()) out.model_dpgf.assign(lens.surfaces.size(), 0.0);
    out.model_dpgf[k] = m.dpgf;
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
  bool profiles = false;
  for (const Surface& s : lens.surfaces) profiles = profiles || !s.is_spherical();
  if (profiles) {
    out.ensure_profiles();
    for (int k = 0; k < k_count; ++k) {
      const Surface& s = lens.surfaces[k];
      out.conic[k] = s.conic;
      out.asphere[static_cast<std::size_t>(k) * kAsphereTerms] = s.asphere_r2_per_mm;
      for (int j = 0; j < kAsphereOrders; ++j)
        out.asphere[static_cast<std::size_t>(k) * kAsphereTerms + j + 1] = s.asphere[j];
      out.profile[k] =
          s.has_asphere() ? kProfileAsphere : (s.conic != 0.0 ? kProfileConic : kProfileSphere);
    }
  }
  out.geometry = make_trace_geometry<double>(lens);
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
