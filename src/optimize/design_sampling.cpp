// The design loss's sampling (optimize/design_sampling.h).
#include "lensopt/optimize/design_sampling.h"

#include <fmt/format.h>
#include <fmt/ranges.h>

#include <algorithm>
#include <cmath>

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
  // As written: the written fields (sorted, one per radial value; lens_setup) and the evenly
  // spread constraint values, merged in order.
  const SystemSetup written = lens_setup(structure, options);
  out.setup = written;
  out.setup.scale = false;
  const int n = static_cast<int>(written.field_values.size());
  const double largest = n > 0 ? written.field_values.back() : 0.0;
  std::vector<double> spread;
  if (largest > 0.0) {
    for (int i = 0; i < kConstraintFields; ++i)
      spread.push_back(largest * i / (kConstraintFields - 1));
  }
  std::vector<double> values, weights;
  std::vector<VignettingFactors> vignetting;
  std::vector<int> spot;
  const bool any_vignetting = !written.vignetting.empty();
  int i = 0;
  std::size_t j = 0;
  while (i < n || j < spread.size()) {
    const bool take_written = i < n && (j >= spread.size() || written.field_values[i] <= spread[j]);
    if (take_written) {
      // A spread value equal to a written one is that field.
      if (j < spread.size() && spread[j] == written.field_values[i]) ++j;
      values.push_back(written.field_values[i]);
      weights.push_back(
          i < static_cast<int>(written.field_weights.size()) ? written.field_weights[i] : 1.0);
      vignetting.push_back(any_vignetting ? written.vignetting[i] : VignettingFactors{});
      spot.push_back(i);
      ++i;
    } else {
      values.push_back(spread[j]);
      weights.push_back(1.0);
      vignetting.push_back({});
      spot.push_back(-1);
      ++j;
    }
  }
  out.setup.field_values = values;
  out.setup.field_weights = weights;
  out.setup.vignetting = any_vignetting ? vignetting : std::vector<VignettingFactors>{};
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
  for (std::size_t hf = 0; hf < d.spot_field.size(); ++hf) {
    if (d.spot_field[hf] < 0) continue;
    spot_values.push_back(d.setup.field_values[hf]);
    spot_weights.push_back(hf < d.setup.field_weights.size() ? d.setup.field_weights[hf] : 1.0);
  }
  const char* unit = d.setup.field_type == FieldType::kAngle ? "deg" : "mm";
  return fmt::format(
      "design sampling ({}): wavelengths {:g} nm (weights {:g}); spot fields {:g} {} (weights "
      "{:g}) among {} traced",
      specs.mode == SpecMode::kPaper ? "paper" : "as written",
      fmt::join(specs.wavelengths_nm, ", "), fmt::join(wavelength_weights, ", "),
      fmt::join(spot_values, ", "), unit, fmt::join(spot_weights, ", "),
      d.setup.field_values.size());
}

}  // namespace lensopt
