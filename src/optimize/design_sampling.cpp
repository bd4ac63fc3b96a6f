// The design loss's sampling (optimize/design_sampling.h).
#include "lensopt/optimize/design_sampling.h"

#include <fmt/format.h>
#include <fmt/ranges.h>

#include <algorithm>
#include <cmath>
#include <string>

#include "lensopt/core/constants.h"
#include "lensopt/optimize/design_loss.h"

namespace lensopt {

DesignSampling design_sampling(const Lens& structure, const TraceOptions& sampling) {
  DesignSampling out;
  TraceOptions options = sampling;
  options.scale_to_spec = false;
  const Specs& specs = structure.specs;
  if (specs.mode == SpecMode::kPaper || specs.fields.empty()) {
    // Every stride-th of the constraint fields 0..hfov is a spot field.
    options.fields = constraint_field_count(sampling.fields, kConstraintFields);
    out.setup = specs.mode == SpecMode::kPaper ? specs_setup(specs, options)
                                               : lens_setup(structure, options);
    out.setup.scale = false;
    const int all = static_cast<int>(out.setup.field_values.size());
    const int stride = sampling.fields > 1 ? (all - 1) / (sampling.fields - 1) : 1;
    out.spot_fields = sampling.fields > 1 ? sampling.fields : 1;
    out.spot_field.assign(all, -1);
    for (int hf = 0; hf < all; ++hf)
      if (hf % stride == 0) out.spot_field[hf] = hf / stride;
    return out;
  }
  // As written: the written fields (sorted by radial value; lens_setup keeps each field's azimuth,
  // TraceSystem::field_azimuth_deg) and the evenly spread constraint values on +y, merged in
  // order. A lens without rotational symmetry traces every field where it is written: a field on
  // -y or on x keeps its azimuth, and a spread value equal to a written field's radial value is
  // that field only when it lies on +y (on a symmetric lens every azimuth traces the same rays).
  const SystemSetup written = lens_setup(structure, options);
  out.setup = written;
  out.setup.scale = false;
  const bool rotational = !structure.breaks_symmetry();
  const int n = static_cast<int>(written.field_values.size());
  const bool any_azimuth = written.field_azimuth_deg.size() == written.field_values.size() &&
                           !written.field_azimuth_deg.empty();
  auto azimuth_of = [&](int i) { return any_azimuth ? written.field_azimuth_deg[i] : 0.0; };
  const double largest = n > 0 ? written.field_values.back() : 0.0;
  std::vector<double> spread;
  if (largest > 0.0) {
    for (int i = 0; i < kConstraintFields; ++i)
      spread.push_back(largest * i / (kConstraintFields - 1));
  }
  std::vector<double> values, weights, azimuths;
  std::vector<VignettingFactors> vignetting;
  std::vector<int> spot;
  const bool any_vignetting = !written.vignetting.empty();
  int i = 0;
  std::size_t j = 0;
  while (i < n || j < spread.size()) {
    const bool take_written = i < n && (j >= spread.size() || written.field_values[i] <= spread[j]);
    if (take_written) {
      // A spread value equal to a written one is that field (on +y, or any field of a
      // rotationally symmetric lens).
      if (j < spread.size() && spread[j] == written.field_values[i] &&
          (rotational || azimuth_of(i) == 0.0))
        ++j;
      values.push_back(written.field_values[i]);
      weights.push_back(
          i < static_cast<int>(written.field_weights.size()) ? written.field_weights[i] : 1.0);
      vignetting.push_back(any_vignetting ? written.vignetting[i] : VignettingFactors{});
      azimuths.push_back(azimuth_of(i));
      spot.push_back(i);
      ++i;
    } else {
      values.push_back(spread[j]);
      weights.push_back(1.0);
      vignetting.push_back({});
      azimuths.push_back(0.0);
      spot.push_back(-1);
      ++j;
    }
  }
  out.setup.field_values = values;
  out.setup.field_weights = weights;
  out.setup.vignetting = any_vignetting ? vignetting : std::vector<VignettingFactors>{};
  // Each traced field's azimuth (before, the merged list lost them: its length no longer matched
  // and prepare_system traced every field on +y, a field on -y or x of a decentred lens as the
  // mirror of +y).
  out.setup.field_azimuth_deg = any_azimuth ? azimuths : std::vector<double>{};
  out.spot_field = spot;
  out.spot_fields = n;
  return out;
}

std::string describe_design_sampling(const Lens& structure, const TraceOptions& sampling) {
  const DesignSampling d = design_sampling(structure, sampling);
  const Specs& specs = structure.specs;
  std::vector<double> wavelength_weights = specs.wavelength_weights;
  if (wavelength_weights.size() != specs.wavelengths_nm.size())
    wavelength_weights.assign(specs.wavelengths_nm.size(), 1.0);
  std::vector<double> spot_values, spot_weights;
  std::vector<std::string> spot_points;  // "(x, y)" of each spot field when any is off +y
  bool off_axis = false;
  for (std::size_t hf = 0; hf < d.spot_field.size(); ++hf) {
    if (d.spot_field[hf] < 0) continue;
    const double r = d.setup.field_values[hf];
    const double a = hf < d.setup.field_azimuth_deg.size() ? d.setup.field_azimuth_deg[hf] : 0.0;
    off_axis = off_axis || a != 0.0;
    // The field point (x, y) = r (sin a, cos a), rounded to print exactly on the axes.
    const double x = a == 0.0 ? 0.0 : std::round(r * std::sin(a * kDegToRad) * 1e12) / 1e12;
    const double y = a == 0.0 ? r : std::round(r * std::cos(a * kDegToRad) * 1e12) / 1e12;
    spot_points.push_back(fmt::format("({:g}, {:g})", x == 0.0 ? 0.0 : x, y == 0.0 ? 0.0 : y));
    spot_values.push_back(r);
    spot_weights.push_back(hf < d.setup.field_weights.size() ? d.setup.field_weights[hf] : 1.0);
  }
  const char* unit = d.setup.field_type == FieldType::kAngle ? "deg" : "mm";
  return fmt::format(
      "design sampling ({}): wavelengths {:g} nm (weights {:g}); spot fields {} {} (weights "
      "{:g}) among {} traced",
      specs.mode == SpecMode::kPaper ? "paper" : "as written",
      fmt::join(specs.wavelengths_nm, ", "), fmt::join(wavelength_weights, ", "),
      off_axis ? fmt::format("{}", fmt::join(spot_points, ", "))
               : fmt::format("{:g}", fmt::join(spot_values, ", ")),
      unit, fmt::join(spot_weights, ", "), d.setup.field_values.size());
}

}  // namespace lensopt
