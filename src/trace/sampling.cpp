#include <fmt/format.h>

#include <algorithm>

#include "lensopt/core/error.h"
#include "lensopt/paraxial/solves.h"
#include "lensopt/trace/system.h"

namespace lensopt {

void TraceOptions::validate() const {
  if (rings < 1 || rings > 256) throw Error(fmt::format("rings = {} must be in [1, 256]", rings));
  if (fields < 1 || fields > 1000)
    throw Error(fmt::format("fields = {} must be in [1, 1000]", fields));
  if (threads < 0) throw Error(fmt::format("threads = {} must be >= 0", threads));
}

PupilSamples paper_pupil_samples(int rings) {
  // Every prepared system asks for the same pattern (a tolerancing run once per trial): the last
  // one is kept per thread and copied, which costs far less than its 2 R^2 sines and cosines.
  thread_local int cached_rings = -1;
  thread_local PupilSamples cached;
  if (rings == cached_rings) return cached;
  PupilSamples out;
  const double spacing = 1.0 / (2.0 * rings - 1.0);
  int k = 0;  // running ray index over all rings
  for (int i = 0; i < rings; ++i) {
    const int ring_count = 2 * i + 1;
    for (int j = 0; j < ring_count; ++j, ++k) {
      const double azimuth = ((j + 0.5) / ring_count - 0.5) * kPi;
      const double radius = 2.0 * i * spacing + ((k + i) % 2) * spacing;
      out.x.push_back(radius * std::cos(azimuth));
      out.y.push_back(radius * std::sin(azimuth));
    }
  }
  cached = out;
  cached_rings = rings;
  return out;
}

PupilSamples mirrored_pupil(const PupilSamples& half) {
  PupilSamples out;
  const std::size_t n = half.size();
  out.x.resize(2 * n);
  out.y.resize(2 * n);
  for (std::size_t i = 0; i < n; ++i) {
    out.x[i] = half.x[i];
    out.y[i] = half.y[i];
    out.x[n + i] = -half.x[i];
    out.y[n + i] = half.y[i];
  }
  return out;
}

bool needs_full_pupil(const std::vector<VignettingFactors>& vignetting) {
  for (const VignettingFactors& v : vignetting)
    if (v.asymmetric()) return true;
  return false;
}

PupilSamples pupil_edge_samples(int count) {
  PupilSamples out;
  for (int j = 0; j < count; ++j) {
    const double azimuth = count == 1 ? 0.0 : (-0.5 + static_cast<double>(j) / (count - 1)) * kPi;
    out.x.push_back(std::cos(azimuth));
    out.y.push_back(std::sin(azimuth));
  }
  return out;
}

SystemSetup paper_setup(double focal_length_mm, double f_number, double half_field_deg,
                        int field_count) {
  SystemSetup setup;
  setup.scale = true;
  setup.focal_length_mm = focal_length_mm;
  setup.aperture_type = ApertureType::kFNumber;
  setup.f_number = f_number;
  setup.field_type = FieldType::kAngle;
  setup.field_values = field_angles_deg(half_field_deg, field_count);
  return setup;
}

SystemSetup specs_setup(const Specs& specs, const TraceOptions& options, bool rotational) {
  // The wavelength weights hold in both modes (the wavelengths are the lens's in both).
  const std::vector<double> wavelength_weights =
      specs.wavelength_weights.size() == specs.wavelengths_nm.size() ? specs.wavelength_weights
                                                                     : std::vector<double>{};
  if (specs.mode == SpecMode::kPaper) {
    SystemSetup setup =
        paper_setup(specs.focal_length_mm(), specs.f_number, specs.half_field_deg, options.fields);
    setup.scale = options.scale_to_spec;
    setup.wavelength_weights = wavelength_weights;
    return setup;
  }
  SystemSetup setup;
  setup.wavelength_weights = wavelength_weights;
  setup.scale = false;
  setup.aperture_type = specs.aperture_type;
  setup.f_number = specs.f_number;
  setup.aperture_value = specs.aperture_value;
  setup.object_distance_mm = specs.object_distance_mm;
  setup.field_type = specs.field_type;
  if (specs.fields.empty()) {
    setup.field_values = field_angles_deg(specs.half_field_deg, options.fields);
    setup.field_type = FieldType::kAngle;
    return setup;
  }
  // Each field as its radial distance and azimuth (FieldPoint): a field on -y of a rotationally
  // symmetric lens is the field on +y (mirrored), one off the y axis keeps its azimuth, and so
  // does one on -y of a lens without that symmetry (turned by 180 deg).
  std::vector<FieldPoint> fields = specs.fields;
  std::vector<double> azimuths;
  for (FieldPoint& f : fields) {
    const double a = f.x != 0.0 ? f.azimuth_deg() : (!rotational && f.value < 0.0) ? 180.0 : 0.0;
    f.value = f.radius();
    f.x = a;  // the azimuth rides along through the sort and the merge below
  }
  std::stable_sort(fields.begin(), fields.end(),
                   [](const FieldPoint& a, const FieldPoint& b) { return a.value < b.value; });
  // Fields at the same radial distance are one field (their weights add), unless their
  // vignetting factors differ (say a field on +y and one on -y with VDY set: different pupils).
  auto same_pupil = [](const VignettingFactors& a, const VignettingFactors& b) {
    return a.vdx == b.vdx && a.vdy == b.vdy && a.vcx == b.vcx && a.vcy == b.vcy &&
           a.van_deg == b.van_deg;
  };
  std::vector<FieldPoint> unique;
  for (const FieldPoint& f : fields) {
    if (!unique.empty() && unique.back().value == f.value && unique.back().x == f.x &&
        same_pupil(unique.back().vignetting, f.vignetting)) {
      unique.back().weight += f.weight;
    } else {
      unique.push_back(f);
    }
  }
  fields = unique;
  bool any_vignetting = false, any_azimuth = false;
  for (const FieldPoint& f : fields) {
    setup.field_values.push_back(f.value);
    setup.field_azimuth_deg.push_back(f.x);
    any_azimuth = any_azimuth || f.x != 0.0;
    setup.field_weights.push_back(f.weight);
    setup.vignetting.push_back(f.vignetting);
    any_vignetting = any_vignetting || f.vignetting.any();
  }
  if (!any_vignetting) setup.vignetting.clear();
  if (!any_azimuth) setup.field_azimuth_deg.clear();
  return setup;
}

SystemSetup lens_setup(const Lens& lens, const TraceOptions& options) {
  SystemSetup setup = specs_setup(lens.specs, options, !lens.breaks_symmetry());
  const int stop = lens.stop_index();
  if (stop >= 0) setup.stop_semi_diameter_mm = lens.surfaces[stop].semi_diameter_mm;
  if (setup.aperture_type == ApertureType::kFloatByStop && !(setup.stop_semi_diameter_mm > 0.0))
    throw Error(SourceLocation{lens.source_path},
                "aperture 'float by stop size' needs the stop's semi-diameter");
  return setup;
}

TraceSystem<double> prepare_lens_system(const Lens& lens, const TraceOptions& options) {
  options.validate();
  // Pickups and solves evaluated on the lens as it is now (paraxial/solves.h): a lens edited
  // since it was read (Python) is traced with its solves met.
  TraceLens<double> trace_lens = make_trace_lens(lens);
  if (lens.has_solves())
    apply_pickups_and_solves(trace_lens, LensSolves::of(lens), 1.0, 0, trace_lens.surface_count());
  TraceSystem<double> sys = prepare_system(trace_lens, lens_setup(lens, options), options);
  if (!sys.field_solve_failure.empty())
    throw Error(SourceLocation{lens.source_path.empty() ? lens.name : lens.source_path},
                sys.field_solve_failure);
  return sys;
}

double lens_spec_scale(const Lens& lens) {
  const SystemSetup setup = specs_setup(lens.specs, TraceOptions{});
  if (!setup.scale) return 1.0;
  const TraceLens<double> trace_lens = make_trace_lens(lens);
  return spec_scale(setup.focal_length_mm,
                    paraxial_data(trace_lens, trace_lens.reference_nm()).efl_mm);
}

std::vector<double> field_angles_deg(double half_field_deg, int count) {
  std::vector<double> out;
  if (count == 1) return {0.0};
  for (int i = 0; i < count; ++i) out.push_back(half_field_deg * i / (count - 1));
  return out;
}

}  // namespace lensopt
